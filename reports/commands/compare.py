"""Compare a test image with a reference: ``translucent compare REF.exr TEST.exr [...]``.

Prints every metric (relative MSE with the reference's noise discounted, RMSE, PSNR, SSIM,
HDR-FLIP, LDR-FLIP, CIEDE2000) and writes the FLIP, relative-error, CIEDE2000 and SSIM
error maps (EXR and PNG) next to the test image, or into ``--maps DIR``. With a threshold
(``--metric flip --max 0.05``, or ``--min`` for psnr and ssim) it exits 0 when the
metric is within it and 1 when not; 2 on bad input (a missing or corrupt EXR, no R, G, B
channels, NaN/Inf pixels, images of different sizes), leaving no output behind.

Where the reference carries its variance, each metric is printed beside its noise floor
(the value the reference's own noise alone gives, :func:`~translucent.reports.metrics.
noise_floor`) and a verdict: "resolved" when the value clears the floor by
:data:`~translucent.reports.metrics.NOISE_MARGIN` in error form, else "within reference
noise". A reference whose median relative standard error exceeds
:data:`~translucent.noise.NOISE_WARNING_RSE` is warned about.
"""

from __future__ import annotations

import math
import sys
from pathlib import Path

from ...errors import InputError

#: The metric a bare ``--max`` applies to.
DEFAULT_METRIC = "hdr_flip"


def add_arguments(parser):
    """Add the reference, the test, the metric and its threshold, where the maps go."""
    from ..metrics.registry import canonical_metric
    from ..metrics.table import METRICS

    def canonical_or_given(name):
        return canonical_metric(name) or str(name).lower()

    parser.add_argument("reference", help="reference OpenEXR (its variance channels, where "
                        "present, are discounted from the relative MSE)")
    parser.add_argument("test", help="test OpenEXR")
    parser.add_argument("--metric", default=None, type=canonical_or_given,
                        choices=list(METRICS), metavar="METRIC",
                        help=f"the metric a threshold applies to: {', '.join(METRICS)} "
                             f"(default {DEFAULT_METRIC}; earlier spellings such as relmse "
                             "and hdr-flip are read too)")
    bound = parser.add_mutually_exclusive_group()
    bound.add_argument("--max", type=float, default=None, dest="maximum",
                       help="fail (exit 1) when the metric is above this (error metrics)")
    bound.add_argument("--min", type=float, default=None, dest="minimum",
                       help="fail (exit 1) when the metric is below this (psnr, ssim)")
    maps = parser.add_mutually_exclusive_group()
    maps.add_argument("--maps", default=None, metavar="DIR",
                      help="folder for the error maps (default: beside the test image)")
    maps.add_argument("--no-maps", action="store_true", help="write no error maps")


def _threshold(args):
    """Return the chosen metric and bound, checked against the metric's direction."""
    from ..metrics.table import metric

    threshold = args.maximum if args.maximum is not None else args.minimum
    definition = metric(args.metric or DEFAULT_METRIC)
    if threshold is None:
        return definition, None
    if not math.isfinite(threshold):
        raise InputError("must be a finite number", field="--max/--min", value=threshold)
    if definition.lower_is_better and args.minimum is not None:
        raise InputError(f"{definition.name} is an error (lower is better): give --max",
                         field="--min", value=args.minimum)
    if not definition.lower_is_better and args.maximum is not None:
        raise InputError(f"{definition.name} is a similarity (higher is better): give --min",
                         field="--max", value=args.maximum)
    return definition, threshold


def _table(rows) -> list[str]:
    """Return the printed table of :func:`~translucent.reports.metrics.table.metric_rows`."""
    lines = [f"{'metric':<10} {'value':>12}  {'noise floor':>12}  {'verdict':<22}  about"]
    for row in rows:
        mark = ""
        if "threshold" in row:
            passed = "ok" if row["within_threshold"] else "FAIL"
            mark = f"  {'<=' if row['lower_is_better'] else '>='} {row['threshold']:g}  {passed}"
        noise = row["noise_floor"]
        noise_text = f"{noise:>12.4g}" if noise is not None else f"{'-':>12}"
        verdict = row["verdict"] or "no floor (no variance)"
        lines.append(f"{row['metric']:<10} {row['value']:>12.6g}  {noise_text}  "
                     f"{verdict:<22}  {row['about']}{mark}")
    return lines


def run(args) -> int:
    """Read both images, compute the metrics, write the maps, print the table."""
    from ...atomic import (
        check_input_file,
        check_output_folder,
        claim_output,
        note_input,
        output_folder,
    )
    from ...image import read_exr
    from ...noise import reference_noise_warning
    from ..metrics.compute import NOISE_MARGIN, evaluate, noise_floor
    from ..metrics.maps import error_map_paths, write_error_maps
    from ..metrics.table import metric_rows
    from .record import record

    definition, threshold = _threshold(args)
    for field in ("reference", "test"):  # named by their argument; a FIFO is never opened
        check_input_file(getattr(args, field), field, what="file")
        note_input(getattr(args, field), field)
    if args.maps and not args.no_maps:
        check_output_folder(args.maps, "--maps")  # before the metrics are computed
    test_path = Path(args.test)
    folder = Path(args.maps) if args.maps else test_path.parent
    prefix = f"{test_path.stem}_"
    if not args.no_maps:  # a map's name may be an input's (compare A_flip.exr A.exr)
        for path in error_map_paths(folder, prefix):
            claim_output(path, "--maps" if args.maps else "error map",
                         hint="give --maps DIR or --no-maps")
    reference = read_exr(args.reference)
    test = read_exr(args.test)
    comparison = evaluate(reference, test)
    floor = noise_floor(reference)
    metrics = comparison.metrics
    files = {}
    if not args.no_maps:
        # a failure (a full disk) removes the maps written and a --maps folder made for them
        with output_folder(folder, field="--maps" if args.maps else "error map",
                           value=str(folder)):
            files = write_error_maps(reference, test, folder, prefix=prefix,
                                     comparison=comparison)
    noise = ("reference variance discounted" if metrics.noise_discounted
             else "reference has no variance: nothing discounted")
    print(f"{args.test} against {args.reference} ({test.shape[1]} x {test.shape[0]}; "
          f"{noise}; display white {metrics.display_white:.4g})")
    rows = metric_rows(metrics, floor, definition=definition, threshold=threshold)
    for line in _table(rows):
        print(line)
    if floor is not None:
        print("noise floor: each metric of the reference against itself perturbed by its own "
              "noise; 'within reference noise': the value does not clear the floor by a "
              f"factor of {NOISE_MARGIN:g} (in error form)")
    warning = reference_noise_warning(reference.rgb, reference.variance)
    if warning:
        print(f"warning: {warning}", file=sys.stderr)
    if files:
        print(f"error maps: {', '.join(str(f.png) for f in files.values())} (and .exr)")
    record(args, reference=args.reference, test=args.test,
           width=test.shape[1], height=test.shape[0],
           noise_discounted=metrics.noise_discounted, display_white=metrics.display_white,
           metrics=rows, reference_warning=warning or None,
           maps={name: {"png": str(f.png), "exr": str(f.exr)} for name, f in files.items()})
    if threshold is None:
        return 0
    return 0 if definition.within(getattr(metrics, definition.field), threshold) else 1
