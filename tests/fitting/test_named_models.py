"""``translucent fit --model NAME``: every radial profile of the literature as a fit model.

The reduced table a chain reads is checked against the profile objects themselves (which
share no code with the table's interpolation); a capture made from a profile evaluated
directly (not from its table) is fitted with that profile and covers its truth, and with
the classical dipole is biased (the profiles differ); bad names and captures a
semi-infinite table cannot predict are refused before anything is written.
"""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from translucent.errors import InputError
from translucent.fitting.capture import write_capture
from translucent.fitting.fit import MODELS, fit_capture, fit_dipole
from translucent.fitting.named_models import NAMED_MODELS
from translucent.fitting.synthetic import Camera, apply_camera, capture_spec, exitance_image
from translucent.materials import Dipole, measured_medium
from translucent.materials.profiles import profile
from translucent.materials.profiles.reduced_table import reduced_table
from translucent.reports.cli import main

#: The table reads a profile within this relative error where it holds more than 1e-3 of
#: its peak, over 0.02-3 reduced mean free paths (measured over 40 random media: at most
#: 0.07 %; the random walk's own table, itself interpolated, 0.24 %).
TABLE_TOLERANCE = 0.003


@settings(max_examples=30, deadline=None)
@given(st.sampled_from(NAMED_MODELS + ("random_walk",)),
       st.floats(-3.0, 0.5), st.floats(-0.5, 1.0))
def test_the_reduced_table_reads_each_profile_as_the_profile_itself(name, ln_a, ln_s):
    sigma_a, sigma_s = 10.0 ** ln_a, 10.0 ** ln_s
    medium = Dipole([sigma_a] * 3, [sigma_s] * 3, eta=1.3)
    sigma_t = sigma_a + sigma_s
    r = np.geomspace(0.02, 3.0, 12) / sigma_t
    exact = profile(name, medium).reflection(r)[:, 0]
    tabled = sigma_t ** 2 * reduced_table(name, (1.3,)).reduced_profile(
        sigma_t * r, sigma_s / sigma_t, 1.3)
    resolved = exact > 1e-3 * exact.max()
    np.testing.assert_allclose(tabled[resolved], exact[resolved], rtol=TABLE_TOLERANCE)
    within = 2.0 / sigma_t
    np.testing.assert_allclose(
        reduced_table(name, (1.3,)).reduced_cumulative(sigma_t * within, sigma_s / sigma_t, 1.3),
        profile(name, medium).total(max_radius=within)[0], rtol=TABLE_TOLERANCE)


def test_fit_offers_every_radial_profile_by_name_and_the_command_line_the_same(capsys):
    from translucent.fast.knobs import radial_profile_names

    radial = {name for name in radial_profile_names() if not name.endswith("_average")}
    assert set(MODELS) == (radial - {"random_walk"}) | {"walk", "subedit"}
    # the command line offers the same names (it lists them without importing the fitter)
    assert main(["fit", "--help"]) == 0
    shown = " ".join(capsys.readouterr().out.split())
    for name in NAMED_MODELS:
        assert name in shown, name


def _profile_capture(name, material, *, size=40, seed=3):
    """A capture of profile ``name`` evaluated directly (no table), exposure known.

    Known, because a Christensen-Burley profile is one shape per channel (its scale d) times
    an amplitude A(albedo): with the exposure free, every channel's albedo can trade
    against it along a ridge of equally good fits (7 unknowns, 6 constraints).
    """
    camera = Camera(peak_signal=40000, exposure_known=True)
    made = profile(name, material)
    pixel = 8.0 / size / float(np.min(material.sigma_tr))
    centre = (size / 2.0, size / 2.0)
    exitance = exitance_image(made.reflection, (size, size), pixel, centre)
    stored, exposure = apply_camera(exitance, camera, np.random.default_rng(seed))
    spec = capture_spec(material, camera, image_name="c.exr", pixel_size_mm=pixel,
                        incident_px=centre, side="reflection", thickness_mm=None,
                        beam_radius_mm=0.0, exposure=exposure, eta_known=True,
                        generator=name)
    return stored, spec


@pytest.mark.slow  # two fits, 18 s
@pytest.mark.parametrize("name", ["burley_dmfp", "better_dipole"])
def test_a_capture_of_a_profile_fitted_with_it_covers_its_truth(name, tmp_path):
    material = measured_medium("Skin1")
    stored, spec = _profile_capture(name, material)
    sidecar = write_capture(tmp_path / "c.json", stored, spec)
    result = fit_dipole(sidecar, forward=name, seed=1, walkers=16)
    assert result.kind == name and result.converged and not result.misfit
    truth = np.concatenate([material.sigma_a, material.sigma_s_prime])
    names = [f"{k}[{c}]" for k in ("sigma_a", "sigma_s_prime") for c in "RGB"]
    inside = [result.parameter(n).low95 <= t <= result.parameter(n).high95
              for n, t in zip(names, truth, strict=True)]
    assert sum(inside) >= 5, list(zip(names, truth, inside, strict=True))
    assert any(f"profile {name!r}" in note for note in result.notes)
    # the classical dipole's coefficients for the same capture are another medium's
    dipole = fit_dipole(sidecar, seed=1, walkers=16)
    shift = [abs(np.log(dipole.parameter(n).median / result.parameter(n).median))
             for n in names]
    assert max(shift) > 0.05


@pytest.mark.parametrize("spec_change, field", [({"side": "transmission", "thickness_mm": 4.0},
                                                 "side"), ({"thickness_mm": 4.0},
                                                           "thickness_mm")])
def test_a_capture_a_half_space_table_cannot_predict_is_refused_before_writing(
        tmp_path, spec_change, field):
    import dataclasses

    stored, spec = _profile_capture("better_dipole", measured_medium("Skin1"), size=24)
    sidecar = write_capture(tmp_path / "c.json", stored, dataclasses.replace(spec,
                                                                              **spec_change))
    with pytest.raises(InputError, match="better_dipole model tabulates") as error:
        fit_capture(sidecar, models=("better_dipole",), out_dir=tmp_path / "fit")
    assert error.value.field == field
    assert not (tmp_path / "fit").exists()


def test_an_unknown_or_directional_model_exits_2_naming_the_field(tmp_path, capsys):
    stored, spec = _profile_capture("better_dipole", measured_medium("Skin1"), size=24)
    sidecar = write_capture(tmp_path / "c.json", stored, spec)
    for name in ("no_such_profile", "directional_dipole"):
        assert main(["fit", str(sidecar), "--model", name, "--no-progress"]) == 2
        assert "--model" in capsys.readouterr().err + capsys.readouterr().out
    with pytest.raises(InputError, match="unknown model"):
        fit_capture(sidecar, models=("directional_dipole",))
