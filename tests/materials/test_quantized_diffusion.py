"""Quantized diffusion: the Gaussians against the continuous extended source they quantize."""

import numpy as np
import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st
from translucent.materials import Dipole, measured_medium
from translucent.materials.profiles import QuantizedDiffusionProfile, profile
from translucent.materials.profiles.better_dipole import grosjean_diffusion
from translucent.materials.profiles.boundary import boundary_factor, exitance_weights

#: The quantization (mid-interval Gaussians of a convex time integral, steps of 1.2):
#: measured at most 0.28 % short of the continuous limit over alpha' in [0.05, 1] and eta
#: in [1, 1.6] (a 20 x 7 grid).
QUANTIZATION_RTOL = 0.005

#: The per-channel lookup against the Gaussian sum: linear interpolation on nodes 0.68 %
#: apart, measured at most 3.3e-4 inside the radius holding 99.9 % of the energy (largest
#: in the exponential tail there, 1e-5 near the beam).
LOOKUP_RTOL = 5e-4


def _continuous_total(medium):
    """The extended source's exitance, integrated in time and depth in closed form.

    A source at depth z with its image at -(z + d_e) gives C_E (e^{-s z} + e^{-s (z + d_e)})/2
    + C_phi (e^{-s z} - e^{-s (z + d_e)}) / (2 D s); the beam's sources
    alpha' sigma_t' e^{-sigma_t' z} and the albedo factor integrate it to the formula below.
    """
    sigma_a, sigma_s = medium.sigma_a[0], medium.sigma_s_prime[0]
    sigma_t = sigma_a + sigma_s
    albedo = sigma_s / sigma_t
    d = grosjean_diffusion(sigma_a, sigma_s)
    s = np.sqrt(sigma_a / d)
    c_phi, c_e = exitance_weights(medium.eta)
    image = 4 * boundary_factor(medium.eta) * d
    fluence = c_phi * (-np.expm1(-s * image)) / (2 * d * s) if s > 0 else c_phi * image / (2 * d)
    return albedo**2 * sigma_t / (sigma_t + s) * (c_e / 2 * (1 + np.exp(-s * image)) + fluence)


@given(albedo=st.floats(min_value=0.05, max_value=1.0), eta=st.floats(min_value=1.0,
                                                                        max_value=1.6))
@settings(max_examples=40, deadline=None)
@example(albedo=1.0 - 1e-16, eta=1.0)  # sigma_a ~ 1e-16: the interval integrals cancelled
@example(albedo=1.0 - 1e-14, eta=1.0)
def test_the_sum_approaches_the_continuous_extended_source(albedo, eta):
    medium = Dipole(1.0 - albedo, albedo, eta=eta)
    made = QuantizedDiffusionProfile(medium)
    expected = _continuous_total(medium)
    assert made.total()[0] <= expected * (1 + 1e-9)
    assert made.total()[0] == pytest.approx(expected, rel=QUANTIZATION_RTOL)


def test_each_gaussian_integrates_to_its_weight():
    made = profile("quantized_diffusion", "Skin1")
    assert np.all(made.weights >= 0) and np.all(made.variances > 0)
    assert made.total() == pytest.approx(made.weights.sum(axis=-1), rel=1e-15)
    assert np.all(np.diff(made.variances, axis=1) > 0)


def test_the_lookup_reads_the_sum():
    made = profile("quantized_diffusion", "Marble")
    inside = made.radius_containing(0.999)
    for channel in range(3):
        r = np.geomspace(1e-5, 1.0, 500) * inside[channel]
        assert made.reflection(r)[:, channel] == pytest.approx(
            made.reflection_sum(r)[:, channel], rel=LOOKUP_RTOL)


def test_it_scales_with_the_extinction():
    medium = measured_medium("Ketchup")
    made = QuantizedDiffusionProfile(medium)
    double = QuantizedDiffusionProfile(Dipole(2 * medium.sigma_a, 2 * medium.sigma_s_prime,
                                              eta=medium.eta))
    r = np.array([0.01, 0.1, 1.0])
    assert double.reflection_sum(r / 2) == pytest.approx(4 * made.reflection_sum(r), rel=1e-10)
    assert double.total() == pytest.approx(made.total(), rel=1e-12)
