"""A measured beam (its own image on a white target) as the forward model's kernel."""

import functools
import json
from dataclasses import replace

import numpy as np
import pytest
import tifffile
from translucent.errors import InputError
from translucent.fitting.beam import beam_convolution_matrix
from translucent.fitting.capture import read_capture, write_capture
from translucent.fitting.geometry import radial_grid
from translucent.fitting.measured_beam import measure_beam
from translucent.fitting.models import DipoleModel
from translucent.fitting.profile import measure_profile
from translucent.fitting.synthetic import Camera, dipole_capture
from translucent.materials import Dipole, dipole_reflectance_profile

MATERIAL = Dipole(sigma_a=[0.05, 0.1, 0.2], sigma_s_prime=[1.0, 1.5, 2.0], eta=1.3)
PIXEL_MM = 0.1
#: A beam image is a pixelated beam: the kernels it gives agree with the exact ones to
#: about the fraction of the beam's power in the pixels its edge cuts (a 6 px disk: ~2 %).
PIXELATION = 0.03


def _beam_image(shape, centre, radius_mm, profile, supersample=8, pixel_mm=PIXEL_MM):
    """The beam on a white target: the irradiance averaged over each pixel (supersampled).

    The averaging blurs the beam by one pixel: imaged at the capture's own pixel size, a
    12 px top hat then gives a reduced chi-square of 4.4 at the true parameters of a
    capture with a 30000 e- peak (1.7 at 2x the magnification, 1.06 at 4x).
    """
    height, width = shape
    offsets = (np.arange(supersample) + 0.5) / supersample
    ys = (np.arange(height)[:, None] + offsets[None, :]).ravel()
    xs = (np.arange(width)[:, None] + offsets[None, :]).ravel()
    rho = np.hypot(xs[None, :] - centre[0], ys[:, None] - centre[1]) * pixel_mm
    if profile == "top_hat":
        values = (rho <= radius_mm).astype(np.float64)
    else:
        values = np.exp(-2.0 * rho ** 2 / radius_mm ** 2)
    values = values.reshape(height, supersample, width, supersample).mean(axis=(1, 3))
    return 30000.0 * values / values.max() + 100.0  # and a background the reader removes


@pytest.mark.parametrize("profile, radius", [("top_hat", 0.6), ("gaussian", 0.5)])
def test_the_measured_kernel_is_the_beams_own(profile, radius):
    beam = measure_beam(_beam_image((48, 48), (24.3, 23.8), radius, profile), PIXEL_MM)
    assert beam.disk_weights.sum() == pytest.approx(1.0, abs=1e-12)
    assert np.hypot(beam.centre_px[0] - 24.3, beam.centre_px[1] - 23.8) < 0.05
    grid = radial_grid(8.0, 1e-3, 0.05)
    f = dipole_reflectance_profile(grid.nodes, 0.1, 1.5, 1.3)
    exact = beam_convolution_matrix(grid, radius, profile) @ f
    measured = beam.convolution_matrix(grid) @ f
    within = grid.nodes < 4.0
    np.testing.assert_allclose(measured[within], exact[within], rtol=PIXELATION)


@functools.lru_cache(maxsize=1)
def _top_hat_data():
    pixels, spec = dipole_capture(MATERIAL, size=48, pixel_size_mm=PIXEL_MM, seed=3,
                                  beam_radius_mm=0.6, beam_profile="top_hat",
                                  camera=Camera(peak_signal=30000))
    # the beam imaged at 8x the capture's magnification (see _beam_image's pixel blur)
    beam = np.rint(_beam_image((320, 320), (160.0, 160.0), 0.6, "top_hat",
                               pixel_mm=PIXEL_MM / 8)).astype(np.uint16)
    return pixels, spec, beam


@pytest.fixture
def top_hat_capture(tmp_path):
    """A top-hat-beam dipole capture whose sidecar gives the beam as an image."""
    pixels, spec, beam = _top_hat_data()
    tifffile.imwrite(tmp_path / "beam.tif", beam)
    sidecar = write_capture(tmp_path / "slab.json",
                            pixels, replace(spec, beam_profile="measured",
                                            beam_image="beam.tif", beam_radius_mm=0.0,
                                            beam_pixel_size_mm=PIXEL_MM / 8))
    return sidecar, spec


def _reduced_chi_square(capture, spec):
    model = DipoleModel(measure_profile(capture), capture.spec)
    theta = np.concatenate([np.log(MATERIAL.sigma_a), np.log(MATERIAL.sigma_s_prime),
                            [np.log(spec.synthetic["exposure"])]])
    total, count = 0.0, 0
    for c, predicted in enumerate(model.predictions(theta)):
        mean, stderr, _ = model.observations(c)
        total += float(np.sum(((mean - predicted[0]) / stderr) ** 2))
        count += mean.size
    return total / count


def test_a_capture_with_its_beam_image_is_predicted_at_its_truth(top_hat_capture):
    sidecar, spec = top_hat_capture
    capture = read_capture(sidecar)
    assert capture.beam is not None
    # the radius holding 99 % of the power, on 1 px rings: the disk's edge pixels count
    assert 0.6 <= capture.spec.beam_radius_mm <= 0.6 + 1.5 * PIXEL_MM / 8
    # at the true parameters the data scatter about the prediction as their noise says
    assert _reduced_chi_square(capture, spec) < 1.5
    # a pencil beam in its place is far off (the beam is 12 pixels wide)
    pencil = replace(capture, spec=replace(capture.spec, beam_profile="gaussian",
                                           beam_image=None, beam_radius_mm=0.0), beam=None)
    assert _reduced_chi_square(pencil, spec) > 10.0


@pytest.mark.slow
def test_a_capture_with_its_beam_image_fits_its_truth(top_hat_capture):
    from translucent.fitting.fit import fit_dipole

    sidecar, _ = top_hat_capture
    fit = fit_dipole(read_capture(sidecar), seed=2, walkers=16)
    assert fit.converged and not fit.misfit
    truth = np.concatenate([MATERIAL.sigma_a, MATERIAL.sigma_s_prime])
    assert sum(s.low95 <= t <= s.high95 for s, t in zip(fit.parameters[:6], truth,
                                                         strict=True)) >= 5


@pytest.mark.parametrize("change, message", [
    ({"beam_image": None}, 'needs beam_image'),
    ({"beam_profile": "gaussian"}, 'only with beam_profile "measured"'),
    ({"beam_image": "missing.tif"}, "no such beam image"),
])
def test_bad_beam_images_are_refused(top_hat_capture, change, message):
    sidecar, _ = top_hat_capture
    data = json.loads(sidecar.read_text())
    data.update(change)
    if data["beam_image"] is None:
        del data["beam_image"]
    sidecar.write_text(json.dumps(data))
    with pytest.raises(InputError, match=message) as error:
        read_capture(sidecar)
    assert error.value.field == "beam_image"


def test_a_beam_cut_by_the_image_border_is_refused():
    image = _beam_image((20, 20), (10.0, 10.0), 1.0, "gaussian")  # 1/e^2 at the border
    with pytest.raises(InputError, match="beam reaches the image border"):
        measure_beam(image, PIXEL_MM)
