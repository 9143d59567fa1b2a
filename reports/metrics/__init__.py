"""The image metrics, by concept: each defined once, computed, picked by name, drawn, tested.

:mod:`.registry` defines every metric once (name, label, unit, direction, tolerance, noise
floor, aliases); :mod:`.compute` computes them and their noise floors (its names are
offered here, as ``translucent.reports.metrics.evaluate``); :mod:`.table` picks them by
name for ``translucent compare`` and the pytest plugin; :mod:`.maps` draws the error maps;
:mod:`.statistics` holds the statistical tests of noisy renders.
"""

from .compute import (
    NOISE_FLOOR_DRAWS,
    NOISE_MARGIN,
    RESOLVED,
    WITHIN_NOISE,
    Comparison,
    Metrics,
    check_image,
    ciede2000_map,
    compare,
    display_white,
    error_scale,
    evaluate,
    evaluate_on,
    flip_map,
    luminance,
    noise_floor,
    noise_floors,
    noise_verdict,
    psnr,
    relative_error_map,
    relative_mse,
    rmse,
    srgb_encode,
    ssim_map,
    to_display,
)

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
