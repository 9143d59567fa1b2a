"""Turn a photo of a lit slab into a capture: ``translucent capture import PHOTO``.

Reads a linear photo (16-bit or float TIFF, OpenEXR, or a camera RAW read linearly by
LibRaw: each colour at its own photosites, black and white levels from the file), subtracts
a dark frame (``--dark``) or a black level, takes the pixel
size in mm (``--pixel-size-mm``, or ``--ruler X1 Y1 X2 Y2 MM``: two points on a ruler in
the photo and their distance), finds the incident point (the brightest spot, refined to
sub-pixel precision), and writes the capture: ``OUT.json`` (the sidecar), ``OUT.exr``
(the stored values) and ``OUT_preview.png`` (the photo in log scale with the found point
and the fitter's annuli, to check by eye). Then ``translucent fit OUT.json``.
See docs/capture-format.md.
"""

from __future__ import annotations

from pathlib import Path


def add_arguments(parser):
    """Options of ``translucent capture import``."""
    parser.add_argument("photo", help="linear photo: .tif/.tiff (16-bit or float), .exr, or a "
                                      "camera RAW (.dng, .cr2, .nef, .arw, ...)")
    size = parser.add_mutually_exclusive_group(required=True)
    size.add_argument("--pixel-size-mm", type=float, default=None,
                      help="size of one pixel on the slab, mm")
    size.add_argument("--ruler", type=float, nargs=5, default=None,
                      metavar=("X1", "Y1", "X2", "Y2", "MM"),
                      help="two points on a ruler in the photo (pixels) and their distance "
                           "(mm)")
    parser.add_argument("--out", "-o", default=None,
                        help="sidecar to write (default: <photo>_capture.json beside it)")
    parser.add_argument("--dark", default=None,
                        help="dark frame of the same size (beam off), subtracted")
    parser.add_argument("--black-level", type=float, default=None,
                        help="raw value of no light, without a dark frame (default 0; a "
                             "RAW's own, which this replaces)")
    parser.add_argument("--white-level", type=float, default=None,
                        help="raw value at and above which a pixel is clipped (default: the "
                             "integer type's top code, a RAW's own; none for float photos)")
    parser.add_argument("--incident", type=float, nargs=2, default=None, metavar=("X", "Y"),
                        help="where the beam enters, pixels (default: the brightest spot)")
    parser.add_argument("--eta", type=float, default=1.3,
                        help="relative index of the slab (default 1.3)")
    parser.add_argument("--unknown-eta", action="store_true",
                        help="write eta as null (the fitter then fits it)")
    parser.add_argument("--side", choices=("reflection", "transmission"), default="reflection")
    parser.add_argument("--thickness", type=float, default=None,
                        help="slab thickness, mm (default: semi-infinite)")
    parser.add_argument("--beam-radius", type=float, default=0.0,
                        help="1/e^2 radius (Gaussian) or radius (top hat) of the beam, mm "
                             "(default 0: a pencil)")
    parser.add_argument("--beam-profile", choices=("gaussian", "top_hat"), default="gaussian")
    parser.add_argument("--beam-image", default=None,
                        help="linear photo of the beam on a white diffuse target: the fitter "
                             "then convolves with the measured beam")
    parser.add_argument("--beam-pixel-size-mm", type=float, default=None,
                        help="pixel size of --beam-image on the target, mm (default: the "
                             "capture's; a finer one is better)")


def run(args) -> int:
    """Import the photo, print what was found, 0 on success."""
    from ...atomic import check_input_file, note_input
    from ...fitting.photo_import import import_photo, ruler_pixel_size

    photo = Path(args.photo)
    # before the outputs are named: none of them may replace a photo (-o photo.json next
    # to photo.exr would write the capture's image over it)
    for field, path in (("photo", args.photo), ("--dark", args.dark),
                        ("--beam-image", args.beam_image)):
        if path is not None:
            check_input_file(path, field, what="photo")
            note_input(path, field)
    pixel = args.pixel_size_mm if args.ruler is None else ruler_pixel_size(*args.ruler)
    out = Path(args.out) if args.out else photo.with_name(f"{photo.stem}_capture.json")
    result = import_photo(photo, out, pixel_size_mm=pixel, dark=args.dark,
                          black_level=args.black_level, white_level=args.white_level,
                          incident_px=args.incident,
                          eta=None if args.unknown_eta else args.eta, side=args.side,
                          thickness_mm=args.thickness, beam_radius_mm=args.beam_radius,
                          beam_profile=args.beam_profile, beam_image=args.beam_image,
                          beam_pixel_size_mm=args.beam_pixel_size_mm)
    contrast = "" if result.spot_contrast != result.spot_contrast else \
        f" (spot {result.spot_contrast:.0f} noise standard deviations above the median)"
    print(f"incident point {result.incident_px[0]:.2f}, {result.incident_px[1]:.2f} px"
          f"{contrast}; pixel size {result.pixel_size_mm:.5g} mm; "
          f"{result.saturated_pixels} clipped pixels")
    if result.raw_layout:
        print(f"camera RAW: {result.raw_layout}; each colour at its own photosites")
    print(f"wrote {result.sidecar}, {result.image.name} and {result.preview.name}: check the "
          f"preview, then `translucent fit {result.sidecar}`")
    from .record import record

    record(args, sidecar=str(result.sidecar), image=str(result.image),
           preview=str(result.preview), incident_px=list(result.incident_px),
           pixel_size_mm=result.pixel_size_mm, saturated_pixels=result.saturated_pixels,
           spot_contrast=result.spot_contrast)
    return 0
