"""The built-in scenes' committed references: ``translucent references [render NAME ...]``.

Without a sub-command, lists each built-in scene's committed reference: its file, spp x
passes, the median and 99th-percentile relative standard error over its lit pixels (the
pixels the report scores), how long it took to render, and whether it is current (rendered
from the scene as it loads now). The common ``--json FILE`` (``-`` for standard output) writes
the same for scripts, under ``references``. Exit code 1 when any committed reference is
missing or stale.

``translucent references render NAME ...`` renders the named references again (``all`` for
every one): passes are added until the noise target of the scene's plan is met or its budget
is spent (``--budget SECONDS`` overrides it), and the file is replaced only when the render
is complete. With ``--profile P`` it renders the scenes' *model references* instead: the
BSSRDF path tracer's render of profile P (``reference/data/model/<scene>.<P>.exr``), which
the report sets beside the volumetric reference to split a method's error. The list shows
both kinds.
"""

from __future__ import annotations

from ...errors import InputError
from .record import record


def add_arguments(parser):
    """``[render NAME ...] [--budget S]``, and the common options."""
    parser.add_argument("action", nargs="?", choices=["list", "render"], default="list",
                        help="list the committed references (default) or render them again")
    parser.add_argument("names", nargs="*", metavar="NAME",
                        help="with render: the scenes to render again, or 'all'")
    parser.add_argument("--profile", default=None, metavar="NAME",
                        help="with render: the model references of this profile (the BSSRDF "
                        "path tracer; dipole+walk or dipole+geometry: with the object's own "
                        "shape by walks or by diffusion) instead of the volumetric references")
    parser.add_argument("--budget", type=float, default=None, metavar="SECONDS",
                        help="with render: rendering time at most per scene (default: the "
                        "scene's plan)")


def _row(name: str, profile: str | None = None) -> dict:
    from ...noise import noise_summary
    from ...reference.committed import MODEL_PLANS, PLANS, committed_reference, rerender_command

    plan = PLANS[name] if profile is None else MODEL_PLANS[name][profile]
    entry = committed_reference(name, profile=profile)
    row = {"scene": name, "profile": profile, "path": str(entry.path),
           "current": entry.current, "problem": entry.problem or None,
           "command": rerender_command(name, profile),
           "target": {"median": plan.target_rse, "p99": plan.target_p99_rse}}
    image = entry.image
    if image is not None:
        meta = image.metadata
        summary = (noise_summary(image.rgb, image.variance).as_dict()
                   if image.variance is not None else None)
        row.update({"spp": meta.get("spp"), "passes": meta.get("passes"),
                    "seconds": meta.get("seconds"), "integrator": meta.get("integrator"),
                    "variant": meta.get("variant"), "mitsuba": meta.get("mitsuba"),
                    "stopped": meta.get("stopped"), "noise": summary})
        row["meets_target"] = bool(summary and summary["pixels"] and
                                   summary["median"] <= row["target"]["median"] and
                                   summary["p99"] <= row["target"]["p99"])
    return row


def _print_rows(rows) -> None:
    for row in rows:
        state = "current" if row["current"] else f"NOT CURRENT: {row['problem']}"
        kind = f" (model reference, profile {row['profile']})" if row["profile"] else ""
        print(f"{row['scene']}{kind}: {state}")
        print(f"  file: {row['path']}")
        noise = row.get("noise")
        if noise and noise.get("pixels"):
            target = row["target"]
            met = "meets" if row["meets_target"] else "misses"
            print(f"  {row['spp']} spp x {row['passes']} passes ({row['integrator']}, "
                  f"{row['variant']}, Mitsuba {row['mitsuba']}), {row['seconds']:.0f} s, "
                  f"stopped: {row['stopped']}")
            print(f"  relative standard error over {noise['pixels']} lit pixels: median "
                  f"{100 * noise['median']:.3g} %, 99th percentile {100 * noise['p99']:.3g} % "
                  f"({met} the target {100 * target['median']:g} % / {100 * target['p99']:g} %)")
        if not row["current"]:
            print(f"  render it again: {row['command']}")


def run(args) -> int:
    """List the committed references, or render the named ones again."""
    from ...reference.committed import (
        MODEL_PROFILES,
        committed_model_cases,
        committed_model_scene_names,
        committed_scene_names,
        render_committed,
    )

    profile = args.profile
    names = committed_scene_names() if profile is None else \
        committed_model_scene_names(profile)
    if args.action == "list":
        if args.names:
            raise InputError("names go with 'render'; 'translucent references' lists all",
                             field="NAME", value=args.names)
        for value, flag in ((args.budget, "--budget"), (profile, "--profile")):
            if value is not None:
                raise InputError("goes with 'render'", field=flag, value=value)
        rows = [_row(name) for name in names] + [
            _row(name, model) for name, model in committed_model_cases()]
        _print_rows(rows)
        record(args, references=rows)
        return 0 if all(row["current"] for row in rows) else 1

    if profile is not None and profile not in MODEL_PROFILES:
        raise InputError(f"no model reference is committed for this profile (committed: "
                         f"{', '.join(MODEL_PROFILES)})", field="--profile", value=profile)
    wanted = names if args.names == ["all"] else list(args.names)
    if not wanted:
        raise InputError(f"name the scenes to render, or 'all' (planned: {', '.join(names)})",
                         field="NAME", value=[])
    unknown = [name for name in wanted if name not in names]
    if unknown:
        raise InputError(f"no committed reference is planned for this scene (planned: "
                         f"{', '.join(names)})", field="NAME", value=unknown[0])
    if args.budget is not None and not args.budget > 0:
        raise InputError("must be > 0 seconds", field="--budget", value=args.budget)
    rendered = []
    for name in wanted:
        image = render_committed(name, budget_seconds=args.budget,
                                 progress=not args.no_progress, profile=profile)
        meta = image.metadata
        noise = meta["noise"]
        rendered.append({"scene": name, "profile": profile, "spp": meta["spp"],
                         "passes": meta["passes"], "seconds": meta["seconds"],
                         "stopped": meta["stopped"], "noise": noise})
        record(args, rendered=rendered)
        kind = f" (model reference, profile {profile})" if profile else ""
        print(f"wrote {name}{kind}: {meta['spp']} spp x {meta['passes']} passes in "
              f"{meta['seconds']:.0f} s ({meta['stopped']}); relative standard error median "
              f"{100 * noise['median']:.3g} %, 99th percentile {100 * noise['p99']:.3g} %")
    return 0
