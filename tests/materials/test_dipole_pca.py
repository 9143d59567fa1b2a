import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from translucent.errors import InputError
from translucent.materials import MEASURED_MEDIA, measured_medium, measured_medium_names
from translucent.materials import dipole_pca as pca
from translucent.materials.dipole import dipole_reflectance_profile, total_diffuse_reflectance
from translucent.materials.dipole_pca import (
    PARAMETERISATIONS,
    ProfileSampling,
    approximation_error_maps,
    area_relative_error,
    compare_parameterisations,
    dipole_pca_basis,
    leading_basis_functions,
    singular_value_roots,
    terms_to_match,
    truncated_diffuse_reflectance,
    write_analysis_figure,
)

#: float64 round-off of sums over 650 distances of values near 1.
ROUND_OFF = 1e-10

#: The streamed Gram decomposition agrees with LAPACK's SVD of the whole matrix to this
#: relative precision on the first 15 singular values and vectors (it is built to reach
#: ~1e-9 on the paper's sampling, whose 15th singular value is ~1e-6 of the first).
DECOMPOSITION_RTOL = 1e-6

#: The trapezoid rule on 4001 distances dense near 0 integrates these smooth profiles to
#: better than 1e-4 of their total (checked against the closed form in the energy test).
QUADRATURE_RTOL = 1e-3

coefficient = st.floats(min_value=1e-6, max_value=1e3)
index = st.floats(min_value=1.0, max_value=2.5)
distance = st.floats(min_value=0.0, max_value=1e3)


@pytest.fixture(scope="module")
def paper():
    return dipole_pca_basis("paper")


@pytest.fixture(scope="module")
def improved():
    return dipole_pca_basis("area_normalised")


def test_presets_ship_with_the_suite():
    for sampling in PARAMETERISATIONS.values():
        assert pca._shipped_path(sampling, 1.3).is_file()


@pytest.mark.parametrize("name", list(PARAMETERISATIONS))
def test_basis_vectors_are_orthonormal(name):
    basis = dipole_pca_basis(name)
    gram = basis.vectors.T @ basis.vectors
    assert np.abs(gram - np.eye(gram.shape[0])).max() < ROUND_OFF


def test_paper_sampling_is_650_uniform_distances_in_0_65_mm(paper):
    assert basis_radii_spacing(paper) == pytest.approx(65.0 / 649)
    assert paper.radii[0] == 0.0 and paper.radii[-1] == 65.0 and paper.radii.size == 650
    assert paper.terms == 12


def basis_radii_spacing(basis):
    spacing = np.diff(basis.radii)
    assert np.allclose(spacing, spacing[0])
    return spacing[0]


def test_streamed_decomposition_matches_a_direct_svd():
    for name in PARAMETERISATIONS:
        sampling = ProfileSampling(**{**pca.asdict(PARAMETERISATIONS[name]), "sigma_samples": 24})
        radii, weights, vectors, singular = pca._decompose(sampling, 1.3)
        matrix = np.vstack(list(pca._profile_blocks(sampling, 1.3, radii, weights))).T
        left, direct, _ = np.linalg.svd(matrix, full_matrices=False)
        assert singular[:15] == pytest.approx(direct[:15], rel=DECOMPOSITION_RTOL)
        for k in range(15):
            sign = np.sign(left[:, k] @ vectors[:, k])
            assert np.abs(vectors[:, k] - sign * left[:, k]).max() < DECOMPOSITION_RTOL


def test_singular_values_decay(paper):
    roots = singular_value_roots(paper)
    assert roots.shape == (15,)
    assert np.all(np.diff(roots) < 0)
    # Fig. 4a: by the 12th term the square root has fallen by more than two decades
    assert roots[11] / roots[0] < 1e-2


def test_projection_of_a_basis_combination_returns_its_coefficients(improved):
    coefficients = np.linspace(1.0, -0.5, improved.terms)
    profile = improved.table[:-1] @ coefficients
    assert improved.project_profile(profile) == pytest.approx(coefficients, abs=1e-9)
    assert improved.project_profile(lambda r: improved.reconstruct(r, coefficients)) == \
        pytest.approx(coefficients, abs=1e-9)


def test_projection_broadcasts_over_channels_and_grids(paper):
    medium = measured_medium("Skin1")
    rgb = paper.project(medium.sigma_a, medium.sigma_s_prime, medium.eta)
    assert rgb.shape == (3, 12)
    for channel in range(3):
        single = paper.project(medium.sigma_a[channel], medium.sigma_s_prime[channel],
                               medium.eta)
        assert single == pytest.approx(rgb[channel])
    grid = paper.project(np.full((2, 5), 0.01), np.full((2, 5), 1.0))
    assert grid.shape == (2, 5, 12)


def test_basis_is_zero_beyond_its_range(improved):
    values = improved.evaluate(np.array([65.5, 100.0, 1e3]))
    assert np.all(values == 0)


@pytest.mark.parametrize("name", measured_medium_names())
def test_projection_conserves_energy_within_the_truncation_error(improved, name):
    """2 pi int R~ r dr differs from the closed-form total by at most the truncation error.

    Cauchy-Schwarz: |2 pi int (R~ - R) r dr| <= 2 pi ||R~ - R||_area (int_0^65 r dr)^1/2, plus
    the tail of R beyond 65 mm, which the basis drops.
    """
    medium = measured_medium(name)
    radii, measure = pca._fine_radii(65.0)
    for channel in range(3):
        args = (medium.sigma_a[channel], medium.sigma_s_prime[channel], medium.eta)
        exact_total = float(total_diffuse_reflectance(*args))
        profile = dipole_reflectance_profile(radii, *args)
        reconstruction = improved.reconstruct(radii, improved.project(*args))
        inside = 2 * np.pi * float((profile * measure).sum())
        tail = exact_total - inside
        truncation = np.sqrt(float(((reconstruction - profile) ** 2 * measure).sum()))
        bound = 2 * np.pi * truncation * np.sqrt(float(measure.sum())) + abs(tail)
        approximate_total = 2 * np.pi * float((reconstruction * measure).sum())
        slack = QUADRATURE_RTOL * exact_total
        assert abs(approximate_total - exact_total) <= bound + slack


def test_error_maps_match_the_paper_layout(paper):
    maps = approximation_error_maps(paper, resolution=12)
    assert maps["sigma_s_prime"][0] == pytest.approx(1e-6)
    assert maps["sigma_a"][-1] == pytest.approx(5.0)
    for key in ("l2", "log10_relative_linf", "area_relative_l2"):
        assert maps[key].shape == (12, 12)
        assert np.all(np.isfinite(maps[key]))
    # the relative L-infinity error of a projection cannot exceed the profile's own size
    # by much: at least no digit is lost on the materials of interest (sigma > 0.1)
    interesting = (maps["sigma_s_prime"][:, None] > 0.1) & (maps["sigma_a"][None, :] > 0.1)
    assert np.all(maps["log10_relative_linf"][interesting] < 0)


def test_more_terms_never_increase_the_l2_error_of_the_paper_basis(paper):
    # the projection is orthogonal in the paper's sampling, so its L2 error on those
    # distances cannot grow with K
    fewer = approximation_error_maps(paper.truncated(4), resolution=8)["l2"]
    more = approximation_error_maps(paper, resolution=8)["l2"]
    assert np.all(more <= fewer * (1 + 1e-9) + 1e-15)


def test_leading_basis_functions_on_0_5_mm(paper):
    radii, functions = leading_basis_functions(paper)
    assert radii[0] == 0 and radii[-1] == 5.0
    assert functions.shape == (4, radii.size)
    # at the sampled distances the functions are the singular vectors themselves
    _, on_samples = leading_basis_functions(paper, radius=paper.radii[49], samples=50)
    assert on_samples == pytest.approx(paper.vectors[:50, :4].T, abs=1e-12)


def test_area_normalised_needs_fewer_terms_for_the_paper_accuracy(paper, improved):
    """Go beyond the paper: fewer terms reach the 12-term error of the paper's basis."""
    assert terms_to_match(paper, improved, statistic="worst") < 12
    assert terms_to_match(paper, improved, statistic="median") < 12
    both = compare_parameterisations({"paper": paper, "improved": improved}, terms=[12])
    assert both["improved"]["worst"][0] < both["paper"]["worst"][0]


def test_measured_errors_cover_every_channel(improved):
    errors = pca.measured_profile_errors(improved)
    assert set(errors) == set(MEASURED_MEDIA)
    assert all(e.shape == (3,) and np.all(e >= 0) for e in errors.values())


def test_custom_sampling_is_cached_on_disk(monkeypatch):
    sampling = ProfileSampling("tiny", sigma_samples=6, distance_samples=32)
    first = dipole_pca_basis(sampling, terms=4)
    pca._cached_decomposition.cache_clear()

    def fail(*args):
        raise AssertionError("the cached basis should have been loaded")

    monkeypatch.setattr(pca, "_decompose", fail)
    second = dipole_pca_basis(sampling, terms=4)
    assert np.array_equal(first.vectors, second.vectors)
    pca._cached_decomposition.cache_clear()


def test_analysis_figure_is_written(tmp_path):
    small = {"paper": dipole_pca_basis("paper", sigma_samples=8).truncated(4)}
    path = write_analysis_figure(tmp_path / "fig4.png", small, resolution=6)
    assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


@settings(max_examples=60, deadline=None)
@given(sigma_a=coefficient, sigma_s_prime=coefficient, eta=index,
       dtype=st.sampled_from([np.float32, np.float64]))
def test_projections_stay_finite(paper, sigma_a, sigma_s_prime, eta, dtype):
    coefficients = paper.project(dtype(sigma_a), dtype(sigma_s_prime), dtype(eta))
    assert np.all(np.isfinite(coefficients))
    profile = paper.reconstruct(np.array([0.0, 1.0, 64.0]), coefficients)
    assert np.all(np.isfinite(profile))


@settings(max_examples=60, deadline=None)
@given(r=distance, sigma_a=coefficient, sigma_s_prime=coefficient, eta=index,
       dtype=st.sampled_from([np.float32, np.float64]))
def test_profiles_stay_finite_and_non_negative(improved, r, sigma_a, sigma_s_prime, eta, dtype):
    profile = dipole_reflectance_profile(dtype(r), dtype(sigma_a), dtype(sigma_s_prime),
                                         dtype(eta))
    assert np.isfinite(profile) and profile >= 0
    assert np.all(np.isfinite(improved.evaluate(dtype(r))))
    assert np.isfinite(area_relative_error(improved, sigma_a, sigma_s_prime, eta))


@settings(max_examples=40, deadline=None)
@given(sigma_a=coefficient, sigma_s_prime=coefficient, eta=index,
       radius=st.floats(min_value=1e-3, max_value=65.0))
def test_truncated_reflectance_is_the_integral_of_the_profile(sigma_a, sigma_s_prime, eta,
                                                               radius):
    """The closed form against the trapezoid rule on 4001 distances dense near 0."""
    radii, measure = pca._fine_radii(radius)
    profile = dipole_reflectance_profile(radii, sigma_a, sigma_s_prime, eta)
    quadrature = 2 * np.pi * float((profile * measure).sum())
    closed = float(truncated_diffuse_reflectance(sigma_a, sigma_s_prime, eta, radius))
    assert closed == pytest.approx(quadrature, rel=QUADRATURE_RTOL, abs=ROUND_OFF)


def test_truncated_reflectance_limits():
    sigma_a, sigma_s_prime = np.array([1e-3, 0.1, 10.0]), np.array([0.5, 2.0, 30.0])
    # all of it far away: the total diffuse reflectance (Eq. 5 of Jensen et al. 2001)
    far = truncated_diffuse_reflectance(sigma_a, sigma_s_prime, 1.3, 1e9)
    np.testing.assert_allclose(far, total_diffuse_reflectance(sigma_a, sigma_s_prime, 1.3),
                               rtol=ROUND_OFF)
    # none of it within radius 0, and it never shrinks as the radius grows
    assert np.all(truncated_diffuse_reflectance(sigma_a, sigma_s_prime, 1.3, 0.0) == 0)
    growing = truncated_diffuse_reflectance(0.1, 2.0, 1.3, np.linspace(0.0, 65.0, 100))
    assert np.all(np.diff(growing) >= 0) and growing[1] > 0
    # no scattering, nothing reflected (and no NaN from the infinite source depths)
    assert truncated_diffuse_reflectance([0.0, 1.0], 0.0, 1.3, 65.0).tolist() == [0.0, 0.0]


@pytest.mark.parametrize("name", list(PARAMETERISATIONS))
def test_projection_energy_is_the_energy_of_the_reconstruction(name):
    basis = dipole_pca_basis(name)
    sigma_a, sigma_s_prime = np.array([0.0021, 0.05, 1.0]), np.array([2.19, 1.0, 3.0])
    coefficients, residual, energy, exact = basis.project_with_energy(sigma_a, sigma_s_prime)
    expected_coefficients, expected_residual = basis.project_with_residual(sigma_a,
                                                                           sigma_s_prime)
    np.testing.assert_array_equal(coefficients, expected_coefficients)
    np.testing.assert_array_equal(residual, expected_residual)
    radii, measure = pca._fine_radii(65.0)
    reconstruction = basis.reconstruct(radii, coefficients)
    np.testing.assert_allclose(energy, 2 * np.pi * (reconstruction * measure[:, None]).sum(0),
                               rtol=ROUND_OFF)
    np.testing.assert_allclose(exact, truncated_diffuse_reflectance(sigma_a, sigma_s_prime,
                                                                    1.3, 65.0), rtol=ROUND_OFF)


def test_bad_truncation_radius_is_rejected():
    with pytest.raises(InputError, match=r"radius.*>= 0 mm"):
        truncated_diffuse_reflectance(0.1, 1.0, 1.3, -1.0)
    with pytest.raises(InputError, match="radius.*finite"):
        truncated_diffuse_reflectance(0.1, 1.0, 1.3, np.nan)
    with pytest.raises(InputError, match=r"eta.*\[1, 3\]"):
        truncated_diffuse_reflectance(0.1, 1.0, 0.5, 1.0)


@pytest.mark.parametrize("kwargs, message", [
    ({"sigma_a": -1.0, "sigma_s_prime": 1.0}, "sigma_a.*>= 0"),
    ({"sigma_a": 0.1, "sigma_s_prime": np.nan}, "sigma_s_prime.*finite"),
    ({"sigma_a": 0.1, "sigma_s_prime": 1.0, "eta": 0.5}, r"eta.*\[1, 3\]"),
    ({"sigma_a": 0.1, "sigma_s_prime": 1.0, "eta": np.inf}, "eta.*finite"),
])
def test_bad_material_values_are_rejected(paper, kwargs, message):
    with pytest.raises(InputError, match=message):
        paper.project(**kwargs)


def test_bad_basis_requests_are_rejected(paper):
    with pytest.raises(InputError, match="unknown parameterisation; valid: paper"):
        dipole_pca_basis("wavelets")
    with pytest.raises(InputError, match=r"terms.*\[1, 32\]"):
        dipole_pca_basis("paper", terms=0)
    with pytest.raises(InputError, match=r"eta.*\[1, 3\]"):
        dipole_pca_basis("paper", eta=5.0)
    with pytest.raises(InputError, match="profile.*650 distances"):
        paper.project_profile(np.ones(10))
    with pytest.raises(InputError, match="sigma_range"):
        approximation_error_maps(paper, sigma_range=(0.0, 5.0))
    with pytest.raises(InputError, match="statistic"):
        terms_to_match(paper, paper, statistic="mean")


@pytest.mark.parametrize("fields, message", [
    ({"distance_warp": "log"}, "distance_warp.*uniform, sqrt"),
    ({"measure": "volume"}, "measure.*samples, area"),
    ({"sigma_spacing": "log"}, "sigma_s_prime_range.*low > 0"),
    ({"sigma_a_range": (5.0, 1.0)}, "sigma_a_range"),
    ({"sigma_samples": 1}, "sigma_samples.*>= 2"),
    ({"radius_max": -1.0}, "radius_max.*> 0"),
])
def test_bad_samplings_are_rejected(fields, message):
    with pytest.raises(InputError, match=message):
        ProfileSampling("bad", **fields)
