r"""MAP point, Laplace start and an emcee run that stops when it has converged.

The recipe of the emcee documentation (Foreman-Mackey et al.), as the suite applies it:

* at least ``2 ndim`` walkers, started from the Laplace approximation about the
  maximum-a-posteriori point (found with ``scipy.optimize``), so that they begin close to
  the typical set;
* the optimiser runs from several starts (the model's ``initial_guesses``, which cover the
  prior); every distinct local optimum within :data:`MODE_WINDOW_NATS` of the best is a
  *mode*, and the walkers are shared between the modes in proportion to their Laplace
  evidence, so a posterior with two modes is sampled in both (a capture that sees only
  part of the profile can leave sigma_a and sigma_s' with two explanations of nearly the
  same probability); every flat sample is labelled with the mode it belongs to;
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

from .. import signals
from ..errors import InputError, check_count

__all__ = ["ChainResult", "Mode", "ModeJumpMove", "find_map", "find_modes", "laplace_covariance",
           "mode_labels", "run_chain", "walkers_per_mode"]

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
#: Local optima more than this many nats below the best are dropped: a mode that much lower
#: holds less than e^-10 = 5e-5 of the mass unless its volume is e^10 times larger, and a
#: volume that large shows in the Laplace evidence of the modes kept.
MODE_WINDOW_NATS = 10.0
#: Two optima are one mode when either lies within this many standard deviations of the
#: other (Mahalanobis, Laplace covariance) ...
SAME_MODE_SIGMAS = 3.0
#: ... or when the log-posterior on the straight segment between them never falls more
#: than this many nats below the lower of the two (no valley: the same basin).
SAME_MODE_BARRIER_NATS = 2.0
#: Points of that segment checked (fractions of the way).
BARRIER_FRACTIONS = (0.25, 0.5, 0.75)
#: Modes below this share of the Laplace evidence get no walkers of their own (they cannot
#: move a 95 % interval); the chain's mode-hopping moves may still visit them.
MODE_WEIGHT_FLOOR = 0.01
#: A mode that gets walkers gets at least this many, so that differences between walkers
#: of the same mode exist on both halves of emcee's red-blue split.
MIN_WALKERS_PER_MODE = 4
#: Share of the steps given to :class:`ModeJumpMove` when there are several modes: the
#: jump is accepted about as often as a Laplace approximation is good (measured 0.3-0.6
#: on a corner capture), so a tenth of the steps moves walkers between modes many times
#: per autocorrelation time without slowing the moves within a mode much.
MODE_JUMP_FRACTION = 0.1


def _gradient(log_probability, theta, step):
    """Central-difference gradient of ``log_probability`` at ``theta``, one vectorised call."""
    ndim = theta.size
    points = np.repeat(theta[None, :], 2 * ndim, axis=0)
    points[np.arange(ndim), np.arange(ndim)] += step
    points[ndim + np.arange(ndim), np.arange(ndim)] -= step
    values = log_probability(points)
    return (values[:ndim] - values[ndim:]) / (2.0 * step)


def _starting_points(model, start):
    """Return the starts of the MAP search: ``start``, or the model's guesses."""
    if start is None and hasattr(model, "initial_guesses"):
        return list(model.initial_guesses())
    return [model.initial_guess() if start is None else start]


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
    optima = [_local_map(model, point, max_iterations)
              for point in _starting_points(model, start)]
    return max(optima, key=lambda optimum: optimum[1])


@dataclass
class Mode:
    """One local maximum of the posterior and its Laplace approximation.

    Attributes
    ----------
    theta : ndarray, shape (ndim,)
        The local MAP point (sampling space).
    log_prob : float
        Log-posterior there.
    covariance : ndarray, shape (ndim, ndim)
        Laplace covariance (inverse negative Hessian).
    weight : float
        Share of the Laplace evidence ``exp(log_prob) sqrt(det 2 pi covariance)`` among the
        modes found.
    """

    theta: np.ndarray
    log_prob: float
    covariance: np.ndarray
    weight: float = 1.0

    def summary(self) -> dict:
        """JSON-able form (no covariance)."""
        return {"theta": self.theta.tolist(), "log_prob": self.log_prob,
                "laplace_weight": self.weight,
                "sd": np.sqrt(np.diag(self.covariance)).tolist()}


def _mahalanobis(delta, covariance) -> float:
    return float(np.sqrt(delta @ np.linalg.solve(covariance, delta)))


def _same_mode(model, mode: Mode, theta, value, covariance) -> bool:
    """Tell whether the optimum ``theta`` lies in the basin of ``mode`` (see the constants)."""
    delta = theta - mode.theta
    if min(_mahalanobis(delta, mode.covariance), _mahalanobis(delta, covariance)) \
            < SAME_MODE_SIGMAS:
        return True
    fractions = np.asarray(BARRIER_FRACTIONS)[:, None]
    along = model.log_probability(mode.theta[None, :] + fractions * delta[None, :])
    return bool(np.min(along) >= min(mode.log_prob, value) - SAME_MODE_BARRIER_NATS)


def find_modes(model, start=None, *, window: float = MODE_WINDOW_NATS,
               max_iterations: int = 500) -> list[Mode]:
    r"""Every distinct local maximum of the posterior within ``window`` nats of the best.

    L-BFGS-B runs from each starting point (see :func:`find_map`); optima are merged when
    they are one basin (:data:`SAME_MODE_SIGMAS`, :data:`SAME_MODE_BARRIER_NATS`), and
    each mode kept carries its Laplace covariance and its share of the Laplace evidence,
    :math:`Z_k \approx p(\theta_k) \sqrt{\det 2\pi\Sigma_k}`.

    Parameters
    ----------
    model : ProfileModel
    start : ndarray, optional
        A single starting point (then only one mode can be found).
    window : float
        Nats below the best optimum within which optima are kept.
    max_iterations : int

    Returns
    -------
    list of Mode
        Heaviest (largest Laplace evidence) first; the weights sum to 1.
    """
    optima = sorted((_local_map(model, point, max_iterations)
                     for point in _starting_points(model, start)),
                    key=lambda optimum: -optimum[1])
    best_value = optima[0][1]
    modes: list[Mode] = []
    for theta, value in optima:
        if value < best_value - window:
            break
        covariance = laplace_covariance(model, theta)
        if not any(_same_mode(model, mode, theta, value, covariance) for mode in modes):
            modes.append(Mode(theta, value, covariance))
    log_evidence = np.array([m.log_prob + 0.5 * np.linalg.slogdet(m.covariance)[1]
                             for m in modes])
    weights = np.exp(log_evidence - log_evidence.max())
    for mode, weight in zip(modes, weights / weights.sum(), strict=True):
        mode.weight = float(weight)
    return sorted(modes, key=lambda mode: -mode.weight)


def mode_labels(modes: list[Mode], samples) -> np.ndarray:
    """Label each sample with the mode whose weighted Laplace Gaussian is densest there.

    Parameters
    ----------
    modes : list of Mode
    samples : ndarray, shape (m, ndim)

    Returns
    -------
    ndarray of int, shape (m,)
        Index into ``modes``.
    """
    samples = np.atleast_2d(samples)
    if len(modes) < 2:
        return np.zeros(samples.shape[0], dtype=int)
    scores = []
    for mode in modes:
        delta = samples - mode.theta
        precision = np.linalg.inv(mode.covariance)
        distance = np.einsum("ni,ij,nj->n", delta, precision, delta)
        scores.append(np.log(max(mode.weight, 1e-300)) - 0.5 * distance
                      - 0.5 * np.linalg.slogdet(mode.covariance)[1])
    return np.argmax(np.array(scores), axis=0)


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
    modes : list of Mode
        The local maxima the walkers were started in (best first).
    sample_modes : ndarray of int, shape (m,)
        The mode each flat sample belongs to (:func:`mode_labels`).
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
    modes: list = field(default_factory=list)
    sample_modes: np.ndarray = field(repr=False, default=None)

    def mode_fractions(self) -> np.ndarray:
        """Share of the flat samples in each mode, shape (len(modes),)."""
        if not self.modes or self.sample_modes is None or self.sample_modes.size == 0:
            return np.ones(max(len(self.modes), 1))
        return np.bincount(self.sample_modes, minlength=len(self.modes)) \
            / self.sample_modes.size

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
                "seconds": self.seconds,
                "modes": [{**mode.summary(), "sample_fraction": float(fraction)}
                          for mode, fraction in zip(self.modes, self.mode_fractions(),
                                                    strict=False)]}


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


class ModeJumpMove(emcee.moves.MHMove):
    r"""Metropolis-Hastings jump of each walker from its mode to the matching point of another.

    A walker at :math:`x` in mode :math:`k` (:func:`mode_labels`) picks another mode
    :math:`j` uniformly and proposes :math:`x' = \mu_j + L_j L_k^{-1}(x - \mu_k)`, where
    :math:`L` are the Cholesky factors of the Laplace covariances: the point with the same
    standardised offset in the other mode. The map is a bijection whose inverse is the jump
    back, so the acceptance is :math:`\min(1, p(x') |\det L_j| / (p(x) |\det L_k|))`
    (Tjelmeland & Hegstad 2001, "Mode jumping proposals in MCMC", Sec. 3); a proposal that
    does not land in mode :math:`j` is refused, which keeps the jump its own inverse. The
    walkers thus settle between the modes at the posterior's own weights, whatever the
    Laplace weights they were started with. The stretch and differential-evolution moves
    cannot do this: their proposals from walkers of two modes cross the valley between
    them (measured on a corner capture: 2 % of the differential-evolution hops accepted in
    one direction, 2e-6 in the other).

    Parameters
    ----------
    modes : list of Mode
        At least two.
    """

    def __init__(self, modes: list[Mode]):
        self.modes = list(modes)
        self.cholesky = [np.linalg.cholesky(mode.covariance) for mode in self.modes]
        self.log_det = np.array([np.sum(np.log(np.diag(factor))) for factor in self.cholesky])
        super().__init__(self._proposal)

    def _proposal(self, coords, random):
        count = len(self.modes)
        labels = mode_labels(self.modes, coords)
        targets = (labels + random.randint(1, count, size=labels.size)) % count
        proposal = coords.copy()
        for k in range(count):
            for j in range(count):
                rows = (labels == k) & (targets == j)
                if j == k or not rows.any():
                    continue
                standard = np.linalg.solve(self.cholesky[k],
                                           (coords[rows] - self.modes[k].theta).T)
                proposal[rows] = self.modes[j].theta + (self.cholesky[j] @ standard).T
        factors = self.log_det[targets] - self.log_det[labels]
        landed = mode_labels(self.modes, proposal) == targets
        return proposal, np.where(landed, factors, -np.inf)


def _with_mode_jumps(moves, modes):
    """Return ``moves`` as emcee's weighted list, plus :class:`ModeJumpMove` for modes."""
    if moves is None:
        moves = [(emcee.moves.StretchMove(), 1.0)]
    elif isinstance(moves, emcee.moves.Move):
        moves = [(moves, 1.0)]
    else:
        moves = [move if isinstance(move, tuple) else (move, 1.0) for move in moves]
    if len(modes) < 2:
        return moves
    total = sum(weight for _, weight in moves)
    return [(move, (1.0 - MODE_JUMP_FRACTION) * weight / total) for move, weight in moves] \
        + [(ModeJumpMove(modes), MODE_JUMP_FRACTION)]


def walkers_per_mode(weights, walkers: int) -> np.ndarray:
    """Share ``walkers`` between modes in proportion to their weights.

    Modes under :data:`MODE_WEIGHT_FLOOR` get none; the others at least
    :data:`MIN_WALKERS_PER_MODE` (fewer modes are served when that does not fit), the rest
    by largest remainder.

    Parameters
    ----------
    weights : ndarray, shape (k,)
        Mode weights, best first, summing to 1.
    walkers : int

    Returns
    -------
    ndarray of int, shape (k,)
        Summing to ``walkers``.
    """
    weights = np.asarray(weights, dtype=np.float64)
    minimum = min(MIN_WALKERS_PER_MODE, walkers)
    served = weights >= MODE_WEIGHT_FLOOR
    served[0] = True
    served &= np.cumsum(served) <= max(1, walkers // minimum)  # best modes first
    share = np.where(served, weights, 0.0) / np.sum(weights[served])
    counts = np.where(served, minimum, 0)
    spare = walkers - int(counts.sum())
    wanted = np.clip(share * walkers - counts, 0.0, None)  # beyond the minimum
    target = wanted * spare / wanted.sum() if wanted.sum() > 0 else share * spare
    extra = np.floor(target).astype(int)
    counts = counts + extra
    for k in np.argsort(-(target - extra))[: walkers - int(counts.sum())]:
        counts[k] += 1
    return counts


def run_chain(model, *, walkers: int | None = None, max_steps: int = 20000,
              check_every: int = 200, seed: int | None = None, progress: bool = False,
              moves=None, start=None, description: str = "emcee") -> ChainResult:
    """Find the posterior's modes, start walkers from their Laplace approximations, sample.

    The walkers are shared between the modes of :func:`find_modes` by
    :func:`walkers_per_mode`; the run stops at convergence or at the step budget.

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
        Default: the stretch move. With several modes, include a move that can jump
        between them (``fitting.fit.default_moves`` does).
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
    given = walkers
    walkers = check_count(walkers, "walkers", 1)
    walkers += walkers % 2  # the stretch move splits the ensemble in halves
    if walkers < 2 * ndim:
        raise InputError(f"must be at least 2 x ndim = {2 * ndim}", field="walkers",
                         value=given)
    if max_steps < check_every:
        raise InputError(f"must be >= check_every ({check_every})", field="max_steps",
                         value=max_steps)
    from ..resources import check_memory

    # emcee keeps every step of every walker: the chain, its log-probabilities, acceptance
    check_memory(float(walkers) * max_steps * (ndim + 2) * 8,
                 what=f"a chain of {walkers} walkers x {max_steps} steps",
                 field="walkers x max_steps", value=f"{given} x {max_steps}")
    calls0, evaluations0 = model.calls, model.evaluations
    modes = find_modes(model, start)
    rng = np.random.default_rng(seed)
    counts = walkers_per_mode([mode.weight for mode in modes], walkers)
    initial = np.vstack([_initial_walkers(rng, mode.theta, mode.covariance, model.bounds,
                                          int(count))
                         for mode, count in zip(modes, counts, strict=True) if count > 0])
    sampler = emcee.EnsembleSampler(walkers, ndim, model, vectorize=True,
                                    moves=_with_mode_jumps(moves, modes))
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
            # a signal inside the log-probability would have emcee print a traceback: it
            # is held and raised here, between steps
            with signals.deferred():
                for _ in sampler.sample(state, iterations=steps):
                    signals.check()
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
                       seconds=time.perf_counter() - began, map_point=modes[0].theta,
                       message=message, chain=sampler.get_chain(), modes=modes,
                       sample_modes=mode_labels(modes, samples))
