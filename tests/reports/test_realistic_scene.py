"""A hand-written realistic scene (examples/scenes/skin_torus.toml) is scored by three methods.

A Skin1 torus on a grey floor under a point and a spot light: PRT (the floor visible, left
black), splatting (the spot light) and radiosity all run on it and get metrics beside the
reference's noise floor. Small (40 x 28 pixels, a 16 spp x 2 reference) to stay quick.
"""

import json
from pathlib import Path

import pytest
from translucent.reports.cli import main

SCENE = Path(__file__).resolve().parents[2] / "examples" / "scenes" / "skin_torus.toml"


@pytest.mark.slow
def test_three_methods_score_the_torus_on_a_floor(tmp_path):
    scene = tmp_path / "skin_torus.toml"
    scene.write_text(SCENE.read_text().replace("width = 96", "width = 40")
                     .replace("height = 64", "height = 28"))
    code = main(["report", str(scene), "--methods", "prt,radiosity,splatting", "--spp", "16",
                 "--passes", "2", "--serial", "--no-progress", "--out", str(tmp_path / "out"),
                 "--baseline", str(tmp_path / "baseline.json"), "--update-baseline"])
    assert code == 0
    methods = json.loads((tmp_path / "out" / "metrics.json").read_text()
                         )["scenes"]["skin_torus"]["methods"]
    for name in ("prt", "radiosity", "splatting"):
        run = methods[name]
        assert run["status"] == "ok", (name, run["reason"])
        assert run["metrics"]["relative_mse"] > 0
        assert run["noise"]["relative_mse"]["noise_floor"] > 0
    # PRT and splatting render the torus only, and are scored on it
    assert methods["prt"]["objects_scored"] == ["torus"]
    assert methods["radiosity"]["objects_scored"] == ["torus", "floor"]
