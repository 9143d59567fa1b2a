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

__all__ = ["Image", "pixel_checksum", "read_exr", "write_exr"]

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


def read_exr(path) -> Image:
    """Read an RGB OpenEXR into an :class:`Image`.

    Raises
    ------
    InputError
        When the file is missing, is not a readable EXR, has no R, G and B channels, holds
        NaN/Inf pixels, or holds pixels that do not match the checksum written with them;
        the message names the file and what was found.
    """
    import OpenEXR

    path = Path(path)
    if not path.is_file():
        raise InputError("no such file", file=path, field="path", value=str(path))
    try:
        with OpenEXR.File(str(path), separate_channels=True) as exr:
            # the header is a view that empties when the file closes: copy what we need
            metadata_text = exr.header().get(METADATA_ATTRIBUTE)
            checksum = exr.header().get(CHECKSUM_ATTRIBUTE)
            planes = {name: np.array(ch.pixels, dtype=np.float32)
                      for name, ch in exr.channels().items()}
    except Exception as error:  # OpenEXR raises bare exceptions on corrupt files
        raise InputError(f"not a readable OpenEXR file ({error})", file=path) from error
    missing = [c for c in "RGB" if c not in planes]
    if missing:
        raise InputError("an RGB image needs channels R, G and B", file=path,
                         field="channels", value=sorted(planes))
    rgb = np.stack([planes[c] for c in "RGB"], axis=-1)
    _refuse_non_finite(rgb, "pixel channels", "", file=path, field="pixels")
    variance = None
    if all(f"variance.{c}" in planes for c in "RGB"):
        variance = np.stack([planes[f"variance.{c}"] for c in "RGB"], axis=-1)
    if checksum is not None and str(checksum) != pixel_checksum(rgb, variance):
        raise InputError("the pixels do not match the checksum written with them: the file "
                         "was changed or damaged after it was written", file=path,
                         field=CHECKSUM_ATTRIBUTE, value=str(checksum)[:16])
    metadata = {}
    if metadata_text is not None:
        try:
            metadata = json.loads(metadata_text)
        except (TypeError, ValueError) as error:
            raise InputError("metadata attribute is not valid JSON", file=path,
                             field=METADATA_ATTRIBUTE) from error
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

