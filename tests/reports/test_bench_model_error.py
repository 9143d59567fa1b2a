"""The model-error table: fast methods against Mitsuba volumetric path tracing, measured media."""

import json
import math

import numpy as np
import pytest
from translucent.errors import InputError
from translucent.fast.object_geometry import QUICK_GEOMETRY_KNOBS
from translucent.image import Image
from translucent.reports.bench import model_error
from translucent.reports.bench.model_error import (
    bench_scene,
    index_matched,
    measure_medium,
    model_error_table,
    object_mask,
    object_metrics,
    reference_noise,
)
from translucent.reports.cli import main
from translucent.reports.metrics.compute import RELMSE_EPSILON

#: The tiny table: two media whose references are rendered in RGB (their albedo is below
#: the per-channel threshold) at 16 x 16 pixels, 4 spp x 2 passes: a few seconds.
TINY = {"size": 16, "spp": 4, "passes": 2}
TINY_MEDIA = ("Skin1", "Ketchup")

#: Cheaper knobs than the methods' defaults (the benchmark uses the defaults): 256
#: illumination samples for PRT (4 parts x 8 x 8, one core) and a 64 x 64 irradiance buffer
#: for splatting. The tests check the table's machinery, not the methods' accuracy.
TINY_KNOBS = {"prt": {"samples": 256, "workers": 1, **QUICK_GEOMETRY_KNOBS},
              "splatting": {"irradiance_resolution": 64, **QUICK_GEOMETRY_KNOBS}}
TINY_METHODS = ("prt", "splatting")

#: Sums of float64 squares over a few hundred pixels agree to rounding.
ROUNDING_RTOL = 1e-12

#: Pixels are counted by their centres: a disc of about 9 px radius gains or loses up to
#: its perimeter's pixels (2 pi r / (pi r^2) ~ 22 %); half of that is a generous bound.
PIXEL_EDGE_FRACTION = 0.1

#: The slow table's reference noise must be below this median relative standard error
#: for every medium. Measured at 48 x 48, 64 spp x 4 passes with eta = 1: 0.07 (Marble,
#: Apple) to 0.12 (Ketchup); the unconverged set-up this replaces (a point light behind a
#: dielectric of eta 1.5) measured 0.6-0.9. Twice the worst converged value separates them.
SLOW_REFERENCE_SE_MAX = 0.25

ROW_METHOD_KEYS = {"status", "reason", "precompute_seconds", "frame_seconds", "hdr_flip",
                   "hdr_flip_image", "relative_mse", "relative_mse_raw", "mean_ratio",
                   "luminance_ratio", "dominated_by"}
REFERENCE_KEYS = {"seconds", "cached", "integrator", "per_channel", "relative_standard_error",
                  "relative_standard_error_mean", "noise_relative_mse", "noise_hdr_flip"}


@pytest.fixture(scope="module")
def tiny_table(tmp_path_factory):
    out = tmp_path_factory.mktemp("model_error")
    result = model_error_table(out, media=TINY_MEDIA, methods=TINY_METHODS, progress=False,
                               knobs=TINY_KNOBS, **TINY)
    return out, result


# ---------------------------------------------------------------------- analytic pieces


def _sphere_like(rng, size=16):
    rgb = rng.uniform(0.2, 1.0, (size, size, 3)).astype(np.float32)
    variance = (rng.uniform(0.0, 0.01, (size, size, 3)) * rgb**2).astype(np.float32)
    mask = np.zeros((size, size), dtype=bool)
    mask[4:12, 3:13] = True
    return Image(rgb, variance=variance), mask


def test_reference_noise_is_the_relative_standard_error_of_the_object(rng):
    reference, mask = _sphere_like(rng)
    noise = reference_noise(reference, mask)
    rgb = reference.rgb[mask].astype(np.float64)
    variance = reference.variance[mask].astype(np.float64)
    relative = np.sqrt(variance) / rgb
    assert noise["relative_standard_error"] == pytest.approx(np.median(relative),
                                                             rel=ROUNDING_RTOL)
    assert noise["relative_standard_error_mean"] == pytest.approx(relative.mean(),
                                                                  rel=ROUNDING_RTOL)
    expected = np.mean(variance / (rgb**2 + RELMSE_EPSILON))
    assert noise["noise_relative_mse"] == pytest.approx(expected, rel=ROUNDING_RTOL)
    assert 0 < noise["noise_hdr_flip"] < 1
    # no noise: no noise-only FLIP
    quiet = Image(reference.rgb, variance=np.zeros_like(reference.variance))
    assert reference_noise(quiet, mask)["noise_hdr_flip"] == 0


def test_object_metrics_of_an_identical_image_are_the_noise_alone(rng):
    reference, mask = _sphere_like(rng)
    metrics = object_metrics(reference, Image(reference.rgb), mask)
    assert metrics["hdr_flip"] == 0 and metrics["relative_mse_raw"] == 0
    # the discounted relMSE subtracts exactly the noise's own relMSE
    noise = reference_noise(reference, mask)["noise_relative_mse"]
    assert metrics["relative_mse"] == pytest.approx(-noise, rel=ROUNDING_RTOL)
    assert metrics["mean_ratio"] == pytest.approx([1.0, 1.0, 1.0], rel=ROUNDING_RTOL)
    assert metrics["luminance_ratio"] == pytest.approx(1.0, rel=ROUNDING_RTOL)


def test_object_metrics_see_only_the_object(rng):
    reference, mask = _sphere_like(rng)
    outside = reference.rgb.copy()
    outside[~mask] *= 3.0  # wrong off the object only
    metrics = object_metrics(reference, Image(outside), mask)
    assert metrics["relative_mse_raw"] == 0
    assert metrics["luminance_ratio"] == pytest.approx(1.0, rel=ROUNDING_RTOL)
    half = reference.rgb * 0.5
    assert object_metrics(reference, Image(half), mask)["mean_ratio"] == pytest.approx(
        [0.5, 0.5, 0.5], rel=1e-6)  # float32 images


def test_index_matched_keeps_the_measured_coefficients():
    medium = index_matched("marble")
    assert medium.eta == 1.0 and medium.name == "Marble"
    np.testing.assert_array_equal(medium.sigma_s_prime, [2.19, 2.62, 3.00])
    np.testing.assert_array_equal(medium.sigma_a, [0.0021, 0.0041, 0.0071])
    assert index_matched("Skin1", 1.3).eta == 1.3


def test_object_mask_covers_the_sphere():
    scene = bench_scene(24)
    mask = object_mask(scene)
    assert mask.shape == (24, 24)
    # a sphere of radius 1 seen from 5 units projects to a disc of radius
    # tan(asin(1/5)) on the image plane, whose half-width is tan(15 deg) (30 deg field)
    radius_px = 12 * math.tan(math.asin(0.2)) / math.tan(math.radians(15.0))
    expected = math.pi * radius_px**2
    assert abs(mask.sum() - expected) < PIXEL_EDGE_FRACTION * expected
    assert not mask[0, 0] and mask[12, 12]


# ---------------------------------------------------------------------- the tiny table


def test_tiny_table_json_schema(tiny_table):
    out, result = tiny_table
    data = json.loads((out / "model_error.json").read_text())
    assert data["benchmark"] == "model error" and data["format"] == model_error.FORMAT
    assert data["complete"] is True
    assert data["eta"] == 1.0 and data["index_matched"] is True
    assert "index-matched" in data["boundary"]
    assert data["size"] == [TINY["size"], TINY["size"]]
    assert data["reference"] == {"renderer": "Mitsuba 3 volumetric path tracing",
                                 "spp": TINY["spp"], "passes": TINY["passes"],
                                 "total_spp": TINY["spp"] * TINY["passes"]}
    assert data["methods"] == list(TINY_METHODS)
    assert data["media"] == list(TINY_MEDIA)
    assert {"mitsuba", "drjit", "variant"} <= set(data["versions"])
    assert [row["medium"] for row in data["rows"]] == list(TINY_MEDIA)
    for row in data["rows"]:
        assert row["eta"] == 1.0 and row["method_medium"] == row["medium"]
        assert len(row["sigma_a"]) == 3 and len(row["sigma_s_prime"]) == 3
        assert set(row["reference"]) == REFERENCE_KEYS
        assert set(row["methods"]) == set(TINY_METHODS)
        for entry in row["methods"].values():
            assert set(entry) == ROW_METHOD_KEYS
            assert entry["status"] == "ok", entry["reason"]
            assert entry["dominated_by"] in ("model", "noise")
        assert (out / row["image"]).is_file()
    markdown = (out / "model_error.md").read_text()
    for name in TINY_MEDIA:
        assert f"| {name} |" in markdown
    assert "prt FLIP" in markdown and "index-matched" in markdown


def test_tiny_table_metrics_are_finite(tiny_table):
    _, result = tiny_table
    for row in result["rows"]:
        noise = row["reference"]
        assert 0 < noise["relative_standard_error"] < math.inf
        assert noise["noise_relative_mse"] > 0
        assert 0 < noise["noise_hdr_flip"] < 1
        for entry in row["methods"].values():
            assert 0 < entry["hdr_flip"] <= 1 and 0 < entry["hdr_flip_image"] <= 1
            assert math.isfinite(entry["relative_mse"])
            assert entry["relative_mse_raw"] > 0
            assert all(0 < r < math.inf for r in entry["mean_ratio"])
            assert entry["dominated_by"] == ("model" if entry["relative_mse"]
                                             > noise["noise_relative_mse"] else "noise")


def test_a_mismatched_material_scores_worse_than_the_matched_one(tiny_table):
    _, result = tiny_table
    matched = result["rows"][0]  # Skin1 rendered as Skin1
    scene = bench_scene(TINY["size"])
    mismatched = measure_medium(scene, index_matched("Skin1"), ("prt",),
                                method_medium=index_matched("Ketchup"), spp=TINY["spp"],
                                passes=TINY["passes"], knobs=TINY_KNOBS)
    assert mismatched["reference"]["cached"]  # the same Skin1 reference
    assert mismatched["method_medium"] == "Ketchup"
    wrong, right = mismatched["methods"]["prt"], matched["methods"]["prt"]
    assert wrong["hdr_flip"] > right["hdr_flip"]
    assert wrong["relative_mse_raw"] > right["relative_mse_raw"]
    assert wrong["relative_mse"] > right["relative_mse"]


def test_rows_are_written_as_they_come(tiny_table, tmp_path, monkeypatch):
    original = model_error.measure_medium
    seen = []

    def failing_second(scene, medium, *args, **kwargs):
        seen.append(medium.name)
        if len(seen) == 2:
            raise RuntimeError("stopped at the second medium")
        return original(scene, medium, *args, **kwargs)

    monkeypatch.setattr(model_error, "measure_medium", failing_second)
    with pytest.raises(RuntimeError, match="second medium"):
        model_error_table(tmp_path, media=TINY_MEDIA, methods=("prt",), progress=False,
                          pngs=False, knobs=TINY_KNOBS, **TINY)
    data = json.loads((tmp_path / "model_error.json").read_text())
    assert data["complete"] is False
    assert [row["medium"] for row in data["rows"]] == ["Skin1"]
    assert "a partial table" in (tmp_path / "model_error.md").read_text()


def test_command_line(tiny_table, tmp_path, capsys):
    code = main(["bench", "model_error", "--out", str(tmp_path), "--media", "Skin1",
                 "--methods", "splatting", "--size", str(TINY["size"]), "--spp",
                 str(TINY["spp"]), "--passes", str(TINY["passes"]), "--no-progress",
                 "--json", str(tmp_path / "table.json")])
    assert code == 0
    printed = capsys.readouterr().out
    assert "| Skin1 |" in printed and "splatting FLIP" in printed
    data = json.loads((tmp_path / "table.json").read_text())
    assert data["rows"][0]["reference"]["cached"]  # rendered by the tiny table already
    assert data["rows"][0]["methods"]["splatting"]["status"] == "ok"
    assert (tmp_path / "model_error.md").is_file()


# ---------------------------------------------------------------------- bad input


@pytest.mark.parametrize(("arguments", "message"), [
    ({"size": 8}, r"--size.*>= 11 \(FLIP"),
    ({"spp": 0}, r"--spp.*>= 1"),
    ({"passes": 1}, r"--passes.*two passes"),
    ({"methods": ("prt", "brdf_pca")}, r"--methods.*valid: prt, splatting, radiosity"),
    ({"methods": ()}, r"unknown or no fast method"),
    ({"eta": 0.5}, r"--eta.*\[1, 3\]"),
    ({"media": ("Marble", "Jelly")}, r"'Jelly': unknown measured material"),
    ({"media": ()}, r"no medium given"),
])
def test_bad_input(tmp_path, arguments, message):
    with pytest.raises(InputError, match=message):
        model_error_table(tmp_path, progress=False, **arguments)
    assert not (tmp_path / "model_error.json").exists()


def test_bad_input_on_the_command_line_exits_2(tmp_path, capsys):
    assert main(["bench", "model_error", "--out", str(tmp_path), "--passes", "1"]) == 2
    assert "--passes" in capsys.readouterr().err


# ---------------------------------------------------------------------- slow


@pytest.mark.slow
def test_model_error_table_against_mitsuba(tmp_path):
    """PRT against volumetric path tracing for the 12 measured media, index-matched sphere.

    This measures the dipole model, not the method: its error is reported, not bounded.
    What is bounded is the reference's own noise, so that the table measures the model.
    """
    result = model_error_table(tmp_path, methods=("prt",), progress=False)
    assert result["complete"]
    assert [row["medium"] for row in result["rows"]] == list(model_error.measured_medium_names())
    for row in result["rows"]:
        assert row["reference"]["relative_standard_error"] < SLOW_REFERENCE_SE_MAX, row["medium"]
        entry = row["methods"]["prt"]
        assert entry["status"] == "ok", entry["reason"]
        assert 0 < entry["hdr_flip"] <= 1
        assert math.isfinite(entry["relative_mse"]) and entry["relative_mse_raw"] >= 0


def test_an_out_that_is_a_file_is_refused_before_any_medium_is_measured(tmp_path, capsys,
                                                                         monkeypatch):
    def never(*args, **kwargs):
        raise AssertionError("measured before --out was checked")

    monkeypatch.setattr(model_error, "measure_medium", never)
    a_file = tmp_path / "a_file"
    a_file.write_text("keep me")
    for out, message in ((a_file, "exists and is not a folder"),
                         (a_file / "sub", "is not a folder")):
        assert main(["bench", "model_error", "--out", str(out), "--media", "marble",
                     "--methods", "prt", "--size", "11", "--no-progress"]) == 2
        assert message in capsys.readouterr().err
    assert a_file.read_text() == "keep me"


def test_the_profile_axis_splits_each_profiles_error_and_names_the_best_pair(tmp_path):
    """One medium, splatting with the default and one more profile, on the tiny set-up."""
    result = model_error_table(tmp_path / "out", media=("Skin1",), methods=("splatting",),
                               progress=False, knobs=TINY_KNOBS, profiles=["better_dipole"],
                               pngs=False, **TINY)
    axis = result["rows"][0]["profiles"]
    assert list(axis["profiles"]) == ["dipole", "better_dipole"]  # the default always
    for profile, entry in axis["profiles"].items():
        method = entry["methods"]["splatting"]
        assert method["status"] == "ok", (profile, method)
        assert math.isfinite(entry["model_relative_mse"])
        assert math.isfinite(method["relative_mse"])
        assert math.isfinite(method["approximation_relative_mse"])
        # two independent renders: the model error's floor carries both variances
        assert entry["model_noise_relative_mse"] > entry["approximation_noise_relative_mse"] > 0
    # the default profile's total is the table's own column
    assert axis["profiles"]["dipole"]["methods"]["splatting"]["relative_mse"] == \
        result["rows"][0]["methods"]["splatting"]["relative_mse"]
    best = axis["best"]
    totals = {p: e["methods"]["splatting"]["relative_mse"] for p, e in axis["profiles"].items()}
    assert best["profile"] == min(totals, key=totals.get) and best["method"] == "splatting"
    speeds = {p: e["methods"]["splatting"]["speedup_vs_path_tracing"]
              for p, e in axis["profiles"].items()}
    assert all(v is not None for v in speeds.values())  # the ladder brackets them here
    assert axis["fastest"]["speedup_vs_path_tracing"] == max(speeds.values())
    assert axis["fastest"]["profile"] == max(speeds, key=speeds.get)
    text = (tmp_path / "out" / "model_error.md").read_text()
    assert "## The profile axis" in text and "Lowest total error per medium" in text
    assert "Highest speed-up over path tracing at equal error per medium" in text


def test_a_refused_pair_is_not_applicable_and_a_profile_without_model_still_runs(tmp_path):
    # PRT refuses quantized diffusion (its basis is too slow to build); the radial average
    # of the directional dipole has no model reference, but the methods' totals need none
    knobs = {"prt": {**TINY_KNOBS["prt"], "basis_samples": 16}}
    result = model_error_table(tmp_path / "out", media=("Skin1",), methods=("prt",),
                               progress=False, knobs=knobs, pngs=False,
                               profiles=["quantized_diffusion", "directional_dipole_average"],
                               **TINY)
    axis = result["rows"][0]["profiles"]["profiles"]
    refused = axis["quantized_diffusion"]["methods"]["prt"]
    assert refused["status"] == "not applicable" and "quantized_diffusion" in refused["reason"]
    average = axis["directional_dipole_average"]
    assert "radial average" in average["error"] and "model_relative_mse" not in average
    ran = average["methods"]["prt"]
    assert ran["status"] == "ok" and math.isfinite(ran["relative_mse"])
    assert ran["approximation_relative_mse"] is None
    text = (tmp_path / "out" / "model_error.md").read_text()
    assert "- prt with quantized_diffusion: not applicable (" in text
    assert "- directional_dipole_average: no model reference (" in text


def test_an_unknown_profile_is_refused_before_anything_runs(tmp_path):
    with pytest.raises(InputError, match="unknown radial profile") as error:
        model_error_table(tmp_path / "out", media=("Skin1",), profiles=["nope"], **TINY)
    assert error.value.field == "--profiles"
    assert not (tmp_path / "out").exists()


def test_the_table_keeps_no_precomputation_larger_than_the_reports(tmp_path, monkeypatch):
    # radiosity's operators (about 1 GB a medium and profile) pushed the references out of
    # the cache's budget, and the next medium's run re-rendered them
    import os

    from translucent.cache import ENTRY_LIMIT_VARIABLE
    from translucent.reports.report.runs import REPORT_CACHE_ENTRY_LIMIT

    seen = []

    def measured(scene, medium, methods, **options):
        seen.append(os.environ.get(ENTRY_LIMIT_VARIABLE))
        raise InputError("stop", field="medium", value=medium.name)

    monkeypatch.delenv(ENTRY_LIMIT_VARIABLE, raising=False)
    monkeypatch.setattr(model_error, "measure_medium", measured)
    with pytest.raises(InputError, match="stop"):
        model_error_table(tmp_path / "out", media=("Skin1",), progress=False, **TINY)
    assert seen == [str(REPORT_CACHE_ENTRY_LIMIT)]
    assert ENTRY_LIMIT_VARIABLE not in os.environ  # restored


def test_a_profile_that_refuses_the_medium_is_not_applicable_not_failed(monkeypatch):
    # burley_dmfp scales a mean free path that is infinite without absorption (Spectralon):
    # no method can run it there, which is "not applicable", as a profile a method refuses
    from types import SimpleNamespace

    import translucent.reports.report.runs as runs
    import translucent.reports.report.speedup as speedup
    from translucent.reports.bench import _model_error_profiles as axis

    monkeypatch.setattr(speedup, "path_tracing_ladder", lambda scene, spp: [])
    monkeypatch.setattr(speedup, "scored_curve", lambda *arguments: None)
    monkeypatch.setattr(axis, "_model_error", lambda *arguments, **options: {
        "error": "not rendered here", "model": None, "methods": {}})
    ran = []
    monkeypatch.setattr(runs, "run_method", lambda *arguments, **options: ran.append(arguments))
    stub = SimpleNamespace(status="failed", reason="not run here")
    from translucent.materials import measured_medium

    table = axis.measure_profiles(None, measured_medium("Spectralon"), None, None,
                                  ("splatting", "radiosity"), ["burley_dmfp"],
                                  {"splatting": stub, "radiosity": stub}, spp=1, passes=2,
                                  metrics=None, noise=None)
    refused = table["profiles"]["burley_dmfp"]["methods"]
    assert {entry["status"] for entry in refused.values()} == {"not applicable"}
    assert all("needs sigma_a > 0" in entry["reason"] for entry in refused.values())
    assert ran == []
    assert axis._refuses_medium("burley_dmfp", measured_medium("Skin1")) is None
