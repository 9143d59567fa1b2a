"""The spot light's angular profile (Mitsuba's ``spot``), shared by every fast method."""

import numpy as np
import pytest
from translucent.scenes import SpotLight


def _direction_at(angle_degrees: float) -> np.ndarray:
    angle = np.radians(angle_degrees)
    return np.array([np.sin(angle), 0.0, np.cos(angle)])


@pytest.mark.parametrize("angle, expected", [
    (0.0, 1.0),      # on the axis
    (10.0, 1.0),     # at the beam width, still full
    (15.0, 0.5),     # half-way through the linear fall-off band
    (20.0, 0.0),     # at the cutoff
    (60.0, 0.0),     # outside the cone
    (180.0, 0.0),    # behind the light
])
def test_spot_falloff_is_flat_then_linear_in_angle(angle, expected):
    light = SpotLight(position=[0, 0, 0], direction=[0, 0, 1], intensity=1.0,
                      cutoff_angle=20.0, beam_width=10.0)
    assert light.falloff(_direction_at(angle)) == pytest.approx(expected, abs=1e-12)


def test_spot_falloff_takes_batches_and_a_hard_edge():
    light = SpotLight(position=[0, 0, 0], direction=[0, 0, 1], intensity=1.0,
                      cutoff_angle=5.0, beam_width=5.0)
    directions = np.stack([_direction_at(a) for a in (0.0, 4.9, 5.1)])
    assert light.falloff(directions).tolist() == [1.0, 1.0, 0.0]


@pytest.mark.parametrize("scale", [-1.0, float("nan")])
def test_image_environment_scale_must_be_a_nonnegative_number(scale):
    from translucent.errors import InputError
    from translucent.scenes import ImageEnvironment

    with pytest.raises(InputError, match=r"scale = (-1\.0|nan): must be"):
        ImageEnvironment(np.ones((4, 8, 3)), scale=scale)


def test_image_environment_needs_three_rows():
    from translucent.errors import InputError
    from translucent.scenes import ImageEnvironment

    with pytest.raises(InputError, match=r"radiance = \(1, 4, 3\): must have at least 3 rows"):
        ImageEnvironment(np.ones((1, 4, 3)))
    with pytest.raises(InputError, match="at least 3 rows"):
        ImageEnvironment(np.ones((2, 4, 3)))  # Mitsuba interpolates two rows otherwise
    assert ImageEnvironment(np.ones((3, 1, 3))).radiance.shape == (3, 1, 3)
