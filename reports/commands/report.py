"""The main job: every fast method against its reference on the built-in scenes, as HTML.

``translucent report [SCENE ...] [--out DIR] [--methods m1,m2] [--update-baseline]
[--baseline FILE] [--scheduler ADDRESS | --serial] [--spp N --passes K]
[--keep-precomputations] [--profiles all|P1,P2] [--renderers NAME[.MODE],...
[--renderer-spp N1,N2,...]]``

Writes ``DIR/index.html`` (images side by side, error maps, metrics, precomputation and
frame times, what each method skipped and why, every subsurface method's error split into
its profile's and its own against the model reference; other renderers' modes, such as
Blender Cycles' subsurface modes, scored beside them) and ``DIR/metrics.json``. Exits 0 when no
gated metric is worse than the baseline beyond its tolerance, 1 when one is (or a result
the baseline expects is missing), 2 on bad input (an unknown scene or method, an ``--out``
that cannot hold a report), leaving nothing half-written.
"""

from __future__ import annotations


def add_arguments(parser):
    """Scenes, output folder, methods, baseline, where tasks run, reference samples."""
    from ..report.peer_runs import RENDERER_SPP
    from ..report.pipeline import (
        DEFAULT_PASSES,
        DEFAULT_REFERENCE_BUDGET,
        DEFAULT_TARGET_RSE,
        PROGRESSIVE_SPP,
        REPORT_CACHE_ENTRY_LIMIT,
    )

    parser.add_argument("scenes", nargs="*", metavar="SCENE",
                        help="built-in scene names or scene TOML files (default: the built-in "
                             "scenes, less the test scenes the page lists)")
    parser.add_argument("--out", "-o", default="report",
                        help="report folder (default ./report; a previous report there is "
                             "replaced, any other folder with files in it refused)")
    parser.add_argument("--methods", default=None, metavar="M1,M2",
                        help="comma-separated fast methods (default: all; those not installed "
                             "are listed as such)")
    parser.add_argument("--baseline", default=None, metavar="FILE",
                        help="baseline JSON (default: the committed reports/baseline/"
                             "default.json)")
    parser.add_argument("--update-baseline", action="store_true",
                        help="write this run's metrics into the baseline and exit 0")
    where = parser.add_mutually_exclusive_group()
    where.add_argument("--scheduler", default=None, metavar="ADDRESS",
                       help="Dask scheduler for the reference renders and method runs "
                            "(default: local processes)")
    where.add_argument("--serial", action="store_true",
                       help="run every task in this process (no Dask)")
    parser.add_argument("--spp", type=int, default=None,
                        help="render every reference afresh with this many samples per pixel "
                             "per pass (with --passes). Default: the built-in scenes' "
                             "committed references (`translucent references`; a stale one "
                             "is an error), and other scenes rendered progressively, "
                             f"{PROGRESSIVE_SPP} spp a pass, to a median relative standard "
                             f"error of {100 * DEFAULT_TARGET_RSE:g} %% or for at most "
                             f"{DEFAULT_REFERENCE_BUDGET:g} s, whichever comes first")
    parser.add_argument("--passes", type=int, default=DEFAULT_PASSES,
                        help=f"independent reference passes with --spp (default "
                             f"{DEFAULT_PASSES})")
    parser.add_argument("--keep-precomputations", action="store_true",
                        help="keep every method's precomputation in the cache (default: "
                             f"those up to {REPORT_CACHE_ENTRY_LIMIT // 2**20} MiB; "
                             "radiosity's of the default spheres, 1-3 GB each, are "
                             "computed again on the next run)")
    parser.add_argument("--images", default=None, metavar="DIR",
                        help="score another renderer's images too: DIR/<renderer>/<scene>.exr "
                             "(times from the EXR header's 'seconds'); without --methods, only "
                             "them")
    parser.add_argument("--renderers", default=None, metavar="NAME[.MODE],...",
                        help="score other renderers like methods: NAME (every mode) or "
                             "NAME.MODE, comma-separated (cycles: burley, random_walk, "
                             "random_walk_skin, volume; a Python with bpy, named by "
                             "TRANSLUCENT_BPY_PYTHON); without --methods, only them")
    parser.add_argument("--renderer-spp", default=None, metavar="N1,N2,...",
                        help="samples per pixel the renderers render at, each timed; the "
                             "largest is the scored run (default "
                             f"{','.join(map(str, RENDERER_SPP))})")
    parser.add_argument("--profiles", default=None, metavar="all|P1,P2",
                        help="also run every method that has a profile knob with these radial "
                             "profiles (or all), each split into its profile's error and "
                             "its own against that profile's model reference (rendered by "
                             "the BSSRDF path tracer; default: the default profile only)")
    parser.add_argument("--no-progress", action="store_true", help="no progress bars")


def run(args) -> int:
    """Run the report; the exit code says whether a metric regressed."""
    from ...errors import InputError
    from ..report.pipeline import DEFAULT_PASSES, make_report

    if args.spp is None and args.passes != DEFAULT_PASSES:
        raise InputError("goes with --spp (without it the references are committed or "
                         "rendered to a noise target)", field="--passes", value=args.passes)
    if args.renderer_spp is not None and args.renderers is None:
        raise InputError("goes with --renderers (the counts other renderers render at)",
                         field="--renderer-spp", value=args.renderer_spp)
    methods = None
    if args.methods is not None:
        methods = [name for name in args.methods.split(",") if name.strip()]
        if not methods:
            raise InputError("give at least one method", field="--methods", value=args.methods)
    result = make_report(args.scenes or None, args.out, methods=methods, baseline=args.baseline,
                         update_baseline=args.update_baseline, scheduler=args.scheduler,
                         serial=args.serial, spp=args.spp, passes=args.passes,
                         progress=not args.no_progress,
                         keep_precomputations=args.keep_precomputations,
                         images=args.images, profiles=args.profiles,
                         renderers=args.renderers,
                         renderer_spp=(None if args.renderer_spp is None
                                       else args.renderer_spp.split(",")))
    from .record import record

    record(args, out=str(result.out), metrics=str(result.out / "metrics.json"),
           page=str(result.out / "index.html"), seconds=result.seconds,
           regressions=result.regressions, summary=result.summary)
    return result.exit_code
