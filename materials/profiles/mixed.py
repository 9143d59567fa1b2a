r"""Heterogeneous objects: one profile per face label, mixed by Eq. 16 of Sheng et al. 2014.

References
----------
Sheng, Shi, Wang, Narasimhan: Translucent radiosity. IEEE TVCG 20(7), 2014, Sect. 3.3, Eq. 16.
"""

from __future__ import annotations

import numpy as np

from ...errors import InputError
from ..homogeneous import Dipole, Lambertian
from .base import RadialProfile, require_radial
from .classical_dipole import DipoleProfile

__all__ = ["HETEROGENEOUS_RULES", "RULE_MAX_MEDIA", "MixedProfiles", "geometric_mean_profile",
           "mixed_profile", "profile_for", "segment_average_profile"]

#: The rules by which a method mixes the media of a heterogeneous object into the profile
#: between an entry and an exit point, by name. Each method says which it follows; the
#: BSSRDF path tracer renders each exactly, so that a method's error on a solid medium
#: splits into its rule's and its own.
HETEROGENEOUS_RULES = {
    "geometric_mean": "Chen et al. 2012, Eq. 8: sqrt(P_xi(r) P_xo(r)), P the profile of the "
                      "medium at each surface point",
    "segment_mix": "Sheng et al. 2014, Eq. 16: the media along the straight segment from "
                   "x_i to x_o, mixed by the fraction of its length in each",
    "segment_average": "the classical dipole of one medium whose coefficients are those of "
                       "the media along the straight segment from x_i to x_o, averaged by "
                       "the fraction of its length in each (beyond the papers)",
}


def segment_average_profile(sigma_a, sigma_s_prime, fractions, r, eta) -> np.ndarray:
    r"""Mix by the ``segment_average`` rule: the dipole of the length-averaged medium.

    .. math:: R(r) = R_d\Big(r;\ \sum_m f_m \sigma_{a,m},\ \sum_m f_m \sigma'_{s,m}\Big)

    with :math:`R_d` the classical dipole (Jensen et al. 2001) and :math:`f_m` the fraction
    of the straight segment between the two points in medium m. Light that diffuses from
    one point to the other crosses the media in between; the profile of their mean
    coefficients is the first-order (Born) estimate of that transport, where Eq. 16 of
    Sheng et al. 2014 multiplies profiles at partial distances. One medium gives its own
    dipole; reciprocal.

    Parameters
    ----------
    sigma_a, sigma_s_prime : ndarray, shape (M, 3)
        The media's coefficients, mm^-1.
    fractions : ndarray, shape (..., M)
        :math:`f_m`, summing to 1 over m.
    r : ndarray, shape (...)
        mm.
    eta : float

    Returns
    -------
    ndarray, shape (..., 3)
        mm^-2.
    """
    from ..dipole import dipole_reflectance_profile

    fractions = np.asarray(fractions, dtype=np.float64)
    mean_a = fractions @ np.asarray(sigma_a, dtype=np.float64)
    mean_s = fractions @ np.asarray(sigma_s_prime, dtype=np.float64)
    return dipole_reflectance_profile(np.asarray(r, dtype=np.float64)[..., None], mean_a,
                                      mean_s, eta)


#: Homogeneous media a heterogeneous object is reduced to, per rule: as many as the method
#: that follows the rule derives (splatting: a texture lookup per texel, many are cheap;
#: radiosity: Eq. 16 multiplies one factor per medium per pair). The BSSRDF path tracer
#: reduces a solid medium as the method does.
RULE_MAX_MEDIA = {"geometric_mean": 64, "segment_mix": 16, "segment_average": 16}


def geometric_mean_profile(values_at_entry, values_at_exit) -> np.ndarray:
    r"""Mix two media's profiles by Chen et al. 2012, Eq. 8: :math:`\sqrt{P_{x_i}(r) P_{x_o}(r)}`.

    Parameters
    ----------
    values_at_entry, values_at_exit : ndarray, shape (..., 3)
        The profiles of the media at the entry and the exit point, at their distance r,
        mm^-2 (>= 0).

    Returns
    -------
    ndarray, shape (..., 3)
        mm^-2; the homogeneous profile where the two media are one.
    """
    return np.sqrt(np.asarray(values_at_entry, dtype=np.float64)
                   * np.asarray(values_at_exit, dtype=np.float64))


def profile_for(material, *, entry_fresnel: bool = True):
    """Return the radial profile of a scene material, or None for an opaque one.

    A :class:`RadialProfile` or :class:`MixedProfiles` is returned as is; a
    :class:`Dipole` becomes a
    :class:`DipoleProfile`; a :class:`Lambertian` (opaque, S = P in Sheng et al. 2014,
    Sect. 3.3) gives None.

    Raises
    ------
    InputError
        For a directional profile (the message names its radial average) and for any
        other material type (the message lists the accepted ones).
    """
    # a directional profile is refused with the way out (its radial average)
    require_radial(material, "material")
    if isinstance(material, (RadialProfile, MixedProfiles)):
        return material
    if isinstance(material, Dipole):
        return DipoleProfile(material, entry_fresnel=entry_fresnel)
    if isinstance(material, Lambertian):
        return None
    raise InputError("translucent radiosity takes a Dipole, a RadialProfile, MixedProfiles "
                     "or a Lambertian material", field="material",
                     value=type(material).__name__)


def mixed_profile(values_at_zero, values_at_distance, fractions) -> np.ndarray:
    r"""Mix profiles by the heterogeneous heuristic of Sheng et al. 2014, Eq. 16 (M materials).

    .. math::
        s = \Big(\sum_m S_m(0)\,\frac{r_m}{\sum r}\Big)\prod_m \frac{S_m(r_m)}{S_m(0)}

    with :math:`r_m` the distance light travels in material m. Eq. 16 is the case M = 2;
    a material not traversed (:math:`r_m = 0`) contributes a factor 1. Not physically
    accurate (the paper says so), but plausible.

    Parameters
    ----------
    values_at_zero : ndarray, shape (M, 3)
        :math:`S_m(0)`, mm^-2.
    values_at_distance : ndarray, shape (..., M, 3)
        :math:`S_m(r_m)` with :math:`r_m = f_m r`, mm^-2.
    fractions : ndarray, shape (..., M)
        :math:`f_m = r_m / \sum r`, >= 0, summing to 1 over m.

    Returns
    -------
    ndarray, shape (..., 3)
        mm^-2; equals the homogeneous profile when one fraction is 1.
    """
    zero = np.asarray(values_at_zero, dtype=np.float64)
    at = np.asarray(values_at_distance, dtype=np.float64)
    fractions = np.asarray(fractions, dtype=np.float64)[..., None]
    with np.errstate(invalid="ignore", divide="ignore"):
        ratio = np.where(zero > 0, at / np.where(zero > 0, zero, 1.0), 0.0)
    ratio = np.where(fractions > 0, ratio, 1.0)
    return np.sum(zero * fractions, axis=-2) * np.prod(ratio, axis=-2)


class MixedProfiles:
    """A heterogeneous object: one homogeneous profile per face label (Sheng et al. 2014, Eq. 16).

    Each face of the object's mesh carries a label m that selects ``profiles[m]``; between
    two points the profiles are mixed by :func:`mixed_profile` with the fractions of the
    path that run through each material (the paper's checkerboard block, Fig. 4).

    Parameters
    ----------
    profiles : sequence of RadialProfile or Dipole
        The homogeneous materials (Dipoles become :class:`DipoleProfile`).
    face_labels : array_like of int, shape (F,)
        Material of each face, in [0, len(profiles)).
    name : str, optional
    volume_labels : callable, optional
        ``volume_labels(points) -> labels``: the material inside the object at points in
        scene units, where the object has one (a solid medium,
        :mod:`translucent.fast.solid_inputs`). Eq. 16's fractions are then read along the
        segment through the volume, the distance light travels in each material; without
        it, from the nearest labelled face (the paper's surface-labelled block).
    volume_key : optional
        What identifies ``volume_labels`` in content hashes.

    Raises
    ------
    InputError
        Fewer than one profile, a label out of range, or an opaque material among them.
    """

    def __init__(self, profiles, face_labels, *, name: str = "", volume_labels=None,
                 volume_key=None):
        converted = []
        for index, material in enumerate(profiles):
            profile = profile_for(material)
            if profile is None:
                raise InputError("every material of a heterogeneous object must be "
                                 "translucent (a Dipole or a RadialProfile)",
                                 field=f"profiles[{index}]", value=type(material).__name__)
            converted.append(profile)
        if not converted:
            raise InputError("needs at least one profile", field="profiles", value=[])
        labels = np.asarray(face_labels)
        if labels.ndim != 1 or not np.issubdtype(labels.dtype, np.integer):
            raise InputError("must be a 1D array of integer labels, one per face",
                             field="face_labels", value=labels.shape)
        if labels.min() < 0 or labels.max() >= len(converted):
            raise InputError(f"labels must lie in [0, {len(converted) - 1}]",
                             field="face_labels", value=[int(labels.min()), int(labels.max())])
        if volume_labels is not None and not callable(volume_labels):
            raise InputError("must be callable (points -> labels)", field="volume_labels",
                             value=type(volume_labels).__name__)
        self.profiles = tuple(converted)
        self.face_labels = labels.astype(np.int64)
        self.name = name or "mixed"
        self.volume_labels = volume_labels
        self.volume_key = volume_key

    def cache_key(self) -> dict:
        """Return what identifies this material in content hashes."""
        return {"type": "mixed", "profiles": [p.cache_key() for p in self.profiles],
                "face_labels": self.face_labels, "volume": self.volume_key}
