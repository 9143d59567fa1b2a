r"""Numerics shared by the profiles: inverse-CDF sampling of radii and log-spaced tables.

:class:`RadialSampler` draws exit radii with density proportional to :math:`r R(r)` (the
energy of a ring), as a BSSRDF path tracer's probe rays need (pbrt-v4 ``SampleSr`` /
``PdfSr``; Cycles ``bssrdf_sample`` / ``bssrdf_pdf``). The density
:math:`p(r) = 2\pi r R(r)` is tabulated on a geometric grid and interpolated linearly
between the nodes; that piecewise-linear density is what is sampled (its cumulative is
quadratic in each segment and inverted in closed form) and what :meth:`RadialSampler.pdf`
returns, so sample and pdf agree exactly. Against the profile's own :math:`2\pi r R(r)/E`
the interpolated density errs by about :math:`h^2/8` of its curvature, h = 0.0068 the
grid's log-step: measured within 5e-4 inside the radius holding 99.9 % of the energy for
every registered profile (tests/materials/test_profile_conformance.py).

:class:`LogRadialTable` is the same idea for evaluation: a profile that is costly to
evaluate exactly (a sum of Gaussians, an average over azimuth, a table's own reading) is
tabulated once on geometric nodes and read back by interpolation linear in
:math:`\ln r`, the node found by arithmetic on :math:`\ln r` (no search).
"""

from __future__ import annotations

import numpy as np

from ...errors import InputError, check_finite

__all__ = [
    "GRID_RANGE",
    "GRID_SAMPLES",
    "LogRadialTable",
    "RadialSampler",
    "check_channel",
    "check_unit_interval",
    "geometric_nodes",
]

#: Nodes of the sampling and evaluation tables per channel.
GRID_SAMPLES = 4096
#: The tables' radii, in units of a profile's length scale (its mean free path): twelve
#: decades, a log-step of 0.0068 with :data:`GRID_SAMPLES` nodes.
GRID_RANGE = (1e-6, 1e6)


def check_unit_interval(u, field: str = "u") -> np.ndarray:
    """Return ``u`` as float64; :class:`InputError` unless every entry lies in [0, 1]."""
    u = check_finite(u, field)
    if ((u < 0.0) | (u > 1.0)).any():
        raise InputError("must lie in [0, 1]", field=field,
                         value=float(u.ravel()[np.flatnonzero((u < 0) | (u > 1))[0]]))
    return u


def check_channel(channel, shape) -> np.ndarray:
    """Return ``channel`` (0, 1 or 2, broadcast to ``shape``) as int; :class:`InputError` else."""
    array = np.asarray(channel)
    if not np.issubdtype(array.dtype, np.integer) or ((array < 0) | (array > 2)).any():
        raise InputError("must be a channel index 0, 1 or 2 (R, G, B)", field="channel",
                         value=channel)
    try:
        return np.broadcast_to(array, shape)
    except ValueError as error:
        raise InputError(f"must broadcast against the radii, shape {shape}",
                         field="channel", value=array.shape) from error


def geometric_nodes(scale, cutoff=None, samples: int = GRID_SAMPLES) -> np.ndarray:
    """Return per-channel radii: 0, then geometric over :data:`GRID_RANGE` times ``scale``.

    Parameters
    ----------
    scale : array_like, shape (3,)
        The length scale of each channel, mm (> 0 and finite, else the channel's nodes
        are 0 and 1 mm: a channel without a medium carries no energy).
    cutoff : array_like, shape (3,), optional
        Radii beyond which the profile is 0, mm: the nodes end there.
    samples : int

    Returns
    -------
    ndarray, shape (3, samples + 1)
        Increasing radii in mm, the first 0.
    """
    scale = np.asarray(scale, dtype=np.float64)
    usable = np.isfinite(scale) & (scale > 0)
    scale = np.where(usable, scale, 1.0)
    low = GRID_RANGE[0] * scale
    high = GRID_RANGE[1] * scale
    if cutoff is not None:
        high = np.minimum(high, np.asarray(cutoff, dtype=np.float64))
        low = np.minimum(low, 1e-3 * high)
    fraction = np.linspace(0.0, 1.0, samples)
    nodes = low[:, None] * (high / low)[:, None] ** fraction[None, :]
    return np.concatenate([np.zeros((3, 1)), nodes], axis=1)


class RadialSampler:
    r"""Sample exit radii with density :math:`\propto r R(r)`, per channel.

    Parameters
    ----------
    radius : ndarray, shape (3, K)
        Increasing node radii of each channel, mm, the first 0.
    density : ndarray, shape (3, K)
        :math:`2\pi r R(r)` at the nodes, mm^-1, finite and >= 0.

    Notes
    -----
    The sampled density is the linear interpolant of ``density`` between the nodes,
    normalised: :meth:`sample` inverts its cumulative exactly (a quadratic per segment)
    and :meth:`pdf` returns it, so the two are consistent to round-off. Nothing is sampled
    beyond the last node. :attr:`energy` is the interpolant's integral,
    :math:`2\pi\int_0^{r_K} R(r)\,r\,dr` by the trapezoidal rule.
    """

    def __init__(self, radius, density):
        self.radius = np.asarray(radius, dtype=np.float64)
        self.density = np.asarray(density, dtype=np.float64)
        widths = np.diff(self.radius, axis=1)
        masses = 0.5 * (self.density[:, 1:] + self.density[:, :-1]) * widths
        self.cumulative = np.concatenate([np.zeros((3, 1)), np.cumsum(masses, axis=1)], axis=1)
        #: Energy inside the last node per channel (dimensionless).
        self.energy = self.cumulative[:, -1].copy()

    @classmethod
    def from_profile(cls, profile, scale, cutoff=None) -> RadialSampler:
        """Tabulate ``profile.reflection`` on :func:`geometric_nodes` of ``scale`` (mm)."""
        radius = geometric_nodes(scale, cutoff)
        values = profile.reflection(radius)  # (3, K, 3): every channel's radii, all channels
        own = np.stack([values[c, :, c] for c in range(3)])
        own = np.where(np.isfinite(own) & (own > 0), own, 0.0)
        return cls(radius, 2.0 * np.pi * radius * own)

    def _invert(self, c: int, fraction):
        """Radii where channel ``c``'s normalised cumulative reaches ``fraction``."""
        energy = self.energy[c]
        if not energy > 0:
            return np.zeros(np.shape(fraction))
        cumulative, radius, density = self.cumulative[c], self.radius[c], self.density[c]
        target = np.asarray(fraction, dtype=np.float64) * energy
        k = np.clip(np.searchsorted(cumulative, target, side="right") - 1, 0, radius.size - 2)
        width = radius[k + 1] - radius[k]
        left = density[k]
        remaining = np.maximum(target - cumulative[k], 0.0)
        # width (left t + (right - left) t^2 / 2) = remaining, solved without cancellation
        quadratic = 0.5 * width * (density[k + 1] - left)
        linear = width * left
        root = np.sqrt(np.maximum(linear * linear + 4.0 * quadratic * remaining, 0.0))
        denominator = linear + root
        with np.errstate(divide="ignore", invalid="ignore"):
            t = np.where(denominator > 0, 2.0 * remaining / denominator, 0.0)
        return radius[k] + np.clip(t, 0.0, 1.0) * width

    def sample(self, u, channel) -> np.ndarray:
        """Radii (mm) for uniform numbers ``u`` in [0, 1]; 0 in a channel without energy."""
        u = check_unit_interval(u)
        channel = check_channel(channel, u.shape)
        out = np.zeros(u.shape)
        for c in range(3):
            chosen = channel == c
            if chosen.any():
                out[chosen] = self._invert(c, u[chosen])
        return out

    def pdf(self, r, channel) -> np.ndarray:
        """Density of the sampled radius at ``r`` (mm), mm^-1; 0 beyond the last node."""
        r = check_finite(r, "r")
        channel = check_channel(channel, r.shape)
        out = np.zeros(r.shape)
        for c in range(3):
            chosen = channel == c
            energy = self.energy[c]
            if not chosen.any() or not energy > 0:
                continue
            radius, density = self.radius[c], self.density[c]
            at = r[chosen]
            k = np.clip(np.searchsorted(radius, at, side="right") - 1, 0, radius.size - 2)
            t = (at - radius[k]) / (radius[k + 1] - radius[k])
            value = density[k] + t * (density[k + 1] - density[k])
            inside = (at >= 0.0) & (at <= radius[-1])
            out[chosen] = np.where(inside, value / energy, 0.0)
        return out

    def quantile(self, fraction) -> np.ndarray:
        """Radius (mm) holding ``fraction`` of each channel's energy, shape (3,)."""
        return np.array([float(self._invert(c, fraction)) for c in range(3)])


class LogRadialTable:
    r"""A profile tabulated on geometric nodes per channel, read by interpolation in ln r.

    Parameters
    ----------
    radius : ndarray, shape (3, K)
        Per channel: 0, then K - 1 geometric nodes of one common ratio
        (:func:`geometric_nodes` without a cut-off), mm.
    values : ndarray, shape (3, K)
        The profile at the nodes, mm^-2.

    Notes
    -----
    Between nodes the value is linear in :math:`\ln r`; below the first geometric node the
    value of that node holds, beyond the last node the profile is 0. With nodes a log-step
    h apart the interpolation errs by about :math:`h^2/8` times the profile's second
    derivative in :math:`\ln r` relative to it (h = 0.0068 on the default grid: 1e-5 where
    a profile varies on the scale of its mean free path, a few 1e-4 deep in an exponential
    tail; each profile's tests state what they measured). The node of
    a radius is found by arithmetic on :math:`\ln r`, the same for every channel but an
    offset: one logarithm per radius, then a few passes per channel.
    """

    def __init__(self, radius, values):
        nodes = np.asarray(radius, dtype=np.float64)[:, 1:]
        self.values = np.ascontiguousarray(np.asarray(values, dtype=np.float64)[:, 1:])
        self.slopes = np.ascontiguousarray(np.diff(self.values, axis=1))
        ln_nodes = np.log(nodes)
        steps = (ln_nodes[:, -1] - ln_nodes[:, 0]) / (nodes.shape[1] - 1)
        if not np.allclose(steps, steps[0], rtol=1e-9):
            raise InputError("the channels' nodes must share one geometric ratio",
                             field="radius", value=steps)
        self.inverse_step = 1.0 / float(steps[0])
        self.offset = ln_nodes[:, 0] * self.inverse_step
        self.last = nodes.shape[1] - 1

    def __call__(self, r) -> np.ndarray:
        """Return the tabulated profile at ``r`` (mm): shape ``r.shape + (3,)``, mm^-2."""
        r = np.asarray(r, dtype=np.float64)
        shape = r.shape
        with np.errstate(divide="ignore", invalid="ignore"):
            base = np.log(r.reshape(-1))
        base *= self.inverse_step
        # beyond the last node (by more than round-off), or NaN: fixed up after the loop
        limit = self.last + self.offset + 1e-6
        regular = base.max(initial=-np.inf) <= limit.min()
        if not regular:
            undefined = np.isnan(base)
            base[undefined] = -np.inf
        out = np.empty((3,) + base.shape)  # channels as rows, transposed once at the end
        top = self.last - 1e-9
        for c in range(3):
            position = base - self.offset[c]
            np.clip(position, 0.0, top, out=position)
            k = position.astype(np.intp)
            position -= k
            value = self.slopes[c].take(k)
            value *= position
            value += self.values[c].take(k)
            out[c] = value
        if not regular:
            out[base[None, :] > limit[:, None]] = 0.0
            out[:, undefined] = np.nan
        return np.ascontiguousarray(out.T).reshape(shape + (3,))
