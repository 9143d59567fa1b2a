"""The light a scene's diffuse surfaces bounce onto its translucent objects (fast.indirect_light).

Checked against closed forms that share no code with the ray-cast gather: the radiosity of
a closed sphere's interior (exact form factors A_j / A), the irradiance of a uniform
enclosure (B times the hemispherical Fresnel transmittance, by quadrature), and, end to
end, against the committed model reference of the Cornell block (the BSSRDF path tracer).
"""

import functools
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy import integrate
from translucent.fast.indirect_light import (
    INDIRECT_LIGHT,
    IndirectLight,
    bouncing_objects,
    precompute_indirect_light,
)
from translucent.fast.radiosity.form_factors import build_patches, form_factors
from translucent.materials import Lambertian
from translucent.materials.fresnel import fresnel_transmittance
from translucent.scenes import Camera, Mesh, Scene, SceneObject, box, icosphere, load_scene
from translucent.scenes.scene import PointLight

CAMERA = Camera([0.0, 0.0, 5.0], [0.0, 0.0, 0.0], width=8, height=8)
ALBEDO = 0.6
INTENSITY = 2.0
KNOBS = {"indirect_light": "diffuse", "indirect_rays": 64, "indirect_patch_rays": 256,
         "seed": 3}
#: Probes near the centre of the enclosure, with normals all round.
PROBES = 400


def _enclosure(light_at=(0.0, 0.0, 0.0)) -> Scene:
    """The inside of a unit sphere, Lambertian, a point light inside."""
    outside = icosphere(2, 1.0)
    inside = Mesh(outside.vertices, outside.faces[:, ::-1], -outside.normals, name="inside")
    return Scene([SceneObject("room", inside, Lambertian(ALBEDO))],
                 [PointLight(light_at, INTENSITY)], CAMERA)


def _probes():
    rng = np.random.default_rng(11)
    normals = rng.normal(size=(PROBES, 3))
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    return 0.05 * rng.uniform(-1, 1, size=(PROBES, 3)), normals


@functools.lru_cache(maxsize=None)
def _enclosure_light(light_at=(0.0, 0.0, 0.0)) -> tuple[Scene, IndirectLight]:
    scene = _enclosure(light_at)
    return scene, precompute_indirect_light(scene, {"probes": _probes()}, KNOBS)


def test_the_bounce_solve_matches_the_closed_sphere_with_exact_form_factors():
    # inside a sphere every point sees patch j with F_ij = A_j / A (Goral et al. 1984):
    # B = rho (E + F B) solved exactly with those, against the ray-cast F iterated
    scene, light = _enclosure_light((0.2, -0.1, 0.3))
    radiosity, facts = light.radiosity(scene, bounces=200)
    patches = light.patches
    points = patches.centroid
    to_light = np.array([0.2, -0.1, 0.3]) - points
    distance = np.linalg.norm(to_light, axis=1)
    cosine = np.einsum("ij,ij->i", to_light / distance[:, None], patches.normal)
    direct = INTENSITY * np.clip(cosine, 0, None) / distance**2
    exact_F = np.broadcast_to(patches.area / patches.area.sum(), (len(patches),) * 2)
    exact = np.linalg.solve(np.eye(len(patches)) - ALBEDO * exact_F, ALBEDO * direct)
    assert facts["last_change"] < 1e-4
    # the ray-cast F has noise of about sqrt(F / 256) per entry; B_j is nearly uniform
    # (the light near the centre), so a row's noise moves B_i by far less than 1 %
    assert radiosity[:, 0] == pytest.approx(exact, rel=0.01)
    # the energy of the whole solve: the area-weighted mean within 0.1 %
    mean = np.average(radiosity[:, 0], weights=patches.area)
    assert mean == pytest.approx(np.average(exact, weights=patches.area), rel=0.001)


def _hemispherical_transmittance(eta: float) -> float:
    r""":math:`2 \int_0^1 F_t(\eta, \mu)\,\mu\,d\mu`, by adaptive quadrature."""
    value, _ = integrate.quad(lambda mu: 2.0 * fresnel_transmittance(eta, mu) * mu, 0.0, 1.0,
                              epsabs=1e-12)
    return value


@pytest.mark.parametrize("eta", [1.0, 1.3, 1.8])
def test_a_uniform_enclosure_gives_its_radiosity_times_the_fresnel_transmittance(eta):
    _, light = _enclosure_light()
    uniform = np.full((len(light.patches), 3), 2.5)
    irradiance = light.irradiance("probes", uniform, eta)[:, 0]
    expected = 2.5 * _hemispherical_transmittance(eta)
    if eta == 1.0:  # every ray hits the room: the weights 1 / K add up to one exactly
        assert irradiance == pytest.approx(expected, rel=1e-12)
        return
    error = irradiance.std(ddof=1) / math.sqrt(len(irradiance))
    assert abs(irradiance.mean() - expected) < 5 * error + 1e-12
    assert abs(irradiance.mean() / expected - 1) < 0.01


@settings(max_examples=25, deadline=None)
@given(eta=st.floats(1.0, 3.0), scale=st.floats(1e-3, 1e3))
def test_the_gather_is_linear_and_never_creates_energy(eta, scale):
    _, light = _enclosure_light()
    matrix = light.gather_matrix("probes", eta)
    sums = np.asarray(matrix.sum(axis=1)).ravel()
    assert np.all(sums <= 1.0 + 1e-12) and np.all(sums >= 0.0)
    rng = np.random.default_rng(5)
    radiosity = rng.uniform(0, 1, size=(len(light.patches), 3))
    assert np.allclose(light.irradiance("probes", scale * radiosity, eta),
                       scale * light.irradiance("probes", radiosity, eta), rtol=1e-12)


def test_form_factors_from_some_rows_leave_the_others_empty_and_keep_energy():
    scene = _enclosure()
    patches = build_patches(scene)
    rows = np.arange(0, len(patches), 7)
    F, facts = form_factors(scene, patches, rays_per_patch=64, rows=rows)
    sums = np.asarray(F.sum(axis=1)).ravel()
    others = np.setdiff1d(np.arange(len(patches)), rows)
    assert np.all(sums[others] == 0)
    assert sums[rows] == pytest.approx(1.0, abs=1e-6)  # a closed room: every ray lands
    assert facts["rays"] == len(rows) * 64


def test_scenes_without_a_lambertian_surface_or_with_it_off_bounce_nothing():
    from translucent.fast.base import StageLog

    sphere = load_scene("sphere")
    assert bouncing_objects(sphere) == []
    log = StageLog()
    assert precompute_indirect_light(sphere, {}, KNOBS, log) is None
    assert "nothing bounces" in log.notes["indirect light"]
    log = StageLog()
    scene = _enclosure()
    assert precompute_indirect_light(scene, {"probes": _probes()},
                                     {**KNOBS, "indirect_light": "off"}, log) is None
    assert any("indirect light off" in sentence for sentence in log.skipped)
    black = Scene([SceneObject("black", box(), Lambertian(0.0))], [], CAMERA)
    assert bouncing_objects(black) == []
    assert INDIRECT_LIGHT == ("diffuse", "lambertian", "off")


@pytest.mark.parametrize("method", ["prt", "splatting"])
def test_the_cornell_block_lit_by_its_walls_follows_the_model_reference(method):
    # the committed model reference of cornell_block (the BSSRDF path tracer with the
    # dipole, the walls' inter-reflection included): without the walls' light PRT and
    # splatting are 0.17-0.19 away in relative MSE (measured at these quick knobs); with
    # it 0.023-0.025
    import translucent
    from translucent.reference.committed import committed_reference
    from translucent.reports.bench.model_error import object_mask, object_metrics

    scene = load_scene("cornell_block")
    model = committed_reference("cornell_block", scene, profile="dipole").require()
    mask = object_mask(scene, "block")
    # the half-space profile: the model reference's model
    quick = {**translucent.method(method).QUICK_KNOBS, "geometry": "half_space"}
    errors = {mode: object_metrics(model, translucent.approx(method, scene, **quick,
                                                             indirect_light=mode), mask)
              for mode in INDIRECT_LIGHT}
    assert errors["off"]["relative_mse"] > 0.15
    assert errors["lambertian"]["relative_mse"] < 0.03
    # the block's own light sent back by the walls: closer still
    assert errors["diffuse"]["relative_mse"] < errors["lambertian"]["relative_mse"]
    # the energy the walls send: at least half of the missing luminance is made up
    # (splatting's own direct light is low on the block, by 0.1-0.2 of the model's)
    gaps = {mode: abs(1.0 - errors[mode]["luminance_ratio"]) for mode in INDIRECT_LIGHT}
    assert gaps["diffuse"] < 0.5 * gaps["off"]


def test_a_translucent_object_of_reflectance_rho_bounces_as_a_lambertian_of_albedo_rho():
    # index-matched (F_t = T_in = 1), R_d E is what a Lambertian of albedo R_d sends on:
    # the same patches, the same form-factor rays, the same solve
    from translucent.materials import Dipole

    outside = icosphere(2, 1.0)
    room = Mesh(outside.vertices, outside.faces[:, ::-1], -outside.normals, name="room")
    ball = icosphere(1, 0.3, center=(0.1, -0.2, 0.0))
    light = PointLight([0.0, 0.5, 0.3], INTENSITY)
    probes = {"ball": (ball.vertices, ball.normals)}
    lambertian = Scene([SceneObject("room", room, Lambertian(ALBEDO)),
                        SceneObject("ball", ball, Lambertian(0.4))], [light], CAMERA)
    translucent = Scene([SceneObject("room", room, Lambertian(ALBEDO)),
                         SceneObject("ball", ball, Dipole([0.01] * 3, [1.0] * 3, 1.0))],
                        [light], CAMERA)
    as_wall = precompute_indirect_light(lambertian, {}, {**KNOBS, "indirect_light": "lambertian"})
    as_ball = precompute_indirect_light(translucent, probes, KNOBS)
    assert as_ball.reflecting == (1,)
    wall_B, _ = as_wall.radiosity(lambertian, bounces=200)
    ball_B, _ = as_ball.radiosity(translucent, bounces=200,
                                  reflectance={1: (np.full(3, 0.4), 1.0)})
    assert np.allclose(ball_B, wall_B, rtol=1e-9, atol=1e-12)
    # without its reflectance the ball absorbs, and the room is darker
    dark_B, _ = as_ball.radiosity(translucent, bounces=200)
    assert dark_B[as_ball.bouncing].sum() < 0.99 * ball_B[as_ball.bouncing].sum()
