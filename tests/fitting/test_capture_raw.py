"""Camera RAW: a DNG made here from a synthetic capture is read by LibRaw and fits its truth."""

import numpy as np
import pytest
import tifffile
from translucent.errors import InputError
from translucent.fitting.capture import read_capture
from translucent.fitting.capture_raw import read_raw
from translucent.fitting.photo_import import import_photo
from translucent.fitting.profile import measure_profile
from translucent.fitting.synthetic import (
    Camera,
    apply_camera,
    exitance_image,
    material_profile_function,
)
from translucent.materials import Dipole
from translucent.reports.cli import main

MATERIAL = Dipole(sigma_a=[0.05, 0.1, 0.2], sigma_s_prime=[1.0, 1.5, 2.0], eta=1.3)
#: A 14-bit sensor: black level and white level, raw units.
BLACK, WHITE = 512, 16383
#: Photosites on a side, pixel size on the slab (mm), the beam's point (pixels).
SIZE, PIXEL_MM, INCIDENT = 80, 0.1, (40.3, 39.6)
#: The capture channel of each photosite of an RGGB cell (row-major) and DNG's colour codes.
RGGB = np.array([[0, 1], [1, 2]])
CFA_RGGB = (0, 1, 1, 2)


def write_dng(path, mosaic, *, black=BLACK, white=WHITE, black_tag=True):
    """Write a Bayer RGGB DNG (the raw image in a SubIFD, as cameras do) with tifffile."""
    raw_tags = [(33421, "H", 2, (2, 2), True),        # CFARepeatPatternDim
                (33422, "B", 4, CFA_RGGB, True),      # CFAPattern
                (50717, "H", 1, white, True)]         # WhiteLevel
    if black_tag:
        raw_tags += [(50713, "H", 2, (1, 1), True),   # BlackLevelRepeatDim
                     (50714, "H", 1, black, True)]    # BlackLevel
    with tifffile.TiffWriter(path) as tiff:
        tiff.write(np.zeros((8, 8, 3), np.uint8), photometric="rgb", subifds=1, subfiletype=1,
                   extratags=[(50706, "B", 4, (1, 4, 0, 0), True),     # DNGVersion
                              (50707, "B", 4, (1, 1, 0, 0), True),     # DNGBackwardVersion
                              (50708, "s", 0, "translucent test sensor", True)])
        tiff.write(np.asarray(mosaic, np.uint16), photometric=32803, subfiletype=0,
                   extratags=raw_tags)


def raw_photo(tmp_path, *, peak=12000.0, seed=5, black_tag=True):
    """A DNG of a dipole capture: each photosite its own colour's noisy count, and the mosaic."""
    exitance = exitance_image(material_profile_function(MATERIAL), (SIZE, SIZE), PIXEL_MM,
                              INCIDENT)
    camera = Camera(peak_signal=peak, black_level=BLACK, saturation_level=WHITE,
                    file_format="tiff")
    stored, _ = apply_camera(exitance, camera, np.random.default_rng(seed))
    channel = np.tile(RGGB, (SIZE // 2, SIZE // 2))
    rows, cols = np.indices((SIZE, SIZE))
    mosaic = stored[rows, cols, channel]
    path = tmp_path / "photo.dng"
    write_dng(path, mosaic, black_tag=black_tag)
    return path, mosaic, channel


def test_a_dng_reads_as_its_photosites_with_the_file_levels(tmp_path):
    path, mosaic, channel = raw_photo(tmp_path)
    raw = read_raw(path)
    assert raw.layout == "CFA RGGB" and raw.black_source == "file"
    assert np.all(raw.black == BLACK) and np.all(raw.white == WHITE)
    for c in range(3):
        own = channel == c
        np.testing.assert_array_equal(raw.values[..., c][own], mosaic[own])
        assert np.isnan(raw.values[..., c][~own]).all()


@pytest.mark.slow  # 9 s; the photo import's fit to its truth stays in the fast tier
def test_an_imported_dng_fits_its_truth(tmp_path):
    from translucent.fitting.fit import fit_dipole

    path, mosaic, channel = raw_photo(tmp_path)
    result = import_photo(path, tmp_path / "slab.json", pixel_size_mm=PIXEL_MM)
    assert result.raw_layout.startswith("CFA RGGB")
    capture = read_capture(result.sidecar)
    assert capture.spec.black_level == 0.0 and capture.spec.saturation_level == WHITE - BLACK
    # every photosite's count less the file's black level, in its own channel only
    signal = capture.linear_signal()
    rows, cols = np.indices(channel.shape)
    np.testing.assert_allclose(signal[rows, cols, channel], mosaic - BLACK)
    assert np.isnan(signal).sum() == 2 * mosaic.size
    assert np.hypot(*np.subtract(result.incident_px, INCIDENT)) < 0.1
    fit = fit_dipole(capture, seed=3, walkers=16)
    assert fit.converged and not fit.misfit
    truth = np.concatenate([MATERIAL.sigma_a, MATERIAL.sigma_s_prime])
    inside = [s.low95 <= v <= s.high95 for s, v in zip(fit.parameters[:6], truth, strict=True)]
    assert sum(inside) >= 5, inside


def test_clipped_photosites_are_saturated_in_their_own_channel(tmp_path):
    path, mosaic, channel = raw_photo(tmp_path, peak=4e5)  # far above the white level
    result = import_photo(path, tmp_path / "slab.json", pixel_size_mm=PIXEL_MM,
                          incident_px=(40.0, 40.0))
    profile = measure_profile(read_capture(result.sidecar))
    for c in range(3):
        assert profile.masked["saturated"][c] == int(((mosaic >= WHITE) & (channel == c)).sum())
    assert min(profile.saturated_annuli) >= 1


def test_a_black_level_given_replaces_a_missing_one(tmp_path):
    path, _, _ = raw_photo(tmp_path, black_tag=False)
    raw = read_raw(path, black_level=BLACK)
    assert raw.black_source == "given" and np.all(raw.black == BLACK)


def test_a_raw_dark_frame_is_subtracted_photosite_by_photosite(tmp_path):
    # neither file states a black level: with a dark frame none is needed
    path, mosaic, channel = raw_photo(tmp_path, black_tag=False)
    dark = np.rint(BLACK + np.random.default_rng(9).normal(0.0, 3.0, mosaic.shape))
    write_dng(tmp_path / "dark.dng", dark, black_tag=False)
    result = import_photo(path, tmp_path / "slab.json", pixel_size_mm=PIXEL_MM,
                          dark=tmp_path / "dark.dng")
    assert "dark frame subtracted" in result.raw_layout
    signal = read_capture(result.sidecar).linear_signal()
    rows, cols = np.indices(channel.shape)
    np.testing.assert_allclose(signal[rows, cols, channel], mosaic - dark)


@pytest.mark.parametrize("case, message, field", [
    ("no black level", "states no black level", "black level"),
    ("not a raw", "LibRaw cannot read this RAW file", "photo"),
])
def test_bad_raw_files_are_refused_by_the_command_with_nothing_written(tmp_path, capsys, case,
                                                                        message, field):
    if case == "no black level":
        path, _, _ = raw_photo(tmp_path, black_tag=False)
    else:
        path = tmp_path / "photo.nef"
        path.write_bytes(b"\x00" * 4096)  # no sensor LibRaw knows
    with pytest.raises(InputError, match=message) as error:
        read_raw(path)
    assert error.value.field == field and str(path) in str(error.value)
    (tmp_path / "out").mkdir()
    code = main(["capture", "import", str(path), "--pixel-size-mm", "0.1",
                 "--out", str(tmp_path / "out" / "c.json")])
    stderr = capsys.readouterr().err
    assert code == 2 and message in stderr and "Traceback" not in stderr
    assert list((tmp_path / "out").iterdir()) == []


def test_a_colour_filter_that_is_not_red_green_blue_is_refused(tmp_path):
    from translucent.fitting.capture_raw import _channel

    with pytest.raises(InputError, match="not red, green and blue") as error:
        _channel("C", "CMYG", tmp_path / "x.dng", "photo")
    assert error.value.value == "CMYG"
