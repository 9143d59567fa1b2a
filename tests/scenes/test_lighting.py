"""The lighting service: the environment looked up exactly as Mitsuba's emitter evaluates it."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from translucent.backend import mitsuba
from translucent.scenes import ConstantEnvironment, ImageEnvironment
from translucent.scenes.lighting import environment_radiance

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
