"""``metrics.json``: every number of the report, for tools.

Per scene: the reference (its settings, noise and noise floor), the path-tracing curve,
and per method the run (status, knobs, times), its metrics over its scored pixels and the
whole image, each gated metric's value, floor and verdict (:func:`metric_verdict`), the
baseline check, the speed-up, the ladder and, where the split exists
(:mod:`translucent.reports.report.split`), the ``model_error`` and
``approximation_error`` blocks (``metrics`` and ``noise`` as the method's own) with the
profile, the part that dominates and why.
"""

from __future__ import annotations

from .baselines import TOLERANCES
from .model import SceneReport
from .runs import json_safe
from .summary import speedup_fields

__all__ = ["METRIC_VERDICTS", "made_with", "metric_verdict", "metrics_json"]


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
    >>> from translucent.reports.report.baselines import BaselineCheck
    >>> check = BaselineCheck("regression", "worse", {"hdr_flip": {"verdict": "worse"}})
    >>> metric_verdict("resolved", check, "hdr_flip"), metric_verdict("resolved", check, "ssim")
    ('regression', 'no baseline')
    >>> metric_verdict("within reference noise", check, "hdr_flip")
    'within reference noise'
    """
    from ..metrics.compute import WITHIN_NOISE

    if noise_verdict == WITHIN_NOISE:
        return WITHIN_NOISE
    gated = (check.metrics.get(key) if check is not None else None) or {}
    if not gated:
        return "no baseline"
    return "regression" if gated.get("verdict") == "worse" else "ok"


def made_with(report: SceneReport) -> dict:
    """Return the reference's spp and passes (what a baseline entry records it was made with)."""
    meta = report.reference.metadata if report.reference is not None else {}
    return {"spp": meta.get("spp", report.spp), "passes": meta.get("passes")}


def metrics_json(reports: list[SceneReport], chosen: list[str], context: dict) -> dict:
    """Return the report's ``metrics.json`` as a dict (strict JSON once dumped)."""
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
            entry["systematic"] = json_safe(report.systematic.get(name))
            entry["ladder"] = json_safe(report.ladder_points.get(name, []))
            entry["files"] = report.files.get(name, {})
            entry["baseline"] = check.as_dict() if check else None
            entry.update(speedup_fields(report, name))
            entry.update(_split_blocks(report, name))
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


def _split_blocks(report: SceneReport, name: str) -> dict:
    """Return the entry's ``model_error``, ``approximation_error`` and ``error_split`` (or None)."""
    split = report.splits.get(name)
    if split is None:
        return {"model_error": None, "approximation_error": None, "error_split": None}
    blocks = split.as_dict()
    return {"model_error": blocks.pop("model_error"),
            "approximation_error": blocks.pop("approximation_error"), "error_split": blocks}
