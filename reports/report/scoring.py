"""What each method of a report is scored on, and against what.

A method is scored on the pixels of the objects it renders: every object the camera sees,
or, for a method with ``scored_objects(scene)`` (PRT and splatting render the translucent
objects and leave the others black), those objects' pixels only
(:func:`~translucent.fast.base.scored_object_names`); object ids come from the camera's
G-buffer. Each set of pixels has its own noise floor (what the reference's noise alone
gives there, :func:`~translucent.reports.metrics.noise_floor`), its own verdicts and its
own path-tracing curve for the speed-up at equal error (:mod:`translucent.reports.report.speedup`).
Whole-image scores are kept beside them.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ...atomic import OutputError
from ...errors import InputError
from .model import SceneReport
from .speedup import scored_curve, scored_relative_mse, speedup, tradeoff_plot
from .split import entry_parts, score_splits

__all__ = ["score_scene", "scored_pixels"]


def score_scene(report: SceneReport, folder: Path) -> None:
    """Write the scene's images and error maps; score each method on its own pixels."""
    from ..metrics.compute import display_white, evaluate_on, noise_verdicts
    from ..metrics.maps import write_error_maps, write_linear_png

    scene_folder = folder / report.slug
    scene_folder.mkdir(parents=True, exist_ok=True)
    white = None
    scored = [name for name, run in report.runs.items()
              if run.status == "ok" and run.image is not None]
    if report.reference is not None:
        report.scored_mask = scored_pixels(report.scene)
        _reference_noise(report)
        for name in scored:
            _object_scoring(report, name)
        _floors(report)
        report.reference.write(scene_folder / "reference.exr")
        white = display_white(report.reference.rgb)
        write_linear_png(scene_folder / "reference.png", report.reference, white=white)
        report.files["reference"] = {"png": f"{report.slug}/reference.png",
                                     "exr": f"{report.slug}/reference.exr"}
    for name, run in report.runs.items():
        if run.status != "ok" or run.image is None:
            continue
        files = {"exr": f"{report.slug}/{name}.exr", "png": f"{report.slug}/{name}.png"}
        run.image.write(folder / files["exr"])
        rgb = np.nan_to_num(run.image.rgb, nan=0.0, posinf=0.0, neginf=0.0)
        write_linear_png(folder / files["png"], rgb, white=white)
        report.files[name] = files
        if report.reference is None:
            report.metric_errors[name] = f"no reference: {report.reference_error}"
            continue
        try:
            # the whole image (its error maps) and the method's own pixels: one set of maps
            mask = report.mask_of(name)
            comparison, on_pixels = evaluate_on(report.reference, run.image, [None, mask])
            # the maps hatch what the numbers beside them do not count
            maps = write_error_maps(report.reference, run.image, scene_folder,
                                    prefix=f"{name}_", comparison=comparison, scored=mask,
                                    scored_metrics=on_pixels.metrics)
        except OutputError:
            raise  # the report cannot be written (a full disk): not this method's failure
        except (InputError, TypeError) as error:
            report.metric_errors[name] = str(error)
            continue
        report.metrics[name] = on_pixels.metrics.as_dict()
        report.systematic[name] = systematic_error(report.reference, run.image, mask)
        report.image_metrics[name] = comparison.metrics.as_dict()
        report.verdicts[name] = noise_verdicts(report.metrics[name], report.floor_of(name))
        for map_name, map_files in maps.items():
            files[f"map_{map_name}"] = f"{report.slug}/{map_files.png.name}"
    if report.reference is not None:
        for profile, image in report.model_references.items():
            image.write(scene_folder / f"model.{profile}.exr")
            report.model_reference_info[profile]["exr"] = f"{report.slug}/model.{profile}.exr"
        score_splits(report)
    _speedups(report, scene_folder)


def systematic_error(reference, image, mask=None) -> dict:
    r"""Return what of ``image``'s error is not noise: its brightness and converged error.

    ``brightness_to_reference``: the image summed over ``mask`` over the reference's, per
    channel (:func:`~.split.brightness_ratio`). Where both images carry a variance (another
    renderer's render, its halves' spread), ``relative_mse_converged``: the relative MSE
    with both images' noise discounted, the error the image would have at infinitely many
    samples, :math:`\frac{1}{N}\sum_i ((t_i - r_i)^2 - \sigma_{r,i}^2 - \sigma_{t,i}^2)
    / (r_i^2 + \epsilon)`, with the standard error of that mean over the pixels.
    """
    from ..metrics.compute import RELMSE_EPSILON
    from .split import brightness_ratio

    found = {"brightness_to_reference": brightness_ratio(image, reference, mask)}
    if image.variance is None or reference.variance is None:
        return found
    arrays = [np.asarray(a, dtype=np.float64) for a in
              (reference.rgb, image.rgb, reference.variance, image.variance)]
    if mask is not None:
        arrays = [a[mask] for a in arrays]
    ref, test, ref_variance, test_variance = (a.reshape(-1, 3) for a in arrays)
    terms = ((test - ref) ** 2 - ref_variance - test_variance) / (ref ** 2 + RELMSE_EPSILON)
    terms = terms.mean(axis=1)
    found["relative_mse_converged"] = {
        "value": float(terms.mean()),
        "standard_error": float(terms.std(ddof=1) / np.sqrt(max(terms.size, 1)))}
    return found


def scored_pixels(scene, objects=None):
    """Return the pixels that see an object of ``scene`` (or one named in ``objects``).

    The background (an environment seen directly, or black) is the same in every method's
    image and the reference's, so it would only dilute the averages; None (the whole image)
    when no pixel sees such an object.
    """
    from ...scenes import gbuffer

    buffer = gbuffer(scene)
    if objects is None:
        hit = buffer.hit
    else:
        indices = [i for i, item in enumerate(scene.objects) if item.name in set(objects)]
        hit = np.isin(buffer.object_id, indices)
    return hit if hit.any() else None


def _object_scoring(report: SceneReport, name: str) -> None:
    """Record which objects ``name`` is scored on and, where fewer than all, their pixels."""
    from ...fast.base import method, scored_object_names

    try:
        objects = scored_object_names(method(entry_parts(name)[0]), report.scene)
    except InputError:  # not a registered method: scored as one that renders everything
        objects = [item.name for item in report.scene.objects]
    report.scored_objects[name] = objects
    if set(objects) == {item.name for item in report.scene.objects}:
        return
    key = tuple(sorted(objects))
    if key not in report.object_masks:
        report.object_masks[key] = (scored_pixels(report.scene, objects), None)
    report.method_masks[name] = report.object_masks[key][0]


def _floors(report: SceneReport) -> None:
    """Every metric's noise floor over the scene's scored pixels and each method's own.

    One set of noise draws serves every pixel set (:func:`~translucent.reports.metrics.
    noise_floors`); a floor is None without a usable variance.
    """
    from ..metrics.compute import noise_floors

    keys = list(report.object_masks)
    masks = [report.scored_mask] + [report.object_masks[key][0] for key in keys]
    try:
        floors = [None if floor is None else floor.as_dict()
                  for floor in noise_floors(report.reference, masks)]
    except InputError:
        floors = [None] * len(masks)
    report.noise_floor = floors[0]
    for key, floor in zip(keys, floors[1:], strict=True):
        report.object_masks[key] = (report.object_masks[key][0], floor)
    for name in report.method_masks:
        key = tuple(sorted(report.scored_objects[name]))
        report.method_floors[name] = report.object_masks[key][1]


def _speedups(report: SceneReport, scene_folder: Path) -> None:
    """Score the path-tracing ladder on each method's pixels; speed-ups; the plot."""
    if report.reference is None or report.path_tracing is None:
        return
    report.curve = scored_curve(report.path_tracing, report.reference, report.scored_mask)
    points = {}
    for name, metrics in report.metrics.items():
        run = report.runs[name]
        curve = report.curve
        if name in report.method_masks:
            key = tuple(sorted(report.scored_objects[name]))
            if key not in report.object_curves:
                report.object_curves[key] = scored_curve(
                    report.path_tracing, report.reference, report.method_masks[name])
            curve = report.object_curves[key]
        verdict = report.verdicts.get(name, {}).get("relative_mse")
        report.speedups[name] = speedup(curve, metrics.get("relative_mse"),
                                        run.frame_seconds, verdict)
        points[name] = (run.frame_seconds, metrics.get("relative_mse"))
        _ladder_points(report, name)
    curves = {"path tracing": report.curve}
    for key, curve in report.object_curves.items():
        curves[f"path tracing on {', '.join(key)}"] = curve
    floor = (report.noise_floor or {}).get("relative_mse")
    ladders = {name: [(p["frame_seconds"], p["relative_mse"]) for p in entries
                      if p["relative_mse"] is not None]
               for name, entries in report.ladder_points.items()}
    plotted = tradeoff_plot(scene_folder / "tradeoff.png", curves, points, floor,
                            f"{report.name}: run time against error", ladders=ladders)
    if plotted is not None:
        report.files["tradeoff"] = {"png": f"{report.slug}/tradeoff.png"}


def _ladder_points(report: SceneReport, name: str) -> None:
    """Score a method's cheaper runs (its quality ladder) on the pixels it is scored on."""
    for run in report.ladders.get(name, []):
        entry = {"knobs": dict(run.knobs), "status": run.status, "reason": run.reason,
                 "precompute_seconds": run.precompute_seconds,
                 "frame_seconds": run.frame_seconds, "relative_mse": None}
        if run.status == "ok" and run.image is not None:
            try:
                entry["relative_mse"] = float(scored_relative_mse(
                    report.reference, run.image, report.mask_of(name)))
            except (InputError, TypeError) as error:
                entry["reason"] = str(error)
        report.ladder_points.setdefault(name, []).append(entry)


def _reference_noise(report: SceneReport) -> None:
    """Summarise the reference's own noise; warn when it is too noisy to judge by."""
    from ...noise import noise_summary, noise_warning

    reference = report.reference
    if reference.variance is None:
        report.noise_warning = ("the reference has no variance: its noise is unknown, no "
                                "noise floor can be given")
        return
    summary = noise_summary(reference.rgb, reference.variance, report.scored_mask,
                            mask_name="scored")
    report.reference_noise = summary
    report.noise_warning = noise_warning(summary) or ""
