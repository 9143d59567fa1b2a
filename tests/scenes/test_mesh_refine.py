"""Midpoint subdivision: more vertices on the same surface (scenes/mesh_refine.py)."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from translucent.scenes import box, icosphere
from translucent.scenes.mesh_refine import edge_lengths, subdivide_midpoints
from translucent.scenes.mesh_shape import closed_surface
from translucent.scenes.raycast import ray_engine


def _edges(faces):
    return {tuple(sorted(edge)) for face in faces for edge in
            ((face[0], face[1]), (face[1], face[2]), (face[2], face[0]))}


@settings(max_examples=20, deadline=None)
@given(levels=st.integers(1, 2), subdivisions=st.integers(0, 2), which=st.sampled_from(
    ["box", "sphere"]))
def test_the_surface_area_and_closedness_stay_and_each_edge_is_split_once(levels,
                                                                       subdivisions, which):
    mesh = box((1.0, 2.0, 0.5), subdivisions=subdivisions + 1) if which == "box" else \
        icosphere(subdivisions, 1.0)
    finer = subdivide_midpoints(mesh, levels)
    assert len(finer.faces) == len(mesh.faces) * 4**levels
    assert finer.area == pytest.approx(mesh.area, rel=1e-12)
    assert closed_surface(finer.faces, finer.vertices) == closed_surface(mesh.faces,
                                                                         mesh.vertices)
    # the old vertices first; each edge gives one new vertex (no T-junction)
    assert np.array_equal(finer.vertices[:len(mesh.vertices)], mesh.vertices)
    if levels == 1:
        assert len(finer.vertices) == len(mesh.vertices) + len(_edges(mesh.faces))
    assert edge_lengths(finer).max() == pytest.approx(edge_lengths(mesh).max() / 2**levels)
    normals = np.linalg.norm(finer.normals, axis=1)
    assert np.allclose(normals, 1.0)


def test_every_ray_hits_the_refined_mesh_where_it_hit_the_mesh():
    mesh = icosphere(2, 1.0)
    finer = subdivide_midpoints(mesh, 2)
    rng = np.random.default_rng(3)
    origins = rng.normal(size=(2000, 3))
    origins = 3.0 * origins / np.linalg.norm(origins, axis=1, keepdims=True)
    targets = rng.uniform(-0.9, 0.9, size=(2000, 3))
    directions = targets - origins
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    before = ray_engine([mesh]).trace(origins, directions)
    after = ray_engine([finer]).trace(origins, directions)
    assert np.array_equal(before.hit, after.hit)
    # the same distance to a few float32 steps of the ray engine (one is 2.4e-7 at t ~ 2;
    # measured 1.2e-6 at most); projecting the midpoints onto the sphere would move
    # them by up to 1e-2
    assert np.allclose(before.t[before.hit], after.t[after.hit], rtol=0, atol=1e-5)


def test_zero_levels_is_the_mesh_itself():
    mesh = box()
    assert subdivide_midpoints(mesh, 0) is mesh
