"""How the speed-ups over path tracing grow with the image and the mesh.

``translucent bench scaling [--scenes sphere,bowl] [--sizes 96,192,384]
[--methods prt,splatting,radiosity] [--subdivisions 3,4,5] [--spp 1,4,16] [--frames 3]
[--plot FILE] [--json FILE]``

The report scores every default scene at 96 px, where path tracing is cheap. A user
renders larger images, where path tracing's cost grows with the pixels while a method's
precomputation does not. For each scene and image width N (the scene's own camera, wider):

- each method's precomputation (cold, at the first size: it does not depend on the
  camera, and the later sizes reuse it), its warm relighting frame (the median of
  ``--frames`` frames with the lights moved, as the report times it) and its error:
  relative MSE against the scene's committed reference over the pixels it is scored on,
  its image box-filtered down to the reference's 96 px (a width that is a multiple of it);
- path tracing's time at the method's error: Mitsuba renders the scene at N px at each of
  ``--spp`` (timed, the reference's own estimator), and the method's 96 px error is
  matched on the curve of the 96 px renders' errors against those times
  (:func:`~translucent.reports.report.speedup.equal_error_seconds`). The relative MSE of a
  path-traced image at a given spp is a per-pixel variance, the same at every width, so
  the 96 px errors stand for every size; the times are measured at each size;
- the speed-up: that time over the method's frame, and the smallest measured width from
  which it is at least 1x and 10x.

``--subdivisions`` repeats the 96 px measurement on ``sphere`` with its icosphere at each
subdivision level (162 to 10,242 vertices at 2 to 5): precomputation and frame against the
mesh, the error still against the committed reference of subdivision 4.
"""

from __future__ import annotations

import math

import numpy as np

from ...errors import InputError
from . import at_width, count_list, steps_bar, write_figures

#: Scenes measured by default: the lone convex object and the thin-walled one.
DEFAULT_SCENES = ("sphere", "bowl")
DEFAULT_METHODS = ("prt", "splatting", "radiosity")

#: ``--quick``: sphere at its own width and twice it, splatting, one mesh level, 1 and 4 spp.
QUICK_ARGUMENTS: dict = {"scenes": "sphere", "sizes": "96,192", "methods": "splatting",
                         "subdivisions": "3", "spp": "1,4", "frames": 1}

#: The speed-ups a width is reported for ("pays from").
PAYS = (1.0, 10.0)


def add_arguments(parser):
    """Scenes, sizes, methods, mesh levels, path-tracing ladder, frames, plot."""
    parser.add_argument("--scenes", default=",".join(DEFAULT_SCENES),
                        help="built-in scenes with a committed reference")
    parser.add_argument("--sizes", default="96,192,384",
                        help="image widths in pixels (multiples of the scene's own width "
                             "are scored against its reference)")
    parser.add_argument("--methods", default=",".join(DEFAULT_METHODS),
                        help="fast methods to measure")
    parser.add_argument("--subdivisions", default="3,4,5",
                        help="icosphere levels of the sphere mesh sweep (empty: none)")
    parser.add_argument("--spp", default="1,4,16",
                        help="path tracing's ladder, samples per pixel")
    parser.add_argument("--frames", type=int, default=3,
                        help="timed relighting frames per method and size")
    parser.add_argument("--plot", default=None, help="write the speed-up plot here (PNG)")


def _box_down(image, factor: int):
    """``image`` averaged over ``factor`` x ``factor`` pixel blocks (an Image)."""
    from ...image import Image

    rgb = np.asarray(image.rgb, dtype=np.float64)
    height, width = rgb.shape[0] // factor, rgb.shape[1] // factor
    blocks = rgb[:height * factor, :width * factor].reshape(height, factor, width, factor, 3)
    return Image(blocks.mean(axis=(1, 3)).astype(np.float32))


def _path_tracing_seconds(scene, spp_values) -> dict:
    """Return ``{spp: seconds}`` of one render of ``scene`` each, and the points."""
    from ..report.speedup import path_tracing_points

    points = path_tracing_points(scene, spp_values, repeats=1)
    failed = [point["error"] for point in points if "error" in point]
    if failed:
        raise RuntimeError(f"path tracing failed: {failed[0]}")
    return {point["spp"]: point["seconds"] for point in points}, points


def _method_row(method_name, scene, knobs, frames, reference, mask, factor, cold) -> dict:
    from ..report.runs import run_method
    from ..report.speedup import scored_relative_mse

    run = run_method(method_name, scene, knobs, cold=cold, relight_frames=frames)
    if run.status != "ok":
        return {"status": run.status, "reason": run.reason}
    image = run.image if factor == 1 else _box_down(run.image, factor)
    error = scored_relative_mse(reference, image, mask) if factor else math.nan
    return {"status": "ok", "frame_seconds": run.frame_seconds,
            "precompute_seconds": run.precompute_seconds, "relative_mse": error,
            "first_frame_seconds": run.first_frame_seconds}


def _speedup(row, curve_errors, seconds_by_spp, spp_values):
    from ..report.speedup import equal_error_seconds

    error = row.get("relative_mse_96", row.get("relative_mse"))
    if row.get("status") != "ok" or not (error and math.isfinite(error) and error > 0):
        return
    seconds, extrapolated = equal_error_seconds(
        curve_errors, [seconds_by_spp[spp] for spp in spp_values], error)
    row["path_tracing_seconds"] = seconds
    row["extrapolated"] = extrapolated
    row["speedup"] = seconds / row["frame_seconds"] if row["frame_seconds"] else None


def measure_scene(name, sizes, methods, spp_values, frames, knobs_of, base_points=None
                  ) -> dict:
    """Every size and method on one scene; return the figures."""
    from ...fast.base import method, scored_object_names
    from ...reference.committed import committed_reference
    from ...scenes import load_scene
    from ..report.scoring import scored_pixels
    from ..report.speedup import scored_relative_mse

    scene = load_scene(name)
    reference = committed_reference(name, scene).require()
    base = scene.camera.width
    masks = {m: scored_pixels(scene, scored_object_names(method(m), scene)) for m in methods}
    base_seconds, points = base_points or _path_tracing_seconds(scene, spp_values)
    curves = {m: [scored_relative_mse(reference, point["images"][0], masks[m])
                  for point in points] for m in methods}
    rows = []
    with steps_bar(f"scaling on {name}", len(sizes) * (len(methods) + 1), unit="run") as bar:
        precomputed = {}
        for size in sizes:
            sized = at_width(scene, size)
            bar.set_postfix_str(f"path tracing at {size} px")
            seconds_by_spp = base_seconds if size == base else \
                _path_tracing_seconds(sized, spp_values)[0]
            bar.update()
            factor = size // base if size % base == 0 else 0
            for m in methods:
                bar.set_postfix_str(f"{m} at {size} px")
                row = {"size": size, "pixels": sized.camera.width * sized.camera.height,
                       "method": m, "path_tracing_spp_seconds": seconds_by_spp,
                       **_method_row(m, sized, knobs_of(m), frames, reference, masks[m],
                                     factor, cold=m not in precomputed)}
                if row["status"] == "ok":
                    if m not in precomputed:
                        precomputed[m] = row["precompute_seconds"]
                    row["precompute_seconds"] = precomputed[m]
                    first = next((r for r in rows if r["method"] == m and r["size"] == base
                                  and r["status"] == "ok"), None)
                    row["relative_mse_96"] = first["relative_mse"] if first else \
                        row["relative_mse"]
                    _speedup(row, curves[m], seconds_by_spp, spp_values)
                rows.append(row)
                bar.update()
    return {"scene": name, "reference_width": base, "path_tracing_curve": {
        m: {"spp": list(spp_values), "relative_mse": curves[m]} for m in methods},
        "rows": rows, "pays_from": _pays_from(rows, methods)}


def _pays_from(rows, methods) -> dict:
    """Per method: the smallest measured width at which the speed-up is >= each of PAYS."""
    found = {}
    for m in methods:
        mine = sorted((r for r in rows if r["method"] == m and r.get("speedup")),
                      key=lambda r: r["size"])
        found[m] = {f"{goal:g}x": next((r["size"] for r in mine if r["speedup"] >= goal), None)
                    for goal in PAYS}
    return found


def measure_meshes(subdivisions, methods, spp_values, frames, knobs_of, base_points=None
                   ) -> dict:
    """Measure the sphere at 96 px with its icosphere at each level; return the figures."""
    from ...fast.base import method, scored_object_names
    from ...reference.committed import committed_reference
    from ...scenes import icosphere, load_scene
    from ...scenes.scene import Scene, SceneObject
    from ..report.scoring import scored_pixels
    from ..report.speedup import scored_relative_mse

    scene = load_scene("sphere")
    reference = committed_reference("sphere", scene).require()
    item = scene.objects[0]
    seconds_by_spp, points = base_points or _path_tracing_seconds(scene, spp_values)
    rows = []
    with steps_bar("scaling over the mesh", len(subdivisions) * len(methods),
                   unit="run") as bar:
        for level in subdivisions:
            mesh = icosphere(level, 1.0)
            meshed = Scene([SceneObject(item.name, mesh, item.material)], scene.lights,
                           scene.camera, scene.mm_per_unit, scene.name)
            for m in methods:
                bar.set_postfix_str(f"{m}, {len(mesh.vertices)} vertices")
                mask = scored_pixels(meshed, scored_object_names(method(m), meshed))
                curve = [scored_relative_mse(reference, point["images"][0], mask)
                         for point in points]
                row = {"subdivisions": level, "vertices": len(mesh.vertices), "method": m,
                       **_method_row(m, meshed, knobs_of(m), frames, reference, mask, 1,
                                     cold=True)}
                _speedup(row, curve, seconds_by_spp, spp_values)
                rows.append(row)
                bar.update()
    return {"scene": "sphere", "path_tracing_spp_seconds": seconds_by_spp, "rows": rows}


def _plot(path, scenes) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import io

    import matplotlib.pyplot as plt

    from ...atomic import atomic_write_bytes

    figure, axes = plt.subplots(1, len(scenes), figsize=(5 * len(scenes), 4), squeeze=False)
    for axis, result in zip(axes[0], scenes, strict=True):
        for m in sorted({r["method"] for r in result["rows"]}):
            mine = [r for r in result["rows"] if r["method"] == m and r.get("speedup")]
            if mine:
                axis.plot([r["pixels"] for r in mine], [r["speedup"] for r in mine], "o-",
                          label=m)
        axis.axhline(1.0, color="grey", lw=0.8)
        axis.axhline(10.0, color="grey", lw=0.8, ls="--")
        axis.set_xscale("log")
        axis.set_yscale("log")
        axis.set_xlabel("pixels")
        axis.set_ylabel("speed-up over path tracing at equal error")
        axis.set_title(result["scene"])
        axis.legend()
    figure.tight_layout()
    buffer = io.BytesIO()
    figure.savefig(buffer, format="png", dpi=100)
    plt.close(figure)
    atomic_write_bytes(path, buffer.getvalue())


def run(args) -> int:
    """Measure, print the tables, write the JSON (and the plot)."""
    from ...fast.registry import method as registered
    from . import quick_knobs

    sizes = count_list(args.sizes, "--sizes")
    spp_values = count_list(args.spp, "--spp")
    levels = count_list(args.subdivisions, "--subdivisions", allow_empty=True)
    if len(set(spp_values)) < 2:
        raise InputError("give at least two sample counts (a curve)", field="--spp",
                         value=args.spp)
    if args.frames < 1:
        raise InputError("must be an integer >= 1", field="--frames", value=args.frames)
    if any(level > 6 for level in levels):
        raise InputError("must be at most 6 (40,962 vertices)", field="--subdivisions",
                         value=args.subdivisions)
    methods = [name.strip() for name in args.methods.split(",") if name.strip()]
    for name in methods:
        try:
            registered(name)
        except InputError as error:
            raise InputError(error.reason, field="--methods", value=name) from None
    scenes = [name.strip() for name in args.scenes.split(",") if name.strip()]
    if not scenes or not methods:
        raise InputError("give at least one scene and one method", field="--scenes",
                         value=args.scenes)
    quick = quick_knobs(methods) or {}

    def knobs_of(name):
        return quick.get(name, {})

    from ...reference.committed import committed_reference
    from ...scenes import load_scene

    for name in scenes:  # before any rendering: each scene needs its reference
        committed_reference(name, load_scene(name)).require()
    # one path-tracing ladder per scene at its own size: its errors and its times
    ladders = {name: _path_tracing_seconds(load_scene(name), spp_values)
               for name in set(scenes) | ({"sphere"} if levels else set())}
    results = [measure_scene(name, sizes, methods, spp_values, args.frames, knobs_of,
                             ladders[name]) for name in scenes]
    meshes = measure_meshes(levels, methods, spp_values, args.frames, knobs_of,
                            ladders["sphere"]) if levels else None
    for result in results:
        print(f"{result['scene']}: error at the reference's {result['reference_width']} px; "
              "path tracing at equal error over the method's warm frame")
        print(f"  {'method':<10} {'width':>5} {'relMSE':>8} {'frame':>9} {'precompute':>10} "
              f"{'PT at equal error':>17} {'speed-up':>9}")
        for row in result["rows"]:
            if row["status"] != "ok":
                print(f"  {row['method']:<10} {row['size']:>5} {row['status']}: "
                      f"{row.get('reason', '')}")
                continue
            speedup = row.get("speedup")
            print(f"  {row['method']:<10} {row['size']:>5} {row['relative_mse']:>8.4f} "
                  f"{row['frame_seconds']:>8.3f}s {row['precompute_seconds']:>9.1f}s "
                  f"{row.get('path_tracing_seconds', math.nan):>16.3f}s "
                  f"{'-' if speedup is None else f'{speedup:.2f}x':>9}"
                  f"{' (extrapolated)' if row.get('extrapolated') else ''}")
        for m, pays in result["pays_from"].items():
            print(f"  {m}: " + ", ".join(f">= {goal} from {width or 'none measured'}"
                                         + (" px" if width else "")
                                         for goal, width in pays.items()))
    if meshes:
        print("sphere at 96 px over its mesh:")
        for row in meshes["rows"]:
            if row["status"] != "ok":
                print(f"  {row['method']:<10} {row['vertices']:>6} {row['status']}")
                continue
            print(f"  {row['method']:<10} {row['vertices']:>6} vertices relMSE "
                  f"{row['relative_mse']:.4f} frame {row['frame_seconds']:.3f}s precompute "
                  f"{row['precompute_seconds']:.1f}s speed-up "
                  f"{row.get('speedup') or math.nan:.2f}x")
    if args.plot:
        _plot(args.plot, results)
        print(f"wrote {args.plot}")
    out = write_figures(args.json, "scaling", {"scenes": results, "meshes": meshes,
                                               "sizes": sizes, "spp": spp_values})
    print(f"wrote {out}")
    return 0
