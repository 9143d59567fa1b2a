import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from translucent.errors import InputError
from translucent.fast.radiosity.optical_distance import (
    optical_distances,
    subdivision_barycentrics,
    voxelize,
)
from translucent.scenes import bowl, box, icosphere, plane, torus
from translucent.scenes.mesh_shape import closed_surface, is_convex, mesh_volume, welded_faces

#: The 26-neighbour voxel graph over-estimates a straight distance by at most 8 % (the
#: worst direction between its edge directions) plus one voxel diagonal at each end.
GRAPH_RELATIVE_EXCESS = 0.08


@given(m=st.integers(min_value=1, max_value=12))
@settings(max_examples=12, deadline=None)
def test_subdivision_points_are_an_exact_midpoint_rule(m):
    weights = subdivision_barycentrics(m)
    assert weights.shape == (m * m, 3)
    assert np.allclose(weights.sum(axis=1), 1.0)
    assert np.all(weights > 0)
    # equal-area sub-triangles: the mean is the centroid, linear functions are exact
    assert np.allclose(weights.mean(axis=0), 1 / 3)


def test_subdivision_rejects_bad_counts():
    with pytest.raises(InputError, match="m.*integer >= 1"):
        subdivision_barycentrics(0)


def test_closed_and_convex_meshes_are_recognised():
    cube = box((1.0, 2.0, 1.0), subdivisions=3)
    assert closed_surface(cube.faces, cube.vertices)  # seams welded
    assert is_convex(cube.vertices, cube.faces)
    sphere = icosphere(2)
    assert is_convex(sphere.vertices, sphere.faces)
    assert mesh_volume(cube.vertices, cube.faces) == pytest.approx(2.0)
    # welding maps the duplicated seam vertices onto one index each
    welded = welded_faces(cube.vertices, cube.faces)
    assert len(np.unique(welded)) == len(np.unique(np.round(cube.vertices, 9), axis=0))
    assert not is_convex(*_arrays(bowl(1.0, 0.2, subdivisions=16)))
    assert not is_convex(*_arrays(torus(1.0, 0.3, subdivisions=16)))
    sheet = plane(1.0, 1.0, subdivisions=2)
    assert not closed_surface(sheet.faces, sheet.vertices)
    assert not is_convex(sheet.vertices, sheet.faces)


def _arrays(mesh):
    return mesh.vertices, mesh.faces


def test_inside_out_mesh_is_not_convex():
    sphere = icosphere(1)
    assert not is_convex(sphere.vertices, sphere.faces[:, ::-1])


def test_voxelised_cube_is_filled():
    cube = box((10.0, 10.0, 10.0), subdivisions=2)
    grid = voxelize(cube.vertices[cube.faces], 1.0)
    # the interior 10^3 voxels plus the surface layer they touch
    assert 1000 <= grid.nodes <= 12**3
    assert grid.graph.nnz > 0
    assert (grid.graph != grid.graph.T).nnz == 0


def test_convex_distances_are_euclidean(rng):
    a, b = rng.normal(size=(50, 3)), rng.normal(size=(50, 3))
    distance = optical_distances(None, a, b, 2.5)
    euclid = np.linalg.norm(a - b, axis=1)
    assert np.array_equal(distance[euclid <= 2.5], euclid[euclid <= 2.5])
    assert np.all(np.isinf(distance[euclid > 2.5]))


def test_bowl_rim_to_rim_goes_around_through_the_wall():
    # a bowl of outer radius 50 mm and 5 mm wall: two opposite points of the rim at radius
    # 47.5 mm are 95 mm apart in a straight line; inside the wall the shortest path runs
    # tangent to the inner sphere (radius 45 mm) and along it, down and up again
    mesh = bowl(50.0, 5.0, subdivisions=48)
    grid = voxelize(mesh.vertices[mesh.faces], 1.25)
    left, right = np.array([[-47.5, 0.0, 0.0]]), np.array([[47.5, 0.0, 0.0]])
    distance = optical_distances(grid, left, right, 500.0)[0]
    tangent = np.sqrt(47.5**2 - 45.0**2)
    around = 2 * tangent + 45.0 * (np.pi - 2 * np.arccos(45.0 / 47.5))
    assert around <= distance <= around * (1 + GRAPH_RELATIVE_EXCESS) + 2 * 1.25 * np.sqrt(3)
    # through the wall (inside to outside at the bottom): the thickness, Euclidean
    bottom_in, bottom_out = np.array([[0.0, -45.2, 0.0]]), np.array([[0.0, -49.8, 0.0]])
    assert optical_distances(grid, bottom_in, bottom_out, 500.0)[0] == pytest.approx(4.6)


def test_early_termination_marks_far_pairs_beyond_the_cutoff():
    mesh = bowl(50.0, 5.0, subdivisions=32)
    grid = voxelize(mesh.vertices[mesh.faces], 2.0)
    left, right = np.array([[-47.5, 0.0, 0.0]]), np.array([[47.5, 0.0, 0.0]])
    # 95 mm apart in a straight line, 143 mm inside: a cut-off of 120 mm drops the pair
    assert np.isinf(optical_distances(grid, left, right, 120.0)[0])


@given(seed=st.integers(min_value=0, max_value=2**16))
@settings(max_examples=10, deadline=None)
def test_optical_distance_is_never_shorter_than_the_straight_line(seed):
    rng = np.random.default_rng(seed)
    mesh = torus(20.0, 6.0, subdivisions=24)
    grid = _torus_grid(mesh)
    corners = mesh.vertices[mesh.faces]
    faces = rng.integers(0, len(mesh.faces), size=(2, 40))
    a, b = corners[faces[0]].mean(axis=1), corners[faces[1]].mean(axis=1)
    distance = optical_distances(grid, a, b, 1e3)
    assert np.all(distance >= np.linalg.norm(a - b, axis=1) - 1e-12)
    assert np.all(np.isfinite(distance))


_GRIDS: dict = {}


def _torus_grid(mesh):
    if "torus" not in _GRIDS:
        _GRIDS["torus"] = voxelize(mesh.vertices[mesh.faces], 1.5)
    return _GRIDS["torus"]


def test_open_sheet_stays_a_shell():
    sheet = plane(20.0, 20.0, subdivisions=4)
    grid = voxelize(sheet.vertices[sheet.faces], 1.0, fill=False)
    assert grid.nodes <= 3 * 22 * 22  # one or two voxel layers, never a filled block


def test_voxelize_rejects_bad_size():
    cube = box()
    with pytest.raises(InputError, match="voxel_size.*must be > 0 mm"):
        voxelize(cube.vertices[cube.faces], 0.0)


def _segment_inside_point_by_point(grid, start, end):
    """The definition: every test point of the segment lies in an occupied voxel."""
    from translucent.fast.radiosity.optical_distance import SEGMENT_POINTS_PER_VOXEL

    steps = int(np.ceil(np.linalg.norm(end - start) / grid.voxel_size
                        * SEGMENT_POINTS_PER_VOXEL))
    t = np.arange(steps + 1) / max(steps, 1)
    points = start + t[:, None] * (end - start)
    ijk = grid.voxel_index(points)
    return bool((grid.node_of[ijk[:, 0], ijk[:, 1], ijk[:, 2]] >= 0).all())


@given(seed=st.integers(min_value=0, max_value=2**31 - 1))
@settings(max_examples=10, deadline=None)
def test_compiled_segment_test_agrees_with_the_point_by_point_definition(seed):
    rng = np.random.default_rng(seed)
    mesh = torus(10.0, 3.0, subdivisions=16)
    grid = voxelize(mesh.vertices[mesh.faces], 1.0)
    # ends on the surface and in the hole, so both answers occur; one zero-length segment
    starts = mesh.vertices[rng.integers(0, len(mesh.vertices), 200)]
    ends = np.concatenate([mesh.vertices[rng.integers(0, len(mesh.vertices), 199)],
                           starts[:1]])
    inside = grid.segment_inside(starts, ends)
    expected = [_segment_inside_point_by_point(grid, a, b)
                for a, b in zip(starts, ends, strict=True)]
    assert inside.tolist() == expected
    assert inside.any() and not inside.all()
