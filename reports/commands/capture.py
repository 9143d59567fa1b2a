"""Make a synthetic slab capture (image + JSON sidecar): ``translucent capture MATERIAL``.

MATERIAL is a measured medium (``marble``, ``skin1``, ...) or a material TOML file with a
dipole table (``type = "dipole"``, as ``translucent fit`` writes). The generator is the
photon random walk (``--generator walk``, the default: traced from the light, exact Fresnel
boundaries, Henyey-Greenstein scattering), Mitsuba 3 volumetric path tracing
(``--generator volpath``: a Gaussian beam starting just inside the medium, the exitance
measured on the slab face, ``--spp`` samples per pixel in passes of ``--pass-spp``) or the
exact dipole / multipole model (``--generator dipole``). The camera adds shot and read
noise, a black level, clipping at the saturation level (``--peak-signal`` above it
saturates the centre) and, unless ``--known-exposure``, leaves the exposure unknown. The
truth goes into the sidecar's ``synthetic`` object. See docs/capture-format.md.
"""

from __future__ import annotations

import math
from pathlib import Path


def add_arguments(parser):
    """Options of ``translucent capture``."""
    parser.add_argument("material", help="measured medium name or material TOML file")
    parser.add_argument("--generator", choices=("walk", "volpath", "dipole"), default="walk",
                        help="photon random walk (default), Mitsuba volumetric path tracing "
                             "or the exact dipole model")
    parser.add_argument("--out", "-o", default=None,
                        help="sidecar path (default: <material>_capture.json)")
    parser.add_argument("--format", choices=("exr", "png", "tiff"), default="exr",
                        help="image format (PNG/TIFF: 16-bit)")
    parser.add_argument("--srgb", action="store_true", help="sRGB-encode a PNG/TIFF")
    parser.add_argument("--size", type=int, default=128, help="image size, pixels")
    parser.add_argument("--pixel-size", type=float, default=None,
                        help="pixel size on the slab, mm (default: the field spans about "
                             "12 diffusion lengths of the most absorbing channel)")
    parser.add_argument("--side", choices=("reflection", "transmission"), default="reflection")
    parser.add_argument("--thickness", type=float, default=None,
                        help="slab thickness, mm (default: semi-infinite)")
    parser.add_argument("--beam-radius", type=float, default=None,
                        help="1/e^2 radius of the Gaussian beam, mm (default: 0, a pencil; "
                             "volpath needs > 0 and defaults to 5 %% of the field width)")
    parser.add_argument("--beam-profile", choices=("gaussian", "top_hat"), default="gaussian",
                        help="the beam's shape (top_hat: a uniform disk of --beam-radius; "
                             "with --generator dipole only)")
    parser.add_argument("--eta", type=float, default=None, help="override the material's eta")
    parser.add_argument("--unknown-eta", action="store_true",
                        help="write eta as null (the fitter then fits it)")
    parser.add_argument("--incident", type=float, nargs=2, default=None, metavar=("X", "Y"),
                        help="incident point, pixels (default: the centre)")
    parser.add_argument("--photons", type=float, default=2e5,
                        help="photons per channel (walk generator; about a minute per 1e5 "
                             "for a high-albedo medium on two cores)")
    parser.add_argument("--rotations", type=int, default=1,
                        help="random rotations per exit on the film (walk generator; more "
                             "give a smoother film whose error the fitter cannot see: it is "
                             "shared along each annulus; default 1)")
    parser.add_argument("--spp", type=int, default=256,
                        help="samples per pixel in all (volpath generator; per channel: "
                             "128 x 128 x 256 takes ~20 min for Skin1 on two busy cores, "
                             "hours for high-albedo media; a GPU variant is far faster)")
    parser.add_argument("--pass-spp", type=int, default=None,
                        help="most samples per pixel in one render pass (volpath; default "
                             "1024; the spread of the passes gives the standard error)")
    parser.add_argument("--sensor", choices=("exitance", "normal-radiance"),
                        default="exitance",
                        help="volpath: measure the exitance on the slab face (default) or the "
                             "radiance along the normal converted by the diffusion factor")
    parser.add_argument("--channels", choices=("separate", "rgb"), default="separate",
                        help="volpath: one grey-medium render per channel (default) or one "
                             "RGB render of the chromatic medium (fireflies in the far field)")
    parser.add_argument("--peak-signal", type=float, default=20000.0,
                        help="stored value above black of the brightest pixel before "
                             "clipping (sets the exposure)")
    parser.add_argument("--gain", type=float, default=1.0, help="electrons per stored unit")
    parser.add_argument("--read-noise", type=float, default=4.0, help="stored units")
    parser.add_argument("--black-level", type=float, default=256.0)
    parser.add_argument("--clip-at-black", action="store_true",
                        help="clip stored values at the black level, as many cameras and HDR "
                             "merges do (the fit treats those pixels as censored)")
    parser.add_argument("--saturation-level", type=float, default=65535.0)
    parser.add_argument("--known-exposure", action="store_true",
                        help="write the exposure into the sidecar")
    parser.add_argument("--seed", type=int, default=None)


def _check_out(sidecar: Path, image: Path) -> None:
    """Refuse an output the capture could not be written to, before the generator runs."""
    from ...atomic import check_output_file, make_output_folder
    from ...errors import InputError

    check_output_file(sidecar, "--out", what="the sidecar's file name (.json)")
    if image.resolve() == sidecar.resolve():
        raise InputError(f"the sidecar would overwrite the image {image.name}: give the "
                         "sidecar its own name (.json)", field="--out", value=str(sidecar))
    make_output_folder(sidecar.parent, field="--out", value=str(sidecar))


def _material_and_sidecar(args):
    """Return the material (with ``--eta``) and the sidecar to write, checked before work.

    The default sidecar is named after the material, as a file name of the working folder
    (:func:`~translucent.atomic.safe_file_name`: a material file's name may hold anything).
    """
    from dataclasses import replace

    from ...atomic import safe_file_name
    from ...errors import InputError, check_count
    from ...fitting.results import read_material

    if args.seed is not None:  # numpy takes no negative seed
        check_count(args.seed, "--seed", 0)
    material = read_material(args.material)
    if args.eta is not None:
        if not 1.0 <= args.eta <= 3.0:
            raise InputError("must be in [1, 3]", field="--eta", value=args.eta)
        material = replace(material, eta=args.eta)
    name = safe_file_name((material.name or Path(args.material).stem).lower())
    return material, Path(args.out) if args.out else Path(f"{name}_capture.json")


def run(args) -> int:
    """Generate the capture and write the image and sidecar."""
    from ...errors import InputError
    from ...fitting.synthetic import Camera, default_pixel_size, dipole_capture

    material, out = _material_and_sidecar(args)
    suffix = {"exr": ".exr", "png": ".png", "tiff": ".tif"}[args.format]
    _check_out(out, out.with_suffix(suffix))
    camera = Camera(peak_signal=args.peak_signal, gain=args.gain, read_noise=args.read_noise,
                    black_level=args.black_level, saturation_level=args.saturation_level,
                    clip_at_black=args.clip_at_black,
                    encoding="srgb" if args.srgb else "linear",
                    exposure_known=args.known_exposure, file_format=args.format)
    if args.size < 16:
        raise InputError("must be >= 16 pixels", field="--size", value=args.size)
    if not math.isfinite(args.photons):
        raise InputError("must be a finite number of photons per channel", field="--photons",
                         value=args.photons)
    from ...resources import CAPTURE_BYTES_PER_PIXEL, WALK_BYTES_PER_PHOTON, check_memory

    check_memory(args.size**2 * CAPTURE_BYTES_PER_PIXEL,
                 what=f"a {args.size} x {args.size} capture", field="--size", value=args.size)
    if args.generator == "walk":
        check_memory(args.photons * WALK_BYTES_PER_PHOTON,
                     what=f"a walk of {args.photons:.3g} photons at once", field="--photons",
                     value=args.photons)
    pixel = args.pixel_size if args.pixel_size is not None else \
        default_pixel_size(material, args.size)
    if not pixel > 0:
        raise InputError("must be > 0", field="--pixel-size", value=pixel)
    beam = args.beam_radius
    if beam is None and args.generator != "volpath":
        beam = 0.0
    if args.beam_profile != "gaussian" and args.generator != "dipole":
        raise InputError("only the dipole generator makes top-hat beams; the walk and "
                         "volpath beams are Gaussian", field="--beam-profile",
                         value=args.beam_profile)
    options = dict(size=args.size, pixel_size_mm=pixel, incident_px=args.incident,
                   side=args.side, thickness_mm=args.thickness,
                   beam_radius_mm=beam, camera=camera, seed=args.seed,
                   image_name=out.with_suffix(suffix).name, eta_known=not args.unknown_eta)
    if args.generator == "volpath":
        from ...fitting.volpath_capture import DEFAULT_PASS_SPP, volpath_capture

        stored, spec, render = volpath_capture(
            material, spp=args.spp,
            pass_spp=DEFAULT_PASS_SPP if args.pass_spp is None else args.pass_spp,
            sensor=args.sensor.replace("-", " "), channels=args.channels, progress=True,
            **options)
        detail = (f"volpath {render.spp} spp in {render.passes} passes on {render.variant}, "
                  f"{render.seconds:.1f} s, total exitance {render.total.round(4).tolist()}, "
                  f"relative standard error "
                  f"{render.relative_standard_error().round(4).tolist()}")
    elif args.generator == "walk":
        from ...fitting.random_walk import walk_capture

        stored, spec, tally = walk_capture(material, photons=int(args.photons),
                                           rotations=args.rotations, progress=True, **options)
        detail = (f"{int(args.photons)} photons per channel in {tally.seconds:.1f} s, "
                  f"total reflectance {tally.total_reflectance.round(4).tolist()}")
    else:
        stored, spec = dipole_capture(material, beam_profile=args.beam_profile, **options)
        detail = "exact dipole model"
    from ...fitting.capture import write_capture

    write_capture(out, stored, spec)
    saturated = int((stored >= camera.saturation_level).any(axis=2).sum())
    from .record import record

    record(args, sidecar=str(out), image=str(out.parent / spec.image), size=args.size,
           pixel_size_mm=pixel, generator=args.generator, saturated_pixels=saturated,
           exposure_known=bool(spec.exposure), detail=detail)
    print(f"wrote {out} and {spec.image} ({args.size} x {args.size}, {pixel:.4g} mm/px, "
          f"{detail}; {saturated} saturated pixels; exposure "
          f"{'written' if spec.exposure else 'unknown (null)'})")
    return 0
