"""The method contract: the conformance checks over every registered method, and the registry.

Every method of :data:`translucent.fast.registry.METHODS` (the four built-in ones, found
through their entry points) runs every check of :mod:`translucent.fast.conformance`; broken
stand-ins show that each check can fail; the example method of ``examples/lambert_method``
is installed as a distribution of its own and scored by the report.
"""

import json
import os
import shutil
import subprocess
import sys
import textwrap
import types
from pathlib import Path

import numpy as np
import pytest
from translucent.errors import InputError
from translucent.fast import conformance, registry
from translucent.fast.base import Refusal, StageLog, refusal_of, with_defaults
from translucent.fast.conformance import CHECKS, ConformanceFailure, NotChecked, run_check
from translucent.fast.registry import (
    METHODS,
    EntryPointTarget,
    MethodContractError,
    contract_problems,
    method,
    register_method,
    unregister_method,
)
from translucent.image import Image
from translucent.reports.cli import main

REPOSITORY = Path(__file__).resolve().parents[2]
EXAMPLE = REPOSITORY / "examples" / "lambert_method"
BUILTIN = ("prt", "radiosity", "splatting", "brdf_pca")


# ------------------------------------------------------------------ every registered method


#: The profile check runs once per profile below (seconds apiece), not as one long test.
PER_PROFILE = "profiles"


def _declared_profiles() -> list[tuple[str, str]]:
    """(method, profile) for every profile a registered method takes or refuses."""
    cases = []
    for name in METHODS:
        try:
            knob = conformance.profile_knob_of(method(name))
        except InputError:  # not installed: the check of every method says why
            continue
        if knob is not None:
            cases += [(name, profile) for profile in knob.choices]
            cases += [(name, profile) for profile, _ in knob.refused]
    return cases


#: Built-in methods a check does not apply to, and why.
NOT_APPLICABLE = {
    ("brdf_pca", "geometry"): "BRDF editing has no subsurface profile",
    # its S carries the object's diffusion escape as an energy gain of its own
    # (finite_object_energy, fast/radiosity/diffusion_escape.py), not the shared correction
    ("radiosity", "geometry"): "radiosity's geometry is its knob finite_object_energy",
}


@pytest.mark.parametrize("check", [c for c in CHECKS if c != PER_PROFILE])
@pytest.mark.parametrize("name", list(METHODS))
def test_every_registered_method_passes_every_check(name, check):
    try:
        found = run_check(name, check)
    except NotChecked as why:
        if (name, check) in NOT_APPLICABLE:
            pytest.skip(NOT_APPLICABLE[name, check])
        if name in BUILTIN:  # each built-in method has something to check in each
            pytest.fail(f"{name}: {check} checked nothing: {why}")
        pytest.skip(str(why))
    assert isinstance(found, str) and found


@pytest.mark.parametrize("name, profile", _declared_profiles())
def test_every_declared_profile_is_taken_and_used_or_refused_by_name(name, profile):
    found = conformance.run_profile_check(name, profile)
    assert profile in found


def test_the_builtin_methods_declare_the_profiles_they_take():
    for name in ("prt", "radiosity", "splatting"):
        knob = conformance.profile_knob_of(method(name))
        assert knob.default == "dipole" and knob.kind == "choice"
        assert "directional_dipole" in dict(knob.refused)  # as its radial average only
        assert "directional_dipole_average" in knob.choices
    with pytest.raises(NotChecked, match="no profile knob"):
        run_check("brdf_pca", PER_PROFILE)


def test_the_builtin_methods_are_found_through_their_entry_points():
    for name in BUILTIN:
        assert isinstance(METHODS[name], EntryPointTarget)
        assert METHODS[name].distribution == "translucent"
        assert METHODS[name].value == f"translucent.fast.{name}"
    assert list(METHODS)[:4] == list(BUILTIN)


# ----------------------------------------------------------------- each check can fail


def _stand_in(render=None, knobs=None, defaults=None, **attributes):
    """A method whose frame is ``render(scene, lights, material, calls)`` (pixels).

    ``knobs={}`` makes a precompute that takes any knob (a broken one).
    """
    defaults = ({"grey": 0.1} if knobs is None else knobs) if defaults is None else defaults
    calls = {"precompute": 0}

    class State:
        def __init__(self, scene):
            self.scene, self.lights, self.material = scene, scene.lights, None
            self.log = StageLog()

        def render(self, lights=None, material=None):
            self.lights = self.lights if lights is None else lights
            self.material = self.material if material is None else material
            camera = self.scene.camera
            pixels = render(self.scene, self.lights, self.material, calls) if render else \
                np.full((camera.height, camera.width, 3), 0.1)
            return Image(np.asarray(pixels, np.float32))

    def precompute(scene, **given):
        calls["precompute"] += 1
        if knobs is None:
            with_defaults(given, defaults)
        return State(scene)

    return types.SimpleNamespace(DEFAULT_KNOBS=defaults, applies_to=lambda scene: None,
                                 precompute=precompute, **attributes)


def _lit(scene, lights, material, calls):
    """Pixels proportional to the first light's x position (a stand-in for shading)."""
    camera = scene.camera
    return np.full((camera.height, camera.width, 3), 1.0 + lights[0].position[0])


@pytest.fixture
def registered():
    names = []

    def add(name, target):
        register_method(name, target)
        names.append(name)
        return name

    yield add
    for name in names:
        unregister_method(name)


def test_a_method_that_follows_the_contract_passes(registered):
    name = registered("good_stand_in", _stand_in(_lit))
    assert run_check(name, "relighting").startswith("relit against precomputed")
    assert run_check(name, "knobs").startswith("an unknown knob is refused")


@pytest.mark.parametrize("check, broken, words", [
    # a state that keeps the first frame's lights
    ("relighting", lambda: _stand_in(lambda s, lights, m, c: _lit(s, s.lights, m, c)),
     "the new lights were not used"),
    # a precompute that accepts any knob
    ("knobs", lambda: _stand_in(knobs={}), "accepted the unknown knob"),
    # a NaN in the image
    ("render", lambda: _stand_in(lambda s, *a: np.full((s.camera.height, s.camera.width, 3),
                                                       np.nan)), "not finite"),
    # negative radiance
    ("render", lambda: _stand_in(lambda s, *a: -np.ones((s.camera.height, s.camera.width,
                                                         3))), "negative radiance"),
    # the wrong size
    ("render", lambda: _stand_in(lambda s, *a: np.ones((3, 5, 3))), "the camera's size"),
    # a black frame
    ("render", lambda: _stand_in(lambda s, *a: np.zeros((s.camera.height, s.camera.width,
                                                         3))), "black"),
    # a different image at every precomputation
    ("determinism", lambda: _stand_in(lambda s, lights, m, calls: np.full(
        (s.camera.height, s.camera.width, 3), float(calls["precompute"]))),
     "two precomputations"),
    # an edit that is ignored
    ("editing", lambda: _stand_in(lambda s, lights, material, c: np.full(
        (s.camera.height, s.camera.width, 3),
        float(s.object("sphere").material.sigma_a[0]))), "relative L2 difference"),
])
def test_each_check_fails_on_a_method_that_breaks_it(registered, check, broken, words):
    name = registered(f"broken_{check}", broken())
    with pytest.raises(ConformanceFailure, match=words):
        run_check(name, check)


def _profiled(used=True, validated=True):
    """A stand-in with a ``profile`` knob whose frame depends on it (unless not ``used``)."""
    from translucent.fast.knobs import KnobSpec, profile_knob

    spec = KnobSpec([profile_knob({"better_dipole": Refusal("unsupported_profile",
                                                            "better_dipole is not taken")},
                                  keyed=True, help="a profile")])
    choices = spec["profile"].choices
    given = {}

    def render(scene, lights, material, calls):
        level = 0.1 + 0.01 * (choices.index(given["profile"]) if used else 0)
        return np.full((scene.camera.height, scene.camera.width, 3), level)

    stand_in = _stand_in(render, defaults=spec.defaults, KNOBS=spec)
    precompute = stand_in.precompute

    def checked(scene, **knobs):
        given.update(spec.resolve(knobs) if validated else spec.defaults | knobs)
        return precompute(scene, **knobs)

    stand_in.precompute = checked
    return stand_in


def test_the_profile_check_passes_a_method_that_uses_its_profiles(registered):
    name = registered("profiled", _profiled())
    assert "from the default's" in conformance.run_profile_check(name, "random_walk")
    assert "is refused: better_dipole is not taken" in conformance.run_profile_check(
        name, "better_dipole")


@pytest.mark.parametrize("broken, profile, words", [
    (lambda: _profiled(used=False), "random_walk", "renders the default profile's image"),
    (lambda: _profiled(validated=False), "better_dipole", "declared refused.*took it"),
])
def test_the_profile_check_fails_a_method_that_breaks_it(registered, broken, profile, words):
    name = registered("broken_profiles", broken())
    with pytest.raises(ConformanceFailure, match=words):
        conformance.run_profile_check(name, profile)


def test_moving_lights_that_change_nothing_is_not_checked(registered):
    name = registered("unlit_stand_in", _stand_in())
    with pytest.raises(NotChecked, match="does not change"):
        run_check(name, "relighting")


def test_check_method_names_the_method_and_the_check(registered):
    name = registered("leaky_knobs", _stand_in(_lit, knobs={}))
    with pytest.raises(ConformanceFailure, match="leaky_knobs: knobs: precompute accepted"):
        conformance.check_method(name)


# ---------------------------------------------------------------------------- the registry


def test_register_method_checks_the_name_and_the_contract():
    with pytest.raises(InputError, match="lower-case letters"):
        register_method("My Method", _stand_in())
    with pytest.raises(MethodContractError, match="precompute: missing"):
        register_method("half_a_method", types.SimpleNamespace(DEFAULT_KNOBS={},
                                                               applies_to=len))
    with pytest.raises(InputError, match="dotted name"):
        register_method("bad_module", "not a module")
    with pytest.raises(InputError, match="unknown fast method"):
        unregister_method("never_registered")


def test_contract_problems_name_each_part():
    problems = contract_problems(types.SimpleNamespace(
        DEFAULT_KNOBS=[], applies_to=1, precompute=print, QUICK_KNOBS={"x": 1}))
    assert any(p.startswith("applies_to: not callable") for p in problems)
    assert any(p.startswith("DEFAULT_KNOBS: not a dict") for p in problems)
    assert contract_problems(_stand_in()) == []
    with_quick = _stand_in(QUICK_KNOBS={"samples": 4})
    assert contract_problems(with_quick) == [
        "QUICK_KNOBS: knobs not in DEFAULT_KNOBS: samples"]


def test_a_method_registered_by_module_name_is_imported_when_used(registered, tmp_path,
                                                                  monkeypatch):
    (tmp_path / "late_method.py").write_text(textwrap.dedent("""
        DEFAULT_KNOBS = {}
        def applies_to(scene):
            return None
        def precompute(scene, **knobs):
            return None
    """))
    monkeypatch.syspath_prepend(str(tmp_path))
    registered("late", "late_method")
    assert method("late").__name__ == "late_method"
    registered("missing", "no_such_module_anywhere")
    with pytest.raises(InputError, match="not installed"):
        method("missing")
    (tmp_path / "not_a_method.py").write_text("VALUE = 1\n")
    registered("not_a_method", "not_a_method")
    with pytest.raises(MethodContractError, match="applies_to: missing"):
        method("not_a_method")


def test_two_distributions_claiming_one_name_are_an_error(monkeypatch):
    table = {"twice": EntryPointTarget("one.module", "first")}
    conflicts = {"twice": ["first (one.module)", "second (other.module)"]}
    fresh = registry.MethodRegistry()
    monkeypatch.setattr(registry, "_discovered", lambda: (dict(table), conflicts))
    monkeypatch.setattr(registry, "METHODS", fresh)
    with pytest.raises(InputError, match="two installed distributions.*second"):
        registry.method("twice")


def test_a_refusal_carries_a_code_and_a_sentence():
    assert refusal_of(None) is None
    assert refusal_of("no light") == Refusal("other", "no light")
    from translucent.fast import radiosity
    from translucent.scenes import load_scene

    glossy = radiosity.applies_to(load_scene("glossy"))
    assert glossy.code == "unsupported_material" and "radiosity" in str(glossy)


# --------------------------------------------------------------- approx for any method


def test_approx_gives_a_method_without_options_its_knobs(registered, tmp_path, capsys):
    def grey(scene, lights, material, calls):
        camera = scene.camera
        return np.full((camera.height, camera.width, 3), 0.25)

    registered("knobbed", _stand_in(grey, defaults={"grey": 0.1, "steps": 4, "shadows": True,
                                                    "mode": "fast"}))
    out = tmp_path / "knobbed.exr"
    assert main(["approx", "knobbed", "sphere", "--out", str(out), "--knob", "steps=8",
                 "--knob", "shadows=false"]) == 0
    assert out.is_file()
    for bad, words in [("steps=many", "must be a int"), ("colour=red", "unknown knob"),
                       ("steps", "NAME=VALUE"), ("shadows=maybe", "must be a bool")]:
        capsys.readouterr()
        assert main(["approx", "knobbed", "sphere", "--out", str(tmp_path / "bad.exr"),
                     "--knob", bad]) == 2
        assert words in capsys.readouterr().err
        assert not (tmp_path / "bad.exr").exists()


# ------------------------------------------------- a method from another distribution


TINY_SCENE = conformance.tiny_sphere_text("tiny_lambert")


@pytest.fixture(scope="module")
def installed_example(tmp_path_factory):
    """The example method installed, as its own distribution, into a folder of its own."""
    folder = tmp_path_factory.mktemp("lambert_install")
    source = folder / "source"
    shutil.copytree(EXAMPLE, source)
    target = folder / "site"
    completed = subprocess.run(
        [sys.executable, "-m", "pip", "install", "--quiet", "--no-deps", "--target",
         str(target), str(source)], capture_output=True, text=True, timeout=300)
    assert completed.returncode == 0, completed.stderr[-2000:]
    assert list(target.glob("translucent_lambert_method-*.dist-info"))
    return target


def _with_example(site: Path) -> dict:
    environment = dict(os.environ)
    environment["PYTHONPATH"] = os.pathsep.join(
        [str(site)] + [p for p in environment.get("PYTHONPATH", "").split(os.pathsep) if p])
    return environment


@pytest.mark.slow  # 16 s; the report's own tests score stand-in methods in the fast tier
def test_an_installed_method_is_scored_in_the_report(installed_example, tmp_path):
    scene = tmp_path / "tiny_lambert.toml"
    scene.write_text(TINY_SCENE)
    out = tmp_path / "report"
    completed = subprocess.run(
        [sys.executable, "-m", "translucent.reports.cli", "report", str(scene), "--out",
         str(out), "--methods", "lambert,prt", "--spp", "16", "--passes", "2", "--serial",
         "--no-progress", "--baseline", str(tmp_path / "baseline.json"),
         "--update-baseline"],
        capture_output=True, text=True, timeout=600, env=_with_example(installed_example),
        cwd=tmp_path)
    assert completed.returncode in (0, 1), completed.stderr[-3000:]
    data = json.loads((out / "metrics.json").read_text())["scenes"]["tiny_lambert"]
    lambert = data["methods"]["lambert"]
    assert lambert["status"] == "ok", lambert
    assert lambert["metrics"]["relative_mse"] > 0
    assert lambert["noise"]["relative_mse"]["noise_floor"] > 0
    assert lambert["noise"]["relative_mse"]["noise_verdict"] in ("resolved",
                                                                 "within reference noise")
    # a first run has no baseline entry: resolved metrics say so, not "ok"
    assert lambert["noise"]["relative_mse"]["verdict"] in ("no baseline",
                                                           "within reference noise")
    assert "lambert" in (out / "index.html").read_text()


def test_an_installed_method_passes_the_conformance_checks(installed_example, tmp_path):
    program = ("from translucent.fast.conformance import check_method\n"
               "found = check_method('lambert')\n"
               "print(sorted(k for k, v in found.items() if not v.startswith('not checked')))")
    completed = subprocess.run([sys.executable, "-c", program], capture_output=True,
                               text=True, timeout=300, env=_with_example(installed_example),
                               cwd=tmp_path)
    assert completed.returncode == 0, completed.stderr[-3000:]
    # every check but the profiles' and the geometry's (the example declares neither knob)
    assert completed.stdout.strip() == str(sorted(set(CHECKS) - {PER_PROFILE, "geometry"}))


def test_an_outside_methods_own_files_key_the_report_cache(registered, tmp_path, monkeypatch):
    from translucent.fast.registry import method_fingerprint

    assert method_fingerprint("prt") == ""  # the suite's own sources key it already
    source = tmp_path / "keyed_method.py"
    source.write_text("DEFAULT_KNOBS = {}\ndef applies_to(scene):\n    return None\n"
                      "def precompute(scene, **knobs):\n    return None\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    registered("keyed", "keyed_method")
    first = method_fingerprint("keyed")
    assert len(first) == 64
    import importlib

    source.write_text(source.read_text() + "# edited\n")
    importlib.invalidate_caches()
    assert method_fingerprint("keyed") != first


@pytest.mark.parametrize("name", sorted(registry.BUILTIN_METHODS))
def test_applies_to_is_asked_once_per_run_and_not_again_when_passed_on(name, monkeypatch):
    """The report asks when it plans a run; the run and the precomputation do not ask again."""
    from translucent.reports.report.runs import run_method

    module = registry.method(name)
    calls = []
    original = module.applies_to

    def counted(scene):
        calls.append(scene)
        return original(scene)

    monkeypatch.setattr(module, "applies_to", counted)
    monkeypatch.setattr(sys.modules[original.__module__], "applies_to", counted)
    scene = conformance.conformance_scene(module)
    calls.clear()
    run = run_method(name, scene, getattr(module, "QUICK_KNOBS", {}))
    assert run.status == "ok", run.reason
    assert calls == [scene]
    calls.clear()
    fresh = conformance.conformance_scene(module)
    calls.clear()
    assert run_method(name, fresh, getattr(module, "QUICK_KNOBS", {}), applies=True).status \
        == "ok"
    assert calls == []
