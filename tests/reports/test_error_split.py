"""The error split: a method's error against transport, its profile's part and its own.

Checked on images of known error (the relative MSE written out here with numpy, not the
suite's function), on which part dominates (a property over random errors), and end to
end: a report of a stand-in method that has a profile knob, run with a second profile,
whose metrics.json carries both blocks with floors and verdicts for both entries, computed
against the model reference the report wrote beside them.
"""

import json
import textwrap

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from translucent.fast import base as fast_base
from translucent.fast.conformance import tiny_sphere_text
from translucent.image import Image, read_exr
from translucent.reports.cli import main
from translucent.reports.metrics.registry import NOISE_FLOOR_FIELDS
from translucent.reports.report import pipeline as report_module
from translucent.reports.report.model import SceneReport
from translucent.reports.report.runs import MethodRun
from translucent.reports.report.scoring import scored_pixels
from translucent.reports.report.split import (
    DOMINANCE_RATIO,
    dominant_part,
    entry_parts,
    model_reference_refusal,
    requested_profiles,
    score_splits,
)
from translucent.scenes import load_scene

EPSILON = 1e-2


def numpy_relative_mse(reference, test):
    """Eq. of the relative MSE, raw (no variance discounted), written independently."""
    reference, test = np.asarray(reference, float), np.asarray(test, float)
    return float(np.mean((test - reference) ** 2 / (reference ** 2 + EPSILON)))


def _report_of(volumetric, model, method_image, method="radiosity"):
    report = SceneReport("synthetic", "synthetic", None, "hash", 16)
    report.reference = volumetric
    report.model_references["dipole"] = model
    report.model_reference_info["dipole"] = {"source": "test"}
    report.runs[method] = MethodRun(method, "synthetic", "ok", image=method_image)
    report.metrics[method] = {}
    return report


def _images(model_scale, method_scale, seed=0):
    rng = np.random.default_rng(seed)
    truth = rng.uniform(0.3, 1.0, (24, 24, 3))
    variance = np.full_like(truth, 1e-8)
    volumetric = Image(truth, variance)
    model = Image(model_scale * truth, variance)
    method = Image(method_scale * model_scale * truth)
    return volumetric, model, method


def test_a_profile_too_bright_is_the_models_error_and_the_method_adds_little():
    volumetric, model, method = _images(1.2, 1.01)
    report = _report_of(volumetric, model, method)
    score_splits(report)
    split = report.splits["radiosity"]
    assert split.profile == "dipole" and not split.reason
    assert split.model["relative_mse_raw"] == pytest.approx(
        numpy_relative_mse(volumetric.rgb, model.rgb), rel=1e-9)
    assert split.approximation["relative_mse_raw"] == pytest.approx(
        numpy_relative_mse(model.rgb, method.rgb), rel=1e-9)
    assert split.model_verdicts["relative_mse"] == "resolved"
    assert split.dominant == "model"
    assert "model's error dominates" in split.sentence()
    blocks = split.as_dict()
    for block in ("model_error", "approximation_error"):
        assert set(blocks[block]["noise"]) == set(NOISE_FLOOR_FIELDS)
        for entry in blocks[block]["noise"].values():
            assert entry["noise_floor"] is not None and entry["noise_verdict"]


def test_a_method_far_from_its_exact_profile_is_the_approximations_error():
    volumetric, model, method = _images(1.0 + 1e-3, 0.7)
    report = _report_of(volumetric, model, method)
    score_splits(report)
    split = report.splits["radiosity"]
    assert split.dominant == "approximation"
    assert split.approximation["relative_mse_raw"] == pytest.approx(
        numpy_relative_mse(model.rgb, method.rgb), rel=1e-9)


def test_the_models_floor_carries_both_renders_noise():
    # a model reference as noisy as the volumetric one: the floor of their difference is
    # about twice the floor of either (the relative MSE's floor is its variance's mean)
    rng = np.random.default_rng(3)
    truth = rng.uniform(0.5, 1.0, (32, 32, 3))
    variance = (0.02 * truth) ** 2
    volumetric = Image(truth + rng.normal(0, 1, truth.shape) * np.sqrt(variance), variance)
    model = Image(truth + rng.normal(0, 1, truth.shape) * np.sqrt(variance), variance)
    report = _report_of(volumetric, model, model)
    score_splits(report)
    split = report.splits["radiosity"]
    ratio = split.model_floor["relative_mse_raw"] / split.approximation_floor["relative_mse_raw"]
    assert 1.6 < ratio < 2.5
    # the same image twice is no error at all, beyond the noise
    assert split.dominant == "within noise"


def test_a_missing_model_reference_and_another_renderer_say_why_there_is_no_split():
    volumetric, model, method = _images(1.1, 1.0)
    report = _report_of(volumetric, model, method, method="brdf_pca")
    report.runs["other"] = MethodRun("other", "synthetic", "ok", image=method)
    report.metrics["other"] = {}
    score_splits(report)
    # BRDF editing stands on its PCA BRDF carried by its Lambertian gather (model_name):
    # without that render, it says so
    model_key = "brdf_pca_k6+lambertian_gather2"
    assert report.splits["brdf_pca"].profile == model_key
    assert f"no model reference of '{model_key}'" in report.splits["brdf_pca"].reason
    assert "another renderer" in report.splits["other"].reason
    assert report.splits["other"].sentence().startswith("No split")


def test_a_model_named_by_parts_splits_its_error_into_steps():
    # transport V, the PCA BRDF 1 % bright, its gather transport 20 % darker still, and
    # the method 1 % off its model: each step is the relative MSE of its own ratio
    volumetric, pca, method = _images(1.01, 1.0)
    gather = Image(0.8 * pca.rgb, pca.variance)
    method = Image(1.01 * gather.rgb)
    report = _report_of(volumetric, pca, method, method="brdf_pca")
    report.model_references = {"brdf_pca_k6": pca, "brdf_pca_k6+lambertian_gather2": gather}
    score_splits(report)
    split = report.splits["brdf_pca"]
    assert [(step.model, step.against, step.label) for step in split.steps] == [
        ("brdf_pca_k6", None, "brdf_pca_k6"),
        ("brdf_pca_k6+lambertian_gather2", "brdf_pca_k6", "+lambertian_gather2")]
    first, second = (step.metrics["relative_mse_raw"] for step in split.steps)
    assert first == pytest.approx(numpy_relative_mse(volumetric.rgb, pca.rgb), rel=1e-9)
    assert second == pytest.approx(numpy_relative_mse(pca.rgb, gather.rgb), rel=1e-9)
    assert split.model["relative_mse_raw"] == pytest.approx(
        numpy_relative_mse(volumetric.rgb, gather.rgb), rel=1e-9)
    assert "+lambertian_gather2 0.0" in split.sentence()
    assert split.sentence().endswith("The largest step: +lambertian_gather2.")
    assert [entry["model"] for entry in split.as_dict()["model_steps"]] == [
        "brdf_pca_k6", "brdf_pca_k6+lambertian_gather2"]
    # without the simpler model's reference there are no steps, and the split stands
    del report.model_references["brdf_pca_k6"]
    score_splits(report)
    assert report.splits["brdf_pca"].steps == [] and not report.splits["brdf_pca"].reason


def test_a_heterogeneous_scene_has_no_model_reference_and_says_why():
    assert "heterogeneous" in model_reference_refusal(load_scene("solid_checker"))
    assert "no homogeneous translucent" in model_reference_refusal(load_scene("glossy"))
    assert model_reference_refusal(load_scene("sphere")) == ""


@given(st.floats(1e-6, 1.0), st.floats(1e-6, 1.0), st.booleans(), st.booleans())
def test_which_part_dominates_is_symmetric(model, approximation, model_resolved,
                                           approximation_resolved):
    found = dominant_part(model, approximation, resolved=(model_resolved,
                                                          approximation_resolved))
    swapped = dominant_part(approximation, model, resolved=(approximation_resolved,
                                                            model_resolved))
    exchange = {"model": "approximation", "approximation": "model"}
    assert swapped == exchange.get(found, found)
    if found == "model":
        assert model_resolved and (not approximation_resolved
                                   or model >= DOMINANCE_RATIO * approximation)
    if found == "both":
        assert model_resolved and approximation_resolved
        assert max(model, approximation) < DOMINANCE_RATIO * min(model, approximation)
    if not (model_resolved or approximation_resolved):
        assert found == "within noise"


def test_profiles_are_read_by_name_or_all_and_an_unknown_one_is_refused():
    from translucent.errors import InputError
    from translucent.fast.knobs import radial_profile_names

    assert requested_profiles("all") == [n for n in radial_profile_names() if n != "dipole"]
    assert requested_profiles(["burley_dmfp", "burley_dmfp"]) == ["burley_dmfp"]
    assert requested_profiles(["all"]) == requested_profiles("all")  # the bench splits on ","
    assert entry_parts("prt@burley_dmfp") == ("prt", "burley_dmfp")
    with pytest.raises(InputError, match="unknown radial profile") as error:
        requested_profiles("dipole,no_such_profile")
    assert error.value.field == "--profiles"


PROFILE_METHOD = textwrap.dedent('''
    """A stand-in method with a profile knob: a flat image as bright as its profile."""
    import numpy as np

    from translucent.fast.base import StageLog
    from translucent.fast.knobs import KnobSpec, profile_knob
    from translucent.image import Image
    from translucent.materials import Dipole
    from translucent.materials.profiles import profile

    KNOBS = KnobSpec([profile_knob({}, keyed=True, help="the profile")])
    DEFAULT_KNOBS = KNOBS.defaults


    def applies_to(scene):
        return None


    class State:
        def __init__(self, scene, name):
            self.scene, self.name = scene, name
            self.log = StageLog()

        def render(self, lights=None, material=None):
            medium = next(o.material for o in self.scene.objects
                          if isinstance(o.material, Dipole))
            total = profile(self.name, medium).total()
            camera = self.scene.camera
            return Image(np.broadcast_to(0.1 * total, (camera.height, camera.width, 3))
                         .astype(np.float32).copy(), metadata={"producer": "flat profile"})


    def precompute(scene, **knobs):
        return State(scene, KNOBS.resolve(knobs)["profile"])
''')


@pytest.mark.parametrize("profiles", [
    [], pytest.param(["better_dipole"], marks=pytest.mark.slow)])  # a second render: 12 s
def test_a_report_splits_each_profiles_error_against_its_model_reference(tmp_path,
                                                                         monkeypatch, profiles):
    (tmp_path / "report_profile_method.py").write_text(PROFILE_METHOD)
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.setitem(fast_base.METHODS, "flatprofile", "report_profile_method")
    monkeypatch.setattr(report_module, "_source_fingerprint", lambda: "fixed for the tests")
    # its own cache: the report tests count the tasks of a tiny scene of the same name
    monkeypatch.setenv("TRANSLUCENT_CACHE", str(tmp_path / "cache"))
    scene = tmp_path / "tiny_sphere.toml"
    scene.write_text(tiny_sphere_text("tiny_sphere", 24))
    out = tmp_path / "report"
    code = main(["report", str(scene), "--out", str(out), "--baseline",
                 str(tmp_path / "baseline.json"), "--update-baseline", "--methods",
                 "flatprofile", "--serial", "--no-progress", "--spp", "4", "--passes", "2"]
                + (["--profiles", ",".join(profiles)] if profiles else []))
    assert code == 0
    data = json.loads((out / "metrics.json").read_text())["scenes"]["tiny_sphere"]
    reference = read_exr(out / "tiny_sphere" / "reference.exr")
    mask = scored_pixels(load_scene(str(scene)))
    for name, profile in [("flatprofile", "dipole")] + [(f"flatprofile@{p}", p)
                                                         for p in profiles]:
        entry = data["methods"][name]
        assert entry["status"] == "ok", entry
        split = entry["error_split"]
        assert split["profile"] == profile and split["reason"] is None
        assert split["dominant"] in ("model", "approximation", "both", "within noise")
        info = split["model_reference"]
        assert info["source"] == "fixed passes" and info["integrator"] == "bssrdf_path"
        model = read_exr(out / info["exr"])
        assert model.metadata["profile"]["name"] == profile
        method = read_exr(out / entry["files"]["exr"])
        for block in ("model_error", "approximation_error"):
            assert set(entry[block]["noise"]) == set(NOISE_FLOOR_FIELDS), block
        # recomputed from the images the report wrote, over the pixels it scored
        assert entry["metrics"]["pixels_scored"] == int(mask.sum())
        assert entry["approximation_error"]["metrics"]["relative_mse_raw"] == pytest.approx(
            numpy_relative_mse(model.rgb[mask], method.rgb[mask]), rel=1e-5)
        assert entry["model_error"]["metrics"]["relative_mse_raw"] == pytest.approx(
            numpy_relative_mse(reference.rgb[mask], model.rgb[mask]), rel=1e-5)
    page = (out / "index.html").read_text()
    assert page.count("Why: the error split") == 1 + len(profiles)
    assert all(f"flatprofile@{p}" in page for p in profiles)


@pytest.mark.parametrize("name, knobs, model", [
    ("prt", {}, "dipole+walk"), ("splatting", None, "dipole+walk"),
    ("prt", {"geometry": "diffusion"}, "dipole+geometry"),
    ("prt", {"geometry": "half_space"}, "dipole"),
    ("splatting@better_dipole", {"profile": "better_dipole"}, "better_dipole+walk"),
    ("radiosity", {}, "dipole"), ("radiosity", {"geometry": "walk"}, "dipole+walk")])
def test_a_method_with_the_geometry_is_split_against_the_model_with_the_geometry(name, knobs,
                                                                               model):
    from translucent.reports.report.split import split_profile

    assert split_profile(name, knobs) == (model, "")


@pytest.mark.parametrize("name, model", [("splatting", "dipole+geometric_mean"),
                                         ("radiosity", "dipole+segment_mix")])
def test_on_a_solid_medium_a_method_is_split_against_its_own_mixing_rule(name, model):
    from translucent.reports.report.split import model_reference_refusal, split_profile
    from translucent.scenes import load_scene

    scene = load_scene("solid_checker")
    assert split_profile(name, {}, scene) == (model, "")
    assert model_reference_refusal(scene, model) == ""
    assert "rule" in model_reference_refusal(scene, "dipole")
    # a method that names no rule is not split there, and says why
    profile, reason = split_profile("prt", {}, scene)
    assert profile is None and "HETEROGENEOUS_RULE" in reason


def test_the_committed_rules_are_the_built_in_methods_own():
    from translucent.fast.base import method
    from translucent.fast.registry import BUILTIN_METHODS
    from translucent.reference.committed import METHOD_RULES

    rules = {getattr(method(name), "HETEROGENEOUS_RULE", None) for name in
             BUILTIN_METHODS} - {None}
    assert rules == set(METHOD_RULES)
