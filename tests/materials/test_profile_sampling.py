"""The numerics every profile shares: the radial sampler, the log-spaced lookup, doctests."""

import doctest
import importlib

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from translucent.errors import InputError
from translucent.materials.profiles import TabulatedProfile, TwoExponentialProfile
from translucent.materials.profiles.sampling import (
    GRID_SAMPLES,
    LogRadialTable,
    RadialSampler,
    geometric_nodes,
)

MODULES = ("base", "boundary", "better_dipole", "burley", "classical_dipole",
           "directional_dipole", "photon_beam_diffusion", "quantized_diffusion",
           "random_walk", "registry", "sampling")


@pytest.mark.parametrize("module", MODULES)
def test_docstring_examples(module):
    found = importlib.import_module(f"translucent.materials.profiles.{module}")
    failures, _ = doctest.testmod(found, optionflags=doctest.NORMALIZE_WHITESPACE)
    assert failures == 0


def _linear_sampler():
    # density 2 pi r R(r) = 1 + r on [0, 2] in every channel: cumulative r + r^2 / 2
    radius = np.tile(np.linspace(0.0, 2.0, 3), (3, 1))
    return RadialSampler(radius, 1.0 + radius)


@given(u=st.floats(min_value=0.0, max_value=1.0))
@settings(max_examples=200, deadline=None)
def test_the_sampler_inverts_a_piecewise_linear_density_exactly(u):
    sampler = _linear_sampler()
    r = sampler.sample(np.array([u]), 1)[0]
    assert 0.0 <= r <= 2.0
    assert (r + r * r / 2) / 4.0 == pytest.approx(u, abs=1e-12)
    assert sampler.pdf(np.array([r]), 1)[0] == pytest.approx((1 + r) / 4.0, rel=1e-12)


def test_the_sampler_handles_channels_apart_and_empty_channels():
    radius = np.tile(np.linspace(0.0, 1.0, 5), (3, 1))
    density = np.stack([np.ones(5), np.zeros(5), radius[2]])
    sampler = RadialSampler(radius, density)
    u = np.array([[0.25, 0.5], [0.75, 1.0]])
    channel = np.array([[0, 1], [2, 0]])
    r = sampler.sample(u, channel)
    assert r.shape == (2, 2)
    np.testing.assert_allclose(r, [[0.25, 0.0], [np.sqrt(0.75), 1.0]], rtol=1e-12)
    assert sampler.pdf(np.array([0.5, 0.5, 0.5]), np.array([0, 1, 2])) == pytest.approx(
        [1.0, 0.0, 1.0])
    assert sampler.pdf(np.array([1.5, -0.1]), 0) == pytest.approx([0.0, 0.0])
    assert sampler.quantile(0.5) == pytest.approx([0.5, 0.0, np.sqrt(0.5)])


@given(ratio=st.floats(min_value=1e-3, max_value=1e3))
@settings(max_examples=30, deadline=None)
def test_the_lookup_is_exact_for_what_is_linear_in_ln_r(ratio):
    radius = geometric_nodes(np.array([1.0, ratio, 1.0 / ratio]))
    assert radius.shape == (3, GRID_SAMPLES + 1)
    with np.errstate(divide="ignore"):
        values = 40.0 - np.log(radius / radius[:, -1:])  # linear in ln r (inf at 0, unused)
    table = LogRadialTable(radius, values)
    for c in range(3):
        r = np.geomspace(radius[c, 1], radius[c, -1], 97)
        assert table(r)[:, c] == pytest.approx(40.0 - np.log(r / radius[c, -1]), rel=1e-9)
    assert np.all(table(np.array([2e6 * max(ratio, 1 / ratio, 1.0)])) == 0)
    assert table(np.array([0.0]))[0] == pytest.approx(values[:, 1])


def test_the_lookup_survives_nan_and_refuses_mixed_ratios():
    radius = geometric_nodes(np.ones(3))
    table = LogRadialTable(radius, np.ones_like(radius))
    out = table(np.array([np.nan, -1.0, 1.0, np.inf]))
    assert np.all(np.isnan(out[:2])) and np.all(out[2] == 1) and np.all(out[3] == 0)
    uneven = radius.copy()
    uneven[1] = geometric_nodes(np.ones(3), cutoff=np.full(3, 10.0))[1]
    with pytest.raises(InputError, match="radius = .*share one geometric ratio"):
        LogRadialTable(uneven, np.ones_like(radius))


def test_older_profiles_sample_too():
    table = TabulatedProfile([0.0, 1.0, 2.0], [2.0, 1.0, 0.0])
    r = table.sample_radius(np.linspace(0, 1, 101), 0)
    assert r.max() <= 2.0 and r.min() == 0.0
    assert table.radius_containing(0.999) == pytest.approx(np.full(3, 2.0), rel=0.05)
    two = TwoExponentialProfile(0.02, 1.0, 0.004, 0.2)
    # 2 pi r (a1 e^{-b1 r} + a2 e^{-b2 r}) / total, at the median
    median = two.radius_containing(0.5)
    assert two.pdf(median, [0, 1, 2]) == pytest.approx(
        2 * np.pi * median * two.reflection(median[0])[0] / two.total(), rel=1e-3)
