"""``bssrdf_path`` used like every reference: the command line, the API, the cache, export."""

import json

import numpy as np
import pytest
from translucent.image import read_exr
from translucent.reports.cli import main

pytest.importorskip("mitsuba")

SCENE = """
[scene]
name = "tiny translucent"
mm_per_unit = 10.0

[camera]
origin = [0.0, 0.0, 4.0]
target = [0.0, 0.0, 0.0]
fov = 40.0
width = 8
height = 6

[[objects]]
name = "ball"
mesh = { type = "icosphere", subdivisions = 2, radius = 1.0 }
material = { type = "measured", name = "Skin1", eta = 1.3 }

[[lights]]
type = "point"
position = [3.0, 4.0, 4.0]
intensity = 100.0
"""


@pytest.fixture
def scene_file(tmp_path, monkeypatch):
    from translucent.backend import mitsuba

    if not mitsuba().variant().startswith(("llvm_", "cuda_")):
        pytest.skip("bssrdf_path needs a JIT variant")
    monkeypatch.setenv("TRANSLUCENT_CACHE", str(tmp_path / "cache"))
    path = tmp_path / "tiny.toml"
    path.write_text(SCENE)
    return path


def test_render_names_the_profile_in_the_header(scene_file, tmp_path, capsys):
    out = tmp_path / "tiny.exr"
    assert main(["render", str(scene_file), "--integrator", "bssrdf_path", "--profile",
                 "better_dipole", "--spp", "4", "--passes", "2", "--out", str(out)]) == 0
    image = read_exr(out)
    meta = image.metadata
    assert meta["integrator"] == "bssrdf_path"
    assert meta["profile"]["name"] == "better_dipole"
    assert meta["profile"]["objects"] == {"ball": "better_dipole (Skin1)"}
    assert meta["variant"].startswith(("llvm_", "cuda_"))
    assert np.isfinite(image.rgb).all() and image.rgb.max() > 0
    assert "profile better_dipole (ball: better_dipole (Skin1))" in capsys.readouterr().out


def test_render_adds_the_objects_geometry_where_the_profile_asks(scene_file, tmp_path, capsys):
    out = tmp_path / "shaped.exr"
    assert main(["render", str(scene_file), "--integrator", "bssrdf_path", "--profile",
                 "dipole+geometry", "--spp", "4", "--passes", "2", "--out", str(out)]) == 0
    meta = read_exr(out).metadata
    assert meta["profile"]["name"] == "dipole" and meta["geometry"]["model"] == "diffusion"
    assert "profile dipole with the object's geometry" in capsys.readouterr().out
    # a Mitsuba file cannot carry it: export says so and writes nothing
    folder = tmp_path / "exported"
    assert main(["export", str(scene_file), "--integrator", "bssrdf_path", "--profile",
                 "dipole+geometry", "--out", str(folder)]) == 2
    assert "export --profile dipole" in capsys.readouterr().err
    assert not folder.exists()


def test_render_progressively_to_a_target(scene_file, tmp_path):
    out = tmp_path / "tiny.exr"
    assert main(["render", str(scene_file), "--integrator", "bssrdf_path", "--profile",
                 "dipole", "--spp", "4", "--target-rse", "0.5", "--out", str(out)]) == 0
    meta = read_exr(out).metadata
    assert meta["stopped"] == "target reached" and meta["profile"]["name"] == "dipole"


@pytest.mark.parametrize(("arguments", "message"), [
    (["--integrator", "bssrdf_path", "--profile", "dipol"],
     "profile = 'dipol': unknown profile; valid: dipole, better_dipole"),
    (["--integrator", "bssrdf_path"], "bssrdf_path needs a profile"),
    (["--profile", "dipole"], "goes with integrator bssrdf_path"),
])
def test_bad_profiles_exit_2_naming_the_file(scene_file, tmp_path, capsys, arguments, message):
    out = tmp_path / "x" / "tiny.exr"
    assert main(["render", str(scene_file), "--out", str(out), *arguments]) == 2
    error = capsys.readouterr().err
    assert message in error and str(scene_file) in error
    assert not out.parent.exists()


def test_the_api_renders_it_and_the_cache_keys_the_profile(scene_file):
    import translucent

    first = translucent.render(str(scene_file), integrator="bssrdf_path", profile="dipole",
                               spp=2, passes=2)
    again = translucent.render(str(scene_file), integrator="bssrdf_path", profile="dipole",
                               spp=2, passes=2)
    other = translucent.render(str(scene_file), integrator="bssrdf_path",
                               profile="better_dipole", spp=2, passes=2)
    assert again.metadata["scene_hash"] == first.metadata["scene_hash"]
    assert np.array_equal(again.rgb, first.rgb)  # from the cache
    assert other.metadata["scene_hash"] != first.metadata["scene_hash"]
    assert other.metadata["profile"]["name"] == "better_dipole"


def test_export_writes_the_tables_and_renders_the_same(scene_file, tmp_path, capsys):
    from translucent.backend import mitsuba
    from translucent.reference.mitsuba_export import register_suite_plugins
    from translucent.reference.mitsuba_scene import convert_scene
    from translucent.scenes import load_scene

    out = tmp_path / "export"
    assert main(["export", str(scene_file), "--integrator", "bssrdf_path", "--profile",
                 "better_dipole", "--out", str(out)]) == 0
    assert "bssrdf_path is a plugin of translucent" in capsys.readouterr().out
    xml = next(out.glob("*.xml"))
    text = xml.read_text()
    assert 'type="bssrdf_path"' in text and "profiles/" in text
    mi = mitsuba()
    register_suite_plugins()
    exported = np.array(mi.render(mi.load_file(str(xml)), spp=16, seed=3))
    scene = load_scene(scene_file)
    converted = mi.load_dict(convert_scene(scene, integrator="bssrdf_path",
                                           profile="better_dipole").scene_dict)
    direct = np.array(mi.render(converted, spp=16, seed=3))
    # the same scene, integrator and seed: the same samples
    assert np.allclose(exported, direct, rtol=1e-4, atol=1e-6)


@pytest.mark.slow  # volpath_mnee compiled: about 20 s here
def test_bench_reference_compares_bssrdf_path_with_volpath_mnee(scene_file, tmp_path, capsys):
    result = tmp_path / "bssrdf.json"
    assert main(["bench", "reference", "--scene", str(scene_file), "--bssrdf", "dipole",
                 "--spp", "2", "--passes", "2", "--size", "0", "--json", str(result)]) == 0
    figures = json.loads(result.read_text())
    assert set(figures["estimators"]) == {"bssrdf_path dipole", "volpath_mnee"}
    assert figures["estimators"]["volpath_mnee"]["efficiency_ratio"] == 1.0
    assert figures["target"]["cpu_seconds"] == 60.0
    assert "bssrdf_path at 60 CPU seconds" in capsys.readouterr().out


def test_render_a_solid_medium_by_a_rule_names_it_and_without_one_says_how(tmp_path, capsys,
                                                                          monkeypatch):
    from translucent.backend import mitsuba

    if not mitsuba().variant().startswith(("llvm_", "cuda_")):
        pytest.skip("bssrdf_path needs a JIT variant")
    monkeypatch.setenv("TRANSLUCENT_CACHE", str(tmp_path / "cache"))
    out = tmp_path / "solid.exr"
    assert main(["render", "solid_checker", "--integrator", "bssrdf_path", "--profile",
                 "dipole+segment_mix", "--spp", "2", "--passes", "2", "--out", str(out)]) == 0
    meta = read_exr(out).metadata
    assert meta["profile"]["name"] == "dipole+segment_mix"
    assert "mixed by segment_mix" in meta["profile"]["objects"]["sphere"]
    capsys.readouterr()
    assert main(["render", "solid_checker", "--integrator", "bssrdf_path", "--profile",
                 "dipole", "--spp", "2", "--passes", "2",
                 "--out", str(tmp_path / "none.exr")]) == 2
    error = capsys.readouterr().err
    assert "segment_mix" in error and "Traceback" not in error
    assert not (tmp_path / "none.exr").exists()
