r"""Image metrics: how far a test image is from a reference image.

``compare(reference, test) -> Metrics`` computes every metric the suite reports; the
functions below it compute one metric each on plain arrays (reference first, test second,
as :mod:`skimage.metrics` does; every other argument keyword-only). ``metric(name)``
picks one by the name the command line and the pytest plugin use.

Two families of metric:

* **Radiometric** metrics work on the linear radiance as it is: relative MSE (with the
  reference's own Monte Carlo noise discounted), RMSE, PSNR. They broadcast over any
  leading axes (``... x 3``) and return NaN, not an exception, where a pixel is NaN.
* **Perceptual** metrics judge what a person sees: HDR-FLIP on the linear image
  (Andersson et al. 2021, which chooses its own exposures), and LDR-FLIP, SSIM and
  CIEDE2000 on the *display image*: the radiance divided by the reference's display
  white (:func:`display_white`), clipped to [0, 1] and sRGB-encoded
  (:func:`to_display`). Both images go through the same exposure, so a brightness
  error stays visible. Negative radiance (which a truncated basis expansion can
  produce) shows as black. They need an ``H x W x 3`` image.

References
----------
- J. Andersson, P. Andersson, J. Nilsson, T. Akenine-Möller, M. D. Fairchild, K. Åström:
  FLIP: a difference evaluator for alternating images. Proc. ACM Comput. Graph.
  Interact. Tech. 3(2), 2020; HDR-FLIP: Visualizing errors in rendered high dynamic
  range images. Eurographics short papers, 2021 (``flip-evaluator`` on PyPI).
- Z. Wang, A. C. Bovik, H. R. Sheikh, E. P. Simoncelli: Image quality assessment: from
  error visibility to structural similarity. IEEE TIP 13(4), 2004.
- G. Sharma, W. Wu, E. N. Dalal: The CIEDE2000 color-difference formula. Color Research
  & Application 30(1), 2005 (``colour.delta_E(..., method="CIE 2000")``).
- IEC 61966-2-1:1999, the sRGB transfer function and primaries.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field

import numpy as np

from ...errors import InputError
from ...image import LUMINANCE_WEIGHTS, Image

__all__ = [
    "Metrics",
    "Comparison",
    "NOISE_FLOOR_DRAWS",
    "NOISE_MARGIN",
    "RESOLVED",
    "WITHIN_NOISE",
    "check_image",
    "compare",
    "error_scale",
    "noise_floor",
    "noise_floors",
    "noise_verdict",
    "noise_verdicts",
    "evaluate",
    "evaluate_on",
    "relative_mse",
    "relative_error_map",
    "rmse",
    "psnr",
    "ssim_map",
    "flip_map",
    "ciede2000_map",
    "luminance",
    "display_white",
    "to_display",
    "srgb_encode",
]

#: Added to ``reference**2`` in the relative MSE denominator (radiance units squared), so
#: that pixels darker than about sqrt(1e-2) = 0.1 are judged by their absolute rather than
#: relative error and a black pixel cannot make the mean infinite.
RELMSE_EPSILON = 1e-2

#: Percentile of the reference's luminance mapped to display white: a robust peak that a
#: few fireflies of a path-traced reference cannot push up.
WHITE_PERCENTILE = 99.0

#: SSIM settings of Wang et al. 2004 (section III.C): an 11 x 11 circular-symmetric
#: Gaussian window of standard deviation 1.5 pixels and population (not sample)
#: covariances. With these, scikit-image reproduces the authors' MATLAB numbers.
SSIM_SIGMA = 1.5
SSIM_WINDOW = 11

#: FLIP's default observer: 0.7 m from a 0.7 m wide 3840-pixel monitor (67 pixels per
#: degree), as in Andersson et al. 2020.
FLIP_PIXELS_PER_DEGREE = 67.0


# --------------------------------------------------------------------------- display


def luminance(rgb) -> np.ndarray:
    """Return the luminance Y of linear sRGB/Rec. 709 values.

    Parameters
    ----------
    rgb : array_like, shape (..., 3)
        Linear RGB.

    Returns
    -------
    ndarray, shape (...)
        ``0.2126 R + 0.7152 G + 0.0722 B`` (IEC 61966-2-1), in the units of ``rgb``.
    """
    return np.asarray(rgb, dtype=np.float64) @ LUMINANCE_WEIGHTS


def display_white(reference) -> float:
    """Return the linear radiance shown as display white for a reference image.

    The ``WHITE_PERCENTILE`` (99th) percentile of the reference's luminance; its maximum
    where that percentile is zero (a mostly black image); 1 for an all-black image.

    Parameters
    ----------
    reference : array_like, shape (..., 3)
        Linear RGB of the reference.

    Returns
    -------
    float
        Radiance (units of ``reference``) that maps to display value 1.
    """
    y = luminance(reference)
    y = y[np.isfinite(y)]
    if y.size == 0:
        return 1.0
    white = float(np.percentile(y, WHITE_PERCENTILE))
    if white <= 0:
        white = float(y.max())
    return white if white > 0 else 1.0


def srgb_encode(linear) -> np.ndarray:
    """Apply the sRGB transfer function (IEC 61966-2-1) to linear values in [0, 1].

    Parameters
    ----------
    linear : array_like
        Display-linear values; clipped to [0, 1] first.

    Returns
    -------
    ndarray
        Encoded values in [0, 1]: ``12.92 x`` below 0.0031308, ``1.055 x^(1/2.4) - 0.055``
        above.
    """
    x = np.clip(np.asarray(linear, dtype=np.float64), 0.0, 1.0)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1 / 2.4) - 0.055)


def to_display(rgb, white: float, *, encode: bool = True) -> np.ndarray:
    """Exposure-normalise linear radiance for an sRGB display.

    Parameters
    ----------
    rgb : array_like, shape (..., 3)
        Linear radiance.
    white : float
        Radiance shown as display white (see :func:`display_white`); > 0.
    encode : bool
        sRGB-encode the result (True, what a PNG holds) or return display-linear values.

    Returns
    -------
    ndarray
        ``clip(rgb / white, 0, 1)``, sRGB-encoded when ``encode``; NaN stays NaN.
    """
    if not (np.isfinite(white) and white > 0):
        raise InputError("display white must be a finite radiance > 0", field="white",
                         value=white)
    linear = np.clip(np.asarray(rgb, dtype=np.float64) / white, 0.0, 1.0)
    return srgb_encode(linear) if encode else linear


# --------------------------------------------------------------------------- checks


def _pair(reference, test, *, image: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """Check a pair with the one shape check every metric shares; return float64 arrays."""
    reference = np.asarray(reference, dtype=np.float64)
    test = np.asarray(test, dtype=np.float64)
    if reference.shape != test.shape:
        raise InputError(f"reference and test must have the same shape; reference is "
                         f"{reference.shape}, test is {test.shape}", field="shape",
                         value=(reference.shape, test.shape))
    if reference.ndim < 1 or reference.shape[-1] != 3:
        raise InputError("the last axis must hold the 3 channels R, G, B", field="shape",
                         value=reference.shape)
    if image:
        if reference.ndim != 3:
            raise InputError("this metric needs an H x W x 3 image", field="shape",
                             value=reference.shape)
        if min(reference.shape[:2]) < SSIM_WINDOW:
            raise InputError(f"images must be at least {SSIM_WINDOW} x {SSIM_WINDOW} pixels "
                             f"(SSIM's Gaussian window, Wang et al. 2004)", field="shape",
                             value=reference.shape)
        for name, array in (("reference", reference), ("test", test)):
            if not np.all(np.isfinite(array)):
                raise InputError(f"{int((~np.isfinite(array)).sum())} pixel channels are NaN "
                                 "or Inf; perceptual metrics need finite pixels", field=name,
                                 value="non-finite")
    return reference, test


# --------------------------------------------------------------------------- radiometric


def relative_mse(reference, test, *, reference_variance=None,
                 epsilon: float = RELMSE_EPSILON) -> float:
    r"""Return the relative mean squared error, discounting the reference's own noise.

    .. math::

        \mathrm{relMSE} = \frac{1}{N} \sum_i
            \frac{(t_i - r_i)^2 - \sigma_{r,i}^2}{r_i^2 + \epsilon}

    over all N pixel channels, where :math:`\sigma_{r,i}^2` is the variance of the
    reference's estimate of its mean (``Image.variance``, the squared standard error
    of independent passes). For an unbiased reference :math:`r = \mu + n` with
    :math:`E[n^2] = \sigma_r^2`, :math:`E[(t - r)^2] = (t - \mu)^2 + \sigma_r^2`:
    subtracting :math:`\sigma_r^2` makes each numerator an unbiased estimate of the
    squared error against the *converged* image. The denominator still carries the
    reference's noise; to second order its bias is about :math:`6 \sigma_r^4 / r^4`
    (1e-6 for a 2 % standard error). The result can be slightly negative when the test is closer to
    the truth than the reference's noise resolves.

    Parameters
    ----------
    reference, test : array_like, shape (..., 3)
        Linear radiance; any leading axes broadcast together (same shape).
    reference_variance : array_like, shape (..., 3), optional
        Variance of each reference pixel channel's mean (radiance units squared). None:
        no discounting (the raw relative MSE).
    epsilon : float
        Added to :math:`r^2` (radiance units squared); ``RELMSE_EPSILON`` = 1e-2.

    Returns
    -------
    float
        Dimensionless; NaN where any pixel is NaN.
    """
    reference, test = _pair(reference, test)
    numerator = (test - reference) ** 2
    if reference_variance is not None:
        variance = np.asarray(reference_variance, dtype=np.float64)
        if variance.shape != reference.shape:
            raise InputError(f"must have the reference's shape {reference.shape}",
                             field="reference_variance", value=variance.shape)
        numerator = numerator - variance
    return float(np.mean(numerator / (reference**2 + epsilon)))


def relative_error_map(reference, test, *, epsilon: float = RELMSE_EPSILON) -> np.ndarray:
    r"""Return the per-pixel relative RMS error over the channels.

    :math:`e = \sqrt{\frac{1}{3}\sum_c (t_c - r_c)^2 / (r_c^2 + \epsilon)}`: a fraction
    (0.1 is 10 % off). The mean of its square is the raw relative MSE
    (:func:`relative_mse` without discounting).

    Parameters
    ----------
    reference, test : array_like, shape (..., 3)
        Linear radiance.
    epsilon : float
        As in :func:`relative_mse` (radiance units squared).

    Returns
    -------
    ndarray, shape (...)
        Dimensionless.
    """
    reference, test = _pair(reference, test)
    return np.sqrt(np.mean((test - reference) ** 2 / (reference**2 + epsilon), axis=-1))


def rmse(reference, test) -> float:
    """Return the root mean squared error over all pixel channels.

    Parameters
    ----------
    reference, test : array_like, shape (..., 3)
        Linear radiance.

    Returns
    -------
    float
        In the radiance units of the images; NaN where a pixel is NaN.
    """
    reference, test = _pair(reference, test)
    return float(np.sqrt(np.mean((test - reference) ** 2)))


def psnr(reference, test, *, data_range: float) -> float:
    r"""Return the peak signal-to-noise ratio :math:`10 \log_{10}(R^2 / \mathrm{MSE})`.

    HDR radiance has no natural peak, so ``data_range`` R is required (as in
    :func:`skimage.metrics.peak_signal_noise_ratio`); :func:`compare` passes the
    reference's maximum.

    Parameters
    ----------
    reference, test : array_like, shape (..., 3)
        Linear radiance.
    data_range : float
        The peak R, in radiance units; > 0.

    Returns
    -------
    float
        Decibels; ``inf`` for identical images, NaN where a pixel is NaN.
    """
    if not (math.isfinite(data_range) and data_range > 0):
        raise InputError("must be a finite radiance > 0", field="data_range",
                         value=data_range)
    reference, test = _pair(reference, test)
    mse = float(np.mean((test - reference) ** 2))
    if mse == 0:
        return math.inf
    return 10.0 * math.log10(data_range**2 / mse)


# --------------------------------------------------------------------------- perceptual


def ssim_map(reference, test, *, white: float | None = None) -> tuple[float, np.ndarray]:
    """Return SSIM (Wang et al. 2004, Eq. 13 and its mean, Eq. 17) on the display images.

    Computed per channel of the sRGB-encoded display images (``data_range`` 1,
    ``SSIM_WINDOW`` Gaussian window of ``SSIM_SIGMA``), with
    :func:`skimage.metrics.structural_similarity`.

    Parameters
    ----------
    reference, test : array_like, shape (H, W, 3)
        Linear radiance, H and W at least 11.
    white : float, optional
        Display white (radiance); default :func:`display_white` of the reference.

    Returns
    -------
    mean_ssim : float
        scikit-image's mean SSIM over the channels (the border of 5 pixels, where the
        window does not fit, excluded): 1 for identical images, in [-1, 1].
    ssim : ndarray, shape (H, W)
        The SSIM map averaged over the channels.
    """
    from skimage.metrics import structural_similarity

    reference, test = _pair(reference, test, image=True)
    white = display_white(reference) if white is None else white
    mean_ssim, full = structural_similarity(
        to_display(reference, white), to_display(test, white), data_range=1.0,
        channel_axis=-1, gaussian_weights=True, sigma=SSIM_SIGMA,
        use_sample_covariance=False, full=True)
    return float(mean_ssim), full.mean(axis=-1)


def flip_map(reference, test, *, dynamic_range: str = "HDR",
             white: float | None = None) -> tuple[float, np.ndarray]:
    """Return the FLIP error (Andersson et al. 2020, 2021) and its per-pixel map.

    ``"HDR"``: HDR-FLIP on the linear radiance (negative values clipped to 0); FLIP picks
    its exposure range from the reference (Andersson et al. 2021, Eq. 3) and takes the
    per-pixel maximum over the exposures. ``"LDR"``: FLIP on the sRGB-encoded display
    images. Calls ``flip_evaluator.evaluate(reference, test, dynamic_range)`` at
    ``FLIP_PIXELS_PER_DEGREE``.

    Parameters
    ----------
    reference, test : array_like, shape (H, W, 3)
        Linear radiance.
    dynamic_range : {"HDR", "LDR"}
        Which FLIP.
    white : float, optional
        Display white for LDR-FLIP (radiance); default :func:`display_white`.

    Returns
    -------
    mean_flip : float
        Mean of the map: 0 for identical images, at most 1.
    flip : ndarray, shape (H, W), float32
        Per-pixel FLIP error in [0, 1].
    """
    import flip_evaluator

    reference, test = _pair(reference, test, image=True)
    dynamic_range = dynamic_range.upper()
    if dynamic_range == "HDR":
        reference = np.maximum(reference, 0.0)
        test = np.maximum(test, 0.0)
        if not (reference > 0).any():
            # flip-evaluator ends the process when it cannot choose exposures
            raise InputError("HDR-FLIP needs a reference with some light; it is all black",
                             field="reference", value="black")
    elif dynamic_range == "LDR":
        white = display_white(reference) if white is None else white
        reference, test = to_display(reference, white), to_display(test, white)
    else:
        raise InputError("must be 'HDR' or 'LDR'", field="dynamic_range", value=dynamic_range)
    errors, mean_flip, _ = flip_evaluator.evaluate(
        np.ascontiguousarray(reference, dtype=np.float32),
        np.ascontiguousarray(test, dtype=np.float32), dynamic_range, applyMagma=False,
        parameters={"ppd": FLIP_PIXELS_PER_DEGREE})
    return float(mean_flip), np.asarray(errors, dtype=np.float32).reshape(reference.shape[:2])


def _colour():
    """Import colour-science without its change to how numpy prints arrays.

    colour sets numpy's print options to the legacy 1.13 style when it is imported, which
    would change every array a user's program prints after its first CIEDE2000.
    """
    options = np.get_printoptions()
    import colour

    np.set_printoptions(**options)
    return colour


def ciede2000_map(reference, test, *, white: float | None = None) -> np.ndarray:
    """Return the per-pixel CIEDE2000 colour difference of the display images.

    Each image is exposure-normalised by the same display white and clipped to [0, 1]
    (the display-linear version of what :func:`to_display` encodes), converted from
    linear sRGB to CIE XYZ and to CIE L*a*b* under D65 with colour-science, and compared
    with ``colour.delta_E(..., method="CIE 2000")`` (Sharma et al. 2005, Eqs. 1-22).

    Parameters
    ----------
    reference, test : array_like, shape (..., 3)
        Linear radiance; leading axes broadcast.
    white : float, optional
        Display white (radiance); default :func:`display_white` of the reference.

    Returns
    -------
    ndarray, shape (...)
        Delta E 2000 (about 1 is just noticeable; L* spans 0-100); NaN where a pixel is NaN.
    """
    colour = _colour()
    reference, test = _pair(reference, test)
    white = display_white(reference) if white is None else white
    srgb = colour.RGB_COLOURSPACES["sRGB"]
    lab = [colour.XYZ_to_Lab(colour.RGB_to_XYZ(to_display(x, white, encode=False), srgb),
                             srgb.whitepoint) for x in (reference, test)]
    return np.asarray(colour.delta_E(lab[0], lab[1], method="CIE 2000"), dtype=np.float64)


# --------------------------------------------------------------------------- compare


@dataclass(frozen=True)
class Metrics:
    """Every metric of a test image against a reference (see :func:`compare`).

    Parameters
    ----------
    relative_mse : float
        Relative MSE with the reference's noise discounted (:func:`relative_mse`); equal
        to ``relative_mse_raw`` when the reference has no variance.
    relative_mse_raw : float
        Relative MSE without discounting.
    rmse : float
        Root mean squared error (radiance units).
    psnr : float
        PSNR in dB with the reference's maximum as peak (``data_range``).
    ssim : float
        Mean SSIM of the display images (1 is identical).
    hdr_flip, ldr_flip : float
        Mean HDR-FLIP and LDR-FLIP (0 is identical).
    ciede2000 : float
        Mean CIEDE2000 of the display images.
    data_range : float
        PSNR's peak (radiance).
    display_white : float
        Radiance shown as white in the perceptual metrics.
    noise_discounted : bool
        Whether the reference carried a variance to discount.
    pixels_scored : int
        How many pixels the metrics average over (all, or those of a mask).
    """

    relative_mse: float
    relative_mse_raw: float
    rmse: float
    psnr: float
    ssim: float
    hdr_flip: float
    ldr_flip: float
    ciede2000: float
    data_range: float
    display_white: float
    noise_discounted: bool
    pixels_scored: int = 0

    def as_dict(self) -> dict:
        """Return the metrics as a plain ``{name: value}`` dict (floats and a bool)."""
        return asdict(self)


@dataclass(frozen=True)
class Comparison:
    """Metrics and the per-pixel error maps they summarise (see :func:`evaluate`).

    Parameters
    ----------
    metrics : Metrics
        The numbers.
    maps : dict of str to ndarray, shape (H, W)
        ``"flip"`` (HDR-FLIP), ``"relative_error"`` (:func:`relative_error_map`),
        ``"ciede2000"``, ``"ssim"``.
    """

    metrics: Metrics
    maps: dict[str, np.ndarray] = field(default_factory=dict)


def check_image(image, name: str) -> None:
    """Refuse a non-Image, NaN/Inf pixels, or a negative or non-finite variance (``name``)."""
    if not isinstance(image, Image):
        raise TypeError(f"{name} must be a translucent.image.Image, not {type(image).__name__}")
    bad = ~np.isfinite(image.rgb)
    if bad.any():
        y, x, c = np.argwhere(bad)[0]
        raise InputError(f"{int(bad.sum())} pixel channels are NaN or Inf (first at x={x}, "
                         f"y={y}, channel {'RGB'[c]})", field=f"{name}.rgb",
                         value=float(image.rgb[y, x, c]))
    if image.variance is not None and not (np.all(np.isfinite(image.variance))
                                           and (image.variance >= 0).all()):
        raise InputError("variance must be finite and >= 0", field=f"{name}.variance",
                         value=float(np.nanmin(image.variance)))


def _check_mask(mask, shape) -> np.ndarray | None:
    if mask is None:
        return None
    mask = np.asarray(mask)
    if mask.shape != tuple(shape) or mask.dtype != bool:
        raise InputError(f"must be a boolean H x W image of the reference's size {shape}",
                         field="mask", value=(mask.shape, str(mask.dtype)))
    if not mask.any():
        raise InputError("selects no pixel: nothing to score", field="mask", value=0)
    return mask


def evaluate(reference: Image, test: Image, *, epsilon: float = RELMSE_EPSILON,
             mask=None) -> Comparison:
    """Compute every metric and the error maps of ``test`` against ``reference``.

    See :func:`compare` for the metrics; the maps are those :class:`Comparison` lists.
    With ``mask`` (boolean ``H x W``) every metric averages over the pixels it selects
    (the maps are still computed on the whole image, SSIM and FLIP with their
    neighbourhoods); PSNR's peak and the display white stay those of the whole
    reference, so that masked and whole-image scores share one exposure.
    """
    return evaluate_on(reference, test, [mask], epsilon=epsilon)[0]


def evaluate_on(reference: Image, test: Image, masks, *,
                epsilon: float = RELMSE_EPSILON) -> list[Comparison]:
    """:func:`evaluate` over several pixel sets, the error maps computed once.

    Parameters
    ----------
    reference, test : Image
    masks : sequence of (ndarray of bool, shape (H, W)) or None
        The pixels each comparison averages over; None: the whole image.
    epsilon : float
        Relative MSE's ``epsilon``.

    Returns
    -------
    list of Comparison
        One per mask, in order, sharing the maps (the maps do not depend on the mask).
    """
    for image, name in ((reference, "reference"), (test, "test")):
        check_image(image, name)
    if reference.shape != test.shape:
        raise InputError(f"reference and test must have the same size; reference is "
                         f"{reference.shape[1]} x {reference.shape[0]} (H, W = "
                         f"{reference.shape}), test is {test.shape[1]} x {test.shape[0]} "
                         f"(H, W = {test.shape})", field="shape",
                         value=(reference.shape, test.shape))
    masks = [_check_mask(mask, reference.shape) for mask in masks]
    data_range = float(reference.rgb.max())
    if data_range <= 0:
        raise InputError("the reference is black: relative error, PSNR and FLIP are "
                         "undefined against it", field="reference.rgb", value=data_range)
    ref, tst = reference.rgb.astype(np.float64), test.rgb.astype(np.float64)
    white = display_white(ref)
    whole_ssim, ssim = ssim_map(ref, tst, white=white)
    whole_flip, flip = flip_map(ref, tst, dynamic_range="HDR")
    whole_ldr, ldr = flip_map(ref, tst, dynamic_range="LDR", white=white)
    delta_e = ciede2000_map(ref, tst, white=white)
    maps = {"flip": flip, "relative_error": relative_error_map(reference.rgb, test.rgb,
                                                                epsilon=epsilon),
            "ciede2000": delta_e, "ssim": ssim}
    comparisons = []
    for mask in masks:
        pixels = np.ones(reference.shape, dtype=bool) if mask is None else mask
        chosen_ref, chosen_tst, variance = ((ref, tst, reference.variance) if mask is None
                                            else (ref[pixels], tst[pixels],
                                                  None if reference.variance is None
                                                  else reference.variance[pixels]))
        # the whole image's SSIM and FLIP are the libraries' own means (SSIM's leaves out
        # the border its window does not cover)
        mean_ssim, hdr_flip, ldr_flip = ((whole_ssim, whole_flip, whole_ldr) if mask is None
                                         else (float(m[pixels].mean())
                                               for m in (ssim, flip, ldr)))
        raw = relative_mse(chosen_ref, chosen_tst, epsilon=epsilon)
        discounted = (raw if variance is None else
                      relative_mse(chosen_ref, chosen_tst, reference_variance=variance,
                                   epsilon=epsilon))
        metrics = Metrics(
            relative_mse=discounted, relative_mse_raw=raw, rmse=rmse(chosen_ref, chosen_tst),
            psnr=psnr(chosen_ref, chosen_tst, data_range=data_range),
            ssim=mean_ssim, hdr_flip=hdr_flip, ldr_flip=ldr_flip,
            ciede2000=float(delta_e[pixels].mean()),
            data_range=data_range, display_white=white,
            noise_discounted=reference.variance is not None,
            pixels_scored=int(pixels.sum()))
        comparisons.append(Comparison(metrics, maps))
    return comparisons


def compare(reference: Image, test: Image, *, epsilon: float = RELMSE_EPSILON,
            mask=None) -> Metrics:
    """Compare a test image with a reference: every metric the suite reports.

    Parameters
    ----------
    reference : Image
        The reference (usually a path-traced mean; its ``variance``, where known, is
        discounted from the relative MSE).
    test : Image
        The image judged (a fast method's render).
    epsilon : float
        Relative MSE's ``epsilon`` (radiance units squared), ``RELMSE_EPSILON``.
    mask : array_like of bool, shape (H, W), optional
        Score only these pixels (e.g. those that see an object); see :func:`evaluate`.

    Returns
    -------
    Metrics
        Relative MSE (noise-discounted and raw), RMSE, PSNR (peak: the reference's
        maximum), SSIM, HDR-FLIP, LDR-FLIP and mean CIEDE2000.

    Raises
    ------
    InputError
        Images of different sizes (the message gives both shapes), NaN/Inf pixels, a
        negative or non-finite reference variance, an all-black reference, or images
        smaller than 11 x 11 pixels.
    TypeError
        When an argument is not an :class:`~translucent.image.Image`.
    """
    return evaluate(reference, test, epsilon=epsilon, mask=mask).metrics


# --------------------------------------------------------------------------- noise floor

#: Independent draws of the reference's own noise averaged into a noise floor.
NOISE_FLOOR_DRAWS = 4

#: A metric resolves a method's error when, in its error form (:func:`error_scale`), it
#: exceeds the noise floor by this factor; below it the verdict is :data:`WITHIN_NOISE`.
#: With 4, a value called resolved owes at most a quarter of itself to the reference's
#: noise.
NOISE_MARGIN = 4.0

#: The verdicts of :func:`noise_verdict`.
RESOLVED = "resolved"
WITHIN_NOISE = "within reference noise"



def noise_floor(reference: Image, *, draws: int = NOISE_FLOOR_DRAWS, seed: int = 0,
                epsilon: float = RELMSE_EPSILON, mask=None) -> Metrics | None:
    r"""Return what every metric gives when the only difference is the reference's noise.

    The reference :math:`r` estimates the converged image :math:`\mu` with per-pixel
    variance :math:`\sigma^2` (``reference.variance``), so a perfect method, whose image is
    :math:`\mu`, scores :math:`m(r, \mu)` and not the ideal value. That score is estimated
    without knowing :math:`\mu`: the reference is compared with itself perturbed by
    Gaussian noise of its own variance, :math:`m(r, r + n)`, :math:`n \sim
    \mathcal{N}(0, \sigma^2)` (clipped at zero radiance), averaged over ``draws``
    independent draws. To the order of the noise, :math:`r + n - r` has the distribution of
    :math:`\mu - r`; the tests check the estimate against :math:`m(\mu + n, \mu)` on
    synthetic images of known truth and variance.

    Tested against the exact value: within 15 % for every metric at 1 % and 3 % relative
    noise, but for SSIM at 3 %, 16 % too low: the perturbed image carries the reference's
    noise as well as its own, which SSIM's contrast term counts where the noise is large
    against the local contrast; the SSIM floor is then a lower bound.

    The relative MSE's floor is that of the *raw* relative MSE: the part the discounted
    value removes. A discounted relative MSE near its floor rests mostly on the discount,
    that is on the reference's variance estimate, and is not resolved.

    Parameters
    ----------
    reference : Image
        With ``variance``.
    draws : int
        Independent noise draws averaged (>= 1).
    seed : int
        Seeds the draws (the floor is deterministic).
    epsilon : float
        Relative MSE's ``epsilon``.
    mask : array_like of bool, shape (H, W), optional
        Score these pixels only, as :func:`evaluate` does.

    Returns
    -------
    Metrics or None
        Each field the mean over the draws (``noise_discounted`` False); None when the
        reference has no variance.

    Examples
    --------
    >>> import numpy as np
    >>> from translucent.image import Image
    >>> rng = np.random.default_rng(1)
    >>> reference = Image(1 + 0.01 * rng.standard_normal((32, 32, 3)),
    ...                   np.full((32, 32, 3), 1e-4))
    >>> round(noise_floor(reference).rmse, 3)
    0.01
    """
    return noise_floors(reference, [mask], draws=draws, seed=seed, epsilon=epsilon)[0]


def noise_floors(reference: Image, masks, *, draws: int = NOISE_FLOOR_DRAWS, seed: int = 0,
                 epsilon: float = RELMSE_EPSILON) -> list:
    """:func:`noise_floor` over several pixel sets: each draw's error maps computed once.

    The draws are the same for every mask (one seed), so each floor equals
    :func:`noise_floor` with that mask alone.

    Returns
    -------
    list of (Metrics or None)
        One per mask; every entry None when the reference has no variance.
    """
    masks = list(masks)
    if reference.variance is None:
        return [None] * len(masks)
    check_image(reference, "reference")
    draws = int(draws)
    if draws < 1:
        raise InputError("must be >= 1", field="draws", value=draws)
    rng = np.random.default_rng(seed)
    plain = Image(reference.rgb)
    sigma = np.sqrt(reference.variance.astype(np.float64))
    values = [[] for _ in masks]
    for _ in range(draws):
        perturbed = np.maximum(reference.rgb + sigma * rng.standard_normal(sigma.shape), 0.0)
        for found, comparison in zip(values, evaluate_on(plain, Image(perturbed), masks,
                                                          epsilon=epsilon), strict=True):
            found.append(comparison.metrics.as_dict())
    return [Metrics(**{key: float(np.mean([v[key] for v in found])) for key in found[0]
                       if key not in ("noise_discounted", "pixels_scored")},
                    noise_discounted=False, pixels_scored=found[0]["pixels_scored"])
            for found in values]


def noise_verdicts(metrics: dict, floors: dict | None) -> dict[str, str]:
    """Return :func:`noise_verdict` of every gated metric of ``metrics`` against ``floors``.

    A metric without a floor says so (the reference has no variance).
    """
    from .registry import NOISE_FLOOR_FIELDS

    floors = floors or {}
    return {key: noise_verdict(key, metrics[key], floors.get(key))
            or "no floor (the reference has no variance)" for key in NOISE_FLOOR_FIELDS}


def error_scale(field: str, value: float) -> float:
    """Return a metric value in its *error form*: 0 for identical images, growing with error.

    Errors are themselves; SSIM becomes ``1 - SSIM``; PSNR becomes the MSE over the peak
    squared, ``10**(-PSNR / 10)``.
    """
    if field == "ssim":
        return 1.0 - value
    if field == "psnr":
        return 10.0 ** (-value / 10.0)
    return value


def noise_verdict(field: str, value: float, floor: float | None,
                  margin: float = NOISE_MARGIN) -> str | None:
    """Say whether a metric's value resolves an error beyond the reference's noise.

    Parameters
    ----------
    field : str
        The :class:`Metrics` field (``"hdr_flip"``, ``"ssim"``, ...).
    value : float
        The method's score.
    floor : float or None
        The same metric's noise floor (:func:`noise_floor`); None: not known.
    margin : float
        How far (a factor, in error form) the value must clear the floor.

    Returns
    -------
    str or None
        :data:`RESOLVED`, :data:`WITHIN_NOISE`, or None when the floor is not known.
    """
    if floor is None or not math.isfinite(floor) or not math.isfinite(value):
        return None
    error, noise = error_scale(field, value), error_scale(field, floor)
    return RESOLVED if error > margin * max(noise, 0.0) else WITHIN_NOISE
