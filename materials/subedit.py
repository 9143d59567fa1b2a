r"""Heterogeneous translucent materials in the SubEdit representation.

SubEdit (Song et al. 2009) factors the 4D diffuse scattering function of a heterogeneous
material into a product of two local radial profiles (Eq. 8 of Chen et al. 2012):

.. math:: R_d(x_i, x_o) = \sqrt{P_{x_i}(r)\,P_{x_o}(r)}, \qquad r = \|x_i - x_o\|,

and stores each profile as a piecewise-linear function of :math:`\ln P` in ``n`` uniform
segments up to the maximum scattering radius :math:`r_s` (Eq. 9):

.. math:: \ln P_x(r) = (1 - w)\hat P_x^k + w \hat P_x^{k+1}, \quad k = \lfloor nr/r_s\rfloor,
          \quad w = nr/r_s - k.

A :class:`SubEditProfiles` is a texture of such profiles mapped over a mesh's uv; a
homogeneous material is a 1 x 1 texture. Lengths are in mm, profiles in mm^-2; beyond
:math:`r_s` a profile is zero.

References
----------
Song, Tong, Pellacini, Peers: SubEdit: a representation for editing measured heterogeneous
subsurface scattering. SIGGRAPH 2009.
Chen, Peers, Zhang, Tong: Real-time rendering of deformable heterogeneous translucent
objects using multiresolution splatting. The Visual Computer (2012), Eq. 8, 9, 11, 15, 16.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from pathlib import Path
from typing import NamedTuple

import numpy as np

from ..atomic import atomic_path
from ..errors import InputError, check_count, check_finite
from .catalogue import measured_medium
from .homogeneous import Dipole
from .profiles.base import require_radial
from .profiles.classical_dipole import DipoleProfile

__all__ = [
    "SubEditProfiles",
    "DipoleConversion",
    "subedit_from_dipole",
    "subedit_from_profile",
    "convert_media",
    "builtin_subedit",
    "BUILTIN_SUBEDIT",
    "save_subedit",
    "load_subedit",
    "subedit_from_spec",
    "ENERGY_FRACTION",
    "DEFAULT_SEGMENTS",
    "FORMAT_NAME",
    "FORMAT_VERSION",
]

#: Fraction of a profile's energy inside its effective scattering range (Chen et al. 2012,
#: text after Eq. 11: "the radius that preserves 95 % percent of the energy").
ENERGY_FRACTION = 0.95
#: Segments of a converted profile; with it every measured medium converts within
#: :data:`CONVERSION_TOLERANCE` of its dipole (see tests/materials/test_subedit.py).
DEFAULT_SEGMENTS = 64
#: Fraction of a dipole's energy inside the default maximum scattering radius r_s.
DEFAULT_RADIUS_ENERGY = 0.999
#: Cap (mm) on the default r_s: a non-absorbing medium (Spectralon) has a 1/r^3 tail whose
#: 99.9 % radius is astronomically far; beyond a metre the truncation is reported instead.
MAX_DEFAULT_RADIUS = 1000.0
#: Largest maximum scattering radius r_s accepted (mm): a kilometre, far beyond any
#: object rendered, and small enough that r^2 and the energy integrals stay finite.
MAX_RADIUS = 1e6
#: Bytes a built-in texture takes per knot and channel while it is made: the blend's
#: float64 table, its temporaries and the validated copy.
BUILD_BYTES_PER_KNOT = 32
#: Relative weight added to every fitted sample so that knots where the dipole carries no
#: energy still follow ln R_d instead of the least-squares minimum-norm value 0.
TAIL_WEIGHT = 1e-9
#: ln P of a profile that is zero: exp(-300) mm^-2 is far below any measured value and
#: keeps sqrt(P_i P_o) and the energy integrals finite.
LOG_FLOOR = -300.0
#: ln P fitted to a profile's negligible tail is bounded below by ln of this fraction of
#: its channel's peak: a tabulated profile that ends in exact zeros (photon beam
#: diffusion's table) would otherwise ask for ln 0 = LOG_FLOOR beside 1e-68 round-off,
#: and the ill-posed knots there spiked to ln P = -2.8 at 47 mm (Chicken1, blue).
RELATIVE_LOG_FLOOR = 1e-30
#: Below this fraction of its channel's peak a profile carries no energy the fit can see;
#: there its ln R is made non-increasing in r (round-off of a table is not a shape).
NEGLIGIBLE_TAIL = 1e-8
#: Texels averaged into the mean normalised profile (a regular subsample of a larger
#: texture: the mean of 256 profiles of a smooth texture moves by well under epsilon).
MEAN_PROFILE_TEXELS = 256
#: File format name and version written into every saved texture (docs/subedit-format.md).
FORMAT_NAME = "translucent-subedit"
FORMAT_VERSION = 1
#: Below this |delta ln P| across a segment the moment integrals use their Taylor series.
_SERIES_THRESHOLD = 1e-2


def _checked_radius(r_s) -> float:
    """Return the maximum scattering radius ``r_s`` as a float in (0, MAX_RADIUS] mm."""
    value = check_finite(r_s, "r_s")
    if value.shape != ():
        raise InputError("must be a number (mm)", field="r_s", value=r_s)
    if not float(value) > 0:
        raise InputError("must be > 0 mm", field="r_s", value=r_s)
    if float(value) > MAX_RADIUS:
        raise InputError(f"must be <= {MAX_RADIUS:g} mm", field="r_s", value=r_s)
    return float(value)


def _moment_factors(delta):
    r"""Return :math:`E_1 = \int_0^1 e^{\delta t}dt`, :math:`E_2 = \int_0^1 t e^{\delta t}dt`."""
    delta = np.asarray(delta, dtype=np.float64)
    small = np.abs(delta) < _SERIES_THRESHOLD
    safe = np.where(small, 1.0, delta)
    with np.errstate(over="ignore", invalid="ignore"):
        expm1 = np.expm1(safe)
        inverse = 1.0 / safe
        e1 = expm1 * inverse
        e2 = ((expm1 + 1.0) - e1) * inverse  # (d e^d - expm1(d)) / d^2
    if small.any():
        d = delta
        e1 = np.where(small, 1.0 + d * (1 / 2 + d * (1 / 6 + d / 24)), e1)
        e2 = np.where(small, 0.5 + d * (1 / 3 + d * (1 / 8 + d * (1 / 30 + d / 144))), e2)
    return e1, e2


def segment_moment(log_start, log_end, r_start, length):
    r"""Exact :math:`\int_{r_0}^{r_0+h} r\,P(r)\,dr` of one log-linear segment, in mm^-2 mm^2.

    With :math:`\ln P` linear from ``log_start`` at :math:`r_0` to ``log_end`` at
    :math:`r_0 + h` (Eq. 9 of Chen et al. 2012 on one segment):
    :math:`h e^{y_0}(r_0 E_1(\delta) + h E_2(\delta))`, :math:`\delta = y_1 - y_0`.
    Broadcasts; ``length`` may be 0.
    """
    log_start = np.asarray(log_start, dtype=np.float64)
    delta = np.asarray(log_end, dtype=np.float64) - log_start
    e1, e2 = _moment_factors(delta)
    length = np.asarray(length, dtype=np.float64)
    with np.errstate(over="ignore", invalid="ignore"):
        value = length * np.exp(log_start) * (np.asarray(r_start, np.float64) * e1 + length * e2)
    return np.where(length > 0, value, 0.0)


@dataclass(frozen=True, eq=False)
class SubEditProfiles:
    r"""A texture of SubEdit scattering profiles (Eq. 9 of Chen et al. 2012).

    Parameters
    ----------
    log_profile : ndarray, shape (H, W, n + 1, 3)
        :math:`\hat P_x^k = \ln P_x(r_k)` at the knots :math:`r_k = k r_s / n`, per texel
        and RGB channel, with :math:`P` in mm^-2. Values below :data:`LOG_FLOOR` are raised
        to it (a zero profile).
    r_s : float
        Maximum scattering radius in mm, > 0; :math:`P_x(r) = 0` for :math:`r \ge r_s`.
    eta : float
        Relative index of refraction of the boundary (for :math:`F_t`), in [1, 3].
    name : str
        A label.
    range_energy : float
        The fraction of each profile's energy within its effective scattering range
        (:attr:`effective_scattering_range`, Eq. 11), in (0, 1]; the paper's 0.95 by
        default.

    Notes
    -----
    Texel ``(row j, column i)`` of an ``H x W`` texture covers
    :math:`u \in [i/W, (i+1)/W)`, :math:`v \in [j/H, (j+1)/H)`; lookups take the nearest
    texel and clamp uv to [0, 1].
    """

    log_profile: np.ndarray
    r_s: float
    eta: float = 1.3
    name: str = ""
    range_energy: float = ENERGY_FRACTION

    def __post_init__(self):
        table = np.asarray(self.log_profile, dtype=np.float64)
        if table.ndim == 2:
            table = table[None, None]
        if table.ndim != 4 or table.shape[2] < 2 or table.shape[3] != 3:
            raise InputError("must have shape (H, W, n + 1 >= 2, 3)", field="log_profile",
                             value=table.shape)
        if np.isnan(table).any() or np.isposinf(table).any():
            raise InputError("must not hold NaN or +Inf", field="log_profile",
                             value=float(table[~np.isfinite(table) & ~np.isneginf(table)][0]))
        table = np.maximum(table, LOG_FLOOR)
        table.flags.writeable = False
        object.__setattr__(self, "log_profile", table)
        object.__setattr__(self, "r_s", _checked_radius(self.r_s))
        eta = float(check_finite(self.eta, "eta"))
        if not 1.0 <= eta <= 3.0:
            raise InputError("must be in [1, 3]", field="eta", value=self.eta)
        object.__setattr__(self, "eta", eta)
        fraction = float(check_finite(self.range_energy, "range_energy"))
        if not 0.0 < fraction <= 1.0:
            raise InputError("must be in (0, 1]", field="range_energy", value=self.range_energy)
        object.__setattr__(self, "range_energy", fraction)

    # ---------------------------------------------------------------- layout
    @property
    def segments(self) -> int:
        """The number ``n`` of linear segments of every profile."""
        return self.log_profile.shape[2] - 1

    @property
    def resolution(self) -> tuple[int, int]:
        """Texture size ``(H, W)`` in texels."""
        return self.log_profile.shape[:2]

    @property
    def texel_count(self) -> int:
        """``H * W``."""
        return self.resolution[0] * self.resolution[1]

    @property
    def knot_radii(self) -> np.ndarray:
        """The knots :math:`r_k = k r_s / n` in mm, shape (n + 1,)."""
        return np.linspace(0.0, self.r_s, self.segments + 1)

    @functools.cached_property
    def flat_log_profile(self) -> np.ndarray:
        """``log_profile`` as (H * W, n + 1, 3), row-major over texels (for gathers)."""
        return self.log_profile.reshape(self.texel_count, self.segments + 1, 3)

    @property
    def is_homogeneous(self) -> bool:
        """True for a 1 x 1 texture."""
        return self.texel_count == 1

    def texel_index(self, uv) -> np.ndarray:
        """Flat texel index of the nearest texel to each uv (clamped to [0, 1]).

        Parameters
        ----------
        uv : array_like, shape (..., 2)
            Texture coordinates.

        Returns
        -------
        ndarray of int64, shape (...)
        """
        uv = np.nan_to_num(np.asarray(uv, dtype=np.float64), nan=0.0, posinf=1.0, neginf=0.0)
        height, width = self.resolution
        column = np.clip((uv[..., 0] * width).astype(np.int64), 0, width - 1)
        row = np.clip((uv[..., 1] * height).astype(np.int64), 0, height - 1)
        return row * width + column

    # ---------------------------------------------------------------- evaluation
    def log_profile_at(self, r, texel=0) -> np.ndarray:
        r"""Eq. 9 of Chen et al. 2012: :math:`\ln P_x(r)` for texels ``texel`` at ``r`` (mm).

        ``r`` and ``texel`` broadcast; the result has shape ``broadcast + (3,)``.
        :data:`LOG_FLOOR` where :math:`r \ge r_s` (outside the support) or ``r`` is not
        finite.
        """
        r = np.asarray(r, dtype=np.float64)
        texel = np.asarray(texel, dtype=np.int64)
        if r.ndim == 0:  # one radius: one segment and weight for every texel (same bits)
            position = float(np.nan_to_num(r, nan=np.inf)) * (self.segments / self.r_s)
            if not 0 <= position < self.segments:
                return np.full(texel.shape + (3,), LOG_FLOOR)
            k = min(int(position), self.segments - 1)
            weight = position - k
            table = self.flat_log_profile
            return (1.0 - weight) * table[texel, k] + weight * table[texel, k + 1]
        r, texel = np.broadcast_arrays(r, texel)
        with np.errstate(over="ignore"):  # a huge r becomes inf: outside the support
            position = np.nan_to_num(r, nan=np.inf) * (self.segments / self.r_s)
        inside = (position >= 0) & (position < self.segments)
        position = np.where(inside, position, 0.0)
        k = np.minimum(position.astype(np.int64), self.segments - 1)
        weight = (position - k)[..., None]
        table = self.flat_log_profile
        value = (1.0 - weight) * table[texel, k] + weight * table[texel, k + 1]
        return np.where(inside[..., None], value, LOG_FLOOR)

    def profile(self, r, texel=0) -> np.ndarray:
        r""":math:`P_x(r)` in mm^-2 (Eq. 9 of Chen et al. 2012, exponentiated); 0 beyond r_s."""
        log_value = self.log_profile_at(r, texel)
        return np.where(log_value <= LOG_FLOOR, 0.0, np.exp(log_value))

    def diffuse_reflectance(self, r, texel_in, texel_out) -> np.ndarray:
        r"""Eq. 8 of Chen et al. 2012: :math:`R_d(x_i, x_o) = \sqrt{P_{x_i}(r)P_{x_o}(r)}`, mm^-2.

        Parameters
        ----------
        r : array_like
            Distance between the points of incidence and exit, mm.
        texel_in, texel_out : array_like of int
            Flat texel indices of :math:`x_i` and :math:`x_o`.
        """
        log_in = self.log_profile_at(r, texel_in)
        log_out = self.log_profile_at(r, texel_out)
        outside = (log_in <= LOG_FLOOR) | (log_out <= LOG_FLOOR)
        return np.where(outside, 0.0, np.exp(0.5 * (log_in + log_out)))

    # ---------------------------------------------------------------- energy
    @functools.cached_property
    def _cumulative_knot_energy(self) -> np.ndarray:
        r"""Return :math:`\int_0^{r_k} P r\,dr` at every knot, shape (T, n + 1, 3)."""
        table = self.flat_log_profile
        step = self.r_s / self.segments
        radii = self.knot_radii[:-1][None, :, None]
        moments = segment_moment(table[:, :-1], table[:, 1:], radii, step)
        cumulative = np.zeros_like(table)
        cumulative[:, 1:] = np.cumsum(moments, axis=1)
        return cumulative

    def radial_energy(self, radius, texel=0) -> np.ndarray:
        r""":math:`\int_0^{\rho} P_x(r)\,r\,dr` (dimensionless), exact for Eq. 9's profile.

        ``radius`` (mm) and ``texel`` broadcast; result ``broadcast + (3,)``.
        """
        radius = np.asarray(radius, dtype=np.float64)
        texel = np.asarray(texel, dtype=np.int64)
        radius, texel = np.broadcast_arrays(radius, texel)
        step = self.r_s / self.segments
        position = np.clip(np.nan_to_num(radius, nan=0.0) / step, 0.0, self.segments)
        k = np.minimum(position.astype(np.int64), self.segments - 1)
        fraction = (position - k)[..., None]
        table = self.flat_log_profile
        start = table[texel, k]
        end = table[texel, k + 1]
        partial = segment_moment(start, start + fraction * (end - start),
                                 (k * step)[..., None], fraction * step)
        return self._cumulative_knot_energy[texel, k] + partial

    def total_diffuse_reflectance(self) -> np.ndarray:
        r""":math:`2\pi\int_0^{r_s} P_x(r)\,r\,dr` per texel and channel, shape (H, W, 3)."""
        total = 2.0 * np.pi * self._cumulative_knot_energy[:, -1]
        return total.reshape(*self.resolution, 3)

    def channel_scattering_ranges(self, fraction: float | None = None) -> np.ndarray:
        r"""Radius keeping ``fraction`` of each profile's energy, mm, shape (H, W, 3).

        The effective scattering range :math:`R_{P_x}` of Eq. 11 of Chen et al. 2012
        (``fraction`` = 0.95 there; default the material's ``range_energy``), per channel.
        Solved exactly on the log-linear segments by bisection; 0 for a zero profile.
        """
        fraction = self.range_energy if fraction is None else fraction
        if not 0.0 < fraction <= 1.0:
            raise InputError("must be in (0, 1]", field="fraction", value=fraction)
        cache = self.__dict__.setdefault("_range_cache", {})
        if float(fraction) not in cache:
            cache[float(fraction)] = self._channel_ranges(float(fraction))
        return cache[float(fraction)]

    def _channel_ranges(self, fraction: float) -> np.ndarray:
        cumulative = self._cumulative_knot_energy  # (T, n + 1, 3)
        target = fraction * cumulative[:, -1:, :]
        # the segment in which the cumulative energy crosses the target
        k = np.clip((cumulative[:, 1:, :] < target).sum(axis=1), 0, self.segments - 1)
        texels = np.arange(self.texel_count)[:, None]
        channels = np.arange(3)[None, :]
        table = self.flat_log_profile
        start = table[texels, k, channels]
        end = table[texels, k + 1, channels]
        base = cumulative[texels, k, channels]
        wanted = target[:, 0, :] - base
        step = self.r_s / self.segments
        low = np.zeros_like(start)
        high = np.ones_like(start)
        for _ in range(48):  # bisection to 2^-48 of a segment
            middle = 0.5 * (low + high)
            energy = segment_moment(start, start + middle * (end - start), k * step,
                                    middle * step)
            below = energy < wanted
            low = np.where(below, middle, low)
            high = np.where(below, high, middle)
        ranges = (k + 0.5 * (low + high)) * step
        ranges = np.where(cumulative[:, -1, :] > 0, ranges, 0.0)
        return ranges.reshape(*self.resolution, 3)

    @functools.cached_property
    def effective_scattering_range(self) -> np.ndarray:
        r""":math:`R_{P_x}`, the effective scattering range of each texel in mm, shape (H, W).

        The radius keeping ``range_energy`` of the profile's energy (95 % in Eq. 11 of
        Chen et al. 2012), taken as the largest over the RGB channels so that splatting up
        to it (Eq. 13) keeps at least that much in every channel.
        """
        return self.channel_scattering_ranges().max(axis=-1)

    @functools.cached_property
    def sampling_scattering_range(self) -> np.ndarray:
        """Return the smallest channel range per texel, mm, shape (H, W).

        It sets the irradiance sampling rate of Eq. 11 of Chen et al. 2012, so that no
        channel is undersampled.
        """
        return self.channel_scattering_ranges().min(axis=-1)

    @functools.cached_property
    def normalization_constant(self) -> np.ndarray:
        r"""Eq. 16 of Chen et al. 2012: :math:`C = R_P^2 / \int_0^{R_P} P(r)\,r\,dr`.

        Per texel and channel, shape (H, W, 3), with :math:`R_P` the texel's
        :attr:`effective_scattering_range`; 0 for a zero profile.
        """
        ranges = self.effective_scattering_range.reshape(-1)
        energy = self.radial_energy(ranges[:, None], np.arange(self.texel_count)[:, None])[:, 0]
        with np.errstate(divide="ignore", invalid="ignore"):
            constant = np.where(energy > 0, ranges[:, None] ** 2 / energy, 0.0)
        return constant.reshape(*self.resolution, 3)

    def normalized_profile(self, r_unit, texel=0) -> np.ndarray:
        r"""Eq. 15 of Chen et al. 2012: :math:`P'_x(r) = C(x)\,P_x(r R_{P_x})`, dimensionless.

        ``r_unit`` is the distance in units of the texel's effective scattering range, so
        that :math:`\int_0^1 P'_x(r)\,r\,dr = 1` in every channel.
        """
        texel = np.asarray(texel, dtype=np.int64)
        ranges = self.effective_scattering_range.reshape(-1)[texel]
        constant = self.normalization_constant.reshape(-1, 3)[texel]
        return constant * self.profile(np.asarray(r_unit, dtype=np.float64) * ranges, texel)

    def mean_normalized_profile(self, r_unit) -> np.ndarray:
        r""":math:`\bar P(r)`: the mean of Eq. 15's normalised profiles over texels and channels.

        Chen et al. 2012, text after Eq. 14. ``r_unit`` in [0, 1]; returns shape of ``r_unit``.
        At most :data:`MEAN_PROFILE_TEXELS` texels (a regular subsample) enter the mean.
        """
        r_unit = np.asarray(r_unit, dtype=np.float64)
        texels = np.arange(self.texel_count)
        texels = texels[:: max(1, len(texels) // MEAN_PROFILE_TEXELS)]
        values = self.normalized_profile(r_unit.reshape(-1, 1), texels[None, :])
        return values.mean(axis=(1, 2)).reshape(r_unit.shape)

    # ---------------------------------------------------------------- construction
    def with_name(self, name: str) -> SubEditProfiles:
        """Return a copy labelled ``name``."""
        return SubEditProfiles(self.log_profile, self.r_s, self.eta, name, self.range_energy)

    def with_range_energy(self, fraction: float) -> SubEditProfiles:
        """Return a copy whose effective scattering range keeps ``fraction`` of the energy."""
        return SubEditProfiles(self.log_profile, self.r_s, self.eta, self.name, fraction)

    @classmethod
    def blend(cls, first: SubEditProfiles, second: SubEditProfiles, weight, *,
              name: str = "") -> SubEditProfiles:
        r"""Texture whose texels interpolate ``ln P`` of two homogeneous profiles.

        :math:`\hat P^k = (1 - t)\hat P_a^k + t\hat P_b^k` per texel, with ``weight`` the
        texture of :math:`t \in [0, 1]`, shape (H, W). Both profiles must share ``r_s`` and
        ``n``; :math:`\eta` is blended linearly.
        """
        for which, profiles in (("first", first), ("second", second)):
            if not profiles.is_homogeneous:
                raise InputError("blending takes homogeneous (1 x 1) profiles", field=which,
                                 value=profiles.resolution)
        if first.segments != second.segments or not np.isclose(first.r_s, second.r_s):
            raise InputError("both profiles must share r_s and the segment count",
                             field="second", value=(second.r_s, second.segments))
        weight = np.clip(check_finite(weight, "weight"), 0.0, 1.0)
        if weight.ndim != 2:
            raise InputError("must be an H x W texture", field="weight", value=weight.shape)
        t = weight[..., None, None]
        table = (1.0 - t) * first.log_profile[0, 0] + t * second.log_profile[0, 0]
        eta = float(np.mean((1.0 - weight) * first.eta + weight * second.eta))
        return cls(table, first.r_s, eta, name)

    def cache_key(self) -> dict:
        """Return what identifies this material in content hashes."""
        return {"type": "subedit", "log_profile": self.log_profile, "r_s": self.r_s,
                "eta": self.eta}


# -------------------------------------------------------------------- dipole conversion
class DipoleConversion(NamedTuple):
    r"""A radial profile (the dipole's, or any) converted to SubEdit, and the error made.

    ``relative_error`` per channel: energy-weighted L1 distance
    :math:`(\int_0^{r_s}|P - R|r\,dr + \int_{r_s}^\infty R r\,dr) /
    \int_0^\infty R r\,dr`; ``truncated_energy``: the second term alone.
    """

    profiles: SubEditProfiles
    relative_error: np.ndarray
    truncated_energy: np.ndarray


def _entering(dipole: Dipole) -> DipoleProfile:
    """Return the dipole's R_d per unit power entering (Chen et al. 2012: F_t at entry)."""
    return DipoleProfile(dipole, entry_fresnel=False)


def _default_radius(profile) -> float:
    """Return the radius (mm) a profile's SubEdit conversion keeps by default (99.9 %)."""
    if isinstance(profile, DipoleProfile):
        return _energy_radius(profile, DEFAULT_RADIUS_ENERGY)
    # the profile's own inverse CDF: a uniform trapezoid misses the energy of a profile
    # that peaks (or diverges, as 1/r) at r = 0 and walks r_s out to its cap
    return min(float(np.max(profile.radius_containing(DEFAULT_RADIUS_ENERGY))),
               MAX_DEFAULT_RADIUS)


def _energy_radius(profile, fraction: float) -> float:
    """Radius (mm) within which every channel of ``profile`` keeps ``fraction`` of its energy."""
    total = profile.total() / (2.0 * np.pi)
    scale = profile.length_scale()
    radius = 4.0 * float(np.max(scale[np.isfinite(scale)], initial=1.0))
    while True:
        grid = np.linspace(0.0, radius, 4001)
        energy = np.trapezoid(profile.reflection(grid) * grid[:, None], grid, axis=0)
        if np.all(energy >= fraction * total) or radius >= MAX_DEFAULT_RADIUS:
            break
        radius = min(1.5 * radius, MAX_DEFAULT_RADIUS)
    cumulative = np.concatenate([np.zeros((1, 3)), np.cumsum(
        0.5 * (profile.reflection(grid[1:]) * grid[1:, None] + profile.reflection(grid[:-1])
               * grid[:-1, None]) * np.diff(grid)[:, None], axis=0)])
    return float(max(np.interp(fraction * total[c], cumulative[:, c], grid) for c in range(3)))


def _quadrature_grid(r_s: float, segments: int, smallest: float) -> np.ndarray:
    """Fine radii on [0, r_s]: geometric near 0 (the dipole peaks within z_r), uniform after."""
    step = r_s / segments
    near = np.geomspace(max(smallest, 1e-9), step, 400)
    far = np.linspace(0.0, r_s, segments * 96 + 1)
    return np.unique(np.concatenate([[0.0], near, far]))


def _log_target(values: np.ndarray) -> np.ndarray:
    """Return ln R of one channel on the fitting grid, its negligible tail floored and monotone.

    Where R is below :data:`NEGLIGIBLE_TAIL` of its peak, ln R is the running minimum
    along r, bounded below by :data:`RELATIVE_LOG_FLOOR` of the peak: what the knots
    follow there carries no energy, and a well-posed least squares needs a smooth target.
    """
    peak = float(values.max(initial=0.0))
    floor = peak * RELATIVE_LOG_FLOOR if peak > 0 else np.exp(LOG_FLOOR)
    logs = np.log(np.maximum(values, max(floor, np.exp(LOG_FLOOR))))
    return np.where(values < peak * NEGLIGIBLE_TAIL, np.minimum.accumulate(logs), logs)


def subedit_from_dipole(dipole: Dipole, *, segments: int = DEFAULT_SEGMENTS,
                        r_s: float | None = None) -> DipoleConversion:
    r"""Convert a dipole medium to a homogeneous SubEdit profile, with the error made.

    :func:`subedit_from_profile` of the dipole's :math:`R_d` (Jensen et al. 2001) per
    unit power entering.

    Parameters
    ----------
    dipole : Dipole
        The medium (coefficients in mm^-1).
    segments : int
        ``n`` of Eq. 9, >= 1.
    r_s : float, optional
        Maximum scattering radius in mm; default: the radius keeping 99.9 % of the energy
        in every channel.

    Returns
    -------
    DipoleConversion
    """
    if not isinstance(dipole, Dipole):
        raise InputError("expected a Dipole", field="dipole", value=type(dipole).__name__)
    return subedit_from_profile(_entering(dipole), dipole.eta, segments=segments, r_s=r_s,
                                name=dipole.name)


def subedit_from_profile(profile, eta: float, *, segments: int = DEFAULT_SEGMENTS,
                         r_s: float | None = None, name: str = "") -> DipoleConversion:
    r"""Convert a radial profile to a homogeneous SubEdit profile, with the error made.

    The knots :math:`\hat P^k` minimise :math:`\sum_j w_j(\ln P(r_j) - \ln R(r_j))^2`
    with energy weights :math:`w_j = r_j R(r_j)\Delta r_j` (a relative error weighted by
    where the energy is), then all knots shift so that :math:`\int_0^{r_s}P r\,dr` equals the
    profile's. For a homogeneous material Eq. 8 of Chen et al. 2012 gives
    :math:`R = \sqrt{P P} = P`.

    Parameters
    ----------
    profile : RadialProfile
        :math:`R(r)` in mm^-2 per unit power entering
        (:mod:`translucent.materials.profiles`; the dipole's in
        :func:`subedit_from_dipole`).
    eta : float
        Relative index of refraction of the boundary, for the Fresnel terms of Eq. 5-7.
    segments : int
        ``n`` of Eq. 9, >= 1.
    r_s : float, optional
        Maximum scattering radius in mm; default: the radius keeping 99.9 % of the energy
        in every channel.
    name : str
        The texture's name.

    Returns
    -------
    DipoleConversion
        ``relative_error`` measured against ``profile``.
    """
    require_radial(profile)
    if int(segments) != segments or not 1 <= int(segments) <= 1024:
        raise InputError("must be an integer in [1, 1024]", field="segments", value=segments)
    segments = int(segments)
    r_s = _checked_radius(_default_radius(profile) if r_s is None else r_s)
    scale = profile.length_scale()
    grid = _quadrature_grid(r_s, segments,
                            0.01 * float(np.min(scale[np.isfinite(scale)], initial=1.0)))
    target = profile.reflection(grid)  # (m, 3)
    weights = np.gradient(grid)[:, None] * grid[:, None] * target
    weights = weights + TAIL_WEIGHT * weights.max(axis=0, keepdims=True) * \
        np.gradient(grid)[:, None] / r_s
    position = grid * segments / r_s
    k = np.minimum(position.astype(np.int64), segments - 1)
    fraction = position - k
    basis = np.zeros((len(grid), segments + 1))
    basis[np.arange(len(grid)), k] = 1.0 - fraction
    basis[np.arange(len(grid)), k + 1] += fraction
    knots = np.full((segments + 1, 3), LOG_FLOOR)
    for channel in range(3):
        w = weights[:, channel]
        if not np.any(w > 0):
            continue
        root = np.sqrt(w)[:, None]
        log_target = _log_target(target[:, channel])
        solution, *_ = np.linalg.lstsq(basis * root, log_target * root[:, 0], rcond=None)
        knots[:, channel] = solution
    profiles = SubEditProfiles(knots, r_s, eta, name)
    fitted = profiles.profile(grid)
    target_inside = np.trapezoid(target * grid[:, None], grid, axis=0)
    fitted_inside = np.trapezoid(fitted * grid[:, None], grid, axis=0)
    with np.errstate(divide="ignore"):
        shift = np.where((fitted_inside > 0) & (target_inside > 0),
                         np.log(target_inside / fitted_inside), 0.0)
    knots = np.maximum(knots + shift, LOG_FLOOR)
    profiles = SubEditProfiles(knots, r_s, eta, name)
    fitted = profiles.profile(grid)
    total = profile.total() / (2.0 * np.pi)
    truncated = np.clip(total - target_inside, 0.0, None)
    difference = np.trapezoid(np.abs(fitted - target) * grid[:, None], grid, axis=0)
    with np.errstate(divide="ignore", invalid="ignore"):
        error = np.where(total > 0, (difference + truncated) / total, 0.0)
        truncated_fraction = np.where(total > 0, truncated / total, 0.0)
    return DipoleConversion(profiles, error, truncated_fraction)


# -------------------------------------------------------------------- built-in materials
def _value_noise(u, v, frequency: int, rng) -> np.ndarray:
    """Smooth value noise on the unit square: random lattice values, smoothstep-interpolated."""
    lattice = rng.random((frequency + 1, frequency + 1))
    x = u * frequency
    y = v * frequency
    i = np.minimum(x.astype(int), frequency - 1)
    j = np.minimum(y.astype(int), frequency - 1)
    fx = x - i
    fy = y - j
    sx = fx * fx * (3 - 2 * fx)
    sy = fy * fy * (3 - 2 * fy)
    top = (1 - sx) * lattice[j, i] + sx * lattice[j, i + 1]
    bottom = (1 - sx) * lattice[j + 1, i] + sx * lattice[j + 1, i + 1]
    return (1 - sy) * top + sy * bottom


def convert_media(media, *, segments: int = DEFAULT_SEGMENTS,
                  profiles=None) -> list[DipoleConversion]:
    """Convert several dipole media to SubEdit profiles that share one ``r_s``.

    ``r_s`` is the largest of their radii keeping :data:`DEFAULT_RADIUS_ENERGY` of the
    energy (each as :func:`subedit_from_profile` takes it alone), so that the profiles can
    share a texture (blend, per-texel lookup).

    ``profiles``: one radial profile per medium, per unit power entering (a registered
    profile of it), converted instead of the medium's dipole.
    """
    media = list(media)
    if not media:
        raise InputError("needs at least one medium", field="media", value=[])
    made = [_entering(medium) for medium in media] if profiles is None else list(profiles)
    if len(made) != len(media):
        raise InputError("needs one profile per medium", field="profiles", value=len(made))
    r_s = max(_default_radius(profile) for profile in made)
    return [subedit_from_profile(profile, medium.eta, segments=segments, r_s=r_s,
                                 name=medium.name) for profile, medium in zip(made, media,
                                                                              strict=True)]


def _converted_pair(first: str, second: str, segments: int):
    a, b = convert_media([measured_medium(first), measured_medium(second)], segments=segments)
    return a.profiles, b.profiles


def _texel_centres(resolution: int):
    resolution = check_count(resolution, "resolution", 1)
    centres = (np.arange(resolution) + 0.5) / resolution
    return np.meshgrid(centres, centres)  # u varies along columns, v along rows


def checker_material(resolution: int = 64, squares: int = 8, first: str = "Marble",
                     second: str = "Skin1", segments: int = DEFAULT_SEGMENTS) -> SubEditProfiles:
    """Build a checkerboard of two measured media (Jensen et al. 2001), ``squares`` per side.

    The heterogeneous "marble chessboard" of Chen et al. 2012, Fig. 8, made from the
    measured table.
    """
    squares = check_count(squares, "squares", 1)
    a, b = _converted_pair(first, second, segments)
    u, v = _texel_centres(resolution)
    weight = ((np.floor(u * squares) + np.floor(v * squares)) % 2).astype(np.float64)
    return SubEditProfiles.blend(a, b, weight, name=f"checker({first},{second})")


def veined_marble_material(resolution: int = 128, seed: int = 7, base: str = "Marble",
                           vein: str = "Skin1", segments: int = DEFAULT_SEGMENTS
                           ) -> SubEditProfiles:
    """Measured marble with veins of a second medium, from procedural turbulence.

    The vein weight is ``|sin(2 pi (3 u + 2 v) + 6 turbulence(u, v))|^(1/4)`` inverted, with
    four octaves of seeded value noise as turbulence; ``ln P`` interpolates between the two
    converted dipoles (Song et al. 2009 edit profiles in the log domain).
    """
    seed = check_count(seed, "seed", 0)
    a, b = _converted_pair(base, vein, segments)
    u, v = _texel_centres(resolution)
    rng = np.random.default_rng(seed)
    turbulence = sum(_value_noise(u, v, 4 * 2**octave, rng) / 2**octave for octave in range(4))
    stripes = np.abs(np.sin(2 * np.pi * (3 * u + 2 * v) + 6.0 * turbulence))
    weight = 1.0 - stripes ** 0.25
    return SubEditProfiles.blend(a, b, weight, name=f"veined_marble({base},{vein})")


def wax_gradient_material(resolution: int = 64, first: str = "Apple", second: str = "Potato",
                          segments: int = DEFAULT_SEGMENTS) -> SubEditProfiles:
    """Build a smooth gradient along v between two measured media (a wax of varying range)."""
    a, b = _converted_pair(first, second, segments)
    _, v = _texel_centres(resolution)
    return SubEditProfiles.blend(a, b, v, name=f"wax_gradient({first},{second})")


#: Built-in heterogeneous materials: name -> constructor taking keyword options.
BUILTIN_SUBEDIT = {
    "checker": checker_material,
    "veined_marble": veined_marble_material,
    "wax_gradient": wax_gradient_material,
}


@functools.lru_cache(maxsize=16)
def _builtin_cached(name: str, options: tuple) -> SubEditProfiles:
    return BUILTIN_SUBEDIT[name](**dict(options))


def builtin_subedit(name: str, **options) -> SubEditProfiles:
    """Return the built-in heterogeneous material ``name`` (see :data:`BUILTIN_SUBEDIT`).

    Options are passed to its constructor (``resolution``, measured-medium names, ...).
    Unknown names raise :class:`InputError` listing the valid ones.
    """
    if name not in BUILTIN_SUBEDIT:
        raise InputError(f"unknown built-in SubEdit material; valid: {', '.join(BUILTIN_SUBEDIT)}",
                         field="builtin", value=name)
    _check_texture_memory(name, options)
    try:
        return _builtin_cached(name, tuple(sorted(options.items())))
    except TypeError as error:
        raise InputError(f"bad option for '{name}' ({error})", field="builtin",
                         value=options) from error


def _check_texture_memory(name: str, options: dict) -> None:
    """Refuse, before it is made, a built-in texture the machine cannot hold."""
    import inspect

    from ..resources import check_memory

    defaults = {key: parameter.default for key, parameter in
                inspect.signature(BUILTIN_SUBEDIT[name]).parameters.items()}
    resolution = check_count(options.get("resolution", defaults["resolution"]), "resolution")
    segments = check_count(options.get("segments", defaults["segments"]), "segments")
    check_memory(float(resolution) ** 2 * (segments + 1) * 3 * BUILD_BYTES_PER_KNOT,
                 what=f"a {resolution} x {resolution} SubEdit texture of {segments} segments",
                 field="resolution", value=resolution)


# -------------------------------------------------------------------- file format
def save_subedit(path, profiles: SubEditProfiles) -> Path:
    """Write ``profiles`` as an uncompressed NumPy ``.npz`` (docs/subedit-format.md), atomically."""
    if not isinstance(profiles, SubEditProfiles):
        raise InputError("expected SubEditProfiles", file=path, field="profiles",
                         value=type(profiles).__name__)
    path = Path(path)
    with atomic_path(path, suffix=".npz") as tmp, open(tmp, "wb") as handle:
        np.savez(handle, format=np.array(FORMAT_NAME), version=np.array(FORMAT_VERSION),
                 log_profile=profiles.log_profile.astype(np.float32),
                 r_s=np.array(profiles.r_s), eta=np.array(profiles.eta),
                 name=np.array(profiles.name))
    return path


def load_subedit(path) -> SubEditProfiles:
    """Read a SubEdit texture written by :func:`save_subedit` (docs/subedit-format.md).

    Raises
    ------
    InputError
        Missing or unreadable file, wrong format name or version, a missing field, a
        wrong shape, or NaN values; the message names the file and the field.
    """
    from ..atomic import check_input_file
    from ..resources import check_npz_memory

    path = check_input_file(path, "path", what="file")
    check_npz_memory(path, field="log_profile")  # before an array is read
    try:
        with np.load(path, allow_pickle=False) as data:
            fields = {key: data[key] for key in data.files}
    except Exception as error:  # numpy raises several types on corrupt archives
        raise InputError(f"not a readable .npz archive ({error})", file=path) from error
    for key in ("format", "version", "log_profile", "r_s"):
        if key not in fields:
            raise InputError("missing field", file=path, field=key)
    for key, integer in (("version", True), ("r_s", False), ("eta", False)):
        value = fields.get(key)
        if value is not None and (value.shape != () or not np.issubdtype(
                value.dtype, np.integer if integer else np.number)
                or np.issubdtype(value.dtype, np.complexfloating)):
            raise InputError("must be an integer" if integer else "must be a number",
                             file=path, field=key, value=value)
    if str(fields["format"]) != FORMAT_NAME:
        raise InputError(f"must be '{FORMAT_NAME}'", file=path, field="format",
                         value=str(fields["format"]))
    if int(fields["version"]) != FORMAT_VERSION:
        raise InputError(f"unsupported version; this reader knows {FORMAT_VERSION}", file=path,
                         field="version", value=int(fields["version"]))
    table = fields["log_profile"]
    if not np.issubdtype(table.dtype, np.floating) and not np.issubdtype(table.dtype,
                                                                         np.integer):
        raise InputError("must hold numbers (float32)", file=path, field="log_profile",
                         value=str(table.dtype))
    if table.ndim != 4 or table.shape[2] < 2 or table.shape[3] != 3 or 0 in table.shape:
        raise InputError("must have shape (H, W, n + 1 >= 2, 3)", file=path,
                         field="log_profile", value=table.shape)
    if np.isnan(table).any():
        raise InputError("holds NaN values", file=path, field="log_profile",
                         value=int(np.isnan(table).sum()))
    try:
        return SubEditProfiles(table, float(fields["r_s"]),
                               float(fields.get("eta", 1.3)), str(fields.get("name", "")))
    except InputError as error:
        raise InputError(error.reason, file=path, field=error.field, value=error.value) from error


def subedit_from_spec(spec: dict, *, file=None) -> SubEditProfiles:
    """Build a SubEdit material from a scene-file table.

    Accepted: ``{type="subedit", builtin="veined_marble", ...options}``,
    ``{type="subedit", file="marble.npz"}`` (relative to the scene file's folder) or
    ``{type="subedit", measured="Marble", segments=32}`` (a converted dipole).
    """
    spec = dict(spec)
    spec.pop("type", None)
    sources = [key for key in ("builtin", "file", "measured") if key in spec]
    if len(sources) != 1:
        raise InputError("a subedit material needs exactly one of builtin, file, measured",
                         file=file, field="material", value=sorted(spec))
    source = sources[0]
    value = spec.pop(source)
    if source == "builtin":
        return builtin_subedit(str(value), **spec)
    if spec and source == "file":
        raise InputError("a subedit file takes no other options", file=file, field="material",
                         value=sorted(spec))
    if source == "file":
        from .factory import spec_file_path

        path = spec_file_path(value, file, "a .npz texture")
        try:
            return load_subedit(path)
        except InputError as error:  # named by the key that holds the path
            reason = error.reason if error.file == str(path) and error.field == "path" \
                else str(error)
            raise InputError(reason, file=file, field="file", value=str(path)) from error
    unknown = sorted(set(spec) - {"segments", "r_s"})
    if unknown:
        raise InputError("unknown option; valid: segments, r_s", file=file, field="material",
                         value=unknown)
    return subedit_from_dipole(measured_medium(str(value)), **spec).profiles


#: Options a scene-file table of type "subedit" may hold (besides exactly one source).
SPEC_KEYS = ("builtin", "file", "measured", "segments", "r_s", "resolution", "squares",
             "first", "second", "seed", "base", "vein")


def _register() -> None:
    from .factory import register_spec_type

    register_spec_type("subedit", subedit_from_spec, SubEditProfiles, keys=SPEC_KEYS,
                       path_keys=("file",),
                       save_hint="this SubEdit texture was made in code: save it with "
                       "save_subedit and refer to it as {type = \"subedit\", file = \"...\"}")


_register()
