"""The run-time-versus-error sweep: equal-error interpolation, ladders, a tiny sweep."""

import json
import math
import types

import numpy as np
import pytest
from translucent.errors import InputError
from translucent.fast.base import METHODS
from translucent.fast.base import method as method_module
from translucent.materials import measured_medium
from translucent.reports.bench import tradeoff
from translucent.reports.bench.tradeoff import equal_error_seconds, sweep
from translucent.reports.cli import main
from translucent.scenes import Camera, ConstantEnvironment, Scene, SceneObject, icosphere

#: Interpolation in log-log space reproduces a power law to rounding.
POWER_LAW_RTOL = 1e-9

#: Samples per pass of the tiny sweep's reference (4 passes): 256 spp in all, so that the
#: 1- and 2-spp renders are far noisier than it and their relMSE clearly ordered.
TINY_REFERENCE_SPP = 64


def _power_law(errors, exponent=-1.0, scale=2.0):
    return scale * np.asarray(errors) ** exponent


def test_equal_error_on_a_power_law_inside_and_outside_the_sweep():
    errors = np.array([0.4, 0.2, 0.1, 0.05])  # 1, 2, 4, 8 spp of a 1/spp estimator
    seconds = _power_law(errors)
    inside, extrapolated = equal_error_seconds(errors, seconds, 0.07)
    assert not extrapolated
    assert inside == pytest.approx(_power_law(0.07), rel=POWER_LAW_RTOL)
    outside, extrapolated = equal_error_seconds(errors, seconds, 0.001)
    assert extrapolated
    assert outside == pytest.approx(_power_law(0.001), rel=POWER_LAW_RTOL)
    # the order of the points does not matter; a noisy curve is interpolated between
    # its neighbours
    shuffled = equal_error_seconds(errors[::-1], seconds[::-1], 0.07)[0]
    assert shuffled == pytest.approx(inside, rel=POWER_LAW_RTOL)


def test_equal_error_ignores_unusable_points_and_says_when_it_cannot():
    errors = [0.4, math.nan, 0.1, -0.01]
    seconds = [1.0, 2.0, 4.0, 8.0]
    value, _ = equal_error_seconds(errors, seconds, 0.2)
    assert value == pytest.approx(2.0, rel=POWER_LAW_RTOL)  # between (0.4, 1) and (0.1, 4)
    assert math.isnan(equal_error_seconds([0.4], [1.0], 0.2)[0])
    assert math.isnan(equal_error_seconds(errors, seconds, math.nan)[0])
    assert math.isnan(equal_error_seconds(errors, seconds, 0.0)[0])


def test_ladders_keep_only_existing_knobs_and_end_at_the_defaults():
    module = types.SimpleNamespace(DEFAULT_KNOBS={"samples": 16384, "terms": 256},
                                   LADDERS=method_module("prt").LADDERS)
    ladders, notes = tradeoff._ladders(module, "prt")
    for points in ladders.values():
        assert points[-1] == {}
        assert all(set(point) <= {"samples", "terms"} for point in points)
    assert any("basis_terms" in note for note in notes)
    for name in METHODS:
        for points in tradeoff.declared_ladders(method_module(name), name).values():
            assert {} in points, "every ladder includes the method's defaults"


def test_a_method_without_a_ladder_gets_one_from_its_quality_knobs():
    module = types.SimpleNamespace(DEFAULT_KNOBS={"gather_terms": 64, "seed": 0,
                                                  "exact": True, "name": "x"})
    ladders, notes = tradeoff._ladders(module, "new_method")
    assert ladders == {"gather_terms": [{"gather_terms": 8}, {"gather_terms": 16},
                                        {"gather_terms": 32}, {}]}
    assert "generated" in notes[0]


def _tiny_scene() -> Scene:
    camera = Camera(np.array([0.0, 0.0, 5.0]), np.array([0.0, 0.0, 0.0]),
                    np.array([0.0, 1.0, 0.0]), 30.0, 24, 24)
    sphere = SceneObject("sphere", icosphere(subdivisions=2), measured_medium("Skin1"))
    # a constant environment: every path leaving the sphere finds light, so even 1 spp
    # renders more than fireflies (a small light behind the dielectric boundary would not)
    light = ConstantEnvironment(radiance=1.0)
    return Scene((sphere,), (light,), camera, 10.0, "tradeoff_tiny", "tiny sweep scene")


def test_bad_sweep_arguments():
    scene = _tiny_scene()
    with pytest.raises(InputError, match="unknown fast method"):
        sweep([scene], methods=["teleport"], serial=True, progress=False)
    with pytest.raises(InputError, match="--size"):
        sweep([scene], size=5, serial=True, progress=False)
    with pytest.raises(InputError, match="--max-spp"):
        sweep([scene], max_spp=0, serial=True, progress=False)


def test_a_tiny_sweep(tmp_path, monkeypatch):
    # one cheap rung of radiosity's ladder, 1 and 2 spp of path tracing, a small reference
    monkeypatch.setattr(method_module("radiosity"), "LADDERS", {"tiny": [
        {"self_samples": 4, "profile_energy_cutoff": 0.1}, {}]})
    figures = sweep([_tiny_scene()], methods=["radiosity"], serial=True, size=0, max_spp=2,
                    reference_spp=TINY_REFERENCE_SPP, reference_passes=4, progress=False)
    entry = figures["scenes"]["tradeoff_tiny"]
    traced = entry["path_tracing"]
    assert [p["spp"] for p in traced] == [1, 2]
    assert all(p["seconds"] > 0 for p in traced)
    # 1 spp is noisier than 2 spp against a reference of 4 x 64 spp
    assert traced[0]["relative_mse"] > traced[1]["relative_mse"] > 0
    assert entry["baseline_seconds"] == traced[0]["seconds"]
    assert traced[0]["ratio"] == 1.0
    method = entry["methods"]["radiosity"]
    if method["status"] != "ok":
        pytest.skip(f"radiosity does not run here: {method['reason']}")
    points = method["ladders"]["tiny"]
    assert [p["knobs"] for p in points] == [{"self_samples": 4, "profile_energy_cutoff": 0.1},
                                            {}]
    for point in points:
        assert point["status"] == "ok", point.get("reason")
        assert point["total_seconds"] == pytest.approx(point["precompute_seconds"]
                                                       + point["first_frame_seconds"])
        assert point["frame_ratio"] == pytest.approx(point["frame_seconds"]
                                                     / entry["baseline_seconds"])
        expected, _ = equal_error_seconds([p["relative_mse"] for p in traced],
                                          [p["seconds"] for p in traced],
                                          point["relative_mse"])
        assert point["path_tracing_seconds_at_equal_error"] == pytest.approx(expected,
                                                                             nan_ok=True)
        if math.isfinite(expected):
            assert point["speedup_frame"] == pytest.approx(expected / point["frame_seconds"])
    picture = tradeoff.plot(figures, tmp_path / "curves.png")
    assert picture.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_the_command_writes_json_and_plot(tmp_path, monkeypatch):
    monkeypatch.setattr(method_module("radiosity"), "LADDERS", {"tiny": [{}]})
    monkeypatch.setattr(tradeoff, "at_width", lambda scene, size: _tiny_scene())
    out = tmp_path / "tradeoff.json"
    code = main(["bench", "tradeoff", "--scene", "sphere", "--methods", "radiosity",
                 "--serial", "--max-spp", "2", "--reference-spp", str(TINY_REFERENCE_SPP),
                 "--reference-passes", "4", "--json", str(out)])
    assert code == 0
    data = json.loads(out.read_text())
    assert data["time_baseline"].startswith("the 1-spp path-traced render")
    assert "tradeoff_tiny" in data["scenes"]
    assert out.with_suffix(".png").read_bytes()[:4] == b"\x89PNG"


def test_a_plot_path_that_is_a_folder_is_refused_before_the_sweep(tmp_path, capsys,
                                                                   monkeypatch):
    def never(*args, **kwargs):
        raise AssertionError("swept before --plot was checked")

    monkeypatch.setattr(tradeoff, "sweep", never)
    assert main(["bench", "tradeoff", "--plot", str(tmp_path), "--json",
                 str(tmp_path / "t.json")]) == 2
    assert "--plot = " in capsys.readouterr().err
    assert not any(tmp_path.iterdir())
