r"""Does the model fit? Goodness-of-fit tests of a posterior, and a model-discrepancy term.

A posterior's intervals are only as honest as the model under them: a dipole fitted to a
material that is not a dipole gives tight, wrong intervals. Every fit is therefore tested,
channel by channel, on its annulus residuals :math:`z_i = (y_i - \mu_i(\theta)) / s_i`
(measured annulus mean, predicted mean, standard error):

* **reduced chi-square** :math:`\chi^2_\nu = \sum_i z_i^2 / (m - k)` at the best posterior
  sample (m annuli, k parameters of the channel; shared parameters split between channels);
* **posterior-predictive p-value** (Gelman, Meng and Stern 1996): for posterior draws
  :math:`\theta_s`, replicated data :math:`y^{rep} = \mu(\theta_s) + s\,t_{\nu_i}` drawn from
  the likelihood itself (Student's t with the annuli's degrees of freedom), and
  :math:`p = P(T(y^{rep}, \theta) \ge T(y, \theta))` with :math:`T = \sum_i z_i^2`;
* **runs test** (Wald and Wolfowitz 1940) on the signs of the residuals ordered by radius:
  a model of the wrong shape leaves long runs of one sign (a smooth trend) that a sum of
  squares can miss when the errors are large.

The model is rejected (``misfit``) when any of these p-values, Bonferroni-corrected over
the tests and channels, falls below :data:`SIGNIFICANCE`.

When it is rejected, :class:`DiscrepancyModel` adds a fractional model-discrepancy term per
channel (the ``ln f`` of emcee's line-fitting example): the likelihood's scale becomes
:math:`\sqrt{s_i^2 + f_c^2 \mu_i^2}`, so that the intervals widen to what the misfit
allows; they are reported beside the model-conditional ones.

References
----------
- A. Gelman, X.-L. Meng, H. Stern: Posterior predictive assessment of model fitness via
  realized discrepancies. Statistica Sinica 6, 1996.
- A. Wald, J. Wolfowitz: On a test whether two samples are from the same population. Ann.
  Math. Statist. 11(2), 1940.
- D. Foreman-Mackey et al.: emcee, "Fitting a model to data" tutorial (the ``ln f`` term).
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numpy as np
from scipy import stats

from .models import ParameterInfo, ProfileModel

__all__ = ["SIGNIFICANCE", "PREDICTIVE_DRAWS", "ChannelFit", "GoodnessOfFit",
           "DiscrepancyModel", "best_sample", "goodness_of_fit", "runs_test"]

#: Family-wise significance of the misfit verdict (all tests, all channels).
SIGNIFICANCE = 0.01

#: Posterior draws of the posterior-predictive p-value (its resolution is 1 / draws).
PREDICTIVE_DRAWS = 4000

#: Fewest annuli for the runs test (below it the normal approximation does not hold).
RUNS_MIN_ANNULI = 10

#: Prior box of ln f, the fractional model discrepancy: from 1e-4 to 3 times the prediction.
LN_F_BOUNDS = (math.log(1e-4), math.log(3.0))

CHANNELS = "RGB"


def runs_test(residuals) -> tuple[int, float, float]:
    """Wald-Wolfowitz runs test for too few runs of one sign (one-sided).

    Parameters
    ----------
    residuals : array_like, shape (m,)
        In their natural order (radius); zeros count as positive.

    Returns
    -------
    runs : int
        Runs of equal sign.
    expected : float
        Their expected number for independent signs with the same counts.
    p_value : float
        Probability of this few runs or fewer (normal approximation); 1 for fewer than
        :data:`RUNS_MIN_ANNULI` residuals or residuals of one sign only.
    """
    signs = np.asarray(residuals, dtype=np.float64) >= 0
    n = signs.size
    if n == 0:
        return 0, 0.0, 1.0
    runs = int(1 + np.count_nonzero(signs[1:] != signs[:-1]))
    plus = int(signs.sum())
    minus = n - plus
    if n < RUNS_MIN_ANNULI or plus == 0 or minus == 0:
        expected = float(runs) if plus == 0 or minus == 0 else 2.0 * plus * minus / n + 1.0
        return runs, expected, 1.0
    expected = 2.0 * plus * minus / n + 1.0
    variance = (expected - 1.0) * (expected - 2.0) / (n - 1.0)
    if variance <= 0:
        return runs, expected, 1.0
    z = (runs - expected) / math.sqrt(variance)
    return runs, expected, float(stats.norm.cdf(z))


@dataclass(frozen=True)
class ChannelFit:
    """The goodness of fit of one channel.

    Attributes
    ----------
    channel : str
        ``"R"``, ``"G"`` or ``"B"``.
    annuli : int
        Annulus means fitted.
    parameters : float
        Parameters of the channel (shared ones split between channels).
    chi_square, reduced_chi_square : float
        At the best posterior sample.
    largest_residual : float
        Largest ``|z|`` (standard errors).
    predictive_p : float
        Posterior-predictive p-value of the sum of squared residuals.
    runs, runs_expected : int, float
        Runs of one sign in the residuals, and their expected number.
    runs_p : float
        One-sided p-value of so few runs.
    misfit : bool
        The channel rejects the model.
    """

    channel: str
    annuli: int
    parameters: float
    chi_square: float
    reduced_chi_square: float
    largest_residual: float
    predictive_p: float
    runs: int
    runs_expected: float
    runs_p: float
    misfit: bool

    def text(self) -> str:
        """Return one line: the figures and the channel's verdict."""
        verdict = "MODEL MISFIT" if self.misfit else "fits"
        return (f"{self.channel}: {verdict}: reduced chi-square {self.reduced_chi_square:.3g} "
                f"over {self.annuli} annuli, largest residual {self.largest_residual:.3g} "
                f"standard errors, posterior-predictive p {self.predictive_p:.3g}, "
                f"{self.runs} runs of one sign (expected {self.runs_expected:.3g}, "
                f"p {self.runs_p:.3g})")


@dataclass(frozen=True)
class GoodnessOfFit:
    """The goodness of fit of every fitted channel and the verdict.

    Attributes
    ----------
    channels : tuple of ChannelFit
    threshold : float
        The per-test significance (Bonferroni: :data:`SIGNIFICANCE` over the tests).
    """

    channels: tuple
    threshold: float

    @property
    def misfit(self) -> bool:
        """True when any channel rejects the model."""
        return any(channel.misfit for channel in self.channels)

    @property
    def verdict(self) -> str:
        """``"model misfit"`` or ``"fits"``."""
        return "model misfit" if self.misfit else "fits"

    def summary(self) -> dict:
        """Return the verdict and every channel's figures, JSON-able."""
        return {"verdict": self.verdict, "significance": SIGNIFICANCE,
                "per_test_threshold": self.threshold,
                "channels": [asdict(channel) for channel in self.channels]}


def _channel_parameters(model: ProfileModel) -> dict[int, float]:
    """Parameters per fitted channel: its own plus a share of the shared ones."""
    own = {c: 0 for c in model.channels}
    shared = 0
    for info in model.parameters:
        if info.kind == "ln_f":
            continue
        if info.channel is None:
            shared += 1
        elif info.channel in own:
            own[info.channel] += 1
    return {c: own[c] + shared / max(len(own), 1) for c in own}


def best_sample(model: ProfileModel, samples: np.ndarray) -> np.ndarray:
    """Return the posterior sample of highest likelihood (a stand-in for the MAP point)."""
    subset = samples[:: max(1, samples.shape[0] // 2000)]
    values = model.log_likelihood(subset)
    return subset[int(np.argmax(values))]


def goodness_of_fit(model: ProfileModel, samples, *, draws: int = PREDICTIVE_DRAWS,
                    seed: int = 0) -> GoodnessOfFit:
    """Test a fitted posterior against its own data (module docstring).

    Parameters
    ----------
    model : ProfileModel
        The model the samples were drawn for (a :class:`DiscrepancyModel` too: its
        inflated standard errors are then the ones tested against).
    samples : ndarray, shape (m, ndim)
        Flat posterior samples in the sampling space.
    draws : int
        Posterior draws of the predictive p-value.
    seed : int
        Seeds the draws (the verdict is deterministic).

    Returns
    -------
    GoodnessOfFit
    """
    samples = np.atleast_2d(np.asarray(samples, dtype=np.float64))
    rng = np.random.default_rng(seed)
    picks = samples[rng.integers(0, samples.shape[0], size=draws)]
    best = best_sample(model, samples)
    parameters = _channel_parameters(model)
    tests = 2 * max(len(model.channels), 1)
    threshold = SIGNIFICANCE / tests
    predicted_draws = model.predictions(picks)
    predicted_best = model.predictions(best[None, :])
    channels = []
    for c in model.channels:
        mean, stderr, dof = model.observations(c)
        scale_draws = model.residual_scale(c, stderr, predicted_draws[c], picks)
        scale_best = model.residual_scale(c, stderr, predicted_best[c], best[None, :])
        z_best = (mean - predicted_best[c][0]) / scale_best[0]
        chi_square = float(np.sum(z_best**2))
        free = max(mean.size - parameters[c], 1.0)
        observed = np.sum(((mean - predicted_draws[c]) / scale_draws) ** 2, axis=1)
        replicated = np.sum(rng.standard_t(dof, size=predicted_draws[c].shape) ** 2, axis=1)
        predictive_p = float(np.mean(replicated >= observed))
        runs, expected, runs_p = runs_test(z_best)
        misfit = predictive_p < threshold or runs_p < threshold
        channels.append(ChannelFit(CHANNELS[c], int(mean.size), float(parameters[c]),
                                   chi_square, chi_square / free,
                                   float(np.max(np.abs(z_best))), predictive_p, runs,
                                   expected, runs_p, bool(misfit)))
    return GoodnessOfFit(tuple(channels), threshold)


class DiscrepancyModel(ProfileModel):
    r"""A profile model with a fractional model-discrepancy term ``ln f`` per channel.

    The likelihood's scale of annulus i of channel c becomes
    :math:`\sqrt{s_i^2 + f_c^2 \mu_i^2}` (Student's t as before, now with its
    normalisation, since the scale varies). Everything else is the base model's.

    Parameters
    ----------
    base : ProfileModel
        The model that misfits.
    start : ndarray, shape (base.ndim,), optional
        A good point of the base model (its best sample): the starting guess, with each
        ``ln f`` from the residual scatter there.
    """

    def __init__(self, base: ProfileModel, start=None):
        self.base = base
        self.profile = base.profile
        self.spec = base.spec
        self._observations = base._observations
        self.channels = base.channels
        self.evaluations = 0
        self.calls = 0
        self._base_ndim = base.ndim
        self.parameters = list(base.parameters) + [
            ParameterInfo(f"discrepancy[{CHANNELS[c]}]", "ln_f", "log", *LN_F_BOUNDS,
                          channel=c, unit="of the prediction")
            for c in base.channels]
        self._start = None if start is None else np.asarray(start, dtype=np.float64)

    def __getattr__(self, name):
        # what the base model offers beyond the ProfileModel interface (material, ...)
        if name == "base":
            raise AttributeError(name)
        return getattr(self.base, name)

    def _split(self, theta):
        theta = np.atleast_2d(np.asarray(theta, dtype=np.float64))
        return theta[:, : self._base_ndim], theta[:, self._base_ndim:]

    def profile_nodes(self, theta):
        """Return the base model's predicted exitance (the ``ln f`` coordinates ignored)."""
        return self.base.profile_nodes(self._split(theta)[0])

    def extra_log_prior(self, theta):
        """Return the base model's extra prior."""
        return self.base.extra_log_prior(self._split(theta)[0])

    def material(self, values):
        """Return the base model's material table (the discrepancy left out)."""
        return self.base.material({k: v for k, v in values.items()
                                   if not k.startswith("discrepancy")})

    def residual_scale(self, channel, stderr, predicted, theta):
        """Return the base model's scale inflated by the discrepancy, ``sqrt(s^2 + f^2 mu^2)``.

        ``s`` is the base model's own scale: the standard errors, plus what the model adds
        (the walk table's noise).
        """
        base_theta, ln_f = self._split(theta)
        scale = self.base.residual_scale(channel, stderr, predicted, base_theta)
        f = np.exp(ln_f[:, self.channels.index(channel)])[:, None]
        return np.sqrt(scale**2 + (f * predicted) ** 2)

    def scale_normalisation(self, scale):
        """Return ``sum(ln scale)`` per row: the inflated scale varies with ``ln f``."""
        return np.sum(np.log(scale), axis=-1)

    def _ln_f_start(self, base_theta):
        predicted = self.base.predictions(base_theta[None, :])
        values = []
        for c in self.channels:
            mean, stderr, _ = self._observations[c]
            excess = np.maximum((mean - predicted[c][0]) ** 2 - stderr**2, 0.0)
            f = math.sqrt(float(np.mean(excess / np.maximum(predicted[c][0] ** 2, 1e-300))))
            values.append(min(max(math.log(max(f, 1e-4)), LN_F_BOUNDS[0] + 0.1),
                              LN_F_BOUNDS[1] - 0.1))
        return np.array(values)

    def initial_guess(self):
        """Return the base model's start (or the given one), ``ln f`` from its residuals."""
        base_theta = self._start if self._start is not None else self.base.initial_guess()
        return np.concatenate([base_theta, self._ln_f_start(base_theta)])

    def initial_guesses(self, *args, **kwargs):
        """Return the optimiser's starts: :meth:`initial_guess` only."""
        return [self.initial_guess()]
