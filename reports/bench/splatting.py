"""Splatting (Chen et al. 2012): frames per second per ablation setting, time per stage, error.

``translucent bench splatting`` renders the heterogeneous scene at 800 x 600 with a
512 x 512 irradiance buffer for each of the paper's ablation settings (Table 1: no
acceleration, multiresolution only, adaptive sampling only, both), plus "both" at tighter
error tolerances (``--epsilons``), and prints for each:

* frames per second (wall clock) and CPU seconds per frame, and the speed-up over no
  acceleration measured in the same run (the machine is shared: the CPU-time ratio is
  the steadier figure);
* the share of each stage of a frame (the paper's Table 2: buffer generation, each
  splatting level, accumulation);
* the error against the brute-force gathering of Eq. 5 on the same buffers, measured
  on every ``--validation-stride``-th pixel of the timed frame itself (so the levels and
  samples are exactly those timed; its cost is those pixels x every irradiance texel),
  and on a whole frame at a small size (``--validation-width``,
  ``--validation-irradiance``), as a check of the silhouettes at low resolution;
* for each built-in heterogeneous material (``--materials``), the relative error and
  HDR-FLIP of the defaults against brute force on that small whole frame.

Error is the relative L1 difference ``sum |test - truth| / sum truth`` over the pixels'
RGB values. Most of it is common to every setting: each profile is splatted only up to its
effective range (95 % of its energy, Eq. 13), about 2.4 % of the frame on the
heterogeneous scene; the accelerations add to it. The comparison "at equal error" is
therefore made over a sweep of the accelerated method's accuracy knobs: ``--epsilons``
(Eq. 14's tolerance), ``--level-samplings`` (the per-level irradiance sampling of
:func:`translucent.fast.splatting.level_sample_masks`), ``--levels-list`` (splatting levels
beyond the paper's three), one knob changed at a time from the defaults, and Eq. 17 as
published (without the profile factors of
:func:`translucent.fast.splatting.upsampling_profile_factors`, which the defaults use). Among
the rows with both accelerations, the fastest whose error is at most
:data:`EQUAL_ERROR_RATIO` times that of no acceleration is compared with no acceleration,
in CPU seconds per frame (the steadier figure on a shared machine) and in wall seconds.
The load average is printed with the results, since other work on the machine slows the
wall clock.
"""

from __future__ import annotations

import os
import time

import numpy as np

from ...fast import splatting
from ...materials.subedit import BUILTIN_SUBEDIT
from ...scenes import load_scene
from . import steps_bar, with_size, write_figures

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
#: "Equal error": the accelerated frame may have no more relative error against brute force
#: than the frame without acceleration (the errors are deterministic, so no allowance for
#: noise is needed; the strided pixels are the same for every row).
EQUAL_ERROR_RATIO = 1.0


#: ``--quick``: a 32 x 24 frame, 32-pixel irradiance, one frame, one setting of each kind.
QUICK_ARGUMENTS: dict = {"width": 32, "height": 24, "irradiance_resolution": 32, "frames": 1,
                         "validation_stride": 16, "validation_width": 16,
                         "validation_irradiance": 16, "epsilons": "0.00025",
                         "level_samplings": "1", "levels_list": "5"}


def add_arguments(parser):
    """Options of ``translucent bench splatting``."""
    parser.add_argument("--scene", default="heterogeneous",
                        help="built-in scene name or scene TOML (default heterogeneous)")
    parser.add_argument("--width", type=int, default=800, help="frame width (default 800)")
    parser.add_argument("--height", type=int, default=600, help="frame height (default 600)")
    parser.add_argument("--irradiance-resolution", type=int, default=512,
                        help="irradiance buffer side (default 512)")
    parser.add_argument("--frames", type=int, default=2,
                        help="timed frames per setting (default 2; one warm-up frame "
                             "compiles the kernels first)")
    parser.add_argument("--backend", choices=splatting.BACKENDS, default="numba",
                        help="splatting kernel (default numba)")
    parser.add_argument("--validation-stride", type=int, default=8,
                        help="brute force on every N-th pixel of the timed frame (default 8)")
    parser.add_argument("--validation-width", type=int, default=96,
                        help="width of the small whole frame checked too (default 96)")
    parser.add_argument("--validation-irradiance", type=int, default=96,
                        help="irradiance buffer side of the small frame (default 96)")
    parser.add_argument("--settings", default=",".join(SETTINGS),
                        help="comma-separated subset of the settings")
    parser.add_argument("--epsilons", default="0.00025,0.0001",
                        help="extra 'both' rows at these Eq. 14 tolerances (comma-separated; "
                             "empty for none)")
    parser.add_argument("--level-samplings", default="1,1.5,2",
                        help="extra 'both' rows with per-level irradiance sampling at these "
                             "pitches in pixels (comma-separated; empty for none)")
    parser.add_argument("--levels-list", default="5",
                        help="extra 'both' rows with this many splatting levels, alone and "
                             "with each level sampling (comma-separated; empty for none)")
    parser.add_argument("--materials", default=",".join(BUILTIN_SUBEDIT),
                        help="built-in heterogeneous SubEdit materials rendered on the small "
                             "frame with the defaults against brute force: relative error "
                             "and HDR-FLIP (comma-separated; empty for none)")
    parser.add_argument("--no-published", action="store_true",
                        help="leave out the row with Eq. 17 as published (no profile "
                             "factors; see translucent.fast.splatting."
                             "upsampling_profile_factors)")


def relative_error(test: np.ndarray, reference: np.ndarray, axis=None):
    """Return ``sum |test - reference| / sum reference`` (over ``axis``; NaN if no light)."""
    total = np.abs(reference).sum(axis=axis)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.abs(test - reference).sum(axis=axis) / np.where(total > 0, total, np.nan)


def _strided(buffer: splatting.SurfaceBuffer, stride: int) -> splatting.SurfaceBuffer:
    return splatting.SurfaceBuffer(*(getattr(buffer, name)[::stride, ::stride] for name in (
        "position", "normal", "uv", "depth", "valid", "footprint")))


def _rows(names, epsilons, pitches, level_counts, published):
    """Return the ablation rows, then 'both' with one accuracy knob changed at a time."""
    rows = {name: dict(SETTINGS[name]) for name in names}
    both = SETTINGS["both"]
    if published:
        rows["both, Eq. 17 as published"] = {**both, "profile_upsampling": False}
    for epsilon in epsilons:
        rows[f"both, epsilon {epsilon:g}"] = {**both, "epsilon": epsilon}
    for levels in [None] + [int(count) for count in level_counts]:
        for pitch in [0.0] + pitches:
            if levels is None and pitch == 0.0:
                continue
            label = ", ".join(part for part in (
                "both", None if levels is None else f"{levels} levels",
                None if pitch == 0.0 else f"level sampling {pitch:g}") if part)
            rows[label] = {**both, "level_sampling": pitch,
                           **({} if levels is None else {"levels": levels})}
    return rows


def _numbers(text: str, flag: str) -> list[float]:
    from ...errors import InputError

    try:
        return [float(value) for value in text.split(",") if value.strip()]
    except ValueError:
        raise InputError("must be comma-separated numbers", field=flag, value=text) from None


def _time_frames(state, frames: int):
    wall, cpu = [], []
    for _ in range(frames):
        clock = time.process_time()
        image = state.render()
        cpu.append(time.process_time() - clock)
        wall.append(image.metadata["seconds"])
    return image, float(np.median(wall)), float(np.median(cpu))


def _checked_arguments(args):
    """Return the settings, epsilons, level samplings, level counts and materials asked for.

    Raises
    ------
    InputError
        An unknown setting or material, a bad number or count.
    """
    from ...errors import InputError, check_count

    names = [name.strip() for name in args.settings.split(",") if name.strip()]
    unknown = [name for name in names if name not in SETTINGS]
    if unknown:
        raise InputError(f"unknown setting; valid: {', '.join(SETTINGS)}", field="--settings",
                         value=unknown)
    epsilons = _numbers(args.epsilons, "--epsilons")
    pitches = _numbers(args.level_samplings, "--level-samplings")
    level_counts = _numbers(args.levels_list, "--levels-list")
    if any(count != int(count) or not 1 <= count <= 12 for count in level_counts):
        raise InputError("must be integers in [1, 12]", field="--levels-list",
                         value=args.levels_list)
    materials = [name.strip() for name in args.materials.split(",") if name.strip()]
    if any(name not in BUILTIN_SUBEDIT for name in materials):
        raise InputError(f"unknown material; valid: {', '.join(BUILTIN_SUBEDIT)}",
                         field="--materials", value=args.materials)
    for name in ("frames", "validation_stride", "validation_width", "validation_irradiance",
                 "width", "height", "irradiance_resolution"):
        check_count(getattr(args, name), f"--{name.replace('_', '-')}")
    return names, epsilons, pitches, level_counts, materials


def run(args) -> int:
    """Time each setting, measure its error, print the tables, write the JSON."""
    names, epsilons, pitches, level_counts, materials = _checked_arguments(args)
    base = load_scene(args.scene)
    full = with_size(base, args.width, args.height)
    small = with_size(base, args.validation_width,
                       max(1, round(args.validation_width * args.height / args.width)))
    common = {"irradiance_resolution": args.irradiance_resolution, "backend": args.backend}
    # ground truth on a regular subset of the timed frame's own pixels (same buffers)
    rows = _rows(names, epsilons, pitches, level_counts, not args.no_published)
    bar = steps_bar("bench splatting", len(rows) + 3)
    bar.set_postfix_str("ground truth")
    started = time.perf_counter()
    camera_buffer, camera, views, material, _ = splatting.precompute(full, **common).buffers()
    validation = _strided(camera_buffer, args.validation_stride)
    truth = splatting.gather_frame(validation, camera, views, material,
                                   mm_per_unit=full.mm_per_unit)
    truth_seconds = time.perf_counter() - started
    small_common = {"irradiance_resolution": args.validation_irradiance,
                    "backend": args.backend}
    small_truth = splatting.precompute(small, **small_common).render_ground_truth().rgb
    bar.update(2)
    results = {}
    warm = False
    load_before = os.getloadavg()
    for name, knobs in rows.items():
        bar.set_postfix_str(name[:40])
        state = splatting.precompute(full, **common, **knobs)
        # Eq. 14's table depends on the material alone: the paper precomputes it
        splatting.rendering_radius_table(material, state.knobs["epsilon"])
        if not warm:
            state.render()  # compiles the kernels (or loads them from numba's cache)
            warm = True
        image, wall, cpu = _time_frames(state, args.frames)
        sampled = image.rgb[::args.validation_stride, ::args.validation_stride]
        small_image = splatting.precompute(small, **small_common, **knobs).render().rgb
        notes = image.metadata["notes"]
        results[name] = {
            "seconds per frame": wall, "cpu seconds per frame": cpu, "fps": 1.0 / wall,
            "stage seconds": image.metadata["stage_seconds"], "samples": notes.get("samples"),
            "samples per level": notes.get("samples per level"),
            "pairs per level": notes.get("pairs per level"),
            "pairs in range per level": notes.get("pairs in range per level"),
            "relative error": float(relative_error(sampled, truth)),
            "relative error per channel": relative_error(sampled, truth, (0, 1)).tolist(),
            "relative error, small frame": float(relative_error(small_image, small_truth)),
            "knobs": knobs}
        print(f"{name:64s} {1 / wall:8.3f} fps  {cpu:7.2f} CPU s/frame  error "
              f"{results[name]['relative error']:.4f}", flush=True)
        bar.update()
    load = {"before": list(load_before), "after": list(os.getloadavg())}
    _report(args, results, truth, truth_seconds, camera_buffer.valid.sum(), small, load)
    bar.set_postfix_str("heterogeneous materials")
    per_material = _materials(small, small_common, materials)
    bar.update()
    bar.close()
    out = write_figures(args.json, "splatting", {
        "scene": base.name, "width": args.width, "height": args.height,
        "irradiance_resolution": args.irradiance_resolution, "backend": args.backend,
        "load average (1, 5, 15 min)": load, "equal error ratio": EQUAL_ERROR_RATIO,
        "validation": {"stride": args.validation_stride,
                       "pixels": int(validation.valid.sum()),
                       "brute force seconds": truth_seconds,
                       "small frame": [small.camera.width, small.camera.height],
                       "small irradiance_resolution": args.validation_irradiance},
        "results": results, "materials": per_material})
    print(f"wrote {out}")
    return 0


def _materials(small, small_common, names) -> dict:
    """Each built-in heterogeneous material with the defaults against brute force (Eq. 5).

    On the whole small frame: relative L1 error and HDR-FLIP (brute force the reference).
    """
    from ...materials.subedit import builtin_subedit
    from ..metrics.compute import flip_map

    out = {}
    for name in names:
        state = splatting.precompute(small, **small_common)
        material = builtin_subedit(name)
        image = state.render(material=material).rgb
        truth = state.render_ground_truth(material=material).rgb
        out[name] = {"relative error": float(relative_error(image, truth)),
                     "hdr_flip": flip_map(truth, image)[0]}
    if out:
        print(f"\nbuilt-in heterogeneous materials, defaults against brute force on the whole "
              f"{small.camera.width} x {small.camera.height} frame:")
        for name, row in out.items():
            print(f"  {name:16s} relative error {row['relative error']:.4f}  HDR-FLIP "
                  f"{row['hdr_flip']:.4f}")
    return out


def _millions(counts) -> float:
    """Sum of per-level counts in millions; NaN where a kernel does not count (Dr.Jit, numpy)."""
    if any(count is None for count in counts):
        return float("nan")
    return sum(counts) / 1e6


def _report(args, results, truth, truth_seconds, pixels, small, load) -> None:
    baseline = results.get("no acceleration")
    print(f"\nsplatting: {args.width} x {args.height} ({pixels} object pixels), irradiance "
          f"{args.irradiance_resolution}^2, backend {args.backend}; error vs brute force "
          f"(Eq. 5) on every {args.validation_stride}th pixel of the timed frame "
          f"({truth_seconds:.0f} s) and on a whole {small.camera.width} x "
          f"{small.camera.height} frame (irradiance {args.validation_irradiance}^2); load "
          f"average {load['before'][0]:.1f} before, {load['after'][0]:.1f} after "
          f"({os.cpu_count()} CPUs)")
    print(f"{'setting':64s} {'fps':>7s} {'s/frame':>8s} {'CPU s':>7s} {'speed-up':>8s} "
          f"{'CPU x':>6s} {'samples':>8s} {'pairs':>8s} {'in range':>8s} {'error':>7s} "
          f"{'err x':>6s} {'R, G, B':>20s} {'small':>7s}")
    for name, result in results.items():
        if baseline:
            result["speed-up over no acceleration"] = (baseline["seconds per frame"]
                                                       / result["seconds per frame"])
            result["CPU speed-up over no acceleration"] = (baseline["cpu seconds per frame"]
                                                           / result["cpu seconds per frame"])
            result["error ratio to no acceleration"] = (result["relative error"]
                                                        / baseline["relative error"])
        channels = ", ".join(f"{value:.4f}" for value in result["relative error per channel"])
        print(f"{name:64s} {result['fps']:7.3f} {result['seconds per frame']:8.2f} "
              f"{result['cpu seconds per frame']:7.2f} "
              f"{result.get('speed-up over no acceleration', float('nan')):8.2f} "
              f"{result.get('CPU speed-up over no acceleration', float('nan')):6.2f} "
              f"{result['samples']:8d} {sum(result['pairs per level']) / 1e6:7.1f}M "
              f"{_millions(result['pairs in range per level']):7.1f}M "
              f"{result['relative error']:7.4f} "
              f"{result.get('error ratio to no acceleration', float('nan')):6.3f} "
              f"{channels:>20s} {result['relative error, small frame']:7.4f}")
    print("\ntime per stage (share of a frame, the paper's Table 2):")
    for name, result in results.items():
        stages = result["stage seconds"]
        total = sum(stages.values())
        shares = ", ".join(f"{stage} {100 * value / total:.1f} %"
                           for stage, value in stages.items() if value / total >= 0.001)
        print(f"  {name}: {shares}")
    print(f"\ntargets (heterogeneous scene, {args.width} x {args.height}, "
          f"{args.irradiance_resolution}^2):")
    accelerated = {name: result for name, result in results.items()
                   if name.startswith("both")}
    for name, result in accelerated.items():
        verdict = "reached" if result["fps"] >= TARGET_FPS else "NOT reached"
        print(f"  {name}: >= {TARGET_FPS:g} fps {verdict} ({result['fps']:.3f} fps wall, "
              f"{1 / result['cpu seconds per frame']:.3f} frames per CPU second)")
    if not baseline or not accelerated:
        return
    equal = {name: result for name, result in accelerated.items()
             if result["error ratio to no acceleration"] <= EQUAL_ERROR_RATIO}
    if not equal:
        closest = min(accelerated, key=lambda name: accelerated[name][
            "error ratio to no acceleration"])
        result = accelerated[closest]
        print(f"  >= {TARGET_SPEEDUP:g}x over no acceleration at equal error NOT reached: no "
              f"row with both accelerations has at most {EQUAL_ERROR_RATIO:g}x the error of "
              f"no acceleration; the closest, '{closest}', has "
              f"{result['error ratio to no acceleration']:.3f}x at "
              f"{result['CPU speed-up over no acceleration']:.2f}x CPU "
              f"({result['speed-up over no acceleration']:.2f}x wall)")
        return
    fastest = min(equal, key=lambda name: equal[name]["cpu seconds per frame"])
    result = equal[fastest]
    fast = min(result["speed-up over no acceleration"],
               result["CPU speed-up over no acceleration"]) >= TARGET_SPEEDUP
    print(f"  >= {TARGET_SPEEDUP:g}x over no acceleration at equal error "
          f"{'reached' if fast else 'NOT reached'}: the fastest row with both accelerations "
          f"and at most {EQUAL_ERROR_RATIO:g}x the error of no acceleration, '{fastest}' "
          f"({result['error ratio to no acceleration']:.3f}x), is "
          f"{result['CPU speed-up over no acceleration']:.2f}x faster in CPU time and "
          f"{result['speed-up over no acceleration']:.2f}x in wall time")
