r"""Compiled kernels of the multiresolution splatting method (Chen et al. 2012).

The frame loop of :mod:`translucent.fast.splatting` spends its time here:

* :func:`splat_samples`: Eq. 12, every selected irradiance sample scattered into the
  pixels of one splatting level that lie within its effective rendering range;
* :func:`gather_samples`: Eq. 5 by brute force (every pixel from every sample), the
  ground truth the method is measured against;
* :func:`median_depth_level`, :func:`irradiance_level`: one level of the splatting
  buffer's median-depth mipmap and of the irradiance buffer's mipmap (Sect. 4);
* :func:`bilateral_upsample_level`: Eq. 17;
* :func:`rasterize`: the G-buffers themselves, a z-buffer over the scene's triangles
  whose per-pixel test is the exact ray-triangle intersection of the pixel's ray.

The profile evaluation of Eq. 8-9 is written in float32 as
:math:`\sqrt{P_i(d)P_o(d)} = \exp(\tfrac12(\hat P_i^k + \hat P_o^k) +
w\,\tfrac12((\hat P_i^{k+1}-\hat P_i^k) + (\hat P_o^{k+1}-\hat P_o^k)))` with a table of
half knot values and half slopes per texel and segment (:func:`segment_table`), and a
float32 exponential (:func:`exp32`, Cephes' ``expf`` polynomial, relative error below
1e-7) that the compiler vectorises. Each splat visits its window row by row in three
passes: distances and segment indices (vectorised), the table look-ups (scalar: the
compiler will not vectorise gathers on this CPU), exponentials and accumulation
(vectorised). Threads own interleaved rows of the output, so no two write one pixel and
the result does not depend on the number of threads.

References
----------
Chen, Peers, Zhang, Tong: Real-time rendering of deformable heterogeneous translucent
objects using multiresolution splatting. The Visual Computer (2012).
Moshier: Cephes Math Library, ``expf`` (the polynomial of :func:`exp32`).
Möller, Trumbore: Fast, minimum storage ray-triangle intersection. JGT 2(1) (1997).
"""

from __future__ import annotations

import math

import numba
import numpy as np
from llvmlite import ir
from numba import types
from numba.extending import intrinsic

__all__ = [
    "exp32",
    "segment_table",
    "splat_samples",
    "block_bounds",
    "BLOCK",
    "gather_samples",
    "median_depth_level",
    "irradiance_level",
    "bilateral_upsample_level",
    "rasterize",
    "STRIPES",
]

#: Interleaved row stripes of a splat, run in parallel: one per core of this 2-core machine
#: (more only add per-sample overhead). Results do not depend on it. The other kernels are
#: serial: on this shared machine, threads cost more than they save on a few milliseconds
#: of work (measured: the irradiance mipmap level takes 4x the CPU time with 2 threads).
STRIPES = 2
#: ln of the value given to a pair outside its range before the exponential: exp(-87) is
#: below float32's smallest normal number times any flux, so the pair adds nothing.
_OUTSIDE = np.float32(-1000.0)
#: Pixels of a row culled together by their bounding box in :func:`splat_samples`.
BLOCK = 16
#: Samples per block of the brute-force gather (its scratch stays in the L1/L2 caches).
_GATHER_BLOCK = 1024


# ====================================================================== float32 exp
@intrinsic
def _float_from_bits(typingctx, bits):
    """Reinterpret the low 32 bits of an integer as a float32 (no conversion)."""
    if not isinstance(bits, types.Integer):
        return None

    def codegen(context, builder, signature, args):
        value = args[0]
        if bits.bitwidth != 32:
            value = builder.trunc(value, ir.IntType(32))
        return builder.bitcast(value, ir.FloatType())

    return types.float32(bits), codegen


@numba.njit(inline="always", fastmath=True, cache=True)
def exp32(x):
    r"""Return :math:`e^x` in float32, vectorisable (no library call).

    Cephes' ``expf``: :math:`x = n\ln 2 + r`, :math:`|r| \le \ln 2 / 2`, a degree-7
    polynomial for :math:`e^r` and :math:`2^n` built from its exponent bits. Arguments are
    clamped to [-87, 88] (float32's normal range). Relative error below 1e-7.
    """
    x = min(max(x, np.float32(-87.0)), np.float32(88.0))
    n = np.floor(x * np.float32(1.44269504088896341) + np.float32(0.5))
    r = x - n * np.float32(0.693359375) + n * np.float32(2.12194440e-4)
    p = np.float32(1.9875691500e-4)
    p = p * r + np.float32(1.3981999507e-3)
    p = p * r + np.float32(8.3334519073e-3)
    p = p * r + np.float32(4.1665795894e-2)
    p = p * r + np.float32(1.6666665459e-1)
    p = p * r + np.float32(5.0000001201e-1)
    p = p * r * r + r + np.float32(1.0)
    return p * _float_from_bits((np.int32(n) + np.int32(127)) << np.int32(23))


def segment_table(flat_log_profile: np.ndarray) -> np.ndarray:
    r"""Half knot values and half slopes of Eq. 9's segments, float32, shape (T, n, 6).

    ``[..., c]`` is :math:`\tfrac12\hat P^k_c` and ``[..., 3 + c]`` is
    :math:`\tfrac12(\hat P^{k+1}_c - \hat P^k_c)` for channel ``c``, so that
    :math:`\ln\sqrt{P_i P_o}` on segment :math:`k` at weight :math:`w` is the sum of the
    two texels' rows' first half plus :math:`w` times their second half (Eq. 8-9 of Chen
    et al. 2012).

    Parameters
    ----------
    flat_log_profile : ndarray (T, n + 1, 3)
        :math:`\ln P` at the knots, mm^-2 (``SubEditProfiles.flat_log_profile``).
    """
    table = np.asarray(flat_log_profile, dtype=np.float64)
    start = table[:, :-1]
    return np.ascontiguousarray(
        0.5 * np.concatenate([start, table[:, 1:] - start], axis=2), dtype=np.float32)


# ====================================================================== splatting
def block_bounds(position: np.ndarray, valid: np.ndarray) -> np.ndarray:
    """Bounding boxes of the valid surface points of each run of :data:`BLOCK` pixels of a row.

    Parameters
    ----------
    position : ndarray (3, H, W) float32
        Surface points, scene units.
    valid : ndarray (H, W) bool

    Returns
    -------
    ndarray (H, ceil(W / BLOCK), 6) float32
        Minimum x, y, z then maximum x, y, z; +inf then -inf for a block with no valid pixel.
    """
    height, width = valid.shape
    blocks = -(-width // BLOCK)
    pad = blocks * BLOCK - width
    low = np.where(valid, position, np.float32(np.inf))
    high = np.where(valid, position, np.float32(-np.inf))
    low = np.pad(low, ((0, 0), (0, 0), (0, pad)), constant_values=np.inf)
    high = np.pad(high, ((0, 0), (0, 0), (0, pad)), constant_values=-np.inf)
    low = low.reshape(3, height, blocks, BLOCK).min(axis=3)
    high = high.reshape(3, height, blocks, BLOCK).max(axis=3)
    return np.ascontiguousarray(np.concatenate([low, high]).transpose(1, 2, 0),
                                dtype=np.float32)


@numba.njit(parallel=True, fastmath=True, cache=True)
def splat_samples(out, position, texel_out, bounds, table, step_inverse, sample_position,
                  sample_texel, sample_flux, centre_x, centre_y, radius, low2, high2,
                  stripes):
    r"""Eq. 12 of Chen et al. 2012: scatter samples into one splatting level, in place.

    Sample ``s`` visits the pixels whose centres lie within ``radius[s]`` pixels of its
    projection ``(centre_x[s], centre_y[s])`` (continuous pixel coordinates) and adds
    :math:`\sqrt{P_{x_o}(d)P_{x_i}(d)}\,\Phi_s` to every valid pixel whose surface point
    lies at a squared distance :math:`d^2 \in` ``[low2[s], high2[s])`` and within the
    profiles' support. Runs of :data:`BLOCK` pixels whose bounding box (``bounds``) lies
    wholly outside the range are skipped without visiting their pixels.

    Parameters
    ----------
    out : ndarray (3, H, W) float32
        :math:`B^k` per channel, accumulated into.
    position : ndarray (3, H, W) float32
        The level's surface points, scene units.
    texel_out : ndarray (H, W) int32
        Each pixel's texel (row of ``table``); negative where the pixel is invalid.
    bounds : ndarray (H, ceil(W / BLOCK), 6) float32
        :func:`block_bounds`.
    table : ndarray (T, n, 6) float32
        :func:`segment_table`.
    step_inverse : float32
        Segments per scene unit, :math:`n / r_s`.
    sample_position : ndarray (3, N) float32
    sample_texel : ndarray (N,) int32
    sample_flux : ndarray (N, 3) float32
        :math:`E\,\Delta A` times the unit conversion of the profile.
    centre_x, centre_y, radius : ndarray (N,) float32
        The window of each sample, pixels.
    low2, high2 : ndarray (N,) float32
        Squared bounds of the effective rendering range, scene units squared.
    stripes : int
        Interleaved row stripes run in parallel.

    Returns
    -------
    ndarray (stripes, 2) int64
        Per stripe: sample-pixel pairs visited, and those within range (evaluated).
    """
    height = texel_out.shape[0]
    width = texel_out.shape[1]
    blocks = bounds.shape[1]
    visited = np.zeros((stripes, 2), np.int64)
    for stripe in numba.prange(stripes):
        weight = np.empty(width, np.float32)
        segment = np.empty(width, np.int32)
        log_value = np.empty((3, width), np.float32)
        count = 0
        used = 0
        for s in range(sample_texel.shape[0]):
            # pixel centres (x + 1/2, y + 1/2) within radius[s] of the projection
            r = radius[s]
            y_first = max(int(math.ceil(centre_y[s] - r - 0.5)), 0)
            y_last = min(int(math.floor(centre_y[s] + r - 0.5)) + 1, height)
            y_first += (stripe - y_first) % stripes
            for y in range(y_first, y_last, stripes):
                dy = y + 0.5 - centre_y[s]
                half = math.sqrt(max(r * r - dy * dy, 0.0))
                x_left = max(int(math.ceil(centre_x[s] - half - 0.5)), 0)
                x_right = min(int(math.floor(centre_x[s] + half - 0.5)) + 1, width)
                if x_right <= x_left:
                    continue
                block = x_left // BLOCK
                block_end = min((x_right + BLOCK - 1) // BLOCK, blocks)
                while block < block_end:
                    # the next run of blocks whose bounding boxes may reach the range
                    while block < block_end and _outside(bounds, y, block, sample_position,
                                                         s, low2[s], high2[s]):
                        block += 1
                    run = block
                    while block < block_end and not _outside(
                            bounds, y, block, sample_position, s, low2[s], high2[s]):
                        block += 1
                    if run == block:
                        break
                    x0 = max(run * BLOCK, x_left)
                    x1 = min(block * BLOCK, x_right)
                    count += x1 - x0
                    used += _splat_run(out, position, texel_out, table, step_inverse,
                                       sample_position, sample_texel, sample_flux, s, y, x0,
                                       x1 - x0, low2[s], high2[s], weight, segment, log_value)
        visited[stripe, 0] = count
        visited[stripe, 1] = used
    return visited


@numba.njit(inline="always", fastmath=True, cache=True)
def _outside(bounds, y, block, sample_position, s, low2, high2):
    """Return True when no point of the block's box lies in [sqrt(low2), sqrt(high2))."""
    fx = sample_position[0, s]
    fy = sample_position[1, s]
    fz = sample_position[2, s]
    gx = max(bounds[y, block, 0] - fx, fx - bounds[y, block, 3], 0.0)
    gy = max(bounds[y, block, 1] - fy, fy - bounds[y, block, 4], 0.0)
    gz = max(bounds[y, block, 2] - fz, fz - bounds[y, block, 5], 0.0)
    hx = max(abs(bounds[y, block, 0] - fx), abs(bounds[y, block, 3] - fx))
    hy = max(abs(bounds[y, block, 1] - fy), abs(bounds[y, block, 4] - fy))
    hz = max(abs(bounds[y, block, 2] - fz), abs(bounds[y, block, 5] - fz))
    return gx * gx + gy * gy + gz * gz >= high2 or hx * hx + hy * hy + hz * hz < low2


@numba.njit(inline="always", fastmath=True, cache=True)
def _splat_run(out, position, texel_out, table, step_inverse, sample_position, sample_texel,
               sample_flux, s, y, x0, n, low, high, weight, segment, log_value):
    """Splat sample ``s`` into pixels ``x0 .. x0 + n - 1`` of row ``y``; return pairs in range.

    Columns are unsigned so that the compiler knows them non-negative (no wrap-around of
    negative indices) and vectorises the first and last passes.
    """
    segments = table.shape[1]
    fx = sample_position[0, s]
    fy = sample_position[1, s]
    fz = sample_position[2, s]
    first = np.uint64(x0)
    for i in range(n):  # vectorised: distances and segments
        x = first + np.uint64(i)
        ddx = position[0, y, x] - fx
        ddy = position[1, y, x] - fy
        ddz = position[2, y, x] - fz
        d2 = ddx * ddx + ddy * ddy + ddz * ddz
        at = math.sqrt(d2) * step_inverse
        inside = (texel_out[y, x] >= 0) & (d2 >= low) & (d2 < high) & (at < segments)
        k = min(np.int32(at), segments - 1)
        segment[i] = k if inside else np.int32(-1)
        weight[i] = at - np.float32(k)
        log_value[0, i] = _OUTSIDE
        log_value[1, i] = _OUTSIDE
        log_value[2, i] = _OUTSIDE
    stride = np.uint64(table.shape[1] * 6)
    own = np.uint64(sample_texel[s]) * stride
    flat = table.reshape(-1)
    used = 0
    for i in range(n):  # scalar: table look-ups of both texels
        k = segment[i]
        if k >= 0:
            used += 1
            w = weight[i]
            knot = np.uint64(k) * np.uint64(6)
            a = np.uint64(texel_out[y, first + np.uint64(i)]) * stride + knot
            b = own + knot
            log_value[0, i] = (flat[a] + flat[b]) + w * (flat[a + np.uint64(3)] +
                                                         flat[b + np.uint64(3)])
            log_value[1, i] = (flat[a + np.uint64(1)] + flat[b + np.uint64(1)]) + \
                w * (flat[a + np.uint64(4)] + flat[b + np.uint64(4)])
            log_value[2, i] = (flat[a + np.uint64(2)] + flat[b + np.uint64(2)]) + \
                w * (flat[a + np.uint64(5)] + flat[b + np.uint64(5)])
    for channel in range(3):  # vectorised: exponentials and accumulation
        flux = sample_flux[s, channel]
        for i in range(n):
            out[channel, y, first + np.uint64(i)] += exp32(log_value[channel, i]) * flux
    return used


@numba.njit(parallel=True, fastmath=True, cache=True)
def gather_samples(out, pixel_position, pixel_texel, table, step_inverse, sample_position,
                   sample_texel, sample_flux):
    r"""Eq. 5 of Chen et al. 2012 by brute force: each pixel gathers every sample.

    :math:`B(x_o) = \sum_i \sqrt{P_{x_i}(d)P_{x_o}(d)}\,\Phi_i` over all samples with
    :math:`d < r_s` (no truncation at the effective range), accumulated in float64.

    Parameters
    ----------
    out : ndarray (P, 3) float64
        Written (not accumulated).
    pixel_position : ndarray (3, P) float32
    pixel_texel : ndarray (P,) int32
    table : ndarray (T, n, 6) float32
        :func:`segment_table`.
    step_inverse : float32
        Segments per scene unit.
    sample_position : ndarray (3, N) float32
    sample_texel : ndarray (N,) int32
    sample_flux : ndarray (3, N) float32
    """
    pixels = pixel_texel.shape[0]
    count = sample_texel.shape[0]
    segments = table.shape[1]
    chunks = max(1, min(pixels, 64))
    for chunk in numba.prange(chunks):
        weight = np.empty(_GATHER_BLOCK, np.float32)
        segment = np.empty(_GATHER_BLOCK, np.int32)
        log_value = np.empty((3, _GATHER_BLOCK), np.float32)
        for p in range(chunk * pixels // chunks, (chunk + 1) * pixels // chunks):
            own = table[pixel_texel[p]]
            px = pixel_position[0, p]
            py = pixel_position[1, p]
            pz = pixel_position[2, p]
            total0 = 0.0
            total1 = 0.0
            total2 = 0.0
            for start in range(0, count, _GATHER_BLOCK):
                n = min(_GATHER_BLOCK, count - start)
                block_x = sample_position[0, start:start + n]
                block_y = sample_position[1, start:start + n]
                block_z = sample_position[2, start:start + n]
                block_texel = sample_texel[start:start + n]
                for i in range(n):
                    ddx = block_x[i] - px
                    ddy = block_y[i] - py
                    ddz = block_z[i] - pz
                    at = math.sqrt(ddx * ddx + ddy * ddy + ddz * ddz) * step_inverse
                    k = min(np.int32(at), segments - 1)
                    segment[i] = k if at < segments else np.int32(-1)
                    weight[i] = at - np.float32(k)
                for i in range(n):
                    k = segment[i]
                    if k < 0:
                        log_value[0, i] = _OUTSIDE
                        log_value[1, i] = _OUTSIDE
                        log_value[2, i] = _OUTSIDE
                        continue
                    t = block_texel[i]
                    w = weight[i]
                    log_value[0, i] = (table[t, k, 0] + own[k, 0]) + \
                        w * (table[t, k, 3] + own[k, 3])
                    log_value[1, i] = (table[t, k, 1] + own[k, 1]) + \
                        w * (table[t, k, 4] + own[k, 4])
                    log_value[2, i] = (table[t, k, 2] + own[k, 2]) + \
                        w * (table[t, k, 5] + own[k, 5])
                part0 = np.float32(0.0)
                part1 = np.float32(0.0)
                part2 = np.float32(0.0)
                flux0 = sample_flux[0, start:start + n]
                flux1 = sample_flux[1, start:start + n]
                flux2 = sample_flux[2, start:start + n]
                for i in range(n):
                    part0 += exp32(log_value[0, i]) * flux0[i]
                    part1 += exp32(log_value[1, i]) * flux1[i]
                    part2 += exp32(log_value[2, i]) * flux2[i]
                total0 += part0
                total1 += part1
                total2 += part2
            out[p, 0] = total0
            out[p, 1] = total1
            out[p, 2] = total2


# ====================================================================== mipmaps
@numba.njit(cache=True)
def _median_child(depth, valid, row, col):
    """Child offset (0-3, row-major in the 2 x 2 block) of the lower-median valid depth."""
    height, width = valid.shape
    order = np.empty(4, np.int64)
    keys = np.empty(4, np.float64)
    count = 0
    for child in range(4):
        y = 2 * row + child // 2
        x = 2 * col + child % 2
        if y < height and x < width and valid[y, x]:
            # insertion sort, stable: equal depths keep the children's order
            slot = count
            while slot > 0 and keys[slot - 1] > depth[y, x]:
                keys[slot] = keys[slot - 1]
                order[slot] = order[slot - 1]
                slot -= 1
            keys[slot] = depth[y, x]
            order[slot] = child
            count += 1
    if count == 0:
        return -1
    return order[(count - 1) // 2]


@numba.njit(cache=True)
def median_depth_level(position, normal, uv, depth, valid, footprint):
    """One level of the splatting buffer's mipmap: the median-depth texel of each 2 x 2 block.

    Sect. 4 of Chen et al. 2012. Among the valid children the lower median depth is
    copied (ties keep the children's row-major order); a block without a valid child is
    invalid and copies its first child. The footprint doubles.

    Returns
    -------
    tuple
        ``position, normal, uv, depth, valid, footprint`` of the coarser level.
    """
    height = (valid.shape[0] + 1) // 2
    width = (valid.shape[1] + 1) // 2
    out_position = np.zeros((height, width, 3), position.dtype)
    out_normal = np.zeros((height, width, 3), normal.dtype)
    out_uv = np.zeros((height, width, 2), uv.dtype)
    out_depth = np.zeros((height, width), depth.dtype)
    out_valid = np.zeros((height, width), np.bool_)
    out_footprint = np.zeros((height, width), footprint.dtype)
    for row in range(height):
        for col in range(width):
            child = _median_child(depth, valid, row, col)
            out_valid[row, col] = child >= 0
            child = max(child, 0)
            y = min(2 * row + child // 2, valid.shape[0] - 1)
            x = min(2 * col + child % 2, valid.shape[1] - 1)
            for c in range(3):
                out_position[row, col, c] = position[y, x, c]
                out_normal[row, col, c] = normal[y, x, c]
            out_uv[row, col, 0] = uv[y, x, 0]
            out_uv[row, col, 1] = uv[y, x, 1]
            out_depth[row, col] = depth[y, x]
            out_footprint[row, col] = 2.0 * footprint[y, x]
    return out_position, out_normal, out_uv, out_depth, out_valid, out_footprint


@numba.njit(cache=True)
def irradiance_level(position, normal, uv, cosine, footprint, flux, depth_min, depth_max,
                     valid):
    """One level of the irradiance buffer's mipmap (Sect. 4 of Chen et al. 2012).

    Position, normal (renormalised), uv, cosine and footprint average the valid children
    (a standard mipmap; the footprint then doubles); flux sums them; the depth range is
    the min / max of the children's (a min/max mipmap).

    Returns
    -------
    tuple
        The nine arrays of the coarser level, in the order of the arguments.
    """
    height = (valid.shape[0] + 1) // 2
    width = (valid.shape[1] + 1) // 2
    out_position = np.zeros((height, width, 3))
    out_normal = np.zeros((height, width, 3))
    out_uv = np.zeros((height, width, 2))
    out_cosine = np.zeros((height, width))
    out_footprint = np.zeros((height, width))
    out_flux = np.zeros((height, width, 3))
    out_min = np.full((height, width), np.inf)
    out_max = np.full((height, width), -np.inf)
    out_valid = np.zeros((height, width), np.bool_)
    for row in range(height):
        for col in range(width):
            count = 0
            for child in range(4):
                y = 2 * row + child // 2
                x = 2 * col + child % 2
                if y >= valid.shape[0] or x >= valid.shape[1]:
                    continue
                for c in range(3):
                    out_flux[row, col, c] += flux[y, x, c]
                out_min[row, col] = min(out_min[row, col], depth_min[y, x])
                out_max[row, col] = max(out_max[row, col], depth_max[y, x])
                if not valid[y, x]:
                    continue
                count += 1
                for c in range(3):
                    out_position[row, col, c] += position[y, x, c]
                    out_normal[row, col, c] += normal[y, x, c]
                out_uv[row, col, 0] += uv[y, x, 0]
                out_uv[row, col, 1] += uv[y, x, 1]
                out_cosine[row, col] += cosine[y, x]
                out_footprint[row, col] += footprint[y, x]
            if count == 0:
                continue
            out_valid[row, col] = True
            scale = 1.0 / count
            length = 0.0
            for c in range(3):
                out_position[row, col, c] *= scale
                out_normal[row, col, c] *= scale
                length += out_normal[row, col, c] ** 2
            length = math.sqrt(length)
            for c in range(3):
                out_normal[row, col, c] = out_normal[row, col, c] / length if length > 0 \
                    else 0.0
            out_uv[row, col, 0] *= scale
            out_uv[row, col, 1] *= scale
            out_cosine[row, col] *= scale
            out_footprint[row, col] *= 2.0 * scale
    return (out_position, out_normal, out_uv, out_cosine, out_footprint, out_flux, out_min,
            out_max, out_valid)


# ====================================================================== accumulation
@numba.njit(fastmath=True, cache=True)
def bilateral_upsample_level(coarse, coarse_depth, coarse_valid, coarse_range, fine_depth,
                             fine_valid, fine_range, depth_scale, range_scale):
    r"""Eq. 17 of Chen et al. 2012: bilateral upsampling of :math:`B^{k+1}` to level k.

    Each valid fine pixel averages its four nearest coarse pixels with weights
    :math:`w_p e^{-\lambda_z |z_o - z_j|/R_w} e^{-\lambda_m |R_{P_o} - R_{P_j}|/R_w}`
    (``depth_scale`` and ``range_scale`` are :math:`\lambda/R_w`); invalid coarse pixels
    weigh 0; a fine pixel with no valid neighbour gets 0.

    Returns
    -------
    ndarray (H, W, 3)
    """
    height, width = fine_valid.shape
    coarse_height, coarse_width = coarse_valid.shape
    out = np.zeros((height, width, 3))
    for row in range(height):
        fy = (row + 0.5) / 2.0 - 0.5
        y0 = min(max(int(math.floor(fy)), 0), coarse_height - 1)
        y1 = min(y0 + 1, coarse_height - 1)
        ty = min(max(fy - math.floor(fy), 0.0), 1.0)
        for col in range(width):
            if not fine_valid[row, col]:
                continue
            fx = (col + 0.5) / 2.0 - 0.5
            x0 = min(max(int(math.floor(fx)), 0), coarse_width - 1)
            x1 = min(x0 + 1, coarse_width - 1)
            tx = min(max(fx - math.floor(fx), 0.0), 1.0)
            total0 = 0.0
            total1 = 0.0
            total2 = 0.0
            weights = 0.0
            for corner in range(4):
                y = y0 if corner < 2 else y1
                x = x0 if corner % 2 == 0 else x1
                if not coarse_valid[y, x]:
                    continue
                w = (1.0 - ty if corner < 2 else ty) * (1.0 - tx if corner % 2 == 0 else tx)
                w *= math.exp(-depth_scale * abs(fine_depth[row, col] - coarse_depth[y, x])
                              - range_scale * abs(fine_range[row, col] - coarse_range[y, x]))
                total0 += w * coarse[y, x, 0]
                total1 += w * coarse[y, x, 1]
                total2 += w * coarse[y, x, 2]
                weights += w
            if weights > 1e-30:
                out[row, col, 0] = total0 / weights
                out[row, col, 1] = total1 / weights
                out[row, col, 2] = total2 / weights
    return out


# ====================================================================== G-buffers
@numba.njit(cache=True)
def rasterize(vertices, faces, eye, forward, left, up, tan_x, tan_y, width, height, near,
              orthographic):
    r"""Find the first triangle seen through each pixel: a z-buffer with exact ray tests.

    For each triangle, the pixels of its projected bounding box are tested with the
    pixel's own ray (Möller-Trumbore, float64), exactly the rays of
    :func:`translucent.scenes.raycast.camera_rays` (perspective: from ``eye`` through the
    pixel centres, starting at the near plane ``near`` along ``forward``; orthographic:
    parallel to ``forward`` from the image plane through ``eye``, half-widths ``tan_x``,
    ``tan_y`` in scene units). Edges are inclusive, so no ray slips between two triangles;
    the nearer hit wins, the lower triangle index on a tie.

    Returns
    -------
    triangle : ndarray (H, W) int64
        Index into ``faces``; -1 where nothing is hit.
    barycentric : ndarray (H, W, 2)
        Weights of the triangle's second and third vertices.
    depth : ndarray (H, W)
        Distance from the eye (perspective) or the image plane along the ray.
    """
    triangle = np.full((height, width), -1, np.int64)
    barycentric = np.zeros((height, width, 2))
    depth = np.full((height, width), np.inf)
    for f in range(faces.shape[0]):
        a = vertices[faces[f, 0]]
        b = vertices[faces[f, 1]]
        c = vertices[faces[f, 2]]
        # the triangle's bounding box in pixels
        col_low = 1e300
        col_high = -1e300
        row_low = 1e300
        row_high = -1e300
        clipped = False
        for corner in range(3):
            p = a if corner == 0 else (b if corner == 1 else c)
            rx = p[0] - eye[0]
            ry = p[1] - eye[1]
            rz = p[2] - eye[2]
            along = rx * forward[0] + ry * forward[1] + rz * forward[2]
            across = rx * left[0] + ry * left[1] + rz * left[2]
            upward = rx * up[0] + ry * up[1] + rz * up[2]
            if not orthographic:
                if along <= near:
                    clipped = True
                    break
                across /= along
                upward /= along
            col = (1.0 - across / tan_x) * 0.5 * width - 0.5
            row = (1.0 - upward / tan_y) * 0.5 * height - 0.5
            col_low = min(col_low, col)
            col_high = max(col_high, col)
            row_low = min(row_low, row)
            row_high = max(row_high, row)
        if clipped:
            x_first, x_last, y_first, y_last = 0, width - 1, 0, height - 1
        else:
            if col_high < -1 or row_high < -1 or col_low > width or row_low > height:
                continue
            x_first = max(int(math.floor(col_low)), 0)
            x_last = min(int(math.ceil(col_high)), width - 1)
            y_first = max(int(math.floor(row_low)), 0)
            y_last = min(int(math.ceil(row_high)), height - 1)
        e1x = b[0] - a[0]
        e1y = b[1] - a[1]
        e1z = b[2] - a[2]
        e2x = c[0] - a[0]
        e2y = c[1] - a[1]
        e2z = c[2] - a[2]
        for y in range(y_first, y_last + 1):
            sy = tan_y * (1.0 - 2.0 * (y + 0.5) / height)
            for x in range(x_first, x_last + 1):
                sx = tan_x * (1.0 - 2.0 * (x + 0.5) / width)
                if orthographic:
                    ox = eye[0] + sx * left[0] + sy * up[0]
                    oy = eye[1] + sx * left[1] + sy * up[1]
                    oz = eye[2] + sx * left[2] + sy * up[2]
                    dx, dy, dz = forward[0], forward[1], forward[2]
                    start = 0.0
                else:
                    ox, oy, oz = eye[0], eye[1], eye[2]
                    dx = forward[0] + sx * left[0] + sy * up[0]
                    dy = forward[1] + sx * left[1] + sy * up[1]
                    dz = forward[2] + sx * left[2] + sy * up[2]
                    norm = 1.0 / math.sqrt(dx * dx + dy * dy + dz * dz)
                    dx *= norm
                    dy *= norm
                    dz *= norm
                    start = near / (dx * forward[0] + dy * forward[1] + dz * forward[2])
                px = dy * e2z - dz * e2y
                py = dz * e2x - dx * e2z
                pz = dx * e2y - dy * e2x
                det = e1x * px + e1y * py + e1z * pz
                if abs(det) < 1e-300:
                    continue
                inverse = 1.0 / det
                tx = ox - a[0]
                ty = oy - a[1]
                tz = oz - a[2]
                u = (tx * px + ty * py + tz * pz) * inverse
                if u < 0.0 or u > 1.0:
                    continue
                qx = ty * e1z - tz * e1y
                qy = tz * e1x - tx * e1z
                qz = tx * e1y - ty * e1x
                v = (dx * qx + dy * qy + dz * qz) * inverse
                if v < 0.0 or u + v > 1.0:
                    continue
                t = (e2x * qx + e2y * qy + e2z * qz) * inverse
                if t < start or t >= depth[y, x]:
                    continue
                depth[y, x] = t
                triangle[y, x] = f
                barycentric[y, x, 0] = u
                barycentric[y, x, 1] = v
    return triangle, barycentric, depth


@numba.njit(cache=True)
def interpolate_surface(triangle, barycentric, first_face, last_face, vertices, faces,
                        normals, uv):
    """Surface attributes of the pixels whose triangle lies in ``[first_face, last_face)``.

    Position and uv are interpolated with the barycentrics; the shading normal is the
    normalised interpolated vertex normal (the face normal where those cancel), as in
    :mod:`translucent.scenes.raycast`. ``faces`` index ``vertices`` of this object alone.

    Returns
    -------
    tuple
        ``valid (H, W) bool, position (H, W, 3), normal (H, W, 3), uv (H, W, 2)``.
    """
    height, width = triangle.shape
    valid = np.zeros((height, width), np.bool_)
    position = np.zeros((height, width, 3))
    normal = np.zeros((height, width, 3))
    out_uv = np.zeros((height, width, 2))
    has_uv = uv.shape[0] == vertices.shape[0]
    for y in range(height):
        for x in range(width):
            f = triangle[y, x]
            if f < first_face or f >= last_face:
                continue
            f -= first_face
            valid[y, x] = True
            b1 = barycentric[y, x, 0]
            b2 = barycentric[y, x, 1]
            b0 = 1.0 - b1 - b2
            i0, i1, i2 = faces[f, 0], faces[f, 1], faces[f, 2]
            length = 0.0
            for c in range(3):
                position[y, x, c] = b0 * vertices[i0, c] + b1 * vertices[i1, c] + \
                    b2 * vertices[i2, c]
                normal[y, x, c] = b0 * normals[i0, c] + b1 * normals[i1, c] + \
                    b2 * normals[i2, c]
                length += normal[y, x, c] ** 2
            length = math.sqrt(length)
            if length > 1e-12:
                for c in range(3):
                    normal[y, x, c] /= length
            else:
                e1 = vertices[i1] - vertices[i0]
                e2 = vertices[i2] - vertices[i0]
                n0 = e1[1] * e2[2] - e1[2] * e2[1]
                n1 = e1[2] * e2[0] - e1[0] * e2[2]
                n2 = e1[0] * e2[1] - e1[1] * e2[0]
                length = math.sqrt(n0 * n0 + n1 * n1 + n2 * n2)
                normal[y, x, 0] = n0 / length
                normal[y, x, 1] = n1 / length
                normal[y, x, 2] = n2 / length
            if has_uv:
                for c in range(2):
                    out_uv[y, x, c] = b0 * uv[i0, c] + b1 * uv[i1, c] + b2 * uv[i2, c]
    return valid, position, normal, out_uv
