import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.integrate import quad
from translucent.errors import InputError
from translucent.materials import (
    Dipole,
    diffuse_fresnel_reflectance,
    dipole_reflectance_profile,
    effective_transport_coefficient,
    measured_medium,
    measured_medium_names,
    total_diffuse_reflectance,
)

#: quad's own error estimate on these smooth integrands is below 1e-9; the closed form is
#: exact, so the two should agree to the integrator's precision.
INTEGRAL_RTOL = 1e-7

coefficient = st.floats(min_value=1e-6, max_value=1e3)
distance = st.floats(min_value=0.0, max_value=1e3)
index = st.floats(min_value=1.0, max_value=2.5)


@pytest.mark.parametrize("name", measured_medium_names())
def test_profile_integrates_to_the_closed_form_total_reflectance(name):
    medium = measured_medium(name)
    for channel in range(3):
        sigma_a = medium.sigma_a[channel]
        sigma_s_prime = medium.sigma_s_prime[channel]

        def integrand(r, sigma_a=sigma_a, sigma_s_prime=sigma_s_prime):
            return 2 * np.pi * r * dipole_reflectance_profile(r, sigma_a, sigma_s_prime,
                                                              medium.eta)

        # split at the scales where the integrand changes: the source depth z_r and the
        # diffusion length 1 / sigma_tr (infinite without absorption)
        z_r = 1.0 / (sigma_a + sigma_s_prime)
        sigma_tr = effective_transport_coefficient(sigma_a, sigma_s_prime)
        diffusion = 1.0 / sigma_tr if sigma_tr > 0 else 1e3 * z_r
        breaks = sorted({0.0, 10 * z_r, diffusion, 30 * max(diffusion, z_r)})
        pieces = list(zip(breaks, breaks[1:], strict=False)) + [(breaks[-1], np.inf)]
        integral = sum(quad(integrand, a, b, limit=400)[0] for a, b in pieces)
        expected = total_diffuse_reflectance(sigma_a, sigma_s_prime, medium.eta)
        assert integral == pytest.approx(expected, rel=INTEGRAL_RTOL)


def test_non_absorbing_medium_reflects_everything():
    assert total_diffuse_reflectance(0.0, 1.0, 1.3) == pytest.approx(1.0)


def test_no_scattering_reflects_nothing():
    assert dipole_reflectance_profile(np.linspace(0, 5, 7), 0.5, 0.0, 1.3) == pytest.approx(0)
    assert total_diffuse_reflectance(0.5, 0.0, 1.3) == pytest.approx(0)


def test_zero_extinction_is_finite_zero():
    assert dipole_reflectance_profile(1.0, 0.0, 0.0, 1.3) == 0.0


def test_diffuse_fresnel_polynomial_values():
    # the polynomial at eta = 1.3 and 1.5, evaluated by hand to 4 decimals
    assert diffuse_fresnel_reflectance(1.3) == pytest.approx(
        -1.440 / 1.69 + 0.710 / 1.3 + 0.668 + 0.0636 * 1.3, abs=1e-12)
    assert diffuse_fresnel_reflectance(1.0) == pytest.approx(0.0016, abs=1e-4)


def test_profile_broadcasts_over_distances_and_channels():
    r = np.linspace(0, 10, 11)[:, None]
    medium = measured_medium("skin1")
    profile = dipole_reflectance_profile(r, medium.sigma_a, medium.sigma_s_prime, medium.eta)
    assert profile.shape == (11, 3)
    assert np.all(np.diff(profile, axis=0) < 0)  # decreasing in r
    assert np.allclose(medium.profile(r[:, 0]), profile)


def test_float32_in_float32_out():
    profile = dipole_reflectance_profile(np.float32([0, 1, 2]), np.float32(0.1),
                                         np.float32(1.0), np.float32(1.3))
    assert profile.dtype == np.float32


@settings(max_examples=200, deadline=None)
@given(r=distance, sigma_a=coefficient, sigma_s_prime=coefficient, eta=index,
       dtype=st.sampled_from([np.float32, np.float64]))
def test_profile_finite_and_nonnegative_everywhere(r, sigma_a, sigma_s_prime, eta, dtype):
    value = dipole_reflectance_profile(dtype(r), dtype(sigma_a), dtype(sigma_s_prime), dtype(eta))
    assert np.isfinite(value) and value >= 0
    total = total_diffuse_reflectance(dtype(sigma_a), dtype(sigma_s_prime), dtype(eta))
    assert np.isfinite(total) and 0 <= total <= 1


@settings(max_examples=100, deadline=None)
@given(sigma_a=coefficient, sigma_s_prime=coefficient, eta=index)
def test_float32_agrees_with_float64(sigma_a, sigma_s_prime, eta):
    r = np.array([0.0, 0.1, 1.0, 10.0])
    p64 = dipole_reflectance_profile(r, sigma_a, sigma_s_prime, eta)
    p32 = dipole_reflectance_profile(r.astype(np.float32), np.float32(sigma_a),
                                     np.float32(sigma_s_prime), np.float32(eta))
    # float32 keeps about 7 digits; exp(-sigma_tr d) amplifies the input rounding by
    # sigma_tr d, so compare where the value is representable and the exponent moderate
    big = p64 > 1e-30
    assert np.allclose(p32[big], p64[big], rtol=1e-3 * (1 + np.log1p(1 / p64[big].min())))


@pytest.mark.parametrize("field, kwargs", [
    ("sigma_a", dict(sigma_a=-0.1, sigma_s_prime=1.0)),
    ("sigma_s_prime", dict(sigma_a=0.1, sigma_s_prime=[1.0, np.nan, 1.0])),
    ("eta", dict(sigma_a=0.1, sigma_s_prime=1.0, eta=0.5)),
    ("g", dict(sigma_a=0.1, sigma_s_prime=1.0, g=1.0)),
    ("sigma_a", dict(sigma_a=[0.1, 0.2], sigma_s_prime=1.0)),
])
def test_bad_coefficients_are_named(field, kwargs):
    with pytest.raises(InputError, match=field):
        Dipole(**kwargs)


def test_dipole_is_immutable():
    medium = Dipole(0.1, 1.0)
    with pytest.raises(ValueError):
        medium.sigma_a[0] = 2.0


@pytest.mark.parametrize("field", ["sigma_a", "sigma_s_prime"])
def test_coefficients_beyond_the_float_range_of_the_renderers_are_refused(field):
    from translucent.materials.homogeneous import MAX_COEFFICIENT

    values = {"sigma_a": 0.01, "sigma_s_prime": 1.0, field: 1e300}
    with pytest.raises(InputError, match=rf"{field} = .*must be <= {MAX_COEFFICIENT}"):
        Dipole(**values)
    Dipole(**{**values, field: MAX_COEFFICIENT})  # the bound itself is a medium
