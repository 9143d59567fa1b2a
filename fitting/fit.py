"""Fit a capture: measure its profile, sample the posterior, summarise, write the outputs.

``fit_capture("capture.json", models=("dipole", "subedit"), out_dir="capture_fit")`` is
what ``translucent fit`` runs. Each fit returns a :class:`FitResult`; :func:`write_outputs`
writes ``<kind>_summary.json``, ``<kind>_material.toml``, ``<kind>_corner.png`` (one
per channel for SubEdit),
``<kind>_profile.png`` and ``<kind>_samples.npz`` into the output folder.
"""

from __future__ import annotations

import functools
import json
import os
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import emcee
import numpy as np

from ..atomic import atomic_path, atomic_write_text, make_output_folder
from ..errors import InputError, check_count
from ..materials.subedit import save_subedit
from .capture import Capture, read_capture
from .goodness import DiscrepancyModel, GoodnessOfFit, best_sample, goodness_of_fit
from .models import DipoleModel, SubEditModel, WalkModel
from .named_models import NAMED_MODELS, NamedProfileModel
from .profile import RadialProfile, measure_profile
from .results import ParameterSummary, summaries_to_json, summarise_posterior, write_material
from .sampler import ChainResult, run_chain

__all__ = ["FitResult", "default_moves", "fit_capture", "fit_dipole", "fit_subedit",
           "output_folder", "output_names", "write_outputs", "MODELS"]

#: Fits ``translucent fit --model`` offers: the dipole (and slab multipole), the walk's
#: table, SubEdit, and every other radial profile by name (:mod:`.named_models`).
MODELS = ("dipole", "walk", "subedit", *NAMED_MODELS)
#: The coefficient models (sigma_a, sigma_s' per channel) and their forward profiles.
COEFFICIENT_MODELS = {"dipole": DipoleModel, "walk": WalkModel,
                      **{name: functools.partial(NamedProfileModel, name=name)
                         for name in NAMED_MODELS}}
#: Step budgets: a three-channel dipole converges in ~2000 steps, a SubEdit channel with
#: 9 knots in ~4000; the budgets leave room for hard captures.
DIPOLE_MAX_STEPS = 20000
SUBEDIT_MAX_STEPS = 40000
#: Keyword options of :func:`fit_capture`.
FIT_OPTIONS = ("r_min_mm", "fit_eta", "walkers", "max_steps", "segments", "r_s_mm",
               "smoothness")


def default_moves():
    """Differential-evolution moves (80 %) with snooker updates (20 %).

    On these near-Gaussian posteriors they reach the same precision in about half the
    log-probability calls of the stretch move (measured: tau 28 against 73 steps for a
    three-channel dipole with unknown exposure). When the posterior has several modes,
    :func:`~translucent.fitting.sampler.run_chain` adds its mode-jump move to these.
    """
    return [(emcee.moves.DEMove(), 0.8), (emcee.moves.DESnookerMove(), 0.2)]


@dataclass
class FitResult:
    """A fitted posterior and what it rests on.

    Attributes
    ----------
    kind : str
        ``"dipole"``, ``"walk"`` or ``"subedit"``.
    capture : Capture
    profile : RadialProfile
    model : ProfileModel
        For SubEdit, the three-channel model used for predictions and plots.
    chains : list of ChainResult
        One (dipole) or one per channel (SubEdit).
    samples : ndarray, shape (m, ndim)
        Flat posterior samples in the model's sampling space.
    parameters : list of ParameterSummary
    material : dict
        The material table: posterior medians (of the heaviest mode when a parameter is
        ``multimodal``). Where the model misfits, the notes and the file's diagnostics say
        so: the medians of a model the data reject.
    goodness : GoodnessOfFit or None
        The goodness-of-fit tests of the posterior (:mod:`translucent.fitting.goodness`).
    discrepancy : list of ParameterSummary or None
        Where the model misfits: the summaries of the posterior with a fractional
        model-discrepancy term per channel (intervals that allow for the misfit).
    discrepancy_goodness : GoodnessOfFit or None
        The same tests of that posterior.
    """

    kind: str
    capture: Capture
    profile: RadialProfile
    model: Any
    chains: list[ChainResult]
    samples: np.ndarray
    parameters: list[ParameterSummary]
    material: dict
    notes: list[str] = field(default_factory=list)
    goodness: GoodnessOfFit | None = None
    discrepancy: list[ParameterSummary] | None = None
    discrepancy_goodness: GoodnessOfFit | None = None
    discrepancy_chains: list[ChainResult] = field(default_factory=list)

    @property
    def converged(self) -> bool:
        """Every chain converged."""
        return all(chain.converged for chain in self.chains + self.discrepancy_chains)

    @property
    def misfit(self) -> bool:
        """The goodness-of-fit tests reject the model."""
        return self.goodness is not None and self.goodness.misfit

    @property
    def seconds(self) -> float:
        """Wall-clock seconds of all chains (MAP included)."""
        return float(sum(chain.seconds for chain in self.chains + self.discrepancy_chains))

    @property
    def log_prob_calls(self) -> int:
        """Vectorised log-probability calls of all chains."""
        return int(sum(chain.log_prob_calls
                       for chain in self.chains + self.discrepancy_chains))

    def parameter(self, name: str) -> ParameterSummary:
        """Return the summary of the parameter called ``name``."""
        for summary in self.parameters:
            if summary.name == name:
                return summary
        raise InputError(f"no such parameter; valid: {', '.join(self.model.names)}",
                         field="parameter", value=name)

    def truths(self) -> np.ndarray | None:
        """Return the true values in the sampling space (synthetic dipole captures), or None."""
        truth = self.capture.spec.synthetic
        if self.kind not in COEFFICIENT_MODELS:
            return None
        # the sidecar's "synthetic" object may hold anything: use it only when it is whole
        try:
            with np.errstate(divide="ignore", invalid="ignore"):
                values = [np.log(np.asarray(truth[key], dtype=np.float64).reshape(3))
                          for key in ("sigma_a", "sigma_s_prime")]
                if self.model.fit_eta:
                    values.append([float(truth["eta"])])
                if self.model.fit_exposure:
                    values.append([np.log(float(truth["exposure"]))])
        except (KeyError, TypeError, ValueError):
            return None
        return np.concatenate(values)

    def summary(self) -> dict:
        """Everything a person or a script needs, JSON-able."""
        return {"kind": self.kind,
                "capture": None if self.capture.path is None else str(self.capture.path),
                "converged": self.converged,
                "verdict": self.goodness.verdict if self.goodness is not None else None,
                "goodness_of_fit": (self.goodness.summary() if self.goodness is not None
                                    else None),
                "chains": [chain.summary() for chain in self.chains],
                "parameters": summaries_to_json(self.parameters),
                "parameters_with_discrepancy": (summaries_to_json(self.discrepancy)
                                                if self.discrepancy is not None else None),
                "discrepancy_goodness_of_fit": (self.discrepancy_goodness.summary()
                                                if self.discrepancy_goodness is not None
                                                else None),
                "discrepancy_chains": [chain.summary() for chain in self.discrepancy_chains],
                "material": self.material, "profile": self.profile.summary(),
                "annulus_means_fitted": self.model.residual_degrees(),
                "notes": self.notes + self.profile.notes}


def _mode_notes(model, chain, summaries) -> list[str]:
    """One sentence per posterior with several modes: where they are and how heavy."""
    fractions = chain.mode_fractions()
    split = [s.name for s in summaries if s.status == "multimodal"]
    if len(chain.modes) < 2:
        return []
    parts = []
    for mode, fraction in zip(chain.modes, fractions, strict=True):
        values = ", ".join(f"{info.name} {float(info.to_physical(value)):.3g}"
                           for info, value in zip(model.parameters, mode.theta, strict=True)
                           if info.kind != "exposure")
        parts.append(f"{fraction:.0%} of the samples (Laplace weight {mode.weight:.0%}) "
                     f"near {values}")
    verdict = (f"the data cannot decide between them for {', '.join(split)}" if split
               else "no parameter tells apart two modes that each hold 5 % or more of the "
                    "samples, so the intervals are those of one mode")
    return [f"the posterior has {len(chain.modes)} modes: " + "; ".join(parts) + f"; {verdict}"]


def _as_capture(capture) -> Capture:
    return capture if isinstance(capture, Capture) else read_capture(capture)


def _checked_seed(seed):
    """``seed`` as given, or :class:`InputError` unless None or an integer >= 0 (NumPy's rule)."""
    return None if seed is None else check_count(seed, "seed", minimum=0)


def _medians(summaries):
    return {s.name: s.median for s in summaries}


def _misfit_statuses(summaries) -> list[ParameterSummary]:
    """Model-conditional summaries of a misfit: no interval is claimed to constrain."""
    return [s if s.status == "nuisance" else replace(s, status="model misfit")
            for s in summaries]


def _misfit_notes(goodness: GoodnessOfFit) -> list[str]:
    bad = [channel for channel in goodness.channels if channel.misfit]
    return [f"model misfit (channel {channel.text()}); the model-conditional intervals and "
            "the material file's medians assume a model the data reject; the intervals with "
            "the model-discrepancy term are wider, but a misfit of this shape can bias them "
            "too" for channel in bad]


def _discrepancy_chain(model, samples, *, walkers, max_steps, seed, progress, description):
    """Sample ``model`` with a model-discrepancy term, started at its best sample."""
    extended = DiscrepancyModel(model, start=best_sample(model, samples))
    if walkers is not None:  # the added coordinates need walkers of their own
        walkers = max(int(walkers), 2 * extended.ndim)
    chain = run_chain(extended, walkers=walkers, max_steps=max_steps, seed=seed,
                      progress=progress, moves=default_moves(), description=description)
    return extended, chain


def fit_dipole(capture, *, fit_eta: bool | None = None, walkers: int | None = None,
               max_steps: int = DIPOLE_MAX_STEPS, seed: int | None = None,
               progress: bool = False, profile: RadialProfile | None = None,
               forward: str = "dipole") -> FitResult:
    """Posterior over the coefficients (sigma_a, sigma_s' per channel) of a capture.

    Parameters
    ----------
    capture : Capture or path
        The capture or its sidecar.
    fit_eta : bool, optional
        Fit eta even when the sidecar gives it.
    walkers : int, optional
    max_steps : int
        Step budget (the run stops earlier once converged).
    seed : int, optional
    progress : bool
        Progress bar on stderr.
    profile : RadialProfile, optional
        A profile already measured from this capture.
    forward : str
        The forward profile: ``"dipole"`` (or slab multipole), :class:`DipoleModel`;
        ``"walk"``, the tabulated photon random walk, :class:`WalkModel`; or any other
        radial profile by name (:data:`~.named_models.NAMED_MODELS`),
        :class:`~.named_models.NamedProfileModel`.

    Returns
    -------
    FitResult
    """
    if forward not in COEFFICIENT_MODELS:
        raise InputError(f"must be one of {', '.join(COEFFICIENT_MODELS)}", field="model",
                         value=forward)
    seed = _checked_seed(seed)
    capture = _as_capture(capture)
    profile = measure_profile(capture) if profile is None else profile
    model = COEFFICIENT_MODELS[forward](profile, capture.spec, fit_eta=fit_eta)
    chain = run_chain(model, walkers=walkers, max_steps=max_steps, seed=seed, progress=progress,
                      moves=default_moves(), description=f"{forward} posterior")
    summaries = summarise_posterior(model, chain.samples, chain.sample_modes)
    notes = [] if chain.converged else [chain.message]
    notes += _mode_notes(model, chain, summaries)
    notes += [f"channel {'RGB'[c]} has no usable annulus: its parameters are the prior's"
              for c in range(3) if c not in model.channels]
    if forward in NAMED_MODELS:
        notes.append(f"the coefficients of profile {forward!r}: a renderer of another profile "
                     f"(the dipole material file's own) gives another image; render with "
                     f"--profile {forward}")
    values = _medians(summaries)
    if any(s.status == "multimodal" for s in summaries):
        # a median between two modes explains the profile worse than either mode
        heaviest = int(np.argmax(chain.mode_fractions()))
        in_mode = chain.samples[chain.sample_modes == heaviest]
        values = _medians(summarise_posterior(model, in_mode))
        notes.append(f"the material file holds the medians of the heaviest mode "
                     f"({chain.mode_fractions()[heaviest]:.0%} of the samples), not of the "
                     "whole posterior")
    goodness = goodness_of_fit(model, chain.samples, seed=0 if seed is None else seed)
    result = FitResult(forward, capture, profile, model, [chain], chain.samples, summaries,
                       model.material(values), notes, goodness)
    if goodness.misfit:
        extended, wide = _discrepancy_chain(
            model, chain.samples, walkers=walkers, max_steps=max_steps, seed=seed,
            progress=progress, description=f"{forward} posterior with model discrepancy")
        result.discrepancy = summarise_posterior(extended, wide.samples)
        result.discrepancy_goodness = goodness_of_fit(extended, wide.samples)
        result.discrepancy_chains = [wide]
        result.parameters = _misfit_statuses(summaries)
        result.notes += _misfit_notes(goodness)
        if not wide.converged:
            result.notes.append(wide.message)
    return result


def fit_subedit(capture, *, segments: int = 8, r_s_mm: float | None = None,
                smoothness: float | None = None, walkers: int | None = None,
                max_steps: int = SUBEDIT_MAX_STEPS, seed: int | None = None,
                progress: bool = False, profile: RadialProfile | None = None) -> FitResult:
    """Posterior over SubEdit knot values, one independent chain per channel.

    The channels share no parameter (the exposure is absorbed into P), so their posteriors
    factor and each is sampled on its own (fewer dimensions: shorter autocorrelation).

    Parameters
    ----------
    capture : Capture or path
    segments : int
        n, the number of piecewise-linear segments of ln P.
    r_s_mm : float, optional
        Maximum scattering radius (default: the last used annulus).
    smoothness : float, optional
        Prior standard deviation of second differences of ln P, nats.
    walkers, max_steps, seed, progress, profile
        As :func:`fit_dipole`.

    Returns
    -------
    FitResult
    """
    seed = _checked_seed(seed)
    capture = _as_capture(capture)
    profile = measure_profile(capture) if profile is None else profile
    options = {"segments": segments, "r_s_mm": r_s_mm}
    if smoothness is not None:
        options["smoothness"] = smoothness
    model = SubEditModel(profile, capture.spec, **options)
    options["r_s_mm"] = model.r_s_mm
    chains, parts, channel_models = [], [], []
    rng = np.random.default_rng(seed)
    for c in model.channels:
        channel_model = SubEditModel(profile, capture.spec, channels=(c,), **options)
        chain = run_chain(channel_model, walkers=walkers, max_steps=max_steps,
                          seed=int(rng.integers(2**31)), progress=progress,
                          moves=default_moves(), description=f"SubEdit {'RGB'[c]}")
        chains.append(chain)
        parts.append(chain.samples)
        channel_models.append(channel_model)
    samples = _stack_channels(parts, rng)
    summaries = summarise_posterior(model, samples)
    notes = [chain.message for chain in chains if not chain.converged]
    goodness = goodness_of_fit(model, samples, seed=0 if seed is None else seed)
    result = FitResult("subedit", capture, profile, model, chains, samples, summaries,
                       model.material(_medians(summaries)), notes, goodness)
    if goodness.misfit:
        wide_parts, ln_f = [], []
        for c, channel_model, part in zip(model.channels, channel_models, parts, strict=True):
            _, wide = _discrepancy_chain(
                channel_model, part, walkers=walkers, max_steps=max_steps,
                seed=int(rng.integers(2**31)), progress=progress,
                description=f"SubEdit {'RGB'[c]} with model discrepancy")
            result.discrepancy_chains.append(wide)
            wide_parts.append(wide.samples)
        stacked = _stack_channels(wide_parts, rng)
        # per channel [knots, ln f] -> every channel's knots, then every ln f
        per_channel = model.segments + 1
        blocks = [stacked[:, i * (per_channel + 1): (i + 1) * (per_channel + 1)]
                  for i in range(len(model.channels))]
        knots = np.hstack([block[:, :per_channel] for block in blocks])
        ln_f = np.hstack([block[:, per_channel:] for block in blocks])
        extended = DiscrepancyModel(model)
        wide_samples = np.hstack([knots, ln_f])
        result.discrepancy = summarise_posterior(extended, wide_samples)
        result.discrepancy_goodness = goodness_of_fit(extended, wide_samples)
        result.parameters = _misfit_statuses(summaries)
        result.notes += _misfit_notes(goodness)
        result.notes += [chain.message for chain in result.discrepancy_chains
                         if not chain.converged]
    return result


def _stack_channels(parts, rng) -> np.ndarray:
    """Independent per-channel chains side by side, each shuffled, cut to the shortest."""
    length = min(part.shape[0] for part in parts)
    return np.hstack([part[rng.permutation(part.shape[0])[:length]] for part in parts])


def material_is_absolute(result: FitResult) -> bool:
    """Tell whether the fitted profile is in mm^-2 (the capture's exposure was known)."""
    return result.capture.spec.exposure is not None


def output_folder(out_dir) -> Path:
    """Create the output folder ``out_dir`` (and its parents) and check it can be written.

    Raises
    ------
    InputError
        When it is a file, cannot be created or is not writable.
    """
    out_dir = make_output_folder(out_dir, field="out_dir", value=str(out_dir),
                                 what="the output folder")
    if not os.access(out_dir, os.W_OK | os.X_OK):
        raise InputError("the output folder is not writable", field="out_dir",
                         value=str(out_dir))
    return out_dir


def output_names(kind: str) -> list[str]:
    """Return the names of the files :func:`write_outputs` writes for a fit of ``kind``.

    Examples
    --------
    >>> output_names("dipole")[:2]
    ['dipole_summary.json', 'dipole_material.toml']
    """
    names = [f"{kind}_summary.json", f"{kind}_material.toml", f"{kind}_profile.png",
             f"{kind}_samples.npz"]
    if kind == "subedit":
        return names + [f"{kind}_profile.npz"] + [f"{kind}_corner_{c}.png" for c in "RGB"]
    return names + [f"{kind}_corner.png"]


def write_outputs(result: FitResult, out_dir) -> dict[str, Path]:
    """Write the summary, material file, corner plot, profile plot and samples of a fit.

    Returns
    -------
    dict
        ``what -> path`` of the files written.
    """
    from .plots import corner_plot, profile_plot

    out_dir = output_folder(out_dir)
    kind = result.kind
    paths = {"summary": out_dir / f"{kind}_summary.json",
             "material": out_dir / f"{kind}_material.toml",
             "corner": out_dir / f"{kind}_corner.png",
             "profile": out_dir / f"{kind}_profile.png",
             "samples": out_dir / f"{kind}_samples.npz"}
    atomic_write_text(paths["summary"], json.dumps(result.summary(), indent=2) + "\n")
    source = "" if result.capture.path is None else result.capture.path.name
    messages = [chain.message for chain in result.chains]
    # the notes say what the values are when they are not plain medians (heaviest mode,
    # a channel left to its prior)
    diagnostics = "; ".join(messages + [n for n in result.notes if n not in messages])
    material = result.material
    if result.kind == "subedit":  # the texture file the scene files' "subedit" type loads
        paths["texture"] = out_dir / f"{kind}_profile.npz"
        save_subedit(paths["texture"], result.model.texture(_medians(result.parameters)))
        # relative to the material file, from whose folder the factory reads it
        material = {"type": "subedit", "file": paths["texture"].name}
        if not material_is_absolute(result):
            diagnostics += ("; the exposure was unknown: P is relative (scale it before "
                            "rendering)")
    write_material(paths["material"], material, result.parameters, source=source,
                   diagnostics=diagnostics)
    title = f"{kind} fit of {source or 'capture'}" + ("" if result.converged
                                                      else " (NOT converged)")
    if result.misfit:
        bad = "".join(channel.channel for channel in result.goodness.channels
                      if channel.misfit)
        title += f" - MODEL MISFIT ({bad})"
    if result.kind == "subedit":  # one corner per channel: the channels are independent
        del paths["corner"]
        per_channel = result.model.segments + 1
        for i, c in enumerate(result.model.channels):
            paths[f"corner_{'RGB'[c]}"] = out_dir / f"{kind}_corner_{'RGB'[c]}.png"
            block = slice(i * per_channel, (i + 1) * per_channel)
            corner_plot(paths[f"corner_{'RGB'[c]}"], result.model, result.samples,
                        columns=block, title=f"{title}, channel {'RGB'[c]}")
    else:
        corner_plot(paths["corner"], result.model, result.samples, truths=result.truths(),
                    title=title)
    profile_plot(paths["profile"], result.model, result.samples, title=title)
    with atomic_path(paths["samples"]) as tmp, open(tmp, "wb") as handle:
        np.savez_compressed(handle, samples=result.samples, names=np.array(result.model.names))
    return paths


def fit_capture(path, *, models=("dipole",), out_dir=None, seed: int | None = None,
                progress: bool = False, **options) -> dict[str, FitResult]:
    """Read a capture, fit each model in ``models`` and write the outputs to ``out_dir``.

    Parameters
    ----------
    path : str or Path
        The capture sidecar.
    models : sequence of str
        Among :data:`MODELS`.
    out_dir : path, optional
        Where to write (default: nothing is written); created, and checked to be
        writable, before any chain runs.
    seed : int, optional
    progress : bool
    **options
        ``r_min_mm`` (profile); ``fit_eta``, ``walkers``, ``max_steps`` (dipole);
        ``segments``, ``r_s_mm``, ``smoothness`` (SubEdit); any other key is an
        :class:`InputError`.

    Returns
    -------
    dict
        ``kind -> FitResult``.
    """
    unknown = [m for m in models if m not in MODELS]
    if unknown:
        raise InputError(f"unknown model; valid: {', '.join(MODELS)}", field="model",
                         value=unknown[0])
    unknown = [key for key in options if key not in FIT_OPTIONS]
    if unknown:
        raise InputError(f"unknown option; valid: {', '.join(FIT_OPTIONS)}", field=unknown[0],
                         value=options[unknown[0]])
    seed = _checked_seed(seed)
    from tqdm.auto import tqdm

    # the steps around the chains (reading, checks, goodness of fit, plots) take seconds
    bar = tqdm(total=1 + 2 * len(models), desc="fit", unit="step", leave=False,
               delay=1.0, disable=None if progress else True)
    try:
        bar.set_postfix_str("reading the capture")
        capture = read_capture(path)
        profile = measure_profile(capture, r_min_mm=options.pop("r_min_mm", 0.0) or 0.0)
        if "subedit" in models:  # its options checked before any fit writes anything
            SubEditModel(profile, capture.spec,
                         **{k: options[k] for k in ("segments", "r_s_mm", "smoothness")
                            if options.get(k) is not None})
        for kind in models:  # a capture a table does not cover is refused before writing
            if kind not in ("dipole", "subedit"):
                COEFFICIENT_MODELS[kind](profile, capture.spec, fit_eta=options.get("fit_eta"))
        if out_dir is not None:  # before the chains run, not after; not for a refused capture
            out_dir = output_folder(out_dir)
        results = {}
        bar.update()
        for kind in models:
            bar.set_postfix_str(f"{kind} posterior")
            if kind in COEFFICIENT_MODELS:
                keys = ("fit_eta", "walkers", "max_steps")
                results[kind] = fit_dipole(capture, seed=seed, progress=progress, profile=profile,
                                           forward=kind,
                                           **{k: options[k] for k in keys if k in options})
            else:
                keys = ("segments", "r_s_mm", "smoothness", "walkers", "max_steps")
                results[kind] = fit_subedit(capture, seed=seed, progress=progress, profile=profile,
                                            **{k: options[k] for k in keys if k in options})
            bar.update()
            bar.set_postfix_str(f"{kind} outputs")
            if out_dir is not None:
                write_outputs(results[kind], out_dir)
            bar.update()
    finally:
        bar.close()
    return results
