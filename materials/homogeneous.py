"""Material types without geometry: the homogeneous dipole medium and the Lambertian surface.

Immutable and validated on construction: a negative or non-finite coefficient raises
:class:`~translucent.errors.InputError` naming the field and the value.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import InputError, check_finite
from .dipole import (
    dipole_reflectance_profile,
    effective_transport_coefficient,
    mean_free_path,
    reduced_albedo,
    total_diffuse_reflectance,
)

__all__ = ["MAX_COEFFICIENT", "Dipole", "Lambertian", "rgb_field"]


#: Largest absorption or reduced scattering coefficient a Dipole takes, mm^-1: a mean free
#: path of a nanometre, far beyond any measured medium (the catalogue's densest is ~10^2),
#: and small enough that the products of coefficients the dipole and the float32 renderers
#: form (sigma_t^2, sigma_tr z) stay finite; 1e300 rendered an all-NaN image.
MAX_COEFFICIENT = 1e6


def rgb_field(value, field: str, *, minimum: float = 0.0, strict: bool = False, file=None,
              maximum: float | None = None) -> np.ndarray:
    """Validate a scalar or RGB triple and return it as a read-only float64 array of shape (3,).

    Raises
    ------
    InputError
        Wrong length, NaN/Inf, below ``minimum`` (or equal, with ``strict``), above ``maximum``.
    """
    array = np.asarray(value, dtype=np.float64)
    if array.ndim == 0:
        array = np.full(3, float(array))
    if array.shape != (3,):
        raise InputError("must be a number or an RGB triple", file=file, field=field, value=value)
    check_finite(array, field, file=file)
    if (array <= minimum).any() if strict else (array < minimum).any():
        relation = ">" if strict else ">="
        raise InputError(f"must be {relation} {minimum}", file=file, field=field, value=value)
    if maximum is not None and (array > maximum).any():
        raise InputError(f"must be <= {maximum}", file=file, field=field, value=value)
    array = array.copy()
    array.flags.writeable = False
    return array


@dataclass(frozen=True)
class Dipole:
    r"""A homogeneous translucent medium described by the dipole model.

    Parameters
    ----------
    sigma_a : float or (3,) array_like
        Absorption coefficient per RGB channel, mm^-1, >= 0.
    sigma_s_prime : float or (3,) array_like
        Reduced scattering coefficient :math:`\sigma'_s = (1 - g)\sigma_s`, mm^-1, >= 0.
    eta : float
        Relative index of refraction of the boundary, in [1, 3].
    g : float
        Henyey-Greenstein mean cosine used by the path-traced reference, in (-1, 1). The
        dipole sees only :math:`\sigma'_s`; the reference uses :math:`\sigma_s = \sigma'_s/(1-g)`.
    name : str, optional
        A label (the catalogue name for measured media).
    """

    sigma_a: np.ndarray
    sigma_s_prime: np.ndarray
    eta: float = 1.3
    g: float = 0.0
    name: str = ""

    def __post_init__(self):
        object.__setattr__(self, "sigma_a", rgb_field(self.sigma_a, "sigma_a",
                                                      maximum=MAX_COEFFICIENT))
        object.__setattr__(self, "sigma_s_prime", rgb_field(self.sigma_s_prime, "sigma_s_prime",
                                                            maximum=MAX_COEFFICIENT))
        eta = float(check_finite(self.eta, "eta"))
        if not 1.0 <= eta <= 3.0:
            raise InputError("must be in [1, 3]", field="eta", value=self.eta)
        g = float(check_finite(self.g, "g"))
        if not -1.0 < g < 1.0:
            raise InputError("must be in (-1, 1)", field="g", value=self.g)
        object.__setattr__(self, "eta", eta)
        object.__setattr__(self, "g", g)

    @property
    def sigma_s(self) -> np.ndarray:
        r"""Scattering coefficient :math:`\sigma_s = \sigma'_s / (1 - g)`, mm^-1."""
        return self.sigma_s_prime / (1.0 - self.g)

    @property
    def sigma_t(self) -> np.ndarray:
        r"""Extinction coefficient :math:`\sigma_t = \sigma_a + \sigma_s`, mm^-1."""
        return self.sigma_a + self.sigma_s

    @property
    def albedo(self) -> np.ndarray:
        r"""Single-scattering albedo :math:`\sigma_s / \sigma_t` (0 where :math:`\sigma_t = 0`)."""
        return reduced_albedo(self.sigma_a, self.sigma_s)

    @property
    def sigma_tr(self) -> np.ndarray:
        """Effective transport coefficient, mm^-1 (see :func:`effective_transport_coefficient`)."""
        return effective_transport_coefficient(self.sigma_a, self.sigma_s_prime)

    @property
    def mean_free_path(self) -> np.ndarray:
        """Reduced mean free path ``1 / sigma_t'``, mm."""
        return mean_free_path(self.sigma_a, self.sigma_s_prime)

    def profile(self, r) -> np.ndarray:
        """:math:`R_d(r)` in mm^-2 for distances ``r`` (mm); shape ``r.shape + (3,)``."""
        r = np.asarray(r, dtype=np.float64)[..., None]
        return dipole_reflectance_profile(r, self.sigma_a, self.sigma_s_prime, self.eta)

    def total_diffuse_reflectance(self) -> np.ndarray:
        """Closed-form total diffuse reflectance per channel (dimensionless)."""
        return total_diffuse_reflectance(self.sigma_a, self.sigma_s_prime, self.eta)

    def cache_key(self) -> dict:
        """Return what identifies this material in content hashes."""
        return {"type": "dipole", "sigma_a": self.sigma_a.tolist(),
                "sigma_s_prime": self.sigma_s_prime.tolist(), "eta": self.eta, "g": self.g}


@dataclass(frozen=True)
class Lambertian:
    """An opaque diffuse surface.

    Parameters
    ----------
    albedo : float or (3,) array_like
        Diffuse reflectance per RGB channel, in [0, 1].
    name : str, optional
    """

    albedo: np.ndarray
    name: str = ""

    def __post_init__(self):
        object.__setattr__(self, "albedo", rgb_field(self.albedo, "albedo", maximum=1.0))

    def cache_key(self) -> dict:
        """Return what identifies this material in content hashes."""
        return {"type": "lambertian", "albedo": self.albedo.tolist()}
