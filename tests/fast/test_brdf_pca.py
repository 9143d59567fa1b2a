"""BRDF editing by PCA with global illumination (Nguyen et al. 2010), fast/brdf_pca/."""

import math
import os
from dataclasses import replace

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from translucent.errors import InputError
from translucent.fast import brdf_pca as bp
from translucent.fast.base import Refusal
from translucent.fast.brdf_pca import kernels as bk
from translucent.fast.brdf_pca import lighting as bl
from translucent.fast.brdf_pca import transfer as bt
from translucent.materials import Dipole, Lambertian
from translucent.materials.brdf_pca import build_pca_basis
from translucent.materials.brdfs import (
    GAMMA_RANGES,
    MODELS,
    AnalyticBRDF,
    fixed_term,
    pca_variable,
)
from translucent.scenes import ConstantEnvironment, PointLight, load_scene
from translucent.scenes.raycast import visible

#: The compiled kernels and materials.brdfs evaluate the same float64 formulas in a
#: different order: differences are rounding, amplified at most ~1e3 times by the
#: steepest terms (Cook-Torrance's 1 / cos^4 near grazing).
KERNEL_RTOL = 1e-10

#: Images are float32: sums of a few float32 terms agree to a few ulps (6e-8 each).
FLOAT32_RTOL = 1e-5

#: Freezing with a budget that keeps every coefficient is exact linear algebra on
#: 16-bit quantised rows: each entry carries up to 1.5e-5 of its row's largest entry
#: (sparse_transport.QuantisedRows), so products agree to ~1e-4 of the pixel's value.
QUANTISATION_RTOL = 1e-4

#: Quasi-Monte Carlo (R2 points) on a smooth disk integrand converges like ~1/N; with
#: 4096 points the measured relative error is 3e-5; 1e-3 bounds it with margin.
DISK_QMC_RTOL = 1e-3

TINY = dict(gather_samples=256, bounces=1, transfer_coefficients=96,
            diffuse_coefficients=48, gather_coefficients=48, frozen_coefficients=48,
            light_samples=4, block_pairs=1 << 14)


def _tiny_scene(width=24, height=18):
    scene = load_scene("glossy")
    return scene.with_camera(replace(scene.camera, width=width, height=height))


@pytest.fixture(scope="module")
def scene():
    return _tiny_scene()


@pytest.fixture(scope="module")
def state(scene, tmp_path_factory):
    # module-scoped: set up before conftest's per-test private cache, so point it there too
    with pytest.MonkeyPatch.context() as patch:
        if not os.environ.get("TRANSLUCENT_CACHE"):
            patch.setenv("TRANSLUCENT_CACHE", str(tmp_path_factory.getbasetemp() / "cache"))
        return bp.precompute(scene, **TINY)


# -- wavelets -----------------------------------------------------------------------------


def test_gather_wavelets_keep_inner_products(rng):
    """Eq. 9 needs T . L = T^w . L^w: the 2D Haar over the gather square is orthonormal."""
    from translucent.fast.wavelets import haar2d_inverse

    rows = rng.normal(size=(5, 64)).astype(np.float32)
    coefficients = bt.haar_rows(rows)
    np.testing.assert_allclose(haar2d_inverse(coefficients.reshape(5, 8, 8)).reshape(5, 64),
                               rows, atol=1e-5)
    other = rng.normal(size=64).astype(np.float32)
    np.testing.assert_allclose(coefficients @ bt.haar_rows(other[None])[0], rows @ other,
                               rtol=1e-4, atol=1e-4)


def test_weighted_selection_keeps_the_coarse_terms(rng):
    """Selection by magnitude times sqrt(support) (Ng et al. 2003): a coarse coefficient
    beats a fine one of the same magnitude, and the kept values are the row's own."""
    weights = bt._support_weights(64)
    row = np.zeros((1, 64), dtype=np.float32)
    row[0, 0], row[0, 63] = 1.0, 2.0           # scaling coefficient, a finest detail
    kept = bt._select(row, 1, weights)
    assert kept.indices.tolist() == [0] and kept.values.tolist() == [1.0]
    dense = rng.normal(size=(3, 64)).astype(np.float32)
    kept = bt._select(dense, 10, weights)
    assert np.all(np.diff(kept.indptr) == 10)
    np.testing.assert_allclose(kept.to_dense()[kept.to_dense() != 0],
                               dense[kept.to_dense() != 0], rtol=1e-6)


# -- compiled BRDF terms against materials.brdfs -----------------------------------------


@pytest.mark.parametrize("model", MODELS)
@settings(max_examples=60, deadline=None)
@given(cos_l=st.one_of(st.sampled_from([0.0, 1e-300, 1e-9, 1.0]), st.floats(-1, 1)),
       cos_v=st.one_of(st.sampled_from([1e-300, 1e-9, 1.0]), st.floats(1e-6, 1)),
       azimuth=st.floats(0, math.pi))
def test_compiled_terms_match_the_materials(model, cos_l, cos_v, azimuth):
    sin_l, sin_v = math.sqrt(1 - cos_l**2), math.sqrt(1 - cos_v**2)
    l_dot_v = cos_l * cos_v + sin_l * sin_v * math.cos(azimuth)
    c = (-0.7, 0.9)
    got = bk._fixed_scalar(bk.MODEL_CODES[model], cos_l, cos_v, l_dot_v, 0.3)
    assert got == pytest.approx(float(fixed_term(model, cos_l, cos_v, l_dot_v, f0=0.3)),
                                rel=KERNEL_RTOL)
    got = bk._variable_scalar(bk.MODEL_CODES[model], cos_l, cos_v, l_dot_v, *c)
    assert got == pytest.approx(float(pca_variable(model, cos_l, cos_v, l_dot_v,
                                                   lafortune_c=c)), rel=KERNEL_RTOL,
                                abs=1e-15)


@pytest.mark.parametrize("model", MODELS)
def test_compiled_basis_matches_interpolated_pca(model, rng):
    material = AnalyticBRDF(model, GAMMA_RANGES[model][0], f0=0.3, lafortune_c=(-0.8, 1.0))
    basis = build_pca_basis(model, 4, gamma_samples=50, delta_samples=128)
    parameters = bt.material_parameters(material, basis)
    out = np.empty(5)
    for _ in range(50):
        cos_l, cos_v = rng.uniform(0.01, 1, 2)
        l_dot_v = cos_l * cos_v + math.sqrt((1 - cos_l**2) * (1 - cos_v**2)) * rng.uniform(-1, 1)
        bk._glossy_basis(parameters[0], cos_l, cos_v, l_dot_v, *parameters[1:], out)
        expected = fixed_term(model, cos_l, cos_v, l_dot_v, f0=0.3) * basis.basis_values(
            pca_variable(model, cos_l, cos_v, l_dot_v, lafortune_c=(-0.8, 1.0)))
        np.testing.assert_allclose(out, expected, rtol=KERNEL_RTOL, atol=1e-300)
    bk._glossy_basis(parameters[0], -0.1, 0.5, 0.0, *parameters[1:], out)
    np.testing.assert_array_equal(out, 0.0)


# -- sub-area sampling ----------------------------------------------------------------


def _disk_quadrature(material, basis, x, n_x, out, centre, normal, area, n=800):
    """Midpoint rule in polar coordinates on the disk: the integral Eq. 3 estimates."""
    radius = math.sqrt(area / math.pi)
    first, second = (v[0] for v in bl.tangent_frames(np.asarray(normal)[None]))
    rr = (np.arange(n) + 0.5) / n * radius
    phi = (np.arange(n) + 0.5) / n * 2 * math.pi
    r, p = np.meshgrid(rr, phi, indexing="ij")
    q = centre + (r * np.cos(p))[..., None] * first + (r * np.sin(p))[..., None] * second
    d = q - x
    r2 = np.einsum("...d,...d->...", d, d)
    w = d / np.sqrt(r2)[..., None]
    cos_x, cos_q = w @ n_x, -(w @ normal)
    cos_v = float(out @ n_x)
    values = fixed_term(material.model, cos_x, cos_v, w @ out, f0=material.f0)[..., None] * \
        basis.basis_values(pca_variable(material.model, cos_x, cos_v, w @ out))
    integrand = np.where((cos_x > 0) & (cos_q > 0), cos_x * cos_q / r2, 0.0)[..., None] * values
    weights = (radius / n) * (2 * math.pi / n) * r
    return np.einsum("ij,ijk->k", weights, integrand)


def test_subarea_estimate_converges_to_the_disk_integral():
    """Eq. 3 with uniform points of K_g converges to the integral over the disk, which the
    single point at its centre misses where the lobe varies across the disk (Fig. 2)."""
    material = AnalyticBRDF("BP", 200.0, rho_s=1.0)
    basis = build_pca_basis("BP", 6)
    x, n_x = np.zeros(3), np.array([0.0, 0.0, 1.0])
    out = np.array([math.sin(0.6), 0.0, math.cos(0.6)])
    mirror = np.array([-math.sin(0.6), 0.0, math.cos(0.6)])
    centre = 0.6 * (mirror + np.array([0.03, 0.02, 0.0]))
    normal = -mirror
    area = math.pi * 0.12**2
    exact = _disk_quadrature(material, basis, x, n_x, out, centre, normal, area)
    estimate = bt.disk_transfer(material, basis, x, n_x, out, centre, normal, area,
                                points=4096)
    np.testing.assert_allclose(estimate, exact, rtol=DISK_QMC_RTOL,
                               atol=DISK_QMC_RTOL * np.abs(exact).max())
    c = basis.coefficients(material.gamma)
    d = centre - x
    r2 = d @ d
    w = d / math.sqrt(r2)
    point = (w @ n_x) * (-(w @ normal)) * area / (r2 + area / math.pi) * \
        basis.basis_values(pca_variable("BP", w @ n_x, out @ n_x, w @ out))
    assert abs(estimate @ c - exact @ c) < 0.1 * abs(point @ c - exact @ c)


# -- precomputation and the interactive path ----------------------------------------------


@pytest.mark.parametrize("block", [1, 37, 256])
def test_gather_pairs_are_traced_once_and_read_back_reversed(state, scene, block):
    """Each unordered gather pair's answer is the ray traced from its earlier gather."""
    positions, normals = state.data.gather_position, state.data.gather_normal
    count = len(positions)
    engine, offset = bl.scene_ray_engine(scene)
    starts, columns, full = bl.pair_visibility(engine, offset, positions, normals, positions,
                                               normals)
    rows = np.repeat(np.arange(count), np.diff(starts))
    traced = {(int(b), int(g)): bool(v)
              for b, g, v in zip(rows, columns, full, strict=True) if g > b}
    assert traced  # the scene's gathers see each other
    known = bl.gather_pair_bits(count)
    parts = []
    for first in range(0, count, block):
        stop = min(count, first + block)
        block_starts, block_columns, seen = bl.gather_pair_visibility(
            engine, offset, positions, normals, first, stop, known)
        assert block_starts[-1] == starts[stop] - starts[first]
        np.testing.assert_array_equal(block_columns, columns[starts[first]:starts[stop]])
        parts.append(seen)
    seen = np.concatenate(parts)
    expected = [traced[(min(b, g), max(b, g))]
                for b, g in zip(rows.tolist(), columns.tolist(), strict=True)]
    np.testing.assert_array_equal(seen, expected)
    # the reversed rays answer the same nearly always: symmetry is a sound shortcut
    assert np.mean(seen == full) > 0.99


def test_precomputation_facts(state, scene):
    notes = state.log.notes
    assert notes["gather_samples"] == TINY["gather_samples"]
    # one glossy gather sample to six diffuse ones (Sect. 5.1)
    assert notes["glossy_gather_samples"] == round(256 / 7)
    assert notes["columns"] == 256
    side_by_side = state.data.gather_position.reshape(16, 16, 3)
    # the quadtree keeps neighbours on the square close in space: horizontal neighbours
    # are much closer than random pairs
    steps = np.linalg.norm(np.diff(side_by_side, axis=1), axis=2).mean()
    spread = np.linalg.norm(state.data.gather_position[:, None] - state.data.gather_position,
                            axis=2).mean()
    assert steps < 0.5 * spread
    assert any("back_wall" in s and "no PCA transfer" in s for s in state.log.skipped)
    assert sorted(state.glossy_objects) == ["box", "floor", "sphere"]
    total_area = sum(o.mesh.area for o in scene.objects)
    assert 0 < state.data.gather_area.sum() <= total_area * 1.001
    for budget in notes["budgets"].values():
        assert sum(budget) <= TINY["transfer_coefficients"] and budget[0] == max(budget)


def _exact_direct(state, scene, materials):
    """Direct lighting of every view sample from scratch: BRDF x irradiance x visibility."""
    data = state.data
    total = np.zeros((len(data.pixel), 3))
    for light in scene.lights:
        to_light = light.position - data.view_position
        distance = np.linalg.norm(to_light, axis=1)
        wi = to_light / distance[:, None]
        cosine = np.clip(np.einsum("ij,ij->i", wi, data.view_normal), 0, None)
        seen = visible(scene, data.view_position, light.position, normals_a=data.view_normal)
        for index, obj in enumerate(scene.objects):
            rows = data.view_object == index
            material = materials.get(obj.name, obj.material)
            if isinstance(material, Lambertian):
                f = np.broadcast_to(material.albedo / math.pi, (rows.sum(), 3))
            else:
                f = material.eval(wi[rows], data.view_out[rows], data.view_normal[rows])
            total[rows] += f * (light.intensity * (seen * cosine / distance**2)[rows, None])
    return total


def test_direct_lighting_is_the_exact_brdf(state, scene):
    image = state.render(component="direct").rgb.reshape(-1, 3)[state.data.pixel]
    np.testing.assert_allclose(image, _exact_direct(state, scene, {}), rtol=FLOAT32_RTOL,
                               atol=1e-7)
    sphere = scene.object("sphere").material.with_gamma(0.05)
    edited = state.render(material={"sphere": sphere}, component="direct")
    np.testing.assert_allclose(edited.rgb.reshape(-1, 3)[state.data.pixel],
                               _exact_direct(state, scene, {"sphere": sphere}),
                               rtol=FLOAT32_RTOL, atol=1e-7)
    state.render(material={"sphere": scene.object("sphere").material})


def test_editing_changes_only_the_edited_object(state, scene):
    before = state.render().rgb
    after = state.edit("floor", 250.0).rgb
    floor = np.zeros(before.shape[:2], dtype=bool).reshape(-1)
    floor[state.data.pixel[state.data.view_object == 0]] = True
    floor = floor.reshape(before.shape[:2])
    np.testing.assert_array_equal(after[~floor], before[~floor])
    assert np.abs(after[floor] - before[floor]).max() > 0
    assert state.render().metadata["gamma"]["floor"] == 250.0
    state.edit("floor", scene.object("floor").material.gamma)


def test_editing_equals_rendering_the_edited_scene(state, scene):
    """A new gamma through Eq. 15 gives the image of a scene built with that gamma: the
    precomputation (cached) does not depend on gamma."""
    edited = state.edit("box", 1.7).rgb
    other = scene.with_material("box", scene.object("box").material.with_gamma(1.7))
    fresh = bp.precompute(other, **TINY)
    assert fresh.log.notes["cache"] == "hit"
    np.testing.assert_array_equal(fresh.render().rgb, edited)
    state.edit("box", scene.object("box").material.gamma)


def test_relighting_equals_rendering_the_relit_scene(state, scene):
    lights = [PointLight([-1.0, 2.0, 1.0], 8.0), PointLight([1.0, 1.0, 2.0], 3.0)]
    relit = state.relight(lights).rgb
    fresh = bp.precompute(scene.with_lights(lights), **TINY).render().rgb
    np.testing.assert_allclose(relit, fresh, rtol=FLOAT32_RTOL, atol=1e-7)
    doubled = state.relight([PointLight(light.position, 2 * light.intensity)
                             for light in lights]).rgb
    np.testing.assert_allclose(doubled, 2 * relit, rtol=FLOAT32_RTOL, atol=1e-7)
    state.relight(scene.lights)


def test_freezing_with_every_coefficient_is_exact(scene):
    knobs = dict(TINY, frozen_coefficients=1 << 16)
    state = bp.precompute(scene, **knobs)
    before = state.render().rgb
    seconds = state.freeze(editing="floor")
    assert seconds >= 0 and sorted(state.frozen) == ["box", "sphere"]
    frozen = state.render().rgb
    np.testing.assert_allclose(frozen, before, rtol=QUANTISATION_RTOL,
                               atol=QUANTISATION_RTOL * before.max())
    # the edited object keeps its K + 1 rows; a frozen one comes back when edited
    state.edit("floor", 10.0)
    state.edit("box", 0.5)
    assert "box" not in state.frozen


def test_freezing_shrinks_the_working_set(scene):
    state = bp.precompute(scene, **TINY)
    state.render()
    before = state.storage_bytes()
    state.freeze()
    after = state.storage_bytes()
    assert after["transfer"] < before["transfer"]
    assert after["diffuse"] == before["diffuse"] and after["gather"] == before["gather"]
    image = state.relight([PointLight([0.5, 2.5, 1.5], 10.0)])
    assert np.all(np.isfinite(image.rgb)) and image.metadata["frozen"] == ["box", "floor",
                                                                           "sphere"]


# -- stability ---------------------------------------------------------------------------


@pytest.mark.parametrize("model", MODELS)
def test_gamma_at_the_ends_of_every_range_renders_finite_images(model):
    scene = _tiny_scene(16, 12)
    floor = AnalyticBRDF(model, GAMMA_RANGES[model][0], rho_s=0.3, rho_d=0.4, f0=0.5)
    scene = scene.with_material("floor", floor)
    state = bp.precompute(scene, **dict(TINY, gather_samples=64, n_basis=4))
    low, high = GAMMA_RANGES[model]
    for gamma in (low, high):
        image = state.edit("floor", gamma).rgb
        assert np.all(np.isfinite(image)) and image.max() > 0
    for bad in (low * 0.999, high * 1.001):
        with pytest.raises(InputError, match=rf"must be in \[{low:g}, {high:g}\] for the "
                                             rf"{model} model"):
            state.edit("floor", bad)


# -- bad input ---------------------------------------------------------------------------


def test_bad_knobs_and_scenes(scene):
    with pytest.raises(InputError, match=r"knobs = \['gather'\]: unknown knob; valid: "
                                         r"gather_samples"):
        bp.precompute(scene, gather=10)
    with pytest.raises(InputError, match=r"gather_samples = 8: must be an integer in "
                                         r"\[16, 4194304\]"):
        bp.precompute(scene, gather_samples=8)
    with pytest.raises(InputError, match=r"gather_samples = 512: must be a power of 4"):
        bp.precompute(scene, gather_samples=512)
    with pytest.raises(InputError, match=r"subarea = 'yes': must be true or false"):
        bp.precompute(scene, subarea="yes")
    with pytest.raises(InputError, match=r"glossy_ratio = 2.0: must be in \[0, 1\]"):
        bp.precompute(scene, glossy_ratio=2.0)
    milk = scene.with_material("box", Dipole(sigma_a=0.01, sigma_s_prime=1.0))
    assert bp.applies_to(milk).code == "unsupported_material"
    assert "Dipole material" in str(bp.applies_to(milk))
    with pytest.raises(InputError, match="does not apply: object 'box' has a Dipole"):
        bp.precompute(milk)
    diffuse = scene
    for name in ("floor", "sphere", "box"):
        diffuse = diffuse.with_material(name, Lambertian(0.5))
    assert bp.applies_to(diffuse) == Refusal("nothing_to_edit", "no object has an analytic BRDF: "
                                             "there is nothing to edit")
    lit = scene.with_lights([ConstantEnvironment(1.0)])
    assert bp.applies_to(lit).code == "unsupported_light"
    assert "environment lights are not supported" in str(bp.applies_to(lit))


def test_bad_edits(state, scene):
    with pytest.raises(InputError, match=r"object = 'back_wall': not an object with an "
                                         r"analytic BRDF; editable: floor"):
        state.edit("back_wall", 10)
    with pytest.raises(InputError, match=r"material\['floor'\] = 'ward': only gamma, rho_s "
                                         r"and rho_d can change"):
        state.render(material={"floor": AnalyticBRDF("W", 0.3)})
    with pytest.raises(InputError, match="several objects have an analytic BRDF: pass a dict"):
        state.render(material=AnalyticBRDF("BP", 10))
    with pytest.raises(InputError, match=r"material = 'lamp': no such object"):
        state.render(material={"lamp": Lambertian(0.5)})
    with pytest.raises(InputError, match=r"component = 'glossy': must be 'all', 'direct' or "
                                         r"'indirect'"):
        state.render(component="glossy")
    with pytest.raises(InputError, match=r"lights\[0\] = 'ConstantEnvironment': environment"):
        state.relight([ConstantEnvironment(1.0)])


# -- gather samples that reflect by their BRDF ----------------------------------------------


def test_each_gather_reflection_comes_closest_to_its_own_transport(scene):
    """'lambertian' renders the paper's transport (+lambertian_gather1), 'brdf' the one whose
    gather samples reflect their direct light by their whole BRDF (+glossy_gather1): each
    is nearer its own path-traced model than the other's image is."""
    from translucent.reference import render
    from translucent.reports.metrics.compute import relative_mse
    from translucent.scenes.gbuffer import gbuffer

    modes = ("lambertian", "brdf")
    names = {mode: bp.model_name({**TINY, "gather_reflection": mode}) for mode in modes}
    assert names == {"lambertian": "brdf_pca_k6+lambertian_gather1",
                     "brdf": "brdf_pca_k6+glossy_gather1"}
    models = {mode: render(scene, spp=256, passes=4, cache=False, progress=False,
                           profile=names[mode]) for mode in modes}
    images = {mode: bp.precompute(scene, **TINY, gather_reflection=mode).render()
              for mode in modes}
    hit = gbuffer(scene).hit

    def error(model, image):
        return relative_mse(models[model].rgb[hit], images[image].rgb[hit],
                            reference_variance=models[model].variance[hit])

    assert error("brdf", "brdf") < error("brdf", "lambertian")
    assert error("lambertian", "lambertian") < error("lambertian", "brdf")


def test_an_edit_with_brdf_gather_reflection_relights_the_other_objects(scene):
    """With 'brdf' the floor's gamma shapes the light its gather samples send the sphere and
    the box: an edit changes their pixels too, and equals rendering the edited scene."""
    state = bp.precompute(scene, **TINY, gather_reflection="brdf")
    before = state.render().rgb
    after = state.edit("floor", 250.0).rgb
    others = np.zeros(before.shape[:2], dtype=bool).reshape(-1)
    others[state.data.pixel[state.data.view_object != 0]] = True
    others = others.reshape(before.shape[:2])
    assert np.abs(after[others] - before[others]).max() > 0
    other = scene.with_material("floor", scene.object("floor").material.with_gamma(250.0))
    fresh = bp.precompute(other, **TINY, gather_reflection="brdf")
    assert fresh.log.notes["cache"] == "hit"  # a run-time knob: the same precomputation
    # the edit adds the floor's change to the kept products (float32 sums), the fresh
    # render sums everything once
    np.testing.assert_allclose(fresh.render().rgb, after, rtol=FLOAT32_RTOL,
                               atol=FLOAT32_RTOL * after.max())
    # and back: the edit undone is the first image
    np.testing.assert_allclose(state.edit("floor", scene.object("floor").material.gamma).rgb,
                               before, rtol=FLOAT32_RTOL, atol=FLOAT32_RTOL * before.max())
    # a new rho_s (the old term taken out, the new one added) is the scene made with it
    shinier = replace(scene.object("box").material, rho_s=np.array([0.9, 0.7, 0.5]))
    edited = state.render(material={"box": shinier}).rgb
    fresh = bp.precompute(scene.with_material("box", shinier), **TINY,
                          gather_reflection="brdf").render().rgb
    np.testing.assert_allclose(edited, fresh, rtol=FLOAT32_RTOL,
                               atol=FLOAT32_RTOL * fresh.max())


def test_block_reflection_is_the_pca_brdf_times_the_irradiance(rng):
    """The compiled reflection towards a block equals rho_s f_F sum_j c_j b_j E written
    with materials.brdfs' numpy terms and the basis' own interpolation; a gather sample
    within the guard, behind its surface from the block, or unlit sends nothing."""
    material = AnalyticBRDF("ward", 0.2, rho_s=[0.4, 0.3, 0.2], rho_d=[0.1, 0.1, 0.1])
    basis = build_pca_basis("ward", 4, gamma_samples=50, delta_samples=128)
    coefficients = basis.coefficients(material.gamma)
    positions = rng.uniform(-1, 1, (6, 3)) * [1, 0, 1]
    normals = np.tile([0.0, 1.0, 0.0], (6, 1))
    disk = np.full(6, 0.01)
    light = rng.normal(size=(6, 2, 3))
    light[..., 1] = np.abs(light[..., 1])
    light /= np.linalg.norm(light, axis=-1, keepdims=True)
    brought = rng.uniform(0.5, 1.0, (6, 2, 3))
    brought[5] = 0.0                                  # unlit
    centres = np.array([[0.3, 2.0, 0.1], [0.0, -1.0, 0.0], positions[0] + [0, 0.01, 0]])
    radius = np.array([0.1, 0.1, 0.05])
    out = np.zeros((3, 3, 8))
    columns = np.arange(6) + 2
    bk.block_reflection(centres, radius, positions, normals, disk, columns, light,
                        brought * material.rho_s, coefficients, 2.0,
                        *bt.material_parameters(material, basis), out)
    towards = centres[0] - positions
    towards /= np.linalg.norm(towards, axis=1, keepdims=True)
    cos_l, cos_v = light[..., 1], towards[:, 1][:, None]
    l_dot_v = np.einsum("nsd,nd->ns", light, towards)
    variable = pca_variable("ward", cos_l, cos_v, l_dot_v)
    lobe = basis.basis_values(variable) @ coefficients
    weight = np.where(cos_l > 0, fixed_term("ward", cos_l, cos_v, l_dot_v) * lobe, 0.0)
    expected = np.einsum("ns,nsc->cn", weight, brought * material.rho_s)
    np.testing.assert_allclose(out[0][:, 2:], expected, rtol=KERNEL_RTOL)
    assert np.all(out[0][:, 2 + 5] == 0) and np.all(out[:, :, :2] == 0)
    assert np.all(out[1] == 0)                        # below the floor: behind every sample
    assert np.all(out[2][:, 2] == 0) and np.any(out[2][:, 3:] > 0)


def test_glossy_objects_out_of_view_reflect_too_and_the_blocks_memory_is_bounded(
        scene, monkeypatch):
    """A glossy object no pixel sees still has gather samples, which reflect by its BRDF
    (its model, the gather integrator, reflects at every second vertex); and a block
    count whose vectors would not fit is refused, naming the knob."""
    from translucent.scenes import Camera

    camera = scene.camera
    aside = scene.with_camera(Camera([1.8, 0.6, 1.8], [1.9, 0.0, 1.5], camera.up, 20.0, 24, 18))
    state = bp.precompute(aside, **TINY, gather_reflection="brdf")
    unseen = set(state._reflecting) - set(state.glossy_objects)
    assert unseen  # the camera sees the floor alone
    state.render()
    assert {term[0] for term in state._reflection_terms()} == set(state._reflecting)
    monkeypatch.setattr(bp.state, "REFLECTION_MAX_BYTES", 1024)
    small = bp.precompute(scene, **TINY, gather_reflection="brdf")
    with pytest.raises(InputError, match="reflection_blocks = .*GiB of gather radiance"):
        small.render()


def test_reflection_blocks_split_squares_by_object():
    pixel = np.array([0, 1, 4, 5, 2, 3])           # a 2 x 4 image, 2 x 2 squares
    view_object = np.array([0, 0, 0, 1, 0, 0])
    position = np.arange(18, dtype=float).reshape(6, 3)
    block, centre, radius = bp.state.reflection_blocks((2, 4), pixel, view_object, position, 2)
    assert len(set(block[:3])) == 1 and block[3] != block[0] and block[4] == block[5]
    assert len(centre) == 3
    np.testing.assert_allclose(centre[block[0]], position[:3].mean(axis=0))
    np.testing.assert_allclose(radius[block[3]], 0.0)
    np.testing.assert_allclose(radius[block[0]], np.linalg.norm(position[0] - position[1]))


# -- against path-traced references (slow) -----------------------------------------------


@pytest.mark.slow
def test_converges_to_the_transport_it_approximates():
    """More gather samples bring the image closer to the path-traced limit of the method's
    own transport (the first surface glossy, every later one Lambertian, Sect. 5.2)."""
    from translucent.reference.brdf_plugins import render_lambertian_gather
    from translucent.reports.metrics.compute import relative_mse
    from translucent.scenes.gbuffer import interior_pixels

    scene = _tiny_scene(48, 36)
    limit = render_lambertian_gather(scene, bounces=2, spp=128, passes=4)
    mask = interior_pixels(scene)
    errors = []
    for gathers in (256, 4096):
        image = bp.precompute(scene, gather_samples=gathers).render()
        errors.append(relative_mse(limit.rgb[mask], image.rgb[mask],
                                   reference_variance=limit.variance[mask]))
    assert errors[1] < errors[0], errors


@pytest.mark.slow
@pytest.mark.parametrize("gamma", [3.0, 300.0])
def test_indirect_light_brings_it_closer_to_the_exact_reference(gamma):
    """Against the exact-BRDF path tracer, the full image beats its own direct lighting:
    the glossy and diffuse transfer carry real light (FLIP and relative MSE)."""
    from translucent.reference import render
    from translucent.reports.metrics.compute import evaluate, relative_mse
    from translucent.scenes.gbuffer import interior_pixels

    scene = _tiny_scene(48, 36)
    scene = scene.with_material("floor", scene.object("floor").material.with_gamma(gamma))
    exact = render(scene, spp=128, passes=4, progress=False)
    state = bp.precompute(scene, gather_samples=4096)
    full, direct = state.render(), state.render(component="direct")
    mask = interior_pixels(scene)
    error = {name: relative_mse(exact.rgb[mask], image.rgb[mask],
                                reference_variance=exact.variance[mask])
             for name, image in (("full", full), ("direct", direct))}
    flip = {name: evaluate(exact, image).metrics.hdr_flip
            for name, image in (("full", full), ("direct", direct))}
    assert error["full"] < error["direct"] and flip["full"] < flip["direct"], (error, flip)


@pytest.mark.parametrize("arguments, message", [
    (["--object", "nosuch", "--gamma", "3"], "object = 'nosuch': not an object with an "
                                              "analytic BRDF; editable: floor, sphere, box"),
    (["--object", "back_wall", "--gamma", "3"], "object = 'back_wall': not an object"),
    (["--object", "sphere", "--gamma", "5"], "gamma = 5.0: must be in [0.05, 2]"),
    (["--gamma", "5"], "several objects have an analytic BRDF"),
    (["--object", "floor"], "--object needs --gamma"),
])
def test_approx_checks_the_edit_before_precomputing(tmp_path, capsys, monkeypatch, arguments,
                                                    message):
    from translucent.reports.cli import main

    def never(*args, **kwargs):
        raise AssertionError("precomputed before the edit was checked")

    monkeypatch.setattr(bp.method, "precompute", never)
    assert main(["approx", "brdf_pca", "glossy", *arguments, "--out",
                 str(tmp_path / "g.exr")]) == 2
    assert message in capsys.readouterr().err
    assert not any(tmp_path.iterdir())
