"""What the report prints, and the rows it prints them from.

The summary table of :func:`~translucent.reports.report.pipeline.make_report` (a row per scene and
method: the gated metrics beside their noise floors, the times, the speed-up over path
tracing, the relative MSE of the model and of the method against it and which dominates
(:mod:`.split`), and the baseline's verdict) and the line that says where the report's time went.
"""

from __future__ import annotations

from .formatting import format_seconds, format_speedup, format_value
from .runs import json_safe
from .speedup import same_run_ratios

__all__ = ["summary_rows", "speedup_fields", "print_summary"]


def summary_rows(reports: list, chosen: list[str]) -> list[dict]:
    """Return a row per scene and method: status, gated metrics, noise floors, times."""
    rows = []
    for report in reports:
        for name in chosen:
            run = report.runs.get(name)
            metrics = report.metrics.get(name, {})
            check = report.checks.get(name)
            rows.append({
                "scene": report.name, "method": name,
                "status": run.status if run else "not run",
                "reason": (report.metric_errors.get(name) or (run.reason if run else "")),
                "hdr_flip": metrics.get("hdr_flip"), "relative_mse": metrics.get("relative_mse"),
                "ciede2000": metrics.get("ciede2000"), "ssim": metrics.get("ssim"),
                "noise_floor": {key: (report.floor_of(name) or {}).get(key)
                                for key in ("hdr_flip", "relative_mse", "ciede2000", "ssim")},
                "within_noise": [key for key, verdict in report.verdicts.get(name, {}).items()
                                 if verdict == "within reference noise"],
                "precompute_seconds": run.precompute_seconds if run else None,
                "frame_seconds": run.frame_seconds if run else None,
                "first_frame_seconds": run.first_frame_seconds if run else None,
                **speedup_fields(report, name),
                "cached": bool(run and run.cached),
                "baseline": check.status if check else "",
                **_split_fields(report.splits.get(name)),
            })
    return rows


def _split_fields(split) -> dict:
    """Return a row's error split: the model's and the approximation's relative MSE."""
    if split is None or split.reason:
        return {"model_relative_mse": None, "approximation_relative_mse": None,
                "dominant": None}
    return {"model_relative_mse": split.model.get("relative_mse"),
            "approximation_relative_mse": split.approximation.get("relative_mse"),
            "dominant": split.dominant}


def speedup_fields(report, name: str) -> dict:
    """Return a method's speed-up over path tracing and why it is missing, for the JSON."""
    found = report.speedups.get(name)
    if found is None:
        reason = ("the method was not scored" if name not in report.metrics else
                  "no path-tracing ladder on this scene")
        return {"speedup_vs_path_tracing": None, "speedup_reason": reason,
                "path_tracing_seconds_at_equal_error": None, "speedup_extrapolated": False}
    return {"speedup_vs_path_tracing": json_safe(found["speedup_vs_path_tracing"]),
            "speedup_reason": found["reason"],
            "path_tracing_seconds_at_equal_error": json_safe(found["path_tracing_seconds"]),
            "speedup_extrapolated": found["extrapolated"],
            **same_run_ratios(report.curve, report.runs.get(name))}


def time_line(timing: dict, task_times: list[dict]) -> str:
    """Where the report's time went: its phases, and its longest task."""
    line = f"time: planning {timing['planning']:.1f} s, tasks {timing['tasks']:.1f} s"
    if task_times:
        busy = sum(t["seconds"] for t in task_times)
        longest = max(task_times, key=lambda t: t["seconds"])
        what = longest.get("method", longest["kind"])
        if longest.get("knobs"):
            what += " " + ", ".join(f"{k}={v}" for k, v in longest["knobs"].items())
        workers = len({t["worker"] for t in task_times})
        line += (f" ({len(task_times)} tasks, {busy:.1f} s of task time on {workers} "
                 f"process(es); longest {longest['scene']} {what} {longest['seconds']:.1f} s)")
    line += f", metrics and error maps {timing.get('scoring', 0.0):.1f} s"
    during = timing.get("scoring_during_tasks", 0.0)
    return line + (f" ({during:.1f} s of it while the tasks ran)" if during else "")


def print_summary(summary, regressions, out, seconds, updated, baseline_path, stream,
                  timing=None, task_times=()):
    """Print the summary table, the regressions, the time line and where the page is."""
    width = max((len(r["scene"]) for r in summary), default=5)
    named = max([6] + [len(r["method"]) for r in summary])
    print(f"{'scene':<{width}}  {'method':<{named}} {'HDR-FLIP':>8} {'(noise)':>7} {'relMSE':>9} "
          f"{'(noise)':>9} {'dE2000':>7} {'SSIM':>6} {'precomp':>8} {'frame':>8} "
          f"{'vs PT':>7} {'model':>8} {'method':>8} {'dominant':<12}  verdict",
          file=stream)
    for row in summary:
        if row["status"] != "ok":
            print(f"{row['scene']:<{width}}  {row['method']:<{named}} {row['status']}: "
                  f"{row['reason'][:90]}", file=stream)
            continue
        cached = " (cached)" if row["cached"] else ""
        floor = row["noise_floor"]
        noisy = (f"; within reference noise: {', '.join(row['within_noise'])}"
                 if row["within_noise"] else "")
        print(f"{row['scene']:<{width}}  {row['method']:<{named}} "
              f"{format_value(row['hdr_flip'], 3):>8} {format_value(floor['hdr_flip'], 2):>7} "
              f"{format_value(row['relative_mse'], 3):>9} "
              f"{format_value(floor['relative_mse'], 2):>9} "
              f"{format_value(row['ciede2000'], 3):>7} "
              f"{format_value(row['ssim'], 3):>6} {format_seconds(row['precompute_seconds']):>8} "
              f"{format_seconds(row['frame_seconds']):>8} "
              f"{format_speedup(row['speedup_vs_path_tracing'], row['speedup_extrapolated']):>7} "
              f"{format_value(row['model_relative_mse'], 2):>8} "
              f"{format_value(row['approximation_relative_mse'], 2):>8} "
              f"{row['dominant'] or '-':<12}  {row['baseline']}{cached}{noisy}",
              file=stream)
    for line in regressions:
        print(f"REGRESSION {line}", file=stream)
    if updated:
        print(f"baseline written: {baseline_path}", file=stream)
    if timing is not None:
        print(time_line(timing, list(task_times)), file=stream)
    print(f"wrote {out / 'index.html'} in {seconds:.1f} s", file=stream, flush=True)
