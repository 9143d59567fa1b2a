"""Translucent radiosity on surfaces: a flat sheet's columns and thin (open) sheets."""

import numpy as np
import pytest
from translucent.errors import InputError
from translucent.fast import radiosity
from translucent.fast.radiosity import precompute, scattering_geometry, scattering_matrix
from translucent.fast.radiosity.form_factors import build_patches
from translucent.materials import Lambertian, measured_medium
from translucent.materials.profiles import TwoExponentialProfile
from translucent.scenes import Camera, PointLight, Scene, SceneObject, plane

#: The default sampling of the scattering factors (m^2 samples falling with distance,
#: centroid only beyond 8 patch radii) under-integrates a convex profile: 0.6 % measured on
#: a flat sheet of 4 mm cells; 1.5 % leaves room for the exit-at-centroid approximation
#: of Eq. 8.
SHEET_ENERGY_RTOL = 0.015

#: Two float64 evaluations of the same image weights, summed in another order.
RECOMPUTED_RTOL = 1e-9

CAMERA = Camera([0.0, 1.0, 4.0], [0.0, 0.5, 0.0], width=16, height=16)


def test_a_flat_sheet_returns_the_profile_total_from_its_middle():
    profile = TwoExponentialProfile(0.02, 1.0, 0.004, 0.3)
    max_d = 30.0
    scene = Scene([SceneObject("sheet", plane(64.0, 64.0, subdivisions=16), profile)], [],
                  CAMERA)
    patches = build_patches(scene)
    geometry = scattering_geometry(scene, patches, [0], max_distance_mm=max_d,
                                   knobs=dict(radiosity.DEFAULT_KNOBS))
    S = scattering_matrix(geometry, scene, patches)
    middle = np.argmin(np.linalg.norm(patches.centroid, axis=1))
    sums = S.power_column_sums(patches.area)[middle]
    assert sums == pytest.approx(profile.total(max_radius=max_d), rel=SHEET_ENERGY_RTOL)
    # reciprocity A_j S_ji = A_i S_ij up to the exit-at-centroid approximation
    power = S.channel(0).multiply(patches.area[:, None]).tocsr()
    assert abs(power - power.T).max() <= 0.02 * power.max()


def _sheet_scene(material):
    sheet = plane(6.0, 6.0, (0.0, 1.0, 0.0), subdivisions=8, name="sheet")
    floor = plane(10.0, 10.0, subdivisions=4, name="floor")
    return Scene([SceneObject("sheet", sheet, material),
                  SceneObject("floor", floor, Lambertian(0.5))],
                 (PointLight([0.0, 4.0, 0.0], 50.0),), CAMERA, mm_per_unit=10.0)


def test_thin_sheet_reflects_on_its_side_and_transmits_across():
    from translucent.materials.profiles import SlabProfile

    skin = measured_medium("Skin1")
    state = precompute(_sheet_scene(skin), sheet_thickness_mm=3.0, rays_per_patch=32)
    assert state.log.notes["thin sheets"] == ["sheet"]
    patches = state.patches
    front = patches.of_object(0)
    front = front[~patches.is_back[front]]
    middle = front[np.argmin(np.linalg.norm(patches.centroid[front] - [0.0, 1.0, 0.0], axis=1))]
    column = state.S.channel(0)[:, [middle]].toarray().ravel() * patches.area / \
        patches.area[middle]
    slab = SlabProfile(skin, 3.0)
    max_d = state.knobs["max_distance_mm"]
    assert column[~patches.is_back].sum() == pytest.approx(
        slab.total(max_radius=max_d)[0], rel=SHEET_ENERGY_RTOL)
    assert column[patches.is_back].sum() == pytest.approx(
        slab.total("transmission", max_radius=max_d)[0], rel=SHEET_ENERGY_RTOL)
    # lit from above only: the back face glows by transmission alone
    irradiance = state.patch_irradiance()
    assert np.all(irradiance[patches.twin[middle]] == 0)
    B, _ = state.solve(irradiance)
    assert np.all(B[patches.twin[middle]] > 0)


def test_dipole_on_a_sheet_needs_a_thickness():
    with pytest.raises(InputError, match="'sheet' is a thin \\(open\\) sheet.*sheet_thickness_mm"):
        precompute(_sheet_scene(measured_medium("Skin1")), rays_per_patch=16)
    # a profile with its own transmission needs none
    petal = TwoExponentialProfile(0.02, 1.0, transmission=(0.01, 1.0, 0.0, 1.0))
    state = precompute(_sheet_scene(petal), rays_per_patch=16, max_distance_mm=15.0)
    assert state.convergence["max_scattering_column_sum"] < 1


@pytest.mark.parametrize("eye", [(0.0, 3.0, 4.0), (0.0, 0.4, 5.0)])
def test_image_weights_of_a_sheet_show_the_face_towards_the_camera(eye):
    scene = _sheet_scene(measured_medium("Skin1"))
    assert scene.objects[0].mesh.normals[:, 1].min() > 0
    target = (0.0, 1.0, 0.0) if eye[1] > 1.0 else (0.0, 0.9, 0.0)
    scene = Scene(scene.objects, scene.lights, Camera(eye, target, width=16, height=16),
                  mm_per_unit=scene.mm_per_unit)
    state = precompute(scene, sheet_thickness_mm=3.0, rays_per_patch=32)
    operators = state._image_operators(state._scene_with_materials())
    gb = state._gbuffer()
    B = np.random.default_rng(7).uniform(0.0, 1.0, size=(len(state.patches), 3))
    mesh = scene.objects[0].mesh
    front = gb.interpolate(0, state.patches.vertex_values(0, mesh, B))
    back = gb.interpolate(0, state.patches.vertex_values(0, mesh, B, back=True))
    behind = np.einsum("hwd,hwd->hw", gb.geometric_normal, gb.view_direction) < 0
    pixels = operators["translucent"]
    expected = np.where(behind[..., None], back, front).reshape(-1, 3)[pixels]
    assert len(pixels) > 10
    got = operators["translucent_weights"] @ B
    assert np.abs(got - expected).max() <= RECOMPUTED_RTOL * np.abs(expected).max()
    # from above the camera sees the front face (normal up), from below the back face
    assert set(behind.reshape(-1)[pixels]) == {eye[1] < 1.0}
