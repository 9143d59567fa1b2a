"""The pytest plugin: assertions, artifacts on failure, reference regeneration, entry point."""

import textwrap

import numpy as np
import pytest
from translucent.errors import InputError
from translucent.image import Image
from translucent.reports.pytest_plugin import (
    ReferenceNoiseWarning,
    artifacts_root,
    assert_image_close,
    assert_render_consistent,
)

pytest_plugins = ["pytester"]


def gradient(height=24, width=24):
    y, x = np.mgrid[0:height, 0:width] / max(height, width)
    return np.stack([0.2 + x, 0.3 + y, 0.5 + x * y], axis=-1).astype(np.float32)


# ----------------------------------------------------------------------------- in this suite


def test_the_fixture_is_registered_here(image_checks, tmp_path_factory):
    """The plugin is active in this suite through its entry point (no conftest)."""
    image = gradient()
    assert image_checks.assert_image_close(image, image, max=0.0) == 0.0
    assert artifacts_root() == tmp_path_factory.getbasetemp() / "translucent-artifacts"
    assert image_checks.artifacts.parent == artifacts_root()


def test_a_failed_image_check_leaves_its_maps_where_the_message_says(image_checks):
    reference = gradient()
    with pytest.raises(AssertionError, match=r"hdr_flip = [\d.]+, above the maximum 0.01 "
                                             r"\(24 x 24 pixels\); error maps in ") as failure:
        image_checks.assert_image_close(reference * 1.5, reference, max=0.01)
    folder = image_checks.artifacts / "hdr_flip"
    assert str(folder) in str(failure.value)
    assert {path.name for path in folder.iterdir()} == {
        f"{name}.{ext}" for name in ("flip", "relative_error", "ciede2000", "ssim")
        for ext in ("exr", "png")}


def test_a_second_failure_gets_its_own_folder(tmp_path):
    reference = gradient()
    for _ in range(2):
        with pytest.raises(AssertionError):
            assert_image_close(reference * 2, reference, "rmse", max=0.0, artifacts=tmp_path)
    assert sorted(path.name for path in tmp_path.iterdir()) == ["rmse", "rmse-2"]


def test_a_failure_against_a_noisy_reference_gives_the_noise_floor(tmp_path, rng):
    truth = gradient()
    sigma = 0.02 * truth
    reference = Image(truth + sigma * rng.standard_normal(truth.shape), sigma**2)
    with pytest.raises(AssertionError, match=r"hdr_flip = [\d.]+ \(noise floor [\d.]+: "
                                             r"resolved\), above the maximum"):
        assert_image_close(truth * 1.5, reference, max=0.05, artifacts=tmp_path)


def test_a_bound_tighter_than_the_noise_floor_warns(tmp_path, rng):
    truth = gradient()
    sigma = 0.05 * truth
    reference = Image(truth + sigma * rng.standard_normal(truth.shape), sigma**2)
    with pytest.warns(ReferenceNoiseWarning, match="tighter than the reference's noise"):
        with pytest.raises(AssertionError, match="within reference noise"):
            assert_image_close(truth, reference, "rmse", max=1e-4, artifacts=tmp_path)
    # a bound the noise allows: no warning, and a perfect image passes
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("error", ReferenceNoiseWarning)
        assert assert_image_close(truth, reference, "rmse", max=0.1) < 0.1


def test_similarity_metrics_take_a_minimum(tmp_path):
    reference = gradient()
    assert assert_image_close(reference, reference, "psnr", min=40) == float("inf")
    with pytest.raises(AssertionError, match="ssim = .*, below the minimum 0.999"):
        assert_image_close(reference * 0.5, reference, "ssim", min=0.999, artifacts=tmp_path)


@pytest.mark.parametrize("metric, bounds, match", [
    ("hdr-flip", {}, r"needs max= and only that bound \(hdr_flip is an error\)"),
    ("psnr", {"max": 3.0}, r"needs min= and only that bound \(psnr is a similarity\)"),
])
def test_the_bound_must_match_the_metric(metric, bounds, match):
    with pytest.raises(TypeError, match=match):
        assert_image_close(gradient(), gradient(), metric, **bounds)


def test_images_may_be_exr_paths(tmp_path):
    path = Image(gradient()).write(tmp_path / "reference.exr")
    assert assert_image_close(gradient(), path, "rmse", max=0.0) == 0.0
    with pytest.raises(InputError, match="missing.exr: path = .*: no such file"):
        assert_image_close(gradient(), tmp_path / "missing.exr", max=0.1)


def test_different_sizes_are_bad_input_not_a_failed_check():
    with pytest.raises(InputError, match="reference is 24 x 24"):
        assert_image_close(gradient(24, 30), gradient(), max=1.0)


def test_render_consistency(rng, tmp_path):
    """Exponential samples: the mean of 64 is Gamma(64, truth / 64); variance truth**2."""
    truth = gradient().astype(np.float64)
    test = Image(rng.gamma(64, truth / 64), metadata={"spp": 64})
    assert assert_render_consistent(test, truth, truth**2).passed
    biased = rng.gamma(4096, 1.2 * truth / 4096)
    with pytest.raises(AssertionError, match=r"z-test FAILED: .* % of 1728 pixel channels "
                                             r"accepted .*p-value image and maps in "):
        assert_render_consistent(biased, truth, truth**2, spp=4096, artifacts=tmp_path)
    written = {path.name for path in (tmp_path / "z-test").iterdir()}
    assert {"p_value.exr", "p_value.png", "rejected.png", "test.exr", "reference.exr",
            "difference.exr"} <= written


def test_render_consistency_needs_spp():
    with pytest.raises(TypeError, match="needs spp="):
        assert_render_consistent(gradient(), gradient(), gradient())


# ----------------------------------------------------------------------------- pytester

#: Options of the inner runs: hypothesis is not what translucent installs, and its plugin
#: re-imports hypothesis (2-3 s here) in every in-process run after pytester restores
#: sys.modules.
QUIET = ("-p", "no:cacheprovider", "-p", "no:hypothesispytest")

CONSUMER_TESTS = """
    import numpy as np
    import translucent

    def image(scale=1.0):
        y, x = np.mgrid[0:16, 0:16] / 16
        return translucent.Image(scale * np.stack([0.2 + x, 0.3 + y, 0.5 + x * y], axis=-1))

    def test_close(image_checks):
        image_checks.assert_image_close(image(), image(), metric="ldr-flip", max=0.0)

    def test_too_far(image_checks):
        image_checks.assert_image_close(image(2.0), image(), metric="hdr-flip", max=0.01)

    def test_reference(reference_image):
        stored = reference_image("refs/gradient.exr", lambda: image())
        print("producer result shape", stored.shape)
"""


def test_a_fresh_project_gets_the_plugin_from_the_entry_point(pytester):
    """A project with no conftest that only imports translucent, run in a new process."""
    pytester.makepyfile(test_consumer=textwrap.dedent(CONSUMER_TESTS))
    artifacts = pytester.path / "artifacts"
    result = pytester.runpytest_subprocess(*QUIET, f"--translucent-artifacts={artifacts}")
    result.assert_outcomes(passed=2, failed=1)
    result.stdout.fnmatch_lines([f"*hdr_flip = *above the maximum 0.01*error maps in "
                                 f"{artifacts}*",
                                 "*references regenerated*", "*refs/gradient.exr"])
    assert (artifacts / "test_consumer.py_test_too_far" / "hdr_flip" / "flip.png").is_file()
    assert (pytester.path / "refs" / "gradient.exr").is_file()


REGENERATION_TESTS = """
    import numpy as np
    from translucent.image import Image

    CALLS = []

    def test_reference(reference_image):
        def producer():
            CALLS.append(1)
            return np.full((4, 4, 3), 2.0)
        stored = reference_image("gradient.exr", producer)
        assert float(stored.rgb.mean()) == 2.0
        print(f"producer called {len(CALLS)} times")
"""


def test_a_stored_reference_is_read_and_regenerated_on_request(pytester):
    """Missing references are made in the fresh-project test above; here one is stored."""
    pytester.makepyfile(test_regeneration=textwrap.dedent(REGENERATION_TESTS))
    reference = Image(np.full((4, 4, 3), 2.0)).write(pytester.path / "gradient.exr")
    stored = reference.stat().st_mtime_ns

    kept = pytester.runpytest(*QUIET, "-s")
    kept.assert_outcomes(passed=1)
    kept.stdout.fnmatch_lines(["*producer called 0 times*"])
    kept.stdout.no_fnmatch_line("*references regenerated*")
    assert reference.stat().st_mtime_ns == stored

    regenerated = pytester.runpytest(*QUIET, "-s", "--translucent-regenerate")
    regenerated.assert_outcomes(passed=1)
    regenerated.stdout.fnmatch_lines(["*producer called 1 times*",
                                      "*references regenerated*", "*gradient.exr"])


def test_the_options_are_registered(pytestconfig):
    assert pytestconfig.getoption("translucent_regenerate") is False
    assert pytestconfig.getoption("translucent_artifacts") is None


@pytest.mark.parametrize("bound", [float("nan"), "0.05", True])
def test_a_bound_that_is_not_a_finite_number_is_bad_input(tmp_path, bound):
    with pytest.raises(InputError, match=r"max = .*: must be a finite number"):
        assert_image_close(gradient(), gradient(), "rmse", max=bound, artifacts=tmp_path)
    assert not any(tmp_path.iterdir())



def test_a_relative_artifacts_folder_is_taken_from_where_pytest_was_started(
        pytestconfig, tmp_path, monkeypatch):
    from pathlib import Path

    original = pytestconfig.getoption

    def getoption(name, *args, **kwargs):
        return "arts" if name == "translucent_artifacts" else original(name, *args, **kwargs)

    monkeypatch.setattr(pytestconfig, "getoption", getoption)
    monkeypatch.chdir(tmp_path)  # a test that moves into another folder
    started = Path(pytestconfig.invocation_params.dir)
    assert artifacts_root(pytestconfig) == (started / "arts").resolve()


def _reference_with_variance(rng, spp=64, passes=16):
    mean = gradient(32, 32).astype(np.float64)
    per_sample = 0.5 * mean  # the per-sample variance of the estimator
    variance_of_mean = per_sample / (spp * passes)
    noisy = mean + np.sqrt(variance_of_mean) * rng.standard_normal(mean.shape)
    return mean, per_sample, Image(noisy, variance_of_mean,
                                   {"producer": "reference", "spp": spp, "passes": passes})


def test_render_consistency_reads_the_variance_a_reference_file_stores(rng, tmp_path):
    mean, per_sample, reference = _reference_with_variance(rng)
    reference.write(tmp_path / "ref.exr")
    honest = Image(mean + np.sqrt(per_sample / 1024) * rng.standard_normal(mean.shape),
                   metadata={"spp": 1024})
    assert assert_render_consistent(honest, tmp_path / "ref.exr").passed
    biased = Image(honest.rgb * 1.2, metadata={"spp": 1024})
    with pytest.raises(AssertionError, match="z-test FAILED"):
        assert_render_consistent(biased, tmp_path / "ref.exr", artifacts=tmp_path / "a")


def test_a_reference_passed_as_its_own_variance_is_refused(rng, tmp_path):
    _, _, reference = _reference_with_variance(rng)
    reference.write(tmp_path / "ref.exr")
    test = Image(reference.rgb, metadata={"spp": 16})
    for variance in (tmp_path / "ref.exr", reference, reference.rgb):
        with pytest.raises(InputError, match="reference_variance"):
            assert_render_consistent(test, reference, variance)
    with pytest.raises(InputError, match="give reference_variance"):
        assert_render_consistent(test, Image(reference.rgb))  # no stored variance


#: Honest renders checked against independent references; the stated family-wise
#: significance is 1 %, so more than 3 failures of 40 (probability 6e-5 at 1 %) is a fault.
HONEST_TRIALS, MOST_FALSE_FAILURES = 40, 3

#: Rejected pixel channels over all trials: the model expects 40 x 3072 x alpha = 1.2
#: (32 x 32 pixels, Sidak alpha 9.8e-6); more than 8 has probability 5e-6 under it.
MOST_REJECTED_CHANNELS = 8


@pytest.mark.slow
@pytest.mark.parametrize("reference_spp, reference_passes", [(4, 4), (16, 8), (64, 8)])
def test_honest_renders_fail_at_most_at_the_stated_rate(tmp_path, reference_spp,
                                                        reference_passes):
    """Against references of few passes, whose own noise the check now counts.

    Each pixel channel, not only each image: with every pixel's own variance a reference
    of 16 spp x 8 passes had 0.88 rejected channels a trial (the model expects 0.03).
    """
    from translucent.fast.conformance import tiny_sphere_text
    from translucent.reference import render
    from translucent.scenes import loads_scene

    scene = loads_scene(tiny_sphere_text(size=32))
    failures = rejected = 0
    for trial in range(HONEST_TRIALS):
        reference = render(scene, spp=reference_spp, passes=reference_passes,
                           seed=1000 + trial, cache=False, progress=False)
        test = render(scene, spp=16, passes=1, seed=50000 + trial, cache=False, progress=False)
        try:
            result = assert_render_consistent(test, reference, spp=16, artifacts=tmp_path)
        except AssertionError:
            failures += 1
            continue
        rejected += int((~result.accepted).sum())
    assert failures <= MOST_FALSE_FAILURES, f"{failures} of {HONEST_TRIALS} honest renders"
    assert rejected <= MOST_REJECTED_CHANNELS, f"{rejected} rejected pixel channels"


def test_a_biased_render_still_fails_against_a_noisy_reference(tmp_path):
    """Counting the reference's noise does not blind the check: 30 % too bright fails."""
    from translucent.fast.conformance import tiny_sphere_text
    from translucent.image import Image
    from translucent.reference import render
    from translucent.scenes import loads_scene

    scene = loads_scene(tiny_sphere_text(size=16))
    reference = render(scene, spp=16, passes=8, seed=3, cache=False, progress=False)
    test = render(scene, spp=16, passes=1, seed=9, cache=False, progress=False)
    assert_render_consistent(test, reference, spp=16, artifacts=tmp_path)
    brighter = Image(test.rgb * 1.3, metadata=test.metadata)
    with pytest.raises(AssertionError, match="accepted"):
        assert_render_consistent(brighter, reference, spp=16, artifacts=tmp_path)


def test_a_reference_of_few_passes_is_warned_about():
    from translucent.image import Image
    from translucent.reports.pytest_plugin import ReferenceNoiseWarning

    rgb = np.full((8, 8, 3), 0.5, dtype=np.float32)
    few = Image(rgb, np.full_like(rgb, 1e-4), metadata={"spp": 16, "passes": 4})
    with pytest.warns(ReferenceNoiseWarning, match="reference of 4 passes.*at least 16"):
        assert_render_consistent(Image(rgb, metadata={"spp": 16}), few)
    enough = Image(rgb, np.full_like(rgb, 1e-4), metadata={"spp": 16, "passes": 16})
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("error", ReferenceNoiseWarning)
        assert_render_consistent(Image(rgb, metadata={"spp": 16}), enough)
