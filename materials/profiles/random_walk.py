r"""The photon random walk's own radial profile, tabulated in reduced units.

The dipole's shape near the beam is not transport's (docs/capture-format.md measures how
far its fits land from the truth); the methods and the fitter need a profile as accurate as
the walk that makes the synthetic captures. This module reads the walk's table and
evaluates it (:class:`WalkProfileTable`, :class:`RandomWalkProfile`); the table is built by
:mod:`translucent.fitting.walk_table`, which runs the walk kernel.

Reduced units. For a semi-infinite medium with isotropic scattering (the reduced
coefficients of the measured media, g = 0) lit by a pencil beam at normal incidence, the
exitance per entering photon scales exactly with the extinction
:math:`\sigma'_t = \sigma_a + \sigma'_s`:

.. math:: R(r;\ \sigma_a, \sigma'_s, \eta) = \sigma'^2_t\, \hat R(\sigma'_t r;\ \alpha', \eta),
          \qquad \alpha' = \sigma'_s / \sigma'_t

so one table over the albedo :math:`\alpha'` and the reduced radius
:math:`\hat r = \sigma'_t r` per relative index :math:`\eta` serves every coefficient.
(For g > 0 this is the similarity relation, exact only far from the beam.)

What is stored (``materials/data/walk_profiles.npz``): per eta (:data:`TABLE_ETAS`) and
per point of the attenuation grid :math:`s = \sqrt{3(1 - \alpha')}` (the diffusion
attenuation in reduced units; :math:`s = 0` is the non-absorbing limit, included
exactly), ``ln(R_hat / alpha')`` at each ring's geometric centre (the ring mean corrected
for the profile's local power law across the ring), its standard error, and the
cumulative exitance at the ring edges.

How it is evaluated (:class:`WalkProfileTable`): the exact single scattering plus the
walked rest per :math:`\alpha'^2` (which varies slowly with the albedo), the latter
bilinear in :math:`(s, \ln \hat r)`; linear in eta. Where a ring is not resolved
(relative standard error above :data:`MAX_RELATIVE_SE`: far from the beam in an
absorbing medium, where the reweighted paths are rare) and beyond the last ring, the
single scattering stays exact and the rest continues as one diffusion source's far field,
:math:`(1 + \kappa r) e^{-\kappa r} / r^3`, with transport's own asymptotic attenuation
:math:`\kappa` (:func:`asymptotic_attenuation`), scaled to meet the table at its last
resolved ring; below the first ring it follows the single-scattering limit
:math:`R \propto 1/r`. The table's own error against independent walks is measured in
tests/fitting/test_walk_table.py and stated in docs/capture-format.md.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cached_property, lru_cache
from pathlib import Path

import numpy as np

from ...errors import InputError
from ..fresnel import fresnel_reflectance
from ..homogeneous import Dipole
from .base import LookupProfile
from .sampling import LogRadialTable, geometric_nodes

__all__ = [
    "MAX_RELATIVE_SE",
    "RADIUS_RANGE",
    "TABLE_ETAS",
    "TABLE_PATH",
    "RandomWalkProfile",
    "WalkProfileTable",
    "asymptotic_attenuation",
    "attenuation_grid",
    "load_table",
    "ring_edges",
    "single_scattering",
]

TABLE_ETAS = tuple(round(1.0 + 0.1 * k, 1) for k in range(11))
#: Base albedos of the walks (each tabulated albedo is reweighted from the smallest base at
#: or above it; the reweighting factor (alpha / alpha_b)^n stays near 1 for the paths that
#: Reduced radii of the rings: edges from :data:`RADIUS_RANGE` [0] to [1], geometric.
RADIUS_RANGE = (1e-3, 64.0)
RINGS_PER_DECADE = 16
#: Attenuation grid s = sqrt(3 (1 - alpha')): 0, then geometric up to s at alpha' =
#: :data:`MIN_ALBEDO`.
ATTENUATION_POINTS = 72
MIN_ATTENUATION = 2e-3
MIN_ALBEDO = 0.01
#: A ring whose relative standard error exceeds this is not used (the far-field shape
#: continues the profile from the last resolved ring).
MAX_RELATIVE_SE = 0.05
#: Rings whose outer edge lies inside this reduced radius are always used.
RESOLVED_FROM = 1.0
#: Photons traced at each base albedo (per eta) and per kernel call.
TABLE_PATH = Path(__file__).parent.parent / "data" / "walk_profiles.npz"


def ring_edges() -> np.ndarray:
    """Return the ring edges in reduced radius: 0, then geometric over :data:`RADIUS_RANGE`."""
    low, high = RADIUS_RANGE
    count = int(round(RINGS_PER_DECADE * math.log10(high / low))) + 1
    return np.concatenate([[0.0], np.geomspace(low, high, count)])


def attenuation_grid() -> np.ndarray:
    """Return the attenuation grid s = sqrt(3 (1 - alpha')): 0, then geometric."""
    top = math.sqrt(3.0 * (1.0 - MIN_ALBEDO))
    return np.concatenate([[0.0], np.geomspace(MIN_ATTENUATION, top, ATTENUATION_POINTS - 1)])


def single_scattering(radius, eta) -> np.ndarray:
    r"""Exact single-scattering exitance per entering photon and unit albedo, reduced units.

    A photon entering at normal incidence scatters first at depth z (density
    :math:`e^{-z}`), isotropically, and leaves at distance :math:`\hat r` from the beam
    without a second interaction through the Fresnel boundary:

    .. math:: \hat R_1(\hat r) = \frac{1}{4\pi}\int_0^\infty e^{-z - d}\,
              \big(1 - F_r(z / d)\big)\, \frac{z}{d^3}\, dz, \qquad d = \sqrt{\hat r^2 + z^2}

    evaluated with :math:`z = \hat r \sinh v` (which takes out the :math:`1/\hat r`
    singularity at the beam). The walk's exits after exactly one scattering estimate the
    same quantity (a test compares them).

    Parameters
    ----------
    radius : array_like
        Reduced radii > 0.
    eta : float
        Relative index of the slab (inside over outside).

    Returns
    -------
    ndarray
        :math:`\hat R_1 / \alpha'` at ``radius``.
    """
    radius = np.asarray(radius, dtype=np.float64)
    flat = radius.ravel()[:, None]
    # e^{-r e^v} is negligible beyond v = ln(50 / r)
    top = np.log(np.maximum(50.0 / flat, 2.0)) + 1.0
    v = np.linspace(0.0, 1.0, SINGLE_SCATTERING_NODES)[None, :] * top
    cos_exit = np.tanh(v)
    # z = r sinh v, d = r cosh v, dz = r cosh v dv
    integrand = (np.exp(-flat * np.exp(v)) * (1.0 - fresnel_reflectance(1.0 / eta, cos_exit))
                 * cos_exit / (flat * np.cosh(v)))
    value = np.trapezoid(integrand, v, axis=1) / (4.0 * np.pi)
    return value.reshape(radius.shape)


#: Floor of the walked part, as a fraction of the whole (where single scattering is all).
MIN_MULTIPLE_FRACTION = 1e-6
#: Reduced radius beyond which single scattering (~e^-r) is taken as 0.
SINGLE_SCATTERING_REACH = 700.0
#: Quadrature nodes of :func:`single_scattering` per radius.
SINGLE_SCATTERING_NODES = 4001


def load_table(path: Path | None = None) -> WalkProfileTable:
    """Load the walk profile table (default: the shipped one, :data:`TABLE_PATH`), cached."""
    return _load_table(Path(TABLE_PATH if path is None else path))


@lru_cache(maxsize=4)
def _load_table(path: Path) -> WalkProfileTable:
    try:
        with np.load(path) as data:
            arrays = {key: data[key] for key in data.files}
        return WalkProfileTable(**{key: arrays[key] for key in (
            "etas", "attenuation", "edges", "ln_profile", "relative_se", "cumulative")})
    except (OSError, ValueError, KeyError) as error:
        raise InputError(f"the walk profile table cannot be read ({error}); rebuild it with "
                         "`python -m translucent.fitting.walk_table`", file=path,
                         field="walk table") from None


@dataclass(frozen=True)
class WalkProfileTable:
    """Tabulated reduced profiles (the arrays :func:`build_table` returns)."""

    etas: np.ndarray
    attenuation: np.ndarray
    edges: np.ndarray
    ln_profile: np.ndarray
    relative_se: np.ndarray
    cumulative: np.ndarray

    @cached_property
    def centres(self) -> np.ndarray:
        """Geometric centres of the rings (the first, from 0, at half its edge)."""
        inner = self.edges[:-1].copy()
        inner[0] = 0.25 * self.edges[1]
        return np.sqrt(inner * self.edges[1:])

    @cached_property
    def _ln_centres(self) -> np.ndarray:
        return np.log(self.centres)

    @cached_property
    def albedos(self) -> np.ndarray:
        """The albedo alpha' = 1 - s^2 / 3 of each attenuation grid point."""
        return 1.0 - self.attenuation ** 2 / 3.0

    @cached_property
    def _ln_cumulative_per_albedo(self) -> np.ndarray:
        """ln(E / alpha') at the ring edges from the first on, shape (E, S, K)."""
        with np.errstate(divide="ignore"):
            return np.log(self.cumulative[..., 1:]) - np.log(self.albedos)[None, :, None]

    def check_eta(self, eta) -> None:
        """Refuse relative indices outside the tabulated range."""
        eta = np.asarray(eta, dtype=np.float64)
        low, high = float(self.etas[0]), float(self.etas[-1])
        bad = ~((eta >= low - 1e-9) & (eta <= high + 1e-9))
        if bad.any():
            raise InputError(f"the walk table covers eta {low:g} .. {high:g}", field="eta",
                             value=float(eta.ravel()[np.flatnonzero(bad.ravel())[0]]))

    def _eta_pairs(self, eta):
        """Return the two tables about each eta and their weights, [(lower, 1 - w), (upper, w)]."""
        eta = np.clip(np.asarray(eta, dtype=np.float64), self.etas[0], self.etas[-1])
        if self.etas.size == 1:
            lower, weight = np.zeros(eta.shape, dtype=np.int64), np.zeros(eta.shape)
            return [(lower, 1.0 - weight), (lower, weight)]
        upper = np.clip(np.searchsorted(self.etas, eta, side="right"), 1, self.etas.size - 1)
        lower = upper - 1
        weight = (eta - self.etas[lower]) / (self.etas[upper] - self.etas[lower])
        return [(lower, 1.0 - weight), (upper, weight)]

    def reduced_profile(self, radius, albedo, eta) -> np.ndarray:
        r"""Reduced exitance :math:`\hat R(\hat r; \alpha', \eta)` per entering photon.

        Parameters
        ----------
        radius : array_like, shape (..., m)
            Reduced radii :math:`\sigma'_t r` >= 0 of each profile.
        albedo : array_like, shape (...)
            :math:`\alpha'` in [0, 1], one per profile.
        eta : array_like, shape (...)
            Relative index within :data:`TABLE_ETAS`, one per profile.

        Returns
        -------
        ndarray, shape (..., m)
            :math:`\hat R`, per unit reduced area.
        """
        radius = np.asarray(radius, dtype=np.float64)
        albedo, eta = np.broadcast_arrays(np.asarray(albedo, dtype=np.float64),
                                          np.asarray(eta, dtype=np.float64))
        rows, last = self._rows(albedo, eta)
        centres = self._ln_centres
        ln_r = np.log(np.maximum(radius, 1e-300))
        # the centres from the second on are equally spaced in ln r: the interval by
        # arithmetic (what searchsorted would give, without its cost)
        step = centres[2] - centres[1]
        k = np.where(ln_r < centres[1], 1,
                     2 + np.floor((ln_r - centres[1]) / step).astype(np.int64))
        k = np.minimum(np.clip(k, 1, centres.size - 1), last[..., None])
        count = rows.shape[-1]
        flat = rows.reshape(-1)
        base = (np.arange(flat.size // count) * count).reshape(rows.shape[:-1] + (1,))
        left = flat[base + k - 1]
        slope = (flat[base + k] - left) / (centres[k] - centres[k - 1])
        value = left + np.minimum(ln_r - centres[k - 1], centres[k] - centres[k - 1]) * slope
        # below the first centre: R ~ 1/r (single scattering)
        value = np.where(ln_r < centres[0], rows[..., :1] - (ln_r - centres[0]), value)
        # beyond the last resolved ring: the far-field shape from there on
        end = centres[last][..., None]
        beyond = ln_r > end
        if np.any(beyond):  # only there: the far-field shape costs logs and exps
            where = np.nonzero(beyond)
            profile = where[:-1]
            end_value = np.take_along_axis(rows, last[..., None], axis=-1)[..., 0]
            kappa = asymptotic_attenuation(albedo)
            ln_end = end[..., 0][profile]
            # the single scattering stays exact; the rest of the profile continues in the
            # far-field shape from what it was at the last resolved ring
            single = self._single_scattering(ln_r[where], eta[profile])
            rest = np.maximum(np.exp(end_value[profile])
                              - self._single_scattering(ln_end, eta[profile]), 0.0)
            with np.errstate(divide="ignore"):
                value[where] = np.log(single + rest * np.exp(_ln_tail_ratio(
                    np.exp(ln_r[where]), np.exp(ln_end), kappa[profile])))
        return np.exp(value) * albedo[..., None]

    def relative_error(self, radius, albedo, eta) -> np.ndarray:
        r"""Return the table's own relative standard error at reduced radii.

        The ring holding each radius in the nearest tabulated (eta, albedo) row; beyond the
        row's last resolved ring, that ring's (the far-field continuation starts from its
        value). A ring without a finite estimate gets :data:`MAX_RELATIVE_SE`.

        Parameters
        ----------
        radius : array_like, shape (..., m)
            Reduced radii :math:`\sigma'_t r` >= 0.
        albedo, eta : array_like, shape (...)
            One per profile, as :meth:`reduced_profile`.

        Returns
        -------
        ndarray, shape (..., m)
            Relative standard error of :math:`\hat R` (dimensionless).
        """
        radius = np.asarray(radius, dtype=np.float64)
        albedo, eta = np.broadcast_arrays(np.asarray(albedo, dtype=np.float64),
                                          np.asarray(eta, dtype=np.float64))
        e = np.abs(np.clip(eta, self.etas[0], self.etas[-1])[..., None]
                   - self.etas).argmin(axis=-1)
        s = np.sqrt(3.0 * np.clip(1.0 - albedo, 0.0, None))
        a = np.abs(s[..., None] - self.attenuation).argmin(axis=-1)
        ring = np.searchsorted(self.edges, radius, side="right") - 1
        ring = np.minimum(np.clip(ring, 0, self.edges.size - 2),
                          self._last_resolved[e, a][..., None])
        rse = self.relative_se[e[..., None], a[..., None], ring]
        return np.where(np.isfinite(rse), rse, MAX_RELATIVE_SE)

    @cached_property
    def _single_scattering_table(self) -> tuple[np.ndarray, np.ndarray]:
        """Return ln r and ln :func:`single_scattering` on a fine grid, per tabulated eta."""
        radius = np.geomspace(RADIUS_RANGE[0], SINGLE_SCATTERING_REACH, 241)
        with np.errstate(divide="ignore"):
            values = np.log(np.stack([single_scattering(radius, eta) for eta in self.etas]))
        return np.log(radius), np.maximum(values, -745.0)

    def _single_scattering(self, ln_r, eta) -> np.ndarray:
        """Single scattering per unit albedo at ln r (linear in ln-ln and in eta)."""
        grid, table = self._single_scattering_table
        position = np.clip((ln_r - grid[0]) / (grid[1] - grid[0]), 0.0, grid.size - 1.0)
        k = np.minimum(np.floor(position).astype(np.int64), grid.size - 2)
        t = position - k
        value = np.zeros(np.shape(ln_r))
        for e, w in self._eta_pairs(eta):
            value += w * (table[e, k] + t * (table[e, k + 1] - table[e, k]))
        return np.where(ln_r > grid[-1], 0.0, np.exp(value))

    def _rows(self, albedo, eta):
        """ln(R_hat / alpha') over the rings, interpolated to each (albedo, eta).

        Returns the rows, shape (..., K), and the index of the last ring resolved in all
        four table rows they blend.
        """
        single_rows, multiple_rows = self._split_rows
        multiple = np.zeros(albedo.shape + (self.edges.size - 1,))
        last = np.full(albedo.shape, self.edges.size - 2)
        for e, a, weight in self._corners(albedo, eta):
            multiple += weight[..., None] * multiple_rows[e, a]
            last = np.minimum(last, self._last_resolved[e, a])
        single = sum(w[..., None] * single_rows[e] for e, w in self._eta_pairs(eta))
        rows = np.log(single + albedo[..., None] * np.exp(multiple))
        return rows, last

    @cached_property
    def _split_rows(self) -> tuple[np.ndarray, np.ndarray]:
        """The table split into its exact and its walked part, for interpolation in s.

        R / alpha' = R_1 + alpha' M: the single scattering R_1 (per unit albedo, exact, at
        the ring centres) and the rest, M = (R / alpha' - R_1) / alpha', which varies
        slowly with the albedo (double scattering and beyond per alpha'^2). Interpolating
        ln(R / alpha') itself across the coarse steps of low albedo (where the two parts
        trade places) would be geometric, biased low between the grid points.

        Returns R_1, shape (E, K), and ln M, shape (E, S, K).
        """
        single = np.stack([single_scattering(self.centres, eta) for eta in self.etas])
        total = np.exp(self.ln_profile)
        rest = np.maximum(total - single[:, None, :], MIN_MULTIPLE_FRACTION * total)
        return single, np.log(rest / self.albedos[None, :, None])

    def _corners(self, albedo, eta):
        """Return the four (eta index, attenuation index, weight) of the bilinear blend."""
        s = np.sqrt(np.clip(3.0 * (1.0 - albedo), 0.0, None))
        grid = self.attenuation
        top = np.clip(np.searchsorted(grid, s, side="right"), 1, grid.size - 1)
        bottom = top - 1
        ws = np.clip((s - grid[bottom]) / (grid[top] - grid[bottom]), 0.0, 1.0)
        return [(e, a, w_e * w_a) for e, w_e in self._eta_pairs(eta)
                for a, w_a in ((bottom, 1.0 - ws), (top, ws))]

    def reduced_cumulative(self, radius, albedo, eta) -> np.ndarray:
        r"""Return the exitance inside reduced radius :math:`\hat r`, per entering photon.

        Interpolated as ln E against ln r between the ring edges (bilinear in s and eta
        like :meth:`reduced_profile`); proportional to r inside the first edge (single
        scattering) and constant beyond the last.

        Parameters
        ----------
        radius, albedo, eta : array_like
            Broadcast together.

        Returns
        -------
        ndarray
        """
        radius, albedo, eta = np.broadcast_arrays(*(np.asarray(a, dtype=np.float64)
                                                    for a in (radius, albedo, eta)))
        edges = np.log(self.edges[1:])
        ln_cumulative = self._ln_cumulative_per_albedo
        ln_r = np.log(np.maximum(radius, 1e-300))
        k = np.clip(np.searchsorted(edges, ln_r, side="right"), 1, edges.size - 1)
        t = np.clip((ln_r - edges[k - 1]) / (edges[k] - edges[k - 1]), None, 1.0)
        value = np.zeros(radius.shape)
        # ln(E / alpha'), as the profile: E itself falls with the albedo too fast for a
        # linear blend across the coarse low-albedo steps
        for e, a, weight in self._corners(albedo, eta):
            left = ln_cumulative[e, a, k - 1]
            right = ln_cumulative[e, a, k]
            value += weight * np.where(ln_r < edges[0], left + (ln_r - edges[0]),
                                       left + t * (right - left))
        return np.exp(value) * albedo

    @cached_property
    def _last_resolved(self) -> np.ndarray:
        """Index of the last ring before the first unresolved one, per table row (>= 1)."""
        # the rings inside RESOLVED_FROM always count (the beam's neighbourhood, where
        # the single-scattering part is exact and the walk's part well sampled)
        resolved = (self.relative_se <= MAX_RELATIVE_SE) | (self.edges[1:] <= RESOLVED_FROM)
        padded = np.concatenate([resolved, np.zeros(resolved.shape[:-1] + (1,), bool)],
                                axis=-1)
        return np.maximum(np.argmin(padded, axis=-1) - 1, 1)


def asymptotic_attenuation(albedo) -> np.ndarray:
    r"""Transport's asymptotic attenuation :math:`\kappa` of isotropic scattering, reduced units.

    Far from the beam the exitance falls as :math:`e^{-\kappa \hat r}`, with
    :math:`\kappa` the root in (0, 1) of :math:`\alpha' \operatorname{artanh}(\kappa) /
    \kappa = 1` (Case's discrete eigenvalue). Diffusion's :math:`\sqrt{3(1 - \alpha')}`
    is its limit for :math:`\alpha' \to 1`; at lower albedo it overestimates it (0.98
    against 0.85 at 0.68).
    """
    albedo = np.clip(np.asarray(albedo, dtype=np.float64), 1e-12, 1.0)
    low = np.zeros(albedo.shape)
    high = np.ones(albedo.shape)
    for _ in range(60):  # bisection: artanh(k) / k grows monotonically from 1
        middle = 0.5 * (low + high)
        with np.errstate(divide="ignore", invalid="ignore"):
            too_small = albedo * np.arctanh(middle) / middle < 1.0
        low = np.where(too_small, middle, low)
        high = np.where(too_small, high, middle)
    return np.where(albedo >= 1.0, 0.0, 0.5 * (low + high))


def _ln_tail_ratio(radius, start, kappa):
    r"""Return ln of the far-field shape at ``radius`` over its value at ``start``.

    The shape is :math:`(1 + \kappa r) e^{-\kappa r} / r^3` (one diffusion source's far
    field, with transport's :math:`\kappa`; at :math:`\kappa = 0` the non-absorbing
    :math:`1/r^3`).
    """
    return (np.log1p(kappa * radius) - np.log1p(kappa * start) - kappa * (radius - start)
            - 3.0 * (np.log(radius) - np.log(start)))


#: Reduced radius below which the walk's profile is held at its value there: R ~ 1/r at
#: the beam (single scattering), integrable but not finite at 0; the energy inside is
#: 1e-6 of a mean free path's worth.
SINGULAR_FLOOR = 1e-6


class RandomWalkProfile(LookupProfile):
    r"""The photon random walk's radial profile of a medium, from the shipped table.

    :math:`R(r) = \sigma'^2_t \hat R(\sigma'_t r; \alpha', \eta)` per channel, read from
    :class:`WalkProfileTable` and tabulated once more per channel on a geometric grid
    (:class:`~translucent.materials.profiles.sampling.LogRadialTable`) so that evaluation
    is a lookup; :meth:`reflection_exact` reads the walk table itself.

    Parameters
    ----------
    medium : Dipole
        sigma_a, sigma_s' (mm^-1) and eta, within the table's eta range (1.0 .. 2.0).
    table : WalkProfileTable, optional
        Default: :func:`load_table`.

    Raises
    ------
    InputError
        For an eta outside the table.
    """

    model = "random_walk"
    summary = ("photon random walk, tabulated in reduced units (isotropic scattering, "
               "exact Fresnel boundary; the transport the other profiles are measured against)")
    derivation = ("R(r) = sigma_t'^2 R_hat(sigma_t' r; alpha', eta) with sigma_t' = sigma_a + "
                  "sigma_s', alpha' = sigma_s'/sigma_t'; R_hat interpolated bilinearly in "
                  "(sqrt(3 (1 - alpha')), ln r) and linearly in eta; g > 0 by similarity")

    def __init__(self, medium: Dipole, *, table: WalkProfileTable | None = None):
        self.adopt(medium)
        self.table = load_table() if table is None else table
        self.table.check_eta(medium.eta)
        sigma_t = medium.sigma_a + medium.sigma_s_prime
        self.present = sigma_t > 0
        self.sigma_t = sigma_t
        self.albedo = np.where(self.present, medium.sigma_s_prime
                               / np.where(self.present, sigma_t, 1.0), 0.0)
        radius = geometric_nodes(self.length_scale())
        self.lookup = LogRadialTable(radius, self._exact_per_channel(radius))

    def _exact_per_channel(self, radius) -> np.ndarray:
        """Channel c's profile at radius[c], shape like ``radius`` (3, ...), mm^-2."""
        sigma_t = np.where(self.present, self.sigma_t, 1.0)
        reduced = np.maximum(radius * sigma_t[:, None], SINGULAR_FLOOR)
        values = self.table.reduced_profile(reduced, self.albedo, np.full(3, self.medium.eta))
        values = values * (sigma_t ** 2)[:, None]
        return np.where(self.present[:, None], values, 0.0)

    def reflection_exact(self, r) -> np.ndarray:
        """Read the walk table at ``r`` (mm) directly: shape ``r.shape + (3,)``, mm^-2."""
        r = np.asarray(r, dtype=np.float64)
        flat = np.broadcast_to(r.reshape(1, -1), (3, r.size))
        return self._exact_per_channel(flat).T.reshape(r.shape + (3,))

    def parameters(self) -> dict[str, tuple[np.ndarray, str]]:
        """Return alpha' and sigma_t' per channel."""
        return {"alpha'": (self.albedo, ""), "sigma_t'": (self.sigma_t, "mm^-1"),
                "eta": (np.full(3, self.medium.eta), "")}

    def cache_key(self) -> dict:
        """Return what identifies this profile in content hashes."""
        return {"type": self.model, "medium": self.medium.cache_key()}
