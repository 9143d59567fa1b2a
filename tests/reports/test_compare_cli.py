"""``translucent compare``: exit codes 0 / 1 / 2, the metrics table, error maps, bad input."""

import re

import numpy as np
import pytest
from translucent.image import Image, write_exr
from translucent.reports.cli import main
from translucent.reports.metrics.compute import compare

MAP_FILES = {f"test_{name}.{ext}" for name in ("flip", "relative_error", "ciede2000", "ssim")
             for ext in ("exr", "png")}


def gradient(height=24, width=32):
    y, x = np.mgrid[0:height, 0:width] / max(height, width)
    return np.stack([0.2 + x, 0.3 + y, 0.5 + x * y], axis=-1).astype(np.float32)


@pytest.fixture
def pair(tmp_path, rng):
    """REF.exr (with variance) and TEST.exr, 10 % multiplicative noise apart."""
    reference = gradient()
    test = reference * (1 + 0.1 * rng.standard_normal(reference.shape)).astype(np.float32)
    write_exr(tmp_path / "ref.exr", Image(reference, np.full_like(reference, 1e-4)))
    write_exr(tmp_path / "test.exr", Image(np.maximum(test, 0)))
    return tmp_path / "ref.exr", tmp_path / "test.exr"


def hdr_flip(pair):
    return compare(Image.read(pair[0]), Image.read(pair[1])).hdr_flip


def files(folder):
    return {path.name for path in folder.iterdir()}


# ----------------------------------------------------------------------------- thresholds


def test_within_threshold_exits_0_and_writes_maps_beside_the_test(pair, capsys):
    value = hdr_flip(pair)
    assert main(["compare", str(pair[0]), str(pair[1]), "--metric", "flip",
                 "--max", str(2 * value)]) == 0
    out = capsys.readouterr().out
    for name in ("hdr_flip", "ldr_flip", "relative_mse", "relative_mse_raw", "rmse", "psnr",
                 "ssim", "ciede2000"):
        assert f"\n{name} " in out
    assert "reference variance discounted" in out
    assert "ok" in out
    assert files(pair[1].parent) == {"ref.exr", "test.exr"} | MAP_FILES


def test_beyond_threshold_exits_1(pair, capsys):
    value = hdr_flip(pair)
    assert main(["compare", str(pair[0]), str(pair[1]), "--metric", "hdr-flip",
                 "--max", str(value / 2)]) == 1
    assert "FAIL" in capsys.readouterr().out


def test_bare_max_applies_to_hdr_flip(pair):
    value = hdr_flip(pair)
    assert main(["compare", str(pair[0]), str(pair[1]), "--max", str(value / 2),
                 "--no-maps"]) == 1
    assert files(pair[1].parent) == {"ref.exr", "test.exr"}


@pytest.mark.parametrize("bound, code", [("1", 0), ("1000", 1)])
def test_similarity_metrics_take_a_minimum(pair, bound, code):
    assert main(["compare", str(pair[0]), str(pair[1]), "--metric", "psnr", "--min", bound,
                 "--no-maps"]) == code


def test_maps_go_to_the_folder_given(pair, tmp_path):
    maps = tmp_path / "maps"
    assert main(["compare", str(pair[0]), str(pair[1]), "--maps", str(maps)]) == 0
    assert files(maps) == MAP_FILES


def test_identical_images_pass_any_error_bound(pair):
    assert main(["compare", str(pair[0]), str(pair[0]), "--metric", "rmse", "--max", "0",
                 "--no-maps"]) == 0


# ----------------------------------------------------------------------------- usage


@pytest.mark.parametrize("arguments, message", [
    (["--metric", "psnr", "--max", "3"], "psnr is a similarity .*give --min"),
    (["--metric", "rmse", "--min", "3"], "rmse is an error .*give --max"),
    (["--metric", "rmse", "--max", "nan"], "must be a finite number"),
    (["--metric", "mse"], "invalid choice: 'mse'"),
    (["--max", "1", "--min", "0"], "not allowed with argument"),
])
def test_bad_usage_exits_2_without_output(pair, arguments, message, capsys):
    assert main(["compare", str(pair[0]), str(pair[1]), *arguments]) == 2
    assert re.search(message, capsys.readouterr().err)
    assert files(pair[1].parent) == {"ref.exr", "test.exr"}


# ----------------------------------------------------------------------------- bad input


def write_without_rgb(path, foreign):
    foreign(path, {"Y": np.ones((24, 32), np.float32)})


def with_pixel(value):
    def write(path, foreign):  # write_exr refuses non-finite pixels
        rgb = gradient()
        rgb[3, 5, 1] = value
        foreign(path, rgb)
    return write


BAD_TESTS = {
    "missing": (lambda path, foreign: None, "no such file"),
    "corrupt": (lambda path, foreign: path.write_bytes(b"not an OpenEXR file\0" * 8),
                "not a readable OpenEXR file"),
    "no RGB": (write_without_rgb, r"channels = \['Y'\]: an RGB image needs channels R, G "
                                  r"and B"),
    "other size": (lambda path, foreign: write_exr(path, Image(gradient(24, 30))),
                   r"reference is 32 x 24 .* test is 30 x 24"),
    "NaN": (with_pixel(np.nan), r"pixels = nan: 1 pixel channels are NaN or Inf \(first at "
                                r"x=5, y=3, channel G\)"),
    "Inf": (with_pixel(np.inf), "pixels = inf: 1 pixel channels are NaN or Inf"),
}


@pytest.mark.parametrize("case", list(BAD_TESTS))
def test_bad_test_image_exits_2_without_output(pair, case, capsys, write_foreign_exr):
    write, message = BAD_TESTS[case]
    bad = pair[1].parent / "bad.exr"
    write(bad, write_foreign_exr)
    before = files(pair[1].parent)
    assert main(["compare", str(pair[0]), str(bad), "--metric", "flip", "--max", "1"]) == 2
    err = capsys.readouterr().err
    assert re.search(message, err), err
    if case not in ("other size",):
        assert "bad.exr" in err  # the message names the file
    assert files(pair[1].parent) == before  # nothing written, nothing half-written


def test_bad_reference_exits_2(pair, capsys):
    bad = pair[0].parent / "black.exr"
    write_exr(bad, Image(np.zeros((24, 32, 3), np.float32)))
    assert main(["compare", str(bad), str(pair[1])]) == 2
    assert "the reference is black" in capsys.readouterr().err
    assert not (pair[1].parent / "test_flip.png").exists()


# ----------------------------------------------------------------------------- error maps


def test_map_files_hold_the_maps(pair, tmp_path):
    from matplotlib.image import imread
    from translucent.reports.metrics.compute import evaluate
    from translucent.reports.metrics.maps import write_error_maps

    reference, test = Image.read(pair[0]), Image.read(pair[1])
    comparison = evaluate(reference, test)
    files = write_error_maps(reference, test, tmp_path / "maps", comparison=comparison)
    for name, written in files.items():
        stored = Image.read(written.exr)
        assert stored.metadata["map"] == name
        assert np.array_equal(stored.rgb[..., 0], comparison.maps[name].astype(np.float32))
        assert imread(written.png).shape[:2] == (24, 32)


def test_linear_png_is_srgb_encoded(tmp_path):
    from matplotlib.image import imread
    from translucent.reports.metrics.maps import write_linear_png

    rgb = np.zeros((2, 3, 3), np.float32)
    rgb[0, 0], rgb[0, 1], rgb[0, 2] = 4.0, 2.0, 8.0  # white, half, beyond white
    pixels = imread(write_linear_png(tmp_path / "image.png", rgb, white=4.0))
    # sRGB of 0.5 is 0.7354 (IEC 61966-2-1): 188 of 255
    assert np.round(pixels[0, :, 0] * 255).tolist() == [255, 188, 255]
    assert pixels[1, :, :3].max() == 0


def test_a_failure_while_writing_leaves_no_maps(pair, tmp_path, monkeypatch):
    from translucent.reports.metrics import maps as error_maps

    calls = []
    original = error_maps.write_png

    def fail_on_the_third(path, pixels):
        calls.append(path)
        if len(calls) == 3:
            raise OSError("disk full")
        return original(path, pixels)

    monkeypatch.setattr(error_maps, "write_png", fail_on_the_third)
    with pytest.raises(OSError, match="disk full"):
        error_maps.write_error_maps(Image.read(pair[0]), Image.read(pair[1]), tmp_path / "maps")
    assert list((tmp_path / "maps").iterdir()) == []


def test_unknown_map_name_lists_the_valid_ones(tmp_path):
    from translucent.errors import InputError
    from translucent.reports.metrics.maps import write_map

    with pytest.raises(InputError, match="name = 'blur': unknown map; valid: flip, "
                                         "relative_error, ciede2000, ssim, p_value"):
        write_map(tmp_path, "x", np.zeros((2, 2)), "blur")


def test_maps_and_no_maps_together_are_bad_usage(pair, tmp_path, capsys):
    assert main(["compare", str(pair[0]), str(pair[1]), "--no-maps", "--maps",
                 str(tmp_path / "maps")]) == 2
    assert "not allowed with" in capsys.readouterr().err
    assert not (tmp_path / "maps").exists()


def test_each_metric_is_printed_beside_its_noise_floor_and_verdict(tmp_path, capsys, rng):
    truth = gradient()
    sigma = 0.03 * truth
    noisy = truth + sigma * rng.standard_normal(truth.shape).astype(np.float32)
    write_exr(tmp_path / "ref.exr", Image(noisy, sigma**2))
    write_exr(tmp_path / "perfect.exr", Image(truth))
    write_exr(tmp_path / "off.exr", Image(1.3 * truth))
    assert main(["compare", str(tmp_path / "ref.exr"), str(tmp_path / "perfect.exr"),
                 "--no-maps"]) == 0
    out = capsys.readouterr().out
    assert "noise floor" in out
    rows = {line.split()[0]: line for line in out.splitlines() if line[:1].isalpha()}
    for name in ("hdr_flip", "ldr_flip", "rmse", "ciede2000", "ssim", "psnr"):
        assert "within reference noise" in rows[name], rows[name]
    assert main(["compare", str(tmp_path / "ref.exr"), str(tmp_path / "off.exr"),
                 "--no-maps"]) == 0
    rows = {line.split()[0]: line for line in capsys.readouterr().out.splitlines()
            if line[:1].isalpha()}
    for name in ("hdr_flip", "relative_mse", "rmse", "ciede2000", "psnr"):
        assert " resolved " in rows[name], rows[name]


def test_a_noisy_reference_is_warned_about(tmp_path, capsys):
    truth = gradient()
    write_exr(tmp_path / "ref.exr", Image(truth, (0.2 * truth) ** 2))
    write_exr(tmp_path / "test.exr", Image(truth))
    assert main(["compare", str(tmp_path / "ref.exr"), str(tmp_path / "test.exr"),
                 "--no-maps"]) == 0
    err = capsys.readouterr().err
    assert "warning: the reference is noisy: median 20 %" in err


def test_a_reference_without_variance_has_no_floor(tmp_path, capsys):
    write_exr(tmp_path / "ref.exr", Image(gradient()))
    write_exr(tmp_path / "test.exr", Image(gradient() * 1.1))
    assert main(["compare", str(tmp_path / "ref.exr"), str(tmp_path / "test.exr"),
                 "--no-maps"]) == 0
    assert "no floor (no variance)" in capsys.readouterr().out
