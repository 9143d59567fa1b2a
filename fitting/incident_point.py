"""Where the beam enters a slab capture: the thresholded centroid of its bright core.

Used by the profile measurement (:mod:`translucent.fitting.profile`), the measured beam
(:mod:`translucent.fitting.measured_beam`) and photo import, none of which it imports.
"""

from __future__ import annotations

import numpy as np

__all__ = ["CENTROID_ITERATIONS", "CENTROID_THRESHOLD", "CENTROID_TOLERANCE_PX",
           "refine_incident_point"]

#: Iterations and tolerance (pixels) of the thresholded-centroid refinement.
CENTROID_ITERATIONS = 50
CENTROID_TOLERANCE_PX = 1e-4
#: Pixels above this fraction of the peak define the bright core whose centroid is the
#: incident point.
CENTROID_THRESHOLD = 0.2

def refine_incident_point(signal, start_xy, *, saturated=None, search_radius_px=None):
    r"""Sub-pixel incident point: the centroid of the bright core, iterated to a fixed point.

    The weights are :math:`\max(v - t, 0)` with :math:`t` = :data:`CENTROID_THRESHOLD`
    times the peak, over a disc that is recentred on each new estimate. Any radially
    symmetric profile is a fixed point at its true centre; saturated pixels keep the peak
    value (a symmetric plateau), NaN pixels weigh nothing. Where the bright core reaches the
    image border the centroid is biased, and ``start_xy`` is returned unchanged.

    Parameters
    ----------
    signal : ndarray, shape (H, W)
        Linear signal (black removed), summed over channels.
    start_xy : (float, float)
        Starting point ``(x, y)`` in pixels (the sidecar's ``incident_px``).
    saturated : ndarray of bool, optional
        Pixels clipped in the stored image.
    search_radius_px : float, optional
        Where to look for the peak around the start (default: a quarter of the image).

    Returns
    -------
    (float, float)
        ``(x, y)`` in the sidecar's convention (pixel centres at half-integers).
    """
    signal = np.nan_to_num(np.asarray(signal, dtype=np.float64), nan=0.0, posinf=0.0,
                           neginf=0.0)
    height, width = signal.shape
    ys, xs = np.mgrid[0:height, 0:width]
    xs = xs + 0.5
    ys = ys + 0.5
    x, y = float(start_xy[0]), float(start_xy[1])
    if search_radius_px is None:
        search_radius_px = 0.25 * max(height, width)
    near = (xs - x) ** 2 + (ys - y) ** 2 <= search_radius_px ** 2
    if saturated is not None and (saturated & near).any():
        peak = signal[saturated & near].max()
        signal = np.where(saturated, peak, signal)
    if not near.any():
        return x, y
    peak = signal[near].max()
    if not peak > 0:
        return x, y
    threshold = CENTROID_THRESHOLD * peak
    # start at the brightest pixel near the given point (the point may be off by pixels)
    core = near & (signal >= threshold)
    weights = np.where(core, signal - threshold, 0.0)
    x = float((weights * xs).sum() / weights.sum())
    y = float((weights * ys).sum() / weights.sum())
    for _ in range(CENTROID_ITERATIONS):
        core_radius = np.sqrt(max(core.sum(), 1) / np.pi)
        window = (xs - x) ** 2 + (ys - y) ** 2 <= (2.0 * core_radius + 3.0) ** 2
        weights = np.where(window, np.clip(signal - threshold, 0.0, None), 0.0)
        total = weights.sum()
        if not total > 0:
            break
        new_x = float((weights * xs).sum() / total)
        new_y = float((weights * ys).sum() / total)
        moved = np.hypot(new_x - x, new_y - y)
        x, y = new_x, new_y
        core = window & (signal >= threshold)
        if moved < CENTROID_TOLERANCE_PX:
            break
    if core[0].any() or core[-1].any() or core[:, 0].any() or core[:, -1].any():
        # a core cut by the image border pulls the centroid inwards (0.5 px for a beam on
        # the border, enough to bias a fit beyond its 95 % intervals): keep the given point
        return float(start_xy[0]), float(start_xy[1])
    return x, y
