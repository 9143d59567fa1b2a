"""Run-time-versus-error benchmarks: ``translucent bench NAME [...]``.

Each benchmark is a module ``translucent.reports.bench.<NAME>`` with
``add_arguments(parser)`` and ``run(args) -> int``. Times are printed as ratios to a
baseline measured in the same run, beside the absolute figures, and written as JSON.
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
        module.add_arguments(command)
        command.set_defaults(bench_run=module.run)


def run(args) -> int:
    """Check the shared options, then run the chosen benchmark."""
    from ...atomic import check_output_file

    if args.json is not None:
        check_output_file(args.json, "--json", what="a file name for the figures")
    return args.bench_run(args)
