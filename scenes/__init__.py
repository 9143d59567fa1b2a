"""Where things are: meshes, lights, cameras, scene files and Mitsuba ray queries."""

from .scene import (
    Camera,
    ConstantEnvironment,
    DirectionalLight,
    ImageEnvironment,
    Mesh,
    PointLight,
    RectangularAreaLight,
    Scene,
    SceneObject,
    SphereAreaLight,
    SpotLight,
)

__all__ = [
    "Camera",
    "ConstantEnvironment",
    "DirectionalLight",
    "ImageEnvironment",
    "Mesh",
    "PointLight",
    "RectangularAreaLight",
    "Scene",
    "SceneObject",
    "SphereAreaLight",
    "SpotLight",
]
