r"""Sparse transport matrices: nonlinear approximation, 16-bit quantisation, products.

Rows of a wavelet-transformed transport matrix are cut to their largest coefficients
(nonlinear approximation: the fewest terms that keep a given fraction of the row's energy,
at most a term budget), then stored as 16-bit integers with 16-bit column indices packed
in one 32-bit word, with one float scale per row; beyond :math:`2^{16}` columns, 14 value
bits and 18 index bits (Sect. 3.2 of Wang et al. 2008, "Implementation notes"). The
product of such a matrix with a dense RGB vector (Eq. 8) streams the packed words once.

References
----------
Wang et al.: Real-time editing and relighting of homogeneous translucent materials. The
Visual Computer 24 (2008), Sect. 3.2-3.3.
Ng, Ramamoorthi, Hanrahan: All-frequency shadows using non-linear wavelet lighting
approximation. ACM TOG 22(3) (2003) (nonlinear approximation of transport rows).
"""

from __future__ import annotations

import functools
import threading
from dataclasses import dataclass

import numba
import numpy as np

from ..compiled import parallel_njit
from ..errors import InputError

__all__ = [
    "order_by_magnitude",
    "select_largest",
    "select_largest_weighted",
    "nonlinear_approximation",
    "SparseRows",
    "QuantisedRows",
    "SharedColumnBlocks",
    "index_bits_for",
    "MAX_COLUMNS",
]

#: Most columns a quantised matrix can index (18 index bits).
MAX_COLUMNS = 1 << 18


def index_bits_for(columns: int) -> int:
    """Index bits for a matrix of ``columns`` columns: 16 up to 2^16, else 18 (Wang et al. 2008).

    Raises
    ------
    InputError
        More than :data:`MAX_COLUMNS` columns.
    """
    if columns > MAX_COLUMNS:
        raise InputError(f"at most {MAX_COLUMNS} columns (18 index bits)", field="columns",
                         value=columns)
    return 16 if columns <= 1 << 16 else 18


#: Histogram bins of the selection: the top 12 bits of a float32 magnitude (8 exponent bits
#: and 3 mantissa bits), so that one bin spans a factor 1.125 in magnitude.
SELECTION_SHIFT = 19
SELECTION_BINS = 1 << (31 - SELECTION_SHIFT)


@numba.njit(cache=True, nogil=True)
def largest_at(values, k):  # pragma: no cover - compiled
    """Return the (k+1)-th largest of ``values`` (``-np.partition(-values, k)[k]``); reorders it.

    Hoare's selection with the middle element as pivot: expected linear time, and a few
    dozen lines for numba to compile where ``np.partition`` took seconds.
    """
    lo, hi = 0, values.shape[0] - 1
    while lo < hi:
        pivot = values[(lo + hi) // 2]
        i, j = lo, hi
        while i <= j:
            while values[i] > pivot:
                i += 1
            while values[j] < pivot:
                j -= 1
            if i <= j:
                values[i], values[j] = values[j], values[i]
                i += 1
                j -= 1
        if k <= j:
            hi = j
        elif k >= i:
            lo = i
        else:
            break
    return values[k]


@numba.njit(cache=True, nogil=True)
def _comes_first(magnitude, candidates, a, b):  # pragma: no cover - compiled
    """Return True where entry a precedes b: larger magnitude, then lower candidate."""
    return magnitude[a] > magnitude[b] or (magnitude[a] == magnitude[b]
                                           and candidates[a] < candidates[b])


@numba.njit(cache=True, nogil=True)
def _sift_down(magnitude, candidates, root, end):  # pragma: no cover - compiled
    while True:
        child = 2 * root + 1
        if child >= end:
            return
        if child + 1 < end and _comes_first(magnitude, candidates, child, child + 1):
            child += 1
        if not _comes_first(magnitude, candidates, root, child):
            return
        magnitude[root], magnitude[child] = magnitude[child], magnitude[root]
        candidates[root], candidates[child] = candidates[child], candidates[root]
        root = child


@numba.njit(cache=True, nogil=True)
def order_by_magnitude(magnitude, candidates):  # pragma: no cover - compiled
    """Sort both arrays in place, largest ``magnitude`` first, ties by ascending ``candidates``.

    A heapsort: O(n log n) with no allocation, a total order (so the kept set of
    :func:`select_largest` does not depend on a sort's handling of ties), and a few
    dozen lines for numba to compile where ``np.argsort`` and ``np.sort`` instantiate
    numba's quicksort, seconds of compilation in every process that meets them.
    With ``magnitude`` all zero it sorts ``candidates`` ascending.
    """
    n = magnitude.shape[0]
    for start in range(n // 2 - 1, -1, -1):
        _sift_down(magnitude, candidates, start, n)
    for end in range(n - 1, 0, -1):
        magnitude[0], magnitude[end] = magnitude[end], magnitude[0]
        candidates[0], candidates[end] = candidates[end], candidates[0]
        _sift_down(magnitude, candidates, 0, end)


@numba.njit(cache=True, nogil=True)
def select_largest(row, energy, max_terms, out_indices, out_values):  # pragma: no cover
    """Keep the largest entries of a float32 ``row`` until ``energy`` of its squared norm.

    At most ``max_terms`` entries; zeros and float32 subnormals (below 1.2e-38) count as
    nothing and are never kept. Compiled. Writes the kept column
    indices (ascending) and values into the first ``count`` slots of ``out_indices`` /
    ``out_values`` and returns ``count``.

    A float32 magnitude orders like its bit pattern, so one pass builds a histogram of the
    top bits, the bin holding the ``max_terms``-th largest entry is found from the top, and
    a second pass gathers the entries at or above it; only those (cut to ``max_terms`` by a
    partition when the bin is crowded) are sorted (:func:`order_by_magnitude`: of equal
    entries, the lower column is kept).
    """
    length = row.shape[0]
    bits = row.view(np.uint32)
    histogram = np.zeros(SELECTION_BINS, dtype=np.int64)
    total = 0.0
    for i in range(length):
        key = (bits[i] & 0x7FFFFFFF) >> SELECTION_SHIFT
        histogram[key] += 1
        if key > 0:  # zeros and subnormals (below 1.2e-38) count as nothing
            value = np.float64(row[i])
            total += value * value
    if total == 0.0:
        return 0
    budget = min(max_terms, length)
    cutoff = SELECTION_BINS - 1
    above = 0
    while cutoff > 1 and above + histogram[cutoff] < budget:
        above += histogram[cutoff]
        cutoff -= 1
    candidates = np.empty(above + histogram[cutoff], dtype=np.int64)
    found = 0
    for i in range(length):
        if (bits[i] & 0x7FFFFFFF) >> SELECTION_SHIFT >= cutoff:
            candidates[found] = i
            found += 1
    magnitude = np.empty(found, dtype=np.float64)
    for j in range(found):
        value = np.float64(row[candidates[j]])
        magnitude[j] = value * value
    if found > 2 * budget:
        # a crowded cutoff bin: keep exactly the `budget` largest before sorting
        threshold = largest_at(magnitude.copy(), budget - 1)
        kept_candidates = np.empty(budget, dtype=np.int64)
        kept_magnitude = np.empty(budget, dtype=np.float64)
        taken = 0
        for j in range(found):
            if magnitude[j] > threshold:
                kept_candidates[taken] = candidates[j]
                kept_magnitude[taken] = magnitude[j]
                taken += 1
        for j in range(found):
            if taken >= budget:
                break
            if magnitude[j] == threshold:
                kept_candidates[taken] = candidates[j]
                kept_magnitude[taken] = magnitude[j]
                taken += 1
        candidates = kept_candidates
        magnitude = kept_magnitude
    order_by_magnitude(magnitude, candidates)
    target = energy * total
    kept = 0.0
    count = 0
    for j in range(min(budget, magnitude.shape[0])):
        if magnitude[j] == 0.0:
            break
        kept += magnitude[j]
        count += 1
        if kept >= target:
            break
    chosen = candidates[:count].copy()
    order_by_magnitude(np.zeros(count), chosen)
    for j in range(count):
        out_indices[j] = chosen[j]
        out_values[j] = row[chosen[j]]
    return count


@numba.njit(cache=True, nogil=True)
def select_largest_weighted(row, weights, energy, max_terms, out_indices, out_values,
                            scratch):  # pragma: no cover
    """Select as :func:`select_largest` does, ranking ``|row * weights|``; keep ``row``'s values.

    With ``weights`` the square root of each Haar function's support, this ranks a
    coefficient by the largest error its removal can cause in a product with any vector
    bounded by 1, instead of by its L2 size (which undervalues the coarse coefficients of
    a peaked row). ``scratch`` is a float32 array of the row's length.
    """
    for i in range(row.shape[0]):
        scratch[i] = row[i] * weights[i]
    count = select_largest(scratch, energy, max_terms, out_indices, out_values)
    for j in range(count):
        out_values[j] = row[out_indices[j]]
    return count


@parallel_njit(cache=True)
def _select_rows(rows, weights, energy, max_terms, out_indices, out_values,
                 counts):  # pragma: no cover
    for r in numba.prange(rows.shape[0]):
        scratch = np.empty(rows.shape[1], dtype=np.float32)
        counts[r] = select_largest_weighted(rows[r], weights, energy, max_terms, out_indices[r],
                                            out_values[r], scratch)


class _RowPointers:
    """Row count and stored entries of a matrix with CSR row pointers ``indptr``."""

    indptr: np.ndarray

    @property
    def rows(self) -> int:
        """Number of rows."""
        return len(self.indptr) - 1

    @property
    def nnz(self) -> int:
        """Stored entries."""
        return int(self.indptr[-1])


@dataclass(frozen=True, eq=False)
class SparseRows(_RowPointers):
    """A row-compressed sparse matrix with float32 values (CSR).

    Attributes
    ----------
    indptr : ndarray, int64, (R + 1,)
    indices : ndarray, int32, (nnz,)
        Column indices, ascending within each row.
    values : ndarray, float32, (nnz,)
    columns : int
    """

    indptr: np.ndarray
    indices: np.ndarray
    values: np.ndarray
    columns: int

    @classmethod
    def from_slots(cls, indices, values, counts, columns: int) -> SparseRows:
        """Compact fixed-size slots (``indices[r, :counts[r]]``) into CSR."""
        counts = np.asarray(counts, dtype=np.int64)
        keep = np.arange(indices.shape[1])[None, :] < counts[:, None]
        indptr = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
        return cls(indptr, indices[keep].astype(np.int32), values[keep].astype(np.float32),
                   int(columns))

    @classmethod
    def concatenate(cls, parts) -> SparseRows:
        """Stack the rows of several matrices with the same number of columns."""
        parts = list(parts)
        offsets = np.cumsum([0] + [p.nnz for p in parts])
        indptr = np.concatenate([[0]] + [p.indptr[1:] + offset
                                         for p, offset in zip(parts, offsets, strict=False)])
        return cls(indptr.astype(np.int64), np.concatenate([p.indices for p in parts]),
                   np.concatenate([p.values for p in parts]), parts[0].columns)

    def to_dense(self) -> np.ndarray:
        """Return the dense (R, columns) float32 matrix."""
        dense = np.zeros((self.rows, self.columns), dtype=np.float32)
        row_of = np.repeat(np.arange(self.rows), np.diff(self.indptr))
        dense[row_of, self.indices] = self.values
        return dense

    def quantised(self) -> QuantisedRows:
        """Quantise to 16-bit values with 16-bit indices (14/18 beyond 2^16 columns)."""
        return QuantisedRows.from_sparse(self)


def nonlinear_approximation(rows, energy: float, max_terms: int, *,
                            weights=None) -> SparseRows:
    """Keep the largest coefficients of each row (nonlinear wavelet approximation).

    Per row: the fewest largest-magnitude entries whose squared sum reaches ``energy``
    times the row's squared norm, at most ``max_terms`` of them (Sect. 3.2 of Wang et al.
    2008: "culling insignificant coefficients based on their magnitude").

    Parameters
    ----------
    rows : array_like, (R, N)
        Dense rows (selected in float32).
    energy : float
        Fraction of each row's energy to keep, in (0, 1].
    max_terms : int
        Term budget per row, >= 1.
    weights : array_like, (N,), optional
        Rank entries by ``|value * weight|`` (see :func:`select_largest_weighted`); by
        magnitude when omitted.

    Returns
    -------
    SparseRows
    """
    rows = np.ascontiguousarray(rows, dtype=np.float32)
    if rows.ndim != 2:
        raise InputError("must be a 2D array of rows", field="rows", value=rows.shape)
    energy, max_terms = check_approximation(energy, max_terms)
    budget = min(max_terms, rows.shape[1])
    indices = np.zeros((rows.shape[0], budget), dtype=np.int32)
    values = np.zeros((rows.shape[0], budget), dtype=np.float32)
    counts = np.zeros(rows.shape[0], dtype=np.int64)
    weights = np.ones(rows.shape[1], dtype=np.float32) if weights is None else \
        np.ascontiguousarray(weights, dtype=np.float32)
    if weights.shape != (rows.shape[1],):
        raise InputError(f"must have one weight per column ({rows.shape[1]})",
                         field="weights", value=weights.shape)
    _select_rows(rows, weights, energy, budget, indices, values, counts)
    return SparseRows.from_slots(indices, values, counts, rows.shape[1])


def check_approximation(energy, max_terms) -> tuple[float, int]:
    """Validate an energy fraction in (0, 1] and a term budget >= 1.

    Raises
    ------
    InputError
        Naming ``energy`` or ``terms`` and the accepted range.
    """
    energy_value = float(energy)
    if not 0.0 < energy_value <= 1.0:
        raise InputError("must be in (0, 1]", field="energy", value=energy)
    if isinstance(max_terms, bool) or int(max_terms) != max_terms or max_terms < 1:
        raise InputError("must be an integer >= 1", field="terms", value=max_terms)
    return energy_value, int(max_terms)


@numba.njit(cache=True, nogil=True)
def _quantise(indptr, indices, values, index_bits, value_max, packed, scales):  # pragma: no cover
    for r in range(len(indptr) - 1):
        start, stop = indptr[r], indptr[r + 1]
        largest = 0.0
        for j in range(start, stop):
            largest = max(largest, abs(np.float64(values[j])))
        scale = largest / value_max if largest > 0 else 0.0
        scales[r] = scale
        inverse = 1.0 / scale if scale > 0 else 0.0
        for j in range(start, stop):
            level = np.int32(np.rint(np.float64(values[j]) * inverse))
            packed[j] = (level << index_bits) | np.int32(indices[j])


@numba.njit(inline="always", fastmath=True)
def _row_rgb(packed, start, stop, index_bits, vector):  # pragma: no cover
    mask = (1 << index_bits) - 1
    red = np.float32(0.0)
    green = np.float32(0.0)
    blue = np.float32(0.0)
    for j in range(start, stop):
        word = packed[j]
        level = np.float32(word >> index_bits)
        column = word & mask
        red += level * vector[column, 0]
        green += level * vector[column, 1]
        blue += level * vector[column, 2]
    return red, green, blue


@parallel_njit(cache=True, fastmath=True)
def product_rgb(indptr, packed, scales, index_bits, vector, out):  # pragma: no cover
    for r in numba.prange(len(indptr) - 1):
        red, green, blue = _row_rgb(packed, indptr[r], indptr[r + 1], index_bits, vector)
        scale = scales[r]
        out[r, 0] = red * scale
        out[r, 1] = green * scale
        out[r, 2] = blue * scale


@numba.njit(cache=True, fastmath=True)
def product_rgb_per_row(indptr, packed, scales, index_bits, vectors, vector_of_row,
                        out):  # pragma: no cover
    """As :func:`product_rgb`, row ``r`` by ``vectors[vector_of_row[r]].T`` (serial).

    ``vectors`` is (V, 3, columns): channels first, as transformed per channel.
    """
    for r in range(len(indptr) - 1):
        red, green, blue = _row_rgb(packed, indptr[r], indptr[r + 1], index_bits,
                                    vectors[vector_of_row[r]].T)
        scale = scales[r]
        out[r, 0] = red * scale
        out[r, 1] = green * scale
        out[r, 2] = blue * scale


@parallel_njit(cache=True, fastmath=True)
def _product_scalar(indptr, packed, scales, index_bits, vector, out):  # pragma: no cover
    mask = (1 << index_bits) - 1
    for r in numba.prange(len(indptr) - 1):
        total = np.float32(0.0)
        for j in range(indptr[r], indptr[r + 1]):
            word = packed[j]
            total += np.float32(word >> index_bits) * vector[word & mask]
        out[r] = total * scales[r]


def _product_vector(vector, columns: int) -> np.ndarray:
    """Return ``vector`` as contiguous float32 of shape (columns, 3) or (columns,), or raise."""
    vector = np.ascontiguousarray(vector, dtype=np.float32)
    if vector.shape not in ((columns, 3), (columns,)):
        raise InputError(f"must have shape ({columns}, 3) or ({columns},)", field="vector",
                         value=vector.shape)
    return vector


@dataclass(frozen=True, eq=False)
class QuantisedRows(_RowPointers):
    """A sparse matrix with 16-bit values and 16-bit indices packed in int32 words.

    Word = ``(level << index_bits) | column``; the level is a signed integer of
    ``32 - index_bits`` bits (arithmetic shift recovers it), the value is
    ``level * scales[row]``. 16/16 bits up to 2^16 columns, 14/18 beyond (Sect. 3.2 of
    Wang et al. 2008). Relative rounding error per entry: at most 1/2 level of the row's
    largest entry, 1.5e-5 (16 bits) or 6.1e-5 (14 bits).

    Attributes
    ----------
    indptr : ndarray, int64, (R + 1,)
    packed : ndarray, int32, (nnz,)
    scales : ndarray, float32, (R,)
    index_bits : int
    columns : int
    """

    indptr: np.ndarray
    packed: np.ndarray
    scales: np.ndarray
    index_bits: int
    columns: int

    @classmethod
    def from_sparse(cls, sparse: SparseRows) -> QuantisedRows:
        """Quantise a :class:`SparseRows` (per-row scale: its largest entry -> the top level)."""
        index_bits = index_bits_for(sparse.columns)
        value_max = float((1 << (31 - index_bits)) - 1)
        packed = np.empty(sparse.nnz, dtype=np.int32)
        scales = np.empty(sparse.rows, dtype=np.float32)
        _quantise(sparse.indptr, sparse.indices, sparse.values, index_bits, value_max, packed,
                  scales)
        return cls(sparse.indptr, packed, scales, index_bits, sparse.columns)

    @property
    def nbytes(self) -> int:
        """Bytes of the packed words, row pointers and scales (what a product reads)."""
        return int(self.packed.nbytes + self.indptr.nbytes + self.scales.nbytes)

    def dequantised(self) -> SparseRows:
        """Return the float32 :class:`SparseRows` the words stand for."""
        levels = (self.packed >> self.index_bits).astype(np.float32)
        columns = (self.packed & ((1 << self.index_bits) - 1)).astype(np.int32)
        row_scale = np.repeat(self.scales, np.diff(self.indptr))
        return SparseRows(self.indptr, columns, levels * row_scale, self.columns)

    def product(self, vector, out=None) -> np.ndarray:
        r"""Matrix times a vector: ``out[r] = sum_j value[r, j] vector[column_j]`` (Eq. 8).

        Parameters
        ----------
        vector : array_like, (columns, 3) or (columns,)
            An RGB or a single-channel vector, cast to float32 (one channel reads the
            matrix once for a third of the arithmetic).
        out : ndarray, (R, 3) or (R,), float32, optional

        Returns
        -------
        ndarray, (R, 3) or (R,), float32
        """
        vector = _product_vector(vector, self.columns)
        if out is None:
            out = np.empty((self.rows,) + vector.shape[1:], dtype=np.float32)
        kernel = product_rgb if vector.ndim == 2 else _product_scalar
        kernel(self.indptr, self.packed, self.scales, self.index_bits, vector, out)
        return out


# ------------------------------------------------------------ shared column blocks


@numba.njit(cache=True, nogil=True)
def _quantise_blocks(indptr, values, levels, scales):  # pragma: no cover
    """Per row r and block k: scale = largest |value| / 32767, levels = rint(value / scale).

    ``values`` and ``levels`` share the layout of :class:`SharedColumnBlocks`.
    """
    blocks = scales.shape[1]
    for r in range(len(indptr) - 1):
        start, count = indptr[r], indptr[r + 1] - indptr[r]
        for k in range(blocks):
            first = blocks * start + k * count
            largest = 0.0
            for j in range(first, first + count):
                largest = max(largest, abs(np.float64(values[j])))
            scale = largest / LEVEL_MAX if largest > 0 else 0.0
            scales[r, k] = scale
            inverse = 1.0 / scale if scale > 0 else 0.0
            for j in range(first, first + count):
                levels[j] = np.int16(np.rint(np.float64(values[j]) * inverse))


@parallel_njit(cache=True, fastmath=True)
def _blocks_product_scalar(indptr, indices, levels, scales, vector, scratch,
                           out):  # pragma: no cover
    """``out[k, r] = scales[r, k] sum_j levels[k, r, j] vector[indices[r, j]]`` (Eq. 8).

    ``vector`` (columns,), ``out`` (blocks, rows).

    One pass over the stored words: per row, the vector entries of its columns are gathered
    once into the calling thread's ``scratch`` row, then each block's levels (contiguous
    int16) meet them in a dense dot product (vectorised: no gather per block).
    """
    blocks = scales.shape[1]
    for r in numba.prange(len(indptr) - 1):
        buffer = scratch[numba.get_thread_id(), 0]
        start = indptr[r]
        count = indptr[r + 1] - start
        # slices, not offsets: the compiler then vectorises the loops (measured 4x)
        columns = indices[start:start + count]
        for j in range(count):
            buffer[j] = vector[columns[j]]
        for k in range(blocks):
            first = blocks * start + k * count
            row = levels[first:first + count]
            total = np.float32(0.0)
            for j in range(count):
                total += np.float32(row[j]) * buffer[j]
            out[k, r] = total * scales[r, k]


@parallel_njit(cache=True, fastmath=True)
def _blocks_product_rgb(indptr, indices, levels, scales, vector, scratch,
                        out):  # pragma: no cover
    """:func:`_blocks_product_scalar` for three channels: each level is read once for all."""
    blocks = scales.shape[1]
    for r in numba.prange(len(indptr) - 1):
        thread = numba.get_thread_id()
        red, green, blue = scratch[thread, 0], scratch[thread, 1], scratch[thread, 2]
        start = indptr[r]
        count = indptr[r + 1] - start
        columns = indices[start:start + count]
        for j in range(count):
            column = columns[j]
            red[j] = vector[column, 0]
            green[j] = vector[column, 1]
            blue[j] = vector[column, 2]
        for k in range(blocks):
            first = blocks * start + k * count
            row = levels[first:first + count]
            total_red = np.float32(0.0)
            total_green = np.float32(0.0)
            total_blue = np.float32(0.0)
            for j in range(count):
                level = np.float32(row[j])
                total_red += level * red[j]
                total_green += level * green[j]
                total_blue += level * blue[j]
            scale = scales[r, k]
            out[k, r, 0] = total_red * scale
            out[k, r, 1] = total_green * scale
            out[k, r, 2] = total_blue * scale


#: Largest magnitude of a 16-bit level.
LEVEL_MAX = 32767.0

#: Per-thread gather buffers of :meth:`SharedColumnBlocks.product` (kept across frames).
_WORKSPACE = threading.local()


def _workspace(channels: int, width: int) -> np.ndarray:
    shape = (numba.config.NUMBA_NUM_THREADS, channels, max(width, 1))
    held = getattr(_WORKSPACE, "scratch", None)
    if held is None or held.shape[0] < shape[0] or held.shape[1] != channels \
            or held.shape[2] < shape[2]:
        held = np.empty(shape, dtype=np.float32)
        _WORKSPACE.scratch = held
    return held


@dataclass(frozen=True, eq=False)
class SharedColumnBlocks:
    """``B`` sparse matrices of ``R`` rows stacked (row ``k R + r``) that share columns per row.

    Row ``r`` of every block keeps the same columns ``indices[indptr[r]:indptr[r + 1]]``
    (the union of the columns each block's own nonlinear approximation kept), so a product
    gathers each column's vector entry once for all ``B`` blocks instead of once per block.
    Values are 16-bit levels with one float32 scale per row and block (Sect. 3.2 of Wang
    et al. 2008: 16-bit quantisation; the largest entry of a row maps to level 32767, so the
    rounding error is at most half a level, 1.5e-5 of that entry). Indices are 16-bit up to
    2^16 columns, 32-bit beyond.

    Attributes
    ----------
    indptr : ndarray, int64, (R + 1,)
        Column pointers per row.
    indices : ndarray, uint16 or int32, (U,)
        Column indices, ascending within a row.
    levels : ndarray, int16, (B * U,)
        Row ``r``'s levels start at ``B * indptr[r]``: block 0's ``n_r`` levels, then block
        1's, ... (``n_r = indptr[r + 1] - indptr[r]``).
    scales : ndarray, float32, (R, B)
    columns : int
    """

    indptr: np.ndarray
    indices: np.ndarray
    levels: np.ndarray
    scales: np.ndarray
    columns: int

    @classmethod
    def from_slots(cls, indices, values, counts, columns: int) -> SharedColumnBlocks:
        """Quantise fixed-size slots: ``indices[r, :counts[r]]``, ``values[k, r, :counts[r]]``.

        Parameters
        ----------
        indices : array_like of int, (R, S)
        values : array_like of float, (B, R, S)
        counts : array_like of int, (R,)
        columns : int

        Raises
        ------
        InputError
            Inconsistent shapes, counts beyond the slots, or more than :data:`MAX_COLUMNS`
            columns.
        """
        indices = np.asarray(indices)
        values = np.asarray(values, dtype=np.float32)
        counts = np.asarray(counts, dtype=np.int64)
        index_bits_for(columns)
        if indices.ndim != 2 or values.shape[1:] != indices.shape or \
                counts.shape != indices.shape[:1] or values.ndim != 3:
            raise InputError("needs indices (R, S), values (B, R, S) and counts (R,)",
                             field="values", value=(indices.shape, values.shape, counts.shape))
        if len(counts) and (counts.min() < 0 or counts.max() > indices.shape[1]):
            raise InputError(f"counts must be in [0, {indices.shape[1]}]", field="counts",
                             value=int(counts.max()))
        blocks = values.shape[0]
        keep = np.arange(indices.shape[1])[None, :] < counts[:, None]
        indptr = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
        dtype = np.uint16 if columns <= 1 << 16 else np.int32
        # row-major blocks: (R, B, S) with the unused slots dropped per row
        flat = np.transpose(values, (1, 0, 2))[np.broadcast_to(keep[:, None, :],
                                                               (len(counts), blocks,
                                                                indices.shape[1]))]
        levels = np.empty(flat.shape, dtype=np.int16)
        scales = np.empty((len(counts), blocks), dtype=np.float32)
        _quantise_blocks(indptr, flat, levels, scales)
        return cls(indptr, indices[keep].astype(dtype), levels, scales, int(columns))

    @classmethod
    def concatenate(cls, parts) -> SharedColumnBlocks:
        """Stack the rows (within every block) of several matrices with the same blocks."""
        parts = list(parts)
        offsets = np.cumsum([0] + [len(p.indices) for p in parts])
        indptr = np.concatenate([[0]] + [p.indptr[1:] + offset
                                         for p, offset in zip(parts, offsets, strict=False)])
        return cls(indptr.astype(np.int64), np.concatenate([p.indices for p in parts]),
                   np.concatenate([p.levels for p in parts]),
                   np.concatenate([p.scales for p in parts]), parts[0].columns)

    @functools.cached_property
    def width(self) -> int:
        """Most columns of any row (the size of the product's gather buffer)."""
        return int(np.diff(self.indptr).max()) if len(self.indptr) > 1 else 0

    @property
    def blocks(self) -> int:
        """B, the number of stacked matrices."""
        return int(self.scales.shape[1])

    @property
    def rows(self) -> int:
        """Rows of the stacked matrix, ``B R``."""
        return self.blocks * (len(self.indptr) - 1)

    @property
    def nnz(self) -> int:
        """Stored values (each shared column counts once per block)."""
        return int(len(self.levels))

    @property
    def nbytes(self) -> int:
        """Bytes of the levels, indices, row pointers and scales (what a product reads)."""
        return int(self.levels.nbytes + self.indices.nbytes + self.indptr.nbytes
                   + self.scales.nbytes)

    def dequantised(self) -> SparseRows:
        """Return the stacked float32 matrix as :class:`SparseRows` (row ``k R + r``)."""
        counts = np.diff(self.indptr)
        row_of = np.repeat(np.arange(len(counts)), counts)
        position = np.arange(len(self.indices)) - self.indptr[row_of]
        columns = self.indices.astype(np.int32)
        pieces = []
        for k in range(self.blocks):
            where = self.blocks * self.indptr[row_of] + k * counts[row_of] + position
            pieces.append(SparseRows(self.indptr, columns,
                                     self.levels[where] * self.scales[row_of, k],
                                     self.columns))
        return SparseRows.concatenate(pieces)

    def product(self, vector, out=None) -> np.ndarray:
        r"""Stacked matrix times a vector, ``out[k R + r] = sum_j value * vector[column_j]``.

        Eq. 8 of Wang et al. 2008 for all blocks at once (see :func:`_blocks_product_scalar`).

        Parameters
        ----------
        vector : array_like, (columns, 3) or (columns,)
            Cast to float32.
        out : ndarray, (B R, 3) or (B R,), float32, optional

        Returns
        -------
        ndarray, (B R, 3) or (B R,), float32
        """
        vector = _product_vector(vector, self.columns)
        channels = 1 if vector.ndim == 1 else 3
        if out is None:
            out = np.empty((self.rows,) + vector.shape[1:], dtype=np.float32)
        if out.shape != (self.rows,) + vector.shape[1:] or out.dtype != np.float32 \
                or not out.flags.c_contiguous:
            raise InputError(f"must be a contiguous float32 array of shape "
                             f"{(self.rows,) + vector.shape[1:]}", field="out", value=out.shape)
        matrix = vector.reshape(self.columns, channels)
        shape = (self.blocks, len(self.indptr) - 1)
        if channels == 3:
            _blocks_product_rgb(self.indptr, self.indices, self.levels, self.scales, matrix,
                                _workspace(3, self.width), out.reshape(shape + (3,)))
        else:
            _blocks_product_scalar(self.indptr, self.indices, self.levels, self.scales,
                                   matrix.reshape(-1), _workspace(1, self.width),
                                   out.reshape(shape))
        return out
