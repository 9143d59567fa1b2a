"""Splatting's lights beyond the paper's: a spot is its point light with the spot's fall-off."""

import math

import numpy as np
import pytest
from translucent.fast import splatting
from translucent.scenes import Camera, PointLight, SpotLight, load_scene
from translucent.scenes.scene_file import CATALOGUE_DIR

#: As tests/fast/test_splatting.py: the hierarchical splat against the exact gather.
SPLAT_TOLERANCE = 0.06
POSITION = np.array([-3.0, 3.0, 4.0])
INTENSITY = 100.0


@pytest.fixture(scope="module")
def state():
    scene = load_scene(CATALOGUE_DIR / "heterogeneous.toml")
    scene = scene.with_camera(Camera(scene.camera.origin, scene.camera.target, scene.camera.up,
                                     scene.camera.fov, 32, 24))
    return splatting.precompute(scene, irradiance_resolution=32)


def _spot(axis, cutoff, width):
    return SpotLight(position=POSITION, direction=axis / np.linalg.norm(axis),
                     intensity=INTENSITY, cutoff_angle=cutoff, beam_width=width)


def test_a_spot_whose_beam_holds_the_object_is_its_point_light(state):
    # the unit sphere seen from 5.8 units subtends 10 degrees: a 30-degree beam holds it
    point = state.render(lights=[PointLight(POSITION, INTENSITY)]).rgb
    spot = state.render(lights=[_spot(-POSITION, 40.0, 30.0)]).rgb
    assert point.sum() > 0
    np.testing.assert_array_equal(spot, point)


def test_a_spot_turned_away_lights_nothing(state):
    assert splatting.applies_to(state.scene.with_lights([_spot(POSITION, 20.0, 15.0)])) is None
    image = state.render(lights=[_spot(POSITION, 20.0, 15.0)])
    assert np.all(image.rgb == 0)


def test_a_spot_on_part_of_the_object_matches_its_gather_and_lights_less(state):
    # aimed 6 degrees off the centre with a 6-degree cone: part of the sphere is lit
    axis = -POSITION / np.linalg.norm(POSITION)
    side = np.cross(axis, [0.0, 1.0, 0.0])
    side /= np.linalg.norm(side)
    turned = math.cos(math.radians(6)) * axis + math.sin(math.radians(6)) * side
    spot = _spot(turned, 6.0, 3.0)
    point = state.render(lights=[PointLight(POSITION, INTENSITY)]).rgb
    image = state.render(lights=[spot]).rgb
    truth = state.render_ground_truth(lights=[spot]).rgb
    assert 0.05 * point.sum() < image.sum() < 0.9 * point.sum()
    assert float(np.abs(image - truth).sum() / truth.sum()) < SPLAT_TOLERANCE


def test_a_sphere_light_is_its_intensity_at_its_centre_in_one_point(state):
    from translucent.scenes import SphereAreaLight

    radius, radiance = 0.2, 40.0
    sphere = SphereAreaLight(POSITION, radius, radiance)
    point = PointLight(POSITION, radiance * math.pi * radius ** 2)
    one = state.render(lights=[sphere], material=None)
    # area_light_points is a knob of the state: a state with one point per area light
    single = splatting.precompute(state.scene, irradiance_resolution=32, area_light_points=1)
    np.testing.assert_allclose(single.render(lights=[sphere]).rgb,
                               single.render(lights=[point]).rgb, rtol=1e-6, atol=0)
    # several points share that intensity: the lit side's light is the same up to the
    # penumbrae they make
    assert one.rgb.sum() == pytest.approx(single.render(lights=[point]).rgb.sum(), rel=0.05)


def test_a_rectangle_light_is_its_lambertian_patches():
    from translucent.fast.splatting.emitters import point_emitters
    from translucent.scenes import RectangularAreaLight

    light = RectangularAreaLight(center=[0, 2.0, 0], u_axis=[0.25, 0, 0], v_axis=[0, 0, 0.25],
                                 radiance=[17.0, 12.0, 4.0])
    for count in (1, 4, 9, 16):
        emitters = point_emitters(light, count, towards=[0, 0, 0])
        assert len(emitters) == count
        # the patches share the rectangle's area: total power L A pi, one-sided
        total = sum(e.intensity for e in emitters)
        np.testing.assert_allclose(total, np.array([17.0, 12.0, 4.0]) * light.area)
        points = np.array([e.position for e in emitters])
        assert np.all(np.abs(points - light.center) <= [0.25, 0.0, 0.25])
        down, up = np.array([[0.0, -1.0, 0.0]]), np.array([[0.0, 1.0, 0.0]])
        assert emitters[0].falloff(down)[0] == pytest.approx(1.0)  # it faces down
        assert emitters[0].falloff(up)[0] == 0.0
