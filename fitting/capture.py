"""Slab captures: an image of a slab lit by a narrow beam, and the JSON sidecar that describes it.

The format is documented in ``docs/capture-format.md``. A capture is read with
:func:`read_capture`, which validates every sidecar field and the image, and written with
:func:`write_capture` (image and sidecar, each atomically).

What a pixel holds (the model every part of :mod:`translucent.fitting` shares)::

    stored value = black_level + exposure * E(x, y)        (linear encodings)

where ``E`` (mm^-2) is the radiant exitance of the slab surface the camera sees, per unit
beam power entering the slab, averaged over the pixel's footprint on the slab. For an
sRGB-encoded file the same holds after decoding (see :func:`decode_pixels`).
"""

from __future__ import annotations

import json
import math
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from ..atomic import atomic_path, atomic_write_text
from ..errors import InputError
from .beam import BEAM_PROFILES

__all__ = [
    "Capture",
    "CaptureSpec",
    "SIDECAR_FIELDS",
    "decode_pixels",
    "read_capture",
    "read_sidecar",
    "write_capture",
    "write_exr_pixels",
]

#: Sidecar keys: name -> one-line meaning (the documentation table is built from the same text).
SIDECAR_FIELDS: dict[str, str] = {
    "image": "image file, relative to the sidecar (.exr, .png or .tif/.tiff)",
    "encoding": '"linear" or "srgb" (PNG/TIFF only; OpenEXR is always linear)',
    "pixel_size_mm": "size of one pixel on the slab surface, mm, > 0",
    "incident_px": "[x, y] of the beam's incident point in pixels (top-left corner 0, 0)",
    "side": '"reflection" (camera on the lit side) or "transmission" (the far side)',
    "thickness_mm": "slab thickness in mm, > 0, or null for a semi-infinite slab",
    "eta": "relative index of refraction in [1, 3], or null to fit it",
    "beam_radius_mm": "1/e^2 radius of the Gaussian beam, or the radius of a top-hat beam, "
                      "mm, >= 0 (0: a pencil beam), at most the image diagonal",
    "beam_profile": '"gaussian" (default), "top_hat" (a uniform disk: a fibre or an '
                    'aperture) or "measured" (the beam\'s own image, beam_image)',
    "beam_image": 'with beam_profile "measured": an image of the beam on a white diffuse '
                  'target, relative to the sidecar',
    "beam_pixel_size_mm": "pixel size of beam_image on the target, mm (default: "
                          "pixel_size_mm; finer is better: the image is blurred by its pixels)",
    "black_level": "stored value of zero light, >= 0",
    "saturation_level": "stored value at and above which a pixel is clipped, > black_level",
    "exposure": "stored units per unit of E (mm^2), > 0, or null when unknown",
    "synthetic": "optional object: the truth of a synthetic capture (not read by the fitter)",
}

_REQUIRED = ("image", "pixel_size_mm", "incident_px", "side", "black_level", "saturation_level")
_SIDES = ("reflection", "transmission")
_ENCODINGS = ("linear", "srgb")
_IMAGE_SUFFIXES = (".exr", ".png", ".tif", ".tiff")
#: Accepted relative index range (the range :class:`~translucent.materials.Dipole` takes).
ETA_RANGE = (1.0, 3.0)


@dataclass(frozen=True)
class CaptureSpec:
    """The validated sidecar of a capture (see ``docs/capture-format.md``).

    Parameters
    ----------
    image : str
        Image file name, relative to the sidecar's folder.
    pixel_size_mm : float
        Pixel footprint on the slab, mm.
    incident_px : tuple of float
        ``(x, y)`` of the incident point in pixel coordinates: the top-left corner of the
        image is ``(0, 0)`` and the centre of the top-left pixel ``(0.5, 0.5)``.
    side : str
        ``"reflection"`` or ``"transmission"``.
    thickness_mm : float or None
        Slab thickness, mm; None for a semi-infinite slab (reflection only).
    eta : float or None
        Relative index of refraction; None: fitted.
    beam_radius_mm : float
        1/e^2 radius of the Gaussian beam irradiance, or the radius of a top-hat beam, mm
        (0: pencil beam).
    beam_profile : str
        ``"gaussian"``, ``"top_hat"`` or ``"measured"``.
    beam_image : str or None
        With ``"measured"``: the beam's image file, relative to the sidecar's folder (its
        radius, holding 99 % of the power, becomes ``beam_radius_mm`` when read).
    beam_pixel_size_mm : float or None
        The beam image's pixel size on the target, mm (None: ``pixel_size_mm``).
    black_level, saturation_level : float
        In stored units (code values for PNG/TIFF).
    exposure : float or None
        Stored units per unit exitance per unit entering power (mm^2); None: unknown.
    encoding : str
        ``"linear"`` or ``"srgb"``.
    synthetic : dict
        Ground truth recorded by the synthetic-capture generators; ignored by the fitter.
    """

    image: str
    pixel_size_mm: float
    incident_px: tuple[float, float]
    side: str = "reflection"
    thickness_mm: float | None = None
    eta: float | None = 1.3
    beam_radius_mm: float = 0.0
    beam_profile: str = "gaussian"
    beam_image: str | None = None
    beam_pixel_size_mm: float | None = None
    black_level: float = 0.0
    saturation_level: float = math.inf
    exposure: float | None = None
    encoding: str = "linear"
    synthetic: dict[str, Any] = field(default_factory=dict)

    def to_json(self) -> dict[str, Any]:
        """Return the sidecar as a JSON-able dict (infinite saturation as a large number)."""
        data = asdict(self)
        data["incident_px"] = [float(v) for v in self.incident_px]
        if not math.isfinite(self.saturation_level):
            data["saturation_level"] = 3.4e38
        if not data["synthetic"]:
            del data["synthetic"]
        for key in ("beam_image", "beam_pixel_size_mm"):
            if data[key] is None:
                del data[key]
        return data


@dataclass(frozen=True)
class Capture:
    """A capture read from disk: the sidecar, the stored pixels and where they came from.

    Parameters
    ----------
    spec : CaptureSpec
    pixels : ndarray, shape (H, W, 3), float64
        Stored values as read (code values for PNG/TIFF), NaN kept where the file has them.
    path : Path or None
        The sidecar's path.
    beam : MeasuredBeam or None
        The measured beam (``beam_profile = "measured"``), read from ``beam_image``.
    """

    spec: CaptureSpec
    pixels: np.ndarray
    path: Path | None = None
    beam: Any = None

    @property
    def shape(self) -> tuple[int, int]:
        """``(H, W)`` in pixels."""
        return self.pixels.shape[:2]

    def linear_signal(self) -> np.ndarray:
        """``exposure * E`` per pixel: decoded, black level removed (see :func:`decode_pixels`)."""
        return decode_pixels(self.pixels, self.spec)


def decode_pixels(pixels, spec: CaptureSpec) -> np.ndarray:
    """Convert stored values to the linear signal above black, ``exposure * E``.

    Linear encodings: ``pixels - black_level``. sRGB (PNG/TIFF): the stored code ``v`` is
    normalised by the largest code (65535), decoded with the sRGB transfer function
    (IEC 61966-2-1), multiplied back by 65535, and the decoded black level subtracted, so
    ``exposure`` and the levels stay in stored units.

    Parameters
    ----------
    pixels : ndarray
        Stored values.
    spec : CaptureSpec

    Returns
    -------
    ndarray, float64
        Linear signal; NaN where the input is NaN.
    """
    pixels = np.asarray(pixels, dtype=np.float64)
    if spec.encoding == "linear":
        return pixels - spec.black_level
    top = 65535.0
    return (_srgb_to_linear(pixels / top) - _srgb_to_linear(spec.black_level / top)) * top


def _srgb_to_linear(value):
    value = np.asarray(value, dtype=np.float64)
    return np.where(value <= 0.04045, value / 12.92, ((value + 0.055) / 1.055) ** 2.4)


def _linear_to_srgb(value):
    value = np.clip(np.asarray(value, dtype=np.float64), 0.0, 1.0)
    return np.where(value <= 0.0031308, value * 12.92, 1.055 * value ** (1 / 2.4) - 0.055)


# --- the sidecar -----------------------------------------------------------------------------


def _as_float(value) -> float:
    """``float(value)``; a JSON integer beyond float range becomes +-inf (refused as infinite)."""
    try:
        return float(value)
    except OverflowError:
        return math.inf if value > 0 else -math.inf


def _number(data, key, path, *, minimum=None, strict=False, maximum=None, allow_null=False):
    value = data.get(key)
    if value is None:
        if allow_null:
            return None
        raise InputError("must be a number (it is missing or null)", file=path, field=key,
                         value=value)
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise InputError("must be a number", file=path, field=key, value=value)
    value = _as_float(value)
    if not math.isfinite(value):
        raise InputError("must be finite", file=path, field=key, value=value)
    if minimum is not None and (value <= minimum if strict else value < minimum):
        relation = ">" if strict else ">="
        accepted = f"must be {relation} {minimum:g}"
        if maximum is not None:
            accepted += f" and <= {maximum:g}"
        raise InputError(accepted, file=path, field=key, value=value)
    if maximum is not None and value > maximum:
        raise InputError(f"must be <= {maximum:g}", file=path, field=key, value=value)
    return value


def _choice(data, key, path, choices, default):
    value = data.get(key, default)
    if value not in choices:
        raise InputError(f"must be one of {', '.join(repr(c) for c in choices)}", file=path,
                         field=key, value=value)
    return value


def read_sidecar(path) -> CaptureSpec:
    """Read and validate a capture sidecar (JSON).

    Parameters
    ----------
    path : str or Path
        The sidecar file.

    Returns
    -------
    CaptureSpec

    Raises
    ------
    InputError
        Missing file, invalid JSON, an unknown or missing key, or any value outside its
        accepted range; the message names the file, the field, the value and the range.
    """
    from ..atomic import check_input_file
    from ..errors import json_object

    path = check_input_file(path, "path", what="capture sidecar")
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as error:
        raise InputError(f"not a readable JSON file ({error})", file=path) from error
    try:  # nested too deep, integers beyond 64 bits: refused here, named
        # each number is checked by its own key (an integer beyond float64 is infinite)
        data = json_object(text, file=path, what="JSON file", integers=False)
    except InputError as error:
        if error.field is not None or error.value is ...:
            raise
        raise InputError("a sidecar must be a JSON object", file=path, field="(top level)",
                         value=error.value) from None
    return sidecar_from_dict(data, path=path)


def sidecar_from_dict(data, *, path=None) -> CaptureSpec:
    """Validate a sidecar already parsed from JSON; see :func:`read_sidecar`."""
    if not isinstance(data, dict):
        raise InputError("a sidecar must be a JSON object", file=path, field="(top level)",
                         value=type(data).__name__)
    unknown = sorted(set(data) - set(SIDECAR_FIELDS))
    if unknown:
        raise InputError(f"unknown key; valid keys: {', '.join(SIDECAR_FIELDS)}", file=path,
                         field=unknown[0], value=data[unknown[0]])
    for key in _REQUIRED:
        if key not in data:
            raise InputError(f"required key is missing ({SIDECAR_FIELDS[key]})", file=path,
                             field=key)
    image = data["image"]
    if not isinstance(image, str) or Path(image).suffix.lower() not in _IMAGE_SUFFIXES:
        raise InputError(f"must be a file name ending in {', '.join(_IMAGE_SUFFIXES)}",
                         file=path, field="image", value=image)
    encoding = _choice(data, "encoding", path, _ENCODINGS, "linear")
    if encoding == "srgb" and Path(image).suffix.lower() == ".exr":
        raise InputError("OpenEXR is linear: 'srgb' applies to PNG/TIFF only", file=path,
                         field="encoding", value=encoding)
    pixel_size = _number(data, "pixel_size_mm", path, minimum=0.0, strict=True)
    incident = data["incident_px"]
    if (not isinstance(incident, (list, tuple)) or len(incident) != 2
            or any(isinstance(v, bool) or not isinstance(v, (int, float)) for v in incident)
            or not all(math.isfinite(_as_float(v)) for v in incident)):
        raise InputError("must be [x, y], two finite numbers (pixels)", file=path,
                         field="incident_px", value=incident)
    side = _choice(data, "side", path, _SIDES, "reflection")
    thickness = _number(data, "thickness_mm", path, minimum=0.0, strict=True, allow_null=True)
    if side == "transmission" and thickness is None:
        raise InputError("a transmission capture needs a finite slab thickness (mm > 0)",
                         file=path, field="thickness_mm", value=None)
    eta = _number(data, "eta", path, minimum=ETA_RANGE[0], maximum=ETA_RANGE[1],
                  allow_null=True)
    beam = _number(data, "beam_radius_mm", path, minimum=0.0) if "beam_radius_mm" in data \
        else 0.0
    beam_profile = _choice(data, "beam_profile", path, BEAM_PROFILES + ("measured",),
                           "gaussian")
    beam_image = data.get("beam_image")
    if beam_profile == "measured":
        if not isinstance(beam_image, str) or \
                Path(beam_image).suffix.lower() not in _IMAGE_SUFFIXES:
            raise InputError('beam_profile "measured" needs beam_image, a file name ending in '
                             f"{', '.join(_IMAGE_SUFFIXES)}", file=path, field="beam_image",
                             value=beam_image)
    elif beam_image is not None:
        raise InputError('beam_image is read only with beam_profile "measured"', file=path,
                         field="beam_image", value=beam_image)
    beam_pixel = _number(data, "beam_pixel_size_mm", path, minimum=0.0, strict=True,
                         allow_null=True) if "beam_pixel_size_mm" in data else None
    black = _number(data, "black_level", path, minimum=0.0)
    saturation = _number(data, "saturation_level", path, minimum=0.0, strict=True)
    if saturation <= black:
        raise InputError(f"must be > black_level ({black:g})", file=path,
                         field="saturation_level", value=saturation)
    exposure = _number(data, "exposure", path, minimum=0.0, strict=True, allow_null=True)
    synthetic = data.get("synthetic", {})
    if not isinstance(synthetic, dict):
        raise InputError("must be a JSON object", file=path, field="synthetic", value=synthetic)
    return CaptureSpec(image=image, pixel_size_mm=pixel_size,
                       incident_px=(float(incident[0]), float(incident[1])), side=side,
                       thickness_mm=thickness, eta=eta, beam_radius_mm=beam,
                       beam_profile=beam_profile, beam_image=beam_image,
                       beam_pixel_size_mm=beam_pixel, black_level=black,
                       saturation_level=saturation, exposure=exposure, encoding=encoding,
                       synthetic=dict(synthetic))


# --- the image -------------------------------------------------------------------------------


def _read_image(path: Path, what: str = "capture image") -> np.ndarray:
    from ..atomic import check_input_file

    suffix = path.suffix.lower()
    # a FIFO or a device is refused here, before any reader opens it (and waits)
    check_input_file(path, "image", what=what)
    if suffix == ".exr":
        return _read_exr_pixels(path)
    if suffix == ".png":
        pixels = _read_png(path)
    else:
        pixels = _read_tiff(path)
    if pixels.dtype != np.uint16:
        raise InputError("PNG/TIFF captures must be 16-bit (8 bits lack the dynamic range "
                         "of a scattering profile)", file=path, field="bit depth",
                         value=str(pixels.dtype))
    return pixels.astype(np.float64)


def _read_exr_pixels(path: Path) -> np.ndarray:
    import OpenEXR

    from ..image import check_planes, read_exr_header

    # declared size and subsampling refused from the header, before any pixel is read
    wanted = ("R", "G", "B", "Y")
    path, header = read_exr_header(path, wanted, field="image", bytes_per_sample=24)
    try:
        with OpenEXR.File(str(path), separate_channels=True) as exr:
            planes = {name: np.array(ch.pixels, dtype=np.float64)
                      for name, ch in exr.channels().items() if name in wanted}
    except Exception as error:  # OpenEXR raises bare exceptions on corrupt files
        raise InputError(f"not a readable OpenEXR file ({error})", file=path,
                         field="image") from error
    check_planes(path, planes, header["size"])
    if all(c in planes for c in "RGB"):
        return np.stack([planes[c] for c in "RGB"], axis=-1)
    if "Y" in planes:
        return np.repeat(planes["Y"][..., None], 3, axis=-1)
    raise InputError("a capture needs channels R, G and B (or Y)", file=path, field="channels",
                     value=sorted(planes))


def _read_png(path: Path) -> np.ndarray:
    import png

    try:
        # read(), not asDirect(): asDirect rescales to an sBIT chunk's depth, and the
        # sidecar's levels are in the file's own codes (16-bit files have no palette)
        width, height, rows, info = png.Reader(filename=str(path)).read()
        dtype = np.uint16 if info["bitdepth"] > 8 else np.uint8
        array = np.vstack([np.asarray(row, dtype=dtype) for row in rows])
    except (png.Error, OSError, ValueError) as error:
        raise InputError(f"not a readable PNG file ({error})", file=path,
                         field="image") from error
    array = array.reshape(height, width, info["planes"])
    return _to_rgb(array, path)


def _read_tiff(path: Path) -> np.ndarray:
    import tifffile

    try:
        with tifffile.TiffFile(str(path)) as tiff:
            series = tiff.series[0]
            array, axes = series.asarray(), series.axes
    except Exception as error:  # tifffile raises several types on corrupt files
        raise InputError(f"not a readable TIFF file ({error})", file=path,
                         field="image") from error
    if axes in ("SYX", "CYX"):  # planar configuration: one plane per sample
        array = np.moveaxis(array, 0, -1)
    elif axes == "YX":
        array = array[..., None]
    elif axes not in ("YXS", "YXC"):
        raise InputError(f"a capture is one image of H x W pixels with 1 to 4 samples (this "
                         f"TIFF's axes are {axes})", file=path, field="shape",
                         value=array.shape)
    return _to_rgb(array, path)


def _to_rgb(array: np.ndarray, path: Path) -> np.ndarray:
    planes = array.shape[2]
    if planes in (1, 2):  # grey (and alpha): the same signal in every channel
        return np.repeat(array[..., :1], 3, axis=-1)
    if planes in (3, 4):
        return array[..., :3]
    raise InputError("expected 1 to 4 channels", file=path, field="channels", value=planes)


def _check_beam(spec: CaptureSpec, shape, path) -> None:
    """:class:`InputError` when the beam is wider than the image's diagonal."""
    diagonal_mm = math.hypot(*shape[:2]) * spec.pixel_size_mm
    if spec.beam_radius_mm > diagonal_mm:
        # the profile would be the beam's own shape, and the forward model's grid (out to
        # six beam radii) would not fit in memory; a radius in um is the usual cause
        raise InputError(f"must be at most the image's diagonal ({diagonal_mm:.3g} mm): a "
                         "wider beam leaves no scattering profile to fit (is it in mm?)",
                         file=path, field="beam_radius_mm", value=spec.beam_radius_mm)


def read_capture(path) -> Capture:
    """Read a capture: the sidecar at ``path`` and the image it names.

    Parameters
    ----------
    path : str or Path
        The JSON sidecar.

    Returns
    -------
    Capture

    Raises
    ------
    InputError
        Bad sidecar (see :func:`read_sidecar`); a missing, unreadable or 8-bit image; an
        ``incident_px`` outside the image; a ``beam_radius_mm`` beyond the image's diagonal;
        an image with no finite pixel.
    """
    from ..atomic import note_input

    path = Path(path)
    spec = read_sidecar(path)
    image_path = path.parent / spec.image
    note_input(path, "capture")  # what no output of the command may replace
    note_input(image_path, "image")
    pixels = _read_image(image_path)
    height, width = pixels.shape[:2]
    if min(height, width) < 8:
        raise InputError("a capture must be at least 8 x 8 pixels", file=image_path,
                         field="shape", value=(height, width))
    x, y = spec.incident_px
    if not (0.0 <= x <= width and 0.0 <= y <= height):
        raise InputError(f"must lie inside the image (x in [0, {width}], y in [0, {height}])",
                         file=path, field="incident_px", value=list(spec.incident_px))
    beam = None
    if spec.beam_profile == "measured":
        from .measured_beam import measure_beam

        beam_path = path.parent / spec.beam_image
        note_input(beam_path, "beam_image")
        try:
            beam_pixels = _read_image(beam_path, "beam image")
        except InputError as error:
            raise InputError(error.reason, file=beam_path, field="beam_image",
                             value=spec.beam_image) from None
        beam = measure_beam(beam_pixels, spec.beam_pixel_size_mm or spec.pixel_size_mm,
                            path=beam_path)
        spec = replace(spec, beam_radius_mm=beam.radius_mm)
    _check_beam(spec, (height, width), path)
    if not np.isfinite(pixels).any():
        raise InputError("no finite pixel in the image", file=image_path, field="pixels")
    return Capture(spec=spec, pixels=pixels, path=path, beam=beam)


def write_capture(path, pixels, spec: CaptureSpec) -> Path:
    """Write the image (format from ``spec.image``'s suffix) and the sidecar, atomically.

    Parameters
    ----------
    path : str or Path
        The sidecar (``.json``); the image goes beside it under ``spec.image``.
    pixels : ndarray, shape (H, W, 3)
        Stored values: float for OpenEXR (written as float32), code values in [0, 65535]
        for PNG/TIFF (rounded to uint16).
    spec : CaptureSpec
        Written as the sidecar (after validation by :func:`sidecar_from_dict`).

    Returns
    -------
    Path
        The sidecar path.
    """
    path = Path(path)
    spec = sidecar_from_dict(spec.to_json(), path=path)
    pixels = np.asarray(pixels)
    if pixels.ndim != 3 or pixels.shape[2] != 3:
        raise InputError("must be H x W x 3", field="pixels", value=pixels.shape)
    _check_beam(spec, pixels.shape, path)  # read_capture would refuse it
    image_path = path.parent / spec.image
    if image_path.resolve() == path.resolve():
        raise InputError("the sidecar would overwrite the image: give the sidecar its own "
                         "name (.json)", file=path, field="image", value=spec.image)
    suffix = image_path.suffix.lower()
    if suffix == ".exr":
        write_exr_pixels(image_path, pixels)
    else:
        codes = np.clip(np.rint(np.nan_to_num(np.asarray(pixels, np.float64))), 0, 65535)
        codes = codes.astype(np.uint16)
        with atomic_path(image_path) as tmp:
            if suffix == ".png":
                import png

                height, width = codes.shape[:2]
                writer = png.Writer(width, height, greyscale=False, bitdepth=16)
                with open(tmp, "wb") as handle:
                    writer.write(handle, codes.reshape(height, -1))
            else:
                import tifffile

                tifffile.imwrite(str(tmp), codes, photometric="rgb")
    atomic_write_text(path, json.dumps(spec.to_json(), indent=2) + "\n")
    return path


def write_exr_pixels(path, pixels) -> None:
    """Write stored values (H, W, 3) as a float32 RGB OpenEXR, atomically."""
    import OpenEXR

    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    channels = {"RGB": np.ascontiguousarray(pixels, dtype=np.float32)}
    with atomic_path(path) as tmp, OpenEXR.File(header, channels) as exr:
        exr.write(str(tmp))


def encode_srgb(linear, spec: CaptureSpec) -> np.ndarray:
    """Inverse of :func:`decode_pixels` for sRGB: linear signal above black -> stored codes."""
    top = 65535.0
    black = _srgb_to_linear(spec.black_level / top)
    return _linear_to_srgb(np.asarray(linear, np.float64) / top + black) * top


def with_spec(capture: Capture, **changes) -> Capture:
    """Return a copy of ``capture`` whose sidecar has ``changes`` (not re-validated)."""
    return Capture(spec=replace(capture.spec, **changes), pixels=capture.pixels,
                   path=capture.path, beam=capture.beam)
