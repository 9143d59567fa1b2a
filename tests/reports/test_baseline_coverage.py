"""The regression gate sees every default scene: a baseline entry per scene and method.

Every default scene of the report, and every method that applies to it, has an entry in
``reports/baseline/default.json`` made against the scene as it loads now and against its
current committed reference (same spp and passes). A new default scene, a re-rendered
reference or a newly applicable method without an entry fails here, instead of leaving
the report's gate silently blind ("no baseline" / "not compared").
"""

import pytest
from translucent.cache import content_hash
from translucent.fast.base import METHODS, applicability, method
from translucent.reference.committed import committed_reference
from translucent.reports.metrics.registry import TOLERANCES
from translucent.reports.report.baselines import DEFAULT_BASELINE, load_baseline
from translucent.reports.report.pipeline import default_scenes
from translucent.scenes import load_scene

BASELINE = load_baseline(DEFAULT_BASELINE, required=True)
SCENES, _ = default_scenes()


@pytest.mark.parametrize("name", SCENES)
def test_every_default_scene_and_method_has_a_current_baseline_entry(name):
    scene = load_scene(name)
    entry = BASELINE["entries"].get(name)
    assert entry is not None, f"{name}: no baseline entry (run `translucent report " \
                              f"{name} --update-baseline`)"
    assert entry["scene_hash"] == content_hash(scene), f"{name}: entry made for another " \
                                                       "version of the scene"
    reference = committed_reference(name, scene)
    assert reference.current, reference.problem
    meta = reference.image.metadata
    assert (entry["reference"].get("spp"), entry["reference"].get("passes")) == \
        (meta.get("spp"), meta.get("passes")), f"{name}: entry made against another reference"
    applicable = [m for m in METHODS
                  if applicability(method(m).applies_to, scene) is None]
    # a method that fails on the scene is kept with its reason, so the gate still sees it
    failures = entry.get("failures", {})
    missing = sorted(set(applicable) - set(entry["methods"]) - set(failures))
    assert not missing, f"{name}: no baseline for {missing}"
    for method_name in applicable:
        if method_name in entry["methods"]:
            assert set(TOLERANCES) <= set(entry["methods"][method_name]), (name, method_name)
        else:
            assert failures[method_name], (name, method_name)


def test_a_known_failure_is_seen_again_and_a_fixed_one_is_an_improvement():
    from translucent.reports.report.baselines import check_against_baseline, updated_baseline

    results = [{"name": "s", "scene_hash": "h", "reference": {"spp": 4, "passes": 2},
                "metrics": {}, "methods_run": ["radiosity"],
                "failures": {"radiosity": "InputError: Eq. 15 broken"}}]
    baseline = updated_baseline({}, results, {})
    assert baseline["entries"]["s"]["failures"] == {"radiosity": "InputError: Eq. 15 broken"}
    reference = {"spp": 4, "passes": 2}
    again = check_against_baseline("s", "h", reference, "radiosity", None, baseline,
                                   failure="InputError: Eq. 15 broken")
    assert again.status == "known failure" and "Eq. 15" in again.message
    fixed = check_against_baseline("s", "h", reference, "radiosity",
                                   {name: 0.1 for name in TOLERANCES}, baseline)
    assert fixed.status == "improved"
    other_scene = check_against_baseline("s", "other", reference, "radiosity", None, baseline)
    assert other_scene.status == "no baseline"
