"""The long validation studies (slow tier): coverage of the 95 % intervals, the dipole's bias."""

import json

import numpy as np
import pytest
from translucent.errors import InputError
from translucent.fitting.validation import (
    COVERAGE_TARGET,
    bias_table_text,
    coverage_study,
    model_bias_table,
)
from translucent.materials import measured_medium_names


@pytest.mark.slow
def test_coverage_of_95_percent_intervals_on_exact_model_captures():
    result = coverage_study(20, seed=2026)
    assert result.converged.all()
    assert result.fraction >= COVERAGE_TARGET, (result.fraction, result.inside.mean(axis=0))


@pytest.mark.slow
def test_coverage_of_the_walk_model_on_random_walk_captures():
    # the walk's captures are made by a generator that shares no code with the fitter's
    # tabulated profile; 40 captures, 240 coefficients
    result = coverage_study(40, seed=7, generator="walk", photons=500_000)
    assert result.converged.all()
    assert result.fraction >= COVERAGE_TARGET, (result.fraction, result.inside.mean(axis=0))
    assert not result.misfit.any()


@pytest.mark.slow
def test_every_random_walk_capture_of_a_measured_medium_misfits_the_dipole():
    # the dipole is not transport: a walk capture fitted with it must say so, medium by medium
    rows = model_bias_table(photons=100_000, size=96, seed=7, forward="dipole")
    assert [row.material for row in rows] == measured_medium_names()
    unflagged = [row.material for row in rows if not row.misfit]
    assert not unflagged, unflagged


@pytest.mark.slow
def test_model_bias_table_of_the_measured_media(tmp_path):
    rows = model_bias_table(photons=20000, size=64, seed=7)
    assert [row.material for row in rows] == measured_medium_names()
    for row in rows:
        assert row.converged, row.material
        assert np.all(np.isfinite(row.fit_sigma_a)) and np.all(np.isfinite(row.fit_sigma_s_prime))
        # a coefficient the data constrain has a 68 % interval that brackets its median
        for (low, high), median in zip(row.fit_sigma_s_prime_68, row.fit_sigma_s_prime,
                                       strict=True):
            assert low <= median <= high
    text = bias_table_text(rows)
    assert text.count("\n") == len(rows) + 1
    (tmp_path / "bias.json").write_text(json.dumps([row.to_json() for row in rows]))



def test_bias_table_hands_pass_spp_0_on_instead_of_the_default(monkeypatch):
    # pass_spp = 0 became the default 1024 samples per pass; volpath_capture refuses it
    from translucent.fitting import volpath_capture

    given = []

    def render(material, **options):  # stands in for Mitsuba
        given.append(options["pass_spp"])
        raise InputError("stop", field="pass_spp", value=options["pass_spp"])

    monkeypatch.setattr(volpath_capture, "volpath_capture", render)
    with pytest.raises(InputError, match="stop"):
        model_bias_table(["skin1"], generator="volpath", size=16, spp=4, pass_spp=0)
    assert given == [0]


@pytest.mark.parametrize("known", [False, True])
def test_bias_table_writes_the_exposure_into_the_capture_only_when_asked(monkeypatch, known):
    # a Christensen-Burley fit is not identifiable with the exposure free: --known-exposure
    # must reach the capture the fitter reads, and the row must say which it was
    from translucent.fitting import validation

    seen = []

    def fit(capture, **options):
        seen.append(capture.spec.exposure)
        raise InputError("stop", field="fit", value=None)

    monkeypatch.setattr(validation, "fit_dipole", fit)
    with pytest.raises(InputError, match="stop"):
        model_bias_table(["skin1"], photons=2000, size=16, exposure_known=known)
    assert len(seen) == 1 and (seen[0] is not None) == known
