"""Christensen-Burley normalized diffusion: the published fits and appleseed's tables."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from translucent.errors import InputError
from translucent.materials import Dipole, measured_medium
from translucent.materials.profiles import BurleyProfile, RandomWalkProfile, profile
from translucent.materials.profiles.burley import (
    CYCLES_TRUNCATION,
    burley_cumulative,
    burley_radius,
    burley_scaling,
)

#: appleseed's unit tests (``test_sss.cpp``) check their values to 1e-4 (float): the
#: tables below are theirs, copied at their precision.
APPLESEED_EPS = 1e-4

#: ``NormalizedDiffusionS``: s = 3.5 + 100 (A - 0.33)^4 at A = 0, 0.05, .., 1 (Eq. 8).
APPLESEED_S_DMFP = [4.68592, 4.11466, 3.77984, 3.60498, 3.52856, 3.5041, 3.50008, 3.50002,
                    3.5024, 3.52074, 3.58352, 3.73426, 4.03144, 4.54858, 5.37416, 6.6117,
                    8.37968, 10.8116, 14.056, 18.2763, 23.6511]

#: ``NormalizedDiffusionR``: R(r) at r = 0.05, 0.15, .. for A = 0.5, l = 1, s = 3.583521.
APPLESEED_R = [2.53511, 0.674967, 0.327967, 0.192204, 0.124137, 0.0852575, 0.0611367,
               0.0452741, 0.0343737, 0.0266197, 0.0209473, 0.0167009, 0.0134603, 0.0109471,
               0.00897108, 0.00739936, 0.00613676, 0.00511384, 0.00427902, 0.0035934,
               0.00302721]

#: ``NormalizedDiffusionCDF``: Eq. 11 at r = 0.05, 0.15, .. for l = 1, s = 14.056001.
APPLESEED_CDF = [0.282838, 0.598244, 0.760091, 0.85267, 0.908478, 0.942885, 0.964293,
                 0.97766, 0.98602, 0.99125, 0.994523, 0.996572, 0.997854, 0.998657, 0.999159,
                 0.999474, 0.999671, 0.999794, 0.999871, 0.999919, 0.999949, 0.999968,
                 0.99998, 0.999988, 0.999992, 0.999995, 0.999997, 0.999998, 0.999999,
                 0.999999, 1.0]


def test_the_dmfp_fit_is_appleseeds_table():
    albedo = np.linspace(0.0, 1.0, 21)
    assert burley_scaling(albedo, "dmfp") == pytest.approx(APPLESEED_S_DMFP, abs=APPLESEED_EPS)


def test_the_mean_free_path_fits_are_eq_5_and_6():
    a = np.array([0.0, 0.3, 0.8, 1.0])
    # Eq. 5 (appleseed's normalized_diffusion_s_mfp), Eq. 6 (Cycles' bssrdf_burley_fitting)
    assert burley_scaling(a, "searchlight") == pytest.approx(
        1.85 - a + 7 * np.abs(a - 0.8) ** 3, rel=1e-15)
    assert burley_scaling(a, "transmission") == pytest.approx(
        1.9 - a + 3.5 * (a - 0.8) ** 2, rel=1e-15)
    assert burley_scaling(0.8, "searchlight") == pytest.approx(1.05)
    assert burley_scaling(0.8, "transmission") == pytest.approx(1.1)
    assert burley_scaling(a, "cycles") == pytest.approx(np.ones(4))


def test_the_profile_is_appleseeds_table():
    # l_d = 1 / sqrt(3 sigma_a sigma_t') = 1 with sigma_a = 1/3, sigma_t' = 1
    made = BurleyProfile(Dipole(1 / 3, 2 / 3), "dmfp", surface_albedo=0.5)
    assert made.d == pytest.approx(np.full(3, 1 / 3.583521), rel=1e-6)
    r = 0.05 + 0.1 * np.arange(21)
    assert made.reflection(r)[:, 1] == pytest.approx(APPLESEED_R, abs=APPLESEED_EPS)


def test_the_cumulative_is_appleseeds_table_and_cycles_constant():
    r = 0.05 + 0.1 * np.arange(31)
    assert burley_cumulative(r * 14.056001) == pytest.approx(APPLESEED_CDF, abs=APPLESEED_EPS)
    # Cycles' BURLEY_TRUNCATE_CDF, cdf(16), printed to 16 digits in bssrdf.h
    assert burley_cumulative(CYCLES_TRUNCATION) == pytest.approx(0.9963790093708328,
                                                                 abs=1e-15)


@given(fraction=st.floats(min_value=0.0, max_value=1.0 - 1e-12))
@settings(max_examples=200, deadline=None)
def test_the_closed_form_inverse_inverts_eq_11(fraction):
    x = burley_radius(fraction)
    assert x >= 0
    assert burley_cumulative(x) == pytest.approx(fraction, abs=1e-13)


def test_parameters_come_from_the_medium():
    medium = measured_medium("Skin1")
    walk_total = RandomWalkProfile(medium).total()
    sigma_t = medium.sigma_a + medium.sigma_s_prime
    for fit, length in (("searchlight", 1 / sigma_t), ("transmission", 1 / sigma_t),
                        ("dmfp", 1 / np.sqrt(3 * medium.sigma_a * sigma_t))):
        made = profile(f"burley_{fit}", medium)
        assert made.surface_albedo == pytest.approx(walk_total, rel=1e-12)
        assert made.d == pytest.approx(length / burley_scaling(walk_total, fit), rel=1e-12)
    cycles = profile("burley_cycles", medium)
    assert cycles.d == pytest.approx(1 / sigma_t, rel=1e-12)  # Cycles' radius / (4 pi)
    assert cycles.total() == pytest.approx(walk_total, rel=1e-12)


def test_cycles_cuts_at_16_d_and_renormalises():
    made = profile("burley_cycles", "Marble", surface_albedo=0.5)
    d = made.d
    inside = made.reflection(0.99 * CYCLES_TRUNCATION * d[0])[0]
    assert inside > 0 and made.reflection(1.01 * CYCLES_TRUNCATION * d[0])[0] == 0
    plain = profile("burley_searchlight", "Marble", surface_albedo=0.5)
    # the same shape at s = 1 (d = l), divided by cdf(16)
    expected = 0.5 * (np.exp(-1) + np.exp(-1 / 3)) / (8 * np.pi * d * d) / 0.9963790093708328
    assert made.reflection(d[0])[0] == pytest.approx(expected[0], rel=1e-12)
    assert plain.total() == pytest.approx(made.total())
    assert np.all(made.sample_radius(np.linspace(0, 1, 101), 0) <= CYCLES_TRUNCATION * d[0])


def test_the_sampled_density_is_exact():
    made = profile("burley_searchlight", "Marble", surface_albedo=[0.2, 0.5, 0.9])
    r = np.geomspace(1e-4, 50, 200)
    for channel in range(3):
        density = 2 * np.pi * r * made.reflection(r)[:, channel] / made.total()[channel]
        assert made.pdf(r, channel) == pytest.approx(density, rel=1e-12)
    u = np.linspace(0.0, 0.999, 50)
    radii = made.sample_radius(u, 1)
    assert burley_cumulative(radii / made.d[1]) == pytest.approx(u, abs=1e-12)


def test_bad_input_is_named():
    with pytest.raises(InputError, match="surface_albedo = 1.2: must lie in \\[0, 1\\]"):
        profile("burley_searchlight", "Marble", surface_albedo=1.2)
    with pytest.raises(InputError, match="surface_albedo = .*nan"):
        burley_scaling(float("nan"), "dmfp")
    with pytest.raises(InputError, match="fit = 'mfp': unknown Burley fit; valid: searchlight"):
        BurleyProfile(measured_medium("Marble"), "mfp")
    with pytest.raises(InputError, match="sigma_a = .*every channel needs sigma_a > 0"):
        profile("burley_dmfp", "Spectralon")
    with pytest.raises(InputError, match="eta = 2.5: the walk table covers eta 1 .. 2"):
        profile("burley_searchlight", Dipole(0.1, 1.0, eta=2.5))
    # a given albedo needs no walk table
    assert profile("burley_searchlight", Dipole(0.1, 1.0, eta=2.5), surface_albedo=0.4)
