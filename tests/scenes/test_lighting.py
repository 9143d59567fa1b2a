"""The lighting service: light samples and the environment, checked against Mitsuba's emitters."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from translucent.backend import mitsuba
from translucent.errors import InputError
from translucent.scenes import (
    ConstantEnvironment,
    DirectionalLight,
    ImageEnvironment,
    PointLight,
    RectangularAreaLight,
    SphereAreaLight,
    SpotLight,
)
from translucent.scenes.lighting import (
    direct_irradiance,
    environment_radiance,
    light_samples,
    rectangle_light_points,
    stratified_cosine_directions,
)

#: Mitsuba evaluates in float32: a texel of radiance <= 1 agrees to a few float32 ulps.
FLOAT32_ATOL = 1e-5


def _mitsuba_radiance(image, directions):
    mi = mitsuba()
    emitter = mi.load_dict({"type": "envmap", "bitmap": mi.Bitmap(image.copy())})
    interaction = mi.SurfaceInteraction3f()
    towards = -np.asarray(directions, dtype=np.float32)  # wi points back along the ray
    interaction.wi = mi.Vector3f(towards[:, 0], towards[:, 1], towards[:, 2])
    values = np.asarray(emitter.eval(interaction))
    return values.T if values.shape[0] == 3 and values.shape != (3, 3) else values


def _directions(rng, count):
    directions = rng.normal(size=(count, 3))
    # the seams: next to the poles (on them u is undefined, and Mitsuba's float32 signs of
    # zero pick one), and u = 0 where the map wraps
    directions[:8] = [[1e-3, 1, 2e-3], [-2e-3, -1, 1e-3], [0, 0, -1], [1e-4, 0.3, -1],
                      [-1e-4, 0.3, -1], [0, 0, 1], [1, 0, 0], [-1, 0, 0]]
    return directions / np.linalg.norm(directions, axis=1)[:, None]


@pytest.mark.parametrize("shape", [(3, 1), (8, 16), (5, 7)])
def test_environment_lookup_is_mitsubas(rng, shape):
    image = np.ascontiguousarray(rng.random(shape + (3,)), dtype=np.float32)
    directions = _directions(rng, 4000)
    ours = environment_radiance(ImageEnvironment(image.copy()), directions)
    np.testing.assert_allclose(ours, _mitsuba_radiance(image, directions), atol=FLOAT32_ATOL)


def test_the_nearest_texel_is_not_mitsubas_lookup(rng):
    """The check can fail: the nearest-texel lookup radiosity once used is far off."""
    image = np.ascontiguousarray(rng.random((8, 16, 3)), dtype=np.float32)
    directions = _directions(rng, 4000)
    u = (np.arctan2(directions[:, 0], -directions[:, 2]) / (2 * np.pi)) % 1.0
    v = np.arccos(np.clip(directions[:, 1], -1, 1)) / np.pi
    nearest = image[np.clip((v * 8).astype(int), 0, 7), np.clip((u * 16).astype(int), 0, 15)]
    assert np.abs(nearest - _mitsuba_radiance(image, directions)).max() > 100 * FLOAT32_ATOL


@settings(max_examples=30, deadline=None)
@given(st.floats(0.0, 10.0), st.floats(-1.0, 1.0), st.floats(-np.pi, np.pi))
def test_a_uniform_map_gives_its_value_everywhere(value, height, azimuth):
    image = np.full((4, 8, 3), value, dtype=np.float32)
    side = np.sqrt(1.0 - height**2)
    direction = [[side * np.sin(azimuth), height, -side * np.cos(azimuth)]]
    np.testing.assert_allclose(environment_radiance(ImageEnvironment(image, 2.0), direction),
                               [[2.0 * np.float32(value)] * 3], rtol=1e-12, atol=1e-12)
    np.testing.assert_array_equal(
        environment_radiance(ConstantEnvironment([value, 1.0, 0.0]), direction),
        [[value, 1.0, 0.0]])


# -- light samples: one sampler for every method -----------------------------------------

RECEIVER = np.array([[0.05, 0.0, -0.1]])
NORMAL = np.array([[0.3, 1.0, 0.1]]) / np.linalg.norm([0.3, 1.0, 0.1])


def _unshadowed(rows, sample):
    return np.zeros(len(rows), dtype=bool)


def _service_irradiance(light, count=4096, seed=0):
    return direct_irradiance([light], RECEIVER, NORMAL, occluded=_unshadowed, count=count,
                             rng=np.random.default_rng(seed))[0]


def _mitsuba_irradiance(entry, samples=1 << 16, seed=1):
    """E at RECEIVER by Mitsuba's own emitter sampling: mean of radiance / pdf x cosine."""
    mi = mitsuba()
    scene = mi.load_dict({"type": "scene", "light": entry})
    import drjit as dr

    interaction = dr.zeros(mi.SurfaceInteraction3f, samples)
    interaction.p = mi.Point3f(*[np.full(samples, c, dtype=np.float32) for c in RECEIVER[0]])
    interaction.n = mi.Normal3f(*[np.full(samples, c, dtype=np.float32) for c in NORMAL[0]])
    sampler = np.random.default_rng(seed).random((2, samples)).astype(np.float32)
    ds, weight = scene.sample_emitter_direction(interaction, mi.Point2f(sampler[0], sampler[1]),
                                                test_visibility=False)
    direction = np.asarray(ds.d).reshape(3, -1)
    cosine = np.clip(NORMAL[0] @ direction, 0.0, None)
    values = np.asarray(weight).reshape(3, -1) * cosine
    return values.mean(axis=1), values.std(axis=1) / np.sqrt(samples)


def _mitsuba_rectangle(light):
    matrix = np.eye(4)
    matrix[:3, 0], matrix[:3, 1], matrix[:3, 2] = light.u_axis, light.v_axis, light.normal
    matrix[:3, 3] = light.center
    return _mitsuba_irradiance({
        "type": "rectangle", "to_world": mitsuba().ScalarTransform4f(matrix.tolist()),
        "emitter": {"type": "area", "radiance": {"type": "rgb",
                                                  "value": light.radiance.tolist()}}})


RECTANGLE = RectangularAreaLight([0.3, 1.0, 0.2], [0.4, 0.0, 0.0], [0.0, 0.0, 0.25],
                                 [2.0, 1.0, 0.5])


def test_rectangle_samples_give_mitsubas_irradiance():
    mean, error = _mitsuba_rectangle(RECTANGLE)
    np.testing.assert_array_less(np.abs(_service_irradiance(RECTANGLE) - mean),
                                 4 * error + 1e-6)


def test_the_irradiance_check_can_fail():
    """A rectangle 4 % wider than Mitsuba's is told apart; one facing away gives nothing."""
    mean, error = _mitsuba_rectangle(RECTANGLE)
    wider = RectangularAreaLight(RECTANGLE.center, 1.04 * RECTANGLE.u_axis, RECTANGLE.v_axis,
                                 RECTANGLE.radiance)
    assert np.all(np.abs(_service_irradiance(wider) - mean) > 4 * error)
    away = RectangularAreaLight(RECTANGLE.center, RECTANGLE.v_axis, RECTANGLE.u_axis, 1.0)
    assert not _service_irradiance(away).any()


def test_sphere_samples_give_mitsubas_irradiance():
    light = SphereAreaLight([0.5, 1.5, -0.2], 0.3, [1.0, 2.0, 3.0])
    mean, error = _mitsuba_irradiance({
        "type": "sphere", "center": [0.5, 1.5, -0.2], "radius": 0.3,
        "emitter": {"type": "area", "radiance": {"type": "rgb", "value": [1.0, 2.0, 3.0]}}})
    np.testing.assert_array_less(np.abs(_service_irradiance(light) - mean), 4 * error + 1e-6)


def test_a_sphere_above_the_horizon_gives_pi_l_sin2():
    """E = pi L (rho / d)^2 for a sphere wholly above the receiver's horizon (exact)."""
    light = SphereAreaLight(RECEIVER[0] + 2.0 * NORMAL[0], 0.5, 1.0)
    np.testing.assert_allclose(_service_irradiance(light, count=16384), np.pi * 0.25**2,
                               rtol=1e-3)


def test_a_constant_environment_gives_pi_l_whatever_the_samples():
    environment = ConstantEnvironment([0.5, 1.0, 2.0])
    for seed, count in [(0, 1), (3, 7), (9, 64)]:
        np.testing.assert_allclose(_service_irradiance(environment, count, seed),
                                   np.pi * np.array([0.5, 1.0, 2.0]), rtol=1e-12)


def test_delta_lights_are_exact():
    position = RECEIVER[0] + [0.0, 2.0, 0.0]
    np.testing.assert_allclose(_service_irradiance(PointLight(position, 4.0), count=1),
                               NORMAL[0, 1], rtol=1e-12)
    spot = SpotLight(position, [0.0, -1.0, 0.0], 4.0, cutoff_angle=30.0, beam_width=10.0)
    np.testing.assert_allclose(_service_irradiance(spot, count=1), NORMAL[0, 1], rtol=1e-12)
    tilted = SpotLight(position, [np.sin(np.radians(20)), -np.cos(np.radians(20)), 0.0], 4.0,
                       cutoff_angle=30.0, beam_width=10.0)
    np.testing.assert_allclose(_service_irradiance(tilted, count=1), 0.5 * NORMAL[0, 1],
                               rtol=1e-9)
    sun = DirectionalLight([0.0, -1.0, 0.0], [1.0, 2.0, 3.0])
    np.testing.assert_allclose(_service_irradiance(sun, count=1),
                               NORMAL[0, 1] * np.array([1.0, 2.0, 3.0]), rtol=1e-12)


def test_a_shadowed_sample_brings_nothing_and_is_asked_only_where_it_lights():
    asked = []

    def everything_blocks(rows, sample):
        asked.append(len(rows))
        return np.ones(len(rows), dtype=bool)

    points = np.array([[0.0, 0.0, 0.0], [0.0, 3.0, 0.0]])  # the second is above the light
    normals = np.array([[0.0, 1.0, 0.0], [0.0, 1.0, 0.0]])
    light = PointLight([0.0, 2.0, 0.0], 1.0)
    assert not direct_irradiance([light], points, normals, occluded=everything_blocks,
                                 rng=np.random.default_rng(0)).any()
    assert asked == [1]


def test_an_unknown_light_and_an_environment_without_normals_are_refused():
    with pytest.raises(InputError, match="unknown light type"):
        direct_irradiance([object()], RECEIVER, NORMAL, occluded=_unshadowed)
    with pytest.raises(InputError, match="normals"):
        list(light_samples(ConstantEnvironment(1.0), RECEIVER, rng=np.random.default_rng(0)))


@settings(max_examples=40, deadline=None)
@given(st.integers(1, 64), st.integers(0, 2**31))
def test_rectangle_points_are_stratified_on_the_rectangle(count, seed):
    light = RectangularAreaLight([1.0, 2.0, 3.0], [0.5, 0.0, 0.0], [0.0, 0.0, 0.2], 1.0)
    points = rectangle_light_points(light, count, np.random.default_rng(seed))
    local = (points - light.center) / [0.5, 1.0, 0.2]
    assert points.shape == (count, 3)
    assert np.all(np.abs(local[:, [0, 2]]) <= 1.0) and np.allclose(local[:, 1], 0.0)
    side = int(np.ceil(np.sqrt(count)))
    cells = (np.floor((local[:, 0] + 1) / 2 * side) + side * np.floor(
        (local[:, 2] + 1) / 2 * side)).astype(int)
    assert len(set(cells.tolist())) == count  # one point per cell


@settings(max_examples=40, deadline=None)
@given(st.integers(1, 32), st.integers(0, 2**31))
def test_cosine_directions_are_unit_and_above_the_surface(count, seed):
    normals = np.random.default_rng(seed).normal(size=(5, 3))
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    directions = stratified_cosine_directions(normals, count, np.random.default_rng(seed))
    np.testing.assert_allclose(np.linalg.norm(directions, axis=-1), 1.0, rtol=1e-12)
    assert np.all(np.einsum("nkd,nd->nk", directions, normals) >= -1e-12)
