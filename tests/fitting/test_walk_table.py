"""The tabulated random-walk profile: its parts against exact results and independent walks."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from translucent.errors import InputError
from translucent.fitting import walk_table
from translucent.fitting.random_walk import photon_random_walk
from translucent.fitting.walk_kernel import drjit_available, walk_exits
from translucent.materials import Dipole

needs_drjit = pytest.mark.skipif(not drjit_available(),
                                 reason="Dr.Jit's LLVM backend is not available")
#: Monte Carlo comparisons: within this many combined standard errors.
SIGMAS = 4.0
#: Linear interpolation between tabulated albedos, ring centres and etas: its own error,
#: measured against walks at the tabulated points and between them (docs/capture-format.md)
#: as at most ~1 % within 10 transport lengths of the beam.
INTERPOLATION = 0.015


def _bin_means(table, edges, albedo, eta):
    """Ring means of the table's profile over ``edges`` (reduced radii), by quadrature."""
    u = np.linspace(0.0, 1.0, 401)
    radius = edges[:-1, None] + np.diff(edges)[:, None] * u[None, :]
    values = table.reduced_profile(radius, np.full(radius.shape[0], albedo),
                                   np.full(radius.shape[0], eta))
    return (np.trapezoid(values * radius, radius, axis=1)
            / np.trapezoid(radius, radius, axis=1))


@needs_drjit
@pytest.mark.parametrize("eta", [1.0, pytest.param(1.4, marks=pytest.mark.slow)])
def test_single_scattering_matches_the_walks_first_exits(eta):
    photons = 100_000
    arrays, _ = walk_exits(11, photons, 0.0, 1.0, 0.0, eta, None, 0.0, 160.0,
                           interactions=True)
    x, y, x0, y0, weight, side, _, scatterings = arrays
    first = (side == 0) & (scatterings == 1)
    radius = np.hypot(x - x0, y - y0)[first]
    edges = np.array([0.0, 0.01, 0.03, 0.1, 0.3, 1.0, 2.0])
    sums = np.histogram(radius, edges, weights=weight[first])[0]
    counts = np.histogram(radius, edges)[0]
    area = np.pi * np.diff(edges ** 2)
    measured = sums / (photons * area)
    # every first exit carries 1 - F: the relative error of a ring is about 1/sqrt(count)
    se = measured / np.sqrt(counts)
    exact = walk_table._single_scattering_rings(edges, eta)
    assert np.all(np.abs(measured - exact) < SIGMAS * se)


def test_the_interaction_count_leaves_the_walk_unchanged():
    if not drjit_available():
        pytest.skip("Dr.Jit's LLVM backend is not available")
    plain, lost = walk_exits(3, 2000, 0.1, 0.9, 0.0, 1.3, None, 0.0, 50.0)
    counted, lost2 = walk_exits(3, 2000, 0.1, 0.9, 0.0, 1.3, None, 0.0, 50.0,
                                interactions=True)
    count = plain[0].size
    assert counted[0].size == count and lost == pytest.approx(lost2, rel=1e-12)
    # the buffer's order depends on the threads: compare photon by photon (a photon's own
    # exits are stored in the order they happen)
    order = np.argsort(plain[6], kind="stable")
    order2 = np.argsort(counted[6], kind="stable")
    for a, b in zip(plain, counted[:7], strict=True):
        np.testing.assert_array_equal(a[order], b[order2])
    assert counted[7].min() >= 1  # no photon leaves before it scatters


@settings(max_examples=60, deadline=None)
@given(st.floats(0.01, 0.999999))
def test_asymptotic_attenuation_solves_the_dispersion_relation(albedo):
    kappa = float(walk_table.asymptotic_attenuation(albedo))
    assert 0.0 < kappa <= 1.0
    if albedo < 0.3:  # 1 - kappa ~ 2 exp(-2 / albedo): beyond double precision soon
        assert kappa > 0.98
        return
    assert albedo * np.arctanh(kappa) / kappa == pytest.approx(1.0, rel=1e-9)
    # below diffusion's sqrt(3 (1 - albedo)), and close to it as the albedo nears 1
    diffusion = np.sqrt(3.0 * (1.0 - albedo))
    assert kappa <= diffusion * (1.0 + 1e-9)
    if albedo > 0.999:
        assert kappa == pytest.approx(diffusion, rel=1e-3)


def test_shipped_table_covers_the_fitters_eta_range():
    from translucent.fitting.models import ETA_FIT_RANGE

    table = walk_table.load_table()
    assert table.etas[0] <= ETA_FIT_RANGE[0] and table.etas[-1] >= ETA_FIT_RANGE[1]
    assert np.all(np.isfinite(table.ln_profile))
    assert np.all(np.diff(table.cumulative, axis=-1) >= 0)  # exitance inside r grows
    assert np.all(table.cumulative[..., -1] <= 1.0)
    # energy: a non-absorbing medium returns everything. Far from the beam its exitance
    # falls as 1/r^3 (diffusion's far field), so what leaves beyond r is 2 pi R(r) r^2;
    # inside r the table's cumulative exitance. The two add up to 1 but for what the walk
    # carried beyond its kill radius (160 mean free paths: < 1.5 %)
    for eta in table.etas:
        radius = np.array([[40.0, 60.0]])
        far = table.reduced_profile(radius, np.array([1.0]), np.array([eta]))[0]
        assert np.log(far[1] / far[0]) / np.log(1.5) == pytest.approx(-3.0, abs=0.15)
        beyond = 2.0 * np.pi * far[1] * 60.0 ** 2
        inside = float(table.reduced_cumulative(60.0, 1.0, eta))
        assert 0.985 < inside + beyond < 1.0 + 3e-3


@needs_drjit
@pytest.mark.parametrize("albedo, eta", [
    pytest.param(0.998, 1.3, marks=pytest.mark.slow),  # the longest walks: 6.6 s
    (0.93, 1.45), (0.55, 1.3), (0.067, 1.3)])
def test_shipped_table_matches_an_independent_walk(albedo, eta):
    # albedos between the tabulated ones; eta 1.45 between two tables
    table = walk_table.load_table()
    medium = Dipole(sigma_a=1.0 - albedo, sigma_s_prime=albedo, eta=eta)
    edges = np.concatenate([[0.0], np.geomspace(0.02, 10.0, 19)])
    tally = photon_random_walk(medium, photons=200_000, radial_edges_mm=edges, seed=5,
                               channels=(0,))
    walked, walked_se = tally.reflectance[:, 0], tally.reflectance_se[:, 0]
    tabulated = _bin_means(table, edges, albedo, eta)
    resolved = walked_se < 0.05 * walked
    assert resolved.sum() >= 12
    bound = SIGMAS * walked_se + INTERPOLATION * walked
    assert np.all(np.abs(tabulated - walked)[resolved] < bound[resolved])
    # the total exitance, from the cumulative table
    total = table.reduced_cumulative(edges[-1], albedo, eta)
    inside = np.sum(walked * np.pi * np.diff(edges ** 2))
    assert total == pytest.approx(inside, rel=INTERPOLATION + SIGMAS * 0.01)


def test_the_table_refuses_an_eta_it_does_not_cover():
    table = walk_table.load_table()
    with pytest.raises(InputError, match="eta"):
        table.check_eta(2.5)


def test_an_unreadable_table_is_an_input_error(tmp_path):
    broken = tmp_path / "table.npz"
    broken.write_bytes(b"not a table")
    with pytest.raises(InputError, match="walk profile table"):
        walk_table.load_table(broken)


# --- the fitter's model -------------------------------------------------------------------

@pytest.fixture(scope="module")
def walk_model(small_capture):
    from translucent.fitting.models import WalkModel

    capture, profile, _ = small_capture
    return WalkModel(profile, capture.spec)


@settings(max_examples=25, deadline=None)
@given(st.floats(1e-3, 5.0), st.floats(0.05, 50.0), st.floats(0.1, 10.0),
       st.floats(1.0, 2.0))
def test_model_profile_scales_with_the_extinction(walk_model, sigma_a, sigma_s, scale, eta):
    # R(r; k sigma) = k^2 R(k r; sigma): checked on the table's own reduced profile
    table = walk_model.table
    nodes = walk_model.profile.operator.grid.nodes[1:]
    sigma_t = sigma_a + sigma_s
    albedo = np.array([sigma_s / sigma_t])
    direct = walk_model.unit_profiles(np.full((1, 3), sigma_a), np.full((1, 3), sigma_s),
                                      np.array([eta]))[0, 1:, 0]
    reduced = table.reduced_profile((sigma_t * nodes)[None], albedo, np.array([eta]))[0]
    np.testing.assert_allclose(direct, sigma_t ** 2 * reduced, rtol=1e-10)
    scaled = walk_model.unit_profiles(np.full((1, 3), scale * sigma_a),
                                      np.full((1, 3), scale * sigma_s), np.array([eta]))
    again = table.reduced_profile((scale * sigma_t * nodes)[None], albedo, np.array([eta]))[0]
    np.testing.assert_allclose(scaled[0, 1:, 0], (scale * sigma_t) ** 2 * again, rtol=1e-10)


def test_model_first_interval_holds_the_exitance_inside_it(walk_model):
    nodes = walk_model.profile.operator.grid.nodes
    sigma_a, sigma_s = np.array([[0.05, 0.5, 3.0]]), np.array([[1.0, 1.0, 1.0]])
    values = walk_model.unit_profiles(sigma_a, sigma_s, np.array([1.3]))[0]
    r1 = nodes[1]
    # the linear interpolant between nodes 0 and 1, integrated over the disc of radius r1
    held = 2.0 * np.pi * r1 ** 2 * (values[0] / 6.0 + values[1] / 3.0)
    sigma_t = (sigma_a + sigma_s)[0]
    inside = walk_model.table.reduced_cumulative(sigma_t * r1, sigma_s[0] / sigma_t, 1.3)
    np.testing.assert_allclose(held, inside, rtol=1e-10)
    assert np.all(values[0] > 0)


def test_the_tables_own_error_is_read_at_its_rows_and_rings():
    table = walk_table.load_table()
    e, a = 3, 40
    eta, albedo = table.etas[e], table.albedos[a]
    last = int(table._last_resolved[e, a])
    rings = np.array([0, last // 2, last])
    inside = np.sqrt(table.edges[rings] * table.edges[rings + 1])[None, :]
    inside[0, 0] = 0.5 * table.edges[1]
    expected = table.relative_se[e, a, rings]
    assert np.all(np.isfinite(expected))
    np.testing.assert_array_equal(table.relative_error(inside, [albedo], [eta]), expected[None])
    # beyond the last resolved ring: that ring's error, where the far field starts
    far = np.array([[table.edges[-1] * 2.0]])
    assert table.relative_error(far, [albedo], [eta])[0, 0] == table.relative_se[e, a, last]
    # between rows: the nearest
    nudged = table.relative_error(inside, [albedo], [eta + 0.2 * (table.etas[1] - table.etas[0])])
    np.testing.assert_array_equal(nudged, expected[None])


def test_walk_likelihood_adds_the_tables_noise_to_the_standard_errors(walk_model):
    from translucent.fitting.models import DipoleModel

    theta = walk_model.initial_guess()[None, :]
    sigma_a, sigma_s_prime, eta, _ = walk_model.split(theta)
    predicted = walk_model.predictions(theta)
    for c in walk_model.channels:
        _, stderr, _ = walk_model.observations(c)
        scale = walk_model.residual_scale(c, stderr, predicted[c], theta)
        sigma_t = sigma_a[0, c] + sigma_s_prime[0, c]
        edges = walk_model.profile.edges_mm
        radius = (0.5 * (edges[:-1] + edges[1:]))[walk_model.profile.used[:, c]]
        epsilon = walk_model.table.relative_error(sigma_t * radius[None], [sigma_s_prime[0, c]
                                                  / sigma_t], eta)
        np.testing.assert_allclose(scale, np.sqrt(stderr**2 + (epsilon * predicted[c]) ** 2))
        assert np.all(scale > stderr) and np.all(epsilon > 0)
    # the scale depends on the parameters: its normalisation is in the likelihood
    dipole = DipoleModel(walk_model.profile, walk_model.spec)
    assert np.ndim(dipole.scale_normalisation(scale)) == 0
    assert walk_model.scale_normalisation(scale).shape == (1,)


def test_walk_model_refuses_what_its_table_does_not_hold():
    from dataclasses import replace

    from translucent.fitting.capture import Capture
    from translucent.fitting.models import WalkModel
    from translucent.fitting.profile import measure_profile
    from translucent.fitting.synthetic import Camera, dipole_capture

    material = Dipole(sigma_a=[0.05, 0.1, 0.2], sigma_s_prime=[1.0, 1.5, 2.0], eta=1.3)
    pixels, spec = dipole_capture(material, size=32, pixel_size_mm=0.2, seed=3,
                                  thickness_mm=5.0, camera=Camera(peak_signal=30000))
    capture = Capture(spec, pixels)
    profile = measure_profile(capture)
    with pytest.raises(InputError, match="thickness_mm"):
        WalkModel(profile, spec)
    with pytest.raises(InputError, match="eta"):
        WalkModel(profile, replace(spec, thickness_mm=None, eta=2.4))


# --- translucent fit --model walk ---------------------------------------------------------

def test_fit_walk_refuses_a_finite_slab_before_writing(tmp_path, capsys):
    from translucent.fitting.capture import write_capture
    from translucent.fitting.synthetic import Camera, dipole_capture
    from translucent.reports.cli import main

    material = Dipole(sigma_a=[0.05, 0.1, 0.2], sigma_s_prime=[1.0, 1.5, 2.0], eta=1.3)
    pixels, spec = dipole_capture(material, size=24, pixel_size_mm=0.2, seed=3,
                                  thickness_mm=4.0, camera=Camera(peak_signal=30000))
    sidecar = write_capture(tmp_path / "slab.json", pixels, spec)
    code = main(["fit", str(sidecar), "--model", "walk", "--no-progress",
                 "--out", str(tmp_path / "fit")])
    captured = capsys.readouterr()
    assert code == 2 and "thickness_mm" in captured.err and "--model dipole" in captured.err
    assert "Traceback" not in captured.err
    assert not (tmp_path / "fit").exists()


@pytest.mark.slow  # 12 s; the outputs of a fit are checked in the fast tier by test_fit.py
@needs_drjit
def test_fit_walk_writes_its_outputs(tmp_path, capsys):
    from translucent.reports.cli import main

    sidecar = tmp_path / "skin.json"
    assert main(["capture", "skin1", "--size", "32", "--seed", "1", "--photons", "20000",
                 "--out", str(sidecar), "--no-progress"]) == 0
    code = main(["fit", str(sidecar), "--model", "walk", "--max-steps", "300",
                 "--walkers", "16", "--no-progress", "--out", str(tmp_path / "fit")])
    output = capsys.readouterr().out
    assert code == 1 and "\nwalk: NOT converged" in output  # 300 steps < 50 tau
    for name in ("summary.json", "material.toml", "profile.png", "corner.png", "samples.npz"):
        assert (tmp_path / "fit" / f"walk_{name}").is_file()


@pytest.mark.slow
@needs_drjit
@pytest.mark.parametrize("name", ["skin1", "marble", "ketchup"])
def test_a_walk_capture_fitted_with_the_walk_model_covers_its_truth(name):
    # the dipole misfits every one of these (docs/capture-format.md)
    from translucent.fitting.capture import Capture
    from translucent.fitting.fit import fit_dipole
    from translucent.fitting.random_walk import walk_capture
    from translucent.fitting.synthetic import default_pixel_size
    from translucent.materials import measured_medium

    material = measured_medium(name)
    pixels, spec, _ = walk_capture(material, size=96,
                                   pixel_size_mm=default_pixel_size(material, 96),
                                   photons=2_000_000, seed=4)
    result = fit_dipole(Capture(spec, pixels), seed=5, forward="walk")
    assert result.converged and not result.misfit
    truth = np.concatenate([material.sigma_a, material.sigma_s_prime])
    inside = [s.low95 <= t <= s.high95 for s, t in zip(result.parameters[:6], truth,
                                                        strict=True)]
    assert sum(inside) >= 5  # 95 % intervals: one miss in six is within chance
