"""One harness over every registered profile: positivity, energy, limits, sampling, input.

A profile added to ``PROFILES`` (translucent.materials.profiles.registry) is checked here
without a line of its own: values finite and >= 0 everywhere, ``total()`` equal to an
independent quadrature of 2 pi r R(r), the albedo limits, and a chi-square test of
``sample_radius`` against R(r) r computed from the profile itself.
"""

import zlib

import numpy as np
import pytest
from scipy import stats
from translucent.errors import InputError
from translucent.materials import Dipole, measured_medium
from translucent.materials.profiles import (
    PROFILE_NAMES,
    PROFILES,
    RadialProfile,
    profile,
    profile_descriptions,
    profile_for,
)

#: Media that span the catalogue: nearly white and long (Marble), chromatic (Skin1),
#: strongly absorbing in green and blue (Ketchup).
MEDIA = ("Marble", "Skin1", "Ketchup")

#: total() against 32-point Gauss-Legendre on 600 log-spaced panels out to 1e7 mean free
#: paths. The dipoles' closed forms agree to 4e-15, Burley's to 2.5e-7 (its profile is held
#: at its value 1e-6 d from the beam, where it diverges); the tabulated ones (random walk,
#: quantized diffusion, directional average, beam diffusion) integrate their lookup's
#: nodes by the trapezoidal rule or pbrt's spline: measured within 1.6e-5.
ENERGY_RTOL = 1e-4

#: The chi-square test: samples per channel and the Sidak-corrected significance over all
#: (profile, medium, channel) cases, family-wise 1 %.
SAMPLES = 20_000
CASES = len(PROFILE_NAMES) * len(MEDIA) * 3
SIGNIFICANCE = 1.0 - (1.0 - 0.01) ** (1.0 / CASES)

#: How far the sampled density may stand from 2 pi r R(r) / E inside the radius holding
#: 99.9 % of the energy: the piecewise-linear density on nodes 0.68 % apart errs by
#: h^2/8 of the local curvature; measured at most 4.2e-4 (beam diffusion, Ketchup).
PDF_RTOL = 1e-3


def _made(name, medium):
    return profile(name, medium, radial=True)


def _panel_integral(made, channel, edges):
    """Integrals of 2 pi r R(r) between consecutive ``edges`` (mm) by panel Gauss-Legendre."""
    scale = made.length_scale()[channel]
    panels = np.unique(np.concatenate([edges, scale * np.geomspace(1e-8, 1e7, 600)]))
    panels = panels[(panels >= edges[0]) & (panels <= edges[-1])]
    nodes, weights = np.polynomial.legendre.leggauss(32)
    left, right = panels[:-1, None], panels[1:, None]
    r = 0.5 * (left + right) + 0.5 * (right - left) * nodes
    values = 2.0 * np.pi * r * made.reflection(r)[..., channel]
    pieces = np.sum(0.5 * (right - left) * weights * values, axis=1)
    cumulative = np.concatenate([[0.0], np.cumsum(pieces)])
    at = np.searchsorted(panels, edges)
    return np.diff(cumulative[at])


@pytest.mark.parametrize("name", PROFILE_NAMES)
def test_every_profile_is_described_in_one_line(name):
    description = profile_descriptions()[name]
    assert description and "\n" not in description
    made = _made(name, "Marble")
    assert isinstance(made, RadialProfile) and made.model == name
    text = made.describe()
    assert text.startswith(made.name) and "from the medium:" in text
    assert "total diffuse reflectance" in text


@pytest.mark.parametrize("medium", MEDIA)
@pytest.mark.parametrize("name", PROFILE_NAMES)
def test_values_are_finite_and_nonnegative_everywhere(name, medium):
    made = _made(name, medium)
    scale = made.length_scale()
    r = np.concatenate([[0.0], np.geomspace(1e-9, 1e9, 400) * scale.min(), [np.inf]])
    values = made.reflection(r)
    assert values.shape == (r.size, 3)
    assert np.all(np.isfinite(values[:-1])) and np.all(values >= 0)
    assert np.all(values[-1] == 0)


@pytest.mark.parametrize("name", PROFILE_NAMES)
def test_values_broadcast_over_any_shape_and_survive_nan(name):
    made = _made(name, "Skin1")
    r = np.linspace(0.0, 4.0, 24).reshape(2, 3, 4)
    values = made.reflection(r)
    assert values.shape == (2, 3, 4, 3)
    assert np.allclose(values.reshape(-1, 3), made.reflection(r.ravel()), rtol=1e-12)
    assert made.reflection(np.float64(1.0)).shape == (3,)
    with np.errstate(all="ignore"):
        odd = made.reflection(np.array([np.nan, 1.0]))
    assert odd.shape == (2, 3) and np.all(np.isfinite(odd[1]))


@pytest.mark.parametrize("medium", MEDIA)
@pytest.mark.parametrize("name", PROFILE_NAMES)
def test_total_is_the_energy_of_the_profile(name, medium):
    made = _made(name, medium)
    far = np.max(made.length_scale()) * 1e7
    cutoff = made.cutoff_radius()
    for channel in range(3):
        end = far if cutoff is None else cutoff[channel]
        energy = _panel_integral(made, channel, np.array([0.0, end]))[0]
        assert made.total()[channel] == pytest.approx(energy, rel=ENERGY_RTOL, abs=1e-12)


@pytest.mark.parametrize("name", PROFILE_NAMES)
def test_no_scattering_reflects_nothing(name):
    if name == "directional_dipole":
        # its extrapolation distance divides by the albedo: refused, not 0
        with pytest.raises(InputError, match="sigma_s_prime.*needs sigma_s' > 0"):
            _made(name, Dipole(1.0, 0.0))
        # and the published model has no albedo factor: as alpha' -> 0 the ray source's
        # diffusion term stays (0.138 at eta = 1.3, as appleseed's and the authors' group's
        # code evaluate it); measured here so that a change shows
        made = _made(name, Dipole(1.0, 1e-9))
        assert made.total() == pytest.approx(np.full(3, 0.1384), abs=1e-3)
        return
    made = _made(name, Dipole(1.0, 0.0))
    assert np.all(made.reflection(np.array([0.0, 0.1, 1.0])) == 0)
    assert np.all(made.total() == 0)
    assert np.all(_made(name, Dipole(1.0, 1e-9)).total() < 1e-8)


#: The non-absorbing, index-matched limit (alpha' -> 1, eta = 1). The diffusion profiles
#: conserve energy there up to their own approximations; photon beam diffusion adds single
#: scattering to a multiple-scattering term that already holds nearly all of it, and the
#: directional dipole's ray source overshoots: measured 1.084 and 1.337, the models'
#: values (pbrt-v4's table has the same excess).
WHITE_LIMIT = {
    "dipole": (1.0, 1e-3), "better_dipole": (1.0, 1e-3),
    "quantized_diffusion": (1.0, 0.01),  # the quantization: 0.4 % short
    "photon_beam_diffusion": (1.084, 0.01), "directional_dipole": (1.337, 0.01),
    "random_walk": (1.0, 0.01),  # the walk's kill radius and tail: 0.3 % short
    "burley_searchlight": (1.0, 0.01), "burley_transmission": (1.0, 0.01),
    "burley_dmfp": (1.0, 0.01), "burley_cycles": (1.0, 0.01),
}


@pytest.mark.parametrize("name", PROFILE_NAMES)
def test_white_limit(name):
    assert set(WHITE_LIMIT) == set(PROFILE_NAMES)
    expected, tolerance = WHITE_LIMIT[name]
    made = _made(name, Dipole(1e-7, 1.0, eta=1.0))
    assert made.total() == pytest.approx(np.full(3, expected), abs=tolerance)


@pytest.mark.parametrize("name", PROFILE_NAMES)
def test_more_absorption_reflects_less(name):
    totals = [_made(name, Dipole(sigma_a, 1.0)).total()[0] for sigma_a in (1e-3, 0.1, 10.0)]
    assert totals[0] > totals[1] > totals[2] > 0


@pytest.mark.parametrize("medium", MEDIA)
@pytest.mark.parametrize("name", PROFILE_NAMES)
def test_sampled_radii_follow_r_times_the_profile(name, medium):
    made = _made(name, medium)
    # str hashes change from run to run (PYTHONHASHSEED): a fixed seed from crc32
    rng = np.random.default_rng(zlib.crc32(f"{name}/{medium}".encode()))
    for channel in range(3):
        if made.total()[channel] < 1e-12:
            continue
        quantiles = np.array([made.radius_containing(q) [channel]
                              for q in np.linspace(0.05, 0.95, 19)])
        last = made.sampler.radius[channel, -1] if made.cutoff_radius() is None \
            else made.cutoff_radius()[channel]
        edges = np.concatenate([[0.0], quantiles, [last]])
        expected = _panel_integral(made, channel, edges)
        expected = SAMPLES * expected / expected.sum()
        radii = made.sample_radius(rng.random(SAMPLES), channel)
        observed = np.histogram(radii, edges)[0]
        assert observed.sum() == SAMPLES
        _, p_value = stats.chisquare(observed, expected)
        assert p_value > SIGNIFICANCE, (name, medium, channel, observed, expected)


@pytest.mark.parametrize("medium", MEDIA)
@pytest.mark.parametrize("name", PROFILE_NAMES)
def test_pdf_is_the_normalised_energy_density(name, medium):
    made = _made(name, medium)
    energy = made.total()
    inside = made.radius_containing(0.999)
    for channel in range(3):
        if energy[channel] < 1e-12:
            continue
        r = np.geomspace(1e-3, 1.0, 300) * inside[channel]
        density = 2 * np.pi * r * made.reflection(r)[:, channel] / energy[channel]
        pdf = made.pdf(r, channel)
        assert pdf == pytest.approx(density, rel=PDF_RTOL)
        # and it integrates to 1 over what can be sampled
        edges = np.concatenate([[0.0], np.geomspace(1e-9, 1.0, 4000) * made.radius_containing(
            1 - 1e-9)[channel]])
        middle = 0.5 * (edges[1:] + edges[:-1])
        assert np.sum(made.pdf(middle, channel) * np.diff(edges)) == pytest.approx(1, abs=2e-3)


@pytest.mark.parametrize("name", PROFILE_NAMES)
def test_radius_containing_holds_that_energy(name):
    made = _made(name, "Skin1")
    for fraction in (0.5, 0.99):
        radius = made.radius_containing(fraction)
        for channel in range(3):
            inside = _panel_integral(made, channel, np.array([0.0, radius[channel]]))[0]
            assert inside / made.total()[channel] == pytest.approx(fraction, rel=1e-3)
    assert np.all(made.radius_containing(0.99) > made.radius_containing(0.5))


def test_an_unknown_name_lists_the_valid_ones():
    with pytest.raises(InputError, match="profile = 'dipol': unknown profile; valid: dipole, "
                                         "better_dipole"):
        profile("dipol", "Marble")
    with pytest.raises(InputError, match="unknown profile"):
        profile(None, "Marble")


def test_a_medium_is_a_dipole_or_a_catalogue_name():
    assert profile("dipole", "marble").total() == pytest.approx(
        profile("dipole", measured_medium("Marble")).total())
    with pytest.raises(InputError, match="material = 'Jade': unknown measured material"):
        profile("dipole", "Jade")
    with pytest.raises(InputError, match="medium = 'float': must be a Dipole"):
        profile("dipole", 3.0)


@pytest.mark.parametrize("field, value", [("sigma_a", -0.1), ("sigma_a", float("nan")),
                                          ("sigma_s_prime", -1.0),
                                          ("sigma_s_prime", float("inf"))])
def test_bad_coefficients_are_named(field, value):
    coefficients = {"sigma_a": 0.1, "sigma_s_prime": 1.0, field: value}
    with pytest.raises(InputError, match=f"{field} = "):
        profile("better_dipole", Dipole(**coefficients))


def test_an_option_a_profile_does_not_take_is_refused():
    with pytest.raises(InputError, match="options = \\['incident_angle'\\]: profile 'dipole' "
                                         "does not take"):
        profile("dipole", "Marble", incident_angle=0.3)


def test_a_directional_profile_is_refused_where_a_radial_one_serves():
    directional = profile("directional_dipole", "Marble", incident_angle=0.5)
    assert PROFILES["directional_dipole"].directional
    with pytest.raises(InputError, match="material = .*directional profile cannot stand"):
        profile_for(directional)
    with pytest.raises(InputError, match="has no R\\(r\\) of the distance alone"):
        directional.reflection(1.0)
    average = profile("directional_dipole", "Marble", incident_angle=0.5, radial=True)
    assert profile_for(average) is average


def test_sampling_input_is_checked():
    made = _made("better_dipole", "Marble")
    with pytest.raises(InputError, match="u = 1.5: must lie in \\[0, 1\\]"):
        made.sample_radius([0.2, 1.5], 0)
    with pytest.raises(InputError, match="channel = 3: must be a channel index"):
        made.sample_radius(0.5, 3)
    with pytest.raises(InputError, match="fraction = 1.0: must lie in \\(0, 1\\)"):
        made.radius_containing(1.0)
    with pytest.raises(InputError, match="r = .*must be finite"):
        made.pdf(np.nan, 0)


def test_the_top_level_package_finds_profiles():
    import translucent

    made = translucent.profile("burley_searchlight", "Skin1")
    assert made.model == "burley_searchlight" and "profile" in dir(translucent)
