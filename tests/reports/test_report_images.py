"""``translucent report --images DIR``: another renderer's images scored like a method's."""

import json
import textwrap

import numpy as np
import OpenEXR
import pytest
from translucent.image import Image
from translucent.reports.cli import main

TINY_SCENE = textwrap.dedent("""
    [scene]
    name = "tiny_images"
    mm_per_unit = 10.0

    [camera]
    origin = [0.0, 0.0, 5.0]
    target = [0.0, 0.0, 0.0]
    fov = 30.0
    width = 24
    height = 24

    [[objects]]
    name = "sphere"
    mesh = { type = "icosphere", subdivisions = 2, radius = 1.0 }
    material = { type = "measured", name = "Skin1" }

    [[lights]]
    type = "point"
    position = [3.0, 4.0, 4.0]
    intensity = 100.0
""")


def _report(tmp_path, images, *extra):
    scene = tmp_path / "tiny_images.toml"
    scene.write_text(TINY_SCENE)
    return main(["report", str(scene), "--images", str(images), "--out",
                 str(tmp_path / "report"), "--serial", "--no-progress", "--spp", "16",
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
