"""Error maps on disk: EXR for tools, colour-mapped sRGB PNG for people.

Every map is written twice, atomically (:mod:`translucent.atomic`): ``NAME.exr`` holds the
values themselves (the scalar map repeated in R, G and B, with the map's name, unit and
range in the header metadata) through :mod:`translucent.image`; ``NAME.png`` shows them
through a matplotlib colour map over a fixed range (``MAP_STYLES``), so that maps of
different runs can be compared by eye. Brighter is always worse.

:func:`write_error_maps` writes the maps of a (reference, test) pair;
:func:`write_z_test_maps` those of a failed statistical test; :func:`write_linear_png`
turns a linear HDR image into a PNG a person can look at (the report uses it).
"""

from __future__ import annotations

import contextlib
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ...atomic import atomic_path
from ...errors import InputError
from ...image import Image
from .compute import Comparison, display_white, evaluate, to_display

__all__ = ["ERROR_MAPS", "error_map_paths", "MAP_STYLES", "MapStyle", "ErrorMapFiles",
           "NOT_SCORED_GREYS", "colour_map", "hatch_not_scored", "srgb8", "write_png",
           "write_linear_png", "write_map", "write_error_maps", "write_z_test_maps"]


@dataclass(frozen=True)
class MapStyle:
    """How a map is shown to a person.

    Parameters
    ----------
    colormap : str
        A matplotlib colour map name.
    vmin, vmax : float
        Values mapped to the two ends of the colour map (clipped beyond).
    unit : str
        What the values are, for the EXR header and the report's legend.
    """

    colormap: str
    vmin: float
    vmax: float
    unit: str


#: map name -> how it is shown. FLIP is in [0, 1] and shown with magma as its authors do;
#: relative error saturates at 100 %; CIEDE2000 at 10 (about 5 just-noticeable
#: differences); SSIM runs from 1 (identical, dark) down to 0 (bright) with magma reversed;
#: the z-test shows -log10 p up to 10 (p = 1e-10, beyond any Sidak alpha of a
#: sub-gigapixel image).
MAP_STYLES: dict[str, MapStyle] = {
    "flip": MapStyle("magma", 0.0, 1.0, "HDR-FLIP error, 0 to 1"),
    "relative_error": MapStyle("viridis", 0.0, 1.0, "relative RMS error over channels"),
    "ciede2000": MapStyle("magma", 0.0, 10.0, "CIEDE2000 delta E of the display images"),
    "ssim": MapStyle("magma_r", 0.0, 1.0, "SSIM of the display images (1 is identical)"),
    "p_value": MapStyle("magma", 0.0, 10.0, "-log10 of the two-sided z-test p-value"),
}


@dataclass(frozen=True)
class ErrorMapFiles:
    """The two files of one map.

    Parameters
    ----------
    exr : Path
        The values (for tools).
    png : Path
        The colour-mapped picture (for people).
    """

    exr: Path
    png: Path


#: The two greys of the hatching that marks pixels a map does not score (sRGB, 8 bit), and
#: the period of its diagonal stripes in pixels.
NOT_SCORED_GREYS = (96, 160)
NOT_SCORED_PERIOD = 4


def hatch_not_scored(rgb: np.ndarray, scored) -> np.ndarray:
    """Draw grey diagonal stripes over the pixels outside ``scored`` (a copy).

    The report scores a method on the pixels of the objects it renders; its maps show the
    others hatched, so that what a map shows and what its numbers count are the same pixels.

    Examples
    --------
    >>> rgb = np.zeros((2, 4, 3), np.uint8)
    >>> hatched = hatch_not_scored(rgb, np.array([[True] * 4, [True, True, False, False]]))
    >>> int(hatched[0].max()), sorted(set(hatched[1, 2:, 0].tolist())) <= list(NOT_SCORED_GREYS)
    (0, True)
    """
    out = np.array(rgb, copy=True)
    if scored is None:
        return out
    scored = np.asarray(scored, dtype=bool)
    rows, columns = np.indices(scored.shape)
    stripe = ((rows + columns) // (NOT_SCORED_PERIOD // 2)) % 2
    greys = np.asarray(NOT_SCORED_GREYS, dtype=np.uint8)[stripe]
    out[~scored] = greys[~scored][:, None]
    return out


def colour_map(values, style: MapStyle) -> np.ndarray:
    """Colour-map a scalar map for a person.

    Parameters
    ----------
    values : array_like, shape (H, W)
        The map.
    style : MapStyle
        Colour map and range; values beyond are clipped, NaN is shown black.

    Returns
    -------
    ndarray, shape (H, W, 3), uint8
        sRGB pixels.
    """
    from matplotlib import colormaps

    values = np.asarray(values, dtype=np.float64)
    scaled = (values - style.vmin) / (style.vmax - style.vmin)
    rgba = colormaps[style.colormap](np.clip(np.nan_to_num(scaled, nan=0.0), 0.0, 1.0))
    rgb = np.round(rgba[..., :3] * 255).astype(np.uint8)
    rgb[np.isnan(values)] = 0
    return rgb


def srgb8(rgb, *, white: float | None = None) -> np.ndarray:
    """Tone-map linear radiance to 8-bit sRGB for a person.

    The exposure of the perceptual metrics (:func:`translucent.reports.metrics.to_display`):
    divide by ``white``, clip to [0, 1], sRGB-encode (IEC 61966-2-1), quantise.

    Parameters
    ----------
    rgb : array_like, shape (H, W, 3)
        Linear radiance.
    white : float, optional
        Radiance shown as white; default the image's own
        :func:`~translucent.reports.metrics.display_white`. Pass the reference's white to
        show a test image with the reference's exposure.

    Returns
    -------
    ndarray, shape (H, W, 3), uint8
    """
    rgb = np.asarray(rgb, dtype=np.float64)
    white = display_white(rgb) if white is None else white
    return np.round(np.nan_to_num(to_display(rgb, white)) * 255).astype(np.uint8)


def write_png(path, pixels) -> Path:
    """Write 8-bit sRGB pixels as a PNG, atomically.

    Parameters
    ----------
    path : str or PathLike
        The target file.
    pixels : ndarray, shape (H, W, 3), uint8
        sRGB pixels.

    Returns
    -------
    Path
    """
    from matplotlib.image import imsave

    pixels = np.asarray(pixels)
    if pixels.dtype != np.uint8 or pixels.ndim != 3 or pixels.shape[2] != 3:
        raise InputError("a PNG needs H x W x 3 uint8 pixels", field="pixels",
                         value=(pixels.shape, str(pixels.dtype)))
    path = Path(path)
    with atomic_path(path) as tmp:
        imsave(tmp, pixels, format="png")
    return path


def write_linear_png(path, image, *, white: float | None = None) -> Path:
    """Write a linear HDR image as an sRGB PNG for a person (see :func:`srgb8`).

    Parameters
    ----------
    path : str or PathLike
        The target ``.png``.
    image : Image or array_like, shape (H, W, 3)
        Linear radiance.
    white : float, optional
        Radiance shown as white; default the image's own display white.

    Returns
    -------
    Path
    """
    rgb = image.rgb if isinstance(image, Image) else image
    return write_png(path, srgb8(rgb, white=white))


def write_map(folder, stem: str, values, name: str, *, scored=None,
              **metadata) -> ErrorMapFiles:
    """Write one scalar map as ``STEM.exr`` (values) and ``STEM.png`` (colour-mapped).

    Parameters
    ----------
    folder : str or PathLike
        Where (created if missing).
    stem : str
        File name without extension.
    values : array_like, shape (H, W)
        The map.
    name : str
        A key of ``MAP_STYLES``.
    scored : array_like of bool, shape (H, W), optional
        The pixels the map's numbers count: the PNG hatches the others in grey
        (:func:`hatch_not_scored`); the EXR keeps every value and says how many were scored.
    **metadata
        Extra JSON-serialisable header entries.

    Returns
    -------
    ErrorMapFiles
    """
    if name not in MAP_STYLES:
        raise InputError(f"unknown map; valid: {', '.join(MAP_STYLES)}", field="name",
                         value=name)
    style = MAP_STYLES[name]
    values = np.asarray(values, dtype=np.float32)
    folder = Path(folder)
    if scored is not None:
        metadata["scored_pixels"] = int(np.count_nonzero(scored))
        metadata["png_not_scored"] = "hatched grey"
    exr = Image(np.repeat(values[..., None], 3, axis=2),
                metadata={"map": name, "unit": style.unit, "png_range": [style.vmin, style.vmax],
                          "colormap": style.colormap, **metadata}).write(folder / f"{stem}.exr")
    with _all_or_nothing([exr]):
        png = write_png(folder / f"{stem}.png",
                        hatch_not_scored(colour_map(values, style), scored))
    return ErrorMapFiles(exr, png)


@contextlib.contextmanager
def _all_or_nothing(written: list[Path]):
    """Remove the files already written when a later one fails: no partial set is left."""
    try:
        yield
    except BaseException:
        for path in written:
            with contextlib.suppress(FileNotFoundError):
                path.unlink()
        raise


#: The maps :func:`write_error_maps` writes (the maps of
#: :func:`translucent.reports.metrics.evaluate`).
ERROR_MAPS = ("flip", "relative_error", "ciede2000", "ssim")


def error_map_paths(folder, prefix: str = "") -> list[Path]:
    """Return the files :func:`write_error_maps` writes into ``folder``: named before any work."""
    return [Path(folder) / f"{prefix}{name}{suffix}" for name in ERROR_MAPS
            for suffix in (".exr", ".png")]


def write_error_maps(reference: Image, test: Image, folder, *, prefix: str = "",
                     comparison: Comparison | None = None, scored=None,
                     scored_metrics=None) -> dict[str, ErrorMapFiles]:
    """Write the FLIP, relative-error, CIEDE2000 and SSIM maps of ``test`` against ``reference``.

    Files are ``PREFIXflip``, ``PREFIXrelative_error``, ``PREFIXciede2000`` and
    ``PREFIXssim``, each ``.exr`` and ``.png``; the maps are defined in
    :func:`translucent.reports.metrics.evaluate`. Everything is computed before the first
    file is written, and a failure while writing removes what was written.

    Parameters
    ----------
    reference, test : Image
        The pair (reference first).
    folder : str or PathLike
        Where (created if missing).
    prefix : str
        Put before each file name (``"scene_prt_"``).
    comparison : Comparison, optional
        The result of ``evaluate(reference, test)`` when already computed.
    scored : array_like of bool, shape (H, W), optional
        The pixels the numbers beside the maps count (a method's own objects): the others
        are hatched grey in the PNGs.
    scored_metrics : Metrics, optional
        The metrics over ``scored``: the headers' means are theirs.

    Returns
    -------
    dict of str to ErrorMapFiles
        Map name -> its two files.
    """
    comparison = evaluate(reference, test) if comparison is None else comparison
    metrics = comparison.metrics if scored_metrics is None else scored_metrics
    written: list[Path] = []
    files: dict[str, ErrorMapFiles] = {}
    with _all_or_nothing(written):
        for name, values in comparison.maps.items():
            mean_value = {"flip": metrics.hdr_flip, "ssim": metrics.ssim,
                          "ciede2000": metrics.ciede2000}.get(name)
            files[name] = write_map(folder, f"{prefix}{name}", values, name, scored=scored,
                                    mean=mean_value, display_white=metrics.display_white)
            written += [files[name].exr, files[name].png]
    return files


def write_z_test_maps(result, folder, *, prefix: str = "", test=None,
                      reference=None) -> dict[str, Path]:
    """Write what a person needs to see why a z-test failed.

    ``PREFIXp_value.exr`` holds the per-channel p-values (R, G, B); ``PREFIXp_value.png``
    shows -log10 of the smallest p over the channels; ``PREFIXrejected.png`` marks the
    rejected pixels red over the dimmed test image (white where no test image is given).
    With ``test`` and ``reference`` also ``PREFIXtest.exr``/``.png``,
    ``PREFIXreference.exr``/``.png`` and ``PREFIXdifference.exr`` (test - reference).

    Parameters
    ----------
    result : ZTestResult
        From :func:`translucent.reports.metrics.statistics.z_test`.
    folder : str or PathLike
        Where (created if missing).
    prefix : str
        Put before each file name.
    test, reference : Image or array_like, shape (H, W, 3), optional
        The images tested.

    Returns
    -------
    dict of str to Path
        Name -> file.
    """
    folder = Path(folder)
    p_values = np.asarray(result.p_values, dtype=np.float64)
    written: list[Path] = []
    paths: dict[str, Path] = {}
    with _all_or_nothing(written):
        channels = p_values if p_values.shape[2] == 3 else np.repeat(
            p_values[..., :1], 3, axis=2)
        paths["p_value.exr"] = Image(channels, metadata={
            "map": "p_value", "alpha": result.alpha, "summary": result.summary()}).write(
            folder / f"{prefix}p_value.exr")
        written.append(paths["p_value.exr"])
        smallest = np.nanmin(np.where(np.isnan(p_values), 0.0, p_values), axis=2)
        minus_log_p = -np.log10(np.maximum(smallest, 1e-300))
        paths["p_value.png"] = write_png(folder / f"{prefix}p_value.png",
                                         colour_map(minus_log_p, MAP_STYLES["p_value"]))
        written.append(paths["p_value.png"])
        rejected = ~np.all(result.accepted, axis=2)
        if test is None:
            base = np.full(rejected.shape + (3,), 255, np.uint8)
        else:
            exposure = display_white(_rgb(test if reference is None else reference))
            base = srgb8(_rgb(test), white=exposure) // 3
        base[rejected] = (255, 0, 0)
        paths["rejected.png"] = write_png(folder / f"{prefix}rejected.png", base)
        written.append(paths["rejected.png"])
        if test is not None and reference is not None:
            test_rgb, reference_rgb = _rgb(test), _rgb(reference)
            white = display_white(reference_rgb)
            for name, rgb in (("test", test_rgb), ("reference", reference_rgb)):
                paths[f"{name}.exr"] = Image(rgb).write(folder / f"{prefix}{name}.exr")
                written.append(paths[f"{name}.exr"])
                paths[f"{name}.png"] = write_linear_png(folder / f"{prefix}{name}.png", rgb,
                                                        white=white)
                written.append(paths[f"{name}.png"])
            paths["difference.exr"] = Image(test_rgb - reference_rgb).write(
                folder / f"{prefix}difference.exr")
            written.append(paths["difference.exr"])
    return paths


def _rgb(image) -> np.ndarray:
    return image.rgb if isinstance(image, Image) else np.asarray(image, dtype=np.float32)
