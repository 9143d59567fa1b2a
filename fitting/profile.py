r"""Radial profiles of a capture, and the operator that predicts them from a model profile.

Measurement (:func:`measure_profile`):

1. Pixels are masked per channel and counted: NaN/Inf, saturated (stored value at or above
   ``saturation_level``, or at the top code 65535 of an integer encoding) and below black
   (stored value below ``black_level``, or at the floor 0 of an integer encoding, where
   the noise has been clipped).
2. The incident point is refined to sub-pixel precision (:func:`refine_incident_point`).
3. Pixels are grouped into annuli about it (:func:`annulus_edges`): at least
   :data:`MIN_PIXELS_PER_ANNULUS` pixels each, 1 px wide near the centre, widening
   geometrically beyond.
4. Per annulus and channel: the mean of the valid pixels and its standard error from the
   annulus's own scatter, taken about a straight line in radius so that the profile's
   gradient across the annulus is not counted as noise (N - 2 degrees of freedom).
   That variance is pooled with the channel's noise model, a smooth function of the signal
   fitted to all its annuli (:mod:`translucent.fitting.profile_noise`): a variance from
   10-30 pixels alone is too noisy a weight.
   Pixels *censored at black* (a float image whose noise was clipped at the black level,
   as many cameras and HDR merges do: recognised by a pile-up of pixels exactly at it) are
   not measurements: an annulus holding some is estimated as a censored normal sample
   (Tobit regression on the same straight line, :func:`censored_line_fit`), which is
   unbiased where the plain mean of the clipped values is not, and which uses every pixel's
   footprint.
   Pixels *saturated* (censored from above) are kept too, at the ceiling: an annulus
   holding some is measured by the mean of its clipped values, ``min(v, S)`` over every
   pixel, and predicted as the expectation of that clipped mean (below), so no annulus is
   chosen by whether its noise crossed the ceiling.
5. Annuli are dropped (and counted) where the data cannot be used: the fully saturated
   annuli more than one inside the innermost one that still holds an unsaturated pixel
   (their pixels only say "above the ceiling", which a profile brighter towards the beam
   satisfies anyway); the first annulus whose below-black fraction exceeds
   :data:`BELOW_BLACK_FRACTION`, or whose censored fraction exceeds
   :data:`CENSORED_MAX_FRACTION` (the noise floor), and every annulus outside it; annuli
   with fewer than :data:`MIN_VALID_PIXELS` valid pixels; on request, annuli reaching
   inside ``r_min_mm``.

Prediction (:class:`ProfileOperator`): the mean of annulus ``a`` in channel ``c`` is
``exposure * (M_c @ f(nodes))[a]`` for a radial exitance profile ``f`` (mm^-2), with
``M_c = A_c K``: ``K`` the beam convolution (:mod:`translucent.fitting.beam`) and ``A_c``
the exact average over the annulus's valid pixel footprints (each pixel split into the
rings of the radial grid by exact disc-square overlap areas). An annulus holding
saturated pixels is predicted pixel by pixel (:class:`CeilingCensoring`): each pixel's
mean ``mu`` from its own footprint, its noise ``sigma(mu)`` from the channel's noise
model, and the annulus's prediction the average of the clipped normal means
``E[min(X, S)]`` (:mod:`translucent.fitting.profile_noise`).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..errors import InputError
from .beam import beam_convolution_matrix
from .capture import Capture, decode_pixels
from .geometry import RadialGrid, disc_rectangle_area, radial_grid
from .incident_point import (  # noqa: F401  (read from here too)
    CENTROID_ITERATIONS,
    CENTROID_THRESHOLD,
    CENTROID_TOLERANCE_PX,
    refine_incident_point,
)
from .profile_noise import CeilingCensoring, NoiseModel, clipped_normal_mean, fit_noise_model

__all__ = [
    "CeilingCensoring",
    "ProfileOperator",
    "RadialProfile",
    "annulus_edges",
    "annulus_average_matrix",
    "censored_line_fit",
    "clipped_normal_mean",
    "fit_noise_model",
    "interpolation_matrix",
    "measure_profile",
    "refine_incident_point",
]

#: An annulus needs this many pixel centres (before masking) to be formed: the first
#: annulus is then a disc of radius ~2 px.
MIN_PIXELS_PER_ANNULUS = 12
#: ... and this many valid pixels to be used: 4 degrees of freedom for its scatter, the
#: fewest for which the Student-t likelihood keeps a finite variance.
MIN_VALID_PIXELS = 7
#: Relative width of the outer annuli (5 % of the radius): narrow enough that the profile
#: is nearly linear across one, wide enough to keep the number of annuli near 60.
ANNULUS_GROWTH = 0.05
#: Fraction of below-black pixels at which an annulus counts as having reached the noise
#: floor. Dropping the lower tail of pixels biases the mean upward by about
#: phi(z) sigma for a fraction Phi(-z); at 0.1 % (z = 3.1) that is 0.003 sigma per pixel,
#: negligible against the annulus's standard error.
BELOW_BLACK_FRACTION = 1e-3
#: Top code of the 16-bit PNG/TIFF captures: a pixel there was clipped by the encoding.
INTEGER_CEILING = 65535.0
#: A float channel with at least this many pixels exactly at the black level was clipped
#: there (noise never lands on one float value by chance): its pixels at or below black
#: are censored observations, not measurements.
CENSORED_PILEUP = 8
#: Beyond this fraction of censored pixels an annulus's censored estimate rests mostly on
#: the normal model of the noise, not on data: it counts as the noise floor.
CENSORED_MAX_FRACTION = 0.5
#: Sub-pixel resolution of the radial grid near the centre (fraction of a pixel); the grid
#: starts at the smaller of this and 1 um.
GRID_RESOLUTION_PX = 0.01
#: Largest change of ln(profile) between grid nodes. A profile linear between nodes then
#: misrepresents an exponential decay by about step^2 / 12 = 2e-4 on average (1e-4 to
#: 2e-4 measured on annulus means): a fifth of the standard error of the best annuli.
MAX_LOG_STEP = 0.05
#: Bounds of the grid's uniform spacing, pixels.
GRID_SPACING_PX = (0.1, 1.0)
#: Fewest unsaturated annuli (each with at least :data:`MIN_VALID_PIXELS` pixels) from which
#: a channel's noise model is fitted; with fewer, its annuli keep their own variances and
#: its saturated annuli are dropped.
NOISE_MODEL_MIN_ANNULI = 3
#: Each interval of the model's grid is split into this many rings for the pixel
#: footprints, the profile between nodes taken as the cubic through the nearest four
#: (:func:`interpolation_matrix`). A straight line between nodes overestimates a convex
#: profile by ~ step^2 / 12 of ln f, 1e-4 to 7e-4 of an annulus mean at the grid's log
#: steps (0.05 and the geometric 2 %): as much as the standard error of a bright annulus of
#: a high exposure. With 4 rings and cubics the operator agrees with 24x-supersampled
#: pixels of a dipole to about 2e-5 (measured).
FINE_RINGS_PER_INTERVAL = 4
#: A per-pixel prediction matrix with fewer non-zero entries than this fraction is stored
#: sparse (a pixel overlaps a few grid rings; only a wide beam fills the rows).
SPARSE_DENSITY = 0.2


def annulus_edges(r_max_px: float) -> np.ndarray:
    """Annulus edges in pixels: 0, then widths of max(1 px, 5 % of r), >= 12 pixels each.

    Parameters
    ----------
    r_max_px : float
        Outermost radius to cover, pixels.

    Returns
    -------
    ndarray
        Increasing edges starting at 0 (the last one >= ``r_max_px``).
    """
    edges = [0.0]
    while edges[-1] < r_max_px:
        last = edges[-1]
        edges.append(max(last + 1.0, last * (1.0 + ANNULUS_GROWTH),
                         np.sqrt(last * last + MIN_PIXELS_PER_ANNULUS / np.pi)))
    return np.asarray(edges)


def _pixel_ring_pairs(radius_px, centre_xy, grid_px, shape):
    """Split every pixel into the rings of the grid: (pixel index, ring index, area, mean r)."""
    height, width = shape
    ys, xs = np.mgrid[0:height, 0:width]
    x0 = (xs - centre_xy[0]).ravel().astype(np.float64)
    y0 = (ys - centre_xy[1]).ravel().astype(np.float64)
    x1, y1 = x0 + 1.0, y0 + 1.0
    nearest_x = np.where(x0 > 0, x0, np.where(x1 < 0, -x1, 0.0))
    nearest_y = np.where(y0 > 0, y0, np.where(y1 < 0, -y1, 0.0))
    rho_min = np.hypot(nearest_x, nearest_y)
    rho_max = np.hypot(np.maximum(np.abs(x0), np.abs(x1)), np.maximum(np.abs(y0), np.abs(y1)))
    keep = rho_min < radius_px
    pixel_index = np.flatnonzero(keep)
    first = np.searchsorted(grid_px, rho_min[keep], side="right") - 1
    last = np.searchsorted(grid_px, rho_max[keep], side="left")
    last = np.minimum(last, grid_px.size - 1)
    counts = np.maximum(last - first, 0)
    pixel = np.repeat(pixel_index, counts)
    ring = np.repeat(first, counts) + (np.arange(counts.sum())
                                       - np.repeat(np.cumsum(counts) - counts, counts))
    inner, outer = grid_px[ring], grid_px[ring + 1]
    area = (disc_rectangle_area(outer, x0[pixel], x1[pixel], y0[pixel], y1[pixel])
            - disc_rectangle_area(inner, x0[pixel], x1[pixel], y0[pixel], y1[pixel]))
    # area-weighted mean radius of a full thin ring: where a linear profile is evaluated
    mean_r = 2.0 / 3.0 * (outer ** 3 - inner ** 3) / np.maximum(outer ** 2 - inner ** 2, 1e-300)
    good = area > 0
    return pixel[good], ring[good], area[good], mean_r[good]


def annulus_average_matrix(pairs, annulus_of_pixel, valid, n_annuli, grid_px):
    """Matrix ``A`` (annuli x nodes): annulus mean of a profile linear between grid nodes.

    Parameters
    ----------
    pairs : tuple
        ``(pixel, ring, area, mean_r)`` from the exact pixel-ring split.
    annulus_of_pixel : ndarray of int
        Annulus of each pixel (by its centre), -1 outside every annulus.
    valid : ndarray of bool
        Pixels that take part (per channel).
    n_annuli : int
    grid_px : ndarray
        Grid nodes in pixels.

    Returns
    -------
    ndarray, shape (n_annuli, grid size)
        Each row sums to 1 where its annulus has a valid pixel, else 0.
    """
    pixel, ring, area, mean_r = pairs
    annulus = annulus_of_pixel[pixel]
    use = (annulus >= 0) & valid[pixel]
    annulus, ring, area, mean_r = annulus[use], ring[use], area[use], mean_r[use]
    t = (mean_r - grid_px[ring]) / (grid_px[ring + 1] - grid_px[ring])
    n = grid_px.size
    matrix = (np.bincount(annulus * n + ring, area * (1.0 - t), minlength=n_annuli * n)
              + np.bincount(annulus * n + ring + 1, area * t, minlength=n_annuli * n))
    # float even with no valid pixel (bincount of empty weights is an integer array)
    matrix = matrix[: n_annuli * n].reshape(n_annuli, n).astype(np.float64)
    totals = matrix.sum(axis=1, keepdims=True)
    return np.divide(matrix, totals, out=np.zeros_like(matrix), where=totals > 0)


def _footprint_rows(pairs, own, count, grid_px):
    """Return sparse ``(count, grid size)``: each chosen pixel's footprint average.

    As :func:`annulus_average_matrix` with every chosen pixel (``own >= 0``) its own
    annulus (rows sum to 1), built sparse: a pixel overlaps only a few rings.
    """
    from scipy import sparse

    pixel, ring, area, mean_r = pairs
    row = own[pixel]
    use = row >= 0
    row, ring, area, mean_r = row[use], ring[use], area[use], mean_r[use]
    t = (mean_r - grid_px[ring]) / (grid_px[ring + 1] - grid_px[ring])
    matrix = sparse.csr_matrix((np.concatenate([area * (1.0 - t), area * t]),
                                (np.concatenate([row, row]), np.concatenate([ring, ring + 1]))),
                               shape=(count, grid_px.size))
    totals = np.asarray(matrix.sum(axis=1)).ravel()
    return sparse.diags(np.divide(1.0, totals, out=np.zeros_like(totals),
                                  where=totals > 0)) @ matrix


def _subdivided(nodes, parts: int) -> np.ndarray:
    """Return ``nodes`` with every interval split into ``parts`` equal ones."""
    steps = np.arange(parts) / parts
    inner = nodes[:-1, None] + np.diff(nodes)[:, None] * steps[None, :]
    return np.concatenate([inner.ravel(), nodes[-1:]])


def interpolation_matrix(nodes, points):
    r"""Sparse matrix of the piecewise-cubic interpolant of values at ``nodes``, at ``points``.

    Between nodes :math:`r_i` and :math:`r_{i+1}` the value is the Lagrange cubic through
    the nodes :math:`i-1 .. i+2`,

    .. math:: f(r) \approx \sum_j f_j \prod_{m \ne j} \frac{r - r_m}{r_j - r_m},

    whose error is :math:`O(h^4)` where a straight line's is :math:`h^2 f'' / 8`. The first
    interval stays a straight line (a profile model may set the value at r = 0 so that the
    line holds the exitance near the beam exactly); the second and the last use the
    quadratic through the three nodes that avoid node 0 or reach the end.

    Parameters
    ----------
    nodes : ndarray, shape (n,)
        Increasing, n >= 2.
    points : ndarray, shape (m,)
        Within ``[nodes[0], nodes[-1]]``.

    Returns
    -------
    scipy.sparse.csr_matrix, shape (m, n)
    """
    from scipy import sparse

    nodes = np.asarray(nodes, dtype=np.float64)
    points = np.asarray(points, dtype=np.float64)
    n = nodes.size
    interval = np.clip(np.searchsorted(nodes, points, side="right") - 1, 0, n - 2)
    # the stencil of each point: its first node and how many nodes (2: a line, 3 or 4)
    first = interval - 1
    size = np.full(points.size, 4)
    first[interval == 0], size[interval == 0] = 0, 2
    second = interval == 1
    first[second], size[second] = 1, 3
    last = (interval == n - 2) & (interval > 1)
    first[last], size[last] = n - 3, 3
    size = np.minimum(size, n - first)
    rows, cols, weights = [], [], []
    for width in (2, 3, 4):
        pick = np.flatnonzero(size == width)
        if pick.size == 0:
            continue
        stencil = first[pick, None] + np.arange(width)[None, :]
        r = nodes[stencil]
        x = points[pick]
        for j in range(width):
            w = np.ones(pick.size)
            for m in range(width):
                if m != j:
                    w = w * (x - r[:, m]) / (r[:, j] - r[:, m])
            rows.append(pick)
            cols.append(stencil[:, j])
            weights.append(w)
    return sparse.csr_matrix((np.concatenate(weights),
                              (np.concatenate(rows), np.concatenate(cols))),
                             shape=(points.size, n))


@dataclass(frozen=True)
class ProfileOperator:
    """Predicts the used annulus means of each channel from a profile on the radial grid.

    Parameters
    ----------
    grid : RadialGrid
        Nodes in mm.
    matrices : tuple of 3 ndarray
        ``M_c`` of shape (used annuli of channel c, grid size): beam convolution then exact
        pixel-footprint average.
    ceilings : tuple of 3 (CeilingCensoring or None)
        Per channel, the annuli holding saturated pixels: their predictions are clipped
        means, not linear in the profile.
    """

    grid: RadialGrid
    matrices: tuple
    ceilings: tuple = (None, None, None)

    def predict(self, profile_nodes, channels=(0, 1, 2), *,
                clipped: bool = True) -> list[np.ndarray | None]:
        """Annulus means per channel for profiles at the nodes.

        Parameters
        ----------
        profile_nodes : ndarray, shape (..., grid size, 3)
            Exitance profile in mm^-2 (already multiplied by any exposure).
        channels : sequence of int
            Channels to predict (the others are None).
        clipped : bool
            Predict saturated annuli as clipped means (default); False gives their plain,
            unclipped means (linear in the profile: for searches that scale it).

        Returns
        -------
        list of 3 (ndarray of shape (..., used annuli of the channel) or None)
        """
        profile_nodes = np.asarray(profile_nodes)
        out = []
        for channel, matrix in enumerate(self.matrices):
            if channel not in channels:
                out.append(None)
                continue
            values = profile_nodes[..., channel] @ matrix.T
            ceiling = self.ceilings[channel]
            if ceiling is not None and clipped:
                values[..., ceiling.rows] = ceiling.predict(profile_nodes[..., channel])
            out.append(values)
        return out

    def linear_rows(self, channel: int, count: int) -> np.ndarray:
        """Tell which of the channel's ``count`` used annuli are predicted linearly.

        Those are the annuli whose prediction scales with the exposure (all but the
        saturated ones): what a search over unit-exposure profiles may compare.
        """
        rows = np.ones(count, dtype=bool)
        if self.ceilings[channel] is not None:
            rows[self.ceilings[channel].rows] = False
        return rows


@dataclass(frozen=True)
class RadialProfile:
    """The measured radial profile of a capture (see the module docstring).

    Attributes
    ----------
    edges_mm : ndarray, shape (n + 1,)
        Annulus edges, mm from the refined incident point.
    radius_mm : ndarray, shape (n, 3)
        Mean pixel-centre radius of each annulus's valid pixels, mm (for plots).
    mean, stderr : ndarray, shape (n, 3)
        Annulus mean of the linear signal (stored units above black) and its standard
        error; NaN where no valid pixel.
    dof : ndarray of int, shape (n, 3)
        Degrees of freedom of the scatter (valid pixels - 2).
    used : ndarray of bool, shape (n, 3)
        Annuli that enter the likelihood.
    centre_px : (float, float)
        Refined incident point.
    masked : dict
        Pixel counts per channel: ``nan``, ``saturated``, ``below_black``, ``valid``.
    dropped : dict
        Annulus counts per channel: ``saturated``, ``noise_floor``, ``too_few_pixels``.
    operator : ProfileOperator
    saturated_annuli : list of int
        Per channel, the used annuli holding saturated pixels (fitted as clipped means).
    """

    edges_mm: np.ndarray
    radius_mm: np.ndarray
    mean: np.ndarray
    stderr: np.ndarray
    dof: np.ndarray
    used: np.ndarray
    centre_px: tuple[float, float]
    given_centre_px: tuple[float, float]
    masked: dict[str, list[int]]
    dropped: dict[str, list[int]]
    operator: ProfileOperator
    pixel_size_mm: float
    notes: list[str] = field(default_factory=list)
    saturated_annuli: list[int] = field(default_factory=lambda: [0, 0, 0])

    def observations(self, channel: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(mean, stderr, dof)`` of the used annuli of ``channel``."""
        use = self.used[:, channel]
        return self.mean[use, channel], self.stderr[use, channel], self.dof[use, channel]

    def summary(self) -> dict[str, Any]:
        """Return the counts for the fit report (JSON-able)."""
        return {"centre_px": list(self.centre_px), "given_centre_px": list(self.given_centre_px),
                "annuli": int(self.mean.shape[0]),
                "used_annuli": self.used.sum(axis=0).tolist(),
                "used_radius_mm": [
                    [float(self.edges_mm[np.flatnonzero(self.used[:, c])[0]]),
                     float(self.edges_mm[np.flatnonzero(self.used[:, c])[-1] + 1])]
                    if self.used[:, c].any() else None for c in range(3)],
                "masked_pixels": self.masked, "dropped_annuli": self.dropped,
                "saturated_annuli_fitted": list(self.saturated_annuli),
                "notes": list(self.notes)}


def _channel_masks(capture: Capture):
    """Per-pixel channel masks: finite, saturated, below black, censored at black."""
    spec = capture.spec
    stored = capture.pixels
    finite = np.isfinite(stored)
    with np.errstate(invalid="ignore"):
        integer = spec.image.lower().endswith((".png", ".tif", ".tiff"))
        # a 16-bit file clips at its top code whatever saturation_level says
        saturated = finite & ((stored >= spec.saturation_level)
                              | (integer & (stored >= INTEGER_CEILING)))
        below = finite & ((stored < spec.black_level) | (integer & (stored <= 0.0)))
        censored = np.zeros_like(finite)
        if not integer:
            pileup = (finite & (stored == spec.black_level)).sum(axis=(0, 1))
            clipped = pileup >= CENSORED_PILEUP
            censored = finite & (stored <= spec.black_level) & clipped[None, None, :]
            below &= ~censored
    return finite, saturated, below, censored


def censored_line_fit(values, radius, censored_radius, floor: float = 0.0):
    r"""Mean and standard error of an annulus whose lowest values were clipped at ``floor``.

    Tobit regression: the signal is :math:`v = \mu + b (r - \bar r) + \sigma \epsilon`
    with normal :math:`\epsilon`; a censored pixel only says :math:`v \le` ``floor``. The
    log-likelihood

    .. math::
        \sum_{\text{measured}} \left[\ln \phi(z_i) - \ln \sigma\right]
        + \sum_{\text{censored}} \ln \Phi(z_j), \qquad
        z = (v - \mu - b (r - \bar r)) / \sigma

    is maximised over :math:`(\mu, b, \ln \sigma)`, and the standard error of
    :math:`\mu` read from the inverse of its Hessian (the observed information).

    Parameters
    ----------
    values, radius : array_like, shape (n,)
        The measured pixels' signal and radius.
    censored_radius : array_like, shape (k,)
        The radii of the censored pixels.
    floor : float
        The clip value in signal units (0: clipped at black).

    Returns
    -------
    (float, float)
        The annulus mean at its mean radius and its standard error; NaN, NaN when the fit
        fails.
    """
    from scipy import optimize, special

    values = np.asarray(values, dtype=np.float64)
    radius = np.asarray(radius, dtype=np.float64)
    censored_radius = np.asarray(censored_radius, dtype=np.float64)
    centre = np.concatenate([radius, censored_radius]).mean()
    dr, dc = radius - centre, censored_radius - centre
    if values.size < 3:
        return float("nan"), float("nan")

    def negative_log_likelihood(x):
        mu, slope, ln_sigma = x
        sigma = np.exp(ln_sigma)
        z = (values - mu - slope * dr) / sigma
        zc = (floor - mu - slope * dc) / sigma
        return -(np.sum(-0.5 * z * z - ln_sigma) + np.sum(special.log_ndtr(zc)))

    slope0 = np.polyfit(dr, values, 1)[0] if values.size >= 3 and np.ptp(dr) > 0 else 0.0
    spread = max(float(np.std(values)), 1e-12)
    start = np.array([float(np.mean(values)) - 0.5 * spread * dc.size / (dc.size + values.size),
                      slope0, np.log(spread)])
    result = optimize.minimize(negative_log_likelihood, start, method="Nelder-Mead",
                               options={"xatol": 1e-9, "fatol": 1e-10, "maxiter": 4000})
    if not np.all(np.isfinite(result.x)):
        return float("nan"), float("nan")
    x = result.x
    steps = np.array([max(abs(x[0]), np.exp(x[2])) * 1e-4, max(abs(x[1]), 1e-6) * 1e-3
                      + np.exp(x[2]) * 1e-4 / max(np.ptp(np.concatenate([dr, dc])), 1e-9),
                      1e-4])
    hessian = np.empty((3, 3))
    for i in range(3):
        for j in range(3):
            ei, ej = np.eye(3)[i] * steps[i], np.eye(3)[j] * steps[j]
            hessian[i, j] = (negative_log_likelihood(x + ei + ej)
                             - negative_log_likelihood(x + ei - ej)
                             - negative_log_likelihood(x - ei + ej)
                             + negative_log_likelihood(x - ei - ej)) / (4 * steps[i] * steps[j])
    try:
        covariance = np.linalg.inv(hessian)
    except np.linalg.LinAlgError:
        return float("nan"), float("nan")
    variance = covariance[0, 0]
    if not (np.isfinite(variance) and variance > 0):
        return float("nan"), float("nan")
    return float(x[0]), float(np.sqrt(variance))


def _grid_spacing(mean, radius_mm, used, pixel_mm, censored_above=None) -> float:
    """Uniform spacing of the radial grid from the steepest measured log-slope (mm).

    Saturated annuli (``censored_above``) hide their slope behind the ceiling: there the
    slope of the first unsaturated annulus is scaled by the ratio of the radii, as the log
    slope of a scattering profile grows towards the beam no faster than ~ k / r.
    """
    steepest = 0.0
    for c in range(3):
        plain = used[:, c] if censored_above is None else used[:, c] & ~censored_above[:, c]
        m = mean[plain, c]
        r = radius_mm[plain, c]
        positive = m > 0
        if positive.sum() >= 2:
            with np.errstate(divide="ignore", invalid="ignore"):
                slopes = np.abs(np.diff(np.log(m[positive])) / np.diff(r[positive]))
            slopes = slopes[np.isfinite(slopes)]
            if slopes.size:
                steepest = max(steepest, float(slopes.max()))
                hidden = used[:, c] & ~plain
                if hidden.any():
                    inner = float(np.nanmin(radius_mm[hidden, c]))
                    steepest = max(steepest, float(slopes[0]) * float(r[positive][0])
                                   / max(inner, 0.5 * pixel_mm))
    low, high = GRID_SPACING_PX[0] * pixel_mm, GRID_SPACING_PX[1] * pixel_mm
    return high if steepest == 0 else float(np.clip(MAX_LOG_STEP / steepest, low, high))


def _ceiling_signal(spec) -> list[float]:
    """Return the saturation level in signal units (stored above black, decoded), per channel."""
    stored = spec.saturation_level
    if spec.image.lower().endswith((".png", ".tif", ".tiff")):
        stored = min(stored, INTEGER_CEILING)
    value = float(decode_pixels(np.array([stored]), spec)[0])
    return [value, value, value]


def _ceiling_annuli(count, sat_count) -> tuple[np.ndarray, np.ndarray]:
    """Annuli of one channel fitted as clipped means, and those dropped inside them.

    Every annulus holding a saturated pixel, from one inside the innermost annulus that
    still holds an unsaturated pixel outward, is fitted; the annuli further in are dropped:
    their pixels say only that the profile is above the ceiling there, which it is
    anyway where it rises towards the beam. Which annuli are fitted does not depend on
    whether a pixel's noise crossed the ceiling in one of them.
    """
    index = np.arange(count.size)
    has = sat_count > 0
    if not has.any():
        return np.zeros(count.size, dtype=bool), np.zeros(count.size, dtype=bool)
    mixed = np.flatnonzero(has & (count > 0))
    first = int(mixed[0]) if mixed.size else int(np.flatnonzero(has)[-1]) + 1
    return has & (index >= first - 1), index < first - 1


def _ceiling_censoring(pairs, annulus, pixels, used, above, grid_px, kernel, ceiling,
                       noise: NoiseModel | None) -> CeilingCensoring | None:
    """Return the per-pixel prediction of one channel's saturated annuli (None without any)."""
    rows = np.flatnonzero(above[used])
    if rows.size == 0:
        return None
    from scipy import sparse

    chosen = np.flatnonzero(pixels)
    own = np.full(annulus.size, -1, dtype=np.int64)
    own[chosen] = np.arange(chosen.size)
    pixel_matrix = _footprint_rows(pairs, own, chosen.size, grid_px) @ kernel
    if sparse.issparse(pixel_matrix) or \
            np.count_nonzero(pixel_matrix) < SPARSE_DENSITY * pixel_matrix.size:
        pixel_matrix = sparse.csr_matrix(pixel_matrix)
    # pixel -> its position among the channel's saturated, used annuli
    position = np.searchsorted(np.flatnonzero(used & above), annulus[chosen])
    averaging = np.zeros((rows.size, chosen.size))
    averaging[position, np.arange(chosen.size)] = 1.0
    averaging /= averaging.sum(axis=1, keepdims=True)
    return CeilingCensoring(rows, pixel_matrix, averaging, float(ceiling), noise)


def measure_profile(capture: Capture, *, r_max_mm: float | None = None,
                    r_min_mm: float = 0.0, refine_centre: bool = True) -> RadialProfile:
    """Measure the radial profile of every channel of ``capture`` (see the module docstring).

    Parameters
    ----------
    capture : Capture
    r_max_mm : float, optional
        Outermost radius to use, mm (default: the farthest image corner).
    r_min_mm : float
        Annuli reaching inside this radius are left out (counted as ``inside_r_min``): a
        way to fit the dipole only where diffusion holds, a few transport lengths out.
    refine_centre : bool
        Refine ``incident_px`` to sub-pixel (default); False keeps the sidecar's point.

    Returns
    -------
    RadialProfile

    Raises
    ------
    InputError
        When no channel keeps enough usable annuli to fit (at least 4).
    """
    spec = capture.spec
    height, width = capture.shape
    finite, saturated, below, censored = _channel_masks(capture)
    signal = capture.linear_signal()
    valid = finite & ~saturated & ~below & ~censored
    given = tuple(float(v) for v in spec.incident_px)
    centre = given
    if refine_centre:
        summed = np.where(finite, signal, 0.0).sum(axis=2)
        centre = refine_incident_point(summed, given, saturated=saturated.any(axis=2))
    ys, xs = np.mgrid[0:height, 0:width]
    radius_px = np.hypot(xs + 0.5 - centre[0], ys + 0.5 - centre[1]).ravel()
    corner = max(np.hypot(cx - centre[0], cy - centre[1])
                 for cx in (0, width) for cy in (0, height))
    pixel = spec.pixel_size_mm
    r_max_px = corner if r_max_mm is None else min(corner, r_max_mm / pixel)
    edges = annulus_edges(r_max_px)
    n_annuli = edges.size - 1
    annulus = np.searchsorted(edges, radius_px, side="right") - 1
    annulus[(annulus >= n_annuli) | (radius_px > r_max_px)] = -1
    inside = annulus >= 0

    mean = np.full((n_annuli, 3), np.nan)
    stderr = np.full((n_annuli, 3), np.nan)
    dof = np.zeros((n_annuli, 3), dtype=np.int64)
    radius_mean = np.full((n_annuli, 3), np.nan)
    used = np.zeros((n_annuli, 3), dtype=bool)
    dropped = {"saturated": [0, 0, 0], "noise_floor": [0, 0, 0], "too_few_pixels": [0, 0, 0],
               "inside_r_min": [0, 0, 0]}
    if not (np.isfinite(r_min_mm) and r_min_mm >= 0):
        raise InputError("must be finite and >= 0, mm", field="r_min_mm", value=r_min_mm)
    too_close = edges[:-1] * pixel < r_min_mm
    masked = {"nan": [0, 0, 0], "saturated": [0, 0, 0], "below_black": [0, 0, 0],
              "censored": [0, 0, 0], "valid": [0, 0, 0]}
    ceiling = _ceiling_signal(spec)
    censored_above = np.zeros((n_annuli, 3), dtype=bool)
    noise = [None, None, None]
    for c in range(3):
        ok = valid[..., c].ravel() & inside
        values = signal[..., c].ravel()
        masked["nan"][c] = int((~finite[..., c]).sum())
        masked["saturated"][c] = int(saturated[..., c].sum())
        masked["below_black"][c] = int(below[..., c].sum())
        masked["censored"][c] = int(censored[..., c].sum())
        masked["valid"][c] = int(valid[..., c].sum())
        idx = annulus[ok]
        v = values[ok]
        r = radius_px[ok]
        count = np.bincount(idx, minlength=n_annuli).astype(np.float64)
        with np.errstate(invalid="ignore", divide="ignore"):
            m = np.bincount(idx, v, minlength=n_annuli) / count
            rm = np.bincount(idx, r, minlength=n_annuli) / count
            dv = v - m[idx]
            dr = r - rm[idx]
            svv = np.bincount(idx, dv * dv, minlength=n_annuli)
            svr = np.bincount(idx, dv * dr, minlength=n_annuli)
            srr = np.bincount(idx, dr * dr, minlength=n_annuli)
            slope_ss = np.where(srr > 0, svr * svr / np.where(srr > 0, srr, 1.0), 0.0)
            residual = np.clip(svv - slope_ss, 0.0, None)
            se = np.sqrt(residual / (count - 2.0) / count)
        enough = count >= MIN_VALID_PIXELS
        mean[:, c] = np.where(count > 0, m, np.nan)
        stderr[:, c] = np.where(enough, se, np.nan)
        dof[:, c] = np.maximum(count - 2, 0).astype(np.int64)
        radius_mean[:, c] = rm * pixel
        sat_here = saturated[..., c].ravel() & inside
        sat_count = np.bincount(annulus[sat_here], minlength=n_annuli)
        below_count = np.bincount(annulus[below[..., c].ravel() & inside], minlength=n_annuli)
        cut = censored[..., c].ravel() & inside
        censored_count = np.bincount(annulus[cut], minlength=n_annuli)
        has_pixels = (count + below_count + censored_count + sat_count) > 0
        censored_fraction = censored_count / np.maximum(count + censored_count, 1)
        for a in np.flatnonzero((censored_count > 0) & enough
                                & (censored_fraction <= CENSORED_MAX_FRACTION)):
            here = idx == a
            m_a, se_a = censored_line_fit(v[here], r[here], radius_px[cut][annulus[cut] == a])
            mean[a, c], stderr[a, c] = m_a, se_a
            dof[a, c] = max(int(count[a] + censored_count[a]) - 3, 0)
        se = np.where(np.isfinite(stderr[:, c]), stderr[:, c], np.nan)
        # censoring from above: annuli with saturated pixels are fitted as clipped means,
        # all but the fully saturated ones deep inside
        above, clipped = _ceiling_annuli(count, sat_count)
        # censoring from below: the noise floor, and everything beyond it
        with np.errstate(invalid="ignore", divide="ignore"):
            fraction = below_count / np.maximum(count + below_count, 1)
        floor_annuli = np.flatnonzero(((fraction > BELOW_BLACK_FRACTION)
                                       | (censored_fraction > CENSORED_MAX_FRACTION))
                                      & ~clipped & ~above)
        floor = np.arange(n_annuli) >= (floor_annuli[0] if floor_annuli.size else n_annuli)
        keep = enough & (se > 0) & ~clipped & ~floor & ~above
        # the channel's noise model, fitted to the annuli measured by their own scatter,
        # whose variances it then pools (profile_noise)
        plain = keep & (censored_count == 0)
        total = count + sat_count
        above &= (total >= MIN_VALID_PIXELS) & ~floor
        model = None
        if plain.sum() >= NOISE_MODEL_MIN_ANNULI:
            rows = np.flatnonzero(plain)
            own = se[rows] ** 2 * count[rows]
            model, outlier = fit_noise_model(mean[rows, c], own, count[rows] - 2.0)
        if model is not None:
            pooled = rows[~outlier]
            variance, degrees = model.moderate(own[~outlier], count[pooled] - 2.0,
                                               mean[pooled, c])
            stderr[pooled, c] = np.sqrt(variance / count[pooled])
            dof[pooled, c] = degrees
            noise[c] = model
        if above.any() and model is not None:
            variances = np.bincount(idx, model.variance(v), minlength=n_annuli)
            sums = np.bincount(idx, v, minlength=n_annuli)
            radius_sums = np.bincount(idx, r, minlength=n_annuli) \
                + np.bincount(annulus[sat_here], radius_px[sat_here], minlength=n_annuli)
            for a in np.flatnonzero(above):
                # the clipped mean of all its pixels, and its standard error from the noise
                # model (a saturated pixel's clipped value has almost no variance)
                mean[a, c] = (sums[a] + sat_count[a] * ceiling[c]) / total[a]
                stderr[a, c] = np.sqrt(max(variances[a], float(model.variance(ceiling[c])))) \
                    / total[a]
                dof[a, c] = model.degrees
                radius_mean[a, c] = radius_sums[a] / total[a] * pixel
        elif above.any():  # no noise model: as before, every annulus up to the outermost
            # saturated one is dropped
            clipped = np.arange(n_annuli) <= np.flatnonzero(sat_count)[-1]
            above[:] = False
            keep &= ~clipped
        censored_above[:, c] = above
        keep |= above
        dropped["saturated"][c] = int((has_pixels & clipped).sum())
        dropped["noise_floor"][c] = int((has_pixels & floor & ~clipped).sum())
        dropped["too_few_pixels"][c] = int((has_pixels & ~clipped & ~floor & ~keep).sum())
        dropped["inside_r_min"][c] = int((keep & too_close).sum())
        keep &= ~too_close
        used[:, c] = keep
    if (used.sum(axis=0) < 4).all():
        why = "saturated, below black or too few pixels everywhere"
        if any(dropped["inside_r_min"]):
            why += (f"; r_min_mm = {r_min_mm:g} mm leaves out "
                    f"{max(dropped['inside_r_min'])} otherwise usable annuli")
        raise InputError(f"no channel has 4 usable annuli ({why})", file=capture.path,
                         field="image",
                         value={"used_annuli": used.sum(axis=0).tolist(), **dropped})

    # the forward operator: beam convolution, then the exact pixel-footprint average
    r_out_mm = edges[min(n_annuli, np.flatnonzero(used.any(axis=1))[-1] + 1)] * pixel \
        + np.sqrt(2.0) * pixel
    grid = radial_grid(r_out_mm + 6.0 * spec.beam_radius_mm + pixel,
                       min(GRID_RESOLUTION_PX * pixel, 1e-3),
                       _grid_spacing(mean, radius_mean, used, pixel, censored_above))
    # the pixel footprints are taken on finer rings than the model's nodes, and the profile
    # between nodes is a cubic through its neighbours, not a straight line (see
    # FINE_RINGS_PER_INTERVAL)
    fine = _subdivided(grid.nodes, FINE_RINGS_PER_INTERVAL)
    grid_px = fine / pixel
    pairs = _pixel_ring_pairs(r_out_mm / pixel + 2.0, centre, grid_px, (height, width))
    if capture.beam is not None:  # the beam's own image
        kernel = capture.beam.convolution_matrix(grid)
    elif spec.beam_profile == "measured":
        raise InputError('beam_profile "measured" needs the capture read with its beam_image '
                         "(read_capture)", file=capture.path, field="beam_image",
                         value=spec.beam_image)
    else:
        kernel = beam_convolution_matrix(grid, spec.beam_radius_mm, spec.beam_profile)
    interpolation = interpolation_matrix(grid.nodes, fine)
    pencil = kernel.shape[0] == kernel.shape[1] and np.array_equal(kernel, np.eye(len(kernel)))
    # fine ring values from the beam-convolved node values (sparse for a pencil beam)
    kernel = interpolation if pencil else np.asarray(interpolation @ kernel)
    matrices, ceilings = [], []
    for c in range(3):
        # a censored annulus estimates the mean over its censored pixels' footprints too
        in_above = np.isin(annulus, np.flatnonzero(used[:, c] & censored_above[:, c]))
        counted = (valid[..., c] | censored[..., c]).ravel() \
            | (saturated[..., c].ravel() & in_above)
        average = annulus_average_matrix(pairs, annulus, counted, n_annuli, grid_px)
        matrices.append(np.asarray((kernel.T @ average[used[:, c]].T).T))
        ceilings.append(_ceiling_censoring(pairs, annulus, counted & in_above, used[:, c],
                                           censored_above[:, c], grid_px, kernel,
                                           ceiling[c], noise[c]))
    notes = []
    shift = float(np.hypot(centre[0] - given[0], centre[1] - given[1]))
    if shift > 0.5:
        notes.append(f"incident point moved by {shift:.2f} px from the sidecar's "
                     f"[{given[0]:.2f}, {given[1]:.2f}] to [{centre[0]:.2f}, {centre[1]:.2f}]")
    return RadialProfile(edges_mm=edges * pixel, radius_mm=radius_mean, mean=mean,
                         stderr=stderr, dof=dof, used=used, centre_px=centre,
                         given_centre_px=given, masked=masked, dropped=dropped,
                         operator=ProfileOperator(grid, tuple(matrices), tuple(ceilings)),
                         pixel_size_mm=pixel, notes=notes,
                         saturated_annuli=(censored_above & used).sum(axis=0).tolist())
