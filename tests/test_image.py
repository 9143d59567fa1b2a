import numpy as np
import pytest
from translucent.errors import InputError
from translucent.image import Image, read_exr, write_exr


def test_round_trip_is_lossless(tmp_path, rng):
    image = Image(rng.random((5, 7, 3)), rng.random((5, 7, 3)) * 1e-3,
                  {"producer": "test", "spp": 16, "knobs": {"terms": 12}, "seconds": 0.5})
    path = image.write(tmp_path / "a.exr")
    back = read_exr(path)
    assert np.array_equal(back.rgb, image.rgb)
    assert np.array_equal(back.variance, image.variance)
    assert back.metadata == image.metadata


def test_without_variance(tmp_path, rng):
    path = Image(rng.random((2, 3, 3))).write(tmp_path / "b.exr")
    assert read_exr(path).variance is None


def test_missing_file(tmp_path):
    with pytest.raises(InputError, match="no such file"):
        read_exr(tmp_path / "nothing.exr")


def test_corrupt_file(tmp_path):
    path = tmp_path / "corrupt.exr"
    path.write_bytes(b"not an exr at all")
    with pytest.raises(InputError, match="corrupt.exr: not a readable OpenEXR"):
        read_exr(path)


def test_no_rgb_channels(tmp_path, write_foreign_exr):
    path = write_foreign_exr(tmp_path / "depth.exr", {"Z": np.zeros((4, 4), np.float32)})
    with pytest.raises(InputError, match=r"depth.exr: channels = \['Z'\]: an RGB image needs"):
        read_exr(path)


def test_nan_pixels_rejected_on_read(tmp_path, write_foreign_exr):
    rgb = np.ones((4, 4, 3), np.float32)
    rgb[2, 1, 0] = np.nan
    path = write_foreign_exr(tmp_path / "nan.exr", rgb)
    with pytest.raises(InputError, match="1 pixel channels are NaN or Inf .first at x=1, y=2"):
        read_exr(path)


def test_shape_checked():
    with pytest.raises(InputError, match="H x W x 3"):
        Image(np.zeros((4, 4)))
    with pytest.raises(InputError, match="variance"):
        Image(np.zeros((4, 4, 3)), np.zeros((4, 3, 3)))


def test_failed_write_leaves_nothing(tmp_path, monkeypatch):
    import OpenEXR

    def broken_write(self, path):
        with open(path, "wb") as handle:
            handle.write(b"half")
        raise OSError("disk full")

    monkeypatch.setattr(OpenEXR.File, "write", broken_write)
    with pytest.raises(OSError):
        write_exr(tmp_path / "out.exr", Image(np.zeros((2, 2, 3))))
    assert list(tmp_path.iterdir()) == []


def test_numpy_metadata_is_written_as_plain_numbers(tmp_path):
    metadata = {"spp": np.int64(4), "white": np.float32(0.5),
                "knobs": {"terms": np.int32(12), "range": np.arange(3)}}
    path = Image(np.ones((2, 2, 3)), metadata=metadata).write(tmp_path / "n.exr")
    assert read_exr(path).metadata == {"spp": 4, "white": 0.5,
                                       "knobs": {"terms": 12, "range": [0, 1, 2]}}


def test_an_empty_image_is_refused_on_construction():
    for shape in ((0, 4, 3), (4, 0, 3)):
        with pytest.raises(InputError, match=r"rgb = \(.*\): an image needs at least one pixel"):
            Image(np.zeros(shape))


def test_a_metadata_key_named_metadata_does_not_hide_the_others(tmp_path):
    metadata = {"metadata": {"note": "nested"}, "spp": 4}
    path = Image(np.ones((2, 2, 3)), metadata=metadata).write(tmp_path / "m.exr")
    assert read_exr(path).metadata == metadata


def _tamper(path, change):
    """Rewrite an EXR with its header kept and its pixels changed by ``change``."""
    import OpenEXR

    with OpenEXR.File(str(path), separate_channels=True) as exr:
        header = dict(exr.header())
        channels = {name: np.array(ch.pixels) for name, ch in exr.channels().items()}
    change(channels)
    with OpenEXR.File(header, channels) as exr:
        exr.write(str(path))


@pytest.mark.parametrize("change", [
    lambda c: c["R"].fill(0.0),                        # zeroed pixels
    lambda c: c["variance.G"].__setitem__((0, 0), 9),  # one variance value
])
def test_pixels_changed_after_writing_are_refused(tmp_path, change):
    from translucent.image import CHECKSUM_ATTRIBUTE

    path = tmp_path / "image.exr"
    rgb = np.random.default_rng(1).uniform(0.1, 1.0, (6, 5, 3))
    Image(rgb, 0.01 * rgb, {"producer": "test"}).write(path)
    assert read_exr(path).metadata == {"producer": "test"}  # intact: read as written
    _tamper(path, change)
    with pytest.raises(InputError, match="do not match the checksum") as caught:
        read_exr(path)
    assert caught.value.field == CHECKSUM_ATTRIBUTE and str(path) in str(caught.value)


def test_an_exr_without_checksum_is_read(tmp_path, write_foreign_exr):
    rgb = np.full((4, 4, 3), 0.5, dtype=np.float32)
    path = write_foreign_exr(tmp_path / "foreign.exr", rgb)
    np.testing.assert_array_equal(read_exr(path).rgb, rgb)


@pytest.mark.parametrize("plane", ["pixels", "variance"])
@pytest.mark.parametrize("bad", [float("nan"), float("inf")])
def test_a_non_finite_image_is_refused_and_nothing_is_written(tmp_path, plane, bad):
    rgb, variance = np.ones((3, 4, 3), np.float32), np.ones((3, 4, 3), np.float32)
    (rgb if plane == "pixels" else variance)[2, 1, 0] = bad
    path = tmp_path / "out.exr"
    with pytest.raises(InputError, match=r"1 channels are NaN or Inf \(first at x=1, y=2, "
                                         r"channel R\)") as caught:
        write_exr(path, Image(rgb, variance))
    assert caught.value.field == plane and str(path) in str(caught.value)
    assert not any(tmp_path.iterdir())
