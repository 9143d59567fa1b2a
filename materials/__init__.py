"""The physics of a material, with no geometry (imports numpy and scipy only)."""

from .catalogue import MEASURED_MEDIA, measured_medium, measured_medium_names
from .dipole import (
    dipole_reflectance_profile,
    effective_transport_coefficient,
    mean_free_path,
    total_diffuse_reflectance,
)
from .fresnel import diffuse_fresnel_reflectance, fresnel_reflectance, fresnel_transmittance
from .homogeneous import Dipole, Lambertian

__all__ = [
    "MEASURED_MEDIA",
    "Dipole",
    "Lambertian",
    "diffuse_fresnel_reflectance",
    "dipole_reflectance_profile",
    "effective_transport_coefficient",
    "fresnel_reflectance",
    "fresnel_transmittance",
    "mean_free_path",
    "measured_medium",
    "measured_medium_names",
    "total_diffuse_reflectance",
]
