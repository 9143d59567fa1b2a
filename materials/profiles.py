r"""Radial (1D) scattering profiles: reflection and transmission as functions of distance.

Translucent radiosity (Sheng et al. 2014, Sect. 4) needs the simplified BSSRDF
:math:`s(r)` as a 1D function of the (optical) distance :math:`r` between the points of
incidence and exit: a *reflection* profile for light entering and leaving on the same side,
and, for thin sheets, a *transmission* profile for light leaving on the other side. Values
are in mm^-2 (exitance per unit incident power), per RGB channel, so that
:math:`2\pi\int_0^\infty s(r)\,r\,dr` is the dimensionless total reflectance (or
transmittance).

Profiles come from

* the dipole of Jensen et al. 2001 (:class:`DipoleProfile`, any measured material or user
  coefficients),
* a slab of finite thickness, reflection and transmission, by the multipole of Donner and
  Jensen 2005 (:class:`SlabProfile`, for thin sheets),
* a user table (:class:`TabulatedProfile`, also from a CSV file), or
* the parametric two-exponential form :math:`a_1 e^{-b_1 r} + a_2 e^{-b_2 r}` that
  Sheng et al. 2014 (Sect. 6.1) use for rose petals (:class:`TwoExponentialProfile`).

A profile is tabulated on a :class:`RadialGrid` (quadratic spacing: fine near 0 where the
dipole peaks) before it is used: the radiosity precomputation stores, for every sample of
the scattering matrix, the grid segment and the offset into it, so that a change of
translucency only re-tabulates the profile (Sheng et al. 2014, Sect. 5.2).

References
----------
Sheng, Shi, Wang, Narasimhan: Translucent radiosity: efficiently combining diffuse
inter-reflection and subsurface scattering. IEEE TVCG 20(7), 2014, Sect. 4, 5.2, 6.1, Eq. 16.
Jensen, Marschner, Levoy, Hanrahan: A practical model for subsurface light transport.
SIGGRAPH 2001.
Donner, Jensen: Light diffusion in multi-layered translucent materials. SIGGRAPH 2005
(the multipole, Eq. 8-11).
"""

from __future__ import annotations

import csv
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import InputError, check_finite
from .dipole import (
    dipole_reflectance_profile,
)
from .fresnel import fresnel_reflectance
from .homogeneous import Dipole, Lambertian, rgb_field
from .multipole import multipole_profiles

__all__ = [
    "PROFILE_KINDS",
    "RadialGrid",
    "RadialProfile",
    "DipoleProfile",
    "MixedProfiles",
    "SlabProfile",
    "TabulatedProfile",
    "TwoExponentialProfile",
    "check_profile_values",
    "diffuse_entry_transmittance",
    "mixed_profile",
    "profile_for",
    "radial_cumulative_integral",
]

#: The two kinds of profile: same side (reflection) and opposite side (transmission).
PROFILE_KINDS = ("reflection", "transmission")

#: Gauss-Legendre nodes for the hemispherical average of the Fresnel transmittance: the
#: integrand is smooth in cos(theta), 64 nodes reach 1e-10.
_FRESNEL_NODES = 64

#: Radial samples per mm-scale feature when a profile's total reflectance is integrated
#: numerically (see :meth:`RadialProfile.total`).
_TOTAL_SAMPLES = 20001


def check_profile_values(values, field: str, *, file=None, name: str = "") -> np.ndarray:
    """Reject NaN, Inf and negative profile values; return them as float64.

    Sheng et al. 2014, Sect. 3.3: a scattering factor is a fraction of energy, so a profile
    must be finite and non-negative everywhere or the radiosity solution is garbage.

    Parameters
    ----------
    values : array_like
        Profile values, mm^-2.
    field : str
        Which field they came from (``"reflection"``, ``"transmission"``).
    file : path, optional
        The file they were read from.
    name : str, optional
        The profile's name, for the message.

    Raises
    ------
    InputError
        Naming the first bad entry and its value.
    """
    array = np.asarray(values, dtype=np.float64)
    label = f"profile '{name}' " if name else "profile "
    bad = ~np.isfinite(array)
    if bad.any():
        index = tuple(int(i) for i in np.argwhere(bad)[0])
        raise InputError(f"{label}values must be finite (no NaN or Inf): {int(bad.sum())} are "
                         f"not (first at index {index})", file=file, field=field,
                         value=float(array[index]))
    negative = array < 0
    if negative.any():
        index = tuple(int(i) for i in np.argwhere(negative)[0])
        raise InputError(f"{label}values must be >= 0 (a scattering profile is an energy "
                         f"density): {int(negative.sum())} are negative (first at index "
                         f"{index})", file=file, field=field, value=float(array[index]))
    return array


def diffuse_entry_transmittance(eta) -> np.ndarray:
    r"""Fraction of diffuse (cosine-weighted) light that enters a smooth dielectric.

    :math:`1 - F_{dr}^{ext} = \int_0^1 (1 - F_r(\eta, \mu))\,2\mu\,d\mu`, evaluated with
    Gauss-Legendre quadrature of the exact Fresnel reflectance. It is the
    :math:`F_t(\eta, \omega_i)` of the dipole BSSRDF of Jensen et al. 2001 averaged over the
    diffuse irradiance of a radiosity patch (Sheng et al. 2014, Sect. 3.2).

    Parameters
    ----------
    eta : array_like
        Relative index of refraction, >= 1.

    Returns
    -------
    ndarray
        Dimensionless, in (0, 1]; 1 at eta = 1, 0.940 at eta = 1.3.
    """
    nodes, weights = np.polynomial.legendre.leggauss(_FRESNEL_NODES)
    mu = 0.5 * (nodes + 1.0)
    eta = np.asarray(eta, dtype=np.float64)
    reflectance = fresnel_reflectance(eta[..., None], mu)
    return 1.0 - np.sum(0.5 * weights * reflectance * 2.0 * mu, axis=-1)


@dataclass(frozen=True)
class RadialGrid:
    r"""Radii on which profiles are tabulated: :math:`r_k = r_{max}(k/(K-1))^2`.

    Quadratic spacing puts half of the nodes within a quarter of ``max_radius``, where the
    dipole varies fastest, and lets :meth:`locate` find a segment in O(1). Beyond
    ``max_radius`` (the cut-off distance max_d of Sheng et al. 2014, Sect. 5.2) a profile is 0.

    Parameters
    ----------
    max_radius : float
        mm, > 0.
    samples : int
        Number of nodes K, >= 2.
    """

    max_radius: float
    samples: int = 2048

    def __post_init__(self):
        max_radius = float(check_finite(self.max_radius, "max_radius"))
        if max_radius <= 0:
            raise InputError("must be > 0 mm", field="max_radius", value=self.max_radius)
        if int(self.samples) != self.samples or int(self.samples) < 2:
            raise InputError("must be an integer >= 2", field="samples", value=self.samples)
        object.__setattr__(self, "max_radius", max_radius)
        object.__setattr__(self, "samples", int(self.samples))

    @property
    def radius(self) -> np.ndarray:
        """The K node radii in mm, increasing from 0 to ``max_radius``."""
        return self.max_radius * np.linspace(0.0, 1.0, self.samples) ** 2

    def locate(self, r) -> tuple[np.ndarray, np.ndarray]:
        """Segment index and offset of each radius: ``value = (1-f) v[k] + f v[k+1]``.

        Parameters
        ----------
        r : array_like
            Radii in mm, >= 0. Radii at or beyond ``max_radius`` get ``k = K - 2, f = 1``
            (the last node); callers drop them first where the profile must be 0 there.

        Returns
        -------
        k : ndarray of int32
            In [0, K-2].
        f : ndarray of float32
            In [0, 1].
        """
        r = np.clip(np.asarray(r, dtype=np.float64), 0.0, self.max_radius)
        position = np.sqrt(r / self.max_radius) * (self.samples - 1)
        k = np.minimum(np.floor(position), self.samples - 2).astype(np.int32)
        radius = self.radius
        left, right = radius[k], radius[k + 1]
        f = np.clip((r - left) / (right - left), 0.0, 1.0).astype(np.float32)
        return k, f


def radial_cumulative_integral(radius, values) -> np.ndarray:
    r"""Cumulative radial integral :math:`C(r_k) = \int_0^{r_k} s(r)\,r\,dr` of a tabulated profile.

    Exact for the piecewise-linear interpolant of ``values`` between the nodes ``radius``
    (the interpolation the radiosity scattering factors use). :math:`2\pi C` is the energy
    of the profile inside radius :math:`r_k` (Sheng et al. 2014, Eq. 8 over a disc).

    Parameters
    ----------
    radius : ndarray, shape (K,)
        Increasing radii, mm, starting at 0.
    values : ndarray, shape (K, ...)
        Profile values at the nodes, mm^-2.

    Returns
    -------
    ndarray, shape (K, ...)
        Dimensionless; ``C[0] = 0``.
    """
    radius = np.asarray(radius, dtype=np.float64)
    values = np.asarray(values, dtype=np.float64)
    h = np.diff(radius)
    left = radius[:-1]
    extra = (1,) * (values.ndim - 1)
    # integral of (s_k (1-t) + s_{k+1} t)(r_k + t h) h dt over t in [0, 1]
    weight_left = (h * (left / 2.0 + h / 6.0)).reshape(-1, *extra)
    weight_right = (h * (left / 2.0 + h / 3.0)).reshape(-1, *extra)
    segments = weight_left * values[:-1] + weight_right * values[1:]
    return np.concatenate([np.zeros((1,) + values.shape[1:]), np.cumsum(segments, axis=0)])


class RadialProfile:
    """A radial scattering profile: reflection and, where defined, transmission.

    Subclasses implement :meth:`reflection` (and :meth:`transmission` when
    ``has_transmission``); everything else follows. Values are mm^-2 per RGB channel.
    """

    name: str = ""
    has_transmission: bool = False

    def reflection(self, r) -> np.ndarray:
        """Reflection profile at distances ``r`` (mm): shape ``r.shape + (3,)``, mm^-2."""
        raise NotImplementedError

    def transmission(self, r) -> np.ndarray:
        """Transmission profile at ``r`` (mm), shape ``r.shape + (3,)``; 0 where undefined."""
        r = np.asarray(r, dtype=np.float64)
        return np.zeros(r.shape + (3,))

    def evaluate(self, r, kind: str = "reflection") -> np.ndarray:
        """Return the profile of ``kind`` (one of :data:`PROFILE_KINDS`) at ``r`` (mm), mm^-2."""
        if kind not in PROFILE_KINDS:
            raise InputError(f"unknown profile kind; valid: {', '.join(PROFILE_KINDS)}",
                             field="kind", value=kind)
        return self.reflection(r) if kind == "reflection" else self.transmission(r)

    def tabulate(self, grid: RadialGrid, kind: str = "reflection") -> np.ndarray:
        """Values on ``grid.radius``, shape (K, 3), checked finite and non-negative.

        Raises
        ------
        InputError
            When the profile gives NaN, Inf or negative values (see
            :func:`check_profile_values`).
        """
        return check_profile_values(self.evaluate(grid.radius, kind), kind, name=self.name)

    def total(self, kind: str = "reflection", max_radius: float | None = None) -> np.ndarray:
        r"""Total reflectance (or transmittance) :math:`2\pi\int_0^{R} s(r)\,r\,dr` per channel.

        Integrated numerically on a quadratic grid (exact closed forms override this).
        ``max_radius`` defaults to :meth:`support_radius`.
        """
        radius = self.support_radius() if max_radius is None else float(max_radius)
        grid = RadialGrid(radius, _TOTAL_SAMPLES)
        values = self.tabulate(grid, kind)
        return 2.0 * np.pi * radial_cumulative_integral(grid.radius, values)[-1]

    def support_radius(self, energy_fraction: float = 1e-3) -> float:
        """Return the radius (mm) beyond which at most ``energy_fraction`` of the energy lies.

        Used to pick the cut-off distance max_d of Sheng et al. 2014, Sect. 5.2. The largest
        of the three channels; found on a geometric sweep out to 1e4 mm.
        """
        if not 0 < energy_fraction < 1:
            raise InputError("must be in (0, 1)", field="energy_fraction", value=energy_fraction)
        far = 1e4
        grid = RadialGrid(far, _TOTAL_SAMPLES)
        kinds = PROFILE_KINDS if self.has_transmission else PROFILE_KINDS[:1]
        needed = 0.0
        for kind in kinds:
            cumulative = radial_cumulative_integral(grid.radius, self.tabulate(grid, kind))
            total = cumulative[-1]
            for channel in range(3):
                if total[channel] <= 0:
                    continue
                inside = cumulative[:, channel] >= (1.0 - energy_fraction) * total[channel]
                needed = max(needed, float(grid.radius[np.argmax(inside)]))
        return needed if needed > 0 else far

    def scaled(self, factor) -> TabulatedProfile:
        """Return the profile times ``factor`` (scalar or RGB), tabulated on its own support."""
        factor = rgb_field(factor, "factor")
        grid = RadialGrid(self.support_radius(1e-6), 4096)
        transmission = self.tabulate(grid, "transmission") * factor \
            if self.has_transmission else None
        return TabulatedProfile(grid.radius, self.tabulate(grid) * factor, transmission,
                                name=f"{self.name} x {factor.tolist()}")

    def cache_key(self) -> dict:
        """Return what identifies this profile in content hashes."""
        raise NotImplementedError


def _rgb(r, values) -> np.ndarray:
    """Broadcast ``r`` (any shape) against RGB parameters: shape ``r.shape + (3,)``."""
    return np.asarray(r, dtype=np.float64)[..., None] + np.zeros_like(values)


class DipoleProfile(RadialProfile):
    r"""The dipole reflection profile of a homogeneous medium (Jensen et al. 2001).

    :math:`s(r) = T_{in}\,R_d(r)` with :math:`R_d` the dipole diffuse reflectance
    (:func:`~translucent.materials.dipole_reflectance_profile`) and :math:`T_{in}` the
    fraction of diffuse light that crosses the boundary (:func:`diffuse_entry_transmittance`;
    1 when ``entry_fresnel`` is False). Sheng et al. 2014 compute the Cornell-box marble
    block's profile this way (Sect. 6.1). No transmission: a thick object.

    Parameters
    ----------
    dipole : Dipole
        The medium (mm^-1).
    entry_fresnel : bool
        Include the Fresnel transmittance of the diffuse irradiance at entry.
    """

    def __init__(self, dipole: Dipole, *, entry_fresnel: bool = True):
        if not isinstance(dipole, Dipole):
            raise InputError("expected a Dipole", field="dipole", value=type(dipole).__name__)
        self.dipole = dipole
        self.entry_fresnel = bool(entry_fresnel)
        self.name = dipole.name or "dipole"
        self.entry = float(diffuse_entry_transmittance(dipole.eta)) if entry_fresnel else 1.0

    def reflection(self, r) -> np.ndarray:
        """:math:`T_{in} R_d(r)`, mm^-2, shape ``r.shape + (3,)``."""
        r = np.asarray(r, dtype=np.float64)[..., None]
        d = self.dipole
        return self.entry * dipole_reflectance_profile(r, d.sigma_a, d.sigma_s_prime, d.eta)

    def total(self, kind: str = "reflection", max_radius: float | None = None) -> np.ndarray:
        """Return the closed form (Jensen et al. 2001, Eq. 6) when integrated to infinity."""
        if kind == "reflection" and max_radius is None:
            return self.entry * self.dipole.total_diffuse_reflectance()
        return super().total(kind, max_radius)

    def cache_key(self) -> dict:
        """Return what identifies this profile in content hashes."""
        return {"type": "dipole_profile", "dipole": self.dipole.cache_key(),
                "entry_fresnel": self.entry_fresnel}


class SlabProfile(RadialProfile):
    r"""Reflection and transmission of a slab of thickness ``d``: the multipole.

    Donner and Jensen 2005, Eq. 8-11, with the same boundary on both faces: dipole pairs
    at :math:`z_{r,i} = 2i(d + 2z_b) + \ell`, :math:`z_{v,i} = 2i(d + 2z_b) - \ell - 2z_b`,
    :math:`i = -n..n`, :math:`\ell = 1/\sigma'_t`, :math:`z_b = 2AD`, :math:`D = 1/(3\sigma'_t)`:

    .. math::
        R(r) = \frac{\alpha'}{4\pi}\sum_i \Big[\frac{z_{r,i}(1+\sigma_{tr}d_{r,i})
        e^{-\sigma_{tr}d_{r,i}}}{d_{r,i}^3} - \frac{z_{v,i}(1+\sigma_{tr}d_{v,i})
        e^{-\sigma_{tr}d_{v,i}}}{d_{v,i}^3}\Big]

    and :math:`T(r)` the same with :math:`z \to d - z`. For the thin sheets (petals) of
    Sheng et al. 2014, Sect. 5.2 and 6.1: same side by :math:`R`, other side by :math:`T`.
    The pair with :math:`i = 0` is the dipole of Jensen et al. 2001, so :math:`R \to R_d`
    as :math:`d \to \infty`.

    Parameters
    ----------
    dipole : Dipole
        The medium (mm^-1).
    thickness : float
        Slab thickness d, mm, larger than the reduced mean free path of every channel.
    pairs : int
        n, the number of image pairs on each side (>= 0); 5 is ample for d >= 1 mfp.
    entry_fresnel : bool
        Multiply by :func:`diffuse_entry_transmittance`, as :class:`DipoleProfile`.
    """

    has_transmission = True

    def __init__(self, dipole: Dipole, thickness: float, *, pairs: int = 5,
                 entry_fresnel: bool = True):
        if not isinstance(dipole, Dipole):
            raise InputError("expected a Dipole", field="dipole", value=type(dipole).__name__)
        thickness = float(check_finite(thickness, "thickness"))
        if thickness <= 0:
            raise InputError("must be > 0 mm", field="thickness", value=thickness)
        if int(pairs) != pairs or pairs < 0:
            raise InputError("must be an integer >= 0", field="pairs", value=pairs)
        longest = float(np.max(dipole.mean_free_path))
        if thickness <= longest:
            # the real source at depth 1/sigma'_t must lie inside the slab
            raise InputError(f"must exceed the reduced mean free path {longest:.4g} mm (the "
                             "diffusion source lies below a thinner slab)", field="thickness",
                             value=thickness)
        self.dipole = dipole
        self.thickness = thickness
        self.pairs = int(pairs)
        self.entry_fresnel = bool(entry_fresnel)
        self.name = f"{dipole.name or 'slab'} ({thickness:g} mm)"
        self.entry = float(diffuse_entry_transmittance(dipole.eta)) if entry_fresnel else 1.0

    def _profiles(self, r, transmission: bool):
        d = self.dipole
        r = np.asarray(r, dtype=np.float64)[..., None]
        reflect, transmit = multipole_profiles(r, d.sigma_a, d.sigma_s_prime, d.eta,
                                               self.thickness, poles=self.pairs,
                                               transmission=transmission)
        return self.entry * (transmit if transmission else reflect)

    def reflection(self, r) -> np.ndarray:
        """:math:`R(r)`, mm^-2, shape ``r.shape + (3,)`` (Donner and Jensen 2005, Eq. 10)."""
        return self._profiles(r, transmission=False)

    def transmission(self, r) -> np.ndarray:
        """:math:`T(r)`, mm^-2, shape ``r.shape + (3,)`` (Donner and Jensen 2005, Eq. 11)."""
        return self._profiles(r, transmission=True)

    def cache_key(self) -> dict:
        """Return what identifies this profile in content hashes."""
        return {"type": "slab_profile", "dipole": self.dipole.cache_key(),
                "thickness": self.thickness, "pairs": self.pairs,
                "entry_fresnel": self.entry_fresnel}


class TwoExponentialProfile(RadialProfile):
    r"""The parametric profile :math:`s(r) = a_1 e^{-b_1 r} + a_2 e^{-b_2 r}` per channel.

    Sheng et al. 2014, Sect. 6.1 (the rose petals): reflection and, optionally,
    transmission each a sum of two exponentials. Total:
    :math:`2\pi(a_1/b_1^2 + a_2/b_2^2)`.

    Parameters
    ----------
    a1, a2 : float or RGB
        Amplitudes, mm^-2, >= 0.
    b1, b2 : float or RGB
        Decay rates, mm^-1, > 0.
    transmission : tuple (a1, b1, a2, b2), optional
        The transmission profile's parameters, same units.
    name : str, optional
    """

    def __init__(self, a1, b1, a2=0.0, b2=1.0, *, transmission=None, name: str = ""):
        self.reflection_parameters = self._check((a1, b1, a2, b2), "reflection")
        self.transmission_parameters = None
        if transmission is not None:
            if len(transmission) != 4:
                raise InputError("must be (a1, b1, a2, b2)", field="transmission",
                                 value=transmission)
            self.transmission_parameters = self._check(transmission, "transmission")
        self.has_transmission = transmission is not None
        self.name = name or "two-exponential"

    @staticmethod
    def _check(parameters, kind):
        a1, b1, a2, b2 = parameters
        return (rgb_field(a1, f"{kind}.a1"), rgb_field(b1, f"{kind}.b1", strict=True),
                rgb_field(a2, f"{kind}.a2"), rgb_field(b2, f"{kind}.b2", strict=True))

    @staticmethod
    def _value(r, parameters):
        a1, b1, a2, b2 = parameters
        r = _rgb(r, a1)
        return a1 * np.exp(-b1 * r) + a2 * np.exp(-b2 * r)

    def reflection(self, r) -> np.ndarray:
        """:math:`a_1 e^{-b_1 r} + a_2 e^{-b_2 r}`, mm^-2."""
        return self._value(r, self.reflection_parameters)

    def transmission(self, r) -> np.ndarray:
        """Evaluate the transmission exponentials (0 when none were given)."""
        if self.transmission_parameters is None:
            return super().transmission(r)
        return self._value(r, self.transmission_parameters)

    def total(self, kind: str = "reflection", max_radius: float | None = None) -> np.ndarray:
        r"""Return the closed form :math:`2\pi(a_1/b_1^2 + a_2/b_2^2)` (integral to infinity)."""
        parameters = self.reflection_parameters if kind == "reflection" \
            else self.transmission_parameters
        if max_radius is None and parameters is not None:
            a1, b1, a2, b2 = parameters
            return 2.0 * np.pi * (a1 / b1**2 + a2 / b2**2)
        return super().total(kind, max_radius)

    def cache_key(self) -> dict:
        """Return what identifies this profile in content hashes."""
        def listed(parameters):
            return None if parameters is None else [p.tolist() for p in parameters]
        return {"type": "two_exponential", "reflection": listed(self.reflection_parameters),
                "transmission": listed(self.transmission_parameters)}


class TabulatedProfile(RadialProfile):
    """A user table: radii and values, linear in between, 0 beyond the last radius.

    Parameters
    ----------
    radius : array_like, shape (K,)
        Strictly increasing radii in mm, the first 0, K >= 2.
    reflection : array_like, shape (K,) or (K, 3)
        mm^-2, finite, >= 0 (one column is used for all three channels).
    transmission : array_like, optional
        Same shape, for thin sheets.
    name : str, optional
    file : path, optional
        Where the table came from (error messages).

    Raises
    ------
    InputError
        Non-increasing radii, a first radius other than 0, a shape mismatch, or NaN / Inf /
        negative values (the message names the first bad entry).
    """

    def __init__(self, radius, reflection, transmission=None, *, name: str = "", file=None):
        radius = check_finite(radius, "radius", file=file)
        if radius.ndim != 1 or len(radius) < 2:
            raise InputError("must be a 1D array of at least 2 radii (mm)", file=file,
                             field="radius", value=radius.shape)
        if radius[0] != 0:
            raise InputError("the first radius must be 0 mm (the profile at the point of "
                             "incidence)", file=file, field="radius", value=float(radius[0]))
        if (np.diff(radius) <= 0).any():
            index = int(np.flatnonzero(np.diff(radius) <= 0)[0]) + 1
            raise InputError(f"radii must increase strictly (entry {index} does not)",
                             file=file, field="radius", value=float(radius[index]))
        self.radius = radius
        self.name = name or (Path(file).stem if file else "table")
        self.values = {"reflection": self._column(reflection, "reflection", file)}
        self.has_transmission = transmission is not None
        if transmission is not None:
            self.values["transmission"] = self._column(transmission, "transmission", file)

    def _column(self, values, field, file):
        values = check_profile_values(values, field, file=file, name=self.name)
        if values.ndim == 1:
            values = np.repeat(values[:, None], 3, axis=1)
        if values.shape != (len(self.radius), 3):
            raise InputError(f"must have shape ({len(self.radius)},) or ({len(self.radius)}, 3)"
                             " to match the radii", file=file, field=field, value=values.shape)
        return values

    def _interpolate(self, r, values):
        r = np.asarray(r, dtype=np.float64)
        out = np.stack([np.interp(r, self.radius, values[:, c], right=0.0) for c in range(3)],
                       axis=-1)
        return out

    def reflection(self, r) -> np.ndarray:
        """Linear interpolation of the table, mm^-2; 0 beyond the last radius."""
        return self._interpolate(r, self.values["reflection"])

    def transmission(self, r) -> np.ndarray:
        """Linear interpolation of the transmission table (0 when there is none)."""
        if not self.has_transmission:
            return super().transmission(r)
        return self._interpolate(r, self.values["transmission"])

    def support_radius(self, energy_fraction: float = 1e-3) -> float:
        """At most the table's last radius (the profile is 0 beyond)."""
        return min(super().support_radius(energy_fraction), float(self.radius[-1]))

    def total(self, kind: str = "reflection", max_radius: float | None = None) -> np.ndarray:
        """Exact for the piecewise-linear table (:func:`radial_cumulative_integral`)."""
        if max_radius is None:
            if kind == "transmission" and not self.has_transmission:
                return np.zeros(3)
            return 2.0 * np.pi * radial_cumulative_integral(self.radius, self.values[kind])[-1]
        return super().total(kind, max_radius)

    @classmethod
    def from_file(cls, path, *, name: str = "") -> TabulatedProfile:
        """Read a CSV table of radii and profile values.

        Columns: ``r`` (mm), then 1 or 3 reflection columns, then optionally as many
        transmission columns; a header row (non-numeric) is skipped.

        Raises
        ------
        InputError
            Missing file, unreadable numbers, wrong column count, or bad values.
        """
        path = Path(path)
        if not path.is_file():
            raise InputError("no such file", file=path, field="path", value=str(path))
        rows = []
        try:
            with open(path, newline="", encoding="utf-8") as handle:
                for number, row in enumerate(csv.reader(handle), start=1):
                    cells = [cell.strip() for cell in row if cell.strip()]
                    if not cells or cells[0].startswith("#"):
                        continue
                    try:
                        rows.append([float(cell) for cell in cells])
                    except ValueError as error:
                        if rows:  # only the first row may be a header
                            raise InputError("not a number", file=path,
                                             field=f"line {number}", value=row) from error
        except (UnicodeDecodeError, csv.Error) as error:
            raise InputError(f"not a text (UTF-8) CSV file ({error})", file=path,
                             field="path", value=str(path)) from error
        if not rows:
            raise InputError("no numeric rows", file=path, field="rows", value=0)
        widths = {len(row) for row in rows}
        if len(widths) != 1 or widths.pop() not in (2, 3, 4, 7):
            raise InputError("every row needs r then 1 or 3 reflection columns, optionally "
                             "followed by as many transmission columns (2, 3, 4 or 7 numbers)",
                             file=path, field="columns", value=sorted({len(r) for r in rows}))
        table = np.array(rows)
        width = table.shape[1]
        channels = 3 if width in (4, 7) else 1
        reflection = table[:, 1:1 + channels]
        transmission = table[:, 1 + channels:] if width in (3, 7) else None
        squeeze = (lambda a: a[:, 0]) if channels == 1 else (lambda a: a)
        return cls(table[:, 0], squeeze(reflection),
                   None if transmission is None else squeeze(transmission),
                   name=name or path.stem, file=path)

    def cache_key(self) -> dict:
        """Return what identifies this profile in content hashes."""
        return {"type": "table", "radius": self.radius,
                **{kind: values for kind, values in self.values.items()}}


def profile_for(material, *, entry_fresnel: bool = True):
    """Return the radial profile of a scene material, or None for an opaque one.

    A :class:`RadialProfile` or :class:`MixedProfiles` is returned as is; a
    :class:`Dipole` becomes a
    :class:`DipoleProfile`; a :class:`Lambertian` (opaque, S = P in Sheng et al. 2014,
    Sect. 3.3) gives None.

    Raises
    ------
    InputError
        For any other material type; the message lists the accepted ones.
    """
    if isinstance(material, (RadialProfile, MixedProfiles)):
        return material
    if isinstance(material, Dipole):
        return DipoleProfile(material, entry_fresnel=entry_fresnel)
    if isinstance(material, Lambertian):
        return None
    raise InputError("translucent radiosity takes a Dipole, a RadialProfile, MixedProfiles "
                     "or a Lambertian material", field="material",
                     value=type(material).__name__)


def mixed_profile(values_at_zero, values_at_distance, fractions) -> np.ndarray:
    r"""Mix profiles by the heterogeneous heuristic of Sheng et al. 2014, Eq. 16 (M materials).

    .. math::
        s = \Big(\sum_m S_m(0)\,\frac{r_m}{\sum r}\Big)\prod_m \frac{S_m(r_m)}{S_m(0)}

    with :math:`r_m` the distance light travels in material m. Eq. 16 is the case M = 2;
    a material not traversed (:math:`r_m = 0`) contributes a factor 1. Not physically
    accurate (the paper says so), but plausible.

    Parameters
    ----------
    values_at_zero : ndarray, shape (M, 3)
        :math:`S_m(0)`, mm^-2.
    values_at_distance : ndarray, shape (..., M, 3)
        :math:`S_m(r_m)` with :math:`r_m = f_m r`, mm^-2.
    fractions : ndarray, shape (..., M)
        :math:`f_m = r_m / \sum r`, >= 0, summing to 1 over m.

    Returns
    -------
    ndarray, shape (..., 3)
        mm^-2; equals the homogeneous profile when one fraction is 1.
    """
    zero = np.asarray(values_at_zero, dtype=np.float64)
    at = np.asarray(values_at_distance, dtype=np.float64)
    fractions = np.asarray(fractions, dtype=np.float64)[..., None]
    with np.errstate(invalid="ignore", divide="ignore"):
        ratio = np.where(zero > 0, at / np.where(zero > 0, zero, 1.0), 0.0)
    ratio = np.where(fractions > 0, ratio, 1.0)
    return np.sum(zero * fractions, axis=-2) * np.prod(ratio, axis=-2)


class MixedProfiles:
    """A heterogeneous object: one homogeneous profile per face label (Sheng et al. 2014, Eq. 16).

    Each face of the object's mesh carries a label m that selects ``profiles[m]``; between
    two points the profiles are mixed by :func:`mixed_profile` with the fractions of the
    path that run through each material (the paper's checkerboard block, Fig. 4).

    Parameters
    ----------
    profiles : sequence of RadialProfile or Dipole
        The homogeneous materials (Dipoles become :class:`DipoleProfile`).
    face_labels : array_like of int, shape (F,)
        Material of each face, in [0, len(profiles)).
    name : str, optional
    volume_labels : callable, optional
        ``volume_labels(points) -> labels``: the material inside the object at points in
        scene units, where the object has one (a solid medium,
        :mod:`translucent.fast.solid_inputs`). Eq. 16's fractions are then read along the
        segment through the volume, the distance light travels in each material; without
        it, from the nearest labelled face (the paper's surface-labelled block).
    volume_key : optional
        What identifies ``volume_labels`` in content hashes.

    Raises
    ------
    InputError
        Fewer than one profile, a label out of range, or an opaque material among them.
    """

    def __init__(self, profiles, face_labels, *, name: str = "", volume_labels=None,
                 volume_key=None):
        converted = []
        for index, material in enumerate(profiles):
            profile = profile_for(material)
            if profile is None:
                raise InputError("every material of a heterogeneous object must be "
                                 "translucent (a Dipole or a RadialProfile)",
                                 field=f"profiles[{index}]", value=type(material).__name__)
            converted.append(profile)
        if not converted:
            raise InputError("needs at least one profile", field="profiles", value=[])
        labels = np.asarray(face_labels)
        if labels.ndim != 1 or not np.issubdtype(labels.dtype, np.integer):
            raise InputError("must be a 1D array of integer labels, one per face",
                             field="face_labels", value=labels.shape)
        if labels.min() < 0 or labels.max() >= len(converted):
            raise InputError(f"labels must lie in [0, {len(converted) - 1}]",
                             field="face_labels", value=[int(labels.min()), int(labels.max())])
        if volume_labels is not None and not callable(volume_labels):
            raise InputError("must be callable (points -> labels)", field="volume_labels",
                             value=type(volume_labels).__name__)
        self.profiles = tuple(converted)
        self.face_labels = labels.astype(np.int64)
        self.name = name or "mixed"
        self.volume_labels = volume_labels
        self.volume_key = volume_key

    def cache_key(self) -> dict:
        """Return what identifies this material in content hashes."""
        return {"type": "mixed", "profiles": [p.cache_key() for p in self.profiles],
                "face_labels": self.face_labels, "volume": self.volume_key}
