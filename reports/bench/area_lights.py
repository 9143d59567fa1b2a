"""Splatting's area lights: error and frame time against the number of point emitters.

``translucent bench area_lights [--scenes bowl,cornell_block] [--counts 1,2,4,8,16,32]
[--frames 3] [--json FILE]``

Splatting turns an area light into ``area_light_points`` point emitters, each with its own
irradiance buffer (:mod:`translucent.fast.splatting.emitters`). For each scene and count,
this renders splatting's warm frame (the median of ``--frames`` after one untimed) and
scores it against the scene's committed reference over the pixels of the translucent
objects it renders: relative MSE (the reference's noise discounted) and HDR-FLIP, each
beside the reference's own noise floor. Times are also given as ratios to the one-point
frame of the same scene, measured in the same run.
"""

from __future__ import annotations

import time

import numpy as np

from ...errors import InputError
from . import count_list, quick_knobs, steps_bar, write_figures

#: Scenes lit by area lights whose translucent objects splatting renders.
DEFAULT_SCENES = ("bowl", "cornell_block")


#: ``--quick``: a Cornell block (its committed reference), one and four emitters, one frame.
QUICK_ARGUMENTS: dict = {"scenes": "cornell_block", "counts": "1,4", "frames": 1}


def add_arguments(parser):
    """Scenes, counts, frames."""
    parser.add_argument("--scenes", default=",".join(DEFAULT_SCENES),
                        help="built-in scenes with a committed reference and an area light")
    parser.add_argument("--counts", default="1,2,4,8,16,32",
                        help="point emitters per area light to try")
    parser.add_argument("--frames", type=int, default=3,
                        help="timed frames per count (after one untimed)")


def measure(scene_name: str, counts, frames: int) -> dict:
    """Render and score splatting at each count on one scene; return the figures."""
    from ...fast import splatting
    from ...fast.base import applicability
    from ...reference.committed import committed_reference
    from ...scenes import load_scene
    from ..metrics.compute import evaluate, noise_floor
    from ..report.scoring import scored_pixels

    scene = load_scene(scene_name)
    reason = applicability(splatting.applies_to, scene)
    if reason is not None:
        raise InputError(f"splatting does not apply: {reason}", field="--scenes",
                         value=scene_name)
    entry = committed_reference(scene_name)
    if entry.image is None or not entry.current:
        raise InputError(f"no current committed reference ({entry.problem})",
                         field="--scenes", value=scene_name)
    reference = entry.image
    mask = scored_pixels(scene, splatting.scored_objects(scene))
    floor = noise_floor(reference, mask=mask)
    rows = []
    cheap = (quick_knobs(["splatting"]) or {}).get("splatting", {})  # --quick: its QUICK_KNOBS
    with steps_bar(f"area lights on {scene_name}", len(counts), unit="count") as bar:
        for count in counts:
            bar.set_postfix_str(f"{count} points")
            state = splatting.precompute(scene, **{**cheap, "area_light_points": count})
            state.render()  # untimed: compiled kernels, first-call costs
            timings = []
            for _ in range(frames):
                started = time.perf_counter()
                image = state.render()
                timings.append(time.perf_counter() - started)
            metrics = evaluate(reference, image, mask=mask).metrics
            rows.append({"points": count, "frame_seconds": float(np.median(timings)),
                         "relative_mse": metrics.relative_mse, "hdr_flip": metrics.hdr_flip})
            bar.update()
    first = rows[0]["frame_seconds"]
    for row in rows:
        row["time_ratio"] = row["frame_seconds"] / first if first > 0 else None
    return {"scene": scene_name, "objects": splatting.scored_objects(scene),
            "pixels": int(mask.sum()) if mask is not None else None,
            "noise_floor": {"relative_mse": floor.relative_mse if floor else None,
                            "hdr_flip": floor.hdr_flip if floor else None},
            "rows": rows}


def run(args) -> int:
    """Measure every scene, print the table, write the JSON."""
    counts = count_list(args.counts, "--counts")
    if args.frames < 1:
        raise InputError("must be an integer >= 1", field="--frames", value=args.frames)
    scenes = [name.strip() for name in args.scenes.split(",") if name.strip()]
    if not scenes:
        raise InputError("give at least one scene", field="--scenes", value=args.scenes)
    results = [measure(name, counts, args.frames) for name in scenes]
    for result in results:
        floor = result["noise_floor"]
        print(f"{result['scene']}: splatting on {', '.join(result['objects'])} "
              f"({result['pixels']} pixels); reference noise floor relMSE "
              f"{floor['relative_mse']:.2g}, HDR-FLIP {floor['hdr_flip']:.3f}")
        print(f"  {'points':>6} {'relMSE':>9} {'HDR-FLIP':>8} {'frame':>9} {'x 1 point':>9}")
        for row in result["rows"]:
            print(f"  {row['points']:>6} {row['relative_mse']:>9.4g} {row['hdr_flip']:>8.4f} "
                  f"{row['frame_seconds']:>8.3f}s {row['time_ratio']:>9.2f}")
    out = write_figures(args.json, "area_lights", {"scenes": results})
    print(f"wrote {out}")
    return 0
