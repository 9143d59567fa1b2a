"""Fitting: time to a converged dipole posterior and to a SubEdit posterior, with tau and calls.

``translucent bench fitting`` makes a dipole-forward capture of a measured medium (fixed
seed; 96 x 96 pixels, exposure unknown, the default camera), then times

* the three-channel dipole posterior (6 coefficients + exposure): MAP, Laplace start,
  emcee until 50 tau (target: at most 60 s on the suite's 2-core machine);
* the posterior with the tabulated random-walk profile (:class:`WalkModel`) of a
  walk-made capture of the same medium and camera (``--photons`` per channel), the capture
  that model is for (target: at most twice the dipole's time on its dipole-made one);
* the SubEdit posterior (``--segments`` segments, three independent channel chains):
  (target: at most 3 minutes);

and, as the baseline measured in the same run, a weighted least-squares point fit of the
same dipole model (``scipy.optimize.least_squares``): the posterior's cost is reported as
a multiple of the point fit's. Also printed: tau, steps, walkers, acceptance and the
number of log-probability calls (vectorised calls and parameter vectors).

``translucent bench fitting --bias-table --generator {walk,volpath} [--forward walk]
--out DIR`` runs the model-bias study instead
(:func:`translucent.fitting.validation.model_bias_table`): transport-solver captures of
the measured media, fitted with the dipole (or the tabulated walk), recovered against true
coefficients, with the fraction of truths inside their 95 % intervals and the fits flagged
as misfits. Each finished medium is printed and ``DIR/bias_<generator>[_walk].json`` and
``.md`` are rewritten (atomically), so an interrupted run keeps what it finished.
"""

from __future__ import annotations

import time

import numpy as np

from ...atomic import atomic_write_text, check_output_folder
from ...errors import check_count
from . import is_quick, steps_bar, write_figures

#: Targets, seconds; the walk model's posterior at most this multiple of the dipole's.
TARGET_DIPOLE_SECONDS = 60.0
TARGET_SUBEDIT_SECONDS = 180.0
TARGET_WALK_RATIO = 2.0


#: ``--quick``: one 24-pixel capture, two SubEdit segments, 200 steps a chain, a walk of 2,000
#: photons a channel; the targets are not judged.
QUICK_ARGUMENTS: dict = {"size": 24, "segments": 2, "max_steps": 200, "photons": 2e3}


def add_arguments(parser):
    """Options of ``translucent bench fitting``."""
    parser.add_argument("--material", default="skin1", help="measured medium (default skin1)")
    parser.add_argument("--size", type=int, default=96, help="capture size, pixels")
    parser.add_argument("--segments", type=int, default=8, help="SubEdit segments")
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--skip-subedit", action="store_true")
    parser.add_argument("--max-steps", type=int, default=None,
                        help="most emcee steps of each posterior (default: the fit's own, "
                             "until converged)")
    bias = parser.add_argument_group("model-bias table (instead of the timings)")
    bias.add_argument("--bias-table", action="store_true",
                      help="fit transport-solver captures of the measured media with the "
                           "dipole; write recovered against true coefficients")
    bias.add_argument("--generator", choices=("walk", "volpath"), default="walk",
                      help="photon random walk (default) or Mitsuba volpath captures")
    bias.add_argument("--materials", nargs="+", default=None,
                      help="measured media (default: all twelve)")
    bias.add_argument("--spp", type=int, default=4096, help="samples per pixel (volpath)")
    bias.add_argument("--pass-spp", type=int, default=None,
                      help="samples per pixel of one render pass (volpath; default 1024)")
    bias.add_argument("--photons", type=float, default=1e5, help="photons per channel (walk)")
    bias.add_argument("--r-min", type=float, nargs="+", default=[0.0],
                      help="fit outside these many transport lengths (one row each)")
    from ...fitting.named_models import NAMED_MODELS as named

    bias.add_argument("--forward", choices=("dipole", "walk", *named), default="dipole",
                      metavar="MODEL",
                      help="the fitted profile: the dipole (default), the tabulated walk, or "
                           f"any other radial profile ({', '.join(named)})")
    bias.add_argument("--known-exposure", action="store_true",
                      help="write the camera's exposure into each capture (the fit does not "
                           "sample it); a Christensen-Burley model is not identifiable "
                           "without it")
    bias.add_argument("--out", default=".",
                      help="folder for bias_<generator>[_<forward>].json / .md")


def _point_fit_seconds(model) -> tuple[float, np.ndarray]:
    """Baseline: weighted least squares of the same model from the same starting grid."""
    from scipy import optimize

    began = time.perf_counter()
    start = model.initial_guess()
    observations = [model.profile.observations(c) for c in range(3)]

    def residuals(theta):
        predicted = model.predictions(theta)
        return np.concatenate([(observations[c][0] - predicted[c][0]) / observations[c][1]
                               for c in model.channels])

    bounds = model.bounds
    result = optimize.least_squares(residuals, start, bounds=(bounds[:, 0], bounds[:, 1]))
    return time.perf_counter() - began, result.x


def _chain_line(chain) -> str:
    return (f"{chain.steps} steps x {chain.walkers} walkers, tau max {chain.tau.max():.1f} "
            f"(min {chain.tau.min():.1f}), acceptance {chain.acceptance_fraction.mean():.2f}, "
            f"{chain.log_prob_calls} calls / {chain.log_prob_evaluations} evaluations, "
            f"{'converged' if chain.converged else 'NOT converged'}")


def _bias_table(args) -> int:
    """Run the model-bias study, writing JSON and Markdown after every medium."""
    from ...fitting.validation import bias_table_text, model_bias_table

    out = check_output_folder(args.out, "--out")
    stem = (f"bias_{args.generator}" + ("" if args.forward == "dipole" else f"_{args.forward}")
            + ("_known_exposure" if args.known_exposure else ""))
    json_path, text_path = out / f"{stem}.json", out / f"{stem}.md"
    rows = []
    began = time.perf_counter()
    solver = (f"volpath {args.spp} spp" if args.generator == "volpath"
              else f"random walk {int(args.photons)} photons/channel")
    print(f"model bias of the {args.forward} fit: {solver}, {args.size} x {args.size}, "
          f"exposure {'known' if args.known_exposure else 'unknown'}, seed {args.seed}, "
          f"materials {', '.join(args.materials) if args.materials else 'all twelve'}",
          flush=True)

    def finished(row):
        rows.append(row)
        out.mkdir(parents=True, exist_ok=True)  # at the first row: bad input leaves nothing
        figures = {"generator": args.generator, "forward": args.forward, "size": args.size,
                   "exposure_known": bool(args.known_exposure),
                   "seed": args.seed,
                   "spp": args.spp if args.generator == "volpath" else None,
                   "photons": int(args.photons) if args.generator == "walk" else None,
                   "seconds": time.perf_counter() - began,
                   "rows": [r.to_json() for r in rows]}
        write_figures(json_path, "fitting", figures)
        atomic_write_text(text_path, bias_table_text(rows) + "\n")
        print(f"[{len(rows)}] {row.material} (r_min {row.r_min_mm:.3g} mm): "
              f"{row.seconds:.0f} s, {'converged' if row.converged else 'NOT converged'}; "
              f"sigma_a fit/true {np.round(np.divide(row.fit_sigma_a, row.true_sigma_a), 2)}"
              f", sigma_s' fit/true "
              f"{np.round(np.divide(row.fit_sigma_s_prime, row.true_sigma_s_prime), 2)}; "
              f"truth inside 95 %: {sum(row.covered)} of 6; "
              f"{'MODEL MISFIT' if row.misfit else 'fits'}", flush=True)

    with np.errstate(divide="ignore", invalid="ignore"):
        model_bias_table(args.materials, photons=int(args.photons), size=args.size,
                         seed=args.seed, r_min_transport_lengths=tuple(args.r_min),
                         generator=args.generator, spp=args.spp, pass_spp=args.pass_spp,
                         progress=True, on_row=finished, forward=args.forward,
                         exposure_known=args.known_exposure)
    print(bias_table_text(rows))
    covered = sum(sum(row.covered) for row in rows)
    print(f"truth inside its 95 % interval: {covered} of {6 * len(rows)} coefficients; "
          f"misfits flagged: {sum(row.misfit for row in rows)} of {len(rows)}")
    print(f"wrote {json_path} and {text_path} ({time.perf_counter() - began:.0f} s)")
    return 0 if all(row.converged for row in rows) else 1


def _walk_timing(args, material, spec, dipole) -> dict:
    """Time the walk model on a walk-made capture (the one it is for); print it; its figures.

    On the dipole's capture it misfits, and its chain mixes slowly in a posterior the data
    pull away from: that cost is the misfit's, not the model's. A model that misfits also
    samples a discrepancy posterior, counted apart.
    """
    from ...fitting.capture import Capture
    from ...fitting.fit import fit_dipole
    from ...fitting.random_walk import walk_capture
    from ...fitting.synthetic import Camera

    walk_pixels, walk_spec, _ = walk_capture(
        material, size=args.size, pixel_size_mm=spec.pixel_size_mm, photons=int(args.photons),
        camera=Camera(peak_signal=40000), seed=args.seed)
    walk = fit_dipole(Capture(walk_spec, walk_pixels), seed=args.seed, forward="walk",
                      progress=True, **_steps(args))
    conditional = walk.chains[0].seconds
    ratio = conditional / dipole.chains[0].seconds
    ok = walk.converged and ratio <= TARGET_WALK_RATIO
    print(f"walk-table posterior of a walk-made capture ({int(args.photons)} photons per "
          f"channel): {conditional:.1f} s = {ratio:.2f} x the dipole's "
          f"{dipole.chains[0].seconds:.1f} s on its dipole-made one (target <= "
          f"{TARGET_WALK_RATIO:g} x: {'met' if ok else 'NOT met'})" + (
              f"; it misfits, and its discrepancy posterior took "
              f"{walk.seconds - conditional:.1f} s more" if walk.misfit else ""))
    print("  " + _chain_line(walk.chains[0]))
    return {"seconds": conditional, "ratio_to_dipole": ratio, "target_met": ok,
            "misfit": bool(walk.misfit), "seconds_with_discrepancy": walk.seconds,
            **walk.chains[0].summary()}


def _steps(args) -> dict:
    """Return the fits' step budget: ``--max-steps`` where given, else each fit's own."""
    return {} if args.max_steps is None else {"max_steps": args.max_steps}


def run(args) -> int:
    """Run the three timings, print them against the targets, write the JSON.

    Exit 1 where a target is missed or a chain did not converge; a ``--quick`` run judges
    neither (its chains are cut short on purpose), and exits 0.
    """
    check_count(args.size, "--size", minimum=16)
    if args.max_steps is not None:
        check_count(args.max_steps, "--max-steps")
    if args.bias_table:
        return _bias_table(args)
    check_count(args.segments, "--segments", minimum=2)
    from ...fitting.capture import Capture
    from ...fitting.fit import fit_dipole, fit_subedit
    from ...fitting.models import DipoleModel
    from ...fitting.profile import measure_profile
    from ...fitting.synthetic import Camera, default_pixel_size, dipole_capture
    from ...materials import measured_medium

    material = measured_medium(args.material)
    bar = steps_bar("bench fitting", 3 if args.skip_subedit else 4)
    bar.set_postfix_str("capture and baseline")
    pixels, spec = dipole_capture(material, size=args.size,
                                  pixel_size_mm=default_pixel_size(material, args.size),
                                  camera=Camera(peak_signal=40000), seed=args.seed)
    capture = Capture(spec, pixels)
    profile = measure_profile(capture)
    baseline, _ = _point_fit_seconds(DipoleModel(profile, spec))
    print(f"capture: {material.name}, {args.size} x {args.size}, "
          f"{spec.pixel_size_mm:.4g} mm/px, annuli used {profile.used.sum(axis=0).tolist()}")
    print(f"baseline (least-squares point fit of the dipole): {baseline:.2f} s")
    figures = {"material": material.name, "size": args.size, "baseline_seconds": baseline}
    status = 0
    bar.update()
    bar.set_postfix_str("dipole posterior")
    dipole = fit_dipole(capture, seed=args.seed, profile=profile, progress=True,
                        **_steps(args))
    chain = dipole.chains[0]
    ok = dipole.converged and dipole.seconds <= TARGET_DIPOLE_SECONDS
    print(f"dipole posterior: {dipole.seconds:.1f} s = {dipole.seconds / baseline:.0f} x "
          f"baseline (target <= {TARGET_DIPOLE_SECONDS:.0f} s: {'met' if ok else 'NOT met'})")
    print("  " + _chain_line(chain))
    figures["dipole"] = {"seconds": dipole.seconds, "ratio_to_baseline": dipole.seconds / baseline,
                         "target_met": ok, **chain.summary()}
    status = max(status, 0 if ok else 1)
    bar.update()
    bar.set_postfix_str("walk-made capture and its walk-table posterior")
    figures["walk"] = _walk_timing(args, material, spec, dipole)
    ok = figures["walk"]["target_met"]
    status = max(status, 0 if ok else 1)
    if not args.skip_subedit:
        bar.update()
        bar.set_postfix_str("SubEdit posterior")
        subedit = fit_subedit(capture, segments=args.segments, seed=args.seed, profile=profile,
                              progress=True, **_steps(args))
        ok = subedit.converged and subedit.seconds <= TARGET_SUBEDIT_SECONDS
        print(f"SubEdit posterior ({args.segments} segments, 3 chains): {subedit.seconds:.1f} s"
              f" = {subedit.seconds / baseline:.0f} x baseline (target <= "
              f"{TARGET_SUBEDIT_SECONDS:.0f} s: {'met' if ok else 'NOT met'})")
        for c, chain in zip(subedit.model.channels, subedit.chains, strict=True):
            print(f"  {'RGB'[c]}: " + _chain_line(chain))
        figures["subedit"] = {"seconds": subedit.seconds,
                              "ratio_to_baseline": subedit.seconds / baseline, "target_met": ok,
                              "chains": [chain.summary() for chain in subedit.chains]}
        status = max(status, 0 if ok else 1)
    bar.update()
    bar.close()
    out = write_figures(args.json, "fitting", figures)
    print(f"wrote {out}")
    if is_quick():
        print("quick run: targets and convergence not judged")
        return 0
    return status
