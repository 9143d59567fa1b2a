"""One task of the report: a fast method run on a scene, or its reference, as a worker runs it.

:func:`run_method` times a method's precomputation and first frame and keeps what it
skipped (:class:`MethodRun`); :func:`render_reference` renders a reference (fixed passes
or to a noise target); :func:`committed_reference_for` finds a built-in scene's committed
reference. The report and the benchmarks share them.
"""

from __future__ import annotations

import contextlib
import datetime
import math
import time
import traceback
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ...cache import private_cache
from ...errors import InputError
from ...image import Image
from ...progress import hidden

__all__ = ["MethodRun", "backend_versions", "committed_reference_for", "json_safe",
           "portable_scene", "reference_path", "render_reference", "run_method", "timestamp"]




@dataclass
class MethodRun:
    """One fast method on one scene: its image, times and what it skipped, or why not.

    Parameters
    ----------
    method, scene : str
        Names.
    status : {"ok", "failed", "not applicable", "not installed", "not run"}
        What happened ("not run": the scene has no reference to compare with).
    reason : str
        Why a method did not run, or the error it raised.
    reason_code : str
        The code of the method's :class:`~translucent.fast.base.Refusal` ("not
        applicable"; "other" where the method gave a plain sentence), else "".
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
    reason_code: str = ""
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
                "reason_code": self.reason_code,
                "precompute_seconds": self.precompute_seconds,
                "frame_seconds": self.frame_seconds,
                "first_frame_seconds": self.first_frame_seconds, "skipped": list(self.skipped),
                "stage_seconds": json_safe(self.stage_seconds), "notes": json_safe(self.notes),
                "knobs": json_safe(self.knobs), "measured_at": self.measured_at,
                "cached": self.cached}


def timestamp() -> str:
    """Return the local time, to the second, as ISO 8601 (when a run was measured)."""
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


def run_method(method_name: str, scene, knobs: dict | None = None, *,
               cold: bool = False, relight_frames: int = 0, applies: bool = False) -> MethodRun:
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
        After the first frame, render this many more with the lights moved a little each
        time (:func:`nudged_lights`: the interactive relighting path, as when a user drags
        a light, so that no method can reuse the first frame's lighting);
        ``frame_seconds`` is then their median and ``first_frame_seconds`` the first
        frame's, which can include first-call costs (compiled kernels loading). 0:
        ``frame_seconds`` is the first frame. The image kept is the first frame's.
    applies : bool
        The caller has asked the method's ``applies_to`` already (in this process or
        another) and it applies: the answer is passed on, not asked again
        (:func:`translucent.fast.base.applicability`).

    Returns
    -------
    MethodRun
        Status "ok" with the image, "not installed", "not applicable" (with the method's
        reason) or "failed" (with the error and its traceback).
    """
    from ...fast.base import applicability, method
    from ...fast.registry import MethodContractError

    knobs = dict(knobs or {})
    base = {"method": method_name, "scene": scene.name, "knobs": knobs,
            "measured_at": timestamp()}
    try:
        module = method(method_name)
    except MethodContractError as error:
        return MethodRun(status="failed", reason=error.reason, **base)
    except InputError as error:
        return MethodRun(status="not installed", reason=error.reason, **base)
    try:
        reason = applicability(module.applies_to, scene, *([None] if applies else []))
        if reason is not None:
            return MethodRun(status="not applicable", reason=reason.sentence,
                             reason_code=reason.code, **base)
        # the method's own bars would garble the run's bar
        with private_cache() if cold else contextlib.nullcontext(), hidden():
            started = time.perf_counter()
            state = module.precompute(scene, **knobs)
            precomputed = time.perf_counter()
            image = state.render()
            finished = time.perf_counter()
            relit = []
            for frame in range(relight_frames):
                lights = nudged_lights(scene.lights, frame + 1)
                relight_started = time.perf_counter()
                state.render(lights=lights)
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
                     budget_seconds: float | None = None, profile: str | None = None):
    """Render (or load from the cache) the reference of ``scene``; an exception is returned.

    ``passes`` fixed passes of ``spp`` samples; or, with ``passes`` None, passes added until
    the median relative standard error is ``target_rse`` or ``budget_seconds`` are spent.
    With ``profile``: the model reference, the BSSRDF path tracer's render of that profile
    (:mod:`translucent.reference.bssrdf_path`), or for a PCA BRDF model
    (``brdf_pca_kK``) the path tracer's with that BRDF (:mod:`translucent.reference.brdf_plugins`).
    A task for :func:`~translucent.reports.report.distributed.run_tasks`: a failure comes back as
    the string ``"Type: message"`` so that one scene's failure does not stop the others.
    """
    from ...materials.brdf_pca import pca_model_basis
    from ...reference.committed import MODEL_INTEGRATOR
    from ...reference.render import render, render_to_target

    model = {} if profile is None else {"profile": profile}
    if profile is not None and pca_model_basis(profile) is None:
        model["integrator"] = MODEL_INTEGRATOR  # a radial profile: the BSSRDF path tracer
    try:
        if passes is None:
            return render_to_target(scene, target_rse=target_rse,
                                    budget_seconds=budget_seconds, spp=spp, progress=False,
                                    **model)
        return render(scene, spp=spp, passes=passes, progress=False, **model)
    except Exception as error:  # shown in the page; the other scenes go on
        return f"{type(error).__name__}: {error}"


def reference_path(scene, spp: int, passes: int) -> Path:
    """Where the reference ``render(scene, spp=spp, passes=passes)`` is cached (may not exist).

    The settings are those of :func:`translucent.reference.render` with its own defaults, read
    from its signature, so a change of a default there cannot make this look in the wrong
    place.
    """
    import inspect

    from ...cache import Cache
    from ...reference.render import reference_key, reference_settings, render

    defaults = {name: parameter.default
                for name, parameter in inspect.signature(render).parameters.items()
                if parameter.default is not inspect.Parameter.empty}
    wanted = inspect.signature(reference_settings).parameters
    settings = reference_settings(**{**{name: defaults[name] for name in wanted
                                        if name in defaults}, "spp": spp, "passes": passes})
    return Cache("reference").path(reference_key(scene, settings), ".exr")


def committed_reference_for(scene, profile: str | None = None):
    """Return the committed reference of a built-in scene loaded from the catalogue, or None.

    With ``profile``: its committed model reference of that profile, or None where none is
    committed.

    Raises
    ------
    InputError
        When the scene has a committed reference that cannot be used (stale, missing,
        unreadable, of another size): the message names the file, the scene and the
        command that renders it again. Never silently re-used, never silently replaced.
    """
    from ...reference.committed import MODEL_PLANS, PLANS, committed_reference
    from ...scenes.scene_file import builtin_scene_path

    planned = scene.name in PLANS if profile is None else \
        profile in MODEL_PLANS.get(scene.name, {})
    if not planned or not scene.source:
        return None
    try:
        builtin = builtin_scene_path(scene.name)
    except InputError:
        return None
    if Path(scene.source).resolve() != Path(builtin).resolve():
        return None  # a scene file of its own that happens to share the name
    return committed_reference(scene.name, scene, profile).require()


#: The largest method precomputation (bytes) a report keeps in the cache by default
#: (``--keep-precomputations`` keeps all): PRT's and BRDF-PCA's are kept, radiosity's
#: dense operators on the default spheres are not (their sizes: docs/report.md). The
#: model-error bench keeps to it too.
REPORT_CACHE_ENTRY_LIMIT = 256 * 2**20

#: How far :func:`nudged_lights` moves a light per frame, scene units (a direction: radians).
LIGHT_NUDGE = 1e-4


def nudged_lights(lights, step: int) -> list:
    """Return ``lights`` moved by ``step`` x :data:`LIGHT_NUDGE`: new lights, the same light.

    Positions and centres move along x, directions turn about the axis they are least
    aligned with; environments stay as they are (nothing to move).
    """
    from ...scenes.scene import moved_lights

    return moved_lights(lights, step * LIGHT_NUDGE)


def portable_scene(scene, scene_hash: str, local_workers: bool):
    """Return the scene file's path when a local worker loads the same scene from it."""
    from ...cache import content_hash
    from ...scenes import load_scene

    source = getattr(scene, "source", None)
    if not local_workers or not source or not Path(source).is_file():
        return scene
    try:
        same = content_hash(load_scene(str(source))) == scene_hash
    except InputError:
        same = False
    return str(source) if same else scene



def backend_versions() -> dict:
    """Return the Mitsuba, Dr.Jit and numpy versions and the variant (they decide images)."""
    from ...backend import mitsuba

    mi = mitsuba()
    import drjit as dr

    return {"mitsuba": mi.__version__, "drjit": dr.__version__, "variant": mi.variant(),
            "numpy": np.__version__}
