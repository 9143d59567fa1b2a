"""Escape probability of diffusion in a finite object (fast/radiosity/diffusion_escape.py)."""

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from translucent.errors import InputError
from translucent.fast.radiosity.diffusion_escape import (
    diffusion_grid,
    escape_probability,
    finite_object_gain,
    halfspace_escape_probability,
    slab_gain,
    voxel_size_for,
)
from translucent.scenes.meshes import box, icosphere

#: Skim milk (mm^-1, Jensen et al. 2001) at a quarter of its scattering: 1/sigma_tr = 37 mm
#: in red, comparable to the 30 x 60 x 30 mm block of the Cornell-box scene.
SIGMA_A = np.array([0.0014, 0.0025, 0.0142])
SIGMA_S_PRIME = 0.25 * np.array([0.70, 1.22, 1.90])

#: The finite-volume half-space against its continuum limit: second order in the cell
#: size; at h = 0.05 mm the measured error is 2-4e-4.
HALFSPACE_ATOL = 1e-3
#: Gain of a box face's centre against the closed-form slab (a 6 mm slab, 1/sigma_tr =
#: 2.5 mm): the box is 16 diffusion lengths wide, whose sides add below 1e-6; the rest is
#: the scheme at 0.5 mm cells (measured 0.05 %).
SLAB_RTOL = 0.01
#: Gain of the same box rotated 20 degrees about the vertical against axis-aligned: the
#: staircase faces weighted by 1/|n|_1 (measured 0.6 %; unweighted 4.9 % in blue).
ROTATION_RTOL = 0.02
#: Gain at a face centre between 20 and 40 cells along the longest side (measured <= 0.35 %).
RESOLUTION_RTOL = 0.01


def _triangles(mesh):
    return mesh.vertices[mesh.faces]


def _box(size, subdivisions=4, rotate_degrees=0.0):
    mesh = box(size=size, center=(0.0, size[1] / 2.0, 0.0), subdivisions=subdivisions)
    triangles = _triangles(mesh)
    if rotate_degrees:
        a = math.radians(rotate_degrees)
        rotation = np.array([[math.cos(a), 0.0, math.sin(a)], [0.0, 1.0, 0.0],
                             [-math.sin(a), 0.0, math.cos(a)]])
        triangles = triangles @ rotation.T
    return triangles


@pytest.mark.parametrize("depth", [0.0, 0.3, 2.0, 10.0])
def test_halfspace_scheme_converges_to_the_closed_form(depth):
    sigma_t_prime = SIGMA_A + SIGMA_S_PRIME
    diffusion = 1.0 / (3.0 * sigma_t_prime)
    sigma_tr = np.sqrt(SIGMA_A / diffusion)
    expected = np.exp(-sigma_tr * depth) / (1.0 + 2.0 * diffusion * sigma_tr)  # A = 1
    got = halfspace_escape_probability(depth, SIGMA_A, SIGMA_S_PRIME, 1.0, 0.05)
    assert got == pytest.approx(expected, abs=HALFSPACE_ATOL)


def test_gain_of_a_wide_box_is_the_slab_closed_form():
    sigma_a, sigma_s_prime = np.array([0.05]), np.array([1.0])
    triangles = _box((40.0, 6.0, 40.0))
    grid = diffusion_grid(triangles, 0.5)
    centre, up = np.array([[0.0, 6.0, 0.0]]), np.array([[0.0, 1.0, 0.0]])
    got = finite_object_gain(grid, centre, up, sigma_a, sigma_s_prime, 1.0)[0, 0]
    expected = slab_gain(1.0 / 1.05, 6.0, sigma_a, sigma_s_prime, 1.0)[0]
    assert expected > 1.05  # the test means something: a thin slab re-emits more
    assert got == pytest.approx(expected, rel=SLAB_RTOL)


def test_gain_tends_to_one_in_a_large_object():
    # 1/sigma_tr = 2.5 mm in a 60 mm cube: the far faces are 24 diffusion lengths away
    triangles = _box((60.0, 60.0, 60.0))
    grid = diffusion_grid(triangles, voxel_size_for(triangles, 24))
    gain = finite_object_gain(grid, [[0.0, 60.0, 0.0]], [[0.0, 1.0, 0.0]], [0.05], [1.0], 1.0)
    assert gain[0, 0] == pytest.approx(1.0, abs=1e-3)


def test_gain_is_above_one_and_largest_near_edges_of_a_small_block():
    triangles = _box((30.0, 60.0, 30.0))
    grid = diffusion_grid(triangles, voxel_size_for(triangles, 24))
    points = [[0.0, 60.0, 0.0], [7.5, 60.0, 0.0], [13.0, 60.0, 0.0]]
    gain = finite_object_gain(grid, points, [[0.0, 1.0, 0.0]] * 3, SIGMA_A, SIGMA_S_PRIME, 1.0)
    assert np.all(gain > 1.0)
    assert np.all(np.diff(gain, axis=0) > 0)


def test_gain_does_not_depend_on_the_voxel_size():
    triangles = _box((30.0, 60.0, 30.0))
    point, normal = [[0.0, 60.0, 0.0]], [[0.0, 1.0, 0.0]]
    gains = [finite_object_gain(diffusion_grid(triangles, voxel_size_for(triangles, n)), point,
                                normal, SIGMA_A, 4.0 * SIGMA_S_PRIME, 1.0)[0]
             for n in (20, 40)]
    assert gains[0] == pytest.approx(gains[1], rel=RESOLUTION_RTOL)


def test_gain_does_not_depend_on_the_orientation():
    straight, turned = _box((30.0, 60.0, 30.0)), _box((30.0, 60.0, 30.0), rotate_degrees=20.0)
    a = math.radians(20.0)
    # the centre of the +x face, before and after the rotation
    point = np.array([15.0, 30.0, 0.0])
    normal = np.array([1.0, 0.0, 0.0])
    rotated = np.array([point[0] * math.cos(a), point[1], -point[0] * math.sin(a)])
    rotated_normal = np.array([math.cos(a), 0.0, -math.sin(a)])
    gains = []
    for triangles, p, n in ((straight, point, normal), (turned, rotated, rotated_normal)):
        grid = diffusion_grid(triangles, voxel_size_for(triangles, 32))
        gains.append(finite_object_gain(grid, [p], [n], SIGMA_A, SIGMA_S_PRIME, 1.0)[0])
    assert gains[1] == pytest.approx(gains[0], rel=ROTATION_RTOL)


def test_grid_holds_the_cells_inside_a_sphere():
    sphere = icosphere(radius=10.0, subdivisions=3)
    grid = diffusion_grid(_triangles(sphere), 1.0)
    volume = grid.cells * 1.0
    # cells whose centres lie inside: +-3 % at 20 cells across (the boundary layer is a
    # quarter of all cells); measured +0.8 %
    assert volume == pytest.approx(4.0 / 3.0 * math.pi * 1000.0, rel=0.03)
    assert np.all(np.linalg.norm(grid.centers, axis=1) < 10.0)


@settings(max_examples=20, deadline=None)
@given(st.floats(1e-3, 1.0), st.floats(0.05, 20.0))
def test_escape_probability_is_a_probability(sigma_a, sigma_s_prime):
    triangles = _box((10.0, 10.0, 10.0), subdivisions=1)
    grid = diffusion_grid(triangles, 1.0)
    escape = escape_probability(grid, [sigma_a], [sigma_s_prime], 1.3)
    assert np.all(escape > 0.0) and np.all(escape <= 1.0 + 1e-9)
    # deeper cells lose more to absorption: the centre escapes least
    centre = np.argmin(np.linalg.norm(grid.centers - [0.0, 5.0, 0.0], axis=1))
    assert escape[centre, 0] == pytest.approx(escape[:, 0].min(), rel=1e-6)


def test_bad_input_is_refused():
    triangles = _box((10.0, 10.0, 10.0), subdivisions=1)
    with pytest.raises(InputError, match="voxel_size"):
        diffusion_grid(triangles, 0.0)
    with pytest.raises(InputError, match="no voxel centre lies inside"):
        diffusion_grid(_box((10.0, 0.01, 10.0), subdivisions=1), 1.0)
    grid = diffusion_grid(triangles, 2.0)
    with pytest.raises(InputError, match="sigma_a > 0"):
        escape_probability(grid, [0.0], [1.0], 1.0)
    with pytest.raises(InputError, match="diffusion_voxels_per_axis"):
        voxel_size_for(triangles, 2)


def test_an_optically_thin_object_keeps_the_dipoles_energy():
    # sigma'_t = 2e-4 mm^-1: the dipole's source lies 5 m below a 30 mm block's surface
    triangles = _box((30.0, 60.0, 30.0))
    grid = diffusion_grid(triangles, voxel_size_for(triangles, 16))
    gain = finite_object_gain(grid, [[0.0, 60.0, 0.0]], [[0.0, 1.0, 0.0]], [1e-4], [1e-4], 1.0)
    assert gain[0, 0] == 1.0

