"""The emcee driver on a posterior whose answer is known: a correlated Gaussian."""

import numpy as np
import pytest
from translucent.errors import InputError
from translucent.fitting.fit import default_moves
from translucent.fitting.sampler import CONVERGENCE_TAUS, find_map, laplace_covariance, run_chain

#: Mean recovered within 5 Monte Carlo standard errors (sd / sqrt(independent samples)).
MEAN_SIGMAS = 5.0
#: Standard deviations recovered within 10 %: with >= 1000 independent samples the
#: sampling error of a standard deviation is ~2 %, so 10 % is 5 of those.
SD_TOLERANCE = 0.10


class GaussianPosterior:
    """A correlated 3-d Gaussian inside a wide box: the shape of a well-constrained fit."""

    def __init__(self):
        self.mean = np.array([1.0, -2.0, 0.5])
        sd = np.array([0.1, 0.5, 0.02])
        correlation = np.array([[1.0, 0.8, -0.3], [0.8, 1.0, 0.1], [-0.3, 0.1, 1.0]])
        self.covariance = correlation * np.outer(sd, sd)
        self.precision = np.linalg.inv(self.covariance)
        self.bounds = np.array([[-10.0, 10.0]] * 3)
        self.ndim = 3
        self.calls = 0
        self.evaluations = 0

    def initial_guess(self):
        return np.zeros(3)

    def log_probability(self, theta, *, bounded=True):
        theta = np.atleast_2d(theta)
        self.calls += 1
        self.evaluations += theta.shape[0]
        delta = theta - self.mean
        value = -0.5 * np.einsum("ni,ij,nj->n", delta, self.precision, delta)
        if bounded:
            inside = np.all((theta >= self.bounds[:, 0]) & (theta <= self.bounds[:, 1]), axis=1)
            value = np.where(inside, value, -np.inf)
        return value

    __call__ = log_probability


def test_map_and_laplace_covariance_are_exact_for_a_gaussian():
    posterior = GaussianPosterior()
    theta, _ = find_map(posterior)
    np.testing.assert_allclose(theta, posterior.mean, atol=1e-4)
    np.testing.assert_allclose(laplace_covariance(posterior, theta), posterior.covariance,
                               rtol=1e-4, atol=1e-10)


@pytest.mark.parametrize("moves", [None, "differential evolution"])
def test_chain_converges_and_recovers_mean_and_spread(moves):
    posterior = GaussianPosterior()
    result = run_chain(posterior, seed=4, max_steps=20000,
                       moves=default_moves() if moves else None)
    assert result.converged, result.message
    assert result.steps > CONVERGENCE_TAUS * result.tau.max()
    assert result.walkers >= 2 * posterior.ndim
    assert 0.1 < np.mean(result.acceptance_fraction) < 0.9
    independent = result.samples.shape[0]
    sd = np.sqrt(np.diag(posterior.covariance))
    assert np.all(np.abs(result.samples.mean(axis=0) - posterior.mean)
                  < MEAN_SIGMAS * sd / np.sqrt(independent))
    np.testing.assert_allclose(result.samples.std(axis=0), sd, rtol=SD_TOLERANCE)
    assert result.log_prob_calls > 0 and result.log_prob_evaluations >= result.log_prob_calls
    assert result.summary()["converged"] is True


def test_step_budget_says_not_converged_and_by_how_much():
    posterior = GaussianPosterior()
    result = run_chain(posterior, seed=1, max_steps=200, check_every=100)
    assert not result.converged
    assert "NOT converged" in result.message
    assert f"{result.steps} steps" in result.message
    assert "x more steps" in result.message or "still changed" in result.message


def test_too_few_walkers_and_budget_below_one_check():
    posterior = GaussianPosterior()
    with pytest.raises(InputError, match="must be at least 2 x ndim = 6"):
        run_chain(posterior, walkers=4)
    with pytest.raises(InputError, match="must be >= check_every"):
        run_chain(posterior, max_steps=10, check_every=100)


def test_non_finite_start_is_an_error():
    posterior = GaussianPosterior()
    with pytest.raises(InputError, match="not finite at the starting point"):
        find_map(posterior, start=np.full(3, np.nan))
