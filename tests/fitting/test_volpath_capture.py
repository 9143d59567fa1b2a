"""Volpath slab captures: the beam emitter, energy, agreement with the photon random walk."""

import json

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy import stats
from translucent.errors import InputError
from translucent.fitting.random_walk import Film, photon_random_walk
from translucent.fitting.volpath_capture import (
    BEAM_DEPTH_MM,
    BEAM_PLUGIN,
    exitance_per_normal_radiance,
    register_plugins,
    render_exitance,
    semi_infinite_depth,
    volpath_capture,
)
from translucent.materials import Dipole, measured_medium
from translucent.materials.fresnel import diffuse_fresnel_reflectance

#: A short-path medium (albedo 0.5, mean free path 0.5 mm): a few hundred spp converge on
#: the CPU in about a second.
SHORT_PATHS = {"sigma_a": 1.0, "sigma_s_prime": 1.0}
#: Family-wise significance of the annulus comparisons (Sidak-corrected per annulus), as
#: in Mitsuba's own statistical render tests.
ALPHA = 0.01
#: Independent passes / walk runs behind each mean: the standard errors are estimated from
#: this many values, so the comparison uses Student's t with PASSES - 1 degrees of freedom.
PASSES = 8
#: The Gaussian beam's irradiance integrates to its power; the grid sum over +-4 w with
#: w / 16 spacing is exact to ~1e-7 (tails e^-32, and the midpoint rule on a Gaussian
#: converges spectrally), float32 evaluation adds ~1e-6.
IRRADIANCE_TOLERANCE = 1e-5
#: The Jensen polynomial for the internal diffuse Fresnel reflectance is a fit good to
#: about 0.002 in F_dr over eta in [1, 2] (0.0016 at eta = 1): the exact factor and the one
#: built from the polynomial agree within that, relative to 1 - F_dr (>= 0.4 there).
POLYNOMIAL_FIT = 0.002 / 0.4


def _annuli(shape, centre, pixel_size_mm, edges):
    yy, xx = np.mgrid[0:shape[0], 0:shape[1]] + 0.5
    r = np.hypot(xx - centre[0], yy - centre[1]) * pixel_size_mm
    return [(r >= a) & (r < b) for a, b in zip(edges[:-1], edges[1:], strict=True)]


def _critical(count, dof):
    """Two-sided Student-t critical value, Sidak-corrected over ``count`` comparisons."""
    per_test = 1.0 - (1.0 - ALPHA) ** (1.0 / count)
    return stats.t.ppf(1.0 - per_test / 2.0, dof)


def _walk_comparison(medium, *, side="reflection", thickness_mm=None, channels=(0,),
                     photons=40000, spp=PASSES * 64):
    """z of volpath minus walk annulus means, (channels, annuli), and the critical value."""
    shape, pixel, centre, beam = (24, 24), 0.25, (14.0, 11.0), 0.5
    render = render_exitance(medium, shape=shape, pixel_size_mm=pixel, incident_px=centre,
                             beam_radius_mm=beam, spp=spp, pass_spp=spp // PASSES, seed=11,
                             side=side, thickness_mm=thickness_mm)
    assert render.passes == PASSES
    film = Film(shape, pixel, centre, side)
    walks = np.stack([photon_random_walk(medium, photons=photons, beam_radius_mm=beam,
                                         film=film, rotations=8, seed=seed,
                                         thickness_mm=thickness_mm, channels=channels).film
                      for seed in range(PASSES)])
    edges = np.array([0.0, 0.25, 0.5, 0.75, 1.0, 1.5, 2.0, 3.0])
    masks = _annuli(shape, centre, pixel, edges)
    z = np.zeros((len(channels), len(masks)))
    for i, c in enumerate(channels):
        for j, mask in enumerate(masks):
            walk = walks[..., c]
            difference = render.exitance[..., c][mask].mean() - walk.mean(axis=0)[mask].mean()
            walk_se = walk[:, mask].mean(axis=1).std(ddof=1) / np.sqrt(PASSES)
            volpath_se = np.sqrt((render.standard_error[..., c][mask] ** 2).sum()) / mask.sum()
            z[i, j] = difference / np.hypot(walk_se, volpath_se)
    return z, _critical(z.size, PASSES - 1), render


@pytest.mark.parametrize(("eta", "side", "thickness_mm"), [
    (1.0, "reflection", None), (1.3, "reflection", None), (1.3, "transmission", 1.0)])
def test_agrees_with_the_photon_random_walk_in_annuli(eta, side, thickness_mm):
    z, critical, render = _walk_comparison(Dipole(eta=eta, **SHORT_PATHS), side=side,
                                           thickness_mm=thickness_mm)
    assert np.all(np.abs(z) < critical), np.round(z, 2)
    # the channels are one grey medium, rendered once
    np.testing.assert_array_equal(render.exitance[..., 1], render.exitance[..., 0])


def test_a_chromatic_medium_agrees_with_the_walk_in_every_channel():
    # red and blue share their coefficients (and one grey render), green differs
    medium = Dipole(sigma_a=[1.0, 0.5, 1.0], sigma_s_prime=[1.0, 2.0, 1.0], eta=1.3)
    z, critical, render = _walk_comparison(medium, channels=(0, 1, 2), photons=15000,
                                           spp=PASSES * 32)
    assert np.all(np.abs(z) < critical), np.round(z, 2)
    np.testing.assert_array_equal(render.exitance[..., 2], render.exitance[..., 0])
    assert not np.array_equal(render.exitance[..., 1], render.exitance[..., 0])


def test_the_comparison_has_teeth():
    # the same annuli, passes and critical value tell a 20 % change of sigma_s' apart
    shape, pixel, centre, beam = (24, 24), 0.25, (14.0, 11.0), 0.5
    renders = [render_exitance(Dipole(sigma_a=1.0, sigma_s_prime=s, eta=1.3), shape=shape,
                               pixel_size_mm=pixel, incident_px=centre, beam_radius_mm=beam,
                               spp=PASSES * 64, pass_spp=64, seed=12) for s in (1.0, 1.2)]
    edges = np.array([0.0, 0.25, 0.5, 0.75, 1.0, 1.5, 2.0, 3.0])
    masks = _annuli(shape, centre, pixel, edges)
    z = []
    for mask in masks:
        means = [r.exitance[..., 0][mask].mean() for r in renders]
        errors = [np.sqrt((r.standard_error[..., 0][mask] ** 2).sum()) / mask.sum()
                  for r in renders]
        z.append((means[1] - means[0]) / np.hypot(*errors))
    assert np.max(np.abs(z)) > _critical(len(masks), PASSES - 1), np.round(z, 2)


def test_beam_irradiance_integrates_to_the_entering_power():
    from translucent.backend import mitsuba

    mi = mitsuba()
    register_plugins()
    w, cx, cy = 0.3, 0.7, -0.2
    beam = mi.load_dict({"type": BEAM_PLUGIN, "beam_radius": w, "centre_x": cx,
                         "centre_y": cy})
    step = w / 16.0
    axis = np.arange(-4.0 * w, 4.0 * w, step) + 0.5 * step
    x, y = np.meshgrid(axis + cx, axis + cy)
    depth = 2.5
    it = mi.Interaction3f()
    it.p = mi.Point3f(x.ravel(), y.ravel(), np.full(x.size, -depth))
    ds, weight = beam.sample_direction(it, mi.Point2f(0.5, 0.5))
    power = np.asarray(weight)[0].sum() * step * step
    assert power == pytest.approx(1.0, abs=IRRADIANCE_TOLERANCE)
    # the shadow ray goes straight up and stops on the origin plane, below the boundary
    np.testing.assert_allclose(np.asarray(ds.d)[:, 0], [0.0, 0.0, 1.0])
    np.testing.assert_allclose(np.asarray(ds.dist), depth - BEAM_DEPTH_MM, rtol=1e-6)
    np.testing.assert_allclose(np.asarray(ds.p)[2], -BEAM_DEPTH_MM, rtol=1e-6)
    np.testing.assert_allclose(np.asarray(ds.p)[:2], [x.ravel(), y.ravel()], rtol=1e-6)
    assert np.all(np.asarray(ds.delta)) and np.all(np.asarray(ds.pdf) == 1.0)
    # nothing reaches a point above the origin plane
    it.p = mi.Point3f(cx, cy, -0.5 * BEAM_DEPTH_MM)
    ds, weight = beam.sample_direction(it, mi.Point2f(0.5, 0.5))
    assert np.asarray(weight).max() == 0.0 and np.asarray(ds.pdf).max() == 0.0


@pytest.mark.parametrize("eta", [1.0, 1.3])
def test_a_non_absorbing_slab_returns_all_the_entering_power(eta):
    # reflected + transmitted = 1 for a thin non-absorbing slab (2 mean free paths): the
    # scattered light spreads a few tenths of a mm, the 3 mm film catches it, and the
    # unscattered beam (e^-2 of it, partly reflected at the faces) is added in closed form
    medium = Dipole(sigma_a=0.0, sigma_s_prime=10.0, eta=eta)
    options = dict(shape=(24, 24), pixel_size_mm=0.125, thickness_mm=0.2, beam_radius_mm=0.3,
                   spp=256, pass_spp=64, seed=13)
    reflected = render_exitance(medium, side="reflection", **options)
    transmitted = render_exitance(medium, side="transmission", **options)
    total = reflected.total[0] + transmitted.total[0]
    error = np.hypot(reflected.total[0] * reflected.relative_standard_error()[0],
                     transmitted.total[0] * transmitted.relative_standard_error()[0])
    assert abs(total - 1.0) < _critical(1, 3) * error, (total, error)
    assert error < 0.015  # the test resolves about a per cent
    # without the unscattered beam (e^-2 = 13.5 % of the light) the sum would fail
    assert abs(total - transmitted.unscattered[0] - reflected.unscattered[0] - 1.0) > \
        _critical(1, 3) * error


@pytest.mark.slow
def test_a_non_absorbing_semi_infinite_slab_returns_nearly_everything():
    # ~30 s: semi-infinite stands for 200 mean free paths (20 mm), which transmit about
    # 4 / (3 x 200) = 0.7 %, and the 16 mm film misses the dipole's r^-3 tail beyond 8 mm,
    # (z_r + z_v) / (2 r) ~ 3.5 %: between 0.93 and 1 of the entering power is on the film
    medium = Dipole(sigma_a=0.0, sigma_s_prime=10.0, eta=1.3)
    render = render_exitance(medium, shape=(8, 8), pixel_size_mm=2.0, beam_radius_mm=2.0,
                             spp=256, pass_spp=32, seed=3)
    error = render.total[0] * render.relative_standard_error()[0]
    critical = _critical(1, render.passes - 1)
    assert 0.93 - critical * error < render.total[0] < 1.0 + critical * error
    assert error < 0.05


def test_volpath_capture_writes_truth_and_puts_the_beam_at_the_incident_point(tmp_path):
    from translucent.fitting.capture import read_capture, write_capture

    medium = Dipole(sigma_a=[1.0, 0.5, 2.0], sigma_s_prime=[1.0, 2.0, 1.0], eta=1.3,
                    name="test")
    stored, spec, render = volpath_capture(medium, size=(16, 20), pixel_size_mm=0.2,
                                           incident_px=(13.0, 5.0), spp=16, pass_spp=8,
                                           seed=15)
    assert stored.shape == (16, 20, 3)
    truth = spec.synthetic
    assert truth["generator"] == "mitsuba volpath" and truth["spp"] == 16
    assert truth["passes"] == 2 and truth["variant"] == render.variant
    assert spec.beam_radius_mm == pytest.approx(0.05 * 20 * 0.2)
    row, col = np.unravel_index(np.argmax(render.exitance.sum(axis=2)), (16, 20))
    assert abs(col + 0.5 - 13.0) <= 1.0 and abs(row + 0.5 - 5.0) <= 1.0
    path = write_capture(tmp_path / "capture.json", stored, spec)
    assert read_capture(path).spec.synthetic["generator"] == "mitsuba volpath"


def test_capture_command_renders_volpath(tmp_path):
    from translucent.reports.cli import main

    out = tmp_path / "ketchup.json"
    code = main(["capture", "ketchup", "--generator", "volpath", "--spp", "8", "--pass-spp",
                 "4", "--size", "16", "--seed", "3", "--out", str(out)])
    assert code == 0
    sidecar = json.loads(out.read_text())
    assert sidecar["synthetic"]["generator"] == "mitsuba volpath"
    assert (tmp_path / sidecar["image"]).is_file()
    assert main(["capture", "ketchup", "--generator", "volpath", "--beam-radius", "0",
                 "--size", "16", "--out", str(out)]) == 2


def test_semi_infinite_depth_follows_the_constants():
    skin = measured_medium("skin1")
    # red: 20 / sigma_tr is shorter than 200 mean free paths
    assert semi_infinite_depth(skin) == pytest.approx(20.0 / skin.sigma_tr[0])
    spectralon = measured_medium("spectralon")  # no absorption: 200 mean free paths
    assert semi_infinite_depth(spectralon) == pytest.approx(
        200.0 / spectralon.sigma_s_prime.min())


@settings(max_examples=30, deadline=None)
@given(st.floats(min_value=1.0, max_value=2.0))
def test_normal_radiance_factor_matches_the_internal_diffuse_fresnel_polynomial(eta):
    # E / L = pi eta^2 (1 - F_dr,int) / (1 - R(0)): the exact factor against the one built
    # from Jensen's polynomial for the internal diffuse reflectance
    r_normal = ((eta - 1.0) / (eta + 1.0)) ** 2
    from_polynomial = np.pi * eta**2 * (1.0 - diffuse_fresnel_reflectance(eta)) / (1 - r_normal)
    factor = exitance_per_normal_radiance(eta)
    assert factor == pytest.approx(from_polynomial, rel=POLYNOMIAL_FIT)
    assert factor <= np.pi + 1e-12


def test_normal_radiance_factor_at_index_match_is_pi():
    assert exitance_per_normal_radiance(1.0) == pytest.approx(np.pi, rel=1e-12)


@pytest.mark.parametrize(("changes", "message"), [
    ({"beam_radius_mm": 0.0}, "camera paths cannot find a pencil beam"),
    ({"spp": 1}, "integer >= 2"),
    ({"spp": 0}, "integer >= 2"),
    ({"pass_spp": 0}, "must be an integer >= 1"),
    ({"side": "top"}, "'reflection' or 'transmission'"),
    ({"side": "transmission"}, "transmission needs a finite thickness"),
    ({"thickness_mm": -1.0}, "must be > 0 or None"),
    ({"pixel_size_mm": 0.0}, "must be > 0"),
    ({"incident_px": (40.0, 2.0)}, "must lie inside the 16 x 16 image"),
    ({"sensor": "camera"}, "must be one of exitance, normal radiance"),
    ({"channels": "spectral"}, "must be one of separate, rgb"),
])
def test_bad_input_is_refused(changes, message):
    options = dict(shape=(16, 16), pixel_size_mm=0.1, beam_radius_mm=0.2, spp=4)
    options.update(changes)
    with pytest.raises(InputError, match=message):
        render_exitance(Dipole(**SHORT_PATHS), **options)


def test_material_must_be_a_dipole():
    with pytest.raises(InputError, match="must be a Dipole"):
        render_exitance("marble", shape=(16, 16), beam_radius_mm=0.2, spp=4)


def test_bias_table_refuses_an_unknown_generator():
    from translucent.fitting.validation import model_bias_table

    with pytest.raises(InputError, match="must be one of walk, volpath"):
        model_bias_table(["skin1"], generator="mcml")


@pytest.mark.slow
def test_bias_table_from_volpath_captures(tmp_path):
    # ~30 s: one medium, a tiny capture (at 32 spp most far pixels get no path to the beam
    # and fall below black: no usable annuli); the row says which solver made it
    from translucent.reports.cli import main

    code = main(["bench", "fitting", "--bias-table", "--generator", "volpath", "--materials",
                 "ketchup", "--size", "32", "--spp", "128", "--pass-spp", "64", "--out",
                 str(tmp_path)])
    figures = json.loads((tmp_path / "bias_volpath.json").read_text())
    (row,) = figures["rows"]
    assert row["generator"] == "mitsuba volpath" and row["spp"] == 128
    assert code == (0 if row["converged"] else 1)
    assert np.all(np.isfinite(row["fit_sigma_s_prime"]))
    assert (tmp_path / "bias_volpath.md").read_text().count("Ketchup") == 1


@pytest.mark.parametrize("field", ["pixel_size_mm", "thickness_mm", "beam_radius_mm"])
def test_an_infinite_length_is_called_not_finite(field):
    # "inf: must be > 0" told the user nothing
    options = dict(shape=(16, 16), pixel_size_mm=0.1, beam_radius_mm=0.2, spp=4)
    options[field] = float("inf")
    with pytest.raises(InputError, match="finite") as error:
        render_exitance(Dipole(**SHORT_PATHS), **options)
    assert error.value.field == field
