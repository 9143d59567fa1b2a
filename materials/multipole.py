r"""Reflectance and transmittance profiles of a finite slab: the multipole of Donner & Jensen.

A slab of thickness :math:`d` (mm) between two boundaries of relative index
:math:`\eta` is modelled by the dipole of Jensen et al. 2001 mirrored about both
extrapolated boundaries: :math:`2n + 1` pairs of sources, for :math:`i = -n \dots n`,

.. math::
    z_{r,i} = 2i(d + 2 z_b) + \ell, \qquad z_{v,i} = 2i(d + 2 z_b) - \ell - 2 z_b,

with :math:`\ell = 1/\sigma'_t`, :math:`z_b = 2AD`, :math:`D = 1/(3\sigma'_t)` and
:math:`A = (1 + F_{dr})/(1 - F_{dr})`. The profiles (Donner & Jensen 2005, Eq. 11 and 12)
are, per unit power entering the slab, mm^-2,

.. math::
    R(r) = \frac{\alpha'}{4\pi}\sum_{i=-n}^{n}\Big[
        \frac{z_{r,i}(1 + \sigma_{tr} d_{r,i}) e^{-\sigma_{tr} d_{r,i}}}{d_{r,i}^3}
      - \frac{z_{v,i}(1 + \sigma_{tr} d_{v,i}) e^{-\sigma_{tr} d_{v,i}}}{d_{v,i}^3}\Big],
    \quad d_{\cdot,i} = \sqrt{r^2 + z_{\cdot,i}^2}

and :math:`T(r)` the same with :math:`z \to d - z` in the numerators and distances
measured from the far surface. The model is the diffusion approximation: it assumes the
slab is thicker than a transport mean free path :math:`\ell` (for :math:`d < \ell` the
real source lies outside the slab and T loses its meaning). With :math:`n = 0` and
:math:`d \to \infty`, :math:`R` is Eq. 2 of Wang et al. 2008 (the dipole of
:mod:`translucent.materials.dipole`). :class:`translucent.materials.profiles.SlabProfile`
evaluates it for one material with a fixed pole count; fits evaluate it for many parameter
sets at once (the walkers of a fit), with the pole count chosen from the coefficients.

References
----------
C. Donner, H. W. Jensen: Light diffusion in multi-layered translucent materials.
ACM Transactions on Graphics 24(3) (SIGGRAPH 2005), Sect. 3, Eq. 11-12.
"""

from __future__ import annotations

import numpy as np

from .dipole import (
    dipole_boundary_factor,
    effective_transport_coefficient,
    reduced_albedo,
    reduced_extinction,
)

__all__ = ["multipole_profiles", "pole_count", "slab_reflectance_profile",
           "slab_transmittance_profile"]

#: Pole pairs are added until the next pair would contribute less than this fraction of the
#: dipole term (its source lies 2 (d + 2 z_b) further away: exp(-sigma_tr dz) (l / dz)^2).
#: Far from the incident point the far poles weigh relatively more; at 1e-8 the truncation
#: error stays below 1e-9 of the profile's peak out to 20 transport lengths.
POLE_TOLERANCE = 1e-8
#: Upper bound on pole pairs either side (a thin, non-absorbing slab needs the most).
MAX_POLES = 64


def pole_count(sigma_a, sigma_s_prime, eta, thickness_mm) -> int:
    """Count the mirrored pole pairs ``n`` either side needed for :data:`POLE_TOLERANCE`.

    Parameters
    ----------
    sigma_a, sigma_s_prime : array_like
        mm^-1 (any shape; the worst case over all entries is taken).
    eta : array_like
        Relative index of refraction.
    thickness_mm : float
        Slab thickness, mm.

    Returns
    -------
    int
        In [1, :data:`MAX_POLES`].
    """
    sigma_t_prime = reduced_extinction(sigma_a, sigma_s_prime)
    sigma_tr = effective_transport_coefficient(sigma_a, sigma_s_prime)
    ell = 1.0 / np.maximum(sigma_t_prime, 1e-300)
    z_b = 2.0 * dipole_boundary_factor(eta) * ell / 3.0
    period = 2.0 * (thickness_mm + 2.0 * z_b)
    # pair i lies ~ i * period away: exp(-sigma_tr i p) (l / (i p))^2 < tol
    i = np.arange(1, MAX_POLES + 1)[:, None]
    size = np.exp(-np.outer(i, np.ravel(sigma_tr * period)).reshape(i.size, -1)) * \
        (np.ravel(ell)[None, :] / (i * np.ravel(period)[None, :])) ** 2
    needed = (size >= POLE_TOLERANCE).sum(axis=0)
    return int(np.clip(needed.max(initial=0) + 1, 1, MAX_POLES))


def multipole_profiles(r, sigma_a, sigma_s_prime, eta, thickness_mm, *, poles=None,
                       transmission=True):
    r"""Reflectance and transmittance profiles :math:`R(r)`, :math:`T(r)` of a slab, mm^-2.

    Eq. 11-12 of Donner & Jensen 2005 (see the module docstring). Broadcasts ``r``
    against the coefficients like :func:`~translucent.materials.dipole_reflectance_profile`.

    Parameters
    ----------
    r : array_like
        Distance from the incident point (its projection, for T), mm.
    sigma_a, sigma_s_prime : array_like
        mm^-1, >= 0.
    eta : array_like
        Relative index of refraction of both boundaries, >= 1.
    thickness_mm : float
        Slab thickness d, mm, > 0.
    poles : int, optional
        Pole pairs either side (default: :func:`pole_count`).
    transmission : bool
        Also compute T (default); False returns ``(R, None)``.

    Returns
    -------
    (ndarray, ndarray or None)
        R and T in mm^-2 per unit power entering the slab.
    """
    r = np.asarray(r, dtype=np.float64)
    sigma_a = np.asarray(sigma_a, dtype=np.float64)
    sigma_s_prime = np.asarray(sigma_s_prime, dtype=np.float64)
    eta = np.asarray(eta, dtype=np.float64)
    d = float(thickness_mm)
    if poles is None:
        poles = pole_count(sigma_a, sigma_s_prime, eta, d)
    sigma_t_prime = reduced_extinction(sigma_a, sigma_s_prime)
    albedo = reduced_albedo(sigma_a, sigma_s_prime)
    sigma_tr = effective_transport_coefficient(sigma_a, sigma_s_prime)
    with np.errstate(divide="ignore"):
        ell = 1.0 / sigma_t_prime
    z_b = 2.0 * dipole_boundary_factor(eta) * ell / 3.0
    shape = np.broadcast_shapes(r.shape, albedo.shape, z_b.shape)
    reflect = np.zeros(shape)
    transmit = np.zeros(shape) if transmission else None
    r2 = r * r

    def term(z, height):
        dist = np.sqrt(r2 + height * height)
        return z * (1.0 + sigma_tr * dist) * np.exp(-sigma_tr * dist) / (dist * dist * dist)

    with np.errstate(invalid="ignore", divide="ignore", over="ignore", under="ignore"):
        for i in range(-poles, poles + 1):
            shift = 2.0 * i * (d + 2.0 * z_b)
            z_real = shift + ell
            z_virtual = shift - ell - 2.0 * z_b
            reflect = reflect + term(z_real, z_real) - term(z_virtual, z_virtual)
            if transmission:
                transmit = transmit + term(d - z_real, d - z_real) \
                    - term(d - z_virtual, d - z_virtual)
        scale = albedo / (4.0 * np.pi)
        # truncating the pole sum can leave values of order -1e-9 of the peak far out
        reflect = np.where(np.isfinite(reflect), np.clip(scale * reflect, 0.0, None), 0.0)
        if transmission:
            transmit = np.where(np.isfinite(transmit), np.clip(scale * transmit, 0.0, None),
                                0.0)
    return reflect, transmit


def slab_reflectance_profile(r, sigma_a, sigma_s_prime, eta, thickness_mm, *, poles=None):
    """:math:`R(r)` of a slab, mm^-2 (see :func:`multipole_profiles`)."""
    return multipole_profiles(r, sigma_a, sigma_s_prime, eta, thickness_mm, poles=poles,
                              transmission=False)[0]


def slab_transmittance_profile(r, sigma_a, sigma_s_prime, eta, thickness_mm, *, poles=None):
    """:math:`T(r)` of a slab, mm^-2 (see :func:`multipole_profiles`)."""
    return multipole_profiles(r, sigma_a, sigma_s_prime, eta, thickness_mm, poles=poles)[1]
