"""Reference noise summaries: relative standard error, lit pixels, median and percentile."""

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from translucent.noise import (
    LIT_FRACTION,
    lit_mask,
    noise_summary,
    relative_standard_error,
    resolvable_error,
)


def test_constant_image_has_the_relative_error_of_its_variance():
    rgb = np.full((8, 8, 3), 2.0)
    variance = np.full((8, 8, 3), 0.04**2)  # standard error 0.04 on a mean of 2: 2 %
    summary = noise_summary(rgb, variance)
    assert summary.median == pytest.approx(0.02)
    assert summary.p99 == pytest.approx(0.02)
    assert summary.pixels == 64 and summary.mask == "lit"
    assert summary.meets(0.02, 0.02) and not summary.meets(0.019)
    assert resolvable_error(summary) == pytest.approx(0.04)


def test_dark_pixels_are_not_counted():
    rgb = np.ones((10, 10, 3))
    rgb[:5] = 0.5 * LIT_FRACTION  # below the lit threshold
    variance = np.full((10, 10, 3), 1e-4)
    assert lit_mask(rgb).sum() == 50
    assert noise_summary(rgb, variance).pixels == 50


def test_mask_intersects_the_lit_pixels_and_is_named():
    rgb = np.ones((4, 4, 3))
    variance = np.zeros((4, 4, 3))
    variance[0, 0] = 1.0
    mask = np.zeros((4, 4), bool)
    mask[0] = True
    summary = noise_summary(rgb, variance, mask, mask_name="sphere")
    assert summary.pixels == 4 and summary.mask == "lit & sphere"
    assert summary.p99 > 0.9  # the noisy pixel is in the mask


def test_black_image_has_no_lit_pixels():
    summary = noise_summary(np.zeros((4, 4, 3)), np.zeros((4, 4, 3)))
    assert summary.pixels == 0 and math.isnan(summary.median)
    assert not summary.meets(1.0)
    assert summary.as_dict()["median"] is None
    assert "no lit pixels" in summary.text()


def test_zero_mean_pixel_has_infinite_relative_error():
    rse = relative_standard_error(np.zeros((1, 1, 3)), np.ones((1, 1, 3)))
    assert np.isinf(rse).all()


@settings(max_examples=40, deadline=None)
@given(scale=st.floats(1e-3, 1e3), seed=st.integers(0, 2**16))
def test_relative_error_is_invariant_to_exposure(scale, seed):
    rng = np.random.default_rng(seed)
    rgb = rng.uniform(0.1, 1.0, (6, 6, 3))
    variance = (rng.uniform(0.0, 0.1, (6, 6, 3)) * rgb) ** 2
    first = relative_standard_error(rgb, variance)
    second = relative_standard_error(scale * rgb, scale**2 * variance)
    np.testing.assert_allclose(first, second, rtol=1e-9)
    assert noise_summary(rgb, variance).median == pytest.approx(
        noise_summary(scale * rgb, scale**2 * variance).median, rel=1e-9)


def test_summary_matches_the_definition_on_random_data(rng):
    rgb = rng.uniform(0.5, 1.5, (16, 16, 3))
    variance = rng.uniform(0, 1e-3, (16, 16, 3))
    expected = np.sqrt(variance).mean(-1) / rgb.mean(-1)
    summary = noise_summary(rgb, variance)
    assert summary.median == pytest.approx(np.median(expected))
    assert summary.p99 == pytest.approx(np.percentile(expected, 99))
