r"""The scene's lights as the point emitters splatting takes (one irradiance buffer each).

Chen et al. 2012 splat point and directional lights. Here a spot light is its point light
with the spot's angular fall-off, and an area light is ``area_light_points`` point
emitters, each with its own irradiance buffer (so each casts its own shadow, and together
they soften it):

* a rectangle of radiance :math:`L` and area :math:`A`: the centres of a grid of cells, each a
  Lambertian patch of intensity :math:`I(\omega) = L\,(A/K)\max(0, n\cdot\omega)` (one-sided,
  as the scene format and the reference have it);
* a sphere of radiance :math:`L` and radius :math:`\rho`: seen from outside it radiates
  :math:`L\pi\rho^2` in every direction, so it lights any surface that sees all of it as
  an isotropic point of that intensity at its centre does; the :math:`K` points share
  that intensity on the disc the sphere shows the object (stratified), which gives its
  penumbrae.

A receiver close to an area light (within a few times its size) differs from these points
most; the error against the count is measured in docs/splatting.md.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from ...scenes.scene import PointLight, RectangularAreaLight, SphereAreaLight, SpotLight

__all__ = ["PointEmitter", "point_emitters", "AREA_LIGHTS"]

#: The area lights splatting turns into point emitters.
AREA_LIGHTS = (RectangularAreaLight, SphereAreaLight)

@dataclass(frozen=True)
class PointEmitter:
    """A point that emits ``intensity`` (W sr^-1, RGB) times ``falloff(directions)``.

    ``falloff`` takes unit directions leaving the point, shape (..., 3), and returns the
    relative intensity in [0, 1], shape (...); None: isotropic.
    """

    position: np.ndarray
    intensity: np.ndarray
    falloff: Callable | None = None


def point_emitters(light, count: int, towards) -> list[PointEmitter]:
    """Return the point emitters that stand for ``light`` for an object at ``towards``.

    Parameters
    ----------
    light : PointLight, SpotLight, RectangularAreaLight or SphereAreaLight
    count : int
        Points an area light is split into (>= 1).
    towards : (3,) scene units
        The lit object's centre (where a sphere light's disc faces).

    Returns
    -------
    list of PointEmitter
    """
    if isinstance(light, PointLight):
        return [PointEmitter(light.position, light.intensity)]
    if isinstance(light, SpotLight):
        return [PointEmitter(light.position, light.intensity, light.falloff)]
    uv = _stratified_square(count)
    if isinstance(light, RectangularAreaLight):
        points = (light.center + (2 * uv[:, :1] - 1) * light.u_axis
                  + (2 * uv[:, 1:] - 1) * light.v_axis)
        intensity = light.radiance * (light.area / len(points))
        normal = light.normal

        def lambertian(directions, normal=normal):
            return np.clip(np.asarray(directions) @ normal, 0.0, None)

        return [PointEmitter(point, intensity, lambertian) for point in points]
    if isinstance(light, SphereAreaLight):
        axis = np.asarray(towards, dtype=np.float64) - light.center
        length = float(np.linalg.norm(axis))
        axis = axis / length if length > 0 else np.array([0.0, 0.0, -1.0])
        helper = np.array([1.0, 0.0, 0.0]) if abs(axis[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
        tangent = np.cross(axis, helper)
        tangent /= np.linalg.norm(tangent)
        bitangent = np.cross(axis, tangent)
        disc = _concentric_disc(uv) if count > 1 else np.zeros((1, 2))
        points = light.center + light.radius * (disc[:, :1] * tangent + disc[:, 1:] * bitangent)
        intensity = light.radiance * (math.pi * light.radius ** 2 / len(points))
        return [PointEmitter(point, intensity) for point in points]
    raise TypeError(f"no point emitters for {type(light).__name__}")


def _stratified_square(count: int) -> np.ndarray:
    """Return the centres of ``count`` cells of a near-square grid on [0, 1)^2.

    Cell centres (the midpoint rule), not jittered points: one point is the emitter's
    centre, and every count places its points symmetrically about it. A last row that is
    not full is spread over the whole width, so the points always cover the square.
    """
    columns = int(math.ceil(math.sqrt(count)))
    rows = int(math.ceil(count / columns))
    points = []
    for row in range(rows):
        in_row = min(columns, count - row * columns)
        for column in range(in_row):
            points.append(((column + 0.5) / in_row, (row + 0.5) / rows))
    return np.array(points)


def _concentric_disc(uv: np.ndarray) -> np.ndarray:
    """Shirley and Chiu's concentric map of [0, 1)^2 onto the unit disc (area-preserving)."""
    a, b = 2.0 * uv[:, 0] - 1.0, 2.0 * uv[:, 1] - 1.0
    first = np.abs(a) > np.abs(b)
    safe_a = np.where(a == 0, 1.0, a)
    safe_b = np.where(b == 0, 1.0, b)
    radius = np.where(first, a, b)
    angle = np.where(first, (math.pi / 4) * (b / safe_a),
                     math.pi / 2 - (math.pi / 4) * (a / safe_b))
    radius = np.where((a == 0) & (b == 0), 0.0, radius)
    return np.stack([radius * np.cos(angle), radius * np.sin(angle)], axis=-1)
