r"""PRT editing and relighting of homogeneous translucent materials (Wang et al. 2008).

The diffuse BSSRDF (Eq. 2) with the dipole profile expanded in a PCA basis,
:math:`R_d(r, \sigma) \approx \sum_k b_k(r) s_k(\sigma)` (Eq. 4,
:mod:`translucent.materials.dipole_pca`), turns Eq. 1 into K precomputed transfers
(Eq. 5-7):

.. math::
    B(x, \omega_o) = \frac{F_t(\eta, \omega_o)}{\pi} \sum_k s_k(\sigma)\,
    \sum_i T_k(x, x_i)\,E(x_i), \qquad T_k(x, x_i) = b_k(\lVert x - x_i\rVert)\,A_i

from uniform illumination samples :math:`x_i` (area :math:`A_i`) on the object to every
vertex :math:`x`, with :math:`E` the irradiance of Eq. 6 (Fresnel-weighted, shadowed).

Precomputation (:func:`precompute`), per translucent object:

1. ``samples = m x 4^n`` uniform surface samples, split into ``m`` parts by median cuts,
   each laid out on a ``2^n x 2^n`` square by a balanced quadtree (Hašan et al. 2006);
2. every row of every :math:`T_k` is transformed by the 2D Haar wavelet over those squares
   and cut to its largest coefficients (energy threshold and term budget: Eq. 8), then
   quantised to 16-bit values with 16-bit indices (14/18 bits beyond 2^16 samples);
3. on meshes that are geometry images (``Mesh.grid_shape``) with more than
   ``spatial_min_vertices`` vertices, a second pass transforms each :math:`T_k` along the
   vertices with the CDF 9/7 wavelet and keeps its largest coefficients (Eq. 9-10); smaller
   meshes and unparameterised ones skip it, as in the paper.

The first pass runs on compiled kernels over all cores (``workers``) with a progress bar;
the result is cached on disk keyed by the object's geometry and the knobs (never by lights
or material).

Interactive path (``state.render(lights=None, material=None)``):

* relighting: irradiance :math:`E` at the samples from point, spot, directional, area
  (rectangle, sphere) and environment lights, with shadows from ``scenes`` ray queries
  (environment: precomputed wavelet-compressed visibility per sample, built only when the
  scene has an environment light); Haar transform of :math:`E`; one sparse product of the
  quantised matrix with :math:`E^w` gives all :math:`v_k = T_k^w E^w` (Eq. 8);
* editing: :math:`s_k(\sigma)` per RGB channel re-weights the cached :math:`v_k`
  (Eq. 7/10; no transfer product is redone), inverse CDF 9/7 where spatially compressed,
  then :math:`F_t(\eta, \omega_o)/\pi` per pixel through the camera G-buffer. Changing
  :math:`\eta` changes :math:`F_t(\eta, \omega_i)` inside :math:`E`, so it relights.

References
----------
Wang, Cheslack-Postava, Wang, Luebke, Chen, Hua, Peng, Bao: Real-time editing and
relighting of homogeneous translucent materials. The Visual Computer 24 (2008).
Hašan, Pellacini, Bala: Direct-to-indirect transfer for cinematic relighting. ACM TOG 25(3)
(2006).
"""

from __future__ import annotations

import concurrent.futures
import contextlib
import functools
import math
import threading
import time
from dataclasses import dataclass, field

import numba
import numpy as np

from ..errors import InputError
from ..image import Image
from ..materials import Dipole, measured_medium
from ..materials.dipole import dipole_reflectance_profile, total_diffuse_reflectance
from ..materials.dipole_pca import (
    PARAMETERISATIONS,
    DipolePCABasis,
    dipole_pca_basis,
    truncated_diffuse_reflectance,
)
from ..materials.fresnel import fresnel_transmittance
from ..scenes.scene import (
    ConstantEnvironment,
    DirectionalLight,
    ImageEnvironment,
    PointLight,
    RectangularAreaLight,
    SphereAreaLight,
    SpotLight,
)
from .base import StageLog, refuse_inapplicable, with_defaults
from .sparse_transport import (
    QuantisedRows,
    SharedColumnBlocks,
    SparseRows,
    check_approximation,
    nonlinear_approximation,
    select_largest_weighted,
)
from .wavelets import (
    SpatialWavelet,
    balanced_split,
    haar2d_forward,
    haar2d_inplace,
    haar2d_support_weights,
    quadtree_layout,
)

__all__ = [
    "DEFAULT_KNOBS",
    "applies_to",
    "precompute",
    "PRTState",
    "ObjectTransfer",
    "IlluminationSamples",
    "illumination_samples",
    "sample_irradiance",
    "brute_force_radiance",
    "projection_blend",
    "add_approx_arguments",
    "approx",
]

#: Knobs of :func:`precompute` and their defaults.
DEFAULT_KNOBS: dict = {
    # illumination samples per translucent object: parts x 4^n
    "samples": 16384,
    "parts": 4,
    # the R_d basis (materials.dipole_pca): parameterisation, K, and the eta it samples
    "basis": "area_normalised",
    "basis_terms": 12,
    "basis_eta": 1.3,
    # pass 1: Haar coefficients kept per transfer row (energy fraction, term budget)
    "energy": 0.9999,
    "terms": 256,
    # rank the coefficients of the basis rows by magnitude (the paper) or by magnitude x
    # sqrt(support) (the local kernel row is always ranked by support)
    "selection": "magnitude",
    # storage of the first pass: "shared" (the K + 1 rows of a vertex keep the union of
    # their kept columns, so a relighting product gathers each column once) or "rows" (each
    # row its own columns, the paper's layout; always so after the spatial pass)
    "layout": "shared",
    # pass 2: CDF 9/7 spatial compression: "auto" (geometry images above
    # spatial_min_vertices), "on" (any geometry image) or "off"
    "spatial": "auto",
    "spatial_min_vertices": 20000,
    "spatial_first_terms": 1024,
    "spatial_energy": 0.999,
    "spatial_terms": 256,
    # environment lighting: visibility directions (res x 2 res) and terms kept per sample
    "environment_resolution": 16,
    "environment_terms": 64,
    # shadow rays per area light and sample
    "area_light_samples": 16,
    "seed": 0,
    # blend profiles the illumination samples cannot resolve into the local vector
    # (SAMPLING_BLEND_START; rendering only, not part of the cache key); False: Eq. 5-7 as
    # the paper sums them, whatever the sample spacing
    "sampling_blend": True,
    # execution only (not part of the cache key)
    "workers": 2,
    "progress": True,
}

#: Knobs that change how, not what, is computed: left out of the cache key.
EXECUTION_KNOBS = ("workers", "progress")

#: Knobs read when rendering, not when precomputing: left out of the cache key too.
RENDER_KNOBS = ("sampling_blend",)
_UNKEYED_KNOBS = EXECUTION_KNOBS + RENDER_KNOBS

#: Bump when the precomputed data change meaning, so that old cache entries miss.
PRT_VERSION = 7

#: Vertices per block of the first pass (one progress-bar step; memory ~ K x block x terms).
VERTICES_PER_BLOCK = 256

#: Width of the local kernel (a Gaussian over the samples around each vertex, normalised to
#: sum 1) in units of the sample spacing sqrt(area per sample): wide enough to average a few
#: samples, narrow enough to follow shadow edges.
LOCAL_KERNEL_WIDTH = 1.0

#: Blend towards the local (opaque-limit) model when the basis misses more than
#: LOCAL_BLEND_START of a profile (relative L2 in the sampling's norm: the measured media
#: miss at most 0.0065 with the default 12 terms, so they are never blended), fully local
#: when it misses LOCAL_BLEND_END (the projection then oscillates with negative lobes of
#: several per cent of the peak).
LOCAL_BLEND_START = 0.02
LOCAL_BLEND_END = 0.2

#: A small residual is not enough: a profile narrower than the basis's sample spacing is
#: seen by a handful of samples, and its K-term reconstruction can hold any energy between
#: them (paper basis, sigma' = 1e3 mm^-1: residual 7.5e-5, energy -204 against 0.073).
#: The projection's energy 2 pi int R r dr over [0, 65] mm must also agree with the exact
#: profile's: blending starts at a relative error of ENERGY_BLEND_START, above the worst of
#: the 36 measured profiles on either preset basis (0.067 paper, 0.057 area_normalised, both
#: Spectralon green), and is complete at ENERGY_BLEND_END.
ENERGY_BLEND_START = 0.1
ENERGY_BLEND_END = 0.5

#: A profile whose reduced mean free path (the depth z_r of its real source, the distance
#: over which it falls from its peak) is shorter than the spacing of the basis's first two
#: distances is sampled too coarsely for the residual to mean anything, and multiple
#: scattering there is local (the paper's "more appropriate to handle using the diffuse
#: BRDF model", Sect. 4 of Wang et al. 2008). Blending starts when the mean free path is
#: one spacing and is complete RESOLUTION_BLEND_OCTAVES octaves below (a quarter spacing:
#: the profile then falls to a few per cent of its peak before the second sample). The
#: measured media inside the paper's grid have mean free paths >= 0.19 mm (twice its
#: 0.1 mm spacing); the area-normalised basis's first spacing is 3e-4 mm.
RESOLUTION_BLEND_OCTAVES = 2.0

#: The transfer sums a profile over the illumination samples (Eq. 5-7 of Wang et al. 2008),
#: a quadrature of spacing h = sqrt(area per sample). The part of the profile's energy
#: within h of a vertex falls on a handful of samples, whose positions then decide the
#: result: a blotchy surface (Spectralon on the 10 mm sphere at 16384 samples, h = 0.28 mm,
#: 56-72 % of its energy within h at eta = 1: relMSE 0.125 against the path-traced
#: reference, 0.005 when rendered fully local). Blending by that fraction starts at
#: SAMPLING_BLEND_START, above the in-grid measured media there (at most 0.41, Cream at
#: eta = 1), and is complete at SAMPLING_BLEND_END.
SAMPLING_BLEND_START = 0.45
SAMPLING_BLEND_END = 0.65

#: Columns per block of the spatial pass (dense block: vertices x columns x 4 bytes).
SPATIAL_COLUMNS_PER_BLOCK = 256

#: Rank of the separable approximation of F_t(eta, mu) mu used by environment lighting.
#: Measured over eta in [1, 3]: 4 terms reproduce it to 3.4e-3 of its peak pointwise and its
#: cosine-weighted hemispherical integral to 2.1e-4 (3 terms: 1.0e-2 and 1.7e-3).
FRESNEL_RANK = 4


# ------------------------------------------------------------------------ knobs


def _check_knobs(knobs: dict) -> dict:
    merged = with_defaults(knobs, DEFAULT_KNOBS)
    integers = {"samples": (1, 1 << 18), "parts": (1, 4096), "basis_terms": (1, 32),
                "terms": (1, 1 << 18), "spatial_min_vertices": (0, 10**9),
                "spatial_first_terms": (1, 1 << 18), "spatial_terms": (1, 1 << 18),
                "environment_resolution": (2, 256), "environment_terms": (1, 1 << 17),
                "area_light_samples": (1, 4096), "seed": (0, 2**32 - 1), "workers": (1, 256)}
    for name, (low, high) in integers.items():
        value = merged[name]
        if isinstance(value, bool) or not isinstance(value, (int, np.integer)) \
                or not low <= value <= high:
            raise InputError(f"must be an integer in [{low}, {high}]", field=name, value=value)
        merged[name] = int(value)
    _quadtree_level(merged["samples"], merged["parts"])
    resolution = merged["environment_resolution"]
    if resolution & (resolution - 1):
        raise InputError("must be a power of two", field="environment_resolution",
                         value=resolution)
    if merged["basis"] not in PARAMETERISATIONS:
        raise InputError(f"unknown basis; valid: {', '.join(PARAMETERISATIONS)}",
                         field="basis", value=merged["basis"])
    if merged["layout"] not in ("shared", "rows"):
        raise InputError("must be 'shared' or 'rows'", field="layout", value=merged["layout"])
    if merged["selection"] not in ("magnitude", "support"):
        raise InputError("must be 'magnitude' or 'support'", field="selection",
                         value=merged["selection"])
    if merged["spatial"] not in ("auto", "on", "off"):
        raise InputError("must be 'auto', 'on' or 'off'", field="spatial",
                         value=merged["spatial"])
    merged["energy"], _ = check_approximation(merged["energy"], merged["terms"])
    merged["spatial_energy"], _ = check_approximation(merged["spatial_energy"],
                                                      merged["spatial_terms"])
    eta = float(merged["basis_eta"])
    if not 1.0 <= eta <= 3.0:
        raise InputError("must be in [1, 3]", field="basis_eta", value=merged["basis_eta"])
    merged["basis_eta"] = eta
    merged["progress"] = bool(merged["progress"])
    if not isinstance(merged["sampling_blend"], (bool, np.bool_)):
        raise InputError("must be True or False", field="sampling_blend",
                         value=merged["sampling_blend"])
    merged["sampling_blend"] = bool(merged["sampling_blend"])
    return merged


def _quadtree_level(count: int, parts: int) -> int:
    """Return n with ``count = parts x 4^n`` (the quadtree layout of every part), else raise."""
    per_part = count // parts
    level = round(math.log(max(per_part, 1), 4))
    if count % parts or 4 ** level != per_part:
        valid = ", ".join(str(parts * 4 ** n) for n in range(2, 9))
        raise InputError(f"must be parts x 4^n (with parts = {parts}: {valid}, ...)",
                         field="samples", value=count)
    return level


def _basis(knobs: dict) -> DipolePCABasis:
    return dipole_pca_basis(knobs["basis"], eta=knobs["basis_eta"], terms=knobs["basis_terms"])


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
    level = _quadtree_level(count, parts)
    rng = np.random.default_rng(seed)
    areas = mesh.face_areas
    cumulative = np.cumsum(areas)
    total = float(cumulative[-1])
    strata = (np.arange(count) + rng.random(count)) * (total / count)
    face = np.minimum(np.searchsorted(cumulative, strata, side="right"), len(areas) - 1)
    root = np.sqrt(rng.random(count))
    second = rng.random(count)
    weights = np.stack([1.0 - root, root * (1.0 - second), root * second], axis=1)
    corners = mesh.faces[face]
    positions = np.einsum("nk,nkd->nd", weights, mesh.vertices[corners])
    normals = np.einsum("nk,nkd->nd", weights, mesh.normals[corners])
    length = np.linalg.norm(normals, axis=1, keepdims=True)
    normals = np.where(length > 1e-12, normals / np.maximum(length, 1e-300),
                       mesh.face_normals[face])
    order = np.concatenate([group[quadtree_layout(positions[group], level).ravel()]
                            for group in balanced_split(positions, parts)])
    return IlluminationSamples(positions[order], normals[order],
                               total * mm_per_unit**2 / count, parts, 2**level)


# ------------------------------------------------------------------- pass 1 kernel


@numba.njit(cache=True, parallel=True)
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


def _progress(total: int, description: str, enabled: bool):
    from tqdm import tqdm

    return tqdm(total=total, desc=description, unit="vertex", disable=not enabled or None,
                leave=False)


def _first_pass(vertices_mm, samples: IlluminationSamples, samples_mm, basis: DipolePCABasis,
                energy: float, terms: int, selection: str, workers: int, progress: bool,
                label: str, shared: bool = False):
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
    with _threads(workers), _progress(len(vertices_mm), f"prt transfer {label}",
                                      progress) as bar:
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
                  budget: int, workers: int) -> tuple[SparseRows, float]:
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


def _spatial_decision(scene_object, knobs: dict, log: StageLog) -> bool:
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


def _transfer_key(scene_object, mm_per_unit: float, knobs: dict) -> str:
    from ..cache import content_hash

    computed = {k: v for k, v in knobs.items() if k not in _UNKEYED_KNOBS}
    return content_hash("prt-transfer", PRT_VERSION, scene_object.mesh.cache_key(),
                        mm_per_unit, computed)


def _precompute_object(scene_object, mm_per_unit: float, knobs: dict,
                       log: StageLog) -> ObjectTransfer:
    mesh = scene_object.mesh
    basis = _basis(knobs)
    spatial = _spatial_decision(scene_object, knobs, log)
    start = time.perf_counter()
    samples = illumination_samples(mesh, knobs["samples"], knobs["parts"],
                                   mm_per_unit=mm_per_unit, seed=knobs["seed"])
    samples_mm = np.ascontiguousarray(samples.positions * mm_per_unit)
    vertices_mm = np.ascontiguousarray(mesh.vertices * mm_per_unit)
    first_terms = knobs["spatial_first_terms"] if spatial else knobs["terms"]
    # the spatial pass transforms each T_k along the vertices on its own, so its rows cannot
    # share columns: the shared layout is for the first pass alone
    shared = knobs["layout"] == "shared" and not spatial
    if knobs["layout"] == "shared" and spatial:
        log.notes.setdefault("layout", {})[scene_object.name] = (
            "rows layout: the spatial pass keeps each T_k's own coefficients")
    matrices = _first_pass(vertices_mm, samples, samples_mm, basis, knobs["energy"],
                           first_terms, knobs["selection"], knobs["workers"],
                           knobs["progress"], scene_object.name, shared=shared)
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
        for matrix in matrices:
            result, fraction = _spatial_pass(matrix, wavelet, knobs["spatial_energy"], budget,
                                             knobs["workers"])
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


def _translucent_objects(scene) -> list[int]:
    return [i for i, item in enumerate(scene.objects) if isinstance(item.material, Dipole)]


def _other_objects_in_view(scene) -> list[str]:
    """Names of the objects that are not homogeneous translucent and that the camera sees."""
    translucent = set(_translucent_objects(scene))
    if len(translucent) == len(scene.objects):
        return []
    from ..scenes.raycast import gbuffer

    seen = set(np.unique(gbuffer(scene).object_id).tolist()) - {-1}
    return [scene.objects[i].name for i in sorted(seen - translucent)]


def applies_to(scene) -> str | None:
    """None when the method renders ``scene``; otherwise why not.

    It needs a homogeneous translucent object (a :class:`~translucent.materials.Dipole`
    material), at least one light, and no other object in the camera's view: the method
    (Wang et al. 2008) computes the multiple scattering of homogeneous translucent objects
    only, so any other surface the camera sees would be black (its direct light alone would
    still miss the light it receives from the other objects). Other objects outside the
    view are fine: they cast shadows through the ray queries.
    """
    if not _translucent_objects(scene):
        return "no homogeneous translucent object (Dipole material) in the scene"
    if not scene.lights:
        return "the scene has no light"
    others = _other_objects_in_view(scene)
    if others:
        kinds = ", ".join(f"'{name}' ({type(scene.object(name).material).__name__})"
                          for name in others)
        return (f"objects that are not homogeneous translucent are visible in the camera: "
                f"{kinds}; the method renders only homogeneous translucent objects and would "
                f"leave them black")
    return None


def precompute(scene, **knobs) -> PRTState:
    """Precompute the transfer of every homogeneous translucent object (Sect. 3.2).

    Cached on disk (namespace ``prt``) by the object's geometry, ``mm_per_unit`` and the
    knobs (not the lights, not the material): a second call with the same inputs loads it.

    Parameters
    ----------
    scene : Scene
    **knobs
        See :data:`DEFAULT_KNOBS`.

    Returns
    -------
    PRTState

    Raises
    ------
    InputError
        The method does not apply (see :func:`applies_to`) or a knob is invalid.
    """
    from ..cache import Cache

    refuse_inapplicable(scene, applies_to(scene), "the prt method cannot render this scene")
    knobs = _check_knobs(knobs)
    log = StageLog()
    cache = Cache("prt")
    transfers = []
    start = time.perf_counter()
    for index in _translucent_objects(scene):
        item = scene.objects[index]
        key = _transfer_key(item, scene.mm_per_unit, knobs)
        transfer = cache.load_pickle(key)
        if isinstance(transfer, ObjectTransfer):
            log.notes.setdefault("cache", {})[item.name] = "loaded from the cache"
            _spatial_decision(item, knobs, log)
        else:
            transfer = _precompute_object(item, scene.mm_per_unit, knobs, log)
            cache.store_pickle(key, transfer)
            log.notes.setdefault("cache", {})[item.name] = "computed and stored"
        transfers.append(transfer)
    others = [o.name for o in scene.objects if not isinstance(o.material, Dipole)]
    if others:
        log.skip(f"objects {', '.join(others)} are not homogeneous translucent and outside "
                 f"the camera's view: they only cast shadows")
    log.seconds["precompute"] = time.perf_counter() - start
    return PRTState(scene, knobs, transfers, log)


# ------------------------------------------------------------------- lighting


def _transmitted_cosine(eta, cosine):
    r""":math:`F_t(\eta, n \cdot \omega_i)\,(n \cdot \omega_i)` of Eq. 6, 0 from below."""
    return np.where(cosine > 0, fresnel_transmittance(eta, np.clip(cosine, 0, 1)) * cosine, 0.0)


def _far_distance(samples: IlluminationSamples) -> float:
    """Return a distance past the samples' extent (scene units), for rays to infinity."""
    return 10.0 * max(1.0, float(np.ptp(samples.positions, axis=0).max()))


def _point_irradiance(samples, position, eta, falloff=None):
    offset = position - samples.positions
    squared = np.maximum(np.einsum("nd,nd->n", offset, offset), 1e-300)
    direction = offset / np.sqrt(squared)[:, None]
    cosine = np.einsum("nd,nd->n", samples.normals, direction)
    weight = _transmitted_cosine(eta, cosine) / squared
    if falloff is not None:
        weight = weight * falloff(-direction)
    return weight, direction


def _stratified_unit_square(count: int, seed: int) -> np.ndarray:
    side = int(math.ceil(math.sqrt(count)))
    rng = np.random.default_rng(seed)
    cells = np.stack(np.meshgrid(np.arange(side), np.arange(side), indexing="ij"), -1)
    cells = cells.reshape(-1, 2)[:count]
    return (cells + rng.random(cells.shape)) / side


def _rectangle_points(light: RectangularAreaLight, count: int, seed: int):
    """Stratified points on a rectangle emitter, its normal, and the area each stands for."""
    uv = _stratified_unit_square(count, seed)
    points = light.center + (2 * uv[:, :1] - 1) * light.u_axis + \
        (2 * uv[:, 1:] - 1) * light.v_axis
    return points, light.normal, light.area / len(points)


def _sphere_light_directions(light: SphereAreaLight, samples: IlluminationSamples,
                             count: int, seed: int):
    r"""Stratified directions in the cone each sample sees the sphere in, and their hit points.

    Solid-angle sampling of a sphere emitter: every direction stands for
    :math:`2\pi(1 - \cos\alpha)/n` sr, where :math:`\sin\alpha = \rho / d`.
    Yields ``(directions (N, 3), points (N, 3), solid angle (N,))`` per stratum; samples
    inside the sphere get a zero solid angle.
    """
    uv = _stratified_unit_square(count, seed)
    offset = light.center - samples.positions
    distance = np.linalg.norm(offset, axis=1)
    axis = offset / np.maximum(distance, 1e-300)[:, None]
    outside = distance > light.radius
    sin_alpha = np.where(outside, light.radius / np.maximum(distance, 1e-300), 1.0)
    cos_alpha = np.sqrt(np.clip(1.0 - sin_alpha**2, 0.0, 1.0))
    helper = np.where(np.abs(axis[:, :1]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])
    tangent = np.cross(axis, helper)
    tangent /= np.linalg.norm(tangent, axis=1, keepdims=True)
    bitangent = np.cross(axis, tangent)
    solid_angle = np.where(outside, 2.0 * np.pi * (1.0 - cos_alpha) / len(uv), 0.0)
    for u, v in uv:
        cos_theta = 1.0 - u * (1.0 - cos_alpha)
        sin_theta = np.sqrt(np.clip(1.0 - cos_theta**2, 0.0, 1.0))
        phi = 2.0 * np.pi * v
        direction = (cos_theta[:, None] * axis + (sin_theta * np.cos(phi))[:, None] * tangent
                     + (sin_theta * np.sin(phi))[:, None] * bitangent)
        along = distance * cos_theta
        reach = along - np.sqrt(np.clip(light.radius**2 - (distance * sin_theta) ** 2, 0.0,
                                        None))
        yield direction, samples.positions + reach[:, None] * direction, solid_angle


def _shadow(scene, samples: IlluminationSamples, weight, targets, target_normal) -> None:
    """Zero ``weight`` where a sample with ``weight > 0`` does not see its target point."""
    from ..scenes.raycast import visible

    lit = np.flatnonzero(weight > 0)
    if not len(lit):
        return
    targets = np.asarray(targets, dtype=np.float64)
    ends = targets[lit] if targets.ndim == 2 else targets
    seen = visible(scene, samples.positions[lit], ends, normals_a=samples.normals[lit],
                   normals_b=target_normal)
    weight[lit[~seen]] = 0.0


def sample_irradiance(scene, samples: IlluminationSamples, lights, eta: float, *,
                      area_light_samples: int = 16, environment=None,
                      seed: int = 0) -> np.ndarray:
    r"""Irradiance :math:`E(x_i)` at the illumination samples (Eq. 6 of Wang et al. 2008).

    :math:`E = \int L\,F_t(\eta, \omega_i)\,(n \cdot \omega_i)\,d\omega_i` with shadows from
    ``scenes`` ray queries: point and spot lights (Mitsuba's linear-in-angle spot profile),
    directional lights, rectangle emitters (``area_light_samples`` stratified points on the
    rectangle) and sphere emitters (as many stratified directions in the cone each sample
    sees the sphere in), and environment lights through ``environment`` (an
    :class:`EnvironmentTransfer`).

    Parameters
    ----------
    scene : Scene
        For the ray queries (every object occludes).
    samples : IlluminationSamples
    lights : sequence of lights
    eta : float
        Index of refraction in :math:`F_t`.

    Returns
    -------
    ndarray, (N, 3), float64
        W per scene unit squared (the lights' units).
    """
    irradiance = np.zeros((len(samples), 3))
    for light_index, light in enumerate(lights):
        if isinstance(light, (PointLight, SpotLight)):
            falloff = light.falloff if isinstance(light, SpotLight) else None
            weight, _ = _point_irradiance(samples, light.position, eta, falloff)
            _shadow(scene, samples, weight, light.position, None)
            irradiance += weight[:, None] * light.intensity
        elif isinstance(light, DirectionalLight):
            cosine = samples.normals @ -light.direction
            weight = _transmitted_cosine(eta, cosine)
            far = _far_distance(samples)
            _shadow(scene, samples, weight, samples.positions - far * light.direction, None)
            irradiance += weight[:, None] * light.irradiance
        elif isinstance(light, RectangularAreaLight):
            points, normal, patch = _rectangle_points(light, area_light_samples,
                                                      seed + light_index)
            for point in points:
                weight, direction = _point_irradiance(samples, point, eta)
                weight *= np.clip(-(direction @ normal), 0.0, None) * patch
                _shadow(scene, samples, weight, point, normal)
                irradiance += weight[:, None] * light.radiance
        elif isinstance(light, SphereAreaLight):
            for direction, points, solid_angle in _sphere_light_directions(
                    light, samples, area_light_samples, seed + light_index):
                cosine = np.einsum("nd,nd->n", samples.normals, direction)
                weight = _transmitted_cosine(eta, cosine) * solid_angle
                _shadow(scene, samples, weight, points, None)
                irradiance += weight[:, None] * light.radiance
        elif isinstance(light, (ConstantEnvironment, ImageEnvironment)):
            if environment is None:
                raise InputError("environment lighting needs the precomputed visibility",
                                 field="environment", value=None)
            irradiance += environment.irradiance(light, eta)
        else:
            raise InputError(f"unknown light type {type(light).__name__}",
                             field=f"lights[{light_index}]", value=type(light).__name__)
    return irradiance


@functools.lru_cache(maxsize=4)
def fresnel_cosine_factors(rank: int = FRESNEL_RANK, *, resolution: int = 256):
    r"""Return a separable form :math:`F_t(\eta, \mu)\,\mu \approx \sum_j a_j(\eta)\,c_j(\mu)`.

    By SVD over :math:`\eta \in [1, 3]` and :math:`\mu \in [0, 1]`: environment visibility
    (which must not depend on the material) is precomputed with each :math:`c_j`, and the
    :math:`a_j(\eta)` of the current material combine them at run time.

    Returns
    -------
    mu : ndarray, (resolution,)
    factors : ndarray, (rank, resolution)
        :math:`c_j` on ``mu``.
    weights : callable
        ``weights(eta) -> (rank,)``: the :math:`a_j`.
    error : float
        Largest absolute error of the approximation on the grid (the function peaks at ~1).
    """
    mu = np.linspace(0.0, 1.0, resolution)
    etas = np.linspace(1.0, 3.0, resolution)
    values = fresnel_transmittance(etas[:, None], mu[None, :]) * mu[None, :]
    _, _, right = np.linalg.svd(values, full_matrices=False)
    factors = right[:rank]

    def weights(eta):
        row = fresnel_transmittance(float(eta), mu) * mu
        return factors @ row

    error = float(np.abs(values - (values @ factors.T) @ factors).max())
    return mu, factors, weights, error


def _environment_directions(resolution: int):
    """Cell-centre directions (Mitsuba's lat-long convention) of a res x 2 res grid, two squares."""
    theta = math.pi * (np.arange(resolution) + 0.5) / resolution
    phi = 2.0 * math.pi * (np.arange(2 * resolution) + 0.5) / (2 * resolution)
    theta, phi = np.meshgrid(theta, phi, indexing="ij")
    directions = np.stack([np.sin(phi) * np.sin(theta), np.cos(theta),
                           -np.cos(phi) * np.sin(theta)], axis=-1)
    solid_angle = (math.pi / resolution) ** 2 * np.sin(theta)
    # two squares: phi in [0, pi) then [pi, 2 pi); each row-major
    squares = np.concatenate([directions[:, :resolution], directions[:, resolution:]], axis=0)
    angles = np.concatenate([solid_angle[:, :resolution], solid_angle[:, resolution:]], axis=0)
    return squares.reshape(-1, 3), angles.reshape(-1)


def _environment_radiance(light, directions) -> np.ndarray:
    """Radiance of an environment light towards each direction cell's centre, (D, 3)."""
    if isinstance(light, ConstantEnvironment):
        return np.broadcast_to(light.radiance, directions.shape).astype(np.float64)
    image = light.radiance.astype(np.float64) * light.scale
    height, width = image.shape[:2]
    u = (np.arctan2(directions[:, 0], -directions[:, 2]) / (2 * np.pi)) % 1.0
    v = np.arccos(np.clip(directions[:, 1], -1.0, 1.0)) / np.pi
    # Mitsuba interpolates bilinearly between texel centres u = (j + 1/2)/W, v = i/(H - 1)
    x = u * width - 0.5
    y = v * (height - 1)
    x0 = np.floor(x).astype(int)
    y0 = np.clip(np.floor(y).astype(int), 0, height - 1)
    fx, fy = (x - x0)[:, None], (y - y0)[:, None]
    y1 = np.clip(y0 + 1, 0, height - 1)
    x0w, x1w = x0 % width, (x0 + 1) % width
    return ((1 - fy) * ((1 - fx) * image[y0, x0w] + fx * image[y0, x1w])
            + fy * ((1 - fx) * image[y1, x0w] + fx * image[y1, x1w]))


@dataclass(frozen=True, eq=False)
class EnvironmentTransfer:
    r"""Precomputed wavelet-compressed visibility of the environment at every sample.

    Rows ``j * N + i``: Haar coefficients (over the two squares of the direction grid) of
    :math:`V_i(\omega)\,c_j(n_i \cdot \omega)\,d\omega`, where :math:`c_j` are the
    :func:`fresnel_cosine_factors`; Sect. 3.3 of Wang et al. 2008, "Environment lighting".
    """

    resolution: int
    transport: QuantisedRows
    samples: int

    def irradiance(self, light, eta: float) -> np.ndarray:
        """E at the samples for one environment light and index ``eta``, (N, 3)."""
        directions, _ = _environment_directions(self.resolution)
        radiance = _environment_radiance(light, directions)
        images = radiance.T.reshape(3, 2, self.resolution, self.resolution)
        radiance_w = haar2d_forward(images.astype(np.float32)).reshape(3, -1).T
        products = self.transport.product(radiance_w).reshape(FRESNEL_RANK, self.samples, 3)
        _, _, weights, _ = fresnel_cosine_factors()
        return np.einsum("j,jnc->nc", weights(eta), products.astype(np.float64))


def precompute_environment(scene, samples: IlluminationSamples, resolution: int,
                           terms: int) -> EnvironmentTransfer:
    """Visibility of ``resolution x 2 resolution`` directions from every sample, compressed.

    Rays from every sample towards every direction of its upper hemisphere
    (:func:`translucent.scenes.visible`); each row, weighted by the solid angle and one
    Fresnel-cosine factor, is Haar-transformed over the two squares of the direction grid
    and cut to its ``terms`` largest coefficients.
    """
    from ..scenes.raycast import visible

    directions, solid_angle = _environment_directions(resolution)
    mu_grid, factors, _, _ = fresnel_cosine_factors()
    far = _far_distance(samples)
    block = max(1, (1 << 20) // len(directions))
    # ranked by support: the lighting is smooth where visibility has sharp horizons, so the
    # coarse coefficients matter more than their size says (measured on a constant
    # environment, 64 of 512 terms: 2.6 % worst-sample error by magnitude)
    ranking = haar2d_support_weights(2, resolution)
    pieces: list[list[SparseRows]] = [[] for _ in range(FRESNEL_RANK)]
    for start in range(0, len(samples), block):
        stop = min(start + block, len(samples))
        cosine = samples.normals[start:stop] @ directions.T
        where = np.nonzero(cosine > 0)
        seen = np.zeros(cosine.shape, dtype=bool)
        if len(where[0]):
            origins = samples.positions[start:stop][where[0]]
            seen[where] = visible(scene, origins, origins + far * directions[where[1]],
                                  normals_a=samples.normals[start:stop][where[0]])
        for j in range(FRESNEL_RANK):
            factor = np.interp(np.clip(cosine, 0.0, 1.0), mu_grid, factors[j])
            rows = np.where(seen, factor * solid_angle, 0.0).astype(np.float32)
            images = haar2d_forward(rows.reshape(-1, 2, resolution, resolution))
            pieces[j].append(nonlinear_approximation(images.reshape(stop - start, -1), 1.0,
                                                     terms, weights=ranking))
    stacked = SparseRows.concatenate([piece for rows in pieces for piece in rows])
    return EnvironmentTransfer(resolution, stacked.quantised(), len(samples))


# ----------------------------------------------------------------- the state


def brute_force_radiance(transfer: ObjectTransfer, vertices, irradiance, material: Dipole,
                         *, mm_per_unit: float = 1.0, vertex_indices=None) -> np.ndarray:
    r"""Eq. 1-2 evaluated directly on the same samples: :math:`\sum_i R_d(r_{vi}) A_i E_i`.

    No basis, no wavelets, no quantisation: the exact dipole :math:`R_d` (all distances,
    also beyond 65 mm). Omits :math:`F_t(\omega_o)/\pi`, like the vertex values of
    :meth:`PRTState.vertex_radiance`.

    Parameters
    ----------
    transfer : ObjectTransfer
        For its samples.
    vertices : ndarray, (V, 3)
        The object's vertices, scene units.
    irradiance : ndarray, (N, 3)
        E at the samples (:func:`sample_irradiance`).
    material : Dipole
    mm_per_unit : float
    vertex_indices : array_like of int, optional
        Evaluate only these vertices (cost V x N).

    Returns
    -------
    ndarray, (V, 3) or (len(vertex_indices), 3), float64
    """
    vertices = np.asarray(vertices, dtype=np.float64)
    if vertex_indices is not None:
        vertices = vertices[np.asarray(vertex_indices)]
    samples = transfer.samples
    out = np.zeros((len(vertices), 3))
    block = max(1, (1 << 22) // len(samples))
    for start in range(0, len(vertices), block):
        chunk = vertices[start:start + block]
        distance = np.linalg.norm(chunk[:, None, :] - samples.positions[None, :, :],
                                  axis=-1) * mm_per_unit
        profile = dipole_reflectance_profile(distance[..., None], material.sigma_a,
                                             material.sigma_s_prime, material.eta)
        out[start:start + block] = np.einsum("vnc,nc->vc", profile, irradiance) * samples.area
    return out


def _material(material) -> Dipole:
    if not isinstance(material, Dipole):
        raise InputError("the prt method renders homogeneous translucent materials: give a "
                         "Dipole", field="material", value=type(material).__name__)
    return material


@dataclass
class _PixelMap:
    """Where an object's vertices land in the image: barycentric gathers, exit cosines."""

    pixels: np.ndarray
    corners: np.ndarray
    barycentrics: np.ndarray
    cosine: np.ndarray


#: E^w counts as one colour when its second singular value is below this fraction of the
#: first (float32 round-off of the Haar transform is ~1e-7).
SINGLE_COLOUR_TOLERANCE = 1e-6


def _single_colour(values) -> np.ndarray | None:
    """Return the unit RGB ``c`` with ``values ~ (values @ c) c^T``, or None if E has colours."""
    gram = values.astype(np.float64).T @ values.astype(np.float64)
    eigenvalues, eigenvectors = np.linalg.eigh(gram)
    if eigenvalues[-1] <= 0 or eigenvalues[-2] > SINGLE_COLOUR_TOLERANCE**2 * eigenvalues[-1]:
        return None
    colour = eigenvectors[:, -1]
    return (colour if colour.sum() >= 0 else -colour).astype(np.float32)


@numba.njit(cache=True, nogil=True, fastmath=True)
def _combine(vectors, coefficients, out):  # pragma: no cover
    """``out[c, r] = sum_k coefficients[c, k] vectors[c, k, r]`` (Eq. 7): the editing step."""
    for c in range(vectors.shape[0]):
        for r in range(vectors.shape[2]):
            out[c, r] = 0.0
        for k in range(vectors.shape[1]):
            weight = coefficients[c, k]
            for r in range(vectors.shape[2]):
                out[c, r] += weight * vectors[c, k, r]


def _same_lights(first, second) -> bool:
    return len(first) == len(second) and all(a is b for a, b in zip(first, second, strict=True))


def _ramp(value, start, end):
    return np.clip((value - start) / (end - start), 0.0, 1.0)


def projection_blend(basis: DipolePCABasis, sigma_a, sigma_s_prime, eta,
                     sample_spacing: float | None = None):
    r"""Coefficients :math:`s_k(\sigma)` and the weight :math:`\beta` of the local vector.

    Sect. 3.3 (step 3) of Wang et al. 2008 projects the profile onto the basis of Eq. 4;
    :math:`\beta` in [0, 1] is the weight of the local (opaque-limit) vector instead,
    0 where the projection is trusted. It is the largest of three weights, each a linear
    ramp from 0 to 1:

    * residual :math:`\rho` of the projection (:meth:`DipolePCABasis.project_with_residual`),
      from :data:`LOCAL_BLEND_START` to :data:`LOCAL_BLEND_END`;
    * relative energy error :math:`|E_K - E|/E` of the K-term profile against the exact one,
      both :math:`2\pi\int_0^{65} R(r)\,r\,dr` (:meth:`DipolePCABasis.project_with_energy`),
      from :data:`ENERGY_BLEND_START` to :data:`ENERGY_BLEND_END`;
    * sampling: :math:`\log_2(\Delta / \ell)`, with :math:`\ell = 1/\sigma'_t` the reduced
      mean free path and :math:`\Delta` the spacing of the basis's first two distances (0.1 mm
      for the paper's basis), from 0 to :data:`RESOLUTION_BLEND_OCTAVES`;
    * with ``sample_spacing`` h (mm), the fraction of the profile's energy within h,
      :math:`R_d(h) / R_d(65)` (closed form:
      :func:`~translucent.materials.dipole_pca.truncated_diffuse_reflectance`), from
      :data:`SAMPLING_BLEND_START` to :data:`SAMPLING_BLEND_END`: the illumination samples
      cannot integrate a profile that lives between them.

    A projection is trusted (:math:`\beta = 0`) only when all the weights are 0; the
    measured media inside a basis's grid always are (the paper's method unchanged), with
    the sampling weight at the default 16384 samples on a 10 mm sphere or denser (0.28 mm).
    About 0.3 ms for three channels.

    Parameters
    ----------
    basis : DipolePCABasis
    sigma_a, sigma_s_prime : array_like
        mm^-1, >= 0, broadcast together (RGB: shape (3,)).
    eta : array_like
        Relative index of refraction in [1, 3].
    sample_spacing : float, optional
        Spacing of the illumination samples, mm; None leaves the last weight out (the
        projection alone).

    Returns
    -------
    coefficients : ndarray, shape ``broadcast shape + (K,)``
    blend : ndarray, broadcast shape
        :math:`\beta`, dimensionless.
    """
    coefficients, residual, energy, exact_energy = basis.project_with_energy(
        sigma_a, sigma_s_prime, eta)
    energy_error = np.abs(energy - exact_energy) / np.where(exact_energy > 0, exact_energy, 1.0)
    spacing = float(basis.radii[1] - basis.radii[0])
    sigma_t_prime = np.asarray(sigma_a, np.float64) + np.asarray(sigma_s_prime, np.float64)
    with np.errstate(divide="ignore"):
        octaves = np.log2(spacing * sigma_t_prime)
    weights = [_ramp(residual, LOCAL_BLEND_START, LOCAL_BLEND_END),
               _ramp(energy_error, ENERGY_BLEND_START, ENERGY_BLEND_END),
               _ramp(octaves, 0.0, RESOLUTION_BLEND_OCTAVES)]
    if sample_spacing is not None:
        within = truncated_diffuse_reflectance(sigma_a, sigma_s_prime, eta, sample_spacing)
        fraction = within / np.where(exact_energy > 0, exact_energy, 1.0)
        weights.append(_ramp(fraction, SAMPLING_BLEND_START, SAMPLING_BLEND_END))
    blend = np.maximum.reduce(weights)
    return coefficients, np.broadcast_to(blend, residual.shape)


@dataclass
class PRTState:
    """What :func:`precompute` returns; ``render(lights=None, material=None) -> Image``.

    Holds the precomputed transfers, the G-buffer of the scene's camera (computed on first
    render) and, per object, the per-basis vectors :math:`v_k` of the last lighting: a new
    material only re-weights them (editing), new lights recompute them (relighting).
    """

    scene: object
    knobs: dict
    transfers: list
    log: StageLog = field(default_factory=StageLog)

    def __post_init__(self):
        self.basis = _basis(self.knobs)
        self._lighting: dict = {}
        self._vertex_vectors: dict = {}
        self._product_buffers: dict = {}
        self._frames_lit: dict = {}
        self._pixels: dict | None = None
        self._exit_factors: dict = {}
        self._environment: dict = {}
        self._wavelets = {t.name: SpatialWavelet(t.spatial_shape) for t in self.transfers
                          if t.spatial_shape is not None}
        self._lock = threading.Lock()

    def _environment_transfer(self, transfer: ObjectTransfer, lights):
        if not any(isinstance(light, (ConstantEnvironment, ImageEnvironment)) for light in lights):
            self.log.notes["environment"] = ("no environment light: no environment visibility "
                                             "precomputed")
            return None
        from ..cache import Cache, content_hash

        # the scene and knobs are fixed for the state: one visibility per object, and the
        # geometry is hashed only when it is first needed, not on every relighting frame
        if transfer.name not in self._environment:
            resolution = self.knobs["environment_resolution"]
            terms = self.knobs["environment_terms"]
            key = content_hash("prt-environment", PRT_VERSION, self.scene.geometry_key(),
                               transfer.name, resolution, terms,
                               {k: v for k, v in self.knobs.items() if k not in _UNKEYED_KNOBS})
            cache = Cache("prt")
            environment = cache.load_pickle(key)
            if not isinstance(environment, EnvironmentTransfer):
                start = time.perf_counter()
                environment = precompute_environment(self.scene, transfer.samples, resolution,
                                                     terms)
                cache.store_pickle(key, environment)
                self.log.seconds["environment visibility"] = time.perf_counter() - start
            self._environment[transfer.name] = environment
        return self._environment[transfer.name]

    def irradiance(self, transfer: ObjectTransfer, lights, eta: float) -> np.ndarray:
        """E at the samples of one object (:func:`sample_irradiance`), (N, 3)."""
        return sample_irradiance(self.scene, transfer.samples, lights, eta,
                                 area_light_samples=self.knobs["area_light_samples"],
                                 environment=self._environment_transfer(transfer, lights),
                                 seed=self.knobs["seed"])

    def basis_vectors(self, transfer: ObjectTransfer, irradiance) -> np.ndarray:
        """:math:`v_k = {}^wT_k^w E^w` (Eq. 8-9) for all k, shape (3, K + 1, R), float32.

        Lights of one colour make E one spectrum times one scalar field: then a single
        channel is multiplied (the matrix is read once either way, for a third of the
        arithmetic) and the colour applied afterwards. The products are written into
        buffers kept per object (no allocation per frame); the returned array is a copy
        only the caller holds.
        """
        irradiance_w = transfer.samples.to_wavelets(irradiance)
        shape = (transfer.basis_terms + 1, transfer.row_count)
        colour = _single_colour(irradiance_w)
        channels = () if colour is not None else (3,)
        key = (transfer.name, channels)
        if key not in self._product_buffers:
            self._product_buffers[key] = np.empty((transfer.transfer.rows,) + channels,
                                                  dtype=np.float32)
        products = self._product_buffers[key]
        if colour is not None:
            transfer.transfer.product(irradiance_w @ colour, out=products)
            return colour[:, None, None] * products.reshape(shape)[None]
        transfer.transfer.product(irradiance_w, out=products)
        return np.ascontiguousarray(products.T.reshape((3,) + shape))

    def relight(self, transfer: ObjectTransfer, lights, eta: float) -> None:
        """Recompute E and the per-basis vectors of one object for ``lights`` and ``eta``."""
        lights = tuple(lights)
        start = time.perf_counter()
        irradiance = self.irradiance(transfer, lights, eta)
        middle = time.perf_counter()
        vectors = self.basis_vectors(transfer, irradiance)
        self.log.seconds["irradiance"] = middle - start
        self.log.seconds["transfer product"] = time.perf_counter() - middle
        self._lighting[transfer.name] = (lights, float(eta), vectors)
        self._vertex_vectors.pop(transfer.name, None)
        self._frames_lit[transfer.name] = 0

    def _spatial_vertex_vectors(self, transfer: ObjectTransfer) -> np.ndarray | None:
        r"""Per-basis vectors in vertex space, or None while only one frame used this light.

        The inverse CDF 9/7 is linear, so :math:`W^{-1} \sum_k s_k v_k = \sum_k s_k
        W^{-1} v_k`: once a second frame (an edit) uses the same lighting, every basis
        vector is transformed back once and each further edit is a plain weighted sum (no
        transfer product and no inverse transform redone; Sect. 3.3 of Wang et al. 2008).
        The first frame after a relighting transforms the 3 combined channels instead (13x
        cheaper), so relighting frames do not pay for it.
        """
        cached = self._vertex_vectors.get(transfer.name)
        if cached is None and self._frames_lit.get(transfer.name, 0) >= 1:
            _, _, vectors = self._lighting[transfer.name]
            channels, blocks, rows = vectors.shape
            coefficients = np.moveaxis(vectors, 2, 0).reshape(rows, channels * blocks)
            values = self._wavelets[transfer.name].inverse(coefficients)
            cached = np.ascontiguousarray(np.moveaxis(values.reshape(rows, channels, blocks),
                                                      0, 2))
            self._vertex_vectors[transfer.name] = cached
        self._frames_lit[transfer.name] = self._frames_lit.get(transfer.name, 0) + 1
        return cached

    def vertex_radiance(self, transfer: ObjectTransfer, material: Dipole) -> np.ndarray:
        r"""Per-vertex :math:`\sum_k s_k(\sigma) v_k` (Eq. 7/10), before :math:`F_t/\pi`, (V, 3).

        Uses the per-basis vectors of the object's last :meth:`relight`.
        """
        _, _, vectors = self._lighting[transfer.name]
        spatial = transfer.spatial_shape is not None
        in_vertex_space = self._spatial_vertex_vectors(transfer) if spatial else vectors
        source = vectors if in_vertex_space is None else in_vertex_space
        combined = np.empty((3, source.shape[2]), dtype=np.float32)
        spacing = float(np.sqrt(transfer.samples.area)) if self.knobs["sampling_blend"] \
            else None
        _combine(source, self.coefficients(material, spacing), combined)
        combined = combined.T
        if in_vertex_space is None:
            combined = self._wavelets[transfer.name].inverse(combined)
        return combined

    def coefficients(self, material: Dipole, sample_spacing: float | None = None) -> np.ndarray:
        r"""Weights of the K basis vectors and of the local vector, per channel, (3, K + 1).

        :math:`s_k(\sigma)` (Sect. 3.3, step 3) for profiles the basis represents. A profile
        it cannot represent (mean free path far below the sampled distances: the paper's
        "uninteresting cases where multiple scattering is insignificant ... more appropriate
        to handle using the diffuse BRDF model", Sect. 4) is blended, by the projection's
        weight :math:`\beta` of :func:`projection_blend` (residual, energy and sampling of
        the projection; with ``sample_spacing`` in mm, also how well the illumination
        samples resolve the profile), into exactly that: the local vector (irradiance averaged
        around each vertex) times the total diffuse reflectance :math:`R_d` (closed form), so
        that in the opaque limit the object is a Lambertian surface of albedo :math:`R_d`,
        the limit of the dipole. For the measured media inside the basis's grid
        :math:`\beta = 0`: the paper's method unchanged.
        """
        coefficients, blend = projection_blend(self.basis, material.sigma_a,
                                               material.sigma_s_prime, material.eta,
                                               sample_spacing)
        local = blend * total_diffuse_reflectance(material.sigma_a, material.sigma_s_prime,
                                                  material.eta)
        kept = (1.0 - blend)[:, None] * coefficients
        return np.concatenate([kept, local[:, None]], axis=1).astype(np.float32)

    def _pixel_maps(self) -> dict:
        if self._pixels is None:
            from ..scenes.raycast import gbuffer

            view = gbuffer(self.scene)
            maps = {}
            for transfer in self.transfers:
                where = view.mask(transfer.name)
                mesh = self.scene.object(transfer.name).mesh
                cosine = np.einsum("...d,...d->...", view.normal, view.view_direction)[where]
                maps[transfer.name] = _PixelMap(
                    np.flatnonzero(where.ravel()), mesh.faces[view.triangle_id[where]],
                    view.barycentrics[where].astype(np.float32), np.clip(cosine, 0.0, 1.0))
            self._pixels = {"shape": view.shape, "maps": maps}
        return self._pixels

    def _exit_factor(self, name: str, pixel_map: _PixelMap, eta: float) -> np.ndarray:
        r""":math:`F_t(\eta, \omega_o)/\pi` at the object's pixels, kept while eta is unchanged.

        Edits that keep eta (most of them) reuse it instead of evaluating Fresnel per pixel.
        """
        held = self._exit_factors.get(name)
        if held is None or held[0] != eta:
            held = (eta, (fresnel_transmittance(eta, pixel_map.cosine) / np.pi)
                    .astype(np.float32))
            self._exit_factors[name] = held
        return held[1]

    def render(self, lights=None, material=None) -> Image:
        """Render a frame: relight if the lights (or eta) changed, re-weight for the material.

        Parameters
        ----------
        lights : sequence of lights, optional
            Replace the scene's lights (relighting: E and the products are recomputed);
            None keeps the lights of the last frame (the scene's at first).
        material : Dipole, optional
            Replace the material of every homogeneous translucent object (editing: only the
            projection onto the basis and the weighted sum are redone, unless eta changes,
            which changes :math:`F_t` in E and relights).

        Returns
        -------
        Image
            Linear radiance; objects that are not homogeneous translucent are black.
        """
        material = None if material is None else _material(material)
        with self._lock:
            start = time.perf_counter()
            maps = self._pixel_maps()
            height, width = maps["shape"]
            image = np.zeros((height * width, 3), dtype=np.float32)
            for transfer in self.transfers:
                chosen = material or self.scene.object(transfer.name).material
                cached = self._lighting.get(transfer.name)
                wanted = tuple(lights) if lights is not None else \
                    (cached[0] if cached else tuple(self.scene.lights))
                if cached is None or cached[1] != chosen.eta or not _same_lights(cached[0],
                                                                                 wanted):
                    self.relight(transfer, wanted, chosen.eta)
                radiance = self.vertex_radiance(transfer, chosen)
                pixel_map = maps["maps"][transfer.name]
                exit_factor = self._exit_factor(transfer.name, pixel_map, chosen.eta)
                gathered = np.einsum("pk,pkc->pc", pixel_map.barycentrics,
                                     radiance[pixel_map.corners])
                image[pixel_map.pixels] = gathered * exit_factor[:, None]
            seconds = time.perf_counter() - start
            return Image(image.reshape(height, width, 3), metadata={
                "producer": "prt", "knobs": self.knobs, "seconds": seconds,
                "stage_seconds": dict(self.log.seconds), "notes": self.log.notes,
                "skipped": list(self.log.skipped)})


# ====================================================================== command line


def add_approx_arguments(parser) -> None:
    """Options of ``translucent approx prt SCENE``."""
    group = parser.add_mutually_exclusive_group()
    group.add_argument("--material", default=None,
                       help="a measured medium of Jensen et al. 2001 (Marble, Skin1, ...)")
    group.add_argument("--sigma-a", type=float, nargs=3, metavar=("R", "G", "B"),
                       help="absorption coefficient, mm^-1 (with --sigma-s-prime)")
    parser.add_argument("--sigma-s-prime", type=float, nargs=3, metavar=("R", "G", "B"),
                        help="reduced scattering coefficient, mm^-1 (with --sigma-a)")
    parser.add_argument("--eta", type=float, default=None,
                        help="relative index of refraction (default 1.3, or the medium's)")
    parser.add_argument("--samples", type=int, default=DEFAULT_KNOBS["samples"],
                        help="illumination samples: parts x 4^n (default 16384)")
    parser.add_argument("--parts", type=int, default=DEFAULT_KNOBS["parts"],
                        help="quadtree parts m (default 4)")
    parser.add_argument("--terms", type=int, default=DEFAULT_KNOBS["terms"],
                        help="Haar terms kept per transfer row (default 256)")
    parser.add_argument("--energy", type=float, default=DEFAULT_KNOBS["energy"],
                        help="energy fraction kept per transfer row (default 0.9999)")
    parser.add_argument("--basis", choices=sorted(PARAMETERISATIONS),
                        default=DEFAULT_KNOBS["basis"], help="R_d basis parameterisation")
    parser.add_argument("--basis-terms", type=int, default=DEFAULT_KNOBS["basis_terms"],
                        help="K, PCA terms of R_d (default 12)")
    parser.add_argument("--spatial", choices=("auto", "on", "off"),
                        default=DEFAULT_KNOBS["spatial"], help="CDF 9/7 spatial compression")
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")


def material_from_arguments(args) -> Dipole | None:
    """Return the Dipole the options ask for (None: keep the scene's).

    Raises
    ------
    InputError
        ``--sigma-a`` without ``--sigma-s-prime`` (or the reverse), ``--sigma-s-prime``
        with ``--material``, bad coefficients.
    """
    if args.material and args.sigma_s_prime is not None:
        raise InputError("give --material or --sigma-a/--sigma-s-prime, not both",
                         field="sigma_s_prime", value=args.sigma_s_prime)
    if args.material:
        medium = measured_medium(args.material)
        if args.eta is None:
            return medium
        return Dipole(medium.sigma_a, medium.sigma_s_prime, args.eta, medium.g, medium.name)
    if (args.sigma_a is None) != (args.sigma_s_prime is None):
        raise InputError("give both --sigma-a and --sigma-s-prime (mm^-1, R G B)",
                         field="sigma_s_prime" if args.sigma_a else "sigma_a", value=None)
    if args.sigma_a is not None:
        return Dipole(args.sigma_a, args.sigma_s_prime, 1.3 if args.eta is None else args.eta)
    if args.eta is not None:
        raise InputError("--eta needs --material or --sigma-a/--sigma-s-prime", field="eta",
                         value=args.eta)
    return None


def approx(scene, args) -> Image:
    """Render ``scene`` with the options parsed by :func:`add_approx_arguments`."""
    material = material_from_arguments(args)
    knobs = {"samples": args.samples, "parts": args.parts, "terms": args.terms,
             "energy": args.energy, "basis": args.basis, "basis_terms": args.basis_terms,
             "spatial": args.spatial, "progress": not args.no_progress}
    state = precompute(scene, **knobs)
    image = state.render(material=material)
    for sentence in image.metadata.get("skipped", []):
        print(f"skipped: {sentence}")
    return image.with_metadata(seconds_precompute=state.log.seconds.get("precompute"))
