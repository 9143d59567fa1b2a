"""``translucent bench``: options every benchmark shares, checked before it runs."""

import pytest
from translucent.reports.bench import prt as bench_prt
from translucent.reports.bench import radiosity as bench_radiosity
from translucent.reports.cli import main


def test_a_json_path_that_is_a_folder_is_refused_before_the_benchmark_runs(tmp_path, capsys,
                                                                           monkeypatch):
    ran = []
    monkeypatch.setattr(bench_prt, "run", lambda args: ran.append(args) or 0)
    assert main(["bench", "prt", "--json", str(tmp_path)]) == 2
    assert ran == []
    assert "--json" in capsys.readouterr().err


def _never(*args, **kwargs):
    raise AssertionError("measured before the options were checked")


@pytest.mark.parametrize("arguments, message", [
    (["--frames", "0"], "--frames = 0: must be an integer >= 1"),
    (["--edits", "0"], "--edits = 0: must be an integer >= 1"),
    (["--error-vertices", "0"], "--error-vertices = 0: must be an integer >= 1"),
    (["--samples", "abc"], "--samples = 'abc': must be comma-separated"),
    (["--samples", ","], "--samples = ',': must be comma-separated"),
    (["--spatial-rows", "-1"], "--spatial-rows = -1: must be an integer >= 0"),
])
def test_bench_prt_checks_its_options_first(monkeypatch, capsys, arguments, message):
    monkeypatch.setattr(bench_prt, "memory_bandwidth", _never)
    assert main(["bench", "prt", *arguments]) == 2
    assert message in capsys.readouterr().err


@pytest.mark.parametrize("arguments, message", [
    (["--frames", "0"], "--frames = 0: must be an integer >= 1"),
    (["--low-rank", "32,abc"], "--low-rank = '32,abc': must be comma-separated"),
    (["--low-rank", "0"], "--low-rank = '0': must be comma-separated"),
])
def test_bench_radiosity_checks_its_options_first(monkeypatch, capsys, arguments, message):
    monkeypatch.setattr(bench_radiosity, "_baseline", _never)
    assert main(["bench", "radiosity", *arguments]) == 2
    assert message in capsys.readouterr().err


@pytest.mark.parametrize("arguments, message", [
    (["--size", "0"], "--size = 0: must be an integer >= 16"),
    (["--segments", "1"], "--segments = 1: must be an integer >= 2"),
])
def test_bench_fitting_checks_its_options_first(monkeypatch, capsys, arguments, message):
    import translucent.fitting.synthetic

    monkeypatch.setattr(translucent.fitting.synthetic, "dipole_capture", _never)
    assert main(["bench", "fitting", *arguments]) == 2
    assert message in capsys.readouterr().err


def test_bench_fitting_bias_table_refuses_an_out_that_is_a_file(tmp_path, capsys, monkeypatch):
    import translucent.fitting.validation

    monkeypatch.setattr(translucent.fitting.validation, "model_bias_table", _never)
    a_file = tmp_path / "a_file"
    a_file.write_text("keep me")
    assert main(["bench", "fitting", "--bias-table", "--out", str(a_file), "--materials",
                 "skin1"]) == 2
    assert "--out = " in capsys.readouterr().err
    assert a_file.read_text() == "keep me"


def test_bench_brdf_pca_refuses_an_out_that_is_a_file_before_measuring(tmp_path, capsys,
                                                                       monkeypatch):
    from translucent.reports.bench import brdf_pca as bench_brdf_pca

    monkeypatch.setattr(bench_brdf_pca, "_performance", _never)
    a_file = tmp_path / "a_file"
    a_file.write_text("keep me")
    assert main(["bench", "brdf_pca", "--validate", "--out", str(a_file)]) == 2
    assert "--out = " in capsys.readouterr().err
    assert a_file.read_text() == "keep me"


def test_bench_reference_integrators_needs_two_passes_before_rendering(capsys, monkeypatch):
    import translucent.reference

    monkeypatch.setattr(translucent.reference, "render", _never)
    assert main(["bench", "reference", "--integrators", "marble", "--passes", "1"]) == 2
    assert "--passes = 1: must be >= 2" in capsys.readouterr().err


def test_bench_prt_refuses_a_sweep_figure_path_that_is_a_folder(tmp_path, capsys,
                                                                 monkeypatch):
    monkeypatch.setattr(bench_prt, "memory_bandwidth", _never)
    assert main(["bench", "prt", "--sweep", "--png", str(tmp_path)]) == 2
    assert "--png = " in capsys.readouterr().err


def test_bench_reference_delta_lights_refuses_a_scene_without_a_dielectric(capsys, monkeypatch):
    import translucent.reference

    monkeypatch.setattr(translucent.reference, "render", _never)
    code = main(["bench", "reference", "--delta-lights", "--scene", "cornell_block",
                 "--size", "8", "--passes", "2"])
    assert code == 2
    assert "needs a delta light and a dielectric boundary" in capsys.readouterr().err


@pytest.mark.slow  # 30 s, most of it compiling the three estimators' kernels
def test_bench_reference_delta_lights_measures_both_estimators(tmp_path, capsys):
    import json

    out = tmp_path / "delta.json"
    assert main(["bench", "reference", "--delta-lights", "--size", "12", "--spp", "4",
                 "--passes", "2", "--json", str(out)]) == 0
    result = json.loads(out.read_text())
    assert result["scene"] == "sphere_dielectric"
    rows = result["estimators"]
    assert set(rows) == {"volpath_mnee", "volpath_mnee, RGB", "volpath + stand-in emitters"}
    assert rows["volpath_mnee"]["median_rse"] is not None  # the connection lights the sphere
    assert any("sphere emitter" in note
               for note in rows["volpath + stand-in emitters"]["substitutions"])
    target = result["target"]
    assert target["reached"] == rows["volpath_mnee"]["median_rse_at_target_minutes"]
    assert target["met"] == (target["reached"] <= 0.02)
    out_text = capsys.readouterr().out
    assert "RSE at 1 CPU min" in out_text and "volpath_mnee at 10 CPU minutes" in out_text


@pytest.mark.parametrize("arguments, message", [
    (["--counts", "0"], "--counts"),
    (["--frames", "0"], "--frames = 0"),
    (["--scenes", "glossy"], "splatting does not apply"),
    (["--scenes", ","], "give at least one scene"),
])
def test_bench_area_lights_refuses_bad_input(capsys, arguments, message):
    assert main(["bench", "area_lights", *arguments]) == 2
    assert message in capsys.readouterr().err


@pytest.mark.parametrize("arguments, message", [
    (["--sizes", "0"], "--sizes"),
    (["--spp", "4"], "give at least two sample counts"),
    (["--subdivisions", "9"], "must be at most 6"),
    (["--methods", "nope"], "--methods = 'nope': unknown fast method"),
    (["--scenes", "furnace_sphere"], "no committed reference is planned"),
    (["--frames", "0"], "--frames = 0"),
])
def test_bench_scaling_refuses_bad_input_before_it_renders(capsys, tmp_path, arguments,
                                                           message):
    out = tmp_path / "scaling.json"
    assert main(["bench", "scaling", *arguments, "--json", str(out)]) == 2
    assert message in capsys.readouterr().err
    assert not out.exists()
