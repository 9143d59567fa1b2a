r"""Photon beam diffusion (Habel, Christensen, Jarosz 2013), tabulated as pbrt-v4 does.

The incident beam is a line of dipole sources along its path, weighted by where the first
interaction happens; a separate single-scattering term adds the light that leaves after one
scattering. pbrt-v4 (``src/pbrt/bssrdf.cpp``) evaluates both in optical units
(:math:`\sigma_t = 1`) and tabulates them, per phase asymmetry g and relative index eta,
over 100 single-scattering albedos :math:`\rho` and 64 optical radii; this module
reproduces that table (:func:`beam_diffusion_table`, about 10 ms to build, kept for the
process) and its Catmull-Rom reading:

* multiple scattering (``BeamDiffusionMS``): 100 real-source depths
  :math:`z_r = -\ln(1 - (i + \tfrac12)/100)/\sigma'_t` (stratified over
  :math:`\sigma'_t e^{-\sigma'_t z}`), each a dipole with Grosjean's
  :math:`D = (2\sigma_a + \sigma'_s)/(3\sigma'^2_t)`, :math:`\sigma_{tr} = \sqrt{\sigma_a/D}`,
  the virtual source at :math:`z_v = -z_r - 4AD` and exitance
  :math:`C_\phi\phi + C_E E` (:mod:`.boundary`), weighted by
  :math:`\kappa\rho'^2` with :math:`\kappa = 1 - e^{-2\sigma'_t(d_r + z_r)}` (Habel et al.
  2013, Eq. 8-12, as pbrt writes them);
* single scattering (``BeamDiffusionSS``): 100 depths
  :math:`t = t_c - \ln(1 - (i + \tfrac12)/100)/\sigma_t` below the critical depth
  :math:`t_c = r\sqrt{\eta^2 - 1}`, each contributing
  :math:`\rho\,e^{-\sigma_t(d + t_c)}\,p(\cos\theta_o)\,(1 - F_r)\,|\cos\theta_o|/d^2` with
  the Henyey-Greenstein phase function p (Habel et al. 2013, Eq. 16).

The table holds :math:`2\pi r\,(R_{SS} + R_{MS})` at albedos
:math:`\rho_i = (1 - e^{-8i/99})/(1 - e^{-8})` and radii :math:`r_0 = 0`,
:math:`r_1 = 0.0025`, :math:`r_{j+1} = 1.2 r_j`, with the total (``rhoEff``) of each row
integrated exactly for its spline (``IntegrateCatmullRom``). A medium reads it
(``TabulatedBSSRDF::Sr``) with :math:`\rho = \sigma_s/\sigma_t` and
:math:`r_{opt} = \sigma_t r` (unreduced: :math:`\sigma_s = \sigma'_s/(1 - g)`):
:math:`R(r) = \sigma_t^2\,\mathrm{spline}(\rho, r_{opt})/(2\pi r_{opt})`, 0 beyond the
last radius (about 203 optical radii), so that its total is the interpolated ``rhoEff``.
The Fresnel moments here are integrated exactly where pbrt uses polynomial fits.

References
----------
R. Habel, P. H. Christensen, W. Jarosz: Photon beam diffusion: a hybrid Monte Carlo
method for subsurface scattering. Computer Graphics Forum 32(4), 2013.
M. Pharr, W. Jakob, G. Humphreys: Physically Based Rendering, 4th ed., Sect. 11.4
(pbrt-v4 ``src/pbrt/bssrdf.cpp``: ``BeamDiffusionMS``, ``BeamDiffusionSS``,
``ComputeBeamDiffusionBSSRDF``; ``util/math.h``: ``CatmullRomWeights``,
``IntegrateCatmullRom``).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from ...errors import InputError
from ..fresnel import fresnel_reflectance
from ..homogeneous import Dipole
from .base import LookupProfile
from .boundary import boundary_factor, exitance_weights
from .sampling import LogRadialTable, geometric_nodes

__all__ = [
    "ALBEDO_SAMPLES",
    "RADIUS_SAMPLES",
    "BeamDiffusionTable",
    "PhotonBeamDiffusionProfile",
    "beam_diffusion_multiple",
    "beam_diffusion_single",
    "beam_diffusion_table",
    "catmull_rom_weights",
    "integrate_catmull_rom",
]

#: pbrt-v4's table size (``BSSRDFTable(100, 64)``).
ALBEDO_SAMPLES = 100
RADIUS_SAMPLES = 64
#: Depth samples of each integral (pbrt-v4's ``nSamples``).
DEPTH_SAMPLES = 100


def _henyey_greenstein(cos_theta, g):
    """pbrt-v4's ``HenyeyGreenstein(cosTheta, g)``, sr^-1."""
    denominator = 1.0 + g * g + 2.0 * g * cos_theta
    return (1.0 - g * g) / (4.0 * np.pi * denominator * np.sqrt(denominator))


def beam_diffusion_multiple(sigma_s, sigma_a, g, eta, r) -> np.ndarray:
    r"""Multiple-scattering exitance of a beam, pbrt-v4's ``BeamDiffusionMS``, mm^-2.

    Parameters
    ----------
    sigma_s, sigma_a : array_like
        Scattering and absorption coefficients, mm^-1 (unreduced); broadcast with ``r``.
    g : float
        Henyey-Greenstein asymmetry.
    eta : float
        Relative index (medium over outside).
    r : array_like
        Radii, mm.

    Returns
    -------
    ndarray
        :math:`R_{MS}(r)`, mm^-2.
    """
    sigma_s, sigma_a, r = np.broadcast_arrays(*(np.asarray(v, dtype=np.float64)
                                                for v in (sigma_s, sigma_a, r)))
    sigmap_s = sigma_s * (1.0 - g)
    sigmap_t = sigma_a + sigmap_s
    rhop = sigmap_s / sigmap_t
    d_g = (2.0 * sigma_a + sigmap_s) / (3.0 * sigmap_t * sigmap_t)  # Grosjean
    sigma_tr = np.sqrt(np.maximum(sigma_a / d_g, 0.0))
    c_phi, c_e = exitance_weights(eta)
    z_e = -2.0 * d_g * float(boundary_factor(eta))
    u = (np.arange(DEPTH_SAMPLES) + 0.5) / DEPTH_SAMPLES
    z_r = -np.log1p(-u) / sigmap_t[..., None]
    z_v = -z_r + 2.0 * z_e[..., None]
    r2 = (r * r)[..., None]
    d_r, d_v = np.sqrt(r2 + z_r * z_r), np.sqrt(r2 + z_v * z_v)
    s = sigma_tr[..., None]
    e_r, e_v = np.exp(-s * d_r), np.exp(-s * d_v)
    phi = (e_r / d_r - e_v / d_v) / (4.0 * np.pi * d_g[..., None])
    flux = (z_r * (1.0 + s * d_r) * e_r / d_r ** 3 - z_v * (1.0 + s * d_v) * e_v / d_v ** 3) \
        / (4.0 * np.pi)
    kappa = 1.0 - np.exp(-2.0 * sigmap_t[..., None] * (d_r + z_r))
    return np.mean(kappa * (rhop * rhop)[..., None] * (phi * c_phi + flux * c_e), axis=-1)


def beam_diffusion_single(sigma_s, sigma_a, g, eta, r) -> np.ndarray:
    r"""Single-scattering exitance of a beam, pbrt-v4's ``BeamDiffusionSS``, mm^-2.

    Parameters as :func:`beam_diffusion_multiple`.

    Returns
    -------
    ndarray
        :math:`R_{SS}(r)`, mm^-2.
    """
    sigma_s, sigma_a, r = np.broadcast_arrays(*(np.asarray(v, dtype=np.float64)
                                                for v in (sigma_s, sigma_a, r)))
    sigma_t = sigma_a + sigma_s
    rho = sigma_s / sigma_t
    t_crit = r * np.sqrt(max(eta * eta - 1.0, 0.0))
    u = (np.arange(DEPTH_SAMPLES) + 0.5) / DEPTH_SAMPLES
    t = t_crit[..., None] - np.log1p(-u) / sigma_t[..., None]
    d = np.sqrt((r * r)[..., None] + t * t)
    cos_o = t / d
    # light inside meets the boundary: relative index 1 / eta (pbrt: FrDielectric(-cos, eta))
    transmitted = 1.0 - fresnel_reflectance(1.0 / eta, cos_o)
    value = (rho[..., None] * np.exp(-sigma_t[..., None] * (d + t_crit[..., None])) / (d * d)
             * _henyey_greenstein(cos_o, g) * transmitted * np.abs(cos_o))
    return np.mean(value, axis=-1)


def integrate_catmull_rom(nodes, values) -> tuple[np.ndarray, np.ndarray]:
    """Integral and running integral of the Catmull-Rom spline through ``values``.

    pbrt-v4's ``IntegrateCatmullRom`` along the last axis: exact for the spline whose
    derivatives are the finite differences ``CatmullRomWeights`` uses.

    Parameters
    ----------
    nodes : ndarray, shape (n,)
        Increasing abscissae.
    values : ndarray, shape (..., n)

    Returns
    -------
    total : ndarray, shape (...)
    cumulative : ndarray, shape (..., n)
        0 at the first node.
    """
    x = np.asarray(nodes, dtype=np.float64)
    f = np.asarray(values, dtype=np.float64)
    width = np.diff(x)
    f0, f1 = f[..., :-1], f[..., 1:]
    d0 = np.empty_like(f0)
    d1 = np.empty_like(f0)
    d0[..., 0] = f1[..., 0] - f0[..., 0]
    d0[..., 1:] = width[1:] * (f[..., 2:] - f[..., :-2]) / (x[2:] - x[:-2])
    d1[..., -1] = f1[..., -1] - f0[..., -1]
    d1[..., :-1] = width[:-1] * (f[..., 2:] - f[..., :-2]) / (x[2:] - x[:-2])
    segments = ((d0 - d1) / 12.0 + (f0 + f1) * 0.5) * width
    cumulative = np.concatenate([np.zeros(f.shape[:-1] + (1,)), np.cumsum(segments, axis=-1)],
                                axis=-1)
    return cumulative[..., -1], cumulative


def catmull_rom_weights(nodes, x) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """pbrt-v4's ``CatmullRomWeights``, vectorised over ``x``.

    Parameters
    ----------
    nodes : ndarray, shape (n,)
        Increasing abscissae, n >= 2.
    x : array_like

    Returns
    -------
    offset : ndarray of int
        Index of the node before the interval's first (may be -1).
    weights : ndarray, shape x.shape + (4,)
        Weights of nodes offset .. offset + 3 (a weight of a node outside the table is 0).
    inside : ndarray of bool
        Where x lies within [nodes[0], nodes[-1]] (pbrt returns false elsewhere).
    """
    nodes = np.asarray(nodes, dtype=np.float64)
    x = np.asarray(x, dtype=np.float64)
    n = nodes.size
    inside = (x >= nodes[0]) & (x <= nodes[-1])
    idx = np.clip(np.searchsorted(nodes, x, side="right") - 1, 0, n - 2)
    x0, x1 = nodes[idx], nodes[idx + 1]
    t = np.where(inside, (x - x0) / (x1 - x0), 0.0)
    t2, t3 = t * t, t * t * t
    w = np.zeros(x.shape + (4,))
    w[..., 1] = 2 * t3 - 3 * t2 + 1
    w[..., 2] = -2 * t3 + 3 * t2
    first = idx > 0
    w0_inner = (t3 - 2 * t2 + t) * (x1 - x0) / (x1 - nodes[np.maximum(idx - 1, 0)])
    w0_edge = t3 - 2 * t2 + t
    w[..., 0] = np.where(first, -w0_inner, 0.0)
    w[..., 1] -= np.where(first, 0.0, w0_edge)
    w[..., 2] += np.where(first, w0_inner, w0_edge)
    last = idx + 2 < n
    w3_inner = (t3 - t2) * (x1 - x0) / (nodes[np.minimum(idx + 2, n - 1)] - x0)
    w3_edge = t3 - t2
    w[..., 1] -= np.where(last, w3_inner, w3_edge)
    w[..., 2] += np.where(last, 0.0, w3_edge)
    w[..., 3] = np.where(last, w3_inner, 0.0)
    return idx - 1, w, inside


@dataclass(frozen=True)
class BeamDiffusionTable:
    """pbrt-v4's ``BSSRDFTable`` for one (g, eta): see the module docstring."""

    g: float
    eta: float
    albedos: np.ndarray        # (100,) single-scattering albedos rho
    radii: np.ndarray          # (64,) optical radii
    profile: np.ndarray        # (100, 64) 2 pi r (R_SS + R_MS) in optical units
    total: np.ndarray          # (100,) rhoEff

    def row(self, albedo: float) -> tuple[np.ndarray, float]:
        """Return the profile row and its total at single-scattering albedo ``albedo``."""
        offset, weights, inside = catmull_rom_weights(self.albedos, albedo)
        if not inside:
            raise InputError("must lie in [0, 1]", field="albedo", value=albedo)
        rows = np.zeros(self.radii.size)
        total = 0.0
        for j in range(4):
            k = int(offset) + j
            if 0 <= k < self.albedos.size and weights[j] != 0:
                rows += weights[j] * self.profile[k]
                total += weights[j] * self.total[k]
        return rows, total


@lru_cache(maxsize=16)
def beam_diffusion_table(g: float = 0.0, eta: float = 1.33) -> BeamDiffusionTable:
    """Build pbrt-v4's table for ``g`` and ``eta`` (``ComputeBeamDiffusionBSSRDF``), cached.

    Parameters
    ----------
    g : float
        Henyey-Greenstein asymmetry, in (-1, 1).
    eta : float
        Relative index (medium over outside), > 0.

    Returns
    -------
    BeamDiffusionTable
    """
    radii = np.empty(RADIUS_SAMPLES)
    radii[0], radii[1] = 0.0, 2.5e-3
    for i in range(2, RADIUS_SAMPLES):
        radii[i] = radii[i - 1] * 1.2
    i = np.arange(ALBEDO_SAMPLES)
    albedos = (1.0 - np.exp(-8.0 * i / (ALBEDO_SAMPLES - 1))) / (1.0 - np.exp(-8.0))
    rho, r = albedos[:, None], radii[None, :]
    with np.errstate(divide="ignore", invalid="ignore"):
        values = (beam_diffusion_single(rho, 1.0 - rho, g, eta, r)
                  + beam_diffusion_multiple(rho, 1.0 - rho, g, eta, r))
    # rho = 0: nothing scatters (pbrt's 0/0 there is its ClampZero's business)
    profile = np.where(np.isfinite(values), 2.0 * np.pi * r * values, 0.0)
    total, _ = integrate_catmull_rom(radii, profile)
    for array in (albedos, radii, profile, total):
        array.flags.writeable = False
    return BeamDiffusionTable(float(g), float(eta), albedos, radii, profile, total)


class PhotonBeamDiffusionProfile(LookupProfile):
    """Photon beam diffusion (MS + SS) of a medium, read from pbrt-v4's table.

    Parameters
    ----------
    medium : Dipole
        sigma_a, sigma_s' (mm^-1), eta and g (the table is built for the medium's g and
        eta; sigma_s = sigma_s'/(1 - g)).

    Notes
    -----
    :meth:`reflection` reads a per-channel geometric table of the spline
    (:class:`~translucent.materials.profiles.sampling.LogRadialTable`);
    :meth:`reflection_spline` reads pbrt's spline itself.
    """

    model = "photon_beam_diffusion"
    summary = ("photon beam diffusion, multiple + single scattering (Habel et al. 2013), "
               "tabulated as pbrt-v4")
    derivation = ("rho = sigma_s/sigma_t and sigma_t = sigma_a + sigma_s with sigma_s = "
                  "sigma_s'/(1 - g); table per (g, eta) over 100 albedos x 64 optical radii, "
                  "Catmull-Rom in both; R(r) = sigma_t^2 spline(rho, sigma_t r) / "
                  "(2 pi sigma_t r)")

    def __init__(self, medium: Dipole):
        self.adopt(medium)
        self.table = beam_diffusion_table(float(medium.g), float(medium.eta))
        sigma_s = medium.sigma_s
        sigma_t = medium.sigma_a + sigma_s
        self.present = sigma_t > 0
        self.sigma_t = np.where(self.present, sigma_t, 1.0)
        self.albedo = np.where(self.present, sigma_s / self.sigma_t, 0.0)
        rows = [self.table.row(float(a)) for a in self.albedo]
        self.rows = np.stack([row for row, _ in rows])
        self.row_totals = np.array([np.where(p, total, 0.0)
                                    for (_, total), p in zip(rows, self.present, strict=True)])
        radius = geometric_nodes(self.length_scale())  # the spline is 0 beyond its reach
        exact = self.reflection_spline(radius.T[:, :, None])[..., 0, :]  # (K, 3 radii, 3)
        self.lookup = LogRadialTable(radius, np.stack([exact[:, c, c] for c in range(3)]))

    def reflection_spline(self, r) -> np.ndarray:
        """pbrt-v4's ``Sr``: the Catmull-Rom spline read at ``r`` (mm), shape ``r.shape + (3,)``."""
        r = np.asarray(r, dtype=np.float64)
        out = np.zeros(r.shape + (3,))
        for c in range(3):
            if not self.present[c]:
                continue
            optical = r * self.sigma_t[c]
            offset, weights, inside = catmull_rom_weights(self.table.radii, optical)
            value = np.zeros(r.shape)
            row = self.rows[c]
            for j in range(4):
                k = np.clip(offset + j, 0, row.size - 1)
                value += weights[..., j] * row[k]
            with np.errstate(divide="ignore", invalid="ignore"):
                value = np.where(optical > 0, value / (2.0 * np.pi * optical), value)
            out[..., c] = np.where(inside, np.maximum(value, 0.0), 0.0) * self.sigma_t[c] ** 2
        return out

    def total(self, kind: str = "reflection", max_radius: float | None = None) -> np.ndarray:
        """Return the interpolated ``rhoEff``: the spline's exact integral (pbrt's total)."""
        if kind == "reflection" and max_radius is None:
            return self.row_totals.copy()
        return super().total(kind, max_radius)

    def length_scale(self) -> np.ndarray:
        """Return the mean free path 1/sigma_t per channel, mm."""
        return 1.0 / self.sigma_t

    def cutoff_radius(self) -> np.ndarray:
        """Return the table's last optical radius over sigma_t, mm: 0 beyond."""
        return self.table.radii[-1] / self.sigma_t

    def parameters(self) -> dict[str, tuple[np.ndarray, str]]:
        """Return rho, sigma_t and the table's reach."""
        return {"rho": (self.albedo, ""), "sigma_t": (self.sigma_t, "mm^-1"),
                "last radius": (self.cutoff_radius(), "mm")}

    def cache_key(self) -> dict:
        """Return what identifies this profile in content hashes."""
        return {"type": self.model, "medium": self.medium.cache_key()}
