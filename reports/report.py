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

import contextlib
import datetime
import hashlib
import html
import json
import math
import os
import re
import shutil
import sys
import tempfile
import time
import traceback
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ..atomic import atomic_write_text, check_output_folder
from ..cache import private_cache
from ..errors import InputError, check_count
from ..image import Image

__all__ = [
    "json_safe",
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

#: A reference whose median relative standard error is above this is warned about.
NOISE_WARNING_RSE = 0.05

#: The committed baseline of the default scenes.
DEFAULT_BASELINE = Path(__file__).resolve().parent / "baseline" / "default.json"

#: Bumped when the baseline layout changes.
BASELINE_FORMAT = 1

#: Bumped when what a cached method run holds changes, so older entries miss.
RUN_FORMAT = 1

#: Built-in scenes the default run leaves out, and why (shown in the page).
EXCLUDED_SCENES: dict[str, str] = {
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


# ====================================================================== tolerances


@dataclass(frozen=True)
class Tolerance:
    """How much worse than its baseline a metric may get before it is a regression.

    A value is a regression when it is worse than the baseline by more than
    ``absolute + relative * |baseline|`` (worse: higher for errors, lower for SSIM).

    Parameters
    ----------
    field : str
        The :class:`~translucent.reports.metrics.Metrics` attribute.
    absolute : float
        Allowed worsening in the metric's units.
    relative : float
        Allowed worsening as a fraction of the baseline value.
    lower_is_better : bool
        True for errors, False for similarities.
    """

    field: str
    absolute: float
    relative: float
    lower_is_better: bool = True

    def limit(self, baseline: float) -> float:
        """Return the worst value still accepted for ``baseline``."""
        allowed = self.absolute + self.relative * abs(baseline)
        return baseline + allowed if self.lower_is_better else baseline - allowed

    def is_worse(self, value: float, baseline: float) -> bool:
        """Return True when ``value`` is worse than ``baseline`` beyond the tolerance (NaN is)."""
        if not math.isfinite(value):
            return True
        limit = self.limit(baseline)
        return value > limit if self.lower_is_better else value < limit

    def is_better(self, value: float, baseline: float) -> bool:
        """Return True when ``value`` improved on ``baseline`` by more than the tolerance."""
        allowed = self.absolute + self.relative * abs(baseline)
        if not math.isfinite(value):
            return False
        return value < baseline - allowed if self.lower_is_better else value > baseline + allowed


# The tolerances are about twice the largest change that re-rendering the references alone
# caused: the default scenes' references were rendered again with another seed (same spp
# and passes) and every method's image compared with both (measured here, Mitsuba 3.9.1).
# A regression must exceed what a new reference (another Mitsuba version, another seed)
# could cause; the noisy references of the bowl and the Cornell box set the scale.

#: HDR-FLIP (0 to 1): 0.005 absolute plus 3 % of the baseline. The largest change measured
#: was 0.0046 (bowl, radiosity: 1.6 %); the largest relative one 2.5 % (sphere, PRT).
HDR_FLIP_TOLERANCE = Tolerance("hdr_flip", absolute=0.005, relative=0.03)

#: Relative MSE (dimensionless): 0.001 absolute plus 30 %. The reference's noise is
#: discounted from it, yet the largest change measured was 0.0033 (bowl, radiosity: 15 %);
#: on the sphere 0.0004 (6 %).
RELATIVE_MSE_TOLERANCE = Tolerance("relative_mse", absolute=0.001, relative=0.30)

#: Mean CIEDE2000 (delta E; about 1 is just noticeable): 0.1 absolute plus 15 %. The largest
#: change measured was 2.0 (Cornell box, PRT, whose walls are black: 7 %); radiosity on the
#: Cornell box moved 0.28 (7 %).
CIEDE2000_TOLERANCE = Tolerance("ciede2000", absolute=0.1, relative=0.15)

#: Mean SSIM (1 is identical): 0.03 absolute, no relative part (it is bounded by 1). The
#: largest change measured was 0.015 (Cornell box, radiosity): reference noise lowers SSIM.
SSIM_TOLERANCE = Tolerance("ssim", absolute=0.03, relative=0.0, lower_is_better=False)

#: The gated metrics, by :class:`Metrics` field.
TOLERANCES: dict[str, Tolerance] = {t.field: t for t in (
    HDR_FLIP_TOLERANCE, RELATIVE_MSE_TOLERANCE, CIEDE2000_TOLERANCE, SSIM_TOLERANCE)}

#: Metrics stored and shown besides the gated ones.
REPORTED_METRICS = ("hdr_flip", "ldr_flip", "relative_mse", "relative_mse_raw", "rmse",
                    "psnr", "ssim", "ciede2000")

#: Names shown in the page for each metric field.
METRIC_LABELS = {"hdr_flip": "HDR-FLIP", "ldr_flip": "LDR-FLIP", "relative_mse": "relMSE",
                 "relative_mse_raw": "relMSE (raw)", "rmse": "RMSE", "psnr": "PSNR (dB)",
                 "ssim": "SSIM", "ciede2000": "CIEDE2000"}


# ====================================================================== method runs


@dataclass
class MethodRun:
    """One fast method on one scene: its image, times and what it skipped, or why not.

    Parameters
    ----------
    method, scene : str
        Names.
    status : {"ok", "failed", "not applicable", "not built", "not run"}
        What happened ("not run": the scene has no reference to compare with).
    reason : str
        Why a method did not run, or the error it raised.
    image : Image, optional
        The rendered image (status "ok").
    precompute_seconds, frame_seconds : float, optional
        Wall-clock seconds of ``precompute`` and of a frame (``state.render()``; see
        :func:`run_method` for relit frames).
    first_frame_seconds : float, optional
        Seconds of the first frame after ``precompute``.
    skipped : list of str
        The method's own sentences on what it skipped for the scene and why.
    stage_seconds : dict
        Seconds per stage from the method's :class:`~translucent.fast.base.StageLog`.
    notes : dict
        The log's notes (JSON-safe).
    knobs : dict
        The knobs given to ``precompute`` (besides the defaults).
    measured_at : str
        ISO time of the run that measured the times.
    cached : bool
        True when this run came from the report cache (times are from ``measured_at``).
    details : str
        The traceback of a failure.
    """

    method: str
    scene: str
    status: str
    reason: str = ""
    image: Image | None = None
    precompute_seconds: float | None = None
    frame_seconds: float | None = None
    first_frame_seconds: float | None = None
    skipped: list[str] = field(default_factory=list)
    stage_seconds: dict[str, float] = field(default_factory=dict)
    notes: dict[str, Any] = field(default_factory=dict)
    knobs: dict[str, Any] = field(default_factory=dict)
    measured_at: str = ""
    cached: bool = False
    details: str = ""

    def as_dict(self) -> dict:
        """Return everything but the image, JSON-safe."""
        return {"method": self.method, "status": self.status, "reason": self.reason,
                "precompute_seconds": self.precompute_seconds,
                "frame_seconds": self.frame_seconds,
                "first_frame_seconds": self.first_frame_seconds, "skipped": list(self.skipped),
                "stage_seconds": json_safe(self.stage_seconds), "notes": json_safe(self.notes),
                "knobs": json_safe(self.knobs), "measured_at": self.measured_at,
                "cached": self.cached}


def _now() -> str:
    return datetime.datetime.now(datetime.timezone.utc).astimezone().isoformat(
        timespec="seconds")


def json_safe(value: Any, depth: int = 0) -> Any:
    """Return a JSON-safe copy: numpy scalars to numbers, small arrays to lists, else str."""
    if depth > 8:
        return str(value)
    if isinstance(value, dict):
        return {str(k): json_safe(v, depth + 1) for k, v in value.items()}
    if isinstance(value, (list, tuple, set)):
        return [json_safe(v, depth + 1) for v in value]
    if isinstance(value, np.ndarray):
        return json_safe(value.tolist(), depth + 1) if value.size <= 16 else \
            f"array{tuple(value.shape)} {value.dtype}"
    if isinstance(value, (np.bool_, bool)):
        return bool(value)
    if isinstance(value, (np.integer, int)):
        return int(value)
    if isinstance(value, (np.floating, float)):
        number = float(value)
        return number if math.isfinite(number) else str(number)
    if value is None or isinstance(value, str):
        return value
    return str(value)


def _quiet_knobs(module, knobs: dict) -> dict:
    """Turn off a method's own progress bars (they would garble the run's bar)."""
    defaults = getattr(module, "DEFAULT_KNOBS", {}) or {}
    if "progress" in defaults and "progress" not in knobs:
        return {**knobs, "progress": False}
    return dict(knobs)


def run_method(method_name: str, scene, knobs: dict | None = None, *,
               cold: bool = False, relight_frames: int = 0) -> MethodRun:
    """Precompute and render ``scene`` with a fast method, timing both; never raises.

    Parameters
    ----------
    method_name : str
        A key of :data:`translucent.fast.base.METHODS`.
    scene : Scene
        The scene.
    knobs : dict, optional
        Knobs for ``precompute`` besides the method's ``DEFAULT_KNOBS``.
    cold : bool
        Run against an empty temporary cache, so that the method's own precomputation
        cache cannot make it look fast (the benchmarks use this).
    relight_frames : int
        After the first frame, render this many more with the scene's lights given again
        (``state.render(lights=scene.lights)``: the relighting path, nothing reused from the
        first frame's lighting); ``frame_seconds`` is then their median and
        ``first_frame_seconds`` the first frame's, which can include first-call costs
        (compiled kernels loading). 0: ``frame_seconds`` is the first frame.

    Returns
    -------
    MethodRun
        Status "ok" with the image, "not built", "not applicable" (with the method's
        reason) or "failed" (with the error and its traceback).
    """
    from ..fast.base import method

    knobs = dict(knobs or {})
    base = {"method": method_name, "scene": scene.name, "knobs": knobs,
            "measured_at": _now()}
    try:
        module = method(method_name)
    except InputError as error:
        return MethodRun(status="not built", reason=error.reason, **base)
    try:
        reason = module.applies_to(scene)
        if reason is not None:
            return MethodRun(status="not applicable", reason=str(reason), **base)
        with private_cache() if cold else contextlib.nullcontext():
            started = time.perf_counter()
            state = module.precompute(scene, **_quiet_knobs(module, knobs))
            precomputed = time.perf_counter()
            image = state.render()
            finished = time.perf_counter()
            relit = []
            for _ in range(relight_frames):
                relight_started = time.perf_counter()
                state.render(lights=scene.lights)
                relit.append(time.perf_counter() - relight_started)
    except Exception as error:  # a failing method is shown in the page; the run goes on
        return MethodRun(status="failed", reason=f"{type(error).__name__}: {error}",
                         details=traceback.format_exc(), **base)
    log = getattr(state, "log", None)
    skipped = list(getattr(log, "skipped", []) or [])
    stage_seconds = dict(getattr(log, "seconds", {}) or {})
    notes = dict(getattr(log, "notes", {}) or {})
    for sentence in image.metadata.get("skipped", []) or []:
        if sentence not in skipped:
            skipped.append(str(sentence))
    first_frame = finished - precomputed
    return MethodRun(status="ok", image=image, precompute_seconds=precomputed - started,
                     frame_seconds=float(np.median(relit)) if relit else first_frame,
                     first_frame_seconds=first_frame, skipped=skipped,
                     stage_seconds={str(k): float(v) for k, v in stage_seconds.items()},
                     notes=json_safe(notes), **base)


def render_reference(scene, spp: int, passes: int | None, target_rse: float | None = None,
                     budget_seconds: float | None = None):
    """Render (or load from the cache) the reference of ``scene``; an exception is returned.

    ``passes`` fixed passes of ``spp`` samples; or, with ``passes`` None, passes added until
    the median relative standard error is ``target_rse`` or ``budget_seconds`` are spent.
    A task for :func:`~translucent.reports.distributed.run_tasks`: a failure comes back as
    the string ``"Type: message"`` so that one scene's failure does not stop the others.
    """
    from ..reference.render import render, render_to_target

    try:
        if passes is None:
            return render_to_target(scene, target_rse=target_rse,
                                    budget_seconds=budget_seconds, spp=spp, progress=False)
        return render(scene, spp=spp, passes=passes, progress=False)
    except Exception as error:  # shown in the page; the other scenes go on
        return f"{type(error).__name__}: {error}"


def committed_reference_for(scene):
    """Return the committed reference of a built-in scene loaded from the catalogue, or None.

    Raises
    ------
    InputError
        When the scene has a committed reference that cannot be used (stale, missing,
        unreadable, of another size): the message names the file, the scene and the
        command that renders it again. Never silently re-used, never silently replaced.
    """
    from ..reference.committed import PLANS, committed_reference
    from ..scenes.scene_file import builtin_scene_path

    if scene.name not in PLANS or not scene.source:
        return None
    try:
        builtin = builtin_scene_path(scene.name)
    except InputError:
        return None
    if Path(scene.source).resolve() != Path(builtin).resolve():
        return None  # a scene file of its own that happens to share the name
    return committed_reference(scene.name, scene).require()


def _task(kind: str, scene, *arguments):
    """Run one task of the report on a worker: a reference render or a method run.

    ``scene`` is a Scene, or the path of the scene file it was loaded from (a local worker
    reads the file instead of receiving the pickled meshes and textures).
    """
    if isinstance(scene, str):
        from ..scenes import load_scene

        scene = load_scene(scene)
    if kind == "reference":
        return render_reference(scene, *arguments)
    return run_method(arguments[0], scene, *arguments[1:])


def _portable(scene, scene_hash: str, local_workers: bool):
    """Return the scene file's path when a local worker loads the same scene from it."""
    from ..cache import content_hash
    from ..scenes import load_scene

    source = getattr(scene, "source", None)
    if not local_workers or not source or not Path(source).is_file():
        return scene
    try:
        same = content_hash(load_scene(str(source))) == scene_hash
    except InputError:
        same = False
    return str(source) if same else scene


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


def backend_versions() -> dict:
    """Return the Mitsuba, Dr.Jit and numpy versions and the variant (they decide images)."""
    from ..backend import mitsuba

    mi = mitsuba()
    import drjit as dr

    return {"mitsuba": mi.__version__, "drjit": dr.__version__, "variant": mi.variant(),
            "numpy": np.__version__}


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


# ====================================================================== baseline


def load_baseline(path, *, required: bool = False) -> dict:
    """Read a baseline file.

    Parameters
    ----------
    path : str or PathLike
        The JSON file.
    required : bool
        Raise when the file is missing (else an empty baseline is returned).

    Returns
    -------
    dict
        ``{"format": 1, "entries": {scene: {"scene_hash", "reference", "methods":
        {method: {metric: value}}}}}``.

    Raises
    ------
    InputError
        A folder, a missing file (when required), invalid JSON, an unknown layout or a
        gated metric that is not a finite number.
    """
    path = Path(path)
    if path.is_dir():
        raise InputError("is a folder; give the baseline's JSON file", file=path,
                         field="--baseline", value=str(path))
    if not path.is_file():
        if required:
            raise InputError("no such baseline file (run with --update-baseline to create it)",
                             file=path, field="--baseline", value=str(path))
        return {"format": BASELINE_FORMAT, "entries": {}}
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, ValueError) as error:
        raise InputError(f"not a readable JSON baseline ({error})", file=path,
                         field="--baseline") from error
    if not isinstance(data, dict) or data.get("format") != BASELINE_FORMAT \
            or not isinstance(data.get("entries"), dict):
        raise InputError(f"not a baseline of format {BASELINE_FORMAT} (a JSON object with "
                         f"'format' and 'entries')", file=path, field="format",
                         value=data.get("format") if isinstance(data, dict) else type(data))
    for scene_name, entry in data["entries"].items():
        _check_baseline_entry(path, f"entries.{scene_name}", entry)
    return data


def _check_baseline_entry(path: Path, where: str, entry) -> None:
    """Refuse an entry the comparison could not read (a hand edit, a foreign file)."""
    if not isinstance(entry, dict):
        raise InputError("must be an object with scene_hash, reference and methods",
                         file=path, field=where, value=entry)
    for key in ("reference", "methods"):
        if not isinstance(entry.get(key, {}), dict):
            raise InputError("must be an object", file=path, field=f"{where}.{key}",
                             value=entry[key])
    for method_name, values in entry.get("methods", {}).items():
        if not isinstance(values, dict):
            raise InputError("must be an object of metric -> value", file=path,
                             field=f"{where}.methods.{method_name}", value=values)
        for metric_name in TOLERANCES:
            value = values.get(metric_name, 0.0)
            if isinstance(value, bool) or not isinstance(value, (int, float)) \
                    or not math.isfinite(value):
                raise InputError("must be a finite number (a gated metric)", file=path,
                                 field=f"{where}.methods.{method_name}.{metric_name}",
                                 value=value)


@dataclass(frozen=True)
class BaselineCheck:
    """The verdict on one method's metrics against the baseline.

    Parameters
    ----------
    status : {"ok", "regression", "improved", "no baseline", "not compared"}
        "regression" makes the report exit 1.
    message : str
        One sentence for the page.
    metrics : dict of str to dict
        Per gated metric: ``value``, ``baseline``, ``limit`` and ``verdict`` ("ok",
        "worse", "better").
    """

    status: str
    message: str
    metrics: dict[str, dict] = field(default_factory=dict)

    def as_dict(self) -> dict:
        """Return a JSON-safe dict."""
        return {"status": self.status, "message": self.message, "metrics": json_safe(self.metrics)}


def check_against_baseline(scene_name: str, scene_hash: str, reference: dict, method_name: str,
                           metrics: dict | None, baseline: dict, *,
                           failure: str = "") -> BaselineCheck:
    """Compare one method's metrics on one scene with the baseline.

    Parameters
    ----------
    scene_name, method_name : str
        The pair.
    scene_hash : str
        The content hash of the scene: an entry made for another scene of the same name is
        not compared.
    reference : dict
        ``{"spp": ..., "passes": ...}`` of this run's reference: an entry made against
        another reference is not compared.
    metrics : dict or None
        ``Metrics.as_dict()`` of this run; None when the method produced no metrics.
    baseline : dict
        From :func:`load_baseline`.
    failure : str
        Why there are no metrics (shown when the baseline expected some).

    Returns
    -------
    BaselineCheck
    """
    entry = baseline.get("entries", {}).get(scene_name)
    stored = None if entry is None else entry.get("methods", {}).get(method_name)
    if stored is None:
        if metrics is None:
            return BaselineCheck("no baseline", "no result and no baseline entry")
        return BaselineCheck("no baseline", "no baseline entry for this scene and method "
                             "(run with --update-baseline to add it)")
    if entry.get("scene_hash") != scene_hash:
        return BaselineCheck("not compared", "the baseline was made for another scene of "
                             "this name (its content hash differs)")
    made_with = entry.get("reference", {})
    if any(made_with.get(key) != reference.get(key) for key in ("spp", "passes")):
        return BaselineCheck("not compared", f"the baseline was made against a reference of "
                             f"{made_with.get('spp')} spp x {made_with.get('passes')} passes; "
                             f"this run's has {reference.get('spp')} x "
                             f"{reference.get('passes')}")
    if metrics is None:
        return BaselineCheck("regression", f"the baseline has metrics but this run has none: "
                             f"{failure or 'no result'}")
    verdicts: dict[str, dict] = {}
    for name, tolerance in TOLERANCES.items():
        if name not in stored:
            continue
        value, base = float(metrics[name]), float(stored[name])
        verdict = ("worse" if tolerance.is_worse(value, base) else
                   "better" if tolerance.is_better(value, base) else "ok")
        verdicts[name] = {"value": value, "baseline": base, "limit": tolerance.limit(base),
                          "verdict": verdict}
    worse = [METRIC_LABELS[n] for n, v in verdicts.items() if v["verdict"] == "worse"]
    better = [METRIC_LABELS[n] for n, v in verdicts.items() if v["verdict"] == "better"]
    if worse:
        return BaselineCheck("regression", f"worse than the baseline beyond tolerance: "
                             f"{', '.join(worse)}", verdicts)
    if better:
        return BaselineCheck("improved", f"better than the baseline beyond tolerance: "
                             f"{', '.join(better)} (--update-baseline records it)", verdicts)
    return BaselineCheck("ok", "within tolerance of the baseline", verdicts)


def updated_baseline(baseline: dict, results: list[dict], versions: dict) -> dict:
    """Return ``baseline`` with this run's scenes replaced by their results.

    Entries of scenes this run did not cover are kept; for a covered scene the entry is
    rebuilt from the methods that produced metrics (a method that failed or no longer
    applies loses its entry).

    Parameters
    ----------
    baseline : dict
        From :func:`load_baseline`.
    results : list of dict
        Per scene: ``name``, ``scene_hash``, ``reference`` (spp, passes) and ``metrics``
        ({method: Metrics dict}) of the methods that ran, plus ``methods_run`` (the
        methods this run asked for).
    versions : dict
        Mitsuba, Dr.Jit, variant: recorded for information.

    Returns
    -------
    dict
    """
    entries = {name: dict(entry) for name, entry in baseline.get("entries", {}).items()}
    for result in results:
        previous = entries.get(result["name"], {})
        methods = {} if previous.get("scene_hash") != result["scene_hash"] else \
            {name: values for name, values in previous.get("methods", {}).items()
             if name not in result["methods_run"]}
        for name, values in result["metrics"].items():
            methods[name] = {key: json_safe(values[key]) for key in REPORTED_METRICS}
        entries[result["name"]] = {"scene_hash": result["scene_hash"],
                                   "reference": dict(result["reference"]),
                                   "methods": dict(sorted(methods.items()))}
    return {"format": BASELINE_FORMAT,
            "note": "image metrics of the fast methods against their references; written by "
                    "`translucent report --update-baseline`",
            "updated": _now(), "versions": versions,
            "tolerances": {name: {"absolute": t.absolute, "relative": t.relative,
                                  "lower_is_better": t.lower_is_better}
                           for name, t in TOLERANCES.items()},
            "entries": dict(sorted(entries.items()))}


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
                progress: bool = True, stream=None) -> ReportResult:
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

    from ..cache import Cache, content_hash
    from ..fast.base import method as method_module
    from ..scenes import Scene, load_scene
    from .distributed import run_tasks

    stream = sys.stdout if stream is None else stream
    started = time.perf_counter()
    spp = None if spp is None else check_count(spp, "--spp")
    passes = check_count(passes, "--passes")
    chosen = _methods(methods)
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
    run_cache = Cache("report")
    tasks: list[tuple] = []
    owners: list[tuple[SceneReport, str | None, str | None]] = []
    portables: dict[str, Any] = {}

    def portable(report: SceneReport):
        # worked out only for a scene with a task: it may load the scene file again
        if report.slug not in portables:
            portables[report.slug] = _portable(report.scene, report.scene_hash,
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
            except InputError as error:
                report.runs[name] = MethodRun(name, report.name, "not built", error.reason)
                continue
            try:
                reason = module.applies_to(report.scene)
            except Exception as error:  # the method's own check failed: show it
                report.runs[name] = MethodRun(name, report.name, "failed",
                                              f"applies_to: {type(error).__name__}: {error}")
                continue
            if reason is not None:
                report.runs[name] = MethodRun(name, report.name, "not applicable", str(reason))
                continue
            key = _run_key(name, report.scene, {}, fingerprint, versions)
            stored = run_cache.load_pickle(key)
            if isinstance(stored, MethodRun) and stored.status == "ok":
                stored.cached = True
                report.runs[name] = stored
                continue
            tasks.append(("method", portable(report), name, {}))
            owners.append((report, name, key))

    if tasks:
        print(f"running {len(tasks)} task(s): "
              f"{sum(1 for t in tasks if t[0] == 'reference')} reference render(s), "
              f"{sum(1 for t in tasks if t[0] == 'method')} method run(s)", file=stream,
              flush=True)
        results = run_tasks(_task, tasks, scheduler=scheduler, local=serial,
                            progress=progress)
    else:
        results = []
    for (report, name, key), result in zip(owners, results, strict=True):
        if name is None:
            if isinstance(result, Image):
                report.reference = result
            else:
                report.reference_error = str(result)
            continue
        report.runs[name] = result
        if result.status == "ok":
            run_cache.store_pickle(key, result)

    staging = None
    try:
        staging = _staging_folder(out)
        for report in tqdm(reports, desc="metrics and error maps", disable=not progress,
                           leave=False, file=sys.stderr):
            _compare_and_write(report, staging)
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
            "generated": _now(), "versions": versions, "reference": reference_settings,
            "baseline": str(baseline_path), "baseline_updated": update_baseline,
            "baseline_versions": stored_baseline.get("versions", {}),
            "excluded": excluded, "methods": chosen, "regressions": regressions,
            "exit_code": exit_code, "fingerprint": fingerprint,
            "scheduler": "this process" if serial else (scheduler or "local processes"),
        }
        summary = _summary(reports, chosen)
        context["seconds"] = time.perf_counter() - started
        atomic_write_text(staging / "metrics.json",
                          json.dumps(_metrics_json(reports, chosen, context), indent=2,
                                     sort_keys=False, allow_nan=False))
        atomic_write_text(staging / "index.html", _html(reports, chosen, context))
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
    _print_summary(summary, regressions, out, seconds, update_baseline, baseline_path, stream)
    for report in reports:
        if report.noise_warning:
            print(f"warning: {report.name}: {report.noise_warning}", file=sys.stderr)
    return ReportResult(exit_code, out, regressions, seconds, summary)


def _made_with(report: SceneReport) -> dict:
    """Return the reference's spp and passes (what a baseline entry records it was made with)."""
    meta = report.reference.metadata if report.reference is not None else {}
    return {"spp": meta.get("spp", report.spp), "passes": meta.get("passes")}


def _staging_folder(out: Path) -> Path:
    parent = out.absolute().parent
    parent.mkdir(parents=True, exist_ok=True)
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


def _compare_and_write(report: SceneReport, folder: Path) -> None:
    """Write the scene's images and error maps; compute the metrics of each method."""
    from .error_maps import write_error_maps, write_linear_png
    from .metrics import NOISE_FLOOR_FIELDS, display_white, evaluate, noise_floor, noise_verdict

    scene_folder = folder / report.slug
    scene_folder.mkdir(parents=True, exist_ok=True)
    white = None
    if report.reference is not None:
        report.scored_mask = _scored_pixels(report.scene)
        _reference_noise(report)
        try:
            floor = noise_floor(report.reference, mask=report.scored_mask)
        except InputError:
            floor = None
        report.noise_floor = floor.as_dict() if floor is not None else None
        report.reference.write(scene_folder / "reference.exr")
        white = display_white(report.reference.rgb)
        write_linear_png(scene_folder / "reference.png", report.reference, white=white)
        report.files["reference"] = {"png": f"{report.slug}/reference.png",
                                     "exr": f"{report.slug}/reference.exr"}
    for name, run in report.runs.items():
        if run.status != "ok" or run.image is None:
            continue
        files = {"exr": f"{report.slug}/{name}.exr", "png": f"{report.slug}/{name}.png"}
        run.image.write(folder / files["exr"])
        rgb = np.nan_to_num(run.image.rgb, nan=0.0, posinf=0.0, neginf=0.0)
        write_linear_png(folder / files["png"], rgb, white=white)
        report.files[name] = files
        if report.reference is None:
            report.metric_errors[name] = f"no reference: {report.reference_error}"
            continue
        try:
            comparison = evaluate(report.reference, run.image)
            maps = write_error_maps(report.reference, run.image, scene_folder,
                                    prefix=f"{name}_", comparison=comparison)
            scored = evaluate(report.reference, run.image, mask=report.scored_mask)
        except (InputError, TypeError) as error:
            report.metric_errors[name] = str(error)
            continue
        report.metrics[name] = scored.metrics.as_dict()
        report.image_metrics[name] = comparison.metrics.as_dict()
        floors = report.noise_floor or {}
        report.verdicts[name] = {
            key: noise_verdict(key, report.metrics[name][key], floors.get(key))
            or "no floor (the reference has no variance)" for key in NOISE_FLOOR_FIELDS}
        for map_name, map_files in maps.items():
            files[f"map_{map_name}"] = f"{report.slug}/{map_files.png.name}"


def _scored_pixels(scene):
    """Return the pixels a method is scored on: those whose centre ray sees an object.

    The background (an environment seen directly, or black) is the same in every method's
    image and the reference's, so it would only dilute the averages; None (the whole image)
    when no pixel sees an object.
    """
    from ..scenes import gbuffer

    hit = gbuffer(scene).hit
    return hit if hit.any() else None


def _reference_noise(report: SceneReport) -> None:
    """Summarise the reference's own noise; warn when it is too noisy to judge by."""
    from ..noise import noise_summary, resolvable_error

    reference = report.reference
    if reference.variance is None:
        report.noise_warning = ("the reference has no variance: its noise is unknown, no "
                                "noise floor can be given")
        return
    summary = noise_summary(reference.rgb, reference.variance, report.scored_mask,
                            mask_name="scored")
    report.reference_noise = summary
    if summary.pixels and summary.median > NOISE_WARNING_RSE:
        report.noise_warning = (
            f"the reference is noisy ({summary.text()}, relative standard error): relative "
            f"errors below about {100 * resolvable_error(summary):.2g} % cannot be resolved")


def _summary(reports: list[SceneReport], chosen: list[str]) -> list[dict]:
    rows = []
    for report in reports:
        for name in chosen:
            run = report.runs.get(name)
            metrics = report.metrics.get(name, {})
            check = report.checks.get(name)
            rows.append({
                "scene": report.name, "method": name,
                "status": run.status if run else "not run",
                "reason": (report.metric_errors.get(name) or (run.reason if run else "")),
                "hdr_flip": metrics.get("hdr_flip"), "relative_mse": metrics.get("relative_mse"),
                "ciede2000": metrics.get("ciede2000"), "ssim": metrics.get("ssim"),
                "noise_floor": {key: (report.noise_floor or {}).get(key)
                                for key in ("hdr_flip", "relative_mse", "ciede2000", "ssim")},
                "within_noise": [key for key, verdict in report.verdicts.get(name, {}).items()
                                 if verdict == "within reference noise"],
                "precompute_seconds": run.precompute_seconds if run else None,
                "frame_seconds": run.frame_seconds if run else None,
                "cached": bool(run and run.cached),
                "baseline": check.status if check else "",
            })
    return rows


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
            entry["pixels_scored"] = ("object" if report.scored_mask is not None else "image")
            entry["image_metrics"] = json_safe(report.image_metrics.get(name))
            metrics = report.metrics.get(name)
            entry["noise"] = None if metrics is None else {
                key: {"value": json_safe(metrics[key]),
                      "noise_floor": json_safe((report.noise_floor or {}).get(key)),
                      "verdict": report.verdicts[name][key]}
                for key in report.verdicts.get(name, {})}
            entry["metrics_error"] = report.metric_errors.get(name, "")
            entry["files"] = report.files.get(name, {})
            check = report.checks.get(name)
            entry["baseline"] = check.as_dict() if check else None
            methods[name] = entry
        scenes[report.name] = {"source": str(report.scene.source or ""),
                               "description": report.scene.description,
                               "scene_hash": report.scene_hash, "folder": report.slug,
                               "reference": reference, "reference_error": report.reference_error,
                               "methods": methods}
    tolerances = {name: {"absolute": t.absolute, "relative": t.relative,
                         "lower_is_better": t.lower_is_better} for name, t in TOLERANCES.items()}
    return {"format": 1, **json_safe(context), "tolerances": tolerances, "scenes": scenes}


def _format(value, digits: int = 4) -> str:
    if value is None:
        return "–"
    if isinstance(value, float):
        if not math.isfinite(value):
            return str(value)
        return f"{value:.{digits}g}"
    return str(value)


def _seconds(value) -> str:
    if value is None:
        return "–"
    return f"{value * 1000:.0f} ms" if value < 1 else f"{value:.1f} s"


def _print_summary(summary, regressions, out, seconds, updated, baseline_path, stream):
    width = max((len(r["scene"]) for r in summary), default=5)
    print(f"{'scene':<{width}}  {'method':<10} {'HDR-FLIP':>8} {'(noise)':>7} {'relMSE':>9} "
          f"{'(noise)':>9} {'dE2000':>7} {'SSIM':>6} {'precomp':>8} {'frame':>8}  verdict",
          file=stream)
    for row in summary:
        if row["status"] != "ok":
            print(f"{row['scene']:<{width}}  {row['method']:<10} {row['status']}: "
                  f"{row['reason'][:90]}", file=stream)
            continue
        cached = " (cached)" if row["cached"] else ""
        floor = row["noise_floor"]
        noisy = (f"; within reference noise: {', '.join(row['within_noise'])}"
                 if row["within_noise"] else "")
        print(f"{row['scene']:<{width}}  {row['method']:<10} {_format(row['hdr_flip'], 3):>8} "
              f"{_format(floor['hdr_flip'], 2):>7} "
              f"{_format(row['relative_mse'], 3):>9} {_format(floor['relative_mse'], 2):>9} "
              f"{_format(row['ciede2000'], 3):>7} "
              f"{_format(row['ssim'], 3):>6} {_seconds(row['precompute_seconds']):>8} "
              f"{_seconds(row['frame_seconds']):>8}  {row['baseline']}{cached}{noisy}",
              file=stream)
    for line in regressions:
        print(f"REGRESSION {line}", file=stream)
    if updated:
        print(f"baseline written: {baseline_path}", file=stream)
    print(f"wrote {out / 'index.html'} in {seconds:.1f} s", file=stream, flush=True)


# ====================================================================== the page


def _reference_text(settings: dict) -> str:
    if settings.get("committed"):
        return (f"the committed ones of the built-in scenes, other scenes rendered to a median "
                f"relative standard error of {100 * settings['target_rse']:g} % (at most "
                f"{settings['budget_seconds']:g} s each)")
    return f"{settings['spp']} spp x {settings['passes']} passes, rendered for this run"


def _stylesheet() -> str:
    path = Path(__file__).resolve().parent / "templates" / "report.css"
    return path.read_text(encoding="utf-8") if path.is_file() else ""


def _e(text) -> str:
    return html.escape(str(text), quote=True)


def _figure(src: str, caption: str, *, css: str = "") -> str:
    return (f'<figure class="{css}"><img src="{_e(src)}" alt="{_e(caption)}">'
            f"<figcaption>{_e(caption)}</figcaption></figure>")


def _verdict_class(status: str) -> str:
    return {"regression": "bad", "improved": "good", "ok": "ok"}.get(status, "note")


def _html(reports: list[SceneReport], chosen: list[str], context: dict) -> str:
    from .error_maps import MAP_STYLES

    versions = context["versions"]
    parts = [
        "<!DOCTYPE html>", '<html lang="en"><head><meta charset="utf-8">',
        "<title>translucent report</title>",
        f"<style>{_stylesheet()}</style></head><body>",
        "<h1>Fast methods against their references</h1>",
        f"<p class=meta>Generated {_e(context['generated'])}; Mitsuba {_e(versions['mitsuba'])} "
        f"({_e(versions['variant'])}), Dr.Jit {_e(versions['drjit'])}; references: "
        f"{_e(_reference_text(context['reference']))}; tasks "
        f"on {_e(context['scheduler'])}; whole run {context['seconds']:.1f} s.</p>",
    ]
    regressions = context["regressions"]
    if regressions:
        parts.append(f'<p class="verdict bad">{len(regressions)} regression(s) against the '
                     f"baseline <code>{_e(context['baseline'])}</code>"
                     f"{' (baseline now rewritten)' if context['baseline_updated'] else ''}:"
                     "</p><ul class=bad>" + "".join(f"<li>{_e(r)}</li>" for r in regressions)
                     + "</ul>")
    else:
        rewritten = " (baseline rewritten from this run)" if context["baseline_updated"] else ""
        # the results with metrics: a method that did not apply has nothing to compare
        checks = [check for report in reports for name, check in report.checks.items()
                  if name in report.metrics]
        compared = sum(check.status in ("ok", "improved") for check in checks)
        unmatched = sum(check.status == "no baseline" for check in checks)
        other = sum(check.status == "not compared" for check in checks)
        reasons = ", ".join(filter(None, [
            f"{unmatched} result(s) had no baseline entry" if unmatched else "",
            f"{other} were made against another reference" if other else ""]))
        baseline = f"<code>{_e(context['baseline'])}</code>"
        if compared:
            extra = f"; {reasons}" if reasons else ""
            parts.append(f'<p class="verdict ok">No regression in the {compared} result(s) '
                         f"compared with the baseline {baseline}{extra}{rewritten}.</p>")
        else:
            parts.append(f'<p class="verdict fail">Nothing was compared with the baseline '
                         f"{baseline} ({reasons or 'no result to compare'}){rewritten}; no "
                         "regression can be told.</p>")
    parts.append(_summary_table(reports, chosen))
    parts.append(_legend(MAP_STYLES))
    if context["excluded"]:
        parts.append("<h2>Built-in scenes left out</h2><ul>" + "".join(
            f"<li><b>{_e(n)}</b>: {_e(r)}</li>" for n, r in context["excluded"].items())
            + "</ul>")
    for report in reports:
        parts.append(_scene_section(report, chosen))
    parts.append(_tolerance_note())
    parts.append("</body></html>")
    return "\n".join(parts) + "\n"


def _summary_table(reports: list[SceneReport], chosen: list[str]) -> str:
    head = "".join(f"<th>{_e(n)}</th>" for n in chosen)
    rows = []
    for report in reports:
        cells = []
        for name in chosen:
            run = report.runs.get(name)
            metrics = report.metrics.get(name)
            check = report.checks.get(name)
            css = _verdict_class(check.status) if check else "note"
            if metrics is not None:
                noisy = report.verdicts.get(name, {}).get("hdr_flip") == \
                    "within reference noise"
                floor = (report.noise_floor or {}).get("hdr_flip")
                floor_text = f" (noise {floor:.3f})" if floor is not None else ""
                text = (f'<a href="#{_e(report.slug)}-{_e(name)}">FLIP '
                        f"{metrics['hdr_flip']:.3f}</a>{_e(floor_text)}<br><small>"
                        f"{'within reference noise; ' if noisy else ''}{_e(check.status)}"
                        "</small>")
            elif run is not None and run.status in ("not applicable", "not built", "not run"):
                text, css = f"<small>{_e(run.status)}</small>", "muted"
                if check is not None and check.status == "regression":
                    text, css = f"<small>{_e(run.status)}; regression</small>", "bad"
            else:
                status = run.status if run else "not run"
                if status == "ok":
                    status = "no metrics"  # an image but no reference, or metrics failed
                text = (f"<small>{_e(status)}"
                        f"{'; regression' if check and check.status == 'regression' else ''}"
                        "</small>")
                css = "bad" if check is not None and check.status == "regression" else "fail"
            cells.append(f'<td class="{css}">{text}</td>')
        rows.append(f'<tr><th><a href="#{_e(report.slug)}">{_e(report.name)}</a></th>'
                    + "".join(cells) + "</tr>")
    return (f'<table class=summary><tr><th>scene</th>{head}</tr>{"".join(rows)}</table>'
            "<p class=meta>HDR-FLIP of each method against the reference (0 is identical), "
            "beside its noise floor (what the reference's own noise alone gives), and its "
            "verdict against the baseline.</p>")


def _legend(styles) -> str:
    items = "".join(f"<li><b>{_e(name)}</b>: {_e(style.unit)}, colour map {_e(style.colormap)} "
                    f"from {style.vmin:g} to {style.vmax:g}</li>"
                    for name, style in styles.items() if name != "p_value")
    return (f"<details><summary>How to read the error maps</summary><ul>{items}</ul><p>"
            "Method images are shown with the reference's exposure (its 99th-percentile "
            "luminance is white), so a brightness error stays visible.</p></details>")


def _scene_section(report: SceneReport, chosen: list[str]) -> str:
    parts = [f'<section id="{_e(report.slug)}"><h2>{_e(report.name)}</h2>',
             f"<p>{_e(report.scene.description)}</p>"]
    if report.reference is not None:
        meta = report.reference.metadata
        caption = (f"reference: {meta.get('integrator', '?')}, {meta.get('spp')} spp x "
                   f"{meta.get('passes')} passes, rendered in {_seconds(meta.get('seconds'))}"
                   f"{_reference_origin(report)}")
        parts.append('<div class=row>' + _figure(report.files["reference"]["png"], caption,
                                                 css="reference") + "</div>")
        for sentence in meta.get("substitutions") or []:
            parts.append(f"<p class=note>Reference: {_e(sentence)}</p>")
        source = {"committed": "committed with the suite (translucent references)",
                  "progressive": f"rendered to a noise target ({meta.get('stopped', '?')})",
                  "fixed passes": "rendered in fixed passes for this run"}.get(
                      report.reference_source, report.reference_source)
        noise = (f"; relative standard error {report.reference_noise.text()}"
                 if report.reference_noise is not None else "")
        parts.append(f"<p class=meta>Reference {_e(source)}{_e(noise)}.</p>")
        if report.scored_mask is not None:
            parts.append(f"<p class=meta>Every metric below is computed over the "
                         f"{int(report.scored_mask.sum())} pixels that see an object of the "
                         "scene (the background, the same in every image, is left out); "
                         "whole-image values are in metrics.json (<code>image_metrics</code>)."
                         "</p>")
        if report.noise_warning:
            parts.append(f"<p class=fail>Warning: {_e(report.noise_warning)}.</p>")
    else:
        parts.append(f"<p class=fail>The reference could not be rendered: "
                     f"{_e(report.reference_error)}</p>")
    not_run = []
    for name in chosen:
        run = report.runs.get(name)
        if run is None or run.status in ("not applicable", "not built", "not run"):
            reason = run.reason if run else "not run"
            status = run.status if run else "not run"
            extra = ""
            check = report.checks.get(name)
            if check is not None and check.status == "regression":
                extra = f' <span class=bad>regression: {_e(check.message)}</span>'
            not_run.append(f"<li><b>{_e(name)}</b> ({_e(status)}): {_e(reason)}{extra}</li>")
            continue
        parts.append(_method_block(report, name, run))
    if not_run:
        parts.append("<h3>Methods not run on this scene</h3><ul>" + "".join(not_run) + "</ul>")
    parts.append("</section>")
    return "\n".join(parts)


def _reference_origin(report: SceneReport) -> str:
    if report.reference_source == "committed":
        return " (committed with the suite)"
    return " (from the cache)" if report.reference_cached else ""


def _method_block(report: SceneReport, name: str, run: MethodRun) -> str:
    check = report.checks.get(name)
    anchor = f"{report.slug}-{name}"
    parts = [f'<div class=method id="{_e(anchor)}"><h3>{_e(name)}']
    if check is not None:
        parts.append(f' <span class="tag {_verdict_class(check.status)}">{_e(check.status)}'
                     "</span>")
    parts.append("</h3>")
    if run.status == "failed":
        parts.append(f"<p class=fail>The method failed: {_e(run.reason)}</p>")
        if run.details:
            parts.append(f"<details><summary>traceback</summary><pre>{_e(run.details)}</pre>"
                         "</details>")
    files = report.files.get(name, {})
    if files:
        figures = [_figure(files["png"], f"{name}")]
        for map_name in ("flip", "relative_error", "ciede2000", "ssim"):
            if f"map_{map_name}" in files:
                figures.append(_figure(files[f"map_{map_name}"], map_name.replace("_", " ")))
        if report.reference is not None:
            figures.insert(0, _figure(report.files["reference"]["png"], "reference"))
        parts.append('<div class=row>' + "".join(figures) + "</div>")
    if name in report.metric_errors:
        parts.append(f"<p class=fail>No metrics: {_e(report.metric_errors[name])}</p>")
    if check is not None:
        parts.append(f'<p class="{_verdict_class(check.status)}">Baseline: {_e(check.message)}'
                     "</p>")
    metrics = report.metrics.get(name)
    if metrics is not None:
        parts.append(_metrics_table(metrics, check, report.noise_floor,
                                    report.verdicts.get(name, {})))
    if run.status == "ok":
        cached = (f" Image and times from the run of {_e(run.measured_at)} (cached: nothing "
                  "it depends on has changed since)." if run.cached else "")
        cache_note = run.notes.get("cache") if isinstance(run.notes, dict) else None
        from_cache = (" The method loaded its precomputation from its own cache; the stage "
                      "times below are those of the run that computed it." if cache_note == "hit"
                      else "")
        parts.append(f"<p>Precomputation {_seconds(run.precompute_seconds)}, first frame "
                     f"(the first <code>state.render()</code>, first-call costs included) "
                     f"{_seconds(run.frame_seconds)}.{cached}{from_cache}</p>")
        if run.stage_seconds:
            parts.append("<details><summary>stage times</summary><table class=small>" + "".join(
                f"<tr><td>{_e(stage)}</td><td>{_seconds(seconds)}</td></tr>"
                for stage, seconds in run.stage_seconds.items()) + "</table></details>")
    if run.skipped:
        parts.append("<p>Skipped for this scene:</p><ul class=skipped>" + "".join(
            f"<li>{_e(sentence)}</li>" for sentence in run.skipped) + "</ul>")
    elif run.status == "ok":
        parts.append("<p class=meta>The method skipped nothing for this scene.</p>")
    parts.append("</div>")
    return "\n".join(parts)


def _metrics_table(metrics: dict, check: BaselineCheck | None, floors: dict | None = None,
                   verdicts: dict | None = None) -> str:
    from .metrics import NOISE_MARGIN

    gated = check.metrics if check is not None else {}
    floors, verdicts = floors or {}, verdicts or {}
    rows = []
    for key in REPORTED_METRICS:
        value = metrics.get(key)
        entry = gated.get(key)
        noise = verdicts.get(key, "")
        noise_css = " muted" if noise == "within reference noise" else ""
        noise_cells = (f"<td>{_format(floors.get(key))}</td>"
                       f'<td class="{noise_css.strip()}">{_e(noise)}</td>')
        if entry is not None:
            css = {"worse": "bad", "better": "good"}.get(entry["verdict"], "")
            rows.append(f'<tr class="{css}"><td>{_e(METRIC_LABELS[key])}</td>'
                        f"<td>{_format(value)}</td>{noise_cells}"
                        f"<td>{_format(entry['baseline'])}</td>"
                        f"<td>{_format(entry['limit'])}</td><td>{_e(entry['verdict'])}</td></tr>")
        else:
            tolerance = "gated" if key in TOLERANCES else ""
            rows.append(f"<tr><td>{_e(METRIC_LABELS[key])}</td><td>{_format(value)}</td>"
                        f"{noise_cells}<td>–</td><td>–</td><td>{tolerance}</td></tr>")
    return ("<table class=metrics><tr><th>metric</th><th>value</th><th>noise floor</th>"
            "<th>against the noise</th><th>baseline</th><th>worst accepted</th>"
            "<th>against the baseline</th></tr>" + "".join(rows) + "</table>"
            "<p class=meta>Noise floor: what the metric gives when the only difference is the "
            "reference's own noise (the reference against itself perturbed by noise of its "
            f"variance). 'within reference noise': the value does not clear the floor by a "
            f"factor of {NOISE_MARGIN:g} (errors; 1 - SSIM; the MSE behind PSNR), so the "
            "reference cannot "
            "tell this method from a perfect one by this metric.</p>")


def _tolerance_note() -> str:
    items = "".join(
        f"<li>{_e(METRIC_LABELS[name])}: worse by more than {t.absolute:g}"
        f"{f' + {t.relative:.0%} of the baseline' if t.relative else ''}</li>"
        for name, t in TOLERANCES.items())
    return (f"<h2>Regression tolerances</h2><p>A result is a regression when a gated metric "
            f"is worse than its baseline by more than:</p><ul>{items}</ul>")
