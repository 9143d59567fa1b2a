import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from translucent.errors import InputError
from translucent.materials import Dipole, Lambertian, measured_medium, measured_medium_names
from translucent.materials.dipole import dipole_reflectance_profile
from translucent.materials.fresnel import fresnel_reflectance
from translucent.materials.profiles import (
    DipoleProfile,
    MixedProfiles,
    RadialGrid,
    RadialProfile,
    SlabProfile,
    TabulatedProfile,
    TwoExponentialProfile,
    check_profile_values,
    diffuse_entry_transmittance,
    mixed_profile,
    profile_for,
    radial_cumulative_integral,
)

#: Gauss-Legendre with 64 nodes integrates the smooth Fresnel average to 1e-10; the
#: identity below is exact for the exact Fresnel terms.
FRESNEL_IDENTITY_ATOL = 1e-7

#: The numeric total integrates a 20001-node quadratic grid out to a radius past 1e-3 of
#: the energy, or out to an explicit 1e3 mm; the piecewise-linear rule's error on the
#: dipole there is below 1e-5 relative (measured against the closed form).
NUMERIC_TOTAL_RTOL = 2e-5

#: Linear interpolation between grid nodes and float32 offsets: 1e-6 relative.
LOCATE_RTOL = 1e-6

#: The image series of the multipole at 5 pairs against the single dipole for a slab
#: 100 diffusion lengths thick: the extra images are e^-100 away.
THICK_SLAB_RTOL = 1e-9

coefficient = st.floats(min_value=1e-3, max_value=50.0)


def test_entry_transmittance_obeys_the_reciprocity_identity():
    # 1 - F_ext(eta) = (1 - F_int(eta)) eta^2 for the exact Fresnel terms (Stokes), with
    # F_int the hemispherical reflectance seen from inside (relative index 1 / eta)
    from scipy.integrate import quad

    for eta in (1.0, 1.3, 1.5, 2.0):
        critical = np.sqrt(max(0.0, 1.0 - 1.0 / eta**2))  # cosine of the critical angle
        internal, _ = quad(lambda mu, eta=eta: float(fresnel_reflectance(1.0 / eta, mu)) * 2 * mu,
                           0.0, 1.0, points=[critical], epsabs=1e-12)
        assert diffuse_entry_transmittance(eta) == pytest.approx(
            (1.0 - internal) * eta**2, abs=FRESNEL_IDENTITY_ATOL)
    assert diffuse_entry_transmittance(1.0) == pytest.approx(1.0, abs=FRESNEL_IDENTITY_ATOL)


def test_entry_transmittance_broadcasts():
    out = diffuse_entry_transmittance(np.array([[1.0, 1.3], [1.5, 2.0]]))
    assert out.shape == (2, 2)
    assert np.all(np.diff(out.ravel()) < 0)  # more index mismatch, more reflection


@given(max_radius=st.floats(min_value=1e-2, max_value=1e3),
       fraction=st.floats(min_value=0.0, max_value=1.0))
@settings(max_examples=60, deadline=None)
def test_grid_locate_reconstructs_the_radius(max_radius, fraction):
    grid = RadialGrid(max_radius, 257)
    r = np.array([fraction * max_radius])
    k, f = grid.locate(r)
    radius = grid.radius
    rebuilt = (1 - f) * radius[k] + f * radius[k + 1]
    assert 0 <= k[0] <= grid.samples - 2
    assert rebuilt[0] == pytest.approx(r[0], rel=LOCATE_RTOL, abs=1e-12 * max_radius)


def test_grid_rejects_bad_sizes():
    with pytest.raises(InputError, match="max_radius.*must be > 0 mm"):
        RadialGrid(0.0)
    with pytest.raises(InputError, match="samples.*integer >= 2"):
        RadialGrid(1.0, 1)


@given(a=st.floats(min_value=0.0, max_value=10.0), b=st.floats(min_value=0.0, max_value=10.0),
       max_radius=st.floats(min_value=0.1, max_value=100.0))
@settings(max_examples=60, deadline=None)
def test_cumulative_integral_is_exact_for_linear_profiles(a, b, max_radius):
    # C(R) = int_0^R (a + b r) r dr = a R^2 / 2 + b R^3 / 3, at every node
    radius = RadialGrid(max_radius, 33).radius
    values = a + b * radius
    expected = a * radius**2 / 2 + b * radius**3 / 3
    assert np.allclose(radial_cumulative_integral(radius, values), expected, rtol=1e-12,
                       atol=1e-12 * max(expected.max(), 1.0))


# Spectralon has no absorption: its profile falls as r^-3 and is checked against that tail
@pytest.mark.parametrize("name", [n for n in measured_medium_names() if n != "Spectralon"])
def test_dipole_profile_total_matches_its_closed_form(name):
    profile = DipoleProfile(measured_medium(name))
    numeric = RadialProfile.total(profile, max_radius=1e3)
    assert numeric == pytest.approx(profile.total(), rel=NUMERIC_TOTAL_RTOL)


def test_non_absorbing_dipole_plus_its_inverse_cube_tail_is_the_closed_form():
    # sigma_tr = 0: R_d -> alpha' (z_r + z_v) / (4 pi r^3), so the energy beyond R is
    # (z_r + z_v) / (2 R) (times the entry transmittance), 2e-4 of the total at 1 m
    from translucent.materials.dipole import dipole_depths

    medium = measured_medium("Spectralon")
    profile = DipoleProfile(medium)
    radius = 1e3
    z_r, z_v = dipole_depths(medium.sigma_a, medium.sigma_s_prime, medium.eta)
    tail = profile.entry * (z_r + z_v) / (2 * radius)
    numeric = RadialProfile.total(profile, max_radius=radius)
    # Spectralon's 0.05 mm mean free path is the hardest case for the grid near r = 0:
    # 2.1e-5 relative measured, hence 3e-5
    assert numeric + tail == pytest.approx(profile.total(), rel=3e-5)
    assert np.all(numeric < profile.total())


def test_dipole_profile_is_the_dipole_times_the_entry_transmittance():
    medium = measured_medium("Marble")
    r = np.linspace(0.0, 20.0, 41)
    bare = dipole_reflectance_profile(r[:, None], medium.sigma_a, medium.sigma_s_prime,
                                      medium.eta)
    assert np.allclose(DipoleProfile(medium, entry_fresnel=False).reflection(r), bare)
    assert np.allclose(DipoleProfile(medium).reflection(r),
                       bare * diffuse_entry_transmittance(medium.eta))
    assert not DipoleProfile(medium).has_transmission
    assert np.all(DipoleProfile(medium).transmission(r) == 0)


@given(sigma_a=coefficient, sigma_s_prime=coefficient,
       eta=st.floats(min_value=1.0, max_value=2.0), r=st.floats(min_value=0.0, max_value=1e3))
@settings(max_examples=80, deadline=None)
def test_profiles_are_finite_and_non_negative(sigma_a, sigma_s_prime, eta, r):
    medium = Dipole(sigma_a, sigma_s_prime, eta)
    slab = SlabProfile(medium, 2.0 * float(medium.mean_free_path.max()))
    for profile in (DipoleProfile(medium), slab):
        for kind in ("reflection", "transmission"):
            value = profile.evaluate(np.array([r, 0.0]), kind)
            assert value.shape == (2, 3)
            assert np.all(np.isfinite(value)) and np.all(value >= 0)


def test_profiles_broadcast_over_any_shape():
    profile = DipoleProfile(measured_medium("Skin1"))
    r = np.linspace(0, 5, 24).reshape(2, 3, 4)
    assert profile.reflection(r).shape == (2, 3, 4, 3)
    assert TwoExponentialProfile(1.0, 2.0).reflection(r).shape == (2, 3, 4, 3)
    assert TabulatedProfile([0, 1, 2], [1, 0.5, 0]).reflection(r).shape == (2, 3, 4, 3)


@pytest.mark.parametrize("name", ["Marble", "Skin1", "Ketchup"])
def test_thick_slab_is_the_dipole(name):
    medium = measured_medium(name)
    # 100 diffusion lengths: the image sources and the far face are e^-100 away
    thickness = 100.0 / float(medium.sigma_tr.min())
    slab, dipole = SlabProfile(medium, thickness), DipoleProfile(medium)
    r = np.linspace(0.0, 30.0, 31)
    assert np.allclose(slab.reflection(r), dipole.reflection(r), rtol=THICK_SLAB_RTOL)
    assert np.all(slab.transmission(r) <= 1e-30 * slab.reflection(r).max())


def test_thinner_slabs_transmit_more_and_conserve_energy():
    medium = measured_medium("Skin1")
    transmitted = []
    # thicker than the reduced mean free path (1.3 mm in red), where diffusion holds
    for thickness in (12.0, 8.0, 4.0, 2.0):
        slab = SlabProfile(medium, thickness)
        reflected, through = slab.total(), slab.total("transmission")
        # an absorbing medium returns less than what entered
        assert np.all(reflected + through < slab.entry)
        transmitted.append(through)
    assert np.all(np.diff(np.array(transmitted), axis=0) > 0)


def test_slab_rejects_bad_thickness():
    with pytest.raises(InputError, match="thickness.*must be > 0 mm"):
        SlabProfile(measured_medium("Skin1"), 0.0)
    with pytest.raises(InputError, match="thickness.*reduced mean free path"):
        SlabProfile(measured_medium("Skin1"), 1.0)
    with pytest.raises(InputError, match="expected a Dipole"):
        SlabProfile(Lambertian(0.5), 1.0)


def test_two_exponential_total_is_closed_form():
    profile = TwoExponentialProfile([0.02, 0.01, 0.03], 1.0, 0.005, [0.2, 0.3, 0.4],
                                    transmission=(0.01, 0.5, 0.0, 1.0))
    expected = 2 * np.pi * (np.array([0.02, 0.01, 0.03]) + 0.005 / np.array([0.2, 0.3, 0.4])**2)
    assert profile.total() == pytest.approx(expected)
    assert RadialProfile.total(profile, max_radius=500.0) == pytest.approx(
        expected, rel=NUMERIC_TOTAL_RTOL)
    assert profile.total("transmission") == pytest.approx(2 * np.pi * 0.01 / 0.25)
    assert np.all(TwoExponentialProfile(1.0, 1.0).transmission(np.ones(3)) == 0)


def test_two_exponential_rejects_bad_parameters():
    with pytest.raises(InputError, match=r"reflection\.b1.*must be > 0"):
        TwoExponentialProfile(1.0, 0.0)
    with pytest.raises(InputError, match=r"reflection\.a2.*must be >= 0"):
        TwoExponentialProfile(1.0, 1.0, -1.0, 1.0)
    with pytest.raises(InputError, match="transmission.*must be \\(a1, b1, a2, b2\\)"):
        TwoExponentialProfile(1.0, 1.0, transmission=(1.0, 1.0))


def test_table_interpolates_and_integrates_exactly():
    # a triangle profile s(r) = 1 - r on [0, 1]: total 2 pi (1/2 - 1/3) = pi / 3
    table = TabulatedProfile([0.0, 0.5, 1.0], [1.0, 0.5, 0.0], [0.5, 0.25, 0.0])
    assert table.total() == pytest.approx(np.full(3, np.pi / 3))
    assert table.total("transmission") == pytest.approx(np.full(3, np.pi / 6))
    assert table.reflection(np.array([0.25, 2.0])) == pytest.approx(
        np.array([[0.75] * 3, [0.0] * 3]))
    assert table.support_radius() <= 1.0


@pytest.mark.parametrize("values, message", [
    ([1.0, np.nan, 0.0], "must be finite.*index \\(1,\\)"),
    ([1.0, -0.5, 0.0], "must be >= 0.*energy density.*index \\(1,\\)"),
    ([1.0, np.inf, 0.0], "must be finite"),
])
def test_table_rejects_nan_and_negative_values(values, message):
    with pytest.raises(InputError, match=message):
        TabulatedProfile([0.0, 1.0, 2.0], values, name="bad")


def test_table_rejects_bad_radii_and_shapes():
    with pytest.raises(InputError, match="first radius must be 0 mm"):
        TabulatedProfile([0.1, 1.0], [1.0, 0.0])
    with pytest.raises(InputError, match="radii must increase strictly"):
        TabulatedProfile([0.0, 1.0, 1.0], [1.0, 0.5, 0.0])
    with pytest.raises(InputError, match="at least 2 radii"):
        TabulatedProfile([0.0], [1.0])
    with pytest.raises(InputError, match="to match the radii"):
        TabulatedProfile([0.0, 1.0], [1.0, 0.5, 0.0])


def test_table_from_csv_with_header(tmp_path):
    path = tmp_path / "petal.csv"
    path.write_text("r,R_r,R_g,R_b,T_r,T_g,T_b\n0,1,2,3,0.1,0.2,0.3\n1,0.5,1,1.5,0,0,0\n"
                    "2,0,0,0,0,0,0\n")
    table = TabulatedProfile.from_file(path)
    assert table.name == "petal"
    assert table.has_transmission
    assert table.reflection(np.array([0.5]))[0] == pytest.approx([0.75, 1.5, 2.25])
    assert table.transmission(np.array([0.5]))[0] == pytest.approx([0.05, 0.1, 0.15])


def test_table_from_csv_errors_name_the_file(tmp_path):
    with pytest.raises(InputError, match="no such file"):
        TabulatedProfile.from_file(tmp_path / "missing.csv")
    bad = tmp_path / "bad.csv"
    bad.write_text("0,1\n1,x\n")
    with pytest.raises(InputError, match="bad.csv.*line 2.*not a number"):
        TabulatedProfile.from_file(bad)
    ragged = tmp_path / "ragged.csv"
    ragged.write_text("0,1,2,3,4,5\n")
    with pytest.raises(InputError, match="ragged.csv.*2, 3, 4 or 7 numbers"):
        TabulatedProfile.from_file(ragged)
    negative = tmp_path / "negative.csv"
    negative.write_text("0,1\n1,-1\n")
    with pytest.raises(InputError, match="negative.csv.*must be >= 0"):
        TabulatedProfile.from_file(negative)


def test_tabulate_rejects_a_profile_that_returns_nan():
    class Broken(RadialProfile):
        name = "broken"

        def reflection(self, r):
            out = np.ones(np.shape(r) + (3,))
            out[..., 1] = np.nan
            return out

    with pytest.raises(InputError, match="profile 'broken' values must be finite"):
        Broken().tabulate(RadialGrid(1.0, 8))


def test_check_profile_values_passes_good_values_through():
    values = check_profile_values([[0.0, 1.0, 2.0]], "reflection")
    assert values.dtype == np.float64 and values.shape == (1, 3)


@given(cutoff=st.floats(min_value=1e-5, max_value=0.5))
@settings(max_examples=20, deadline=None)
def test_support_radius_keeps_the_requested_energy(cutoff):
    profile = TwoExponentialProfile(0.02, 1.0, 0.004, 0.2)
    radius = profile.support_radius(cutoff)
    inside = RadialProfile.total(profile, max_radius=radius)
    # the sweep's grid resolution at the support radius is < 0.5 % of it
    assert np.all(1.0 - inside / profile.total() <= cutoff * 1.05 + 1e-6)


def test_support_radius_rejects_bad_fraction():
    with pytest.raises(InputError, match="energy_fraction.*must be in \\(0, 1\\)"):
        TwoExponentialProfile(1.0, 1.0).support_radius(1.0)


@given(b=st.floats(min_value=0.01, max_value=5.0), r=st.floats(min_value=0.0, max_value=20.0),
       fraction=st.floats(min_value=0.0, max_value=1.0))
@settings(max_examples=60, deadline=None)
def test_mixing_one_exponential_material_with_itself_is_homogeneous(b, r, fraction):
    # Eq. 16 with S_1 = S_2 = a e^{-b r}: (a f + a (1-f)) e^{-b f r} e^{-b (1-f) r} = S(r)
    a = np.array([0.3, 0.2, 0.1])
    zero = np.stack([a, a])
    at = np.stack([a * np.exp(-b * fraction * r), a * np.exp(-b * (1 - fraction) * r)])
    mixed = mixed_profile(zero, at, np.array([fraction, 1 - fraction]))
    assert mixed == pytest.approx(a * np.exp(-b * r), rel=1e-12)


def test_mixing_with_an_untraversed_material_ignores_it():
    zero = np.array([[1.0, 1.0, 1.0], [5.0, 5.0, 5.0]])
    at = np.array([[[0.5, 0.4, 0.3], [123.0, 0.0, 7.0]]])
    assert mixed_profile(zero, at, np.array([[1.0, 0.0]]))[0] == pytest.approx([0.5, 0.4, 0.3])


def test_mixed_profiles_validate_labels_and_materials():
    marble, skin = measured_medium("Marble"), measured_medium("Skin1")
    mixed = MixedProfiles([marble, skin], np.array([0, 1, 1, 0]))
    assert isinstance(mixed.profiles[0], DipoleProfile)
    assert profile_for(mixed) is mixed
    with pytest.raises(InputError, match="face_labels.*labels must lie in \\[0, 1\\]"):
        MixedProfiles([marble, skin], np.array([0, 2]))
    with pytest.raises(InputError, match="profiles\\[1\\].*must be translucent"):
        MixedProfiles([marble, Lambertian(0.5)], np.array([0, 1]))
    with pytest.raises(InputError, match="one per face"):
        MixedProfiles([marble], np.array([0.5, 1.0]))


def test_profile_for_dispatches_on_the_material():
    assert isinstance(profile_for(measured_medium("Apple")), DipoleProfile)
    assert profile_for(Lambertian(0.3)) is None
    table = TabulatedProfile([0, 1], [1, 0])
    assert profile_for(table) is table
    with pytest.raises(InputError, match="takes a Dipole, a RadialProfile"):
        profile_for("marble")


def test_scaled_profile_scales_the_total():
    profile = TwoExponentialProfile(0.02, 1.0)
    scaled = profile.scaled([0.5, 1.0, 2.0])
    assert scaled.total() == pytest.approx(profile.total() * [0.5, 1.0, 2.0], rel=1e-4)


def test_cache_keys_tell_profiles_apart():
    a = DipoleProfile(measured_medium("Apple")).cache_key()
    b = DipoleProfile(measured_medium("Apple"), entry_fresnel=False).cache_key()
    assert a != b
    assert SlabProfile(measured_medium("Apple"), 1.0).cache_key()["thickness"] == 1.0


def test_from_file_refuses_a_file_that_is_not_text(tmp_path):
    path = tmp_path / "binary.csv"
    path.write_bytes(b"\xff\xfe\x00r,R\n")
    with pytest.raises(InputError, match=r"binary\.csv: .*not a text \(UTF-8\) CSV file"):
        TabulatedProfile.from_file(path)
