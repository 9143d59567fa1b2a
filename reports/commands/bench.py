"""Run-time-versus-error benchmarks: ``translucent bench NAME [...]``.

Each benchmark is a module ``translucent.reports.bench.<NAME>`` with
``add_arguments(parser)``, ``run(args) -> int`` and ``QUICK_ARGUMENTS``. Times are printed
as ratios to a baseline measured in the same run, beside the absolute figures, and written
as JSON.

``--quick`` (every benchmark) runs the same code paths at tiny sizes: each option the user
left at its default takes the module's ``QUICK_ARGUMENTS`` value (a small scene, few
samples, few ladder points, one medium), and the JSON, of the same shape, says
``"quick": true``. It is a smoke run that proves the benchmark works, not a measurement.
"""

from __future__ import annotations

import importlib
import pkgutil

from .. import bench as bench_package


def _benchmarks() -> dict:
    found = {}
    for info in pkgutil.iter_modules(bench_package.__path__):
        if not info.name.startswith("_"):
            found[info.name] = importlib.import_module(f"{bench_package.__name__}.{info.name}")
    return found


def add_arguments(parser):
    """One sub-command per benchmark module."""
    sub = parser.add_subparsers(dest="benchmark", metavar="NAME", parser_class=type(parser))
    sub.required = True
    for name, module in sorted(_benchmarks().items()):
        command = sub.add_parser(name, help=(module.__doc__ or "").strip().split("\n")[0],
                                 description=module.__doc__)
        command.add_argument("--json", default=None,
                             help="write the measured figures here (default: bench_<NAME>.json)")
        command.add_argument("--quick", action="store_true",
                             help="the same code paths at tiny sizes (a smoke run, not a "
                                  "measurement; the JSON says quick)")
        module.add_arguments(command)
        quick = module.QUICK_ARGUMENTS
        command.set_defaults(bench_run=module.run, bench_quick={
            dest: (command.get_default(dest), value) for dest, value in quick.items()})


def quick_arguments(args) -> list[str]:
    """Give ``args`` the benchmark's quick values where the user left an option at its default.

    Returns the options changed, as ``dest=value`` texts.
    """
    changed = []
    for dest, (default, value) in args.bench_quick.items():
        if getattr(args, dest) == default:
            setattr(args, dest, value)
            changed.append(f"{dest}={value}")
    return changed


def run(args) -> int:
    """Check the shared options, then run the chosen benchmark."""
    from ...atomic import check_output_file
    from ..bench import quick_run

    if args.json is not None:
        check_output_file(args.json, "--json", what="a file name for the figures")
    if not args.quick:
        return args.bench_run(args)
    changed = quick_arguments(args)
    print(f"quick run of bench {args.benchmark} (tiny sizes; its figures are not "
          f"measurements): {', '.join(changed) or 'no option changed'}")
    with quick_run():
        return args.bench_run(args)
