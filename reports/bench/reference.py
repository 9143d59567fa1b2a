"""Overhead of the reference renderer over a plain ``mitsuba.render`` call, and integrator choice.

``translucent bench reference [--scene NAME --spp N --passes K --repeats R --size PX]``
renders a built-in scene through :func:`translucent.reference.render` (cache off, one RGB
render per pass: scene conversion, ``load_dict``, K passes of N spp, the running mean and
variance) and through one plain ``mitsuba.render`` call of K x N spp on the same Mitsuba
scene, loaded beforehand, alternating the two R times after one warm-up each (kernels
compiled). It prints the median ratio of the suite's time to the plain call's (target at
most :data:`TARGET_OVERHEAD`), in wall-clock and in process CPU time (all threads:
steadier when other jobs share the cores), beside the absolute seconds, and writes them
as JSON.

``--integrators MATERIAL`` measures instead which estimator converges fastest for a
medium: the scene's first translucent object gets the measured medium MATERIAL, the
lights become a constant environment of radiance 1 (every path that leaves finds light,
so the noise is the medium's), and the scene is rendered with ``volpath``,
``volpathmis`` and per-channel ``volpath`` at the same spp. Each gets the mean over
object pixels and channels of the relative variance of the mean, and the efficiency
``1 / (relative variance x seconds)``, printed as a ratio to ``volpath``'s.

``--delta-lights`` compares the two ways of lighting a medium behind a dielectric boundary
with a point, spot or directional light (default scene ``sphere_dielectric``): manifold
next-event estimation (``volpath_mnee``) and ``volpath`` with the lights replaced by small
emitters of the same power. Each is rendered at the same spp; printed are the median
relative standard error over the object's lit pixels, the process CPU time, that error
scaled to one CPU minute (error falls as the square root of time) and the efficiency
ratio. ``volpath_mnee`` renders a chromatic medium one channel at a time (the reference's
own choice); its RGB render is shown beside it. The verdict is on the median error
scaled to :data:`DELTA_LIGHT_CPU_MINUTES` CPU minutes against
:data:`DELTA_LIGHT_TARGET_RSE`.

``--bssrdf PROFILE`` measures the BSSRDF path tracer (``bssrdf_path`` with that profile)
against ``volpath_mnee`` in the same run, on the same scene (default ``sphere_dielectric``)
at the same spp: the median relative standard error over the object's lit pixels per CPU
minute of each, and the verdict on ``bssrdf_path``'s error scaled to
:data:`BSSRDF_CPU_SECONDS` CPU seconds against :data:`BSSRDF_TARGET_RSE`.
"""

from __future__ import annotations

import statistics
import time

import numpy as np

from . import at_width, steps_bar, write_figures

#: The overhead the suite may add to a plain Mitsuba render (issue 2).
TARGET_OVERHEAD = 1.05

#: The estimators ``--integrators`` compares: name -> keyword arguments of ``render``.
ESTIMATORS = {
    "volpath": {"integrator": "volpath", "per_channel": False},
    "volpathmis": {"integrator": "volpathmis", "per_channel": False},
    "per-channel volpath": {"integrator": "volpath", "per_channel": True},
}


#: ``--quick``: a 12-pixel sphere, one sample, two passes, one repeat.
QUICK_ARGUMENTS: dict = {"size": 12, "spp": 1, "passes": 2, "repeats": 1}


def add_arguments(parser):
    """Add the scene, sample counts, repeats, image size and the integrator comparison."""
    parser.add_argument("--scene", default="sphere", help="built-in scene name or TOML "
                        "path (default sphere)")
    parser.add_argument("--spp", type=int, default=16, help="samples per pixel of each "
                        "pass (default 16)")
    parser.add_argument("--passes", type=int, default=4, help="passes of the suite's "
                        "render; the plain call renders passes x spp at once (default 4)")
    parser.add_argument("--repeats", type=int, default=3, help="timed repeats after the "
                        "warm-up (default 3)")
    parser.add_argument("--size", type=int, default=48, help="image width in pixels (the "
                        "height follows the scene's aspect; default 48, 0: the scene's)")
    parser.add_argument("--integrators", metavar="MATERIAL", default=None,
                        help="compare volpath, volpathmis and per-channel volpath on this "
                        "measured medium instead of timing the overhead")
    parser.add_argument("--bssrdf", metavar="PROFILE", default=None,
                        help="compare bssrdf_path with this profile against volpath_mnee "
                        "(default scene sphere_dielectric)")
    parser.add_argument("--delta-lights", action="store_true",
                        help="compare volpath_mnee with volpath and stand-in emitters on a "
                        "scene with a dielectric boundary and a delta light (default scene "
                        "sphere_dielectric)")


def _scene(args):
    from ...errors import InputError
    from ...scenes import load_scene

    if (getattr(args, "delta_lights", False) or getattr(args, "bssrdf", None)) \
            and args.scene == "sphere":
        args.scene = "sphere_dielectric"
    scene = load_scene(args.scene)
    for name in ("spp", "passes", "repeats"):
        if getattr(args, name) < 1:
            raise InputError("must be >= 1", field=f"--{name}", value=getattr(args, name))
    if args.size < 0:
        raise InputError("must be >= 0 (0: the scene's own size)", field="--size",
                         value=args.size)
    if (args.integrators or getattr(args, "delta_lights", False)
            or getattr(args, "bssrdf", None)) and args.passes < 2:
        raise InputError("must be >= 2 with --integrators (the spread of the passes gives "
                         "the variance compared)", field="--passes", value=args.passes)
    return at_width(scene, args.size)


def _overhead(scene, args) -> dict:
    from ...backend import mitsuba
    from ...reference import convert_scene, render

    mi = mitsuba()
    total_spp = args.spp * args.passes
    start = time.perf_counter()
    plain_scene = mi.load_dict(convert_scene(scene, spp=total_spp).scene_dict)
    load_seconds = time.perf_counter() - start

    def suite():
        # one RGB render per pass, as the plain call does (no per-channel renders)
        render(scene, spp=args.spp, passes=args.passes, cache=False, progress=False,
               per_channel=False)

    def plain():
        np.array(mi.render(plain_scene, spp=total_spp, seed=0))

    def timed(function):
        wall, cpu = time.perf_counter(), time.process_time()
        function()
        return time.perf_counter() - wall, time.process_time() - cpu

    suite_times, plain_times = [], []
    with steps_bar("bench reference", args.repeats + 1, unit="timing") as bar:
        bar.set_postfix_str("warm-up")
        timed(suite), timed(plain)  # warm-up: compile the kernels of both
        bar.update()
        for repeat in range(args.repeats):
            bar.set_postfix_str(f"repeat {repeat + 1}")
            suite_times.append(timed(suite))
            plain_times.append(timed(plain))
            bar.update()
    suite_seconds, suite_cpu = (list(column) for column in zip(*suite_times, strict=True))
    plain_seconds, plain_cpu = (list(column) for column in zip(*plain_times, strict=True))
    tick = 1e-9  # a clock's resolution: a plain call too short to measure is not a zero
    ratios = [s / max(p, tick) for s, p in zip(suite_seconds, plain_seconds, strict=True)]
    cpu_ratios = [s / max(p, tick) for s, p in zip(suite_cpu, plain_cpu, strict=True)]
    return {"benchmark": "reference overhead", "scene": scene.name,
            "size": [scene.camera.width, scene.camera.height], "spp": args.spp,
            "passes": args.passes, "variant": mi.variant(), "mitsuba": mi.__version__,
            "suite_seconds": suite_seconds, "plain_seconds": plain_seconds,
            "load_seconds": load_seconds, "ratios": ratios,
            "median_ratio": statistics.median(ratios), "suite_cpu_seconds": suite_cpu,
            "plain_cpu_seconds": plain_cpu, "cpu_ratios": cpu_ratios,
            "median_cpu_ratio": statistics.median(cpu_ratios), "target": TARGET_OVERHEAD}


def _print_overhead(result) -> None:
    width, height = result["size"]
    print(f"reference overhead: {result['scene']} {width} x {height}, {result['spp']} spp x "
          f"{result['passes']} passes ({result['variant']}, Mitsuba {result['mitsuba']})")
    print(f"{'repeat':>6}  {'suite s':>9}  {'plain s':>9}  {'ratio':>6}  {'suite cpu s':>11}  "
          f"{'plain cpu s':>11}  {'cpu ratio':>9}")
    for index, row in enumerate(zip(result["suite_seconds"], result["plain_seconds"],
                                    result["ratios"], result["suite_cpu_seconds"],
                                    result["plain_cpu_seconds"], result["cpu_ratios"],
                                    strict=True)):
        suite, plain, ratio, suite_cpu, plain_cpu, cpu_ratio = row
        print(f"{index + 1:>6}  {suite:>9.3f}  {plain:>9.3f}  {ratio:>6.3f}  {suite_cpu:>11.3f}  "
              f"{plain_cpu:>11.3f}  {cpu_ratio:>9.3f}")
    for label, key in (("wall-clock", "median_ratio"), ("CPU-time", "median_cpu_ratio")):
        verdict = "within" if result[key] <= TARGET_OVERHEAD else "ABOVE"
        print(f"median {label} ratio {result[key]:.3f} ({verdict} the target "
              f"{TARGET_OVERHEAD})")
    print(f"the plain call's scene was loaded once beforehand in {result['load_seconds']:.3f} s "
          f"(CPU time counts every thread of this process: steadier on a shared machine)")


def _object_mask(scene) -> np.ndarray:
    from ...scenes.gbuffer import gbuffer

    return gbuffer(scene).hit


def _comparison_header(benchmark: str, scene, args, mask) -> dict:
    """Return what an estimator comparison's JSON says of its set-up."""
    from ...backend import mitsuba

    mi = mitsuba()
    return {"benchmark": benchmark, "scene": scene.name,
            "size": [scene.camera.width, scene.camera.height], "spp": args.spp,
            "passes": args.passes, "variant": mi.variant(), "mitsuba": mi.__version__,
            "object_pixels": int(mask.sum())}


def _integrators(scene, args) -> dict:
    from ...materials import Dipole, measured_medium
    from ...reference import render
    from ...scenes import ConstantEnvironment

    medium = measured_medium(args.integrators)
    translucent = [o.name for o in scene.objects if isinstance(o.material, Dipole)]
    target = translucent[0] if translucent else scene.objects[0].name
    scene = scene.with_material(target, medium).with_lights([ConstantEnvironment(1.0)])
    mask = _object_mask(scene)
    rows = {}
    for name, options in ESTIMATORS.items():
        render(scene, spp=1, passes=2, cache=False, progress=False, **options)  # warm-up
        image = render(scene, spp=args.spp, passes=args.passes, cache=False, progress=True,
                       **options)
        relative = image.variance[mask] / np.maximum(image.rgb[mask], 1e-6) ** 2
        per_channel = relative.mean(axis=0)
        seconds = image.metadata["seconds"]
        rows[name] = {"seconds": seconds, "relative_variance": per_channel.tolist(),
                      "efficiency": float(1.0 / (per_channel.mean() * seconds)),
                      "channel_efficiency": (1.0 / (per_channel * seconds)).tolist()}
    baseline = rows["volpath"]["efficiency"]
    for row in rows.values():
        row["efficiency_ratio"] = row["efficiency"] / baseline
    return {**_comparison_header("reference integrators", scene, args, mask),
            "material": medium.name or args.integrators, "estimators": rows}


def _print_integrators(result) -> None:
    width, height = result["size"]
    print(f"integrators on {result['material']} ({result['scene']}, constant environment, "
          f"{width} x {height}, {result['spp']} spp x {result['passes']} passes, "
          f"{result['object_pixels']} object pixels)")
    print(f"{'estimator':>20}  {'seconds':>8}  {'rel. variance R G B':>26}  "
          f"{'efficiency / volpath':>20}")
    for name, row in result["estimators"].items():
        variance = " ".join(f"{v:.2e}" for v in row["relative_variance"])
        print(f"{name:>20}  {row['seconds']:>8.2f}  {variance:>26}  "
              f"{row['efficiency_ratio']:>20.2f}")


#: The lighting estimators ``--delta-lights`` compares: name -> keyword arguments of render.
DELTA_LIGHT_ESTIMATORS = {
    "volpath_mnee": {"integrator": "volpath_mnee"},
    "volpath_mnee, RGB": {"integrator": "volpath_mnee", "per_channel": False},
    "volpath + stand-in emitters": {"integrator": "volpath"},
}

#: ``--delta-lights``' target: the median relative standard error over the object that
#: ``volpath_mnee`` reaches in this many CPU minutes, at most this.
DELTA_LIGHT_CPU_MINUTES, DELTA_LIGHT_TARGET_RSE = 10.0, 0.02


def _delta_lights(scene, args) -> dict:
    from ...errors import InputError
    from ...noise import noise_summary
    from ...reference import convert_scene, render

    if convert_scene(scene, spp=1).integrator != "volpath_mnee":
        raise InputError("needs a delta light and a dielectric boundary around a medium",
                         field="--scene", value=args.scene)
    mask = _object_mask(scene)
    rows = {}
    for name, options in DELTA_LIGHT_ESTIMATORS.items():
        render(scene, spp=1, passes=2, cache=False, progress=False, **options)  # warm-up
        cpu = time.process_time()
        image = render(scene, spp=args.spp, passes=args.passes, cache=False, progress=True,
                       **options)
        cpu_seconds = time.process_time() - cpu
        summary = noise_summary(image.rgb, image.variance, mask, mask_name="object")
        # no object pixel lit (a stand-in found by no path): an unbounded error
        median = summary.median if summary.pixels and np.isfinite(summary.median) else np.inf
        p99 = summary.p99 if summary.pixels and np.isfinite(summary.p99) else np.inf
        per_minute = median * (cpu_seconds / 60.0) ** 0.5
        rows[name] = {"seconds": image.metadata["seconds"], "cpu_seconds": cpu_seconds,
                      "median_rse": median, "p99_rse": p99,
                      "pixels": summary.pixels, "median_rse_per_cpu_minute": per_minute,
                      "substitutions": image.metadata.get("substitutions", [])}
    baseline = rows["volpath + stand-in emitters"]
    for row in rows.values():
        with np.errstate(invalid="ignore", divide="ignore"):
            row["efficiency_ratio"] = float((baseline["median_rse_per_cpu_minute"]
                                             / row["median_rse_per_cpu_minute"]) ** 2)
        row["median_rse_at_target_minutes"] = float(
            row["median_rse_per_cpu_minute"] / DELTA_LIGHT_CPU_MINUTES ** 0.5)
    for row in rows.values():  # JSON has no infinity: null for "no lit pixel"
        for key, value in row.items():
            if isinstance(value, float) and not np.isfinite(value):
                row[key] = None
    reached = rows["volpath_mnee"]["median_rse_at_target_minutes"]
    return {**_comparison_header("reference delta lights", scene, args, mask),
            "estimators": rows,
            "target": {"cpu_minutes": DELTA_LIGHT_CPU_MINUTES,
                       "median_rse": DELTA_LIGHT_TARGET_RSE, "reached": reached,
                       "met": reached is not None and reached <= DELTA_LIGHT_TARGET_RSE}}


def _print_delta_lights(result) -> None:
    width, height = result["size"]
    print(f"delta lights behind a dielectric: {result['scene']} {width} x {height}, "
          f"{result['spp']} spp x {result['passes']} passes ({result['variant']})")
    print(f"{'estimator':>28}  {'cpu s':>8}  {'median RSE':>10}  {'p99 RSE':>8}  "
          f"{'RSE at 1 CPU min':>16}  {'efficiency':>10}")
    def percent(value, width):
        return f"{'none lit':>{width + 1}}" if value is None else f"{100 * value:>{width}.2f}%"

    for name, row in result["estimators"].items():
        ratio = row["efficiency_ratio"]
        ratio_text = "n/a" if ratio is None else f"{ratio:.1f}"
        print(f"{name:>28}  {row['cpu_seconds']:>8.1f}  {percent(row['median_rse'], 9)}  "
              f"{percent(row['p99_rse'], 7)}  {percent(row['median_rse_per_cpu_minute'], 15)}"
              f"  {ratio_text:>10}")
    print("efficiency: 1 / (RSE^2 x CPU time) as a ratio to the stand-in emitters' (n/a: "
          "no object pixel received the stand-ins' light)")
    target = result["target"]
    reached = target["reached"]
    verdict = "meets" if target["met"] else "MISSES"
    shown = "none lit" if reached is None else f"{100 * reached:.2f} %"
    print(f"volpath_mnee at {target['cpu_minutes']:g} CPU minutes: median RSE {shown} "
          f"({verdict} the target {100 * target['median_rse']:g} %; scaled from this run "
          f"as the square root of time)")


#: ``--bssrdf``'s target: the median relative standard error over the object that
#: ``bssrdf_path`` reaches in this many CPU seconds, at most this.
BSSRDF_CPU_SECONDS, BSSRDF_TARGET_RSE = 60.0, 0.02


def _bssrdf(scene, args) -> dict:
    from ...noise import noise_summary
    from ...reference import render

    mask = _object_mask(scene)
    estimators = {f"bssrdf_path {args.bssrdf}": {"integrator": "bssrdf_path",
                                                 "profile": args.bssrdf},
                  "volpath_mnee": {"integrator": "volpath_mnee"}}
    rows = {}
    for name, options in estimators.items():
        render(scene, spp=1, passes=2, cache=False, progress=False, **options)  # warm-up
        cpu = time.process_time()
        image = render(scene, spp=args.spp, passes=args.passes, cache=False, progress=True,
                       **options)
        cpu_seconds = time.process_time() - cpu
        summary = noise_summary(image.rgb, image.variance, mask, mask_name="object")
        median = summary.median if summary.pixels and np.isfinite(summary.median) else None
        per_minute = None if median is None else median * (cpu_seconds / 60.0) ** 0.5
        rows[name] = {"cpu_seconds": cpu_seconds, "seconds": image.metadata["seconds"],
                      "median_rse": median, "pixels": summary.pixels,
                      "median_rse_per_cpu_minute": per_minute}
    bssrdf, baseline = rows.values()
    for row in rows.values():
        both = row["median_rse_per_cpu_minute"] and baseline["median_rse_per_cpu_minute"]
        row["efficiency_ratio"] = (float((baseline["median_rse_per_cpu_minute"]
                                          / row["median_rse_per_cpu_minute"]) ** 2)
                                   if both else None)
    per_minute = bssrdf["median_rse_per_cpu_minute"]
    reached = None if per_minute is None else per_minute / (BSSRDF_CPU_SECONDS / 60.0) ** 0.5
    return {**_comparison_header("reference bssrdf_path", scene, args, mask),
            "profile": args.bssrdf, "estimators": rows,
            "target": {"cpu_seconds": BSSRDF_CPU_SECONDS, "median_rse": BSSRDF_TARGET_RSE,
                       "reached": reached,
                       "met": reached is not None and reached <= BSSRDF_TARGET_RSE}}


def _print_bssrdf(result) -> None:
    width, height = result["size"]
    print(f"bssrdf_path ({result['profile']}) against volpath_mnee: {result['scene']} "
          f"{width} x {height}, {result['spp']} spp x {result['passes']} passes "
          f"({result['variant']})")
    print(f"{'estimator':>28}  {'cpu s':>8}  {'median RSE':>10}  {'RSE at 1 CPU min':>16}  "
          f"{'efficiency':>10}")
    for name, row in result["estimators"].items():
        rse, per_minute, ratio = (row["median_rse"], row["median_rse_per_cpu_minute"],
                                  row["efficiency_ratio"])
        print(f"{name:>28}  {row['cpu_seconds']:>8.1f}  "
              f"{'none lit' if rse is None else f'{100 * rse:.2f}%':>10}  "
              f"{'none lit' if per_minute is None else f'{100 * per_minute:.2f}%':>16}  "
              f"{'n/a' if ratio is None else f'{ratio:.1f}':>10}")
    print("efficiency: 1 / (RSE^2 x CPU time) as a ratio to volpath_mnee's")
    target = result["target"]
    shown = "none lit" if target["reached"] is None else f"{100 * target['reached']:.2f} %"
    verdict = "meets" if target["met"] else "MISSES"
    print(f"bssrdf_path at {target['cpu_seconds']:g} CPU seconds: median RSE {shown} "
          f"({verdict} the target {100 * target['median_rse']:g} %; scaled from this run as "
          f"the square root of time)")


def run(args) -> int:
    """Run the overhead timing (or the integrator comparison), print it, write the JSON."""
    scene = _scene(args)
    if getattr(args, "bssrdf", None):
        result = _bssrdf(scene, args)
        _print_bssrdf(result)
        default = "bench_reference_bssrdf.json"
    elif getattr(args, "delta_lights", False):
        result = _delta_lights(scene, args)
        _print_delta_lights(result)
        default = "bench_reference_delta_lights.json"
    elif args.integrators:
        result = _integrators(scene, args)
        _print_integrators(result)
        default = "bench_reference_integrators.json"
    else:
        result = _overhead(scene, args)
        _print_overhead(result)
        default = "bench_reference.json"
    path = write_figures(args.json or default, "reference", result)
    print(f"wrote {path}")
    return 0
