r"""Posteriors over profile parameters given a measured radial profile.

Every model maps a parameter vector :math:`\theta` (in its sampling space) to the exitance
profile at the nodes of the capture's radial grid, which the capture's
:class:`~translucent.fitting.profile.ProfileOperator` turns into predicted annulus means.
The log-probability is vectorised: it takes an ``(n, ndim)`` array and returns ``(n,)``,
as ``emcee.EnsembleSampler(..., vectorize=True)`` calls it.

Likelihood. Each used annulus ``a`` of channel ``c`` has a mean :math:`m`, a standard error
:math:`s` from its own scatter and :math:`\nu = N - 2` degrees of freedom. With the noise
level itself estimated from the same pixels, the mean has a Student-t distribution about
the prediction :math:`\mu` (the marginal over the unknown pixel variance):

.. math:: \ln L = \sum_{a,c} -\frac{\nu + 1}{2}\ln\Big(1 + \frac{(m - \mu)^2}{\nu s^2}\Big)

Priors (documented in ``docs/capture-format.md`` too):

========================  ===============================  ==============================
parameter                 prior                            range
========================  ===============================  ==============================
sigma_a (per channel)     log-uniform                      :data:`SIGMA_A_RANGE` mm^-1
sigma_s' (per channel)    log-uniform                      :data:`SIGMA_S_PRIME_RANGE`
eta (when fitted)         uniform                          :data:`ETA_FIT_RANGE`
exposure (when unknown)   log-uniform                      :data:`EXPOSURE_RANGE`
SubEdit ln P knots        uniform box + smoothness         :data:`KNOT_BOX_NATS` about the
                          (Gaussian second differences)    data's peak
========================  ===============================  ==============================
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np

from ..errors import InputError
from ..materials.dipole import dipole_reflectance_profile
from ..materials.multipole import slab_reflectance_profile, slab_transmittance_profile
from ..materials.subedit import LOG_FLOOR, SubEditProfiles
from .capture import CaptureSpec
from .profile import RadialProfile

__all__ = [
    "DipoleModel",
    "ReducedTableModel",
    "check_semi_infinite_reflection",
    "ETA_FIT_RANGE",
    "EXPOSURE_RANGE",
    "ProfileModel",
    "SIGMA_A_RANGE",
    "SIGMA_S_PRIME_RANGE",
    "SubEditModel",
    "WalkModel",
    "student_t_log_likelihood",
]

#: Absorption prior, mm^-1 (log-uniform): from 1e-5 (no capture of a few cm can tell less)
#: to 10 (opaque within 0.1 mm); the measured media of Jensen et al. 2001 span 2e-4 .. 1.45.
SIGMA_A_RANGE = (1e-5, 10.0)
#: Reduced scattering prior, mm^-1 (log-uniform): 0.01 (10 cm transport length) to 1000
#: (1 um); the measured media span 0.03 .. 20.4.
SIGMA_S_PRIME_RANGE = (1e-2, 1e3)
#: Relative index prior when fitted (uniform): water-like to glass-like and beyond.
ETA_FIT_RANGE = (1.0, 2.0)
#: Exposure prior when unknown (log-uniform, stored units per mm^-2): wide enough never to
#: bind; the data fix the scale to a few per cent.
EXPOSURE_RANGE = (1e-30, 1e30)
#: SubEdit knot box: ln P within this many nats below / above ln of the measured peak
#: (divided by the exposure when known). Never binding in practice.
KNOT_BOX_NATS = (60.0, 10.0)
#: Default smoothness of SubEdit profiles: the prior standard deviation of the second
#: difference of ln P between adjacent knots, nats. A dipole sampled at 8 knots has second
#: differences of 0.1-3 nats; 2 lets such shapes through while damping knot-to-knot noise.
SUBEDIT_SMOOTHNESS = 2.0

CHANNELS = "RGB"
#: Grid points evaluated together by :meth:`DipoleModel.initial_guesses`.
GRID_BLOCK = 48
#: Grid of the starting-point search: points per decade range of sigma_a and sigma_s'.
GRID_POINTS = 32
#: Exposures tried for the shared-exposure start: a log grid from the channels' smallest
#: own best exposure / e^3 to their largest x e^3.
SCALE_SEARCH_NATS = 3.0
SCALE_SEARCH_POINTS = 121
#: Relative error added in quadrature to every annulus in the starting-point search.
#: Neighbouring grid points predict profiles tens of per cent apart; against annuli known
#: to 1e-4 (a capture that saturates) every grid point is thousands of standard errors
#: off, and their ranking rests on the few worst annuli: such a capture's search started
#: in a wrong basin of one channel (sigma_s' 12 times the truth; 1 of 30 captures with 30 %
#: of the pixels saturated). At 5 % the grid sees the profile's shape; the polishing that
#: follows uses the standard errors themselves.
START_SEARCH_RELATIVE_ERROR = 0.05
#: Grid points per channel polished at each shared exposure tried
#: (:meth:`DipoleModel._shared_exposure_start`).
SHARED_GRID_STARTS = 2
#: Grid basins per channel polished on their own before the joint MAP search.
CHANNEL_CANDIDATES = 4
#: A channel's second basin becomes a start of its own when its log-likelihood is within
#: this many nats of the channel's best (the window of the modes kept by the sampler).
ALTERNATIVE_BASIN_NATS = 10.0


def student_t_log_likelihood(residual, stderr, dof) -> np.ndarray:
    """Sum over the last axis of the Student-t log-density of ``residual`` (up to a constant).

    Parameters
    ----------
    residual : ndarray, shape (..., m)
        Measured minus predicted annulus means.
    stderr : ndarray, shape (m,)
        Standard errors of the means, > 0.
    dof : ndarray, shape (m,)
        Degrees of freedom, > 0.

    Returns
    -------
    ndarray, shape (...)
    """
    t2 = (residual / stderr) ** 2
    return np.sum(-0.5 * (dof + 1.0) * np.log1p(t2 / dof), axis=-1)


@dataclass(frozen=True)
class ParameterInfo:
    """One coordinate of the sampling space.

    ``transform`` is ``"log"`` (the coordinate is ln of the physical value) or
    ``"linear"``; ``kind`` groups parameters (``sigma_a``, ``sigma_s_prime``, ``eta``,
    ``exposure``, ``ln_p``); ``channel`` is 0-2 or None.
    """

    name: str
    kind: str
    transform: str
    lower: float
    upper: float
    channel: int | None = None
    unit: str = ""

    def to_physical(self, values):
        """Map sampling coordinates to physical values."""
        values = np.asarray(values, dtype=np.float64)
        return np.exp(values) if self.transform == "log" else values


class ProfileModel:
    """Base class: a vectorised log-probability over a measured profile.

    Subclasses set ``parameters`` (a list of :class:`ParameterInfo`) and ``channels``
    and implement :meth:`profile_nodes` and :meth:`initial_guess`.
    """

    parameters: list[ParameterInfo]
    channels: tuple[int, ...] = (0, 1, 2)

    def __init__(self, profile: RadialProfile, spec: CaptureSpec):
        self.profile = profile
        self.spec = spec
        self._observations = [profile.observations(c) for c in range(3)]
        # the annuli whose prediction scales with the exposure (not the saturated ones,
        # predicted as clipped means): what a search over unit-exposure profiles compares
        self._linear = [profile.operator.linear_rows(c, self._observations[c][0].size)
                        for c in range(3)]
        self.evaluations = 0
        self.calls = 0

    # --- the sampling space ---------------------------------------------------------------
    @property
    def ndim(self) -> int:
        """Number of parameters."""
        return len(self.parameters)

    @property
    def names(self) -> list[str]:
        """Parameter names, in order."""
        return [p.name for p in self.parameters]

    @property
    def bounds(self) -> np.ndarray:
        """``(ndim, 2)`` prior bounds in the sampling space."""
        return np.array([[p.lower, p.upper] for p in self.parameters])

    # --- to be provided by subclasses --------------------------------------------------------
    def profile_nodes(self, theta: np.ndarray) -> np.ndarray:
        """Predicted exitance times exposure at the grid nodes, shape (n, nodes, 3)."""
        raise NotImplementedError

    def initial_guess(self) -> np.ndarray:
        """Return a starting point for the optimiser, shape (ndim,)."""
        raise NotImplementedError

    def extra_log_prior(self, theta: np.ndarray) -> np.ndarray:
        """Log-prior terms beyond the uniform box, shape (n,) (default 0)."""
        return np.zeros(theta.shape[0])

    # --- the posterior ---------------------------------------------------------------------
    def predictions(self, theta) -> list[np.ndarray | None]:
        """Predicted annulus means per channel (None for channels not modelled)."""
        theta = np.atleast_2d(np.asarray(theta, dtype=np.float64))
        return self.profile.operator.predict(self.profile_nodes(theta), channels=self.channels)

    def log_likelihood(self, theta) -> np.ndarray:
        """Student-t log-likelihood of the measured annulus means, shape (n,).

        The scale of each annulus is :meth:`residual_scale`; where it depends on the
        parameters, its normalisation (:meth:`scale_normalisation`) enters too.
        """
        theta = np.atleast_2d(np.asarray(theta, dtype=np.float64))
        total = np.zeros(theta.shape[0])
        for c, predicted in enumerate(self.predictions(theta)):
            if predicted is None:
                continue
            mean, stderr, dof = self._observations[c]
            scale = self.residual_scale(c, stderr, predicted, theta)
            total += student_t_log_likelihood(mean - predicted, scale, dof) \
                - self.scale_normalisation(scale)
        return np.where(np.isfinite(total), total, -np.inf)

    def scale_normalisation(self, scale) -> np.ndarray | float:
        """Return ``sum(ln scale)`` per row where the scale varies with the parameters.

        The standard errors alone are fixed, so their normalisation is a constant: 0.
        """
        return 0.0

    def in_bounds(self, theta) -> np.ndarray:
        """Tell, per row, whether every coordinate lies within the prior box, shape (n,)."""
        bounds = self.bounds
        return np.all((theta >= bounds[:, 0]) & (theta <= bounds[:, 1]), axis=1)

    def log_probability(self, theta, *, bounded: bool = True) -> np.ndarray:
        """Log-posterior (up to a constant), vectorised: ``(n, ndim) -> (n,)``.

        ``bounded=False`` drops the prior box (used for finite differences at the MAP point
        when it lies on a bound).
        """
        theta = np.atleast_2d(np.asarray(theta, dtype=np.float64))
        self.calls += 1
        self.evaluations += theta.shape[0]
        result = np.full(theta.shape[0], -np.inf)
        inside = self.in_bounds(theta) if bounded else np.all(np.isfinite(theta), axis=1)
        if inside.any():
            points = theta[inside]
            result[inside] = self.log_likelihood(points) + self.extra_log_prior(points)
        return np.where(np.isnan(result), -np.inf, result)

    def __call__(self, theta) -> np.ndarray:
        """Evaluate the vectorised log-probability for ``emcee`` (see :meth:`log_probability`)."""
        return self.log_probability(theta)

    def physical(self, samples) -> dict[str, np.ndarray]:
        """Map samples in the sampling space to ``name -> physical values``."""
        samples = np.atleast_2d(samples)
        return {p.name: p.to_physical(samples[:, i]) for i, p in enumerate(self.parameters)}

    def observations(self, channel: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(mean, stderr, dof)`` of the annulus means of ``channel`` that enter the fit."""
        return self._observations[channel]

    def residual_scale(self, channel: int, stderr, predicted, theta) -> np.ndarray:
        """Return the likelihood's scale of each annulus, shaped as ``predicted``.

        The standard errors; a model with a discrepancy term inflates them.
        """
        return np.broadcast_to(stderr, np.shape(predicted))

    def residual_degrees(self) -> int:
        """Count the annulus means that enter the likelihood."""
        return int(sum(self._observations[c][0].size for c in self.channels))


class DipoleModel(ProfileModel):
    r"""Dipole (semi-infinite) or multipole (slab) exitance with per-channel coefficients.

    Parameters (sampling space): ``ln sigma_a`` and ``ln sigma_s'`` per channel, then
    ``eta`` when the sidecar leaves it null (or ``fit_eta``), then ``ln exposure`` when the
    sidecar's exposure is null. The profile is :math:`R_d(r)` of Jensen et al. 2001 (Eq. 2
    of Wang et al. 2008) for a semi-infinite slab, and :math:`R(r)` or :math:`T(r)` of the
    multipole (Eq. 11-12 of Donner & Jensen 2005) for a slab of finite thickness.

    Parameters
    ----------
    profile : RadialProfile
    spec : CaptureSpec
    fit_eta : bool, optional
        Fit eta even if the sidecar gives it (default: fit only when it is null; False
        with a null eta is an :class:`InputError`).
    """

    def __init__(self, profile: RadialProfile, spec: CaptureSpec, *, fit_eta: bool | None = None):
        super().__init__(profile, spec)
        if fit_eta is not None and not fit_eta and spec.eta is None:
            raise InputError("the capture's eta is unknown (null): it must be fitted",
                             field="fit_eta", value=fit_eta)
        self.fit_eta = spec.eta is None if fit_eta is None else bool(fit_eta)
        self.fit_exposure = spec.exposure is None
        params = []
        for kind, (low, high) in (("sigma_a", SIGMA_A_RANGE),
                                  ("sigma_s_prime", SIGMA_S_PRIME_RANGE)):
            for c in range(3):
                params.append(ParameterInfo(f"{kind}[{CHANNELS[c]}]", kind, "log",
                                            np.log(low), np.log(high), c, "mm^-1"))
        if self.fit_eta:
            params.append(ParameterInfo("eta", "eta", "linear", *ETA_FIT_RANGE))
        if self.fit_exposure:
            params.append(ParameterInfo("exposure", "exposure", "log",
                                        np.log(EXPOSURE_RANGE[0]), np.log(EXPOSURE_RANGE[1]),
                                        None, "stored units mm^2"))
        self.parameters = params
        self.channels = tuple(c for c in range(3) if self._observations[c][0].size >= 2)
        if not self.channels:
            raise InputError("no channel has usable annuli", field="profile")

    def split(self, theta):
        """``(sigma_a, sigma_s_prime, eta, exposure)`` arrays from ``theta`` (n, ndim)."""
        theta = np.atleast_2d(theta)
        sigma_a = np.exp(theta[:, 0:3])
        sigma_s_prime = np.exp(theta[:, 3:6])
        index = 6
        if self.fit_eta:
            eta = theta[:, index]
            index += 1
        else:
            eta = np.full(theta.shape[0], self.spec.eta)
        exposure = np.exp(theta[:, index]) if self.fit_exposure else \
            np.full(theta.shape[0], self.spec.exposure)
        return sigma_a, sigma_s_prime, eta, exposure

    def unit_profiles(self, sigma_a, sigma_s_prime, eta) -> np.ndarray:
        """Return the exitance per unit entering power at the nodes, mm^-2, (n, nodes, 3)."""
        r = self.profile.operator.grid.nodes[None, :, None]
        sigma_a = sigma_a[:, None, :]
        sigma_s_prime = sigma_s_prime[:, None, :]
        eta = np.asarray(eta, dtype=np.float64)[:, None, None]
        thickness = self.spec.thickness_mm
        if self.spec.side == "transmission":
            return slab_transmittance_profile(r, sigma_a, sigma_s_prime, eta, thickness)
        if thickness is None:
            return dipole_reflectance_profile(r, sigma_a, sigma_s_prime, eta)
        return slab_reflectance_profile(r, sigma_a, sigma_s_prime, eta, thickness)

    def profile_nodes(self, theta):
        """Exposure times the dipole/multipole exitance at the nodes, shape (n, nodes, 3)."""
        sigma_a, sigma_s_prime, eta, exposure = self.split(theta)
        return exposure[:, None, None] * self.unit_profiles(sigma_a, sigma_s_prime, eta)

    def initial_guess(self) -> np.ndarray:
        """Return the best of :meth:`initial_guesses` (the shared-exposure grid point)."""
        return self.initial_guesses()[0]

    def initial_guesses(self, grid_points: int = GRID_POINTS) -> list[np.ndarray]:
        """Return starting points for the optimiser from a grid over the prior.

        Each channel's (sigma_a, sigma_s') runs over a ``grid_points`` x ``grid_points``
        log grid (and eta over {1.1, 1.3, 1.5} when fitted). The first point shares one
        exposure (and eta) between the channels, as the model does: for each exposure on a
        fine log grid, each channel takes its best grid point, and the exposure with the
        best total wins. The second lets every channel take its own best exposure
        (weighted least squares) and combines them geometrically. Two starts guard the
        MAP search against the valleys of the sigma_a - sigma_s' - exposure degeneracy.
        """
        log_a = np.linspace(*np.log(SIGMA_A_RANGE), grid_points)
        log_s = np.linspace(*np.log(SIGMA_S_PRIME_RANGE), grid_points)
        fixed_eta = self.split(np.zeros((1, self.ndim)))[2][0]
        etas = np.array([1.1, 1.3, 1.5]) if self.fit_eta else np.array([fixed_eta])
        grid_a, grid_s, grid_eta = (g.ravel() for g in np.meshgrid(log_a, log_s, etas,
                                                                    indexing="ij"))
        predicted = [np.empty((grid_a.size, int(self._linear[c].sum()))) for c in range(3)]
        # in blocks: a slab's pole count is set by the block's least absorbing point
        for start in range(0, grid_a.size, GRID_BLOCK):
            block = slice(start, start + GRID_BLOCK)
            unit = self.unit_profiles(np.repeat(np.exp(grid_a[block])[:, None], 3, axis=1),
                                      np.repeat(np.exp(grid_s[block])[:, None], 3, axis=1),
                                      grid_eta[block])
            for c, values in enumerate(self.profile.operator.predict(unit, clipped=False)):
                predicted[c][block] = values[:, self._linear[c]]
        # each channel on its own: the weighted least-squares exposure of every grid point
        profiled = {c: self._profiled_exposure(c, predicted[c]) for c in self.channels}
        own = {}
        for c, (scale, loglike) in profiled.items():
            k = int(np.argmax(loglike))
            own[c] = (k, scale[k])
        scales = np.array([own[c][1] for c in own], dtype=np.float64)
        scales = scales[np.isfinite(scales) & (scales > 0)]
        own_scale = float(np.exp(np.mean(np.log(scales)))) if scales.size else 1.0
        guesses = [self._grid_theta(grid_a, grid_s, grid_eta, {c: own[c][0] for c in own},
                                    own_scale)]
        guesses += self._refined_channel_starts(profiled, grid_a, grid_s, grid_eta, predicted)
        # one exposure (and eta) for all channels, as the model has it
        if self.fit_exposure and scales.size:
            trial_scales = np.exp(np.linspace(np.log(scales.min()) - SCALE_SEARCH_NATS,
                                              np.log(scales.max()) + SCALE_SEARCH_NATS,
                                              SCALE_SEARCH_POINTS))
        else:
            trial_scales = np.array([own_scale if self.fit_exposure else self.spec.exposure])
        best_total, shared = -np.inf, None
        for eta in etas:
            subset = np.flatnonzero(grid_eta == eta)
            totals = np.zeros(trial_scales.size)
            picks = {}
            for c in self.channels:
                mean, stderr, dof = self._search_observations(c)
                loglike = student_t_log_likelihood(
                    mean - trial_scales[:, None, None] * predicted[c][subset][None], stderr, dof)
                loglike = np.where(np.isfinite(loglike), loglike, -np.inf)
                picks[c] = subset[np.argmax(loglike, axis=1)]
                totals += loglike.max(axis=1)
            k = int(np.argmax(totals))
            if totals[k] > best_total:
                best_total = totals[k]
                shared = ({c: int(picks[c][k]) for c in picks}, float(trial_scales[k]))
        if shared is not None:
            guesses.insert(0, self._grid_theta(grid_a, grid_s, grid_eta, *shared))
        return guesses

    def _search_observations(self, c, *, grid: bool = True):
        """``(mean, stderr, dof)`` of channel ``c`` for the starting-point search.

        Only the annuli whose prediction scales with the exposure. For the grid
        (``grid=True``) their standard errors are widened by
        :data:`START_SEARCH_RELATIVE_ERROR` of the mean, so that grid points are ranked by
        the profile's shape at the grid's own resolution; polishing uses them as they are.
        """
        mean, stderr, dof = (part[self._linear[c]] for part in self._observations[c])
        if grid:
            stderr = np.hypot(stderr, START_SEARCH_RELATIVE_ERROR * mean)
        return mean, stderr, dof

    def _profiled_exposure(self, c, unit_predictions):
        """Best exposure of each grid point for channel ``c`` alone, and its log-likelihood.

        The exposure is the weighted least-squares scale of the unit-exposure predictions
        (the sidecar's, when known); points where it is not positive get -inf.
        """
        mean, stderr, dof = self._search_observations(c)
        u = unit_predictions
        weights = 1.0 / stderr ** 2
        with np.errstate(invalid="ignore", divide="ignore"):
            scale = (u * mean * weights).sum(axis=1) / (u * u * weights).sum(axis=1)
        if not self.fit_exposure:
            scale = np.full_like(scale, self.spec.exposure)
        good = np.isfinite(scale) & (scale > 0)
        scale = np.where(good, scale, 1.0)
        loglike = student_t_log_likelihood(mean - scale[:, None] * u, stderr, dof)
        return scale, np.where(good & np.isfinite(loglike), loglike, -np.inf)

    def _channel_log_likelihood(self, c, points, eta) -> np.ndarray:
        """Log-likelihood of channel ``c`` alone at ``(ln sigma_a, ln sigma_s', ln scale)``.

        Every annulus of the channel, the saturated ones as clipped means: where the centre
        saturates, where the ceiling is crossed pins the profile as no tail annulus does.
        """
        points = np.atleast_2d(points)
        sigma_a = np.repeat(np.exp(points[:, :1]), 3, axis=1)
        sigma_s = np.repeat(np.exp(points[:, 1:2]), 3, axis=1)
        unit = self.unit_profiles(sigma_a, sigma_s, np.full(points.shape[0], eta))
        predicted = self.profile.operator.predict(np.exp(points[:, 2])[:, None, None] * unit,
                                                  channels=(c,))[c]
        mean, stderr, dof = self._observations[c]
        value = student_t_log_likelihood(mean - predicted, stderr, dof)
        return np.where(np.isfinite(value), value, -1e300)

    def _refined_channel_starts(self, profiled, grid_a, grid_s, grid_eta, predicted) -> list:
        """Refine each channel's best grid basins on their own, then join the channels.

        ``profiled`` maps each channel to its grid points' exposures and log-likelihoods
        (:meth:`_profiled_exposure`); ``predicted`` holds the grid points' unit-exposure
        predictions per channel.

        The :data:`CHANNEL_CANDIDATES` best grid points of each channel (at least two grid
        cells apart) are polished by L-BFGS-B in (ln sigma_a, ln sigma_s', ln exposure) of
        that channel alone. Two starts come back: every channel at its best basin, and every
        channel at its second-best distinct basin (its best where it has one only) within
        :data:`ALTERNATIVE_BASIN_NATS` of the best: a capture that sees part of the profile
        can leave a channel with two explanations, and the sampler needs both
        (:func:`~translucent.fitting.sampler.find_modes`). The exposures are combined
        geometrically. Where channels have two basins, the mix of basins with the best joint
        log-probability (one exposure for all) comes first.
        """
        from scipy import optimize

        eta = float(np.median(grid_eta))
        bounds = [(np.log(SIGMA_A_RANGE[0]), np.log(SIGMA_A_RANGE[1])),
                  (np.log(SIGMA_S_PRIME_RANGE[0]), np.log(SIGMA_S_PRIME_RANGE[1])),
                  (np.log(EXPOSURE_RANGE[0]), np.log(EXPOSURE_RANGE[1]))]
        ranked = {}
        cell = np.diff(np.unique(grid_a))[0] if np.unique(grid_a).size > 1 else 1.0
        for c, (scale, loglike) in profiled.items():
            chosen = []
            for k in np.argsort(loglike)[::-1]:
                if not np.isfinite(loglike[k]) or len(chosen) == CHANNEL_CANDIDATES:
                    break
                if all(max(abs(grid_a[k] - grid_a[j]), abs(grid_s[k] - grid_s[j])) > 2 * cell
                       for j in chosen):
                    chosen.append(k)
            polished = []
            for k in chosen:
                start = np.array([grid_a[k], grid_s[k], np.log(scale[k])])
                fixed = not self.fit_exposure

                def objective(x, c=c, fixed=fixed):
                    point = np.array(x)
                    if fixed:
                        point[2] = np.log(self.spec.exposure)
                    return -float(self._channel_log_likelihood(c, point, eta)[0])

                polished.append(optimize.minimize(objective, start, method="L-BFGS-B",
                                                  bounds=bounds, options={"maxiter": 200}))
            if not polished:
                return []
            polished.sort(key=lambda result: result.fun)
            distinct = [polished[0]]
            for result in polished[1:]:
                if result.fun > polished[0].fun + ALTERNATIVE_BASIN_NATS:
                    break
                if np.max(np.abs(result.x[:2] - distinct[0].x[:2])) > 2 * cell:
                    distinct.append(result)
                    break
            ranked[c] = [result.x for result in distinct]
        starts = [self._channel_theta({c: points[0] for c, points in ranked.items()}, eta)]
        if any(len(points) > 1 for points in ranked.values()):
            starts.append(self._channel_theta({c: points[-1] for c, points in ranked.items()},
                                              eta))
            # a channel alone may not tell its basins apart (its exposure is free), the
            # shared exposure can: the mix of basins the joint posterior likes best first
            mixes = np.array([self._channel_theta(dict(zip(ranked, choice, strict=True)), eta)
                              for choice in itertools.product(*ranked.values())])
            best = mixes[int(np.argmax(self.log_probability(mixes)))]
            if not any(np.array_equal(best, start) for start in starts):
                starts.insert(0, best)
        if self.fit_exposure and len(ranked) > 1:
            on_eta = np.flatnonzero(grid_eta == eta) if np.any(grid_eta == eta) \
                else np.arange(grid_eta.size)
            grid = (grid_a[on_eta], grid_s[on_eta],
                    {c: predicted[c][on_eta] for c in ranked})
            starts.insert(0, self._shared_exposure_start(ranked, eta, bounds[:2], grid))
        return starts

    def _shared_exposure_start(self, ranked, eta, bounds, grid) -> np.ndarray:
        """Join the channels at one exposure: the start of the best joint log-probability.

        Seen only in its tail (the centre saturated, or cut off), a channel alone fixes its
        diffusion length but hardly where it lies along its sigma_a - sigma_s' - exposure
        valley, so its own basin may sit at an exposure far from the other channels'. At a
        fixed exposure the valley is a narrow pit instead. For each exposure of a channel's
        basin (and their geometric mean) every channel's (sigma_a, sigma_s') is polished at
        that exposure from its basins and from its :data:`SHARED_GRID_STARTS` best grid
        points at that exposure (ranked by the standard errors themselves); the candidate
        the joint posterior likes best is returned.

        ``grid`` is ``(ln sigma_a, ln sigma_s', {channel: unit-exposure predictions})`` of
        the grid points at the search's eta.
        """
        from scipy import optimize

        grid_a, grid_s, unit = grid
        exposures = sorted({round(float(point[2]), 3) for points in ranked.values()
                            for point in points})
        exposures.append(float(np.mean([points[0][2] for points in ranked.values()])))
        candidates = []
        for exposure in exposures:
            picks = {}
            for c, points in ranked.items():
                mean, stderr, dof = self._search_observations(c, grid=False)
                loglike = student_t_log_likelihood(mean - np.exp(exposure) * unit[c], stderr,
                                                   dof)
                best_grid = np.argsort(np.where(np.isfinite(loglike), loglike, -np.inf))
                starts = [point[:2] for point in points] + [
                    np.array([grid_a[k], grid_s[k]]) for k in best_grid[::-1][:SHARED_GRID_STARTS]]

                def objective(x, c=c, exposure=exposure):
                    return -float(self._channel_log_likelihood(c, [x[0], x[1], exposure],
                                                               eta)[0])

                results = [optimize.minimize(objective, start, method="L-BFGS-B",
                                             bounds=bounds, options={"maxiter": 200})
                           for start in starts]
                best = min(results, key=lambda result: result.fun)
                picks[c] = np.array([best.x[0], best.x[1], exposure])
            candidates.append(self._channel_theta(picks, eta))
        candidates = np.array(candidates)
        return candidates[int(np.argmax(self.log_probability(candidates)))]

    def _channel_theta(self, picks, eta) -> np.ndarray:
        """Return a parameter vector from per-channel (ln sigma_a, ln sigma_s', ln exposure)."""
        theta = np.zeros(self.ndim)
        fallback = picks[self.channels[0]]
        for c in range(3):
            theta[c], theta[3 + c] = picks.get(c, fallback)[:2]
        index = 6
        if self.fit_eta:
            theta[index] = eta
            index += 1
        if self.fit_exposure:
            theta[index] = float(np.mean([point[2] for point in picks.values()]))
        return np.clip(theta, self.bounds[:, 0], self.bounds[:, 1])

    def _grid_theta(self, grid_a, grid_s, grid_eta, picks, scale) -> np.ndarray:
        """Return a parameter vector from per-channel grid indices and one exposure."""
        theta = np.zeros(self.ndim)
        fallback = picks[self.channels[0]]
        for c in range(3):
            k = picks.get(c, fallback)
            theta[c], theta[3 + c] = grid_a[k], grid_s[k]
        index = 6
        if self.fit_eta:
            theta[index] = float(np.median([grid_eta[k] for k in picks.values()]))
            index += 1
        if self.fit_exposure:
            theta[index] = np.log(scale)
        return np.clip(theta, self.bounds[:, 0], self.bounds[:, 1])

    def material(self, values: dict[str, float]) -> dict:
        """Return the material dict (``type = "dipole"``) of physical parameter values."""
        sigma_a = [float(values[f"sigma_a[{c}]"]) for c in CHANNELS]
        sigma_s_prime = [float(values[f"sigma_s_prime[{c}]"]) for c in CHANNELS]
        eta = float(values["eta"]) if self.fit_eta else float(self.split(
            np.zeros((1, self.ndim)))[2][0])
        return {"type": "dipole", "sigma_a": sigma_a, "sigma_s_prime": sigma_s_prime,
                "eta": eta, "g": 0.0}


def check_semi_infinite_reflection(spec: CaptureSpec, model: str) -> None:
    """Refuse a capture a semi-infinite reflection table cannot predict (naming ``model``)."""
    if spec.side != "reflection":
        raise InputError(f"the {model} model tabulates reflection only; fit a transmission "
                         "capture with --model dipole (the slab multipole)", field="side",
                         value=spec.side)
    if spec.thickness_mm is not None:
        raise InputError(f"the {model} model tabulates a semi-infinite slab; fit a slab of "
                         "finite thickness with --model dipole (the slab multipole)",
                         field="thickness_mm", value=spec.thickness_mm)


class ReducedTableModel(DipoleModel):
    r"""A profile read from a table in reduced units, with the dipole's parameters.

    :math:`R(r) = \sigma'^2_t \hat R(\sigma'_t r; \alpha', \eta)`, the table (``self.table``,
    set by the subclass before this class's ``__init__``) giving :math:`\hat R` and the
    exitance within a reduced radius. The node at r = 0, where a profile may diverge like
    1/r, gets the value that gives the first grid interval its exact share of the exitance.
    """

    def unit_profiles(self, sigma_a, sigma_s_prime, eta) -> np.ndarray:
        """Return the exitance per unit entering power at the nodes, mm^-2, (n, nodes, 3)."""
        nodes = self.profile.operator.grid.nodes
        sigma_t = sigma_a + sigma_s_prime  # (n, 3)
        albedo = sigma_s_prime / sigma_t
        eta = np.broadcast_to(np.asarray(eta, dtype=np.float64)[:, None], albedo.shape)
        reduced = sigma_t[..., None] * nodes[1:]  # (n, 3, nodes - 1)
        values = self.table.reduced_profile(reduced, albedo, eta) * sigma_t[..., None] ** 2
        # node 0: the linear interpolant's integral over [0, r1] equals the exitance there
        r1 = nodes[1]
        inside = self.table.reduced_cumulative(sigma_t * r1, albedo, eta) / (2.0 * np.pi)
        first = 6.0 * (inside / r1 ** 2 - values[..., 0] / 3.0)
        return np.moveaxis(np.concatenate([first[..., None], values], axis=-1), 1, -1)


class WalkModel(ReducedTableModel):
    r"""The photon random walk's own profile, tabulated, with per-channel coefficients.

    The parameters, priors, starting points and material file are the dipole's
    (:class:`DipoleModel`); the profile is the semi-infinite slab's reflectance of the walk
    of :mod:`translucent.fitting.random_walk` (exact Fresnel boundary, isotropic
    scattering), read from the table of :mod:`translucent.fitting.walk_table` in reduced
    units: :math:`R(r) = \sigma'^2_t \hat R(\sigma'_t r; \alpha', \eta)`. The node at
    r = 0, where single scattering makes the profile diverge like 1/r, gets the value that
    gives the first grid interval its exact share of the exitance.

    Parameters
    ----------
    profile, spec, fit_eta
        As :class:`DipoleModel`.

    Raises
    ------
    InputError
        For a slab of finite thickness or a transmission capture (the table is the
        semi-infinite reflectance), or an eta outside the table.
    """

    def __init__(self, profile: RadialProfile, spec: CaptureSpec, *, fit_eta: bool | None = None):
        from ..materials.profiles.random_walk import load_table

        check_semi_infinite_reflection(spec, "walk")
        self.table = load_table()
        if spec.eta is not None:
            self.table.check_eta(spec.eta)
        # the table spans ETA_FIT_RANGE (a test checks it), so the dipole's eta prior holds
        super().__init__(profile, spec, fit_eta=fit_eta)

    def residual_scale(self, channel: int, stderr, predicted, theta) -> np.ndarray:
        r"""Return the standard errors with the table's own noise added, per annulus.

        :math:`\sqrt{s^2 + (\epsilon\,\mu)^2}`, with :math:`\epsilon` the table's
        relative standard error (:meth:`~.walk_table.WalkProfileTable.relative_error`) at
        the annulus's mid radius in this channel's reduced units: the prediction is a Monte
        Carlo estimate too, and without its noise the intervals were too narrow.
        """
        theta = np.atleast_2d(np.asarray(theta, dtype=np.float64))
        sigma_a, sigma_s_prime, eta, _ = self.split(theta)
        sigma_t = sigma_a[:, channel] + sigma_s_prime[:, channel]
        radius = self._annulus_radius(channel)
        epsilon = self.table.relative_error(sigma_t[:, None] * radius[None, :],
                                            sigma_s_prime[:, channel] / sigma_t, eta)
        return np.sqrt(stderr ** 2 + (epsilon * predicted) ** 2)

    def scale_normalisation(self, scale) -> np.ndarray:
        """Return ``sum(ln scale)`` per row: the table's part varies with the parameters."""
        return np.sum(np.log(scale), axis=-1)

    def _annulus_radius(self, channel: int) -> np.ndarray:
        """Mid radius of each annulus of ``channel`` that enters the fit, mm."""
        edges = self.profile.edges_mm
        return (0.5 * (edges[:-1] + edges[1:]))[self.profile.used[:, channel]]


#: The most segments a fitted SubEdit profile may have (as a converted one,
#: :func:`translucent.materials.subedit.subedit_from_dipole`).
MAX_SEGMENTS = 1024


class SubEditModel(ProfileModel):
    r"""SubEdit profile: ``n + 1`` knots of :math:`\ln P` per channel (Chen et al. 2012, Eq. 9).

    The exitance is :math:`P(r)` (for a homogeneous material Eq. 8 of Chen et al. gives
    :math:`R_d = P`). With the exposure known, :math:`P` is absolute (mm^-2); unknown, the
    exposure is absorbed into :math:`P` (relative profile). The smoothness prior is a
    Gaussian of standard deviation ``smoothness`` on the second differences of the knot
    values.

    Parameters
    ----------
    profile : RadialProfile
    spec : CaptureSpec
    segments : int
        n, >= 2.
    r_s_mm : float, optional
        Maximum scattering radius (default: the outer edge of the last used annulus).
    smoothness : float
        Prior standard deviation of second differences of ln P, nats, > 0.
    channels : tuple of int
        Channels modelled (each channel's posterior is independent of the others).
    """

    def __init__(self, profile: RadialProfile, spec: CaptureSpec, *, segments: int = 8,
                 r_s_mm: float | None = None, smoothness: float = SUBEDIT_SMOOTHNESS,
                 channels=(0, 1, 2)):
        super().__init__(profile, spec)
        if not 2 <= int(segments) <= MAX_SEGMENTS:  # SubEdit profiles' own bound
            raise InputError(f"must be in [2, {MAX_SEGMENTS}]", field="segments",
                             value=segments)
        if not (np.isfinite(smoothness) and smoothness > 0):
            raise InputError("must be > 0 and finite, nats", field="smoothness",
                             value=smoothness)
        self.segments = int(segments)
        self.smoothness = float(smoothness)
        self.channels = tuple(c for c in channels if self._observations[c][0].size >= 2)
        if not self.channels:
            raise InputError("no requested channel has usable annuli", field="channels",
                             value=channels)
        if r_s_mm is None:
            last = max(int(np.flatnonzero(profile.used[:, c])[-1]) for c in self.channels)
            r_s_mm = float(profile.edges_mm[last + 1])
        if not (np.isfinite(r_s_mm) and r_s_mm > 0):
            raise InputError("must be > 0 and finite, mm", field="r_s_mm", value=r_s_mm)
        self.r_s_mm = float(r_s_mm)
        self.knots = np.linspace(0.0, self.r_s_mm, self.segments + 1)
        self._matrix, self._support = self._interpolation()
        self.exposure = 1.0 if spec.exposure is None else float(spec.exposure)
        peak = max(float(np.nanmax(self._observations[c][0])) for c in self.channels)
        centre = np.log(max(peak, 1e-300) / self.exposure)
        params = []
        for c in self.channels:
            for k in range(self.segments + 1):
                params.append(ParameterInfo(f"ln_p{k}[{CHANNELS[c]}]", "ln_p", "linear",
                                            centre - KNOT_BOX_NATS[0], centre + KNOT_BOX_NATS[1],
                                            c, "ln mm^-2" if spec.exposure else "ln (relative)"))
        self.parameters = params

    def knot_values(self, theta) -> np.ndarray:
        """Knot values per modelled channel, shape (n, channels, segments + 1)."""
        theta = np.atleast_2d(theta)
        return theta.reshape(theta.shape[0], len(self.channels), self.segments + 1)

    def _interpolation(self):
        """Eq. 9 as a matrix on the knot values, built with ``SubEditProfiles`` itself.

        ``ln P`` is linear in the knot values, so evaluating textures whose knot values are
        unit vectors gives the matrix ``L`` with ``ln P(nodes) = L @ knots``; a texture of
        zeros marks the nodes outside the support (``r >= r_s``, where P = 0).
        """
        count = self.segments + 1
        nodes = self.profile.operator.grid.nodes
        basis = np.zeros((count, 1, count, 3))
        basis[np.arange(count), 0, np.arange(count), :] = 1.0
        values = SubEditProfiles(basis, self.r_s_mm).log_profile_at(
            nodes[None, :], np.arange(count)[:, None])[..., 0]
        support = SubEditProfiles(np.zeros((1, 1, count, 3)), self.r_s_mm).log_profile_at(
            nodes)[..., 0] > LOG_FLOOR
        return np.where(support[None, :], values, 0.0).T, support

    def profile_nodes(self, theta):
        """Exposure times P(r) at the nodes, shape (n, nodes, 3) (0 in channels not modelled).

        P is Eq. 9 of Chen et al. 2012 as :class:`~translucent.materials.subedit.SubEditProfiles`
        evaluates it (through the matrix of :meth:`_interpolation`).
        """
        knots = self.knot_values(theta)
        out = np.zeros((knots.shape[0], self.profile.operator.grid.size, 3))
        with np.errstate(under="ignore", over="ignore"):
            for i, c in enumerate(self.channels):
                out[:, :, c] = self.exposure * np.exp(knots[:, i] @ self._matrix.T) \
                    * self._support
        return out

    def extra_log_prior(self, theta):
        """Smoothness: Gaussian second differences of the knot values, shape (n,)."""
        second = np.diff(self.knot_values(theta), n=2, axis=-1)
        return -0.5 * np.sum((second / self.smoothness) ** 2, axis=(1, 2))

    def initial_guess(self) -> np.ndarray:
        """Ln of the measured annulus means at the knots (linear inter-/extrapolation)."""
        theta = []
        for c in self.channels:
            use = self.profile.used[:, c]
            # saturated annuli hold clipped means, below the profile: left out of the start
            radius = self.profile.radius_mm[use, c][self._linear[c]]
            mean = self.profile.mean[use, c][self._linear[c]]
            positive = mean > 0
            log_mean = np.log(mean[positive] / self.exposure)
            radius = radius[positive]
            values = np.interp(self.knots, radius, log_mean)
            if radius.size >= 2:  # extrapolate linearly beyond the measured range
                slope_in = (log_mean[1] - log_mean[0]) / max(radius[1] - radius[0], 1e-12)
                slope_out = (log_mean[-1] - log_mean[-2]) / max(radius[-1] - radius[-2], 1e-12)
                values = np.where(self.knots < radius[0],
                                  log_mean[0] + slope_in * (self.knots - radius[0]), values)
                values = np.where(self.knots > radius[-1],
                                  log_mean[-1] + slope_out * (self.knots - radius[-1]), values)
            theta.append(values)
        theta = np.concatenate(theta)
        return np.clip(theta, self.bounds[:, 0], self.bounds[:, 1])

    def material(self, values: dict[str, float]) -> dict:
        """Return the SubEdit profile dict (``type = "subedit"``) of physical knot values."""
        log_profile = [[float(values[f"ln_p{k}[{CHANNELS[c]}]"]) if c in self.channels else None
                        for k in range(self.segments + 1)] for c in range(3)]
        return {"type": "subedit", "r_s": self.r_s_mm, "segments": self.segments,
                "log_profile": log_profile, "absolute": self.spec.exposure is not None}

    def texture(self, values: dict[str, float]) -> SubEditProfiles:
        """Return a 1 x 1 :class:`SubEditProfiles` of physical knot values.

        Channels not modelled hold the floor (a zero profile).
        """
        table = np.full((1, 1, self.segments + 1, 3), LOG_FLOOR)
        for c in self.channels:
            table[0, 0, :, c] = [values[f"ln_p{k}[{CHANNELS[c]}]"]
                                 for k in range(self.segments + 1)]
        return SubEditProfiles(table, self.r_s_mm, eta=self.spec.eta or 1.3,
                               name="fitted SubEdit profile")
