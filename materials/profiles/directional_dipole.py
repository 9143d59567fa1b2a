r"""The directional dipole (Frisvad, Hachisuka, Kjeldsen 2014): the profile of a direction.

Light refracted into the medium along :math:`\omega_{12}` is a ray source; the diffusion
solution of a directional point source in an infinite medium (Menon et al.) at distance
:math:`d`, seen along :math:`x` from the source and through a surface of normal
:math:`n_o`, is

.. math::
    S'_d(x, \omega, d) = \frac{e^{-\sigma_{tr}d}}{d^3}\Big[C_\phi\Big(\frac{d^2}{D}
    + 3(1 + \sigma_{tr}d)\,x\cdot\omega\Big) - C_E\Big(3D(1 + \sigma_{tr}d)\,\omega\cdot n_o
    - \Big(1 + \sigma_{tr}d + \frac{3D}{d^2}\big(3(1 + \sigma_{tr}d) + (\sigma_{tr}d)^2\big)
    x\cdot\omega\Big)x\cdot n_o\Big)\Big]

and the profile is the real source minus its image,
:math:`R = \max(S'_d(x, \omega_{12}, d_r) - S'_d(x - 2Ad_e n, \omega_v, d_v), 0)/(4\pi)`,
per unit power entering (Frisvad et al.'s BSSRDF times
:math:`4\pi C_\phi(1/\eta)`, the integral of the exit Fresnel transmittance over the
cosine-weighted hemisphere). On a plane, with :math:`\mu_0 = -n\cdot\omega_{12}`:

* the real source lies at the corrected distance
  :math:`d_r^2 = r^2 + D\mu_0(D\mu_0 - 2d_e\cos\beta)`,
  :math:`\cos\beta = -\sqrt{(r^2 - (x\cdot\omega_{12})^2)/(r^2 + d_e^2)}`;
* the image at :math:`2Ad_e` above the point of incidence, direction :math:`\omega_{12}`
  mirrored in the surface, :math:`d_v^2 = r^2 + (2Ad_e)^2`;
* :math:`D = 1/(3\sigma'_t)`, :math:`\sigma_{tr} = \sqrt{\sigma_a/D}`, the extrapolation
  distance :math:`d_e = 2.131 D/\sqrt{\alpha'}` (Eq. 21), :math:`A = (1 - C_E)/(2C_\phi)`
  with the exact :math:`C_\phi(\eta), C_E(\eta)` (:mod:`.boundary`; the authors' code uses
  d'Eon's fits).

The profile depends on the direction of incidence: :class:`DirectionalDipoleProfile` is
not a radial profile and is refused where one is needed
(:func:`~translucent.materials.profiles.base.require_radial`); its azimuthal average
:meth:`DirectionalDipoleProfile.radial_average` is one.

References
----------
J. R. Frisvad, T. Hachisuka, T. K. Kjeldsen: Directional dipole model for subsurface
scattering. ACM Transactions on Graphics 34(1), 2014 (Sect. 4-5, Eq. 21).
appleseed: ``renderer/modeling/bssrdf/directionaldipolebssrdf.cpp``.
"""

from __future__ import annotations

import numpy as np

from ...errors import InputError, check_finite
from ..homogeneous import Dipole
from .base import LookupProfile, RadialProfile
from .boundary import boundary_factor, exitance_weights
from .sampling import LogRadialTable, geometric_nodes

__all__ = ["AZIMUTHS", "DirectionalDipoleAverage", "DirectionalDipoleProfile"]

#: Azimuths of the radial average on (0, pi) (the profile is even in the azimuth): the
#: midpoint rule of a periodic function, 1e-6 against 512 azimuths at 60 degrees incidence.
AZIMUTHS = 48


def _source_term(r2, x_dot_w, w_dot_n, x_dot_n, d, diffusion, sigma_tr, c_phi, c_e):
    """Frisvad et al.'s S'_d of the module docstring (without 1/(4 pi)), broadcast."""
    sd = sigma_tr * d
    one = 1.0 + sd
    return np.exp(-sd) / (d * d * d) * (
        c_phi * (d * d / diffusion + 3.0 * one * x_dot_w)
        - c_e * (3.0 * diffusion * one * w_dot_n
                 - (one + 3.0 * diffusion * (3.0 * one + sd * sd) / (d * d) * x_dot_w)
                 * x_dot_n))


class DirectionalDipoleProfile:
    """The directional dipole of a medium lit from ``incident_angle``; see the module docstring.

    Parameters
    ----------
    medium : Dipole
        sigma_a, sigma_s' (mm^-1), eta.
    incident_angle : float
        Angle of the incident light to the normal, outside the medium, radians in
        [0, pi/2); refracted by Snell's law. Its plane is the xz-plane (azimuth 0).

    Raises
    ------
    InputError
        A medium that is not a Dipole, an angle outside [0, pi/2), or a channel without
        scattering (the extrapolation distance divides by the albedo).
    """

    directional = True
    model = "directional_dipole"
    summary = ("directional dipole (Frisvad, Hachisuka, Kjeldsen 2014): a ray source along "
               "the refracted direction and its image")
    derivation = ("D = 1/(3 sigma_t'), sigma_tr = sqrt(sigma_a / D), d_e = 2.131 D / "
                  "sqrt(alpha'), A = (1 - C_E)/(2 C_phi), C_phi and C_E from the exact Fresnel "
                  "moments at eta; the incident direction refracted by eta")

    def __init__(self, medium: Dipole, incident_angle: float = 0.0):
        if not isinstance(medium, Dipole):
            raise InputError("expected a Dipole medium", field="medium",
                             value=type(medium).__name__)
        angle = float(check_finite(incident_angle, "incident_angle"))
        if not 0.0 <= angle < np.pi / 2:
            raise InputError("must lie in [0, pi/2) radians", field="incident_angle",
                             value=incident_angle)
        sigma_a, sigma_s = medium.sigma_a, medium.sigma_s_prime
        sigma_t = sigma_a + sigma_s
        if (sigma_s <= 0).any():
            raise InputError("the directional dipole needs sigma_s' > 0 in every channel (its "
                             "extrapolation distance is 2.131 D / sqrt(alpha'))",
                             field="sigma_s_prime", value=sigma_s)
        self.medium = medium
        self.incident_angle = angle
        self.name = f"{self.model} ({medium.name})" if medium.name else self.model
        self.albedo = sigma_s / sigma_t
        self.diffusion = 1.0 / (3.0 * sigma_t)
        self.sigma_tr = np.sqrt(sigma_a / self.diffusion)
        self.c_phi, self.c_e = (float(c) for c in exitance_weights(medium.eta))
        self.boundary = float(boundary_factor(medium.eta))
        self.extrapolation = 2.131 * self.diffusion / np.sqrt(self.albedo)
        sin_t = np.sin(angle) / medium.eta
        #: The refracted direction, pointing into the medium (z up out of the surface).
        self.direction = np.array([sin_t, 0.0, -np.sqrt(1.0 - sin_t * sin_t)])

    def evaluate(self, x, y) -> np.ndarray:
        """:math:`R` at the surface displacement (x, y) mm from the point of incidence.

        Parameters
        ----------
        x, y : array_like
            mm, broadcast together; x along the plane of incidence.

        Returns
        -------
        ndarray, shape ``broadcast(x, y).shape + (3,)``
            mm^-2, >= 0.
        """
        x, y = np.broadcast_arrays(np.asarray(x, dtype=np.float64),
                                   np.asarray(y, dtype=np.float64))
        x, y = x[..., None], y[..., None]
        r2 = x * x + y * y
        wx, _, wz = self.direction
        mu0 = -wz
        x_dot_w = x * wx
        d, de = self.diffusion, self.extrapolation
        with np.errstate(divide="ignore", invalid="ignore"):
            cos_beta = -np.sqrt(np.maximum(r2 - x_dot_w * x_dot_w, 0.0) / (r2 + de * de))
        d_r = np.sqrt(r2 + d * mu0 * (d * mu0 - 2.0 * de * cos_beta))
        real = _source_term(r2, x_dot_w, -mu0, 0.0, d_r, d, self.sigma_tr, self.c_phi,
                            self.c_e)
        height = 2.0 * self.boundary * de
        d_v = np.sqrt(r2 + height * height)
        # the image: direction mirrored in the surface, seen from 2 A d_e above
        image_x_dot_w = x_dot_w - height * mu0
        image = _source_term(r2, image_x_dot_w, mu0, -height, d_v, d, self.sigma_tr,
                             self.c_phi, self.c_e)
        return np.maximum(real - image, 0.0) / (4.0 * np.pi)

    def reflection(self, r):
        """Refuse: the profile depends on the direction; use :meth:`radial_average`."""
        raise InputError("a directional profile has no R(r) of the distance alone; use its "
                         "radial_average() or evaluate(x, y)", field="profile", value=self.name)

    def radial_average(self) -> DirectionalDipoleAverage:
        """Return the azimuthal average of :meth:`evaluate`: a radial profile."""
        return DirectionalDipoleAverage(self)

    def total(self) -> np.ndarray:
        """Return the total diffuse reflectance per channel (of the radial average)."""
        return self.radial_average().total()

    def parameters(self) -> dict[str, tuple[np.ndarray, str]]:
        """Return alpha', D, sigma_tr, d_e, A, C_phi, C_E and the refracted cosine."""
        return {"alpha'": (self.albedo, ""), "D": (self.diffusion, "mm"),
                "sigma_tr": (self.sigma_tr, "mm^-1"), "d_e": (self.extrapolation, "mm"),
                "A": (np.full(3, self.boundary), ""), "C_phi": (np.full(3, self.c_phi), ""),
                "C_E": (np.full(3, self.c_e), ""),
                "mu_0": (np.full(3, -self.direction[2]), "")}

    def describe(self) -> str:
        """Return what the profile is, its source, and its parameters from the medium."""
        return RadialProfile.describe(self)

    def cache_key(self) -> dict:
        """Return what identifies this profile in content hashes."""
        return {"type": self.model, "medium": self.medium.cache_key(),
                "incident_angle": self.incident_angle}


class DirectionalDipoleAverage(LookupProfile):
    """The azimuthal average of a :class:`DirectionalDipoleProfile`: a radial profile.

    Tabulated per channel on a geometric grid
    (:class:`~translucent.materials.profiles.sampling.LogRadialTable`); at normal incidence
    the directional dipole is radial already and one azimuth serves.

    Parameters
    ----------
    directional : DirectionalDipoleProfile
    """

    model = "directional_dipole"

    def __init__(self, directional: DirectionalDipoleProfile):
        self.directional_profile = directional
        self.medium = directional.medium
        self.name = f"{directional.name}, radial average"
        degrees = np.degrees(directional.incident_angle)
        self.summary = f"{directional.summary}; azimuthal average at {degrees:g} degrees"
        self.derivation = directional.derivation
        radius = geometric_nodes(self.length_scale())
        values = self.average(radius.T[:, :, None])[..., 0, :]
        self.lookup = LogRadialTable(radius, np.stack([values[:, c, c] for c in range(3)]))

    def average(self, r) -> np.ndarray:
        """Average over azimuth at ``r`` (mm) by the midpoint rule, ``r.shape + (3,)``."""
        r = np.asarray(r, dtype=np.float64)
        count = 1 if self.directional_profile.incident_angle == 0.0 else AZIMUTHS
        phi = np.pi * (np.arange(count) + 0.5) / count
        values = self.directional_profile.evaluate(r[..., None] * np.cos(phi),
                                                   r[..., None] * np.sin(phi))
        return values.mean(axis=-2)

    def parameters(self) -> dict[str, tuple[np.ndarray, str]]:
        """Return the directional profile's parameters."""
        return self.directional_profile.parameters()

    def cache_key(self) -> dict:
        """Return what identifies this profile in content hashes."""
        return {"type": "directional_dipole_average",
                "profile": self.directional_profile.cache_key()}
