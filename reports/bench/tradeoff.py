"""Run time against error: each fast method's quality knobs and path tracing at growing spp.

``translucent bench tradeoff [--scene S ...] [--methods m1,m2] [--scheduler ADDRESS |
--serial] [--size PX] [--max-spp N] [--reference-spp N --reference-passes K] [--json FILE]
[--plot FILE]``

For each scene (default: ``sphere``, where PRT, translucent radiosity and splatting apply,
and ``glossy``, where BRDF editing does), every built fast method that applies is run along
its quality ladder (its knob spec's ladders, :func:`declared_ladders`: a few knob
settings from cheap to the method's
defaults: PCA terms, wavelet terms, solver tolerance, splatting levels and irradiance
resolution, gather samples), each against an empty cache so that its precomputation is
timed in full, then renders its first frame and :data:`RELIGHT_FRAMES` relit ones (the
scene's lights given again: the interactive relighting path); the frame time is their
median, the first image's time the precomputation plus the first frame. Mitsuba's
volumetric path tracer renders the same scene at 1, 2, 4, ... ``--max-spp`` samples per
pixel (:data:`~translucent.reports.report.speedup.PATH_TRACING_REPEATS` timed renders each, after
an untimed one that compiles its kernels: the median time, the mean error). Every image is
compared with a converged reference (``--reference-spp`` x ``--reference-passes``, from
the reference cache); the error is the relative MSE with the reference's noise discounted (see
:func:`translucent.reports.metrics.relative_mse`).

Times are given in seconds and as ratios to the 1-spp path-traced render of the same scene
measured in the same run. For each method point, the path tracer's time at the same error is
interpolated on its log-log curve (extrapolated along the fitted power law beyond the swept
spp, and flagged so), giving the speedup at equal error: per frame (the interactive path,
``state.render``) and for the first image (precomputation + frame).

Each method point's error is also split through the model it renders (its ``model_name``
or profile knob, :func:`translucent.reports.report.split.split_profile`), rendered exactly
once per scene and model at the reference's samples: the model's error against the
reference, the method's own against the model, and which dominates
(:func:`~translucent.reports.report.split.dominant_part`); the table names it at each
method's defaults. A knob that changes the model (BRDF editing's ``gather_reflection``)
moves the floor its ladder can reach; the others cannot go below it.

Every sweep point is an independent task (:func:`translucent.reports.report.distributed.run_tasks`):
local processes by default, ``--scheduler`` for a Dask cluster, ``--serial`` in this process.
Writes the figures as JSON (``--json``, default ``bench_tradeoff.json``) and the curves as
one log-log PNG beside it (``--plot``, default the JSON's name with ``.png``).
"""

from __future__ import annotations

import datetime
import math
import os
from pathlib import Path

import numpy as np

from ...atomic import atomic_save_figure, check_output_file
from ...errors import InputError, check_count
from ..report.speedup import equal_error_seconds, path_tracing_point
from . import at_width, quick_knobs, steps_bar, write_figures

__all__ = ["DEFAULT_SCENES", "add_arguments", "declared_ladders", "run", "sweep",
           "path_tracing_point", "equal_error_seconds"]

#: The scenes swept by default: between them every fast method applies to one.
DEFAULT_SCENES = ("sphere", "glossy")

#: Words in the name of an integer knob that sets quality, for a method without a ladder.
QUALITY_WORDS = ("terms", "samples", "iterations", "levels", "resolution", "rays", "basis",
                 "coefficients")

#: Fractions of the default a generated ladder takes for such a knob.
GENERATED_FRACTIONS = (0.125, 0.25, 0.5)

#: Relit frames per method point after the first frame: the median is the frame time.
RELIGHT_FRAMES = 3

#: Smallest relative MSE drawn on the log axis: a noise-discounted relMSE can come out at
#: or below zero when an image is closer to the truth than the reference's noise resolves.
PLOT_FLOOR = 1e-6


#: ``--quick``: the sphere at 12 pixels, path tracing to 2 spp, a 4 x 2 spp reference, in this
#: process; radiosity and splatting, each ladder at its cheapest point on the method's
#: ``QUICK_KNOBS`` (the sweep treats every method alike).
QUICK_ARGUMENTS: dict = {"scene": ["sphere"], "size": 12, "max_spp": 2, "reference_spp": 4,
                         "reference_passes": 2, "serial": True,
                         "methods": "radiosity,splatting"}


def add_arguments(parser):
    """Scenes, methods, where the tasks run, image size, spp range, reference, outputs."""
    parser.add_argument("--scene", action="append", default=None, metavar="SCENE",
                        help="built-in scene or scene file, repeatable (default: "
                             f"{', '.join(DEFAULT_SCENES)})")
    parser.add_argument("--methods", default=None, metavar="M1,M2",
                        help="comma-separated fast methods (default: every built one)")
    where = parser.add_mutually_exclusive_group()
    where.add_argument("--scheduler", default=None, metavar="ADDRESS",
                       help="Dask scheduler for the sweep points (default: local processes)")
    where.add_argument("--serial", action="store_true",
                       help="run every sweep point in this process")
    parser.add_argument("--size", type=int, default=48,
                        help="image width in pixels, the height following the scene's aspect "
                             "(default 48; 0: the scene's own)")
    parser.add_argument("--max-spp", type=int, default=64,
                        help="largest spp of the path-tracing sweep, doubling from 1 "
                             "(default 64)")
    parser.add_argument("--reference-spp", type=int, default=256,
                        help="spp per pass of the converged reference (default 256)")
    parser.add_argument("--reference-passes", type=int, default=4,
                        help="passes of the converged reference (default 4)")
    parser.add_argument("--plot", default=None,
                        help="PNG of the curves (default: beside the JSON, same name)")
    parser.add_argument("--ladder-points", type=int, default=0,
                        help="keep only the last N points of each ladder (0: all); for quick "
                             "checks")


# ====================================================================== tasks


def _task(kind: str, scene, *arguments):
    """Run one sweep point: a (model) reference, a path-traced render or a method run."""
    from ..report.runs import render_reference, run_method

    if kind == "reference":
        return render_reference(scene, *arguments)
    if kind == "model":
        model, spp, passes = arguments
        return render_reference(scene, spp, passes, profile=model)
    if kind == "path tracing":
        return path_tracing_point(scene, *arguments)
    method_name, knobs = arguments
    # the sweep asked applies_to when it planned the point
    return run_method(method_name, scene, knobs, cold=True, relight_frames=RELIGHT_FRAMES,
                      applies=True)


# ====================================================================== ladders


def declared_ladders(module, name: str) -> dict[str, list[dict]] | None:
    """Return a method's quality ladders: its ``LADDERS``, else its knob spec's, else None.

    Each is named, from cheap settings to the method's defaults (``{}``); knobs a method
    does not have (any more) are dropped by the sweep, and its JSON says so.
    """
    ladders = getattr(module, "LADDERS", None)
    spec = getattr(module, "KNOBS", None)
    if not ladders and spec is not None and hasattr(spec, "ladders"):
        ladders = spec.ladders
    return ladders or None


def _ladders(module, name: str) -> tuple[dict[str, list[dict]], list[str]]:
    """Return the ladders of a method, restricted to its knobs, and notes on what was dropped."""
    defaults = getattr(module, "DEFAULT_KNOBS", {}) or {}
    notes = []
    ladders = declared_ladders(module, name)
    if ladders is None:
        ladders = {}
        for knob, default in defaults.items():
            if isinstance(default, bool) or not isinstance(default, int) or default < 8:
                continue
            if any(word in knob for word in QUALITY_WORDS):
                ladders[knob] = [{knob: max(1, int(default * f))} for f in GENERATED_FRACTIONS]
                ladders[knob].append({})
        notes.append(f"no ladder for {name}: generated from its integer quality knobs "
                     f"({', '.join(ladders) or 'none found'})")
    kept: dict[str, list[dict]] = {}
    for ladder, points in ladders.items():
        cleaned = []
        for knobs in points:
            unknown = sorted(set(knobs) - set(defaults))
            if unknown:
                notes.append(f"{ladder}: knobs {', '.join(unknown)} are not knobs of {name} "
                             "any more; dropped")
            point = {k: v for k, v in knobs.items() if k in defaults}
            if point not in cleaned:
                cleaned.append(point)
        kept[ladder] = cleaned
    return kept, notes


# ====================================================================== the sweep


def _metrics(reference, image) -> dict:
    from ..metrics.compute import evaluate

    try:
        metrics = evaluate(reference, image).metrics
    except (InputError, TypeError) as error:
        return {"error": str(error)}
    return {"relative_mse": metrics.relative_mse, "hdr_flip": metrics.hdr_flip,
            "ssim": metrics.ssim}


def _mean_metrics(reference, images) -> dict:
    """Return the metrics of each image averaged over the images (errors are kept)."""
    each = [_metrics(reference, image) for image in images]
    failed = [m["error"] for m in each if "error" in m]
    if failed:
        return {"error": failed[0]}
    return {key: float(np.mean([m[key] for m in each])) for key in each[0]}


def sweep(scenes, *, methods=None, scheduler=None, serial=False, size: int = 48,
          max_spp: int = 64, reference_spp: int = 256, reference_passes: int = 4,
          ladder_points: int = 0, progress: bool = True) -> dict:
    """Run the sweep and return the figures (what the JSON holds).

    Parameters
    ----------
    scenes : list of str or Scene
        Built-in names, scene files or scenes.
    methods : list of str, optional
        Default every method of :data:`translucent.fast.base.METHODS` (unbuilt ones are
        listed as such).
    scheduler : str, optional
        Dask scheduler address; None: local processes.
    serial : bool
        Run in this process.
    size : int
        Image width (0: the scene's own).
    max_spp : int
        Largest spp of the path-tracing sweep (1, 2, 4, ... up to it).
    reference_spp, reference_passes : int
        The converged reference.
    ladder_points : int
        Keep only the last N points of each ladder (0: all).
    progress : bool
        Progress bar over the tasks.

    Returns
    -------
    dict
        ``{"scenes": {name: {...}}, ...}``; see the module docstring.
    """
    from ...fast.base import METHODS, applicability, method
    from ...fast.registry import MethodContractError, check_known
    from ...scenes import Scene, load_scene
    from ..report.distributed import run_tasks
    from ..report.runs import backend_versions

    for value, name in ((max_spp, "--max-spp"), (reference_spp, "--reference-spp"),
                        (reference_passes, "--reference-passes")):
        check_count(value, name)
    if size < 0 or (0 < size < 11):
        raise InputError("must be 0 (the scene's own) or >= 11 pixels (SSIM's window)",
                         field="--size", value=size)
    if ladder_points < 0:
        raise InputError("must be >= 0", field="--ladder-points", value=ladder_points)
    chosen = list(METHODS) if methods is None else list(methods)
    for name in chosen:
        check_known(name, field="--methods")
    loaded = [at_width(s if isinstance(s, Scene) else load_scene(s), size) for s in scenes]
    spps = [2**k for k in range(int(math.log2(max_spp)) + 1)]

    tasks, owners = [], []
    results: dict = {}
    for scene in loaded:
        entry = results.setdefault(scene.name, {
            "size": [scene.camera.width, scene.camera.height],
            "reference": {"spp": reference_spp, "passes": reference_passes},
            "path_tracing": [], "methods": {}})
        tasks.append(("reference", scene, reference_spp, reference_passes))
        owners.append((scene.name, "reference", None, None))
        for spp in spps:
            tasks.append(("path tracing", scene, spp))
            owners.append((scene.name, "path tracing", None, None))
        for name in chosen:
            try:
                module = method(name)
            except MethodContractError as error:
                entry["methods"][name] = {"status": "failed", "reason": error.reason}
                continue
            except InputError as error:
                entry["methods"][name] = {"status": "not installed", "reason": error.reason}
                continue
            reason = applicability(module.applies_to, scene)
            if reason is not None:
                entry["methods"][name] = {"status": "not applicable",
                                          "reason": reason.sentence, "code": reason.code}
                continue
            ladders, notes = _ladders(module, name)
            entry["methods"][name] = {"status": "ok", "notes": notes,
                                      "ladders": {ladder: [] for ladder in ladders}}
            cheap = (quick_knobs([name]) or {}).get(name)
            for ladder, points in ladders.items():
                if cheap is not None:  # a quick run: the cheapest point, on cheap knobs
                    points = [{**cheap, **points[0]}]
                for knobs in points[-ladder_points:] if ladder_points else points:
                    model = _model_of(name, knobs, scene)
                    tasks.append(("method", scene, name, knobs))
                    owners.append((scene.name, "method", name, (ladder, model)))
                    if model is not None and model not in entry.setdefault("models", {}):
                        entry["models"][model] = {}
                        tasks.append(("model", scene, model, reference_spp, reference_passes))
                        owners.append((scene.name, "model", model, None))

    answers = run_tasks(_task, tasks, scheduler=scheduler, local=serial, progress=progress)
    _score_answers(owners, answers, results, progress)
    for entry in results.values():
        _ratios_and_speedups(entry)
    return {"benchmark": "tradeoff",
            "generated": datetime.datetime.now().astimezone().isoformat(timespec="seconds"),
            "cpu_count": os.cpu_count(), "versions": backend_versions(),
            "where": "this process" if serial else (scheduler or "local processes"),
            "error_metric": "relative MSE, reference noise discounted",
            "time_baseline": "the 1-spp path-traced render of the same scene in this run",
            "scenes": results}


def _model_of(name: str, knobs: dict, scene) -> str | None:
    """Return the model a method's point renders, where a model reference can be made."""
    from ..report.split import model_reference_refusal, split_profile, unrendered_profile

    model, reason = split_profile(name, knobs, scene)
    if reason or model is None or unrendered_profile(model) or \
            model_reference_refusal(scene, model):
        return None
    return model


def _split_point(point: dict, reference, model, image, cache: dict) -> None:
    """Add the point's error split through its model (model and own part, which dominates)."""
    from ..report.split import ErrorSplit, split_images

    try:
        parts = split_images(reference, model, image, cache=cache, key=point["model"])
    except (InputError, TypeError) as error:
        point["split_error"] = str(error)
        return
    split = ErrorSplit(point["model"], "", *parts)
    point.update(model_relative_mse=split.model.get("relative_mse"),
                 own_relative_mse=split.approximation.get("relative_mse"),
                 dominant=split.dominant)


def _score_answers(owners: list, answers: list, results: dict, progress: bool) -> None:
    """Score every task's answer against its scene's reference into ``results``."""
    references, models, split_cache = {}, {}, {}
    for (scene_name, kind, name, _), answer in zip(owners, answers, strict=True):
        if kind == "reference":
            references[scene_name] = answer
        elif kind == "model":
            models[scene_name, name] = answer
    scoring = steps_bar("scoring", len(answers), unit="image", enabled=progress)
    for (scene_name, kind, name, ladder), answer in zip(owners, answers, strict=True):
        scoring.update()
        entry = results[scene_name]
        reference = references[scene_name]
        if kind == "reference":
            if isinstance(answer, str):
                entry["reference"]["error"] = answer
            else:
                entry["reference"]["seconds"] = answer.metadata.get("seconds")
            continue
        if kind == "model":
            entry["models"][name] = ({"error": answer} if isinstance(answer, str) else
                                     {"seconds": answer.metadata.get("seconds")})
            continue
        if kind == "path tracing":
            point = {k: v for k, v in answer.items() if k != "images"}
            if "images" in answer and not isinstance(reference, str):
                point.update(_mean_metrics(reference, answer["images"]))
            entry["path_tracing"].append(point)
            continue
        point = {"knobs": answer.knobs, "status": answer.status}
        if answer.status == "ok":
            first_frame = answer.first_frame_seconds or answer.frame_seconds
            point.update(precompute_seconds=answer.precompute_seconds,
                         first_frame_seconds=first_frame, frame_seconds=answer.frame_seconds,
                         total_seconds=answer.precompute_seconds + first_frame)
            if not isinstance(reference, str):
                point.update(_metrics(reference, answer.image))
            point["model"] = ladder[1]
            model = models.get((scene_name, point["model"]))
            if model is not None and not isinstance(model, str) \
                    and not isinstance(reference, str):
                _split_point(point, reference, model, answer.image,
                             split_cache.setdefault(scene_name, {}))
        else:
            point["reason"] = answer.reason
        entry["methods"][name]["ladders"][ladder[0]].append(point)
    scoring.close()


def _ratios_and_speedups(entry: dict) -> None:
    """Add time ratios to the 1-spp render and speedups at equal error to one scene's entry."""
    traced = [p for p in entry["path_tracing"] if "seconds" in p]
    baseline = next((p["seconds"] for p in traced if p["spp"] == 1), None)
    entry["baseline_seconds"] = baseline
    errors = [p.get("relative_mse", math.nan) for p in traced]
    seconds = [p["seconds"] for p in traced]
    for point in traced:
        point["ratio"] = point["seconds"] / baseline if baseline else None
    for method_entry in entry["methods"].values():
        for points in method_entry.get("ladders", {}).values():
            for point in points:
                if point.get("status") != "ok":
                    continue
                for key in ("frame", "total"):
                    value = point[f"{key}_seconds"]
                    point[f"{key}_ratio"] = value / baseline if baseline else None
                error = point.get("relative_mse", math.nan)
                traced_seconds, extrapolated = equal_error_seconds(errors, seconds, error)
                point["path_tracing_seconds_at_equal_error"] = traced_seconds
                point["equal_error_extrapolated"] = extrapolated
                for key in ("frame", "total"):
                    value = point[f"{key}_seconds"]
                    point[f"speedup_{key}"] = (traced_seconds / value
                                               if value > 0 and math.isfinite(traced_seconds)
                                               else None)


# ====================================================================== outputs


def plot(figures: dict, path) -> Path:
    """Draw every scene's run-time-versus-error curves, log-log, into one PNG (atomically).

    Parameters
    ----------
    figures : dict
        What :func:`sweep` returns.
    path : str or PathLike
        The PNG.

    Returns
    -------
    Path
    """
    import matplotlib

    matplotlib.use("Agg")
    from matplotlib import pyplot

    scenes = figures["scenes"]
    figure, axes = pyplot.subplots(1, max(1, len(scenes)), figsize=(6.5 * max(1, len(scenes)),
                                                                    5.2), squeeze=False)
    colours = pyplot.rcParams["axes.prop_cycle"].by_key()["color"]
    for axis, (name, entry) in zip(axes[0], scenes.items(), strict=False):
        baseline = entry.get("baseline_seconds") or 1.0
        traced = [p for p in entry["path_tracing"] if "relative_mse" in p]
        if traced:
            x = [p["seconds"] / baseline for p in traced]
            y = [max(p["relative_mse"], PLOT_FLOOR) for p in traced]
            axis.plot(x, y, "k-o", label="path tracing (1, 2, 4, ... spp)")
            for point, xi, yi in zip(traced, x, y, strict=True):
                axis.annotate(str(point["spp"]), (xi, yi), textcoords="offset points",
                              xytext=(4, 4), fontsize=7)
        colour_index = 0
        for method_name, method_entry in entry["methods"].items():
            for ladder, points in method_entry.get("ladders", {}).items():
                usable = [p for p in points if "relative_mse" in p]
                if not usable:
                    continue
                colour = colours[colour_index % len(colours)]
                colour_index += 1
                y = [max(p["relative_mse"], PLOT_FLOOR) for p in usable]
                axis.plot([p["frame_seconds"] / baseline for p in usable], y, "-o",
                          color=colour, label=f"{method_name} ({ladder}): frame")
                axis.plot([p["total_seconds"] / baseline for p in usable], y, "--",
                          color=colour, marker="o", markerfacecolor="none",
                          label=f"{method_name}: precomputation + frame")
        axis.set_xscale("log")
        axis.set_yscale("log")
        axis.set_xlabel(f"time / 1-spp path-traced render ({baseline:.3g} s)")
        axis.set_ylabel("relative MSE against the converged reference")
        axis.set_title(f"{name} ({entry['size'][0]} x {entry['size'][1]})")
        axis.grid(True, which="both", alpha=0.3)
        axis.legend(fontsize=6.5, loc="best")
    figure.tight_layout()
    return atomic_save_figure(path, figure, dpi=110)


def _print_table(figures: dict) -> None:
    for name, entry in figures["scenes"].items():
        baseline = entry.get("baseline_seconds")
        print(f"{name}: {entry['size'][0]} x {entry['size'][1]}, 1-spp path-traced render "
              f"{baseline:.3g} s" if baseline else f"{name}: no 1-spp baseline")
        for point in entry["path_tracing"]:
            if "seconds" in point:
                print(f"  path tracing {point['spp']:>5} spp  {point['seconds']:8.3f} s  "
                      f"x{point['ratio']:8.2f}  relMSE {point.get('relative_mse', math.nan):.4g}")
            else:
                print(f"  path tracing {point['spp']:>5} spp  {point.get('error')}")
        for method_name, method_entry in entry["methods"].items():
            if method_entry["status"] != "ok":
                print(f"  {method_name}: {method_entry['status']}: {method_entry['reason']}")
                continue
            for ladder, points in method_entry["ladders"].items():
                print(f"  {method_name} ({ladder})")
                for point in points:
                    knobs = ", ".join(f"{k}={v}" for k, v in point["knobs"].items()) or "defaults"
                    if point["status"] != "ok":
                        print(f"    {knobs}: {point['status']}: {point.get('reason', '')[:100]}")
                        continue
                    flag = " (extrapolated)" if point["equal_error_extrapolated"] else ""
                    speedup = point.get("speedup_frame")
                    total = point.get("speedup_total")
                    print(f"    {knobs}: precompute {point['precompute_seconds']:.3g} s, frame "
                          f"{point['frame_seconds']:.3g} s (x{point['frame_ratio']:.3g}), "
                          f"relMSE {point.get('relative_mse', math.nan):.4g}, speedup at equal "
                          f"error: frame {_times(speedup)}, first image {_times(total)}{flag}"
                          + _split_text(point))
            defaults = next((p for points in method_entry["ladders"].values() for p in points
                             if p.get("knobs") == {} and "dominant" in p), None)
            if defaults is not None:
                print(f"  {method_name} at its defaults: {DOMINANT_WORDS[defaults['dominant']]} "
                      f"(model {defaults['model']}: {defaults['model_relative_mse']:.4g}, "
                      f"own {defaults['own_relative_mse']:.4g})")


#: How the table names the part of a method's error that dominates at its defaults.
DOMINANT_WORDS = {"model": "its model's error dominates: knobs that keep the model cannot "
                           "go below it",
                  "approximation": "its own approximation dominates: its knobs hold it",
                  "both": "model and approximation share the error",
                  "within noise": "neither part clears the reference's noise",
                  "unknown": "no split"}


def _split_text(point: dict) -> str:
    if "dominant" not in point:
        return ""
    return (f"; model {point['model_relative_mse']:.4g}, own {point['own_relative_mse']:.4g}"
            f" ({point['dominant']})")


def _times(value) -> str:
    return "n/a" if value is None or not math.isfinite(value) else f"{value:.3g}x"


def run(args) -> int:
    """Run the sweep, print the table, write the JSON and the plot."""
    methods = None
    if args.methods is not None:
        methods = [m.strip() for m in args.methods.split(",") if m.strip()]
    if args.plot is not None:
        check_output_file(args.plot, "--plot", what="a file name for the PNG")
    figures = sweep(args.scene or list(DEFAULT_SCENES), methods=methods,
                    scheduler=args.scheduler, serial=args.serial, size=args.size,
                    max_spp=args.max_spp, reference_spp=args.reference_spp,
                    reference_passes=args.reference_passes, ladder_points=args.ladder_points)
    _print_table(figures)
    json_path = Path(args.json or "bench_tradeoff.json")
    plot_path = Path(args.plot) if args.plot else json_path.with_suffix(".png")
    write_figures(json_path, "tradeoff", figures)
    plot(figures, plot_path)
    print(f"wrote {json_path} and {plot_path}")
    return 0
