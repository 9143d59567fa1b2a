"""The analytic BRDFs of Nguyen et al. 2010: Table 3 forms, Table 4 split, limits, stability."""

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from translucent.errors import InputError
from translucent.materials.brdfs import (
    COSINE_FLOOR,
    GAMMA_RANGES,
    MODELS,
    AnalyticBRDF,
    canonical_model,
    check_gamma,
    edited_term,
    fixed_term,
    lobe_terms,
    pca_variable,
    pca_variable_range,
    schlick_fresnel,
)

#: The same formula through different algebra (explicit half vector and local-frame
#: components here, three cosines in the module): the difference is float64 rounding,
#: amplified at most a few hundred times by exp(-tan^2/gamma^2) with gamma = 0.05.
FLOAT64_IDENTITY_RTOL = 1e-9

#: Gauss-Legendre quadrature of the normalisation integrals: doubling the nodes from 512
#: to 1024 changes the narrowest lobes (gamma = 300, gamma = 0.05) by less than 1e-8, so
#: 1e-6 bounds the quadrature error with a wide margin.
QUADRATURE_RTOL = 1e-6


def _random_directions(rng, n, min_cos=1e-3):
    """Unit vectors of the upper hemisphere with cos theta >= min_cos."""
    v = rng.normal(size=(n, 3))
    v[:, 2] = np.abs(v[:, 2])
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    keep = v[:, 2] >= min_cos
    return v[keep]


def _table3(model, gamma, l, v, f0=0.5, c=(-1.0, 1.0)):
    """Table 3 of Nguyen et al. 2010 written from explicit vectors (rho_s = 1)."""
    h = (l + v) / np.linalg.norm(l + v, axis=-1, keepdims=True)
    nl, nv, nh, vh = l[:, 2], v[:, 2], h[:, 2], np.sum(v * h, axis=-1)
    delta = np.arccos(np.clip(nh, -1, 1))
    fresnel = f0 + (1 - f0) * (1 - vh) ** 5
    if model == "blinn_phong":
        return (gamma + 2) / (2 * np.pi) * np.cos(delta) ** gamma
    if model in ("ward", "ward_duer"):
        lobe = np.exp(-np.tan(delta) ** 2 / gamma**2) / (4 * np.pi * gamma**2)
        return lobe / (np.sqrt(nl * nv) if model == "ward" else nl * nv)
    if model == "lafortune":
        cx = cy = c[0]
        cz = c[1]
        dot = cx * l[:, 0] * v[:, 0] + cy * l[:, 1] * v[:, 1] + cz * l[:, 2] * v[:, 2]
        scale = max(abs(cx), abs(cy), abs(cz))
        return (gamma + 2) * np.maximum(dot, 0) ** gamma / (2 * np.pi * scale**gamma)
    if model == "cook_torrance":
        d = np.exp(-(np.tan(delta) / gamma) ** 2) / (gamma**2 * np.cos(delta) ** 4)
        g = np.minimum(1, np.minimum(2 * nh * nv / vh, 2 * nh * nl / vh))
        return d * g / (np.pi * nl * nv) * fresnel
    if model == "ashikhmin_shirley":
        return ((gamma + 1) / (8 * np.pi) * nh**gamma / (vh * np.maximum(nl, nv))
                * fresnel)
    raise AssertionError(model)


def _parameter_values(model):
    low, high = GAMMA_RANGES[model]
    return [low, math.sqrt(low * high), high]


@pytest.mark.parametrize("model", MODELS)
def test_eval_is_table3_plus_lambertian(model, rng):
    l = _random_directions(rng, 400)
    v = _random_directions(rng, 400)[: len(l)]
    l = l[: len(v)]
    for gamma in _parameter_values(model):
        for c in ((-1.0, 1.0), (-0.6, 0.9)):
            brdf = AnalyticBRDF(model, gamma, rho_s=[1.0, 0.5, 0.25], rho_d=[0.2, 0.1, 0.0],
                                f0=0.5, lafortune_c=c)
            expected = _table3(model, gamma, l, v, f0=0.5, c=c)
            got = brdf.eval(l, v)
            np.testing.assert_allclose(got[:, 0], expected + 0.2 / np.pi,
                                       rtol=FLOAT64_IDENTITY_RTOL, atol=1e-300)
            np.testing.assert_allclose(got[:, 2], 0.25 * expected, rtol=FLOAT64_IDENTITY_RTOL,
                                       atol=1e-300)


@pytest.mark.parametrize("model", [m for m in MODELS if m != "lafortune"])
def test_edited_term_depends_on_half_angle_only(model, rng):
    """Table 4: f_E is a function of (gamma, delta); all else is in f_F."""
    gamma = _parameter_values(model)[1]
    delta = 0.3
    h = np.array([math.sin(delta), 0.0, math.cos(delta)])
    edited = []
    for phi_v in (0.2, 1.0, 2.5):
        # directions v whose mirror image about h stays above the horizon
        v = np.array([math.sin(0.4) * math.cos(phi_v), math.sin(0.4) * math.sin(phi_v),
                      math.cos(0.4)])
        l = 2 * np.dot(v, h) * h - v
        assert l[2] > 0
        _, e = lobe_terms(model, gamma, l[2], v[2], np.dot(l, v))
        edited.append(float(e))
    np.testing.assert_allclose(edited, edited[0], rtol=FLOAT64_IDENTITY_RTOL)
    np.testing.assert_allclose(edited[0], edited_term(model, gamma, delta),
                               rtol=FLOAT64_IDENTITY_RTOL)


def _half_vector_quadrature(n=512):
    nodes, weights = np.polynomial.legendre.leggauss(n)
    theta = 0.25 * np.pi * (nodes + 1)
    return theta, 0.25 * np.pi * weights * 2 * np.pi * np.sin(theta)


@pytest.mark.parametrize("model", ["blinn_phong", "ward", "ward_duer", "cook_torrance",
                                   "ashikhmin_shirley"])
def test_edited_term_normalisation(model):
    """Each f_E is a normalised distribution of half vectors up to a known factor.

    BP: int f_E cos(delta) dw_h = 1; W, WD: 4 f_E / cos^3 is Beckmann's D, int D cos = 1;
    CT: f_E / cos^3 likewise; AS: int f_E dw_h = 1/4.
    """
    theta, weight = _half_vector_quadrature()
    expected = {"blinn_phong": 1.0, "ward": 1.0, "ward_duer": 1.0, "cook_torrance": 1.0,
                "ashikhmin_shirley": 0.25}[model]
    for gamma in _parameter_values(model):
        f_e = edited_term(model, gamma, theta)
        factor = {"blinn_phong": np.cos(theta), "ward": 4 / np.cos(theta) ** 3,
                  "ward_duer": 4 / np.cos(theta) ** 3, "cook_torrance": 1 / np.cos(theta) ** 3,
                  "ashikhmin_shirley": np.ones_like(theta)}[model]
        assert np.sum(weight * f_e * factor) == pytest.approx(expected, rel=QUADRATURE_RTOL)


def test_lafortune_lobe_is_normalised_at_normal_incidence():
    """With C = (-1, 1) the lobe is cos^gamma about the mirror direction: at normal
    incidence (gamma+2)/(2 pi) int cos^(gamma+1) dw = 1, so the albedo is rho_s."""
    for gamma in _parameter_values("lafortune"):
        albedo = AnalyticBRDF("La", gamma, rho_s=1.0).directional_albedo(1.0)
        np.testing.assert_allclose(albedo, 1.0, rtol=QUADRATURE_RTOL)


def test_lambertian_part_has_albedo_rho_d():
    brdf = AnalyticBRDF("ward", 0.3, rho_s=0.0, rho_d=[0.8, 0.5, 0.1])
    for cos_o in (1.0, 0.5, 0.05):
        np.testing.assert_allclose(brdf.directional_albedo(cos_o), [0.8, 0.5, 0.1],
                                   rtol=QUADRATURE_RTOL)


@pytest.mark.parametrize("model", MODELS)
@settings(max_examples=60, deadline=None)
@given(a=st.tuples(st.floats(-1, 1), st.floats(-1, 1), st.floats(1e-3, 1)),
       b=st.tuples(st.floats(-1, 1), st.floats(-1, 1), st.floats(1e-3, 1)),
       unit_gamma=st.floats(0, 1))
def test_reciprocity(model, a, b, unit_gamma):
    low, high = GAMMA_RANGES[model]
    brdf = AnalyticBRDF(model, low + unit_gamma * (high - low), rho_s=1.0, f0=0.2)
    forward = brdf.eval(np.array(a), np.array(b))
    backward = brdf.eval(np.array(b), np.array(a))
    np.testing.assert_allclose(forward, backward, rtol=FLOAT64_IDENTITY_RTOL, atol=1e-300)


#: Cosines that stress the denominators: exactly at, just above and just below the horizon.
GRAZING_COSINES = [0.0, 5e-324, 1e-300, 1e-12, COSINE_FLOOR, 1e-3, -1e-12, 1.0]


@pytest.mark.parametrize("model", MODELS)
@settings(max_examples=80, deadline=None)
@given(cos_l=st.one_of(st.sampled_from(GRAZING_COSINES), st.floats(-1, 1)),
       cos_v=st.one_of(st.sampled_from(GRAZING_COSINES), st.floats(-1, 1)),
       azimuth=st.floats(0, 2 * math.pi), at_end=st.booleans())
def test_finite_and_nonnegative_at_grazing_angles(model, cos_l, cos_v, azimuth, at_end):
    low, high = GAMMA_RANGES[model]
    for gamma in (low, high) if at_end else (0.5 * (low + high),):
        brdf = AnalyticBRDF(model, gamma, rho_s=1.0, rho_d=0.5, f0=0.0)
        sin_l, sin_v = math.sqrt(1 - cos_l**2), math.sqrt(1 - cos_v**2)
        l = np.array([sin_l, 0.0, cos_l])
        v = np.array([sin_v * math.cos(azimuth), sin_v * math.sin(azimuth), cos_v])
        for value in (brdf.eval(l, v), brdf.eval(l, -l * [1, 1, -1])):
            assert np.all(np.isfinite(value)) and np.all(value >= 0)
        for dtype in (np.float32, np.float64):
            fixed, edited = lobe_terms(model, gamma, dtype(cos_l), dtype(cos_v),
                                       dtype(np.dot(l, v)), f0=0.0)
            assert np.isfinite(fixed) and np.isfinite(edited) and np.isfinite(fixed * edited)


def test_below_horizon_reflects_nothing():
    for model in MODELS:
        brdf = AnalyticBRDF(model, GAMMA_RANGES[model][0], rho_s=1.0, rho_d=1.0)
        np.testing.assert_array_equal(brdf.eval([0, 0.3, -0.5], [0, 0, 1]), 0.0)
        np.testing.assert_array_equal(brdf.eval([0, 0.3, 0.5], [0, 0.2, 0.0]), 0.0)


def test_schlick_fresnel_limits():
    f0 = np.array([0.0, 0.04, 0.5, 1.0])
    np.testing.assert_allclose(schlick_fresnel(f0, 1.0), f0)          # normal incidence
    np.testing.assert_allclose(schlick_fresnel(f0, 0.0), 1.0)         # grazing incidence
    np.testing.assert_allclose(schlick_fresnel(f0, -0.5), 1.0)        # clamped
    np.testing.assert_allclose(schlick_fresnel(f0, 1.5), f0)          # clamped
    cosines = np.linspace(0, 1, 101)
    assert np.all(np.diff(schlick_fresnel(0.04, cosines)) <= 0)
    assert schlick_fresnel(0.04, 0.5) == pytest.approx(0.04 + 0.96 / 32)


@pytest.mark.parametrize("model", ["cook_torrance", "ashikhmin_shirley"])
def test_fresnel_in_the_lobe_at_normal_and_grazing_incidence(model):
    """At the mirror configuration V.H = cos(theta); the lobe scales as F(F0, V.H)."""
    gamma = GAMMA_RANGES[model][0]
    ratios = []
    for cos_theta in (1.0, 1e-4):
        sin_theta = math.sqrt(1 - cos_theta**2)
        v = np.array([sin_theta, 0, cos_theta])
        l = np.array([-sin_theta, 0, cos_theta])
        lobe = [AnalyticBRDF(model, gamma, rho_s=1.0, f0=f0).eval(l, v)[0] for f0 in (0.1, 1.0)]
        ratios.append(lobe[0] / lobe[1])
    assert ratios[0] == pytest.approx(0.1, rel=FLOAT64_IDENTITY_RTOL)
    assert ratios[1] == pytest.approx(schlick_fresnel(0.1, 1e-4), rel=FLOAT64_IDENTITY_RTOL)


def test_vectorised_over_any_leading_shape(rng):
    brdf = AnalyticBRDF("CT", 0.4, rho_s=[1, 0.5, 0.2], rho_d=0.1)
    wi = _random_directions(rng, 200)[:60].reshape(4, 5, 3, 3)
    wo = np.array([0.3, 0.1, 0.9])
    got = brdf.eval(wi, wo)
    assert got.shape == (4, 5, 3, 3)
    one_by_one = np.array([brdf.eval(w, wo) for w in wi.reshape(-1, 3)]).reshape(got.shape)
    np.testing.assert_allclose(got, one_by_one, rtol=FLOAT64_IDENTITY_RTOL)
    normals = np.broadcast_to([0.0, 0.0, 2.0], wi.shape)  # unnormalised normals
    np.testing.assert_allclose(brdf.eval(wi, wo, normals), got, rtol=FLOAT64_IDENTITY_RTOL)


def test_nan_directions_do_not_crash():
    brdf = AnalyticBRDF("W", 0.3, rho_s=1.0)
    value = brdf.eval([np.nan, 0, 1], [0, 0, 1])
    assert value.shape == (3,)
    value = brdf.eval([0, 0, 0], [0, 0, 1])  # a zero vector has no direction
    assert value.shape == (3,)


@pytest.mark.parametrize("model", MODELS)
def test_gamma_at_both_ends_accepted_and_beyond_rejected(model):
    low, high = GAMMA_RANGES[model]
    assert AnalyticBRDF(model, low).gamma == low
    assert AnalyticBRDF(model, high).gamma == high
    message = rf"gamma = .*must be in \[{low:g}, {high:g}\] for the {model} model"
    for bad in (low * (1 - 1e-9), high * (1 + 1e-9), 0.0, -1.0, 1e6):
        with pytest.raises(InputError, match=message):
            AnalyticBRDF(model, bad)
    with pytest.raises(InputError, match="gamma = nan: must be finite"):
        AnalyticBRDF(model, float("nan"))
    with pytest.raises(InputError, match=message):
        AnalyticBRDF(model, low).with_gamma(high * 2)


def test_bad_parameters_name_field_and_range():
    with pytest.raises(InputError, match=r"model = 'phong2': unknown BRDF model; valid: "
                                         r"blinn_phong, ward"):
        AnalyticBRDF("phong2", 10)
    with pytest.raises(InputError, match=r"rho_s = -0.1: must be >= 0"):
        AnalyticBRDF("BP", 10, rho_s=-0.1)
    with pytest.raises(InputError, match=r"rho_d = 1.5: must be <= 1.0"):
        AnalyticBRDF("BP", 10, rho_d=1.5)
    with pytest.raises(InputError, match=r"f0 = 1.2: must be in \[0, 1\]"):
        AnalyticBRDF("CT", 0.5, f0=1.2)
    with pytest.raises(InputError, match=r"lafortune_c = \(0, 0\): C_xy and C_z must not"):
        AnalyticBRDF("La", 10, lafortune_c=(0, 0))
    with pytest.raises(InputError, match=r"lafortune_c = \(-1, -1, 1\): must be \(C_xy, C_z\)"):
        AnalyticBRDF("La", 10, lafortune_c=(-1, -1, 1))
    with pytest.raises(InputError, match=r"gamma = 2: must be in \[3, 300\]"):
        check_gamma("AS", 2)


def test_model_aliases_and_identity():
    assert [canonical_model(s) for s in ("BP", "w", "WD", "La", "ct", "AS", "Blinn-Phong")] == \
        ["blinn_phong", "ward", "ward_duer", "lafortune", "cook_torrance",
         "ashikhmin_shirley", "blinn_phong"]
    a = AnalyticBRDF("BP", 10, rho_s=0.5)
    assert a.cache_key() != a.with_gamma(11).cache_key()
    assert a.with_gamma(11).rho_s.tolist() == [0.5] * 3
    with pytest.raises(ValueError, match="read-only"):
        a.rho_s[0] = 1.0
    assert pca_variable_range("la") == (1e-3, 1 - 1e-3)
    assert pca_variable_range("bp") == (0.0, math.pi / 2)


# -- the scalar forms compiled kernels take -------------------------------------------------

_PAIRS = st.tuples(st.floats(-0.2, 1.0), st.floats(-0.2, 1.0), st.floats(-1.0, 1.0),
                   st.floats(0.0, 1.0))


@settings(max_examples=200, deadline=None)
@given(st.sampled_from(MODELS), _PAIRS)
def test_the_scalar_terms_are_the_array_terms(model, pair):
    """Bit for bit: the kernels of BRDF editing compile these very functions."""
    from translucent.materials.brdfs import MODEL_CODES, fixed_term_scalar, pca_variable_scalar

    cos_l, cos_v, l_dot_v, f0 = pair
    arrays = [np.array([value]) for value in (cos_l, cos_v, l_dot_v)]
    code = MODEL_CODES[model]
    assert fixed_term_scalar(code, cos_l, cos_v, l_dot_v, f0) == \
        fixed_term(model, *arrays, f0=f0)[0]
    c = (-1.1, 0.9)
    assert pca_variable_scalar(code, cos_l, cos_v, l_dot_v, *c) == \
        pca_variable(model, *arrays, lafortune_c=c)[0]


@settings(max_examples=100, deadline=None)
@given(st.sampled_from(MODELS), _PAIRS)
def test_the_compiled_terms_are_the_scalar_terms(model, pair):
    from translucent.fast.brdf_pca import kernels
    from translucent.materials.brdfs import MODEL_CODES, fixed_term_scalar, pca_variable_scalar

    code = MODEL_CODES[model]
    cos_l, cos_v, l_dot_v, f0 = pair
    assert kernels._fixed_scalar(code, cos_l, cos_v, l_dot_v, f0) == \
        pytest.approx(fixed_term_scalar(code, cos_l, cos_v, l_dot_v, f0), rel=1e-14)
    assert kernels._variable_scalar(code, cos_l, cos_v, l_dot_v, -1.1, 0.9) == \
        pytest.approx(pca_variable_scalar(code, cos_l, cos_v, l_dot_v, -1.1, 0.9), rel=1e-14)
