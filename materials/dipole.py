r"""The dipole diffusion approximation of Jensen et al. 2001.

All lengths are in mm and all coefficients in mm^-1. Every function broadcasts over its
arguments (for example ``r`` of shape ``(N, 1)`` against RGB coefficients of shape
``(3,)``) and computes in float64 unless every input is float32.

References
----------
Jensen, Marschner, Levoy, Hanrahan: A practical model for subsurface light transport.
SIGGRAPH 2001.
Wang et al.: Real-time editing and relighting of homogeneous translucent materials.
The Visual Computer 24 (2008), Sect. 3, Eq. 2-3 (the form implemented here).
"""

from __future__ import annotations

import numpy as np

from .fresnel import diffuse_fresnel_reflectance, float_dtype

__all__ = [
    "reduced_extinction",
    "reduced_albedo",
    "effective_transport_coefficient",
    "mean_free_path",
    "dipole_boundary_factor",
    "dipole_depths",
    "dipole_reflectance_profile",
    "total_diffuse_reflectance",
]


def reduced_extinction(sigma_a, sigma_s_prime):
    r""":math:`\sigma'_t = \sigma_a + \sigma'_s` in mm^-1."""
    dtype = float_dtype(sigma_a, sigma_s_prime)
    return np.asarray(sigma_a, dtype) + np.asarray(sigma_s_prime, dtype)


def reduced_albedo(sigma_a, sigma_s_prime):
    r""":math:`\alpha' = \sigma'_s / \sigma'_t`, dimensionless; 0 where :math:`\sigma'_t = 0`."""
    dtype = float_dtype(sigma_a, sigma_s_prime)
    sigma_s_prime = np.asarray(sigma_s_prime, dtype)
    sigma_t_prime = reduced_extinction(sigma_a, sigma_s_prime)
    with np.errstate(invalid="ignore", divide="ignore"):
        albedo = sigma_s_prime / sigma_t_prime
    return np.where(sigma_t_prime > 0, albedo, 0.0).astype(dtype)


def effective_transport_coefficient(sigma_a, sigma_s_prime):
    r"""Effective transport coefficient :math:`\sigma_{tr} = \sqrt{3\sigma_a\sigma'_t}`.

    Jensen et al. 2001; Wang et al. 2008, text after Eq. 2. In mm^-1.
    """
    dtype = float_dtype(sigma_a, sigma_s_prime)
    return np.sqrt(3.0 * np.asarray(sigma_a, dtype) * reduced_extinction(sigma_a, sigma_s_prime))


def mean_free_path(sigma_a, sigma_s_prime):
    r"""Reduced mean free path :math:`\ell = 1/\sigma'_t` in mm (inf where it is 0)."""
    sigma_t_prime = reduced_extinction(sigma_a, sigma_s_prime)
    with np.errstate(divide="ignore"):
        return 1.0 / sigma_t_prime


def dipole_boundary_factor(eta):
    r""":math:`A = (1 + F_{dr}) / (1 - F_{dr})`, the internal-reflection factor of the boundary."""
    fdr = diffuse_fresnel_reflectance(eta)
    return (1.0 + fdr) / (1.0 - fdr)


def dipole_depths(sigma_a, sigma_s_prime, eta):
    r"""Source depths :math:`z_r = 1/\sigma'_t` and :math:`z_v = z_r(1 + 4A/3)`.

    In mm (Wang et al. 2008, text after Eq. 2).
    """
    z_r = mean_free_path(sigma_a, sigma_s_prime)
    z_v = z_r * (1.0 + 4.0 * dipole_boundary_factor(eta) / 3.0)
    return z_r, z_v


def dipole_reflectance_profile(r, sigma_a, sigma_s_prime, eta):
    r"""Diffuse reflectance profile :math:`R_d(r)` of the dipole, in mm^-2.

    Eq. 2 of Wang et al. 2008 (Jensen et al. 2001):

    .. math::
        R_d(r) = \frac{\alpha'}{4\pi}\Big[z_r(\sigma_{tr} + 1/d_r)\frac{e^{-\sigma_{tr} d_r}}{d_r^2}
        + z_v(\sigma_{tr} + 1/d_v)\frac{e^{-\sigma_{tr} d_v}}{d_v^2}\Big]

    with :math:`d_{r,v} = \sqrt{r^2 + z_{r,v}^2}`. Finite and non-negative for every
    ``r >= 0`` and every non-negative coefficient; 0 where :math:`\sigma'_s = 0`.

    Parameters
    ----------
    r : array_like
        Distance between the points of incidence and exit, mm, >= 0.
    sigma_a, sigma_s_prime : array_like
        Absorption and reduced scattering coefficients, mm^-1, >= 0.
    eta : array_like
        Relative index of refraction, >= 1.

    Returns
    -------
    ndarray
        :math:`R_d(r)` in mm^-2, broadcast shape of the inputs. Its integral over the plane,
        :math:`2\pi\int_0^\infty R_d(r) r\,dr`, is :func:`total_diffuse_reflectance`.
    """
    dtype = float_dtype(r, sigma_a, sigma_s_prime, eta)
    r = np.asarray(r, dtype)
    sigma_a = np.asarray(sigma_a, dtype)
    sigma_s_prime = np.asarray(sigma_s_prime, dtype)
    albedo = reduced_albedo(sigma_a, sigma_s_prime)
    sigma_tr = effective_transport_coefficient(sigma_a, sigma_s_prime)
    z_r, z_v = dipole_depths(sigma_a, sigma_s_prime, np.asarray(eta, dtype))
    with np.errstate(invalid="ignore", divide="ignore", over="ignore", under="ignore"):
        total = np.zeros(np.broadcast_shapes(r.shape, albedo.shape, z_v.shape), dtype)
        for z in (z_r, z_v):
            d = np.sqrt(r * r + z * z)
            total = total + z * (sigma_tr + 1.0 / d) * np.exp(-sigma_tr * d) / (d * d)
        profile = albedo / (4.0 * np.pi) * total
    # sigma'_t = 0 puts the sources at infinity: nothing comes back
    return np.where(np.isfinite(profile), profile, 0.0).astype(dtype)


def total_diffuse_reflectance(sigma_a, sigma_s_prime, eta):
    r"""Total diffuse reflectance :math:`R_d = 2\pi\int_0^\infty R_d(r)\,r\,dr`, closed form.

    Jensen et al. 2001, Eq. 6 (the integral of Eq. 2 of Wang et al. 2008):

    .. math::
        R_d = \frac{\alpha'}{2}\left(1 + e^{-\frac{4}{3}A\sqrt{3(1-\alpha')}}\right)
        e^{-\sqrt{3(1-\alpha')}}

    Parameters
    ----------
    sigma_a, sigma_s_prime : array_like
        mm^-1, >= 0.
    eta : array_like
        Relative index of refraction.

    Returns
    -------
    ndarray
        Dimensionless, in [0, 1).
    """
    dtype = float_dtype(sigma_a, sigma_s_prime, eta)
    sigma_a = np.asarray(sigma_a, dtype)
    sigma_t_prime = reduced_extinction(sigma_a, sigma_s_prime)
    albedo = reduced_albedo(sigma_a, sigma_s_prime)
    # 1 - alpha' as sigma_a / sigma_t' directly: the subtraction loses every digit when
    # the albedo is close to 1 (float32 rounds 1 - 1e-9 to 1)
    with np.errstate(invalid="ignore", divide="ignore"):
        one_minus_albedo = np.where(sigma_t_prime > 0, sigma_a / sigma_t_prime, 1.0)
    root = np.sqrt(3.0 * one_minus_albedo)
    boundary = dipole_boundary_factor(np.asarray(eta, dtype))
    total = 0.5 * albedo * (1.0 + np.exp(-4.0 / 3.0 * boundary * root)) * np.exp(-root)
    return total.astype(dtype)
