"""``translucent render`` and ``translucent bench reference`` from the command line."""

import json

import numpy as np
import pytest
from translucent.image import read_exr
from translucent.reports.cli import main

SCENE = """
[scene]
name = "tiny"
mm_per_unit = 10.0

[camera]
origin = [0.0, 0.0, 4.0]
target = [0.0, 0.0, 0.0]
fov = 40.0
width = 8
height = 6

[[objects]]
name = "ball"
mesh = { type = "icosphere", subdivisions = 1, radius = 1.0 }
material = { type = "lambertian", albedo = 0.5 }

[[lights]]
type = "constant_env"
radiance = 1.0
"""


@pytest.fixture
def scene_file(tmp_path, monkeypatch):
    monkeypatch.setenv("TRANSLUCENT_CACHE", str(tmp_path / "cache"))
    path = tmp_path / "tiny.toml"
    path.write_text(SCENE)
    return path


def test_render_writes_the_exr_with_its_variance_and_metadata(scene_file, tmp_path, capsys):
    out = tmp_path / "out" / "tiny.exr"
    assert main(["render", str(scene_file), "--spp", "2", "--passes", "3", "--out",
                 str(out)]) == 0
    image = read_exr(out)
    assert image.shape == (6, 8)
    assert image.variance is not None
    assert image.metadata["spp"] == 2 and image.metadata["passes"] == 3
    assert image.metadata["integrator"] == "path"
    assert f"wrote {out}" in capsys.readouterr().out


def test_a_cache_without_room_is_a_warning_and_the_render_still_comes(scene_file, tmp_path,
                                                                       capsys, monkeypatch):
    import errno
    from pathlib import Path

    from translucent import image as image_module

    cache, write = tmp_path / "cache", image_module.write_exr

    def full_cache(path, image):
        if cache in Path(path).absolute().parents:
            raise OSError(errno.ENOSPC, "No space left on device")
        return write(path, image)

    monkeypatch.setattr(image_module, "write_exr", full_cache)
    out = tmp_path / "tiny.exr"
    assert main(["render", str(scene_file), "--spp", "1", "--passes", "2", "--out",
                 str(out)]) == 0
    assert read_exr(out).shape == (6, 8)
    err = capsys.readouterr().err
    assert "the cache cannot store" in err and "No space left" in err
    assert not [p for p in cache.rglob("*") if p.is_file() and p.suffix == ".exr"]


@pytest.mark.parametrize(("arguments", "message"), [
    (["no_such_scene"], "no such built-in scene"),
    (["{scene}", "--spp", "0"], "spp = 0: must be an integer >= 1"),
    (["{scene}", "--passes", "-2"], "passes = -2: must be an integer >= 1"),
    (["{scene}", "--out", "{tmp}/tiny.png"], "must be an OpenEXR file ending in .exr"),
    (["{scene}", "--integrator", "bdpt"], "invalid choice"),
])
def test_bad_input_exits_2_and_writes_nothing(scene_file, tmp_path, capsys, arguments,
                                             message):
    arguments = [a.format(scene=scene_file, tmp=tmp_path) for a in arguments]
    if "--out" not in arguments:
        arguments += ["--out", str(tmp_path / "result.exr")]
    assert main(["render", *arguments]) == 2
    assert message in capsys.readouterr().err
    assert not list(tmp_path.glob("*.exr")) and not list(tmp_path.glob("*.png"))


def test_bad_scene_file_exits_2(tmp_path, capsys):
    broken = tmp_path / "broken.toml"
    broken.write_text(SCENE.replace("fov = 40.0", "fov = 40.0\nzoom = 2"))
    assert main(["render", str(broken), "--out", str(tmp_path / "x.exr")]) == 2
    assert "zoom" in capsys.readouterr().err
    assert not (tmp_path / "x.exr").exists()


@pytest.mark.slow  # three integrators compiled: about 11 s here
def test_bench_reference_compares_integrators(scene_file, tmp_path):
    result = tmp_path / "integrators.json"
    assert main(["bench", "reference", "--scene", str(scene_file), "--integrators", "skin1",
                 "--spp", "1", "--passes", "2", "--size", "0", "--json", str(result)]) == 0
    estimators = json.loads(result.read_text())["estimators"]
    assert set(estimators) == {"volpath", "volpathmis", "per-channel volpath"}
    assert estimators["volpath"]["efficiency_ratio"] == 1.0


def test_bench_reference_refuses_bad_counts(scene_file, tmp_path, capsys):
    assert main(["bench", "reference", "--scene", str(scene_file), "--repeats", "0",
                 "--json", str(tmp_path / "b.json")]) == 2
    assert "--repeats = 0: must be >= 1" in capsys.readouterr().err
    assert not (tmp_path / "b.json").exists()


def test_an_output_folder_is_refused_before_rendering(scene_file, tmp_path, capsys,
                                                      monkeypatch):
    import translucent.reference

    def render(*args, **kwargs):
        raise AssertionError("rendered before the output path was checked")

    monkeypatch.setattr(translucent.reference, "render", render)
    (tmp_path / "folder.exr").mkdir()
    assert main(["render", str(scene_file), "--out", str(tmp_path / "folder.exr")]) == 2
    assert "--out = " in capsys.readouterr().err
    assert not any((tmp_path / "folder.exr").iterdir())


@pytest.mark.parametrize(("flags", "expected"), [([], None), (["--per-channel"], True),
                                                 (["--no-per-channel"], False)])
def test_per_channel_is_left_to_the_reference_unless_asked(scene_file, tmp_path, monkeypatch,
                                                          flags, expected):
    import translucent.reference
    from translucent.image import Image

    seen = {}

    def render(scene, **kwargs):
        seen.update(kwargs)
        return Image(np.zeros((6, 8, 3)), None, {"spp": 1, "passes": 1, "integrator": "path",
                                                 "seconds": 0.0})

    monkeypatch.setattr(translucent.reference, "render", render)
    assert main(["render", str(scene_file), *flags, "--out", str(tmp_path / "x.exr")]) == 0
    assert seen["per_channel"] is expected


def test_an_output_folder_that_cannot_be_made_is_refused_before_rendering(scene_file, tmp_path,
                                                                         capsys, monkeypatch):
    import translucent.reference

    def render(*args, **kwargs):
        raise AssertionError("rendered before the output folder was checked")

    monkeypatch.setattr(translucent.reference, "render", render)
    (tmp_path / "plain_file").write_text("not a folder")
    out = tmp_path / "plain_file" / "x.exr"
    assert main(["render", str(scene_file), "--out", str(out)]) == 2
    assert f"--out = '{out}': cannot create the output folder" in capsys.readouterr().err
