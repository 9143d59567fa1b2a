"""Every ``translucent`` sub-command, once, through the installed console script.

Each command runs in a subprocess with its smallest valid input (a 16-pixel sphere, a
24-pixel capture, short chains), as a user types it; the check is its exit code, no
traceback, and what it wrote. The sub-commands are read from ``translucent --help``: one
that :data:`SMOKE_TESTS` does not name fails here, so a new command comes with its smoke
test. The benchmarks, each ``--quick``, are in ``test_bench_quick*.py``; ``capture`` and
``fit`` with every model in ``test_every_fit_model.py`` (a file of their own, so that the
two test processes share the runs).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from hostile import TINY_SPHERE
from smoke import listed, run_ok
from translucent.fast.registry import BUILTIN_METHODS, method
from translucent.scenes import load_scene

ROOT = Path(__file__).resolve().parents[2]
REFERENCE = ROOT / "reference" / "data" / "sphere.exr"
MODEL = ROOT / "reference" / "data" / "model" / "sphere.dipole.exr"

#: Each sub-command ``translucent --help`` lists -> the tests here that run it.
SMOKE_TESTS = {
    "doctor": ["test_doctor"],
    "scenes": ["test_scenes"],
    "profiles": ["test_profiles"],
    "render": ["test_render_with_every_integrator", "test_render_progressively"],
    "references": ["test_references"],
    "cache": ["test_cache"],
    "compare": ["test_compare"],
    "approx": ["test_approx_with_every_method"],
    "export": ["test_export"],
    "report": ["test_report"],
    "bench": ["test_bench_quick.py", "test_bench_quick_methods.py"],
    "stress": ["test_stress_only"],
    "fit": ["test_every_fit_model.py"],
    "capture": ["test_every_fit_model.py"],
    "capture-import": ["test_capture_import"],
}

def test_every_sub_command_has_a_smoke_test():
    commands = listed()
    assert "render" in commands and "capture-import" in commands
    assert sorted(commands) == sorted(SMOKE_TESTS)
    here = Path(__file__).parent
    for tests in SMOKE_TESTS.values():
        for test in tests:
            assert test in globals() or (here / test).is_file(), test


@pytest.fixture(scope="module")
def inputs(tmp_path_factory):
    """The small inputs: a 16-pixel sphere, a small glossy scene, a photo and its dark."""
    folder = tmp_path_factory.mktemp("smoke_inputs")
    (folder / "tiny.toml").write_text(TINY_SPHERE, encoding="utf-8")
    glossy = Path(load_scene("glossy").source).read_text(encoding="utf-8")
    (folder / "glossy.toml").write_text(
        glossy.replace("width = 96", "width = 16").replace("height = 72", "height = 12")
        .replace("subdivisions = 16", "subdivisions = 2"), encoding="utf-8")
    return folder


def test_doctor(tmp_path):
    shown = run_ok("doctor", cwd=tmp_path,
                   env={"TRANSLUCENT_BPY_PYTHON": str(tmp_path / "no_python")}).stdout
    assert "mitsuba" in shown and "variant" in shown
    assert "cycles not usable (TRANSLUCENT_BPY_PYTHON names" in shown


def test_scenes(tmp_path):
    listed_scenes = run_ok("scenes", cwd=tmp_path).stdout
    assert "sphere" in listed_scenes and "cornell_block" in listed_scenes


def test_profiles(tmp_path):
    assert "photon_beam_diffusion" in run_ok("profiles", cwd=tmp_path).stdout
    shown = run_ok("profiles", "--show", "dipole", "--medium", "Skin1", cwd=tmp_path).stdout
    assert "Skin1" in shown


@pytest.mark.parametrize("integrator", ["volpath", "volpathmis", "volpath_mnee", "path",
                                        "bssrdf_path"])
def test_render_with_every_integrator(inputs, tmp_path, integrator):
    from translucent.image import read_exr

    profile = ["--profile", "dipole"] if integrator == "bssrdf_path" else []
    # the path integrator refuses a scene with a medium: the glossy scene has none
    scene = inputs / ("glossy.toml" if integrator == "path" else "tiny.toml")
    run_ok("render", scene, "--spp", "1", "--passes", "2", "--integrator",
           integrator, *profile, "--no-cache", "-o", tmp_path / "r.exr", cwd=tmp_path)
    image = read_exr(tmp_path / "r.exr")
    assert image.rgb.shape[1] == 16 and np.isfinite(image.rgb).all()
    assert image.metadata["integrator"].startswith(integrator)


def test_render_progressively(inputs, tmp_path):
    result = run_ok("render", inputs / "tiny.toml", "--spp", "1", "--target-rse", "0.9",
                    "--budget", "20", "-o", tmp_path / "p.exr", cwd=tmp_path)
    assert (tmp_path / "p.exr").is_file() and "target" in result.stdout + result.stderr


def test_references(tmp_path):
    listed_references = run_ok("references", cwd=tmp_path).stdout
    assert "sphere" in listed_references and "current" in listed_references


def test_cache(tmp_path):
    assert "cache" in run_ok("cache", cwd=tmp_path).stdout.lower()


def test_compare(tmp_path):
    result = run_ok("compare", REFERENCE, MODEL, "--maps", tmp_path / "maps", "--metric",
                    "relative_mse", "--max", "1", cwd=tmp_path)
    assert "relative_mse" in result.stdout and list((tmp_path / "maps").glob("*.png"))


def _knob_flags(name) -> list[str]:
    flags = []
    for knob, value in (getattr(method(name), "QUICK_KNOBS", None) or {}).items():
        flags += [f"--{knob.replace('_', '-')}", str(value)]
    return flags


@pytest.mark.parametrize("name", sorted(BUILTIN_METHODS))
def test_approx_with_every_method(inputs, tmp_path, name):
    from translucent.image import read_exr

    scene = inputs / ("glossy.toml" if name == "brdf_pca" else "tiny.toml")
    own = ["--object", "sphere", "--gamma", "0.5"] if name == "brdf_pca" else []
    run_ok("approx", name, scene, *own, *_knob_flags(name), "-o", tmp_path / "a.exr",
           cwd=tmp_path)
    image = read_exr(tmp_path / "a.exr")
    assert np.isfinite(image.rgb).all() and image.rgb.max() > 0


def test_export(tmp_path):
    run_ok("export", "sphere", "--out", tmp_path / "x", cwd=tmp_path)
    assert list((tmp_path / "x").glob("*.xml"))
    # for Cycles: the description and the script that builds it (no bpy here: no .blend)
    result = run_ok("export", "bowl", "--format", "blender", "--mode", "burley", "--out",
                    tmp_path / "b", cwd=tmp_path,
                    env={"TRANSLUCENT_BPY_PYTHON": str(tmp_path / "no_python")})
    described = json.loads((tmp_path / "b" / "scene.json").read_text())
    assert [o["material"]["type"] for o in described["objects"]] == \
        ["subsurface", "diffuse", "diffuse"]
    assert (tmp_path / "b" / "build_cycles.py").is_file()
    assert "scene.blend" not in {p.name for p in (tmp_path / "b").iterdir()}
    assert "blender --background --python" in result.stdout


def test_report(inputs, tmp_path):
    # Cycles named where no bpy is: each of its modes says so, the method runs
    result = run_ok("report", inputs / "tiny.toml", "--methods", "splatting", "--serial",
                    "--spp", "2", "--passes", "2", "--out", tmp_path / "r",
                    "--renderers", "cycles.burley", "--renderer-spp", "2,8", cwd=tmp_path,
                    env={"TRANSLUCENT_BPY_PYTHON": str(tmp_path / "no_python")})
    metrics = json.loads((tmp_path / "r" / "metrics.json").read_text())
    assert (tmp_path / "r" / "index.html").is_file() and "splatting" in result.stdout
    methods = next(iter(metrics["scenes"].values()))["methods"]
    assert methods["splatting"]["status"] == "ok"
    assert methods["cycles.burley"]["status"] == "not installed"
    assert "no_python, which is not an executable" in methods["cycles.burley"]["reason"]


def test_stress_only(tmp_path):
    result = run_ok("stress", "--only", "Fresnel", "--json", tmp_path / "s.json", cwd=tmp_path)
    assert "Fresnel" in result.stdout
    assert json.loads((tmp_path / "s.json").read_text())


def test_capture_import(tmp_path):
    import tifffile
    from translucent.fitting.synthetic import Camera, dipole_capture
    from translucent.materials import measured_medium

    pixels, _ = dipole_capture(measured_medium("Skin1"), size=32, pixel_size_mm=0.2, seed=3,
                               camera=Camera(peak_signal=30000, black_level=0.0,
                                             saturation_level=1e9))
    tifffile.imwrite(tmp_path / "photo.tif", np.clip(np.rint(pixels + 100), 0, 65535)
                     .astype(np.uint16))
    # the spelling the documentation gives; the parser lists it as capture-import
    result = run_ok("capture", "import", tmp_path / "photo.tif", "--black-level", "100",
                    "--pixel-size-mm", "0.2", "--out", tmp_path / "c.json", cwd=tmp_path)
    assert (tmp_path / "c.json").is_file() and "translucent fit" in result.stdout
