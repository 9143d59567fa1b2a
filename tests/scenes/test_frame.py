"""The rendering frame: the same physics in other numbers (scenes/frame.py)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from translucent.materials import Lambertian, measured_medium
from translucent.materials.solid import checker_solid
from translucent.scenes import (
    Camera,
    ConstantEnvironment,
    DirectionalLight,
    PointLight,
    RectangularAreaLight,
    Scene,
    SceneObject,
    SphereAreaLight,
    SpotLight,
    load_scene,
)
from translucent.scenes.frame import FRAME_RADIUS, Frame, rendering_frame
from translucent.scenes.meshes import icosphere, plane


def _scene(radius=2.5, centre=(1.0, -2.0, 3.0)):
    sphere = icosphere(2, radius, center=centre)
    floor = plane(40.0, 40.0, center=(0.0, -10.0, 0.0))
    lights = [PointLight([0.0, 9.0, 0.0], [2.0, 3.0, 4.0]),
              SpotLight([1.0, 8.0, 1.0], [0.0, -1.0, 0.0], 5.0, cutoff_angle=30.0),
              RectangularAreaLight([0.0, 12.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0], 7.0),
              SphereAreaLight([5.0, 5.0, 5.0], 0.5, 3.0),
              DirectionalLight([0.0, -1.0, 0.0], 2.0), ConstantEnvironment(0.1)]
    camera = Camera(origin=[0.0, 0.0, 30.0], target=list(centre), fov=40.0, width=8, height=8)
    return Scene([SceneObject("floor", floor, Lambertian(0.5)),
                  SceneObject("ball", sphere, measured_medium("Skin1"))], lights, camera,
                 mm_per_unit=4.0)


def test_the_frame_centres_and_scales_the_translucent_objects_by_a_power_of_two():
    scene = _scene()
    frame = rendering_frame(scene)
    # centred on the ball, not on the floor that holds the scene's bounding box
    moved = frame.apply(scene).objects[1].mesh.vertices
    centre = 0.5 * (moved.min(axis=0) + moved.max(axis=0))
    radius = np.linalg.norm(moved - centre, axis=1).max()
    assert np.abs(centre).max() < 1e-9 * radius
    assert FRAME_RADIUS / 2 < radius <= FRAME_RADIUS
    assert math.log2(frame.scale) == round(math.log2(frame.scale))


def test_the_frame_keeps_what_light_does():
    scene = _scene()
    frame = Frame((1.0, -2.0, 3.0), 64.0)
    moved = frame.apply(scene)
    s = frame.scale
    assert moved.mm_per_unit == scene.mm_per_unit / s
    point, spot, rectangle, sphere, sun, environment = moved.lights
    old = scene.lights
    # a point light's irradiance I / d^2 at the ball's centre stays
    for new, before in ((point, old[0]), (spot, old[1])):
        d_new = np.linalg.norm(new.position - frame.point((1.0, -2.0, 3.0)))
        d_old = np.linalg.norm(before.position - np.array([1.0, -2.0, 3.0]))
        np.testing.assert_allclose(new.intensity / d_new**2, before.intensity / d_old**2)
    assert spot.cutoff_angle == old[1].cutoff_angle
    np.testing.assert_array_equal(spot.direction, old[1].direction)
    # area lights keep their radiance, their size scales
    assert rectangle.area == pytest.approx(old[2].area * s * s)
    np.testing.assert_array_equal(rectangle.radiance, old[2].radiance)
    assert sphere.radius == old[3].radius * s
    assert sun is old[4] and environment is old[5]
    # the camera sees the same: its direction and field of view stay
    np.testing.assert_allclose(moved.camera.forward, scene.camera.forward)
    assert moved.camera.fov == scene.camera.fov


def test_a_solid_medium_box_moves_with_the_frame():
    solid = checker_solid(bounds=((-1.0, -1.0, -1.0), (1.0, 1.0, 1.0)))
    scene = Scene([SceneObject("ball", icosphere(2, 1.0), solid)], [PointLight([0, 3, 0], 1.0)],
                  Camera(origin=[0, 0, 5], target=[0, 0, 0], width=4, height=4))
    frame = Frame((0.5, 0.0, 0.0), 4.0)
    moved = frame.apply(scene).objects[0].material
    np.testing.assert_array_equal(moved.bounds, [[-6.0, -4.0, -4.0], [2.0, 4.0, 4.0]])
    np.testing.assert_array_equal(moved.sigma_a, solid.sigma_a)


def test_an_unknown_light_is_a_type_error():
    class Laser:
        pass

    scene = load_scene("sphere")
    broken = Scene(scene.objects, [], scene.camera, scene.mm_per_unit)
    object.__setattr__(broken, "lights", (Laser(),))
    with pytest.raises(TypeError, match="Laser"):
        Frame((0.0, 0.0, 0.0), 2.0).apply(broken)


@settings(max_examples=50, deadline=None)
@given(st.lists(st.floats(-1e4, 1e4), min_size=3, max_size=3),
       st.floats(1e-6, 1e6), st.lists(st.floats(-1e4, 1e4), min_size=3, max_size=3))
def test_point_matrix_and_back_agree(origin, scale, point):
    frame = Frame(tuple(origin), scale)
    moved = frame.point(point)
    homogeneous = frame.matrix() @ np.append(point, 1.0)
    np.testing.assert_allclose(homogeneous[:3], moved, rtol=1e-9, atol=1e-9 * scale * 1e4)
    np.testing.assert_allclose(frame.to_scene(moved), point, rtol=1e-9, atol=1e-7)
