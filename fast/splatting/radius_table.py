"""The minimal rendering radius lookup table (Chen et al. 2012, Eq. 14)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ...errors import InputError


@dataclass(frozen=True)
class RenderingRadiusTable:
    r"""The minimal effective rendering radius :math:`\bar R(T)` of Eq. 14, tabulated.

    ``resolutions`` (ascending) are values of :math:`T` (pixels across the effective
    scattering range); ``radii`` the normalised :math:`\bar R \in [0, 1]` (non-increasing).
    """

    resolutions: np.ndarray
    radii: np.ndarray

    def __call__(self, resolution) -> np.ndarray:
        r"""Return :math:`\bar R(T)`, linear in :math:`\ln T` (clamped at the ends)."""
        resolution = np.asarray(resolution, np.float64)
        if resolution.size and not (np.isfinite(lowest := resolution.min()) and lowest >= 1e-30
                                    and np.isfinite(resolution.max())):
            resolution = np.clip(np.nan_to_num(resolution, nan=1.0, posinf=1e30), 1e-30, None)
        return np.interp(np.log(resolution), np.log(self.resolutions), self.radii)


#: Fewest pixels of a level across a profile's effective range for the level to render any of
#: it: bilinear upsampling (Eq. 17 of Chen et al. 2012) cannot reconstruct a ring narrower
#: than two of its pixels, however smooth the profile is there.
MIN_LEVEL_RESOLUTION = 2.0


def minimal_rendering_radius_table(mean_profile, epsilon: float = 0.001, *,
                                   resolutions=None, radius_samples: int = 128
                                   ) -> RenderingRadiusTable:
    r"""Tabulate Eq. 14 of Chen et al. 2012: the smallest radius rendered at a resolution.

    For a resolution :math:`T` (pixels across the effective scattering range),
    :math:`\bar R(T)` is the smallest :math:`r` such that the sampled tail
    :math:`\sum_m \bar P(\hat r_m)\hat r_m\,h_m` differs from
    :math:`\int_r^1 \bar P(r) r\,dr` by less than :math:`\varepsilon` for every
    :math:`r' \ge r` (the absolute difference; the paper's set definition read as "from
    here outwards"). The cells are the paper's, :math:`[r + m/T, r + (m+1)/T]` clipped to
    :math:`[r, 1]` (width :math:`h_m`), each sampled at its centre :math:`\hat r_m`, as a
    pixel of the level samples the profile at its centre; no level renders anything below
    :data:`MIN_LEVEL_RESOLUTION` pixels across the range (:math:`\bar R = 1`).

    Why cell centres and not the left ends :math:`r + m/T` of the paper's notation: that
    sum is biased by :math:`\approx (\bar P(r) r + \bar P(1))/(2T)`, a first-order
    artefact of the notation (a pixel stands for the cell around its centre), which at
    :math:`\varepsilon = 0.001` keeps every coarse level unused until the range covers
    about 70 of its pixels. The paper's own scenes (ranges of 0.04-0.35 bounding-sphere
    radii at 800 x 600, so at most ~45 pixels at level 1) then could never use levels 1
    and 2, yet its Table 2 gives them 25-80 % of the splatting time. With cell centres the
    error is the quadrature error of the pixel grid, second order in :math:`1/T`.

    Parameters
    ----------
    mean_profile : callable
        :math:`\bar P(r)` on :math:`r \in [0, 1]` (normalised so that
        :math:`\int_0^1 \bar P r\,dr = 1`), vectorised.
    epsilon : float
        Error tolerance (0.001 in the paper), > 0.
    resolutions : array_like, optional
        Values of :math:`T`; default 37 values from 0.5 to 2048, log-spaced (beyond the
        last one the table's last radius is used, a radius too large: safe, just slower).
    radius_samples : int
        Candidate radii in [0, 1].
    """
    if not np.isfinite(epsilon) or epsilon <= 0:
        raise InputError("must be > 0", field="epsilon", value=epsilon)
    if resolutions is None:
        resolutions = np.geomspace(0.5, 2048.0, 37)
    resolutions = np.asarray(resolutions, dtype=np.float64)
    fine = np.linspace(0.0, 1.0, 2049)
    density = np.asarray(mean_profile(fine), dtype=np.float64) * fine
    tail = np.concatenate([np.cumsum((0.5 * (density[1:] + density[:-1]) / 2048)[::-1])[::-1],
                           [0.0]])  # integral from fine[j] to 1
    candidates = np.linspace(0.0, 1.0, radius_samples + 1)
    integral = np.interp(candidates, fine, tail)
    radii = np.empty(len(resolutions))
    for index, resolution in enumerate(resolutions):
        if resolution < MIN_LEVEL_RESOLUTION:
            radii[index] = 1.0
            continue
        step = 1.0 / resolution
        # cells [r + m/T, r + (m+1)/T] clipped to [r, 1], each sampled at its centre
        count = np.ceil((1.0 - candidates) * resolution - 1e-9).astype(np.int64)
        total = np.zeros_like(candidates)
        for start in range(0, int(count.max()), 4096):
            m = np.arange(start, min(int(count.max()), start + 4096))[None, :]
            lower = candidates[:, None] + m * step
            upper = np.minimum(lower + step, 1.0)
            width = np.where(m < count[:, None], upper - lower, 0.0)
            total += (np.interp(0.5 * (lower + upper), fine, density) * width).sum(axis=1)
        bad = np.abs(total - integral) >= epsilon
        # smallest r with every r' >= r within tolerance
        last_bad = np.flatnonzero(bad)
        radii[index] = 0.0 if len(last_bad) == 0 else min(
            1.0, candidates[min(last_bad[-1] + 1, radius_samples)])
    radii = np.minimum.accumulate(radii)  # finer resolution never needs a larger radius
    return RenderingRadiusTable(resolutions, radii)


