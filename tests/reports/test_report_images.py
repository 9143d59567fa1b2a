"""``translucent report --images DIR``: another renderer's images scored like a method's."""

import json

import numpy as np
import OpenEXR
import pytest
from translucent.fast.conformance import tiny_sphere_text
from translucent.image import Image
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
