"""``translucent profiles``: the list, one profile described, bad names exit 2."""

import json

from translucent.materials.profiles import PROFILE_NAMES
from translucent.reports.cli import main


def test_the_list_names_every_profile(capsys):
    assert main(["profiles"]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert [line.split(":")[0] for line in lines] == list(PROFILE_NAMES)


def test_one_profile_is_described_with_its_parameters(capsys, tmp_path):
    record = tmp_path / "profile.json"
    assert main(["profiles", "--show", "burley_dmfp", "--medium", "Skin1",
                 "--json", str(record)]) == 0
    out = capsys.readouterr().out
    assert out.startswith("burley_dmfp (Skin1): Christensen-Burley")
    assert "from the medium:" in out and "radius holding 99 % = [" in out
    written = json.loads(record.read_text())
    assert written["profile"]["name"] == "burley_dmfp"
    assert len(written["profile"]["radius_99_mm"]) == 3


def test_the_directional_dipole_is_shown_by_its_average(capsys):
    assert main(["profiles", "--show", "directional_dipole"]) == 0
    assert "radial average" in capsys.readouterr().out


def test_bad_names_exit_2(capsys):
    assert main(["profiles", "--show", "dipol"]) == 2
    assert "profile = 'dipol': unknown profile; valid: dipole" in capsys.readouterr().err
    assert main(["profiles", "--show", "dipole", "--medium", "Jade"]) == 2
    assert "unknown measured material" in capsys.readouterr().err
