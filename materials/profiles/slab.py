r"""Reflection and transmission of a finite slab: the multipole of Donner and Jensen.

References
----------
C. Donner, H. W. Jensen: Light diffusion in multi-layered translucent materials. SIGGRAPH
2005 (Eq. 8-11).
Sheng, Shi, Wang, Narasimhan: Translucent radiosity. IEEE TVCG 20(7), 2014, Sect. 5.2, 6.1.
"""

from __future__ import annotations

import numpy as np

from ...errors import InputError, check_finite
from ..homogeneous import Dipole
from ..multipole import multipole_profiles
from .base import RadialProfile, diffuse_entry_transmittance

__all__ = ["SlabProfile"]


class SlabProfile(RadialProfile):
    r"""Reflection and transmission of a slab of thickness ``d``: the multipole.

    Donner and Jensen 2005, Eq. 8-11, with the same boundary on both faces: dipole pairs
    at :math:`z_{r,i} = 2i(d + 2z_b) + \ell`, :math:`z_{v,i} = 2i(d + 2z_b) - \ell - 2z_b`,
    :math:`i = -n..n`, :math:`\ell = 1/\sigma'_t`, :math:`z_b = 2AD`, :math:`D = 1/(3\sigma'_t)`:

    .. math::
        R(r) = \frac{\alpha'}{4\pi}\sum_i \Big[\frac{z_{r,i}(1+\sigma_{tr}d_{r,i})
        e^{-\sigma_{tr}d_{r,i}}}{d_{r,i}^3} - \frac{z_{v,i}(1+\sigma_{tr}d_{v,i})
        e^{-\sigma_{tr}d_{v,i}}}{d_{v,i}^3}\Big]

    and :math:`T(r)` the same with :math:`z \to d - z`. For the thin sheets (petals) of
    Sheng et al. 2014, Sect. 5.2 and 6.1: same side by :math:`R`, other side by :math:`T`.
    The pair with :math:`i = 0` is the dipole of Jensen et al. 2001, so :math:`R \to R_d`
    as :math:`d \to \infty`.

    Parameters
    ----------
    dipole : Dipole
        The medium (mm^-1).
    thickness : float
        Slab thickness d, mm, larger than the reduced mean free path of every channel.
    pairs : int
        n, the number of image pairs on each side (>= 0); 5 is ample for d >= 1 mfp.
    entry_fresnel : bool
        Multiply by :func:`diffuse_entry_transmittance`, as :class:`DipoleProfile`.
    """

    has_transmission = True
    model = "slab"
    summary = "finite slab, reflection and transmission: the multipole (Donner and Jensen 2005)"
    derivation = ("dipole pairs mirrored about both extrapolated boundaries, z_b = 2AD, "
                  "D = 1/(3 sigma_t'), A = (1 + F_dr)/(1 - F_dr)")

    def __init__(self, dipole: Dipole, thickness: float, *, pairs: int = 5,
                 entry_fresnel: bool = True):
        if not isinstance(dipole, Dipole):
            raise InputError("expected a Dipole", field="dipole", value=type(dipole).__name__)
        thickness = float(check_finite(thickness, "thickness"))
        if thickness <= 0:
            raise InputError("must be > 0 mm", field="thickness", value=thickness)
        if int(pairs) != pairs or pairs < 0:
            raise InputError("must be an integer >= 0", field="pairs", value=pairs)
        longest = float(np.max(dipole.mean_free_path))
        if thickness <= longest:
            # the real source at depth 1/sigma'_t must lie inside the slab
            raise InputError(f"must exceed the reduced mean free path {longest:.4g} mm (the "
                             "diffusion source lies below a thinner slab)", field="thickness",
                             value=thickness)
        self.dipole = dipole
        self.thickness = thickness
        self.pairs = int(pairs)
        self.entry_fresnel = bool(entry_fresnel)
        self.name = f"{dipole.name or 'slab'} ({thickness:g} mm)"
        self.entry = float(diffuse_entry_transmittance(dipole.eta)) if entry_fresnel else 1.0

    def _profiles(self, r, transmission: bool):
        d = self.dipole
        r = np.asarray(r, dtype=np.float64)[..., None]
        reflect, transmit = multipole_profiles(r, d.sigma_a, d.sigma_s_prime, d.eta,
                                               self.thickness, poles=self.pairs,
                                               transmission=transmission)
        return self.entry * (transmit if transmission else reflect)

    def reflection(self, r) -> np.ndarray:
        """:math:`R(r)`, mm^-2, shape ``r.shape + (3,)`` (Donner and Jensen 2005, Eq. 10)."""
        return self._profiles(r, transmission=False)

    def transmission(self, r) -> np.ndarray:
        """:math:`T(r)`, mm^-2, shape ``r.shape + (3,)`` (Donner and Jensen 2005, Eq. 11)."""
        return self._profiles(r, transmission=True)

    def length_scale(self) -> np.ndarray:
        """Return the reduced mean free path 1/sigma_t' per channel, mm."""
        return self.dipole.mean_free_path

    def cache_key(self) -> dict:
        """Return what identifies this profile in content hashes."""
        return {"type": "slab_profile", "dipole": self.dipole.cache_key(),
                "thickness": self.thickness, "pairs": self.pairs,
                "entry_fresnel": self.entry_fresnel}
