"""Every metric of the suite, defined once: its name, label, unit, direction, tolerance, floor.

One :class:`MetricSpec` per metric. Everything else is derived from :data:`REGISTRY`: the
metrics that get a noise floor (:data:`NOISE_FLOOR_FIELDS`), the ones stored and shown
(:data:`REPORTED_METRICS`), their labels (:data:`METRIC_LABELS`), the gated ones and their
tolerances (:data:`TOLERANCES`), and the names ``--metric`` takes
(:mod:`translucent.reports.metrics.table`). A metric's name is its
:class:`~translucent.reports.metrics.Metrics` field and its JSON key; the spellings of
earlier versions (``relmse``, ``hdr-flip``, ``flip``) are read as aliases
(:func:`canonical_metric`), so old baselines and command lines still work.

Examples
--------
>>> canonical_metric("relmse"), METRIC_LABELS["relative_mse"]
('relative_mse', 'relMSE')
>>> sorted(TOLERANCES)
['ciede2000', 'hdr_flip', 'relative_mse', 'ssim']
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from ...errors import InputError

__all__ = ["METRIC_LABELS", "NOISE_FLOOR_FIELDS", "REGISTRY", "REPORTED_METRICS", "TOLERANCES",
           "MetricSpec", "Tolerance", "canonical_metric", "metric_spec"]


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


@dataclass(frozen=True)
class MetricSpec:
    """One metric: what it is called, shown as and measured in, and how it is judged.

    Parameters
    ----------
    name : str
        The :class:`~translucent.reports.metrics.Metrics` field, the JSON key and the name
        ``--metric`` takes.
    label : str
        How pages and tables show it.
    unit : str
        Its unit ("" for dimensionless ones).
    lower_is_better : bool
        True for errors (a threshold is a maximum), False for PSNR and SSIM.
    description : str
        One line for tables and help.
    tolerance : Tolerance or None
        Gated in the regression check with this tolerance; None: reported, not gated.
    noise_floor : bool
        Whether it gets a noise floor and a verdict (:func:`~.metrics.noise_floor`).
    aliases : tuple of str
        Other spellings accepted on input (earlier command-line names).
    """

    name: str
    label: str
    unit: str
    lower_is_better: bool
    description: str
    tolerance: Tolerance | None = None
    noise_floor: bool = True
    aliases: tuple[str, ...] = ()


#: Every metric, in the order tables show them. The tolerances are about twice the largest
#: change that rendering the references again alone caused, so that a regression exceeds what
#: a new reference could cause (the figures: docs/report.md, "Regression tolerances").
REGISTRY: tuple[MetricSpec, ...] = (
    MetricSpec("hdr_flip", "HDR-FLIP", "", True, "HDR-FLIP, mean over pixels (0 = identical)",
               Tolerance("hdr_flip", absolute=0.005, relative=0.03),
               aliases=("hdr-flip", "flip")),
    MetricSpec("ldr_flip", "LDR-FLIP", "", True, "LDR-FLIP of the sRGB display images",
               aliases=("ldr-flip",)),
    MetricSpec("relative_mse", "relMSE", "", True, "relative MSE, reference noise discounted",
               Tolerance("relative_mse", absolute=0.001, relative=0.30),
               aliases=("relmse", "relative-mse")),
    MetricSpec("relative_mse_raw", "relMSE (raw)", "", True,
               "relative MSE, reference noise not discounted",
               aliases=("relmse-raw", "relative-mse-raw")),
    MetricSpec("rmse", "RMSE", "radiance", True, "root mean squared error (radiance)"),
    MetricSpec("psnr", "PSNR (dB)", "dB", False, "PSNR in dB, peak = reference maximum"),
    MetricSpec("ssim", "SSIM", "", False, "mean SSIM of the sRGB display images",
               Tolerance("ssim", absolute=0.03, relative=0.0, lower_is_better=False)),
    MetricSpec("ciede2000", "CIEDE2000", "", True, "mean CIEDE2000 of the display images",
               Tolerance("ciede2000", absolute=0.1, relative=0.15)),
)

_BY_NAME = {spec.name: spec for spec in REGISTRY}
_ALIASES = {alias: spec.name for spec in REGISTRY for alias in spec.aliases}

#: The metrics that get a noise floor and a verdict.
NOISE_FLOOR_FIELDS = tuple(spec.name for spec in REGISTRY if spec.noise_floor)

#: The metrics stored and shown for every run.
REPORTED_METRICS = tuple(spec.name for spec in REGISTRY)

#: How pages show each metric.
METRIC_LABELS = {spec.name: spec.label for spec in REGISTRY}

#: The gated metrics and their tolerances.
TOLERANCES: dict[str, Tolerance] = {spec.name: spec.tolerance for spec in REGISTRY
                                    if spec.tolerance is not None}

#: The tolerances by name, for those who read them one at a time.
HDR_FLIP_TOLERANCE = TOLERANCES["hdr_flip"]
RELATIVE_MSE_TOLERANCE = TOLERANCES["relative_mse"]
CIEDE2000_TOLERANCE = TOLERANCES["ciede2000"]
SSIM_TOLERANCE = TOLERANCES["ssim"]


def canonical_metric(name) -> str | None:
    """Return the metric's name for ``name`` or one of its aliases (case-insensitive); None."""
    key = str(name).strip().lower()
    return key if key in _BY_NAME else _ALIASES.get(key)


def metric_spec(name) -> MetricSpec:
    """Return the :class:`MetricSpec` of ``name`` (or an alias).

    Raises
    ------
    InputError
        An unknown name; the message lists the valid ones.
    """
    found = canonical_metric(name)
    if found is None:
        raise InputError(f"unknown metric; valid: {', '.join(_BY_NAME)}", field="metric",
                         value=name)
    return _BY_NAME[found]
