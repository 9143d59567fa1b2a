"""Linear HDR images with metadata, stored as OpenEXR.

An :class:`Image` is what every renderer in the suite returns: the reference path tracer
and each fast method. Radiance is linear (no sRGB, no tone mapping), float32,
``H x W x 3``; the per-pixel variance of the *mean* is kept where the producer knows it
(independent passes of a reference render).
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from .atomic import atomic_path
from .errors import InputError

__all__ = ["Image", "pixel_checksum", "read_exr", "read_exr_header", "write_exr"]

#: Rec. 709 / linear-sRGB luminance weights (the Y row of the sRGB -> XYZ matrix).
LUMINANCE_WEIGHTS = np.array([0.2126, 0.7152, 0.0722])

#: Header attribute holding the metadata as JSON (read back losslessly).
METADATA_ATTRIBUTE = "translucent:metadata"

#: Header attribute holding the SHA-256 of the pixels as written (:func:`pixel_checksum`):
#: a file whose pixels were changed or damaged after it was written is refused on reading.
CHECKSUM_ATTRIBUTE = "translucent:pixels_sha256"


def pixel_checksum(rgb, variance=None) -> str:
    """Return the SHA-256 of an image's float32 pixels (and variance), as hex.

    Parameters
    ----------
    rgb : array_like, shape (H, W, 3)
    variance : array_like, shape (H, W, 3), optional
    """
    import hashlib

    digest = hashlib.sha256()
    for array in (rgb, variance):
        if array is not None:
            array = np.ascontiguousarray(array, dtype=np.float32)
            digest.update(str(array.shape).encode())
            digest.update(array.tobytes())
    return digest.hexdigest()


@dataclass(frozen=True)
class Image:
    """A linear HDR RGB image with provenance.

    Parameters
    ----------
    rgb : ndarray, shape (H, W, 3), float32
        Linear radiance (W sr^-1 m^-2 in the scene's units; relative where the lights are).
    variance : ndarray, shape (H, W, 3), optional
        Variance of the estimate of the mean in each pixel channel (the squared standard
        error), where known.
    metadata : dict
        JSON-serialisable provenance: ``producer`` (``"reference"``, ``"prt"``, ...),
        ``knobs``, ``seconds``, ``spp``, ``passes``, ``scene_hash``, ``variant``, ...
    """

    rgb: np.ndarray
    variance: np.ndarray | None = None
    metadata: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self):
        rgb = np.ascontiguousarray(self.rgb, dtype=np.float32)
        if rgb.ndim != 3 or rgb.shape[2] != 3:
            raise InputError("an image must be H x W x 3", field="rgb", value=rgb.shape)
        if rgb.size == 0:
            raise InputError("an image needs at least one pixel (H, W >= 1)", field="rgb",
                             value=rgb.shape)
        object.__setattr__(self, "rgb", rgb)
        if self.variance is not None:
            variance = np.ascontiguousarray(self.variance, dtype=np.float32)
            if variance.shape != rgb.shape:
                raise InputError(f"must have the shape of rgb {rgb.shape}", field="variance",
                                 value=variance.shape)
            object.__setattr__(self, "variance", variance)
        object.__setattr__(self, "metadata", dict(self.metadata))

    @property
    def shape(self) -> tuple[int, int]:
        """``(H, W)`` in pixels."""
        return self.rgb.shape[:2]

    def with_metadata(self, **items) -> Image:
        """Return a copy whose metadata is updated with ``items``."""
        return replace(self, metadata={**self.metadata, **items})

    def write(self, path) -> Path:
        """Write as OpenEXR (see :func:`write_exr`) and return the path."""
        return write_exr(path, self)

    @classmethod
    def read(cls, path) -> Image:
        """Read an OpenEXR written by :func:`write_exr` or any RGB EXR (see :func:`read_exr`)."""
        return read_exr(path)


def _json_default(value):
    """JSON for what ``json`` cannot encode: numpy scalars and arrays as numbers, else str."""
    if isinstance(value, (np.generic, np.ndarray)):
        return value.tolist()
    return str(value)


def _header_value(value):
    """Header attributes OpenEXR can hold natively (str, int, float); JSON otherwise."""
    if isinstance(value, np.generic):
        value = value.item()
    if isinstance(value, bool):
        return int(value)
    if isinstance(value, (str, int)):
        return value
    if isinstance(value, float) and math.isfinite(value):
        return value
    return json.dumps(value, sort_keys=True, default=_json_default)


def _refuse_non_finite(plane, noun: str, tail: str, *, file, field: str) -> None:
    """Raise InputError naming how many channels of ``plane`` are NaN or Inf, and the first."""
    if plane is None:
        return
    bad = ~np.isfinite(plane)
    if bad.any():
        y, x, c = np.argwhere(bad)[0]
        raise InputError(f"{int(bad.sum())} {noun} are NaN or Inf (first at x={x}, y={y}, "
                         f"channel {'RGB'[c]}){tail}", file=file, field=field,
                         value=float(plane[y, x, c]))


def write_exr(path, image: Image) -> Path:
    """Write ``image`` to ``path`` as a ZIP-compressed float32 OpenEXR, atomically.

    Channels ``R, G, B`` hold the radiance, ``variance.R, variance.G, variance.B`` the
    variance where known. The metadata go into the header twice: as one JSON attribute
    (read back losslessly) and as individual ``translucent:KEY`` attributes for tools. The
    pixels' SHA-256 (:func:`pixel_checksum`) goes into ``translucent:pixels_sha256``, which
    :func:`read_exr` checks.
    """
    import OpenEXR

    if not isinstance(image, Image):
        raise InputError("expected an Image", file=path, field="image", value=type(image))
    # a NaN image is never written: read_exr refuses it, so it could only mislead
    for name, plane in (("pixels", image.rgb), ("variance", image.variance)):
        _refuse_non_finite(plane, "channels", "; nothing was written", file=path, field=name)
    channels = {"RGB": image.rgb}
    if image.variance is not None:
        for index, name in enumerate("RGB"):
            channels[f"variance.{name}"] = np.ascontiguousarray(image.variance[..., index])
    header = {f"translucent:{key}": _header_value(value)
              for key, value in image.metadata.items()}
    # after the per-key attributes, so that a key named "metadata" cannot replace it
    header.update({
        "compression": OpenEXR.ZIP_COMPRESSION,
        "type": OpenEXR.scanlineimage,
        METADATA_ATTRIBUTE: json.dumps(image.metadata, sort_keys=True,
                                       default=_json_default),
        CHECKSUM_ATTRIBUTE: pixel_checksum(image.rgb, image.variance),
    })
    path = Path(path)
    with atomic_path(path) as tmp, OpenEXR.File(header, channels) as exr:
        exr.write(str(tmp))
    return path


#: Bytes a declared pixel costs :func:`read_exr` per channel it keeps: the decoded plane,
#: its float32 copy and the stacked image (4 bytes each), and room for the checks' masks.
READ_BYTES_PER_SAMPLE = 16

#: The deepest nesting the metadata JSON may have (the suite writes 3 or 4 levels).
MAX_METADATA_DEPTH = 64

#: The channels :func:`read_exr` keeps.
_CHANNELS = ("R", "G", "B", "variance.R", "variance.G", "variance.B")


def _declared_size(path: Path, header: dict) -> tuple[int, int]:
    """Return ``(height, width)`` of the header's data window; refuse an empty one."""
    try:
        (x_min, y_min), (x_max, y_max) = (np.asarray(corner, dtype=np.int64)
                                          for corner in header["dataWindow"])
    except (KeyError, TypeError, ValueError) as error:
        raise InputError("the header has no usable dataWindow", file=path,
                         field="dataWindow") from error
    height, width = int(y_max - y_min + 1), int(x_max - x_min + 1)
    if height < 1 or width < 1:
        raise InputError("the data window holds no pixel", file=path, field="dataWindow",
                         value=[int(x_min), int(y_min), int(x_max), int(y_max)])
    return height, width


def read_exr_header(path, channels=_CHANNELS, *, field: str = "path",
                    bytes_per_sample: int = READ_BYTES_PER_SAMPLE) -> tuple[Path, dict]:
    """Read an EXR's header and refuse, from it alone, a file that cannot be read whole.

    Parameters
    ----------
    path : str or PathLike
    channels : sequence of str
        The channels the caller will read: each must have a sample per pixel.
    field : str
        What the message calls ``path`` when it is missing or a folder.
    bytes_per_sample : int
        Memory the caller takes per declared pixel and channel it reads.

    Returns
    -------
    path : Path
    header : dict
        With ``"size"``: the data window's ``(height, width)``.

    Raises
    ------
    InputError
        A missing file or a folder, no readable EXR, an empty data window, a subsampled
        channel, or more declared pixels than the machine can hold
        (:func:`translucent.resources.check_memory`), before any pixel is read.
    """
    import OpenEXR

    from .atomic import check_input_file
    from .resources import check_memory

    path = check_input_file(path, field)
    try:
        with OpenEXR.File(str(path), header_only=True) as exr:
            header = dict(exr.header())
    except Exception as error:  # OpenEXR raises bare exceptions on corrupt files
        raise InputError(f"not a readable OpenEXR file ({error})", file=path) from error
    height, width = _declared_size(path, header)
    found = header.get("channels") or []
    for channel in found:
        sampling = (getattr(channel, "xSampling", 1), getattr(channel, "ySampling", 1))
        if channel.name in channels and sampling != (1, 1):
            raise InputError(f"is subsampled ({sampling[0]} x {sampling[1]}); every channel "
                             "read must have a sample per pixel", file=path,
                             field=f"channel {channel.name}", value=list(sampling))
    kept = sum(1 for channel in found if channel.name in channels) or 3
    check_memory(height * width * kept * bytes_per_sample,
                 what=f"reading a {width} x {height} image", file=path, field="dataWindow",
                 value=f"{width} x {height}")
    header["size"] = (height, width)
    return path, header


def check_planes(path, planes: dict, size: tuple[int, int]) -> None:
    """Refuse channel planes whose shape is not the data window's ``size`` (H, W)."""
    height, width = size
    for name, plane in planes.items():
        if plane.shape != (height, width):
            raise InputError(f"holds {plane.shape} samples for a {width} x {height} image",
                             file=path, field=f"channel {name}", value=list(plane.shape))


def _metadata_object(path: Path, text) -> dict:
    """Parse the metadata attribute: a JSON object of at most MAX_METADATA_DEPTH levels."""
    from .errors import json_object

    return json_object(text, file=path, field=METADATA_ATTRIBUTE,
                       max_depth=MAX_METADATA_DEPTH)


def read_exr(path, *, require_checksum: bool = False) -> Image:
    """Read an RGB OpenEXR into an :class:`Image`.

    The header is read first: a data window the machine cannot hold
    (:func:`translucent.resources.check_memory`) or subsampled channels are refused before
    any pixel is read.

    Parameters
    ----------
    path : str or PathLike
    require_checksum : bool
        Refuse a file without the pixels' checksum (what the suite writes): for files the
        suite made itself, such as cache entries.

    Raises
    ------
    InputError
        When the file is missing or a folder, is not a readable EXR, declares more pixels
        than the machine can hold, has subsampled channels, no R, G and B channels, or only
        some variance channels, holds NaN/Inf pixels or variance, or negative variance,
        holds pixels that do not match the checksum written with them, or metadata that
        are not a JSON object; the message names the file and what was found.
    """
    import OpenEXR

    path, header = read_exr_header(path)
    try:
        with OpenEXR.File(str(path), separate_channels=True) as exr:
            # the header is a view that empties when the file closes: copy what we need
            metadata_text = exr.header().get(METADATA_ATTRIBUTE)
            checksum = exr.header().get(CHECKSUM_ATTRIBUTE)
            names = sorted(exr.channels())
            planes = {name: np.array(ch.pixels, dtype=np.float32)
                      for name, ch in exr.channels().items() if name in _CHANNELS}
    except Exception as error:  # OpenEXR raises bare exceptions on corrupt files
        raise InputError(f"not a readable OpenEXR file ({error})", file=path) from error
    missing = [c for c in "RGB" if c not in planes]
    if missing:
        raise InputError("an RGB image needs channels R, G and B", file=path,
                         field="channels", value=names)
    check_planes(path, planes, header["size"])
    rgb = np.stack([planes[c] for c in "RGB"], axis=-1)
    _refuse_non_finite(rgb, "pixel channels", "", file=path, field="pixels")
    variance = None
    present = [f"variance.{c}" for c in "RGB" if f"variance.{c}" in planes]
    if present and len(present) < 3:
        raise InputError("variance needs all of variance.R, variance.G and variance.B",
                         file=path, field="channels", value=names)
    if present:
        variance = np.stack([planes[f"variance.{c}"] for c in "RGB"], axis=-1)
        _refuse_non_finite(variance, "variance channels", "", file=path, field="variance")
        if (variance < 0).any():
            y, x, c = np.argwhere(variance < 0)[0]
            raise InputError(f"{int((variance < 0).sum())} variance channels are negative "
                             f"(first at x={x}, y={y}, channel {'RGB'[c]})", file=path,
                             field="variance", value=float(variance[y, x, c]))
    if checksum is None and require_checksum:
        raise InputError("the pixels carry no checksum: not a file this suite wrote",
                         file=path, field=CHECKSUM_ATTRIBUTE)
    if checksum is not None and str(checksum) != pixel_checksum(rgb, variance):
        raise InputError("the pixels do not match the checksum written with them: the file "
                         "was changed or damaged after it was written", file=path,
                         field=CHECKSUM_ATTRIBUTE, value=str(checksum)[:16])
    metadata = {} if metadata_text is None else _metadata_object(path, metadata_text)
    return Image(rgb, variance, metadata)


def header_number(path, names) -> float | None:
    """Return the first of the header attributes ``names`` of an EXR that is a number.

    For times written by other renderers (``renderTime``, ``seconds``, ...); None where
    there is none, or the file cannot be read (:func:`read_exr` says why).
    """
    import OpenEXR

    try:
        with OpenEXR.File(str(path), separate_channels=True) as exr:
            header = {name: exr.header().get(name) for name in names}
    except Exception:  # the file's own problems are read_exr's to report
        return None
    for name in names:
        value = header.get(name)
        if isinstance(value, (int, float, np.floating, np.integer)) and \
                not isinstance(value, bool) and np.isfinite(value):
            return float(value)
    return None

