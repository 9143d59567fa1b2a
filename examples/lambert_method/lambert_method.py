"""Translucent objects as opaque Lambertian surfaces: the approximation before any BSSRDF.

Each translucent (dipole) object is shaded as a diffuse surface whose albedo is the dipole's
total diffuse reflectance R_d (Jensen et al. 2001, Eq. 15 integrated over the surface);
Lambertian objects keep their albedo. Only point lights, with shadows, and no interreflection:
the outgoing radiance of a pixel is

    L = R_d / pi * sum_lights I cos(theta) / d^2      (visible lights only)

It is an example of a fast method kept outside the suite, registered through the
``translucent.methods`` entry point (see this folder's pyproject.toml).
"""

from __future__ import annotations

import numpy as np
from translucent.errors import InputError
from translucent.fast.base import Refusal, StageLog, applicability
from translucent.fast.knobs import Knob, KnobSpec
from translucent.image import Image
from translucent.materials import Dipole, Lambertian
from translucent.scenes import PointLight, gbuffer, visible

#: The knobs, declared once: checks, `translucent approx lambert` flags and cache keys
#: all follow from it.
KNOBS = KnobSpec([Knob("shadows", True, "cast shadow rays to the lights", kind="bool")])
DEFAULT_KNOBS = KNOBS.defaults

#: Cheap knobs for smoke runs: the defaults are already cheap.
QUICK_KNOBS = {"shadows": True}


def applies_to(scene):
    """None when every light is a point light and every material a Dipole or Lambertian."""
    for light in scene.lights:
        if not isinstance(light, PointLight):
            return Refusal("unsupported_light",
                           f"a {type(light).__name__}: this method takes point lights only")
    for obj in scene.objects:
        if not isinstance(obj.material, (Dipole, Lambertian)):
            return Refusal("unsupported_material",
                           f"object '{obj.name}' has a {type(obj.material).__name__} material")
    if not scene.lights:
        return Refusal("no_light", "the scene has no light")
    return None


def scored_objects(scene):
    """Every object is shaded."""
    return [obj.name for obj in scene.objects]


def _albedo(material) -> np.ndarray:
    if isinstance(material, Dipole):
        return np.asarray(material.total_diffuse_reflectance(), dtype=np.float64)
    return np.asarray(material.albedo, dtype=np.float64)


class LambertState:
    """The camera's first hits, kept for relighting and editing."""

    def __init__(self, scene, knobs):
        self.scene, self.knobs = scene, knobs
        self.log = StageLog()
        if not knobs["shadows"]:
            self.log.skip("no shadow rays: the knob shadows is false")
        self.view = gbuffer(scene)
        self.lights = tuple(scene.lights)
        self.materials = {o.name: o.material for o in scene.objects}

    def render(self, lights=None, material=None) -> Image:
        """Shade the kept hits; ``material`` replaces every translucent object's material."""
        if lights is not None:
            self.lights = tuple(lights)
            if any(not isinstance(light, PointLight) for light in self.lights):
                raise InputError("point lights only", field="lights", value=self.lights)
        if material is not None:
            for name, current in self.materials.items():
                if isinstance(current, Dipole):
                    self.materials[name] = material
        view = self.view
        height, width = view.hit.shape
        radiance = np.zeros((height, width, 3))
        hit = view.hit
        points, normals = view.position[hit], view.normal[hit]
        albedo = np.zeros((len(points), 3))
        for index, obj in enumerate(self.scene.objects):
            albedo[view.object_id[hit] == index] = _albedo(self.materials[obj.name])
        irradiance = np.zeros((len(points), 3))
        for light in self.lights:
            towards = light.position - points
            distance = np.linalg.norm(towards, axis=1)
            cosine = np.maximum(np.einsum("ij,ij->i", normals, towards) / distance, 0.0)
            lit = cosine > 0
            if self.knobs["shadows"] and lit.any():
                lit[lit] = visible(self.scene, points[lit], light.position,
                                   normals_a=normals[lit])
            irradiance += np.where(lit, cosine / distance**2, 0.0)[:, None] * light.intensity
        radiance[hit] = albedo / np.pi * irradiance
        return Image(radiance.astype(np.float32), metadata={"producer": "lambert"})


def precompute(scene, **knobs) -> LambertState:
    """Cast the camera's rays once (the only step that does not change with lights)."""
    resolved = KNOBS.resolve(knobs)
    reason = applicability(applies_to, scene)  # asked once per scene, however many ask
    if reason is not None:
        raise InputError(f"the lambert method does not apply: {reason}", field="scene",
                         value=scene.name)
    return LambertState(scene, resolved)
