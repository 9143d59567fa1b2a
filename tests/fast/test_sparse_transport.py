import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays
from translucent.errors import InputError
from translucent.fast.sparse_transport import (
    MAX_COLUMNS,
    QuantisedRows,
    SharedColumnBlocks,
    SparseRows,
    index_bits_for,
    nonlinear_approximation,
)

#: Half a quantisation level of the row's largest entry: 0.5 / (2^15 - 1) with 16 value
#: bits, 0.5 / (2^13 - 1) with 14 (Sect. 3.2 of Wang et al. 2008), plus float32 round-off.
HALF_LEVEL_16 = 0.5 / 32767 + 1e-7
HALF_LEVEL_14 = 0.5 / 8191 + 1e-7

#: float32 round-off of sums of a few hundred products of order 1.
ROUND_OFF_32 = 1e-5

row_values = arrays(np.float32, st.integers(1, 300),
                    elements=st.floats(-1e3, 1e3, allow_nan=False, width=32))


@settings(max_examples=80, deadline=None)
@given(row=row_values, energy=st.floats(0.05, 1.0), budget=st.integers(1, 400))
def test_selection_keeps_the_largest_entries_until_the_energy(row, energy, budget):
    sparse = nonlinear_approximation(row[None, :], energy, budget)
    kept = sparse.indices
    assert sparse.nnz <= budget
    assert np.all(np.diff(kept) > 0)
    assert np.array_equal(sparse.values, row[kept])
    # float32 subnormals count as zero
    significant = np.abs(row) >= np.finfo(np.float32).tiny
    squared = np.where(significant, row.astype(np.float64) ** 2, 0.0)
    total = squared.sum()
    dropped = np.setdiff1d(np.arange(row.size), kept)
    if total == 0:
        assert sparse.nnz == 0
        return
    if dropped.size and sparse.nnz:
        # nothing dropped is larger than anything kept
        assert squared[dropped].max() <= squared[kept].min()
    kept_energy = squared[kept].sum()
    nonzero = np.count_nonzero(significant)
    if sparse.nnz < min(budget, nonzero):
        # stopped by the energy, and not one entry later than needed
        assert kept_energy >= energy * total * (1 - 1e-12)
        assert kept_energy - squared[kept].min() < energy * total


@settings(max_examples=80, deadline=None)
@given(values=arrays(np.float64, st.integers(1, 200),
                     elements=st.sampled_from([0.0, 1.0, 2.0, 2.0, 3.5]) | st.floats(0, 1e6)),
       data=st.data())
def test_largest_at_is_the_partition_of_the_negated_values(values, data):
    from translucent.fast.sparse_transport import largest_at

    k = data.draw(st.integers(0, len(values) - 1))
    copy = values.copy()
    assert largest_at(copy, k) == -np.partition(-values, k)[k]
    assert np.array_equal(np.sort(copy), np.sort(values))  # reordered, nothing lost


@settings(max_examples=80, deadline=None)
@given(magnitude=arrays(np.float64, st.integers(0, 300),
                        elements=st.sampled_from([0.0, 1.0, 2.0, 2.0, 3.5]) | st.floats(0, 1e6)),
       data=st.data())
def test_order_by_magnitude_is_the_lexicographic_sort(magnitude, data):
    from translucent.fast.sparse_transport import order_by_magnitude

    candidates = np.array(data.draw(st.permutations(range(len(magnitude)))), dtype=np.int64)
    expected = np.lexsort((candidates, -magnitude))
    m, c = magnitude.copy(), candidates.copy()
    order_by_magnitude(m, c)
    assert np.array_equal(m, magnitude[expected]) and np.array_equal(c, candidates[expected])
    # all-zero magnitudes: an ascending sort of the candidates
    zeros, c = np.zeros(len(candidates)), candidates.copy()
    order_by_magnitude(zeros, c)
    assert np.array_equal(c, np.sort(candidates))


def test_selection_keeps_the_lower_column_of_equal_entries():
    row = np.array([1.0, -2.0, 2.0, 0.5, -2.0, 2.0], dtype=np.float32)
    assert list(nonlinear_approximation(row[None, :], 1.0, 2).indices) == [1, 2]
    assert list(nonlinear_approximation(row[None, :], 1.0, 3).indices) == [1, 2, 4]


def test_selection_respects_the_budget_on_a_decaying_row(rng):
    row = (rng.normal(size=4096) * np.geomspace(1, 1e-6, 4096)).astype(np.float32)
    sparse = nonlinear_approximation(row[None, :], 1.0, 100)
    assert sparse.nnz == 100
    assert set(sparse.indices) == set(np.argsort(-np.abs(row))[:100])


def test_selection_of_many_rows_and_slots(rng):
    rows = rng.normal(size=(7, 64)).astype(np.float32)
    sparse = nonlinear_approximation(rows, 0.9, 16)
    assert sparse.rows == 7 and sparse.columns == 64
    dense = sparse.to_dense()
    for r in range(7):
        assert np.array_equal(dense[r, sparse.indices[sparse.indptr[r]:sparse.indptr[r + 1]]],
                              rows[r, sparse.indices[sparse.indptr[r]:sparse.indptr[r + 1]]])
    both = SparseRows.concatenate([sparse, sparse])
    assert both.rows == 14 and np.array_equal(both.to_dense()[7:], dense)


def test_quantisation_error_is_half_a_level(rng):
    rows = rng.normal(size=(20, 500)).astype(np.float32)
    sparse = nonlinear_approximation(rows, 1.0, 500)
    quantised = sparse.quantised()
    assert quantised.index_bits == 16 and quantised.packed.dtype == np.int32
    error = np.abs(quantised.dequantised().to_dense() - sparse.to_dense())
    largest = np.abs(rows).max(axis=1, keepdims=True)
    assert np.all(error <= HALF_LEVEL_16 * largest)


def test_wide_matrices_use_14_value_bits_and_18_index_bits(rng):
    columns = (1 << 16) + 5
    indices = np.array([0, 7, columns - 1], dtype=np.int32)
    values = rng.normal(size=3).astype(np.float32)
    sparse = SparseRows(np.array([0, 3]), indices, values, columns)
    quantised = sparse.quantised()
    assert quantised.index_bits == 18
    restored = quantised.dequantised()
    assert np.array_equal(restored.indices, indices)
    assert np.all(np.abs(restored.values - values) <= HALF_LEVEL_14 * np.abs(values).max())


def test_index_bits_and_their_limit():
    assert index_bits_for(1 << 16) == 16
    assert index_bits_for((1 << 16) + 1) == 18
    with pytest.raises(InputError, match="columns.*at most 262144"):
        index_bits_for(MAX_COLUMNS + 1)


def test_product_equals_the_dense_product(rng):
    rows = rng.normal(size=(50, 256)).astype(np.float32)
    quantised = nonlinear_approximation(rows, 0.99, 64).quantised()
    vector = rng.normal(size=(256, 3)).astype(np.float32)
    expected = quantised.dequantised().to_dense().astype(np.float64) @ vector
    result = quantised.product(vector)
    assert result.shape == (50, 3) and result.dtype == np.float32
    assert np.abs(result - expected).max() < ROUND_OFF_32 * np.abs(expected).max()
    assert quantised.nbytes == quantised.packed.nbytes + quantised.indptr.nbytes + \
        quantised.scales.nbytes


def test_empty_rows_give_zero(rng):
    quantised = QuantisedRows.from_sparse(nonlinear_approximation(np.zeros((3, 8)), 1.0, 4))
    assert quantised.nnz == 0
    assert np.all(quantised.product(np.ones((8, 3))) == 0)


@pytest.mark.parametrize("energy, terms, message", [
    (0.0, 4, r"energy.*\(0, 1\]"),
    (1.5, 4, r"energy.*\(0, 1\]"),
    (0.5, 0, "terms.*integer >= 1"),
    (0.5, 2.5, "terms.*integer >= 1"),
])
def test_bad_approximation_knobs(energy, terms, message):
    with pytest.raises(InputError, match=message):
        nonlinear_approximation(np.ones((2, 4)), energy, terms)


def test_bad_shapes():
    with pytest.raises(InputError, match="2D array of rows"):
        nonlinear_approximation(np.ones(4), 0.5, 2)
    quantised = nonlinear_approximation(np.ones((2, 4)), 1.0, 4).quantised()
    with pytest.raises(InputError, match=r"vector.*\(4, 3\)"):
        quantised.product(np.ones((5, 3)))


# --- shared column blocks ---------------------------------------------------------------


def random_blocks(rng, rows=40, slots=30, blocks=5, columns=200):
    indices = np.array([np.sort(rng.choice(columns, slots, replace=False)) for _ in range(rows)])
    values = rng.normal(size=(blocks, rows, slots)).astype(np.float32)
    counts = rng.integers(0, slots + 1, rows)
    counts[0] = 0  # an empty row
    dense = np.zeros((blocks * rows, columns))
    for k in range(blocks):
        for r in range(rows):
            dense[k * rows + r, indices[r, :counts[r]]] = values[k, r, :counts[r]]
    return SharedColumnBlocks.from_slots(indices, values, counts, columns), dense


def test_shared_blocks_store_each_block_at_16_bits(rng):
    matrix, dense = random_blocks(rng)
    assert matrix.rows == 200 and matrix.blocks == 5 and matrix.nnz == 5 * len(matrix.indices)
    assert matrix.indices.dtype == np.uint16 and matrix.levels.dtype == np.int16
    stored = matrix.dequantised().to_dense()
    largest = np.abs(dense).max(axis=1, keepdims=True)
    assert np.all(np.abs(stored - dense) <= HALF_LEVEL_16 * largest)
    assert matrix.nbytes == matrix.levels.nbytes + matrix.indices.nbytes + \
        matrix.indptr.nbytes + matrix.scales.nbytes


@pytest.mark.parametrize("channels", [(3,), ()])
def test_shared_blocks_product_equals_the_dense_product(rng, channels):
    matrix, _ = random_blocks(rng)
    vector = rng.normal(size=(200,) + channels).astype(np.float32)
    expected = matrix.dequantised().to_dense().astype(np.float64) @ vector
    result = matrix.product(vector)
    assert result.shape == (200,) + channels and result.dtype == np.float32
    assert np.abs(result - expected).max() < ROUND_OFF_32 * np.abs(expected).max()
    out = np.empty_like(result)
    assert matrix.product(vector, out=out) is out
    np.testing.assert_array_equal(out, result)


@settings(max_examples=30, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), parts=st.integers(1, 4))
def test_shared_blocks_concatenate_stacks_rows_within_every_block(seed, parts):
    rng = np.random.default_rng(seed)
    pieces = [random_blocks(rng, rows=int(rng.integers(1, 8)), slots=6, blocks=3, columns=20)
              for _ in range(parts)]
    stacked = SharedColumnBlocks.concatenate([matrix for matrix, _ in pieces])
    dense = np.concatenate([matrix.dequantised().to_dense().reshape(3, -1, 20)
                            for matrix, _ in pieces], axis=1).reshape(-1, 20)
    np.testing.assert_array_equal(stacked.dequantised().to_dense(), dense)
    vector = rng.normal(size=20).astype(np.float32)
    assert np.allclose(stacked.product(vector), dense @ vector, atol=1e-5)


def test_shared_blocks_beyond_16_bit_columns_use_32_bit_indices():
    columns = (1 << 16) + 4
    matrix = SharedColumnBlocks.from_slots([[3, columns - 1]], np.ones((2, 1, 2)), [2],
                                           columns)
    assert matrix.indices.dtype == np.int32 and matrix.indices.tolist() == [3, columns - 1]
    vector = np.zeros(columns, dtype=np.float32)
    vector[columns - 1] = 2.0
    assert matrix.product(vector).tolist() == [2.0, 2.0]


def test_shared_blocks_bad_input(rng):
    with pytest.raises(InputError, match=r"values.*indices \(R, S\), values \(B, R, S\)"):
        SharedColumnBlocks.from_slots(np.zeros((4, 3)), np.zeros((2, 4, 5)), np.zeros(4), 10)
    with pytest.raises(InputError, match=r"counts.*\[0, 3\]"):
        SharedColumnBlocks.from_slots(np.zeros((4, 3)), np.zeros((2, 4, 3)), [0, 4, 1, 1], 10)
    with pytest.raises(InputError, match="columns.*18 index bits"):
        SharedColumnBlocks.from_slots(np.zeros((1, 1)), np.zeros((1, 1, 1)), [1], MAX_COLUMNS + 1)
    matrix, _ = random_blocks(rng)
    with pytest.raises(InputError, match=r"vector.*\(200, 3\)"):
        matrix.product(np.ones((199, 3)))
    with pytest.raises(InputError, match=r"out.*contiguous float32.*\(200, 3\)"):
        matrix.product(np.ones((200, 3)), out=np.empty((200, 3), dtype=np.float64))
