"""The main job: every fast method against its reference, as one HTML report folder.

``make_report(scenes, out, ...)`` runs, for each scene, the Mitsuba reference (from the
cache; rendered only when missing) and every built fast method that applies to it
(:mod:`translucent.fast.base`: ``precompute`` then ``state.render()``, both timed), compares
each image with the reference (:func:`translucent.reports.metrics.evaluate`: HDR-FLIP,
LDR-FLIP, relative MSE with the reference noise discounted, RMSE, PSNR, SSIM, CIEDE2000)
and writes one self-contained folder::

    OUT/index.html        images side by side, error maps, metrics, times, skipped notes
    OUT/metrics.json      the same numbers for tools
    OUT/SCENE/reference.{png,exr}, OUT/SCENE/METHOD.{png,exr},
    OUT/SCENE/METHOD_{flip,relative_error,ciede2000,ssim}.{png,exr}

The folder is built under a temporary name beside ``OUT`` and renamed when complete, so
an interrupted or failed run leaves no half-written report (a previous report in ``OUT``
is replaced only then).

Reference renders and method runs are independent tasks
(:func:`translucent.reports.distributed.run_tasks`): a local Dask process cluster by
default, a Dask scheduler with ``scheduler=``, or this process with ``serial=True``.
A method run is kept in the ``"report"`` cache, keyed by the scene, the method, its knobs,
the versions and a hash of the source of the packages it depends on; a second report with
nothing changed therefore renders nothing and shows the image and times measured when it
was first rendered (the page says so). A method that fails shows its error in the page and
the run goes on; one that is not built yet or does not apply to a scene is listed with the
reason.

Regression: the four gated metrics (:data:`TOLERANCES`) are compared with a stored baseline
(``reports/baseline/default.json`` for the default scenes); a result worse than its
baseline beyond the metric's tolerance, or a baseline entry that now has no result, is a
regression: marked in the page, listed in ``metrics.json``, exit code 1.
``update_baseline=True`` writes the run's numbers into the baseline (atomically).
"""

from __future__ import annotations

import hashlib
import json
import os
import re
import shutil
import sys
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from ..atomic import atomic_write_text, check_output_folder
from ..errors import InputError, check_count
from ..image import Image
from .regression import (
    BASELINE_FORMAT,
    DEFAULT_BASELINE,
    METRIC_LABELS,
    REPORTED_METRICS,
    TOLERANCES,
    BaselineCheck,
    Tolerance,
    check_against_baseline,
    load_baseline,
    updated_baseline,
)
from .renderer_images import renderer_images, renderers_in
from .report_page import html_page
from .report_summary import print_summary, speedup_fields, summary_rows, task_time
from .runs import (
    MethodRun,
    backend_versions,
    committed_reference_for,
    json_safe,
    portable_scene,
    render_reference,
    report_task,
    run_method,
    timestamp,
)
from .scoring import score_scene
from .speedup import PATH_TRACING_SPP

__all__ = [
    "METRIC_LABELS",
    "REPORTED_METRICS",
    "committed_reference_for",
    "json_safe",
    "render_reference",
    "reference_path",
    "BASELINE_FORMAT",
    "DEFAULT_BASELINE",
    "DEFAULT_PASSES",
    "DEFAULT_REFERENCE_BUDGET",
    "DEFAULT_TARGET_RSE",
    "backend_versions",
    "EXCLUDED_SCENES",
    "TOLERANCES",
    "BaselineCheck",
    "MethodRun",
    "ReportResult",
    "Tolerance",
    "check_against_baseline",
    "default_scenes",
    "load_baseline",
    "make_report",
    "run_method",
    "updated_baseline",
]

#: Independent reference passes of a reference rendered with an explicit ``--spp``: 4 give
#: the per-pixel variance the relative MSE discounts.
DEFAULT_PASSES = 4

#: A scene without a committed reference (a user's own, or a built-in one given by file)
#: is rendered progressively (:func:`~translucent.reference.render.render_to_target`) to
#: this median relative standard error over its lit pixels ...
DEFAULT_TARGET_RSE = 0.02

#: ... or until this many seconds of rendering are spent, whichever comes first.
DEFAULT_REFERENCE_BUDGET = 300.0

#: Samples per pixel of each pass of such a progressive reference.
PROGRESSIVE_SPP = 32

#: The largest method precomputation (bytes) a report keeps in the cache by default
#: (``--keep-precomputations`` keeps all): PRT's and BRDF-PCA's tens of MB are kept,
#: radiosity's dense operators on the default spheres (1-3 GB each) are not.
REPORT_CACHE_ENTRY_LIMIT = 256 * 2**20

#: Bumped when what a cached method run holds changes, so older entries miss (2: the warm
#: frame is the median of relit frames).
RUN_FORMAT = 2

#: Frames rendered after the first, with the scene's lights given again: their median is
#: the warm frame time the page shows (compiling kernels and first-call costs excluded).
REPORT_RELIGHT_FRAMES = 3

#: Points of each method's quality ladder the report runs besides its defaults: the
#: cheapest settings of its first ladder (the method's ``LADDERS`` or knob spec:
#: :func:`~translucent.reports.bench.tradeoff.declared_ladders`), so that the plot shows
#: which way, and how fast, the error falls with cost.
#: One point keeps a fresh report within 5 minutes on the 2-core machine (docs/report.md).
REPORT_LADDER_POINTS = 1

#: The owner of a ladder run among a report's tasks: ``(LADDER, method name)``.
LADDER = "ladder"


def ladder_knobs(module, name: str, points: int = REPORT_LADDER_POINTS) -> list[dict]:
    """Return the knob settings of the report's ladder for a method (cheap first).

    The first ``points`` settings of the method's first quality ladder that differ from its
    defaults; [] for a method with none.
    """
    from .bench.tradeoff import declared_ladders

    ladders = declared_ladders(module, name) or {}
    defaults = getattr(module, "DEFAULT_KNOBS", {}) or {}
    for settings in ladders.values():
        chosen = [knobs for knobs in settings if knobs and set(knobs) <= set(defaults)
                  and any(defaults[k] != v for k, v in knobs.items())]
        return chosen[:points]
    return []


def _keep_run(report, owner, run: MethodRun) -> None:
    """File a finished run under its method, or under its method's ladder."""
    if isinstance(owner, tuple) and owner[0] == LADDER:
        report.ladders.setdefault(owner[1], []).append(run)
    else:
        report.runs[owner] = run

#: The owner name of a scene's path-tracing ladder task (not a method).
PATH_TRACING = "path tracing"

#: Built-in scenes the default run leaves out, and why (shown in the page).
EXCLUDED_SCENES: dict[str, str] = {
    "heterogeneous": "a SubEdit texture is a surface model with no physical counterpart, so "
                     "it has no volumetric reference; solid_checker, solid_gradient and "
                     "solid_veins are heterogeneous media defined in the volume, rendered by "
                     "the reference and read at the surface by splatting and radiosity; "
                     "this scene stays the splatting benchmark's (`translucent bench "
                     "splatting`)",
    "furnace_sphere": "a check of the reference renderer (a Lambertian sphere in a constant "
                      "environment renders 0.5); it has no translucent object and no analytic "
                      "BRDF, so no fast method has anything to approximate",
    "slab_beam": "the slab-capture set-up for fitting: a narrow beam seen by a camera path "
                 "tracer is black or very noisy away from the beam (docs/references.md), so its "
                 "reference is no usable truth for image metrics; give it by name to run it",
    "glossy_cornell": "the 400 x 400 scene of `translucent bench brdf_pca` (Nguyen et al. "
                      "2010, Table 5): its reference and precomputation alone would take most "
                      "of a first run's 10 minutes; the glossy scene covers BRDF editing at "
                      "96 x 72; give it by name to run it",
}

#: The packages whose source decides a method's image: a change there re-runs the methods.
SOURCE_FOLDERS = ("fast", "materials", "scenes")
SOURCE_FILES = ("image.py", "backend.py", "cache.py", "errors.py")


# ====================================================================== scenes and caches


def default_scenes() -> tuple[list[str], dict[str, str]]:
    """Return the built-in scenes a default report covers and those it leaves out (with why).

    Returns
    -------
    names : list of str
        Every built-in scene but those in :data:`EXCLUDED_SCENES`.
    excluded : dict of str to str
        Scene name -> the reason it is left out.
    """
    from ..scenes import builtin_scene_names

    names = builtin_scene_names()
    excluded = {name: reason for name, reason in EXCLUDED_SCENES.items() if name in names}
    return [name for name in names if name not in excluded], excluded


def _source_fingerprint() -> str:
    """SHA-256 of the source files a method's image depends on."""
    root = Path(__file__).resolve().parents[1]
    digest = hashlib.sha256()
    paths = [root / name for name in SOURCE_FILES]
    for folder in SOURCE_FOLDERS:
        paths += sorted((root / folder).rglob("*.py"))
    for path in paths:
        if path.is_file():
            digest.update(str(path.relative_to(root)).encode())
            digest.update(path.read_bytes())
    return digest.hexdigest()


def _run_key(method_name: str, scene, knobs: dict, fingerprint: str, versions: dict) -> str:
    from ..cache import content_hash

    return content_hash("report-run", RUN_FORMAT, method_name, scene, knobs, fingerprint,
                        versions)


def reference_path(scene, spp: int, passes: int) -> Path:
    """Where the reference ``render(scene, spp=spp, passes=passes)`` is cached (may not exist).

    The settings are those of :func:`translucent.reference.render` with its own defaults, read
    from its signature, so a change of a default there cannot make this look in the wrong
    place.
    """
    import inspect

    from ..cache import Cache
    from ..reference.render import reference_key, reference_settings, render

    defaults = {name: parameter.default
                for name, parameter in inspect.signature(render).parameters.items()
                if parameter.default is not inspect.Parameter.empty}
    wanted = inspect.signature(reference_settings).parameters
    settings = reference_settings(**{**{name: defaults[name] for name in wanted
                                        if name in defaults}, "spp": spp, "passes": passes})
    return Cache("reference").path(reference_key(scene, settings), ".exr")


def _unconvertible(scene) -> str:
    """Return why Mitsuba cannot take ``scene`` (no render needed to know), or ""."""
    from ..reference import convert_scene

    try:
        convert_scene(scene)
    except InputError as error:
        return f"InputError: {error}"
    return ""


def _cached_reference(scene, spp: int, passes: int) -> Image | None:
    from ..image import read_exr

    path = reference_path(scene, spp, passes)
    if not path.is_file():
        return None
    try:
        return read_exr(path)
    except InputError:
        return None  # unreadable: rendered again


# ====================================================================== the run


@dataclass
class SceneReport:
    """Everything the page shows for one scene (internal to the report)."""

    name: str
    slug: str
    scene: Any
    scene_hash: str
    spp: int
    reference: Image | None = None
    reference_error: str = ""
    reference_cached: bool = False
    #: "committed", "progressive" or "fixed passes"
    reference_source: str = ""
    #: the reference's noise (:class:`~translucent.noise.NoiseSummary`) and its warning
    reference_noise: Any = None
    noise_warning: str = ""
    #: the noise floor of every metric (:func:`~translucent.reports.metrics.noise_floor`)
    noise_floor: dict | None = None
    verdicts: dict[str, dict[str, str]] = field(default_factory=dict)
    #: the pixels scored (those that see an object of the scene) and the whole-image scores
    scored_mask: Any = None
    image_metrics: dict[str, dict] = field(default_factory=dict)
    runs: dict[str, MethodRun] = field(default_factory=dict)
    metrics: dict[str, dict] = field(default_factory=dict)
    metric_errors: dict[str, str] = field(default_factory=dict)
    checks: dict[str, BaselineCheck] = field(default_factory=dict)
    files: dict[str, dict[str, str]] = field(default_factory=dict)
    #: what the path-tracing ladder task returned, its scored curve, each method's speed-up
    #: (:mod:`translucent.reports.speedup`)
    path_tracing: Any = None
    curve: Any = None
    speedups: dict[str, dict] = field(default_factory=dict)
    #: per method, the objects it is scored on; where fewer than the scene's, its pixels
    #: and noise floor (:mod:`translucent.reports.scoring`), kept per set of objects
    scored_objects: dict[str, list[str]] = field(default_factory=dict)
    method_masks: dict[str, Any] = field(default_factory=dict)
    method_floors: dict[str, dict | None] = field(default_factory=dict)
    object_masks: dict[tuple, tuple] = field(default_factory=dict)
    object_curves: dict[tuple, Any] = field(default_factory=dict)
    #: per method, its runs at the cheap end of its quality ladder (:func:`ladder_knobs`),
    #: and their (frame seconds, relative MSE on its scored pixels)
    ladders: dict[str, list[MethodRun]] = field(default_factory=dict)
    ladder_points: dict[str, list[dict]] = field(default_factory=dict)

    def mask_of(self, name: str):
        """Return the pixels method ``name`` is scored on (None: the whole image)."""
        return self.method_masks.get(name, self.scored_mask)

    def floor_of(self, name: str) -> dict | None:
        """Return the noise floor of every metric over the pixels ``name`` is scored on."""
        return self.method_floors.get(name, self.noise_floor)


@dataclass
class ReportResult:
    """What :func:`make_report` did.

    Parameters
    ----------
    exit_code : int
        0 fine, 1 a regression against the baseline.
    out : Path
        The report folder.
    regressions : list of str
        ``"scene/method: message"`` for each regression.
    seconds : float
        Wall-clock seconds of the whole run.
    summary : list of dict
        Per scene and method: status, the gated metrics, times, baseline verdict.
    """

    exit_code: int
    out: Path
    regressions: list[str]
    seconds: float
    summary: list[dict]


def _check_out(out) -> Path:
    """Check ``out`` can take a report before anything is computed."""
    out = check_output_folder(Path(out).expanduser(), "--out")
    if out.is_dir() and any(out.iterdir()) and not (out / "metrics.json").is_file():
        raise InputError("is a folder with other files in it; give a new or empty folder (a "
                         "previous report there is replaced)", field="--out", value=str(out))
    ancestor = out.absolute().parent
    while not ancestor.exists():
        ancestor = ancestor.parent
    if not os.access(ancestor, os.W_OK | os.X_OK):
        raise InputError(f"cannot be created: {ancestor} is not writable", field="--out",
                         value=str(out))
    return out


def _methods(methods) -> list[str]:
    from ..fast.base import METHODS

    if methods is None:
        return list(METHODS)
    chosen = []
    for name in methods:
        name = str(name).strip()
        if name not in METHODS:
            raise InputError(f"unknown fast method; valid: {', '.join(METHODS)}",
                             field="--methods", value=name)
        if name not in chosen:
            chosen.append(name)
    if not chosen:
        raise InputError(f"no method given; valid: {', '.join(METHODS)}", field="--methods",
                         value=methods)
    return chosen


def _check_distinct_names(scenes) -> None:
    """Refuse two scenes of one name: metrics.json and the baseline key results by name."""
    seen: dict[str, Any] = {}
    for scene in scenes:
        if scene.name in seen:
            sources = [str(getattr(s, "source", None) or "given as a Scene")
                       for s in (seen[scene.name], scene)]
            raise InputError(f"two scenes are named {scene.name!r} ({sources[0]}; "
                             f"{sources[1]}); results are kept by scene name: give each "
                             "scene once, with a name of its own", field="scenes",
                             value=scene.name)
        seen[scene.name] = scene


def _slug(name: str, taken: set[str]) -> str:
    slug = re.sub(r"[^A-Za-z0-9_.-]+", "_", name).strip("._") or "scene"
    candidate, count = slug, 2
    while candidate in taken:
        candidate, count = f"{slug}-{count}", count + 1
    taken.add(candidate)
    return candidate


def make_report(scenes=None, out="report", *, methods=None, baseline=None,
                update_baseline: bool = False, scheduler: str | None = None,
                serial: bool = False, spp: int | None = None, passes: int = DEFAULT_PASSES,
                progress: bool = True, stream=None,
                keep_precomputations: bool = False, images=None) -> ReportResult:
    """Run the report: references, fast methods, metrics, error maps, baseline, HTML.

    Parameters
    ----------
    scenes : list of str or Scene, optional
        Built-in scene names, scene files or scenes; default :func:`default_scenes`.
    out : str or PathLike
        The report folder (created; a previous report there is replaced).
    methods : list of str, optional
        Fast methods to run; default all of :data:`translucent.fast.base.METHODS` (those
        not built yet are listed as such).
    baseline : str or PathLike, optional
        Baseline JSON; default :data:`DEFAULT_BASELINE`. A file given explicitly must exist
        unless ``update_baseline``.
    update_baseline : bool
        Write this run's metrics into the baseline (atomically) and exit 0.
    scheduler : str, optional
        Dask scheduler address for the tasks; None: a local process cluster.
    serial : bool
        Run every task in this process, without Dask.
    spp : int, optional
        Render every reference afresh in ``passes`` fixed passes of this many samples per
        pixel. Default: a built-in scene's committed reference
        (:mod:`translucent.reference.committed`; a stale one is an error), and for any
        other scene a progressive render to :data:`DEFAULT_TARGET_RSE` within
        :data:`DEFAULT_REFERENCE_BUDGET` seconds.
    passes : int
        Reference passes with ``spp``.
    progress : bool
        Progress bars (on stderr).
    stream : file, optional
        Where the summary lines go (default stdout).
    keep_precomputations : bool
        Keep every method's precomputation in the cache. Default: those up to
        :data:`REPORT_CACHE_ENTRY_LIMIT` bytes (the report keeps its own results; writing
        radiosity's dense operators, 1-3 GB a scene, cost more than recomputing them saves
        on a later run, docs/references.md). A method says what it did not keep.
    images : str or PathLike, optional
        A folder of another renderer's images, scored beside (or, without ``methods``,
        instead of) the fast methods: one subfolder per renderer, named as it is to be
        shown, holding ``<scene name>.exr`` for each scene it rendered
        (:func:`renderer_images`).

    Returns
    -------
    ReportResult

    Raises
    ------
    InputError
        Unknown scene or method, bad counts, an ``out`` that cannot hold a report, an
        unreadable baseline, a stale or unusable committed reference; raised before
        anything is written.
    """
    from tqdm.auto import tqdm

    from ..cache import Cache, content_hash, limited_entries
    from ..fast.base import applicability
    from ..fast.base import method as method_module
    from ..fast.registry import MethodContractError, method_fingerprint
    from ..scenes import Scene, load_scene
    from .distributed import run_tasks

    stream = sys.stdout if stream is None else stream
    started = time.perf_counter()
    spp = None if spp is None else check_count(spp, "--spp")
    passes = check_count(passes, "--passes")
    chosen = _methods(methods) if methods is not None or images is None else []
    renderers = renderers_in(images, chosen)
    out = _check_out(out)
    baseline_path = Path(baseline) if baseline is not None else DEFAULT_BASELINE
    stored_baseline = load_baseline(baseline_path,
                                    required=baseline is not None and not update_baseline)
    excluded: dict[str, str] = {}
    if scenes:
        names = list(scenes)
    else:
        names, excluded = default_scenes()
    loaded = [name if isinstance(name, Scene) else load_scene(name) for name in names]
    _check_distinct_names(loaded)
    versions = backend_versions()
    fingerprint = _source_fingerprint()
    reference_settings = ({"spp": spp, "passes": passes, "seed": 0} if spp is not None else
                          {"committed": True, "target_rse": DEFAULT_TARGET_RSE,
                           "budget_seconds": DEFAULT_REFERENCE_BUDGET,
                           "spp": PROGRESSIVE_SPP})

    taken: set[str] = set()
    reports = [SceneReport(scene.name, _slug(scene.name, taken), scene, content_hash(scene),
                           spp if spp is not None else PROGRESSIVE_SPP)
               for scene in loaded]
    if spp is None:
        # before any work: a stale committed reference stops the run, naming the fix
        for report in reports:
            report.reference = committed_reference_for(report.scene)
            if report.reference is not None:
                report.reference_source = "committed"
                report.reference_cached = True
    for report in reports:
        report.runs.update(renderer_images(images, renderers, report.scene))
    run_cache = Cache("report")
    method_sources: dict[str, str] = {}
    tasks: list[tuple] = []
    owners: list[tuple[SceneReport, str | None, str | None]] = []
    portables: dict[str, Any] = {}

    def portable(report: SceneReport):
        # worked out only for a scene with a task: it may load the scene file again
        if report.slug not in portables:
            portables[report.slug] = portable_scene(report.scene, report.scene_hash,
                                               scheduler is None)
        return portables[report.slug]

    for report in reports:
        if report.reference is None and spp is not None:
            report.reference_source = "fixed passes"
            report.reference = _cached_reference(report.scene, report.spp, passes)
            report.reference_cached = report.reference is not None
        if report.reference is None:
            report.reference_error = _unconvertible(report.scene)
        if report.reference is None and not report.reference_error:
            if spp is None:
                report.reference_source = "progressive"
                tasks.append(("reference", portable(report), PROGRESSIVE_SPP, None,
                              DEFAULT_TARGET_RSE, DEFAULT_REFERENCE_BUDGET))
            else:
                tasks.append(("reference", portable(report), report.spp, passes))
            owners.append((report, None, None))
        for name in chosen:
            if report.reference_error:
                report.runs[name] = MethodRun(name, report.name, "not run",
                                              "the scene has no reference to compare with")
                continue
            try:
                module = method_module(name)
            except MethodContractError as error:
                report.runs[name] = MethodRun(name, report.name, "failed", error.reason)
                continue
            except InputError as error:
                report.runs[name] = MethodRun(name, report.name, "not built", error.reason)
                continue
            try:
                reason = applicability(module.applies_to, report.scene)
            except Exception as error:  # the method's own check failed: show it
                report.runs[name] = MethodRun(name, report.name, "failed",
                                              f"applies_to: {type(error).__name__}: {error}")
                continue
            if reason is not None:
                report.runs[name] = MethodRun(name, report.name, "not applicable",
                                              reason.sentence, reason_code=reason.code)
                continue
            if name not in method_sources:  # its own files, read once a run
                method_sources[name] = fingerprint + method_fingerprint(name)
            # the method at its defaults, then the cheap end of its quality ladder
            for knobs in [{}] + ladder_knobs(module, name):
                key = _run_key(name, report.scene, knobs, method_sources[name], versions)
                owner = name if not knobs else (LADDER, name)
                stored = run_cache.load_object(key)
                if isinstance(stored, MethodRun) and stored.status == "ok":
                    stored.cached = True
                    _keep_run(report, owner, stored)
                    continue
                tasks.append(("method", portable(report), name, knobs, REPORT_RELIGHT_FRAMES))
                owners.append((report, owner, key))
        # the path-tracing ladder, for the speed-ups of the methods that will be scored
        if not report.reference_error and any(
                report.runs.get(n) is None or report.runs[n].status == "ok"
                for n in chosen + renderers):
            key = content_hash("path tracing", report.scene_hash, PATH_TRACING_SPP, versions,
                               fingerprint)
            report.path_tracing = run_cache.load_object(key)
            if report.path_tracing is None:
                tasks.append(("path tracing", portable(report), list(PATH_TRACING_SPP)))
                owners.append((report, PATH_TRACING, key))

    if tasks:
        print(f"running {len(tasks)} task(s): "
              f"{sum(1 for t in tasks if t[0] == 'reference')} reference render(s), "
              f"{sum(1 for t in tasks if t[0] == 'method')} method run(s), "
              f"{sum(1 for t in tasks if t[0] == 'path tracing')} path-tracing ladder(s)",
              file=stream,
              flush=True)
    timing: dict[str, Any] = {"planning": time.perf_counter() - started, "tasks": 0.0,
                              "scoring": 0.0, "scoring_during_tasks": 0.0}
    task_times: list[dict] = []
    chosen = chosen + renderers
    pending = {report.slug: 0 for report in reports}
    for report, _, _ in owners:
        pending[report.slug] += 1
    # a scene with no task is scored after the tasks; the others as their last task is in
    untasked = [report for report in reports if pending[report.slug] == 0]
    staging = None
    try:
        staging = _staging_folder(out)
        bar = None  # the scenes scored after the tasks (the tasks' own bar runs before)

        def score(report: SceneReport) -> None:
            for name in renderers:
                if report.reference_error and report.runs[name].status == "ok":
                    report.runs[name] = MethodRun(name, report.name, "not run",
                                                  "the scene has no reference to compare with")
            scoring_started = time.perf_counter()
            score_scene(report, staging)
            timing["scoring"] += time.perf_counter() - scoring_started
            if bar is not None:
                bar.update()

        def arrived(position: int, timed_result) -> None:
            # a scene is scored as soon as its last task is in, while the others run on
            report, name, key = owners[position]
            result = timed_result[0]
            if name == PATH_TRACING:
                report.path_tracing = result
                if isinstance(result, list) and not any("error" in p for p in result):
                    run_cache.store_object(key, result)
            elif name is None:
                if isinstance(result, Image):
                    report.reference = result
                else:
                    report.reference_error = str(result)
            else:
                _keep_run(report, name, result)
                if result.status == "ok":
                    run_cache.store_object(key, result)
            pending[report.slug] -= 1
            if pending[report.slug] == 0:
                score(report)

        if tasks:
            tasks_started = time.perf_counter()
            with limited_entries(None if keep_precomputations else REPORT_CACHE_ENTRY_LIMIT):
                # on local workers one method's runs wait for its first, which compiles its
                # kernels into numba's on-disk cache for the others
                groups = [task[2] if task[0] == "method" else None for task in tasks]
                timed = run_tasks(report_task, tasks, scheduler=scheduler, local=serial,
                                  progress=progress, timed=True,
                                  groups=groups if scheduler is None else None,
                                  on_result=arrived)
            timing["tasks"] = time.perf_counter() - tasks_started
            timing["scoring_during_tasks"] = timing["scoring"]
            task_times = [task_time(task, owner, seconds, worker)
                          for task, owner, (_, seconds, worker) in zip(tasks, owners, timed,
                                                                        strict=True)]
        bar = tqdm(total=len(untasked), desc="metrics and error maps", disable=not progress,
                   leave=False, file=sys.stderr)
        for report in untasked:
            score(report)
        bar.close()
        regressions = []
        for report in reports:
            reference = _made_with(report)
            for name in chosen:
                run = report.runs.get(name)
                metrics = report.metrics.get(name)
                failure = report.metric_errors.get(name) or (run.reason if run else "") \
                    or report.reference_error
                check = check_against_baseline(report.name, report.scene_hash, reference, name,
                                               metrics, stored_baseline, failure=failure)
                report.checks[name] = check
                if check.status == "regression":
                    regressions.append(f"{report.name}/{name}: {check.message}")
        exit_code = 1 if regressions and not update_baseline else 0
        context = {
            "generated": timestamp(), "versions": versions, "reference": reference_settings,
            "baseline": str(baseline_path), "baseline_updated": update_baseline,
            "baseline_versions": stored_baseline.get("versions", {}),
            "excluded": excluded, "methods": chosen, "regressions": regressions,
            "exit_code": exit_code, "fingerprint": fingerprint,
            "scheduler": "this process" if serial else (scheduler or "local processes"),
        }
        summary = summary_rows(reports, chosen)
        context["seconds"] = time.perf_counter() - started
        context["timing"] = {**{f"{phase}_seconds": value for phase, value in timing.items()},
                             "task_seconds": task_times}
        atomic_write_text(staging / "metrics.json",
                          json.dumps(_metrics_json(reports, chosen, context), indent=2,
                                     sort_keys=False, allow_nan=False))
        context["overview"] = _overview(reports, staging)
        atomic_write_text(staging / "index.html", html_page(reports, chosen, context))
        _replace_folder(staging, out)
        staging = None
    finally:
        if staging is not None:
            shutil.rmtree(staging, ignore_errors=True)

    if update_baseline:
        results_for_baseline = [
            {"name": r.name, "scene_hash": r.scene_hash, "reference": _made_with(r),
             "metrics": r.metrics, "methods_run": chosen}
            for r in reports if r.reference is not None]
        new = updated_baseline(stored_baseline, results_for_baseline, versions)
        atomic_write_text(baseline_path, json.dumps(new, indent=2, allow_nan=False) + "\n")
    seconds = time.perf_counter() - started
    print_summary(summary, regressions, out, seconds, update_baseline, baseline_path, stream,
                   timing, task_times)
    for report in reports:
        if report.noise_warning:
            print(f"warning: {report.name}: {report.noise_warning}", file=sys.stderr)
    return ReportResult(exit_code, out, regressions, seconds, summary)


#: The verdicts of one metric in ``metrics.json``.
METRIC_VERDICTS = ("ok", "regression", "within reference noise", "no baseline")


def metric_verdict(noise_verdict: str, check, key: str) -> str:
    """Return one metric's verdict: noise first, then the baseline (:data:`METRIC_VERDICTS`).

    A value that does not clear the reference's own noise is "within reference noise",
    whatever the baseline says (a difference the reference cannot resolve is not a
    result); otherwise "regression" where the baseline check found it worse, "no
    baseline" where there is no entry for it (or the metric is not gated), else "ok".

    Examples
    --------
    >>> from translucent.reports.regression import BaselineCheck
    >>> check = BaselineCheck("regression", "worse", {"hdr_flip": {"verdict": "worse"}})
    >>> metric_verdict("resolved", check, "hdr_flip"), metric_verdict("resolved", check, "ssim")
    ('regression', 'no baseline')
    >>> metric_verdict("within reference noise", check, "hdr_flip")
    'within reference noise'
    """
    from .metrics import WITHIN_NOISE

    if noise_verdict == WITHIN_NOISE:
        return WITHIN_NOISE
    gated = (check.metrics.get(key) if check is not None else None) or {}
    if not gated:
        return "no baseline"
    return "regression" if gated.get("verdict") == "worse" else "ok"


def _made_with(report: SceneReport) -> dict:
    """Return the reference's spp and passes (what a baseline entry records it was made with)."""
    meta = report.reference.metadata if report.reference is not None else {}
    return {"spp": meta.get("spp", report.spp), "passes": meta.get("passes")}


def _staging_folder(out: Path) -> Path:
    from ..atomic import sweep_orphans

    parent = out.absolute().parent
    parent.mkdir(parents=True, exist_ok=True)
    sweep_orphans(parent)  # staging folders of reports killed before they finished
    return Path(tempfile.mkdtemp(prefix=f".{out.name}.", suffix=".part", dir=parent))


def _replace_folder(staging: Path, out: Path) -> None:
    """Rename the finished ``staging`` onto ``out``; an old report there goes only then."""
    os.chmod(staging, 0o755)
    old = None
    if out.exists():
        old = Path(tempfile.mkdtemp(prefix=f".{out.name}.", suffix=".old",
                                    dir=out.absolute().parent))
        os.rmdir(old)
        os.rename(out, old)
    os.rename(staging, out)
    if old is not None:
        shutil.rmtree(old, ignore_errors=True)


def _overview(reports: list[SceneReport], folder: Path) -> str | None:
    """Draw every scored method on every scene in one plot; return its path in the report."""
    from .speedup import overview_plot

    points = [(report.name, name, report.runs[name].frame_seconds,
               metrics.get("relative_mse"),
               report.verdicts.get(name, {}).get("relative_mse") == "within reference noise")
              for report in reports for name, metrics in report.metrics.items()]
    return "overview.png" if overview_plot(folder / "overview.png", points) else None


def _metrics_json(reports: list[SceneReport], chosen: list[str], context: dict) -> dict:
    scenes = {}
    for report in reports:
        reference = None
        if report.reference is not None:
            meta = report.reference.metadata
            reference = {key: json_safe(meta.get(key)) for key in (
                "spp", "passes", "seconds", "integrator", "variant", "mitsuba",
                "substitutions", "scene_hash", "scene_content_hash", "stopped")}
            reference["cached"] = report.reference_cached
            reference["source"] = report.reference_source
            reference["noise"] = (report.reference_noise.as_dict()
                                  if report.reference_noise is not None else None)
            reference["noise_warning"] = report.noise_warning or None
            reference["noise_floor"] = json_safe(report.noise_floor)
            reference["files"] = report.files.get("reference", {})
        methods = {}
        for name in chosen:
            run = report.runs.get(name)
            entry = run.as_dict() if run else {"status": "not run"}
            entry["metrics"] = json_safe(report.metrics.get(name))
            entry["pixels_scored"] = ("object" if report.mask_of(name) is not None else "image")
            entry["objects_scored"] = report.scored_objects.get(name)
            entry["image_metrics"] = json_safe(report.image_metrics.get(name))
            metrics = report.metrics.get(name)
            check = report.checks.get(name)
            entry["noise"] = None if metrics is None else {
                key: {"value": json_safe(metrics[key]),
                      "noise_floor": json_safe((report.floor_of(name) or {}).get(key)),
                      "noise_verdict": report.verdicts[name][key],
                      "verdict": metric_verdict(report.verdicts[name][key], check, key)}
                for key in report.verdicts.get(name, {})}
            entry["metrics_error"] = report.metric_errors.get(name, "")
            entry["ladder"] = json_safe(report.ladder_points.get(name, []))
            entry["files"] = report.files.get(name, {})
            entry["baseline"] = check.as_dict() if check else None
            entry.update(speedup_fields(report, name))
            methods[name] = entry
        scenes[report.name] = {"source": str(report.scene.source or ""),
                               "description": report.scene.description,
                               "scene_hash": report.scene_hash, "folder": report.slug,
                               "reference": reference, "reference_error": report.reference_error,
                               "path_tracing": (json_safe(report.curve.as_dict())
                                                if report.curve is not None else None),
                               "path_tracing_on_objects": {
                                   ", ".join(key): json_safe(curve.as_dict())
                                   for key, curve in report.object_curves.items()},
                               "methods": methods}
    tolerances = {name: {"absolute": t.absolute, "relative": t.relative,
                         "lower_is_better": t.lower_is_better} for name, t in TOLERANCES.items()}
    return {"format": 1, **json_safe(context), "tolerances": tolerances, "scenes": scenes}


