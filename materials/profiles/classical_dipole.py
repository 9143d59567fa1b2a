r"""The classical dipole of Jensen et al. 2001 as a radial profile.

References
----------
Jensen, Marschner, Levoy, Hanrahan: A practical model for subsurface light transport.
SIGGRAPH 2001 (Eq. 4-6).
Sheng, Shi, Wang, Narasimhan: Translucent radiosity. IEEE TVCG 20(7), 2014, Sect. 6.1.
"""

from __future__ import annotations

import numpy as np

from ...errors import InputError
from ..dipole import (
    dipole_depths,
    dipole_reflectance_profile,
    effective_transport_coefficient,
    reduced_albedo,
)
from ..homogeneous import Dipole
from .base import RadialProfile, diffuse_entry_transmittance

__all__ = ["DipoleProfile"]


class DipoleProfile(RadialProfile):
    r"""The dipole reflection profile of a homogeneous medium (Jensen et al. 2001).

    :math:`s(r) = T_{in}\,R_d(r)` with :math:`R_d` the dipole diffuse reflectance
    (:func:`~translucent.materials.dipole_reflectance_profile`) and :math:`T_{in}` the
    fraction of diffuse light that crosses the boundary (:func:`diffuse_entry_transmittance`;
    1 when ``entry_fresnel`` is False). Sheng et al. 2014 compute the Cornell-box marble
    block's profile this way (Sect. 6.1). No transmission: a thick object.

    Parameters
    ----------
    dipole : Dipole
        The medium (mm^-1).
    entry_fresnel : bool
        Include the Fresnel transmittance of the diffuse irradiance at entry.

    Examples
    --------
    >>> from translucent.materials import measured_medium
    >>> profile = DipoleProfile(measured_medium("Marble"), entry_fresnel=False)
    >>> [round(float(v), 4) for v in profile.total()]
    [0.8302, 0.791, 0.7526]
    """

    model = "dipole"
    summary = "classical dipole (Jensen et al. 2001, Eq. 4-5; total Eq. 6)"
    derivation = ("sigma_tr = sqrt(3 sigma_a sigma_t'), z_r = 1/sigma_t', "
                  "z_v = z_r (1 + 4A/3) with A = (1 + F_dr)/(1 - F_dr) and F_dr Egan and "
                  "Hilgeman's polynomial in eta; alpha' = sigma_s'/sigma_t'")

    def __init__(self, dipole: Dipole, *, entry_fresnel: bool = True):
        if not isinstance(dipole, Dipole):
            raise InputError("expected a Dipole", field="dipole", value=type(dipole).__name__)
        self.dipole = dipole
        self.entry_fresnel = bool(entry_fresnel)
        self.name = dipole.name or "dipole"
        self.entry = float(diffuse_entry_transmittance(dipole.eta)) if entry_fresnel else 1.0

    def reflection(self, r) -> np.ndarray:
        """:math:`T_{in} R_d(r)`, mm^-2, shape ``r.shape + (3,)``."""
        r = np.asarray(r, dtype=np.float64)
        d = self.dipole
        # channels as rows (numpy's loops then run along the radii); the same arithmetic
        # element by element as broadcasting r[..., None] against the RGB coefficients
        values = dipole_reflectance_profile(r.reshape(1, -1), d.sigma_a[:, None],
                                            d.sigma_s_prime[:, None], d.eta)
        return self.entry * np.ascontiguousarray(values.T).reshape(r.shape + (3,))

    def total(self, kind: str = "reflection", max_radius: float | None = None) -> np.ndarray:
        """Return the closed form (Jensen et al. 2001, Eq. 6) when integrated to infinity."""
        if kind == "reflection" and max_radius is None:
            return self.entry * self.dipole.total_diffuse_reflectance()
        return super().total(kind, max_radius)

    def length_scale(self) -> np.ndarray:
        """Return the reduced mean free path 1/sigma_t' per channel, mm."""
        return self.dipole.mean_free_path

    def parameters(self) -> dict[str, tuple[np.ndarray, str]]:
        """Return alpha', sigma_tr, z_r and z_v per channel, and the entry transmittance."""
        d = self.dipole
        z_r, z_v = dipole_depths(d.sigma_a, d.sigma_s_prime, d.eta)
        return {"alpha'": (reduced_albedo(d.sigma_a, d.sigma_s_prime), ""),
                "sigma_tr": (effective_transport_coefficient(d.sigma_a, d.sigma_s_prime),
                             "mm^-1"),
                "z_r": (z_r, "mm"), "z_v": (z_v, "mm"),
                "entry transmittance": (np.full(3, self.entry), "")}

    def cache_key(self) -> dict:
        """Return what identifies this profile in content hashes."""
        return {"type": "dipole_profile", "dipole": self.dipole.cache_key(),
                "entry_fresnel": self.entry_fresnel}
