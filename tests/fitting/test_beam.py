"""The Gaussian beam and its convolution matrix: normalisation, symmetry, an analytic case."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy import integrate
from translucent.errors import InputError
from translucent.fitting.beam import (
    beam_convolution_kernel,
    beam_convolution_matrix,
    beam_irradiance,
)
from translucent.fitting.geometry import radial_grid

#: The convolution of a constant is the constant up to the quadrature's error (4-point
#: Gauss-Legendre on cells of sigma / 2: better than 1e-8); tested at 1e-6.
NORMALISATION = 1e-6
#: A Gaussian profile is linear between grid nodes only approximately: with the grid's
#: 4 % node ratio and a uniform spacing of s / 20 its interpolation errs by < 5e-4 of the
#: peak; the convolution matrix must add nothing beyond that.
GAUSSIAN_CASE = 5e-4


@given(w=st.floats(0.01, 5.0))
def test_beam_irradiance_integrates_to_one(w):
    total, _ = integrate.quad(lambda r: 2 * np.pi * r * beam_irradiance(r, w), 0, 10 * w)
    assert total == pytest.approx(1.0, rel=1e-8)


@given(rho=st.floats(0, 5), s=st.floats(0, 5), w=st.floats(0.05, 2))
def test_kernel_is_symmetric_and_finite(rho, s, w):
    forward = beam_convolution_kernel(rho, s, w)
    assert np.isfinite(forward) and forward >= 0
    assert forward == pytest.approx(beam_convolution_kernel(s, rho, w), rel=1e-12)


@settings(max_examples=20, deadline=None)
@given(w=st.floats(0.005, 1.0))
def test_convolving_a_constant_gives_the_constant(w):
    grid = radial_grid(10.0, 1e-3, 0.05)
    kernel = beam_convolution_matrix(grid, w)
    inner = grid.nodes < grid.r_max - 6 * w  # beyond, the profile is cut at the last node
    np.testing.assert_allclose((kernel @ np.ones(grid.size))[inner], 1.0, atol=NORMALISATION)


@settings(max_examples=10, deadline=None)
@given(w=st.floats(0.05, 1.5), s=st.floats(0.3, 1.5))
def test_gaussian_profile_convolves_to_the_analytic_gaussian(w, s):
    grid = radial_grid(12 * s + 6 * w, 1e-3, s / 20)
    profile = np.exp(-grid.nodes ** 2 / (2 * s * s))
    sigma2 = s * s + (w / 2) ** 2  # a Gaussian beam of 1/e^2 radius w has sigma = w / 2
    exact = s * s / sigma2 * np.exp(-grid.nodes ** 2 / (2 * sigma2))
    result = beam_convolution_matrix(grid, w) @ profile
    np.testing.assert_allclose(result, exact, atol=GAUSSIAN_CASE)


def test_zero_radius_is_identity_and_negative_is_an_error():
    grid = radial_grid(5.0, 1e-3)
    np.testing.assert_array_equal(beam_convolution_matrix(grid, 0.0), np.eye(grid.size))
    with pytest.raises(InputError, match="must be >= 0"):
        beam_convolution_matrix(grid, -1.0)
    with pytest.raises(InputError, match="must be >= 0"):
        beam_convolution_matrix(grid, np.nan)


# ------------------------------------------------------------------------ top-hat beam

#: The top-hat rows are integrated between the grid nodes and the kernel's kinks, the
#: intervals at a kink after a cosine map: a constant convolves to itself within 3e-5
#: (measured), the Gaussian case stays within the grid's own interpolation error.
TOP_HAT_NORMALISATION = 1e-4


@given(a=st.floats(0.01, 5.0))
def test_top_hat_irradiance_integrates_to_one(a):
    total, _ = integrate.quad(lambda r: 2 * np.pi * r * beam_irradiance(r, a, "top_hat"),
                              0, 2 * a, points=[a])
    assert total == pytest.approx(1.0, rel=1e-8)


@given(rho=st.floats(0, 5), s=st.floats(0, 5), a=st.floats(0.05, 2))
def test_top_hat_kernel_is_symmetric_finite_and_normalised(rho, s, a):
    forward = beam_convolution_kernel(rho, s, a, "top_hat")
    assert np.isfinite(forward) and forward >= 0
    assert forward == pytest.approx(beam_convolution_kernel(s, rho, a, "top_hat"), rel=1e-9,
                                    abs=1e-12)
    if abs(rho - s) > a:
        assert forward == 0.0


@settings(max_examples=8, deadline=None)
@given(a=st.floats(0.005, 1.0))
def test_top_hat_convolving_a_constant_gives_the_constant(a):
    grid = radial_grid(10.0, 1e-3, 0.05)
    kernel = beam_convolution_matrix(grid, a, "top_hat")
    inner = grid.nodes < grid.r_max - 2 * a
    np.testing.assert_allclose((kernel @ np.ones(grid.size))[inner], 1.0,
                               atol=TOP_HAT_NORMALISATION)


@settings(max_examples=6, deadline=None)
@given(a=st.floats(0.1, 1.5), s=st.floats(0.3, 1.5))
def test_top_hat_convolves_a_gaussian_as_the_direct_integral(a, s):
    from scipy.special import i0e

    grid = radial_grid(12 * s + 6 * a, 1e-3, s / 20)
    result = beam_convolution_matrix(grid, a, "top_hat") @ np.exp(-grid.nodes**2 / (2 * s * s))

    def direct(rho):  # (1 / pi a^2) over the disk, the angle integrated in closed form
        return 2 / a**2 * integrate.quad(
            lambda b: np.exp(-(rho - b) ** 2 / (2 * s * s)) * i0e(rho * b / (s * s)) * b,
            0, a, limit=200)[0]

    picks = np.arange(0, grid.size, 11)
    exact = np.array([direct(rho) for rho in grid.nodes[picks]])
    np.testing.assert_allclose(result[picks], exact, atol=GAUSSIAN_CASE)


def test_an_unknown_beam_profile_is_an_input_error():
    with pytest.raises(InputError, match="beam_profile"):
        beam_irradiance(0.0, 1.0, "square")
