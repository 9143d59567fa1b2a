r"""MAP point, Laplace start and an emcee run that stops when it has converged.

The recipe of the emcee documentation (Foreman-Mackey et al.), as the suite applies it:

* at least ``2 ndim`` walkers, started from the Laplace approximation about the
  maximum-a-posteriori point (found with ``scipy.optimize``), so that they begin close to
  the typical set;
* the integrated autocorrelation time :math:`\tau` is estimated every
  ``check_every`` steps; the chain has converged when it is longer than
  :data:`CONVERGENCE_TAUS` times every :math:`\tau` and :math:`\tau` changed by less than
  :data:`TAU_STABILITY` since the last check;
* otherwise the run stops at the step budget and says so, and by how much it fell short;
* burn-in :math:`2\max\tau`, thinning :math:`\max(1, \lfloor\min\tau/2\rfloor)`.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import emcee
import numpy as np
from scipy import optimize

from ..errors import InputError

__all__ = ["ChainResult", "find_map", "laplace_covariance", "run_chain"]

#: The chain must be longer than this many autocorrelation times (emcee documentation).
CONVERGENCE_TAUS = 50
#: ... and tau must have moved by less than this fraction between two checks.
TAU_STABILITY = 0.05
#: Burn-in and thinning in units of tau (emcee documentation: ~2 max tau, ~min tau / 2).
BURN_IN_TAUS = 2.0
THIN_TAUS = 0.5
#: Relative step of the finite differences for gradients and the Hessian, as a fraction of
#: the posterior's standard deviation once it is known (first pass: absolute 1e-3).
HESSIAN_STEP = 0.2
FIRST_PASS_STEP = 1e-3
#: Where the Hessian says nothing (a flat or concave direction), the Laplace start spreads
#: walkers over this fraction of the prior width.
FLAT_DIRECTION_FRACTION = 0.05


def _gradient(log_probability, theta, step):
    """Central-difference gradient of ``log_probability`` at ``theta``, one vectorised call."""
    ndim = theta.size
    points = np.repeat(theta[None, :], 2 * ndim, axis=0)
    points[np.arange(ndim), np.arange(ndim)] += step
    points[ndim + np.arange(ndim), np.arange(ndim)] -= step
    values = log_probability(points)
    return (values[:ndim] - values[ndim:]) / (2.0 * step)


def find_map(model, start=None, *, max_iterations: int = 500) -> tuple[np.ndarray, float]:
    """Maximum-a-posteriori point with L-BFGS-B inside the prior box.

    The gradient is a central difference evaluated in one vectorised call of the model.
    Without ``start``, the search runs from every point of ``model.initial_guesses()``
    (when the model offers several) and keeps the best.

    Parameters
    ----------
    model : ProfileModel
    start : ndarray, optional
        Starting point (default: ``model.initial_guesses()`` or ``model.initial_guess()``).
    max_iterations : int

    Returns
    -------
    (ndarray, float)
        The MAP point (sampling space) and its log-posterior.

    Raises
    ------
    InputError
        When the log-posterior is not finite at the starting point.
    """
    if start is None and hasattr(model, "initial_guesses"):
        starts = model.initial_guesses()
    else:
        starts = [model.initial_guess() if start is None else start]
    best = None
    for point in starts:
        theta, value = _local_map(model, point, max_iterations)
        if best is None or value > best[1]:
            best = (theta, value)
    return best


def _local_map(model, start, max_iterations):
    """L-BFGS-B from one starting point (see :func:`find_map`)."""
    bounds = model.bounds
    theta0 = np.clip(np.asarray(start, dtype=np.float64), bounds[:, 0], bounds[:, 1])
    value0 = float(model.log_probability(theta0)[0])
    if not np.isfinite(value0):
        raise InputError("the log-probability is not finite at the starting point; the "
                         "profile cannot be explained by this model", field="initial point",
                         value=theta0.tolist())

    def unbounded(points):
        return model.log_probability(points, bounded=False)

    def objective(theta):
        value = float(unbounded(theta)[0])
        return -value if np.isfinite(value) else 1e300

    def gradient(theta):
        grad = _gradient(unbounded, theta, FIRST_PASS_STEP)
        return -np.where(np.isfinite(grad), grad, 0.0)

    result = optimize.minimize(objective, theta0, jac=gradient, method="L-BFGS-B",
                               bounds=[tuple(b) for b in bounds],
                               options={"maxiter": max_iterations})
    theta = np.clip(result.x, bounds[:, 0], bounds[:, 1])
    value = float(model.log_probability(theta)[0])
    if not value >= value0:
        theta, value = theta0, value0
    return theta, value


def _hessian(log_probability, theta, step):
    """Central-difference Hessian, all stencil points in one vectorised call."""
    ndim = theta.size
    eye = np.diag(step)
    points = [theta]
    pairs = [(i, j) for i in range(ndim) for j in range(i + 1, ndim)]
    for i in range(ndim):
        points += [theta + eye[i], theta - eye[i]]
    for i, j in pairs:
        points += [theta + eye[i] + eye[j], theta + eye[i] - eye[j],
                   theta - eye[i] + eye[j], theta - eye[i] - eye[j]]
    values = log_probability(np.array(points))
    centre = values[0]
    hessian = np.zeros((ndim, ndim))
    for i in range(ndim):
        plus, minus = values[1 + 2 * i], values[2 + 2 * i]
        hessian[i, i] = (plus - 2.0 * centre + minus) / step[i] ** 2
    base = 1 + 2 * ndim
    for k, (i, j) in enumerate(pairs):
        pp, pm, mp, mm = values[base + 4 * k: base + 4 * k + 4]
        hessian[i, j] = hessian[j, i] = (pp - pm - mp + mm) / (4.0 * step[i] * step[j])
    return hessian


def laplace_covariance(model, theta) -> np.ndarray:
    """Covariance of the Laplace approximation at ``theta``: the inverse negative Hessian.

    Computed twice: with a small fixed step, then with steps of :data:`HESSIAN_STEP` times
    the standard deviations found. Directions where the log-posterior is flat or not
    concave get a variance of (:data:`FLAT_DIRECTION_FRACTION` x prior width)^2.

    Returns
    -------
    ndarray, shape (ndim, ndim)
        Symmetric positive definite.
    """

    def unbounded(points):
        return model.log_probability(points, bounded=False)

    widths = np.diff(model.bounds, axis=1).ravel()
    floor_var = (FLAT_DIRECTION_FRACTION * widths) ** 2
    step = np.full(theta.size, FIRST_PASS_STEP)
    covariance = np.diag(floor_var)
    for _ in range(2):
        hessian = _hessian(unbounded, theta, step)
        if not np.all(np.isfinite(hessian)):
            break
        values, vectors = np.linalg.eigh(-0.5 * (hessian + hessian.T))
        max_var = float(floor_var.max())
        variances = np.where(values > 1.0 / max_var, 1.0 / np.maximum(values, 1e-300), max_var)
        covariance = (vectors * variances) @ vectors.T
        step = np.clip(HESSIAN_STEP * np.sqrt(np.diag(covariance)), 1e-6, 0.1 * widths)
    return covariance


@dataclass
class ChainResult:
    """What an emcee run produced and how far it can be trusted.

    Attributes
    ----------
    samples : ndarray, shape (m, ndim)
        Flat chain after burn-in and thinning (sampling space).
    log_prob : ndarray, shape (m,)
    tau : ndarray, shape (ndim,)
        Integrated autocorrelation time per parameter, steps.
    steps, walkers : int
    converged : bool
        Longer than 50 tau and tau stable.
    steps_needed : int
        50 max(tau): the chain length that convergence asks for.
    acceptance_fraction : ndarray, shape (walkers,)
    burn_in, thin : int
    log_prob_calls, log_prob_evaluations : int
        Vectorised calls of the log-probability and parameter vectors evaluated (the MAP
        search included).
    seconds : float
        Wall-clock time of the whole fit (MAP and sampling).
    message : str
        One sentence: converged, or not and by how much.
    """

    samples: np.ndarray
    log_prob: np.ndarray
    tau: np.ndarray
    steps: int
    walkers: int
    converged: bool
    steps_needed: int
    acceptance_fraction: np.ndarray
    burn_in: int
    thin: int
    log_prob_calls: int
    log_prob_evaluations: int
    seconds: float
    map_point: np.ndarray
    message: str
    chain: np.ndarray = field(repr=False, default=None)

    def summary(self) -> dict:
        """JSON-able diagnostics."""
        return {"converged": self.converged, "message": self.message, "steps": self.steps,
                "walkers": self.walkers, "steps_needed": self.steps_needed,
                "tau": self.tau.tolist(), "burn_in": self.burn_in, "thin": self.thin,
                "acceptance_fraction_mean": float(np.mean(self.acceptance_fraction)),
                "acceptance_fraction_min": float(np.min(self.acceptance_fraction)),
                "independent_samples": int(self.samples.shape[0]),
                "log_prob_calls": self.log_prob_calls,
                "log_prob_evaluations": self.log_prob_evaluations,
                "seconds": self.seconds}


def _initial_walkers(rng, theta, covariance, bounds, walkers):
    """Draws from N(theta, covariance) inside the prior box (rejection, then clipping)."""
    ndim = theta.size
    out = np.empty((walkers, ndim))
    filled = 0
    for _ in range(100):
        draws = rng.multivariate_normal(theta, covariance, size=4 * walkers)
        inside = np.all((draws > bounds[:, 0]) & (draws < bounds[:, 1]), axis=1)
        take = draws[inside][: walkers - filled]
        out[filled: filled + take.shape[0]] = take
        filled += take.shape[0]
        if filled == walkers:
            return out
    margin = 1e-9 * np.diff(bounds, axis=1).ravel()
    out[filled:] = np.clip(rng.multivariate_normal(theta, covariance, size=walkers - filled),
                           bounds[:, 0] + margin, bounds[:, 1] - margin)
    return out


def run_chain(model, *, walkers: int | None = None, max_steps: int = 20000,
              check_every: int = 200, seed: int | None = None, progress: bool = False,
              moves=None, start=None, description: str = "emcee") -> ChainResult:
    """Find the MAP point, start walkers from the Laplace approximation, sample to convergence.

    Parameters
    ----------
    model : ProfileModel
        Callable, vectorised log-probability with ``bounds`` and ``initial_guess``.
    walkers : int, optional
        Number of walkers (default: ``max(4 ndim, 32)`` rounded up to even); at least
        ``2 ndim``.
    max_steps : int
        Step budget.
    check_every : int
        Steps between convergence checks.
    seed : int, optional
    progress : bool
        Show a tqdm progress bar (on stderr).
    moves : emcee moves, optional
        Default: the stretch move.
    start : ndarray, optional
        Starting point of the MAP search.
    description : str
        Progress-bar label.

    Returns
    -------
    ChainResult
    """
    began = time.perf_counter()
    ndim = model.ndim
    if walkers is None:
        walkers = max(4 * ndim, 32)
    walkers = int(walkers) + int(walkers) % 2
    if walkers < 2 * ndim:
        raise InputError(f"must be at least 2 x ndim = {2 * ndim}", field="walkers",
                         value=walkers)
    if max_steps < check_every:
        raise InputError(f"must be >= check_every ({check_every})", field="max_steps",
                         value=max_steps)
    calls0, evaluations0 = model.calls, model.evaluations
    theta_map, _ = find_map(model, start)
    covariance = laplace_covariance(model, theta_map)
    rng = np.random.default_rng(seed)
    initial = _initial_walkers(rng, theta_map, covariance, model.bounds, walkers)
    sampler = emcee.EnsembleSampler(walkers, ndim, model, vectorize=True, moves=moves)
    sampler.random_state = np.random.RandomState(rng.integers(2**31)).get_state()
    state = emcee.State(initial, random_state=sampler.random_state)
    previous_tau = None
    tau = np.full(ndim, np.inf)
    converged = False
    bar = None
    if progress:
        from tqdm.auto import tqdm

        bar = tqdm(total=max_steps, desc=description, unit="step", leave=False)
    try:
        while sampler.iteration < max_steps:
            steps = min(check_every, max_steps - sampler.iteration)
            for _ in sampler.sample(state, iterations=steps):
                if bar is not None:
                    bar.update(1)
            state = sampler.get_last_sample()
            tau = sampler.get_autocorr_time(tol=0)
            if np.all(np.isfinite(tau)) and previous_tau is not None:
                long_enough = sampler.iteration > CONVERGENCE_TAUS * tau.max()
                stable = np.all(np.abs(previous_tau - tau) < TAU_STABILITY * tau)
                if long_enough and stable:
                    converged = True
                    break
            previous_tau = tau
            if bar is not None and np.all(np.isfinite(tau)):
                bar.set_postfix(tau=f"{tau.max():.0f}", need=int(CONVERGENCE_TAUS * tau.max()))
    finally:
        if bar is not None:
            bar.close()
    steps = sampler.iteration
    tau_max = float(np.max(tau)) if np.all(np.isfinite(tau)) else float(steps)
    tau_min = float(np.min(tau)) if np.all(np.isfinite(tau)) else 1.0
    burn_in = min(int(BURN_IN_TAUS * tau_max), steps // 2)
    thin = max(1, int(THIN_TAUS * tau_min))
    samples = sampler.get_chain(discard=burn_in, thin=thin, flat=True)
    log_prob = sampler.get_log_prob(discard=burn_in, thin=thin, flat=True)
    needed = int(np.ceil(CONVERGENCE_TAUS * tau_max))
    if converged:
        message = (f"converged: {steps} steps > {CONVERGENCE_TAUS} tau = {needed} "
                   f"(tau max {tau_max:.1f}, stable to {TAU_STABILITY:.0%})")
    elif steps > needed:
        message = (f"NOT converged: {steps} steps > {CONVERGENCE_TAUS} tau = {needed}, but tau "
                   f"still changed by more than {TAU_STABILITY:.0%} at the last check; run "
                   f"longer (about 2 x) before trusting the intervals")
    else:
        message = (f"NOT converged: the chain is {steps} steps but {CONVERGENCE_TAUS} tau = "
                   f"{needed} steps (tau max {tau_max:.1f}); it would need about "
                   f"{max(needed / max(steps, 1), 1.0):.1f} x more steps; treat the intervals "
                   f"as indicative")
    return ChainResult(samples=samples, log_prob=log_prob, tau=np.asarray(tau, np.float64),
                       steps=steps, walkers=walkers, converged=converged, steps_needed=needed,
                       acceptance_fraction=np.asarray(sampler.acceptance_fraction),
                       burn_in=burn_in, thin=thin,
                       log_prob_calls=model.calls - calls0,
                       log_prob_evaluations=model.evaluations - evaluations0,
                       seconds=time.perf_counter() - began, map_point=theta_map,
                       message=message, chain=sampler.get_chain())
