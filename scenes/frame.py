r"""The same physical scene in another length unit and origin.

A scene's length unit is the user's choice (``mm_per_unit``); its physics must not depend
on it. A renderer working in float32 does in one place: where a path crosses a surface it
restarts a little off it, by Mitsuba's ``spawn_ray`` offset of
:math:`\epsilon_{ray}\,(1 + \max_k |p_k|)` scene units along the normal
(:math:`\epsilon_{ray} = 1500 \cdot 2^{-24} \approx 8.9\cdot10^{-5}`). A path entering a
medium skips that shell: neither attenuated nor scattered there. The "1 +" makes the skipped
shell an absolute length: with the same object in smaller units (coordinates below one)
it is a larger part of the object, and in units a hundred times smaller a Skin1 sphere of
radius 10 mm lost 1.5 / 5.8 / 12 % (R G B) of its light (docs/references.md).

:func:`rendering_frame` puts the translucent objects' bounding box at the origin and scales
the scene by a power of two so that their bounding radius lies in ``(512, 1024]``
(:data:`FRAME_RADIUS`). There the "1 +" is below 0.2 % of the offset, so the shell is
:math:`\epsilon_{ray}` times the distance from the object's centre, whatever the user's
unit: the render no longer depends on the unit. A power of two scales a float exactly.

:meth:`Frame.apply` moves everything that carries a length: vertices, the camera, lights
(positions, axes and radii; a point or spot light's intensity by :math:`s^2`, so that its
irradiance :math:`I/d^2` stays), ``mm_per_unit`` (divided by :math:`s`), and a material's
own positions through its ``in_frame(origin, scale)`` method (a solid medium's box).
Radiances, irradiances and directions do not change.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..materials import Dipole
from ..materials.solid import SolidMedium
from ..materials.subedit import SubEditProfiles
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

__all__ = ["FRAME_RADIUS", "Frame", "rendering_frame", "translucent_object_indices"]

#: The bounding radius of the translucent objects in the rendering frame lies in
#: ``(FRAME_RADIUS / 2, FRAME_RADIUS]``: large enough that the ray offset's "1 +" is
#: negligible, far from float32's range.
FRAME_RADIUS = 1024.0


def translucent_object_indices(scene: Scene) -> list[int]:
    """Return the indices of the objects with a medium inside: Dipole, SubEdit or solid."""
    return [index for index, item in enumerate(scene.objects)
            if isinstance(item.material, (Dipole, SubEditProfiles, SolidMedium))]


@dataclass(frozen=True)
class Frame:
    r"""The map :math:`x' = (x - \text{origin})\,\text{scale}` of scene units.

    Parameters
    ----------
    origin : (3,) scene units
        The point that becomes the frame's origin.
    scale : float, > 0
        New units per old unit.
    """

    origin: tuple[float, float, float]
    scale: float

    def point(self, value) -> np.ndarray:
        """Return a position (or an array of them) in the frame."""
        return (np.asarray(value, dtype=np.float64) - np.asarray(self.origin)) * self.scale

    def to_scene(self, value) -> np.ndarray:
        """Return a position (or an array of them) of the frame in scene units."""
        return np.asarray(value, dtype=np.float64) / self.scale + np.asarray(self.origin)

    def matrix(self) -> np.ndarray:
        """Return the 4 x 4 homogeneous matrix from scene units to the frame."""
        out = np.diag([self.scale, self.scale, self.scale, 1.0])
        out[:3, 3] = -np.asarray(self.origin) * self.scale
        return out

    def apply(self, scene: Scene) -> Scene:
        """Return ``scene`` in this frame: the same physics, other numbers.

        Raises
        ------
        TypeError
            A light type this module does not know (a new light must say how it scales).
        """
        objects = []
        for obj in scene.objects:
            mesh = obj.mesh
            moved = Mesh(self.point(mesh.vertices), mesh.faces, mesh.normals, mesh.uv,
                         mesh.grid_shape, mesh.name)
            in_frame = getattr(obj.material, "in_frame", None)
            material = obj.material if in_frame is None else in_frame(self.origin, self.scale)
            objects.append(SceneObject(obj.name, moved, material))
        camera = scene.camera
        moved_camera = Camera(self.point(camera.origin), self.point(camera.target), camera.up,
                              camera.fov, camera.width, camera.height)
        return Scene(objects, [self._light(light) for light in scene.lights], moved_camera,
                     scene.mm_per_unit / self.scale, scene.name, scene.description,
                     scene.source)

    def _light(self, light):
        s = self.scale
        if isinstance(light, PointLight):
            return PointLight(self.point(light.position), light.intensity * s * s)
        if isinstance(light, SpotLight):
            return SpotLight(self.point(light.position), light.direction,
                             light.intensity * s * s, light.cutoff_angle, light.beam_width)
        if isinstance(light, RectangularAreaLight):
            return RectangularAreaLight(self.point(light.center), light.u_axis * s,
                                        light.v_axis * s, light.radiance)
        if isinstance(light, SphereAreaLight):
            return SphereAreaLight(self.point(light.center), light.radius * s, light.radiance)
        if isinstance(light, (DirectionalLight, ConstantEnvironment, ImageEnvironment)):
            return light
        raise TypeError(f"no frame change for a light of type {type(light).__name__}")


def rendering_frame(scene: Scene) -> Frame:
    """Return the frame a float32 renderer should see ``scene`` in (module docstring).

    Centred on the bounding box of the translucent objects (of every object when there is
    none), scaled by the power of two that brings their bounding radius into
    ``(FRAME_RADIUS / 2, FRAME_RADIUS]``.

    Examples
    --------
    >>> from translucent.scenes import load_scene
    >>> frame = rendering_frame(load_scene("sphere"))   # a unit sphere at the origin
    >>> frame.scale
    1024.0
    """
    indices = translucent_object_indices(scene) or range(len(scene.objects))
    vertices = np.concatenate([scene.objects[i].mesh.vertices for i in indices])
    low, high = vertices.min(axis=0), vertices.max(axis=0)
    centre = 0.5 * (low + high)
    radius = float(np.max(np.linalg.norm(vertices - centre, axis=1)))
    exponent = math.floor(math.log2(FRAME_RADIUS / radius)) if radius > 0 else 0
    return Frame(tuple(float(c) for c in centre), math.ldexp(1.0, exponent))
