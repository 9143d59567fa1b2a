"""translucent capture import: a 16-bit TIFF photo (and dark frame) becomes a capture that fits."""

import numpy as np
import pytest
import tifffile
from translucent.errors import InputError
from translucent.fitting.capture import read_capture
from translucent.fitting.photo_import import import_photo, ruler_pixel_size
from translucent.fitting.profile import measure_profile
from translucent.fitting.synthetic import Camera, dipole_capture
from translucent.materials import Dipole
from translucent.reports.cli import main

MATERIAL = Dipole(sigma_a=[0.05, 0.1, 0.2], sigma_s_prime=[1.0, 1.5, 2.0], eta=1.3)
#: Dark-frame offset and read noise of the simulated camera, codes.
DARK_OFFSET, DARK_NOISE = 180.0, 2.0


def _photo(tmp_path, *, incident=(20.3, 17.6), peak=30000.0, size=40, grey=False):
    """A 16-bit TIFF of a dipole capture with a dark offset, its dark frame, and the truth."""
    rng = np.random.default_rng(7)
    pixels, spec = dipole_capture(MATERIAL, size=size, pixel_size_mm=0.2, seed=3,
                                  incident_px=incident,
                                  camera=Camera(peak_signal=peak, black_level=0.0,
                                                saturation_level=1e9))
    dark = DARK_OFFSET + rng.normal(0.0, DARK_NOISE, pixels.shape)
    photo = pixels + DARK_OFFSET + rng.normal(0.0, DARK_NOISE, pixels.shape)
    if grey:
        photo, dark = photo.mean(axis=2), dark.mean(axis=2)
    codes = lambda a: np.clip(np.rint(a), 0, 65535).astype(np.uint16)  # noqa: E731
    photo_path, dark_path = tmp_path / "photo.tif", tmp_path / "dark.tif"
    tifffile.imwrite(photo_path, codes(photo))
    tifffile.imwrite(dark_path, codes(dark))
    return photo_path, dark_path, spec, pixels


def test_a_tiff_and_its_dark_frame_become_a_capture(tmp_path):
    photo, dark, truth, original = _photo(tmp_path)
    result = import_photo(photo, tmp_path / "slab.json", pixel_size_mm=0.2, dark=dark)
    assert result.preview.is_file() and result.image.is_file()
    capture = read_capture(result.sidecar)
    assert capture.spec.black_level == 0.0 and capture.spec.exposure is None
    # the found point is the true one to a small fraction of a pixel
    assert np.hypot(*np.subtract(result.incident_px, truth.incident_px)) < 0.1
    # the signal is the original one: the photo minus its dark frame differs from it by
    # the two frames' read noise and rounding only, with no offset left
    difference = capture.linear_signal() - original
    spread = np.sqrt(2.0 * DARK_NOISE ** 2 + 2.0 / 12.0)
    assert abs(difference.mean()) < 4.0 * spread / np.sqrt(difference.size)
    assert difference.std() == pytest.approx(spread, rel=0.05)
    assert measure_profile(capture).used.sum(axis=0).min() >= 10


def test_the_imported_capture_fits_its_truth(tmp_path):
    from translucent.fitting.fit import fit_dipole

    photo, dark, _, _ = _photo(tmp_path)
    result = import_photo(photo, tmp_path / "slab.json", pixel_size_mm=0.2, dark=dark)
    fit = fit_dipole(read_capture(result.sidecar), seed=2, walkers=16)
    assert fit.converged and not fit.misfit
    values = np.concatenate([MATERIAL.sigma_a, MATERIAL.sigma_s_prime])
    inside = [s.low95 <= v <= s.high95 for s, v in zip(fit.parameters[:6], values,
                                                        strict=True)]
    assert sum(inside) >= 5


def test_clipped_pixels_are_marked_saturated(tmp_path):
    photo, dark, _, _ = _photo(tmp_path, peak=3e5, grey=True)  # the centre exceeds 65535
    result = import_photo(photo, tmp_path / "slab.json", pixel_size_mm=0.2, dark=dark)
    assert result.saturated_pixels > 0
    profile = measure_profile(read_capture(result.sidecar))
    assert profile.masked["saturated"][0] == result.saturated_pixels


def test_the_ruler_gives_the_pixel_size():
    assert ruler_pixel_size(10, 10, 13, 14, 1.0) == pytest.approx(0.2)
    with pytest.raises(InputError, match="must differ"):
        ruler_pixel_size(1, 1, 1, 1, 5.0)
    with pytest.raises(InputError, match="> 0 mm"):
        ruler_pixel_size(0, 0, 1, 1, 0.0)


def test_the_command_line_spelling_and_its_output(tmp_path, capsys):
    photo, dark, _, _ = _photo(tmp_path)
    code = main(["capture", "import", str(photo), "--dark", str(dark), "--ruler", "0", "0",
                 "30", "40", "10", "--out", str(tmp_path / "c.json")])
    output = capsys.readouterr().out
    assert code == 0 and "pixel size 0.2 mm" in output and "translucent fit" in output
    assert read_capture(tmp_path / "c.json").spec.pixel_size_mm == pytest.approx(0.2)


@pytest.mark.parametrize("case, message", [
    ("zero pixel size", "--pixel-size-mm"),
    ("dark of another size", "dark frame is 20 x 20"),
    ("no spot", "no incident spot found"),
    ("raw", "LibRaw cannot read this RAW file"),
    ("dark and black level", "not both"),
])
def test_bad_input_is_refused_with_nothing_written(tmp_path, capsys, case, message):
    photo, dark, _, _ = _photo(tmp_path)
    arguments = ["capture", "import", str(photo), "--pixel-size-mm", "0.2",
                 "--out", str(tmp_path / "out" / "c.json")]
    (tmp_path / "out").mkdir()
    if case == "zero pixel size":
        arguments[4] = "0"
    elif case == "dark of another size":
        tifffile.imwrite(dark, np.full((20, 20, 3), 180, np.uint16))
        arguments += ["--dark", str(dark)]
    elif case == "no spot":
        tifffile.imwrite(photo, np.random.default_rng(1).normal(1000, 5, (40, 40, 3))
                         .astype(np.uint16))
    elif case == "raw":
        raw = tmp_path / "photo.dng"
        raw.write_bytes(b"II*\x00")
        arguments[2] = str(raw)
    else:
        arguments += ["--dark", str(dark), "--black-level", "100"]
    code = main(arguments)
    error = capsys.readouterr().err
    assert code == 2 and message in error and "Traceback" not in error
    assert list((tmp_path / "out").iterdir()) == []


def test_a_beam_photo_makes_the_beam_measured(tmp_path):
    photo, dark, _, _ = _photo(tmp_path)
    yy, xx = np.mgrid[0:64, 0:64] + 0.5
    beam = 20000.0 * np.exp(-2.0 * ((xx - 32.0) ** 2 + (yy - 32.0) ** 2) / 8.0 ** 2) + 50.0
    tifffile.imwrite(tmp_path / "beam.tif", np.rint(beam).astype(np.uint16))
    result = import_photo(photo, tmp_path / "slab.json", pixel_size_mm=0.2, dark=dark,
                          beam_image=tmp_path / "beam.tif", beam_pixel_size_mm=0.05)
    capture = read_capture(result.sidecar)
    assert capture.spec.beam_profile == "measured" and capture.beam is not None
    # a Gaussian of 1/e^2 radius 8 px x 0.05 mm holds 99 % of its power within 1.52 w
    assert capture.spec.beam_radius_mm == pytest.approx(1.52 * 0.4, abs=0.05)
