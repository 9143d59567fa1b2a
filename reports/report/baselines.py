"""Baselines: the stored results a run is checked against, read, judged and written.

A result is a regression when a gated metric (:data:`TOLERANCES`, from
:mod:`translucent.reports.metrics.registry`) is worse than its baseline entry beyond the
metric's tolerance, or when a baseline entry now has no result.
:func:`load_baseline` reads and validates a baseline file, :func:`check_against_baseline`
judges one result, :func:`updated_baseline` writes a run's results into it.
"""

from __future__ import annotations

import json
import math
import os
from dataclasses import dataclass, field
from pathlib import Path

from ...atomic import check_input_file
from ...errors import InputError
from ..metrics.registry import (
    METRIC_LABELS,
    REPORTED_METRICS,
    TOLERANCES,
    Tolerance,
    canonical_metric,
)
from .runs import json_safe, timestamp

__all__ = ["BASELINE_FORMAT", "DEFAULT_BASELINE", "METRIC_LABELS", "REPORTED_METRICS",
           "TOLERANCES", "BaselineCheck", "Tolerance", "check_against_baseline",
           "load_baseline", "updated_baseline"]

#: The committed baseline of the default scenes.
DEFAULT_BASELINE = Path(__file__).resolve().parents[1] / "baseline" / "default.json"

#: Bumped when the baseline layout changes.
BASELINE_FORMAT = 1


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
    if os.path.lexists(path) and not path.is_file():
        # a FIFO, a device, a link to nothing: said for what it is, before it is opened
        check_input_file(path, "--baseline", what="baseline file")
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
    for key in ("reference", "methods", "failures"):
        if not isinstance(entry.get(key, {}), dict):
            raise InputError("must be an object", file=path, field=f"{where}.{key}",
                             value=entry[key])
    for method_name, values in entry.get("methods", {}).items():
        if not isinstance(values, dict):
            raise InputError("must be an object of metric -> value", file=path,
                             field=f"{where}.methods.{method_name}", value=values)
        # a baseline written with an earlier spelling of a metric ("relmse") reads as today's
        for key in list(values):
            name = canonical_metric(key)
            if name is not None and name != key and name not in values:
                values[name] = values.pop(key)
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
    status : {"ok", "regression", "improved", "known failure", "no baseline", "not compared"}
        "regression" makes the report exit 1; "known failure": the method fails on the scene
        as it did when the baseline was made (the entry's ``failures``).
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
    known = None if entry is None else entry.get("failures", {}).get(method_name)
    if stored is None and known is not None and entry.get("scene_hash") == scene_hash:
        if metrics is None:
            return BaselineCheck("known failure", f"fails as when the baseline was made: "
                                 f"{failure or known}")
        return BaselineCheck("improved", "the baseline records a failure here; this run has "
                             "metrics (--update-baseline records them)")
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
    rebuilt from the methods that produced metrics; a method that failed is kept under
    ``failures`` with its reason (so the gate still sees the scene and method), one that no
    longer applies loses its entry.

    Parameters
    ----------
    baseline : dict
        From :func:`load_baseline`.
    results : list of dict
        Per scene: ``name``, ``scene_hash``, ``reference`` (spp, passes) and ``metrics``
        ({method: Metrics dict}) of the methods that ran, ``failures`` ({method: reason}) of
        those that failed, plus ``methods_run`` (the methods this run asked for).
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
        failures = {name: str(reason) for name, reason in result.get("failures", {}).items()
                    if name not in methods}
        entries[result["name"]] = {"scene_hash": result["scene_hash"],
                                   "reference": dict(result["reference"]),
                                   "methods": dict(sorted(methods.items()))}
        if failures:
            entries[result["name"]]["failures"] = dict(sorted(failures.items()))
    return {"format": BASELINE_FORMAT,
            "note": "image metrics of the fast methods against their references; written by "
                    "`translucent report --update-baseline`",
            "updated": timestamp(), "versions": versions,
            "tolerances": {name: {"absolute": t.absolute, "relative": t.relative,
                                  "lower_is_better": t.lower_is_better}
                           for name, t in TOLERANCES.items()},
            "entries": dict(sorted(entries.items()))}


