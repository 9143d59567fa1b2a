"""Ground truth: Mitsuba 3 volumetric path tracing and exact-BRDF reference renders."""

from .mitsuba_scene import (
    ConversionContext,
    MaterialParts,
    MitsubaConversion,
    convert_scene,
    register_material_converter,
    to_mitsuba_dict,
)
from .render import render

__all__ = [
    "ConversionContext",
    "MaterialParts",
    "MitsubaConversion",
    "convert_scene",
    "register_material_converter",
    "render",
    "to_mitsuba_dict",
]
