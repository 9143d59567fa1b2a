"""Other renderers scored like methods (``report --renderers``): their tasks and their runs.

A renderer of :mod:`translucent.reference.peers.registry` renders each scene in each mode
asked (the entry ``NAME.MODE``) at every count of :data:`RENDERER_SPP`, timed after an
untimed warm-up. The last count's render is the entry's run, scored and timed as a fast
method's frame; the others are its ladder, drawn on the scene's run-time-against-error plot
beside path tracing's. A mode whose model the suite knows (Cycles' ``burley``:
``burley_cycles``) has its error split as a method's (:func:`.split.split_profile`).
"""

from __future__ import annotations

from ...errors import InputError
from .runs import MethodRun, timestamp

__all__ = ["RENDERER_SPP", "check_renderer_spp", "peer_runs", "plan_peer"]

#: The samples per pixel each mode is rendered at; the last is the scored run.
RENDERER_SPP = (4, 16, 64)


def check_renderer_spp(values) -> tuple[int, ...]:
    """Return the counts (ascending, distinct, positive), or an InputError naming the value."""
    try:
        counts = tuple(sorted({int(v) for v in values}))
    except (TypeError, ValueError):
        raise InputError("must be whole numbers of samples per pixel, comma-separated",
                         field="--renderer-spp", value=str(values)) from None
    if not counts or counts[0] < 1 or counts[-1] > 1 << 20:
        raise InputError("must be between 1 and 1048576 samples per pixel",
                         field="--renderer-spp", value=list(values))
    return counts


def plan_peer(report, entry: str) -> bool:
    """Decide whether ``entry`` renders ``report``'s scene; file why not in its runs.

    Returns True when a task is to be planned.
    """
    from ...reference.peers.registry import entry_mode

    module, mode = entry_mode(entry)
    base = {"method": entry, "scene": report.name, "measured_at": timestamp()}
    if report.reference_error:
        report.runs[entry] = MethodRun(status="not run", reason="the scene has no reference "
                                       "to compare with", **base)
        return False
    missing = module.available()
    if missing:
        report.runs[entry] = MethodRun(status="not installed", reason=missing, **base)
        return False
    try:
        reason = module.applies_to(report.scene, mode)
    except Exception as error:  # the renderer's own check failed: show it
        reason = f"applies_to: {type(error).__name__}: {error}"
    if reason:
        report.runs[entry] = MethodRun(status="not applicable", reason=reason, **base)
        return False
    return True


def peer_runs(entry: str, scene_name: str, points: list[dict]):
    """Return the entry's run (the last count's render) and its ladder (the others)."""
    runs = []
    for point in points:
        base = {"method": entry, "scene": scene_name, "measured_at": timestamp(),
                "knobs": {"spp": point["spp"]}}
        if "error" in point:
            runs.append(MethodRun(status="failed", reason=point["error"], **base))
            continue
        meta = point["image"].metadata
        version = meta.get("blender") or meta.get("version") or ""
        runs.append(MethodRun(
            status="ok", image=point["image"], frame_seconds=point["seconds"],
            first_frame_seconds=point["seconds"],
            skipped=[f"rendered by {entry.partition('.')[0]} {version} ({entry}) at "
                     f"{point['spp']} spp: its own noise is part of its error"],
            notes={key: value for key, value in meta.items() if isinstance(value, str)},
            **base))
    return runs[-1], runs[:-1]
