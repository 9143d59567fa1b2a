r"""The six analytic BRDFs of Nguyen et al. 2010 (Table 3) with their fixed/edited split (Table 4).

Every model is a Lambertian term plus one glossy lobe,

.. math:: f(\omega_i, \omega_o) = \frac{\rho_d}{\pi}
          + \rho_s\, f_F(\omega_i, \omega_o)\, f_E(\gamma, \delta)

where :math:`f_E` is the *edited term* (all that depends on the editing parameter
:math:`\gamma`, a function of one scalar :math:`\delta` only) and :math:`f_F` the *fixed term*
(Eq. 5 and Table 4 of Nguyen et al. 2010). :math:`\delta` is the angle between the normal
and the half vector, except for Lafortune where it is the normalised lobe cosine
:math:`(C_x l_x v_x + C_y l_y v_y + C_z l_z v_z) / \max(|C_x|, |C_y|, |C_z|)` (Sect. 4).

The lobes are written once, in :func:`lobe_terms`, over an *array namespace* (``NUMPY_OPS``
here; the Mitsuba plugins pass a Dr.Jit one), so the BRDF the fast method edits and the
one the exact reference path-traces are the same code.

All terms depend on three cosines only, :math:`N\cdot L`, :math:`N\cdot V` and
:math:`L\cdot V` (Lafortune lobes are isotropic here, :math:`C_x = C_y`), so no tangent frame is
needed: :math:`|L+V| = \sqrt{2 + 2 L\cdot V}`, :math:`N\cdot H = (N\cdot L + N\cdot V)/|L+V|`,
:math:`V\cdot H = |L+V|/2` and
:math:`C_{xy}(l_x v_x + l_y v_y) + C_z l_z v_z = C_{xy}(L\cdot V - l_z v_z) + C_z l_z v_z`.

Notes
-----
============================  =======  ===============  =====================================
model                         symbol   gamma range      gamma is
============================  =======  ===============  =====================================
``blinn_phong``               BP       [3, 300]         the exponent of :math:`\cos\delta`
``ward``                      W        [0.05, 2]        the roughness (slope std. dev.)
``ward_duer``                 WD       [0.05, 2]        the roughness
``lafortune``                 La       [3, 300]         the lobe exponent
``cook_torrance``             CT       [0.1, 2]         the Beckmann roughness
``ashikhmin_shirley``         AS       [3, 300]         the exponent of :math:`\cos\delta`
============================  =======  ===============  =====================================

The ranges are the ones of Table 5 of Nguyen et al. 2010.

The forms are Table 3's as printed. Several are not energy conserving for every
:math:`\rho_s`: Blinn-Phong's :math:`(\gamma+2)/(2\pi)` normalises :math:`\cos^\gamma\delta`
over the hemisphere of half vectors, not of light directions, and reflects up to about
:math:`4\rho_s` at normal view for large :math:`\gamma`; Cook-Torrance's :math:`1/\pi` (instead of
:math:`1/4`) reflects up to :math:`4\rho_s F`. :meth:`AnalyticBRDF.directional_albedo` measures it.

Cook-Torrance and Ashikhmin-Shirley carry Schlick's Fresnel term
:math:`F(F_0, V\cdot H) = F_0 + (1 - F_0)(1 - V\cdot H)^5` with a grey :math:`F_0` (``f0``).
Table 3 writes Ashikhmin-Shirley without :math:`\rho_s`: :math:`\rho_s = 1` gives that form and
another :math:`\rho_s` tints the lobe.

Directions within :data:`COSINE_FLOOR` of the horizon enter the denominators at that
floor, so no value is NaN or Inf at grazing incidence; directions at or below the
horizon reflect nothing.

References
----------
C. H. Nguyen, M.-H. Kyung, J.-H. Lee, S.-W. Nam: A PCA decomposition for real-time BRDF
editing and relighting with global illumination. Computer Graphics Forum 29(4), 2010.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from types import SimpleNamespace

import numpy as np

from ..errors import InputError, check_finite
from .factory import register_material_type
from .homogeneous import rgb_field

__all__ = [
    "MODELS",
    "MODEL_ALIASES",
    "MODEL_CODES",
    "GAMMA_RANGES",
    "COSINE_FLOOR",
    "NUMPY_OPS",
    "AnalyticBRDF",
    "canonical_model",
    "check_gamma",
    "edited_term",
    "fixed_term",
    "fixed_term_scalar",
    "lobe_terms",
    "pca_variable",
    "pca_variable_scalar",
    "pca_variable_range",
    "schlick_fresnel",
    "uses_half_angle",
]

#: The models, in the order of Table 3 of Nguyen et al. 2010.
MODELS = ("blinn_phong", "ward", "ward_duer", "lafortune", "cook_torrance",
          "ashikhmin_shirley")

#: The paper's abbreviations (Table 3), accepted case-insensitively.
MODEL_ALIASES = {"bp": "blinn_phong", "w": "ward", "wd": "ward_duer", "la": "lafortune",
                 "lf": "lafortune", "ct": "cook_torrance", "as": "ashikhmin_shirley"}

#: model -> (gamma_min, gamma_max), the editing ranges of Table 5 of Nguyen et al. 2010.
GAMMA_RANGES = {
    "blinn_phong": (3.0, 300.0),
    "ward": (0.05, 2.0),
    "ward_duer": (0.05, 2.0),
    "lafortune": (3.0, 300.0),
    "cook_torrance": (0.1, 2.0),
    "ashikhmin_shirley": (3.0, 300.0),
}

#: Smallest cosine a denominator sees. 1e-6 keeps the largest fixed term (Cook-Torrance's
#: 1/((N.L)(N.V) cos^4 delta), 1e36) inside float32 range, so the float32 Mitsuba plugins
#: and the float64 fast method stay finite at grazing incidence.
COSINE_FLOOR = 1e-6

#: Lafortune's lobe variable delta lies in [eps, 1 - eps]: Sect. 4 of Nguyen et al. 2010
#: omits 0 and 1 "to avoid singularity of the PCA linearization", eps = 1e-3.
LAFORTUNE_EPSILON = 1e-3

#: The array namespace of :func:`lobe_terms` for NumPy arrays.
NUMPY_OPS = SimpleNamespace(sqrt=np.sqrt, exp=np.exp, maximum=np.maximum,
                            minimum=np.minimum, select=np.where, power=np.power, abs=np.abs)


def canonical_model(model, *, file=None) -> str:
    r"""Return the canonical model name (``"blinn_phong"``, ...) of a name or Table 3 symbol.

    Raises
    ------
    InputError
        For an unknown name; the message lists the valid ones.
    """
    key = str(model).strip().lower().replace("-", "_").replace(" ", "_")
    key = MODEL_ALIASES.get(key, key)
    if key not in MODELS:
        raise InputError(f"unknown BRDF model; valid: {', '.join(MODELS)} "
                         f"(or {', '.join(sorted(MODEL_ALIASES))})", file=file, field="model",
                         value=model)
    return key


def check_gamma(model: str, gamma, *, file=None, field: str = "gamma") -> float:
    r"""Return ``gamma`` as a float after checking it lies in the model's editing range.

    Raises
    ------
    InputError
        ``gamma`` is not finite or lies outside :data:`GAMMA_RANGES` of the model; the
        message names the model and the range.
    """
    model = canonical_model(model, file=file)
    value = float(check_finite(gamma, field, file=file))
    low, high = GAMMA_RANGES[model]
    if not low <= value <= high:
        raise InputError(f"must be in [{low:g}, {high:g}] for the {model} model",
                         file=file, field=field, value=gamma)
    return value


def uses_half_angle(model: str) -> bool:
    r"""Tell whether the edited term is a function of the half angle delta (all but La)."""
    return canonical_model(model) != "lafortune"


def pca_variable_range(model: str) -> tuple[float, float]:
    r"""Return the interval of the PCA variable delta (Sect. 4 of Nguyen et al. 2010).

    Radians ``[0, pi/2]`` for the half-angle models; ``[eps, 1 - eps]`` with eps = 1e-3
    for Lafortune, whose delta is the normalised lobe cosine.
    """
    if uses_half_angle(model):
        return 0.0, 0.5 * math.pi
    return LAFORTUNE_EPSILON, 1.0 - LAFORTUNE_EPSILON


def schlick_fresnel(f0, cos_theta, ops=NUMPY_OPS):
    r"""Schlick's Fresnel approximation :math:`F_0 + (1 - F_0)(1 - \cos\theta)^5`.

    Parameters
    ----------
    f0 : float or array
        Reflectance at normal incidence, in [0, 1].
    cos_theta : array
        :math:`V\cdot H`; clamped to [0, 1], so it is ``f0`` at normal incidence and 1 at
        grazing incidence.
    ops : namespace
        Array functions (:data:`NUMPY_OPS` or the Dr.Jit one of the plugins).
    """
    one_minus = 1.0 - ops.minimum(ops.maximum(cos_theta, 0.0), 1.0)
    squared = one_minus * one_minus
    return f0 + (1.0 - f0) * (squared * squared * one_minus)


def _tan_squared(cos_delta, ops):
    r""":math:`\tan^2\delta` from :math:`\cos\delta`, finite at :math:`\delta = \pi/2`."""
    cos2 = ops.maximum(cos_delta * cos_delta, COSINE_FLOOR * COSINE_FLOOR)
    return ops.maximum(1.0 - cos2, 0.0) / cos2


def edited_term(model: str, gamma, delta, ops=NUMPY_OPS, *, cos_delta=None):
    r"""Evaluate the edited term :math:`f_E(\gamma, \delta)` of Table 4 of Nguyen et al. 2010.

    ==========  ==========================================================
    BP          :math:`\frac{\gamma+2}{2\pi}\cos^\gamma\delta`
    W, WD       :math:`\exp(-\tan^2\delta/\gamma^2) / (4\pi\gamma^2)`
    La          :math:`\frac{\gamma+2}{2\pi}\delta^\gamma` (delta the normalised lobe cosine)
    CT          :math:`\exp(-\tan^2\delta/\gamma^2) / (\pi\gamma^2)`
    AS          :math:`\frac{\gamma+1}{8\pi}\cos^\gamma\delta`
    ==========  ==========================================================

    Parameters
    ----------
    model : str
    gamma : float or array
        Editing parameter (not range-checked here: the PCA samples exactly the range).
    delta : array
        Half angle in radians (ignored when ``cos_delta`` is given), or Lafortune's lobe
        cosine (negative values reflect nothing).
    ops : namespace
    cos_delta : array, optional
        :math:`\cos\delta` when the caller has it (saves an arccos).

    Returns
    -------
    array
        :math:`f_E` in sr^-1, >= 0, broadcast over ``gamma`` and ``delta``.
    """
    model = canonical_model(model)
    if model == "lafortune":
        lobe = ops.maximum(delta, 0.0)
        return (gamma + 2.0) / (2.0 * math.pi) * ops.power(lobe, gamma)
    if cos_delta is None:
        cos_delta = np.cos(delta)
    cos_delta = ops.maximum(cos_delta, 0.0)
    if model == "blinn_phong":
        return (gamma + 2.0) / (2.0 * math.pi) * ops.power(cos_delta, gamma)
    if model == "ashikhmin_shirley":
        return (gamma + 1.0) / (8.0 * math.pi) * ops.power(cos_delta, gamma)
    gamma2 = gamma * gamma
    gaussian = ops.exp(-_tan_squared(cos_delta, ops) / gamma2)
    if model == "cook_torrance":
        return gaussian / (math.pi * gamma2)
    return gaussian / (4.0 * math.pi * gamma2)  # ward, ward_duer


def fixed_term(model: str, cos_l, cos_v, l_dot_v, ops=NUMPY_OPS, *, f0=1.0):
    r"""Evaluate the fixed term :math:`f_F` of Table 4 (Nguyen et al. 2010), without :math:`\rho_s`.

    ==========  ===============================================================
    BP, La      1
    W           :math:`1/\sqrt{(N\cdot L)(N\cdot V)}`
    WD          :math:`1/((N\cdot L)(N\cdot V))`
    CT          :math:`G\,F(F_0, V\cdot H) / ((N\cdot L)(N\cdot V)\cos^4\delta)`
    AS          :math:`F(F_0, V\cdot H) / ((V\cdot H)\max(N\cdot L, N\cdot V))`
    ==========  ===============================================================

    with :math:`G = \min\{1, 2(N\cdot H)(N\cdot V)/(V\cdot H), 2(N\cdot H)(N\cdot L)/(V\cdot H)\}`.
    Denominators see cosines no smaller than :data:`COSINE_FLOOR`.

    Parameters
    ----------
    cos_l, cos_v, l_dot_v : array
        :math:`N\cdot L`, :math:`N\cdot V`, :math:`L\cdot V` (L towards the light, V towards
        the viewer), broadcast together.
    f0 : float
        Fresnel reflectance at normal incidence (CT, AS).

    Returns
    -------
    array
        Dimensionless (W), sr^0 ... as in Table 4; finite for every input in [-1, 1].
    """
    model = canonical_model(model)
    if model in ("blinn_phong", "lafortune"):
        return cos_l * 0.0 + 1.0
    floor = COSINE_FLOOR
    nl = ops.maximum(cos_l, floor)
    nv = ops.maximum(cos_v, floor)
    if model == "ward":
        return 1.0 / ops.sqrt(nl * nv)
    if model == "ward_duer":
        return 1.0 / (nl * nv)
    length = ops.sqrt(ops.maximum(2.0 + 2.0 * l_dot_v, floor * floor))  # |L + V|
    v_dot_h = ops.maximum(0.5 * length, floor)
    fresnel = schlick_fresnel(f0, v_dot_h, ops)
    if model == "ashikhmin_shirley":
        return fresnel / (v_dot_h * ops.maximum(nl, nv))
    n_dot_h = ops.maximum((nl + nv) / length, floor)
    shadowing = ops.minimum(1.0, ops.minimum(2.0 * n_dot_h * nv / v_dot_h,
                                             2.0 * n_dot_h * nl / v_dot_h))
    cos4 = (n_dot_h * n_dot_h) * (n_dot_h * n_dot_h)
    return shadowing * fresnel / ((nl * nv) * cos4)


def pca_variable(model: str, cos_l, cos_v, l_dot_v, ops=NUMPY_OPS, *, lafortune_c=(-1.0, 1.0)):
    r"""Return the edited term's variable: :math:`\cos\delta = N\cdot H`, or the Lafortune cosine.

    Returns :math:`\cos\delta` for the half-angle models (the angle itself is
    ``arccos`` of it) and the normalised lobe cosine
    :math:`(C_{xy}(L\cdot V - l_z v_z) + C_z l_z v_z)/\max(|C_{xy}|, |C_z|)` for Lafortune
    (Sect. 4 of Nguyen et al. 2010).
    """
    model = canonical_model(model)
    if model == "lafortune":
        c_xy, c_z = lafortune_c
        scale = max(abs(c_xy), abs(c_z))
        product = cos_l * cos_v
        return (c_xy * (l_dot_v - product) + c_z * product) / scale
    length = ops.sqrt(ops.maximum(2.0 + 2.0 * l_dot_v, COSINE_FLOOR * COSINE_FLOOR))
    return ops.minimum(ops.maximum((cos_l + cos_v) / length, 0.0), 1.0)


#: Model codes of compiled kernels, in the order of :data:`MODELS`.
MODEL_CODES = {name: code for code, name in enumerate(MODELS)}
_BP, _W, _WD, _LA, _CT, _AS = range(6)


def fixed_term_scalar(code: int, cos_l: float, cos_v: float, l_dot_v: float,
                      f0: float) -> float:
    """:func:`fixed_term` for one direction pair, in plain arithmetic (Table 4).

    ``code`` is the model's :data:`MODEL_CODES` entry. Written so that compiled kernels
    take this very function (``numba.njit(fixed_term_scalar)`` in
    :mod:`translucent.fast.brdf_pca.kernels`) instead of a copy of the formulas; tested
    equal to the array version.
    """
    if code == _BP or code == _LA:
        return 1.0
    nl = max(cos_l, COSINE_FLOOR)
    nv = max(cos_v, COSINE_FLOOR)
    if code == _W:
        return 1.0 / math.sqrt(nl * nv)
    if code == _WD:
        return 1.0 / (nl * nv)
    length = math.sqrt(max(2.0 + 2.0 * l_dot_v, COSINE_FLOOR * COSINE_FLOOR))
    v_dot_h = max(0.5 * length, COSINE_FLOOR)
    one_minus = 1.0 - min(max(v_dot_h, 0.0), 1.0)
    squared = one_minus * one_minus
    fresnel = f0 + (1.0 - f0) * (squared * squared * one_minus)  # schlick_fresnel's order
    if code == _AS:
        return fresnel / (v_dot_h * max(nl, nv))
    n_dot_h = max((nl + nv) / length, COSINE_FLOOR)
    shadowing = min(1.0, min(2.0 * n_dot_h * nv / v_dot_h, 2.0 * n_dot_h * nl / v_dot_h))
    cos4 = (n_dot_h * n_dot_h) * (n_dot_h * n_dot_h)
    return shadowing * fresnel / ((nl * nv) * cos4)


def pca_variable_scalar(code: int, cos_l: float, cos_v: float, l_dot_v: float, c_xy: float,
                        c_z: float) -> float:
    """:func:`pca_variable` for one direction pair, in plain arithmetic (compiled as above)."""
    if code == _LA:
        product = cos_l * cos_v
        return (c_xy * (l_dot_v - product) + c_z * product) / max(abs(c_xy), abs(c_z))
    length = math.sqrt(max(2.0 + 2.0 * l_dot_v, COSINE_FLOOR * COSINE_FLOOR))
    return min(max((cos_l + cos_v) / length, 0.0), 1.0)


def lobe_terms(model: str, gamma, cos_l, cos_v, l_dot_v, ops=NUMPY_OPS, *, f0=1.0,
               lafortune_c=(-1.0, 1.0)):
    r"""Evaluate the fixed and edited terms of the glossy lobe, zero below the horizon.

    Parameters
    ----------
    model : str
    gamma : float or array
    cos_l, cos_v, l_dot_v : array
        :math:`N\cdot L`, :math:`N\cdot V`, :math:`L\cdot V`.
    ops : namespace
        :data:`NUMPY_OPS` or the Dr.Jit namespace of :mod:`translucent.reference.brdf_plugins`.
    f0 : float
    lafortune_c : (float, float)
        :math:`(C_x = C_y, C_z)` of the Lafortune lobe.

    Returns
    -------
    fixed, edited : array
        :math:`f_F` (Table 4, without :math:`\rho_s`) and :math:`f_E` (sr^-1); their product
        is the glossy lobe of Table 3 over :math:`\rho_s`. Both 0 where
        :math:`N\cdot L \le 0` or :math:`N\cdot V \le 0`.
    """
    above = (cos_l > 0.0) & (cos_v > 0.0)
    variable = pca_variable(model, cos_l, cos_v, l_dot_v, ops, lafortune_c=lafortune_c)
    fixed = fixed_term(model, cos_l, cos_v, l_dot_v, ops, f0=f0)
    if canonical_model(model) == "lafortune":
        edited = edited_term(model, gamma, variable, ops)
    else:
        edited = edited_term(model, gamma, None, ops, cos_delta=variable)
    return ops.select(above, fixed, 0.0), ops.select(above, edited, 0.0)


def _unit(vectors) -> np.ndarray:
    vectors = np.asarray(vectors, dtype=np.float64)
    if vectors.shape[-1:] != (3,):
        raise InputError("directions must have a last axis of length 3", field="directions",
                         value=vectors.shape)
    length = np.linalg.norm(vectors, axis=-1, keepdims=True)
    with np.errstate(invalid="ignore", divide="ignore"):
        return vectors / length


@dataclass(frozen=True)
class AnalyticBRDF:
    r"""An analytic BRDF of Table 3 of Nguyen et al. 2010: a Lambertian term plus a glossy lobe.

    Parameters
    ----------
    model : str
        One of :data:`MODELS` or Table 3's symbols (BP, W, WD, La, CT, AS).
    gamma : float
        The editing parameter, in the model's range (:data:`GAMMA_RANGES`).
    rho_s : float or (3,) array_like
        Glossy coefficient :math:`k_s` per RGB channel, >= 0 (Table 2).
    rho_d : float or (3,) array_like
        Diffuse albedo :math:`k_d` per RGB channel, in [0, 1].
    f0 : float
        Fresnel reflectance at normal incidence of CT and AS, in [0, 1]; 0.04 (glass,
        water) by default.
    lafortune_c : (float, float)
        :math:`(C_x = C_y, C_z)` of the Lafortune lobe; (-1, 1) is the Phong lobe about the
        mirror direction. Not both zero.
    name : str, optional

    Raises
    ------
    InputError
        Unknown model, gamma outside the model's range, negative or non-finite
        coefficients; the message names the field, the value and the accepted range.
    """

    model: str
    gamma: float
    rho_s: np.ndarray = 1.0
    rho_d: np.ndarray = 0.0
    f0: float = 0.04
    lafortune_c: tuple = (-1.0, 1.0)
    name: str = ""

    def __post_init__(self):
        model = canonical_model(self.model)
        object.__setattr__(self, "model", model)
        object.__setattr__(self, "gamma", check_gamma(model, self.gamma))
        object.__setattr__(self, "rho_s", rgb_field(self.rho_s, "rho_s"))
        object.__setattr__(self, "rho_d", rgb_field(self.rho_d, "rho_d", maximum=1.0))
        f0 = float(check_finite(self.f0, "f0"))
        if not 0.0 <= f0 <= 1.0:
            raise InputError("must be in [0, 1]", field="f0", value=self.f0)
        object.__setattr__(self, "f0", f0)
        coefficients = np.asarray(self.lafortune_c, dtype=np.float64)
        if coefficients.shape != (2,):
            raise InputError("must be (C_xy, C_z): the lobe is isotropic (C_x = C_y)",
                             field="lafortune_c", value=self.lafortune_c)
        check_finite(coefficients, "lafortune_c")
        if not np.any(coefficients != 0):
            raise InputError("C_xy and C_z must not both be 0", field="lafortune_c",
                             value=self.lafortune_c)
        object.__setattr__(self, "lafortune_c", (float(coefficients[0]), float(coefficients[1])))

    @property
    def gamma_range(self) -> tuple[float, float]:
        r"""The model's editing range ``(gamma_min, gamma_max)``."""
        return GAMMA_RANGES[self.model]

    def with_gamma(self, gamma) -> AnalyticBRDF:
        r"""Return a copy with another editing parameter (range-checked)."""
        return replace(self, gamma=gamma)

    def cosines(self, wi, wo, normal=None):
        r"""Return :math:`(N\cdot L, N\cdot V, L\cdot V)` of ``wi`` (to light) and ``wo`` (to eye).

        Directions are normalised; ``normal`` defaults to +z (a local shading frame).
        """
        wi, wo = _unit(wi), _unit(wo)
        normal = np.array([0.0, 0.0, 1.0]) if normal is None else _unit(normal)
        cos_l = np.sum(wi * normal, axis=-1)
        cos_v = np.sum(wo * normal, axis=-1)
        l_dot_v = np.sum(wi * wo, axis=-1)
        return cos_l, cos_v, l_dot_v

    def lobe(self, cos_l, cos_v, l_dot_v, gamma=None):
        r"""Evaluate the glossy lobe over :math:`\rho_s`, :math:`f_F f_E` in sr^-1 (Eq. 5)."""
        fixed, edited = lobe_terms(self.model, self.gamma if gamma is None else gamma,
                                   np.asarray(cos_l, dtype=np.float64),
                                   np.asarray(cos_v, dtype=np.float64),
                                   np.asarray(l_dot_v, dtype=np.float64),
                                   f0=self.f0, lafortune_c=self.lafortune_c)
        return fixed * edited

    def eval_cosines(self, cos_l, cos_v, l_dot_v) -> np.ndarray:
        r"""Evaluate the BRDF from the three cosines; shape ``broadcast + (3,)``, sr^-1."""
        cos_l = np.asarray(cos_l, dtype=np.float64)
        cos_v = np.asarray(cos_v, dtype=np.float64)
        lobe = self.lobe(cos_l, cos_v, l_dot_v)
        above = ((cos_l > 0) & (cos_v > 0))[..., None]
        return np.where(above, self.rho_d / math.pi, 0.0) + self.rho_s * lobe[..., None]

    def eval(self, wi, wo, normal=None) -> np.ndarray:
        r"""Evaluate the BRDF :math:`f(\omega_i, \omega_o)` in sr^-1, per RGB channel.

        Parameters
        ----------
        wi : array_like, shape (..., 3)
            Directions towards the light (need not be normalised).
        wo : array_like, shape (..., 3)
            Directions towards the viewer.
        normal : array_like, shape (..., 3), optional
            Surface normals; +z (local frame) by default.

        Returns
        -------
        ndarray, shape (..., 3)
            :math:`\rho_d/\pi + \rho_s f_F f_E` (Eq. 5 and Table 3 of Nguyen et al. 2010);
            0 when either direction is at or below the horizon.
        """
        return self.eval_cosines(*self.cosines(wi, wo, normal))

    def directional_albedo(self, cos_theta_o, *, n_theta: int = 512, n_phi: int = 256):
        r"""Integrate :math:`\int f \cos\theta_i\, d\omega_i`, the albedo seen at ``cos_theta_o``.

        Integrated over half vectors (:math:`d\omega_i = 4 (\omega_o\cdot h) d\omega_h`):
        for each azimuth :math:`\phi_h` (trapezoid rule) the half angle runs over
        :math:`[0, \theta_{max}(\phi_h)]`, where :math:`\omega_i` meets the horizon,
        :math:`\theta_{max} = (\pi/2 + \operatorname{atan2}(\sin\theta_o\cos\phi_h,
        \cos\theta_o))/2`, with Gauss-Legendre nodes (dense near the lobe at
        :math:`\theta_h = 0`). The integrand is smooth on that domain, so the rule converges
        fast.

        Returns
        -------
        ndarray, shape (3,)
            The albedo per channel (what a white furnace shows); > 1 where the model
            gains energy.
        """
        cos_o = float(np.clip(cos_theta_o, COSINE_FLOOR, 1.0))
        sin_o = math.sqrt(1.0 - cos_o**2)
        wo = np.array([sin_o, 0.0, cos_o])
        nodes, weights = np.polynomial.legendre.leggauss(n_theta)
        phi = (np.arange(n_phi) + 0.5) * (2.0 * math.pi / n_phi)
        theta_max = 0.5 * (0.5 * math.pi + np.arctan2(sin_o * np.cos(phi), cos_o))
        theta = 0.5 * theta_max[:, None] * (nodes + 1.0)            # (phi, theta)
        theta_weights = 0.5 * theta_max[:, None] * weights
        sin_t, cos_t = np.sin(theta), np.cos(theta)
        h = np.stack([sin_t * np.cos(phi)[:, None], sin_t * np.sin(phi)[:, None], cos_t], -1)
        o_dot_h = h @ wo
        wi = 2.0 * o_dot_h[..., None] * h - wo
        wi[..., 2] = np.maximum(wi[..., 2], 0.0)  # rounding at the horizon node
        value = self.eval_cosines(wi[..., 2], cos_o, wi @ wo)
        jacobian = 4.0 * o_dot_h * wi[..., 2] * sin_t
        weight = theta_weights * (2.0 * math.pi / n_phi) * jacobian
        return np.einsum("pt,ptc->c", weight, value)

    def cache_key(self) -> dict:
        r"""Return what identifies this material in content hashes."""
        return {"type": "analytic_brdf", "model": self.model, "gamma": self.gamma,
                "rho_s": self.rho_s.tolist(), "rho_d": self.rho_d.tolist(), "f0": self.f0,
                "lafortune_c": list(self.lafortune_c)}


def _analytic_brdf_to_dict(material: AnalyticBRDF) -> dict:
    out = {"model": material.model, "gamma": material.gamma, "rho_s": material.rho_s,
           "rho_d": material.rho_d, "f0": material.f0,
           "lafortune_c": list(material.lafortune_c)}
    if material.name:
        out["name"] = material.name
    return out


register_material_type("analytic_brdf", AnalyticBRDF, to_dict=_analytic_brdf_to_dict)
