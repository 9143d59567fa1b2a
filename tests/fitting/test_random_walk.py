"""The photon random walk: a published benchmark, energy conservation, the dipole where it holds."""

import numpy as np
import pytest
from translucent.errors import InputError
from translucent.fitting.random_walk import Film, photon_random_walk, walk_capture
from translucent.fitting.walk_kernel import drjit_available
from translucent.materials import Dipole, dipole_reflectance_profile

#: van de Hulst's values for the MCML benchmark slab (Wang, Jacques & Zheng 1995, Table 2:
#: n = 1, mu_a = 10 cm^-1, mu_s = 90 cm^-1, g = 0.75, d = 0.02 cm), at their precision.
VAN_DE_HULST_REFLECTANCE = 0.09739
VAN_DE_HULST_TRANSMITTANCE = 0.66096
#: Published values are compared within 4 Monte Carlo standard errors plus half a unit in
#: their last digit.
PUBLISHED_SIGMAS = 4.0
#: Where the dipole holds (reduced albedo 0.99, eta = 1.3, 2-10 transport lengths from the
#: beam), the classical dipole differs from transport theory by a few per cent up to about
#: ten (its extrapolated-boundary and single-depth-source approximations; Donner & Jensen
#: 2005, d'Eon 2012): the walk must agree within this, plus 3 Monte Carlo standard errors.
DIPOLE_ACCURACY = 0.10


BACKENDS = ["numpy", pytest.param("drjit", marks=pytest.mark.skipif(
    not drjit_available(), reason="Dr.Jit's LLVM backend is not available"))]


@pytest.mark.parametrize("backend", BACKENDS)
def test_mcml_benchmark_slab(backend):
    # 0.1 mm^-1 per cm^-1: mu_a = 1, mu_s = 9 mm^-1 (sigma_s' = 9 x 0.25), d = 0.2 mm
    slab = Dipole(sigma_a=1.0, sigma_s_prime=2.25, g=0.75, eta=1.0)
    tally = photon_random_walk(slab, photons=60000, thickness_mm=0.2, seed=1, channels=(0,),
                               backend=backend)
    reflect, reflect_se = tally.total_reflectance[0], tally.total_reflectance_se[0]
    transmit, transmit_se = tally.total_transmittance[0], tally.total_transmittance_se[0]
    assert abs(reflect - VAN_DE_HULST_REFLECTANCE) < PUBLISHED_SIGMAS * reflect_se + 5e-6
    assert abs(transmit - VAN_DE_HULST_TRANSMITTANCE) < PUBLISHED_SIGMAS * transmit_se + 5e-6


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("eta", [1.0, 1.3])
def test_without_absorption_everything_leaves_or_is_counted_lost(eta, backend):
    medium = Dipole(sigma_a=0.0, sigma_s_prime=2.0, eta=eta)
    tally = photon_random_walk(medium, photons=4000, seed=2, r_kill_mm=3.0, channels=(0,),
                               backend=backend)
    # weights are only ever split at boundaries or moved by unbiased roulette: the sum of
    # what left and what was dropped at the kill radius is 1 in expectation; roulette adds
    # noise of order 1e-4 / sqrt(N)
    assert tally.total_reflectance[0] + tally.lost[0] == pytest.approx(1.0, abs=5e-3)
    assert tally.total_transmittance[0] == 0.0


@pytest.mark.parametrize("backend", BACKENDS)
def test_agrees_with_the_dipole_where_the_dipole_holds(backend):
    medium = Dipole(sigma_a=0.01, sigma_s_prime=1.0, eta=1.3)
    edges = np.array([2.0, 3.5, 5.0, 7.5, 10.0])
    tally = photon_random_walk(medium, photons=20000, seed=3, radial_edges_mm=edges,
                               r_kill_mm=20.0, channels=(0,), backend=backend)
    fine = np.linspace(edges[0], edges[-1], 16001)
    dipole = dipole_reflectance_profile(fine, 0.01, 1.0, 1.3)
    expected = [np.trapezoid((dipole * fine)[(fine >= a) & (fine <= b)],
                             fine[(fine >= a) & (fine <= b)]) * 2 / (b * b - a * a)
                for a, b in zip(edges[:-1], edges[1:], strict=True)]
    ratio = tally.reflectance[:, 0] / expected
    error = tally.reflectance_se[:, 0] / expected
    assert np.all(np.abs(ratio - 1) < DIPOLE_ACCURACY + 3 * error), ratio
    # and the comparison has teeth: twice the absorption is far outside the tolerance
    doubled = dipole_reflectance_profile(8.75, 0.02, 1.0, 1.3) / \
        dipole_reflectance_profile(8.75, 0.01, 1.0, 1.3)
    assert abs(doubled - 1) > 3 * DIPOLE_ACCURACY


@pytest.mark.parametrize("backend", BACKENDS)
def test_film_holds_the_same_light_as_the_tally(backend):
    medium = Dipole(sigma_a=0.5, sigma_s_prime=2.0, eta=1.3)
    film = Film((40, 40), 0.1, (20.0, 20.0))
    tally = photon_random_walk(medium, photons=3000, seed=4, film=film, channels=(0,),
                               beam_radius_mm=0.2, backend=backend)
    on_film = tally.film[..., 0].sum() * 0.1 ** 2
    # the 4 x 4 mm film misses only the light leaving > 2 mm away (exp(-sigma_tr 2) tail)
    assert on_film == pytest.approx(tally.total_reflectance[0], rel=0.02)
    assert on_film <= tally.total_reflectance[0] * (1 + 1e-12)


def test_walk_capture_records_truth_and_bad_input():
    medium = Dipole(sigma_a=0.3, sigma_s_prime=1.0, eta=1.3, name="test")
    stored, spec, tally = walk_capture(medium, size=24, pixel_size_mm=0.2, photons=500,
                                       rotations=2, seed=5)
    assert stored.shape == (24, 24, 3)
    assert spec.synthetic["generator"] == "photon random walk"
    assert spec.synthetic["photons"] == 500 and spec.exposure is None
    with pytest.raises(InputError, match="transmission needs a finite thickness"):
        walk_capture(medium, side="transmission", photons=100)
    with pytest.raises(InputError, match="must be > 0 or None"):
        photon_random_walk(medium, photons=100, thickness_mm=-1.0)
    with pytest.raises(InputError, match="need photons >= batches >= 2"):
        photon_random_walk(medium, photons=5)
    with pytest.raises(InputError, match="must be 'auto', 'drjit' or 'numpy'"):
        photon_random_walk(medium, photons=100, backend="cuda")


@pytest.mark.skipif(not drjit_available(), reason="Dr.Jit's LLVM backend is not available")
def test_both_backends_agree_on_the_profile():
    medium = Dipole(sigma_a=0.05, sigma_s_prime=1.5, eta=1.4)
    edges = np.array([0.0, 0.5, 1.0, 2.0, 4.0])
    tallies = [photon_random_walk(medium, photons=20000, seed=seed, radial_edges_mm=edges,
                                  channels=(0,), backend=backend)
               for seed, backend in ((5, "numpy"), (6, "drjit"))]
    difference = tallies[0].reflectance[:, 0] - tallies[1].reflectance[:, 0]
    error = np.hypot(tallies[0].reflectance_se[:, 0], tallies[1].reflectance_se[:, 0])
    # independent estimates of the same profile: within 4 combined standard errors
    assert np.all(np.abs(difference) < 4 * error), difference / error


def test_one_seed_gives_one_capture():
    # the compiled walk appends exits from parallel lanes in any order; the capture (each
    # exit's rotation, its pixel, the camera noise) must not depend on that order
    medium = Dipole(sigma_a=[0.01, 0.05, 0.2], sigma_s_prime=[1.0, 1.5, 2.0], eta=1.3)
    options = dict(size=24, pixel_size_mm=0.2, photons=20000, seed=5)
    first, _, _ = walk_capture(medium, **options)
    second, _, _ = walk_capture(medium, **options)
    np.testing.assert_array_equal(first, second)
    other, _, _ = walk_capture(medium, **{**options, "seed": 6})
    assert not np.array_equal(first, other)


def test_walk_capture_refuses_an_incident_point_outside_the_image():
    medium = Dipole(sigma_a=0.3, sigma_s_prime=1.0, eta=1.3, name="test")
    with pytest.raises(InputError, match="must lie inside the 24 x 24 image") as error:
        walk_capture(medium, size=24, pixel_size_mm=0.2, incident_px=(30.0, 5.0),
                     photons=100, rotations=1)
    assert error.value.field == "incident_px"


@pytest.mark.parametrize("photons", [float("nan"), float("inf")])
def test_a_non_finite_photon_count_is_an_input_error(photons):
    medium = Dipole(sigma_a=0.3, sigma_s_prime=1.0, eta=1.3, name="test")
    with pytest.raises(InputError, match="must be a finite number") as error:
        photon_random_walk(medium, photons=photons)
    assert error.value.field == "photons"
