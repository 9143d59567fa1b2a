r"""Any radial profile in reduced units, tabulated: what a fitter evaluates millions of times.

A profile made from a homogeneous medium (absorption :math:`\sigma_a`, reduced scattering
:math:`\sigma'_s`, relative index :math:`\eta`) has every length in units of the reduced mean
free path :math:`1/\sigma'_t`, :math:`\sigma'_t = \sigma_a + \sigma'_s`: the dipoles, quantized
and photon beam diffusion (at g = 0, which the reduced coefficients stand for), the three
Christensen-Burley fits and Cycles' (their scale is the mean free path over a function of the
albedo). So

.. math::
    R(r; \sigma_a, \sigma'_s, \eta) = \sigma'^2_t\,\hat R(\sigma'_t r; \alpha', \eta),
    \qquad \alpha' = \sigma'_s / \sigma'_t,

and one table of :math:`\hat R` over the reduced albedo and the radius serves every medium
(the photon random walk's own table, :mod:`.random_walk`, is made the same way). The table
holds :math:`\ln \hat R` on a grid of the albedo's logit :math:`\ln(\alpha' / (1 - \alpha'))`
(in which :math:`\ln \hat R` is near linear at both ends: :math:`\propto \ln\alpha'` at low
albedo, smooth in :math:`\ln(1 - \alpha')` near 1), :math:`\ln \hat r` and the given :math:`\eta`;
it is read by multilinear interpolation, with the cumulative exitance
:math:`2\pi\int_0^{\hat r} \hat R\,\hat r'\,d\hat r'` beside it (its first piece from the
profile's own :meth:`~.base.MediumProfile.total`, so a profile that diverges at the entry
point, like photon beam diffusion's single scattering, keeps its share).

Outside the grid: an albedo beyond its ends takes the end's profile; a radius below the
first node or beyond the last follows the straight line in :math:`(\ln \hat r, \ln \hat R)`
of the two nodes at that end (a power law: a profile that diverges like :math:`1/r` at the
entry point keeps diverging).

Examples
--------
>>> import numpy as np
>>> from translucent.materials import Dipole
>>> from translucent.materials.profiles import profile
>>> table = reduced_table("burley_dmfp", (1.3,))
>>> medium = Dipole([0.02, 0.05, 0.2], [1.0, 1.2, 1.5], eta=1.3)
>>> sigma_t = medium.sigma_a + medium.sigma_s_prime
>>> r = np.array([0.5, 2.0])
>>> exact = profile("burley_dmfp", medium).reflection(r)[:, 0]
>>> tabled = sigma_t[0]**2 * table.reduced_profile(sigma_t[0] * r, 1.0 / 1.02, 1.3)
>>> bool(np.allclose(tabled, exact, rtol=0.01))
True
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np

from ...errors import InputError

__all__ = ["ReducedProfileTable", "reduced_table", "TABLE_ALBEDO_RANGE",
           "TABLE_RADIUS_RANGE"]

#: Reduced albedos the table spans: :math:`\alpha'` from 0.001 to :math:`1 - 10^{-7}` (the
#: fitter's priors reach further; beyond, the end's profile).
TABLE_ALBEDO_RANGE = (1e-3, 1.0 - 1e-7)
#: Reduced radii the table spans, in reduced mean free paths.
TABLE_RADIUS_RANGE = (1e-4, 300.0)
#: Grid points: in ln(1 - albedo) and in ln r.
ALBEDO_POINTS = 256
RADIUS_POINTS = 360
#: The value ln R takes where the profile is zero (below what a float64 holds).
LN_FLOOR = -700.0


@dataclass(frozen=True)
class ReducedProfileTable:
    r""":math:`\ln \hat R` and its cumulative over (eta, logit of the albedo, ln r).

    Attributes
    ----------
    name : str
        The profile.
    etas : ndarray, shape (E,)
        Increasing relative indices.
    logit : ndarray, shape (A,)
        Increasing :math:`\ln(\alpha' / (1 - \alpha'))`.
    ln_radius : ndarray, shape (M,)
        Equally spaced :math:`\ln \hat r`.
    ln_values, ln_cumulative : ndarray, shape (E, A, M)
        :math:`\ln \hat R` (per unit reduced area) and the log of the exitance within
        :math:`\hat r`.
    """

    name: str
    etas: np.ndarray
    logit: np.ndarray
    ln_radius: np.ndarray
    ln_values: np.ndarray
    ln_cumulative: np.ndarray

    def check_eta(self, eta) -> None:
        """Raise :class:`InputError` for an eta outside the table's."""
        eta = np.asarray(eta, dtype=np.float64)
        low, high = self.etas[0], self.etas[-1]
        if np.any((eta < low - 1e-12) | (eta > high + 1e-12)):
            raise InputError(f"the {self.name} table spans eta {low:g} to {high:g}",
                             field="eta", value=float(np.ravel(eta)[0]))

    def reduced_profile(self, radius, albedo, eta) -> np.ndarray:
        r"""Return :math:`\hat R(\hat r; \alpha', \eta)`.

        Parameters
        ----------
        radius : array_like, shape (..., m)
            Reduced radii, one row per profile.
        albedo, eta : array_like, shape (...)
            One per profile.
        """
        return np.exp(self._interpolate(self.ln_values, radius, albedo, eta))

    def reduced_cumulative(self, radius, albedo, eta) -> np.ndarray:
        r"""Return the exitance within reduced radius ``radius`` (shape (...)), per photon."""
        radius = np.asarray(radius, dtype=np.float64)
        return np.exp(self._interpolate(self.ln_cumulative, radius[..., None], albedo,
                                        eta))[..., 0]

    def _interpolate(self, table, radius, albedo, eta) -> np.ndarray:
        radius = np.asarray(radius, dtype=np.float64)
        albedo, eta = np.broadcast_arrays(np.asarray(albedo, dtype=np.float64),
                                          np.asarray(eta, dtype=np.float64))
        e0, e1, we = _bracket(self.etas, eta)
        albedo = np.clip(albedo, *TABLE_ALBEDO_RANGE)
        a0, a1, wa = _bracket(self.logit, np.log(albedo) - np.log1p(-albedo))
        ln_r = np.log(np.maximum(radius, 1e-300))
        step = self.ln_radius[1] - self.ln_radius[0]
        position = (ln_r - self.ln_radius[0]) / step
        k = np.clip(np.floor(position).astype(np.int64), 0, self.ln_radius.size - 2)
        # beyond either end: the end interval's straight line in (ln r, ln R), a power law
        # (a profile that diverges at the entry point, like 1/r, keeps diverging)
        t = position - k
        # the four corners' nodes gathered from the flat table (a fit calls this thousands
        # of times: no row of the table is copied)
        flat = table.reshape(-1)
        points, radii = table.shape[1], table.shape[2]
        result = 0.0
        for ei, ew in ((e0, 1.0 - we), (e1, we)):
            for ai, aw in ((a0, 1.0 - wa), (a1, wa)):
                start = ((ei * points + ai) * radii)[..., None] + k
                left, right = flat[start], flat[start + 1]
                weight = (ew * aw)[..., None]
                result = result + weight * ((1.0 - t) * left + t * right)
        return result


def _bracket(grid: np.ndarray, value: np.ndarray):
    """Return the lower and upper indices and the weight of ``value`` on ``grid`` (clamped)."""
    if grid.size == 1:
        zero = np.zeros(value.shape, dtype=np.int64)
        return zero, zero, np.zeros(value.shape)
    value = np.clip(value, grid[0], grid[-1])
    upper = np.clip(np.searchsorted(grid, value, side="right"), 1, grid.size - 1)
    lower = upper - 1
    weight = (value - grid[lower]) / (grid[upper] - grid[lower])
    return lower, upper, weight


@functools.lru_cache(maxsize=16)
def reduced_table(name: str, etas: tuple) -> ReducedProfileTable:
    """Build (once a process) the reduced table of radial profile ``name`` at ``etas``.

    Parameters
    ----------
    name : str
        A radial profile of :data:`~translucent.materials.profiles.PROFILE_NAMES`.
    etas : tuple of float
        The relative indices to tabulate (increasing; one for a known eta).

    Raises
    ------
    InputError
        An unknown or directional profile, or etas that are not increasing.
    """
    from .. import Dipole
    from .registry import PROFILES, profile

    if name not in PROFILES or PROFILES[name].directional:
        radial = [n for n, entry in PROFILES.items() if not entry.directional]
        raise InputError(f"not a radial profile; valid: {', '.join(radial)}", field="profile",
                         value=name)
    etas = np.asarray(etas, dtype=np.float64)
    if etas.ndim != 1 or etas.size == 0 or np.any(np.diff(etas) <= 0):
        raise InputError("must be increasing", field="etas", value=etas.tolist())
    low, high = TABLE_ALBEDO_RANGE
    logit = np.linspace(np.log(low / (1 - low)), np.log(high / (1 - high)), ALBEDO_POINTS)
    albedos = 1.0 / (1.0 + np.exp(-logit))
    ln_radius = np.linspace(*np.log(TABLE_RADIUS_RANGE), RADIUS_POINTS)
    radius = np.exp(ln_radius)
    values = np.empty((etas.size, albedos.size, radius.size))
    cumulative = np.empty_like(values)
    for e, eta in enumerate(etas):
        for start in range(0, albedos.size, 3):  # a medium holds three albedos at once
            chunk = albedos[start:start + 3]
            padded = np.pad(chunk, (0, 3 - chunk.size), mode="edge")
            made = profile(name, Dipole(1.0 - padded, padded, eta=float(eta)))
            rows = np.maximum(made.reflection(radius), 0.0).T  # (3, M)
            inside = made.total(max_radius=float(radius[0]))  # (3,)
            values[e, start:start + chunk.size] = rows[:chunk.size]
            cumulative[e, start:start + chunk.size] = (
                inside[:chunk.size, None] + _cumulative(rows[:chunk.size], radius))
    with np.errstate(divide="ignore"):
        ln_values = np.maximum(np.log(values), LN_FLOOR)
        ln_cumulative = np.maximum(np.log(cumulative), LN_FLOOR)
    return ReducedProfileTable(name, etas, logit, ln_radius, ln_values, ln_cumulative)


def _cumulative(rows: np.ndarray, radius: np.ndarray) -> np.ndarray:
    r"""Return :math:`2\pi\int_{r_0}^{r} R\,r'\,dr'` at every node (trapezoids in r)."""
    integrand = 2.0 * np.pi * rows * radius
    pieces = 0.5 * (integrand[:, 1:] + integrand[:, :-1]) * np.diff(radius)
    return np.concatenate([np.zeros((rows.shape[0], 1)), np.cumsum(pieces, axis=1)], axis=1)
