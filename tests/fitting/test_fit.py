"""Fits of synthetic captures: recovery, robustness to real defects, honesty, outputs, CLI."""

import json

import numpy as np
import pytest
import tomllib
from translucent.errors import InputError
from translucent.fitting.capture import Capture, CaptureSpec, read_capture, write_capture
from translucent.fitting.fit import fit_capture, fit_dipole, fit_subedit, write_outputs
from translucent.fitting.synthetic import Camera, apply_camera, dipole_capture, exitance_image
from translucent.materials import Dipole
from translucent.materials.factory import material_from_dict
from translucent.materials.subedit import SubEditProfiles
from translucent.reports.cli import main

#: A recovered parameter lies within this many posterior standard deviations (half the
#: 68 % interval) of the truth: 4 keeps the chance of a false failure per parameter
#: below 1e-4 for a well-calibrated posterior.
RECOVERY_SIGMAS = 4.0
#: Walkers for the quick fits (2 x ndim = 14 rounds up to 16): fewer evaluations per step.
QUICK_WALKERS = 16

SKIN = Dipole(sigma_a=[0.032, 0.17, 0.48], sigma_s_prime=[0.74, 0.88, 1.01], eta=1.3,
              name="Skin1")


def assert_recovered(result, material, *, sigmas=RECOVERY_SIGMAS):
    assert result.converged, result.chains[0].message
    for kind, values in (("sigma_a", material.sigma_a),
                         ("sigma_s_prime", material.sigma_s_prime)):
        for c, truth in enumerate(values):
            summary = result.parameter(f"{kind}[{'RGB'[c]}]")
            sd = 0.5 * (np.log(summary.high68) - np.log(summary.low68))
            assert abs(np.log(summary.median) - np.log(truth)) < sigmas * sd, summary.describe()


def capture(material=SKIN, **options):
    options.setdefault("size", 40)
    options.setdefault("pixel_size_mm", 0.25)
    options.setdefault("seed", 11)
    pixels, spec = dipole_capture(material, **options)
    return Capture(spec, pixels)


@pytest.mark.slow  # 9 s; the fast tier keeps the other recoveries (defects, finite slab, eta)
def test_recovers_dipole_parameters_with_unknown_exposure():
    result = fit_dipole(capture(camera=Camera(peak_signal=40000)), seed=1, walkers=QUICK_WALKERS)
    assert_recovered(result, SKIN)
    assert all(s.status in ("constrained", "nuisance") for s in result.parameters)
    # a capture of the model itself: the goodness-of-fit tests accept it
    assert result.goodness.verdict == "fits", result.goodness.summary()
    assert not result.misfit and result.discrepancy is None
    for channel in result.goodness.channels:
        assert 0.5 < channel.reduced_chi_square < 1.6
        assert channel.predictive_p > result.goodness.threshold
    chain = result.chains[0]
    assert chain.steps > 50 * chain.tau.max()
    assert chain.burn_in == min(int(2 * chain.tau.max()), chain.steps // 2)
    assert chain.thin == max(1, int(0.5 * chain.tau.min()))


@pytest.mark.slow
@pytest.mark.parametrize("case", ["saturated centre", "heavy noise", "offset incident point",
                                  "known exposure", "beam", "srgb png"])
def test_robust_to_capture_defects(case, tmp_path):
    options = {"camera": Camera(peak_signal=40000)}
    if case == "saturated centre":
        options["camera"] = Camera(peak_signal=400000)  # centre clipped 6x over
    elif case == "heavy noise":
        options["camera"] = Camera(peak_signal=3000, read_noise=40, gain=0.05)
    elif case == "known exposure":
        options["camera"] = Camera(peak_signal=40000, exposure_known=True)
    elif case == "beam":
        options["beam_radius_mm"] = 0.6
    elif case == "srgb png":
        options["camera"] = Camera(peak_signal=40000, encoding="srgb", file_format="png")
        options["image_name"] = "capture.png"
    data = capture(**options)
    if case == "offset incident point":
        x, y = data.spec.incident_px
        data = Capture(type(data.spec)(**{**data.spec.__dict__, "incident_px": (x + 3.4, y - 2.7)}),
                       data.pixels)
    if case == "srgb png":
        data = read_capture(write_capture(tmp_path / "capture.json", data.pixels, data.spec))
    result = fit_dipole(data, seed=2, walkers=QUICK_WALKERS)
    assert_recovered(result, SKIN)
    if case == "saturated centre":
        assert result.profile.dropped["saturated"][0] > 0
        assert result.profile.masked["saturated"][0] > 0
    if case == "offset incident point":
        centre = np.array(result.profile.centre_px)
        assert np.hypot(*(centre - np.array(data.spec.synthetic["incident_px"]))) < 0.05
        assert any("incident point moved" in note for note in result.profile.notes)


@pytest.mark.slow
@pytest.mark.parametrize("side", ["transmission", "reflection"])
def test_recovers_a_finite_slab(side):
    material = Dipole(sigma_a=[0.02, 0.05, 0.1], sigma_s_prime=[1.0, 1.5, 2.0], eta=1.4)
    data = capture(material, side=side, thickness_mm=4.0, camera=Camera(peak_signal=40000))
    assert_recovered(fit_dipole(data, seed=3, walkers=QUICK_WALKERS), material)


@pytest.mark.slow
def test_recovers_eta_when_unknown():
    data = capture(camera=Camera(peak_signal=40000), eta_known=False)
    result = fit_dipole(data, seed=4)
    assert_recovered(result, SKIN)
    eta = result.parameter("eta")
    assert eta.low95 < SKIN.eta < eta.high95


@pytest.mark.slow
def test_a_dark_channel_is_reported_as_unconstrained():
    # blue: opaque within a fraction of a pixel, so every blue annulus is at the noise floor
    material = Dipole(sigma_a=[0.03, 0.1, 8.0], sigma_s_prime=[1.0, 1.0, 0.05], eta=1.3)
    result = fit_dipole(capture(material, camera=Camera(peak_signal=40000)), seed=5)
    assert result.converged
    for name in ("sigma_a[B]", "sigma_s_prime[B]"):
        summary = result.parameter(name)
        assert summary.status == "unconstrained", summary.describe()
        assert summary.width_ratio > 0.8  # the prior's own spread is 1
    assert any("channel B has no usable annulus" in note for note in result.notes)
    assert result.parameter("sigma_a[R]").status == "constrained"


@pytest.mark.slow
def test_subedit_fit_recovers_a_subedit_profile():
    # an exact-model capture for SubEdit: the exitance IS a piecewise-linear ln P profile
    knots = np.array([[0.0, -1.2, -2.2, -3.1, -3.9, -4.6, -5.2],
                      [0.3, -1.0, -2.1, -3.1, -4.0, -4.8, -5.5],
                      [0.6, -0.9, -2.2, -3.4, -4.5, -5.5, -6.4]]).T
    truth = SubEditProfiles(knots[None, None], r_s=6.0)
    image = exitance_image(truth.profile, (40, 40), 0.2, (20.0, 20.0))
    stored, exposure = apply_camera(image, Camera(peak_signal=40000, exposure_known=True),
                                    np.random.default_rng(8))
    spec = CaptureSpec(image="c.exr", pixel_size_mm=0.2, incident_px=(20.0, 20.0),
                       black_level=256.0, saturation_level=65535.0, exposure=exposure)
    result = fit_subedit(Capture(spec, stored), segments=6, r_s_mm=6.0, seed=6)
    assert result.converged, [chain.message for chain in result.chains]
    for c in range(3):
        for k in range(6):  # the last knot sits at r_s, where P is cut to 0
            summary = result.parameter(f"ln_p{k}[{'RGB'[c]}]")
            sd = 0.5 * (summary.high68 - summary.low68)
            assert abs(summary.median - knots[k, c]) < RECOVERY_SIGMAS * sd + 1e-3, \
                summary.describe()


def test_outputs_and_material_file_load_in_scenes(tmp_path):
    data = capture(camera=Camera(peak_signal=40000))
    result = fit_dipole(data, seed=1, walkers=QUICK_WALKERS, max_steps=400)
    paths = write_outputs(result, tmp_path)
    for path in paths.values():
        assert path.is_file() and path.stat().st_size > 0
    table = tomllib.loads(paths["material"].read_text())
    material = material_from_dict(table, file=paths["material"])
    np.testing.assert_allclose(material.sigma_a, result.material["sigma_a"])
    summary = json.loads(paths["summary"].read_text())
    assert summary["chains"][0]["tau"] and "acceptance_fraction_mean" in summary["chains"][0]
    assert summary["converged"] is False and "NOT converged" in summary["notes"][0]
    assert {p["name"] for p in summary["parameters"]} >= {"sigma_a[R]", "exposure"}


def test_subedit_outputs_load_as_a_subedit_material(tmp_path):
    data = capture(camera=Camera(peak_signal=40000, exposure_known=True))
    write_capture(tmp_path / "c.json", data.pixels, data.spec)
    results = fit_capture(tmp_path / "c.json", models=("subedit",), out_dir=tmp_path / "fit",
                          seed=1, segments=4, max_steps=400, walkers=12)
    path = tmp_path / "fit" / "subedit_material.toml"
    table = tomllib.loads(path.read_text())
    material = material_from_dict(table, file=path)
    knots = np.array(results["subedit"].material["log_profile"])
    np.testing.assert_allclose(material.log_profile[0, 0].T, knots, rtol=1e-6)


def test_command_line_bad_input_exits_2(tmp_path, capsys):
    (tmp_path / "bad.json").write_text(json.dumps({"image": "x.exr"}))
    assert main(["fit", str(tmp_path / "bad.json")]) == 2
    assert "required key is missing" in capsys.readouterr().err
    assert main(["capture", "unobtainium", "--generator", "dipole"]) == 2
    assert "unknown measured material" in capsys.readouterr().err


def test_an_output_folder_that_cannot_be_made_is_refused_before_fitting(tmp_path, capsys):
    data = capture(size=24)
    sidecar = write_capture(tmp_path / "c.json", data.pixels, data.spec)
    (tmp_path / "taken").write_text("a file, not a folder")
    code = main(["fit", str(sidecar), "--out", str(tmp_path / "taken"), "--walkers", "16",
                 "--max-steps", "200", "--no-progress"])
    captured = capsys.readouterr()
    assert code == 2 and "out_dir" in captured.err and "taken" in captured.err
    assert "converged" not in captured.out  # refused before the chain ran


@pytest.mark.parametrize("model", ["dipole", "subedit"])
def test_a_negative_seed_is_an_input_error(tmp_path, capsys, model):
    data = capture(size=24)
    sidecar = write_capture(tmp_path / "c.json", data.pixels, data.spec)
    code = main(["fit", str(sidecar), "--model", model, "--seed", "-1", "--walkers", "16",
                 "--max-steps", "200", "--no-progress", "--out", str(tmp_path / "fit")])
    assert code == 2 and "seed = -1: must be an integer >= 0" in capsys.readouterr().err
    assert not (tmp_path / "fit").exists()


def test_fit_capture_refuses_an_option_it_does_not_take(tmp_path):
    data = capture(size=24)
    sidecar = write_capture(tmp_path / "c.json", data.pixels, data.spec)
    with pytest.raises(InputError, match="unknown option; valid: r_min_mm, fit_eta") as error:
        fit_capture(sidecar, walker=16, max_steps=200)  # "walker" for "walkers"
    assert error.value.field == "walker"


@pytest.fixture
def no_plots(monkeypatch):
    """Skip the corner and profile plots (slow to draw) in ``write_outputs``."""
    from translucent.fitting import plots

    monkeypatch.setattr(plots, "corner_plot", lambda *args, **kwargs: None)
    monkeypatch.setattr(plots, "profile_plot", lambda *args, **kwargs: None)


def test_subedit_material_file_names_its_texture_relative_to_itself(tmp_path, no_plots):
    # docs/capture-format.md: file = "subedit_profile.npz"; the folder can then be moved
    data = capture(size=24, camera=Camera(peak_signal=40000, exposure_known=True))
    result = fit_subedit(data, segments=2, walkers=6, max_steps=200, seed=1)
    write_outputs(result, tmp_path / "fit")
    (tmp_path / "fit").rename(tmp_path / "moved")
    path = tmp_path / "moved" / "subedit_material.toml"
    table = tomllib.loads(path.read_text())
    assert table["file"] == "subedit_profile.npz"
    material_from_dict(table, file=path)


def test_the_material_file_carries_the_fit_notes(tmp_path, no_plots):
    # docs/capture-format.md: with several modes the material file takes the heaviest
    # mode's medians "and says so"; it said only "Values are posterior medians"
    result = fit_dipole(capture(size=24), seed=1, walkers=QUICK_WALKERS, max_steps=200)
    note = ("the material file holds the medians of the heaviest mode (60% of the samples), "
            "not of the whole posterior")
    result.notes.append(note)
    text = write_outputs(result, tmp_path)["material"].read_text()
    assert any(line.startswith("#") and note in line for line in text.splitlines())


def test_command_line_prints_the_fit_notes(tmp_path, capsys, monkeypatch):
    from types import SimpleNamespace

    from translucent.fitting import fit

    chain = SimpleNamespace(message="converged: 400 steps", acceptance_fraction=np.ones(2))
    profile = SimpleNamespace(notes=["incident point moved"], summary=lambda: {
        "centre_px": [1.0, 2.0], "used_annuli": [9, 9, 0], "dropped_annuli": {},
        "masked_pixels": {"saturated": [0] * 3, "below_black": [0] * 3, "nan": [0] * 3}})
    result = SimpleNamespace(
        profile=profile, converged=True, seconds=1.0, log_prob_calls=10, chains=[chain],
        parameters=[], notes=["channel B has no usable annulus: its parameters are the "
                              "prior's", chain.message], goodness=None, discrepancy=None,
        misfit=False)
    monkeypatch.setattr(fit, "fit_capture", lambda *args, **kwargs: {"dipole": result})
    assert main(["fit", str(tmp_path / "c.json"), "--no-progress"]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert "  note: channel B has no usable annulus: its parameters are the prior's" in lines
    assert "  note: incident point moved" in lines
    assert not any(line.startswith("  note: converged") for line in lines)  # said once


@pytest.fixture(scope="module")
def short_fit():
    """A short dipole fit of a small capture (not converged; its outputs are what count)."""
    return fit_dipole(capture(size=24), seed=1, walkers=QUICK_WALKERS, max_steps=200)


@pytest.mark.parametrize("synthetic", [{"sigma_a": [0.1, 0.2, 0.3]},
                                       {"sigma_a": "unknown", "sigma_s_prime": 1},
                                       {"sigma_a": [1, 2], "sigma_s_prime": [1, 2],
                                        "eta": 1.3, "exposure": 1.0}])
def test_a_synthetic_object_of_any_shape_does_not_stop_the_outputs(tmp_path, no_plots,
                                                                    short_fit, synthetic):
    # docs/capture-format.md: "synthetic" is any JSON object, never read by the fitter
    from dataclasses import replace

    data = short_fit.capture
    result = replace(short_fit, capture=Capture(replace(data.spec, synthetic=synthetic),
                                                data.pixels))
    assert result.truths() is None
    assert write_outputs(result, tmp_path)["material"].is_file()


def test_a_capture_refused_by_the_profile_leaves_no_output_folder(tmp_path):
    data = capture(size=24)
    sidecar = write_capture(tmp_path / "c.json", data.pixels, data.spec)
    with pytest.raises(InputError, match="no channel has 4 usable annuli"):
        fit_capture(sidecar, out_dir=tmp_path / "fit", r_min_mm=1000.0)
    assert not (tmp_path / "fit").exists()


@pytest.mark.parametrize("option", [["--segments", "0"], ["--smoothness", "-1"]])
def test_bad_subedit_options_stop_both_fits_before_any_output(tmp_path, capsys, option):
    sidecar = tmp_path / "skin.json"
    assert main(["capture", "skin1", "--generator", "dipole", "--size", "32", "--seed", "1",
                 "--out", str(sidecar), "--pixel-size", "0.3"]) == 0
    out = tmp_path / "fit"
    assert main(["fit", str(sidecar), "--model", "both", "--no-progress", "--out", str(out),
                 *option]) == 2
    assert not out.exists()
    assert option[0].lstrip("-") in capsys.readouterr().err
