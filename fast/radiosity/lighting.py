"""Direct lighting of patches and pixels: the irradiance E of Eq. 14."""

from __future__ import annotations

import numpy as np

from ...scenes.lighting import (
    ENVIRONMENT_LIGHTS,
    environment_radiance,
    rectangle_light_points,
)
from ...scenes.lighting import direct_irradiance as shared_direct_irradiance
from ...scenes.scene import RectangularAreaLight, SphereAreaLight
from .kernels import compiled_shadow_rays


def direct_irradiance(scene, points, normals, *, lights=None, samples: int = 16,
                      seed: int = 0, visible=None, trace=None, response=None) -> np.ndarray:
    """Irradiance from the lights at surface points, with shadows (W m^-2 in scene units).

    The :math:`E` of Sheng et al. 2014, Eq. 7 (per patch) and of the per-pixel direct
    lighting of diffuse surfaces (Sect. 6.1, the hybrid of [36], [37]): the light samples
    of :func:`translucent.scenes.lighting.direct_irradiance` (point, spot and directional
    lights exact; rectangles, spheres and environments with ``samples`` stratified
    samples per point, drawn from one generator seeded with ``seed``), shadowed by the
    ray queries below.

    Parameters
    ----------
    scene : Scene
    points, normals : ndarray, shape (N, 3)
        Scene units; unit normals on the lit side.
    lights : sequence, optional
        Default ``scene.lights``.
    samples : int
    seed : int
    visible, trace : callable, optional
        Ray queries (default :mod:`translucent.scenes.raycast`).
    response : callable, optional
        ``response(cosine) -> weight`` of each light sample (default the cosine): a
        dielectric boundary's directional entry passes ``F_t(eta, mu) mu``.

    Returns
    -------
    ndarray, shape (N, 3)
    """
    if visible is None or trace is None:
        from ...scenes import raycast

        visible = visible or raycast.visible
        trace = trace or raycast.trace
    lights = scene.lights if lights is None else tuple(lights)
    points = np.asarray(points, dtype=np.float64)
    normals = np.asarray(normals, dtype=np.float64)

    def occluded(rows, sample):
        if sample.target is None:  # infinitely far: any hit shadows
            return trace(scene, points[rows] + 1e-5 * normals[rows],
                         sample.direction[rows]).hit
        ends = sample.target if np.ndim(sample.target) == 1 else sample.target[rows]
        return ~visible(scene, points[rows], ends, normals_a=normals[rows])

    return shared_direct_irradiance(lights, points, normals, occluded=occluded, count=samples,
                                    rng=np.random.default_rng(seed), response=response)


class AreaLightShadows:
    """Surface points lit by rectangular area lights every frame: shadow rays without overhead.

    The per-frame part of :func:`direct_irradiance` (Sheng et al. 2014, Eq. 7, and the
    per-pixel direct light of Sect. 6.1) for points that stay put while the lights move:
    the offset ray origins of :func:`translucent.scenes.raycast.visible` are computed once,
    the cosines and the rays of all samples in two compiled loops, and every shadow ray of
    a light in one call of the ray engine. Same samples, same rays, same result as
    :func:`direct_irradiance` (up to float rounding).

    Parameters
    ----------
    scene : Scene
    points, normals : ndarray, (N, 3)
        Scene units; normals of unit length on the lit side.
    engine : {"auto", "embree", "mitsuba"}, optional
        Ray engine of the shadow rays (knob ``shadow_ray_engine``); default: the scene's.
    """

    def __init__(self, scene, points, normals, engine=None):
        from ...scenes.raycast import OFFSET_FRACTION, ray_engine

        self.scene = scene
        self.points = np.ascontiguousarray(points, dtype=np.float64)
        self.normals = np.ascontiguousarray(normals, dtype=np.float64)
        self.engine = ray_engine(scene, engine)
        # the offset of visible(): the bounding box, hence the diagonal, is every engine's
        self.offset = self.engine.diagonal * OFFSET_FRACTION
        # a lit point faces the light: visible() moves it along +normal
        length = np.linalg.norm(self.normals, axis=-1)
        self.starts = self.points + (self.offset / np.where(length > 0, length, 1.0))[:, None] \
            * self.normals

    @staticmethod
    def handles(lights) -> bool:
        """Return True when every light is a rectangular area light (else: the general path)."""
        return all(isinstance(light, RectangularAreaLight) for light in lights)

    def irradiance(self, lights, samples: int, seed: int) -> np.ndarray:
        """Irradiance at the points, (N, 3): :func:`direct_irradiance` for the same arguments."""
        strengths, rays = compiled_shadow_rays()
        rng = np.random.default_rng(seed)
        total = np.zeros((len(self.points), 3))
        strength = np.empty((len(self.points), samples))
        for light in lights:
            positions = rectangle_light_points(light, samples, rng)
            strengths(self.points, self.normals, positions,
                      np.asarray(light.normal, dtype=np.float64), strength)
            lit = np.flatnonzero(strength.ravel() > 0)
            origins = np.empty((len(lit), 3), dtype=np.float32)
            directions = np.empty((len(lit), 3), dtype=np.float32)
            tmax = np.empty(len(lit), dtype=np.float32)
            close = np.empty(len(lit), dtype=np.bool_)
            rays(self.starts, positions, lit, samples, self.offset, origins, directions, tmax,
                 close)
            blocked = self.engine.occluded_unit(origins, directions, tmax)
            strength.ravel()[lit[blocked & ~close]] = 0.0
            total += strength.sum(axis=1)[:, None] * (light.radiance * light.area / samples)
        return total


def emitters_seen(scene, gbuffer) -> np.ndarray:
    """Radiance of area lights and environments seen directly by the camera, (H, W, 3)."""
    image = np.zeros(gbuffer.shape + (3,))
    directions = -gbuffer.view_direction
    origin = scene.camera.origin
    depth = np.where(gbuffer.hit, gbuffer.depth, np.inf)
    for light in scene.lights:
        if isinstance(light, RectangularAreaLight):
            denominator = directions @ light.normal
            with np.errstate(divide="ignore", invalid="ignore"):
                t = ((light.center - origin) @ light.normal) / denominator
            point = origin + t[..., None] * directions
            u = (point - light.center) @ light.u_axis / (light.u_axis @ light.u_axis)
            v = (point - light.center) @ light.v_axis / (light.v_axis @ light.v_axis)
            seen = (denominator < 0) & (t > 0) & (t < depth) & (np.abs(u) <= 1) & (np.abs(v) <= 1)
            image[seen] = light.radiance
        elif isinstance(light, SphereAreaLight):
            relative = origin - light.center
            b = directions @ relative
            c = relative @ relative - light.radius**2
            disc = b * b - c
            t = -b - np.sqrt(np.clip(disc, 0.0, None))
            seen = (disc > 0) & (t > 0) & (t < depth)
            image[seen] = light.radiance
        elif isinstance(light, ENVIRONMENT_LIGHTS):
            background = ~gbuffer.hit
            image[background] += environment_radiance(light, directions[background])
    return image


