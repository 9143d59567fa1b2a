"""Blender Cycles against the suite's references (reference/peers/blender.py).

The renders need a Python with ``bpy`` (the ``peers`` extra, in an environment of its own:
``python3.11 -m venv peers && peers/bin/pip install bpy``, then
``TRANSLUCENT_BPY_PYTHON=peers/bin/python``); without it they are skipped with that hint.
The description checks need nothing.
"""

from __future__ import annotations

import dataclasses
import json
import math
import os

import numpy as np
import pytest
from translucent.errors import InputError
from translucent.materials import Dipole, Lambertian, measured_medium
from translucent.reference.peers import blender
from translucent.scenes import (
    Camera,
    ConstantEnvironment,
    DirectionalLight,
    ImageEnvironment,
    PointLight,
    RectangularAreaLight,
    Scene,
    SceneObject,
    SphereAreaLight,
    SpotLight,
)
from translucent.scenes.meshes import icosphere

#: Standard errors at most between the two renderers' sums over the image, per channel.
Z_LIMIT = 4.0


def _sphere(material, size=24, lights=None):
    """The `sphere` scene's set-up: a sphere of radius 10 mm under a point light."""
    camera = Camera(origin=[0.0, 0.0, 5.0], target=[0.0, 0.0, 0.0], fov=30.0, width=size,
                    height=size)
    lights = [PointLight([3.0, 4.0, 4.0], 100.0)] if lights is None else lights
    return Scene([SceneObject("sphere", icosphere(4, 1.0), material)], lights, camera,
                 mm_per_unit=10.0, name="sphere")


SKIN1 = dataclasses.replace(measured_medium("Skin1"), eta=1.0)


# ----------------------------------------------------------------- the description
def _described(scene, mode="volume"):
    return blender.describe_scene(scene, renders=[(8, 0), (8, 1)], output="x", mode=mode)


def test_the_description_gives_coefficients_per_scene_unit():
    medium = Dipole(sigma_a=[0.1, 0.2, 0.3], sigma_s_prime=[1.0, 2.0, 3.0], eta=1.0, g=0.5)
    described = _described(_sphere(medium))
    (item,) = described["objects"]
    # mm^-1 x 10 mm per unit; sigma_s = sigma_s' / (1 - g)
    np.testing.assert_allclose(item["material"]["sigma_s"], [20.0, 40.0, 60.0])
    np.testing.assert_allclose(item["material"]["sigma_a"], [1.0, 2.0, 3.0])
    assert item["material"]["g"] == 0.5 and item["material"]["ior"] == 1.0
    (light,) = described["lights"]
    np.testing.assert_allclose(light["energy"], [400.0 * math.pi] * 3)
    assert described["camera"]["fov_x_degrees"] == 30.0
    assert described["renders"] == [{"samples": 8, "seed": 0}, {"samples": 8, "seed": 1}]


def test_subsurface_modes_get_the_radius_cycles_divides_into_the_mean_free_path():
    from translucent.materials.profiles.random_walk import RandomWalkProfile

    medium = measured_medium("Skin1")  # eta 1.3
    for mode, method in blender.SUBSURFACE_METHODS.items():
        (item,) = _described(_sphere(medium), mode)["objects"]
        material = item["material"]
        assert material["type"] == "subsurface" and material["method"] == method
        # Cycles' radius / (4 pi) is the reduced mean free path: 1/sigma_t' in units of 10 mm
        sigma_t = medium.sigma_a + medium.sigma_s_prime
        np.testing.assert_allclose(np.array(material["radius"]) / (4.0 * math.pi),
                                   1.0 / (10.0 * sigma_t))
        np.testing.assert_allclose(material["base_color"], RandomWalkProfile(medium).total())
        assert material["ior"] == 1.3 and material["anisotropy"] == medium.g


def _frame(matrix):
    matrix = np.asarray(matrix)
    assert matrix.shape == (4, 4)
    rotation = matrix[:3, :3]
    np.testing.assert_allclose(rotation.T @ rotation, np.eye(3), atol=1e-12)
    assert np.linalg.det(rotation) == pytest.approx(1.0)  # a rotation, not a reflection
    return rotation, matrix[:3, 3]


def test_every_light_gets_the_power_cycles_units_need():
    lights = [SphereAreaLight([0.0, 3.0, 0.0], 0.5, 2.0),
              SpotLight([0.0, 4.0, 0.0], [0.0, -1.0, 0.0], 10.0, cutoff_angle=30.0,
                        beam_width=20.0),
              RectangularAreaLight([0.0, 2.0, 0.0], [0.5, 0.0, 0.0], [0.0, 0.0, 0.25], 3.0),
              DirectionalLight([0.0, -1.0, -1.0], [1.0, 2.0, 3.0]),
              ConstantEnvironment(0.7)]
    sphere_light, spot, rect, sun, world = _described(_sphere(Lambertian(0.5),
                                                              lights=lights))["lights"]
    # a sphere of radiance L and radius r: P = 4 pi^2 r^2 L
    assert sphere_light["radius"] == 0.5
    np.testing.assert_allclose(sphere_light["energy"], [4.0 * math.pi ** 2 * 0.25 * 2.0] * 3)
    rotation, origin = _frame(spot["matrix"])
    np.testing.assert_allclose(-rotation[:, 2], [0.0, -1.0, 0.0], atol=1e-12)
    np.testing.assert_allclose(origin, [0.0, 4.0, 0.0])
    np.testing.assert_allclose(spot["energy"], [40.0 * math.pi] * 3)
    assert spot["cutoff"] == pytest.approx(math.radians(30.0))
    assert spot["beam_width"] == pytest.approx(math.radians(20.0))
    rotation, _ = _frame(rect["matrix"])
    # Cycles emits along the local -z: the suite's cross(u, v), here -y (down)
    np.testing.assert_allclose(-rotation[:, 2], np.cross([0.5, 0, 0], [0, 0, 0.25]) /
                               0.125, atol=1e-12)
    assert (rect["size_x"], rect["size_y"]) == (1.0, 0.5)
    np.testing.assert_allclose(rect["energy"], [math.pi * 0.5 * 3.0] * 3)  # L pi A
    rotation, _ = _frame(sun["matrix"])
    np.testing.assert_allclose(-rotation[:, 2], np.array([0.0, -1.0, -1.0]) / math.sqrt(2.0),
                               atol=1e-12)
    assert sun["strength"] == [1.0, 2.0, 3.0]
    assert world == {"type": "environment", "radiance": [0.7, 0.7, 0.7]}


def test_what_cycles_is_not_given_is_named():
    from translucent.materials.brdfs import AnalyticBRDF
    from translucent.scenes import load_scene

    cases = [
        (_sphere(AnalyticBRDF("ward", 0.2, rho_s=0.5, rho_d=0.3)), "objects[0].material"),
        (load_scene("heterogeneous"), "objects[0].material"),
        (_sphere(Lambertian(0.5), lights=[ImageEnvironment(np.ones((4, 8, 3)))]),
         "lights[0]"),
        (_sphere(Lambertian(0.5), lights=[RectangularAreaLight(
            [0.0, 2.0, 0.0], [0.5, 0.0, 0.0], [0.3, 0.0, 0.25], 1.0)]), "lights[0].v_axis"),
    ]
    for scene, field in cases:
        with pytest.raises(InputError) as caught:
            _described(scene)
        assert caught.value.field == field
    with pytest.raises(InputError) as caught:
        _described(_sphere(Lambertian(0.5)), mode="photon_map")
    assert caught.value.field == "mode"


def test_without_bpy_the_error_says_how_to_install_it(monkeypatch):
    monkeypatch.delenv(blender.BPY_PYTHON_VARIABLE, raising=False)
    monkeypatch.setattr(blender.importlib.util, "find_spec", lambda name: None)
    with pytest.raises(InputError, match="pip install bpy"):
        blender.render_cycles(_sphere(Lambertian(0.5)), spp=1, passes=2)


# ----------------------------------------------------------------- the renders
def _python():
    python = blender.bpy_python()
    if python is None:
        pytest.skip(blender.INSTALL_HINT)
    return python


def _sums(image):
    total = image.rgb.astype(np.float64).sum(axis=(0, 1))
    return total, np.sqrt(image.variance.astype(np.float64).sum(axis=(0, 1)))


def _ratio(first, second):
    (a, sa), (b, sb) = _sums(first), _sums(second)
    ratio = a / b
    return ratio, ratio * np.hypot(sa / a, sb / b)


@pytest.mark.slow  # about 40 s on 2 cores
def test_cycles_agrees_with_the_reference_on_the_skin1_sphere():
    """Light units calibrated on a Lambertian sphere, then the volumetric Skin1 sphere.

    Cycles offsets no rays at surfaces, so it would see the shell of medium that Mitsuba's
    float32 offset skipped before the rendering frame (scenes/frame.py).
    """
    from translucent.reference import render

    python = _python()
    lambertian = _sphere(Lambertian(0.5), size=16)
    calibration, calibration_error = _ratio(
        blender.render_cycles(lambertian, spp=256, passes=8, python=python),
        render(lambertian, spp=256, passes=8, cache=False, progress=False))
    # Cycles' point light of 4 pi I watts is the suite's intensity I
    assert np.all(np.abs(calibration - 1.0) < Z_LIMIT * calibration_error), calibration
    skin = _sphere(SKIN1, size=16)
    ratio, error = _ratio(blender.render_cycles(skin, spp=1024, passes=16, python=python),
                          render(skin, spp=1024, passes=16, cache=False, progress=False,
                                 per_channel=True))
    ratio, error = ratio / calibration, np.hypot(error, ratio * calibration_error)
    assert np.all(np.abs(ratio - 1.0) < Z_LIMIT * error), (ratio, error)
    # and the check resolves the old shell: 0.01x units lost 12 % of blue
    assert np.all(error < 0.01), error


def _light_cases():
    return {
        "sphere light": SphereAreaLight([3.0, 4.0, 4.0], 0.5, 20.0),
        # the sphere (9 degrees seen from the light) inside the beam
        "spot": SpotLight([3.0, 4.0, 4.0], [-3.0, -4.0, -4.0], 100.0, cutoff_angle=40.0,
                          beam_width=30.0),
        # the sphere (9 degrees seen from the light) across the ramp from 3 to 8 degrees
        "spot penumbra": SpotLight([3.0, 4.0, 4.0], [-3.0, -4.0, -4.0], 100.0,
                                   cutoff_angle=8.0, beam_width=3.0),
        "rectangle": RectangularAreaLight([0.0, 3.0, 1.0], [0.5, 0.0, 0.0], [0.0, 0.0, 0.5],
                                          20.0),
        # behind the sphere, facing the camera: the emitter seen as well as its light
        "rectangle seen": RectangularAreaLight([1.5, 0.0, -3.0], [0.4, 0.0, 0.0],
                                               [0.0, 0.4, 0.0], 2.0),
        "sphere light seen": SphereAreaLight([0.9, 0.9, -2.0], 0.4, 5.0),
        "sun": DirectionalLight([-0.5, -1.0, -0.5], 3.0),
        "constant environment": ConstantEnvironment(1.0),
    }


@pytest.mark.slow  # about 10 s a light on 2 cores
@pytest.mark.parametrize("kind", list(_light_cases()))
def test_every_light_type_calibrates_on_a_lambertian_sphere(kind):
    """Cycles' light given as :func:`describe_scene` converts it equals the suite's light."""
    from translucent.reference import render

    python = _python()
    scene = _sphere(Lambertian(0.5), size=16, lights=[_light_cases()[kind]])
    # an emitter seen: its edges' pixels, partly covered, are most of the sums' noise
    spp = 2048 if kind.endswith("seen") else 256
    ratio, error = _ratio(blender.render_cycles(scene, spp=spp, passes=8, python=python),
                          render(scene, spp=spp, passes=8, cache=False, progress=False))
    assert np.all(np.abs(ratio - 1.0) < Z_LIMIT * error), (kind, ratio, error)
    assert np.all(error < 0.01), error  # the check resolves a 4 % error


#: Cycles' Burley mode over the profile it evaluates (burley_cycles) rendered exactly, on
#: the index-matched Skin1 sphere, R G B: the disk-probe estimator's brightening (a model
#: of the estimator gives 1.0607 / 1.0455 / 1.0296; docs/peers.md).
BURLEY_BRIGHTENING = (1.0607, 1.0455, 1.0296)


@pytest.mark.slow  # about 60 s on 2 cores
def test_cycles_burley_is_brighter_than_its_profile_on_a_curved_surface():
    from translucent.reports.report.runs import render_reference
    from translucent.reports.report.split import brightness_ratio

    python = _python()
    skin = _sphere(SKIN1, size=48)
    cycles = blender.render_cycles(skin, spp=256, passes=4, mode="burley", python=python)
    model = render_reference(skin, 32, 32, profile="burley_cycles")
    found = brightness_ratio(cycles, model)
    ratio, error = np.array(found["ratio"]), np.array(found["standard_error"])
    assert np.all(error < 0.003), error
    np.testing.assert_allclose(ratio, BURLEY_BRIGHTENING, atol=0.01)


def test_export_refuses_a_scene_cycles_is_not_given_and_writes_nothing(tmp_path, capsys):
    from translucent.reports.cli import main

    assert main(["export", "glossy", "--format", "blender", "--out",
                 str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert "objects[0].material" in err and "no Ward, Blinn-Phong" in err
    assert not (tmp_path / "out").exists()


def test_a_solid_medium_is_its_grid_in_the_volume_and_its_voxel_per_face_in_subsurface():
    from translucent.scenes import load_scene

    scene = load_scene("solid_checker")
    solid = scene.objects[0].material
    (volume,) = _described(scene)["objects"]
    np.testing.assert_allclose(volume["material"]["sigma_s"],
                               solid.sigma_s_prime * scene.mm_per_unit, rtol=1e-6)
    np.testing.assert_allclose(volume["material"]["sigma_a"],
                               solid.sigma_a * scene.mm_per_unit, rtol=1e-6)
    assert volume["material"]["bounds"] == solid.bounds.tolist()
    (surface,) = _described(scene, "random_walk")["objects"]
    material = surface["material"]
    mesh = scene.objects[0].mesh
    assert material["face_radius"].shape == material["face_base_color"].shape == \
        (len(mesh.faces), 3)
    # a checker of two media: two radii, each that of the voxel under the face's centroid
    sigma_a, sigma_s = solid.coefficients_at(mesh.vertices[mesh.faces].mean(axis=1))
    np.testing.assert_allclose(material["face_radius"],
                               4.0 * math.pi / ((sigma_a + sigma_s) * 10.0), rtol=1e-6)
    assert len(np.unique(material["face_radius"], axis=0)) == 2


def test_the_arrays_of_a_description_are_written_beside_it(tmp_path):
    from translucent.scenes import load_scene

    described = _described(load_scene("solid_checker"))
    path = blender.write_description(described, tmp_path)
    written = json.loads(path.read_text())
    name = written["objects"][0]["material"]["sigma_s"]["npy"]
    np.testing.assert_array_equal(np.load(tmp_path / name),
                                  described["objects"][0]["material"]["sigma_s"])


@pytest.mark.slow  # about 60 s on 2 cores
def test_the_report_scores_every_cycles_mode_through_the_command(tmp_path):
    """``translucent report --renderers cycles``, as a user types it, on a 24-pixel sphere."""
    import subprocess
    import sys
    from pathlib import Path

    from translucent.fast.conformance import tiny_sphere_text

    python = _python()
    scene = tmp_path / "tiny_cycles.toml"
    scene.write_text(tiny_sphere_text("tiny_cycles", 24).replace('name = "Skin1"',
                                                                 'name = "Skin1", eta = 1.0'))
    script = Path(sys.executable).with_name("translucent")
    done = subprocess.run([str(script), "report", str(scene), "--renderers", "cycles",
                           "--renderer-spp", "4,32", "--spp", "16", "--passes", "4",
                           "--out", str(tmp_path / "r"), "--no-progress"],
                          capture_output=True, text=True, timeout=600,
                          env={**os.environ, blender.BPY_PYTHON_VARIABLE: python})
    assert done.returncode == 0, done.stderr[-2000:]
    assert "Traceback" not in done.stderr + done.stdout
    methods = json.loads((tmp_path / "r" / "metrics.json").read_text())[
        "scenes"]["tiny_cycles"]["methods"]
    assert sorted(methods) == ["cycles.burley", "cycles.random_walk",
                               "cycles.random_walk_skin", "cycles.volume"]
    for entry in methods.values():
        assert entry["status"] == "ok" and entry["metrics"]["relative_mse"] > 0
        assert [p["knobs"]["spp"] for p in entry["ladder"]] == [4]
    split = methods["cycles.burley"]["error_split"]
    assert split["profile"] == "burley_cycles" and split["reason"] is None
    assert len(split["brightness_to_model"]["ratio"]) == 3
