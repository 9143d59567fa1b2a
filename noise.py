r"""How noisy a reference is: per-pixel relative standard error and its summary.

A reference image stores the mean of independent passes and the variance of that mean
(:class:`~translucent.image.Image`). Its noise is summarised the same way everywhere in the
suite (``translucent render``, ``translucent references``, the report):

* the relative standard error of a pixel is the mean over R, G, B of the standard error
  :math:`\sqrt{\mathrm{Var}[\bar L_c]}` divided by the mean over R, G, B of the radiance;
* it is summarised by its median and its 99th percentile over a set of pixels: the *lit*
  pixels (mean luminance above :data:`LIT_FRACTION` of the image's 99th-percentile
  luminance, so that shadows, whose relative error means little, do not count), optionally
  intersected with the pixels a method is scored on (an object mask).
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numpy as np

__all__ = ["LIT_FRACTION", "NOISE_WARNING_RSE", "NoiseSummary", "lit_mask", "noise_summary",
           "noise_warning", "reference_noise_warning", "relative_standard_error",
           "resolvable_error"]

#: A pixel is lit when its mean luminance exceeds this fraction of the image's
#: 99th-percentile luminance.
LIT_FRACTION = 0.02

#: ``render``, ``compare`` and the report warn about a reference whose median relative
#: standard error is above this.
NOISE_WARNING_RSE = 0.05


def lit_mask(rgb) -> np.ndarray:
    """Return the boolean ``H x W`` mask of lit pixels of a linear RGB image.

    The luminance here is the plain mean of R, G and B (as :func:`relative_standard_error`
    uses); a pixel is lit when it exceeds :data:`LIT_FRACTION` of the 99th percentile.
    """
    luminance = np.asarray(rgb, dtype=np.float64).mean(axis=-1)
    top = float(np.percentile(luminance, 99))
    return luminance > LIT_FRACTION * top if top > 0 else np.zeros(luminance.shape, bool)


def relative_standard_error(rgb, variance) -> np.ndarray:
    """Return the per-pixel relative standard error, ``H x W`` (inf where the mean is 0).

    Parameters
    ----------
    rgb : array_like, shape (H, W, 3)
        Mean radiance.
    variance : array_like, shape (H, W, 3)
        Variance of that mean in each channel (the squared standard error).
    """
    mean = np.asarray(rgb, dtype=np.float64).mean(axis=-1)
    error = np.sqrt(np.maximum(np.asarray(variance, dtype=np.float64), 0.0)).mean(axis=-1)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(mean > 0, error / np.where(mean > 0, mean, 1.0), np.inf)


@dataclass(frozen=True)
class NoiseSummary:
    """Median and 99th percentile of the relative standard error over a set of pixels.

    Attributes
    ----------
    median, p99 : float
        Dimensionless (0.01 is 1 %); NaN when no pixel was counted.
    pixels : int
        How many pixels were counted.
    mask : str
        Which pixels: ``"lit"`` or ``"lit & <what>"``.
    """

    median: float
    p99: float
    pixels: int
    mask: str = "lit"

    def meets(self, median: float, p99: float | None = None) -> bool:
        """Return True when the median (and the 99th percentile, if given) are at most these."""
        if not self.pixels:
            return False
        return self.median <= median and (p99 is None or self.p99 <= p99)

    def as_dict(self) -> dict:
        """Return the summary as a JSON-able dict (NaN as None)."""
        return {key: (None if isinstance(value, float) and not math.isfinite(value) else value)
                for key, value in asdict(self).items()}

    def text(self) -> str:
        """Return ``"median 0.8 %, 99th percentile 3.1 % over 3558 lit pixels"``."""
        if not self.pixels:
            return f"no {self.mask} pixels"
        return (f"median {100 * self.median:.3g} %, 99th percentile {100 * self.p99:.3g} % "
                f"over {self.pixels} {self.mask} pixels")


def noise_summary(rgb, variance, mask=None, *, mask_name: str = "scored") -> NoiseSummary:
    """Summarise a reference's relative standard error over its lit pixels.

    Parameters
    ----------
    rgb, variance : array_like, shape (H, W, 3)
        As :func:`relative_standard_error`.
    mask : array_like of bool, shape (H, W), optional
        Count only these pixels as well (the pixels a method is scored on).
    mask_name : str
        How the summary calls ``mask``.

    Returns
    -------
    NoiseSummary

    Examples
    --------
    >>> import numpy as np
    >>> rgb = np.ones((4, 4, 3)); variance = np.full((4, 4, 3), 1e-4)
    >>> noise_summary(rgb, variance).median
    0.01
    """
    counted = lit_mask(rgb)
    name = "lit"
    if mask is not None:
        counted = counted & np.asarray(mask, dtype=bool)
        name = f"lit & {mask_name}"
    rse = relative_standard_error(rgb, variance)[counted]
    if rse.size == 0:
        return NoiseSummary(math.nan, math.nan, 0, name)
    return NoiseSummary(float(np.median(rse)), float(np.percentile(rse, 99)), int(rse.size),
                        name)


def resolvable_error(summary: NoiseSummary) -> float:
    """Return the smallest relative error a reference of this noise can resolve (~2 x median).

    Two standard errors: a method whose pixels differ from the reference by less than this
    cannot be told apart from one that matches the truth.
    """
    return 2.0 * summary.median


def noise_warning(summary: NoiseSummary) -> str | None:
    """Return the warning for a reference too noisy to judge small errors by, else None.

    Parameters
    ----------
    summary : NoiseSummary
        The reference's noise (:func:`noise_summary`).

    Returns
    -------
    str or None
        ``"the reference is noisy: ..."`` when the median exceeds
        :data:`NOISE_WARNING_RSE`, naming the figure and the smallest relative error it
        resolves (:func:`resolvable_error`).
    """
    if not summary.pixels or summary.median <= NOISE_WARNING_RSE:
        return None
    return (f"the reference is noisy: {summary.text()} (relative standard error); relative "
            f"errors below about {100 * resolvable_error(summary):.2g} % cannot be resolved "
            "against it; render more passes (translucent render --target-rse)")


def reference_noise_warning(rgb, variance) -> str | None:
    """Return :func:`noise_warning` of a reference over its lit pixels (None without variance)."""
    if variance is None:
        return None
    return noise_warning(noise_summary(rgb, variance))
