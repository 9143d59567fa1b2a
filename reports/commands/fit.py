"""Fit dipole, walk or SubEdit profiles to a captured slab image: ``translucent fit CAPTURE``.

Measures the radial profile of every channel, samples the posterior with emcee until it
has converged (or the step budget runs out, which is said), and writes into the output
folder, per model: ``<model>_summary.json`` (parameters with 16/84 % and 2.5/97.5 %
quantiles, tau, acceptance, masks and dropped annuli), ``<model>_material.toml`` (the
material table scene files load), ``<model>_corner.png``, ``<model>_profile.png`` (the
fitted profile over the measured one, with residuals) and ``<model>_samples.npz``.

Every fit is tested against its own data (reduced chi-square, posterior-predictive p-value
and a runs test of the residuals per channel, :mod:`translucent.fitting.goodness`). When
the tests reject the model the verdict is "model misfit": the model-conditional intervals
are marked so, and intervals from a posterior with a fractional model-discrepancy term per
channel are printed beside them (and written to the summary JSON).

Exit code 0 when every chain converged and the model fits, 1 when a chain did not converge
or the model misfits, 2 for bad input.
"""

from __future__ import annotations

from pathlib import Path


def add_arguments(parser):
    """Options of ``translucent fit``."""
    parser.add_argument("capture", help="the capture's JSON sidecar (docs/capture-format.md)")
    from ...fitting.named_models import NAMED_MODELS as named  # imports no emcee

    models = ("dipole", "walk", "subedit", *named)
    parser.add_argument("--model", choices=(*models, "both"), default="dipole",
                        metavar="MODEL",
                        help="profile model to fit: dipole (or slab multipole), walk (the "
                             "photon random walk's own profile, tabulated: semi-infinite "
                             "reflection), subedit, both (dipole and subedit), or any other "
                             "radial profile by name (semi-infinite reflection): "
                             f"{', '.join(named)} (default: dipole)")
    parser.add_argument("--out", "-o", default=None,
                        help="output folder (default: <capture>_fit beside the sidecar)")
    parser.add_argument("--r-min", type=float, default=0.0,
                        help="leave out annuli inside this radius, mm (fit the dipole only "
                             "where diffusion holds)")
    parser.add_argument("--fit-eta", action="store_true",
                        help="fit eta even when the sidecar gives it")
    parser.add_argument("--walkers", type=int, default=None,
                        help="emcee walkers (default: max(4 ndim, 32); at least 2 ndim)")
    parser.add_argument("--max-steps", type=int, default=None,
                        help="step budget per chain (default: 20000 dipole, 40000 SubEdit)")
    parser.add_argument("--segments", type=int, default=8,
                        help="SubEdit: number n of piecewise-linear segments of ln P")
    parser.add_argument("--r-s", type=float, default=None,
                        help="SubEdit: maximum scattering radius, mm (default: last used "
                             "annulus)")
    parser.add_argument("--smoothness", type=float, default=None,
                        help="SubEdit: prior std. dev. of second differences of ln P, nats")
    parser.add_argument("--seed", type=int, default=None, help="random seed")
    parser.add_argument("--no-progress", action="store_true", help="no progress bars")


def run(args) -> int:
    """Fit, write the outputs, print the summary; 1 if a chain did not converge or misfit."""
    from ...atomic import check_output_folder, claim_output
    from ...fitting.fit import fit_capture, output_names
    from ...staging import staged_outputs
    from .record import json_target, record

    capture = Path(args.capture)
    out_dir = Path(args.out) if args.out else capture.with_name(f"{capture.stem}_fit")
    check_output_folder(out_dir, "out_dir (--out)")
    models = ("dipole", "subedit") if args.model == "both" else (args.model,)
    options = {"segments": args.segments, "r_s_mm": args.r_s, "smoothness": args.smoothness,
               "r_min_mm": args.r_min}
    if args.fit_eta:
        options["fit_eta"] = True
    if args.walkers is not None:
        options["walkers"] = args.walkers
    if args.max_steps is not None:
        options["max_steps"] = args.max_steps
    # every file it will write is named before any work: one that would replace an input
    # (the capture itself, say) is refused before the chains run, not after
    for kind in models:
        for name in output_names(kind):
            claim_output(out_dir / name, "out_dir (--out)")
    # written into a staging folder beside it, moved in when every model is done: a
    # refused, failed (a full disk) or interrupted fit leaves no empty or half-filled --out,
    # and a killed one's staging folder is swept by the next write beside it
    with staged_outputs(out_dir, field="out_dir (--out)") as staging:
        results = fit_capture(capture, models=models, out_dir=staging, seed=args.seed,
                              progress=not args.no_progress, **options)
    status = 0
    for kind, result in results.items():
        profile = result.profile.summary()
        print(f"{kind}: {'converged' if result.converged else 'NOT converged'} in "
              f"{result.seconds:.1f} s, {result.log_prob_calls} log-probability calls; "
              f"incident point {profile['centre_px'][0]:.2f}, {profile['centre_px'][1]:.2f} px; "
              f"annuli used R/G/B {profile['used_annuli']}")
        for chain in result.chains:
            print(f"  {chain.message}; acceptance {chain.acceptance_fraction.mean():.2f}")
        masked = profile["masked_pixels"]
        print(f"  masked pixels R/G/B: saturated {masked['saturated']}, below black "
              f"{masked['below_black']}, NaN {masked['nan']}; dropped annuli "
              f"{profile['dropped_annuli']}")
        for summary in result.parameters:
            print("  " + summary.describe().strip())
        if result.goodness is not None:
            print(f"  goodness of fit: {result.goodness.verdict}")
            for channel in result.goodness.channels:
                print(f"    {channel.text()}")
        if result.discrepancy is not None:
            print("  with a fractional model-discrepancy term per channel (intervals that "
                  "allow for the misfit):")
            for summary in result.discrepancy:
                print("    " + summary.describe().strip())
        messages = [chain.message for chain in result.chains]  # printed above
        for note in [n for n in result.notes if n not in messages] + result.profile.notes:
            print(f"  note: {note}")
        status = max(status, 0 if result.converged and not result.misfit else 1)
    print(f"wrote {out_dir}/")
    if json_target(args) is not None:
        record(args, capture=str(capture), out=str(out_dir),
               fits={kind: result.summary() for kind, result in results.items()})
    return status
