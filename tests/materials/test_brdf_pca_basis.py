"""The PCA linearisation of Sect. 4 of Nguyen et al. 2010: algebra, accuracy, bad input."""

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from translucent.errors import InputError
from translucent.materials.brdf_pca import (
    DEFAULT_DELTA_SAMPLES,
    DEFAULT_GAMMA_SAMPLES,
    build_pca_basis,
    pca_analysis,
)
from translucent.materials.brdfs import GAMMA_RANGES, MODELS

#: Orthonormality, projections and exact reconstructions are float64 linear algebra on
#: values up to ~50 sr^-1: residuals are rounding, below 1e-10 of the largest value.
LINEAR_ALGEBRA_ATOL = 1e-10

#: The edited terms are smooth in gamma, so the RMS error between grid values of gamma
#: exceeds the one at grid values by no more than the slow variation of the error along
#: gamma (measured: at most 1.3 % larger, for every model at K = 6, k' = 200 and 1000).
GENERALISATION_RTOL = 0.05

#: Interpolating at delta = arccos(cos(midpoint)) moves the point by the rounding of
#: arccos near delta = 0 (~1e-13 rad, 1e-10 of a grid step): 1e-7 of the largest value
#: bounds what that does to the interpolated value.
ARCCOS_ROUNDING_RTOL = 1e-7

SMALL = dict(gamma_samples=40, delta_samples=256)


@pytest.mark.parametrize("model", MODELS)
def test_basis_is_orthonormal_and_projection_inverts_it(model):
    basis = build_pca_basis(model, 6, **SMALL)
    gram = basis.components @ basis.components.T
    np.testing.assert_allclose(gram, np.eye(6), atol=LINEAR_ALGEBRA_ATOL)
    # Eq. 15: H B' = I, so the coefficients of a basis combination are recovered exactly
    np.testing.assert_allclose(basis.projection @ basis.components.T, np.eye(6),
                               atol=LINEAR_ALGEBRA_ATOL)


@pytest.mark.parametrize("model", MODELS)
def test_mean_is_b0_and_full_rank_is_exact(model):
    """Eq. 13: b_0 is the mean sample; with K = k' - 1 the training samples are exact."""
    k_prime = 12
    basis = build_pca_basis(model, k_prime - 1, gamma_samples=k_prime, delta_samples=256)
    gammas = np.linspace(*GAMMA_RANGES[model], k_prime)
    samples = basis.samples(gammas)
    np.testing.assert_allclose(basis.mean, samples.mean(axis=0), atol=LINEAR_ALGEBRA_ATOL)
    scale = samples.max()
    for gamma, exact in zip(gammas, samples, strict=True):
        np.testing.assert_allclose(basis.reconstruct(gamma), exact,
                                   atol=LINEAR_ALGEBRA_ATOL * scale)


@pytest.mark.parametrize("model", ["blinn_phong", "ward", "lafortune"])
def test_training_error_is_the_discarded_spectrum(model):
    """Eckart-Young: the squared error over the training samples is sum_{j>K} s_j^2."""
    gammas = np.linspace(*GAMMA_RANGES[model], SMALL["gamma_samples"])
    for k in (1, 3, 6, 10):
        basis = build_pca_basis(model, k, **SMALL)
        squared = np.sum(basis.rms_error(gammas) ** 2) * len(basis.delta)
        discarded = np.sum(basis.singular_values[k:] ** 2)
        assert squared == pytest.approx(discarded, rel=1e-8, abs=LINEAR_ALGEBRA_ATOL)


def _check_generalisation(model, gamma_samples, delta_samples):
    low, high = GAMMA_RANGES[model]
    grid = np.linspace(low, high, gamma_samples)
    between = 0.5 * (grid[1:] + grid[:-1])
    previous = np.inf
    for k in (2, 4, 6):
        basis = build_pca_basis(model, k, gamma_samples=gamma_samples,
                                delta_samples=delta_samples)
        on_grid = math.sqrt(np.mean(basis.rms_error(grid) ** 2))
        off_grid = math.sqrt(np.mean(basis.rms_error(between) ** 2))
        if k == 6:
            assert off_grid <= on_grid * (1 + GENERALISATION_RTOL)
        assert on_grid < previous
        previous = on_grid


@pytest.mark.parametrize("model", MODELS)
def test_error_decreases_with_k_and_generalises_between_grid_gammas(model):
    _check_generalisation(model, 200, 256)


@pytest.mark.slow
@pytest.mark.parametrize("model", MODELS)
def test_generalisation_at_the_default_sampling(model):
    _check_generalisation(model, DEFAULT_GAMMA_SAMPLES, DEFAULT_DELTA_SAMPLES)


@pytest.mark.parametrize("model", MODELS)
def test_basis_values_interpolate_the_grid(model, rng):
    basis = build_pca_basis(model, 24, gamma_samples=200, delta_samples=512)
    # at grid nodes: the rows of B exactly
    variable = np.cos(basis.delta) if model != "lafortune" else basis.delta
    np.testing.assert_allclose(basis.basis_values(variable[5:9]), basis.basis_matrix()[5:9],
                               atol=LINEAR_ALGEBRA_ATOL * 100)
    # between nodes: linear interpolation of the linearised term on the grid
    gamma = rng.uniform(*GAMMA_RANGES[model])
    on_grid = basis.reconstruct(gamma)
    midpoints = 0.5 * (basis.delta[1:] + basis.delta[:-1])
    mid_variable = np.cos(midpoints) if model != "lafortune" else midpoints
    approx = basis.basis_values(mid_variable) @ basis.coefficients(gamma)
    np.testing.assert_allclose(approx, 0.5 * (on_grid[1:] + on_grid[:-1]),
                               atol=ARCCOS_ROUNDING_RTOL * np.abs(on_grid).max())


def test_lafortune_basis_is_zero_outside_the_lobe():
    basis = build_pca_basis("La", 6, **SMALL)
    values = basis.basis_values(np.array([-0.5, 0.0, 0.5]))
    np.testing.assert_array_equal(values[:2], 0.0)
    assert np.any(values[2] != 0)
    assert basis.basis_values(np.zeros((2, 3))).shape == (2, 3, 7)


@pytest.mark.parametrize("model", MODELS)
@settings(max_examples=25, deadline=None)
@given(unit=st.floats(0, 1))
def test_coefficients_finite_over_the_range(model, unit):
    low, high = GAMMA_RANGES[model]
    basis = build_pca_basis(model, 6)
    c = basis.coefficients(low + unit * (high - low))
    assert c.shape == (7,) and c[0] == 1.0 and np.all(np.isfinite(c))


def test_gamma_outside_the_range_is_rejected():
    basis = build_pca_basis("BP", 6, **SMALL)
    for bad in (2.9, 300.5, float("nan")):
        with pytest.raises(InputError, match=r"gamma = .*must be"):
            basis.coefficients(bad)
    narrow = build_pca_basis("BP", 6, gamma_range=(10, 100), **SMALL)
    with pytest.raises(InputError, match=r"gamma = 200: must be in the basis' range \[10, 100\]"):
        narrow.coefficients(200)


def test_bad_construction_arguments():
    with pytest.raises(InputError, match=r"n_basis = 0: must be an integer in \[1, 64\]"):
        build_pca_basis("BP", 0)
    with pytest.raises(InputError, match=r"gamma_samples = 5: must be an integer in \[7, "):
        build_pca_basis("BP", 6, gamma_samples=5)
    with pytest.raises(InputError, match=r"delta_samples = 8: must be an integer in \[16, "):
        build_pca_basis("BP", 6, delta_samples=8)
    with pytest.raises(InputError, match=r"gamma_range = \(1, 50\): must be a sub-interval of "
                                         r"\[3, 300\] for the blinn_phong model"):
        build_pca_basis("BP", 6, gamma_range=(1, 50))
    with pytest.raises(InputError, match="unknown BRDF model"):
        build_pca_basis("phong2", 6)


def test_fig5_analysis_is_consistent():
    """Panel (a) at K = 6 and panel (c) are the same errors; panel (a) decreases with K."""
    analysis = pca_analysis("BP", max_basis=8, test_gammas=101, **SMALL)
    assert np.all(np.diff(analysis.rms_mean) < 0)
    six = list(analysis.basis_sizes).index(6)
    assert analysis.rms_max[six] == pytest.approx(analysis.rms_along_gamma.max())
    assert analysis.first_basis.shape == (7, SMALL["delta_samples"])
    summary = analysis.to_dict()
    assert summary["model"] == "blinn_phong" and len(summary["rms_max"]) == 8
