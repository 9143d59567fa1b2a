"""``translucent bench splatting`` on a tiny frame: rows, JSON, input checks."""

import json

import pytest
from translucent.reports.cli import main

TINY = ["bench", "splatting", "--width", "32", "--height", "24", "--irradiance-resolution",
        "16", "--validation-width", "16", "--validation-irradiance", "16", "--frames", "1",
        "--validation-stride", "2", "--epsilons", ""]


@pytest.mark.slow  # 9 s; `bench splatting --quick` runs in the fast tier (test_bench_quick_methods)
def test_tiny_bench_writes_every_row_with_its_error(tmp_path, capsys):
    out = tmp_path / "bench.json"
    assert main(TINY + ["--settings", "no acceleration,both", "--level-samplings", "1",
                        "--levels-list", "4", "--materials", "checker,wax_gradient",
                        "--json", str(out)]) == 0
    written = json.loads(out.read_text())
    results = written["results"]
    assert list(written["materials"]) == ["checker", "wax_gradient"]
    for row in written["materials"].values():
        assert 0 < row["relative error"] < 1 and 0 < row["hdr_flip"] < 1
    assert list(results) == ["no acceleration", "both", "both, Eq. 17 as published",
                             "both, level sampling 1", "both, 4 levels",
                             "both, 4 levels, level sampling 1"]
    assert results["both, 4 levels"]["knobs"]["levels"] == 4
    assert results["both, Eq. 17 as published"]["knobs"]["profile_upsampling"] is False
    for row in results.values():
        assert row["seconds per frame"] > 0 and 0 <= row["relative error"] < 1
    assert "5x over no acceleration at equal error" in capsys.readouterr().out


@pytest.mark.parametrize("flag, value, message", [
    ("--levels-list", "0", "--levels-list = '0': must be integers in [1, 12]"),
    ("--level-samplings", "a", "--level-samplings = 'a': must be comma-separated numbers"),
    ("--settings", "fast", "unknown setting"),
    ("--materials", "jade", "--materials = 'jade': unknown material"),
    ("--frames", "0", "--frames = 0: must be an integer >= 1"),
    ("--validation-stride", "0", "--validation-stride = 0: must be an integer >= 1"),
    ("--validation-width", "-4", "--validation-width = -4: must be an integer >= 1"),
])
def test_bench_refuses_bad_options(flag, value, message, capsys):
    assert main(TINY + [flag, value]) == 2
    assert message in capsys.readouterr().err
