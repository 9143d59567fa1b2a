"""The report's data model: what is known of each scene as the report plans, runs and judges.

The orchestrator (:mod:`translucent.reports.report.pipeline`) fills a :class:`SceneReport` per
scene; the scoring (:mod:`.scoring`), the page (:mod:`.report_page`) and the summary
(:mod:`.report_summary`) read it. Nothing here computes.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from ...image import Image
from .baselines import BaselineCheck
from .runs import MethodRun

__all__ = ["LADDER", "PATH_TRACING", "PEER", "ReportResult", "SceneReport", "keep_run"]

#: The owner of a ladder run among a report's tasks: ``(LADDER, method name)``.
LADDER = "ladder"

#: The owner of another renderer's task among a report's tasks: ``(PEER, "NAME.MODE")``.
PEER = "peer"

#: The owner name of a scene's path-tracing ladder task (not a method).
PATH_TRACING = "path tracing"


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
    #: per entry, its brightness against the reference and, with its own variance, its
    #: error with its noise discounted (:func:`~.scoring.systematic_error`)
    systematic: dict[str, dict] = field(default_factory=dict)
    metric_errors: dict[str, str] = field(default_factory=dict)
    checks: dict[str, BaselineCheck] = field(default_factory=dict)
    files: dict[str, dict[str, str]] = field(default_factory=dict)
    #: what the path-tracing ladder task returned, its scored curve, each method's speed-up
    #: (:mod:`translucent.reports.report.speedup`)
    path_tracing: Any = None
    curve: Any = None
    speedups: dict[str, dict] = field(default_factory=dict)
    #: per method, the objects it is scored on; where fewer than the scene's, its pixels
    #: and noise floor (:mod:`translucent.reports.report.scoring`), kept per set of objects
    scored_objects: dict[str, list[str]] = field(default_factory=dict)
    method_masks: dict[str, Any] = field(default_factory=dict)
    method_floors: dict[str, dict | None] = field(default_factory=dict)
    object_masks: dict[tuple, tuple] = field(default_factory=dict)
    object_curves: dict[tuple, Any] = field(default_factory=dict)
    #: per method, its runs at the cheap end of its quality ladder (:func:`ladder_knobs`),
    #: and their (frame seconds, relative MSE on its scored pixels)
    ladders: dict[str, list[MethodRun]] = field(default_factory=dict)
    ladder_points: dict[str, list[dict]] = field(default_factory=dict)
    #: per profile, the model reference (the BSSRDF path tracer's render of the scene with
    #: it), or why there is none, and where it came from (:mod:`.split`)
    model_references: dict[str, Image] = field(default_factory=dict)
    model_reference_errors: dict[str, str] = field(default_factory=dict)
    model_reference_info: dict[str, dict] = field(default_factory=dict)
    #: per scored entry, its error split into the profile's and its own
    splits: dict[str, Any] = field(default_factory=dict)

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


def keep_run(report: SceneReport, owner, run: MethodRun) -> None:
    """File a finished run under its method, or under its method's ladder."""
    if isinstance(owner, tuple) and owner[0] == LADDER:
        report.ladders.setdefault(owner[1], []).append(run)
    else:
        report.runs[owner] = run
