import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from translucent.materials import fresnel_reflectance, fresnel_transmittance


def test_normal_incidence():
    eta = 1.5
    assert fresnel_reflectance(eta, 1.0) == pytest.approx(((eta - 1) / (eta + 1)) ** 2)


def test_grazing_incidence_reflects_all():
    assert fresnel_reflectance(1.3, 0.0) == pytest.approx(1.0)


def test_index_matched_transmits_all():
    cos = np.linspace(0.01, 1, 50)
    assert np.allclose(fresnel_transmittance(1.0, cos), 1.0)


def test_total_internal_reflection():
    # from inside glass (eta = 1/1.5) beyond the critical angle (sin > 1/1.5)
    assert fresnel_reflectance(1 / 1.5, np.cos(np.radians(60))) == 1.0


def test_brewster_angle_p_polarisation_vanishes():
    eta = 1.5
    theta = np.arctan(eta)
    cos_i = np.cos(theta)
    cos_t = np.sqrt(1 - np.sin(theta) ** 2 / eta**2)
    r_s = ((cos_i - eta * cos_t) / (cos_i + eta * cos_t)) ** 2
    assert fresnel_reflectance(eta, cos_i) == pytest.approx(0.5 * r_s, rel=1e-9)


@settings(max_examples=200, deadline=None)
@given(eta=st.floats(0.2, 3.0), cos=st.floats(0.0, 1.0),
       dtype=st.sampled_from([np.float32, np.float64]))
def test_in_unit_interval(eta, cos, dtype):
    value = fresnel_transmittance(dtype(eta), dtype(cos))
    assert np.isfinite(value) and 0.0 <= value <= 1.0


def test_nan_input_does_not_crash():
    value = fresnel_transmittance(1.3, np.array([np.nan, 0.5]))
    assert value.shape == (2,)


@settings(max_examples=300, deadline=None)
@given(st.floats(0.05, 4.0), st.floats(-0.5, 1.5, allow_nan=False))
def test_the_scalar_transmittance_is_the_array_one_bit_for_bit(eta, cosine):
    """Compiled kernels take the scalar function: it must be the same physics, to the bit."""
    from translucent.materials.fresnel import fresnel_transmittance_scalar

    assert fresnel_transmittance_scalar(eta, cosine) == float(fresnel_transmittance(eta, cosine))


def test_the_scalar_transmittance_at_its_limits():
    from translucent.materials.fresnel import fresnel_transmittance_scalar

    assert fresnel_transmittance_scalar(1.0, 1.0) == 1.0  # index-matched: all through
    assert fresnel_transmittance_scalar(1.3, 0.0) == 0.0  # grazing: all reflected
    assert fresnel_transmittance_scalar(0.7, 0.1) == 0.0  # total internal reflection
