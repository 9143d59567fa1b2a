"""How much faster than path tracing, at equal error: the report's path-tracing ladder.

For each scene with a reference, Mitsuba renders the scene at :data:`PATH_TRACING_SPP`
samples per pixel (one timed render each, after one untimed render that compiles the
kernels: :func:`path_tracing_points`, the estimator the reference itself uses), and each
render is scored against the reference on the pixels the methods are scored on: relative
MSE, the reference's noise discounted. A method's speed-up is the path tracer's time at the
method's relative MSE (interpolated on the log-log curve, or extrapolated along its power
law beyond the swept spp and flagged so:
:func:`~translucent.reports.bench.tradeoff.equal_error_seconds`) over the method's warm
frame time. Where the method's error does not clear the reference's noise, the speed-up is
not given: the error it would be matched at is not known.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

__all__ = ["PATH_TRACING_REPEATS", "PATH_TRACING_SPP", "equal_error_seconds",
           "path_tracing_point", "path_tracing_points", "PathTracingCurve", "overview_plot",
           "path_tracing_ladder",
           "same_run_ratios", "scored_curve", "scored_relative_mse", "speedup",
           "tradeoff_plot"]

#: The report's path-tracing ladder, samples per pixel (per channel where the reference
#: renders one channel at a time).
PATH_TRACING_SPP = (1, 4, 16)


def path_tracing_ladder(scene, spp_values=PATH_TRACING_SPP) -> list[dict]:
    """Render ``scene`` with Mitsuba at each of ``spp_values``, timed (a report task).

    Returns
    -------
    list of dict
        Per spp: ``spp``, ``seconds`` and ``images`` (one), or ``error`` (a string).
    """
    return path_tracing_points(scene, spp_values, repeats=1)


@dataclass
class PathTracingCurve:
    """Path tracing's run time against error on one scene.

    Attributes
    ----------
    spp : list of int
    seconds : list of float
        Wall-clock seconds of one render at each spp.
    relative_mse : list of float
        Its relative MSE against the reference over the scored pixels.
    error : str
        Why the curve is missing or short ("" when every point was rendered).
    """

    spp: list[int] = field(default_factory=list)
    seconds: list[float] = field(default_factory=list)
    relative_mse: list[float] = field(default_factory=list)
    error: str = ""

    def as_dict(self) -> dict:
        """JSON-able."""
        return {"spp": self.spp, "seconds": self.seconds, "relative_mse": self.relative_mse,
                "error": self.error or None}


def scored_curve(points, reference, mask=None) -> PathTracingCurve:
    """Score the renders of :func:`path_tracing_ladder` against ``reference``.

    Parameters
    ----------
    points : list of dict, or an exception's text
        What the ladder task returned.
    reference : Image
    mask : array_like of bool, shape (H, W), optional
        The scored pixels (those of the objects).
    """
    from ...errors import InputError

    if not isinstance(points, list):
        return PathTracingCurve(error=str(points))
    curve = PathTracingCurve()
    errors = []
    for point in points:
        if "error" in point:
            errors.append(f"{point['spp']} spp: {point['error']}")
            continue
        try:
            score = scored_relative_mse(reference, point["images"][0], mask)
        except (InputError, TypeError) as error:
            errors.append(f"{point['spp']} spp: {error}")
            continue
        curve.spp.append(int(point["spp"]))
        curve.seconds.append(float(point["seconds"]))
        curve.relative_mse.append(float(score))
    curve.error = "; ".join(errors)
    return curve


def scored_relative_mse(reference, image, mask) -> float:
    """Relative MSE over the scored pixels, the reference's noise discounted, as the methods'."""
    import numpy as np

    from ..metrics.compute import relative_mse

    ref, test, variance = reference.rgb, image.rgb, reference.variance
    if ref.shape != test.shape:
        from ...errors import InputError

        raise InputError(f"the render is {test.shape}, the reference {ref.shape}",
                         field="shape", value=test.shape)
    if mask is not None:
        mask = np.asarray(mask, dtype=bool)
        ref, test = ref[mask], test[mask]
        variance = None if variance is None else variance[mask]
    return relative_mse(ref, test, reference_variance=variance)


def speedup(curve: PathTracingCurve | None, relative_mse, frame_seconds,
            verdict: str | None) -> dict:
    """Return a method's speed-up over path tracing at its own relative MSE.

    Parameters
    ----------
    curve : PathTracingCurve or None
    relative_mse : float or None
        The method's relative MSE over the scored pixels.
    frame_seconds : float or None
        The method's warm frame time.
    verdict : str or None
        Its relative MSE's noise verdict (:func:`~translucent.reports.metrics.noise_verdict`).

    Returns
    -------
    dict
        ``speedup_vs_path_tracing`` (None when not measured), ``path_tracing_seconds``
        (path tracing's time at that error), ``extrapolated`` and ``reason`` (why it is
        None, or what qualifies it).
    """
    from ..metrics.compute import WITHIN_NOISE

    empty = {"speedup_vs_path_tracing": None, "path_tracing_seconds": None,
             "extrapolated": False}
    if curve is None:
        return {**empty, "reason": "no path-tracing ladder on this scene"}
    if len(curve.relative_mse) < 2:
        return {**empty, "reason": f"path tracing's ladder has under two points "
                                   f"({curve.error or 'nothing rendered'})"}
    if relative_mse is None or not math.isfinite(relative_mse) or relative_mse <= 0:
        return {**empty, "reason": "the method's relative MSE is not positive and finite"}
    if verdict == WITHIN_NOISE:
        return {**empty, "reason": "the method's relative MSE is within the reference's "
                                   "noise: the error to match is not resolved"}
    if not frame_seconds or frame_seconds <= 0:
        return {**empty, "reason": "the method's frame time is not known"}
    seconds, extrapolated = equal_error_seconds(curve.relative_mse, curve.seconds,
                                                relative_mse)
    if not math.isfinite(seconds):
        return {**empty, "reason": "path tracing's curve gives no time at this error"}
    reason = None
    if extrapolated:
        reason = (f"extrapolated beyond path tracing's {min(curve.spp)}-{max(curve.spp)} spp "
                  "along its power law")
    return {"speedup_vs_path_tracing": seconds / frame_seconds,
            "path_tracing_seconds": seconds, "extrapolated": extrapolated, "reason": reason}


def tradeoff_plot(path, curves: dict, methods: dict, noise_floor: float | None,
                  title: str, ladders: dict | None = None) -> Path | None:
    """Draw run time against relative MSE, log-log: path tracing's curves, each method's point.

    Parameters
    ----------
    path : str or Path
        The PNG (written atomically).
    curves : dict
        ``label -> PathTracingCurve`` (or None): path tracing scored on each set of pixels
        a method is scored on.
    methods : dict
        ``name -> (frame_seconds, relative_mse)``.
    noise_floor : float or None
        The relative MSE the reference's noise alone gives, drawn as a band: errors below
        it are not resolved.
    title : str
    ladders : dict, optional
        ``name -> [(frame_seconds, relative_mse), ...]``: a method at cheaper settings,
        drawn hollow and joined to its point at the defaults.

    Returns
    -------
    Path or None
        None when there is nothing to draw.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import matplotlib.ticker

    from ...atomic import atomic_save_figure

    usable = {name: (t, e) for name, (t, e) in methods.items()
              if t and e and t > 0 and e > 0 and math.isfinite(t) and math.isfinite(e)}
    traced = {label: curve for label, curve in curves.items()
              if curve is not None and len(curve.relative_mse) > 0}
    if not usable and not traced:
        return None
    figure, axes = plt.subplots(figsize=(7.4, 3.6))
    drawn = [e for _, e in usable.values()]
    for number, (label, curve) in enumerate(traced.items()):
        colour = ("0.35", "tab:brown", "tab:olive", "tab:cyan")[number % 4]
        positive = [(s, e, n) for s, e, n in zip(curve.seconds, curve.relative_mse, curve.spp,
                                                  strict=True) if s > 0 and e > 0]
        if not positive:
            continue
        seconds, errors, spp = zip(*positive, strict=True)
        drawn += list(errors)
        axes.plot(seconds, errors, "o-", color=colour, label=label)
        lowest = min((e for _, e in usable.values()), default=min(errors))
        if len(positive) >= 2 and lowest < min(errors):
            # where a method's error lies beyond the ladder: the power law its speed-up is
            # extrapolated along

            reach = equal_error_seconds(errors, seconds, lowest)[0]
            if math.isfinite(reach):
                axes.plot([seconds[errors.index(min(errors))], reach], [min(errors), lowest],
                          ":", color=colour, label=f"{label}, extrapolated")
        if number == 0:
            for s_, e_, n_ in positive:
                axes.annotate(f"{n_} spp", (s_, e_), textcoords="offset points",
                              xytext=(4, 4), fontsize=7, color=colour)
    markers = "sD^v<>p*"
    for index, (name, (seconds, error)) in enumerate(sorted(usable.items())):
        marker = markers[index % len(markers)]
        (line,) = axes.plot([seconds], [error], marker, markersize=8, label=name)
        cheaper = [(t, e) for t, e in (ladders or {}).get(name, [])
                   if t and e and t > 0 and e > 0 and math.isfinite(t) and math.isfinite(e)]
        if cheaper:
            points = sorted(cheaper + [(seconds, error)])
            axes.plot([t for t, _ in points], [e for _, e in points], "--",
                      color=line.get_color(), lw=1)
            axes.plot([t for t, _ in cheaper], [e for _, e in cheaper], marker, markersize=7,
                      color=line.get_color(), markerfacecolor="none",
                      label=f"{name}, cheaper settings")
            drawn += [e for _, e in cheaper]
    floor = noise_floor if noise_floor is not None and math.isfinite(noise_floor) \
        and noise_floor > 0 else None
    values = [v for v in drawn + ([floor] if floor else []) if v > 0 and math.isfinite(v)]
    low, high = min(values) / 3.0, max(values) * 3.0
    if floor:
        # errors below the floor are not resolved against this reference
        axes.axhspan(low, floor, color="tab:red", alpha=0.12, lw=0)
        axes.axhline(floor, color="tab:red", lw=1, ls="--", label="reference noise floor")
    axes.set_xscale("log")
    axes.set_yscale("log")
    axes.xaxis.set_minor_formatter(matplotlib.ticker.NullFormatter())
    axes.set_ylim(low, high)
    axes.set_xlabel("seconds per frame (path tracing: per render)")
    axes.set_ylabel("relative MSE over the scored pixels")
    axes.set_title(title, fontsize=9)
    axes.grid(True, which="both", alpha=0.3)
    # outside the axes: with a ladder per method the legend would hide points
    axes.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.02, 1.0), borderaxespad=0.0)
    figure.tight_layout()
    return atomic_save_figure(path, figure)


def overview_plot(path, points: list[tuple], title: str = "every scene") -> Path | None:
    """Draw each method on each scene at its warm frame time and relative MSE, log-log.

    Parameters
    ----------
    path : str or Path
        The PNG (written atomically).
    points : list of tuple
        ``(scene, method, frame_seconds, relative_mse, within_noise)``; a point whose
        error is within the reference's noise is drawn hollow.
    title : str

    Returns
    -------
    Path or None
        None when no point has a positive time and error.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import matplotlib.ticker

    from ...atomic import atomic_save_figure

    usable = [p for p in points if p[2] and p[3] and p[2] > 0 and p[3] > 0
              and math.isfinite(p[2]) and math.isfinite(p[3])]
    if not usable:
        return None
    methods = sorted({p[1] for p in usable})
    scenes = sorted({p[0] for p in usable})
    colours = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    markers = "osD^v<>p*hX"
    figure, axes = plt.subplots(figsize=(5.0, 3.9))
    for scene, name, seconds, error, within_noise in usable:
        colour = colours[methods.index(name) % len(colours)]
        axes.plot([seconds], [error], markers[scenes.index(scene) % len(markers)],
                  markersize=7, color=colour,
                  markerfacecolor="none" if within_noise else colour)
    for index, name in enumerate(methods):
        axes.plot([], [], "s", color=colours[index % len(colours)], label=name)
    for index, scene in enumerate(scenes):
        axes.plot([], [], markers[index % len(markers)], color="0.4", markerfacecolor="none",
                  label=scene)
    axes.set_xscale("log")
    axes.set_yscale("log")
    axes.xaxis.set_minor_formatter(matplotlib.ticker.NullFormatter())
    axes.set_xlabel("seconds per frame (warm)")
    axes.set_ylabel("relative MSE over the scored pixels")
    axes.set_title(f"{title}: how wrong and how fast (hollow: within reference noise)",
                   fontsize=8)
    axes.grid(True, which="both", alpha=0.3)
    axes.legend(fontsize=6.5, loc="center left", bbox_to_anchor=(1.0, 0.5), frameon=False)
    figure.tight_layout()
    return atomic_save_figure(path, figure)


#: Timed renders per path-tracing point: the median time and the mean error over them (a
#: 1-spp render of a small image lasts tens of milliseconds, where one timing is noisy, and
#: one low-spp render's error depends much on its fireflies).
PATH_TRACING_REPEATS = 3


def path_tracing_point(scene, spp: int, seed: int = 1, repeats: int = PATH_TRACING_REPEATS):
    """Render ``scene`` with Mitsuba at ``spp`` and time it (a sweep task).

    :func:`path_tracing_points` with one spp.

    Returns
    -------
    dict
        ``spp``, ``seconds`` (the median of the timed renders), ``per_channel`` and
        ``images`` (one :class:`~translucent.image.Image` per timed render), or ``error`` (a
        string) when Mitsuba failed.
    """
    return path_tracing_points(scene, [spp], seed, repeats)[0]


def path_tracing_points(scene, spp_values, seed: int = 1,
                        repeats: int = PATH_TRACING_REPEATS) -> list[dict]:
    """Render ``scene`` with Mitsuba at each of ``spp_values`` and time each.

    The estimator is the reference's (:func:`translucent.reference.render`): one RGB render,
    or one render per channel where the conversion recommends it (chromatic media of high
    albedo), so the path tracer is timed as the suite itself would run it. The scene is
    converted and loaded once and rendered once untimed at the first spp, which compiles
    the kernels; the other spp values use the same kernels (the sample count of a render
    is not part of them, the sample count a scene is loaded with is: loading once per spp
    compiled every kernel again). Then ``repeats`` renders per spp with the seeds ``seed,
    seed + 1, ...``, each timed.

    Parameters
    ----------
    scene : Scene
    spp_values : sequence of int
        Samples per pixel (>= 1), per channel where rendered per channel.
    seed : int
        Seed of the first timed render (the untimed one uses ``seed + repeats``).
    repeats : int
        Timed renders per spp.

    Returns
    -------
    list of dict
        Per spp as :func:`path_tracing_point`.
    """
    from ...image import Image
    from ...reference.render import load_scenes, render_sample

    spp_values = [int(spp) for spp in spp_values]
    try:
        channels, conversions, loaded = load_scenes(scene, spp=spp_values[0])
        per_channel = channels != (None,)
        render_sample(channels, loaded, spp_values[0], seed + repeats)
    except Exception as error:  # reported in the JSON; the sweep goes on
        return [{"spp": spp, "error": f"{type(error).__name__}: {error}"}
                for spp in spp_values]
    points = []
    for spp in spp_values:
        try:
            timings, images = [], []
            for k in range(repeats):
                started = time.perf_counter()
                rgb = render_sample(channels, loaded, spp, seed + k)
                timings.append(time.perf_counter() - started)
                images.append(Image(rgb, metadata={
                    "producer": "path tracing", "spp": spp, "seed": seed + k,
                    "per_channel": per_channel, "integrator": conversions[0].integrator}))
        except Exception as error:  # reported in the JSON; the sweep goes on
            points.append({"spp": spp, "error": f"{type(error).__name__}: {error}"})
            continue
        points.append({"spp": spp, "seconds": float(np.median(timings)),
                       "per_channel": per_channel, "images": images})
    return points


def equal_error_seconds(errors, seconds, error: float) -> tuple[float, bool]:
    """Return the path tracer's time at ``error``, interpolated on its log-log curve.

    Inside the range of measured errors: linear interpolation of log seconds against log
    error between the two neighbouring points. Outside: the least-squares power law
    ``seconds = a * error^b`` through all points (Monte Carlo error falls as 1/spp, so
    b is near -1).

    Parameters
    ----------
    errors, seconds : array_like
        The path-tracing sweep: relative MSE and seconds per point (> 0).
    error : float
        The error to match (> 0).

    Returns
    -------
    seconds : float
        Path-tracing seconds at that error; NaN when it cannot be estimated.
    extrapolated : bool
        True when ``error`` lies outside the measured errors.
    """
    errors = np.asarray(errors, dtype=np.float64)
    seconds = np.asarray(seconds, dtype=np.float64)
    usable = np.isfinite(errors) & np.isfinite(seconds) & (errors > 0) & (seconds > 0)
    errors, seconds = errors[usable], seconds[usable]
    if not (math.isfinite(error) and error > 0) or len(np.unique(errors)) < 2:
        return math.nan, True
    log_e, log_t = np.log(errors), np.log(seconds)
    order = np.argsort(log_e)
    log_e, log_t = log_e[order], log_t[order]
    target = math.log(error)
    # an error equal to a ladder point's, up to the rounding of the logarithms, is inside
    reach = 1e-12 * max(1.0, abs(log_e[0]), abs(log_e[-1]))
    if log_e[0] - reach <= target <= log_e[-1] + reach:
        target = min(max(target, log_e[0]), log_e[-1])
        return float(np.exp(np.interp(target, log_e, log_t))), False
    slope, intercept = np.polyfit(log_e, log_t, 1)
    return float(np.exp(intercept + slope * target)), True


def same_run_ratios(curve: PathTracingCurve | None, run) -> dict:
    """Return a method's times as multiples of one 1-spp path-traced render of the same run.

    Times measured on a shared machine move with its load; the 1-spp render of the
    path-tracing ladder is timed in the same run on the same scene, so these ratios
    compare across runs and machines where the seconds do not.

    Parameters
    ----------
    curve : PathTracingCurve or None
        The scene's ladder (its 1-spp point is the unit).
    run : MethodRun or None
        The method's run (``frame_seconds``, ``precompute_seconds``).

    Returns
    -------
    dict
        ``path_tracing_1spp_seconds``, ``frame_in_path_traced_1spp_renders`` and
        ``precompute_in_path_traced_1spp_renders``; None where a time is missing.
    """
    base = None
    if curve is not None and 1 in curve.spp:
        base = curve.seconds[curve.spp.index(1)]
    ratios = {"path_tracing_1spp_seconds": base}
    for key in ("frame", "precompute"):
        seconds = getattr(run, f"{key}_seconds", None) if run is not None else None
        ratios[f"{key}_in_path_traced_1spp_renders"] = (
            float(seconds) / base if base and base > 0 and seconds is not None else None)
    return ratios

