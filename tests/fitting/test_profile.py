"""Radial profiles: the operator against analytic pixel integrals, centre refinement, masks."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.special import erf
from translucent.errors import InputError
from translucent.fitting.capture import Capture, CaptureSpec
from translucent.fitting.profile import (
    MIN_PIXELS_PER_ANNULUS,
    annulus_edges,
    measure_profile,
    refine_incident_point,
)

#: The operator averages a profile that is linear between grid nodes over exact pixel
#: footprints. Its error is the interpolation error, ~step^2 / 12 for a log-step of up to
#: 0.05 between nodes, plus the mean-radius approximation of partly covered rings, which
#: grows with the profile's curvature. A Gaussian of sigma = 6 px at 4 sigma falls by
#: 0.67 per pixel, steeper than any scattering profile, where the 0.1-px floor of the grid
#: spacing allows a log-step of 0.067: 4e-4 from interpolation, ~1e-3 in all (measured).
OPERATOR_ACCURACY = 2e-3
#: A symmetric blob sampled on pixels: the thresholded centroid is unbiased up to the
#: pixel sampling of the threshold contour, a few hundredths of a pixel for a blob of
#: sigma >= 2 px.
CENTRE_ACCURACY_PX = 0.05


def gaussian_pixels(shape, centre, sigma):
    """Exact pixel means of exp(-r^2 / (2 sigma^2)) (pixels of unit size)."""

    def integral(a, b):
        return np.sqrt(np.pi / 2) * sigma * (erf(b / (np.sqrt(2) * sigma))
                                             - erf(a / (np.sqrt(2) * sigma)))

    xs = np.arange(shape[1]) - centre[0]
    ys = np.arange(shape[0]) - centre[1]
    return np.outer(integral(ys, ys + 1), integral(xs, xs + 1))


def capture_of(values, centre, **spec):
    pixels = np.repeat(np.asarray(values, np.float64)[..., None], 3, axis=2)
    options = dict(image="c.exr", pixel_size_mm=0.1, incident_px=centre, black_level=0.0,
                   saturation_level=1e12)
    options.update(spec)
    return Capture(CaptureSpec(**options), pixels)


@given(r_max=st.floats(1, 300))
def test_annulus_edges_cover_and_hold_enough_pixels(r_max):
    edges = annulus_edges(r_max)
    assert edges[0] == 0 and edges[-1] >= r_max
    widths = np.diff(edges)
    assert np.all(widths >= 1.0 - 1e-12)
    assert np.all(np.pi * np.diff(edges ** 2) >= MIN_PIXELS_PER_ANNULUS - 1e-9)


@settings(max_examples=8, deadline=None)
@given(cx=st.floats(-0.5, 0.5), cy=st.floats(-0.5, 0.5), sigma=st.floats(6.0, 12.0))
def test_operator_reproduces_exact_pixel_integrals(cx, cy, sigma):
    centre = (24.0 + cx, 23.0 + cy)
    image = 1000.0 * gaussian_pixels((48, 48), centre, sigma)
    profile = measure_profile(capture_of(image, centre), refine_centre=False)
    s_mm = sigma * 0.1
    nodes = profile.operator.grid.nodes
    model = 1000.0 * np.exp(-nodes ** 2 / (2 * s_mm ** 2))
    predicted = profile.operator.predict(np.repeat(model[:, None], 3, axis=1))[0]
    mean, _, _ = profile.observations(0)
    relevant = mean > 1e-6 * mean.max()
    np.testing.assert_allclose(predicted[relevant], mean[relevant],
                               rtol=OPERATOR_ACCURACY, atol=1e-9 * mean.max())


@settings(max_examples=10, deadline=None)
@given(cx=st.floats(20, 28), cy=st.floats(20, 28), sigma=st.floats(2.0, 5.0),
       start=st.tuples(st.floats(-3, 3), st.floats(-3, 3)))
def test_centre_refinement_finds_a_subpixel_centre(cx, cy, sigma, start):
    image = gaussian_pixels((48, 48), (cx, cy), sigma)
    found = refine_incident_point(image, (cx + start[0], cy + start[1]))
    assert np.hypot(found[0] - cx, found[1] - cy) < CENTRE_ACCURACY_PX


def test_centre_refinement_with_a_saturated_plateau():
    cx, cy = 30.3, 27.8
    image = gaussian_pixels((60, 60), (cx, cy), 4.0)
    clipped = np.minimum(image, 0.3 * image.max())
    found = refine_incident_point(clipped, (33, 25), saturated=clipped >= 0.3 * image.max())
    assert np.hypot(found[0] - cx, found[1] - cy) < CENTRE_ACCURACY_PX


def test_masks_are_counted_and_saturated_annuli_fitted_as_clipped_means(rng):
    centre = (32.0, 32.0)
    image = 1000.0 * gaussian_pixels((64, 64), centre, 10.0) + 50.0
    image = image + rng.normal(0, 0.5, image.shape)
    saturation = 0.9 * image.max()
    image = np.minimum(image, saturation)
    image[5, 7] = np.nan
    capture = capture_of(image, centre, black_level=50.0, saturation_level=saturation)
    profile = measure_profile(capture)
    assert profile.masked["nan"] == [1, 1, 1]
    assert profile.masked["saturated"][0] == int((image >= saturation).sum())
    assert profile.masked["below_black"][0] == int((image < 50.0).sum())
    assert profile.dropped["noise_floor"][0] >= 1
    # the annuli holding saturated pixels are used, from one inside the innermost annulus
    # that holds an unsaturated pixel; the fully saturated core inside it is dropped
    ys, xs = np.mgrid[0:64, 0:64] + 0.5
    radius = np.hypot(xs - profile.centre_px[0], ys - profile.centre_px[1])
    annulus = np.searchsorted(profile.edges_mm / 0.1, radius, side="right") - 1
    mixed = np.intersect1d(annulus[image >= saturation], annulus[image < saturation])
    used = np.flatnonzero(profile.used[:, 0])
    assert used[0] == mixed.min() - 1
    assert profile.saturated_annuli[0] == int(np.sum(np.unique(annulus[image >= saturation])
                                                     >= used[0]))
    assert profile.dropped["saturated"][0] == used[0]
    assert np.all(np.diff(used) == 1)  # one contiguous range
    # a saturated annulus holds the mean of its clipped values
    first = used[0] + 1
    expected = np.minimum(image[annulus == first], saturation).mean() - 50.0
    assert profile.mean[first, 0] == pytest.approx(expected, rel=1e-12)


def test_nothing_usable_is_an_error():
    image = np.full((32, 32), 5.0)
    capture = capture_of(image, (16, 16), black_level=10.0, saturation_level=100.0)
    with pytest.raises(InputError, match="no channel has 4 usable annuli"):
        measure_profile(capture)


def test_integer_floor_counts_as_below_black():
    centre = (16.0, 16.0)
    image = np.rint(2000.0 * gaussian_pixels((32, 32), centre, 3.0))
    capture = capture_of(image, centre, image="c.png", black_level=0.0, saturation_level=65535)
    profile = measure_profile(capture)
    assert profile.masked["below_black"][0] == int((image <= 0).sum()) > 0


@pytest.mark.parametrize("image_name", ["c.png", "c.tif"])
def test_integer_ceiling_counts_as_saturated(image_name):
    # a 16-bit file clips at 65535 whatever saturation_level the sidecar gives
    centre = (16.0, 16.0)
    image = np.minimum(np.rint(2e5 * gaussian_pixels((32, 32), centre, 3.0)) + 10.0, 65535.0)
    capture = capture_of(image, centre, image=image_name, black_level=0.0,
                         saturation_level=1e9)
    profile = measure_profile(capture)
    assert profile.masked["saturated"][0] == int((image >= 65535).sum()) > 0
    assert profile.saturated_annuli[0] > 0
    # the ceiling is the file's top code, not the sidecar's level: the first used annulus
    # is the fully saturated one at it, the clipped means further out lie below it
    censored = profile.operator.ceilings[0]
    assert censored.ceiling == 65535.0  # black level 0
    means = profile.mean[profile.used[:, 0], 0]
    assert means[0] == censored.ceiling and np.all(means[1:] < censored.ceiling)


#: The fitter's operator and the independent dipole-forward generator (24x / 64x
#: supersampled pixels near the centre, 16x elsewhere) agree on annulus means to their
#: combined discretisation errors: the operator's cubic between nodes on four rings an
#: interval, the generator's midpoint rule, 1.5e-5 to 3.1e-5 measured here (5e-4 with
#: straight lines between nodes and 6x pixels).
GENERATOR_AGREEMENT = 1e-4


def test_operator_agrees_with_the_independent_dipole_generator():
    from translucent.fitting.synthetic import exitance_image, material_profile_function
    from translucent.materials import Dipole

    medium = Dipole(sigma_a=[0.04, 0.09, 0.27], sigma_s_prime=[0.8, 0.75, 0.7], eta=1.3)
    profile_fn = material_profile_function(medium)
    centre = (24.3, 23.6)
    image = exitance_image(profile_fn, (48, 48), 0.25, centre)
    spec = CaptureSpec(image="c.exr", pixel_size_mm=0.25, incident_px=centre, black_level=0.0,
                       saturation_level=1e30)
    # a whisper of noise so that every annulus has a finite standard error
    noisy = image * (1 + 1e-7 * np.random.default_rng(0).standard_normal(image.shape))
    profile = measure_profile(Capture(spec, noisy), refine_centre=False)
    predicted = profile.operator.predict(profile_fn(profile.operator.grid.nodes))
    for c in range(3):
        mean, _, _ = profile.observations(c)
        np.testing.assert_allclose(predicted[c], mean, rtol=GENERATOR_AGREEMENT)


def test_an_r_min_beyond_the_data_is_named_in_the_error():
    values = gaussian_pixels((24, 24), (12.0, 12.0), 4.0) * 1e4 + 1.0
    noisy = values + np.random.default_rng(3).normal(0.0, 0.5, values.shape)
    with pytest.raises(InputError, match=r"r_min_mm = 100 mm leaves out") as error:
        measure_profile(capture_of(noisy, (12.0, 12.0)), r_min_mm=100.0)
    assert error.value.value["inside_r_min"][0] > 0


def test_a_channel_with_no_valid_pixel_is_left_out_not_a_crash():
    # a red-laser capture in a PNG: green and blue at the integer floor 0 everywhere
    centre = (16.0, 16.0)
    image = np.rint(2e4 * gaussian_pixels((32, 32), centre, 3.0)) + 100.0
    capture = capture_of(image, centre, image="c.png", saturation_level=65535)
    pixels = capture.pixels.copy()
    pixels[..., 1:] = 0.0
    profile = measure_profile(Capture(capture.spec, pixels))
    assert profile.used[:, 0].sum() >= 4 and not profile.used[:, 1:].any()
    assert profile.masked["valid"][1:] == [0, 0]
    assert profile.operator.matrices[1].shape[0] == 0


@pytest.mark.parametrize("r_min", [float("inf"), float("nan"), -1.0])
def test_a_bad_r_min_says_what_is_accepted(r_min):
    values = gaussian_pixels((24, 24), (12.0, 12.0), 4.0) * 1e4
    with pytest.raises(InputError, match="must be finite and >= 0") as error:
        measure_profile(capture_of(values, (12.0, 12.0)), r_min_mm=r_min)
    assert error.value.field == "r_min_mm"


# ------------------------------------------------------------------ censored at black


def test_censored_line_fit_is_unbiased_and_its_standard_error_calibrated(rng):
    from translucent.fitting.profile import censored_line_fit

    estimates, errors, plain = [], [], []
    for _ in range(300):
        radius = rng.uniform(10.0, 12.0, 60)
        values = 2.0 + 0.5 * (radius - 11.0) + 3.0 * rng.standard_normal(60)
        cut = values <= 0.0  # about 30 % censored
        mean, se = censored_line_fit(values[~cut], radius[~cut], radius[cut])
        estimates.append(mean)
        errors.append(se)
        plain.append(np.maximum(values, 0.0).mean())
    estimates, errors = np.array(estimates), np.array(errors)
    spread = estimates.std() / np.sqrt(estimates.size)
    # the truth at the annulus's mean radius (11 on average) is 2
    assert abs(estimates.mean() - 2.0) < 4 * spread
    assert errors.mean() == pytest.approx(estimates.std(), rel=0.15)
    assert np.mean(plain) - 2.0 > 10 * spread  # the clipped values' mean is biased up


def _noisy_capture(rng, *, clip: bool):
    centre = (24.0, 24.0)
    signal = 400.0 * gaussian_pixels((48, 48), centre, 6.0)
    noisy = signal + rng.normal(0.0, 3.0, signal.shape)
    if clip:
        noisy = np.maximum(noisy, 0.0)
    return capture_of(noisy, centre, black_level=0.0, saturation_level=1e9)


def test_pixels_clipped_at_black_are_censored_and_estimated_without_bias():
    clipped = measure_profile(_noisy_capture(np.random.default_rng(5), clip=True),
                              refine_centre=False)
    kept = measure_profile(_noisy_capture(np.random.default_rng(5), clip=False),
                           refine_centre=False)
    assert clipped.masked["censored"][0] > 0 and kept.masked["censored"][0] == 0
    both = clipped.used[:, 0] & kept.used[:, 0]
    assert both.sum() >= 8
    z = (clipped.mean[both, 0] - kept.mean[both, 0]) / kept.stderr[both, 0]
    # the same noise draw, censored or not: the censored estimate stays within its errors
    assert np.abs(z).max() < 3.0
    assert abs(z.mean()) < 3.0 / np.sqrt(both.sum())


def test_noise_below_an_unclipped_black_level_is_not_censored(rng):
    centre = (16.0, 16.0)
    image = 100.0 + 500.0 * gaussian_pixels((32, 32), centre, 4.0) \
        + rng.normal(0.0, 2.0, (32, 32))
    profile = measure_profile(capture_of(image, centre, black_level=100.0,
                                         saturation_level=1e9))
    assert profile.masked["censored"][0] == 0
    assert profile.masked["below_black"][0] == int((image < 100.0).sum()) > 0
