"""The asv benchmarks (benchmarks/accuracy.py) read the report's figures and cover its scenes."""

import importlib.util
import math
from pathlib import Path

import pytest
from translucent.fast.base import METHODS
from translucent.reports.report.pipeline import default_scenes

ROOT = Path(__file__).resolve().parents[1]


def _load(name: str):
    """Import ``benchmarks/<name>.py`` (asv's folder is not part of the package)."""
    spec = importlib.util.spec_from_file_location(f"asv_{name}", ROOT / "benchmarks" /
                                                  f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _benchmarks():
    return _load("accuracy")


def test_the_history_tracks_every_default_scene_and_method():
    # a new default scene or built-in method without a history fails here: the lists are
    # fixed, so that old commits are asked the same
    accuracy = _benchmarks()
    assert sorted(accuracy.BUILTIN_SCENES) == sorted(default_scenes()[0])
    assert sorted(accuracy.BUILTIN_METHODS) == sorted(METHODS)
    assert accuracy.METHODS[:len(accuracy.BUILTIN_METHODS)] == accuracy.BUILTIN_METHODS


def test_figures_are_read_from_a_reports_metrics_and_missing_ones_are_not_numbers():
    accuracy = _benchmarks()
    metrics = {"scenes": {"sphere": {"methods": {
        "prt": {"status": "ok",
                "noise": {"relative_mse": {"value": 0.01, "noise_floor": 2e-4},
                          "hdr_flip": {"value": 0.1, "noise_floor": 0.01}},
                "model_error": {"metrics": {"relative_mse": 0.006}},
                "approximation_error": None},
        "brdf_pca": {"status": "not applicable"}}}}}
    figures = accuracy.figures_of(metrics)
    assert figures == {"sphere": {"prt": {
        "relative_mse": 0.01, "relative_mse_noise_floor": 2e-4, "hdr_flip": 0.1,
        "hdr_flip_noise_floor": 0.01, "model_relative_mse": 0.006}}}
    benchmark = accuracy.Accuracy()
    assert set(accuracy.TRACKED) == set(accuracy.FIGURES)  # one track_ a figure
    assert benchmark.track_relative_mse(figures, "sphere", "prt") == 0.01
    assert benchmark.track_hdr_flip_noise_floor(figures, "sphere", "prt") == 0.01
    assert accuracy.Accuracy.track_relative_mse.unit == "relative MSE"
    assert benchmark.track_relative_mse_noise_floor(figures, "sphere", "prt") == 2e-4
    # a figure this commit's report lacks is not a number; a method it did not run is skipped
    assert math.isnan(benchmark.track_approximation_relative_mse(figures, "sphere", "prt"))
    benchmark.setup(figures, "sphere", "prt")
    for args in (("sphere", "brdf_pca"), ("bowl", "prt")):
        with pytest.raises(NotImplementedError):
            benchmark.setup(figures, *args)


def test_the_fits_figures_are_its_coverage_its_mean_seconds_and_its_convergence():
    from types import SimpleNamespace

    import numpy as np

    accuracy = _benchmarks()
    result = SimpleNamespace(fraction=5 / 6, fit_seconds=np.array([2.0, 4.0]), seconds=7.0,
                             converged=np.array([True, False]))
    figures = accuracy.fit_figures(result)
    assert figures == {"coverage": 5 / 6, "seconds": 3.0, "converged": 0.5}
    fit = accuracy.Fit()
    assert fit.track_interval_coverage(figures) == 5 / 6
    assert fit.track_seconds_per_fit(figures) == 3.0
    with pytest.raises(NotImplementedError):
        fit.setup(None)


def test_the_published_pages_load_their_scripts_from_the_copies_beside_them():
    publish = _load("publish")
    page = ('<script src="https://code.jquery.com/jquery-3.3.1.min.js" integrity="sha256-x" '
            'crossorigin="anonymous" onerror="f()"></script>\n<script src="asv.js"></script>\n'
            '<link rel="stylesheet" href="https://cdn.jsdelivr.net/npm/bootstrap@3.1.1/dist/css/'
            'bootstrap.min.css">\n<a href="https://github.com/airspeed-velocity/asv/">asv</a>')
    local = publish.localise(page)
    assert '<script src="vendor/jquery.min.js" onerror="f()"></script>' in local
    assert '<link rel="stylesheet" href="vendor/bootstrap.min.css">' in local
    assert '<script src="asv.js"></script>' in local            # its own scripts stay
    assert 'href="https://github.com/airspeed-velocity/asv/"' in local  # a link is no load
    for name in [*publish.COPIES.values(), "LICENSES.md"]:       # every copy is committed
        assert (publish.VENDOR / name).is_file(), name
    with pytest.raises(ValueError, match="no copy of https://example.org/new.js"):
        publish.localise('<script src="https://example.org/new.js"></script>')
