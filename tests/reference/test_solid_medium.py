"""The volumetric truth of solid media: Mitsuba's gridvolume reads the material's own grid."""

import numpy as np
import pytest
from translucent.backend import mitsuba
from translucent.image import Image
from translucent.materials import Dipole, measured_medium
from translucent.materials.solid import checker_solid, uniform_solid, veined_solid
from translucent.reference.mitsuba_scene import ConversionContext
from translucent.reference.render import render
from translucent.reference.solid_medium import solid_medium_dict
from translucent.reports.metrics.statistics import z_test_known_variance
from translucent.scenes import load_scene
from translucent.scenes.scene import Camera


def _small(scene, size=16):
    camera = scene.camera
    return scene.with_camera(Camera(camera.origin, camera.target, camera.up, camera.fov,
                                    size, size))


def _volume_values(volume_dict, points):
    mi = mitsuba()
    volume = mi.load_dict(volume_dict)
    interaction = mi.Interaction3f()
    interaction.p = mi.Point3f(*np.asarray(points, dtype=np.float64).T)
    return np.array(volume.eval(interaction)).T


@pytest.mark.parametrize("make", [lambda: checker_solid(cells=5),
                                  lambda: veined_solid(resolution=12)])
def test_mitsuba_reads_the_same_voxel_as_the_material(make, rng):
    solid = make()
    scene = _small(load_scene("solid_checker"))
    medium = solid_medium_dict(solid, ConversionContext(scene, "sphere"))
    points = rng.uniform(-0.999, 0.999, (400, 3))
    sigma_t = _volume_values(medium["sigma_t"], points) * medium["scale"]
    albedo = _volume_values(medium["albedo"], points)
    sigma_a, sigma_s_prime = solid.coefficients_at(points)
    expected_t = (sigma_a + sigma_s_prime) * scene.mm_per_unit
    assert np.allclose(sigma_t, expected_t, rtol=1e-6)  # float32 grid
    assert np.allclose(albedo, sigma_s_prime / (sigma_a + sigma_s_prime), rtol=1e-6)


def test_a_per_channel_render_gives_every_channel_the_one_channel():
    solid = checker_solid()
    scene = _small(load_scene("solid_checker"))
    medium = solid_medium_dict(solid, ConversionContext(scene, "sphere", channel=2))
    values = _volume_values(medium["sigma_t"], [[0.1, 0.2, 0.3]]) * medium["scale"]
    sigma_a, sigma_s_prime = solid.coefficients_at([[0.1, 0.2, 0.3]])
    assert np.allclose(values, (sigma_a + sigma_s_prime)[0, 2] * scene.mm_per_unit, rtol=1e-6)


def test_the_homogeneous_limit_renders_as_the_homogeneous_medium():
    # a uniform field on a 3^3 grid against the Dipole of the same coefficients: the same
    # transport, sampled by delta tracking against a majorant equal to sigma_t
    scene = _small(load_scene("solid_checker"))
    skin = measured_medium("Skin1")
    homogeneous = scene.with_material("sphere", Dipole(skin.sigma_a, skin.sigma_s_prime,
                                                       eta=1.0, g=0.0))
    solid = scene.with_material("sphere", uniform_solid("Skin1", eta=1.0, resolution=3))
    first = render(homogeneous, spp=32, passes=4, seed=1, cache=False, progress=False)
    second = render(solid, spp=32, passes=4, seed=2, cache=False, progress=False)
    assert first.rgb.mean() > 0.01  # the sphere is lit
    result = z_test_known_variance(first, second)
    assert result.passed, result


def test_a_checker_is_not_its_homogeneous_limit():
    # the test above can fail: Skin1 everywhere is far from the Skin1 / Ketchup checker
    scene = _small(load_scene("solid_checker"))
    uniform = scene.with_material("sphere", uniform_solid("Skin1", eta=1.0))
    first = render(uniform, spp=32, passes=4, seed=1, cache=False, progress=False)
    second = render(scene, spp=32, passes=4, seed=2, cache=False, progress=False)
    assert not z_test_known_variance(first, second).passed


def test_a_dielectric_solid_boundary_blocks_delta_lights_as_a_dipole_does():
    from translucent.reference.mitsuba_scene import convert_scene

    scene = _small(load_scene("solid_checker"))
    dielectric = scene.with_material("sphere", checker_solid(eta=1.3))
    assert convert_scene(dielectric).integrator == "volpath_mnee"  # reaches the light
    conversion = convert_scene(dielectric, integrator="volpath")
    assert conversion.substitutions  # the point light became an emitter of finite size
    assert not any(k.startswith("light_0") and v.get("type") == "point"
                   for k, v in conversion.scene_dict.items() if isinstance(v, dict))
    matched = convert_scene(scene)
    assert not matched.substitutions
    assert matched.scene_dict["light_0"]["type"] == "point"


def test_the_image_header_states_the_field_and_its_grid():
    scene = _small(load_scene("solid_veins"), 8)
    image = render(scene, spp=4, passes=2, cache=False, progress=False)
    assert isinstance(image, Image) and np.isfinite(image.rgb).all()
    said = image.metadata["media"]["sphere"]
    assert "Ketchup veins in Skin2" in said and "64 x 64 x 64 voxels" in said
