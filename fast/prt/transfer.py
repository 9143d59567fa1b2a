"""Illumination samples and the compressed transfer matrices (Wang et al. 2008).

Eq. 5-7 tabulated on the samples, the Haar pass of Eq. 8 and the spatial CDF 9/7 pass of Eq. 9-10.
"""

from __future__ import annotations

import concurrent.futures
import contextlib
import math
import time
from dataclasses import dataclass

import numba
import numpy as np

from ...compiled import parallel_njit
from ...materials.dipole_pca import (
    DipolePCABasis,
)
from ...scenes.mesh_shape import stratified_surface_points
from ..base import StageLog
from ..sparse_transport import (
    QuantisedRows,
    SharedColumnBlocks,
    SparseRows,
    select_largest_weighted,
)
from ..wavelets import (
    SpatialWavelet,
    balanced_split,
    haar2d_forward,
    haar2d_inplace,
    haar2d_support_weights,
    quadtree_layout,
)
from .knobs import (
    LOCAL_KERNEL_WIDTH,
    PRT_VERSION,
    SPATIAL_COLUMNS_PER_BLOCK,
    UNKEYED_KNOBS,
    VERTICES_PER_BLOCK,
    pca_basis_for,
    quadtree_level,
)

# ------------------------------------------------------------- illumination samples


@dataclass(frozen=True, eq=False)
class IlluminationSamples:
    """Uniform surface samples in the order of their quadtree layout.

    Sample ``p * side**2 + row * side + col`` is the pixel ``(row, col)`` of part ``p``.

    Attributes
    ----------
    positions, normals : ndarray, (N, 3)
        Scene units; unit interpolated vertex normals.
    area : float
        Surface area each sample stands for, mm^2 (all equal).
    parts, side : int
        ``m`` and ``2^n``.
    """

    positions: np.ndarray
    normals: np.ndarray
    area: float
    parts: int
    side: int

    def __len__(self) -> int:
        return len(self.positions)

    def to_wavelets(self, values) -> np.ndarray:
        """Haar coefficients (Eq. 8) of per-sample values ``(N, C)``, shape ``(N, C)``."""
        values = np.asarray(values, dtype=np.float32)
        images = values.T.reshape(values.shape[1], self.parts, self.side, self.side)
        return haar2d_forward(images).reshape(values.shape[1], -1).T.copy()


def illumination_samples(mesh, count: int, parts: int, *, mm_per_unit: float = 1.0,
                         seed: int = 0) -> IlluminationSamples:
    """Uniform samples on a mesh, split into parts and laid out by balanced quadtrees.

    Sect. 3.2 of Wang et al. 2008 ("Transfer compression"): ``count = parts x 4^n`` points
    placed uniformly by area (stratified along the faces' cumulative area, uniform within a
    face), split into ``parts`` equal groups by median cuts (:func:`balanced_split`), each
    group laid out on a ``2^n`` square by :func:`quadtree_layout`.

    Parameters
    ----------
    mesh : Mesh
    count, parts : int
    mm_per_unit : float
        Scene scale, for the per-sample area in mm^2.
    seed : int

    Returns
    -------
    IlluminationSamples
    """
    level = quadtree_level(count, parts)
    positions, normals, total = stratified_surface_points(mesh, count,
                                                          np.random.default_rng(seed))
    order = np.concatenate([group[quadtree_layout(positions[group], level).ravel()]
                            for group in balanced_split(positions, parts)])
    return IlluminationSamples(positions[order], normals[order],
                               total * mm_per_unit**2 / count, parts, 2**level)


# ------------------------------------------------------------------- pass 1 kernel


@parallel_njit(cache=True)
def _transfer_rows(vertices, samples, area, table, sqrt_warp, radius_max, local_width, parts,
                   side, selection_weights, local_weights, energy, terms, out_indices,
                   out_values, counts, shared, union_indices, union_values,
                   union_counts):  # pragma: no cover
    """Rows of T_k (Eq. 7) for a block of vertices, Haar-transformed and cut (Eq. 8).

    ``vertices`` (Vb, 3) and ``samples`` (N, 3) in mm; ``table`` (n + 1, K) holds the basis
    at its sample distances with a zero row past the last. Row K is the local kernel:
    Gaussian weights of width ``local_width`` (mm), normalised to sum 1. Coefficients are
    ranked by ``|value| * selection_weights`` (``local_weights`` for the kernel row; see
    :func:`select_largest_weighted`). Writes slots ``(K + 1, Vb, terms)``; with ``shared``
    also the union of the K + 1 kept column sets of each vertex (ascending, slots
    ``(Vb, (K + 1) terms)``) and every row's coefficients at those columns
    (``(K + 1, Vb, (K + 1) terms)``).
    """
    count = samples.shape[0]
    n_radii = table.shape[0] - 1
    basis_terms = table.shape[1]
    pixels = side * side
    for v in numba.prange(vertices.shape[0]):
        rows = np.empty((basis_terms + 1, count), dtype=np.float32)
        scratch = np.empty(pixels, dtype=np.float32)
        weighted = np.empty(count, dtype=np.float32)
        x, y, z = vertices[v, 0], vertices[v, 1], vertices[v, 2]
        kernel_sum = 0.0
        for i in range(count):
            dx = samples[i, 0] - x
            dy = samples[i, 1] - y
            dz = samples[i, 2] - z
            r = math.sqrt(dx * dx + dy * dy + dz * dz)
            kernel = math.exp(-(r / local_width) ** 2)
            rows[basis_terms, i] = kernel
            kernel_sum += kernel
            if r > radius_max:
                for k in range(basis_terms):
                    rows[k, i] = 0.0
                continue
            if sqrt_warp:
                coordinate = n_radii * math.sqrt(r / radius_max) - 0.5
            else:
                coordinate = r * (n_radii - 1) / radius_max
            coordinate = min(max(coordinate, 0.0), n_radii - 1.0)
            index = int(coordinate)
            fraction = coordinate - index
            for k in range(basis_terms):
                value = table[index, k] * (1.0 - fraction) + table[index + 1, k] * fraction
                rows[k, i] = value * area
        if kernel_sum > 0:
            for i in range(count):
                rows[basis_terms, i] /= kernel_sum
        for k in range(basis_terms + 1):
            for p in range(parts):
                image = rows[k, p * pixels:(p + 1) * pixels].reshape((side, side))
                haar2d_inplace(image, scratch)
            ranking = local_weights if k == basis_terms else selection_weights
            counts[k, v] = select_largest_weighted(rows[k], ranking, energy, terms,
                                                   out_indices[k, v], out_values[k, v],
                                                   weighted)
        if shared:
            marked = np.zeros(count, dtype=np.uint8)
            for k in range(basis_terms + 1):
                for j in range(counts[k, v]):
                    marked[out_indices[k, v, j]] = 1
            found = 0
            for i in range(count):
                if marked[i]:
                    union_indices[v, found] = i
                    for k in range(basis_terms + 1):
                        union_values[k, v, found] = rows[k, i]
                    found += 1
            union_counts[v] = found


@contextlib.contextmanager
def _threads(workers: int):
    previous = numba.get_num_threads()
    numba.set_num_threads(max(1, min(workers, numba.config.NUMBA_NUM_THREADS)))
    try:
        yield
    finally:
        numba.set_num_threads(previous)


def _progress(total: int, description: str, unit: str = "vertex"):
    from ...progress import progress_bar

    return progress_bar(total=total, description=description, unit=unit)


def _first_pass(vertices_mm, samples: IlluminationSamples, samples_mm, basis: DipolePCABasis,
                energy: float, terms: int, selection: str, workers: int, label: str,
                shared: bool = False):
    """Per basis function k (and the local kernel last), Haar-compressed rows for every vertex.

    Returns a list of K + 1 :class:`SparseRows` (one per block), or with ``shared`` one
    :class:`SharedColumnBlocks`: every row of a vertex keeps the union of the columns the
    K + 1 selections kept (a superset of each), so that a product gathers each column once.
    """
    table = np.ascontiguousarray(basis.table, dtype=np.float32)
    sqrt_warp = basis.sampling.distance_warp == "sqrt"
    budget = min(terms, len(samples))
    rows_per_vertex = basis.terms + 1
    union_budget = min(rows_per_vertex * budget, len(samples)) if shared else 1
    local_width = LOCAL_KERNEL_WIDTH * math.sqrt(samples.area)
    # the peaked local kernel is ranked by support always: by magnitude it keeps its fine
    # details and drops the coarse terms that meet the bulk of a smooth irradiance (measured:
    # 6 % error of the local vector by magnitude, 0.3 % by support, 256 of 4096 terms)
    local_weights = haar2d_support_weights(samples.parts, samples.side)
    selection_weights = local_weights if selection == "support" \
        else np.ones(len(samples), dtype=np.float32)
    pieces: list[list] = [[] for _ in range(rows_per_vertex)]
    with _threads(workers), _progress(len(vertices_mm), f"prt transfer {label}") as bar:
        for start in range(0, len(vertices_mm), VERTICES_PER_BLOCK):
            block = np.ascontiguousarray(vertices_mm[start:start + VERTICES_PER_BLOCK])
            indices = np.zeros((rows_per_vertex, len(block), budget), dtype=np.int32)
            values = np.zeros((rows_per_vertex, len(block), budget), dtype=np.float32)
            counts = np.zeros((rows_per_vertex, len(block)), dtype=np.int64)
            union_shape = (len(block), union_budget) if shared else (1, 1)
            union_indices = np.zeros(union_shape, dtype=np.int32)
            union_values = np.zeros((rows_per_vertex,) + union_shape, dtype=np.float32)
            union_counts = np.zeros(union_shape[0], dtype=np.int64)
            _transfer_rows(block, samples_mm, np.float32(samples.area), table, sqrt_warp,
                           float(basis.sampling.radius_max), local_width, samples.parts,
                           samples.side, selection_weights, local_weights, energy, budget,
                           indices, values, counts, shared, union_indices, union_values,
                           union_counts)
            if shared:
                pieces[0].append(SharedColumnBlocks.from_slots(union_indices, union_values,
                                                               union_counts, len(samples)))
            else:
                for k in range(rows_per_vertex):
                    pieces[k].append(SparseRows.from_slots(indices[k], values[k], counts[k],
                                                           len(samples)))
            bar.update(len(block))
    if shared:
        return SharedColumnBlocks.concatenate(pieces[0])
    return [SparseRows.concatenate(parts) for parts in pieces]


# ------------------------------------------------------------------- pass 2 (spatial)


@numba.njit(cache=True, nogil=True)
def _dense_columns(indptr, indices, values, start, stop, out):  # pragma: no cover
    """Columns [start, stop) of a CSR matrix into ``out`` (rows, stop - start)."""
    for r in range(len(indptr) - 1):
        lo, hi = indptr[r], indptr[r + 1]
        first = lo + np.searchsorted(indices[lo:hi], start)
        for j in range(first, hi):
            column = indices[j]
            if column >= stop:
                break
            out[r, column - start] = values[j]


def _spatial_pass(matrix: SparseRows, wavelet: SpatialWavelet, energy: float,
                  budget: int, workers: int, bar=None) -> tuple[SparseRows, float]:
    """CDF 9/7 along the vertices of one T_k^w, keeping its largest coefficients (Eq. 9).

    Column blocks are transformed on ``workers`` threads; the selection streams: entries
    below a running threshold (the ``budget``-th largest magnitude seen) are dropped as
    blocks arrive. Returns the matrix (rows = spatial coefficients) and the fraction of
    the coefficients' energy it keeps.
    """
    rows = matrix.rows
    starts = list(range(0, matrix.columns, SPATIAL_COLUMNS_PER_BLOCK))

    def transform(start):
        stop = min(start + SPATIAL_COLUMNS_PER_BLOCK, matrix.columns)
        dense = np.zeros((rows, stop - start), dtype=np.float32)
        _dense_columns(matrix.indptr, matrix.indices, matrix.values, start, stop, dense)
        coefficients = wavelet.forward(dense)
        return start, coefficients

    threshold = 0.0
    total_energy = 0.0
    kept_rows, kept_columns, kept_values = [], [], []
    held = 0
    with concurrent.futures.ThreadPoolExecutor(max_workers=workers) as pool:
        for start, coefficients in pool.map(transform, starts):
            if bar is not None:
                bar.update(1)
            squared = coefficients.astype(np.float64) ** 2
            total_energy += float(squared.sum())
            row, column = np.nonzero(squared > threshold)
            kept_rows.append(row.astype(np.int32))
            kept_columns.append((column + start).astype(np.int32))
            kept_values.append(coefficients[row, column])
            held += len(row)
            if held > 2 * budget:
                values = np.concatenate(kept_values)
                threshold = float(np.partition(values.astype(np.float64) ** 2,
                                               len(values) - budget)[len(values) - budget])
                keep = values.astype(np.float64) ** 2 >= threshold
                kept_rows = [np.concatenate(kept_rows)[keep]]
                kept_columns = [np.concatenate(kept_columns)[keep]]
                kept_values = [values[keep]]
                held = int(keep.sum())
    row = np.concatenate(kept_rows)
    column = np.concatenate(kept_columns)
    values = np.concatenate(kept_values)
    squared = values.astype(np.float64) ** 2
    order = np.argsort(-squared, kind="stable")
    cumulative = np.cumsum(squared[order])
    count = min(budget, int(np.searchsorted(cumulative, energy * total_energy) + 1),
                len(order))
    chosen = order[:count]
    kept_fraction = float(cumulative[count - 1] / total_energy) if total_energy > 0 else 1.0
    chosen = chosen[np.lexsort((column[chosen], row[chosen]))]
    indptr = np.zeros(rows + 1, dtype=np.int64)
    np.add.at(indptr, row[chosen] + 1, 1)
    return SparseRows(np.cumsum(indptr), column[chosen], values[chosen],
                      matrix.columns), kept_fraction


# -------------------------------------------------------------------- precompute


@dataclass(frozen=True, eq=False)
class ObjectTransfer:
    """The precomputed transfer of one translucent object.

    Attributes
    ----------
    name : str
        The object's name in the scene.
    samples : IlluminationSamples
    transfer : SharedColumnBlocks or QuantisedRows
        All K matrices and the local kernel stacked: row ``k * R + r`` is row ``r`` of
        :math:`{}^wT_k^w` (R = vertices, or spatial coefficients when ``spatial_shape`` is
        set), block K the local kernel; columns are the Haar coefficients of the samples.
    spatial_shape : (int, int) or None
        Geometry-image shape when the second pass was applied.
    statistics : dict
        Sizes, timings and kept energies, for the report.
    """

    name: str
    samples: IlluminationSamples
    transfer: SharedColumnBlocks | QuantisedRows
    spatial_shape: tuple[int, int] | None
    statistics: dict

    @property
    def basis_terms(self) -> int:
        """K (the matrix holds K + 1 blocks: the basis functions, then the local kernel)."""
        return self.transfer.rows // self.row_count - 1

    @property
    def row_count(self) -> int:
        """R: rows per basis function."""
        return int(self.statistics["vertices"])


def spatial_decision(scene_object, knobs: dict, log: StageLog) -> bool:
    """Whether the object gets the spatial pass; the reason goes into ``log`` either way."""
    spatial, sentence = _spatial_reason(scene_object.mesh, knobs)
    log.notes.setdefault("spatial", {})[scene_object.name] = sentence
    if not spatial:
        log.skip(f"object '{scene_object.name}': {sentence}")
    return spatial


def _spatial_reason(mesh, knobs: dict) -> tuple[bool, str]:
    if knobs["spatial"] == "off":
        return False, "spatial compression off (knob spatial = 'off')"
    if mesh.grid_shape is None:
        return False, ("no spatial compression: the mesh has no square parameterisation "
                       "(not a geometry image)")
    if knobs["spatial"] == "auto" and len(mesh.vertices) <= knobs["spatial_min_vertices"]:
        return False, (f"no spatial compression: {len(mesh.vertices)} vertices <= "
                       f"{knobs['spatial_min_vertices']} (small meshes relight fast without "
                       f"it, Sect. 3.2)")
    return True, (f"spatial compression: CDF 9/7 over the {mesh.grid_shape[0]} x "
                  f"{mesh.grid_shape[1]} geometry image")


def check_transfer_memory(scene_object, samples: int, rows_per_vertex: int, terms: int,
                          shared: bool) -> int:
    """Refuse, before the first pass, a transfer whose coefficients the machine cannot hold.

    The bound: every vertex keeps at most ``terms`` coefficients per row (with ``shared``,
    the union of its rows' columns, at most ``rows_per_vertex * terms``), never more than
    the samples, each an int32 column and a float32 value before quantisation. Returns the
    bytes.
    """
    from ...resources import check_memory

    columns = min(terms * (rows_per_vertex if shared else 1), samples)
    estimate = len(scene_object.mesh.vertices) * rows_per_vertex * columns * 8
    check_memory(estimate, what=f"the PRT transfer of {scene_object.name!r} "
                                f"({len(scene_object.mesh.vertices)} vertices x "
                                f"{rows_per_vertex} rows x {columns} coefficients at most)",
                 field="terms", value=terms)
    return estimate


def transfer_key(scene_object, mm_per_unit: float, knobs: dict) -> str:
    """Return the cache key of an object's transfer: its geometry, scale and keyed knobs."""
    from ...cache import content_hash

    computed = {k: v for k, v in knobs.items() if k not in UNKEYED_KNOBS}
    return content_hash("prt-transfer", PRT_VERSION, scene_object.mesh.cache_key(),
                        mm_per_unit, computed)


def precompute_object(scene_object, mm_per_unit: float, knobs: dict,
                      log: StageLog) -> ObjectTransfer:
    """Return one object's compressed transfer: samples and both passes (cached on disk)."""
    mesh = scene_object.mesh
    basis = pca_basis_for(knobs)
    spatial = spatial_decision(scene_object, knobs, log)
    start = time.perf_counter()
    samples = illumination_samples(mesh, knobs["samples"], knobs["parts"],
                                   mm_per_unit=mm_per_unit, seed=knobs["seed"])
    samples_mm = np.ascontiguousarray(samples.positions * mm_per_unit)
    vertices_mm = np.ascontiguousarray(mesh.vertices * mm_per_unit)
    first_terms = knobs["spatial_first_terms"] if spatial else knobs["terms"]
    # the spatial pass transforms each T_k along the vertices on its own, so its rows cannot
    # share columns: the shared layout is for the first pass alone
    shared = knobs["layout"] == "shared" and not spatial
    check_transfer_memory(scene_object, len(samples), basis.terms + 1, first_terms, shared)
    if knobs["layout"] == "shared" and spatial:
        log.notes.setdefault("layout", {})[scene_object.name] = (
            "rows layout: the spatial pass keeps each T_k's own coefficients")
    matrices = _first_pass(vertices_mm, samples, samples_mm, basis, knobs["energy"],
                           first_terms, knobs["selection"], knobs["workers"],
                           scene_object.name, shared=shared)
    first_seconds = time.perf_counter() - start
    statistics = {"vertices": len(mesh.vertices), "samples": len(samples),
                  "basis_terms": basis.terms, "pass1_seconds": first_seconds,
                  "pass1_nnz": matrices.nnz if shared else int(sum(m.nnz for m in matrices)),
                  "dense_entries": len(mesh.vertices) * len(samples) * basis.terms,
                  "layout": "shared" if shared else "rows"}
    spatial_shape = None
    if spatial:
        start = time.perf_counter()
        wavelet = SpatialWavelet(mesh.grid_shape)
        budget = knobs["spatial_terms"] * len(mesh.vertices)
        compressed, kept = [], []
        blocks = sum(-(-matrix.columns // SPATIAL_COLUMNS_PER_BLOCK) for matrix in matrices)
        with _progress(blocks, f"prt spatial pass {scene_object.name}", unit="block") as bar:
            for matrix in matrices:
                result, fraction = _spatial_pass(matrix, wavelet, knobs["spatial_energy"],
                                                 budget, knobs["workers"], bar)
                compressed.append(result)
                kept.append(fraction)
        matrices = compressed
        spatial_shape = tuple(mesh.grid_shape)
        statistics.update(pass2_seconds=time.perf_counter() - start,
                          pass2_nnz=int(sum(m.nnz for m in matrices)),
                          pass2_energy_kept=[float(k) for k in kept])
    if shared:
        transfer = matrices
        statistics.update(nnz=transfer.nnz, megabytes=transfer.nbytes / 2**20,
                          index_bits=8 * transfer.indices.itemsize,
                          shared_columns=len(transfer.indices))
    else:
        transfer = SparseRows.concatenate(matrices).quantised()
        statistics.update(nnz=transfer.nnz, megabytes=transfer.nbytes / 2**20,
                          index_bits=transfer.index_bits)
    return ObjectTransfer(scene_object.name, samples, transfer, spatial_shape, statistics)
