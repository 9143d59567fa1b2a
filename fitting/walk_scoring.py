"""Tallies of the photon random walk: exits binned by radius and landed on a film.

Shared by the numpy walk (:mod:`translucent.fitting.random_walk`) and the compiled one
(:mod:`translucent.fitting.walk_kernel`), so that neither imports the other.
"""

from __future__ import annotations

import numpy as np

__all__ = ["score_exits"]


def score_exits(rng, side, dx, dy, x0, y0, weight, batch, edges, film, rotations, radial,
                totals, film_sum) -> None:
    """Add exits to the tallies, in place.

    Parameters
    ----------
    rng : numpy.random.Generator
        Draws the random offset of the film rotations.
    side : int
        0 for exits through the lit surface, 1 through the far one.
    dx, dy : ndarray
        Exit point minus entry point, mm.
    x0, y0 : ndarray
        Entry points, mm from the beam axis.
    weight : ndarray
        Weight leaving.
    batch : ndarray of int
        Batch of each exit's photon.
    edges : ndarray
        Radial bin edges, mm.
    film : Film or None
    rotations : int
        Each exit lands on the film at this many rotations about its entry point, equally
        spaced from a random offset (the slab is invariant under them), each with
        ``weight / rotations``.
    radial : ndarray, shape (2, batches, bins)
    totals : ndarray, shape (2, batches)
    film_sum : ndarray, shape (H * W,) or None
    """
    n_bins = edges.size - 1
    r = np.hypot(dx, dy)
    bins = np.searchsorted(edges, r, side="right") - 1
    inside = (bins >= 0) & (bins < n_bins)
    np.add.at(radial[side], (batch[inside], bins[inside]), weight[inside])
    np.add.at(totals[side], batch, weight)
    if film_sum is None or side != (0 if film.side == "reflection" else 1):
        return
    height, width = film.shape
    offset = rng.random(r.size)
    for k in range(rotations):
        angle = 2.0 * np.pi * (offset + k / rotations)
        c, s = np.cos(angle), np.sin(angle)
        fx = film.centre_px[0] + (x0 + c * dx - s * dy) / film.pixel_size_mm
        fy = film.centre_px[1] + (y0 + s * dx + c * dy) / film.pixel_size_mm
        ix, iy = np.floor(fx).astype(np.int64), np.floor(fy).astype(np.int64)
        on = (ix >= 0) & (ix < width) & (iy >= 0) & (iy < height)
        film_sum += np.bincount(iy[on] * width + ix[on], weight[on] / rotations,
                                minlength=height * width)
