"""The capture format: round trips of every encoding, and a clear error for every bad field."""

import json

import numpy as np
import pytest
from translucent.errors import InputError
from translucent.fitting.capture import (
    CaptureSpec,
    decode_pixels,
    encode_srgb,
    read_capture,
    read_sidecar,
    write_capture,
)

#: sRGB encode/decode through 16-bit codes: rounding moves a code by at most 0.5, and the
#: sRGB decoder's slope (linear units per code) is at most 2.4 / 1.055 (at the top), so the
#: round trip is exact to 0.5 * 2.4 / 1.055 linear units.
SRGB_ROUND_TRIP = 0.5 * 2.4 / 1.055


@pytest.mark.parametrize("suffix", [".exr", ".png", ".tif"])
def test_write_read_round_trip(tmp_path, suffix, rng):
    pixels = np.rint(rng.uniform(0, 60000, size=(12, 10, 3)))
    spec = CaptureSpec(image=f"capture{suffix}", pixel_size_mm=0.05, incident_px=(5.0, 6.0),
                       black_level=10.0, saturation_level=65535.0, exposure=2.5)
    path = write_capture(tmp_path / "capture.json", pixels, spec)
    capture = read_capture(path)
    assert capture.spec == spec
    np.testing.assert_array_equal(capture.pixels, pixels.astype(np.float32))
    np.testing.assert_allclose(capture.linear_signal(), pixels - 10.0, rtol=1e-6)


def test_srgb_round_trip(rng):
    spec = CaptureSpec(image="c.png", pixel_size_mm=1.0, incident_px=(0, 0), black_level=300.0,
                       encoding="srgb", saturation_level=65535.0)
    linear = rng.uniform(0, 40000, size=1000)
    codes = np.rint(encode_srgb(linear, spec))
    assert np.abs(decode_pixels(codes, spec) - linear).max() <= SRGB_ROUND_TRIP


def test_srgb_decoding_is_monotone_and_zero_at_black(rng):
    spec = CaptureSpec(image="c.png", pixel_size_mm=1.0, incident_px=(0, 0), black_level=300.0,
                       encoding="srgb", saturation_level=65535.0)
    codes = np.arange(0, 65536, 7.0)
    linear = decode_pixels(codes, spec)
    assert np.all(np.diff(linear) > 0)
    assert decode_pixels(300.0, spec) == pytest.approx(0.0, abs=1e-9)


def test_grey_and_rgba_pngs_become_rgb(tmp_path):
    import png

    grey = (np.arange(64, dtype=np.uint16) * 1000).reshape(8, 8)
    with open(tmp_path / "g.png", "wb") as handle:
        png.Writer(8, 8, greyscale=True, bitdepth=16).write(handle, grey)
    data = {"image": "g.png", "pixel_size_mm": 0.1, "incident_px": [4, 4], "side": "reflection",
            "black_level": 0, "saturation_level": 65535}
    (tmp_path / "g.json").write_text(json.dumps(data))
    capture = read_capture(tmp_path / "g.json")
    assert capture.pixels.shape == (8, 8, 3)
    np.testing.assert_array_equal(capture.pixels[..., 2], grey)


BAD_FIELDS = [
    ({"pixel_size_mm": 0}, "pixel_size_mm", "must be > 0"),
    ({"pixel_size_mm": "big"}, "pixel_size_mm", "must be a number"),
    ({"pixel_size_mm": float("nan")}, "pixel_size_mm", "must be finite"),
    ({"incident_px": [1, 2, 3]}, "incident_px", r"must be \[x, y\]"),
    ({"incident_px": [40.0, 3.0]}, "incident_px", "must lie inside the image"),
    ({"side": "top"}, "side", "must be one of 'reflection', 'transmission'"),
    ({"thickness_mm": -1}, "thickness_mm", "must be > 0"),
    ({"side": "transmission", "thickness_mm": None}, "thickness_mm", "needs a finite slab"),
    ({"eta": 0.5}, "eta", r"must be >= 1 and <= 3"),
    ({"eta": 4.0}, "eta", "must be <= 3"),
    ({"beam_radius_mm": -0.1}, "beam_radius_mm", "must be >= 0"),
    ({"beam_profile": "square"}, "beam_profile", "must be one of"),
    ({"black_level": -5}, "black_level", "must be >= 0"),
    ({"saturation_level": 5}, "saturation_level", r"must be > black_level \(10\)"),
    ({"exposure": 0}, "exposure", "must be > 0"),
    ({"encoding": "gamma"}, "encoding", "must be one of 'linear', 'srgb'"),
    ({"encoding": "srgb"}, "encoding", "OpenEXR is linear"),
    ({"image": "capture.jpg"}, "image", "must be a file name ending in .exr"),
    ({"synthetic": [1]}, "synthetic", "must be a JSON object"),
    ({"colour": "red"}, "colour", "unknown key; valid keys: image"),
]


@pytest.mark.parametrize("changes, field, message", BAD_FIELDS)
def test_bad_sidecar_fields_name_file_field_and_value(write_sidecar, sidecar_data, changes,
                                                      field, message):
    sidecar_data.update(changes)
    path = write_sidecar(sidecar_data)
    with pytest.raises(InputError, match=message) as error:
        read_capture(path)
    assert error.value.field == field
    assert error.value.file == str(path)
    assert str(path) in str(error.value)


@pytest.mark.parametrize("key", ["image", "pixel_size_mm", "incident_px", "side",
                                 "black_level", "saturation_level"])
def test_missing_required_key(write_sidecar, sidecar_data, key):
    del sidecar_data[key]
    with pytest.raises(InputError, match="required key is missing") as error:
        read_sidecar(write_sidecar(sidecar_data))
    assert error.value.field == key


def test_missing_sidecar_and_bad_json(tmp_path):
    with pytest.raises(InputError, match="no such capture sidecar"):
        read_sidecar(tmp_path / "nothing.json")
    (tmp_path / "bad.json").write_text("{not json")
    with pytest.raises(InputError, match="not a readable JSON file"):
        read_sidecar(tmp_path / "bad.json")
    (tmp_path / "list.json").write_text("[1, 2]")
    with pytest.raises(InputError, match="a sidecar must be a JSON object"):
        read_sidecar(tmp_path / "list.json")


def test_missing_corrupt_and_8_bit_images(tmp_path, sidecar_data):
    import png

    path = tmp_path / "capture.json"
    path.write_text(json.dumps(sidecar_data))
    with pytest.raises(InputError, match="no such capture image"):
        read_capture(path)
    (tmp_path / "capture.exr").write_bytes(b"not an exr")
    with pytest.raises(InputError, match="not a readable OpenEXR file"):
        read_capture(path)
    with open(tmp_path / "eight.png", "wb") as handle:
        png.Writer(32, 32, greyscale=True, bitdepth=8).write(
            handle, np.zeros((32, 32), dtype=np.uint8))
    path.write_text(json.dumps({**sidecar_data, "image": "eight.png"}))
    with pytest.raises(InputError, match="must be 16-bit") as error:
        read_capture(path)
    assert error.value.field == "bit depth"


def test_tiny_and_all_nan_images(tmp_path):
    spec = CaptureSpec(image="capture.exr", pixel_size_mm=0.1, incident_px=(2, 2))
    path = write_capture(tmp_path / "capture.json", np.ones((4, 4, 3)), spec)
    with pytest.raises(InputError, match="at least 8 x 8"):
        read_capture(path)
    path = write_capture(tmp_path / "capture.json", np.full((9, 9, 3), np.nan), spec)
    with pytest.raises(InputError, match="no finite pixel"):
        read_capture(path)


@pytest.mark.parametrize("key, literal", [("pixel_size_mm", "1" + "0" * 400),
                                          ("incident_px", "[1" + "0" * 400 + ", 3]")])
def test_integers_too_large_for_a_float_are_input_errors(write_sidecar, sidecar_data, key,
                                                         literal):
    path = write_sidecar(sidecar_data)
    text = json.dumps({**sidecar_data, key: "HUGE"}).replace('"HUGE"', literal)
    path.write_text(text)
    with pytest.raises(InputError, match="finite") as error:
        read_capture(path)
    assert error.value.field == key
    assert error.value.file == str(path)


def test_planar_rgb_tiff_reads_as_rgb_and_a_stack_is_refused(tmp_path, sidecar_data):
    import tifffile

    rgb = (np.arange(8 * 9 * 3, dtype=np.uint16) * 200).reshape(8, 9, 3)
    tifffile.imwrite(tmp_path / "planar.tif", np.moveaxis(rgb, -1, 0), photometric="rgb",
                     planarconfig="separate")
    path = tmp_path / "capture.json"
    path.write_text(json.dumps({**sidecar_data, "image": "planar.tif", "incident_px": [4, 4]}))
    np.testing.assert_array_equal(read_capture(path).pixels, rgb)
    tifffile.imwrite(tmp_path / "stack.tif", np.stack([rgb, rgb]), photometric="rgb")
    path.write_text(json.dumps({**sidecar_data, "image": "stack.tif", "incident_px": [4, 4]}))
    with pytest.raises(InputError, match="one image") as error:
        read_capture(path)
    assert error.value.field == "shape"


def test_a_sidecar_named_like_its_image_is_refused(tmp_path):
    spec = CaptureSpec(image="c.exr", pixel_size_mm=0.1, incident_px=(4, 4))
    with pytest.raises(InputError, match="would overwrite the image") as error:
        write_capture(tmp_path / "c.exr", np.ones((8, 8, 3)), spec)
    assert error.value.field == "image"
    assert not (tmp_path / "c.exr").exists()


def test_a_beam_wider_than_the_image_is_refused(write_sidecar, sidecar_data):
    # 32 x 32 pixels of 0.1 mm: the diagonal is 4.53 mm; 200 is a radius given in um
    path = write_sidecar({**sidecar_data, "beam_radius_mm": 200.0})
    with pytest.raises(InputError, match=r"at most the image's diagonal \(4.53 mm\)") as error:
        read_capture(path)
    assert error.value.field == "beam_radius_mm" and error.value.file == str(path)
    path = write_sidecar({**sidecar_data, "beam_radius_mm": 4.5})
    assert read_capture(path).spec.beam_radius_mm == 4.5
    assert read_capture(path).spec.beam_profile == "gaussian"  # the default
    path = write_sidecar({**sidecar_data, "beam_radius_mm": 1.0, "beam_profile": "top_hat"})
    assert read_capture(path).spec.beam_profile == "top_hat"
    spec = CaptureSpec(image="w.exr", pixel_size_mm=0.1, incident_px=(16, 16),
                       beam_radius_mm=200.0)
    with pytest.raises(InputError, match="at most the image's diagonal"):
        write_capture(path.with_name("w.json"), np.ones((32, 32, 3)), spec)
    assert not path.with_name("w.json").exists()


def test_a_16_bit_png_with_an_sbit_chunk_keeps_its_stored_codes(tmp_path, sidecar_data):
    # an sBIT chunk (12 significant bits, as cameras write) made the reader rescale the
    # codes to 12 bits, 16 times below the black and saturation levels of the sidecar
    import io
    import struct
    import zlib

    import png

    grey = (np.arange(64, dtype=np.uint16) * 1000).reshape(8, 8)
    buffer = io.BytesIO()
    png.Writer(8, 8, greyscale=True, bitdepth=16).write(buffer, grey)
    data = buffer.getvalue()
    chunk = b"sBIT" + bytes([12])
    sbit = struct.pack(">I", 1) + chunk + struct.pack(">I", zlib.crc32(chunk))
    header_end = 8 + 8 + 13 + 4  # signature, IHDR length and type, IHDR data, CRC
    (tmp_path / "s.png").write_bytes(data[:header_end] + sbit + data[header_end:])
    path = tmp_path / "s.json"
    path.write_text(json.dumps({**sidecar_data, "image": "s.png", "incident_px": [4, 4]}))
    np.testing.assert_array_equal(read_capture(path).pixels[..., 0], grey)
