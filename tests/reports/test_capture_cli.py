"""``translucent capture``: bad arguments are input errors, found before the generator runs."""

import pytest
from translucent.reports.cli import main


@pytest.mark.parametrize("photons", ["nan", "inf"])
def test_a_non_finite_photon_count_is_an_input_error(tmp_path, capsys, photons):
    code = main(["capture", "skin1", "--size", "16", "--photons", photons,
                 "--out", str(tmp_path / "c.json")])
    assert code == 2
    assert f"--photons = {float(photons)!r}" in capsys.readouterr().err
    assert not (tmp_path / "c.json").exists()


@pytest.fixture
def generators_run(monkeypatch):
    """Fail if a generator runs (it must not, on a bad --out)."""
    from translucent.fitting import random_walk, synthetic

    def generate(*args, **kwargs):
        raise AssertionError("the generator ran before --out was checked")

    monkeypatch.setattr(synthetic, "dipole_capture", generate)
    monkeypatch.setattr(random_walk, "walk_capture", generate)


@pytest.mark.parametrize("generator", ["walk", "dipole"])
@pytest.mark.parametrize("name, message", [
    ("folder", "is a folder"),
    ("c.exr", "would overwrite the image"),
    ("file/c.json", "cannot create the folder"),
])
def test_a_bad_out_is_refused_before_the_generator_runs(tmp_path, capsys, generators_run,
                                                        generator, name, message):
    (tmp_path / "folder").mkdir()
    (tmp_path / "file").write_text("not a folder")
    code = main(["capture", "skin1", "--generator", generator, "--size", "16",
                 "--out", str(tmp_path / name)])
    assert code == 2
    error = capsys.readouterr().err
    assert message in error and "--out" in error


def test_pass_spp_0_is_refused_not_replaced_by_the_default(tmp_path, capsys):
    # "--pass-spp 0" ran with the default 1024 samples per pass
    code = main(["capture", "skin1", "--generator", "volpath", "--size", "16", "--spp", "16",
                 "--pass-spp", "0", "--out", str(tmp_path / "c.json")])
    assert code == 2
    assert "pass_spp = 0: must be an integer >= 1" in capsys.readouterr().err


def test_capture_top_hat_beam(tmp_path):
    import json

    out = tmp_path / "th.json"
    assert main(["capture", "skin1", "--generator", "dipole", "--beam-profile", "top_hat",
                 "--beam-radius", "1", "--size", "24", "--pixel-size", "0.3",
                 "--out", str(out)]) == 0
    data = json.loads(out.read_text())
    assert data["beam_profile"] == "top_hat" and data["beam_radius_mm"] == 1.0
    assert main(["capture", "skin1", "--beam-profile", "top_hat",
                 "--out", str(tmp_path / "walk.json")]) == 2
    assert not (tmp_path / "walk.json").exists()
