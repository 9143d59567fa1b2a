"""``translucent bench heterogeneous``: the surface heuristics against the volumetric truth."""

import json

import numpy as np
import pytest
from translucent.materials import measured_medium, measured_medium_names
from translucent.materials.profiles import HETEROGENEOUS_RULES
from translucent.reports.bench.heterogeneous import (
    AFFORDABLE_ALBEDO,
    checker_scene,
    diffusion_lengths,
    heterogeneous_table,
    most_different_pair,
)
from translucent.reports.cli import main

#: A tiny run: 12 x 12 pixels, 4 spp x 2 passes, a 9-row sphere; seconds, not minutes.
TINY = {"size": 12, "spp": 4, "passes": 2, "rows": 9}


def test_the_default_pair_is_the_most_different_affordable_one():
    first, second = most_different_pair()
    pair = (measured_medium(first), measured_medium(second))
    ratio = np.max(np.abs(np.log(diffusion_lengths(pair[0]) / diffusion_lengths(pair[1]))))
    for a in measured_medium_names():
        for b in measured_medium_names():
            media = measured_medium(a), measured_medium(b)
            if a == b or any(float(np.max(m.albedo)) > AFFORDABLE_ALBEDO for m in media):
                continue
            other = np.max(np.abs(np.log(diffusion_lengths(media[0])
                                         / diffusion_lengths(media[1]))))
            assert other <= ratio + 1e-12, (a, b)


def test_the_checker_scene_holds_the_two_media():
    skin, ketchup = measured_medium("Skin1"), measured_medium("Ketchup")
    scene = checker_scene(skin, ketchup, 2, size=16, rows=9)
    solid = scene.object("sphere").material
    assert solid.shape == (2, 2, 2) and solid.eta == 1.0
    assert np.array_equal(solid.sigma_a[0, 0, 0], skin.sigma_a)
    assert np.array_equal(solid.sigma_a[0, 0, 1], ketchup.sigma_a)


@pytest.fixture(scope="module")
def tiny_table(tmp_path_factory):
    out = tmp_path_factory.mktemp("heterogeneous")
    return out, heterogeneous_table(out, pair=("Skin1", "Ketchup"), contrasts=(0.0,),
                                    cells=(8,), progress=False, **TINY)


def test_the_table_has_both_sweeps_with_noise_beside_every_error(tiny_table):
    out, result = tiny_table
    assert result["complete"] and [r["sweep"] for r in result["rows"]] == \
        ["contrast", "cell size"]
    homogeneous, fine = result["rows"]
    assert homogeneous["contrast"] == pytest.approx(1.0) and fine["contrast"] > 2
    assert fine["cell_mm"] == pytest.approx(2.5) and homogeneous["cell_mm"] == \
        pytest.approx(5.0)
    for row in result["rows"]:
        assert row["reference"]["noise_relative_mse"] > 0
        for entry in row["methods"].values():
            assert entry["status"] == "ok", entry
            assert entry["dominated_by"] in ("model", "noise")
    media = fine["methods"]["radiosity"]["solid_medium"]["media"]
    assert media == 2 and homogeneous["methods"]["splatting"]["solid_medium"]["media"] == 1
    saved = json.loads((out / "heterogeneous.json").read_text())
    assert len(saved["rows"]) == 2
    assert "| contrast |" in (out / "heterogeneous.md").read_text()


def test_each_method_is_split_against_its_own_rule_rendered_exactly(tiny_table):
    out, result = tiny_table
    homogeneous, fine = result["rows"]
    rules = {"splatting": "geometric_mean", "radiosity": "segment_mix"}
    for row in result["rows"]:
        assert set(row["rules"]) == set(HETEROGENEOUS_RULES)
        for name, entry in row["methods"].items():
            assert entry["rule"] == rules[name]
            assert np.isfinite(entry["approximation"]["relative_mse"])
            assert entry["dominant"] in ("model", "approximation")
    # the homogeneous limit: one medium, so both rules are the same model, bit for bit
    first, second = (homogeneous["rules"][rule] for rule in rules.values())
    assert first["relative_mse"] == second["relative_mse"]
    assert "own relMSE" in (out / "heterogeneous.md").read_text()


@pytest.mark.parametrize("arguments, field", [
    (["--contrasts", "0,2"], "--contrasts"), (["--contrasts", "x"], "--contrasts"),
    (["--rows", "8"], "--rows"), (["--pair", "Skin1,Jelly"], "--pair"),
    (["--methods", "prt"], "--methods"), (["--passes", "1"], "--passes"),
])
def test_bad_options_are_usage_errors_naming_the_option(capsys, tmp_path, arguments, field):
    code = main(["bench", "heterogeneous", "--out", str(tmp_path / "h"), "--no-progress",
                 *arguments])
    assert code == 2 and field in capsys.readouterr().err
    assert not (tmp_path / "h").exists()
