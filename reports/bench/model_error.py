"""Model error: the fast methods against Mitsuba volumetric path tracing, 12 measured media.

``translucent bench model_error`` renders the built-in ``sphere`` scene (a 10 mm sphere
under a point light) once per measured medium of Jensen et al. 2001 (Table 1,
:mod:`translucent.materials.catalogue`), with Mitsuba 3 volumetric path tracing as the
reference (:func:`translucent.reference.render`, cached: rendered once per medium, size,
spp and passes) and with each fast method that applies (``prt``, ``splatting``,
``radiosity``; ``--methods``) at its default knobs
(:func:`translucent.reports.report.run_method`). It prints, per medium and method:

* HDR-FLIP (Andersson et al. 2021) and the relative MSE with the reference's own noise
  discounted (:func:`translucent.reports.metrics.relative_mse`), both over the object's
  pixels only (the background is black in every image and would dilute the means);
* the reference's own noise, so that a reader sees whether it or the model dominates:
  the median relative standard error of its mean over the object's pixel channels; the
  relative MSE that this noise alone adds (the amount the discounting subtracts); and the
  HDR-FLIP of the reference against a copy of itself with Gaussian noise of its own
  per-pixel variance added (about the FLIP the reference's noise alone causes).

A method's relative MSE below the noise's own is marked "noise": the reference does not
resolve that model error, and more samples (``--spp``, ``--passes``) are needed.

The media are made index-matched (``eta = 1``, ``--eta`` to try others): the built-in
sphere scene is index-matched because a point light behind a smooth dielectric boundary
cannot be reached by next-event estimation in ``volpath`` (docs/references.md), and its reference
at ``eta = 1.5`` stays at a relative standard error of 0.6-0.9 after 256 spp at 48 x 48.
The dipole takes the same ``eta``, so the table measures the model and the method, not a
mismatch of boundaries. This measures the dipole model (Jensen et al. 2001) as each method
uses it, not the method's approximation of its own model: it is reported, not tuned.

The table is written as JSON and Markdown into ``--out`` after every medium (a run that
stops at medium 9 keeps media 1-8; running it again re-renders no reference, since they
are cached), with one PNG per medium (reference, then each method, at the reference's
exposure).
"""

from __future__ import annotations

import math
import time
from pathlib import Path

import numpy as np

from ...atomic import atomic_write_text, check_output_folder
from ...errors import InputError, check_count
from ...materials import Dipole, measured_medium, measured_medium_names
from ..report.split import requested_profiles
from . import quick_knobs, write_figures
from ._model_error_profiles import measure_profiles, profiles_markdown

__all__ = [
    "DEFAULT_ETA",
    "DEFAULT_PASSES",
    "DEFAULT_SIZE",
    "DEFAULT_SPP",
    "METHODS",
    "NOISE_FLIP_SEED",
    "SCENE",
    "bench_scene",
    "index_matched",
    "markdown",
    "method_cells",
    "table_cell",
    "write_table",
    "measure_medium",
    "model_error_table",
    "object_mask",
    "object_metrics",
    "reference_noise",
]

#: The fast methods of homogeneous translucency the table covers, in column order.
METHODS = ("prt", "splatting", "radiosity")

#: The built-in scene and its translucent object.
SCENE = "sphere"
OBJECT = "sphere"

#: Defaults sized for a 2-core CPU: a 48 x 48 image, 64 spp x 4 passes (256 spp in all),
#: where the index-matched references reach a median relative standard error of 0.07
#: (Potato, Marble) to 0.12 (Ketchup); the 12 media with the three methods took 22 minutes
#: of wall clock on this shared machine (measured; docs/model-error.md).
DEFAULT_SIZE = 48
DEFAULT_SPP = 64
DEFAULT_PASSES = 4

#: Index-matched boundary: the reference converges (see the module docstring).
DEFAULT_ETA = 1.0

#: FLIP needs images of at least this side (the SSIM window the shared check enforces).
MIN_SIZE = 11

#: Seed of the Gaussian noise added to the reference for its noise-only HDR-FLIP.
NOISE_FLIP_SEED = 20260101

#: Output files inside ``--out``.
JSON_NAME = "model_error.json"
MARKDOWN_NAME = "model_error.md"

#: Bumped when the JSON layout changes.
FORMAT = 1


# ---------------------------------------------------------------------- the pieces


def index_matched(name: str, eta: float = DEFAULT_ETA) -> Dipole:
    """Return the measured medium ``name`` with its boundary's index replaced by ``eta``.

    Parameters
    ----------
    name : str
        A medium of Jensen et al. 2001, Table 1 (case-insensitive).
    eta : float
        Relative index of refraction of the boundary, in [1, 3]; 1 is index-matched.

    Returns
    -------
    Dipole
        The table's sigma_a and sigma_s' (mm^-1, R G B), ``eta`` and g = 0.

    Raises
    ------
    InputError
        An unknown name (the message lists the valid ones) or ``eta`` outside [1, 3].
    """
    medium = measured_medium(name)
    return Dipole(sigma_a=medium.sigma_a, sigma_s_prime=medium.sigma_s_prime, eta=eta,
                  g=medium.g, name=medium.name)


def bench_scene(size: int = DEFAULT_SIZE):
    """Return the built-in sphere scene seen by a ``size`` x ``size`` camera.

    Parameters
    ----------
    size : int
        Image side in pixels, at least :data:`MIN_SIZE`.

    Returns
    -------
    Scene
    """
    from ...scenes import load_scene
    from . import with_size

    return with_size(load_scene(SCENE), size, size)


def object_mask(scene, object_name: str = OBJECT) -> np.ndarray:
    """Return the pixels that see ``object_name`` (its G-buffer coverage), ``(H, W)`` bool."""
    from ...scenes import gbuffer

    buffer = gbuffer(scene)
    index = buffer.object_names.index(object_name)
    return buffer.object_id == index


def reference_noise(reference, mask: np.ndarray) -> dict:
    r"""Return how noisy a reference is on the pixels of ``mask``.

    Parameters
    ----------
    reference : Image
        A path-traced mean with the variance of that mean (``passes >= 2``).
    mask : ndarray of bool, shape (H, W)
        The object's pixels.

    Returns
    -------
    dict
        ``relative_standard_error``: the median over the object's pixel channels of
        :math:`\sigma_r / r` (channels where :math:`r > 0`; a fraction);
        ``relative_standard_error_mean``: their mean (fireflies raise it);
        ``noise_relative_mse``: :math:`\mathrm{mean}(\sigma_r^2 / (r^2 + \epsilon))`, what
        the noise adds to the raw relative MSE and what :func:`relative_mse` subtracts
        (dimensionless, ``RELMSE_EPSILON``); ``noise_hdr_flip``: HDR-FLIP over the object
        of the reference against itself plus Gaussian noise of its own per-pixel variance
        (seed :data:`NOISE_FLIP_SEED`), about the FLIP the reference's noise alone causes
        (heavy-tailed path-tracing noise is not Gaussian: an indication, not a bound).
    """
    from ..metrics.compute import RELMSE_EPSILON, flip_map

    rgb = reference.rgb.astype(np.float64)
    variance = reference.variance.astype(np.float64)
    values, spread = rgb[mask], variance[mask]
    lit = values > 0
    relative = np.sqrt(spread[lit]) / values[lit]
    noisy = rgb + np.random.default_rng(NOISE_FLIP_SEED).normal(size=rgb.shape) * np.sqrt(
        variance)
    _, flip = flip_map(rgb, np.maximum(noisy, 0.0), dynamic_range="HDR")
    return {
        "relative_standard_error": float(np.median(relative)) if relative.size else math.nan,
        "relative_standard_error_mean": float(relative.mean()) if relative.size else math.nan,
        "noise_relative_mse": float(np.mean(spread / (values**2 + RELMSE_EPSILON))),
        "noise_hdr_flip": float(flip[mask].mean()),
    }


def object_metrics(reference, test, mask: np.ndarray) -> dict:
    """Return HDR-FLIP and relative MSE of ``test`` against ``reference`` on ``mask``.

    HDR-FLIP (Andersson et al. 2021) is computed on the whole images (its filters see the
    silhouette's neighbourhood) and its per-pixel map averaged over the object's pixels;
    the relative MSE (:func:`~translucent.reports.metrics.relative_mse`) is taken over
    the object's pixel channels, with the reference's variance discounted.

    Parameters
    ----------
    reference, test : Image
        Same size; linear radiance.
    mask : ndarray of bool, shape (H, W)
        The object's pixels.

    Returns
    -------
    dict
        ``hdr_flip`` (object pixels, 0 is identical), ``hdr_flip_image`` (whole image),
        ``relative_mse`` (noise discounted), ``relative_mse_raw`` (dimensionless),
        ``mean_ratio`` (R, G, B: the test's mean radiance over the object divided by the
        reference's; 1 where the energy agrees) and ``luminance_ratio`` (the same for the
        luminance Y).

    Raises
    ------
    InputError
        Images of different sizes, NaN pixels, an all-black reference.
    """
    from ..metrics.compute import evaluate, luminance, relative_mse

    comparison = evaluate(reference, test)  # checks sizes, NaN and a black reference
    ref, tst = reference.rgb.astype(np.float64), test.rgb.astype(np.float64)
    variance = None if reference.variance is None else reference.variance[mask]
    with np.errstate(divide="ignore", invalid="ignore"):  # a black channel: inf or NaN
        mean_ratio = tst[mask].mean(axis=0) / ref[mask].mean(axis=0)
        luminance_ratio = luminance(tst[mask]).mean() / luminance(ref[mask]).mean()
    return {
        "hdr_flip": float(comparison.maps["flip"][mask].mean()),
        "hdr_flip_image": comparison.metrics.hdr_flip,
        "relative_mse": relative_mse(ref[mask], tst[mask], reference_variance=variance),
        "relative_mse_raw": relative_mse(ref[mask], tst[mask]),
        "mean_ratio": mean_ratio.tolist(),
        "luminance_ratio": float(luminance_ratio),
    }


def _reference(scene, spp: int, passes: int):
    """Render (or load from the cache) the reference; return it and whether it was cached."""
    from ...reference import render
    from ..report.runs import reference_path

    cached = reference_path(scene, spp, passes).is_file()
    return render(scene, spp=spp, passes=passes, progress=False), cached


def _side_by_side(folder: Path, name: str, reference, images: dict) -> str:
    """Write the reference and each method's image in one PNG at the reference's exposure."""
    from ..metrics.compute import display_white
    from ..metrics.maps import srgb8, write_png

    white = display_white(reference.rgb)
    gap = np.full((reference.shape[0], 2, 3), 255, dtype=np.uint8)
    tiles = [srgb8(reference.rgb, white=white)]
    for image in images.values():
        tiles += [gap, srgb8(image.rgb, white=white)]
    path = folder / f"{name}.png"
    write_png(path, np.concatenate(tiles, axis=1))
    return path.name


def measure_medium(scene, medium: Dipole, methods=METHODS, *, spp: int = DEFAULT_SPP,
                   passes: int = DEFAULT_PASSES, method_medium: Dipole | None = None,
                   mask: np.ndarray | None = None, images: Path | None = None,
                   knobs: dict | None = None, profiles=()) -> dict:
    """Return one row of the table: a medium's reference, its noise, each method's error.

    Parameters
    ----------
    scene : Scene
        The sphere scene (:func:`bench_scene`); its object :data:`OBJECT` gets ``medium``.
    medium : Dipole
        The medium path-traced for the reference (coefficients in mm^-1).
    methods : sequence of str
        Fast methods (:data:`METHODS`), each run at its default knobs.
    spp, passes : int
        Reference samples per pixel per pass and independent passes (>= 2: the noise).
    method_medium : Dipole, optional
        The medium the methods render; default ``medium``. Another medium measures a
        deliberately mismatched material (a check that the table can tell them apart).
    mask : ndarray of bool, optional
        The object's pixels; default :func:`object_mask` of ``scene``.
    images : Path, optional
        A folder for the side-by-side PNG (none written when None).
    knobs : dict, optional
        Method name -> knobs for its ``precompute`` besides its defaults (the benchmark
        uses the defaults; tests make the methods cheaper).
    profiles : sequence of str
        Radial profiles for the profile axis (:mod:`._model_error_profiles`); none: no axis.

    Returns
    -------
    dict
        ``medium``, ``sigma_a``, ``sigma_s_prime`` (mm^-1), ``eta``, ``method_medium``,
        ``reference`` (seconds, cached, integrator, per_channel and
        :func:`reference_noise`), ``methods`` (per method: status, reason, seconds and
        :func:`object_metrics`, ``dominated_by`` "model" or "noise"), ``image``.
    """
    from ..report.runs import run_method

    method_medium = medium if method_medium is None else method_medium
    mask = object_mask(scene) if mask is None else mask
    reference, cached = _reference(scene.with_material(OBJECT, medium), spp, passes)
    noise = reference_noise(reference, mask)
    method_scene = scene.with_material(OBJECT, method_medium)
    results, rendered, runs = {}, {}, {}
    for name in methods:
        run = runs[name] = run_method(name, method_scene, (knobs or {}).get(name))
        entry = {"status": run.status, "reason": run.reason,
                 "precompute_seconds": run.precompute_seconds,
                 "frame_seconds": run.frame_seconds}
        if run.status == "ok":
            try:
                entry.update(object_metrics(reference, run.image, mask))
            except InputError as error:
                entry.update(status="failed", reason=f"metrics: {error}")
            else:
                entry["dominated_by"] = ("model" if entry["relative_mse"]
                                         > noise["noise_relative_mse"] else "noise")
                rendered[name] = run.image
        results[name] = entry
    meta = reference.metadata
    row = {"medium": medium.name, "sigma_a": medium.sigma_a.tolist(),
           "sigma_s_prime": medium.sigma_s_prime.tolist(), "eta": medium.eta,
           "method_medium": method_medium.name,
           "reference": {"seconds": meta.get("seconds"), "cached": cached,
                         "integrator": meta.get("integrator"),
                         "per_channel": meta.get("per_channel"), **noise},
           "methods": results, "image": None}
    if profiles:
        row["profiles"] = measure_profiles(method_scene, method_medium, reference, mask,
                                           methods, profiles, runs, spp=spp, passes=passes,
                                           metrics=object_metrics, noise=reference_noise,
                                           knobs=knobs)
    if images is not None:
        row["image"] = f"{images.name}/{_side_by_side(images, medium.name, reference, rendered)}"
    return row


# ---------------------------------------------------------------------- the table


def _check(size: int, spp: int, passes: int, methods, eta: float) -> tuple:
    for name, value, minimum in (("--size", size, MIN_SIZE), ("--spp", spp, 1),
                                 ("--passes", passes, 2)):
        why = {"--size": " (FLIP and SSIM need 11 x 11 pixels)",
               "--passes": " (the reference's noise needs two passes)"}.get(name, "")
        check_count(value, name, minimum, why=why)
    methods = tuple(methods)
    unknown = [m for m in methods if m not in METHODS]
    if unknown or not methods:
        raise InputError(f"unknown or no fast method; valid: {', '.join(METHODS)}",
                         field="--methods", value=",".join(unknown) or "")
    if not (math.isfinite(eta) and 1.0 <= eta <= 3.0):
        raise InputError("must be in [1, 3] (1: index-matched)", field="--eta", value=eta)
    return int(size), int(spp), int(passes), methods, float(eta)


def _context(scene, mask, size, spp, passes, methods, eta, media) -> dict:
    from ..report.runs import backend_versions

    boundary = ("index-matched (eta = 1): the boundary neither refracts nor reflects, in the "
                "reference and in the dipole" if eta == 1.0 else
                f"dielectric boundary of eta = {eta:g} in the reference and the dipole; the "
                "reference reaches the point light through it by manifold next-event "
                "estimation (volpath_mnee)")
    return {"benchmark": "model error", "format": FORMAT, "scene": scene.name,
            "description": "the built-in sphere (radius 10 mm) under one point light, its "
                           "medium replaced in each row", "size": [size, size],
            "object_pixels": int(mask.sum()), "eta": eta, "index_matched": eta == 1.0,
            "boundary": boundary,
            "reference": {"renderer": "Mitsuba 3 volumetric path tracing", "spp": spp,
                          "passes": passes, "total_spp": spp * passes},
            "methods": list(methods), "media": list(media), "versions": backend_versions(),
            "metrics": "HDR-FLIP and relative MSE (reference variance discounted) over the "
                       "object's pixels"}


def table_cell(value, digits: int = 3) -> str:
    """Return a number for a Markdown table: ``digits`` significant figures, "–" for none."""
    if value is None or (isinstance(value, float) and not math.isfinite(value)):
        return "–"
    return f"{value:.{digits}g}"


def method_cells(entry: dict) -> list[str]:
    """Return a method's three cells (FLIP, relMSE with * when noise-dominated, Y ratio)."""
    if entry.get("status") != "ok":
        return [entry.get("status", "not run"), "–", "–"]
    star = "*" if entry["dominated_by"] == "noise" else ""
    return [table_cell(entry["hdr_flip"]), table_cell(entry["relative_mse"]) + star,
            table_cell(entry["luminance_ratio"])]


def markdown(result: dict) -> str:
    """Return the table of a :func:`model_error_table` result as Markdown."""
    methods = result["methods"]
    reference = result["reference"]
    lines = [f"# Model error against Mitsuba volumetric path tracing ({result['scene']})", "",
             f"{result['description']}; {result['size'][0]} x {result['size'][1]} px, "
             f"{result['object_pixels']} object pixels; reference {reference['spp']} spp x "
             f"{reference['passes']} passes ({reference['total_spp']} spp); boundary: "
             f"{result['boundary']}.", "",
             "Metrics over the object's pixels: HDR-FLIP (0 is identical) and relative MSE "
             "with the reference's noise discounted. ref SE: median relative standard "
             "error of the reference; noise relMSE / noise FLIP: what the reference's noise "
             "alone gives; a method's relMSE below the noise relMSE is marked * (the "
             "reference does not resolve it). Y ratio: the method's mean luminance over the "
             "object divided by the reference's.",
             "", f"Complete: {'yes' if result['complete'] else 'no (a partial table)'}.", ""]
    header = ["medium", "ref SE", "noise relMSE", "noise FLIP"]
    for name in methods:
        header += [f"{name} FLIP", f"{name} relMSE", f"{name} Y ratio"]
    lines += ["| " + " | ".join(header) + " |", "|" + " --- |" * len(header)]
    for row in result["rows"]:
        noise = row["reference"]
        cells = [row["medium"], table_cell(noise["relative_standard_error"]),
                 table_cell(noise["noise_relative_mse"]), table_cell(noise["noise_hdr_flip"])]
        for name in methods:
            cells += method_cells(row["methods"].get(name, {}))
        lines.append("| " + " | ".join(cells) + " |")
    failures = [(row["medium"], name, entry["reason"]) for row in result["rows"]
                for name, entry in row["methods"].items() if entry.get("status") != "ok"]
    if failures:
        lines += ["", "Not measured:", ""]
        lines += [f"- {medium}, {name}: {reason}" for medium, name, reason in failures]
    return "\n".join(lines) + "\n" + profiles_markdown(result, table_cell)


def write_table(result: dict, json_path: Path, markdown_path: Path, to_markdown=None) -> None:
    """Write a benchmark's result as JSON and its Markdown table (default :func:`markdown`)."""
    write_figures(json_path, "model_error", result)
    atomic_write_text(markdown_path, (to_markdown or markdown)(result))


def model_error_table(out, *, media=None, methods=METHODS, size: int = DEFAULT_SIZE,
                      spp: int = DEFAULT_SPP, passes: int = DEFAULT_PASSES,
                      eta: float = DEFAULT_ETA, json_path=None, progress: bool = True,
                      pngs: bool = True, knobs: dict | None = None, profiles=()) -> dict:
    """Measure the model error of the fast methods for measured media; write it into ``out``.

    The dipole of Jensen et al. 2001 (Eq. 4-5 there), as each method renders it, against
    Mitsuba 3 volumetric path tracing of the same medium in the built-in sphere scene.
    The JSON and Markdown are rewritten after each medium.

    Parameters
    ----------
    out : str or PathLike
        Folder for ``model_error.json``, ``model_error.md`` and ``images/``.
    media : sequence of str, optional
        Measured media (Jensen et al. 2001, Table 1); default all 12, in table order.
    methods : sequence of str
        Fast methods among :data:`METHODS`.
    size : int
        Image side in pixels (>= 11).
    spp, passes : int
        Reference samples per pixel per pass (>= 1) and passes (>= 2).
    eta : float
        Boundary index of every medium, in [1, 3]; 1 (index-matched) converges.
    json_path : str or PathLike, optional
        Where the JSON goes; default ``out/model_error.json``.
    progress : bool
        Show a progress bar over the media.
    pngs : bool
        Write a side-by-side PNG per medium into ``out/images``.
    knobs : dict, optional
        Method name -> knobs besides its defaults (see :func:`measure_medium`).
    profiles : sequence of str
        Radial profiles of the profile axis (``--profiles``; the default profile is always
        in it when any is asked): model error, and per method total and approximation
        error and speed-up over path tracing (:mod:`._model_error_profiles`).

    Returns
    -------
    dict
        The context (scene, size, reference spp, eta, versions), ``rows`` (one
        :func:`measure_medium` row per medium) and ``complete``.

    Raises
    ------
    InputError
        Bad sizes or counts, an unknown method or medium, ``eta`` outside [1, 3].
    """
    from ...cache import limited_entries
    from ...progress import progress_bar
    from ..report.runs import REPORT_CACHE_ENTRY_LIMIT

    size, spp, passes, methods, eta = _check(size, spp, passes, methods, eta)
    profiles = requested_profiles(profiles)  # the default one is measured anyway
    names = list(measured_medium_names() if media is None else media)
    if not names:
        raise InputError("no medium given", field="--media", value="")
    chosen = [index_matched(name, eta) for name in names]  # every name checked up front
    out = check_output_folder(out, "--out")
    json_path = out / JSON_NAME if json_path is None else Path(json_path)
    images = out / "images" if pngs else None
    scene = bench_scene(size)
    mask = object_mask(scene)
    result = {**_context(scene, mask, size, spp, passes, methods, eta,
                         [m.name for m in chosen]), "complete": False, "rows": []}
    started = time.perf_counter()
    bar = progress_bar(chosen, description="model error", unit="medium", enabled=progress,
                       terminal_only=False)
    # the report's policy: a medium's radiosity operators (about 1 GB on the 48 px sphere,
    # one per medium and profile, each used once) would push the references out of the
    # cache's budget, which a second run re-renders no more
    with limited_entries(REPORT_CACHE_ENTRY_LIMIT):
        for medium in bar:
            bar.set_postfix_str(medium.name)
            result["rows"].append(measure_medium(scene, medium, methods, spp=spp,
                                                 passes=passes, mask=mask, images=images,
                                                 knobs=knobs, profiles=profiles))
            result["seconds"] = time.perf_counter() - started
            write_table(result, json_path, out / MARKDOWN_NAME)
    result["complete"] = True
    write_table(result, json_path, out / MARKDOWN_NAME)
    return result


# ---------------------------------------------------------------------- the command


#: ``--quick``: one medium at 16 pixels, 4 x 2 spp, splatting and radiosity on their quick
#: knobs (the table treats every method alike; PRT's quick run is ``bench prt --quick``).
QUICK_ARGUMENTS: dict = {"media": "Skin1", "size": 16, "spp": 4, "passes": 2,
                         "methods": "splatting,radiosity"}


def add_arguments(parser):
    """Options of ``translucent bench model_error``."""
    parser.add_argument("--out", default="model_error",
                        help="folder for model_error.json, model_error.md and images/ "
                             "(default ./model_error)")
    parser.add_argument("--media", default=None,
                        help="comma-separated measured media (default: all 12 of Jensen et "
                             "al. 2001)")
    parser.add_argument("--methods", default=",".join(METHODS),
                        help=f"comma-separated fast methods (default {','.join(METHODS)})")
    parser.add_argument("--size", type=int, default=DEFAULT_SIZE,
                        help=f"image side in pixels (default {DEFAULT_SIZE})")
    parser.add_argument("--spp", type=int, default=DEFAULT_SPP,
                        help=f"reference samples per pixel per pass (default {DEFAULT_SPP})")
    parser.add_argument("--passes", type=int, default=DEFAULT_PASSES,
                        help=f"independent reference passes, >= 2 (default {DEFAULT_PASSES})")
    parser.add_argument("--eta", type=float, default=DEFAULT_ETA,
                        help="boundary index of every medium (default 1: index-matched; "
                             "the reference of a point light behind a dielectric converges "
                             "slowly)")
    parser.add_argument("--profiles", default=None, metavar="all|P1,P2",
                        help="the profile axis: each method with each of these radial "
                             "profiles, each profile's model error (BSSRDF path tracer) and "
                             "the best (method, profile) per medium with its speed-up over "
                             "path tracing")
    parser.add_argument("--no-images", action="store_true",
                        help="write no side-by-side PNG per medium")
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")


def _split(text) -> list[str] | None:
    if text is None:
        return None
    return [part.strip() for part in str(text).split(",") if part.strip()]


def run(args) -> int:
    """Measure the table, print it, write JSON and Markdown into ``--out``."""
    out = Path(args.out)
    result = model_error_table(out, media=_split(args.media), methods=_split(args.methods),
                               size=args.size, spp=args.spp, passes=args.passes,
                               eta=args.eta, json_path=args.json,
                               progress=not args.no_progress, pngs=not args.no_images,
                               profiles=_split(args.profiles),
                               knobs=quick_knobs(_split(args.methods) or METHODS))
    print(markdown(result), end="")
    print(f"wrote {Path(args.json) if args.json else out / JSON_NAME} and "
          f"{out / MARKDOWN_NAME} in {result['seconds']:.1f} s")
    return 0
