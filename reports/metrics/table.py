"""The metrics by name: what ``--metric`` picks, and the table ``compare`` prints.

Each :class:`MetricDefinition` computes one metric of :mod:`translucent.reports.metrics`
on a pair of images and says which way is better; :func:`metric_rows` lays a
:class:`~translucent.reports.metrics.Metrics` beside its noise floor and verdict.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable

from ...image import Image
from .compute import (
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
from .registry import REGISTRY, MetricSpec, metric_spec

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
    """One metric as users pick it by name: its :class:`MetricSpec` and how to compute it.

    Calling it with ``(reference, test)`` images computes only this metric.

    Parameters
    ----------
    spec : MetricSpec
        Name, label, unit, direction and tolerance (:mod:`.metric_registry`).
    function : callable
        ``(reference: Image, test: Image) -> float``.
    """

    spec: MetricSpec
    function: Callable[[Image, Image], float]

    @property
    def name(self) -> str:
        """The metric's name: its :class:`Metrics` field and JSON key."""
        return self.spec.name

    @property
    def field(self) -> str:
        """The :class:`Metrics` attribute holding it (its name)."""
        return self.spec.name

    @property
    def lower_is_better(self) -> bool:
        """True for errors (a threshold is a maximum), False for PSNR and SSIM."""
        return self.spec.lower_is_better

    @property
    def description(self) -> str:
        """One line for tables and help."""
        return self.spec.description

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


def _relmse_raw_on_images(reference: Image, test: Image) -> float:
    for image, name in ((reference, "reference"), (test, "test")):
        check_image(image, name)
    return relative_mse(reference.rgb, test.rgb)


#: How each metric of the registry is computed on a pair of images.
_FUNCTIONS: dict[str, Callable[[Image, Image], float]] = {
    "hdr_flip": _on_images(lambda r, t: flip_map(r, t, dynamic_range="HDR")[0]),
    "ldr_flip": _on_images(lambda r, t: flip_map(r, t, dynamic_range="LDR")[0]),
    "relative_mse": _relmse_on_images,
    "relative_mse_raw": _relmse_raw_on_images,
    "rmse": _on_images(rmse),
    "psnr": _on_images(lambda r, t: psnr(r, t, data_range=float(r.max()))),
    "ssim": _on_images(lambda r, t: ssim_map(r, t)[0]),
    "ciede2000": _on_images(lambda r, t: ciede2000_map(r, t).mean()),
}

#: name -> definition, one per metric of :data:`~.metric_registry.REGISTRY`; :func:`metric`
#: also takes the earlier spellings (``flip`` and ``hdr-flip`` are HDR-FLIP: renders are HDR).
METRICS: dict[str, MetricDefinition] = {spec.name: MetricDefinition(spec, _FUNCTIONS[spec.name])
                                        for spec in REGISTRY}


def metric(name: str) -> MetricDefinition:
    """Return the metric called ``name`` or one of its aliases (case-insensitive).

    Parameters
    ----------
    name : str
        One of ``METRICS`` (hdr_flip, ldr_flip, relative_mse, relative_mse_raw, rmse, psnr,
        ssim, ciede2000), or an earlier spelling (flip, hdr-flip, relmse, ...).

    Returns
    -------
    MetricDefinition
        Callable as ``definition(reference, test) -> float``.

    Raises
    ------
    InputError
        For an unknown name; the message lists the valid ones.
    """
    return METRICS[metric_spec(name).name]


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
        One per metric of :data:`METRICS`: ``metric``,
        ``value``, ``noise_floor``, ``verdict`` (:data:`RESOLVED`, :data:`WITHIN_NOISE` or
        None), ``lower_is_better``, ``about``.
    """
    values = metrics.as_dict()
    floors = floor.as_dict() if floor is not None else {}
    rows = []
    for name, entry in METRICS.items():
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
