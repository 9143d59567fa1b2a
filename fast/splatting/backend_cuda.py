r"""CUDA kernels of the multiresolution splatting method (Chen et al. 2012), via numba.cuda.

The GPU counterpart of :func:`translucent.fast.splatting.backend_numba.bin_samples` and
:func:`~translucent.fast.splatting.backend_numba.splat_tiles` (Eq. 12, backend ``"cuda"`` of
:func:`translucent.fast.splatting.splat_level`). Binning: one thread per sample walks the
tiles of its window, culls them against each tile's box with the CPU kernel's own
functions compiled for the device, and counts, then fills, each tile's list. Splatting:
one thread block per tile of :data:`~translucent.fast.splatting.backend_numba.TILE` x ``TILE``
pixels, one thread per pixel; the block walks its tile's samples in chunks staged in
shared memory, each thread tests its pixel's distance against the sample's
:math:`[R^k_{min}, R^k_{max})` and adds :math:`\sqrt{P_{x_o}(d)P_{x_i}(d)}\,\Phi_s`
(Eq. 8-9, float32 terms) to float64 sums in registers. The terms are the CPU kernel's;
they differ by the exponential (the GPU's ``__expf`` under fastmath, relative error of a
few 1e-6 over the profile's range), by where multiply-adds are fused, and by the order of
the sums (the CPU adds in float32 in sample order).

Measured on an NVIDIA H100 (heterogeneous scene, 800 x 600, 512^2, both accelerations,
111 million pairs in range): the splat kernel took 0.42, 1.10 and 5.93 ms at levels 0, 1
and 2 with float32 sums and CPU binning (7.5 ms a frame, against about 0.6 CPU-bound
seconds for the compiled CPU kernel on two cores); with the binning on the GPU, binning,
splatting and the transfers take 38 ms a frame. The frame (0.21 s, 4.8 frames per second
with 16 CPU cores beside it) is bound by the stages that run on the CPU.

Without a GPU the same kernels run in numba's CUDA simulator (``NUMBA_ENABLE_CUDASIM=1``),
which is how they are tested on machines without one.

References
----------
Chen, Peers, Zhang, Tong: Real-time rendering of deformable heterogeneous translucent
objects using multiresolution splatting. The Visual Computer (2012).
"""

from __future__ import annotations

import functools
import math

import numpy as np
from numba import cuda, float32, float64, int32

from ...errors import InputError
from . import backend_numba as _cpu

__all__ = ["available", "bin_and_splat_tiles", "gather_samples", "SAMPLES_PER_CHUNK"]

#: Samples staged in shared memory at a time by :func:`splat_tiles` (one per thread of an
#: 8 x 8 tile: each thread loads one).
SAMPLES_PER_CHUNK = 64
#: Threads per block of the binning (one thread per sample).
_BIN_THREADS = 128
#: Threads per block of the brute-force gather.
_GATHER_THREADS = 128


def available() -> bool:
    """Return True when numba.cuda can run kernels here (a GPU, or the simulator)."""
    try:
        return bool(cuda.is_available())
    except Exception:  # noqa: BLE001 - a broken driver reads as "no GPU"
        return False


def _require():
    if not available():
        raise InputError("backend 'cuda' needs a CUDA GPU that numba.cuda can use (or "
                         "NUMBA_ENABLE_CUDASIM=1 for the simulator); use backend 'numba'",
                         field="backend", value="cuda")
    problem = _compile_problem()
    if problem is not None:
        raise InputError(f"numba.cuda sees a GPU but cannot compile a kernel ({problem}); "
                         "see docs/splatting.md for a known numba-cuda / numpy clash, or "
                         "use backend 'numba'", field="backend", value="cuda")


@functools.lru_cache(maxsize=1)
def _compile_problem() -> str | None:
    """Compile and run a one-thread kernel once: None, or what went wrong."""
    try:
        probe = cuda.device_array(1, np.float32)
        _probe[1, 1](probe)
        cuda.synchronize()
    except Exception as error:  # noqa: BLE001 - whatever the toolchain raises is reported
        return f"{type(error).__name__}: {error}"
    return None


@cuda.jit
def _probe(out):
    out[0] = float32(1.0)


# the CPU binning's own functions, compiled for the device (one source for both)
_culled = cuda.jit(device=True, inline=True)(_cpu._culled.py_func)
_disc_columns = cuda.jit(device=True, inline=True)(_cpu._disc_columns.py_func)


@cuda.jit(device=True, inline=True, fastmath=True)
def _pair(table, label, own, at):
    # Eq. 8-9: sqrt(P_o(d) P_i(d)) per channel, float32, at ``at`` segments from the sample
    k = int32(at)
    w = at - float32(k)
    return (math.exp((table[label, k, 0] + table[own, k, 0]) +
                     w * (table[label, k, 3] + table[own, k, 3])),
            math.exp((table[label, k, 1] + table[own, k, 1]) +
                     w * (table[label, k, 4] + table[own, k, 4])),
            math.exp((table[label, k, 2] + table[own, k, 2]) +
                     w * (table[label, k, 5] + table[own, k, 5])))


@cuda.jit(fastmath=True)
def _bin_tiles(bounds, sample_position, centre_x, centre_y, radius, low2, high2, tiles_y,
               tiles_x, counter, start, members, fill):
    # one thread per sample; counts its tiles into ``counter`` or, with ``fill``, takes a
    # slot of each tile's list (``counter`` zeroed again) and writes itself there
    s = cuda.grid(1)
    if s >= centre_x.shape[0]:
        return
    first_row = max(int(math.floor((centre_y[s] - radius[s]) / _cpu.TILE)), 0)
    last_row = min(int(math.floor((centre_y[s] + radius[s]) / _cpu.TILE)), tiles_y - 1)
    for row in range(first_row, last_row + 1):
        first, last = _disc_columns(row, centre_x[s], centre_y[s], radius[s], tiles_x)
        for column in range(first, last + 1):
            tile = row * tiles_x + column
            if _culled(bounds, tile, sample_position[0, s], sample_position[1, s],
                       sample_position[2, s], low2[s], high2[s]):
                continue
            slot = cuda.atomic.add(counter, tile, 1)
            if fill:
                members[start[tile] + slot] = s


@cuda.jit(fastmath=True)
def _splat(out, used, position, texel, table, step_inverse, sample_position,
          sample_texel, sample_flux, low2, high2, start, members):
    tile = cuda.blockIdx.x
    lane = cuda.threadIdx.x
    shared_x = cuda.shared.array(SAMPLES_PER_CHUNK, float32)
    shared_y = cuda.shared.array(SAMPLES_PER_CHUNK, float32)
    shared_z = cuda.shared.array(SAMPLES_PER_CHUNK, float32)
    shared_low = cuda.shared.array(SAMPLES_PER_CHUNK, float32)
    shared_high = cuda.shared.array(SAMPLES_PER_CHUNK, float32)
    shared_texel = cuda.shared.array(SAMPLES_PER_CHUNK, int32)
    shared_flux = cuda.shared.array((SAMPLES_PER_CHUNK, 3), float32)
    px = position[tile, 0, lane]
    py = position[tile, 1, lane]
    pz = position[tile, 2, lane]
    label = texel[tile, lane]
    segments = table.shape[1]
    support = float32(segments)
    # float64 sums: the binning orders a tile's samples as its threads arrive
    red = float64(0.0)
    green = float64(0.0)
    blue = float64(0.0)
    pairs = 0
    first = start[tile]
    last = start[tile + 1]
    for base in range(first, last, SAMPLES_PER_CHUNK):
        cuda.syncthreads()  # the previous chunk is read by every thread
        if lane < SAMPLES_PER_CHUNK and base + lane < last:
            s = members[base + lane]
            shared_x[lane] = sample_position[0, s]
            shared_y[lane] = sample_position[1, s]
            shared_z[lane] = sample_position[2, s]
            shared_low[lane] = low2[s]
            shared_high[lane] = high2[s]
            shared_texel[lane] = sample_texel[s]
            shared_flux[lane, 0] = sample_flux[s, 0]
            shared_flux[lane, 1] = sample_flux[s, 1]
            shared_flux[lane, 2] = sample_flux[s, 2]
        cuda.syncthreads()
        if label < 0:
            continue
        for m in range(min(SAMPLES_PER_CHUNK, last - base)):
            dx = px - shared_x[m]
            dy = py - shared_y[m]
            dz = pz - shared_z[m]
            d2 = dx * dx + dy * dy + dz * dz
            if d2 < shared_low[m] or d2 >= shared_high[m]:
                continue
            at = math.sqrt(d2) * step_inverse
            if at >= support:
                continue
            r, g, b = _pair(table, label, shared_texel[m], at)
            red += r * shared_flux[m, 0]
            green += g * shared_flux[m, 1]
            blue += b * shared_flux[m, 2]
            pairs += 1
    out[tile, 0, lane] = red
    out[tile, 1, lane] = green
    out[tile, 2, lane] = blue
    if pairs:
        cuda.atomic.add(used, tile, pairs)

@cuda.jit(fastmath=True)
def _gather(out, pixel_position, pixel_texel, table, step_inverse, sample_position,
           sample_texel, sample_flux):
    pixel = cuda.grid(1)
    if pixel >= pixel_texel.shape[0]:
        return
    px = pixel_position[0, pixel]
    py = pixel_position[1, pixel]
    pz = pixel_position[2, pixel]
    label = pixel_texel[pixel]
    segments = table.shape[1]
    support = float32(segments)
    # float64 sums: hundreds of thousands of terms per pixel (the CPU kernel's too)
    red = float64(0.0)
    green = float64(0.0)
    blue = float64(0.0)
    for s in range(sample_texel.shape[0]):
        dx = px - sample_position[0, s]
        dy = py - sample_position[1, s]
        dz = pz - sample_position[2, s]
        at = math.sqrt(dx * dx + dy * dy + dz * dz) * step_inverse
        if at >= support:
            continue
        r, g, b = _pair(table, label, sample_texel[s], at)
        red += r * sample_flux[0, s]
        green += g * sample_flux[1, s]
        blue += b * sample_flux[2, s]
    out[pixel, 0] = red
    out[pixel, 1] = green
    out[pixel, 2] = blue


#: Segment tables on the device, by the identity of the host array (which each entry keeps
#: alive, so that the identity is not reused): ``splatting._segment_table`` returns one
#: array per material, so a material's table is uploaded once.
_DEVICE_TABLES: dict[int, tuple] = {}
#: Device tables kept at most (the oldest is dropped first).
_DEVICE_TABLES_KEPT = 8


def _table_on_device(table: np.ndarray):
    entry = _DEVICE_TABLES.get(id(table))
    if entry is None or entry[0] is not table:
        if len(_DEVICE_TABLES) >= _DEVICE_TABLES_KEPT:
            _DEVICE_TABLES.pop(next(iter(_DEVICE_TABLES)))
        entry = (table, cuda.to_device(np.ascontiguousarray(table, np.float32)))
        _DEVICE_TABLES[id(table)] = entry
    return entry[1]


def bin_and_splat_tiles(out, position, texel, tile_bounds, tiles_x, table, step_inverse,
                        sample_position, sample_texel, sample_flux, low2, high2, centre_x,
                        centre_y, radius):
    r"""Bin samples to tiles and splat them (Eq. 12 of Chen et al. 2012), all on the GPU.

    The binning is :func:`translucent.fast.splatting.backend_numba.bin_samples`' (the same disc
    of tiles, the same culling against each tile's box: its functions compiled for the
    device), counted per tile, then filled, by one thread per sample; the splat is
    :func:`translucent.fast.splatting.backend_numba.splat_tiles`'. The fill orders a tile's
    samples as the threads arrive, so each pixel sums its terms in float64 (the float32
    result then hardly depends on that order: it changes in the last bit only where the sum
    lies within about 1e-12 of a rounding boundary).

    Parameters
    ----------
    out : ndarray (tiles, 3, TILE * TILE) float32
        Written.
    position, texel, tile_bounds, tiles_x
        :func:`~translucent.fast.splatting.backend_numba.tile_layout`.
    table, step_inverse, sample_position, sample_texel, sample_flux, low2, high2
        As :func:`~translucent.fast.splatting.backend_numba.splat_tiles` (``table`` is uploaded
        once and kept on the device).
    centre_x, centre_y, radius : ndarray (N,) float32
        Each sample's window, as :func:`~translucent.fast.splatting.backend_numba.bin_samples`.

    Returns
    -------
    used : ndarray (tiles,) int64
        Sample-pixel pairs within range per tile.
    binned : int
        Sample-tile pairs binned.
    """
    _require()
    tiles, _, lanes = position.shape
    count = len(sample_texel)
    if tiles == 0 or count == 0:
        out[...] = 0.0
        return np.zeros(tiles, np.int64), 0
    tiles_y = tiles // tiles_x
    stream = cuda.stream()

    def upload(array):
        return cuda.to_device(np.ascontiguousarray(array), stream=stream)

    window = [upload(array) for array in (tile_bounds, sample_position, centre_x, centre_y,
                                          radius, low2, high2)]
    counter = cuda.to_device(np.zeros(tiles, np.int64), stream=stream)
    blocks = -(-count // _BIN_THREADS)
    start = np.zeros(tiles + 1, np.int64)
    # the counting pass writes no list: one-element stand-ins of the fill pass's types
    _bin_tiles[blocks, _BIN_THREADS, stream](
        *window, tiles_y, tiles_x, counter, cuda.device_array(1, np.int64, stream=stream),
        cuda.device_array(1, np.int32, stream=stream), False)
    np.cumsum(counter.copy_to_host(stream=stream), out=start[1:])  # synchronises
    binned = int(start[-1])
    if binned == 0:
        out[...] = 0.0
        return np.zeros(tiles, np.int64), 0
    device_start = upload(start)
    members = cuda.device_array(binned, np.int32, stream=stream)
    counter = cuda.to_device(np.zeros(tiles, np.int64), stream=stream)
    _bin_tiles[blocks, _BIN_THREADS, stream](*window, tiles_y, tiles_x, counter, device_start,
                                             members, True)
    device_out = cuda.device_array(out.shape, np.float32, stream=stream)
    used = cuda.to_device(np.zeros(tiles, np.int64), stream=stream)
    _splat[tiles, lanes, stream](device_out, used, upload(position), upload(texel),
                                 _table_on_device(table), np.float32(step_inverse),
                                 window[1], upload(sample_texel), upload(sample_flux),
                                 window[5], window[6], device_start, members)
    device_out.copy_to_host(out, stream=stream)
    counts = used.copy_to_host(stream=stream)
    stream.synchronize()
    return counts, binned


def gather_samples(out, pixel_position, pixel_texel, table, step_inverse, sample_position,
                   sample_texel, sample_flux):
    r"""Eq. 5 by brute force on the GPU, as :func:`.backend_numba.gather_samples`.

    ``out`` (pixels, 3) receives the sums (float64, each term float32); ``sample_flux``
    is (3, N).
    """
    _require()
    pixels = len(pixel_texel)
    if pixels == 0 or len(sample_texel) == 0:
        out[...] = 0.0
        return
    device_out = cuda.device_array((pixels, 3), np.float64)
    blocks = -(-pixels // _GATHER_THREADS)
    _gather[blocks, _GATHER_THREADS](
        device_out, cuda.to_device(np.ascontiguousarray(pixel_position, np.float32)),
        cuda.to_device(np.ascontiguousarray(pixel_texel, np.int32)), _table_on_device(table),
        np.float32(step_inverse),
        cuda.to_device(np.ascontiguousarray(sample_position, np.float32)),
        cuda.to_device(np.ascontiguousarray(sample_texel, np.int32)),
        cuda.to_device(np.ascontiguousarray(sample_flux, np.float32)))
    out[...] = device_out.copy_to_host()
