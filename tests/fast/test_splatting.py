"""Multiresolution splatting (Chen et al. 2012): kernels on synthetic G-buffers, then scenes."""

import math

import numba
import numpy as np
import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st
from translucent.errors import InputError
from translucent.fast import splatting
from translucent.fast.base import StageLog
from translucent.fast.splatting import (
    CameraModel,
    SurfaceBuffer,
    bilateral_upsample,
    buffer_kernels,
    gather_frame,
    irradiance_mipmap,
    light_view,
    median_depth_mipmap,
    minimal_rendering_radius_table,
    select_irradiance_samples,
    splat_frame,
)
from translucent.fast.splatting import backend_numba as kernels
from translucent.fast.splatting.backend_numba import exp32
from translucent.materials import measured_medium
from translucent.materials.subedit import SubEditProfiles, builtin_subedit, subedit_from_dipole
from translucent.scenes import Camera, DirectionalLight, PointLight, load_scene
from translucent.scenes.scene_file import CATALOGUE_DIR

#: The method splats each profile only up to its effective range (95 % of the energy,
#: Eq. 11 and 13), so it may lose up to 5 % against the full-support ground truth; 1 %
#: more covers the discretisation of the splat discs and the bilateral upsampling.
SPLAT_TOLERANCE = 0.06
#: numpy (float64 accumulation) and Dr.Jit (float32 scatter-add) kernels: float32 sums of
#: ~1e4 terms agree to ~1e-5 relative.
BACKEND_RTOL = 1e-4
#: The two paths of the splat kernel add the same float32 terms, fused into multiply-adds in
#: different places: the log-value (|ln P| < 30 in the tests) moves by a few roundings of
#: 30 * 2^-24 = 1.8e-6, and the exponential carries that relative error into the value.
TWO_SEGMENT_RTOL = 1e-5
#: Cephes' expf polynomial is accurate to about one float32 ulp (6e-8); two ulps of margin
#: cover the rounding of the argument reduction.
EXP32_RTOL = 2e-7
#: Mitsuba intersects in float32 (relative error ~1e-7 of distances of order 5 scene units),
#: amplified by 1/cos of the incidence angle, up to ~100 at the silhouettes of these
#: buffers: 5e-5; then it interpolates in float64. The rasteriser works in float64.
RAYCAST_ATOL = 1e-4
#: Frames from rasterised and from ray-traced buffers may differ by at most this share of
#: the method's own error against brute force.
BUFFER_SHARE = 0.1
#: Scene units to mm in the synthetic tests: a 2 x 2 plane is 40 mm across.
MM_PER_UNIT = 20.0


# ---------------------------------------------------------------------------- synthetic
def plane_camera_buffer(camera, *, half=1.0, step_at=None, step_height=0.0):
    """Analytic G-buffer of the plane z = 0 (|x|, |y| <= half) seen by a pinhole camera.

    With ``step_at``, the half x > step_at is lifted to z = step_height (a depth step).
    """
    model = CameraModel.from_camera(camera)
    focal = camera.width / (2 * model.tan_half_fov)
    xs = (np.arange(camera.width) + 0.5 - camera.width / 2) / focal
    ys = -(np.arange(camera.height) + 0.5 - camera.height / 2) / focal
    directions = model.forward + xs[None, :, None] * model.right + ys[:, None, None] * model.up
    height = np.zeros(directions.shape[:2])
    t = (height - model.origin[2]) / directions[..., 2]
    points = model.origin + t[..., None] * directions
    if step_at is not None:
        lifted = points[..., 0] > step_at
        t = np.where(lifted, (step_height - model.origin[2]) / directions[..., 2], t)
        points = model.origin + t[..., None] * directions
    valid = (np.abs(points[..., 0]) <= half) & (np.abs(points[..., 1]) <= half) & (t > 0)
    normal = np.broadcast_to([0.0, 0.0, 1.0], points.shape)
    uv = (points[..., :2] / half + 1) / 2
    depth = (points - model.origin) @ model.forward
    footprint = depth * 2 * model.tan_half_fov / camera.width
    return SurfaceBuffer(points, normal, uv, depth, valid, footprint), model


def plane_light_buffer(resolution, *, half=1.0, step_at=None, step_height=0.0):
    """Orthographic G-buffer of the same plane seen from straight above."""
    centres = (np.arange(resolution) + 0.5) / resolution * 2 * half - half
    x, y = np.meshgrid(centres, -centres)
    z = np.zeros_like(x) if step_at is None else np.where(x > step_at, step_height, 0.0)
    points = np.stack([x, y, z], -1)
    normal = np.broadcast_to([0.0, 0.0, 1.0], points.shape)
    uv = (points[..., :2] / half + 1) / 2
    return SurfaceBuffer(points, normal, uv, 5.0 - z, np.ones(x.shape, bool),
                         np.full(x.shape, 2 * half / resolution))


def small_setup(material=None, *, width=48, resolution=32, **plane):
    camera = Camera(origin=[0, 0, 3.0], target=[0, 0, 0], fov=45, width=width,
                    height=width * 3 // 4)
    buffer, model = plane_camera_buffer(camera, **plane)
    material = material if material is not None else builtin_subedit("checker", resolution=16)
    view = light_view(plane_light_buffer(resolution, **plane), np.array([0, 0, 1.0]),
                      np.ones(3), material.eta)
    return buffer, model, view, material


def relative_error(test, reference):
    return float(np.abs(test - reference).sum() / reference.sum())


@pytest.fixture(scope="module")
def checker_setup():
    return small_setup()


@pytest.fixture(scope="module")
def checker_truth(checker_setup):
    buffer, model, view, material = checker_setup
    return gather_frame(buffer, model, [view], material, mm_per_unit=MM_PER_UNIT)


ABLATION = {
    "no acceleration": dict(multiresolution=False, adaptive=False),
    "multiresolution only": dict(multiresolution=True, adaptive=False),
    "adaptive only": dict(multiresolution=False, adaptive=True),
    "both": dict(multiresolution=True, adaptive=True),
}


@pytest.mark.parametrize("setting", sorted(ABLATION))
def test_every_ablation_setting_matches_brute_force(setting, checker_setup, checker_truth):
    buffer, model, view, material = checker_setup
    image = splat_frame(buffer, model, [view], material, mm_per_unit=MM_PER_UNIT,
                        sphere_radius=math.sqrt(2), knobs=ABLATION[setting])
    assert np.all(np.isfinite(image))
    assert relative_error(image, checker_truth) < SPLAT_TOLERANCE


@pytest.mark.parametrize("backend", ["numba", "drjit"])
@pytest.mark.parametrize("plane", [{}, {"step_at": 0.0, "step_height": 0.8}],
                         ids=["flat", "depth step"])
def test_compiled_kernels_agree_with_numpy(backend, plane):
    # the depth step makes the numba kernel skip whole blocks by their bounding boxes
    buffer, model, view, material = small_setup(**plane)
    images = [splat_frame(buffer, model, [view], material, mm_per_unit=MM_PER_UNIT,
                          sphere_radius=math.sqrt(2), knobs={"backend": name})
              for name in ("numpy", backend)]
    assert np.allclose(images[0], images[1], rtol=BACKEND_RTOL, atol=BACKEND_RTOL * images[0].max())


def test_compiled_brute_force_agrees_with_numpy(checker_setup):
    buffer, model, view, material = checker_setup
    samples = splatting.IrradianceSamples(
        view.buffer.position.reshape(-1, 3), material.texel_index(view.buffer.uv).reshape(-1),
        view.flux.reshape(-1, 3), np.zeros(view.buffer.valid.size, np.int64))
    exitance = [splatting.brute_force_exitance(samples, buffer, material,
                                               mm_per_unit=MM_PER_UNIT, backend=name)
                for name in ("numpy", "numba")]
    assert np.allclose(exitance[0], exitance[1], rtol=BACKEND_RTOL,
                       atol=BACKEND_RTOL * exitance[0].max())


@settings(max_examples=20, deadline=None)
@given(st.integers(min_value=1, max_value=21), st.integers(min_value=1, max_value=21),
       st.integers(min_value=0, max_value=2**31 - 1))
def test_tile_layout_round_trips_and_bounds_the_valid_points(height, width, seed):
    # sizes that are not multiples of the tile pad with invalid pixels
    rng = np.random.default_rng(seed)
    position = rng.normal(size=(3, height, width)).astype(np.float32)
    valid = rng.random((height, width)) > 0.3
    texel = rng.integers(0, 50, (height, width))
    tiled, labels, bounds, tiles_y, tiles_x = kernels.tile_layout(position, texel, valid)
    assert np.array_equal(kernels.untile(tiled, tiles_y, tiles_x, height, width),
                          np.moveaxis(position, 0, -1))
    widened = kernels.untile_float64(tiled, tiles_x, height, width)
    assert widened.dtype == np.float64
    assert np.array_equal(widened, np.moveaxis(position, 0, -1))
    values = kernels.untile(np.repeat(labels[:, None, :], 3, axis=1), tiles_y, tiles_x,
                            height, width)[..., 0]
    assert np.array_equal(values, np.where(valid, texel, -1))
    assert (labels >= 0).sum() == valid.sum()
    inside = labels >= 0
    for tile in range(tiles_y * tiles_x):
        points = tiled[tile][:, inside[tile]]
        if points.size:
            assert np.all(points.min(axis=1) == bounds[tile, :3])
            assert np.all(points.max(axis=1) == bounds[tile, 3:])
        else:
            assert np.all(np.isinf(bounds[tile]))


#: Relative rounding of a float32 distance (a few units in the last place).
FLOAT32_EDGE = 8 * 2.0**-24


@settings(max_examples=15, deadline=None)
@given(st.integers(min_value=5, max_value=40), st.floats(min_value=0.05, max_value=1.5),
       st.floats(min_value=0.0, max_value=0.9))
@example(34, 1.2508387090723545, 0.5)  # a pixel 4e-8 inside the outer edge
def test_tiled_splat_equals_numpy_for_any_level_size_and_range(width, reach, inner):
    # the numpy kernel visits plain discs: any pixel the tiles' binning or culling lost, or
    # counted twice, shows as a difference
    buffer, model, view, material = small_setup(width=width, resolution=12)
    rows, cols = np.nonzero(view.buffer.valid)
    samples = splatting.IrradianceSamples(view.buffer.position[rows, cols],
                                          material.texel_index(view.buffer.uv[rows, cols]),
                                          view.flux[rows, cols], np.zeros(len(rows), np.int64))
    texel = material.texel_index(buffer.uv)

    def splat(backend, widen=0.0):
        low = np.full(len(samples), inner * reach * (1.0 - widen))
        high = np.full(len(samples), reach * (1.0 + widen))
        return splatting.splat_level(samples, low, high, buffer, texel, material, model,
                                     mm_per_unit=MM_PER_UNIT, backend=backend)

    tiled = splat("numba")
    # a pair whose distance lies within float32's rounding of a range's edge may fall on
    # either side in the float32 kernel: it lies between the numpy splats of the range
    # narrowed and widened by that rounding (contributions are >= 0)
    narrow, wide = splat("numpy", -FLOAT32_EDGE), splat("numpy", FLOAT32_EDGE)
    atol = BACKEND_RTOL * wide.max()
    assert np.all(tiled >= narrow * (1.0 - BACKEND_RTOL) - atol)
    assert np.all(tiled <= wide * (1.0 + BACKEND_RTOL) + atol)
    # and away from such ties the two agree
    if np.allclose(narrow, wide, rtol=0.0, atol=0.0):
        assert np.allclose(tiled, wide, rtol=BACKEND_RTOL, atol=atol)


def two_segment_case(seed, pitch, narrow_share):
    """A jittered plane of 16 x 24 pixels, a random table, samples on the plane.

    A ``narrow_share`` of the samples have annuli 1.5 segments wide from their own point
    (every pixel in range lies in segment 0 or 1: the two-segment path); the others 6 to 12
    segments wide from a random inner radius (the general path).
    """
    rng = np.random.default_rng(seed)
    segments, r_s, texels = 8, 1.0, 7
    rows, cols = np.mgrid[0:16, 0:24] * pitch
    position = np.stack([cols, rows, rng.normal(scale=0.1 * pitch, size=cols.shape)])
    valid = rng.random(cols.shape) > 0.1
    tiled, labels, bounds, tiles_y, tiles_x = kernels.tile_layout(
        position.astype(np.float32), rng.integers(0, texels, cols.shape), valid)
    table = kernels.segment_table(rng.uniform(-20.0, 2.0, (texels, segments + 1, 3)))
    step_inverse = np.float32(segments / r_s)
    count = 40
    pick = rng.integers(0, cols.size, count)
    sample_position = np.ascontiguousarray(position.reshape(3, -1)[:, pick], np.float32)
    narrow = rng.random(count) < narrow_share
    low = np.where(narrow, 0.0, rng.uniform(0.0, 3.0, count) / step_inverse)
    high = low + np.where(narrow, 1.5, rng.uniform(6.0, 12.0, count)) / step_inverse
    low2, high2 = (np.square(bound).astype(np.float32) for bound in (low, high))
    # every sample's window (centre 12, 8; radius 20 pixels) covers the level, so only the
    # tiles' bounding boxes cull
    start, members = kernels.bin_samples(
        bounds, tiles_y, tiles_x, sample_position, np.full(count, 12.0, np.float32),
        np.full(count, 8.0, np.float32), np.full(count, 20.0, np.float32), low2, high2)
    arguments = (tiled, labels, table, step_inverse, sample_position,
                 rng.integers(0, texels, count).astype(np.int32),
                 rng.uniform(0.1, 2.0, (count, 3)).astype(np.float32), low2, high2, start,
                 members)
    return arguments, narrow


@settings(max_examples=15, deadline=None)
@given(st.integers(min_value=0, max_value=2**31 - 1), st.floats(min_value=0.002, max_value=0.02),
       st.floats(min_value=0.3, max_value=1.0))
def test_two_segment_path_equals_the_general_path(seed, pitch, narrow_share):
    arguments, narrow = two_segment_case(seed, pitch, narrow_share)
    out = [np.empty(arguments[0].shape, np.float32) for _ in range(2)]
    used = [kernels.splat_tiles(out[0], *arguments),
            kernels.splat_tiles(out[1], *arguments, np.float32(0.0))]  # general path only
    assert np.array_equal(used[0], used[1])
    assert np.allclose(out[0], out[1], rtol=TWO_SEGMENT_RTOL, atol=TWO_SEGMENT_RTOL * out[1].max())
    # the case does take the two-segment path: some narrow sample has enough pixels in
    # range in one tile
    tiled, labels, _, _, sample_position, _, _, _, high2, start, members = arguments
    fewest = max(kernels.FEWEST_IN_VECTORS, 1)
    reached = [
        np.sum((labels[tile] >= 0) & (np.sum(np.square(
            tiled[tile] - sample_position[:, s, None]), axis=0) < high2[s])) >= fewest
        for tile in range(len(start) - 1) for s in members[start[tile]:start[tile + 1]]
        if narrow[s]]
    assert any(reached)


def test_two_segment_path_leaves_unreached_pixels_black():
    # lanes out of range are evaluated in the vectors too, then masked to exactly 0
    arguments, _ = two_segment_case(3, 0.01, 1.0)
    out = np.empty(arguments[0].shape, np.float32)
    kernels.splat_tiles(out, *arguments)
    general = np.empty_like(out)
    kernels.splat_tiles(general, *arguments, np.float32(0.0))
    assert np.all(np.isfinite(out))
    assert np.array_equal(out == 0, general == 0)
    assert (out == 0).any()


def test_projection_is_the_pinhole_of_the_camera_frame():
    camera = Camera(origin=[0.3, -0.2, 3.0], target=[0, 0.1, 0], fov=40, width=64, height=48)
    model = CameraModel.from_camera(camera)
    points = np.random.default_rng(5).normal(size=(50, 3))
    x, y, z = model.project(points, 32, 24)
    relative = points - model.origin
    focal = 32 / (2 * model.tan_half_fov)
    assert np.allclose(z, relative @ model.forward, rtol=1e-12, atol=1e-12)
    assert np.allclose(x, relative @ model.right / z * focal + 16, rtol=1e-12, atol=1e-9)
    assert np.allclose(y, -(relative @ model.up) / z * focal + 12, rtol=1e-12, atol=1e-9)


@numba.njit
def exp32_of_array(x):
    out = np.empty_like(x)
    for i in range(len(x)):
        out[i] = exp32(x[i])
    return out


@settings(max_examples=50, deadline=None)
@given(st.lists(st.floats(min_value=-86.0, max_value=88.0), min_size=1, max_size=64))
def test_exp32_is_exp_to_float32_precision(values):
    x = np.asarray(values, dtype=np.float32)
    exact = np.exp(x.astype(np.float64))
    assert np.all(np.abs(exp32_of_array(x) / exact - 1.0) < EXP32_RTOL)


def test_multiresolution_moves_pairs_to_coarse_levels(checker_setup, checker_truth):
    # At 48 pixels the paper's epsilon keeps everything at level 0 (R_bar = 1 below ~60
    # pixels per range); a looser tolerance exercises the coarse levels and Eq. 17.
    buffer, model, view, material = checker_setup
    logs = {}
    for multiresolution in (False, True):
        logs[multiresolution] = StageLog()
        image = splat_frame(buffer, model, [view], material, mm_per_unit=MM_PER_UNIT,
                            sphere_radius=math.sqrt(2), log=logs[multiresolution],
                            knobs={"multiresolution": multiresolution, "epsilon": 0.05})
        assert relative_error(image, checker_truth) < SPLAT_TOLERANCE + 0.05
    single = logs[False].notes["pairs per level"]
    multiple = logs[True].notes["pairs per level"]
    assert len(single) == 1 and len(multiple) == 3
    assert multiple[0] < single[0] and sum(multiple[1:]) > 0


def test_adaptive_sampling_takes_coarse_samples_for_long_ranges():
    # ln P falling by 4 over 40 mm: R_P is about 25 mm, more than 15x the 1.25 mm texel of
    # level 1 of a 64-texel buffer over 40 mm (Eq. 11 accepts it) but less than 15x the
    # 2.5 mm of level 2 (refused): every sample comes from level 1.
    long_range = SubEditProfiles(np.tile(np.linspace(0, -4, 9)[:, None], (1, 3)), 40.0)
    buffer, model, view, material = small_setup(long_range, width=32, resolution=64)
    log = StageLog()
    truth = gather_frame(buffer, model, [view], material, mm_per_unit=MM_PER_UNIT)
    image = splat_frame(buffer, model, [view], material, mm_per_unit=MM_PER_UNIT,
                        sphere_radius=math.sqrt(2), log=log)
    assert log.notes["samples per level"] == [0, 32 * 32, 0]
    assert relative_error(image, truth) < SPLAT_TOLERANCE


def test_level_sampling_thins_coarse_levels_at_the_same_error(checker_setup, checker_truth):
    # epsilon 0.05 puts most of each range on the coarse levels (as in the test above); a
    # sample grid as fine as each level's pixels then needs fewer samples there (with a
    # grid of 2 pixels and more, this 48-pixel frame's error doubles: see the knob's doc)
    buffer, model, view, material = checker_setup
    logs = {}
    for pitch in (0.0, 1.0):
        logs[pitch] = StageLog()
        image = splat_frame(buffer, model, [view], material, mm_per_unit=MM_PER_UNIT,
                            sphere_radius=math.sqrt(2), log=logs[pitch],
                            knobs={"epsilon": 0.05, "level_sampling": pitch})
        assert relative_error(image, checker_truth) < SPLAT_TOLERANCE + 0.05
    assert "samples per splatting level" not in logs[0.0].notes
    paper = logs[0.0].notes["samples"]
    counts = logs[1.0].notes["samples per splatting level"]
    assert counts[0] == paper and counts[2] < counts[1] <= paper


def test_profile_upsampling_crosses_material_boundaries(checker_setup, checker_truth):
    # the checker's squares switch between two measured materials; coarse levels (epsilon
    # 0.05) upsampled across those switches are what the knob corrects
    buffer, model, view, material = checker_setup
    errors = [relative_error(splat_frame(buffer, model, [view], material,
                                         mm_per_unit=MM_PER_UNIT, sphere_radius=math.sqrt(2),
                                         knobs={"epsilon": 0.05, "profile_upsampling": on}),
                             checker_truth) for on in (False, True)]
    assert errors[1] < errors[0]


def test_profile_upsampling_is_eq17_for_a_homogeneous_material():
    homogeneous = subedit_from_dipole(measured_medium("Ketchup"), segments=16).profiles
    buffer, model, view, material = small_setup(homogeneous)
    images = [splat_frame(buffer, model, [view], material, mm_per_unit=MM_PER_UNIT,
                          sphere_radius=math.sqrt(2),
                          knobs={"epsilon": 0.05, "profile_upsampling": on})
              for on in (False, True)]
    # the factors are one value per channel, divided out and multiplied back in float64
    assert np.allclose(images[0], images[1], rtol=1e-12, atol=0)
    factors = splatting.upsampling_profile_factors(material, 0.3)
    assert factors.shape == (material.texel_count, 3) and np.all(factors == factors[0])


@pytest.mark.parametrize("inner", [0.0, 0.5, 1.0, 2.0, np.nan])
def test_upsampling_profile_factors_are_positive_and_finite(inner):
    factors = splatting.upsampling_profile_factors(builtin_subedit("checker", resolution=8),
                                                   inner)
    assert np.all(np.isfinite(factors)) and np.all(factors > 0)
    assert len(np.unique(factors[:, 0])) == 2  # the checker's two materials


#: The factors' Gauss-Legendre integral against a 4001-point trapezoid rule of the same
#: integrand, as a ratio between texels (what the upsampling uses), from an inner edge of
#: 0.1 (measured up to 3e-4; 1.6 % from 0, where the integrand is steepest).
FACTOR_TOLERANCE = 2e-3


@pytest.mark.parametrize("inner", [0.1, 0.4, 0.8])
def test_upsampling_factors_are_each_texels_exitance_under_the_mean_profile(inner):
    material = builtin_subedit("veined_marble", resolution=16)
    factors = splatting.upsampling_profile_factors(material, inner)
    typical = float(np.median(material.effective_scattering_range))
    texels = np.arange(material.texel_count)
    u = np.linspace(inner, 1.0, 4001)
    values = np.stack([material.profile(x * typical, texels) for x in u])  # (U, T, 3)
    integrand = np.sqrt(values * values.mean(axis=1, keepdims=True)) * u[:, None, None]
    expected = np.trapezoid(integrand, u, axis=0)
    ratio = factors / expected
    assert np.all(np.abs(ratio / ratio.mean(axis=0) - 1) < FACTOR_TOLERANCE)


def test_level_sample_masks_keep_every_selection_a_partition():
    buffer, model, view, material = small_setup(width=64, resolution=32)
    pyramid = irradiance_mipmap(view.buffer, view.flux, view.cosine, 3)
    for level, pitch in ((1, 1.0), (2, 1.0), (2, 8.0)):
        masks = splatting.level_sample_masks(pyramid, model, level, pitch)
        samples = select_irradiance_samples(pyramid, material, mm_per_unit=MM_PER_UNIT,
                                            z0=0.03, alpha=15.0, coarse_enough=masks)
        # Algorithm 1 with a looser rate test still covers each texel once
        assert np.allclose(samples.flux.sum(axis=0), view.flux.sum(axis=(0, 1)))
    # 8 level-2 pixels are coarser than every texel of this 32-texel buffer (a 2 x 2 plane
    # seen from 3 units at 64 pixels across 45 degrees: 0.26 units vs 0.25 at level 2)
    assert np.all(masks[2][pyramid[2].valid])


def test_sample_selector_ids_name_the_same_samples_over_several_lights():
    buffer, model, view, material = small_setup(width=64, resolution=32)
    other = light_view(plane_light_buffer(16), np.array([0.6, 0, 0.8]), np.full(3, 2.0),
                       material.eta)
    pyramids = [irradiance_mipmap(v.buffer, v.flux, v.cosine, 3) for v in (view, other)]
    knobs = dict(mm_per_unit=MM_PER_UNIT, z0=0.03, alpha=15.0)
    selector = splatting.SampleSelector(pyramids, material, **knobs)
    for level, pitch in ((None, None), (1, 1.0), (2, 8.0)):
        coarse = None if level is None else selector.level_masks(model, level, pitch)
        ids = selector.select(coarse)
        assert len(np.unique(ids)) == len(ids) and ids.max() < selector.size
        together = selector.samples(ids)
        # light by light, the samples (and their order) of one pyramid selected alone
        alone = splatting.IrradianceSamples.concatenate(
            select_irradiance_samples(
                pyramid, material, **knobs,
                coarse_enough=None if level is None
                else splatting.level_sample_masks(pyramid, model, level, pitch))
            for pyramid in pyramids)
        for name in ("position", "texel", "flux", "level"):
            assert np.array_equal(getattr(together, name), getattr(alone, name))
        assert np.allclose(together.flux.sum(axis=0),
                           view.flux.sum(axis=(0, 1)) + other.flux.sum(axis=(0, 1)))


# ---------------------------------------------------------------------------- mipmaps
def test_irradiance_mipmap_conserves_flux_and_bounds_depth(rng):
    buffer = plane_light_buffer(13)  # odd size: padding with invalid texels
    valid = rng.random(buffer.shape) > 0.3
    depth = rng.random(buffer.shape)
    buffer = SurfaceBuffer(buffer.position, buffer.normal, buffer.uv, depth, valid,
                           buffer.footprint)
    flux = rng.random(buffer.shape + (3,))
    pyramid = irradiance_mipmap(buffer, flux, np.ones(buffer.shape), 3)
    total = np.where(valid[..., None], flux, 0).sum(axis=(0, 1))
    for level in pyramid:
        assert np.allclose(level.flux.sum(axis=(0, 1)), total)
    level1 = pyramid[1]
    block = depth[0:2, 2:4][valid[0:2, 2:4]]
    if block.size:
        assert level1.depth_min[0, 1] == block.min() and level1.depth_max[0, 1] == block.max()
    assert level1.valid[0, 1] == valid[0:2, 2:4].any()


def test_irradiance_level_reads_non_finite_inputs_as_nan_to_num(rng):
    shape = (9, 7)
    valid = rng.random(shape) > 0.3
    arrays = [rng.normal(size=shape + (3,)), rng.normal(size=shape + (3,)),
              rng.random(shape + (2,)), rng.random(shape), rng.random(shape),
              rng.random(shape + (3,))]
    for array in arrays:
        flat = array.reshape(-1)
        flat[rng.random(flat.size) < 0.1] = np.nan
        flat[rng.random(flat.size) < 0.05] = np.inf
        flat[rng.random(flat.size) < 0.05] = -np.inf
    depth = rng.random(shape)
    bounds = (np.where(valid, depth, np.inf), np.where(valid, depth, -np.inf), valid)
    raw = buffer_kernels.irradiance_level(*arrays, *bounds)
    cleaned = buffer_kernels.irradiance_level(*(np.nan_to_num(array) for array in arrays), *bounds)
    for a, b in zip(raw, cleaned, strict=True):
        assert np.array_equal(a, b)


def test_median_depth_mipmap_copies_the_median_texel():
    depth = np.array([[1.0, 5.0], [3.0, 9.0]])
    valid = np.array([[True, True], [True, False]])
    position = np.stack([depth, depth * 2, depth * 3], -1)
    buffer = SurfaceBuffer(position, np.zeros((2, 2, 3)), np.zeros((2, 2, 2)), depth, valid,
                           np.ones((2, 2)))
    coarse = median_depth_mipmap(buffer, 2)[1]
    assert coarse.depth[0, 0] == 3.0 and coarse.valid[0, 0]
    assert np.allclose(coarse.position[0, 0], [3.0, 6.0, 9.0])
    empty = SurfaceBuffer(position, np.zeros((2, 2, 3)), np.zeros((2, 2, 2)), depth,
                          np.zeros((2, 2), bool), np.ones((2, 2)))
    assert not median_depth_mipmap(empty, 2)[1].valid.any()


# ---------------------------------------------------------------------------- selection
@settings(max_examples=25, deadline=None)
@given(st.floats(min_value=0.2, max_value=60.0), st.floats(min_value=0.0, max_value=0.5),
       st.integers(min_value=1, max_value=4))
def test_selection_covers_every_texel_once(range_mm, step_height, levels):
    material = subedit_from_dipole(measured_medium("Marble"), segments=8,
                                   r_s=range_mm * 3).profiles
    buffer = plane_light_buffer(24, step_at=0.1, step_height=step_height)
    view = light_view(buffer, np.array([0, 0, 1.0]), np.ones(3), material.eta)
    pyramid = irradiance_mipmap(view.buffer, view.flux, view.cosine, levels)
    samples = select_irradiance_samples(pyramid, material, mm_per_unit=MM_PER_UNIT,
                                        z0=0.03, alpha=15.0)
    # Algorithm 1: no texel is counted twice or dropped, so the flux is conserved
    assert np.allclose(samples.flux.sum(axis=0), view.flux.sum(axis=(0, 1)))
    if step_height > 0.03 and levels > 1:
        # a depth discontinuity larger than z0 is sampled at the finest level
        near_step = np.abs(samples.position[:, 0] - 0.1) < 2.0 / 24
        assert np.all(samples.level[near_step] == 0)


def test_selection_without_adaptive_takes_all_finest_texels():
    material = builtin_subedit("wax_gradient", resolution=8)
    view = light_view(plane_light_buffer(16), np.array([0, 0, 1.0]), np.ones(3), material.eta)
    pyramid = irradiance_mipmap(view.buffer, view.flux, view.cosine, 1)
    samples = select_irradiance_samples(pyramid, material, mm_per_unit=MM_PER_UNIT,
                                        z0=0.03, alpha=15.0, adaptive=False)
    assert len(samples) == 16 * 16 and np.all(samples.level == 0)


# ---------------------------------------------------------------------------- Eq. 14 table
@settings(max_examples=20, deadline=None)
@given(st.floats(min_value=0.5, max_value=20.0))
def test_rendering_radius_table_is_monotone(decay):
    norm = (1 - math.exp(-decay) * (1 + decay)) / decay**2

    def mean_profile(r):
        return np.exp(-decay * np.asarray(r)) / norm  # int_0^1 P r dr = 1

    table = minimal_rendering_radius_table(mean_profile, 0.001)
    assert np.all(np.diff(table.radii) <= 0)
    assert np.all((table.radii >= 0) & (table.radii <= 1))
    # half a pixel across the range renders only the faint outer tail
    assert table.radii[0] > 0.5
    assert table.radii[-1] < table.radii[0]
    assert np.all(np.isfinite(table([np.nan, np.inf, 0.0, -1.0])))


def test_rendering_radius_table_renders_a_linear_density_at_any_resolvable_level():
    # P(r) = 2 makes P(r) r = 2r linear: sampling each cell at its centre is exact, so every
    # level with at least MIN_LEVEL_RESOLUTION pixels across the range may render all of it
    table = minimal_rendering_radius_table(lambda r: np.full_like(r, 2.0), 0.001)
    resolvable = table.resolutions >= splatting.MIN_LEVEL_RESOLUTION
    assert np.all(table.radii[resolvable] == 0) and np.all(table.radii[~resolvable] == 1)


def test_rendering_radius_table_rejects_bad_epsilon():
    with pytest.raises(InputError, match="epsilon = 0: must be > 0"):
        minimal_rendering_radius_table(lambda r: np.ones_like(r), 0)


# ---------------------------------------------------------------------------- Eq. 17
def test_bilateral_upsampling_keeps_constants_and_respects_depth_steps():
    fine = SurfaceBuffer(np.zeros((4, 4, 3)), np.zeros((4, 4, 3)), np.zeros((4, 4, 2)),
                         np.where(np.arange(4)[None, :] < 2, 1.0, 9.0) * np.ones((4, 1)),
                         np.ones((4, 4), bool), np.ones((4, 4)))
    coarse = median_depth_mipmap(fine, 2)[1]
    ranges = np.ones((4, 4))
    constant = bilateral_upsample(np.full((2, 2, 3), 2.5), coarse, np.ones((2, 2)), fine,
                                  ranges, scene_diameter=1.0)
    assert np.allclose(constant, 2.5)
    values = np.zeros((2, 2, 3))
    values[:, 1] = 7.0  # the far (depth 9) half
    upsampled = bilateral_upsample(values, coarse, np.ones((2, 2)), fine, ranges,
                                   scene_diameter=1.0)
    # lambda_z = 8 over a depth step of 8 R_w: the near half sees almost none of the far
    assert upsampled[:, 1].max() < 1e-10 and np.allclose(upsampled[:, 2], 7.0)


# ---------------------------------------------------------------------------- stability
@pytest.mark.parametrize("r_s", [1e-4, 1e4])
def test_profile_ranges_far_below_a_pixel_to_the_whole_object(r_s):
    tiny_or_huge = SubEditProfiles(np.tile(np.linspace(0, -8, 9)[:, None], (1, 3)), r_s)
    buffer, model, view, material = small_setup(tiny_or_huge)
    truth = gather_frame(buffer, model, [view], material, mm_per_unit=MM_PER_UNIT)
    image = splat_frame(buffer, model, [view], material, mm_per_unit=MM_PER_UNIT,
                        sphere_radius=math.sqrt(2))
    assert np.all(np.isfinite(image)) and np.all(image >= 0)
    if r_s > 1:  # the whole object is within range: same as brute force
        assert relative_error(image, truth) < SPLAT_TOLERANCE


def test_grazing_light_gives_no_flux_and_no_nan():
    buffer, model, view, material = small_setup()
    grazing = light_view(view.buffer, np.array([1.0, 0, 0]), np.ones(3), material.eta)
    assert np.all(grazing.flux == 0)
    image = splat_frame(buffer, model, [grazing], material, mm_per_unit=MM_PER_UNIT,
                        sphere_radius=math.sqrt(2))
    assert np.all(image == 0)


def test_depth_discontinuity_renders_finite(rng):
    buffer, model, view, material = small_setup(step_at=0.0, step_height=0.8)
    image = splat_frame(buffer, model, [view], material, mm_per_unit=MM_PER_UNIT,
                        sphere_radius=math.sqrt(2))
    truth = gather_frame(buffer, model, [view], material, mm_per_unit=MM_PER_UNIT)
    assert np.all(np.isfinite(image))
    assert relative_error(image, truth) < SPLAT_TOLERANCE


def test_empty_buffers_give_black_images():
    buffer, model, view, material = small_setup()
    empty_camera = SurfaceBuffer(buffer.position, buffer.normal, buffer.uv, buffer.depth,
                                 np.zeros(buffer.shape, bool), buffer.footprint)
    image = splat_frame(empty_camera, model, [view], material, mm_per_unit=MM_PER_UNIT,
                        sphere_radius=math.sqrt(2))
    assert image.shape == buffer.shape + (3,) and np.all(image == 0)
    dark = light_view(SurfaceBuffer(view.buffer.position, view.buffer.normal, view.buffer.uv,
                                    view.buffer.depth, np.zeros(view.buffer.shape, bool),
                                    view.buffer.footprint), np.array([0, 0, 1.0]),
                      np.ones(3), material.eta)
    assert np.all(splat_frame(buffer, model, [dark], material, mm_per_unit=MM_PER_UNIT,
                              sphere_radius=math.sqrt(2)) == 0)


# ---------------------------------------------------------------------------- scenes
@pytest.fixture(scope="module")
def heterogeneous_scene():
    scene = load_scene(CATALOGUE_DIR / "heterogeneous.toml")
    return scene.with_camera(Camera(scene.camera.origin, scene.camera.target, scene.camera.up,
                                    scene.camera.fov, 32, 24))


def test_heterogeneous_scene_against_ground_truth(heterogeneous_scene):
    state = splatting.precompute(heterogeneous_scene, irradiance_resolution=48)
    image = state.render()
    truth = state.render_ground_truth()
    assert image.metadata["producer"] == "splatting"
    assert np.all(np.isfinite(image.rgb)) and image.rgb.sum() > 0
    assert relative_error(image.rgb, truth.rgb) < SPLAT_TOLERANCE


def test_directional_light_and_relighting(heterogeneous_scene):
    state = splatting.precompute(heterogeneous_scene, irradiance_resolution=32)
    light = DirectionalLight(direction=[0, 0, -1.0], irradiance=1.0)
    image = state.render(lights=[light])
    truth = state.render_ground_truth(lights=[light])
    assert relative_error(image.rgb, truth.rgb) < SPLAT_TOLERANCE


def test_deformed_mesh_renders_without_stale_state():
    from translucent.scenes import Scene, SceneObject, geometry_image

    camera = Camera(origin=[0, 3.0, 0.5], target=[0, 0, 0], up=[0, 0, -1.0], fov=60,
                    width=24, height=24)
    material = builtin_subedit("checker", resolution=16)
    light = PointLight(position=[0.5, 3.0, 0.0], intensity=50.0)

    def sheet(bend):
        mesh = geometry_image(17, shape="sheet", bend=bend, name="sheet")
        return Scene((SceneObject("sheet", mesh, material),), (light,), camera, 20.0)

    flat, bent = sheet(0.0), sheet(120.0)
    state = splatting.precompute(flat, irradiance_resolution=32)
    before = state.render().rgb
    after = state.render(scene=bent).rgb
    fresh = splatting.precompute(bent, irradiance_resolution=32).render().rgb
    assert not np.allclose(before, after)
    assert np.array_equal(after, fresh)
    assert np.array_equal(state.render().rgb, before)


def test_object_out_of_view_is_black(heterogeneous_scene):
    scene = heterogeneous_scene
    away = Camera(scene.camera.origin, scene.camera.origin + [0, 0, 1.0], scene.camera.up,
                  scene.camera.fov, 16, 12)
    image = splatting.precompute(scene.with_camera(away), irradiance_resolution=16).render()
    assert np.all(image.rgb == 0)
    assert any("out of view" in sentence for sentence in image.metadata["skipped"])


def test_applies_to_and_knob_errors(heterogeneous_scene):
    from translucent.scenes import ConstantEnvironment

    assert splatting.applies_to(heterogeneous_scene) is None
    sky = heterogeneous_scene.with_lights([ConstantEnvironment(1.0)])
    refusal = splatting.applies_to(sky)
    assert refusal.code == "unsupported_light"
    assert "point, spot, directional and area lights only" in str(refusal)
    with pytest.raises(InputError, match="cannot render this scene"):
        splatting.precompute(sky)
    with pytest.raises(InputError, match="area_light_points = 0: must be an integer"):
        splatting.precompute(heterogeneous_scene, area_light_points=0)
    with pytest.raises(InputError, match="unknown knob"):
        splatting.precompute(heterogeneous_scene, colour=1)
    with pytest.raises(InputError, match=r"levels = 0: must be an integer in \[1, 12\]"):
        splatting.precompute(heterogeneous_scene, levels=0)
    with pytest.raises(InputError,
                       match="backend = 'opencl': must be one of 'numba', 'cuda', 'drjit'"):
        splatting.precompute(heterogeneous_scene, backend="opencl")
    with pytest.raises(InputError, match="buffers = 'gpu': must be one of 'raster', 'mitsuba'"):
        splatting.precompute(heterogeneous_scene, buffers="gpu")
    with pytest.raises(InputError, match="sampling_range = 'red': must be one of 'shortest'"):
        splatting.precompute(heterogeneous_scene, sampling_range="red")
    with pytest.raises(InputError, match=r"level_sampling = -1: must be >= 0"):
        splatting.precompute(heterogeneous_scene, level_sampling=-1)
    # values of the wrong type are input errors too, not TypeError or ValueError
    with pytest.raises(InputError, match=r"alpha = 'many': must be a finite number"):
        splatting.precompute(heterogeneous_scene, alpha="many")
    with pytest.raises(InputError, match=r"levels = 'three': must be an integer"):
        splatting.precompute(heterogeneous_scene, levels="three")
    with pytest.raises(InputError, match=r"irradiance_resolution = inf: must be an integer"):
        splatting.precompute(heterogeneous_scene, irradiance_resolution=math.inf)
    with pytest.raises(InputError, match=r"epsilon = True: must be a finite number"):
        splatting.precompute(heterogeneous_scene, epsilon=True)


def test_approx_command_writes_an_exr(tmp_path):
    from translucent.image import read_exr
    from translucent.reports.cli import main

    out = tmp_path / "het.exr"
    code = main(["approx", "splatting", str(CATALOGUE_DIR / "heterogeneous.toml"), "--out",
                 str(out), "--irradiance-resolution", "32", "--material", "checker",
                 "--level-sampling", "1", "--no-profile-upsampling", "--epsilon", "0.002",
                 "--sampling-range", "luminance"])
    assert code == 0
    image = read_exr(out)
    assert image.metadata["producer"] == "splatting" and image.rgb.sum() > 0
    knobs = image.metadata["knobs"]
    assert knobs["level_sampling"] == 1.0 and knobs["profile_upsampling"] is False


@pytest.mark.parametrize("view", ["camera", "point light", "directional light"])
def test_rasterized_buffers_match_ray_queries(heterogeneous_scene, view):
    from translucent.scenes.gbuffer import gbuffer, gbuffer_from_point, gbuffer_orthographic

    scene = heterogeneous_scene
    mesh = scene.objects[0].mesh
    if view == "camera":
        raster = splatting.rasterize_view(scene, camera=scene.camera)
        traced = gbuffer(scene)
    elif view == "point light":
        camera = Camera([-3.0, 3.0, 4.0], [0.0, 0.0, 0.0], [0.0, 1.0, 0.0], 22.0, 40, 40)
        raster = splatting.rasterize_view(scene, camera=camera)
        traced = gbuffer_from_point(scene, camera.origin, camera.forward, camera.fov, 40)
    else:
        direction = np.array([0.3, -1.0, -0.2]) / np.linalg.norm([0.3, -1.0, -0.2])
        raster = splatting.rasterize_view(scene, direction=direction, size=40,
                                          centre=np.zeros(3), extent=1.1)
        traced = gbuffer_orthographic(scene, direction, 40, center=np.zeros(3), extent=1.1)
    ours = raster.surface(scene, 0)
    assert np.array_equal(ours.valid, traced.mask(0))
    hit = ours.valid
    assert np.allclose(ours.position[hit], traced.position[hit], atol=RAYCAST_ATOL)
    assert np.allclose(ours.normal[hit], traced.normal[hit], atol=RAYCAST_ATOL)
    assert np.allclose(ours.uv[hit], traced.interpolate(0, mesh.uv)[hit], atol=RAYCAST_ATOL)
    assert np.allclose(ours.depth[hit], traced.depth[hit], atol=RAYCAST_ATOL)


def test_raster_and_ray_query_buffers_render_alike(heterogeneous_scene):
    states = [splatting.precompute(heterogeneous_scene, irradiance_resolution=32,
                                   buffers=buffers) for buffers in ("raster", "mitsuba")]
    images = [state.render().rgb for state in states]
    truth = states[0].render_ground_truth().rgb
    # discrete choices (the median texel, a pair's level, a sample's level) may flip on the
    # 1e-6 differences of the buffers, so the frames are not equal to rounding; they must
    # differ far less than either differs from the truth
    assert relative_error(images[0], images[1]) < BUFFER_SHARE * relative_error(images[0],
                                                                                  truth)


def test_sampling_ranges_are_ordered_and_thin_the_samples():
    material = builtin_subedit("veined_marble", resolution=16)
    shortest, luminance, longest = (splatting.sampling_range(material, name)
                                    for name in splatting.SAMPLING_RANGES)
    assert np.all(shortest <= luminance + 1e-12) and np.all(luminance <= longest + 1e-12)
    view = light_view(plane_light_buffer(64), np.array([0, 0, 1.0]), np.ones(3), material.eta)
    pyramid = irradiance_mipmap(view.buffer, view.flux, view.cosine, 3)
    counts = [len(select_irradiance_samples(pyramid, material, mm_per_unit=MM_PER_UNIT,
                                            z0=0.03, alpha=15.0, sampling=name))
              for name in splatting.SAMPLING_RANGES]
    assert counts[0] >= counts[1] >= counts[2]
    with pytest.raises(InputError, match="sampling_range = 'max': must be one of"):
        splatting.sampling_range(material, "max")


#: A 1.25 mm checker of two media whose diffusion lengths differ 6.8x: the multiresolution
#: frame over the single-level one, per channel, measured 1.02 / 1.21 / 1.05 (the factors
#: of the profiles at one distance gave 1.01 / 2.23 / 1.97).
FINE_CHECKER_RATIO = 1.25


def test_a_fine_checker_of_unlike_media_keeps_its_energy_through_the_levels():
    from translucent.materials import measured_medium
    from translucent.reports.bench.heterogeneous import OBJECT, checker_scene
    from translucent.reports.bench.model_error import object_mask

    scene = checker_scene(measured_medium("Chicken1"), measured_medium("Ketchup"), 16,
                          size=32, rows=17)
    mask = object_mask(scene, OBJECT)
    levels, single = (splatting.precompute(scene, multiresolution=on).render().rgb[mask]
                      for on in (True, False))
    ratio = levels.sum(axis=0) / single.sum(axis=0)
    assert np.all(ratio < FINE_CHECKER_RATIO) and np.all(ratio > 1 / FINE_CHECKER_RATIO), ratio


@settings(max_examples=40, deadline=None)
@given(st.integers(1, 9), st.integers(1, 9), st.integers(1, 4), st.integers(0, 2**31 - 1))
def test_entry_blocks_keep_every_texels_flux_and_enter_it_at_a_valid_texel_of_its_block(
        height, width, block, seed):
    from translucent.fast.splatting.state import _entry_blocks

    rng = np.random.default_rng(seed)
    valid = rng.random((height, width)) < 0.7
    flux = rng.random((height, width, 3))
    (row, col), sums = _entry_blocks(valid, flux, block)
    assert np.allclose(sums.sum(axis=0), flux[valid].sum(axis=0))
    assert np.all(valid[row, col])
    # one texel per block that has a valid texel, and it carries that block's flux
    blocks = set(zip((row // block).tolist(), (col // block).tolist(), strict=True))
    assert len(blocks) == len(row)
    for r, c, total in zip(row, col, sums, strict=True):
        tile = np.s_[r // block * block:(r // block + 1) * block,
                     c // block * block:(c // block + 1) * block]
        assert np.allclose(total, (flux[tile] * valid[tile][..., None]).sum(axis=(0, 1)))
