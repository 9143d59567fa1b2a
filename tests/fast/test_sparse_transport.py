import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays
from translucent.errors import InputError
from translucent.fast.sparse_transport import (
    MAX_COLUMNS,
    QuantisedRows,
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
