r"""The better dipole of d'Eon 2012: Grosjean's diffusion coefficient, an exact boundary.

Against the classical dipole of Jensen et al. 2001 (:mod:`.classical_dipole`) it changes
three things, each from the medium (RGB, mm^-1):

* Grosjean's diffusion coefficient :math:`D = (2\sigma_a + \sigma'_s)/(3\sigma'^2_t)`
  (instead of :math:`1/(3\sigma'_t)`), and with it
  :math:`\sigma_{tr} = \sqrt{\sigma_a / D}`;
* the boundary: the exact Fresnel moments give :math:`A = (1 + 3C_2)/(1 - 2C_1)`, the
  extrapolated boundary :math:`z_b = 2AD` and the virtual source at
  :math:`z_v = -z_r - 2z_b` (:mod:`.boundary`);
* the exitance is :math:`C_\phi\,\phi + C_E\,E`: fluence and normal flux both count.

.. math::
    R(r) = \frac{\alpha'^2}{4\pi}\Big[\Big(\frac{C_\phi}{D} + C_E z_r\frac{1 + \sigma_{tr}
    d_r}{d_r^2}\Big)\frac{e^{-\sigma_{tr} d_r}}{d_r} - \Big(\frac{C_\phi}{D} + C_E z_v
    \frac{1 + \sigma_{tr} d_v}{d_v^2}\Big)\frac{e^{-\sigma_{tr} d_v}}{d_v}\Big]

with :math:`z_r = 1/\sigma'_t`, :math:`d_{r,v} = \sqrt{r^2 + z_{r,v}^2}` and
:math:`\alpha' = \sigma'_s/\sigma'_t` (the square: one albedo for the first interaction, one
for Grosjean's source, as pbrt-v4's ``BeamDiffusionMS`` and appleseed's
``BetterDipoleBSSRDF`` write it). Its integral over the plane is closed:

.. math::
    R_d = \frac{\alpha'^2}{2} e^{-\sigma_{tr} z_r}\Big[C_E\big(1 + e^{-4AD\sigma_{tr}}\big)
    + \frac{C_\phi}{D\sigma_{tr}}\big(1 - e^{-4AD\sigma_{tr}}\big)\Big]

(appleseed ``ComputeRdBetterDipole``; 1 at :math:`\alpha' = 1`, eta = 1).

References
----------
E. d'Eon: A better dipole. Technical note, 2012 (Eq. 5: D; Eq. 8-10: the boundary).
appleseed: ``renderer/modeling/bssrdf/betterdipolebssrdf.cpp`` and ``sss.cpp``.
"""

from __future__ import annotations

import numpy as np

from ..homogeneous import Dipole
from .base import MediumProfile, check_albedo
from .boundary import boundary_factor, exitance_weights

__all__ = ["BetterDipoleProfile", "better_dipole_total_reflectance", "grosjean_diffusion"]


def grosjean_diffusion(sigma_a, sigma_s_prime) -> np.ndarray:
    r"""Grosjean's diffusion coefficient :math:`D = (2\sigma_a + \sigma'_s)/(3\sigma'^2_t)`, mm.

    d'Eon 2012, Eq. 5 (pbrt-v4 ``BeamDiffusionMS``: ``D_g``). Infinite where
    :math:`\sigma'_t = 0`.

    Parameters
    ----------
    sigma_a, sigma_s_prime : array_like
        mm^-1, >= 0.

    Examples
    --------
    >>> float(grosjean_diffusion(0.0, 1.0))  # no absorption: the classical 1/(3 sigma_t')
    0.3333333333333333
    """
    sigma_a = np.asarray(sigma_a, dtype=np.float64)
    sigma_t = sigma_a + np.asarray(sigma_s_prime, dtype=np.float64)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(sigma_t > 0, (sigma_a + sigma_t) / (3.0 * sigma_t * sigma_t), np.inf)


def better_dipole_total_reflectance(reduced_albedo, eta) -> np.ndarray:
    r"""Total diffuse reflectance of the better dipole as a function of :math:`\alpha'`.

    The closed form of the module docstring in reduced units (:math:`\sigma'_t = 1`):
    :math:`D = (2 - \alpha')/3`, :math:`\sigma_{tr} = \sqrt{3(1-\alpha')/(2-\alpha')}`.

    Parameters
    ----------
    reduced_albedo : array_like
        :math:`\alpha' = \sigma'_s/\sigma'_t` in [0, 1].
    eta : array_like
        Relative index (medium over outside), > 0.

    Returns
    -------
    ndarray
        Dimensionless.

    Examples
    --------
    >>> round(float(better_dipole_total_reflectance(1.0, 1.0)), 12)
    1.0
    """
    albedo = check_albedo(reduced_albedo, "reduced_albedo")
    c_phi, c_e = exitance_weights(eta)
    a = boundary_factor(eta)
    d = (2.0 - albedo) / 3.0
    sigma_tr = np.sqrt((1.0 - albedo) / d)
    x = 4.0 * a * d * sigma_tr
    with np.errstate(divide="ignore", invalid="ignore"):
        # (1 - e^{-x}) / (D sigma_tr), 4 A at sigma_tr = 0
        fluence = np.where(sigma_tr > 0, -np.expm1(-x) / (d * sigma_tr), 4.0 * a)
    return 0.5 * albedo ** 2 * np.exp(-sigma_tr) * (c_e * (1.0 + np.exp(-x)) + c_phi * fluence)


class BetterDipoleProfile(MediumProfile):
    """The better dipole (d'Eon 2012) of a homogeneous medium; see the module docstring.

    Parameters
    ----------
    medium : Dipole
        sigma_a, sigma_s' (mm^-1) and eta; g enters only through sigma_s'.

    Examples
    --------
    >>> from translucent.materials import Dipole
    >>> profile = BetterDipoleProfile(Dipole(0.0, 1.0, eta=1.0))
    >>> [round(float(v), 9) for v in profile.total()]  # no absorption, no boundary: all
    [1.0, 1.0, 1.0]
    """

    model = "better_dipole"
    summary = "better dipole (d'Eon 2012): Grosjean's D, exact boundary, C_phi phi + C_E E"
    derivation = ("D = (2 sigma_a + sigma_s')/(3 sigma_t'^2), sigma_tr = sqrt(sigma_a / D), "
                  "z_r = 1/sigma_t', z_v = -z_r - 4AD with A = (1 + 3C_2)/(1 - 2C_1), "
                  "C_phi = (1 - 2C_1)/4, C_E = (1 - 3C_2)/2 from the exact Fresnel moments "
                  "at eta; alpha' = sigma_s'/sigma_t'")

    def __init__(self, medium: Dipole):
        self.adopt(medium)
        sigma_a, sigma_s = medium.sigma_a, medium.sigma_s_prime
        sigma_t = sigma_a + sigma_s
        self.present = sigma_t > 0  # a channel without a medium reflects nothing
        safe_t = np.where(self.present, sigma_t, 1.0)
        self.albedo = np.where(self.present, sigma_s / safe_t, 0.0)
        self.diffusion = np.where(self.present, grosjean_diffusion(sigma_a, sigma_s), 1.0)
        self.sigma_tr = np.sqrt(sigma_a / self.diffusion)
        self.c_phi, self.c_e = (float(c) for c in exitance_weights(medium.eta))
        self.boundary = float(boundary_factor(medium.eta))
        self.z_r = 1.0 / safe_t
        self.z_v = -self.z_r - 4.0 * self.boundary * self.diffusion

    def reflection(self, r) -> np.ndarray:
        """:math:`R(r)` of the module docstring, mm^-2, shape ``r.shape + (3,)``."""
        r = np.asarray(r, dtype=np.float64)
        # channels as rows: numpy's loops then run along the radii, not over 3 channels
        r2 = np.square(r.reshape(1, -1))
        out = np.zeros((3, r2.shape[1]))
        with np.errstate(invalid="ignore"):
            self._add_sources(r2, out)
        out *= (self.albedo ** 2 / (4.0 * np.pi))[:, None]
        np.maximum(out, 0.0, out=out)
        out[:, np.isinf(r.reshape(-1))] = 0.0  # infinitely far: nothing (not inf / inf)
        return np.ascontiguousarray(out.T).reshape(r.shape + (3,))

    def _add_sources(self, r2, out) -> None:
        """Add the real and subtract the virtual source's exitance at r^2 to ``out`` (3, N)."""
        sigma_tr = self.sigma_tr[:, None]
        c_phi_d = (self.c_phi / self.diffusion)[:, None]
        for z, sign in ((self.z_r[:, None], 1.0), (self.z_v[:, None], -1.0)):
            d = r2 + z * z
            np.sqrt(d, out=d)
            attenuation = np.multiply(d, -sigma_tr)
            np.exp(attenuation, out=attenuation)
            attenuation /= d
            weight = np.multiply(d, sigma_tr)
            weight += 1.0
            weight *= sign * self.c_e * z
            d *= d
            weight /= d
            weight += sign * c_phi_d
            attenuation *= weight
            out += attenuation

    def total(self, kind: str = "reflection", max_radius: float | None = None) -> np.ndarray:
        """Return the closed form of the module docstring (integral to infinity)."""
        if kind == "reflection" and max_radius is None:
            values = better_dipole_total_reflectance(self.albedo, self.medium.eta)
            return np.where(self.present, values, 0.0)
        return super().total(kind, max_radius)

    def length_scale(self) -> np.ndarray:
        """Return the reduced mean free path 1/sigma_t' per channel, mm."""
        return self.medium.mean_free_path

    def parameters(self) -> dict[str, tuple[np.ndarray, str]]:
        """Return alpha', D, sigma_tr, z_r, z_v, A, C_phi and C_E."""
        return {"alpha'": (self.albedo, ""), "D": (self.diffusion, "mm"),
                "sigma_tr": (self.sigma_tr, "mm^-1"), "z_r": (self.z_r, "mm"),
                "z_v": (self.z_v, "mm"), "A": (np.full(3, self.boundary), ""),
                "C_phi": (np.full(3, self.c_phi), ""), "C_E": (np.full(3, self.c_e), "")}

    def cache_key(self) -> dict:
        """Return what identifies this profile in content hashes."""
        return {"type": self.model, "medium": self.medium.cache_key()}
