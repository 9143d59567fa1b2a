"""The analytic BRDF Mitsuba plugin: 1 create, 2 eval, 3 chi-square, 4 furnace, 5 render."""

import math

import numpy as np
import pytest
from scipy.stats import norm
from translucent.backend import mitsuba
from translucent.errors import InputError
from translucent.materials.brdfs import GAMMA_RANGES, MODELS, AnalyticBRDF
from translucent.reference.brdf_plugins import PLUGIN_NAME, bsdf_dict, register_plugin

#: The plugin runs in float32: cosines carry rounding of ~6e-8, which the steepest lobes
#: amplify by gamma = 300 (a power) or 1/gamma^2 = 400 (Ward's exponent) to ~3e-5
#: relative; 1e-3 bounds that with margin. Values below 1e-6 of the largest compare in
#: absolute terms (float32 has no relative precision left in exp(-400 tan^2)).
FLOAT32_RTOL = 1e-3
FLOAT32_ATOL_FRACTION = 1e-6

#: Parameter values per model: both ends of the editing range and the geometric middle.
PARAMETERS = [(m, g) for m in MODELS for g in (GAMMA_RANGES[m][0],
                                                math.sqrt(GAMMA_RANGES[m][0] * GAMMA_RANGES[m][1]),
                                                GAMMA_RANGES[m][1])]

#: Incident directions (local frame): normal, 37 degrees, 76 degrees from the normal.
INCIDENT = [(0.0, 0.0, 1.0), (0.6, 0.0, 0.8), (0.97, 0.0, 0.2431)]

#: Significance of the whole family of chi-square tests in this file (Mitsuba's own BSDF
#: tests use 0.01 with a Sidak correction over the family).
SIGNIFICANCE = 0.01
CHI2_TEST_COUNT = len(PARAMETERS) * len(INCIDENT)

#: Furnace z-tests, Sidak-corrected over their family like the chi-square tests.
FURNACE_CASES = [(m, g) for m in MODELS for g in GAMMA_RANGES[m]]
FURNACE_TEST_COUNT = len(FURNACE_CASES) * 2


def _material(model, gamma, **overrides):
    values = dict(rho_s=[0.5, 0.4, 0.3], rho_d=[0.3, 0.2, 0.1], f0=0.5, lafortune_c=(-1.0, 1.0))
    values.update(overrides)
    return AnalyticBRDF(model, gamma, **values)


def _unit(v):
    v = np.asarray(v, dtype=np.float64)
    return v / np.linalg.norm(v)


def _surface(mi, wi, n):
    import drjit as dr

    si = dr.zeros(mi.SurfaceInteraction3f, n)
    si.wi = mi.Vector3f(*[float(x) for x in _unit(wi)])
    return si


def test_1_create_and_reject_bad_gamma():
    mi = mitsuba()
    bsdf = mi.load_dict(bsdf_dict(_material("BP", 20)))
    assert "blinn_phong" in str(bsdf)
    assert bsdf.flags() & int(mi.BSDFFlags.GlossyReflection)
    with pytest.raises(Exception, match=r"must be in \[3, 300\] for the blinn_phong model"):
        mi.load_dict({"type": PLUGIN_NAME, "model": "BP", "gamma": 400.0})
    with pytest.raises(Exception, match=r"unknown BRDF model"):
        mi.load_dict({"type": PLUGIN_NAME, "model": "phong2", "gamma": 4.0})


@pytest.mark.parametrize("model,gamma", PARAMETERS)
def test_2_eval_matches_the_material(model, gamma, rng):
    """Mitsuba's eval is f cos(theta_o); it must equal materials.brdfs at float32 precision."""
    mi = mitsuba()
    material = _material(model, gamma, lafortune_c=(-0.8, 0.9))
    bsdf = mi.load_dict(bsdf_dict(material))
    wo = rng.normal(size=(2000, 3))
    wo[:, 2] = np.abs(wo[:, 2]) + 1e-3
    wo /= np.linalg.norm(wo, axis=1, keepdims=True)
    for wi in INCIDENT:
        # directions near the mirror direction too, where the lobes peak
        mirror = _unit(wi) * [-1, -1, 1]
        near = mirror + 0.05 * rng.normal(size=(500, 3))
        near[:, 2] = np.abs(near[:, 2])
        near /= np.linalg.norm(near, axis=1, keepdims=True)
        directions = np.concatenate([wo, near])
        si = _surface(mi, wi, len(directions))
        wo_mi = mi.Vector3f(directions.T.astype(np.float32))
        got = np.array(bsdf.eval(mi.BSDFContext(), si, wo_mi))
        expected = material.eval(directions, np.broadcast_to(_unit(wi), directions.shape)) \
            * directions[:, 2:3]
        atol = FLOAT32_ATOL_FRACTION * expected.max()
        np.testing.assert_allclose(got.T, expected, rtol=FLOAT32_RTOL, atol=atol)


def _chi2(model, gamma, wi, *, plugin=PLUGIN_NAME, material=None):
    from mitsuba.chi2 import BSDFAdapter, ChiSquareTest, SphericalDomain

    entry = dict(bsdf_dict(material or _material(model, gamma)), type=plugin)
    sample_func, pdf_func = BSDFAdapter(plugin, entry, wi=[float(x) for x in _unit(wi)])
    test = ChiSquareTest(domain=SphericalDomain(), sample_func=sample_func, pdf_func=pdf_func,
                         sample_dim=3, sample_count=1_000_000, res=201, ires=8)
    return test


@pytest.mark.parametrize("wi", INCIDENT)
@pytest.mark.parametrize("model,gamma", PARAMETERS)
def test_3_chi_square_sampling(model, gamma, wi):
    """Mitsuba's chi-square test: samples follow the pdf the plugin reports."""
    mitsuba()
    test = _chi2(model, gamma, wi)
    assert test.run(SIGNIFICANCE, test_count=CHI2_TEST_COUNT, quiet=True), test.messages


def test_3_chi_square_detects_a_wrong_sampler():
    """The test has power: a sampler drawing gamma 20 % too wide is rejected."""
    mi = mitsuba()
    base = register_plugin()

    class WrongSampler(base):
        def _sample_glossy(self, wi, sample2):
            self.gamma, true_gamma = self.gamma * 0.8, self.gamma
            try:
                return super()._sample_glossy(wi, sample2)
            finally:
                self.gamma = true_gamma

    mi.register_bsdf("translucent_wrong_sampler", lambda props: WrongSampler(props))
    test = _chi2("BP", 30.0, INCIDENT[1], plugin="translucent_wrong_sampler",
                 material=_material("BP", 30.0, rho_d=0.0))
    assert not test.run(SIGNIFICANCE, test_count=1, quiet=True)


def _sample_weights(mi, material, wi, n, seed):
    import drjit as dr

    bsdf = mi.load_dict(bsdf_dict(material))
    sampler = mi.load_dict({"type": "independent"})
    sampler.seed(seed, n)
    si = _surface(mi, wi, n)
    _, weight = bsdf.sample(mi.BSDFContext(), si, sampler.next_1d(), sampler.next_2d())
    dr.eval(weight)
    return np.array(weight)


@pytest.mark.parametrize("model,gamma", FURNACE_CASES)
def test_4_white_furnace(model, gamma):
    """E[sample weight] = directional albedo (Monte Carlo estimate of int f cos in a
    furnace of radiance 1), against the quadrature of materials.brdfs, as a z-test."""
    mi = mitsuba()
    material = _material(model, gamma, rho_s=1.0, rho_d=0.2, f0=1.0)
    n = 1 << 20
    alpha = 1 - (1 - SIGNIFICANCE) ** (1 / FURNACE_TEST_COUNT)
    z_critical = norm.ppf(1 - alpha / 2)
    for index, wi in enumerate(INCIDENT[:2]):
        weights = _sample_weights(mi, material, wi, n, seed=index)[0]
        mean, standard_error = weights.mean(), weights.std() / math.sqrt(n)
        expected = material.directional_albedo(_unit(wi)[2])[0]
        assert np.all(np.isfinite(weights)) and np.all(weights >= 0)
        assert abs(mean - expected) <= z_critical * standard_error, (mean, expected,
                                                                     standard_error)


def test_5_render_a_furnace_rectangle():
    """A small render in a constant environment: the rectangle seen head-on shows the
    normal-incidence albedo (pixels judged by a z-test over the image mean)."""
    mi = mitsuba()
    material = _material("CT", 0.5, rho_s=0.2, rho_d=0.3, f0=0.5)
    scene = mi.load_dict({
        "type": "scene", "integrator": {"type": "path", "max_depth": 4},
        "sensor": {"type": "perspective", "fov": 2.0,
                   "to_world": mi.ScalarTransform4f().look_at(origin=[0, 0, 50],
                                                              target=[0, 0, 0], up=[0, 1, 0]),
                   "film": {"type": "hdrfilm", "width": 16, "height": 16,
                            "rfilter": {"type": "box"}},
                   "sampler": {"type": "independent", "sample_count": 64}},
        "rect": {"type": "rectangle", "bsdf": bsdf_dict(material)},
        "env": {"type": "constant", "radiance": {"type": "rgb", "value": 1.0}}})
    image = np.array(mi.render(scene, spp=64))[..., :3].reshape(-1, 3)
    expected = material.directional_albedo(1.0)
    standard_error = image.std(axis=0) / math.sqrt(len(image))
    z_critical = norm.ppf(1 - (1 - (1 - SIGNIFICANCE) ** (1 / 3)) / 2)
    assert np.all(np.abs(image.mean(axis=0) - expected) <= z_critical * standard_error)


def _small_glossy_scene(diffuse: bool):
    from dataclasses import replace

    from translucent.scenes import load_scene

    scene = load_scene("glossy")
    scene = scene.with_camera(replace(scene.camera, width=24, height=18))
    if diffuse:
        for obj in scene.objects:
            if isinstance(obj.material, AnalyticBRDF):
                scene = scene.with_material(obj.name, replace(obj.material, rho_s=0.0))
    return scene


def test_6_scene_conversion_uses_the_plugin_two_sided():
    from translucent.reference import to_mitsuba_dict

    description = to_mitsuba_dict(_small_glossy_scene(diffuse=False))
    loaded = mitsuba().load_dict(description)
    names = sorted(str(shape.bsdf()) for shape in loaded.shapes())
    assert sum("AnalyticBRDFPlugin" in name for name in names) == 3
    assert all("TwoSided" in name for name in names)


def test_7_lambertian_gather_is_the_path_tracer_on_diffuse_scenes():
    """With no glossy lobe the method's transport is all of the transport: the integrator
    must agree with Mitsuba's path tracer of the same depth (bounces + 3 segments)."""
    from translucent.reference import render
    from translucent.reference.brdf_plugins import render_lambertian_gather
    from translucent.reports.metrics.statistics import z_test_known_variance

    scene = _small_glossy_scene(diffuse=True)
    limit = render_lambertian_gather(scene, bounces=1, spp=64, passes=4)
    path = render(scene, spp=64, passes=4, max_depth=4, progress=False)
    result = z_test_known_variance(limit, path)
    assert result.passed, result.summary()


def test_7_lambertian_gather_misses_glossy_paths():
    """Every path it drops (glossy reflection after the first surface) carries light >= 0,
    so on a glossy scene its image is darker than the path tracer's, beyond the noise."""
    from translucent.reference import render
    from translucent.reference.brdf_plugins import render_lambertian_gather

    scene = _small_glossy_scene(diffuse=False)
    limit = render_lambertian_gather(scene, bounces=1, spp=64, passes=4)
    path = render(scene, spp=64, passes=4, max_depth=4, progress=False)
    difference = path.rgb.sum() - limit.rgb.sum()
    standard_error = math.sqrt(path.variance.sum() + limit.variance.sum())
    assert difference > 5 * standard_error
    with pytest.raises(InputError, match=r"bounces = -1: must be an integer >= 0"):
        render_lambertian_gather(scene, bounces=-1)


@pytest.mark.parametrize("model,gamma", [("BP", 60.0), ("W", 0.2), ("CT", 0.3), ("La", 20.0)])
def test_8_pca_plugin_evaluates_the_k_term_reconstruction(model, gamma, rng):
    """With pca_basis = K the edited term is b_0 + sum c_j b_j (Eq. 10), as numpy makes it."""
    from translucent.materials.brdf_pca import build_pca_basis
    from translucent.materials.brdfs import canonical_model, lobe_terms, pca_variable

    mi = mitsuba()
    material = _material(model, gamma, lafortune_c=(-0.8, 0.9))
    directions = rng.normal(size=(3000, 3))
    directions[:, 2] = np.abs(directions[:, 2]) + 1e-3
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    wi = _unit(INCIDENT[1])
    cos_l, cos_v = directions[:, 2], np.full(len(directions), wi[2])
    l_dot_v = directions @ wi
    fixed, exact = lobe_terms(canonical_model(model), gamma, cos_l, cos_v, l_dot_v,
                              f0=material.f0, lafortune_c=(-0.8, 0.9))
    variable = pca_variable(canonical_model(model), cos_l, cos_v, l_dot_v,
                            lafortune_c=(-0.8, 0.9))
    differences = {}
    for k in (6, 48):
        basis = build_pca_basis(canonical_model(model), k)
        edited = basis.basis_values(variable) @ basis.coefficients(gamma)
        expected = (material.rho_d / math.pi + material.rho_s * (fixed * edited)[:, None]) \
            * cos_l[:, None]
        bsdf = mi.load_dict(bsdf_dict(material, pca_basis=k))
        got = np.array(bsdf.eval(mi.BSDFContext(), _surface(mi, wi, len(directions)),
                                 mi.Vector3f(directions.T.astype(np.float32)))).T
        scale = expected.max()
        np.testing.assert_allclose(got, expected, rtol=FLOAT32_RTOL,
                                   atol=FLOAT32_ATOL_FRACTION * scale * 10)
        exact_value = (material.rho_d / math.pi + material.rho_s * (fixed * exact)[:, None]) \
            * cos_l[:, None]
        differences[k] = np.abs(got - exact_value).max() / scale
    # the exact plugin's lobe is approached as K grows: 48 terms reproduce it closely
    assert differences[48] < 0.02 and differences[48] < differences[6]


def test_8_a_pca_model_render_converges_to_the_exact_one_with_many_terms():
    from translucent.reference.render import render
    from translucent.scenes import load_scene

    scene = load_scene("glossy")
    exact = render(scene, spp=4, passes=2, cache=False, progress=False)
    many = render(scene, spp=4, passes=2, cache=False, progress=False, profile="brdf_pca_k48")
    six = render(scene, spp=4, passes=2, cache=False, progress=False, profile="brdf_pca_k6")
    assert many.metadata["profile"]["name"] == "brdf_pca_k48"
    # the same seeds: the renders differ by the BRDF's values alone
    scale = exact.rgb.mean()
    assert np.abs(many.rgb - exact.rgb).mean() < 0.1 * np.abs(six.rgb - exact.rgb).mean()
    assert np.abs(six.rgb - exact.rgb).mean() > 1e-4 * scale
    with pytest.raises(InputError, match="needs an analytic BRDF"):
        render(load_scene("sphere"), spp=1, passes=1, cache=False, progress=False,
               profile="brdf_pca_k6")


def test_9_a_glossy_gather_without_bounces_is_the_path_tracer_of_two_reflections():
    """``+glossy_gather0``: the first and second surface reflect the direct light by their
    whole (PCA) BRDF and nothing goes further: Mitsuba's own path tracer limited to the
    light's reflection at two surfaces (max_depth 3) renders the same transport."""
    from translucent.reference import render
    from translucent.reports.metrics.statistics import z_test_known_variance

    scene = _small_glossy_scene(diffuse=False)
    gather = render(scene, spp=64, passes=4, cache=False, progress=False,
                    profile="brdf_pca_k6+glossy_gather0")
    path = render(scene, spp=64, passes=4, cache=False, progress=False, max_depth=3,
                  integrator="path", profile="brdf_pca_k6")
    result = z_test_known_variance(gather, path)
    assert result.passed, result.summary()
    assert "by its BRDF" in gather.metadata["profile"]["transport"]
    # the Lambertian gather drops the second surface's glossy reflection: darker
    lambertian = render(scene, spp=64, passes=4, cache=False, progress=False,
                        profile="brdf_pca_k6+lambertian_gather0")
    difference = gather.rgb.sum() - lambertian.rgb.sum()
    assert difference > 5 * math.sqrt(gather.variance.sum() + lambertian.variance.sum())


def test_9_a_lambertian_gather_model_is_the_methods_limit_rendered_with_the_pca():
    """The model ``brdf_pca_k48+lambertian_gather1`` is :func:`render_lambertian_gather`
    with 48 PCA terms, which reproduce the exact lobe closely: equal within the noise."""
    from translucent.reference import render
    from translucent.reference.brdf_plugins import render_lambertian_gather
    from translucent.reports.metrics.statistics import z_test_known_variance

    scene = _small_glossy_scene(diffuse=False)
    model = render(scene, spp=64, passes=4, cache=False, progress=False,
                   profile="brdf_pca_k48+lambertian_gather1")
    limit = render_lambertian_gather(scene, bounces=1, spp=64, passes=4, seed=1)
    result = z_test_known_variance(model, limit)
    assert result.passed, result.summary()


@pytest.mark.parametrize("name", ["brdf_pca_k6+gather2", "brdf_pca_k6+lambertian_gather",
                                  "brdf_pca_k6+lambertian_gather65", "brdf_pca_k0",
                                  "brdf_pca_k6+", "brdf_pca_k6+lambertian_gather\u00b2"])
def test_9_a_badly_named_pca_model_names_the_grammar(name):
    from translucent.materials.brdf_pca import pca_model_basis

    with pytest.raises(InputError, match="lambertian_gather, glossy_gather"):
        pca_model_basis(name)


def test_9_the_gather_integrator_is_only_for_a_gather_model():
    from translucent.reference import render
    from translucent.reference.mitsuba_scene import GATHER_INTEGRATOR

    scene = _small_glossy_scene(diffuse=False)
    with pytest.raises(InputError, match="lambertian_gatherN only"):
        render(scene, spp=1, passes=1, cache=False, progress=False,
               integrator=GATHER_INTEGRATOR, profile="brdf_pca_k6")
    with pytest.raises(InputError, match="renders with the path integrator"):
        render(scene, spp=1, passes=1, cache=False, progress=False, integrator="path",
               profile="brdf_pca_k6+lambertian_gather2")
