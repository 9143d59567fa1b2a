r"""Christensen-Burley normalized diffusion: an empirical profile fitted to Monte Carlo.

.. math::
    R(r) = A\,\frac{e^{-r/d} + e^{-r/(3d)}}{8\pi d\,r}, \qquad d = \ell / s(A)

(Christensen and Burley 2015, Eq. 2-3), normalised so that
:math:`2\pi\int_0^\infty R\,r\,dr = A`, with cumulative
:math:`1 - \tfrac14 e^{-r/d} - \tfrac34 e^{-r/(3d)}` (Eq. 11), inverted here in closed form
(:func:`burley_radius`). The surface albedo :math:`A` is the medium's total diffuse
reflectance; the authors fitted the scaling :math:`s(A)` of the length :math:`\ell` to
Monte Carlo references in three configurations, each a named variant:

==========================  ==============================  ====================  ========
variant                     fit                             length :math:`\ell`   equation
==========================  ==============================  ====================  ========
``burley_searchlight``      :math:`1.85 - A + 7|A-0.8|^3`   mean free path        Eq. 5
``burley_transmission``     :math:`1.9 - A + 3.5(A-0.8)^2`  mean free path        Eq. 6
``burley_dmfp``             :math:`3.5 + 100(A-0.33)^4`     diffuse mean free     Eq. 8
                                                            path
``burley_cycles``           none (:math:`d = \ell`)         Cycles' radius/4pi    --
==========================  ==============================  ====================  ========

(appleseed's ``normalized_diffusion_s_mfp`` and ``normalized_diffusion_s_dmfp`` are Eq. 5
and 8; Cycles' ``bssrdf_burley_fitting`` is Eq. 6.)

From the medium (sigma_a, sigma_s', eta): :math:`A` is transport's total diffuse
reflectance, the photon random walk's (:class:`.random_walk.RandomWalkProfile`, at the
medium's eta), the quantity the fits were made against; the mean free path is
:math:`\ell = 1/\sigma'_t` and the diffuse mean free path
:math:`\ell_d = 1/\sigma_{tr} = 1/\sqrt{3\sigma_a\sigma'_t}` (Sect. 5 of the paper).

Cycles (Blender 3 and later, ``kernel/closure/bssrdf.h``) no longer applies a fit: its
user radius :math:`\rho` becomes :math:`d = \rho/(4\pi)`, the same scaling that makes its
random walk's mean free path :math:`1/\sigma'_t = \rho/(4\pi)`; a medium therefore has
:math:`d = 1/\sigma'_t`. The profile is cut at :math:`16d` and renormalised by the
cumulative there (``BURLEY_TRUNCATE``, ``BURLEY_TRUNCATE_CDF``), so its total is still
:math:`A`.

References
----------
P. H. Christensen, B. Burley: Approximate reflectance profiles for efficient subsurface
scattering. Pixar Technical Memo 15-04, 2015 (Eq. 2, 3, 5, 6, 8, 11).
Blender Cycles: ``intern/cycles/kernel/closure/bssrdf.h`` (``bssrdf_burley_*``).
appleseed: ``renderer/modeling/bssrdf/sss.cpp`` (``normalized_diffusion_*``).
"""

from __future__ import annotations

import numpy as np

from ...errors import InputError, check_finite
from ..homogeneous import Dipole
from .base import RadialProfile, check_albedo
from .random_walk import RandomWalkProfile
from .sampling import check_channel, check_unit_interval

__all__ = [
    "BURLEY_FITS",
    "CYCLES_TRUNCATION",
    "BurleyProfile",
    "burley_cumulative",
    "burley_radius",
    "burley_scaling",
]

#: The variants: name -> (what the fit is, s(A), the length it scales).
BURLEY_FITS = {
    "searchlight": ("searchlight fit, Eq. 5", "s = 1.85 - A + 7 |A - 0.8|^3",
                    "mean free path l = 1/sigma_t'"),
    "transmission": ("diffuse surface transmission fit, Eq. 6",
                     "s = 1.9 - A + 3.5 (A - 0.8)^2", "mean free path l = 1/sigma_t'"),
    "dmfp": ("searchlight fit on the diffuse mean free path, Eq. 8",
             "s = 3.5 + 100 (A - 0.33)^4",
             "diffuse mean free path l = 1/sigma_tr = 1/sqrt(3 sigma_a sigma_t')"),
    "cycles": ("as Blender Cycles evaluates it: no fit, cut at 16 d", "s = 1",
               "d = radius / (4 pi) = 1/sigma_t'"),
}

#: Cycles' cut-off in units of d (``BURLEY_TRUNCATE``).
CYCLES_TRUNCATION = 16.0

#: The profile is held at its value at this many d from the point of incidence, where it
#: diverges as 1/r (integrable): the energy inside is changed by 2.5e-7 of A.
SINGULAR_FLOOR = 1e-6


def burley_scaling(surface_albedo, fit: str) -> np.ndarray:
    r"""Return the scaling factor :math:`s(A)` of Christensen and Burley 2015 for ``fit``.

    Parameters
    ----------
    surface_albedo : array_like
        A in [0, 1].
    fit : {"searchlight", "transmission", "dmfp", "cycles"}
        Eq. 5, Eq. 6, Eq. 8; "cycles" is 1 (no fit).

    Returns
    -------
    ndarray
        Dimensionless, > 0.

    Examples
    --------
    >>> [round(float(burley_scaling(0.5, fit)), 5)
    ...  for fit in ("searchlight", "transmission", "dmfp", "cycles")]
    [1.539, 1.715, 3.58352, 1.0]
    """
    a = check_albedo(surface_albedo, "surface_albedo")
    if fit == "searchlight":
        return 1.85 - a + 7.0 * np.abs(a - 0.8) ** 3
    if fit == "transmission":
        return 1.9 - a + 3.5 * (a - 0.8) ** 2
    if fit == "dmfp":
        return 3.5 + 100.0 * (a - 0.33) ** 4
    if fit == "cycles":
        return np.ones_like(a)
    raise InputError(f"unknown Burley fit; valid: {', '.join(BURLEY_FITS)}", field="fit",
                     value=fit)


def burley_cumulative(x) -> np.ndarray:
    r"""Energy fraction inside :math:`r = x d`: :math:`1 - e^{-x}/4 - 3e^{-x/3}/4` (Eq. 11)."""
    x = np.asarray(x, dtype=np.float64)
    third = np.exp(-x / 3.0)
    return 1.0 - 0.25 * third ** 3 - 0.75 * third


def burley_radius(fraction) -> np.ndarray:
    r"""Invert :func:`burley_cumulative`: the :math:`x = r/d` holding ``fraction`` of the energy.

    With :math:`y = e^{-x/3}` Eq. 11 is the cubic :math:`y^3 + 3y = 4(1 - F)`, whose one
    real root is Cardano's :math:`y = a - b`, :math:`a, b = \sqrt[3]{\sqrt{w^2 + 1} \pm w}`,
    :math:`w = 2(1 - F)`; written :math:`y = 2w/(a^2 + ab + b^2)` it keeps its digits as
    :math:`F \to 1` (Cycles and appleseed iterate Newton's method instead).

    Parameters
    ----------
    fraction : array_like
        F in [0, 1].

    Returns
    -------
    ndarray
        x >= 0 (inf at F = 1).

    Examples
    --------
    >>> round(float(burley_cumulative(burley_radius(0.99))), 12)
    0.99
    """
    w = 2.0 * (1.0 - np.asarray(fraction, dtype=np.float64))
    root = np.sqrt(w * w + 1.0)
    a = np.cbrt(root + w)
    b = np.cbrt(root - w)
    y = 2.0 * w / (a * a + a * b + b * b)
    with np.errstate(divide="ignore"):
        return np.maximum(-3.0 * np.log(y), 0.0)


class BurleyProfile(RadialProfile):
    r"""Christensen-Burley normalized diffusion of a medium, in one of its variants.

    Parameters
    ----------
    medium : Dipole
        sigma_a, sigma_s' (mm^-1) and eta (within the random walk table's 1.0 .. 2.0,
        which gives A).
    fit : {"searchlight", "transmission", "dmfp", "cycles"}
        The variant (module docstring).
    surface_albedo : float or RGB, optional
        A in [0, 1] instead of the walk's total reflectance.

    Raises
    ------
    InputError
        An unknown fit, an albedo outside [0, 1], an eta the walk table does not hold, or
        the ``dmfp`` variant of a channel without absorption (its diffuse mean free path
        is infinite).

    Examples
    --------
    >>> from translucent.materials import measured_medium
    >>> profile = BurleyProfile(measured_medium("Marble"), "dmfp", surface_albedo=0.5)
    >>> [round(float(v), 12) for v in profile.total()]
    [0.5, 0.5, 0.5]
    """

    summary = "Christensen-Burley normalized diffusion (2015, Eq. 3)"

    def __init__(self, medium: Dipole, fit: str = "searchlight", *, surface_albedo=None):
        if not isinstance(medium, Dipole):
            raise InputError("expected a Dipole medium", field="medium",
                             value=type(medium).__name__)
        if fit not in BURLEY_FITS:
            raise InputError(f"unknown Burley fit; valid: {', '.join(BURLEY_FITS)}",
                             field="fit", value=fit)
        self.medium = medium
        self.fit = fit
        self.model = f"burley_{fit}"
        self.name = f"{self.model} ({medium.name})" if medium.name else self.model
        what, formula, length = BURLEY_FITS[fit]
        self.summary = f"Christensen-Burley normalized diffusion (2015, Eq. 3), {what}"
        sigma_t = medium.sigma_a + medium.sigma_s_prime
        self.present = sigma_t > 0
        if surface_albedo is None:
            self.albedo_source = "the photon random walk's total reflectance"
            albedo = RandomWalkProfile(medium).total()
        else:
            self.albedo_source = "given"
            albedo = np.broadcast_to(check_albedo(surface_albedo, "surface_albedo"), (3,))
        self.surface_albedo = np.where(self.present, albedo, 0.0)
        with np.errstate(divide="ignore"):
            if fit == "dmfp":
                sigma_tr = np.sqrt(3.0 * medium.sigma_a * sigma_t)
                lacking = self.present & (sigma_tr <= 0)
                if lacking.any():
                    raise InputError("burley_dmfp scales the diffuse mean free path "
                                     "1/sqrt(3 sigma_a sigma_t'), infinite without absorption; "
                                     "every channel needs sigma_a > 0", field="sigma_a",
                                     value=medium.sigma_a)
                self.length = np.where(self.present, 1.0 / sigma_tr, 1.0)
            else:
                self.length = np.where(self.present, 1.0 / sigma_t, 1.0)
        self.scaling = burley_scaling(self.surface_albedo, fit)
        self.d = self.length / self.scaling
        self.truncation = (burley_cumulative(CYCLES_TRUNCATION) if fit == "cycles"
                           else 1.0)
        if fit == "cycles":
            self.derivation = (f"A = {self.albedo_source}; {length}, Cycles' radius being "
                               "the one that gives its random walk this mean free path; "
                               "cut at 16 d and renormalised")
        else:
            self.derivation = f"A = {self.albedo_source}; {length}; {formula}; d = l / s"

    def reflection(self, r) -> np.ndarray:
        """:math:`R(r)` (Eq. 3), mm^-2, shape ``r.shape + (3,)``; held at 1e-6 d below it."""
        r = np.asarray(r, dtype=np.float64)
        # channels as rows: numpy's loops then run along the radii, not over 3 channels
        d = self.d[:, None]
        radius = np.maximum(r.reshape(1, -1), SINGULAR_FLOOR * d)
        third = np.multiply(radius, -1.0 / (3.0 * d))
        np.exp(third, out=third)
        value = np.square(third)
        value *= third
        value += third
        value /= radius
        value *= (self.surface_albedo / (8.0 * np.pi * self.d * self.truncation))[:, None]
        if self.fit == "cycles":
            value *= radius < CYCLES_TRUNCATION * d
        return np.ascontiguousarray(value.T).reshape(r.shape + (3,))

    def total(self, kind: str = "reflection", max_radius: float | None = None) -> np.ndarray:
        """Return A (the profile is normalised; Cycles' renormalises its cut)."""
        if kind == "reflection" and max_radius is None:
            return self.surface_albedo.copy()
        return super().total(kind, max_radius)

    def length_scale(self) -> np.ndarray:
        """Return d per channel, mm."""
        return self.d

    def cutoff_radius(self) -> np.ndarray | None:
        """Return 16 d for the Cycles variant (None otherwise), mm."""
        return CYCLES_TRUNCATION * self.d if self.fit == "cycles" else None

    def sample_radius(self, u, channel) -> np.ndarray:
        """Exit radii (mm) by the closed-form inverse of Eq. 11 (:func:`burley_radius`)."""
        u = check_unit_interval(u)
        channel = check_channel(channel, u.shape)
        x = burley_radius(np.minimum(u * self.truncation, 1.0 - 1e-16))
        if self.fit == "cycles":  # u = 1 lands on the cut, not a rounding beyond it
            x = np.minimum(x, CYCLES_TRUNCATION)
        return np.where(self.surface_albedo[channel] > 0, x * self.d[channel], 0.0)

    def pdf(self, r, channel) -> np.ndarray:
        r"""Density of the sampled radii, :math:`(e^{-r/d} + e^{-r/3d})/(4d)`, mm^-1."""
        r = check_finite(r, "r")
        channel = check_channel(channel, r.shape)
        d = self.d[channel]
        third = np.exp(-np.maximum(r, 0.0) / (3.0 * d))
        value = (third * third * third + third) / (4.0 * d * self.truncation)
        inside = r >= 0.0
        if self.fit == "cycles":
            inside &= r < CYCLES_TRUNCATION * d
        return np.where(inside & (self.surface_albedo[channel] > 0), value, 0.0)

    def radius_containing(self, fraction: float = 0.99) -> np.ndarray:
        """Return the radius (mm) per channel inside which ``fraction`` of the energy lies."""
        fraction = float(check_finite(fraction, "fraction"))
        if not 0.0 < fraction < 1.0:
            raise InputError("must lie in (0, 1)", field="fraction", value=fraction)
        radius = burley_radius(fraction * self.truncation) * self.d
        return np.where(self.surface_albedo > 0, radius, 0.0)

    def parameters(self) -> dict[str, tuple[np.ndarray, str]]:
        """Return A, the length l, s(A) and d per channel."""
        return {"A": (self.surface_albedo, ""), "l": (self.length, "mm"),
                "s": (self.scaling, ""), "d": (self.d, "mm")}

    def cache_key(self) -> dict:
        """Return what identifies this profile in content hashes."""
        return {"type": self.model, "medium": self.medium.cache_key(),
                "surface_albedo": self.surface_albedo.tolist()}
