"""Posterior models: vectorisation, priors, and agreement with the materials they stand for."""

import numpy as np
import pytest
from translucent.errors import InputError
from translucent.fitting.models import (
    SIGMA_A_RANGE,
    DipoleModel,
    SubEditModel,
    student_t_log_likelihood,
)
from translucent.materials.subedit import SubEditProfiles


def truth_theta(model, material, exposure):
    theta = list(np.log(material.sigma_a)) + list(np.log(material.sigma_s_prime))
    if model.fit_eta:
        theta.append(material.eta)
    if model.fit_exposure:
        theta.append(np.log(exposure))
    return np.array(theta)


def test_log_probability_is_vectorised_and_row_wise_identical(small_capture, rng):
    capture, profile, material = small_capture
    model = DipoleModel(profile, capture.spec)
    theta = truth_theta(model, material, capture.spec.synthetic["exposure"])
    batch = theta + 0.01 * rng.standard_normal((7, model.ndim))
    together = model(batch)
    assert together.shape == (7,)
    np.testing.assert_allclose(together, [model(row)[0] for row in batch], rtol=1e-12)


def test_truth_beats_perturbed_parameters(small_capture):
    capture, profile, material = small_capture
    model = DipoleModel(profile, capture.spec)
    theta = truth_theta(model, material, capture.spec.synthetic["exposure"])
    worse = theta.copy()
    worse[0] += 0.5  # sigma_a[R] x 1.65
    assert model(theta)[0] > model(worse)[0]


def test_outside_prior_and_non_finite_give_minus_infinity(small_capture):
    capture, profile, material = small_capture
    model = DipoleModel(profile, capture.spec, fit_eta=True)
    assert [p.name for p in model.parameters][-2:] == ["eta", "exposure"]
    theta = truth_theta(model, material, capture.spec.synthetic["exposure"])
    below = theta.copy()
    below[0] = np.log(SIGMA_A_RANGE[0]) - 1.0
    nan = theta.copy()
    nan[3] = np.nan
    inf = theta.copy()
    inf[-1] = np.inf
    values = model(np.array([theta, below, nan, inf]))
    assert np.isfinite(values[0])
    assert np.all(values[1:] == -np.inf)


def test_starting_points_and_map_land_near_the_truth(small_capture):
    from translucent.fitting.sampler import find_map

    capture, profile, material = small_capture
    model = DipoleModel(profile, capture.spec)
    truth = np.log(np.concatenate([material.sigma_a, material.sigma_s_prime]))
    # a grid cell is 6 decades / 31 = 0.45 in ln sigma_a; the polished start is closer
    assert any(np.all(np.abs(guess[:6] - truth) < 1.0) for guess in model.initial_guesses())
    theta, _ = find_map(model)
    assert np.all(np.abs(theta[:6] - truth) < 0.05)


def test_student_t_likelihood_limits():
    residual = np.array([0.0, 1.0, 3.0])
    stderr = np.ones(3)
    dof = np.full(3, 1e8)
    # huge dof: the Gaussian -t^2 / 2
    assert student_t_log_likelihood(residual, stderr, dof) == pytest.approx(-5.0, rel=1e-6)
    heavy = student_t_log_likelihood(residual, stderr, np.full(3, 4.0))
    assert heavy > -5.0  # heavier tails punish the outlier less


def test_subedit_profile_matches_materials_subedit(small_capture, rng):
    capture, profile, _ = small_capture
    model = SubEditModel(profile, capture.spec, segments=6)
    knots = rng.normal(0, 2, size=(4, model.ndim))
    nodes = profile.operator.grid.nodes
    ours = model.profile_nodes(knots)
    for walker in range(4):
        table = knots[walker].reshape(3, 7).T[None, None]
        reference = SubEditProfiles(table, model.r_s_mm).profile(nodes)
        np.testing.assert_allclose(ours[walker], reference, rtol=1e-12, atol=1e-300)


def test_subedit_smoothness_prior_prefers_straight_lines(small_capture):
    capture, profile, _ = small_capture
    model = SubEditModel(profile, capture.spec, segments=4, channels=(0,))
    straight = np.array([[5.0, 4.0, 3.0, 2.0, 1.0]])
    kinked = np.array([[5.0, 4.0, 5.0, 2.0, 1.0]])
    assert model.extra_log_prior(straight)[0] == 0.0
    assert model.extra_log_prior(kinked)[0] < 0.0


def test_subedit_bad_options(small_capture):
    capture, profile, _ = small_capture
    with pytest.raises(InputError, match=r"must be in \[2, 1024\]"):
        SubEditModel(profile, capture.spec, segments=1)
    with pytest.raises(InputError, match="must be > 0"):
        SubEditModel(profile, capture.spec, smoothness=0.0)
    with pytest.raises(InputError, match="must be > 0"):
        SubEditModel(profile, capture.spec, r_s_mm=-1.0)


def test_an_unknown_eta_cannot_be_left_unfitted(small_capture):
    from dataclasses import replace

    capture, profile, _ = small_capture
    spec = replace(capture.spec, eta=None)
    # it silently assumed eta = 1.3 and wrote it into the material as if measured
    with pytest.raises(InputError, match="eta is unknown") as error:
        DipoleModel(profile, spec, fit_eta=False)
    assert error.value.field == "fit_eta"
    assert DipoleModel(profile, spec).fit_eta


@pytest.mark.parametrize("option", ["r_s_mm", "smoothness"])
def test_an_infinite_subedit_option_is_called_not_finite(small_capture, option):
    capture, profile, _ = small_capture
    with pytest.raises(InputError, match="must be > 0 and finite") as error:
        SubEditModel(profile, capture.spec, **{option: float("inf")})
    assert error.value.field == option
