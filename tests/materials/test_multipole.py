"""The multipole of Donner & Jensen 2005: limits, energy, the per-material implementation."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from translucent.materials import Dipole, dipole_reflectance_profile
from translucent.materials.multipole import multipole_profiles, pole_count
from translucent.materials.profiles import SlabProfile

#: Same formula, different code: agreement to round-off.
SAME_FORMULA = 1e-10
#: Without absorption, what enters leaves (R + T = 1). The pole sum then converges only
#: like 1/n (sigma_tr = 0: no exponential damping of far images); with n = 200 pairs and
#: d >= 2 transport lengths the flux missed is below 1e-3 (0.5 % with n = 64 at d = 2).
ENERGY = 1e-3
ENERGY_POLES = 200

coefficient = st.floats(1e-3, 2.0)
scattering = st.floats(0.2, 20.0)
eta = st.floats(1.0, 1.6)


@settings(max_examples=30)
@given(sigma_a=coefficient, sigma_s=scattering, eta=eta)
def test_thick_slab_reflectance_is_the_dipole(sigma_a, sigma_s, eta):
    r = np.linspace(0, 5, 51)
    thick = 1e4 / min(sigma_a, sigma_s)
    reflect, transmit = multipole_profiles(r, sigma_a, sigma_s, eta, thick)
    dipole = dipole_reflectance_profile(r, sigma_a, sigma_s, eta)
    np.testing.assert_allclose(reflect, dipole, rtol=SAME_FORMULA, atol=1e-300)
    assert np.all(transmit < 1e-30)


@settings(max_examples=3, deadline=None)
@given(sigma_s=st.floats(1.0, 3.0), eta=eta, thickness=st.floats(2.0, 6.0))
def test_no_absorption_conserves_energy(sigma_s, eta, thickness):
    r = np.concatenate([np.arange(0, 5, 0.0025), np.arange(5, 60, 0.02)])
    reflect, transmit = multipole_profiles(r, 0.0, sigma_s, eta, thickness, poles=ENERGY_POLES)
    total = np.trapezoid(2 * np.pi * r * (reflect + transmit), r)
    assert total == pytest.approx(1.0, abs=ENERGY)


@settings(max_examples=20)
@given(sigma_a=coefficient, sigma_s=scattering, eta=eta, thickness=st.floats(0.5, 20))
def test_agrees_with_materials_slab_profile(sigma_a, sigma_s, eta, thickness):
    medium = Dipole(sigma_a=sigma_a, sigma_s_prime=sigma_s, eta=eta)
    if thickness <= float(np.max(medium.mean_free_path)):
        return  # SlabProfile rejects slabs thinner than a transport length
    r = np.linspace(0, 10, 41)
    poles = 5
    slab = SlabProfile(medium, thickness, pairs=poles, entry_fresnel=False)
    reflect, transmit = multipole_profiles(r[:, None], medium.sigma_a, medium.sigma_s_prime,
                                           eta, thickness, poles=poles)
    np.testing.assert_allclose(reflect, slab.reflection(r), rtol=1e-9, atol=1e-14)
    np.testing.assert_allclose(transmit, slab.transmission(r), rtol=1e-9, atol=1e-14)


def test_vectorised_over_parameter_sets_and_non_negative():
    r = np.linspace(0, 8, 33)[None, :, None]
    sigma_a = np.array([[0.01, 0.1, 1.0], [0.02, 0.2, 0.5]])[:, None, :]
    sigma_s = np.array([[1.0, 2.0, 3.0], [0.5, 1.5, 2.5]])[:, None, :]
    reflect, transmit = multipole_profiles(r, sigma_a, sigma_s, 1.3, 4.0)
    assert reflect.shape == transmit.shape == (2, 33, 3)
    assert np.all(reflect >= 0) and np.all(transmit >= 0)
    one, _ = multipole_profiles(r[0], sigma_a[1], sigma_s[1], 1.3, 4.0)
    np.testing.assert_allclose(reflect[1], one, rtol=1e-12)


def test_pole_count_grows_as_the_slab_thins_and_absorption_falls():
    assert pole_count(0.01, 1.0, 1.3, 1.0) > pole_count(0.01, 1.0, 1.3, 10.0)
    assert pole_count(0.001, 1.0, 1.3, 2.0) >= pole_count(0.5, 1.0, 1.3, 2.0)
    assert pole_count(1.0, 1.0, 1.3, 1e4) == 1


def test_nan_coefficients_do_not_crash():
    reflect, transmit = multipole_profiles(np.linspace(0, 1, 5), np.nan, 1.0, 1.3, 2.0,
                                           poles=2)
    assert np.all(reflect == 0) and np.all(transmit == 0)
