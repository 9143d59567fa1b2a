"""Camera RAW photos, read linearly with LibRaw (rawpy): every colour at its own photosites.

A RAW file holds what the sensor counted, one colour per photosite behind its colour filter
array (CFA), before any demosaicing, white balance, tone curve or gamma: exactly the linear
signal a capture needs (docs/capture-format.md, "From a photo"). :func:`read_raw` returns it
as an image of the sensor's own size whose pixel holds its photosite's count in that
photosite's colour channel and NaN in the two others. No colour is interpolated: the fitter
masks NaN per channel, so each channel's annuli average only the photosites that measured
it, at their true positions and footprints, with independent noise (a demosaic would blur
each channel by its interpolation kernel and correlate neighbouring pixels' noise, which
the annuli's standard errors from their own scatter would not see).

* **Levels from the file.** LibRaw's black level of each CFA colour (DNG ``BlackLevel``, or
  the camera's masked pixels and maker notes) is subtracted photosite by photosite; the
  white level (per colour where the camera gives one) says where a photosite clipped. A
  file that states no black level (a DNG without ``BlackLevel``; any other RAW whose black
  levels LibRaw reports as 0 in every colour) is refused unless the black level is given.
* **Layouts.** Any CFA LibRaw decodes (Bayer 2 x 2, X-Trans 6 x 6) whose colours are R, G
  and B (both greens of a Bayer cell are G); a demosaiced "linear raw" DNG (three values a
  pixel); a monochrome sensor (one value a pixel, used for all three channels).
* **Orientation.** The image is the sensor's as stored (LibRaw's visible area), not turned
  by the camera's orientation flag: pixel coordinates (``--incident``, ``--ruler``) are the
  sensor's.

References: LibRaw (https://www.libraw.org), the ``raw_image_visible``,
``raw_colors_visible``, ``black_level_per_channel`` and ``white_level`` of rawpy; Adobe DNG
Specification 1.4, tags 33421-33422 (CFA), 50714 (BlackLevel), 50717 (WhiteLevel).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import InputError

__all__ = ["RAW_SUFFIXES", "RawMosaic", "read_raw"]

#: Camera RAW suffixes read through LibRaw.
RAW_SUFFIXES = (".dng", ".cr2", ".cr3", ".crw", ".nef", ".nrw", ".arw", ".srf", ".sr2",
                ".raf", ".orf", ".rw2", ".pef", ".srw", ".raw", ".rwl", ".3fr", ".iiq",
                ".erf", ".mef", ".mos", ".x3f", ".kdc", ".dcr")
#: The DNG tag that states the black level (Adobe DNG Specification 1.4).
DNG_BLACK_LEVEL_TAG = 50714
#: CFA colour letters LibRaw names, and the capture channel each one feeds.
CHANNEL_OF_COLOUR = {"R": 0, "G": 1, "B": 2}


@dataclass(frozen=True)
class RawMosaic:
    """A RAW photo's photosites (see the module docstring).

    Attributes
    ----------
    values : ndarray, shape (H, W, 3), float64
        Each photosite's raw count in its own colour channel; NaN in the other channels.
    black : ndarray, shape (H, W), float64
        The black level of each photosite, raw units.
    white : ndarray, shape (H, W), float64
        The raw count at and above which each photosite clipped.
    layout : str
        ``"CFA RGGB"`` (the repeating pattern's colours, row by row), ``"linear"`` or
        ``"monochrome"``.
    black_source : str
        Where the black level came from: ``"file"`` or ``"given"``.
    """

    values: np.ndarray
    black: np.ndarray
    white: np.ndarray
    layout: str
    black_source: str


def _rawpy():
    try:
        import rawpy
    except ImportError as error:  # a dependency; named, in case an environment lacks it
        raise InputError("reading camera RAW needs the rawpy package (pip install rawpy)",
                         field="photo", value="rawpy") from error
    return rawpy


def _dng_states_black_level(path: Path) -> bool:
    """Tell whether any image file directory of a DNG carries the BlackLevel tag."""
    import tifffile

    try:
        with tifffile.TiffFile(str(path)) as tiff:
            pages = list(tiff.pages)
            for page in list(pages):
                pages += [sub for sub in (getattr(page, "pages", None) or [])]
            return any(DNG_BLACK_LEVEL_TAG in page.tags for page in pages)
    except Exception:  # LibRaw read it; a TIFF reader that cannot is no reason to refuse
        return True


def _check_level(value, name, path, field):
    if value is None:
        return None
    value = float(value)
    if not (math.isfinite(value) and value >= 0):
        raise InputError("must be a finite number >= 0 (raw units)", file=path,
                         field=f"{name} (--{name.replace('_', '-')})", value=value)
    return value


def read_raw(path, field: str = "photo", *, black_level: float | None = None,
             white_level: float | None = None) -> RawMosaic:
    """Read a camera RAW file linearly: photosite counts per colour, black and white levels.

    Parameters
    ----------
    path : str or Path
        The RAW file (any format LibRaw decodes; see :data:`RAW_SUFFIXES`).
    field : str
        Named in errors (``"photo"``, ``"dark"``).
    black_level : float, optional
        Raw value of no light for every photosite, replacing the file's (needed when the
        file states none).
    white_level : float, optional
        Raw value at and above which a photosite clipped, replacing the file's.

    Returns
    -------
    RawMosaic

    Raises
    ------
    InputError
        A file LibRaw cannot read (an unknown sensor, not a RAW, damaged), a colour filter
        that is not R, G and B, a file that states no black level (without
        ``black_level``), or a white level not above the black level; each names the file,
        the field and the value.
    """
    from ..atomic import check_input_file

    path = Path(path)
    check_input_file(path, field, what="photo")  # a FIFO is refused before LibRaw waits on it
    black_level = _check_level(black_level, "black_level", path, field)
    white_level = _check_level(white_level, "white_level", path, field)
    rawpy = _rawpy()
    try:
        with rawpy.imread(str(path)) as raw:
            counts = np.array(raw.raw_image_visible, dtype=np.float64)
            colours = np.array(raw.raw_colors_visible) if counts.ndim == 2 else None
            description = raw.color_desc.decode("ascii", "replace")
            number = int(raw.num_colors)
            pattern = np.array(raw.raw_pattern) if raw.raw_pattern is not None else None
            file_black = np.array(raw.black_level_per_channel, dtype=np.float64)
            file_white = float(raw.white_level)
            per_colour_white = raw.camera_white_level_per_channel
    except rawpy.LibRawError as error:
        detail = error.args[0].decode() if error.args and isinstance(error.args[0], bytes) \
            else str(error)
        raise InputError(f"LibRaw cannot read this RAW file ({detail}): an unknown sensor, "
                         "not a RAW, or damaged", file=path, field=field,
                         value=path.suffix.lower()) from None
    height, width = counts.shape[:2]
    if min(height, width) < 8:
        raise InputError("must be at least 8 x 8 photosites", file=path, field=field,
                         value=[height, width])
    if black_level is None:
        stated = _dng_states_black_level(path) if path.suffix.lower() == ".dng" \
            else bool(np.any(file_black > 0))
        if not stated:
            raise InputError("the RAW file states no black level (the raw value of no "
                             "light): give it (--black-level, raw units)", file=path,
                             field="black level", value=file_black.tolist())
        black_source = "file"
    else:
        black_source = "given"
    white_of_colour = np.full(4, file_white)
    if per_colour_white is not None and all(v and v > 0 for v in per_colour_white):
        white_of_colour = np.array(per_colour_white, dtype=np.float64)
    if white_level is not None:
        white_of_colour = np.full(4, white_level)
    black_of_colour = np.full(4, black_level) if black_level is not None else file_black

    values = np.full((height, width, 3), np.nan)
    black = np.empty((height, width))
    white = np.empty((height, width))
    if counts.ndim == 3:  # a "linear raw": a value of every colour at every pixel
        layout = "linear"
        for index in range(min(counts.shape[2], len(description))):
            channel = _channel(description[index], description, path, field)
            if np.isnan(values[..., channel]).all():
                values[..., channel] = counts[..., index]
        if np.isnan(values).any():
            raise InputError("a linear raw needs R, G and B values", file=path, field=field,
                             value=description)
        # one black and white level a pixel: the channels of a linear raw share them here
        black[:] = float(np.max(black_of_colour[:3]))
        white[:] = float(np.min(white_of_colour[:3]))
    elif number == 1:
        layout = "monochrome"
        values[:] = counts[..., None]
        black[:] = black_of_colour[0]
        white[:] = white_of_colour[0]
    else:
        channel_of_index = np.array([_channel(letter, description, path, field)
                                     for letter in description])
        colours = np.clip(colours, 0, len(description) - 1)
        rows, cols = np.indices((height, width))
        values[rows, cols, channel_of_index[colours]] = counts
        black = black_of_colour[colours]
        white = white_of_colour[colours]
        letters = "".join(description[i] for i in pattern.ravel()) if pattern is not None \
            else "?"
        layout = f"CFA {letters}"
    if not np.all(white > black):
        raise InputError("the white level must lie above the black level in every colour",
                         file=path, field="white level",
                         value={"black": black_of_colour.tolist(),
                                "white": white_of_colour.tolist()})
    return RawMosaic(values, black, white, layout, black_source)


def _channel(letter: str, description: str, path: Path, field: str) -> int:
    """Return the capture channel of a CFA colour letter; :class:`InputError` unless R, G or B."""
    if letter not in CHANNEL_OF_COLOUR:
        raise InputError("the colour filter array is not red, green and blue (LibRaw names "
                         "its colours here)", file=path, field=f"{field} colours",
                         value=description)
    return CHANNEL_OF_COLOUR[letter]
