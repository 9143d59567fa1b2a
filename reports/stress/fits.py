"""Stability of the profile fit on degenerate captures.

Captures without information (all black, all saturated, one bright pixel, a constant
image, all NaN) must be refused with an :class:`~translucent.errors.InputError` naming the
image, or fitted with every parameter reported as ``unconstrained`` or a limit; captures
that still hold a profile (NaN pixels, the incident point on the border or in a corner)
must give finite medians and intervals that cover the truth. Every fit has a small step
budget so that the sweep takes seconds, never NaN medians, never a hang.
"""

from __future__ import annotations

import time

import numpy as np
from scipy.stats import norm

from ...errors import InputError
from ...fitting.capture import Capture
from ...fitting.fit import fit_dipole
from ...fitting.synthetic import default_pixel_size, dipole_capture
from ...materials import measured_medium
from . import StressResult, count_nonfinite, stress_kernel

#: Captures with no profile to fit: refused, or every parameter unconstrained or a limit.
EMPTY_CASES = ("all black", "all saturated", "single bright pixel", "constant", "all NaN")
#: Captures that keep a profile: fitted, and the truth inside the intervals.
PROFILE_CASES = ("NaN pixels", "incident on the border", "incident in a corner")
#: Verdicts that say the data do not constrain a parameter (fitting.results).
UNINFORMED = ("unconstrained", "upper limit", "lower limit", "nuisance")
#: Steps per fit: the smallest budget run_chain takes (one convergence check). The chains
#: are not converged at this length; their intervals are indicative.
MAX_STEPS = 200
#: A fit that takes longer than this counts as a hang (a 32 x 32 fit of 200 steps takes
#: 5 to 15 s on a shared 2-core machine).
HANG_SECONDS = 120.0
#: Family-wise 5 % over the parameters judged (Sidak): a calibrated Gaussian posterior puts
#: the truth within this many 95 % half-widths of the median.
FAMILY_SIGNIFICANCE = 0.05
SIZE = 32
#: Camera-noise seeds of the captures with a profile (two, so that a verdict is not one
#: noise draw's luck).
SEEDS = (1, 2)
#: Pixels set to NaN in the "NaN pixels" captures.
NAN_FRACTION = 0.1


def _captures(material, size: int, cases, seeds) -> dict:
    """Capture name -> Capture; the captures with a profile once per noise seed."""
    pixel = default_pixel_size(material, size)
    pixels, spec = dipole_capture(material, size=size, pixel_size_mm=pixel, seed=0)
    black = np.full_like(pixels, spec.black_level)
    bright = black.copy()
    bright[size // 2, size // 2] = spec.black_level + 0.5 * (spec.saturation_level
                                                            - spec.black_level)
    images = {"all black": black,
              "all saturated": np.full_like(pixels, spec.saturation_level),
              "single bright pixel": bright,
              "constant": np.full_like(pixels, 0.5 * spec.saturation_level),
              "all NaN": np.full_like(pixels, np.nan)}
    captures = {name: Capture(spec, image) for name, image in images.items() if name in cases}
    incidents = {"NaN pixels": (size / 2.0, size / 2.0),
                 "incident on the border": (0.0, size / 2.0),
                 "incident in a corner": (0.0, 0.0)}
    for name in PROFILE_CASES:
        for seed in seeds if name in cases else ():
            pixels, spec = dipole_capture(material, size=size, pixel_size_mm=pixel, seed=seed,
                                          incident_px=incidents[name])
            if name == "NaN pixels":
                holes = np.random.default_rng(seed).random((size, size, 1)) < NAN_FRACTION
                pixels = np.where(holes, np.nan, pixels)
            captures[f"{name} (seed {seed})"] = Capture(spec, pixels)
    return captures


def _deviations(result, capture) -> dict:
    """|median - truth| in 95 % half-widths, in the sampling space (log coefficients)."""
    truth = capture.spec.synthetic
    out = {}
    for summary in result.parameters:
        name, _, channel = summary.name.partition("[")
        if name not in ("sigma_a", "sigma_s_prime"):
            continue
        value = truth[name]["RGB".index(channel[0])]
        low, median, high = np.log([summary.low95, summary.median, summary.high95])
        half = (high - median) if np.log(value) > median else (median - low)
        out[summary.name] = float(abs(np.log(value) - median) / max(half, 1e-300))
    return out


@stress_kernel("fits on degenerate captures")
def degenerate_fits(cases=EMPTY_CASES + PROFILE_CASES, size: int = SIZE,
                    max_steps: int = MAX_STEPS, material: str = "Skimmilk",
                    seeds=SEEDS) -> StressResult:
    """Fit every degenerate capture with a small step budget and judge the outcome.

    Parameters
    ----------
    cases : sequence of str
        Among :data:`EMPTY_CASES` and :data:`PROFILE_CASES`.
    size : int
        Image side, pixels.
    max_steps : int
        Step budget of each fit.
    material : str
        Measured medium of the synthetic captures (Jensen et al. 2001).
    seeds : sequence of int
        Camera-noise seeds of the captures with a profile.
    """
    captures = _captures(measured_medium(material), size, cases, seeds)
    result = StressResult(evaluations=0, against="truth, in 95 % half-widths (log space)",
                          notes="captures with a profile: the truth within the Sidak-corrected "
                                "5 % family-wise deviation of a Gaussian posterior; negative "
                                "counts empty captures fitted as constrained, errors other than "
                                "InputError and fits slower than a hang")
    deviations = {}
    for name, capture in captures.items():
        began = time.perf_counter()
        case = {"capture": name}
        result.evaluations += 1  # the outcome itself; a fit adds its quantiles
        try:
            fit = fit_dipole(capture, max_steps=max_steps, seed=0)
        except InputError as error:
            case.update(outcome="refused", message=str(error))
            if name not in EMPTY_CASES:
                result.negative += 1
        except Exception as error:  # noqa: BLE001 - any other failure is what we count
            case.update(outcome="crashed", message=f"{type(error).__name__}: {error}")
            result.negative += 1
        else:
            quantiles = np.array([[s.median, s.low68, s.high68, s.low95, s.high95]
                                  for s in fit.parameters])
            result.evaluations += quantiles.size
            count_nonfinite(quantiles, result, negative=False)
            statuses = {s.name: s.status for s in fit.parameters}
            case.update(outcome="fitted", statuses=statuses, converged=fit.converged,
                        medians={s.name: s.median for s in fit.parameters})
            if name in EMPTY_CASES and any(v not in UNINFORMED for v in statuses.values()):
                result.negative += 1
            if name not in EMPTY_CASES and np.isfinite(quantiles).all():
                case["deviation_in_half_widths"] = _deviations(fit, capture)
                deviations.update({(name, k): v for k, v in
                                   case["deviation_in_half_widths"].items()})
        case["seconds"] = time.perf_counter() - began
        if case["seconds"] > HANG_SECONDS:
            result.negative += 1
        result.details.append(case)
    if deviations:
        # the 97.5 % quantile over 1.96: the deviation a calibrated posterior stays within
        sidak = 1.0 - (1.0 - FAMILY_SIGNIFICANCE) ** (1.0 / len(deviations))
        result.bound = float(norm.ppf(1.0 - sidak / 2.0) / norm.ppf(0.975))
        worst = max(deviations, key=deviations.get)
        result.worst_relative_error = deviations[worst]
        result.worst_at = {"capture": worst[0], "parameter": worst[1]}
    else:
        result.bound = 1.0
    return result
