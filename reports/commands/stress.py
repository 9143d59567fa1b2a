"""Numerical stability sweeps of every kernel: NaN/Inf counts and worst relative errors.

Prints one line per kernel, writes a JSON (``--json``) and exits 1 when any kernel fails
its bound.
"""

from __future__ import annotations

import json

from ...atomic import atomic_write_text, check_output_file


def add_arguments(parser):
    """``--only NAME`` (repeatable), ``--json FILE``."""
    parser.add_argument("--only", action="append", default=None, metavar="NAME",
                        help="run only kernels whose name contains NAME")
    parser.add_argument("--json", default="stress.json", help="where to write the results")


def run(args) -> int:
    """Run the sweeps and print the table."""
    from ...errors import InputError
    from ...progress import progress_bar
    from ..stress import all_kernels

    check_output_file(args.json, "--json", what="a file name for the results")
    kernels = all_kernels()
    if args.only:
        kernels = {n: k for n, k in kernels.items() if any(o in n for o in args.only)}
        if not kernels:
            raise InputError(f"no kernel matches; kernels: {', '.join(all_kernels())}",
                             field="--only", value=args.only)
    results = {}
    for name, kernel in progress_bar(kernels.items(), description="stress",
                                     terminal_only=False):
        results[name] = kernel()
    width = max(len(n) for n in results)
    print(f"{'kernel':<{width}}  {'evals':>9} {'NaN':>5} {'Inf':>5} {'neg':>5} "
          f"{'worst rel err':>13} {'bound':>9}  verdict")
    for name, result in results.items():
        print(f"{name:<{width}}  {result.evaluations:>9} {result.nan:>5} {result.inf:>5} "
              f"{result.negative:>5} {result.worst_relative_error:>13.3e} {result.bound:>9.1e}  "
              f"{'ok' if result.passed else 'FAIL'}")
    atomic_write_text(args.json, json.dumps({n: r.as_dict() for n, r in results.items()},
                                            indent=2, default=float))
    print(f"wrote {args.json}")
    return 0 if all(r.passed for r in results.values()) else 1
