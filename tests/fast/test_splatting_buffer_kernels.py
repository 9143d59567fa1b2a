"""The buffer-stage kernels of splatting (rasteriser, light views, windows) against numpy."""

import math

import numba
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from translucent.fast import splatting
from translucent.fast.splatting import (
    CameraModel,
    SurfaceBuffer,
    buffer_kernels,
    light_view,
)
from translucent.fast.splatting import backend_numba as kernels

# ------------------------------------------------------------------ buffer-stage kernels
#: Float64 round-off between a compiled kernel and the numpy formula it replaces: the
#: kernels sum a 3-vector dot product in index order where ``numpy.einsum`` pairs the
#: first and last terms, and take cos^1.5 as cos sqrt(cos) where numpy calls pow. Each
#: moves a value by a few eps (2.2e-16) of its terms' size; F_t's slope in the cosine is
#: below 4 for eta <= 2; 64 eps of the value's scale bounds the sum with margin.
ROUNDOFF = 64 * np.finfo(np.float64).eps


def _random_view(rng, height=7, width=9, eta=1.3):
    """A random irradiance-buffer-like set of pixels (unit normals, footprints, a mask)."""
    normal = rng.normal(size=(height, width, 3))
    normal /= np.linalg.norm(normal, axis=-1, keepdims=True)
    valid = rng.random((height, width)) < 0.7
    position = rng.uniform(-1.0, 1.0, (height, width, 3))
    footprint = rng.uniform(0.001, 0.1, (height, width))
    return position, normal, valid, footprint


def _numpy_flux(normal, valid, footprint, to_light, normal_irradiance, eta):
    """The numpy formula that ``light_view`` had before its compiled kernel."""
    from translucent.materials.fresnel import fresnel_transmittance

    cosine = np.abs(np.einsum("...k,...k->...", normal, np.broadcast_to(to_light,
                                                                         normal.shape)))
    cosine = np.where(valid, np.clip(np.nan_to_num(cosine), 0.0, 1.0), 0.0)
    area = np.where(valid, np.nan_to_num(footprint), 0.0)
    flux = (fresnel_transmittance(eta, cosine) * area**2)[..., None] * np.broadcast_to(
        normal_irradiance, valid.shape + (3,))
    return np.where(valid[..., None], flux, 0.0), cosine


def _rasterize_args(vertices, faces, eye, forward, width, height, orthographic):
    forward = np.asarray(forward, np.float64) / np.linalg.norm(forward)
    left = np.cross([0.0, 1.0, 0.0], forward)
    left /= np.linalg.norm(left)
    up = np.cross(forward, left)
    tan_x = 0.9 if orthographic else math.tan(math.radians(70.0) / 2.0)
    return (vertices, faces, np.asarray(eye, np.float64), forward, left, up, tan_x,
            tan_x * height / width, width, height, 1e-3, orthographic)


@settings(max_examples=15, deadline=None)
@pytest.mark.slow  # 9 s
@given(st.integers(min_value=0, max_value=2**31 - 1), st.booleans())
def test_rasterizer_bits_do_not_depend_on_bands_outlines_or_threads(seed, orthographic):
    # random overlapping triangles around an eye inside the cloud: some behind it, some
    # through the near plane (the whole image is their box), five slivers (a corner within
    # 1e-9 of the opposite edge), and ten exact duplicates, whose later copy must never
    # win its tie
    rng = np.random.default_rng(seed)
    vertices = rng.uniform(-1.0, 1.0, (60, 3))
    faces = np.array([rng.choice(60, 3, replace=False) for _ in range(40)], np.int64)
    sliver = 0.5 * (vertices[faces[:5, 0]] + vertices[faces[:5, 1]]) + \
        1e-9 * rng.normal(size=(5, 3))
    vertices = np.concatenate([vertices, sliver])
    slivers = np.stack([faces[:5, 0], faces[:5, 1], 60 + np.arange(5)], axis=1)
    faces = np.concatenate([faces, faces[:10], slivers])
    args = _rasterize_args(vertices, faces, [0.0, 0.0, -0.5], [0.1, 0.0, 1.0], 23, 17,
                           orthographic)
    threads = numba.get_num_threads()
    numba.set_num_threads(1)
    try:
        # one band, no outline test: every pixel of each triangle's box tests its ray
        # against the triangle, triangles in index order, in one thread
        single_pass = buffer_kernels.rasterize(*args, 17, -1.0)
    finally:
        numba.set_num_threads(threads)
    assert (single_pass[0] >= 0).any()
    assert not ((single_pass[0] >= 40) & (single_pass[0] < 50)).any()
    for band_rows in (1, 3, 8):
        banded = buffer_kernels.rasterize(*args, band_rows)
        for ours, reference in zip(banded, single_pass, strict=True):
            assert np.array_equal(ours, reference)


@settings(max_examples=200, deadline=None)
@given(st.floats(min_value=1.0, max_value=2.0), st.floats(min_value=0.0, max_value=1.0))
def test_compiled_fresnel_transmittance_is_the_numpy_one(eta, cosine):
    from translucent.materials.fresnel import fresnel_transmittance

    # the same operations in the same order: the same bits
    assert buffer_kernels.fresnel_transmittance_at(eta, cosine) == float(
        fresnel_transmittance(eta, cosine))


def test_compiled_fresnel_transmittance_edges():
    from translucent.materials.fresnel import fresnel_transmittance

    etas = np.array([0.5, 0.8, 1.0, 1.33, 2.0])
    cosines = np.array([0.0, 1e-300, 0.3, 0.6, 1.0, np.nan])
    for eta in etas:
        for cosine in cosines:
            expected = float(fresnel_transmittance(eta, cosine))
            assert buffer_kernels.fresnel_transmittance_at(eta, cosine) == expected, (eta, cosine)


@settings(max_examples=25, deadline=None)
@given(st.integers(min_value=0, max_value=2**31 - 1), st.floats(min_value=1.0, max_value=2.0),
       st.booleans())
def test_light_view_kernels_equal_the_numpy_formula(seed, eta, point):
    rng = np.random.default_rng(seed)
    position, normal, valid, footprint = _random_view(rng)
    if point:
        light, intensity = rng.uniform(2.0, 4.0, 3), rng.uniform(0.5, 2.0, 3)
        offset = light - np.where(valid[..., None], position, 0.0)
        squared = np.maximum(np.einsum("...k,...k->...", offset, offset), 1e-300)
        to_light = offset / np.sqrt(squared)[..., None]
        irradiance = intensity / squared[..., None]
        flux, cosine = buffer_kernels.light_flux(position, normal, valid, footprint,
                                          light.reshape(1, 1, 3), intensity.reshape(1, 1, 3),
                                          eta, True)
    else:
        to_light = rng.normal(size=3)
        to_light /= np.linalg.norm(to_light)
        irradiance = rng.uniform(0.5, 2.0, 3)
        buffer = SurfaceBuffer(position, normal, np.zeros(valid.shape + (2,)),
                               np.ones(valid.shape), valid, footprint)
        view = light_view(buffer, to_light, irradiance, eta)
        flux, cosine = view.flux, view.cosine
    expected_flux, expected_cosine = _numpy_flux(normal, valid, footprint, to_light,
                                                 irradiance, eta)
    assert np.allclose(cosine, expected_cosine, rtol=0.0, atol=ROUNDOFF)
    scale = np.broadcast_to(irradiance, flux.shape) * (footprint**2)[..., None]
    assert np.all(np.abs(flux - expected_flux) <= ROUNDOFF * scale)
    assert np.all(flux[~valid] == 0.0) and np.all(cosine[~valid] == 0.0)


def test_light_view_kernel_reads_nan_as_nothing():
    rng = np.random.default_rng(3)
    position, normal, valid, footprint = _random_view(rng)
    valid[:] = True
    normal[0, 0] = np.nan
    footprint[1, 1] = np.nan
    flux, cosine = buffer_kernels.light_flux(position, normal, valid, footprint, np.broadcast_to(
        [0.0, 0.0, 1.0], normal.shape), np.ones(normal.shape), 1.3, False)
    expected_flux, expected_cosine = _numpy_flux(normal, valid, footprint,
                                                 np.array([0.0, 0.0, 1.0]), np.ones(3), 1.3)
    assert np.all(np.isfinite(flux)) and np.all(np.isfinite(cosine))
    assert cosine[0, 0] == expected_cosine[0, 0] == 0.0
    assert np.all(flux[0, 0] == 0.0) and np.all(flux[1, 1] == 0.0)
    assert np.all(flux[1, 1] == expected_flux[1, 1])


@settings(max_examples=25, deadline=None)
@given(st.integers(min_value=0, max_value=2**31 - 1), st.floats(min_value=1.0, max_value=2.0))
def test_exitant_radiance_kernel_equals_the_numpy_formula(seed, eta):
    from translucent.materials.fresnel import fresnel_transmittance

    rng = np.random.default_rng(seed)
    position, normal, valid, _ = _random_view(rng)
    exitance = rng.uniform(0.0, 5.0, valid.shape + (3,))
    exitance[0, 0, 0] = np.nan
    exitance[0, 1, 1] = np.inf
    valid[0, :2] = True
    origin = rng.uniform(3.0, 5.0, 3)
    radiance = buffer_kernels.exitant_radiance(exitance, position, normal, valid, origin, eta)
    # Eq. 7 as numpy evaluated it before the kernel
    to_camera = origin - position
    to_camera /= np.maximum(np.linalg.norm(to_camera, axis=-1, keepdims=True), 1e-300)
    cosine = np.clip(np.abs(np.einsum("...k,...k->...", normal, to_camera)), 0.0, 1.0)
    expected = np.nan_to_num(fresnel_transmittance(eta, np.nan_to_num(cosine))[..., None] *
                             exitance / np.pi)
    expected = np.where(valid[..., None], expected, 0.0)
    finite = np.isfinite(exitance)
    assert np.all(np.abs(radiance - expected)[finite] <= ROUNDOFF * exitance[finite] / np.pi)
    assert radiance[0, 0, 0] == 0.0 and radiance[0, 1, 1] == expected[0, 1, 1]
    assert np.all(radiance[~valid] == 0.0)


@settings(max_examples=15, deadline=None)
@given(st.integers(min_value=0, max_value=2**31 - 1))
def test_perspective_footprint_kernel_equals_the_numpy_formula(seed):
    rng = np.random.default_rng(seed)
    height, width, tan_x = 13, 21, math.tan(math.radians(rng.uniform(10.0, 90.0)) / 2.0)
    tan_y = tan_x * height / width
    triangle = np.where(rng.random((height, width)) < 0.6, 5, -1)
    depth = np.where(triangle >= 0, rng.uniform(0.5, 10.0, (height, width)), np.inf)
    footprint = buffer_kernels.perspective_footprint(triangle, depth, tan_x, tan_y)
    sx = tan_x * (1.0 - 2.0 * (np.arange(width) + 0.5) / width)
    sy = tan_y * (1.0 - 2.0 * (np.arange(height) + 0.5) / height)
    cosine = 1.0 / np.sqrt(1.0 + sx[None, :] ** 2 + sy[:, None] ** 2)
    expected = np.where(triangle >= 0, depth, 0.0) * (2.0 * tan_x / width) * cosine**1.5
    assert np.allclose(footprint, expected, rtol=ROUNDOFF, atol=0.0)
    assert np.all(footprint[triangle < 0] == 0.0)


def test_interpolated_normals_fall_back_to_the_face_normal():
    # vertex normals that cancel (here all zero) leave the face's own normal
    vertices = np.array([[-1.0, -1.0, 0.0], [1.0, -1.0, 0.0], [0.0, 1.0, 0.0]])
    faces = np.array([[0, 1, 2]], np.int64)
    args = _rasterize_args(vertices, faces, [0.0, 0.0, -2.0], [0.0, 0.0, 1.0], 9, 9, True)
    triangle, barycentric, depth = buffer_kernels.rasterize(*args)
    valid, position, normal, uv, *_ = buffer_kernels.interpolate_surface(
        triangle, barycentric, depth, np.ones(depth.shape), 0, 1, vertices, faces,
        np.zeros((3, 3)), np.zeros((0, 2)))
    assert valid.any() and np.array_equal(valid, triangle == 0)
    assert np.allclose(normal[valid], [0.0, 0.0, 1.0])
    assert np.allclose(position[valid][:, 2], 0.0) and np.all(uv == 0.0)
    assert np.all(normal[~valid] == 0.0)


@settings(max_examples=30, deadline=None)
@given(st.integers(min_value=0, max_value=2000))
def test_parallel_row_order_visits_every_row_once(count):
    order = buffer_kernels._spread(count)
    assert np.array_equal(np.sort(order), np.arange(count))
    if count >= 32:
        # each of four threads' consecutive chunks reaches into every quarter of the rows
        # (not so for a few counts below 32, whose chunks hold four or five rows)
        for thread in range(4):
            chunk = order[thread * count // 4:(thread + 1) * count // 4]
            assert len(np.unique(chunk * 4 // count)) == 4


def _numpy_windows(samples, low, high, camera, width, height):
    """The windows of splat_level as numpy formulas: the reference of splat_windows."""
    active = (high > low) & (samples.flux.max(axis=1) > 0)
    index = np.flatnonzero(active)
    x, y, z = camera.project(samples.position[index], width, height)
    reach = high[index]
    focal = width / (2.0 * camera.tan_half_fov)
    limit = max(width, height)
    spread = np.sqrt(1.0 + ((x - 0.5 * width) / focal) ** 2 + ((y - 0.5 * height) / focal) ** 2)
    with np.errstate(divide="ignore", invalid="ignore"):
        reach_pixels = np.where(z - reach > 1e-9 * np.abs(reach) + 1e-300,
                                reach * focal * spread / (z - reach), np.inf)
    radius = np.minimum(np.ceil(reach_pixels) + 1.0, limit)
    onscreen = (x + radius >= 0) & (x - radius < width) & (y + radius >= 0) & \
        (y - radius < height) & np.isfinite(x) & np.isfinite(y)
    behind = z - reach <= 0
    keep = onscreen | behind
    return (index[keep], np.where(behind, 0.5 * width, x)[keep],
            np.where(behind, 0.5 * height, y)[keep], np.where(behind, limit, radius)[keep],
            np.where(behind, limit, np.minimum(reach_pixels, limit))[keep])


@settings(max_examples=25, deadline=None)
@given(st.integers(min_value=0, max_value=2**31 - 1), st.sampled_from([(64, 48), (7, 5)]))
def test_splat_windows_equal_the_numpy_formulas(seed, size):
    # samples in front of, around and behind the camera, some without flux or range
    rng = np.random.default_rng(seed)
    count = 400
    camera = CameraModel(np.array([0.3, -0.2, 4.0]), np.array([0.0, 0.0, -1.0]),
                         np.array([1.0, 0.0, 0.0]), np.array([0.0, 1.0, 0.0]), 0.4, 64, 48)
    position = rng.normal(scale=3.0, size=(count, 3))
    flux = rng.random((count, 3)) * (rng.random((count, 1)) > 0.1)
    flux[rng.random(count) < 0.02, 1] = np.nan
    low = rng.random(count) * 0.5
    high = low + rng.random(count) * 2.0 * (rng.random(count) > 0.1)
    samples = splatting.IrradianceSamples(position, np.zeros(count, np.int64), flux,
                                          np.zeros(count, np.int64))
    width, height = size
    compiled = kernels.splat_windows(position, flux, low, high, camera.origin, camera.forward,
                                     camera.right, camera.up, camera.tan_half_fov, width,
                                     height)
    for ours, reference in zip(compiled, _numpy_windows(samples, low, high, camera, width,
                                                        height), strict=True):
        assert np.array_equal(ours, reference)
    assert 0 < len(compiled[0]) < count


@settings(max_examples=20, deadline=None)
@given(st.integers(min_value=0, max_value=2**31 - 1))
def test_add_scaled_by_texel_is_the_numpy_expression(seed):
    rng = np.random.default_rng(seed)
    exitance, upsampled = rng.random((2, 5, 7, 3))
    factors = rng.random((11, 3)) + 0.1
    texel = rng.integers(0, 11, (5, 7))
    assert np.array_equal(buffer_kernels.add_scaled_by_texel(exitance, upsampled, factors, texel),
                          exitance + factors[texel] * upsampled)


@pytest.mark.slow
def test_rasterizer_bits_do_not_depend_on_threads_with_two_threads():
    # the fast tier runs one numba thread a process (tox.ini): there the test above compares
    # a single-threaded rasterizer with itself; here it runs with two threads
    import os
    import subprocess
    import sys

    if numba.get_num_threads() > 1:
        pytest.skip("this process has several numba threads: the test above compared them")
    test = f"{__file__}::test_rasterizer_bits_do_not_depend_on_bands_outlines_or_threads"
    result = subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider",
                             "-p", "no:xdist", test],
                            env={**os.environ, "NUMBA_NUM_THREADS": "2"}, capture_output=True,
                            text=True, timeout=1200)
    assert result.returncode == 0, result.stdout[-3000:] + result.stderr[-3000:]
    assert "1 passed" in result.stdout
