"""Progressive references: passes added until a noise target or a budget, resumable."""

import numpy as np
import pytest
from translucent.errors import InputError
from translucent.image import read_exr
from translucent.materials import Lambertian
from translucent.noise import noise_summary
from translucent.reference.render import (
    PROGRESSIVE_SEED_OFFSET,
    check_noise_target,
    render,
    render_to_target,
)
from translucent.reports.cli import main
from translucent.reports.metrics.statistics import z_test_known_variance
from translucent.scenes import (
    Camera,
    Scene,
    SceneObject,
    SphereAreaLight,
    icosphere,
)

SIZE = 16


def _scene(albedo=0.5):
    """A diffuse ball under a sphere light: light sampling makes every lit pixel noisy."""
    camera = Camera(origin=[0, 0, 4], target=[0, 0, 0], fov=40, width=SIZE, height=SIZE)
    light = SphereAreaLight(center=np.array([2.0, 2.0, 2.0]), radius=1.0,
                            radiance=np.array([5.0, 5.0, 5.0]))
    return Scene((SceneObject("ball", icosphere(2, 1.0), Lambertian(albedo)),), (light,),
                 camera, mm_per_unit=10.0, name="ball")


def test_stops_when_the_target_is_reached():
    passes = []
    image = render_to_target(_scene(), target_rse=0.2, spp=2, min_passes=3, cache=False,
                             progress=False, on_pass=lambda n, s, r: passes.append((n, r)))
    meta = image.metadata
    assert meta["stopped"] == "target reached"
    reached = noise_summary(image.rgb, image.variance)
    assert reached.median <= 0.2 and meta["noise"]["median"] == pytest.approx(reached.median)
    assert meta["passes"] == len(passes) >= 3
    # it stopped at the first pass that met the target (after the minimum)
    assert all(r is None or r.median > 0.2 for n, r in passes[2:-1])
    assert meta["seed_offset"] == PROGRESSIVE_SEED_OFFSET


@pytest.mark.slow  # 17 s; the stopping rules are checked in the fast tier below
def test_tighter_target_takes_more_passes_and_p99_target_counts():
    loose = render_to_target(_scene(), target_rse=0.2, spp=1, min_passes=2, cache=False,
                             progress=False)
    tight = render_to_target(_scene(), target_rse=0.2, target_p99_rse=0.1, spp=1,
                             min_passes=2, cache=False, progress=False)
    assert tight.metadata["passes"] > loose.metadata["passes"]
    assert tight.metadata["noise"]["p99"] <= 0.1


def test_budget_and_max_passes_stop_it_and_say_so():
    spent = render_to_target(_scene(), target_rse=1e-6, spp=1, min_passes=2,
                             budget_seconds=1e-3, cache=False, progress=False)
    assert spent.metadata["stopped"] == "budget spent"
    assert spent.metadata["passes"] == 2  # the variance needs two, whatever the budget
    capped = render_to_target(_scene(), target_rse=1e-6, spp=1, min_passes=2, max_passes=3,
                              cache=False, progress=False)
    assert capped.metadata["stopped"] == "max passes" and capped.metadata["passes"] == 3


def test_an_interrupted_render_resumes_from_its_passes():
    scene = _scene(0.6)
    first = render_to_target(scene, target_rse=1e-6, spp=1, min_passes=2, max_passes=3,
                             progress=False)
    counted = []
    second = render_to_target(scene, target_rse=1e-6, spp=1, min_passes=2, max_passes=5,
                              progress=False, on_pass=lambda n, s, r: counted.append(n))
    assert counted == [4, 5]  # passes 1-3 came from the saved state
    assert second.metadata["passes"] == 5
    # the same image as five passes rendered in one go
    fresh = render_to_target(scene, target_rse=1e-6, spp=1, min_passes=2, max_passes=5,
                             progress=False, cache=False)
    np.testing.assert_allclose(second.rgb, fresh.rgb, rtol=1e-6)
    assert first.metadata["passes"] == 3


def test_progressive_and_fixed_pass_renders_are_independent_and_consistent():
    scene = _scene()
    progressive = render_to_target(scene, target_rse=0.05, spp=4, min_passes=8,
                                   cache=False, progress=False)
    fixed = render(scene, spp=4, passes=8, cache=False, progress=False)
    assert not np.array_equal(progressive.rgb, fixed.rgb)  # other seeds
    assert z_test_known_variance(progressive, fixed).passed


@pytest.mark.parametrize("arguments, field", [
    ({"target_rse": 0.0}, "target_rse"),
    ({"target_rse": 1.0}, "target_rse"),
    ({"target_rse": float("nan")}, "target_rse"),
    ({"target_rse": 0.1, "target_p99_rse": 2.0}, "target_p99_rse"),
    ({"target_rse": 0.1, "budget_seconds": -1.0}, "budget_seconds"),
    ({"target_rse": 0.1, "budget_seconds": 0.0}, "budget_seconds"),
    ({"target_rse": 0.1, "min_passes": 1}, "min_passes"),
    ({"target_rse": 0.1, "min_passes": 4, "max_passes": 3}, "max_passes"),
    ({"target_rse": 0.1, "seed": 2**15}, "seed"),
    ({"target_rse": 0.1, "mask": np.ones((3, 3), bool)}, "mask"),
])
def test_bad_settings_are_input_errors(arguments, field):
    with pytest.raises(InputError) as caught:
        render_to_target(_scene(), cache=False, progress=False, **arguments)
    assert caught.value.field == field


def test_check_noise_target_names_the_options():
    assert check_noise_target(0.01, None, None) == (0.01, None, None)
    with pytest.raises(InputError, match="--target-rse"):
        check_noise_target(1.5)
    with pytest.raises(InputError, match="--budget"):
        check_noise_target(0.1, None, float("inf"))


def test_render_command_target_rse(tmp_path, capsys):
    scene_file = tmp_path / "ball.toml"
    scene_file.write_text(BALL_TOML)
    out = tmp_path / "ball.exr"
    assert main(["render", str(scene_file), "--target-rse", "0.2", "--spp", "2",
                 "--budget", "60", "--no-progress", "-o", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "target reached" in printed and "relative standard error median" in printed
    meta = read_exr(out).metadata
    assert meta["stopped"] == "target reached" and meta["target_rse"] == 0.2
    assert meta["budget_seconds"] == 60.0


@pytest.mark.parametrize("arguments, field", [
    (["--target-rse", "0"], "--target-rse"),
    (["--target-rse", "1"], "--target-rse"),
    (["--target-rse", "0.1", "--budget", "-5"], "--budget"),
    (["--target-rse", "0.1", "--target-p99", "3"], "--target-p99"),
    (["--budget", "5"], "--budget"),
    (["--target-p99", "0.1"], "--target-p99"),
    (["--target-rse", "0.1", "--passes", "8"], "--passes"),
])
def test_render_command_refuses_bad_targets(tmp_path, capsys, arguments, field):
    scene_file = tmp_path / "ball.toml"
    scene_file.write_text(BALL_TOML)
    out = tmp_path / "x" / "ball.exr"
    assert main(["render", str(scene_file), "-o", str(out), *arguments]) == 2
    assert field in capsys.readouterr().err
    assert not (tmp_path / "x").exists()


def test_render_command_warns_about_a_noisy_reference(tmp_path, capsys):
    scene_file = tmp_path / "ball.toml"
    scene_file.write_text(BALL_TOML)
    assert main(["render", str(scene_file), "--spp", "1", "--passes", "2", "--no-progress",
                 "-o", str(tmp_path / "b.exr")]) == 0
    err = capsys.readouterr().err
    assert "warning: the reference is noisy" in err and "cannot be resolved" in err


BALL_TOML = """
[scene]
name = "ball"
mm_per_unit = 10.0

[camera]
origin = [0.0, 0.0, 4.0]
target = [0.0, 0.0, 0.0]
fov = 40.0
width = 16
height = 16

[[objects]]
name = "ball"
mesh = { type = "icosphere", subdivisions = 2, radius = 1.0 }
material = { type = "lambertian", albedo = 0.5 }

[[lights]]
type = "sphere"
center = [2.0, 2.0, 2.0]
radius = 1.0
radiance = 5.0
"""


def _entry(scene, spp=2, passes=2):
    from translucent.cache import Cache
    from translucent.reference.render import reference_key, reference_settings

    settings = reference_settings(spp=spp, passes=passes, seed=0, integrator=None,
                                  max_depth=None, rr_depth=None, per_channel=None,
                                  substitute_delta_lights=None, delta_light_size=0.1)
    return Cache("reference").path(reference_key(scene, settings), ".exr")


def test_a_cache_entry_of_another_size_or_with_changed_pixels_is_rendered_again(tmp_path):
    import OpenEXR
    from translucent.image import Image

    scene = _scene(0.35)
    first = render(scene, spp=2, passes=2, progress=False)
    path = _entry(scene)
    assert path.is_file()
    Image(np.ones((4, 4, 3)), np.ones((4, 4, 3)), first.metadata).write(path)
    again = render(scene, spp=2, passes=2, progress=False)
    assert again.shape == (SIZE, SIZE)
    np.testing.assert_array_equal(again.rgb, first.rgb)  # rendered again, same seeds
    # pixels zeroed behind the header's back: the checksum refuses the entry
    with OpenEXR.File(str(path), separate_channels=True) as exr:
        header = dict(exr.header())
        channels = {name: np.array(ch.pixels) for name, ch in exr.channels().items()}
    channels["R"][:] = 0.0
    with OpenEXR.File(header, channels) as exr:
        exr.write(str(path))
    served = render(scene, spp=2, passes=2, progress=False)
    np.testing.assert_array_equal(served.rgb, first.rgb)


def test_a_render_with_nan_pixels_is_refused_and_not_cached(monkeypatch):
    import importlib

    render_module = importlib.import_module("translucent.reference.render")
    scene = _scene(0.45)
    monkeypatch.setattr(render_module, "render_sample",
                        lambda *args, **kwargs: np.full((SIZE, SIZE, 3), np.nan))
    with pytest.raises(InputError, match="NaN or Inf pixel channels"):
        render(scene, spp=2, passes=2, progress=False)
    assert not _entry(scene).is_file()
    with pytest.raises(InputError, match="NaN or Inf pixel channels"):
        render_to_target(scene, target_rse=0.1, spp=1, min_passes=2, max_passes=2,
                         progress=False)
