"""The report: a tiny scene end to end, the baseline's regression logic, bad input."""

import html
import json
import math
import os
import re
import textwrap
from pathlib import Path

import numpy as np
import pytest
from translucent.errors import InputError
from translucent.fast import base as fast_base
from translucent.fast.conformance import tiny_sphere_text
from translucent.reports.cli import main
from translucent.reports.report import pipeline as report_module
from translucent.reports.report.pipeline import (
    DEFAULT_BASELINE,
    TOLERANCES,
    Tolerance,
    check_against_baseline,
    default_scenes,
    load_baseline,
    make_report,
    updated_baseline,
)
from translucent.scenes import builtin_scene_names, loads_scene

#: The methods the quick tier runs: a stand-in that renders a flat image at once (so the
#: report's own logic is tested in seconds, whatever the built methods cost: PRT's first
#: run computes its dipole PCA basis, splatting compiles its kernels, each tens of seconds
#: here), one that fails, one that is not installed, and brdf_pca, which does not apply to a
#: translucent sphere. Every built method runs on the tiny scene in the slow test below.
QUICK_METHODS = ["flat", "failing", "unbuilt", "brdf_pca"]

#: Reference samples of the tiny scene: enough for a finite, non-black reference.
TINY_SPP, TINY_PASSES = 16, 2

TINY_SCENE = tiny_sphere_text("tiny_sphere", 24)


def _tiny_scene(folder: Path) -> Path:
    path = folder / "tiny_sphere.toml"
    path.write_text(TINY_SCENE)
    return path


def _run(scene_path, out, baseline, *extra, methods=QUICK_METHODS):
    return main(["report", str(scene_path), "--out", str(out), "--baseline", str(baseline),
                 "--methods", ",".join(methods), "--serial", "--no-progress",
                 "--spp", str(TINY_SPP), "--passes", str(TINY_PASSES), *extra])


def _page_images(out: Path) -> list[str]:
    return re.findall(r'<img src="([^"]+)"', (out / "index.html").read_text())


def _check_page(out: Path) -> dict:
    """Every image the page shows exists, and every PNG in the folder is shown."""
    shown = set(_page_images(out))
    assert shown, "the page shows no image"
    for source in shown:
        assert (out / source).is_file(), f"the page links a missing image {source}"
    written = {p.relative_to(out).as_posix() for p in out.rglob("*.png")}
    assert written == shown
    return json.loads((out / "metrics.json").read_text())


STAND_IN_METHODS = textwrap.dedent('''
    """Stand-in fast methods for the report's tests."""
    import numpy as np

    from translucent.cache import entry_limit
    from translucent.fast.base import StageLog
    from translucent.image import Image

    DEFAULT_KNOBS = {"grey": 0.05}

    #: its quality ladder: the report runs the cheap end beside the defaults
    LADDERS = {"grey level": [{"grey": 0.02}, {}]}


    def applies_to(scene):
        return None


    class FlatState:
        def __init__(self, scene, grey):
            self.scene, self.grey = scene, grey
            self.log = StageLog(skipped=["no transfer: a flat image needs none"],
                                seconds={"nothing": 0.0},
                                notes={"cache_entry_limit": entry_limit()})

        def render(self, lights=None, material=None):
            camera = self.scene.camera
            return Image(np.full((camera.height, camera.width, 3), self.grey, np.float32),
                         metadata={"producer": "flat"})


    def precompute(scene, **knobs):
        return FlatState(scene, {**DEFAULT_KNOBS, **knobs}["grey"])
''')

FAILING_METHOD = textwrap.dedent('''
    """A method whose precomputation fails, for the report's tests."""
    DEFAULT_KNOBS = {}


    def applies_to(scene):
        return None


    def precompute(scene, **knobs):
        raise RuntimeError("the transfer matrix has a NaN on purpose")
''')


@pytest.fixture(scope="module")
def tiny(tmp_path_factory):
    """One report of the tiny scene with the stand-in methods, its baseline written.

    The stand-ins are registered in ``fast.base.METHODS`` for the module; the source
    fingerprint is held fixed, so that edits of the methods' files during the test run cannot
    make a second run miss the report cache.
    """
    folder = tmp_path_factory.mktemp("tiny_report")
    (folder / "report_flat_method.py").write_text(STAND_IN_METHODS)
    (folder / "report_failing_method.py").write_text(FAILING_METHOD)
    with pytest.MonkeyPatch.context() as patch:
        if not os.environ.get("TRANSLUCENT_CACHE"):
            # the private cache of tests/conftest.py (set per test, after module fixtures)
            patch.setenv("TRANSLUCENT_CACHE", str(tmp_path_factory.getbasetemp() / "cache"))
        patch.syspath_prepend(str(folder))
        patch.setitem(fast_base.METHODS, "flat", "report_flat_method")
        patch.setitem(fast_base.METHODS, "failing", "report_failing_method")
        patch.setitem(fast_base.METHODS, "unbuilt", "translucent.fast.no_such_method")
        patch.setattr(report_module, "_source_fingerprint", lambda: "fixed for the tests")
        scene_path = _tiny_scene(folder)
        baseline = folder / "baseline.json"
        code = _run(scene_path, folder / "report", baseline, "--update-baseline")
        yield {"folder": folder, "scene": scene_path, "baseline": baseline, "code": code,
               "out": folder / "report"}


def _data(out: Path) -> dict:
    return json.loads((out / "metrics.json").read_text())["scenes"]["tiny_sphere"]


def _metrics(out: Path, method: str) -> dict:
    return _data(out)["methods"][method]


# ---------------------------------------------------------------------------- end to end


def test_the_cheap_end_of_a_methods_ladder_is_scored_beside_its_defaults(tiny):
    flat = _metrics(tiny["out"], "flat")
    (point,) = flat["ladder"]
    assert point["knobs"] == {"grey": 0.02} and point["status"] == "ok"
    assert point["frame_seconds"] is not None
    # a darker flat image than the defaults' 0.05: another error, measured the same way
    assert point["relative_mse"] > 0 and point["relative_mse"] != flat["metrics"]["relative_mse"]
    assert "At cheaper settings" in (tiny["out"] / "index.html").read_text()
    assert _metrics(tiny["out"], "failing")["ladder"] == []


def test_times_are_also_given_in_path_traced_renders_of_the_same_run(tiny):
    data = _data(tiny["out"])
    flat = data["methods"]["flat"]
    curve = data["path_tracing"]
    one_spp = curve["seconds"][curve["spp"].index(1)]
    assert flat["path_tracing_1spp_seconds"] == pytest.approx(one_spp)
    assert flat["frame_in_path_traced_1spp_renders"] == pytest.approx(
        flat["frame_seconds"] / one_spp)
    assert flat["precompute_in_path_traced_1spp_renders"] == pytest.approx(
        flat["precompute_seconds"] / one_spp)
    assert "1-spp path-traced renders" in (tiny["out"] / "index.html").read_text()


def test_the_report_says_where_its_time_went(tiny):
    timing = json.loads((tiny["out"] / "metrics.json").read_text())["timing"]
    tasks = timing["task_seconds"]
    # the reference, flat and failing at defaults and at the ladder's cheap end, the ladder
    kinds = sorted(t["kind"] for t in tasks)
    assert kinds.count("reference") == 1 and kinds.count("path tracing") == 1
    assert {t.get("method") for t in tasks if t["kind"] == "method"} == {"flat", "failing"}
    assert all(t["seconds"] > 0 and t["scene"] == "tiny_sphere" for t in tasks)
    # serial: every task ran in this process, one after the other, inside the tasks phase
    assert {t["worker"] for t in tasks} == {os.getpid()}
    assert sum(t["seconds"] for t in tasks) <= timing["tasks_seconds"]
    assert timing["planning_seconds"] > 0 and timing["scoring_seconds"] > 0
    # the scene was scored as its last task came in, inside the tasks phase
    assert timing["scoring_during_tasks_seconds"] == timing["scoring_seconds"]
    assert sum(t["seconds"] for t in tasks) + timing["scoring_seconds"] <= timing["tasks_seconds"]


def test_ladder_knobs_take_the_cheap_end_of_the_first_ladder():
    from types import SimpleNamespace

    from translucent.fast import splatting
    from translucent.reports.report.pipeline import ladder_knobs

    assert ladder_knobs(splatting, "splatting") == [{"irradiance_resolution": 64}]
    own = SimpleNamespace(DEFAULT_KNOBS={"n": 8}, LADDERS={"n": [{"n": 8}, {"n": 2}, {}]})
    assert ladder_knobs(own, "own") == [{"n": 2}]  # the defaults themselves are not a point
    assert ladder_knobs(SimpleNamespace(DEFAULT_KNOBS={"n": 8}), "unknown") == []


def test_tiny_report_shows_every_image_it_wrote(tiny):
    assert tiny["code"] == 0
    data = _check_page(tiny["out"])
    scene = data["scenes"]["tiny_sphere"]
    assert scene["reference"]["spp"] == TINY_SPP and scene["reference"]["passes"] == TINY_PASSES
    assert set(scene["methods"]) == set(QUICK_METHODS)
    flat = scene["methods"]["flat"]
    assert flat["status"] == "ok"
    assert math.isfinite(flat["metrics"]["hdr_flip"])
    assert flat["precompute_seconds"] >= 0 and flat["frame_seconds"] > 0
    assert flat["skipped"] == ["no transfer: a flat image needs none"]
    # the tasks ran under the report's cache entry limit, and it was lifted afterwards
    assert flat["notes"]["cache_entry_limit"] == report_module.REPORT_CACHE_ENTRY_LIMIT
    assert os.environ.get("TRANSLUCENT_CACHE_MAX_ENTRY_BYTES") is None
    for map_name in ("flip", "relative_error", "ciede2000", "ssim"):
        assert (tiny["out"] / flat["files"][f"map_{map_name}"]).is_file()
    page = (tiny["out"] / "index.html").read_text()
    assert "no transfer: a flat image needs none" in page
    assert not list(tiny["folder"].glob(".report.*")), "a temporary folder was left behind"


def test_every_error_map_has_its_colour_bar_with_range_and_unit(tiny):
    from translucent.reports.metrics.maps import MAP_STYLES, colour_map
    from translucent.reports.report.page import colour_bar

    page = (tiny["out"] / "index.html").read_text()
    for name in ("flip", "relative_error", "ciede2000", "ssim"):
        style = MAP_STYLES[name]
        bar = colour_bar(style)
        figure = re.search(r'<figure class=""><img src="[^"]*_' + name
                           + r'\.png"[^>]*>(.*?)</figure>', page)
        assert figure is not None, f"no {name} map in the page"
        assert bar in figure.group(1)
        ends = re.findall(r"<span>([^<]*)</span>", bar)
        assert ends == [f"{style.vmin:g}", html.escape(style.unit, quote=True),
                        f"{style.vmax:g}"]
        first, last = colour_map(np.array([[style.vmin, style.vmax]]), style)[0]
        stops = re.findall(r"rgb\((\d+),(\d+),(\d+)\) ([\d.]+)%", bar)
        assert [int(v) for v in stops[0][:3]] == first.tolist() and stops[0][3] == "0"
        assert [int(v) for v in stops[-1][:3]] == last.tolist() and stops[-1][3] == "100"


def test_every_metric_comes_with_its_noise_floor_and_verdict(tiny):
    from translucent.reports.metrics.compute import noise_floor, noise_verdict
    from translucent.reports.metrics.registry import NOISE_FLOOR_FIELDS

    scene = _data(tiny["out"])
    reference = scene["reference"]
    assert reference["source"] == "fixed passes"
    assert reference["noise"]["pixels"] > 0 and reference["noise"]["median"] > 0
    # 16 spp x 2 passes of a skin sphere: too noisy, and the page says so
    assert "cannot be resolved" in reference["noise_warning"]
    flat = scene["methods"]["flat"]
    assert set(flat["noise"]) == set(NOISE_FLOOR_FIELDS)
    from translucent.image import read_exr
    from translucent.scenes import gbuffer, load_scene

    scored = gbuffer(load_scene(str(tiny["scene"]))).hit
    floor = noise_floor(read_exr(tiny["out"] / "tiny_sphere" / "reference.exr"), mask=scored)
    assert flat["pixels_scored"] == "object"
    assert flat["metrics"]["pixels_scored"] == int(scored.sum()) < 24 * 24
    assert flat["image_metrics"]["pixels_scored"] == 24 * 24
    for field, entry in flat["noise"].items():
        assert entry["noise_floor"] == pytest.approx(getattr(floor, field), rel=1e-4)
        assert entry["noise_verdict"] == noise_verdict(field, entry["value"],
                                                       entry["noise_floor"])
        gated = flat["baseline"]["metrics"].get(field)
        expected = ("within reference noise" if entry["noise_verdict"] != "resolved" else
                    "no baseline" if not gated else
                    "regression" if gated["verdict"] == "worse" else "ok")
        assert entry["verdict"] == expected
    page = (tiny["out"] / "index.html").read_text()
    assert "noise floor" in page and "Warning: the reference is noisy" in page


def test_each_method_has_its_speedup_over_path_tracing_or_the_reason(tiny):
    from translucent.reports.report.speedup import PATH_TRACING_SPP

    scene = _data(tiny["out"])
    curve = scene["path_tracing"]
    assert curve["spp"] == list(PATH_TRACING_SPP) and curve["error"] is None
    assert all(seconds > 0 for seconds in curve["seconds"])
    # Monte Carlo: more samples, less error
    assert curve["relative_mse"][0] > curve["relative_mse"][-1]
    flat = scene["methods"]["flat"]
    assert flat["first_frame_seconds"] > 0
    if flat["speedup_vs_path_tracing"] is None:
        assert flat["speedup_reason"]
    else:
        assert flat["speedup_vs_path_tracing"] == pytest.approx(
            flat["path_tracing_seconds_at_equal_error"] / flat["frame_seconds"])
    assert scene["methods"]["failing"]["speedup_vs_path_tracing"] is None
    assert scene["methods"]["failing"]["speedup_reason"] == "the method was not scored"
    page = (tiny["out"] / "index.html").read_text()
    assert "tiny_sphere/tradeoff.png" in page and "vs path tracing" in page


SPHERE_ONLY_METHOD = textwrap.dedent('''
    """A stand-in that renders the translucent sphere only (the ball left black)."""
    import numpy as np
    from translucent.fast.base import StageLog
    from translucent.image import Image
    from translucent.scenes import gbuffer

    DEFAULT_KNOBS = {}


    def applies_to(scene):
        return None


    def scored_objects(scene):
        return ["sphere"]


    class State:
        def __init__(self, scene):
            self.scene, self.log = scene, StageLog()

        def render(self, lights=None, material=None):
            seen = gbuffer(self.scene).object_id
            rgb = np.where((seen == 0)[..., None], 0.3, 0.0).astype(np.float32)
            return Image(np.broadcast_to(rgb, seen.shape + (3,)).copy(),
                         metadata={"producer": "sphere_only"})


    def precompute(scene, **knobs):
        return State(scene)
''')


def test_a_method_is_scored_on_the_objects_it_renders(tmp_path, monkeypatch):
    from translucent.image import read_exr
    from translucent.reports.metrics.compute import noise_floor
    from translucent.scenes import gbuffer, load_scene

    (tmp_path / "report_sphere_only.py").write_text(SPHERE_ONLY_METHOD)
    (tmp_path / "report_flat_method.py").write_text(STAND_IN_METHODS)
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.setitem(fast_base.METHODS, "sphere_only", "report_sphere_only")
    monkeypatch.setitem(fast_base.METHODS, "flat", "report_flat_method")
    scene_path = tmp_path / "two.toml"
    scene_path.write_text(TINY_SCENE.replace('name = "tiny_sphere"', 'name = "two"') + """
    [[objects]]
    name = "ball"
    mesh = { type = "icosphere", subdivisions = 2, radius = 0.4, center = [1.3, 0.0, 0.0] }
    material = { type = "lambertian", albedo = 0.5 }
    """.replace("\n    ", "\n"))
    out = tmp_path / "report"
    assert _run(scene_path, out, tmp_path / "baseline.json", "--update-baseline",
                methods=["flat", "sphere_only"]) == 0
    scene = json.loads((out / "metrics.json").read_text())["scenes"]["two"]
    ids = gbuffer(load_scene(str(scene_path))).object_id
    reference = read_exr(out / "two" / "reference.exr")
    flat, only = scene["methods"]["flat"], scene["methods"]["sphere_only"]
    assert flat["objects_scored"] == ["sphere", "ball"]
    assert only["objects_scored"] == ["sphere"]
    assert flat["metrics"]["pixels_scored"] == int((ids >= 0).sum())
    assert only["metrics"]["pixels_scored"] == int((ids == 0).sum()) < int((ids >= 0).sum())
    floor = noise_floor(reference, mask=ids == 0)
    for field, entry in only["noise"].items():
        assert entry["noise_floor"] == pytest.approx(getattr(floor, field), rel=1e-4)
    # its speed-up is measured against path tracing scored on the sphere's pixels too
    assert set(scene["path_tracing_on_objects"]) == {"sphere"}
    page = (out / "index.html").read_text()
    assert "pixels of the objects it renders (sphere)" in page


def test_a_scene_without_committed_reference_is_rendered_to_a_noise_target(tmp_path,
                                                                             monkeypatch):
    monkeypatch.setattr(report_module, "DEFAULT_TARGET_RSE", 0.5)
    monkeypatch.setattr(report_module, "DEFAULT_REFERENCE_BUDGET", 3.0)
    monkeypatch.setattr(report_module, "PROGRESSIVE_SPP", 4)
    scene_path = _tiny_scene(tmp_path)
    result = make_report([str(scene_path)], tmp_path / "r", methods=["brdf_pca"],
                         serial=True, progress=False, baseline=None)
    reference = json.loads((tmp_path / "r" / "metrics.json").read_text())[
        "scenes"]["tiny_sphere"]["reference"]
    assert result.exit_code in (0, 1)
    assert reference["source"] == "progressive"
    assert reference["stopped"] in ("target reached", "budget spent")
    assert reference["noise"]["median"] <= 0.5 or reference["stopped"] == "budget spent"


def test_failing_and_unbuilt_methods_are_shown_and_the_run_goes_on(tiny):
    methods = _data(tiny["out"])["methods"]
    assert methods["failing"]["status"] == "failed"
    assert "NaN on purpose" in methods["failing"]["reason"]
    assert methods["unbuilt"]["status"] == "not installed"
    page = (tiny["out"] / "index.html").read_text()
    assert "The method failed: RuntimeError: the transfer matrix has a NaN on purpose" in page
    assert "this fast method is not installed" in page
    if methods["brdf_pca"]["status"] == "not applicable":
        assert html.escape(methods["brdf_pca"]["reason"]) in page
    assert methods["flat"]["status"] == "ok"


def test_baseline_written_from_the_run(tiny):
    stored = load_baseline(tiny["baseline"], required=True)
    entry = stored["entries"]["tiny_sphere"]
    assert entry["reference"] == {"spp": TINY_SPP, "passes": TINY_PASSES}
    assert set(entry["methods"]) == {"flat"}
    assert entry["methods"]["flat"]["hdr_flip"] == _metrics(tiny["out"], "flat")["metrics"][
        "hdr_flip"]


def test_second_run_uses_the_cached_runs_and_passes(tiny, tmp_path):
    assert _run(tiny["scene"], tmp_path / "again", tiny["baseline"]) == 0
    entry = _metrics(tmp_path / "again", "flat")
    assert entry["cached"] is True
    assert entry["baseline"]["status"] == "ok"
    assert _data(tmp_path / "again")["reference"]["cached"] is True
    assert "(cached: nothing it depends on has changed since)" in (
        tmp_path / "again" / "index.html").read_text()
    page = (tmp_path / "again" / "index.html").read_text()
    assert "No regression in the 1 result(s) compared with the baseline" in page


def test_a_run_with_nothing_to_compare_says_so(tiny):
    # the fixture's run wrote the baseline: there was nothing in it to compare with
    page = (tiny["out"] / "index.html").read_text()
    assert "Nothing was compared with the baseline" in page
    assert "No regression" not in page


def _baseline_copy(tiny, tmp_path, change) -> Path:
    stored = json.loads(tiny["baseline"].read_text())
    change(stored["entries"]["tiny_sphere"]["methods"])
    path = tmp_path / "baseline.json"
    path.write_text(json.dumps(stored))
    return path


def _better_than_achieved(methods):
    methods["flat"]["hdr_flip"] = 0.0
    methods["flat"]["ssim"] = 1.0


def test_a_worse_metric_exits_1_and_is_marked(tiny, tmp_path):
    baseline = _baseline_copy(tiny, tmp_path, _better_than_achieved)
    out = tmp_path / "report"
    assert _run(tiny["scene"], out, baseline) == 1
    data = _check_page(out)
    assert [line.split(":")[0] for line in data["regressions"]] == ["tiny_sphere/flat"]
    check = data["scenes"]["tiny_sphere"]["methods"]["flat"]["baseline"]
    assert check["status"] == "regression"
    assert check["metrics"]["hdr_flip"]["verdict"] == "worse"
    assert check["metrics"]["ssim"]["verdict"] == "worse"
    assert check["metrics"]["relative_mse"]["verdict"] == "ok"
    page = (out / "index.html").read_text()
    assert "1 regression(s) against the baseline" in page
    assert '<tr class="bad"><td>HDR-FLIP</td>' in page
    assert '<tr class="bad"><td>SSIM</td>' in page


def test_update_baseline_rewrites_it_atomically(tiny, tmp_path):
    baseline = _baseline_copy(tiny, tmp_path, _better_than_achieved)
    out = tmp_path / "report"
    assert _run(tiny["scene"], out, baseline, "--update-baseline") == 0
    rewritten = load_baseline(baseline, required=True)
    value = rewritten["entries"]["tiny_sphere"]["methods"]["flat"]["hdr_flip"]
    assert value == _metrics(out, "flat")["metrics"]["hdr_flip"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["baseline.json", "report"]
    assert _run(tiny["scene"], tmp_path / "after", baseline) == 0


def test_a_missing_baseline_entry_is_reported_not_a_failure(tiny, tmp_path):
    baseline = _baseline_copy(tiny, tmp_path, lambda methods: methods.clear())
    out = tmp_path / "report"
    assert _run(tiny["scene"], out, baseline) == 0
    assert _metrics(out, "flat")["baseline"]["status"] == "no baseline"
    assert "no baseline entry for this scene and method" in (out / "index.html").read_text()


def test_a_baseline_entry_without_a_result_is_a_regression(tiny, tmp_path):
    def expect_failing(methods):
        methods["failing"] = dict(methods["flat"])

    baseline = _baseline_copy(tiny, tmp_path, expect_failing)
    out = tmp_path / "report"
    assert _run(tiny["scene"], out, baseline) == 1
    check = _metrics(out, "failing")["baseline"]
    assert check["status"] == "regression"
    assert "NaN on purpose" in check["message"]


# ---------------------------------------------------------------------------- bad input


@pytest.mark.parametrize("arguments, message", [
    (["no_such_scene"], "no such built-in scene"),
    (["sphere", "--methods", "prt,teleport"], "unknown fast method"),
    (["sphere", "--spp", "0"], "--spp"),
])
def test_bad_input_exits_2_and_writes_nothing(tmp_path, capsys, arguments, message):
    out = tmp_path / "out" / "report"
    assert main(["report", *arguments, "--out", str(out), "--serial", "--no-progress"]) == 2
    assert message in capsys.readouterr().err
    assert not (tmp_path / "out").exists()


def test_out_that_cannot_hold_a_report_exits_2(tmp_path, capsys):
    a_file = tmp_path / "a_file"
    a_file.write_text("keep me")
    busy = tmp_path / "busy"
    busy.mkdir()
    (busy / "notes.txt").write_text("keep me too")
    for out, message in ((a_file, "exists and is not a folder"),
                         (a_file / "report", "is not a folder"),
                         (busy, "a folder with other files in it")):
        assert main(["report", "sphere", "--out", str(out), "--serial", "--no-progress"]) == 2
        assert message in capsys.readouterr().err
    assert a_file.read_text() == "keep me"
    assert sorted(p.name for p in busy.iterdir()) == ["notes.txt"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a_file", "busy"]


def test_an_explicit_baseline_must_exist(tmp_path, capsys):
    missing = tmp_path / "missing.json"
    code = main(["report", "sphere", "--out", str(tmp_path / "r"), "--baseline", str(missing),
                 "--serial", "--no-progress"])
    assert code == 2
    assert "no such baseline file" in capsys.readouterr().err
    assert not (tmp_path / "r").exists()


def test_unreadable_baselines(tmp_path):
    corrupt = tmp_path / "corrupt.json"
    corrupt.write_text("{not json")
    with pytest.raises(InputError, match="not a readable JSON baseline"):
        load_baseline(corrupt)
    foreign = tmp_path / "foreign.json"
    foreign.write_text(json.dumps({"format": 99, "entries": {}}))
    with pytest.raises(InputError, match="not a baseline of format 1"):
        load_baseline(foreign)
    assert load_baseline(tmp_path / "absent.json") == {"format": 1, "entries": {}}
    with pytest.raises(InputError, match="no such baseline file"):
        load_baseline(tmp_path / "absent.json", required=True)


# ---------------------------------------------------------------------------- logic


def test_tolerance_direction_and_nan():
    error = Tolerance("hdr_flip", absolute=0.01, relative=0.1)
    assert error.limit(0.2) == pytest.approx(0.23)
    assert not error.is_worse(0.229, 0.2) and error.is_worse(0.231, 0.2)
    assert error.is_better(0.169, 0.2) and not error.is_better(0.171, 0.2)
    assert error.is_worse(float("nan"), 0.2)
    similarity = Tolerance("ssim", absolute=0.01, relative=0.0, lower_is_better=False)
    assert similarity.is_worse(0.889, 0.9) and not similarity.is_worse(0.891, 0.9)
    assert similarity.is_better(0.911, 0.9)


def _entry(scene_hash="h", spp=16, passes=2, **values):
    metrics = {key: 0.1 for key in report_module.REPORTED_METRICS}
    metrics["ssim"] = 0.9
    metrics.update(values)
    return {"entries": {"s": {"scene_hash": scene_hash, "reference": {"spp": spp,
                                                                     "passes": passes},
                              "methods": {"m": metrics}}}}


def test_checks_compare_only_like_with_like():
    reference = {"spp": 16, "passes": 2}
    metrics = {key: 0.1 for key in report_module.REPORTED_METRICS} | {"ssim": 0.9}
    assert check_against_baseline("s", "h", reference, "m", metrics, _entry()).status == "ok"
    other_scene = check_against_baseline("s", "other", reference, "m", metrics, _entry())
    assert other_scene.status == "not compared" and "content hash" in other_scene.message
    other_reference = check_against_baseline("s", "h", {"spp": 64, "passes": 4}, "m", metrics,
                                             _entry())
    assert other_reference.status == "not compared"
    assert "16 spp x 2 passes" in other_reference.message
    assert check_against_baseline("s", "h", reference, "new", metrics,
                                  _entry()).status == "no baseline"
    worse = dict(metrics, relative_mse=0.5)
    check = check_against_baseline("s", "h", reference, "m", worse, _entry())
    assert check.status == "regression" and "relMSE" in check.message
    better = dict(metrics, hdr_flip=0.01)
    assert check_against_baseline("s", "h", reference, "m", better,
                                  _entry()).status == "improved"


def test_updating_keeps_other_scenes_and_drops_methods_that_stopped():
    stored = _entry()
    stored["entries"]["kept"] = {"scene_hash": "k", "reference": {}, "methods": {"x": {}}}
    metrics = {key: 0.2 for key in report_module.REPORTED_METRICS}
    new = updated_baseline(stored, [{"name": "s", "scene_hash": "h", "reference": {
        "spp": 16, "passes": 2}, "metrics": {"n": metrics}, "methods_run": ["m", "n"]}], {})
    assert new["entries"]["kept"] == stored["entries"]["kept"]
    assert set(new["entries"]["s"]["methods"]) == {"n"}
    assert set(new["tolerances"]) == set(TOLERANCES)


# ---------------------------------------------------------------------------- defaults


def test_default_scenes_leave_out_only_listed_scenes_with_reasons():
    names, excluded = default_scenes()
    assert set(names) | set(excluded) == set(builtin_scene_names())
    assert not set(names) & set(excluded)
    assert all(len(reason) > 40 for reason in excluded.values())


def test_committed_baseline_covers_default_scenes_with_the_stated_tolerances():
    stored = load_baseline(DEFAULT_BASELINE, required=True)
    names, _ = default_scenes()
    assert stored["entries"], "the committed baseline is empty"
    assert set(stored["entries"]) <= set(names)
    for name, tolerance in TOLERANCES.items():
        assert stored["tolerances"][name] == {"absolute": tolerance.absolute,
                                              "relative": tolerance.relative,
                                              "lower_is_better": tolerance.lower_is_better}


def test_scenes_given_as_objects(tmp_path):
    scene = loads_scene(TINY_SCENE)
    with pytest.raises(InputError, match="unknown fast method"):
        make_report([scene], tmp_path / "r", methods=["nope"], serial=True, progress=False)
    assert not (tmp_path / "r").exists()


@pytest.mark.slow
def test_every_built_method_on_the_tiny_scene(tmp_path):
    scene_path = _tiny_scene(tmp_path)
    out = tmp_path / "report"
    code = _run(scene_path, out, tmp_path / "b.json", "--update-baseline",
                methods=list(fast_base.METHODS))
    assert code == 0
    data = _check_page(out)
    methods = data["scenes"]["tiny_sphere"]["methods"]
    assert set(methods) == set(fast_base.METHODS)
    for entry in methods.values():
        assert entry["status"] == "ok" or entry["reason"]


def test_two_scenes_of_one_name_are_refused_before_anything_runs(tmp_path, monkeypatch):
    # metrics.json and the baseline key results by scene name: one would hide the other
    def never():
        raise AssertionError("the run started with two scenes of one name")

    monkeypatch.setattr(report_module, "backend_versions", never)
    copy = tmp_path / "copy.toml"
    copy.write_text(TINY_SCENE)
    for scenes in ([_tiny_scene(tmp_path), copy], ["sphere", "sphere"]):
        with pytest.raises(InputError, match="scenes = .*two scenes are named"):
            make_report([str(s) for s in scenes], tmp_path / "r", methods=["prt"],
                        serial=True, progress=False)
    assert not (tmp_path / "r").exists()


def test_a_baseline_that_is_a_folder_is_refused_before_anything_runs(tmp_path, monkeypatch):
    def never():
        raise AssertionError("the run started with a folder as its baseline")

    monkeypatch.setattr(report_module, "backend_versions", never)
    for update in (True, False):
        with pytest.raises(InputError, match="--baseline = .*: is a folder"):
            make_report([str(_tiny_scene(tmp_path))], tmp_path / "r", methods=["prt"],
                        baseline=tmp_path, update_baseline=update, serial=True,
                        progress=False)
    assert not (tmp_path / "r").exists()


@pytest.mark.parametrize("value", [None, "0.1", float("nan"), True])
def test_a_baseline_with_a_gated_metric_that_is_not_a_number_is_refused_on_reading(tmp_path,
                                                                                   value):
    path = tmp_path / "baseline.json"
    path.write_text(json.dumps({"format": 1, "entries": {"sphere": {
        "scene_hash": "h", "reference": {"spp": 4, "passes": 2},
        "methods": {"prt": {"hdr_flip": value, "ssim": 0.9}}}}}))
    with pytest.raises(InputError, match=r"baseline.json: entries.sphere.methods.prt.hdr_flip "
                                         r"= .*: must be a finite number"):
        load_baseline(path)


def test_a_baseline_entry_that_is_not_an_object_is_refused_on_reading(tmp_path):
    path = tmp_path / "baseline.json"
    path.write_text(json.dumps({"format": 1, "entries": {"sphere": {"methods": ["prt"]}}}))
    with pytest.raises(InputError, match=r"entries.sphere.methods = \['prt'\]: must be"):
        load_baseline(path)
