"""The metrics by name: what ``--metric`` picks, and the table ``compare`` prints.

Each :class:`MetricDefinition` computes one metric of :mod:`translucent.reports.metrics`
on a pair of images and says which way is better; :func:`metric_rows` lays a
:class:`~translucent.reports.metrics.Metrics` beside its noise floor and verdict.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Callable

from ..errors import InputError
from ..image import Image
from .metrics import (
    Metrics,
    check_image,
    ciede2000_map,
    flip_map,
    noise_verdict,
    psnr,
    relative_mse,
    rmse,
    ssim_map,
)

__all__ = ["METRICS", "MetricDefinition", "metric", "metric_rows"]


def _on_images(function: Callable) -> Callable[[Image, Image], float]:
    """Lift an array metric ``function(reference_rgb, test_rgb)`` to checked images."""
    def on_images(reference: Image, test: Image) -> float:
        for image, name in ((reference, "reference"), (test, "test")):
            check_image(image, name)
        return float(function(reference.rgb, test.rgb))
    return on_images


@dataclass(frozen=True)
class MetricDefinition:
    """One metric as users pick it by name: how to compute it and which way is better.

    Calling it with ``(reference, test)`` images computes only this metric.

    Parameters
    ----------
    name : str
        The name on the command line (``"hdr-flip"``).
    field : str
        The :class:`Metrics` attribute holding it.
    lower_is_better : bool
        True for errors (a threshold is a maximum), False for PSNR and SSIM (a minimum).
    description : str
        One line for tables and help.
    function : callable
        ``(reference: Image, test: Image) -> float``.
    """

    name: str
    field: str
    lower_is_better: bool
    description: str
    function: Callable[[Image, Image], float]

    def __call__(self, reference: Image, test: Image) -> float:
        """Compute the metric of ``test`` against ``reference``."""
        return self.function(reference, test)

    def within(self, value: float, threshold: float) -> bool:
        """Return whether ``value`` is on the good side of ``threshold`` (NaN never is)."""
        if math.isnan(value):
            return False
        return value <= threshold if self.lower_is_better else value >= threshold


def _relmse_on_images(reference: Image, test: Image) -> float:
    for image, name in ((reference, "reference"), (test, "test")):
        check_image(image, name)
    return relative_mse(reference.rgb, test.rgb, reference_variance=reference.variance)


_HDR_FLIP = MetricDefinition(
    "hdr-flip", "hdr_flip", True, "HDR-FLIP, mean over pixels (0 = identical)",
    _on_images(lambda r, t: flip_map(r, t, dynamic_range="HDR")[0]))

#: name -> definition; ``flip`` is HDR-FLIP (renders are HDR).
METRICS: dict[str, MetricDefinition] = {
    "flip": replace(_HDR_FLIP, name="flip"),
    "hdr-flip": _HDR_FLIP,
    "ldr-flip": MetricDefinition(
        "ldr-flip", "ldr_flip", True, "LDR-FLIP of the sRGB display images",
        _on_images(lambda r, t: flip_map(r, t, dynamic_range="LDR")[0])),
    "relmse": MetricDefinition(
        "relmse", "relative_mse", True, "relative MSE, reference noise discounted",
        _relmse_on_images),
    "rmse": MetricDefinition("rmse", "rmse", True, "root mean squared error (radiance)",
                             _on_images(rmse)),
    "psnr": MetricDefinition("psnr", "psnr", False, "PSNR in dB, peak = reference maximum",
                             _on_images(lambda r, t: psnr(r, t, data_range=float(r.max())))),
    "ssim": MetricDefinition("ssim", "ssim", False, "mean SSIM of the sRGB display images",
                             _on_images(lambda r, t: ssim_map(r, t)[0])),
    "ciede2000": MetricDefinition(
        "ciede2000", "ciede2000", True, "mean CIEDE2000 of the display images",
        _on_images(lambda r, t: ciede2000_map(r, t).mean())),
}


def metric(name: str) -> MetricDefinition:
    """Return the metric called ``name`` (case-insensitive).

    Parameters
    ----------
    name : str
        One of ``METRICS``: flip, hdr-flip, ldr-flip, relmse, rmse, psnr, ssim, ciede2000.

    Returns
    -------
    MetricDefinition
        Callable as ``definition(reference, test) -> float``.

    Raises
    ------
    InputError
        For an unknown name; the message lists the valid ones.
    """
    key = str(name).strip().lower()
    if key not in METRICS:
        raise InputError(f"unknown metric; valid: {', '.join(METRICS)}", field="metric",
                         value=name)
    return METRICS[key]


def metric_rows(metrics: Metrics, floor: Metrics | None = None, *,
                definition: MetricDefinition | None = None,
                threshold: float | None = None) -> list[dict]:
    """Return each metric of ``metrics`` beside its noise floor and verdict, as plain data.

    Parameters
    ----------
    metrics : Metrics
        The scores (:func:`compare`).
    floor : Metrics, optional
        The same metrics of the reference against its own noise (:func:`noise_floor`);
        None: no verdicts.
    definition, threshold : optional
        A metric and the bound it is held to: its row gains ``threshold`` and
        ``within_threshold``.

    Returns
    -------
    list of dict
        One per metric of :data:`METRICS` (``flip`` folded into ``hdr-flip``): ``metric``,
        ``value``, ``noise_floor``, ``verdict`` (:data:`RESOLVED`, :data:`WITHIN_NOISE` or
        None), ``lower_is_better``, ``about``.
    """
    values = metrics.as_dict()
    floors = floor.as_dict() if floor is not None else {}
    rows = []
    for name, entry in METRICS.items():
        if name == "flip":
            continue  # the same number as hdr-flip
        value = values[entry.field]
        noise = floors.get(entry.field)
        row = {"metric": name, "value": value, "noise_floor": noise,
               "verdict": noise_verdict(entry.field, value, noise),
               "lower_is_better": entry.lower_is_better, "about": entry.description}
        if threshold is not None and definition is not None and entry.field == definition.field:
            row["threshold"] = threshold
            row["within_threshold"] = bool(definition.within(value, threshold))
        rows.append(row)
    return rows
