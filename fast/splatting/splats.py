"""Effective rendering ranges and the splatting kernels (Chen et al. 2012, Eq. 12-15)."""

from __future__ import annotations

import functools
import math

import numpy as np

from ...errors import InputError
from ...materials.subedit import SubEditProfiles
from .backend_drjit import DrJitKernel
from .buffers import CameraModel, SurfaceBuffer
from .knobs import BUCKET_RATIO, PAIR_CHUNK
from .radius_table import RenderingRadiusTable
from .selection import IrradianceSamples


def effective_rendering_ranges(samples: IrradianceSamples, material: SubEditProfiles,
                               table: RenderingRadiusTable, camera: CameraModel, *,
                               mm_per_unit: float, levels: int, multiresolution: bool = True,
                               near: float = 1e-6) -> np.ndarray:
    r"""Eq. 13 of Chen et al. 2012: :math:`[R^k_{min}, R^k_{max})` of each sample at each level.

    :math:`R^k_{min} = R_{P_{x_i}}\bar R(T^k(x_i))` with
    :math:`T^k(x_i) = T^k R_{P_{x_i}} / (2\tan(\mathrm{fov}/2) z(x_i))`, :math:`T^k` the width
    in pixels of splatting level :math:`k`; :math:`R^0_{min} = 0`,
    :math:`R^k_{max} = R^{k+1}_{min}`, :math:`R^{n-1}_{max} = R_{P_{x_i}}`. Without
    multiresolution level 0 takes :math:`[0, R_{P_{x_i}})`.

    Returns
    -------
    ndarray (N, levels + 1)
        Boundaries in scene units: level ``k`` covers ``[out[:, k], out[:, k + 1])``.
    """
    ranges = material.effective_scattering_range.reshape(-1)[samples.texel] / mm_per_unit
    bounds = np.zeros((len(samples), levels + 1))
    bounds[:, levels] = ranges
    if not multiresolution or levels == 1:
        bounds[:, 1:] = ranges[:, None]
        return bounds
    z = np.maximum(np.abs(camera.depth(samples.position)), near)
    for k in range(1, levels):
        width_k = max(1, camera.width >> k)
        resolution = width_k * ranges / (2.0 * camera.tan_half_fov * z)
        bounds[:, k] = ranges * table(resolution)
    for k in range(2, levels):  # running maximum (np.maximum.accumulate along rows is slow)
        np.maximum(bounds[:, k - 1], bounds[:, k], out=bounds[:, k])
    return bounds


@functools.lru_cache(maxsize=64)
def _disc_offsets(radius: int) -> tuple[np.ndarray, np.ndarray]:
    span = np.arange(-radius, radius + 1)
    dx, dy = np.meshgrid(span, span)
    inside = dx * dx + dy * dy <= (radius + 0.75) ** 2
    return dx[inside].astype(np.int64), dy[inside].astype(np.int64)


def _bucket_radii(limit: int) -> np.ndarray:
    radii = [1]
    while radii[-1] < limit:
        radii.append(max(radii[-1] + 1, int(math.ceil(radii[-1] * BUCKET_RATIO))))
    return np.asarray(radii, dtype=np.int64)


def evaluate_pairs(table, step_inverse, segments, distance, texel_in, texel_out):
    """sqrt(P_i(d) P_o(d)) for pairs (Eq. 8 with Eq. 9), float32, shape (M, 3); 0 at r >= r_s."""
    position = distance * step_inverse
    inside = position < segments
    position = np.where(inside, position, 0.0)
    k = np.minimum(position.astype(np.int64), segments - 1)
    weight = (position - k)[:, None].astype(np.float32)
    start_i = table[texel_in, k]
    end_i = table[texel_in, k + 1]
    start_o = table[texel_out, k]
    end_o = table[texel_out, k + 1]
    log_value = 0.5 * ((start_i + start_o) + weight * ((end_i + end_o) - (start_i + start_o)))
    value = np.exp(log_value)
    return np.where(inside[:, None], value, 0.0)


def splat_level(samples: IrradianceSamples, bounds_low: np.ndarray, bounds_high: np.ndarray,
                level: SurfaceBuffer, level_texel: np.ndarray, material: SubEditProfiles,
                camera: CameraModel, *, mm_per_unit: float, backend: str = "numpy",
                stats: dict | None = None) -> np.ndarray:
    r"""Splat samples into one splatting level (Eq. 12 of Chen et al. 2012).

    For every sample :math:`x_i` and every valid pixel :math:`x_o` of the level whose
    surface point lies at a distance :math:`d \in [R^k_{min}, R^k_{max})`:
    :math:`B^k(x_o) \mathrel{+}= \sqrt{P_{x_o}(d) P_{x_i}(d)}\,E(x_i)\Delta A_{x_i}`.
    The pixels visited are those of a disc around the sample's projection whose radius
    bounds the projection of a sphere of radius :math:`R^k_{max}` (then the 3D distance
    decides).

    Returns
    -------
    ndarray (H_k, W_k, 3)
        :math:`B^k` in flux per scene unit squared.
    """
    height, width = level.shape
    exitance = np.zeros((height * width, 3), dtype=np.float64)
    if not len(samples) or not level.valid.any():
        return exitance.reshape(height, width, 3)
    from .backend_numba import splat_windows

    limit = max(width, height)
    index, centre_x, centre_y, radius, reach_pixels = splat_windows(
        samples.position, samples.flux, bounds_low, bounds_high,
        *(np.asarray(vector, dtype=np.float64) for vector in (
            camera.origin, camera.forward, camera.right, camera.up)),
        float(camera.tan_half_fov), width, height)
    if not len(index):
        return exitance.reshape(height, width, 3)
    scale = float(mm_per_unit) ** 2  # mm^-2 -> per scene unit squared
    kernels = {"numba": None, "cuda": None, "numpy": _NumpyKernel, "drjit": DrJitKernel}
    if backend not in kernels:
        raise InputError(f"unknown backend; valid: {', '.join(kernels)}", field="backend",
                         value=backend)
    if kernels[backend] is None:
        exitance, pairs = _splat_tiled(samples, bounds_low, bounds_high, level, level_texel,
                                       material, mm_per_unit, scale, index, centre_x,
                                       centre_y, reach_pixels, gpu=backend == "cuda")
        if stats is not None:
            stats["pairs"] = stats.get("pairs", 0) + pairs[0]
            stats["pairs in range"] = stats.get("pairs in range", 0) + pairs[1]
        return exitance
    buckets = _bucket_radii(limit)
    bucket_of = np.searchsorted(buckets, radius.astype(np.int64))
    kernel = kernels[backend](samples, bounds_low, bounds_high, level, level_texel, material,
                              mm_per_unit, scale)
    pairs = 0
    for bucket in np.unique(bucket_of):
        members = bucket_of == bucket
        dx, dy = _disc_offsets(int(buckets[bucket]))
        pairs += int(members.sum()) * len(dx)
        kernel.splat(index[members], np.floor(centre_x[members]).astype(np.int64),
                     np.floor(centre_y[members]).astype(np.int64), dx, dy)
    if stats is not None:
        stats["pairs"] = stats.get("pairs", 0) + pairs
    return kernel.result().reshape(height, width, 3)


def _splat_tiled(samples, bounds_low, bounds_high, level, level_texel, material, mm_per_unit,
                 scale, index, centre_x, centre_y, radius, gpu=False):
    """Run the tiled kernels of :func:`splat_level` (numba on the CPU, or CUDA).

    Samples are binned to tiles (:func:`.backend_numba.bin_samples`), then splatted
    (:func:`.backend_numba.splat_tiles`); with ``gpu`` both run on the device
    (:func:`.backend_cuda.bin_and_splat_tiles`).
    """
    from . import backend_numba as kernels

    height, width = level.shape
    position, texel, tile_bounds, tiles_y, tiles_x = kernels.tile_layout(
        np.moveaxis(level.position, -1, 0), level_texel, level.valid)
    sample_position = np.ascontiguousarray(np.take(samples.position, index, axis=0).T,
                                           dtype=np.float32)
    low2 = np.square(bounds_low[index]).astype(np.float32)
    high2 = np.square(bounds_high[index]).astype(np.float32)
    window = (centre_x.astype(np.float32), centre_y.astype(np.float32),
              # the surface point of a pixel of a coarser level is one of its finest
              # children's: it projects inside the pixel, within sqrt(2)/2 of its centre;
              # 1e-3 and 1e-5 cover the float32 rounding of the bound
              (radius * (1.0 + 1e-5) + (0.5 * math.sqrt(2.0) + 1e-3)).astype(np.float32))
    profile = (subedit_segment_table(material),
               np.float32(material.segments / (material.r_s / mm_per_unit)), sample_position,
               samples.texel[index].astype(np.int32),
               np.ascontiguousarray(np.take(samples.flux, index, axis=0) * scale,
                                    dtype=np.float32), low2, high2)
    out = np.empty(position.shape, dtype=np.float32)
    if gpu:
        from .backend_cuda import bin_and_splat_tiles

        used, binned = bin_and_splat_tiles(out, position, texel, tile_bounds, tiles_x,
                                           *profile, *window)
    else:
        start, members = kernels.bin_samples(tile_bounds, tiles_y, tiles_x, sample_position,
                                             *window, low2, high2)
        used = kernels.splat_tiles(out, position, texel, *profile, start, members)
        binned = len(members)
    visited = binned * kernels.TILE ** 2
    return (kernels.untile_float64(out, tiles_x, height, width), [visited, int(used.sum())])


@functools.lru_cache(maxsize=16)
def subedit_segment_table(material: SubEditProfiles) -> np.ndarray:
    """Return the material's profile table in the kernels' segment layout (cached)."""
    from .backend_numba import segment_table

    return segment_table(material.flat_log_profile)


class _NumpyKernel:
    """The numpy kernel of :func:`splat_level`: pairs in chunks, accumulated by bincount."""

    def __init__(self, samples, bounds_low, bounds_high, level, level_texel, material,
                 mm_per_unit, scale):
        self.samples = samples
        self.bounds_low = bounds_low
        self.bounds_high = bounds_high
        self.height, self.width = level.shape
        self.valid = level.valid.reshape(-1)
        self.position = level.position.reshape(-1, 3)
        self.texel_out = level_texel.reshape(-1)
        self.material = material
        self.table = material.flat_log_profile.astype(np.float32)
        self.step_inverse = material.segments / (material.r_s / mm_per_unit)
        self.flux = samples.flux * scale
        self.exitance = np.zeros((len(self.valid), 3))

    def splat(self, index, column, row, dx, dy):
        """Splat samples ``index`` centred on pixels (column, row) over offsets (dx, dy)."""
        per_chunk = max(1, PAIR_CHUNK // len(dx))
        for start in range(0, len(index), per_chunk):
            part = slice(start, start + per_chunk)
            sample = np.repeat(index[part], len(dx))
            px = (column[part][:, None] + dx[None, :]).reshape(-1)
            py = (row[part][:, None] + dy[None, :]).reshape(-1)
            inside = (px >= 0) & (px < self.width) & (py >= 0) & (py < self.height)
            sample, px, py = sample[inside], px[inside], py[inside]
            pixel = py * self.width + px
            hit = self.valid[pixel]
            sample, pixel = sample[hit], pixel[hit]
            offset = self.position[pixel] - self.samples.position[sample]
            distance = np.sqrt(np.einsum("ij,ij->i", offset, offset))
            within = (distance >= self.bounds_low[sample]) & (distance < self.bounds_high[sample])
            sample, pixel, distance = sample[within], pixel[within], distance[within]
            if not len(sample):
                continue
            value = evaluate_pairs(self.table, self.step_inverse, self.material.segments,
                                    distance, self.samples.texel[sample], self.texel_out[pixel])
            weight = value * self.flux[sample]
            for channel in range(3):
                self.exitance[:, channel] += np.bincount(pixel, weights=weight[:, channel],
                                                         minlength=len(self.valid))

    def result(self) -> np.ndarray:
        """Return the accumulated exitance, (H * W, 3)."""
        return self.exitance
