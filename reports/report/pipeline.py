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
is replaced only then), and a disk that fills up ends it with nothing left behind. Every
report folder holds a marker, :data:`REPORT_MARKER`, that lists the files the report
wrote: only a folder whose every file is so listed is replaced; any other folder with
something in it is refused before any work.

Reference renders and method runs are independent tasks
(:func:`translucent.reports.report.distributed.run_tasks`): a local Dask process cluster by
default, a Dask scheduler with ``scheduler=``, or this process with ``serial=True``.
A method run is kept in the ``"report"`` cache, keyed by the scene, the method, its knobs,
the versions and a hash of the source of the packages it depends on; a second report with
nothing changed therefore renders nothing and shows the image and times measured when it
was first rendered (the page says so). A method that fails shows its error in the page and
the run goes on; one that is not installed or does not apply to a scene is listed with the
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
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ...atomic import atomic_write_text, check_output_folder, note_input
from ...errors import InputError, check_count
from ...image import Image
from ...progress import progress_bar
from ...reference.peers.registry import renderer_entries
from ...staging import replace_folder, staging_folder
from .baselines import (
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
from .metrics_json import made_with, metrics_json
from .model import LADDER, PATH_TRACING, PEER, ReportResult, SceneReport, keep_run
from .page import html_page
from .peer_runs import RENDERER_SPP, check_renderer_spp, plan_peer
from .renderer_images import renderer_images, renderers_in
from .runs import (
    REPORT_CACHE_ENTRY_LIMIT,
    MethodRun,
    backend_versions,
    committed_reference_for,
    json_safe,
    portable_scene,
    reference_path,
    render_reference,
    run_method,
    timestamp,
)
from .scoring import score_scene
from .speedup import PATH_TRACING_SPP
from .split import (
    MODEL,
    entry_name,
    entry_parts,
    model_reference_info,
    model_reference_refusal,
    model_steps,
    profile_knob_of,
    refused_profile,
    requested_profiles,
    split_profile,
    unrendered_profile,
)
from .summary import print_summary, summary_rows
from .tasks import (
    MethodTask,
    PathTracingTask,
    ReferenceTask,
    RendererTask,
    run_task,
    task_entry,
)

__all__ = [
    "METRIC_LABELS",
    "REPORTED_METRICS",
    "committed_reference_for",
    "json_safe",
    "render_reference",
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
#: One point, since each adds a method run per scene and method to a fresh report (what
#: it cost, measured: docs/report.md).
REPORT_LADDER_POINTS = 1

def ladder_knobs(module, name: str, points: int = REPORT_LADDER_POINTS) -> list[dict]:
    """Return the knob settings of the report's ladder for a method (cheap first).

    The first ``points`` settings of the method's first quality ladder that differ from its
    defaults; [] for a method with none.
    """
    from ..bench.tradeoff import declared_ladders

    ladders = declared_ladders(module, name) or {}
    defaults = getattr(module, "DEFAULT_KNOBS", {}) or {}
    for settings in ladders.values():
        chosen = [knobs for knobs in settings if knobs and set(knobs) <= set(defaults)
                  and any(defaults[k] != v for k, v in knobs.items())]
        return chosen[:points]
    return []


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
    from ...scenes import builtin_scene_names

    names = builtin_scene_names()
    excluded = {name: reason for name, reason in EXCLUDED_SCENES.items() if name in names}
    return [name for name in names if name not in excluded], excluded


def _source_fingerprint() -> str:
    """SHA-256 of the source files a method's image depends on."""
    root = Path(__file__).resolve().parents[2]
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
    from ...cache import content_hash

    return content_hash("report-run", RUN_FORMAT, method_name, scene, knobs, fingerprint,
                        versions)


def _unconvertible(scene) -> str:
    """Return why Mitsuba cannot take ``scene`` (no render needed to know), or ""."""
    from ...reference import convert_scene

    try:
        convert_scene(scene)
    except InputError as error:
        return f"InputError: {error}"
    return ""


def _cached_reference(scene, spp: int, passes: int) -> Image | None:
    from ...reference.render import read_cached_reference

    path = reference_path(scene, spp, passes)
    # served only if made for this key (the file's name); else rendered again
    return read_cached_reference(path, path.name.removesuffix(".exr"))


def _check_out(out) -> Path:
    """Check ``out`` can take a report before anything is computed."""
    try:
        out = Path(out).expanduser()
    except RuntimeError as error:  # "~someone" of no such user
        raise InputError(f"cannot be resolved ({error})", field="--out", value=str(out)) \
            from None
    # the folder's content is replaced: no input (the --images folder) may lie inside it
    out = check_output_folder(out, "--out", replaces=True)
    problem = _not_replaceable(out) if out.is_dir() else None
    if problem:
        raise InputError(problem, field="--out", value=str(out))
    ancestor = out.absolute().parent
    while not ancestor.exists():
        ancestor = ancestor.parent
    if not os.access(ancestor, os.W_OK | os.X_OK):
        raise InputError(f"cannot be created: {ancestor} is not writable", field="--out",
                         value=str(out))
    return out


def _methods(methods) -> list[str]:
    from ...fast.base import METHODS
    from ...fast.registry import check_known

    if methods is None:
        return list(METHODS)
    chosen = []
    for name in methods:
        name = str(name).strip()
        check_known(name, field="--methods")
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
                keep_precomputations: bool = False, images=None,
                profiles=None, renderers=None, renderer_spp=None) -> ReportResult:
    """Run the report: references, fast methods, metrics, error maps, baseline, HTML.

    Parameters
    ----------
    scenes : list of str or Scene, optional
        Built-in scene names, scene files or scenes; default :func:`default_scenes`.
    out : str or PathLike
        The report folder (created; a previous report there is replaced).
    methods : list of str, optional
        Fast methods to run; default all of :data:`translucent.fast.base.METHODS` (those
        not installed are listed as such).
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
        radiosity's dense operators costs more than recomputing them saves on a later
        run, docs/report.md). A method says what it did not keep.
    images : str or PathLike, optional
        A folder of another renderer's images, scored beside (or, without ``methods``,
        instead of) the fast methods: one subfolder per renderer, named as it is to be
        shown, holding ``<scene name>.exr`` for each scene it rendered
        (:func:`renderer_images`).
    renderers : str, optional
        Other renderers to score like methods: ``NAME`` (every mode) or ``NAME.MODE``,
        comma-separated (:mod:`translucent.reference.peers.registry`; Cycles: ``cycles``),
        each mode the entry ``NAME.MODE`` (:mod:`.peer_runs`).
    renderer_spp : list of int, optional
        The samples per pixel the renderers render at (default
        :data:`~.peer_runs.RENDERER_SPP`); the largest is the scored run.
    profiles : "all" or list of str, optional
        Besides its default profile, run every method that has a ``profile`` knob with
        each of these radial profiles (``"all"``: every one), as the entries
        ``METHOD@PROFILE``. Every entry's error is split into its profile's and its own
        against the scene's model reference of that profile (:mod:`.split`): committed
        for the default profile of a built-in scene, rendered otherwise.

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
    stream = sys.stdout if stream is None else stream
    started = time.perf_counter()
    spp = None if spp is None else check_count(spp, "--spp")
    passes = check_count(passes, "--passes")
    peers = [] if renderers is None else renderer_entries(renderers)
    peer_spp = check_renderer_spp(RENDERER_SPP if renderer_spp is None else renderer_spp)
    chosen = (_methods(methods) if methods is not None or (images is None and not peers)
              else [])
    renderers = renderers_in(images, chosen)
    clash = sorted(set(peers) & set(renderers))
    if clash:
        raise InputError("an --images folder has the name of a renderer's mode being run: "
                         "rename the folder", field="--images", value=clash[0])
    asked_profiles = requested_profiles(profiles)
    note_input(images, "--images")
    out = _check_out(out)
    baseline_path = Path(baseline) if baseline is not None else DEFAULT_BASELINE
    stored_baseline = load_baseline(baseline_path,
                                    required=baseline is not None and not update_baseline)
    plan = _plan(scenes, chosen, renderers, images, spp, passes, asked_profiles,
                 local_workers=scheduler is None, peers=(peers, peer_spp))
    _announce(plan.tasks, stream)
    timing: dict[str, Any] = {"planning": time.perf_counter() - started, "tasks": 0.0,
                              "scoring": 0.0, "scoring_during_tasks": 0.0}
    # built beside --out and renamed onto it when complete; a killed run's is swept
    with staging_folder(out, field="--out") as staging:
        task_times = _run(plan, staging, timing, scheduler=scheduler, serial=serial,
                          progress=progress, keep_precomputations=keep_precomputations)
        regressions = _judge(plan, stored_baseline)
        exit_code = 1 if regressions and not update_baseline else 0
        context = {
            "generated": timestamp(), "versions": plan.versions,
            "reference": plan.reference_settings, "baseline": str(baseline_path),
            "baseline_updated": update_baseline,
            "baseline_versions": stored_baseline.get("versions", {}),
            "excluded": plan.excluded, "methods": plan.scored, "regressions": regressions,
            "exit_code": exit_code, "fingerprint": plan.fingerprint,
            "scheduler": "this process" if serial else (scheduler or "local processes"),
            "seconds": time.perf_counter() - started,
            "timing": {**{f"{phase}_seconds": value for phase, value in timing.items()},
                       "task_seconds": task_times},
        }
        summary = summary_rows(plan.reports, plan.scored)
        _write(plan, staging, context)
        replace_folder(staging, out, field="--out")
    if update_baseline:
        _update_baseline(plan, stored_baseline, baseline_path)
    seconds = time.perf_counter() - started
    print_summary(summary, regressions, out, seconds, update_baseline, baseline_path, stream,
                  timing, task_times)
    for report in plan.reports:
        if report.noise_warning:
            print(f"warning: {report.name}: {report.noise_warning}", file=sys.stderr)
    return ReportResult(exit_code, out, regressions, seconds, summary)


# ====================================================================== plan


@dataclass
class _Planned:
    """A task and whose result it is: a scene's reference, method run or ladder."""

    task: Any
    report: SceneReport
    #: None: the reference; a method's name; ``(LADDER, name)``; :data:`PATH_TRACING`
    owner: Any
    #: where a finished method run or ladder is kept in the report's cache (None: nowhere)
    key: str | None


@dataclass
class _Plan:
    """What a report will do: its scenes, the tasks still to run, how references are made."""

    reports: list[SceneReport]
    tasks: list[_Planned]
    #: the methods and other renderers scored
    scored: list[str]
    renderers: list[str]
    excluded: dict[str, str]
    reference_settings: dict
    versions: dict
    fingerprint: str
    run_cache: Any


def _plan(scenes, chosen, renderers, images, spp, passes, profiles, *,
          local_workers: bool, peers=((), ())) -> _Plan:
    """Load the scenes, find what is cached (references, runs, ladders), list the rest."""
    from ...cache import Cache, content_hash
    from ...scenes import Scene, load_scene

    excluded: dict[str, str] = {}
    names = list(scenes) if scenes else None
    if names is None:
        names, excluded = default_scenes()
    loaded = [name if isinstance(name, Scene) else load_scene(name) for name in names]
    _check_distinct_names(loaded)
    taken: set[str] = set()
    reports = [SceneReport(scene.name, _slug(scene.name, taken), scene, content_hash(scene),
                           spp if spp is not None else PROGRESSIVE_SPP) for scene in loaded]
    if spp is None:
        # before any work: a stale committed reference stops the run, naming the fix
        for report in reports:
            report.reference = committed_reference_for(report.scene)
            if report.reference is not None:
                report.reference_source, report.reference_cached = "committed", True
    for report in reports:
        report.runs.update(renderer_images(images, renderers, report.scene))
    plan = _Plan(reports, [], chosen + renderers, renderers, excluded,
                 ({"spp": spp, "passes": passes, "seed": 0} if spp is not None else
                  {"committed": True, "target_rse": DEFAULT_TARGET_RSE,
                   "budget_seconds": DEFAULT_REFERENCE_BUDGET, "spp": PROGRESSIVE_SPP}),
                 backend_versions(), _source_fingerprint(), Cache("report"))
    portables: dict[str, Any] = {}

    def portable(report: SceneReport):
        # worked out only for a scene with a task: it may load the scene file again
        if report.slug not in portables:
            portables[report.slug] = portable_scene(report.scene, report.scene_hash,
                                                    local_workers)
        return portables[report.slug]

    method_sources: dict[str, str] = {}
    variants = [entry_name(name, profile) for name in chosen for profile in profiles
                if profile_knob_of(name) is not None]
    peer_entries, peer_spp = peers
    plan.scored = chosen + variants + list(peer_entries) + renderers
    for report in reports:
        _plan_reference(plan, report, portable, spp, passes)
        for name in chosen + variants:
            _plan_method(plan, report, name, portable, method_sources)
        for entry in peer_entries:
            if plan_peer(report, entry):
                plan.tasks.append(_Planned(RendererTask(portable(report), entry,
                                                        tuple(peer_spp)),
                                           report, (PEER, entry), None))
        _plan_model_references(plan, report, portable, spp, passes)
        _plan_path_tracing(plan, report, portable, chosen + variants + list(peer_entries))
    return plan


def _plan_reference(plan: _Plan, report: SceneReport, portable, spp, passes) -> None:
    """Find the scene's reference in the cache, or plan its render."""
    if report.reference is None and spp is not None:
        report.reference_source = "fixed passes"
        report.reference = _cached_reference(report.scene, report.spp, passes)
        report.reference_cached = report.reference is not None
    if report.reference is None:
        report.reference_error = _unconvertible(report.scene)
    if report.reference is not None or report.reference_error:
        return
    if spp is None:
        report.reference_source = "progressive"
        task = ReferenceTask(portable(report), PROGRESSIVE_SPP, None, DEFAULT_TARGET_RSE,
                             DEFAULT_REFERENCE_BUDGET)
    else:
        task = ReferenceTask(portable(report), report.spp, passes)
    plan.tasks.append(_Planned(task, report, None, None))


def _plan_method(plan: _Plan, report: SceneReport, name: str, portable,
                 method_sources: dict) -> None:
    """Plan a method on a scene at its defaults and the cheap end of its ladder.

    Or say why not: no reference, not installed, not applicable, a broken contract.
    """
    from ...fast.base import applicability
    from ...fast.base import method as method_module
    from ...fast.registry import MethodContractError, method_fingerprint

    def refused(status: str, reason: str, **extra) -> None:
        report.runs[name] = MethodRun(name, report.name, status, reason, **extra)

    if report.reference_error:
        return refused("not run", "the scene has no reference to compare with")
    name_of_method, profile = entry_parts(name)
    try:
        module = method_module(name_of_method)
    except MethodContractError as error:
        return refused("failed", error.reason)
    except InputError as error:
        return refused("not installed", error.reason)
    try:
        reason = applicability(module.applies_to, report.scene)
    except Exception as error:  # the method's own check failed: show it
        return refused("failed", f"applies_to: {type(error).__name__}: {error}")
    if reason is None and profile is not None:
        reason = refused_profile(module, profile)
    if reason is not None:
        return refused("not applicable", reason.sentence, reason_code=reason.code)
    if name_of_method not in method_sources:  # its own files, read once a run
        method_sources[name_of_method] = plan.fingerprint + method_fingerprint(name_of_method)
    runs = ([{}] + ladder_knobs(module, name) if profile is None
            else [{"profile": profile}])  # a profile's run: its defaults, no ladder
    for knobs in runs:
        key = _run_key(name_of_method, report.scene, knobs, method_sources[name_of_method],
                       plan.versions)
        owner = name if not knobs or profile is not None else (LADDER, name)
        stored = plan.run_cache.load_object(key)
        if isinstance(stored, MethodRun) and stored.status == "ok":
            stored.cached = True
            keep_run(report, owner, stored)
            continue
        task = MethodTask(portable(report), name_of_method, knobs, REPORT_RELIGHT_FRAMES)
        plan.tasks.append(_Planned(task, report, owner, key))


def _plan_model_references(plan: _Plan, report: SceneReport, portable, spp, passes) -> None:
    """Find or plan the scene's model reference of each profile its entries render.

    A built-in scene's committed one (the default profile), the cache's, or a render as
    the volumetric reference's (fixed passes with ``spp``, else progressive); or why none
    can be made (a heterogeneous medium).
    """
    if report.reference_error:
        return
    wanted = {split_profile(name, run.knobs, report.scene)[0]
              for name, run in report.runs.items() if run.status == "ok"}
    wanted |= {split_profile(p.owner, p.task.knobs, report.scene)[0] for p in plan.tasks
               if p.report is report and isinstance(p.owner, str) and p.owner != PATH_TRACING}
    wanted |= {split_profile(p.owner[1], None, report.scene)[0] for p in plan.tasks
               if p.report is report and isinstance(p.owner, tuple) and p.owner[0] == PEER}
    for profile in sorted(wanted - {None}):
        refusal = unrendered_profile(profile) or model_reference_refusal(report.scene, profile)
        if refusal:
            report.model_reference_errors[profile] = refusal
            continue
        committed = committed_reference_for(report.scene, profile) if spp is None else None
        # the simpler models a key builds on split the model's error where committed
        for simpler in model_steps(profile)[:-1] if spp is None else ():
            try:
                found = committed_reference_for(report.scene, simpler)
            except InputError as error:  # a stale step loses the steps, not the report
                report.model_reference_errors[simpler] = error.reason
                continue
            if found is not None and simpler not in wanted:
                report.model_references[simpler] = found
                report.model_reference_info[simpler] = model_reference_info(found, "committed")
        if committed is not None:
            report.model_references[profile] = committed
            report.model_reference_info[profile] = model_reference_info(committed, "committed")
            continue
        task = (ReferenceTask(portable(report), spp, passes, profile=profile)
                if spp is not None else
                ReferenceTask(portable(report), PROGRESSIVE_SPP, None, DEFAULT_TARGET_RSE,
                              DEFAULT_REFERENCE_BUDGET, profile=profile))
        plan.tasks.append(_Planned(task, report, (MODEL, profile), None))


def _plan_path_tracing(plan: _Plan, report: SceneReport, portable, chosen) -> None:
    """Find or plan the path-tracing ladder, for the speed-ups of the methods to be scored."""
    from ...cache import content_hash

    if report.reference_error or not any(
            report.runs.get(n) is None or report.runs[n].status == "ok"
            for n in chosen + plan.renderers):
        return
    key = content_hash("path tracing", report.scene_hash, PATH_TRACING_SPP, plan.versions,
                       plan.fingerprint)
    report.path_tracing = plan.run_cache.load_object(key)
    if report.path_tracing is None:
        plan.tasks.append(_Planned(PathTracingTask(portable(report), tuple(PATH_TRACING_SPP)),
                                   report, PATH_TRACING, key))


def _announce(tasks: list[_Planned], stream) -> None:
    if not tasks:
        return
    count = {kind: sum(1 for p in tasks if p.task.kind == kind)
             for kind in ("reference", "method", "path tracing", "renderer")}
    models = sum(1 for p in tasks if p.task.kind == "reference" and p.task.profile)
    count["reference"] -= models
    model_text = f"{models} model reference render(s), " if models else ""
    print(f"running {len(tasks)} task(s): {count['reference']} reference render(s), "
          f"{model_text}"
          f"{count['method']} method run(s), "
          + (f"{count['renderer']} other renderer's ladder(s), " if count["renderer"] else "")
          + f"{count['path tracing']} path-tracing ladder(s)",
          file=stream, flush=True)


# ====================================================================== run


def _run(plan: _Plan, staging: Path, timing: dict, *, scheduler, serial: bool,
         progress: bool, keep_precomputations: bool) -> list[dict]:
    """Run the tasks; score each scene as soon as its last task is in, the rest after.

    Returns the tasks' timing entries (:func:`~.report_tasks.task_entry`).
    """
    from ...cache import limited_entries
    from .distributed import run_tasks

    pending = {report.slug: 0 for report in plan.reports}
    for planned in plan.tasks:
        pending[planned.report.slug] += 1

    def score(report: SceneReport) -> None:
        for name in plan.renderers:
            if report.reference_error and report.runs[name].status == "ok":
                report.runs[name] = MethodRun(name, report.name, "not run",
                                              "the scene has no reference to compare with")
        scoring_started = time.perf_counter()
        score_scene(report, staging)
        timing["scoring"] += time.perf_counter() - scoring_started

    def arrived(position: int, timed_result) -> None:
        planned = plan.tasks[position]
        _keep_result(plan, planned, timed_result[0])
        pending[planned.report.slug] -= 1
        if pending[planned.report.slug] == 0:
            score(planned.report)

    task_times: list[dict] = []
    if plan.tasks:
        tasks_started = time.perf_counter()
        with limited_entries(None if keep_precomputations else REPORT_CACHE_ENTRY_LIMIT):
            groups = [planned.task.group for planned in plan.tasks]
            timed = run_tasks(run_task, [(planned.task,) for planned in plan.tasks],
                              scheduler=scheduler, local=serial, progress=progress,
                              timed=True, groups=groups if scheduler is None else None,
                              on_result=arrived)
        timing["tasks"] = time.perf_counter() - tasks_started
        timing["scoring_during_tasks"] = timing["scoring"]
        task_times = [task_entry(planned.task, planned.report.name, seconds, worker)
                      for planned, (_, seconds, worker) in zip(plan.tasks, timed, strict=True)]
    # a scene with no task is scored after the tasks (the tasks' own bar runs before)
    untasked = [report for report in plan.reports if pending[report.slug] == 0
                and not any(p.report is report for p in plan.tasks)]
    with progress_bar(total=len(untasked), description="metrics and error maps",
                      enabled=progress, terminal_only=False) as bar:
        for report in untasked:
            score(report)
            bar.update()
    return task_times


def _keep_result(plan: _Plan, planned: _Planned, result) -> None:
    """File a finished task's result in its scene's report (and the report's cache)."""
    report = planned.report
    if planned.owner == PATH_TRACING:
        report.path_tracing = result
        if isinstance(result, list) and not any("error" in p for p in result):
            plan.run_cache.store_object(planned.key, result)
    elif planned.owner is None:
        if isinstance(result, Image):
            report.reference = result
        else:
            report.reference_error = str(result)
    elif isinstance(planned.owner, tuple) and planned.owner[0] == PEER:
        main, ladder = result
        report.runs[planned.owner[1]] = main
        report.ladders[planned.owner[1]] = list(ladder)
    elif isinstance(planned.owner, tuple) and planned.owner[0] == MODEL:
        profile = planned.owner[1]
        if isinstance(result, Image):
            report.model_references[profile] = result
            report.model_reference_info[profile] = model_reference_info(
                result, "fixed passes" if planned.task.passes else "progressive")
        else:
            report.model_reference_errors[profile] = str(result)
    else:
        keep_run(report, planned.owner, result)
        if result.status == "ok":
            plan.run_cache.store_object(planned.key, result)


# ====================================================================== judge and write


def _judge(plan: _Plan, stored_baseline: dict) -> list[str]:
    """Check every scored result against the baseline; return the regressions."""
    regressions = []
    for report in plan.reports:
        reference = made_with(report)
        for name in plan.scored:
            run = report.runs.get(name)
            metrics = report.metrics.get(name)
            failure = report.metric_errors.get(name) or (run.reason if run else "") \
                or report.reference_error
            check = check_against_baseline(report.name, report.scene_hash, reference, name,
                                           metrics, stored_baseline, failure=failure)
            report.checks[name] = check
            if check.status == "regression":
                regressions.append(f"{report.name}/{name}: {check.message}")
    return regressions


def _write(plan: _Plan, staging: Path, context: dict) -> None:
    """Write ``metrics.json`` and the page into the staging folder."""
    atomic_write_text(staging / "metrics.json",
                      json.dumps(metrics_json(plan.reports, plan.scored, context), indent=2,
                                 sort_keys=False, allow_nan=False))
    context["overview"] = _overview(plan.reports, staging)
    atomic_write_text(staging / "index.html", html_page(plan.reports, plan.scored, context))
    _write_marker(staging)  # last: it lists every file the report wrote


def _update_baseline(plan: _Plan, stored_baseline: dict, baseline_path: Path) -> None:
    results = [{"name": r.name, "scene_hash": r.scene_hash, "reference": made_with(r),
                "metrics": r.metrics, "methods_run": plan.scored,
                "failures": {name: run.reason for name, run in r.runs.items()
                             if run.status == "failed"}}
               for r in plan.reports if r.reference is not None]
    new = updated_baseline(stored_baseline, results, plan.versions)
    atomic_write_text(baseline_path, json.dumps(new, indent=2, allow_nan=False) + "\n")


#: The file every report folder holds: what wrote it and the files it wrote. A folder is
#: replaced by a new report only where it holds this and nothing it does not list.
REPORT_MARKER = ".translucent-report.json"

#: The largest marker read (a report's lists a few hundred names).
_MARKER_LIMIT = 1 << 22


def _report_files(folder: Path) -> list[str]:
    """Return every entry of ``folder`` below it that is not a folder, as relative names.

    Symbolic links are listed, not followed; the marker itself is left out.
    """
    found = []
    for root, folders, files in os.walk(folder):
        links = [name for name in folders if os.path.islink(os.path.join(root, name))]
        for name in files + links:
            relative = Path(root, name).relative_to(folder).as_posix()
            if relative != REPORT_MARKER:
                found.append(relative)
    return sorted(found)


def _write_marker(folder: Path) -> None:
    atomic_write_text(folder / REPORT_MARKER, json.dumps(
        {"written_by": "translucent report", "files": _report_files(folder)}, indent=1) + "\n")


def _marked_files(folder: Path) -> set[str] | None:
    """Return the files the marker in ``folder`` lists; None where there is no such marker."""
    marker = folder / REPORT_MARKER
    try:
        if not marker.is_file() or marker.is_symlink() or \
                marker.stat().st_size > _MARKER_LIMIT:
            return None
        found = json.loads(marker.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    if not isinstance(found, dict) or found.get("written_by") != "translucent report":
        return None
    files = found.get("files")
    if not isinstance(files, list) or not all(isinstance(name, str) for name in files):
        return None
    return set(files)


def _not_replaceable(out: Path) -> str | None:
    """Return why the folder ``out`` may not be replaced by a report; None where it may.

    It may where it is empty, or a report this suite wrote (its :data:`REPORT_MARKER`)
    holding no file the report did not write.
    """
    try:
        if not any(os.scandir(out)):
            return None
    except OSError as error:
        return f"cannot be read ({error.strerror or error})"
    listed = _marked_files(out)
    if listed is None:
        return (f"is a folder with other files in it, not a report folder (it has no "
                f"{REPORT_MARKER}); give a new or empty folder (a previous report there is "
                "replaced; one written before reports were marked is not: remove it first)")
    others = [name for name in _report_files(out) if name not in listed]
    if others:
        more = f" and {len(others) - 1} other file(s)" if len(others) > 1 else ""
        return (f"holds {others[0]}{more} that the report there did not write, which "
                "replacing it would destroy; move them out or give another folder")
    return None


def _overview(reports: list[SceneReport], folder: Path) -> str | None:
    """Draw every scored method on every scene in one plot; return its path in the report."""
    from .speedup import overview_plot

    points = [(report.name, name, report.runs[name].frame_seconds,
               metrics.get("relative_mse"),
               report.verdicts.get(name, {}).get("relative_mse") == "within reference noise")
              for report in reports for name, metrics in report.metrics.items()]
    return "overview.png" if overview_plot(folder / "overview.png", points) else None
