"""Speed-up over path tracing at equal error, and the run-time-against-error plot."""

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from translucent.image import Image
from translucent.reports.report.speedup import (
    PathTracingCurve,
    scored_curve,
    speedup,
    tradeoff_plot,
)


def _power_law(c=1.0, t1=0.25, spp=(1, 4, 16)):
    """Path tracing as Monte Carlo runs it: error c / spp, time t1 * spp."""
    return PathTracingCurve(list(spp), [t1 * n for n in spp], [c / n for n in spp])


@settings(max_examples=40, deadline=None)
@given(c=st.floats(0.05, 20.0), t1=st.floats(1e-3, 5.0), frame=st.floats(1e-4, 10.0),
       spp_at=st.floats(1.0, 16.0))
def test_inside_the_ladder_the_speedup_is_the_exact_time_ratio(c, t1, frame, spp_at):
    # on an exact power law, log-log interpolation is exact: path tracing reaches the error
    # c / n at n spp, in t1 * n seconds
    found = speedup(_power_law(c, t1), c / spp_at, frame, "resolved")
    assert not found["extrapolated"] and found["reason"] is None
    assert found["path_tracing_seconds"] == pytest.approx(t1 * spp_at, rel=1e-9)
    assert found["speedup_vs_path_tracing"] == pytest.approx(t1 * spp_at / frame, rel=1e-9)


def test_beyond_the_ladder_the_power_law_is_extended_and_flagged():
    found = speedup(_power_law(1.0, 0.25), 1.0 / 256, 0.01, "resolved")
    assert found["extrapolated"] and "extrapolated" in found["reason"]
    assert found["path_tracing_seconds"] == pytest.approx(0.25 * 256, rel=1e-6)
    assert found["speedup_vs_path_tracing"] == pytest.approx(0.25 * 256 / 0.01, rel=1e-6)


@pytest.mark.parametrize("curve, error, frame, verdict, words", [
    (None, 0.1, 0.01, "resolved", "no path-tracing ladder"),
    (PathTracingCurve([1], [0.2], [1.0], "4 spp: failed"), 0.1, 0.01, "resolved",
     "under two points (4 spp: failed)"),
    ("power", 0.1, 0.01, "within reference noise", "within the reference's noise"),
    ("power", math.nan, 0.01, "resolved", "not positive and finite"),
    ("power", 0.1, None, "resolved", "frame time is not known"),
])
def test_no_speedup_without_what_it_needs_and_the_reason_says_which(curve, error, frame,
                                                                    verdict, words):
    curve = _power_law() if curve == "power" else curve
    found = speedup(curve, error, frame, verdict)
    assert found["speedup_vs_path_tracing"] is None
    assert words in found["reason"]


def test_the_ladder_is_scored_on_the_scored_pixels(rng):
    truth = np.full((8, 8, 3), 2.0)
    reference = Image(truth, np.full_like(truth, 1e-8))
    mask = np.zeros((8, 8), dtype=bool)
    mask[2:6, 2:6] = True
    noisy = truth.copy()
    noisy[~mask] = 20.0  # outside the scored pixels: must not count
    noisy[mask] *= 1.1
    points = [{"spp": 1, "seconds": 0.5, "images": [Image(noisy)]},
              {"spp": 4, "error": "RuntimeError: out of memory"}]
    curve = scored_curve(points, reference, mask)
    assert curve.spp == [1] and curve.seconds == [0.5]
    # (0.2^2 - 1e-8) / (2^2 + epsilon 0.01) on every scored channel
    assert curve.relative_mse[0] == pytest.approx((0.04 - 1e-8) / 4.01, rel=1e-6)  # float32 pixels
    assert "4 spp: RuntimeError" in curve.error
    assert scored_curve("TypeError: the task failed", reference).error.startswith("TypeError")


def test_the_plot_is_written_or_nothing_when_there_is_nothing_to_draw(tmp_path):
    path = tradeoff_plot(tmp_path / "t.png", {"path tracing": _power_law()}, {"prt": (0.01, 1e-3),
                                                           "broken": (None, 0.1)},
                         1e-4, "sphere")
    assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert tradeoff_plot(tmp_path / "none.png", {"path tracing": None},
                         {"broken": (0.0, 0.1)}, None, "x") is None
    assert sorted(p.name for p in tmp_path.iterdir()) == ["t.png"]


def test_relit_frames_move_every_light_a_little():
    from translucent.reports.report.runs import LIGHT_NUDGE, nudged_lights
    from translucent.scenes import (
        ConstantEnvironment,
        DirectionalLight,
        PointLight,
        RectangularAreaLight,
        SphereAreaLight,
        SpotLight,
    )

    lights = [PointLight([1.0, 2.0, 3.0], 5.0),
              SpotLight([0.0, 1.0, 0.0], [0.0, -1.0, 0.0], 5.0),
              DirectionalLight([0.0, 0.0, -1.0], 1.0),
              SphereAreaLight([0.0, 3.0, 0.0], 0.2, 1.0),
              RectangularAreaLight([0, 2.0, 0], [0.25, 0, 0], [0, 0, 0.25], 1.0),
              ConstantEnvironment(1.0)]
    moved = nudged_lights(lights, 2)
    assert [type(a) for a in moved] == [type(b) for b in lights]
    for before, after in zip(lights[:5], moved[:5], strict=True):
        # a new light: no method may reuse the last frame's lighting
        assert after is not before
        assert any(not np.array_equal(getattr(before, name), getattr(after, name))
                   for name in ("position", "center", "direction") if hasattr(before, name))
    np.testing.assert_allclose(moved[0].position - lights[0].position, [2 * LIGHT_NUDGE, 0, 0])
    np.testing.assert_allclose(moved[3].center - lights[3].center, [2 * LIGHT_NUDGE, 0, 0])
    assert np.linalg.norm(moved[2].direction) == pytest.approx(1.0)
    assert np.degrees(np.arccos(moved[2].direction @ lights[2].direction)) < 0.1
    assert moved[5] is lights[5]


def test_the_ladder_loads_and_compiles_once_and_times_every_spp(monkeypatch):
    """One load and one untimed render for the whole ladder: loading a scene once per spp
    compiled every kernel again (the loaded sample count is part of them)."""
    import importlib

    from translucent.reports.report.speedup import path_tracing_ladder
    from translucent.scenes import load_scene

    render_module = importlib.import_module("translucent.reference.render")
    loads, renders = [], []

    def load_scenes(scene, *, spp, **options):
        loads.append(spp)
        return (None,), [type("Conversion", (), {"integrator": "volpath"})()], ["loaded"]

    def render_sample(channels, loaded, spp, seed, on_render=None):
        renders.append((spp, seed))
        if spp == 8:
            raise RuntimeError("out of memory")
        return np.full((2, 2, 3), float(spp))

    monkeypatch.setattr(render_module, "load_scenes", load_scenes)
    monkeypatch.setattr(render_module, "render_sample", render_sample)
    points = path_tracing_ladder(load_scene("sphere"), (1, 4, 8, 16))
    assert loads == [1]
    assert renders == [(1, 2), (1, 1), (4, 1), (8, 1), (16, 1)]  # untimed first
    assert [p["spp"] for p in points] == [1, 4, 8, 16]
    assert "out of memory" in points[2]["error"]
    assert all(p["seconds"] >= 0 and p["images"][0].rgb[0, 0, 0] == p["spp"]
               for p in points if "error" not in p)
