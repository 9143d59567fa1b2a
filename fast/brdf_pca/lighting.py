"""Geometry and lights of BRDF editing with global illumination (Nguyen et al. 2010).

Oriented normals, tangent frames, hemisphere directions, ray visibility between samples,
and the direct light of every supported light at the gather samples.
"""

from __future__ import annotations

import math

import numpy as np

from ...errors import InputError
from ...scenes.lighting import ENVIRONMENT_LIGHTS, SAMPLED_LIGHTS, light_samples, tangent_frames
from .kernels import (
    front_counts,
    front_rays,
    gather_front_counts,
    gather_front_rays,
    gather_visibility,
)

# ---------------------------------------------------------------------------------------
# geometry helpers


def oriented_normals(normals, towards):
    """Flip unit normals to the side of the unit vectors ``towards``."""
    side = np.where(np.einsum("...d,...d->...", normals, towards) < 0, -1.0, 1.0)
    return normals * side[..., None]


def hemisphere_directions(normals, rng, exponent=None, axes=None):
    """Directions about ``normals``: uniform (exponent None) or power-cosine about ``axes``."""
    count = len(normals)
    u1, u2 = rng.random(count), rng.random(count)
    cos_t = u1 if exponent is None else u1 ** (1.0 / (exponent + 1.0))
    sin_t = np.sqrt(np.clip(1.0 - cos_t**2, 0.0, None))
    phi = 2.0 * math.pi * u2
    centre = normals if axes is None else axes
    first, second = tangent_frames(centre)
    return (cos_t[:, None] * centre + (sin_t * np.cos(phi))[:, None] * first
            + (sin_t * np.sin(phi))[:, None] * second)


def scene_ray_engine(scene):
    """Return the scene's ray engine and the offset its rays start at."""
    from ...scenes.raycast import OFFSET_FRACTION, ray_engine

    engine = ray_engine(scene)
    return engine, engine.diagonal * OFFSET_FRACTION


def occluded_rays(engine, origins, directions, reach) -> np.ndarray:
    """Any-hit tests of rays given as (3, N) float32 arrays, through the scene's engine."""
    # (N, 3) views of the (3, N) arrays: the Mitsuba engine's rays take their transposes,
    # so a batch within one of its calls is not copied
    return engine.occluded_unit(origins.T, directions.T, reach)


def pair_visibility(engine, offset, x, n_x, positions, normals):
    """Front-facing (view, gather) pairs of a block and whether each is unoccluded.

    Returns ``starts`` (B + 1,), the gather index of each pair and its visibility.
    """
    counts = np.zeros(len(x), dtype=np.int64)
    front_counts(x, n_x, positions, normals, counts)
    starts = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
    total = int(starts[-1])
    columns = np.empty(total, dtype=np.int64)
    origins = np.empty((3, total), dtype=np.float32)
    directions = np.empty((3, total), dtype=np.float32)
    reach = np.empty(total, dtype=np.float32)
    front_rays(x, n_x, positions, normals, offset, starts, columns, origins, directions, reach)
    seen = ~occluded_rays(engine, origins, directions, reach) | (reach == 0)
    return starts, columns, seen


def gather_pair_bits(count: int) -> np.ndarray:
    """Return the bitset :func:`gather_pair_visibility` keeps: a bit per unordered gather pair."""
    return np.zeros((count * (count - 1) // 2 + 7) // 8, dtype=np.uint8)


def gather_pair_visibility(engine, offset, positions, normals, first, stop, known):
    """Return :func:`pair_visibility` of gather rows ``first:stop``, each pair traced once.

    Visibility between two gathers is symmetric: the pair is front-facing both ways
    exactly (the offsets are ``d`` and ``-d``), and its two shadow rays run along one
    segment, each stopping ``offset`` short of the far end.
    Call with ``first`` increasing from 0 and one ``known`` (:func:`gather_pair_bits`):
    a pair with a later gather is traced and its answer kept there, one with an earlier
    gather reads the answer its reverse left. Half of the gather matrix's rays
    (Nguyen et al. 2010, Sect. 5.2) are saved.
    """
    counts = np.zeros(stop - first, dtype=np.int64)
    later = np.zeros(stop - first, dtype=np.int64)
    gather_front_counts(positions, normals, first, counts, later)
    starts = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
    later_starts = np.concatenate([[0], np.cumsum(later)]).astype(np.int64)
    total, rays = int(starts[-1]), int(later_starts[-1])
    columns = np.empty(total, dtype=np.int64)
    traced = np.empty(total, dtype=np.int64)
    origins = np.empty((3, rays), dtype=np.float32)
    directions = np.empty((3, rays), dtype=np.float32)
    reach = np.empty(rays, dtype=np.float32)
    gather_front_rays(positions, normals, offset, first, starts, later_starts, columns, traced,
                      origins, directions, reach)
    blocked = occluded_rays(engine, origins, directions, reach)
    seen = np.empty(total, dtype=bool)
    gather_visibility(first, starts, columns, traced, blocked, reach, known, seen)
    return starts, columns, seen


# ---------------------------------------------------------------------------------------
# lights


def check_lights(lights) -> None:
    """Refuse the lights the method does not take (environments), naming each."""
    for index, light in enumerate(lights):
        if isinstance(light, ENVIRONMENT_LIGHTS):
            raise InputError("environment lights are not supported by the BRDF-editing method "
                             "(point, spot, directional, rect and sphere lights are)",
                             field=f"lights[{index}]", value=type(light).__name__)
        if not isinstance(light, SAMPLED_LIGHTS):
            raise InputError("unknown light type", field=f"lights[{index}]",
                             value=type(light).__name__)


def _shadowed(engine, offset, points, normals, wi, reach, lit) -> np.ndarray:
    rows = np.flatnonzero(lit)
    origins = (points[rows] + offset * normals[rows]).T.astype(np.float32)
    blocked = np.zeros(len(points), dtype=bool)
    if len(rows):
        limit = np.minimum(np.maximum(reach[rows] - offset, 0.0), np.finfo(np.float32).max)
        blocked[rows] = occluded_rays(engine, origins, wi[rows].T.astype(np.float32),
                                      limit.astype(np.float32))
    return blocked


def direct_samples(scene, lights, points, normals, samples: int, seed: int):
    r"""Per point and light sample: the direction to the light and the irradiance it brings.

    Returns ``(wi, irradiance)`` of shapes (N, S, 3): the reflected radiance towards
    :math:`\omega_o` is :math:`\sum_s f(\omega_{i,s}, \omega_o) E_s`, shadows included.
    The samples are :func:`translucent.scenes.lighting.light_samples`'s: point, spot and
    directional lights exact, rectangles and spheres ``samples`` stratified samples each.
    """
    engine, offset = scene_ray_engine(scene)
    rng = np.random.default_rng(seed)
    directions, irradiance = [], []
    for light in lights:
        for sample in light_samples(light, points, count=samples, rng=rng, normals=normals):
            wi = np.ascontiguousarray(sample.direction)
            strength = np.clip(np.einsum("ij,ij->i", normals, wi), 0.0, None)
            brought = strength[:, None] * sample.irradiance
            lit = brought.max(axis=1) > 0
            brought[_shadowed(engine, offset, points, normals, wi, sample.distance, lit)] = 0
            directions.append(wi[:, None])
            irradiance.append(brought[:, None])
    if not directions:
        empty = np.zeros((len(points), 0, 3))
        return empty, empty
    return np.concatenate(directions, axis=1), np.concatenate(irradiance, axis=1)
