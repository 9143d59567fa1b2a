"""Other renderers scored like methods: ``report --images DIR`` and ``report --renderers``.

One file, so that one test process pays the first report's compiled kernels for both.
"""

import json
import types

import numpy as np
import OpenEXR
import pytest
from translucent.fast.conformance import tiny_sphere_text
from translucent.image import Image
from translucent.reference.peers import blender, registry
from translucent.reports.cli import main

#: The conformance checks' tiny skin sphere, at 24 x 24 pixels.
TINY_SCENE = tiny_sphere_text("tiny_images", 24)


def _report(tmp_path, images, *extra):
    scene = tmp_path / "tiny_images.toml"
    scene.write_text(TINY_SCENE)
    return main(["report", str(scene), "--images", str(images), "--out",
                 str(tmp_path / "report"), "--serial", "--no-progress", "--spp", "4",
                 "--passes", "2", "--baseline", str(tmp_path / "baseline.json"),
                 "--update-baseline", *extra])


def _foreign_exr(path, rgb, **header):
    """An EXR as another renderer writes one: no suite metadata, a float time attribute."""
    planes = {"RGB": np.ascontiguousarray(rgb, np.float32)}
    with OpenEXR.File({"compression": OpenEXR.ZIP_COMPRESSION,
                       "type": OpenEXR.scanlineimage, **header}, planes) as exr:
        exr.write(str(path))


def test_each_renderers_image_is_scored_with_its_header_time(tmp_path):
    images = tmp_path / "images"
    (images / "grey_renderer").mkdir(parents=True)
    (images / "foreign").mkdir()
    (images / "absent").mkdir()
    Image(np.full((24, 24, 3), 0.05, np.float32),
          metadata={"seconds": 0.25, "precompute_seconds": 3.0}).write(
        images / "grey_renderer" / "tiny_images.exr")
    _foreign_exr(images / "foreign" / "tiny_images.exr", np.full((24, 24, 3), 0.08),
                 renderTime=1.5)
    assert _report(tmp_path, images) == 0
    data = json.loads((tmp_path / "report" / "metrics.json").read_text())
    methods = data["scenes"]["tiny_images"]["methods"]
    assert set(methods) == {"absent", "foreign", "grey_renderer"}  # no fast method ran
    grey = methods["grey_renderer"]
    assert grey["status"] == "ok" and grey["metrics"]["relative_mse"] > 0
    assert grey["frame_seconds"] == 0.25 and grey["precompute_seconds"] == 3.0
    assert grey["noise"]["relative_mse"]["noise_floor"] > 0
    assert methods["foreign"]["frame_seconds"] == 1.5
    assert methods["absent"]["status"] == "not run"
    assert "no image" in methods["absent"]["reason"]
    assert "grey_renderer" in (tmp_path / "report" / "index.html").read_text()


@pytest.mark.parametrize("make, words", [
    (lambda images: None, "must be a folder"),
    (lambda images: images.mkdir(), "has no subfolder"),
    (lambda images: (images / "bad name!").mkdir(parents=True), "renderer's folder is named"),
    (lambda images: Image(np.ones((8, 8, 3), np.float32)).write(
        _made(images / "small") / "tiny_images.exr"), "the scene's camera is 24 x 24"),
    (lambda images: (_made(images / "broken") / "tiny_images.exr").write_text("not an exr"),
     "not a readable OpenEXR"),
])
def test_bad_image_folders_are_input_errors_and_write_nothing(tmp_path, capsys, make, words):
    images = tmp_path / "images"
    make(images)
    assert _report(tmp_path, images) == 2
    assert words in capsys.readouterr().err
    assert not (tmp_path / "report").exists()
    assert not (tmp_path / "baseline.json").exists()


def test_a_renderer_named_as_a_method_being_run_is_refused(tmp_path, capsys):
    images = tmp_path / "images"
    (images / "splatting").mkdir(parents=True)
    assert _report(tmp_path, images, "--methods", "splatting") == 2
    assert "rename the folder" in capsys.readouterr().err


def _made(folder):
    folder.mkdir(parents=True, exist_ok=True)
    return folder


def test_error_maps_hatch_the_pixels_the_numbers_do_not_count(tmp_path):
    # a map and the numbers beside it count the same pixels: the others are hatched grey
    import numpy as np
    from translucent.image import Image, read_exr
    from translucent.reports.metrics.compute import evaluate_on
    from translucent.reports.metrics.maps import NOT_SCORED_GREYS, write_error_maps

    rng = np.random.default_rng(3)
    reference = Image(rng.random((12, 16, 3)).astype(np.float32) + 0.5)
    test = Image(reference.rgb * 1.2)
    scored = np.zeros((12, 16), bool)
    scored[3:9, 4:12] = True
    comparison, on_pixels = evaluate_on(reference, test, [None, scored])
    files = write_error_maps(reference, test, tmp_path, comparison=comparison, scored=scored,
                             scored_metrics=on_pixels.metrics)
    import png

    width, height, rows, _ = png.Reader(filename=str(files["flip"].png)).asRGBA8()
    pixels = np.array([list(row) for row in rows], np.uint8).reshape(height, width, 4)[..., :3]
    outside = pixels[~scored]
    assert set(np.unique(outside).tolist()) <= set(NOT_SCORED_GREYS)
    assert (outside[:, 0] == outside[:, 1]).all() and (outside[:, 1] == outside[:, 2]).all()
    header = read_exr(files["flip"].exr).metadata
    assert header["scored_pixels"] == int(scored.sum())
    assert header["mean"] == pytest.approx(on_pixels.metrics.hdr_flip)


# ------------------------------------------------------------------ --renderers
PEERS_SCENE = tiny_sphere_text("tiny_peers", 16)


def _fake_render(scene, mode, spp_values, seed=0):
    if mode == "broken":
        return [{"spp": spp, "error": "RuntimeError: the fake renderer broke"}
                for spp in spp_values]
    if mode == "raises":
        raise TimeoutError("the fake renderer took too long")
    shape = (scene.camera.height, scene.camera.width, 3)
    return [{"spp": spp, "seconds": 0.01 * spp,
             "image": Image(np.full(shape, 0.05 + 0.1 / spp, np.float32),
                            metadata={"version": "fake 1.0"})}
            for spp in sorted(spp_values)]


FAKE = types.SimpleNamespace(
    NAME="fake",
    MODES={"plain": "a grey image", "refuses": "never applies", "broken": "always fails",
           "raises": "raises instead of returning"},
    available=lambda: None,
    applies_to=lambda scene, mode: "it has no light of that kind" if mode == "refuses"
    else None,
    model_of=lambda mode: None,
    render=_fake_render,
)


@pytest.fixture
def fake_renderer(monkeypatch):
    registry.register_renderer("fake", FAKE)
    # Cycles without bpy: its modes are "not installed", with the hint
    monkeypatch.setattr(blender, "bpy_python", lambda: None)
    yield
    registry.unregister_renderer("fake")


def _renderers_report(tmp_path, *extra):
    scene = tmp_path / "tiny_peers.toml"
    scene.write_text(PEERS_SCENE)
    return main(["report", str(scene), "--out", str(tmp_path / "report"), "--serial",
                 "--no-progress", "--spp", "4", "--passes", "2", "--baseline",
                 str(tmp_path / "baseline.json"), "--update-baseline", *extra])


def test_each_mode_is_scored_with_its_ladder_or_says_why_not(tmp_path, fake_renderer):
    assert _renderers_report(tmp_path, "--renderers", "fake,cycles.burley",
                   "--renderer-spp", "16,4,64") == 0
    data = json.loads((tmp_path / "report" / "metrics.json").read_text())
    methods = data["scenes"]["tiny_peers"]["methods"]
    assert set(methods) == {"fake.plain", "fake.refuses", "fake.broken", "fake.raises",
                            "cycles.burley"}
    plain = methods["fake.plain"]
    assert plain["status"] == "ok" and plain["knobs"] == {"spp": 64}
    assert plain["frame_seconds"] == pytest.approx(0.64)
    assert plain["metrics"]["relative_mse"] > 0
    # the cheaper counts are its ladder, each scored on the same pixels
    assert [p["knobs"]["spp"] for p in plain["ladder"]] == [4, 16]
    errors = [p["relative_mse"] for p in plain["ladder"]] + [plain["metrics"]["relative_mse"]]
    assert errors[0] != errors[1] != errors[2]
    assert "renders no model the suite knows" in plain["error_split"]["reason"]
    # a render without a variance: its brightness, not its converged error
    assert len(plain["systematic"]["brightness_to_reference"]["ratio"]) == 3
    assert "relative_mse_converged" not in plain["systematic"]
    assert methods["fake.refuses"]["status"] == "not applicable"
    assert methods["fake.refuses"]["reason"] == "it has no light of that kind"
    assert methods["fake.broken"]["status"] == "failed"
    assert "the fake renderer broke" in methods["fake.broken"]["reason"]
    # an exception is the entry's failure, named, not the report's
    assert methods["fake.raises"]["status"] == "failed"
    assert "TimeoutError: the fake renderer took too long" in methods["fake.raises"]["reason"]
    assert methods["cycles.burley"]["status"] == "not installed"
    assert "pip install bpy" in methods["cycles.burley"]["reason"]
    page = (tmp_path / "report" / "index.html").read_text()
    assert "fake.plain" in page and "Summed over its pixels, against the reference" in page


@pytest.mark.parametrize("extra, words", [
    (["--renderers", "nosuch"], "unknown renderer; known: cycles"),
    (["--renderers", "cycles.photon_map"], "cycles has no mode 'photon_map'"),
    (["--renderers", ","], "give at least one renderer"),
    (["--renderers", "cycles", "--renderer-spp", "0"], "between 1 and 1048576"),
    (["--renderers", "cycles", "--renderer-spp", "4,many"], "whole numbers"),
    (["--renderer-spp", "4,16"], "goes with --renderers"),
])
def test_bad_renderer_arguments_are_input_errors_and_write_nothing(tmp_path, capsys, extra,
                                                                    words):
    assert _renderers_report(tmp_path, *extra) == 2
    assert words in capsys.readouterr().err
    assert not (tmp_path / "report").exists()
    assert not (tmp_path / "baseline.json").exists()


def test_a_renderer_lacking_part_of_the_contract_is_named(fake_renderer):
    registry.register_renderer("half", types.SimpleNamespace(NAME="half", MODES={"a": "a"}))
    try:
        with pytest.raises(registry.InputError, match="lacks available"):
            registry.renderer_entries("half")
    finally:
        registry.unregister_renderer("half")


def test_the_suite_finds_cycles_through_its_entry_point():
    import importlib.metadata

    found = {e.name: e.value for e in
             importlib.metadata.entry_points(group=registry.RENDERER_GROUP)}
    assert found["cycles"] == "translucent.reference.peers.cycles"
    assert registry.renderer_entries("cycles") == [
        "cycles.burley", "cycles.random_walk", "cycles.random_walk_skin", "cycles.volume"]


def test_only_the_burley_mode_has_a_model_the_split_knows():
    from translucent.reports.report.split import split_profile

    assert split_profile("cycles.burley", None) == ("burley_cycles", "")
    model, reason = split_profile("cycles.random_walk", None)
    assert model is None and "renders no model the suite knows" in reason


def test_the_converged_error_discounts_both_images_noise():
    from translucent.reports.report.scoring import systematic_error

    rng = np.random.default_rng(7)
    truth = rng.uniform(5.0, 20.0, (64, 64, 3))

    def noisy(scale, sigma):
        return Image(truth * scale + rng.normal(0.0, sigma, truth.shape),
                     np.full(truth.shape, sigma ** 2))

    reference = noisy(1.0, 0.5)
    unbiased = systematic_error(reference, noisy(1.0, 1.0))
    converged = unbiased["relative_mse_converged"]
    # the raw relative MSE is about 1.25 / 150 = 0.008; its converged part is 0
    assert abs(converged["value"]) < 4.0 * converged["standard_error"]
    assert converged["standard_error"] < 0.1 * 1.25 / 150.0
    brighter = systematic_error(reference, noisy(1.05, 1.0))["relative_mse_converged"]
    # 5 % brighter: (0.05 r)^2 / (r^2 + eps) of relative MSE once the noise is discounted
    expected = np.mean((0.05 * truth) ** 2 / (truth ** 2 + 1e-2))
    assert abs(brighter["value"] - expected) < 4.0 * brighter["standard_error"]
    ratio = systematic_error(reference, noisy(1.05, 0.0))["brightness_to_reference"]
    np.testing.assert_allclose(ratio["ratio"], 1.05, atol=4.0 * max(ratio["standard_error"]))
