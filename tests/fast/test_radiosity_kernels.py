"""The compiled loops and array helpers of translucent radiosity, against plain numpy."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy import sparse
from translucent.fast.radiosity.form_factors import build_patches
from translucent.fast.radiosity.geometry import pair_fractions
from translucent.fast.radiosity.kernels import (
    csr_order,
    csr_pattern,
    directed_pairs,
    sample_operator,
    samples_per_edge,
    scatter_product,
    scattering_samples,
)
from translucent.fast.radiosity.optical_distance import subdivision_barycentrics
from translucent.fast.radiosity.scattering import mixed_values
from translucent.materials import Lambertian
from translucent.materials.profiles import MixedProfiles, RadialGrid, TwoExponentialProfile
from translucent.scenes import Camera, Scene, SceneObject, box


def _samples_by_numpy(exit_local, incident, m, centroids, patches):
    """The midpoint-rule samples written out with einsum, one sample count at a time."""
    mm = patches.mm_per_unit
    rows, faces = patches.faces_of(incident)
    pair, weight, distance = [], [], []
    for value in np.unique(m[rows]):
        chosen = np.flatnonzero(m[rows] == value)
        barycentric = subdivision_barycentrics(int(value))
        corners = patches.triangles[faces[chosen]] * mm
        points = np.einsum("sk,nkd->nsd", barycentric, corners).reshape(-1, 3)
        owner = np.repeat(rows[chosen], len(barycentric))
        pair.append(owner)
        weight.append(np.repeat(patches.triangle_area[faces[chosen]] * mm * mm / value**2,
                                len(barycentric)))
        distance.append(np.linalg.norm(points - centroids[exit_local[owner]], axis=1))
    return np.concatenate(pair), np.concatenate(weight), np.concatenate(distance)


def _box_patches():
    camera = Camera([0.0, 0.0, 10.0], [0.0, 0.0, 0.0], width=8, height=8)
    scene = Scene([SceneObject("block", box((1.0, 2.0, 3.0), subdivisions=2),
                               Lambertian(0.5))], [], camera)
    return build_patches(scene, triangles_per_patch=2)


def test_scattering_samples_are_the_midpoint_rule_in_pair_order(rng):
    patches = _box_patches()
    count = len(patches)
    exit_local = rng.integers(0, count, 300)
    incident = rng.integers(0, count, 300)
    m = rng.integers(1, 5, 300)
    centroids = patches.centroid * patches.mm_per_unit
    offsets, weight, distance, points = scattering_samples(exit_local, incident, m,
                                                           centroids, patches, points=True)
    pair = np.repeat(np.arange(300), np.diff(offsets))
    expected_pair, expected_weight, expected_distance = _samples_by_numpy(
        exit_local, incident, m, centroids, patches)
    order = np.lexsort((expected_distance, expected_pair))
    mine = np.lexsort((distance, pair))
    assert np.array_equal(pair[mine], expected_pair[order])
    assert weight[mine] == pytest.approx(expected_weight[order], rel=1e-14)
    assert distance[mine] == pytest.approx(expected_distance[order], rel=1e-12, abs=1e-12)
    assert np.linalg.norm(points - centroids[exit_local[pair]], axis=1) == pytest.approx(
        distance, rel=1e-14, abs=1e-14)
    # the weights of a pair are its incident patch's area, whatever m
    areas = np.bincount(pair, weight, minlength=300)
    assert areas == pytest.approx(patches.area[incident] * patches.mm_per_unit**2, rel=1e-12)
    _, _, _, none = scattering_samples(exit_local, incident, m, centroids, patches,
                                       points=False)
    assert none.shape == (0, 3)


@pytest.mark.parametrize("share", [1.0, 0.1])  # dense rows (a scan), sparse rows (a sort)
def test_directed_pairs_are_both_directions_and_the_self_pairs_within_reach_sorted(rng, share):
    centroids = rng.uniform(0.0, 10.0, (40, 3))
    radius = rng.uniform(0.1, 1.0, 40)
    undirected = np.array([(a, b) for a in range(40) for b in range(a + 1, 40)])
    undirected = undirected[rng.permutation(len(undirected))[:int(share * len(undirected))]]
    exit_local, incident, distance = directed_pairs(undirected, centroids, radius, 4.0,
                                                    with_self=True)
    every_exit = np.concatenate([undirected[:, 0], undirected[:, 1], np.arange(40)])
    every_incident = np.concatenate([undirected[:, 1], undirected[:, 0], np.arange(40)])
    length = np.linalg.norm(centroids[every_exit] - centroids[every_incident], axis=1)
    keep = length <= 4.0 + radius[every_incident]
    assert 0 < keep.sum() < len(keep)
    order = np.lexsort((every_incident[keep], every_exit[keep]))
    assert np.array_equal(exit_local, every_exit[keep][order])
    assert np.array_equal(incident, every_incident[keep][order])
    assert np.array_equal(distance, length[keep][order])
    without, _, _ = directed_pairs(undirected, centroids, radius, 4.0, with_self=False)
    assert len(without) == len(exit_local) - 40


@settings(max_examples=40, deadline=None)
@given(st.integers(1, 12), st.integers(0, 60), st.integers(3, 40), st.integers(0, 2**32 - 1))
def test_sample_operator_equals_the_coo_assembly(pairs, samples, nodes, seed):
    rng = np.random.default_rng(seed)
    grid = RadialGrid(10.0, nodes)
    pair = np.sort(rng.integers(0, pairs, samples))
    offsets = np.searchsorted(pair, np.arange(pairs + 1))
    weight = rng.uniform(0.1, 2.0, samples)
    # beyond max_d and at inf: left out; at 0 and at max_d exactly: kept
    distance = rng.choice([0.0, 10.0, 10.5, np.inf, *rng.uniform(0.0, 12.0, 8)], samples)
    indptr, indices, data = sample_operator(offsets, weight, distance, grid.radius)
    kept = distance <= grid.max_radius
    k, f = grid.locate(distance[kept])
    f = f.astype(np.float64)
    expected = sparse.coo_matrix(
        (np.concatenate([weight[kept] * (1.0 - f), weight[kept] * f]),
         (np.concatenate([pair[kept], pair[kept]]), np.concatenate([k, k + 1]))),
        shape=(pairs, nodes)).tocsr()
    expected.sum_duplicates()
    assert np.array_equal(indptr, expected.indptr)
    assert np.array_equal(indices, expected.indices)
    assert data == pytest.approx(expected.data, rel=1e-14, abs=1e-300)


@settings(max_examples=40, deadline=None)
@given(st.integers(0, 10), st.integers(0, 6), st.integers(0, 2**32 - 1))
def test_scatter_product_adds_each_row_at_its_position(rows, spare, seed):
    rng = np.random.default_rng(seed)
    operator = sparse.random(rows, 7, density=0.4, random_state=seed % 1000, format="csr")
    table = rng.normal(size=(7, 3))
    size = rows + spare
    positions = rng.permutation(size)[:rows]
    out = rng.normal(size=(size, 3))
    expected = out.copy()
    expected[positions] += operator @ table
    scatter_product(operator, table, positions, out)
    # summed in scipy's order: equal to the last bit
    assert np.array_equal(out, expected)


def test_scatter_product_refuses_a_position_count_that_is_not_the_row_count():
    operator = sparse.identity(3, format="csr")
    with pytest.raises(ValueError, match="3 operator rows for 2 positions"):
        scatter_product(operator, np.ones((3, 3)), np.array([0, 1]), np.zeros((4, 3)))


@settings(max_examples=40, deadline=None)
@given(st.integers(0, 10), st.integers(0, 6), st.integers(0, 2**32 - 1))
def test_add_rows_is_numpys_fancy_add(rows, spare, seed):
    from translucent.fast.radiosity.kernels import add_rows

    rng = np.random.default_rng(seed)
    size = rows + spare
    positions = rng.permutation(size)[:rows]
    values = rng.normal(size=(rows, 3))
    out = rng.normal(size=(size, 3))
    expected = out.copy()
    expected[positions] += values
    add_rows(values, positions, out)
    assert np.array_equal(out, expected)
    with pytest.raises(ValueError, match=f"{rows} rows of values for {rows + 1} positions"):
        add_rows(values, np.arange(rows + 1), out)


def test_compiled_eq16_equals_mixed_profile_sample_by_sample(rng):
    from types import SimpleNamespace

    from translucent.materials.profiles import mixed_profile

    profiles = [TwoExponentialProfile(0.005 * (m + 1), 0.3 + 0.1 * m) for m in range(5)]
    material = MixedProfiles(profiles, np.zeros(4, dtype=np.int64))
    grid = RadialGrid(30.0, 64)
    samples, pairs, points = 500, 40, 8
    counts = np.zeros((pairs, len(profiles)), dtype=np.uint8)
    for row in range(pairs):  # each path crosses 1-3 materials
        crossed = rng.choice(len(profiles), size=rng.integers(1, 4), replace=False)
        counts[row] = np.bincount(rng.choice(crossed, size=points),
                                  minlength=len(profiles))
    pair = rng.integers(0, pairs, samples)
    distance = rng.uniform(0.0, 35.0, samples)  # beyond max_d: the last node, as locate
    weight = rng.uniform(0.1, 2.0, samples)
    item = SimpleNamespace(samples={"pair": pair, "distance": distance, "weight": weight,
                                    "fractions": counts, "mix_points": points},
                           sample_operator=sparse.csr_matrix((pairs, grid.samples)))
    tables = [p.tabulate(grid, "reflection") for p in profiles]
    fractions = counts[pair] / points
    at = np.empty((samples, len(profiles), 3))
    radius = grid.radius
    for m, table in enumerate(tables):
        r = np.clip(fractions[:, m] * distance, 0.0, grid.max_radius)
        at[:, m] = np.stack([np.interp(r, radius, table[:, c]) for c in range(3)], axis=1)
    expected = mixed_profile(np.stack([t[0] for t in tables]), at, fractions) * weight[:, None]
    summed = np.stack([np.bincount(pair, expected[:, c], minlength=pairs) for c in range(3)],
                      axis=1)
    assert mixed_values(item, material, grid) == pytest.approx(summed, rel=1e-12,
                                                                           abs=1e-300)


def test_pair_fractions_count_the_points_in_each_material():
    centroids = np.array([[0.0, 0.0, 0.0], [10.0, 0.0, 0.0], [0.0, 10.0, 0.0]])
    # three slabs of x: [0, 2.5) label 0, [2.5, 7.5) label 1, beyond label 2
    def labels(points):
        return np.digitize(points[:, 0], [2.5, 7.5])

    counts = pair_fractions(centroids, None, None, np.array([0, 0, 1]),
                                       np.array([1, 2, 2]), 3, 8, labels)
    # 8 points at t = (i + 0.5) / 8 along each segment
    assert counts.tolist() == [[2, 4, 2], [8, 0, 0], [2, 4, 2]]


def test_csr_order_is_a_stable_lexsort(rng):
    rows, cols = rng.integers(0, 7, 500), rng.integers(0, 5, 500)  # many ties
    assert np.array_equal(csr_order(rows, cols, 7), np.lexsort((cols, rows)))
    assert len(csr_order(np.zeros(0, int), np.zeros(0, int), 3)) == 0


@settings(max_examples=60, deadline=None)
@given(st.integers(1, 12), st.floats(0.1, 8.0), st.floats(0.5, 20.0),
       st.integers(0, 2**32 - 1))
def test_samples_per_edge_is_the_numpy_formula(most, falloff, beyond, seed):
    rng = np.random.default_rng(seed)
    radius = rng.uniform(0.01, 3.0, 300)
    edge = beyond * radius[298]
    distance = np.concatenate([rng.uniform(0.0, 40.0, 296),
                               [0.0, beyond * radius[297], np.nextafter(edge, np.inf), 1e9]])
    expected = np.clip(np.rint(most * np.exp(-distance / (falloff * radius))), 1, most)
    expected = np.where(distance > beyond * radius, 1, expected.astype(np.int64))
    assert np.array_equal(samples_per_edge(distance, radius, most, falloff, beyond), expected)


@settings(max_examples=40, deadline=None)
@given(st.integers(1, 9), st.integers(0, 40), st.integers(0, 2**32 - 1))
def test_csr_pattern_places_every_entry_in_row_and_column_order(size, count, seed):
    rng = np.random.default_rng(seed)
    # S's diagonal first, then sorted and shuffled blocks: rows of 1, 2 and more runs
    rows = np.concatenate([np.arange(size), np.sort(rng.integers(0, size, count)),
                           rng.integers(0, size, count // 3)])
    cols = np.concatenate([np.arange(size), rng.integers(0, size, count),
                           rng.integers(0, size, count // 3)])
    order = np.lexsort((cols, rows))
    indptr, indices, position = csr_pattern(rows, cols, size)
    assert np.array_equal(csr_order(rows, cols, size), order)
    counts = np.bincount(rows, minlength=size)
    assert np.array_equal(indptr, np.concatenate([[0], np.cumsum(counts)]))
    assert indices.dtype == np.int32 and np.array_equal(indices, cols[order])
    assert np.array_equal(position[order], np.arange(len(rows)))
