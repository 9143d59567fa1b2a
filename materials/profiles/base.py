r"""Radial scattering profiles: what every profile offers, and the helpers they share.

A profile gives the radial reflectance :math:`R(r)` of a semi-infinite medium lit at one
point: the exitance at distance :math:`r` (mm) per unit power, per RGB channel, in mm^-2,
so that :math:`2\pi\int_0^\infty R(r)\,r\,dr` is the dimensionless total reflectance.
Translucent radiosity (Sheng et al. 2014, Sect. 4) needs it as the simplified BSSRDF
:math:`s(r)`: a *reflection* profile for light entering and leaving on the same side and,
for thin sheets, a *transmission* profile for light leaving on the other side.

Every :class:`RadialProfile` offers

* :meth:`~RadialProfile.reflection` (and :meth:`~RadialProfile.transmission`): values at
  any array of radii, shape ``r.shape + (3,)``, vectorised;
* :meth:`~RadialProfile.total`: its total diffuse reflectance per channel, closed form
  where the model has one;
* :meth:`~RadialProfile.sample_radius` and :meth:`~RadialProfile.pdf`: exit radii drawn with
  density proportional to :math:`r R(r)` and the density itself (the inverse CDF a BSSRDF
  path tracer samples probe rays with), consistent with each other
  (:mod:`~translucent.materials.profiles.sampling` states the accuracy);
* :meth:`~RadialProfile.radius_containing`: the radius holding a fraction (99 %) of its
  energy;
* :attr:`~RadialProfile.name`, :meth:`~RadialProfile.describe` and
  :meth:`~RadialProfile.parameters`: what it is, where it comes from, and how its
  parameters follow from the medium.

A profile is tabulated on a :class:`RadialGrid` (quadratic spacing: fine near 0 where the
dipole peaks) before the radiosity precomputation uses it (Sheng et al. 2014, Sect. 5.2).

References
----------
Sheng, Shi, Wang, Narasimhan: Translucent radiosity: efficiently combining diffuse
inter-reflection and subsurface scattering. IEEE TVCG 20(7), 2014, Sect. 4, 5.2.
Jensen, Marschner, Levoy, Hanrahan: A practical model for subsurface light transport.
SIGGRAPH 2001.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ...errors import InputError, check_finite
from ..fresnel import fresnel_reflectance
from ..homogeneous import Dipole, rgb_field
from .sampling import RadialSampler

__all__ = [
    "PROFILE_KINDS",
    "RadialGrid",
    "RadialProfile",
    "ScaledProfile",
    "check_albedo",
    "check_profile_values",
    "diffuse_entry_transmittance",
    "radial_cumulative_integral",
    "require_radial",
    "rgb_broadcast",
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



def rgb_broadcast(r, values) -> np.ndarray:
    """Broadcast radii ``r`` (any shape) against RGB parameters: shape ``r.shape + (3,)``."""
    return np.asarray(r, dtype=np.float64)[..., None] + np.zeros_like(values)


def check_albedo(value, field: str = "albedo") -> np.ndarray:
    """Return ``value`` as float64; :class:`InputError` unless finite and within [0, 1]."""
    array = check_finite(value, field)
    if ((array < 0.0) | (array > 1.0)).any():
        raise InputError("must lie in [0, 1] (an albedo)", field=field, value=value)
    return array


def require_radial(profile, field: str = "profile"):
    """Return ``profile`` if it is radial; :class:`InputError` for a directional one.

    A directional profile (one that depends on the incident direction, such as the
    directional dipole) cannot stand where only a function of the distance serves; its
    radial average can (``profile.radial_average()``).
    """
    if getattr(profile, "directional", False):
        raise InputError("a directional profile cannot stand where a radial one is needed; "
                         "use its radial_average()", field=field,
                         value=getattr(profile, "name", type(profile).__name__))
    return profile


class RadialProfile:
    """A radial scattering profile: reflection and, where defined, transmission.

    Subclasses implement :meth:`reflection` (and :meth:`transmission` when
    ``has_transmission``); everything else follows. Values are mm^-2 per RGB channel.
    A subclass states what it is in :attr:`summary` and how its parameters come from the
    medium in :attr:`derivation` (both shown by :meth:`describe`); where it knows its
    length scale (:meth:`length_scale`) or its total in closed form (:meth:`total`) it
    says so, and the sampling tables follow.
    """

    name: str = ""
    #: The model's name in the registry (:data:`~translucent.materials.profiles.PROFILE_NAMES`).
    model: str = ""
    has_transmission: bool = False
    #: False: a function of the distance alone (a directional profile sets True).
    directional: bool = False
    #: One line: the model and its source.
    summary: str = "a radial scattering profile"
    #: How the profile's parameters follow from the medium (empty where none).
    derivation: str = ""

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

    def scaled(self, factor) -> ScaledProfile:
        """Return the profile times ``factor`` (scalar or RGB)."""
        return ScaledProfile(self, factor)

    def cache_key(self) -> dict:
        """Return what identifies this profile in content hashes."""
        raise NotImplementedError

    # -- sampling: exit radii with density proportional to r R(r) --------------------------

    def length_scale(self) -> np.ndarray:
        """Return the distance (mm) on which the profile varies, per channel, shape (3,).

        The sampling tables span twelve decades about it
        (:data:`~translucent.materials.profiles.sampling.GRID_RANGE`). Profiles of a
        medium return its mean free path; this default takes a tenth of
        :meth:`support_radius`.
        """
        return np.full(3, 0.1 * self.support_radius())

    def cutoff_radius(self) -> np.ndarray | None:
        """Return the radius (mm) per channel beyond which the profile is 0, or None."""
        return None

    @property
    def sampler(self) -> RadialSampler:
        """The reflection profile's sampling tables (built on first use)."""
        sampler = self.__dict__.get("_sampler")
        if sampler is None:
            sampler = RadialSampler.from_profile(self, self.length_scale(), self.cutoff_radius())
            self.__dict__["_sampler"] = sampler
        return sampler

    def sample_radius(self, u, channel) -> np.ndarray:
        r"""Exit radii (mm) drawn with density :math:`\propto r R(r)` from uniform numbers.

        The inverse CDF in r of channel ``channel``'s reflection profile, tabulated
        (:class:`~translucent.materials.profiles.sampling.RadialSampler`).

        Parameters
        ----------
        u : array_like
            Uniform numbers in [0, 1].
        channel : int or array_like of int
            0, 1 or 2 (R, G, B), broadcast against ``u``.

        Returns
        -------
        ndarray
            Radii in mm, shape of ``u``; 0 in a channel that reflects nothing.
        """
        return self.sampler.sample(u, channel)

    def pdf(self, r, channel) -> np.ndarray:
        r"""Density (mm^-1) of :meth:`sample_radius`'s radii at ``r`` (mm).

        :math:`2\pi r R(r) / E` to the tables' accuracy, E the energy sampled; exactly the
        density :meth:`sample_radius` draws from. The density over the plane (mm^-2) is
        this divided by :math:`2\pi r`.
        """
        return self.sampler.pdf(r, channel)

    def radius_containing(self, fraction: float = 0.99) -> np.ndarray:
        """Return the radius (mm) per channel inside which ``fraction`` of the energy lies.

        Parameters
        ----------
        fraction : float
            In (0, 1).

        Returns
        -------
        ndarray, shape (3,)
            mm; 0 for a channel that reflects nothing.
        """
        fraction = float(check_finite(fraction, "fraction"))
        if not 0.0 < fraction < 1.0:
            raise InputError("must lie in (0, 1)", field="fraction", value=fraction)
        return self.sampler.quantile(fraction)

    # -- what it is -------------------------------------------------------------------------

    def parameters(self) -> dict[str, tuple[np.ndarray, str]]:
        """Return the parameters derived from the medium: name -> (RGB values, unit)."""
        return {}

    def describe(self) -> str:
        """Return what the profile is, its source, and its parameters from the medium."""
        lines = [f"{self.name}: {self.summary}"]
        if self.derivation:
            lines.append(f"  from the medium: {self.derivation}")
        for key, (values, unit) in self.parameters().items():
            shown = ", ".join(f"{v:.6g}" for v in np.broadcast_to(values, (3,)))
            lines.append(f"  {key} = [{shown}]{' ' + unit if unit else ''}")
        shown = ", ".join(f"{v:.6g}" for v in self.total())
        lines.append(f"  total diffuse reflectance = [{shown}]")
        return "\n".join(lines)


class ScaledProfile(RadialProfile):
    """A profile times a constant factor per channel (an RGB tint of its energy).

    Parameters
    ----------
    profile : RadialProfile
    factor : float or RGB
        Dimensionless, >= 0.
    """

    def __init__(self, profile: RadialProfile, factor):
        require_radial(profile)
        self.profile = profile
        self.factor = rgb_field(factor, "factor")
        self.has_transmission = profile.has_transmission
        self.name = f"{profile.name} x {self.factor.tolist()}"
        self.summary = f"{profile.summary}, scaled"
        self.derivation = profile.derivation

    def reflection(self, r) -> np.ndarray:
        """Return the profile's reflection times the factor, mm^-2."""
        return self.profile.reflection(r) * self.factor

    def transmission(self, r) -> np.ndarray:
        """Return the profile's transmission times the factor, mm^-2."""
        return self.profile.transmission(r) * self.factor

    def total(self, kind: str = "reflection", max_radius: float | None = None) -> np.ndarray:
        """Return the profile's total times the factor."""
        return self.profile.total(kind, max_radius) * self.factor

    def length_scale(self) -> np.ndarray:
        """Return the profile's length scale (mm)."""
        return self.profile.length_scale()

    def cutoff_radius(self) -> np.ndarray | None:
        """Return the profile's cut-off radius (mm), if any."""
        return self.profile.cutoff_radius()

    def cache_key(self) -> dict:
        """Return what identifies this profile in content hashes."""
        return {"type": "scaled", "profile": self.profile.cache_key(),
                "factor": self.factor.tolist()}


class MediumProfile(RadialProfile):
    """A profile made from a homogeneous medium: it keeps the medium and is named after it."""

    model = ""

    def adopt(self, medium) -> Dipole:
        """Keep ``medium`` (a :class:`~translucent.materials.homogeneous.Dipole`); return it.

        The profile is named ``"MODEL (MEDIUM)"``.

        Raises
        ------
        InputError
            ``medium`` is not a Dipole.
        """
        if not isinstance(medium, Dipole):
            raise InputError("expected a Dipole medium", field="medium",
                             value=type(medium).__name__)
        self.medium = medium
        self.name = f"{self.model} ({medium.name})" if medium.name else self.model
        return medium


class LookupProfile(MediumProfile):
    """A medium's profile evaluated through a per-channel lookup table (``self.lookup``).

    The exact form is tabulated once on log-spaced radii
    (:class:`~translucent.materials.profiles.sampling.LogRadialTable`); evaluation and the
    total read the table, and lengths scale with the reduced mean free path.
    """

    def reflection(self, r) -> np.ndarray:
        """:math:`R(r)`, mm^-2, shape ``r.shape + (3,)`` (the per-channel lookup)."""
        return self.lookup(r)

    def total(self, kind: str = "reflection", max_radius: float | None = None) -> np.ndarray:
        """Return the profile's integral to infinity (trapezoidal on the lookup's nodes)."""
        if kind == "reflection" and max_radius is None:
            return self.sampler.energy.copy()
        return super().total(kind, max_radius)

    def length_scale(self) -> np.ndarray:
        """Return the reduced mean free path 1/sigma_t' per channel, mm."""
        return self.medium.mean_free_path
