"""The HTML report, read top to bottom: plan, run, judge, write.

:mod:`.pipeline` is the orchestrator (:func:`make_report`); :mod:`.model` the data model
every step reads (:class:`~.model.SceneReport`); :mod:`.tasks` the typed tasks that run on
the workers (:mod:`.distributed`); :mod:`.runs` what one method run or reference render is;
:mod:`.scoring` scores a scene as its last task arrives; :mod:`.baselines` judges against
the regression baseline; :mod:`.page` and :mod:`.summary` write what people read, with the
numbers formatted by :mod:`.formatting`; :mod:`.speedup` is the equal-error speed-up over
path tracing; :mod:`.renderer_images` scores another renderer's images.

``make_report``, ``ReportResult`` and ``default_scenes`` are offered here, imported on first
use (the workers import the task modules without the orchestrator).
"""

from __future__ import annotations

__all__ = ["ReportResult", "default_scenes", "make_report"]


def __getattr__(name):
    if name in __all__:
        from . import pipeline

        return getattr(pipeline, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
