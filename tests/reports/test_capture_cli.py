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
