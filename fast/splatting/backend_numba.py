r"""Compiled kernels of the multiresolution splatting method (Chen et al. 2012).

The frame loop of :mod:`translucent.fast.splatting` spends its time here:

* :func:`bin_samples`, :func:`splat_tiles`: Eq. 12, every selected irradiance sample
  scattered into the pixels of one splatting level that lie within its effective
  rendering range, tile by tile (:func:`tile_layout`);
* :func:`gather_samples`: Eq. 5 by brute force (every pixel from every sample), the
  ground truth the method is measured against.

The buffers these read (G-buffers, their mipmaps, the per-pixel light) are made by
:mod:`translucent.fast.splatting.buffer_kernels`.

The profile evaluation of Eq. 8-9 is written in float32 as
:math:`\sqrt{P_i(d)P_o(d)} = \exp(\tfrac12(\hat P_i^k + \hat P_o^k) +
w\,\tfrac12((\hat P_i^{k+1}-\hat P_i^k) + (\hat P_o^{k+1}-\hat P_o^k)))` with a table of
half knot values and half slopes per texel and segment (:func:`segment_table`), and a
float32 exponential (:func:`exp32`, Cephes' ``expf`` polynomial, relative error below
1e-7) that the compiler vectorises. The splat runs over square tiles of :data:`TILE`
pixels stored contiguously: each tile gathers the samples binned to it, and for each
sample computes the distances to all its pixels (vectorised), lists the pixels in range
(branch-free), reads the table for those (scalar: the compiler will not vectorise gathers
on this CPU) and takes the exponentials (vectorised); a sample whose pixels in range fall
into at most two segments skips the list and the scalar reads (the two-segment path of
:func:`splat_tiles`). Tiles run in parallel and each owns its pixels, so no two threads
write one pixel and the result does not depend on the number of threads.

The measurements behind these choices, and what was tried and dropped, are in
docs/splatting.md ("The splat kernel, measured").

References
----------
Chen, Peers, Zhang, Tong: Real-time rendering of deformable heterogeneous translucent
objects using multiresolution splatting. The Visual Computer (2012).
Moshier: Cephes Math Library, ``expf`` (the polynomial of :func:`exp32`).
"""

from __future__ import annotations

import math

import numba
import numpy as np
from llvmlite import ir
from numba import types
from numba.extending import intrinsic

from ...compiled import parallel_njit

__all__ = [
    "exp32",
    "segment_table",
    "tile_layout",
    "untile",
    "untile_float64",
    "bin_samples",
    "splat_tiles",
    "splat_windows",
    "TILE",
    "NARROW_WIDTH",
    "FEWEST_IN_VECTORS",
    "gather_samples",
    "prefix_sum",
]

#: Side of the square tiles of a splatting level (:func:`tile_layout`): 64 pixels, four
#: float32 vectors of AVX-512 per pass (docs/splatting.md: why 8).
TILE = 8
#: Annulus width (:math:`\sqrt{high2} - \sqrt{low2}`, in profile segments) below which
#: :func:`splat_tiles` looks for a sample whose pixels in a tile fall into at most two
#: segments, evaluated in vectors without a list (narrow annuli qualify; wide ones only pay
#: for the test: docs/splatting.md).
NARROW_WIDTH = np.float32(4.0)
#: Fewest pixels in range for the two-segment path, which evaluates all 64 pixels: below,
#: the general path's short list is as cheap (docs/splatting.md).
FEWEST_IN_VECTORS = 8
#: ln of the value given to a pair outside its range before the exponential: exp(-87) is
#: below float32's smallest normal number times any flux, so the pair adds nothing.
_OUTSIDE = np.float32(-1000.0)
#: Chunks of samples listed per row in parallel by :func:`bin_samples` (a constant, so that
#: the kernel can be cached; several per thread up to 16 threads).
_BIN_CHUNKS = 64
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
def tile_layout(position: np.ndarray, texel: np.ndarray, valid: np.ndarray):
    """Reorder one splatting level into square tiles of :data:`TILE` x :data:`TILE` pixels.

    Each tile's pixels are contiguous (row-major inside the tile), so that one sample's
    distances to a whole tile are one vectorised loop; each tile also gets the bounding box
    of its valid surface points, against which a sample's range is culled.

    Parameters
    ----------
    position : ndarray (3, H, W)
        Surface points, scene units (any float type and strides; stored as float32).
    texel : ndarray (H, W) int
        Each pixel's SubEdit texel.
    valid : ndarray (H, W) bool

    Returns
    -------
    position : ndarray (tiles, 3, TILE * TILE) float32
    texel : ndarray (tiles, TILE * TILE) int32
        -1 at invalid (and padding) pixels.
    bounds : ndarray (tiles, 6) float32
        Minimum x, y, z then maximum x, y, z; +inf then -inf for a tile with no valid pixel.
    tiles_y, tiles_x : int
        Tiles down and across (the image is padded to whole tiles).
    """
    height, width = valid.shape
    tiles_y, tiles_x = -(-height // TILE), -(-width // TILE)
    tiled_position = np.empty((tiles_y * tiles_x, 3, TILE * TILE), np.float32)
    tiled_texel = np.empty((tiles_y * tiles_x, TILE * TILE), np.int32)
    bounds = np.empty((tiles_y * tiles_x, 6), np.float32)
    _fill_tiles(position, np.asarray(texel), np.asarray(valid, np.bool_), tiles_x,
                tiled_position, tiled_texel, bounds)
    return tiled_position, tiled_texel, bounds, tiles_y, tiles_x


@parallel_njit(cache=True)
def _fill_tiles(position, texel, valid, tiles_x, tiled_position, tiled_texel, bounds):
    """Fill the arrays of :func:`tile_layout`, in parallel over tiles (padding: 0, texel -1)."""
    height, width = valid.shape
    for tile in numba.prange(tiled_texel.shape[0]):
        top = (tile // tiles_x) * TILE
        left = (tile % tiles_x) * TILE
        for c in range(3):
            bounds[tile, c] = np.inf
            bounds[tile, 3 + c] = -np.inf
        for i in range(TILE * TILE):
            y = top + i // TILE
            x = left + i % TILE
            inside = y < height and x < width
            counted = inside and valid[y, x]
            tiled_texel[tile, i] = texel[y, x] if counted else -1
            for c in range(3):
                value = np.float32(position[c, y, x]) if inside else np.float32(0.0)
                tiled_position[tile, c, i] = value
                if counted:
                    bounds[tile, c] = min(bounds[tile, c], value)
                    bounds[tile, 3 + c] = max(bounds[tile, 3 + c], value)


def untile(tiled: np.ndarray, tiles_y: int, tiles_x: int, height: int, width: int):
    """Return the (H, W, 3) image of per-tile values ``tiled`` (tiles, 3, TILE * TILE)."""
    return tiled.reshape(tiles_y, tiles_x, 3, TILE, TILE).transpose(0, 3, 1, 4, 2).reshape(
        tiles_y * TILE, tiles_x * TILE, 3)[:height, :width]


@parallel_njit(cache=True)
def untile_float64(tiled, tiles_x, height, width):
    """Return :func:`untile` as a new float64 (H, W, 3) array, filled in parallel over rows."""
    out = np.empty((height, width, 3))
    for y in numba.prange(height):
        for x in range(width):
            tile = (y // TILE) * tiles_x + x // TILE
            i = (y % TILE) * TILE + x % TILE
            for c in range(3):
                out[y, x, c] = tiled[tile, c, i]
    return out


@parallel_njit(cache=True)
def splat_windows(position, flux, low, high, origin, forward, right, up, tan_half_fov, width,
                  height):
    r"""Each sample's window on one splatting level: which samples a level splats, and where.

    A sample takes part when its range is not empty (``high > low``) and it carries flux.
    Its point projects (pinhole, ``origin`` and the unit ``forward``, ``right``, ``up``) to
    continuous pixel coordinates :math:`(x, y)` at depth :math:`z`; a point within
    :math:`R` = ``high`` of it projects within ``reach`` pixels, :math:`f R s / (z - R)`
    with :math:`f` the focal length in pixels and :math:`s = \sqrt{1 + ((x - W/2)/f)^2 +
    ((y - H/2)/f)^2}` (Cauchy-Schwarz: off axis too); a sample whose sphere reaches the
    camera plane (:math:`z - R \le 0`) gets the whole level. Samples whose disc lies wholly
    off the level are dropped. Not fastmath: the same float64 operations, in the same
    order, as the numpy formulas these replace.

    Parameters
    ----------
    position : ndarray (N, 3)
        Sample points, scene units.
    flux : ndarray (N, 3)
    low, high : ndarray (N,)
        :math:`[R^k_{min}, R^k_{max})`, scene units.
    origin, forward, right, up : ndarray (3,)
        The camera.
    tan_half_fov : float
        Of the horizontal field of view.
    width, height : int
        The level's size in pixels.

    Returns
    -------
    index : ndarray (M,) int64
        The samples splatted, in input order.
    centre_x, centre_y : ndarray (M,)
        Window centres, continuous pixel coordinates.
    radius : ndarray (M,)
        Whole-pixel radius of the window, ``ceil(reach) + 1`` (at most the level's side).
    reach : ndarray (M,)
        The projected reach in pixels (at most the level's side).
    """
    count = position.shape[0]
    focal = width / (2.0 * tan_half_fov)
    limit = float(max(width, height))
    keep = np.zeros(count, np.bool_)
    values = np.empty((count, 4))
    for i in numba.prange(count):
        f0, f1, f2 = flux[i, 0], flux[i, 1], flux[i, 2]
        # as numpy's max: a NaN channel makes the maximum NaN, which is not > 0
        if not (high[i] > low[i]) or f0 != f0 or f1 != f1 or f2 != f2 or \
                not (max(f0, f1, f2) > 0):
            continue
        rx = position[i, 0] - origin[0]
        ry = position[i, 1] - origin[1]
        rz = position[i, 2] - origin[2]
        z = rx * forward[0] + ry * forward[1] + rz * forward[2]
        safe = z if abs(z) > 1e-12 else 1e-12
        x = (rx * right[0] + ry * right[1] + rz * right[2]) / safe * focal + 0.5 * width
        y = -(rx * up[0] + ry * up[1] + rz * up[2]) / safe * focal + 0.5 * height
        reach_world = high[i]
        dx = (x - 0.5 * width) / focal
        dy = (y - 0.5 * height) / focal
        spread = math.sqrt(1.0 + dx * dx + dy * dy)
        gap = z - reach_world
        if gap > 1e-9 * abs(reach_world) + 1e-300:
            reach = reach_world * focal * spread / gap
        else:
            reach = np.inf
        radius = min(np.ceil(reach) + 1.0, limit)
        behind = gap <= 0
        onscreen = (x + radius >= 0) and (x - radius < width) and (y + radius >= 0) and \
            (y - radius < height) and np.isfinite(x) and np.isfinite(y)
        if not (onscreen or behind):
            continue
        keep[i] = True
        values[i, 0] = 0.5 * width if behind else x
        values[i, 1] = 0.5 * height if behind else y
        values[i, 2] = limit if behind else radius
        values[i, 3] = limit if behind else min(reach, limit)
    index = np.flatnonzero(keep)
    kept = index.shape[0]
    centre_x = np.empty(kept)
    centre_y = np.empty(kept)
    radius_out = np.empty(kept)
    reach_out = np.empty(kept)
    for j in numba.prange(kept):
        i = index[j]
        centre_x[j] = values[i, 0]
        centre_y[j] = values[i, 1]
        radius_out[j] = values[i, 2]
        reach_out[j] = values[i, 3]
    return index, centre_x, centre_y, radius_out, reach_out


@numba.njit(inline="always", fastmath=True, cache=True)
def _culled(bounds, tile, fx, fy, fz, low2, high2):
    """Return True when no point of the tile's box lies in [sqrt(low2), sqrt(high2))."""
    gx = max(bounds[tile, 0] - fx, fx - bounds[tile, 3], 0.0)
    gy = max(bounds[tile, 1] - fy, fy - bounds[tile, 4], 0.0)
    gz = max(bounds[tile, 2] - fz, fz - bounds[tile, 5], 0.0)
    hx = max(abs(bounds[tile, 0] - fx), abs(bounds[tile, 3] - fx))
    hy = max(abs(bounds[tile, 1] - fy), abs(bounds[tile, 4] - fy))
    hz = max(abs(bounds[tile, 2] - fz), abs(bounds[tile, 5] - fz))
    return gx * gx + gy * gy + gz * gz >= high2 or hx * hx + hy * hy + hz * hz < low2


@numba.njit(cache=True)
def prefix_sum(count):  # pragma: no cover - compiled
    """Turn ``count`` into its inclusive running sum, in place."""
    for index in range(1, count.shape[0]):
        count[index] += count[index - 1]


@numba.njit(inline="always", fastmath=True, cache=True)
def _disc_columns(row, centre_x, centre_y, radius, tiles_x):
    """First and last tile column whose square meets the disc, in one row of tiles."""
    gap = max(TILE * row - centre_y, centre_y - TILE * (row + 1), 0.0)
    if gap > radius:
        return 0, -1
    half = math.sqrt(radius * radius - gap * gap)
    first = max(int(math.floor((centre_x - half) / TILE)), 0)
    last = min(int(math.floor((centre_x + half) / TILE)), tiles_x - 1)
    return first, last


@parallel_njit(fastmath=True, cache=True)
def bin_samples(bounds, tiles_y, tiles_x, sample_position, centre_x, centre_y, radius, low2,
                high2):
    r"""List, per tile, the samples whose effective rendering range may reach it.

    A sample reaches the tiles that its window (pixel centres within ``radius`` of
    ``(centre_x, centre_y)``, continuous pixel coordinates) overlaps, less those whose
    bounding box lies wholly outside :math:`[\sqrt{low2}, \sqrt{high2})` of it. Samples
    keep their input order within a tile. Binned by tile rows first, so that the per-tile
    pass runs in parallel over rows of tiles; each row's tiles that meet the disc are
    culled once, the survivors kept in row order, then scattered to their tiles.

    Returns
    -------
    start : ndarray (tiles + 1,) int64
        Tile ``t``'s samples are ``members[start[t]:start[t + 1]]``.
    members : ndarray int32
    """
    count = sample_position.shape[1]
    first_row = np.empty(count, np.int64)
    last_row = np.empty(count, np.int64)
    for s in numba.prange(count):
        first_row[s] = max(int(math.floor((centre_y[s] - radius[s]) / TILE)), 0)
        last_row[s] = min(int(math.floor((centre_y[s] + radius[s]) / TILE)), tiles_y - 1)
    # rows' member lists in parallel over chunks of samples: each chunk counts its samples
    # per row, the counts are laid out row by row and chunk by chunk, then each chunk fills
    # its slots, so every row lists its samples in input order as a serial pass would
    chunks = max(1, min(count, _BIN_CHUNKS))
    per_chunk = np.zeros((chunks, tiles_y), np.int64)
    for chunk in numba.prange(chunks):
        for s in range(chunk * count // chunks, (chunk + 1) * count // chunks):
            for row in range(first_row[s], last_row[s] + 1):
                per_chunk[chunk, row] += 1
    row_start = np.zeros(tiles_y + 1, np.int64)
    running = 0
    for row in range(tiles_y):
        row_start[row] = running
        for chunk in range(chunks):
            count_here = per_chunk[chunk, row]
            per_chunk[chunk, row] = running
            running += count_here
    row_start[tiles_y] = running
    row_members = np.empty(running, np.int32)
    for chunk in numba.prange(chunks):
        cursor = per_chunk[chunk].copy()
        for s in range(chunk * count // chunks, (chunk + 1) * count // chunks):
            for row in range(first_row[s], last_row[s] + 1):
                row_members[cursor[row]] = s
                cursor[row] += 1
    # room for every (sample, tile) candidate of each row, before culling
    room = np.zeros(tiles_y + 1, np.int64)
    for row in numba.prange(tiles_y):
        total = 0
        for j in range(row_start[row], row_start[row + 1]):
            s = row_members[j]
            first, last = _disc_columns(row, centre_x[s], centre_y[s], radius[s], tiles_x)
            total += max(last - first + 1, 0)
        room[row + 1] = total
    prefix_sum(room)
    kept_sample = np.empty(room[-1], np.int32)
    kept_column = np.empty(room[-1], np.int32)
    kept = np.zeros(tiles_y, np.int64)
    start = np.zeros(tiles_y * tiles_x + 1, np.int64)
    for row in numba.prange(tiles_y):
        at = room[row]
        for j in range(row_start[row], row_start[row + 1]):
            s = row_members[j]
            first, last = _disc_columns(row, centre_x[s], centre_y[s], radius[s], tiles_x)
            for column in range(first, last + 1):
                tile = row * tiles_x + column
                if _culled(bounds, tile, sample_position[0, s], sample_position[1, s],
                           sample_position[2, s], low2[s], high2[s]):
                    continue
                kept_sample[at] = s
                kept_column[at] = column
                at += 1
                start[tile + 1] += 1
        kept[row] = at - room[row]
    prefix_sum(start)
    members = np.empty(start[-1], np.int32)
    for row in numba.prange(tiles_y):
        slot = start[row * tiles_x:(row + 1) * tiles_x].copy()
        for q in range(room[row], room[row] + kept[row]):
            column = kept_column[q]
            members[slot[column]] = kept_sample[q]
            slot[column] += 1
    return start, members


@numba.njit(inline="always", fastmath=True, cache=True)
def _lane_in_range(px, py, pz, labels, i, fx, fy, fz, low, high, step_inverse, support):
    """Segment position (segments from the sample) of lane ``i`` and whether it is in range."""
    ddx = px[i] - fx
    ddy = py[i] - fy
    ddz = pz[i] - fz
    d2 = ddx * ddx + ddy * ddy + ddz * ddz
    at = math.sqrt(d2) * step_inverse
    return at, (labels[i] >= 0) & (d2 >= low) & (d2 < high) & (at < support)


@parallel_njit(fastmath=True, cache=True)
def splat_tiles(out, position, texel, table, step_inverse, sample_position, sample_texel,
                sample_flux, low2, high2, start, members, narrow=NARROW_WIDTH):
    r"""Eq. 12 of Chen et al. 2012: every tile gathers the splats of its binned samples.

    Tile ``t`` adds :math:`\sqrt{P_{x_o}(d)P_{x_i}(d)}\,\Phi_s` (Eq. 8-9) of each of its
    samples ``s`` (:func:`bin_samples`) to every valid pixel whose surface point lies at a
    squared distance :math:`d^2 \in` ``[low2[s], high2[s])`` and within the profiles'
    support. Per sample and tile, the distances over the tile's pixels (vectorised), then
    one of two paths:

    * *two segments* (a sample whose annulus is narrower than ``narrow`` segments, and
      whose pixels in range, at least :data:`FEWEST_IN_VECTORS`, all fall into segments
      :math:`k` and :math:`k+1`): the
      pixels' halves of the table come from a copy local to the tile laid out
      [segment, 6, pixel] (filled once per segment and tile), the sample's half is two
      scalars, and all 64 pixels are evaluated in vectors, those out of range masked;
    * *general*: the pixels in range gathered into a list (branch-free), the two
      texels' table rows read for those (scalar), the exponentials (vectorised), then
      the accumulation.

    Tiles run in parallel and each owns its pixels, so the result does not depend on the
    number of threads. The two paths agree to float32 rounding (the same sums, contracted
    to fused multiply-adds in different places).

    Parameters
    ----------
    out : ndarray (tiles, 3, TILE * TILE) float32
        :math:`B^k` per tile, channel and pixel; written.
    position : ndarray (tiles, 3, TILE * TILE) float32
        The level's surface points, scene units (:func:`tile_layout`).
    texel : ndarray (tiles, TILE * TILE) int32
        Each pixel's texel (row of ``table``); negative where the pixel is invalid.
    table : ndarray (T, n, 6) float32
        :func:`segment_table`.
    step_inverse : float32
        Segments per scene unit, :math:`n / r_s`.
    sample_position : ndarray (3, N) float32
    sample_texel : ndarray (N,) int32
    sample_flux : ndarray (N, 3) float32
        :math:`E\,\Delta A` times the unit conversion of the profile.
    low2, high2 : ndarray (N,) float32
        Squared bounds of the effective rendering range, scene units squared.
    start, members : ndarray
        :func:`bin_samples`.
    narrow : float32, optional
        Width of the annulus :math:`\sqrt{high2} - \sqrt{low2}`, in segments, below which
        the two-segment path is tried (:data:`NARROW_WIDTH`); 0 takes the general path
        for every sample.

    Returns
    -------
    ndarray (tiles,) int64
        Sample-pixel pairs within range (evaluated) per tile.
    """
    tiles = start.shape[0] - 1
    lanes = position.shape[2]
    segments = table.shape[1]
    stride = np.uint64(segments * 6)
    flat = table.reshape(-1)
    support = np.float32(segments)
    used = np.zeros(tiles, np.int64)
    # decided once per sample, not per sample and tile: the test in the tile loop cost the
    # wide annuli of level 2 about 4 % more time
    is_narrow = np.empty(low2.shape[0], np.bool_)
    for s in range(low2.shape[0]):
        is_narrow[s] = (math.sqrt(high2[s]) - math.sqrt(max(low2[s], np.float32(0.0)))) * \
            step_inverse < narrow
    for tile in numba.prange(tiles):
        out[tile] = 0.0
        if start[tile + 1] == start[tile]:
            continue
        px = position[tile, 0]
        py = position[tile, 1]
        pz = position[tile, 2]
        labels = texel[tile]
        accumulated = out[tile]
        at = np.empty(lanes, np.float32)
        inside = np.empty(lanes, np.int32)
        lane = np.empty(lanes, np.int32)
        value = np.zeros((3, lanes), np.float32)
        local = np.empty((segments, 6, lanes), np.float32)
        ready = np.zeros(segments, np.bool_)
        pairs = 0
        for j in range(start[tile], start[tile + 1]):
            s = members[j]
            fx = sample_position[0, s]
            fy = sample_position[1, s]
            fz = sample_position[2, s]
            low = low2[s]
            high = high2[s]
            own = np.uint64(sample_texel[s]) * stride
            if is_narrow[s]:
                first = segments
                last = -1
                count = 0
                for i in range(lanes):  # vectorised: distances, range test, segment range
                    at[i], ok = _lane_in_range(px, py, pz, labels, i, fx, fy, fz, low, high,
                                               step_inverse, support)
                    inside[i] = np.int32(ok)
                    count += np.int32(ok)
                    k = np.int32(at[i])
                    first = min(first, k if ok else segments)
                    last = max(last, k if ok else -1)
                if last < 0:
                    continue
                if last - first <= 1 and count >= FEWEST_IN_VECTORS:
                    pairs += _splat_two_segments(accumulated, at, inside, labels, flat, own,
                                                 stride, first, local, ready,
                                                 sample_flux[s])
                    continue
            else:
                for i in range(lanes):  # vectorised: distances and the range test
                    at[i], ok = _lane_in_range(px, py, pz, labels, i, fx, fy, fz, low, high,
                                               step_inverse, support)
                    inside[i] = np.int32(ok)
            n = 0
            for i in range(lanes):  # branch-free list of the pixels in range
                lane[n] = i
                n += inside[i]
            pairs += n
            for m in range(n):  # scalar: table look-ups of both texels (Eq. 8-9)
                i = lane[m]
                k = np.int32(at[i])
                w = at[i] - np.float32(k)
                knot = np.uint64(k) * np.uint64(6)
                a = np.uint64(labels[i]) * stride + knot
                b = own + knot
                value[0, m] = (flat[a] + flat[b]) + w * (flat[a + np.uint64(3)] +
                                                         flat[b + np.uint64(3)])
                value[1, m] = (flat[a + np.uint64(1)] + flat[b + np.uint64(1)]) + \
                    w * (flat[a + np.uint64(4)] + flat[b + np.uint64(4)])
                value[2, m] = (flat[a + np.uint64(2)] + flat[b + np.uint64(2)]) + \
                    w * (flat[a + np.uint64(5)] + flat[b + np.uint64(5)])
            # whole vectors of 16 (past n: stale values, never accumulated), so that short
            # lists do not fall to the compiler's scalar remainder loop
            padded = min((n + 15) & ~15, lanes)
            for c in range(3):  # vectorised: exponentials
                flux = sample_flux[s, c]
                for m in range(padded):
                    value[c, m] = exp32(value[c, m]) * flux
            for m in range(n):
                i = lane[m]
                accumulated[0, i] += value[0, m]
                accumulated[1, i] += value[1, m]
                accumulated[2, i] += value[2, m]
        used[tile] = pairs
    return used


@numba.njit(fastmath=True, cache=True)
def _splat_two_segments(accumulated, at, inside, labels, flat, own, stride, first, local,
                        ready, flux):
    """Splat one sample into all pixels of a tile: the two-segment path of :func:`splat_tiles`.

    The pixels in range (``inside``) lie in segments ``first`` and ``first + 1``; returns
    their number. A regular (not inlined) function: inlined into the tile loop, the
    compiler no longer vectorised its loop over the pixels (measured 10x slower).
    """
    lanes = at.shape[0]
    segments = local.shape[0]
    second = min(first + 1, segments - 1)
    for k in range(first, second + 1):
        if ready[k]:
            continue
        ready[k] = True
        for c in range(6):
            for i in range(lanes):  # invalid pixels read texel 0 and are masked below
                local[k, c, i] = flat[np.uint64(max(labels[i], 0)) * stride +
                                      np.uint64(k * 6 + c)]
    count = 0
    for i in range(lanes):
        count += inside[i]
    base = own + np.uint64(first * 6)
    step = np.uint64(6) if second > first else np.uint64(0)
    split = np.float32(first + 1)
    for c in range(3):
        half0 = flat[base + np.uint64(c)]
        slope0 = flat[base + np.uint64(3 + c)]
        half1 = flat[base + step + np.uint64(c)]
        slope1 = flat[base + step + np.uint64(3 + c)]
        pixel_half0 = local[first, c]
        pixel_slope0 = local[first, 3 + c]
        pixel_half1 = local[second, c]
        pixel_slope1 = local[second, 3 + c]
        row = accumulated[c]
        scale = flux[c]
        for i in range(lanes):  # vectorised: both segments' values loaded, then selected
            upper = at[i] >= split
            h0 = pixel_half0[i] + half0
            h1 = pixel_half1[i] + half1
            g0 = pixel_slope0[i] + slope0
            g1 = pixel_slope1[i] + slope1
            w = at[i] - (split if upper else np.float32(first))
            h = h1 if upper else h0
            g = g1 if upper else g0
            term = exp32(h + w * g) * scale
            row[i] += term if inside[i] != 0 else np.float32(0.0)
    return count


@parallel_njit(fastmath=True, cache=True)
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
