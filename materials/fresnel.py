"""Fresnel terms of a smooth dielectric boundary.

References
----------
Jensen, Marschner, Levoy, Hanrahan: A practical model for subsurface light transport.
SIGGRAPH 2001 (the diffuse Fresnel polynomial, after Egan and Hilgeman 1979).
Wang et al.: Real-time editing and relighting of homogeneous translucent materials.
The Visual Computer 24 (2008), Sect. 3 (same polynomial, Eq. 2).
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["diffuse_fresnel_reflectance", "fresnel_reflectance", "fresnel_transmittance",
           "fresnel_transmittance_scalar", "transmitted_cosine"]


def float_dtype(*arrays) -> np.dtype:
    """float32 when every input is float32 (or narrower), float64 otherwise."""
    dtype = np.result_type(*[np.asarray(a) for a in arrays], np.float32)
    return dtype if dtype in (np.float32, np.float64) else np.dtype(np.float64)


def diffuse_fresnel_reflectance(eta):
    r"""Diffuse Fresnel reflectance :math:`F_{dr}(\eta)`, the polynomial fit.

    .. math:: F_{dr} = -1.440/\eta^2 + 0.710/\eta + 0.668 + 0.0636\,\eta

    (Jensen et al. 2001; Wang et al. 2008, Sect. 3.) Valid for :math:`\eta \ge 1`;
    broadcasts.

    Parameters
    ----------
    eta : array_like
        Relative index of refraction (inside over outside), dimensionless.

    Returns
    -------
    ndarray
        :math:`F_{dr}`, dimensionless; 0.0064 at eta = 1 (the fit's residual).
    """
    eta = np.asarray(eta, dtype=float_dtype(eta))
    return -1.440 / eta**2 + 0.710 / eta + 0.668 + 0.0636 * eta


def fresnel_reflectance(eta, cos_theta_i):
    r"""Unpolarised Fresnel reflectance of a smooth dielectric, exact.

    Light arrives from outside (index 1) at angle :math:`\theta_i` to the normal and meets
    a medium of relative index ``eta``. Total internal reflection (``eta < 1`` past the
    critical angle) gives 1.

    Parameters
    ----------
    eta : array_like
        Relative index of refraction, > 0.
    cos_theta_i : array_like
        Cosine of the incident angle, in [0, 1] (clipped there).

    Returns
    -------
    ndarray
        :math:`F_r \in [0, 1]`.
    """
    dtype = float_dtype(eta, cos_theta_i)
    eta = np.asarray(eta, dtype=dtype)
    cos_i = np.clip(np.asarray(cos_theta_i, dtype=dtype), 0.0, 1.0)
    # (1 - cos)(1 + cos) keeps its digits near normal incidence, where 1 - cos^2 cancels
    # x * x, not x**2: a 0-d array's power can differ from the product by an ulp, and
    # fresnel_transmittance_scalar (compiled kernels) multiplies
    sin2_t = (1.0 - cos_i) * (1.0 + cos_i) / (eta * eta)
    total = sin2_t >= 1.0
    cos_t = np.sqrt(np.clip(1.0 - sin2_t, 0.0, 1.0))
    with np.errstate(invalid="ignore", divide="ignore"):
        r_s = (cos_i - eta * cos_t) / (cos_i + eta * cos_t)
        r_p = (eta * cos_i - cos_t) / (eta * cos_i + cos_t)
        reflectance = 0.5 * (r_s * r_s + r_p * r_p)
    # cos_i = 0 and no TIR: grazing incidence reflects everything
    reflectance = np.where(np.isfinite(reflectance), reflectance, 1.0)
    return np.where(total, 1.0, np.clip(reflectance, 0.0, 1.0)).astype(dtype)


def fresnel_transmittance(eta, cos_theta):
    r"""Fresnel transmittance :math:`F_t(\eta, \cos\theta) = 1 - F_r`, exact.

    The :math:`F_t` of Eq. 1 of Wang et al. 2008 and Eq. 7 of Chen et al. 2012.

    Parameters
    ----------
    eta : array_like
        Relative index of refraction, > 0.
    cos_theta : array_like
        Cosine of the angle to the normal, in [0, 1].

    Returns
    -------
    ndarray
        :math:`F_t \in [0, 1]`.
    """
    return 1.0 - fresnel_reflectance(eta, cos_theta)


def transmitted_cosine(eta, cosine):
    r"""Return :math:`F_t(\eta, \mu)\,\mu` for :math:`\mu > 0`, 0 from below.

    The response of a surface behind a dielectric to light arriving at cosine
    :math:`\mu`: what enters, per unit irradiance on a surface facing the light (Eq. 6 of
    Wang et al. 2008).
    """
    cosine = np.asarray(cosine)
    return np.where(cosine > 0, fresnel_transmittance(eta, np.clip(cosine, 0.0, 1.0)) * cosine,
                    0.0)


def fresnel_transmittance_scalar(eta: float, cosine: float) -> float:
    r"""Fresnel transmittance :math:`F_t = 1 - F_r` of one cosine, in plain arithmetic.

    The operations of :func:`fresnel_transmittance` on one number (the same bits for
    ``eta`` > 0 and any ``cosine``, clipped to [0, 1]), written so that compiled kernels
    take this very function (``numba.njit(fresnel_transmittance_scalar)`` in
    :mod:`translucent.fast.splatting.buffer_kernels`) instead of a copy of the formula.
    0 at total internal reflection and at grazing incidence.

    Examples
    --------
    >>> round(fresnel_transmittance_scalar(1.3, 1.0), 6)
    0.982987
    """
    cos_i = 0.0 if cosine < 0.0 else (1.0 if cosine > 1.0 else cosine)
    # (1 - cos)(1 + cos) keeps its digits near normal incidence, where 1 - cos^2 cancels;
    # x * x, not x**2: numpy squares by multiplying, Python's pow() can differ by an ulp
    sin2_t = (1.0 - cos_i) * (1.0 + cos_i) / (eta * eta)
    if sin2_t >= 1.0:
        return 0.0
    under = 1.0 - sin2_t
    cos_t = math.sqrt(0.0 if under < 0.0 else (1.0 if under > 1.0 else under))
    divisor_s = cos_i + eta * cos_t
    divisor_p = eta * cos_i + cos_t
    if divisor_s == 0.0 or divisor_p == 0.0:
        return 0.0
    r_s = (cos_i - eta * cos_t) / divisor_s
    r_p = (eta * cos_i - cos_t) / divisor_p
    reflectance = 0.5 * (r_s * r_s + r_p * r_p)
    if not math.isfinite(reflectance):
        return 0.0
    return 1.0 - (0.0 if reflectance < 0.0 else (1.0 if reflectance > 1.0 else reflectance))

