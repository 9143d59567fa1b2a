"""Radial scattering profiles, one module a profile, found by name.

A profile is made from a medium (:class:`~translucent.materials.homogeneous.Dipole`:
sigma_a, sigma_s', eta and g, RGB in mm^-1) and gives the radial reflectance R(r) per RGB
channel in mm^-2, its total diffuse reflectance, an inverse CDF in r to sample exit radii
with, and the radius holding 99 % of its energy (:class:`RadialProfile`, in
:mod:`~translucent.materials.profiles.base`). :func:`profile` finds one by name
(:data:`PROFILE_NAMES`; ``translucent profiles`` lists them).

This package only re-exports; each model lives in its own module.
"""

from .base import (
    PROFILE_KINDS,
    RadialGrid,
    RadialProfile,
    ScaledProfile,
    check_albedo,
    check_profile_values,
    diffuse_entry_transmittance,
    radial_cumulative_integral,
    require_radial,
    rgb_broadcast,
)
from .better_dipole import BetterDipoleProfile
from .burley import BurleyProfile
from .classical_dipole import DipoleProfile
from .directional_dipole import DirectionalDipoleAverage, DirectionalDipoleProfile
from .mixed import (
    HETEROGENEOUS_RULES,
    RULE_MAX_MEDIA,
    MixedProfiles,
    geometric_mean_profile,
    mixed_profile,
    profile_for,
    segment_average_profile,
)
from .photon_beam_diffusion import PhotonBeamDiffusionProfile
from .quantized_diffusion import QuantizedDiffusionProfile
from .random_walk import RandomWalkProfile
from .registry import PROFILE_NAMES, PROFILES, profile, profile_descriptions
from .slab import SlabProfile
from .tabulated import TabulatedProfile
from .two_exponential import TwoExponentialProfile

__all__ = [
    "PROFILES",
    "PROFILE_KINDS",
    "PROFILE_NAMES",
    "BetterDipoleProfile",
    "BurleyProfile",
    "DipoleProfile",
    "DirectionalDipoleAverage",
    "DirectionalDipoleProfile",
    "MixedProfiles",
    "PhotonBeamDiffusionProfile",
    "QuantizedDiffusionProfile",
    "RadialGrid",
    "RadialProfile",
    "RandomWalkProfile",
    "ScaledProfile",
    "SlabProfile",
    "TabulatedProfile",
    "TwoExponentialProfile",
    "check_albedo",
    "check_profile_values",
    "diffuse_entry_transmittance",
    "mixed_profile",
    "geometric_mean_profile",
    "segment_average_profile",
    "HETEROGENEOUS_RULES",
    "RULE_MAX_MEDIA",
    "profile",
    "profile_descriptions",
    "profile_for",
    "radial_cumulative_integral",
    "require_radial",
    "rgb_broadcast",
]
