"""The report's tasks: each knows what it runs, on a worker, and how it is named in the timing.

A task is a small frozen dataclass (picklable, so Dask sends it to a worker process) whose
:meth:`run` does the work there: a reference render (:class:`ReferenceTask`), a fast method
on a scene (:class:`MethodTask`) or a scene's path-tracing ladder (:class:`PathTracingTask`).
The scene travels as the :class:`~translucent.scenes.Scene` or, for a local worker, as the
path of the scene file it was loaded from (:func:`~.runs.portable_scene`): the worker reads
the file instead of receiving the pickled meshes and textures. :func:`run_task` is the one
function the task runner (:func:`~.distributed.run_tasks`) calls.

Examples
--------
>>> task = PathTracingTask("sphere", (1, 2))
>>> task.kind, task.group
('path tracing', None)
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, ClassVar

from .runs import json_safe, render_reference, run_method

__all__ = ["MethodTask", "PathTracingTask", "ReferenceTask", "RendererTask", "run_task",
           "task_entry"]


def _scene(scene):
    if isinstance(scene, str):
        from ...scenes import load_scene

        return load_scene(scene)
    return scene


@dataclass(frozen=True)
class ReferenceTask:
    """Render a scene's reference: ``passes`` fixed passes, or progressively to a target.

    Parameters
    ----------
    scene : Scene or str
    spp : int
        Samples per pixel of each pass.
    passes : int, optional
        Fixed passes; None with ``target_rse``: progressive.
    target_rse : float, optional
        Median relative standard error the progressive render stops at.
    budget_seconds : float, optional
        Seconds the progressive render may spend.
    profile : str, optional
        The model reference of this radial profile (the BSSRDF path tracer) instead of the
        volumetric reference.
    """

    kind: ClassVar[str] = "reference"
    scene: Any
    spp: int
    passes: int | None = None
    target_rse: float | None = None
    budget_seconds: float | None = None
    profile: str | None = None

    @property
    def group(self) -> None:
        """Reference renders wait for nothing."""
        return None

    def run(self):
        """Return the reference :class:`~translucent.image.Image`, or why there is none."""
        return render_reference(_scene(self.scene), self.spp, self.passes, self.target_rse,
                                self.budget_seconds, self.profile)


@dataclass(frozen=True)
class MethodTask:
    """Run one fast method on a scene at some knobs, timing its precomputation and frames.

    Parameters
    ----------
    scene : Scene or str
    method : str
        The registered method's name.
    knobs : dict
        Its knobs (the defaults: ``{}``).
    relight_frames : int
        Frames rendered after the first, for the warm frame time.
    """

    kind: ClassVar[str] = "method"
    scene: Any
    method: str
    knobs: dict
    relight_frames: int

    @property
    def group(self) -> str:
        """Return the method: on local workers its runs wait for its first.

        The first compiles its kernels into numba's on-disk cache for the others.
        """
        return self.method

    def run(self):
        """Return the :class:`~.runs.MethodRun` (the report asked ``applies_to`` already)."""
        return run_method(self.method, _scene(self.scene), self.knobs,
                          relight_frames=self.relight_frames, applies=True)


@dataclass(frozen=True)
class PathTracingTask:
    """Path-trace a scene at each count of samples per pixel: the speed-up's yardstick.

    Parameters
    ----------
    scene : Scene or str
    spps : tuple of int
        The ladder's samples per pixel (:data:`~.speedup.PATH_TRACING_SPP`).
    """

    kind: ClassVar[str] = "path tracing"
    scene: Any
    spps: tuple

    @property
    def group(self) -> None:
        """Path-tracing ladders wait for nothing."""
        return None

    def run(self):
        """Return the ladder's points (:func:`~.speedup.path_tracing_ladder`)."""
        from .speedup import path_tracing_ladder

        return path_tracing_ladder(_scene(self.scene), list(self.spps))


@dataclass(frozen=True)
class RendererTask:
    """Render a scene with another renderer's mode at each count of samples per pixel.

    Parameters
    ----------
    scene : Scene or str
    entry : str
        ``NAME.MODE`` (:mod:`translucent.reference.peers.registry`).
    spps : tuple of int
        The counts (:data:`~.peer_runs.RENDERER_SPP`); the last is the scored run.
    """

    kind: ClassVar[str] = "renderer"
    scene: Any
    entry: str
    spps: tuple

    @property
    def group(self) -> None:
        """Renderer tasks wait for nothing."""
        return None

    def run(self):
        """Return the entry's run and its ladder (:func:`~.peer_runs.peer_runs`)."""
        from ...reference.peers.registry import entry_mode
        from .peer_runs import peer_runs

        scene = _scene(self.scene)
        module, mode = entry_mode(self.entry)
        try:
            points = module.render(scene, mode, list(self.spps))
        except Exception as error:  # the renderer's failure is its entry's, not the report's
            points = [{"spp": spp, "error": f"{type(error).__name__}: {error}"}
                      for spp in sorted(self.spps)]
        return peer_runs(self.entry, scene.name, points)


def run_task(task):
    """Run ``task`` (on a worker): what its :meth:`run` returns."""
    return task.run()


def task_entry(task, scene_name: str, seconds: float, worker: int) -> dict:
    """Return one task's entry in ``metrics.json``'s timing: what it ran, where, how long."""
    entry = {"scene": scene_name, "kind": task.kind, "seconds": seconds, "worker": worker}
    if isinstance(task, MethodTask):
        entry["method"], entry["knobs"] = task.method, json_safe(task.knobs)
    elif isinstance(task, RendererTask):
        entry["method"], entry["knobs"] = task.entry, {"spp": list(task.spps)}
    elif isinstance(task, ReferenceTask) and task.profile is not None:
        entry["profile"] = task.profile
    return entry
