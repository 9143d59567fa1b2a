"""Splatting (Chen et al. 2012): frames per second per ablation setting, time per stage, error.

``translucent bench splatting``: renders the heterogeneous scene at 800 x 600 with a
512 x 512 irradiance buffer for each of the paper's ablation settings (Table 1: no
acceleration, multiresolution only, adaptive sampling only, both), prints frames per second
and the speed-up over no acceleration measured in the same run, and the share of each
stage of a frame (the paper's Table 2: buffer generation, each splatting level,
accumulation). The error of each setting is measured against the brute-force gathering of
Eq. 5 on the same buffers at a smaller validation size (``--validation-width``,
``--validation-irradiance``), where brute force is affordable: its cost is pixels x
irradiance samples.
"""

from __future__ import annotations

import json
import time

import numpy as np

from ...atomic import atomic_write_text
from ...fast import splatting
from ...scenes import Camera, load_scene

#: The ablation settings of the paper's Table 1.
SETTINGS = {
    "no acceleration": {"multiresolution": False, "adaptive": False},
    "multiresolution only": {"multiresolution": True, "adaptive": False},
    "adaptive only": {"multiresolution": False, "adaptive": True},
    "both": {"multiresolution": True, "adaptive": True},
}
#: Targets of the task: frames per second with both accelerations, speed-up over none.
TARGET_FPS = 10.0
TARGET_SPEEDUP = 5.0


def add_arguments(parser):
    """Options of ``translucent bench splatting``."""
    parser.add_argument("--scene", default="heterogeneous",
                        help="built-in scene name or scene TOML (default heterogeneous)")
    parser.add_argument("--width", type=int, default=800, help="frame width (default 800)")
    parser.add_argument("--height", type=int, default=600, help="frame height (default 600)")
    parser.add_argument("--irradiance-resolution", type=int, default=512,
                        help="irradiance buffer side (default 512)")
    parser.add_argument("--frames", type=int, default=2,
                        help="timed frames per setting after one warm-up (default 2)")
    parser.add_argument("--backend", choices=("numpy", "drjit"), default="drjit",
                        help="splatting kernel (default drjit)")
    parser.add_argument("--validation-width", type=int, default=96,
                        help="frame width for the error against brute force (default 96)")
    parser.add_argument("--validation-irradiance", type=int, default=96,
                        help="irradiance buffer side for the error (default 96)")
    parser.add_argument("--settings", default=",".join(SETTINGS),
                        help="comma-separated subset of the settings")


def _with_size(scene, width: int, height: int):
    camera = scene.camera
    return scene.with_camera(Camera(camera.origin, camera.target, camera.up, camera.fov,
                                    width, height))


def _relative_error(test: np.ndarray, reference: np.ndarray) -> float:
    total = float(np.abs(reference).sum())
    return float(np.abs(test - reference).sum() / total) if total > 0 else float("nan")


def run(args) -> int:
    """Time each setting, measure its error, print the tables, write the JSON."""
    names = [name.strip() for name in args.settings.split(",") if name.strip()]
    unknown = [name for name in names if name not in SETTINGS]
    if unknown:
        from ...errors import InputError

        raise InputError(f"unknown setting; valid: {', '.join(SETTINGS)}", field="--settings",
                         value=unknown)
    base = load_scene(args.scene)
    full = _with_size(base, args.width, args.height)
    aspect = args.height / args.width
    small = _with_size(base, args.validation_width,
                       max(1, round(args.validation_width * aspect)))
    truth_state = splatting.precompute(small, irradiance_resolution=args.validation_irradiance,
                                       backend=args.backend)
    started = time.perf_counter()
    truth = truth_state.render_ground_truth().rgb
    truth_seconds = time.perf_counter() - started
    results = {}
    for name in names:
        knobs = {**SETTINGS[name], "backend": args.backend}
        error = _relative_error(splatting.precompute(
            small, irradiance_resolution=args.validation_irradiance, **knobs).render().rgb, truth)
        state = splatting.precompute(full, irradiance_resolution=args.irradiance_resolution,
                                     **knobs)
        state.render()  # warm-up: kernels compile, material tables are built
        seconds = []
        for _ in range(max(1, args.frames)):
            image = state.render()
            seconds.append(image.metadata["seconds"])
        results[name] = {"seconds per frame": float(np.median(seconds)),
                         "fps": 1.0 / float(np.median(seconds)),
                         "stage seconds": image.metadata["stage_seconds"],
                         "samples": image.metadata["notes"].get("samples"),
                         "samples per level": image.metadata["notes"].get("samples per level"),
                         "pairs per level": image.metadata["notes"].get("pairs per level"),
                         "relative error": error, "knobs": knobs}
        print(f"{name:22s} {results[name]['fps']:8.3f} fps  error {error:.4f}", flush=True)
    baseline = results.get("no acceleration", {}).get("seconds per frame")
    print(f"\nsplatting: {args.width} x {args.height}, irradiance {args.irradiance_resolution}^2,"
          f" backend {args.backend}; error vs brute force (Eq. 5) at {small.camera.width} x "
          f"{small.camera.height}, irradiance {args.validation_irradiance}^2 "
          f"(brute force {truth_seconds:.1f} s)")
    print(f"{'setting':22s} {'fps':>8s} {'s/frame':>9s} {'speed-up':>9s} {'samples':>9s} "
          f"{'pairs':>12s} {'rel. error':>10s}")
    for name, result in results.items():
        speedup = baseline / result["seconds per frame"] if baseline else float("nan")
        result["speed-up over no acceleration"] = speedup
        print(f"{name:22s} {result['fps']:8.3f} {result['seconds per frame']:9.3f} "
              f"{speedup:9.2f} {result['samples']:9d} {sum(result['pairs per level']):12d} "
              f"{result['relative error']:10.4f}")
    print("\ntime per stage (share of a frame, the paper's Table 2):")
    for name, result in results.items():
        stages = result["stage seconds"]
        total = sum(stages.values())
        shares = ", ".join(f"{stage} {100 * value / total:.1f} %"
                           for stage, value in stages.items() if value / total >= 0.001)
        print(f"  {name}: {shares}")
    both = results.get("both")
    if both is not None:
        verdict = "reached" if both["fps"] >= TARGET_FPS else "NOT reached"
        print(f"\ntarget >= {TARGET_FPS:g} fps with both accelerations: {verdict} "
              f"({both['fps']:.3f} fps)")
        if baseline:
            speedup = both["speed-up over no acceleration"]
            verdict = "reached" if speedup >= TARGET_SPEEDUP else "NOT reached"
            print(f"target >= {TARGET_SPEEDUP:g}x over no acceleration: {verdict} "
                  f"({speedup:.2f}x)")
    out = args.json or "bench_splatting.json"
    atomic_write_text(out, json.dumps({
        "scene": base.name, "width": args.width, "height": args.height,
        "irradiance_resolution": args.irradiance_resolution, "backend": args.backend,
        "validation": {"width": small.camera.width, "height": small.camera.height,
                       "irradiance_resolution": args.validation_irradiance,
                       "brute force seconds": truth_seconds},
        "results": results}, indent=2, default=str))
    print(f"wrote {out}")
    return 0
