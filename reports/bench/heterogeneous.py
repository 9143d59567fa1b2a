r"""What the heterogeneous heuristics cost: splatting and radiosity against the volume.

``translucent bench heterogeneous`` renders a sphere (radius 10 mm, index-matched, one
point light: the ``solid_checker`` scene) whose medium is a 3D checker of two media
(:func:`~translucent.materials.solid.checker_solid`), with Mitsuba 3 volumetric path
tracing of the solid medium as the reference, and with splatting (Chen et al. 2012,
Eq. 8) and radiosity (Sheng et al. 2014, Eq. 16), which read the medium at the surface
(:mod:`translucent.fast.solid_inputs`). Two sweeps:

* **contrast**: the second medium moves from the first (``t = 0``: the homogeneous limit,
  where only the dipole model's own error remains) to the pair's second medium
  (``t = 1``) by linear mixing of the coefficients, at a fixed cell size;
* **cell size**: the pair at full contrast with ``2 .. 16`` cells a side, from cells
  larger than the diffusion length (light stays in one medium) to cells smaller than it
  (light crosses many cells under the surface).

The default pair is the catalogue's most different pair among the media whose references
are affordable (single-scattering albedo at most :data:`AFFORDABLE_ALBEDO`: the walks of
Marble, milks, Cream and Spectralon are hundreds of events long): the largest ratio of
diffusion lengths :math:`1/\sigma_{tr}` in some channel.

Every row prints each method's HDR-FLIP and relative MSE (the reference's variance
discounted) over the object's pixels, with the reference's own noise beside them, as in
``translucent bench model_error``; a method's relative MSE below the noise's is marked
``*`` (the reference does not resolve it). JSON and Markdown go to ``--out`` after every
row.
"""

from __future__ import annotations

import itertools
import math
import time
from pathlib import Path

import numpy as np

from ...atomic import check_output_folder
from ...errors import InputError, check_count
from ...materials import Dipole, measured_medium, measured_medium_names
from . import count_list, quick_knobs, with_size
from .model_error import (
    method_cells,
    object_mask,
    object_metrics,
    reference_noise,
    table_cell,
    write_table,
)

__all__ = ["AFFORDABLE_ALBEDO", "METHODS", "most_different_pair", "diffusion_lengths",
           "checker_scene", "measure_checker", "heterogeneous_table", "markdown"]

#: The surface methods of heterogeneous media, in column order.
METHODS = ("splatting", "radiosity")

#: Media whose largest single-scattering albedo is at most this have walks of tens of
#: events, which a 2-core reference converges in minutes.
AFFORDABLE_ALBEDO = 0.99

SCENE = "solid_checker"
OBJECT = "sphere"
DEFAULT_SIZE = 48
DEFAULT_SPP = 256
DEFAULT_PASSES = 8
#: Geometry-image rows of the sphere (radiosity's precomputation grows with its faces).
DEFAULT_ROWS = 33
DEFAULT_CONTRASTS = (0.0, 0.25, 0.5, 1.0)
DEFAULT_CELLS = (2, 4, 8, 16)
#: Cells a side in the contrast sweep (5 mm cells in the 20 mm box).
CONTRAST_CELLS = 4
JSON_NAME = "heterogeneous.json"
MARKDOWN_NAME = "heterogeneous.md"
FORMAT = 2


def diffusion_lengths(medium: Dipole) -> np.ndarray:
    r"""Return :math:`1/\sigma_{tr} = 1/\sqrt{3\sigma_a(\sigma_a + \sigma'_s)}` per channel, mm."""
    with np.errstate(divide="ignore"):
        return 1.0 / np.sqrt(3.0 * medium.sigma_a * (medium.sigma_a + medium.sigma_s_prime))


def _contrast(first: Dipole, second: Dipole) -> float:
    """Largest ratio of the two media's diffusion lengths over channels (>= 1)."""
    ratio = diffusion_lengths(first) / diffusion_lengths(second)
    return float(np.exp(np.max(np.abs(np.log(ratio)))))


def most_different_pair() -> tuple[str, str]:
    """Return the affordable measured pair of the largest diffusion-length ratio."""
    media = [measured_medium(name) for name in measured_medium_names()]
    affordable = [m for m in media if np.all(np.isfinite(diffusion_lengths(m)))
                  and float(np.max(m.albedo)) <= AFFORDABLE_ALBEDO]
    first, second = max(itertools.combinations(affordable, 2),
                        key=lambda pair: _contrast(*pair))
    return first.name, second.name


def _mixed(first: Dipole, second: Dipole, t: float) -> Dipole:
    return Dipole((1 - t) * first.sigma_a + t * second.sigma_a,
                  (1 - t) * first.sigma_s_prime + t * second.sigma_s_prime, eta=1.0, g=0.0,
                  name=f"{first.name}->{second.name} t={t:g}")


def checker_scene(first: Dipole, second: Dipole, cells: int, *, size: int = DEFAULT_SIZE,
                  rows: int = DEFAULT_ROWS):
    """Return the ``solid_checker`` scene with a checker of ``first`` and ``second``."""
    from ...materials.solid import checker_solid
    from ...scenes import load_scene
    from ...scenes.meshes import geometry_image
    from ...scenes.scene import SceneObject

    scene = with_size(load_scene(SCENE), size, size)
    obj = scene.object(OBJECT)
    mesh = geometry_image(rows, shape="sphere", radius=1.0)
    solid = checker_solid(first, second, cells=cells, eta=1.0)
    return type(scene)((SceneObject(obj.name, mesh, solid),), scene.lights, scene.camera,
                       scene.mm_per_unit, scene.name, scene.description)


def measure_checker(scene, *, spp: int = DEFAULT_SPP, passes: int = DEFAULT_PASSES,
                    methods=METHODS, mask=None) -> dict:
    """Return one row: the reference's noise, each rule's and each method's error on ``scene``.

    Each mixing rule (:data:`~translucent.materials.profiles.HETEROGENEOUS_RULES`) is
    rendered exactly by the BSSRDF path tracer with the dipole of each medium (``spp`` x
    ``passes``): its error against the volumetric reference is the rule's (the *model*,
    both renders' variances discounted), and a method's error against its own rule's
    render is the method's own (the *approximation*).
    """
    from ...fast.base import method as method_module
    from ...materials.profiles import HETEROGENEOUS_RULES
    from ...reference import render
    from ..report.runs import run_method
    from ..report.split import with_both_variances

    mask = object_mask(scene, OBJECT) if mask is None else mask
    started = time.perf_counter()
    reference = render(scene, spp=spp, passes=passes, progress=False)
    noise = reference_noise(reference, mask)
    models, rules = {}, {}
    for rule in HETEROGENEOUS_RULES:
        models[rule] = render(scene, spp=spp, passes=passes, progress=False,
                              integrator="bssrdf_path", profile=f"dipole+{rule}")
        rules[rule] = {"seconds": models[rule].metadata.get("seconds"),
                       **object_metrics(with_both_variances(reference, models[rule]),
                                        models[rule], mask)}
    results = {}
    knobs = quick_knobs(methods) or {}
    for name in methods:
        run = run_method(name, scene, knobs.get(name))
        entry = {"status": run.status, "reason": run.reason,
                 "precompute_seconds": run.precompute_seconds,
                 "frame_seconds": run.frame_seconds}
        if run.status == "ok":
            entry.update(object_metrics(reference, run.image, mask))
            entry["dominated_by"] = ("model" if entry["relative_mse"]
                                     > noise["noise_relative_mse"] else "noise")
            entry["solid_medium"] = (run.notes or {}).get("solid medium", {}).get(OBJECT)
            rule = method_module(name).HETEROGENEOUS_RULE
            own = object_metrics(models[rule], run.image, mask)
            entry["rule"] = rule
            entry["approximation"] = {key: own[key] for key in
                                      ("relative_mse", "hdr_flip", "luminance_ratio")}
            entry["dominant"] = ("model" if rules[rule]["relative_mse"]
                                 >= own["relative_mse"] else "approximation")
        results[name] = entry
    return {"reference": {"seconds": reference.metadata.get("seconds"), **noise},
            "rules": rules, "methods": results, "seconds": time.perf_counter() - started}


def _check(size, spp, passes, rows, methods, contrasts, cells):
    check_count(size, "--size", 11, why=" (FLIP and SSIM need 11 x 11 pixels)")
    check_count(spp, "--spp")
    check_count(passes, "--passes", 2, why=" (the reference's noise needs two passes)")
    check_count(rows, "--rows", 5)
    if rows % 2 == 0:
        raise InputError("must be odd (the sphere's geometry image)", field="--rows",
                         value=rows)
    unknown = [m for m in methods if m not in METHODS]
    if unknown or not methods:
        raise InputError(f"unknown or no method; valid: {', '.join(METHODS)}",
                         field="--methods", value=",".join(unknown))
    for t in contrasts:
        if not (math.isfinite(t) and 0.0 <= t <= 1.0):
            raise InputError("each must be in [0, 1]", field="--contrasts", value=t)
    for count in cells:
        if count > 64:
            raise InputError("at most 64 cells a side", field="--cells", value=count)


def heterogeneous_table(out, *, pair=None, contrasts=DEFAULT_CONTRASTS, cells=DEFAULT_CELLS,
                        methods=METHODS, size: int = DEFAULT_SIZE, spp: int = DEFAULT_SPP,
                        passes: int = DEFAULT_PASSES, rows: int = DEFAULT_ROWS,
                        json_path=None, progress: bool = True) -> dict:
    """Run both sweeps; write JSON and Markdown into ``out`` after every row.

    Parameters
    ----------
    out : str or PathLike
        Folder for ``heterogeneous.json`` and ``heterogeneous.md``.
    pair : (str, str), optional
        The two measured media; default :func:`most_different_pair`.
    contrasts : sequence of float
        Mixing fractions ``t`` in [0, 1] of the contrast sweep.
    cells : sequence of int
        Cells a side of the cell-size sweep.
    methods : sequence of str
    size, spp, passes, rows : int
        Image side, reference samples per pixel per pass and passes, sphere grid rows.

    Returns
    -------
    dict
        The context, ``rows`` (sweep, t, cells, cell size and its ratio to the diffusion
        length, contrast, and :func:`measure_checker`'s row) and ``complete``.
    """
    from ...progress import progress_bar
    from ..report.runs import backend_versions

    methods = tuple(methods)
    contrasts, cells = [float(t) for t in contrasts], [int(c) for c in cells]
    _check(size, spp, passes, rows, methods, contrasts, cells)
    names = most_different_pair() if pair is None else tuple(pair)
    if len(names) != 2:
        raise InputError("needs two media", field="--pair", value=",".join(names))
    try:
        first, second = (measured_medium(name) for name in names)
    except InputError as error:
        raise InputError(error.reason, field="--pair", value=",".join(names)) from error
    out = check_output_folder(out, "--out")
    json_path = out / JSON_NAME if json_path is None else Path(json_path)
    plan = [("contrast", t, CONTRAST_CELLS) for t in contrasts] + \
        [("cell size", 1.0, count) for count in cells]
    probe = checker_scene(first, second, 2, size=size, rows=rows)
    mask = object_mask(probe, OBJECT)
    box_mm = 2.0 * probe.mm_per_unit
    result = {"benchmark": "heterogeneous", "format": FORMAT, "scene": SCENE,
              "description": "sphere of radius 10 mm, index-matched, one point light; a 3D "
                             "checker of two media over its 20 mm box",
              "pair": list(names), "full_contrast": _contrast(first, second),
              "size": [size, size], "object_pixels": int(mask.sum()), "rows_of_mesh": rows,
              "reference": {"renderer": "Mitsuba 3 volumetric path tracing, heterogeneous "
                                        "medium on the checker's grid", "spp": spp,
                            "passes": passes},
              "methods": list(methods), "versions": backend_versions(), "complete": False,
              "rows": []}
    started = time.perf_counter()
    for sweep, t, count in progress_bar(plan, description="heterogeneous", unit="row",
                                        enabled=progress, terminal_only=False):
        other = _mixed(first, second, t)
        base = _mixed(first, second, 0.0)
        scene = checker_scene(base, other, count, size=size, rows=rows)
        longest = float(max(np.max(diffusion_lengths(base)), np.max(diffusion_lengths(other))))
        cell_mm = box_mm / count
        row = {"sweep": sweep, "t": t, "cells": count, "cell_mm": cell_mm,
               "cell_over_diffusion_length": cell_mm / longest,
               "contrast": _contrast(base, other),
               **measure_checker(scene, spp=spp, passes=passes, methods=methods, mask=mask)}
        result["rows"].append(row)
        result["seconds"] = time.perf_counter() - started
        write_table(result, json_path, out / MARKDOWN_NAME, markdown)
    result["complete"] = True
    write_table(result, json_path, out / MARKDOWN_NAME, markdown)
    return result


def markdown(result: dict) -> str:
    """Return the table of a :func:`heterogeneous_table` result as Markdown."""
    methods = result["methods"]
    first, second = result["pair"]
    lines = [f"# Heterogeneous heuristics against the volumetric reference ({result['scene']})",
             "", f"{result['description']}; pair {first} / {second} (largest diffusion-length "
             f"ratio {result['full_contrast']:.3g}); {result['size'][0]} x "
             f"{result['size'][1]} px, {result['object_pixels']} object pixels; reference "
             f"{result['reference']['spp']} spp x {result['reference']['passes']} passes.", "",
             "t: fraction of the way from the first medium to the second (0: homogeneous); "
             "cell / l_d: cell edge over the longest diffusion length 1/sigma_tr of the two "
             "media. Metrics over the object's pixels; relMSE with the reference's noise "
             "discounted, * where it is below what the noise alone gives.", "",
             f"Complete: {'yes' if result['complete'] else 'no (a partial table)'}.", ""]
    rules = list(result["rows"][0].get("rules", {})) if result["rows"] else []
    header = ["sweep", "t", "cells", "cell mm", "cell / l_d", "contrast", "ref SE",
              "noise relMSE"]
    header += [f"{rule} relMSE" for rule in rules]
    for name in methods:
        header += [f"{name} FLIP", f"{name} relMSE", f"{name} Y ratio", f"{name} own relMSE"]
    lines += ["Each rule's relMSE: the rule rendered exactly (BSSRDF path tracer, the dipole of "
              "each medium) against the reference, the model's error; a method's own relMSE: "
              "the method against its own rule's render (splatting: geometric_mean, Eq. 8; "
              "radiosity: segment_mix, Eq. 16), its approximation's error.", ""]
    lines += ["| " + " | ".join(header) + " |", "|" + " --- |" * len(header)]
    for row in result["rows"]:
        noise = row["reference"]
        cells = [row["sweep"], table_cell(row["t"]), str(row["cells"]),
                 table_cell(row["cell_mm"]), table_cell(row["cell_over_diffusion_length"]),
                 table_cell(row["contrast"]), table_cell(noise["relative_standard_error"]),
                 table_cell(noise["noise_relative_mse"])]
        cells += [table_cell(row.get("rules", {}).get(rule, {}).get("relative_mse"))
                  for rule in rules]
        for name in methods:
            entry = row["methods"].get(name, {})
            cells += method_cells(entry)
            cells.append(table_cell((entry.get("approximation") or {}).get("relative_mse")))
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


#: ``--quick``: a 12-pixel image, a 9-row sphere, one contrast, one cell size, 4 x 2 spp.
QUICK_ARGUMENTS: dict = {"size": 12, "rows": 9, "contrasts": "1", "cells": "2", "spp": 4,
                         "passes": 2}


def add_arguments(parser):
    """Options of ``translucent bench heterogeneous``."""
    parser.add_argument("--out", default="heterogeneous",
                        help="folder for heterogeneous.json and heterogeneous.md "
                             "(default ./heterogeneous)")
    parser.add_argument("--pair", default=None,
                        help="two measured media, comma-separated (default: the most "
                             "different affordable pair)")
    parser.add_argument("--contrasts", default=",".join(f"{t:g}" for t in DEFAULT_CONTRASTS),
                        help="mixing fractions t in [0, 1] of the contrast sweep")
    parser.add_argument("--cells", default=",".join(str(c) for c in DEFAULT_CELLS),
                        help="cells a side of the cell-size sweep (empty: no sweep)")
    parser.add_argument("--methods", default=",".join(METHODS))
    parser.add_argument("--size", type=int, default=DEFAULT_SIZE)
    parser.add_argument("--spp", type=int, default=DEFAULT_SPP,
                        help="reference samples per pixel per pass")
    parser.add_argument("--passes", type=int, default=DEFAULT_PASSES)
    parser.add_argument("--rows", type=int, default=DEFAULT_ROWS,
                        help="geometry-image rows of the sphere (odd)")
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")


def _fractions(text: str) -> list[float]:
    values = []
    for part in (p.strip() for p in str(text).split(",")):
        if not part:
            continue
        try:
            values.append(float(part))
        except ValueError as error:
            raise InputError("must be comma-separated numbers in [0, 1]",
                             field="--contrasts", value=text) from error
    return values


def run(args) -> int:
    """Run both sweeps, print the table, write JSON and Markdown into ``--out``."""
    pair = None if args.pair is None else [p.strip() for p in args.pair.split(",")]
    methods = [m.strip() for m in args.methods.split(",") if m.strip()]
    result = heterogeneous_table(
        Path(args.out), pair=pair, contrasts=_fractions(args.contrasts),
        cells=count_list(args.cells, "--cells", allow_empty=True), methods=methods,
        size=args.size, spp=args.spp, passes=args.passes, rows=args.rows,
        json_path=args.json, progress=not args.no_progress)
    print(markdown(result), end="")
    out = Path(args.out)
    print(f"wrote {Path(args.json) if args.json else out / JSON_NAME} and "
          f"{out / MARKDOWN_NAME} in {result['seconds']:.1f} s")
    return 0
