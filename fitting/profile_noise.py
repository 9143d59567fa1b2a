r"""The noise of a capture's pixels, pooled over its annuli, and annuli clipped from above.

Two things a radial profile needs beyond each annulus's own scatter
(:mod:`translucent.fitting.profile`):

* **Pooled standard errors.** An annulus's pixel variance :math:`s^2` from its own scatter
  has only :math:`\nu = N - 2` degrees of freedom (10 to 30 near the beam, where the
  profile is best measured). Weighting annuli by such noisy variances made the posteriors
  too narrow: measured on 30 dipole captures (48 x 48, peak 40000), the squared Mahalanobis
  distance of the truth from the MAP point averaged 8.7 for 7 parameters, and 7.1 with each
  annulus's true variance. A camera's noise is a smooth function of the signal (read noise,
  shot noise, a gain spread): :func:`fit_noise_model` fits
  :math:`\sigma_0^2(\mu) = a + b\mu + c\mu^2` to the annuli's variances, and
  :meth:`NoiseModel.moderate` pools each annulus's variance with it as the empirical Bayes
  "moderated" variance of Smyth (2004),

  .. math:: \tilde s^2 = \frac{d_0 \sigma_0^2(\bar v) + \nu s^2}{d_0 + \nu},

  a Student-t with :math:`d_0 + \nu` degrees of freedom, where the prior degrees of freedom
  :math:`d_0` say how closely the annuli's variances follow the model (Eq. 8-9 of Smyth
  2004: from the spread of :math:`\ln s^2` beyond its sampling spread
  :math:`\psi'(\nu/2)`). Annuli whose scatter the model does not describe (more than
  :data:`NOISE_OUTLIER` sampling standard deviations away: structure within the annulus,
  a defect) keep their own.
* **Clipped annuli** (:class:`CeilingCensoring`): an annulus holding saturated pixels is
  predicted as the mean of :math:`E[\min(X, S)]` over its pixels
  (:func:`clipped_normal_mean`), each pixel's :math:`X \sim N(\mu, \sigma_0^2(\mu))`.

Reference: G. K. Smyth, Linear models and empirical Bayes methods for assessing
differential expression in microarray experiments, Statistical Applications in Genetics
and Molecular Biology 3 (2004), article 3.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

__all__ = ["CeilingCensoring", "NoiseModel", "clipped_normal_mean", "fit_noise_model"]

#: Reweighting passes of the noise model's least squares (the weights depend on the fit).
NOISE_MODEL_PASSES = 5
#: An annulus whose log pixel variance lies more than this many of its sampling standard
#: deviations (:math:`\sqrt{\psi'(\nu / 2)}`) from the model's is left out of the fit and
#: keeps its own variance: 4 rejects about 1 in 10^4 normal annuli.
NOISE_OUTLIER = 4.0
#: Degrees of freedom standing for "the variances follow the model exactly" (a Student-t
#: of 10^6 degrees of freedom is a normal law to 1e-6).
MAX_DEGREES = 10 ** 6


def clipped_normal_mean(mu, sigma, ceiling):
    r"""Return the expectation of a normal variable clipped from above, :math:`E[\min(X, S)]`.

    For :math:`X \sim N(\mu, \sigma^2)` and :math:`e = (S - \mu) / \sigma`,

    .. math:: E[\min(X, S)] = S - (S - \mu)\,\Phi(e) - \sigma\,\phi(e),

    (:math:`S - E[(S - X)^+]`, the expected shortfall of the normal law below S): ``mu``
    far below the ceiling gives ``mu``, far above it ``S``.

    Parameters
    ----------
    mu, sigma : array_like
        Mean and standard deviation of the unclipped value (signal units); ``sigma >= 0``
        (0: the value itself, clipped).
    ceiling : float
        The clip level S, same units.

    Returns
    -------
    ndarray
        Broadcast shape of ``mu`` and ``sigma``.
    """
    from scipy import special

    mu = np.asarray(mu, dtype=np.float64)
    sigma = np.asarray(sigma, dtype=np.float64)
    positive = sigma > 0
    safe = np.where(positive, sigma, 1.0)
    # far from the ceiling in units of sigma, e^2 overflows and phi(e) is 0: both limits hold
    e = np.clip((ceiling - mu) / safe, -1e100, 1e100)
    value = ceiling - (ceiling - mu) * special.ndtr(e) \
        - safe * np.exp(-0.5 * np.minimum(e * e, 1e4)) / np.sqrt(2.0 * np.pi)
    return np.where(positive, value, np.minimum(mu, ceiling))


@dataclass(frozen=True)
class NoiseModel:
    r"""A channel's pixel noise against its signal, and how closely the annuli follow it.

    Attributes
    ----------
    coefficients : (float, float, float)
        :math:`(a, b, c)` of :math:`\sigma_0^2(\mu) = a + b\mu + c\mu^2`, signal units.
    prior_dof : float
        :math:`d_0` (inf: the annuli's variances scatter only as sampling allows).
    """

    coefficients: tuple[float, float, float]
    prior_dof: float

    def variance(self, mu) -> np.ndarray:
        """Pixel variance at signal ``mu`` (negative signal counts as 0)."""
        a, b, c = self.coefficients
        mu = np.clip(np.asarray(mu, dtype=np.float64), 0.0, None)
        return a + mu * (b + c * mu)

    @property
    def degrees(self) -> int:
        """The degrees of freedom of a variance read from the model alone (capped)."""
        return int(min(self.prior_dof, MAX_DEGREES))

    def moderate(self, pixel_variance, dof, mean) -> tuple[np.ndarray, np.ndarray]:
        r"""Pooled pixel variances and their degrees of freedom (Smyth 2004, Eq. 9).

        Parameters
        ----------
        pixel_variance, dof, mean : array_like, shape (n,)
            Each annulus's own pixel variance :math:`s^2`, its degrees of freedom
            :math:`\nu` and its mean signal.

        Returns
        -------
        (ndarray, ndarray of int)
            :math:`\tilde s^2` and :math:`\nu + d_0` (capped at :data:`MAX_DEGREES`).
        """
        s2 = np.asarray(pixel_variance, dtype=np.float64)
        nu = np.asarray(dof, dtype=np.float64)
        prior = self.variance(mean)
        if not math.isfinite(self.prior_dof):
            return prior, np.full(nu.shape, MAX_DEGREES, dtype=np.int64)
        d0 = self.prior_dof
        pooled = (d0 * prior + nu * s2) / (d0 + nu)
        return pooled, np.minimum(np.rint(nu + d0), MAX_DEGREES).astype(np.int64)


def _inverse_trigamma(value: float) -> float:
    """``x`` with ``polygamma(1, x) == value`` (> 0); the trigamma falls from inf to 0."""
    from scipy import optimize, special

    # psi'(x) ~ 1/x + 1/(2 x^2) for large x, ~ 1/x^2 for small x: bracket around both
    low, high = 1e-8, max(10.0 / value, 10.0)
    return float(optimize.brentq(lambda x: special.polygamma(1, x) - value, low, high,
                                 xtol=1e-12 * high))


def fit_noise_model(mean, pixel_variance, dof) -> tuple[NoiseModel | None, np.ndarray]:
    r"""Fit a channel's noise model to its annuli; tell which annuli it does not describe.

    The coefficients :math:`a, b, c \ge 0` come from non-negative least squares, each
    annulus weighted by the inverse of its variance's sampling standard deviation
    :math:`\sigma_0^2 \sqrt{2 / \nu}` (its own variance in the first pass, the fit's
    after), reweighted a few times; annuli whose :math:`\ln s^2` lies more than
    :data:`NOISE_OUTLIER` sampling standard deviations from the fit's are left out of the
    next pass. Then the
    model is scaled to the annuli's log-variances and :math:`d_0` estimated (Smyth 2004,
    Section 6.2): with :math:`e = \ln s^2 - \ln\sigma_0^2 - \psi(\nu/2) + \ln(\nu/2)`,
    :math:`\psi'(d_0/2) = \mathrm{Var}(e) - \overline{\psi'(\nu/2)}` (inf where that is not
    positive) and the scale :math:`\exp(\bar e + \psi(d_0/2) - \ln(d_0/2))`.

    Parameters
    ----------
    mean : array_like, shape (n,)
        Annulus means (signal units).
    pixel_variance : array_like, shape (n,)
        The variance of one pixel about the annulus's straight line in radius, > 0.
    dof : array_like, shape (n,)
        Its degrees of freedom, > 0.

    Returns
    -------
    (NoiseModel or None, ndarray of bool)
        The model (None with fewer than 3 annuli the model describes) and the annuli left
        out as outliers.
    """
    from scipy import optimize, special

    mean = np.asarray(mean, dtype=np.float64)
    s2 = np.asarray(pixel_variance, dtype=np.float64)
    nu = np.asarray(dof, dtype=np.float64)
    valid = np.isfinite(s2) & (s2 > 0) & np.isfinite(mean) & (nu > 0)
    if valid.sum() < 3:
        return None, ~valid
    mean = np.clip(np.where(valid, mean, 0.0), 0.0, None)
    s2 = np.where(valid, s2, 1.0)
    nu = np.where(valid, nu, 1.0)
    half = nu / 2.0
    # ln s^2 about ln sigma^2: offset psi(nu/2) - ln(nu/2), spread psi'(nu/2)
    offset = special.digamma(half) - np.log(half)
    spread = np.sqrt(special.polygamma(1, half))
    scale = max(float(mean.max()), 1.0)  # columns of one order: a well-conditioned design
    design = np.stack([np.ones_like(mean), mean / scale, (mean / scale) ** 2], axis=1)
    fitted = s2  # the first pass weighs each annulus by its own variance
    outlier = ~valid
    for _ in range(NOISE_MODEL_PASSES):
        use = ~outlier
        weight = np.sqrt(nu[use] / 2.0) / fitted[use]
        coefficients, _ = optimize.nnls(design[use] * weight[:, None], s2[use] * weight)
        fitted = design @ coefficients
        if not np.all(fitted[valid] > 0):
            return None, ~valid
        distance = np.abs(np.log(s2 / fitted) - offset) / spread
        now = ~valid | (distance > NOISE_OUTLIER)
        if (~now).sum() < 3 or np.array_equal(now, outlier):
            break
        outlier = now
    use = ~outlier
    half = half[use]
    e = np.log(s2[use]) - np.log(fitted[use]) - offset[use]
    excess = float(np.var(e, ddof=1)) - float(np.mean(special.polygamma(1, half))) \
        if use.sum() > 1 else 0.0
    d0 = 2.0 * _inverse_trigamma(excess) if excess > 1e-12 else math.inf
    shift = float(np.mean(e))
    if math.isfinite(d0):
        shift += float(special.digamma(d0 / 2.0) - np.log(d0 / 2.0))
    a, b, c = coefficients * math.exp(shift)
    return NoiseModel((float(a), float(b / scale), float(c / scale ** 2)), d0), outlier


@dataclass(frozen=True)
class CeilingCensoring:
    r"""The annuli of one channel that hold saturated pixels, predicted as clipped means.

    Such an annulus is measured by the mean of :math:`\min(v, S)` over all its pixels
    (saturated ones at the ceiling S) and predicted as
    :math:`\frac{1}{N}\sum_i E[\min(X_i, S)]` (:func:`clipped_normal_mean`), with
    :math:`\mu_i` the exact footprint average of pixel i and
    :math:`\sigma_i^2 = \sigma_0^2(\mu_i)` the channel's noise model.

    Parameters
    ----------
    rows : ndarray of int
        The annuli, as indices into the channel's used annuli.
    pixel_matrix : ndarray or scipy.sparse matrix, shape (pixels, grid size)
        Beam convolution then the exact footprint average of each of their pixels (sparse
        where most entries are 0: a pixel sees a few grid rings unless the beam is wide).
    averaging : ndarray, shape (len(rows), pixels)
        ``1 / N`` where the pixel belongs to the annulus, else 0.
    ceiling : float
        S, signal units (stored units above black).
    noise : NoiseModel
    """

    rows: np.ndarray
    pixel_matrix: Any
    averaging: np.ndarray
    ceiling: float
    noise: NoiseModel

    def predict(self, profile_nodes) -> np.ndarray:
        """Clipped annulus means for profiles at the nodes, (..., grid size) -> (..., rows)."""
        profile_nodes = np.asarray(profile_nodes)
        flat = profile_nodes.reshape(-1, profile_nodes.shape[-1])
        # (pixels x nodes) @ (nodes x profiles): the matrix may be sparse (a narrow beam)
        mu = np.asarray(self.pixel_matrix @ flat.T).T.reshape(
            profile_nodes.shape[:-1] + (self.averaging.shape[1],))
        sigma = np.sqrt(self.noise.variance(mu))
        return clipped_normal_mean(mu, sigma, self.ceiling) @ self.averaging.T
