"""The stress kernels beyond the materials: PCA projections, radiosity, wavelets, fits, diffusion.

Each kernel runs here in a tiny configuration; the full sweeps are what
``translucent stress`` runs. A kernel whose method is made to return NaN must fail, and
make the command exit 1.
"""

import functools
import json
import types

import numpy as np
import pytest
from translucent.fast.prt import LOCAL_BLEND_START
from translucent.fast.wavelets import SpatialWavelet
from translucent.fitting.results import ParameterSummary
from translucent.materials.dipole_pca import DipolePCABasis
from translucent.reports import stress
from translucent.reports.cli import main
from translucent.reports.stress import diffusion, fits, pca, radiosity, splatting, wavelets

#: Coefficients inside both preset grids (area_normalised: sigma_s' in [0.02, 25],
#: sigma_a in [1e-4, 5] mm^-1), where the bases are built to work.
INSIDE_GRID = (0.05, 0.5, 2.0)

TINY = {
    "dipole PCA projection float32 vs float64":
        functools.partial(pca.pca_float32, sigmas=(1e-6, 1.0, 1e3), etas=(1.0, 2.5)),
    "dipole PCA energy outside the grid (area_normalised)":
        functools.partial(pca.pca_energy, "area_normalised", sigmas=INSIDE_GRID, etas=(1.3,)),
    "radiosity near the convergence limit":
        functools.partial(radiosity.radiosity_limit, albedos=(0.9, 1.0, 1.01), patches=16,
                          tolerances=(5e-3,)),
    "wavelet compression at extreme ratios":
        functools.partial(wavelets.wavelet_compression, sides=(8,)),
    "fits on degenerate captures":
        functools.partial(fits.degenerate_fits, cases=fits.EMPTY_CASES),
    "spatial CDF 9/7 compression at extreme ratios":
        functools.partial(wavelets.spatial_compression, grids=((9, 10),)),
    "finite-object diffusion gain":
        functools.partial(diffusion.finite_object_gain_sweep, sigma_as=(1e-8, 1e-2),
                          sigma_s_primes=(0.5, 1e3), etas=(1.0, 2.0)),
    "splatting over profile supports and light angles":
        functools.partial(splatting.splatting_sweep, supports=(1e-2, 10.0),
                          elevations=(90.0, 0.5)),
}


def test_every_new_kernel_is_registered():
    assert set(TINY) <= set(stress.all_kernels())
    assert "dipole PCA energy outside the grid (paper)" in stress.all_kernels()


@pytest.mark.parametrize("name", sorted(TINY))
def test_tiny_configurations_pass_without_nan(name):
    result = TINY[name]()
    assert result.evaluations > 0
    assert (result.nan, result.inf, result.negative) == (0, 0, 0)
    assert result.worst_relative_error <= result.bound
    assert result.passed


def test_pca_float32_error_is_within_the_roundoff_bound():
    result = TINY["dipole PCA projection float32 vs float64"]()
    # the bound is a few float32 roundoffs times sqrt(K): far above the measured error
    assert result.bound == pytest.approx(pca.float32_reconstruction_bound(12))
    assert 0 < result.worst_relative_error < result.bound


def test_pca_energy_no_longer_trusts_an_unresolved_profile():
    # sigma = 1e3 mm^-1: a profile 1e-3 mm wide, between the paper's first two samples
    # (0.1 mm apart). The residual alone (7.5e-5, below LOCAL_BLEND_START) trusted it while
    # the K-term energy is wrong in sign; the method's criterion now refuses it, so the
    # kernel judges nothing there and passes.
    result = pca.pca_energy("paper", sigmas=(1e3,), etas=(1.3,))
    assert result.worst_at["residual"] < LOCAL_BLEND_START
    assert result.worst_at["energy"] < 0 < result.worst_at["exact_energy"]
    assert result.details[0]["trusted"] == 0
    assert result.details[0]["untrusted_worst_energy_error"] > 100 * result.bound
    assert result.passed


def test_radiosity_refuses_at_and_above_albedo_one():
    result = TINY["radiosity near the convergence limit"]()
    checks = {d["albedo"]: d["check_convergence"] for d in result.details
              if "check_convergence" in d}
    assert checks == {0.9: "accepted", 1.0: "refused", 1.01: "refused"}
    outcomes = [(d["albedo"], d["outcome"]) for d in result.details if "solver" in d]
    assert all(outcome == "refused" for albedo, outcome in outcomes if albedo > 1.0)
    assert all(outcome == "solved" for albedo, outcome in outcomes if albedo < 1.0)
    assert not any(d.get("garbage") for d in result.details)


def test_radiosity_exact_answer_is_the_closed_form():
    row = np.full(4, 0.25)
    source = np.ones((4, 3))
    # uniform emission inside a closed sphere: B = E / (1 - rho)
    np.testing.assert_allclose(radiosity.exact_radiosity(0.9, row, source), 10.0 * source)


def test_wavelet_kernel_covers_one_term_to_all_and_refuses_19_index_bits():
    result = wavelets.wavelet_compression(sides=(4,), kinds=("delta",))
    assert {d["terms"] for d in result.details if "terms" in d} == {1, 2, 4, 16}
    assert result.details[-1]["outcome"] == "refused"


def test_wavelet_rows_span_the_dynamic_range():
    row = wavelets.make_row("dynamic range 1e-30..1e30", 4096, np.random.default_rng(0))
    magnitude = np.abs(row[row != 0])
    assert magnitude.min() < 1e-28 and magnitude.max() > 1e28
    assert np.isfinite(row).all() and row.dtype == np.float32


def test_empty_captures_are_refused_naming_the_image():
    result = TINY["fits on degenerate captures"]()
    assert [d["outcome"] for d in result.details] == ["refused"] * len(fits.EMPTY_CASES)
    assert all("image" in d["message"] and "usable annuli" in d["message"]
               for d in result.details)


def _nan_fit(*_, **__):
    nan = float("nan")
    summary = ParameterSummary("sigma_a[R]", "mm^-1", nan, nan, nan, nan, nan, "constrained",
                               (1e-4, 10.0), nan)
    return types.SimpleNamespace(parameters=[summary], converged=False)


def _nan_like_first(function):
    def broken(*args, **kwargs):
        out = function(*args, **kwargs)
        first = out[0] if isinstance(out, tuple) else out
        nan = np.full_like(np.asarray(first, dtype=np.float64), np.nan)
        return (nan,) + tuple(out[1:]) if isinstance(out, tuple) else nan
    return broken


BREAKS = {
    "dipole PCA projection float32 vs float64":
        (DipolePCABasis, "project", _nan_like_first(DipolePCABasis.project)),
    "dipole PCA energy outside the grid (area_normalised)":
        (DipolePCABasis, "project_with_residual",
         _nan_like_first(DipolePCABasis.project_with_residual)),
    "radiosity near the convergence limit":
        (radiosity, "solve_radiosity", _nan_like_first(radiosity.solve_radiosity)),
    "wavelet compression at extreme ratios":
        (wavelets, "haar2d_inverse", _nan_like_first(wavelets.haar2d_inverse)),
    "fits on degenerate captures": (fits, "fit_dipole", _nan_fit),
    "spatial CDF 9/7 compression at extreme ratios":
        (SpatialWavelet, "forward", _nan_like_first(SpatialWavelet.forward)),
}


@pytest.mark.parametrize("name", sorted(BREAKS))
def test_a_kernel_whose_method_returns_nan_makes_the_command_exit_1(name, monkeypatch,
                                                                    tmp_path):
    target, attribute, broken = BREAKS[name]
    monkeypatch.setitem(stress._KERNELS, name, TINY[name])
    monkeypatch.setattr(target, attribute, broken)
    out = tmp_path / "stress.json"
    assert main(["stress", "--only", name, "--json", str(out)]) == 1
    written = json.loads(out.read_text())[name]
    assert written["nan"] > 0 and not written["passed"]
    assert isinstance(written["details"], list)


def test_a_kernel_that_raises_is_a_failure_not_a_crash(monkeypatch, tmp_path):
    def broken():
        raise ZeroDivisionError("deliberately")

    stress.stress_kernel("raises (test)")(broken)
    try:
        assert main(["stress", "--only", "raises (test)", "--json",
                     str(tmp_path / "s.json")]) == 1
        written = json.loads((tmp_path / "s.json").read_text())["raises (test)"]
        assert "ZeroDivisionError: deliberately" in written["notes"]
    finally:
        stress._KERNELS.pop("raises (test)")


def test_spatial_float32_bound_grows_with_the_levels():
    assert wavelets.lifting_rounding_bound(2) == pytest.approx(
        2 * wavelets.lifting_rounding_bound(1))
    # a few thousand float32 roundoffs per level: crude, but far below any compression error
    assert 1e-5 < wavelets.lifting_rounding_bound(1) < 1e-3


@pytest.mark.slow
def test_a_capture_with_nan_pixels_is_fitted_with_finite_medians():
    result = fits.degenerate_fits(cases=("NaN pixels",), seeds=(1,))
    (case,) = result.details
    assert case["outcome"] == "fitted"
    assert all(np.isfinite(v) for v in case["medians"].values())
    assert result.passed


def test_splatting_sweep_compares_resolved_supports_and_blacks_out_an_empty_view():
    result = splatting.splatting_sweep(supports=(1e-2, 10.0), elevations=(30.0,))
    compared = [case for case in result.details if "relative_error" in case]
    assert [case["support_mm"] for case in compared] == [10.0]
    assert 0 < compared[0]["relative_error"] <= result.bound
    assert result.details[-1] == {"camera": "turned away", "nonzero_pixels": 0}
