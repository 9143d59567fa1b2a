"""The per-pixel z-test: Šidák threshold, same-distribution renders pass, biased ones fail."""

from decimal import Decimal, getcontext

import numpy as np
import pytest
from translucent.errors import InputError
from translucent.image import Image
from translucent.reports.metrics.statistics import (
    REQUIRED_FRACTION,
    SIGNIFICANCE,
    sidak_alpha,
    z_test,
    z_test_known_variance,
)

#: sidak_alpha goes through log1p/expm1 in float64: 1e-12 relative is rounding only.
FLOAT64_RTOL = 1e-12

#: Samples per pixel of the simulated test renders, and of the converged reference.
TEST_SPP = 64
REFERENCE_SPP = 65536

#: Pixels of the simulated renders (48 x 48: Sidak alpha about 4.4e-6).
SHAPE = (48, 48, 3)


def render(truth, spp, rng):
    """A simulated Monte Carlo render: the mean of ``spp`` exponential samples per pixel.

    Exponential samples (mean ``truth``, variance ``truth**2``) are as skewed as the
    radiance samples of a path tracer; their mean of n is Gamma(n, truth / n).
    """
    return rng.gamma(spp, truth / spp)


@pytest.fixture
def scene(rng):
    """Truth, a converged reference mean and its per-sample variance (exponential samples)."""
    y, x = np.mgrid[0:SHAPE[0], 0:SHAPE[1]] / SHAPE[0]
    truth = np.stack([0.2 + x, 0.3 + y, 0.5 + x * y], axis=-1)
    reference_mean = render(truth, REFERENCE_SPP, rng)
    return truth, reference_mean, reference_mean**2


# ----------------------------------------------------------------------------- Sidak


@pytest.mark.parametrize("pixels", [1, 4096, 1920 * 1080])
def test_sidak_alpha_matches_high_precision(pixels):
    getcontext().prec = 50
    exact = Decimal(1) - (Decimal(1) - Decimal(str(SIGNIFICANCE))) ** (Decimal(1) / pixels)
    assert sidak_alpha(pixels) == pytest.approx(float(exact), rel=FLOAT64_RTOL)


def test_sidak_alpha_keeps_the_family_wise_rate():
    alpha = sidak_alpha(4096)
    assert 1 - (1 - alpha) ** 4096 == pytest.approx(SIGNIFICANCE, rel=1e-9)
    assert sidak_alpha(1) == pytest.approx(SIGNIFICANCE, rel=FLOAT64_RTOL)


@pytest.mark.parametrize("pixels, significance, match", [
    (0, 0.01, "pixels = 0: must be an integer >= 1"),
    (10, 1.5, "significance = 1.5: must be in"),
])
def test_sidak_alpha_bad_input(pixels, significance, match):
    with pytest.raises(InputError, match=match):
        sidak_alpha(pixels, significance)


# ----------------------------------------------------------------------------- z-test


def test_a_render_of_the_same_distribution_passes(scene, rng):
    truth, reference_mean, reference_variance = scene
    result = z_test(render(truth, TEST_SPP, rng), reference_mean, reference_variance,
                    TEST_SPP)
    assert result.passed and bool(result)
    assert result.p_values.shape == SHAPE
    assert result.alpha == pytest.approx(sidak_alpha(SHAPE[0] * SHAPE[1]), rel=FLOAT64_RTOL)
    assert result.fraction_accepted >= REQUIRED_FRACTION
    assert "passed" in result.summary()


def test_a_biased_render_fails(scene, rng):
    """A 10 % bias at 4096 spp: z = 0.1 sqrt(4096) = 6.4 on average, above the bound 4.6."""
    truth, reference_mean, reference_variance = scene
    spp = 4096
    result = z_test(render(1.1 * truth, spp, rng), reference_mean, reference_variance, spp)
    assert not result.passed
    assert "FAILED" in result.summary()


def test_a_small_biased_patch_fails(scene, rng):
    """A 6 x 6 patch (1.6 % of pixels, above the 0.25 % allowed) three times too bright.

    In the patch the test mean is 3 T (1 + e / 8) with e ~ N(0, 1) (64 exponential
    samples), so z = 16 + 3 e: the rejection bound z = 4.6 (Sidak alpha 4.4e-6) is 3.8
    sigma below, and every patch channel is rejected.
    """
    truth, reference_mean, reference_variance = scene
    biased = truth.copy()
    biased[10:16, 20:26] *= 3
    result = z_test(render(biased, TEST_SPP, rng), reference_mean, reference_variance,
                    TEST_SPP)
    assert not result.passed
    assert not result.accepted[10:16, 20:26].any()


def test_p_values_are_uniform_under_the_null(rng):
    """Gaussian means: the fraction of p below 0.05 is 0.05 within 4 binomial sigmas."""
    shape = (64, 64, 3)
    reference = np.ones(shape)
    variance = np.full(shape, 0.25)
    spp = 16
    test = reference + rng.standard_normal(shape) * np.sqrt(variance / spp)
    p_values = z_test(test, reference, variance, spp).p_values
    sigma = np.sqrt(0.05 * 0.95 / p_values.size)
    assert abs(np.mean(p_values < 0.05) - 0.05) < 4 * sigma


def test_variance_floor_keeps_noiseless_pixels_finite():
    reference = np.zeros((16, 16, 3))
    result = z_test(reference + 1e-6, reference, np.zeros_like(reference), 4)
    assert result.passed
    assert np.isfinite(result.z).all()


def test_nan_pixels_are_rejected_not_crashed(scene, rng):
    truth, reference_mean, reference_variance = scene
    test = render(truth, TEST_SPP, rng)
    test[0, 0, 0] = np.nan
    result = z_test(test, reference_mean, reference_variance, TEST_SPP)
    assert not result.accepted[0, 0, 0]
    assert result.passed  # one channel in 6912 is within the 0.25 % allowed


def test_images_and_grey_arrays_are_accepted(scene, rng):
    truth, reference_mean, reference_variance = scene
    test = Image(render(truth, TEST_SPP, rng))
    assert z_test(test, Image(reference_mean), Image(reference_variance), TEST_SPP).passed
    grey = z_test(test.rgb[..., 0], reference_mean[..., 0], reference_variance[..., 0],
                  TEST_SPP)
    assert grey.p_values.shape == SHAPE[:2] + (1,)


@pytest.mark.parametrize("spp", [0, 2.5])
def test_z_test_needs_integer_spp(spp):
    with pytest.raises(InputError, match=f"spp = {spp}: must be an integer >= 1"):
        z_test(np.ones((4, 4)), np.ones((4, 4)), np.ones((4, 4)), spp)


def test_z_test_refuses_negative_variance():
    with pytest.raises(InputError, match=r"reference_variance = -1.0: must be >= 0"):
        z_test(np.ones((4, 4)), np.ones((4, 4)), -np.ones((4, 4)), 4)


def test_z_test_lists_every_shape():
    with pytest.raises(InputError, match=r"test_mean \(4, 4, 1\), reference_mean "
                                         r"\(4, 5, 1\), reference_variance \(4, 4, 1\)"):
        z_test(np.ones((4, 4)), np.ones((4, 5)), np.ones((4, 4)), 4)


def test_z_test_refuses_a_stack_of_images():
    with pytest.raises(InputError, match=r"test_mean = \(2, 4, 4, 3\): must be an H x W"):
        z_test(np.ones((2, 4, 4, 3)), np.ones((2, 4, 4, 3)), np.ones((2, 4, 4, 3)), 4)


# ----------------------------------------------------------------------------- two renders


def noisy_pair(truth, rng, passes=8, spp=16, second_truth=None):
    """Two independent multi-pass renders, each with its variance of the mean."""
    images = []
    for mean in (truth, truth if second_truth is None else second_truth):
        pass_means = np.stack([render(mean, spp, rng) for _ in range(passes)])
        images.append(Image(pass_means.mean(axis=0),
                            pass_means.var(axis=0, ddof=1) / passes,
                            metadata={"passes": passes}))
    return images


def test_two_renders_of_the_same_image_agree(scene, rng):
    truth = scene[0]
    first, second = noisy_pair(truth, rng)
    assert z_test_known_variance(first, second).passed


def test_two_renders_of_different_images_disagree(scene, rng):
    """16 passes of 64 spp, one image 1.5 times the other.

    Standard errors 0.031 T and 0.047 T: z = 0.5 / 0.056 = 8.9 on average, above the
    Student-t bound 5.8 (about 26 Welch-Satterthwaite degrees of freedom, alpha 4.4e-6).
    """
    truth = scene[0]
    first, second = noisy_pair(truth, rng, passes=16, spp=64, second_truth=1.5 * truth)
    assert not z_test_known_variance(first, second).passed


def test_known_variance_needs_a_variance():
    with pytest.raises(InputError, match=r"second.variance = None: needs its per-pixel "
                                         r"variance of the mean"):
        z_test_known_variance(Image(np.ones((4, 4, 3)), np.ones((4, 4, 3))),
                              Image(np.ones((4, 4, 3))))


def test_known_variance_needs_images():
    with pytest.raises(TypeError, match="first must be a translucent.image.Image"):
        z_test_known_variance(np.ones((4, 4, 3)), Image(np.ones((4, 4, 3))))


def test_a_render_against_an_exact_value(rng):
    """A furnace-style check: a noisy render against an analytic constant of zero variance."""
    exact = Image(np.full((16, 16, 3), 0.8), np.zeros((16, 16, 3)))
    first, _ = noisy_pair(np.full((16, 16, 3), 0.8), rng)
    assert z_test_known_variance(first, exact).passed
    darker, _ = noisy_pair(np.full((16, 16, 3), 0.6), rng)
    assert not z_test_known_variance(darker, exact).passed


def test_estimated_variances_need_students_t(rng):
    """Eight passes against an exact value, 16 x 16 pixels.

    With the pass count (Student's t, 7 degrees of freedom) every render passes. Judged
    by normal tails, P(|t_7| > 4.11) = 0.45 % of the 768 channels are rejected on
    average, 3.5 where 1.9 are allowed: a render fails with probability 0.86 (Poisson),
    so at least half of 40 renders fail (a binomial tail below 1e-7).
    """
    truth = np.full((16, 16, 3), 0.8)
    exact = Image(truth, np.zeros_like(truth))
    failures_with_normal_tails = 0
    for _ in range(40):
        render_, _ = noisy_pair(truth, rng)
        assert z_test_known_variance(render_, exact).passed
        failures_with_normal_tails += not z_test_known_variance(
            render_, exact, passes=(None, None)).passed
    assert failures_with_normal_tails >= 20


def test_pass_counts_must_be_at_least_two():
    image = Image(np.ones((4, 4, 3)), np.ones((4, 4, 3)), metadata={"passes": 1})
    with pytest.raises(InputError, match="first passes = 1: an estimated variance needs"):
        z_test_known_variance(image, image)


def test_block_means_average_pixels_and_their_variances():
    from translucent.reports.metrics.statistics import block_means

    rgb = np.arange(8 * 6 * 3, dtype=float).reshape(8, 6, 3)
    variance = np.full((8, 6, 3), 4.0)
    blocks = block_means(Image(rgb, variance, {"passes": 5}), 2)
    assert blocks.shape == (4, 3) and blocks.metadata["passes"] == 5
    np.testing.assert_allclose(blocks.rgb[0, 0], rgb[:2, :2].mean(axis=(0, 1)))
    np.testing.assert_allclose(blocks.variance, 1.0)  # 4 pixels of variance 4: 4 * 4 / 16
    assert block_means(Image(rgb, variance), 5).shape == (1, 1)  # partial blocks dropped
    with pytest.raises(InputError, match="variance"):
        block_means(Image(rgb), 2)
    with pytest.raises(InputError, match="size"):
        block_means(Image(rgb, variance), 9)


# -- a reference that is itself noisy ------------------------------------------------------


def _noisy_pair(rng, passes, spp_ref, spp_test, shape=(200, 250, 3), sigma=1.0):
    """A reference of ``passes`` passes and an independent test, Gaussian samples of mean 1."""
    pass_means = 1.0 + rng.normal(0.0, sigma / np.sqrt(spp_ref), (passes,) + shape)
    reference = pass_means.mean(axis=0)
    mean_variance = pass_means.var(axis=0, ddof=1) / passes
    per_sample = mean_variance * spp_ref * passes
    test = 1.0 + rng.normal(0.0, sigma / np.sqrt(spp_test), shape)
    return test, reference, per_sample


@pytest.mark.parametrize("passes, spp_ref, spp_test", [(4, 4, 16), (8, 16, 16), (32, 64, 4)])
def test_a_noisy_reference_gives_calibrated_p_values(rng, passes, spp_ref, spp_test):
    """With the reference's samples and passes, p-values are uniform: 5 % fall below 0.05.

    Each pixel's own variance (the t model itself); pooled over its neighbours (the
    default) the test is conservative for normal pixels: fewer fall below.
    """
    test, reference, per_sample = _noisy_pair(rng, passes, spp_ref, spp_test)
    options = {"variance_floor": 0.0, "reference_samples": spp_ref * passes,
               "reference_passes": passes}
    result = z_test(test, reference, per_sample, spp_test, variance_neighbourhood=0,
                    **options)
    below = np.mean(result.p_values < 0.05)
    count = result.p_values.size
    assert abs(below - 0.05) < 5 * np.sqrt(0.05 * 0.95 / count)
    pooled = z_test(test, reference, per_sample, spp_test, **options)
    assert np.mean(pooled.p_values < 0.05) < 0.05


def test_taking_a_noisy_reference_as_exact_rejects_honest_renders(rng):
    """The check can fail: Mitsuba's form on a 4-pass reference is far from calibrated."""
    test, reference, per_sample = _noisy_pair(rng, 4, 4, 16)
    exact = z_test(test, reference, per_sample, 16, variance_floor=0.0)
    assert np.mean(exact.p_values < 0.05) > 0.2
    assert not exact.passed


def test_a_reference_pass_count_is_checked(rng):
    test, reference, per_sample = _noisy_pair(rng, 4, 4, 16, shape=(4, 4, 3))
    with pytest.raises(InputError, match="reference_passes = 1"):
        z_test(test, reference, per_sample, 16, reference_samples=4, reference_passes=1)
    with pytest.raises(InputError, match="reference_samples = 2"):
        z_test(test, reference, per_sample, 16, reference_samples=2, reference_passes=4)


def _rare_path_render(rng, samples, shape=(32, 32, 3)):
    """A mean of ``samples`` samples per pixel: 0.1 plus, rarely, a path of radiance 1.

    The rare path's probability grows from 0.4 % to 3.4 % across the image, as light that
    a long random walk reaches seldom: few passes of a reference miss it in many pixels.
    """
    columns = np.arange(shape[1]) / shape[1]
    probability = np.broadcast_to((0.004 + 0.03 * columns)[None, :, None], shape)
    return 0.1 + rng.binomial(samples, probability) / samples


def test_pooling_the_variance_keeps_rare_paths_from_failing_honest_renders():
    from translucent.reports.metrics.statistics import z_test

    rng = np.random.default_rng(0)
    rejected = {"own": 0, "pooled": 0}
    for _ in range(20):
        passes = np.stack([_rare_path_render(rng, 16) for _ in range(8)])
        per_sample = 16 * passes.var(axis=0, ddof=1)
        test = _rare_path_render(rng, 16)
        for kind, radius in (("own", 0), ("pooled", 1)):
            result = z_test(test, passes.mean(axis=0), per_sample, 16, reference_samples=128,
                            reference_passes=8, variance_neighbourhood=radius)
            rejected[kind] += int((~result.accepted).sum())
    # 20 x 3072 channels: each pixel's own estimate is 0 wherever the passes missed the
    # path, and a test that caught it is then rejected
    assert rejected["own"] > 1000
    assert rejected["pooled"] <= 20, rejected


def _block_test_trials(make_render, trials: int, seed: int) -> dict[str, int]:
    """Honest and 1.2x renders of 16 spp against 8 passes of 16: how many fail each test."""
    from translucent.reports.metrics.statistics import z_test, z_test_blocks

    rng = np.random.default_rng(seed)
    failures = {"honest": 0, "bright": 0, "bright_pixel": 0}
    options = {"reference_samples": 128, "reference_passes": 8}
    for _ in range(trials):
        passes = np.stack([make_render(rng, 16) for _ in range(8)])
        reference, per_sample = passes.mean(axis=0), 16 * passes.var(axis=0, ddof=1)
        test = make_render(rng, 16)
        failures["honest"] += not z_test_blocks(test, reference, per_sample, 16, **options)
        failures["bright"] += not z_test_blocks(1.2 * test, reference, per_sample, 16,
                                                **options)
        failures["bright_pixel"] += not z_test(1.2 * test, reference, per_sample, 16,
                                               **options)
    return failures


def test_block_means_catch_a_render_a_fifth_too_bright_and_pass_honest_ones():
    failures = _block_test_trials(_rare_path_render, 20, seed=1)
    assert failures["honest"] <= 1
    assert failures["bright"] == 20
    assert failures["bright_pixel"] < 20  # what the per-pixel test alone lets through


def test_one_firefly_the_reference_never_met_does_not_reject_its_block():
    """A 16-spp render with one rare bright path, against 8 passes that all missed it."""
    from translucent.reports.metrics.statistics import z_test_blocks

    rng = np.random.default_rng(2)
    passes = 0.1 + 0.01 * rng.standard_normal((8, 16, 16, 3))
    reference, per_sample = passes.mean(axis=0), 16 * passes.var(axis=0, ddof=1)
    test = 0.1 + 0.04 * rng.standard_normal((16, 16, 3))
    test[3, 5, 0] += 50.0 / 16  # one sample of radiance 50 among the pixel's 16
    options = {"reference_samples": 128, "reference_passes": 8}
    result = z_test_blocks(test, reference, per_sample, 16, **options)
    assert result.passed, result.summary()
    assert "of 12 block channels accepted" in result.summary()
    # a drift of every pixel of a block is still seen past the firefly
    drifted = test.copy()
    drifted[:8, :8] += 0.03
    assert not z_test_blocks(drifted, reference, per_sample, 16, **options).passed


def _firefly_render(rng, samples, shape=(32, 32, 3)):
    """A mean of ``samples`` samples: 0.1 with noise, and a path of radiance 20 at 1/4000.

    A block of 8 x 8 pixels of 16 samples meets the path a quarter of the time, and a
    reference of 8 passes of 16 about twice: its variance misses it in many blocks.
    """
    base = 0.1 + 0.05 * rng.standard_normal(shape) / np.sqrt(samples)
    return base + 20.0 * rng.binomial(samples, 1 / 4000, size=shape) / samples


def test_block_means_pass_honest_renders_with_fireflies_and_catch_a_fifth_too_bright():
    failures = _block_test_trials(_firefly_render, 40, seed=3)
    # the stated family-wise significance is 1 % a channel; with the reference's modelled
    # variance alone 28 of these 40 honest renders failed
    assert failures["honest"] <= 2, failures
    assert failures["bright"] == 40, failures


def test_block_means_need_two_blocks_and_check_their_input():
    from translucent.reports.metrics.statistics import z_test_blocks

    small = np.ones((8, 12, 3))
    assert z_test_blocks(small, small, small, 4, reference_samples=8,
                         reference_passes=2) is None
    with pytest.raises(InputError, match="reference_variance"):
        z_test_blocks(np.ones((16, 16, 3)), np.ones((16, 16, 3)), -np.ones((16, 16, 3)), 4,
                      reference_samples=8, reference_passes=2)
