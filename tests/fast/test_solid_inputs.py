"""The fast methods' inputs derived from a solid medium (splatting texture, radiosity labels)."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from translucent.fast import radiosity, splatting
from translucent.fast.solid_inputs import (
    VoxelLabels,
    mixed_profiles_from_solid,
    subedit_from_solid,
    texel_positions,
)
from translucent.materials import Dipole, measured_medium
from translucent.materials.profiles import MixedProfiles
from translucent.materials.solid import checker_solid, uniform_solid, veined_solid
from translucent.materials.subedit import convert_media, subedit_from_dipole
from translucent.scenes import load_scene
from translucent.scenes.meshes import geometry_image
from translucent.scenes.scene import Camera


def _small(scene, rows=17, size=24):
    camera = scene.camera
    scene = scene.with_camera(Camera(camera.origin, camera.target, camera.up, camera.fov,
                                     size, size))
    from translucent.scenes.scene import SceneObject

    obj = scene.objects[0]
    mesh = geometry_image(rows, shape="sphere")
    return type(scene)((SceneObject(obj.name, mesh, obj.material),), scene.lights,
                       scene.camera, scene.mm_per_unit, scene.name)


def test_texel_centres_land_on_the_surface_at_their_uv():
    mesh = geometry_image(33, shape="sphere")
    points = texel_positions(mesh, 64)
    radius = np.linalg.norm(points, axis=-1)
    assert radius.max() <= 1.0 + 1e-12 and radius.min() > 0.98  # chords of a 33-row grid
    # a texel centre lies on the quad of the vertices around it in uv
    rows, cols = mesh.grid_shape
    grid = mesh.vertices.reshape(rows, cols, 3)
    j, i = 20, 41  # texel (row, col) -> uv centre -> grid cell
    u, v = (i + 0.5) / 64, (j + 0.5) / 64
    cell = grid[int(v * (rows - 1)):int(v * (rows - 1)) + 2,
                int(u * (cols - 1)):int(u * (cols - 1)) + 2].reshape(-1, 3)
    assert np.all(points[j, i] >= cell.min(axis=0) - 1e-12)
    assert np.all(points[j, i] <= cell.max(axis=0) + 1e-12)


def test_a_mesh_without_uv_cannot_carry_a_texture():
    from translucent.errors import InputError
    from translucent.scenes.meshes import icosphere

    with pytest.raises(InputError, match="uv"):
        texel_positions(icosphere(1), 8)


def test_the_checker_texture_holds_each_cell_medium_converted():
    solid = checker_solid("Skin1", "Ketchup", cells=4, eta=1.0)
    mesh = geometry_image(33, shape="sphere")
    conversion = subedit_from_solid(solid, mesh, resolution=32)
    assert conversion.media == 2 and conversion.quantisation_error == 0.0
    skin, ketchup = (c.profiles.log_profile[0, 0] for c in convert_media(
        [Dipole(m.sigma_a, m.sigma_s_prime, eta=1.0) for m in
         (measured_medium("Skin1"), measured_medium("Ketchup"))]))
    points = texel_positions(mesh, 32)
    sigma_a = solid.coefficients_at(points)[0]
    is_ketchup = np.all(sigma_a == measured_medium("Ketchup").sigma_a, axis=-1)
    texture = conversion.material.log_profile
    assert is_ketchup.any() and (~is_ketchup).any()
    assert np.allclose(texture[is_ketchup], ketchup)
    assert np.allclose(texture[~is_ketchup], skin)
    assert 0 < conversion.profile_error < 0.05


def test_the_uniform_field_gives_the_homogeneous_conversion_exactly():
    solid = uniform_solid("Skin1", eta=1.0, resolution=4)
    conversion = subedit_from_solid(solid, geometry_image(17, shape="sphere"))
    assert conversion.material.is_homogeneous
    expected = subedit_from_dipole(solid.dipole()).profiles
    assert np.array_equal(conversion.material.log_profile, expected.log_profile)
    assert isinstance(mixed_profiles_from_solid(solid, geometry_image(17)).material, Dipole)


def test_splatting_renders_the_homogeneous_limit_as_the_homogeneous_material():
    scene = _small(load_scene("solid_checker"))
    skin = measured_medium("Skin1")
    dipole = scene.with_material("sphere", Dipole(skin.sigma_a, skin.sigma_s_prime, eta=1.0))
    solid = scene.with_material("sphere", uniform_solid("Skin1", eta=1.0, resolution=2))
    # the half-space profile: a solid medium has no geometry correction (a Dipole has)
    first = splatting.precompute(dipole, geometry="half_space").render()
    second = splatting.precompute(solid, geometry="half_space").render()
    assert first.rgb.max() > 0
    assert np.allclose(first.rgb, second.rgb, rtol=1e-6, atol=0)
    assert splatting.precompute(_small(load_scene("solid_checker"))).render().metadata[
        "notes"]["solid medium"]["sphere"]["media"] == 2


def test_radiosity_labels_faces_by_the_voxel_and_reads_fractions_through_the_volume():
    solid = checker_solid("Skin1", "Ketchup", cells=2, eta=1.0)
    mesh = geometry_image(17, shape="sphere")
    material = mixed_profiles_from_solid(solid, mesh).material
    assert isinstance(material, MixedProfiles) and len(material.profiles) == 2
    skin_first = np.array_equal(material.profiles[0].dipole.sigma_a,
                                measured_medium("Skin1").sigma_a)
    centroids = mesh.face_centroids
    octant_odd = ((centroids > 0).sum(axis=1) % 2).astype(int)  # 2 cells a side
    expected = octant_odd if skin_first else 1 - octant_odd
    assert np.array_equal(material.face_labels, expected)
    # a chord along x at y, z > 0 spends half its length in each cell
    t = (np.arange(1000) + 0.5) / 1000
    chord = np.stack([-0.9 + 1.8 * t, np.full_like(t, 0.3), np.full_like(t, 0.3)], axis=1)
    labels = material.volume_labels(chord)
    assert labels.mean() == pytest.approx(0.5, abs=2e-3)


@settings(max_examples=25, deadline=None)
@given(st.integers(1, 5), st.integers(1, 40), st.integers(0, 2**32 - 1))
def test_compiled_counts_along_segments_equal_the_point_lookup(cells, points, seed):
    from translucent.fast.radiosity.geometry import pair_fractions

    rng = np.random.default_rng(seed)
    solid = checker_solid("Skin1", "Ketchup", cells=cells, eta=1.0)
    labels = rng.integers(0, 3, solid.shape)  # three labels, in any pattern
    volume = VoxelLabels(solid, labels)
    # ends inside and beyond the box (clamped to the border voxels), in mm at 10 mm a unit
    ends = rng.uniform(-1.3, 1.3, (12, 3)) * 10.0
    first, second = rng.integers(0, 12, 30), rng.integers(0, 12, 30)
    t = (np.arange(points) + 0.5) / points
    along = ends[first][:, None] + t[None, :, None] * (ends[second] - ends[first])[:, None]
    looked_up = volume(along.reshape(-1, 3) / 10.0).reshape(30, points)
    expected = np.stack([(looked_up == label).sum(axis=1) for label in range(3)], axis=1)
    counts = volume.counts_along(ends, first, second, points, 3, scale=10.0)
    assert counts.dtype == np.uint8
    assert np.array_equal(counts, expected)
    assert np.array_equal(pair_fractions(ends, None, None, first, second, 3, points, volume,
                                         10.0), expected)


def test_radiosity_renders_the_homogeneous_limit_as_the_homogeneous_material():
    scene = _small(load_scene("solid_checker"), rows=13, size=16)
    skin = measured_medium("Skin1")
    dipole = scene.with_material("sphere", Dipole(skin.sigma_a, skin.sigma_s_prime, eta=1.0))
    solid = scene.with_material("sphere", uniform_solid("Skin1", eta=1.0))
    first = radiosity.precompute(dipole).render()
    second = radiosity.precompute(solid).render()
    assert first.rgb.max() > 0 and np.allclose(first.rgb, second.rgb, rtol=1e-9)


def _assert_between_media(scene, image, names):
    """The image's total light per channel lies between those of its media alone."""
    lit = image.rgb.sum(axis=-1) > 0
    totals = []
    for name in names:
        medium = measured_medium(name)
        homogeneous = scene.with_material("sphere", Dipole(medium.sigma_a,
                                                           medium.sigma_s_prime, eta=1.0))
        totals.append(radiosity.precompute(homogeneous).render().rgb[lit].sum(axis=0))
    mixed = image.rgb[lit].sum(axis=0)
    low, high = np.min(totals, axis=0), np.max(totals, axis=0)
    assert np.all(mixed >= low * 0.999) and np.all(mixed <= high * 1.001)


def test_radiosity_renders_a_checker_between_its_two_media():
    scene = _small(load_scene("solid_checker"), rows=13, size=16)
    state = radiosity.precompute(scene)
    image = state.render()
    assert state.log.notes["solid medium"]["sphere"]["media"] == 2
    _assert_between_media(scene, image, ("Skin1", "Ketchup"))


def test_radiosity_renders_the_gradient_between_its_end_media_and_converges():
    scene = _small(load_scene("solid_gradient"), rows=13, size=16)
    state = radiosity.precompute(scene)
    image = state.render()
    assert state.log.notes["solid medium"]["sphere"]["media"] > 2
    assert state.convergence["max_scattering_column_sum"] < 1.0  # Eq. 15 holds
    _assert_between_media(scene, image, ("Skin1", "Ketchup"))


def test_the_veins_are_quantised_with_their_error_recorded():
    solid = veined_solid(resolution=16, eta=1.0)
    mesh = geometry_image(17, shape="sphere")
    texture = subedit_from_solid(solid, mesh, resolution=32, max_media=8)
    assert texture.media == 8 and 0 < texture.quantisation_error < 1
    fine = subedit_from_solid(solid, mesh, resolution=32, max_media=64)
    assert fine.quantisation_error < texture.quantisation_error
