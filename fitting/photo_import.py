"""From a photo of a lit slab to a capture: ``translucent capture import PHOTO``.

A lab photo of a laser spot on a translucent slab becomes a capture the fitter reads
(docs/capture-format.md): a linear float OpenEXR of the stored values beside a JSON
sidecar, and a preview PNG (the image in log scale, the found incident point and the
annuli the fitter will average) for a person to check.

* **Photo.** A 16-bit (or 8-bit, or float) TIFF (tifffile) or an OpenEXR, linear: no gamma,
  no auto-brightening; or a camera RAW, read linearly by LibRaw
  (:mod:`translucent.fitting.capture_raw`: each colour at its own photosites, the others
  NaN, black and white levels from the file). Greyscale photos are used as three equal
  channels.
* **Black and white levels.** A dark frame (the same camera settings with the beam off, or
  the lens capped) is subtracted pixel by pixel; otherwise ``black_level`` (default 0; a
  RAW's own) is the stored value of no light. ``white_level`` is the raw value at and
  above which a pixel is clipped (default: the integer type's top code, a RAW's own; none
  for float photos). A channel at or above it is written at the sidecar's saturation
  level, a level every clipped pixel's own ceiling reaches (with a dark frame the white
  level minus the dark frame's 99.9th percentile; a clipped pixel whose dark value lies
  above that is written NaN), so the fitter reads it as censored from above: its
  signal is at least that level.
* **Pixel size.** Given in mm, or measured from two points on a ruler in the photo and
  their distance.
* **Incident point.** The brightest spot of the luminance smoothed over a few pixels,
  refined to sub-pixel precision by
  :func:`~translucent.fitting.profile.refine_incident_point`. A photo without a spot that
  stands clear of its noise (peak over median less than :data:`MIN_SPOT_CONTRAST` times the
  noise) is refused.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..atomic import atomic_path, check_output_file
from ..errors import InputError
from .capture import CaptureSpec, read_capture, write_capture, write_exr_pixels
from .capture_raw import RAW_SUFFIXES, read_raw
from .incident_point import refine_incident_point
from .profile import annulus_edges

__all__ = ["ImportedCapture", "MIN_SPOT_CONTRAST", "RAW_SUFFIXES", "import_photo",
           "ruler_pixel_size"]

PHOTO_SUFFIXES = (".tif", ".tiff", ".exr")
#: With a dark frame every pixel clips at its own level, ``white - dark``: the sidecar's
#: saturation level is this percentile of those levels (the dark frame's hot pixels left
#: out), and a clipped pixel whose own level lies below it is written NaN.
CEILING_PERCENTILE = 0.1
#: The spot must stand this many noise standard deviations (from the median absolute
#: deviation of the smoothed luminance) above the image's median.
MIN_SPOT_CONTRAST = 20.0
#: Smoothing of the luminance before the brightest spot is taken, pixels (Gaussian sigma).
SPOT_SMOOTHING_PX = 2.0


@dataclass(frozen=True)
class ImportedCapture:
    """What :func:`import_photo` wrote and found."""

    sidecar: Path
    image: Path
    preview: Path
    incident_px: tuple[float, float]
    pixel_size_mm: float
    saturated_pixels: int
    spot_contrast: float
    raw_layout: str = ""


def ruler_pixel_size(x1, y1, x2, y2, distance_mm) -> float:
    """Pixel size, mm, from two points on a ruler (pixels) and their distance (mm)."""
    values = [float(v) for v in (x1, y1, x2, y2, distance_mm)]
    if not all(math.isfinite(v) for v in values):
        raise InputError("must be finite numbers", field="--ruler", value=values)
    length = math.hypot(values[2] - values[0], values[3] - values[1])
    if not length > 0:
        raise InputError("the two ruler points must differ", field="--ruler", value=values[:4])
    if not values[4] > 0:
        raise InputError("the ruler distance must be > 0 mm", field="--ruler",
                         value=values[4])
    return values[4] / length


def _read_photo(path: Path, field: str) -> tuple[np.ndarray, float]:
    """Pixels (H, W, 3) float64 and the white level the file's type implies (inf: float)."""
    suffix = path.suffix.lower()
    if suffix not in PHOTO_SUFFIXES:
        raise InputError(f"unsupported photo format; valid: {', '.join(PHOTO_SUFFIXES)} and "
                         f"camera RAW ({', '.join(RAW_SUFFIXES)})", file=path, field=field,
                         value=suffix)
    from ..atomic import check_input_file

    check_input_file(path, field, what="photo")  # a FIFO is refused before a reader waits on it
    if suffix == ".exr":
        from ..image import read_exr

        try:
            pixels = np.asarray(read_exr(path).rgb, dtype=np.float64)
        except InputError:
            raise
        except Exception as error:  # OpenEXR raises several types on corrupt files
            raise InputError(f"cannot read the OpenEXR ({error})", file=path,
                             field=field) from None
        top = math.inf
    else:
        import tifffile

        try:
            raw = tifffile.imread(str(path))
        except Exception as error:  # tifffile raises several types on corrupt files
            raise InputError(f"cannot read the TIFF ({error})", file=path,
                             field=field) from None
        top = float(np.iinfo(raw.dtype).max) if np.issubdtype(raw.dtype, np.integer) \
            else math.inf
        pixels = np.asarray(raw, dtype=np.float64)
    if pixels.ndim == 2:
        pixels = np.repeat(pixels[..., None], 3, axis=2)
    if pixels.ndim != 3 or pixels.shape[2] not in (3, 4) or min(pixels.shape[:2]) < 8:
        raise InputError("must be a greyscale or RGB image of at least 8 x 8 pixels",
                         file=path, field=field, value=list(pixels.shape))
    return pixels[..., :3], top


def _saturation_level(ceiling, shape) -> float:
    """Return the sidecar's saturation level from every pixel's own clip level (stored units)."""
    ceiling = np.broadcast_to(np.asarray(ceiling, dtype=np.float64), shape)
    finite = ceiling[np.isfinite(ceiling)]
    return float(np.percentile(finite, CEILING_PERCENTILE)) if finite.size else math.inf


def _spot(luminance: np.ndarray, path: Path) -> tuple[tuple[float, float], float]:
    """Return the brightest smoothed spot (x, y) in pixels and its contrast over the noise."""
    from scipy import ndimage

    smooth = ndimage.gaussian_filter(np.nan_to_num(luminance), SPOT_SMOOTHING_PX)
    median = float(np.median(smooth))
    noise = 1.4826 * float(np.median(np.abs(luminance - np.median(luminance))))
    noise = max(noise, 1e-12 * max(float(np.abs(smooth).max()), 1e-300))
    iy, ix = np.unravel_index(int(np.argmax(smooth)), smooth.shape)
    contrast = (float(smooth[iy, ix]) - median) / noise
    if not contrast >= MIN_SPOT_CONTRAST:
        raise InputError(f"no incident spot found: the brightest spot stands {contrast:.3g} "
                         f"noise standard deviations above the median, fewer than "
                         f"{MIN_SPOT_CONTRAST:g} (give --incident X Y if the spot is there)",
                         file=path, field="incident_px (--incident)")
    return (ix + 0.5, iy + 0.5), contrast


def import_photo(photo, sidecar, *, pixel_size_mm: float, dark=None,
                 black_level: float | None = None, white_level: float | None = None,
                 incident_px=None, eta: float | None = 1.3, side: str = "reflection",
                 thickness_mm: float | None = None, beam_radius_mm: float = 0.0,
                 beam_profile: str = "gaussian", beam_image=None,
                 beam_pixel_size_mm: float | None = None) -> ImportedCapture:
    """Turn a linear photo into a capture (see the module docstring); nothing is left on error.

    Parameters
    ----------
    photo : path
        TIFF or OpenEXR, linear; or a camera RAW (:func:`~.capture_raw.read_raw`).
    sidecar : path
        The capture's JSON sidecar to write; the image goes beside it as
        ``<stem>.exr`` and the preview as ``<stem>_preview.png``.
    pixel_size_mm : float
        > 0 (see :func:`ruler_pixel_size`).
    dark : path, optional
        A dark frame of the same size (subtracted; then ``black_level`` must not be given).
    black_level : float, optional
        Raw value of no light without a dark frame (default 0; a RAW's own, which this
        replaces).
    white_level : float, optional
        Raw value at and above which a pixel is clipped (default: the integer type's top
        code; a RAW's own; none for a float photo).
    incident_px : (float, float), optional
        Where to look for the spot (default: the brightest spot of the photo).
    eta, side, thickness_mm, beam_radius_mm, beam_profile
        Written to the sidecar (docs/capture-format.md); ``eta`` None: fitted.
    beam_image : path, optional
        A linear photo of the beam on a white diffuse target (TIFF or OpenEXR), written
        beside the capture as ``<stem>_beam.exr``; the sidecar's beam is then
        ``"measured"`` (:mod:`translucent.fitting.measured_beam`).
    beam_pixel_size_mm : float, optional
        The beam photo's pixel size on the target (default: ``pixel_size_mm``).

    Returns
    -------
    ImportedCapture
    """
    photo, sidecar = Path(photo), Path(sidecar)
    if not (isinstance(pixel_size_mm, (int, float)) and math.isfinite(pixel_size_mm)
            and pixel_size_mm > 0):
        raise InputError("must be a finite number > 0", field="pixel_size_mm (--pixel-size-mm)",
                         value=pixel_size_mm)
    if sidecar.suffix.lower() != ".json":
        raise InputError("the sidecar must be a .json file", file=sidecar, field="--out")
    image_path = sidecar.with_suffix(".exr")
    preview_path = sidecar.with_name(f"{sidecar.stem}_preview.png")
    beam_path = sidecar.with_name(f"{sidecar.stem}_beam.exr")
    for path in (sidecar, image_path, preview_path, beam_path):
        check_output_file(path, "--out")
    if not sidecar.parent.is_dir():
        raise InputError("no such folder", file=sidecar.parent, field="--out")
    raw = photo.suffix.lower() in RAW_SUFFIXES
    layout = ""
    if raw:
        if dark is not None and black_level is not None:
            raise InputError("give a dark frame or a black level, not both",
                             field="black_level (--black-level)", value=black_level)
        # with a dark frame the file's black level is not used (nor needed)
        mosaic = read_raw(photo, "photo", white_level=white_level,
                          black_level=0.0 if dark is not None else black_level)
        pixels, white = mosaic.values, mosaic.white[..., None]
        layout = f"{mosaic.layout}, " + ("the dark frame subtracted" if dark is not None
                                          else f"black level from the {mosaic.black_source}")
    else:
        pixels, top = _read_photo(photo, "photo")
        white = top if white_level is None else float(white_level)
        if not (math.isfinite(white) or white == math.inf) or white <= 0:
            raise InputError("must be > 0", field="white_level (--white-level)",
                             value=white_level)
    with np.errstate(invalid="ignore"):
        clipped = pixels >= white  # per channel: a channel clips on its own
    if dark is not None:
        if black_level is not None:
            raise InputError("give a dark frame or a black level, not both",
                             field="black_level (--black-level)", value=black_level)
        if raw:
            dark_pixels = read_raw(Path(dark), "dark", white_level=white_level,
                                   black_level=0.0).values
        else:
            dark_pixels, _ = _read_photo(Path(dark), "dark")
        if dark_pixels.shape != pixels.shape or \
                not np.array_equal(np.isnan(dark_pixels), np.isnan(pixels)):
            raise InputError(f"the dark frame is {dark_pixels.shape[1]} x "
                             f"{dark_pixels.shape[0]} pixels, the photo "
                             f"{pixels.shape[1]} x {pixels.shape[0]} (a RAW dark frame needs "
                             "the photo's colour filter layout)", file=Path(dark),
                             field="dark (--dark)", value=list(dark_pixels.shape[:2]))
        stored = pixels - dark_pixels
        black = 0.0
        ceiling = white - dark_pixels
    elif raw:  # the file's black level of every photosite, subtracted
        stored = pixels - mosaic.black[..., None]
        black = 0.0
        ceiling = white - mosaic.black[..., None]
    else:
        black = 0.0 if black_level is None else float(black_level)
        if not (math.isfinite(black) and black >= 0):
            raise InputError("must be a finite number >= 0", field="black_level (--black-level)",
                             value=black_level)
        stored = pixels
        ceiling = white
    saturation = _saturation_level(ceiling, pixels.shape)
    if not saturation > black:
        raise InputError("the white level must lie above the black level",
                         field="white_level (--white-level)",
                         value=white_level if white_level is not None else saturation)
    if math.isfinite(saturation):
        # a clipped channel says only "at least its own ceiling": written at a level every
        # such ceiling reaches, or NaN where its own lies below it (a hot dark pixel)
        unknown = clipped & (np.broadcast_to(ceiling, pixels.shape) < saturation)
        stored = np.where(clipped, saturation, stored)
        stored[unknown] = np.nan
    clipped_any = clipped.any(axis=2)
    luminance = np.nansum(stored - black, axis=2)
    if incident_px is None:
        start, contrast = _spot(luminance, photo)
    else:
        start, contrast = (float(incident_px[0]), float(incident_px[1])), math.nan
    centre = refine_incident_point(luminance, start, saturated=clipped_any)
    beam_pixels = None
    if beam_image is not None:
        beam_pixels, _ = _read_photo(Path(beam_image), "beam_image (--beam-image)")
        beam_profile, beam_radius_mm = "measured", 0.0
    spec = CaptureSpec(image=image_path.name, pixel_size_mm=float(pixel_size_mm),
                       incident_px=(round(centre[0], 3), round(centre[1], 3)), side=side,
                       thickness_mm=thickness_mm, eta=eta, beam_radius_mm=beam_radius_mm,
                       beam_profile=beam_profile,
                       beam_image=None if beam_pixels is None else beam_path.name,
                       beam_pixel_size_mm=beam_pixel_size_mm if beam_pixels is not None
                       else None, black_level=black, saturation_level=saturation,
                       exposure=None, synthetic={})
    written = []
    try:
        _write_preview(preview_path, luminance, centre, clipped_any)
        written.append(preview_path)
        if beam_pixels is not None:
            write_exr_pixels(beam_path, beam_pixels)
            written.append(beam_path)
        write_capture(sidecar, stored, spec)
        written += [image_path, sidecar]
        read_capture(sidecar)  # what the fitter will read: refused now, not later
    except BaseException:
        for path in written:
            path.unlink(missing_ok=True)
        raise
    return ImportedCapture(sidecar, image_path, preview_path, centre, float(pixel_size_mm),
                           int(clipped_any.sum()), contrast, layout)


def _write_preview(path: Path, luminance, centre, clipped) -> None:
    """Draw the photo in log scale, the incident point, the fitter's annuli, clipped pixels."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    height, width = luminance.shape
    positive = luminance[luminance > 0]
    floor = float(np.percentile(positive, 5)) if positive.size else 1.0
    shown = np.log10(np.clip(luminance, floor, None))
    figure, axes = plt.subplots(figsize=(6, 6 * height / width + 0.4), dpi=100)
    axes.imshow(shown, cmap="magma", extent=(0, width, height, 0))
    if clipped.any():
        ys, xs = np.nonzero(clipped)
        axes.scatter(xs + 0.5, ys + 0.5, s=2, c="cyan", label="clipped")
    reach = math.hypot(max(centre[0], width - centre[0]), max(centre[1], height - centre[1]))
    edges = annulus_edges(reach)
    for radius in edges[1::max(1, len(edges) // 12)]:
        axes.add_patch(plt.Circle(centre, radius, fill=False, lw=0.6, color="white",
                                  alpha=0.7))
    axes.plot(*centre, marker="+", ms=14, mew=1.5, color="lime", label="incident point")
    axes.set_xlim(0, width)
    axes.set_ylim(height, 0)
    axes.set_title(f"incident point ({centre[0]:.2f}, {centre[1]:.2f}) px; some annuli")
    axes.legend(loc="upper right", fontsize=7)
    with atomic_path(path) as tmp:
        figure.savefig(tmp, format="png")
    plt.close(figure)
