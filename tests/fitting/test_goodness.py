"""Goodness of fit: runs test, posterior-predictive verdicts, the model-discrepancy term."""

import json

import numpy as np
import pytest
from translucent.fitting.capture import Capture, write_capture
from translucent.fitting.goodness import (
    RUNS_MIN_ANNULI,
    DiscrepancyModel,
    goodness_of_fit,
    runs_test,
)
from translucent.fitting.models import DipoleModel
from translucent.fitting.profile import measure_profile
from translucent.fitting.synthetic import (
    Camera,
    apply_camera,
    capture_spec,
    dipole_capture,
    exitance_image,
    material_profile_function,
)
from translucent.materials import Dipole
from translucent.reports.cli import main

SKIN = Dipole(sigma_a=[0.032, 0.17, 0.48], sigma_s_prime=[0.74, 0.88, 1.01], eta=1.3,
              name="Skin1")
QUICK_WALKERS = 16


def test_runs_test_counts_runs_and_flags_a_trend():
    alternating = np.tile([1.0, -1.0], 10)
    runs, expected, p = runs_test(alternating)
    assert runs == 20 and expected == pytest.approx(11.0) and p > 0.99
    trend = np.linspace(-1, 1, 30)  # one sign change: the signature of a wrong shape
    runs, _, p = runs_test(trend)
    assert runs == 2 and p < 1e-5
    assert runs_test(np.ones(30))[2] == 1.0  # one sign only: nothing to test
    assert runs_test(trend[: RUNS_MIN_ANNULI - 1])[2] == 1.0


def test_runs_test_is_calibrated_on_independent_signs(rng):
    p = np.array([runs_test(rng.standard_normal(40))[2] for _ in range(2000)])
    assert np.mean(p < 0.05) == pytest.approx(0.05, abs=0.02)


def _misfit_capture(size=40, pixel_size_mm=0.25, seed=11):
    """The dipole's profile bent by a radial ramp: a shape no dipole can take."""
    dipole = material_profile_function(SKIN)
    camera = Camera(peak_signal=40000)
    exitance = exitance_image(lambda r: dipole(r) * (1.0 + 0.6 * np.asarray(r)[..., None]),
                              (size, size), pixel_size_mm, (size / 2, size / 2))
    stored, exposure = apply_camera(exitance, camera, np.random.default_rng(seed))
    spec = capture_spec(SKIN, camera, image_name="capture.exr", pixel_size_mm=pixel_size_mm,
                         incident_px=(size / 2, size / 2), side="reflection",
                         thickness_mm=None, beam_radius_mm=0.0, exposure=exposure,
                         eta_known=True, generator="dipole times a ramp")
    return Capture(spec, stored)


def _good_capture():
    pixels, spec = dipole_capture(SKIN, size=40, pixel_size_mm=0.25, seed=11,
                                  camera=Camera(peak_signal=40000))
    return Capture(spec, pixels)


def test_the_discrepancy_likelihood_reduces_to_the_base_one_without_discrepancy():
    profile = measure_profile(_good_capture())
    base = DipoleModel(profile, _good_capture().spec)
    theta = base.initial_guess()
    extended = DiscrepancyModel(base, start=theta)
    no_discrepancy = np.concatenate([theta, np.full(len(base.channels), np.log(1e-12))])
    constant = -sum(np.sum(np.log(base.observations(c)[1])) for c in base.channels)
    assert extended.log_likelihood(no_discrepancy)[0] == pytest.approx(
        base.log_likelihood(theta)[0] + constant, rel=1e-9, abs=1e-6)
    assert extended.ndim == base.ndim + len(base.channels)
    assert extended.names[-1] == f"discrepancy[{'RGB'[base.channels[-1]]}]"
    # a large discrepancy makes every residual small: the tests then pass
    assert goodness_of_fit(base, theta[None, :], draws=200).channels


@pytest.mark.slow  # 23 s: two chains; the verdict's parts are tested in the fast tier above
def test_a_misspecified_capture_is_flagged_with_wider_intervals(tmp_path, capsys):
    """A capture no dipole can explain: the verdict, exit code 1, the wider intervals."""
    data = _misfit_capture()
    sidecar = tmp_path / "bent.json"
    write_capture(sidecar, data.pixels, data.spec)
    code = main(["fit", str(sidecar), "--walkers", "16", "--no-progress", "--seed", "2",
                 "--out", str(tmp_path / "fit")])
    out = capsys.readouterr().out
    assert code == 1
    assert "goodness of fit: model misfit" in out and "MODEL MISFIT" in out
    assert "with a fractional model-discrepancy term" in out
    summary = json.loads((tmp_path / "fit" / "dipole_summary.json").read_text())
    assert summary["verdict"] == "model misfit" and summary["converged"]
    channels = summary["goodness_of_fit"]["channels"]
    assert any(channel["misfit"] for channel in channels)
    # no model-conditional interval claims to constrain
    assert all(p["status"] in ("model misfit", "nuisance") for p in summary["parameters"])
    assert any("model misfit" in note for note in summary["notes"])
    narrow = {p["name"]: p for p in summary["parameters"]}
    wide = {p["name"]: p for p in summary["parameters_with_discrepancy"]}
    for name in ("sigma_a[G]", "sigma_s_prime[G]"):
        assert (np.log(wide[name]["high68"]) - np.log(wide[name]["low68"])
                > np.log(narrow[name]["high68"]) - np.log(narrow[name]["low68"])), name
    assert any(wide[f"discrepancy[{c}]"]["median"] > 0.01 for c in "RGB")
    assert summary["discrepancy_goodness_of_fit"]["channels"]


@pytest.mark.slow
def test_a_top_hat_beam_fits_as_a_top_hat_and_misfits_as_a_gaussian():
    import dataclasses

    from translucent.fitting.fit import fit_dipole

    pixels, spec = dipole_capture(SKIN, size=40, pixel_size_mm=0.25, seed=11,
                                  camera=Camera(peak_signal=40000), beam_radius_mm=1.0,
                                  beam_profile="top_hat")
    right = fit_dipole(Capture(spec, pixels), seed=1, walkers=QUICK_WALKERS)
    assert right.goodness.verdict == "fits", right.goodness.summary()
    for kind, values in (("sigma_a", SKIN.sigma_a), ("sigma_s_prime", SKIN.sigma_s_prime)):
        for c, truth in enumerate(values):
            summary = right.parameter(f"{kind}[{'RGB'[c]}]")
            assert summary.low95 <= truth <= summary.high95, summary.describe()
    wrong = dataclasses.replace(spec, beam_profile="gaussian")
    assert fit_dipole(Capture(wrong, pixels), seed=1, walkers=QUICK_WALKERS).misfit
