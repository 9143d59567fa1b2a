import os

import numpy as np
import pytest
from translucent.errors import InputError
from translucent.fast import prt
from translucent.fast.object_geometry import QUICK_GEOMETRY_KNOBS
from translucent.fast.sparse_transport import SharedColumnBlocks
from translucent.image import Image
from translucent.materials import MEASURED_MEDIA, Dipole, Lambertian, measured_medium
from translucent.materials.dipole import total_diffuse_reflectance
from translucent.materials.dipole_pca import PARAMETERISATIONS, dipole_pca_basis
from translucent.materials.fresnel import fresnel_transmittance
from translucent.reports.cli import main
from translucent.scenes import (
    Camera,
    ConstantEnvironment,
    DirectionalLight,
    PointLight,
    RectangularAreaLight,
    Scene,
    SceneObject,
    SphereAreaLight,
    SpotLight,
    geometry_image,
    icosphere,
    load_scene,
)

#: The issue's accuracy target: PRT against Eq. 1 evaluated directly with the exact R_d on
#: the same samples, relative L2 over vertices and channels, at the default knobs.
BRUTE_FORCE_TARGET = 0.01

#: float32 accumulation over a few thousand products (products and sums are float32).
ROUND_OFF_32 = 1e-5

#: Spatial compression keeping 99.9 % of the CDF 9/7 coefficients' energy (the default):
#: measured 1.4-1.6 % against the brute force on 17^2 to 33^2 geometry images with 1024
#: samples (0.4 % without it); 2x that as the bound.
SPATIAL_TARGET = 0.03

#: Environment visibility on a 16 x 32 direction grid: the midpoint rule alone is within
#: 0.4 % of the exact hemispherical integral for every normal (measured), the 64 Haar terms
#: ranked by support and the rank-4 Fresnel factors add < 0.05 %; bounds with 2.5x margin.
ENVIRONMENT_SAMPLE_TOLERANCE = 0.01
ENVIRONMENT_MEAN_TOLERANCE = 0.005

#: A far, small emitter against its point-light equivalent: (size / distance)^2 ~ 1e-4
#: and 16 stratified samples; the rectangle is sampled by area, the sphere by solid angle.
AREA_LIGHT_TOLERANCE = 2e-3

#: The local vector (irradiance averaged around each vertex by a Gaussian one sample spacing
#: wide, Haar-compressed to 256 terms ranked by support): measured 0.3 % of its peak.
LOCAL_VECTOR_TOLERANCE = 0.01

#: Averaging the irradiance over one sample spacing (~0.55 mm on a 10 mm sphere) changes
#: its mean over the sphere by the curvature of E: well under 2 %.
SMOOTHING_TOLERANCE = 0.02

#: Samples lie on the flat facets of a subdivision-3 icosphere (edges ~0.1 units): one
#: whose interpolated normal faces the light by less than this cosine can be shadowed by the
#: neighbouring facets (the shadow terminator).
GRAZING_COSINE = 0.2

#: Illumination sample spacing of the default 16384 samples on the 10 mm sphere, mm.
DEFAULT_SAMPLE_SPACING = float(np.sqrt(4 * np.pi * 10.0**2 / 16384))

#: Coefficients swept by the trust tests, mm^-1: the stress sweep's decades (1e-6 to 1e3).
SWEPT_SIGMAS = np.geomspace(1e-6, 1e3, 10)

SAMPLES = 4096
MM_PER_UNIT = 10.0
LIGHT = PointLight([3.0, 4.0, 4.0], 100.0)


def sphere_scene(material=None, lights=(LIGHT,), mesh=None):
    mesh = icosphere(3) if mesh is None else mesh
    material = measured_medium("Marble") if material is None else material
    return Scene([SceneObject("sphere", mesh, material)], list(lights),
                 Camera([0, 0, 5], [0, 0, 0], fov=30, width=32, height=32),
                 mm_per_unit=MM_PER_UNIT)


@pytest.fixture(scope="module")
def state(tmp_path_factory):
    # module fixtures start before the function-scoped private cache of conftest: point the
    # cache at the same folder here so that nothing reaches the user's cache
    with pytest.MonkeyPatch.context() as patch:
        if not os.environ.get("TRANSLUCENT_CACHE"):
            patch.setenv("TRANSLUCENT_CACHE", str(tmp_path_factory.getbasetemp() / "cache"))
        # a coarse geometry correction: each edit to a new material solves it once
        yield prt.precompute(sphere_scene(), samples=SAMPLES, **QUICK_GEOMETRY_KNOBS)


def relative_error(approximation, reference):
    return float(np.linalg.norm(approximation - reference) / np.linalg.norm(reference))


def brute_force(state, material, lights=(LIGHT,)):
    transfer = state.transfers[0]
    irradiance = state.irradiance(transfer, lights, material.eta)
    return prt.brute_force_radiance(transfer, state.scene.objects[0].mesh.vertices, irradiance,
                                    material, mm_per_unit=MM_PER_UNIT)


def vertex_radiance(state, material, lights=(LIGHT,)):
    transfer = state.transfers[0]
    state.relight(transfer, lights, material.eta)
    return state.vertex_radiance(transfer, material)


def eq1_vertex_radiance(state, material, lights=(LIGHT,)):
    """PRT's sum of Eq. 5-7 over the samples, without the sampling blend.

    The sampling blend deliberately departs from Eq. 1 on the samples where they do not
    resolve the profile (at 1024-4096 samples on the 10 mm sphere, h = 0.55-1.1 mm, some
    measured channels): the brute-force comparisons measure the compression alone.
    """
    saved = state.knobs["sampling_blend"]
    state.knobs["sampling_blend"] = False
    try:
        return vertex_radiance(state, material, lights)
    finally:
        state.knobs["sampling_blend"] = saved


@pytest.mark.parametrize("name", ["Marble", "Skin1", "Chicken1", "Ketchup", "Wholemilk"])
def test_prt_matches_the_brute_force_eq1_on_the_same_samples(state, name):
    material = measured_medium(name)
    error = relative_error(eq1_vertex_radiance(state, material), brute_force(state, material))
    assert error < BRUTE_FORCE_TARGET, f"{name}: relative L2 {error:.4f}"


def test_samples_are_uniform_and_laid_out_on_squares(state):
    samples = state.transfers[0].samples
    assert len(samples) == SAMPLES and samples.parts == 4 and samples.side == 32
    mesh = state.scene.objects[0].mesh
    assert samples.area == pytest.approx(mesh.area * MM_PER_UNIT**2 / SAMPLES)
    assert np.allclose(np.linalg.norm(samples.positions, axis=1), 1.0, atol=0.02)
    assert np.allclose(np.linalg.norm(samples.normals, axis=1), 1.0)
    # the quadtree keeps neighbours close: each pixel's right neighbour within a few spacings
    image = samples.positions.reshape(4, 32, 32, 3)
    step = np.linalg.norm(np.diff(image, axis=2), axis=-1)
    spacing = np.sqrt(samples.area) / MM_PER_UNIT
    assert np.median(step) < 3 * spacing


def test_transfer_is_compressed_and_quantised(state):
    transfer = state.transfers[0]
    statistics = transfer.statistics
    matrix = transfer.transfer
    assert isinstance(matrix, SharedColumnBlocks) and statistics["layout"] == "shared"
    assert matrix.indices.dtype == np.uint16 and matrix.levels.dtype == np.int16
    assert transfer.basis_terms == 12 and transfer.row_count == 642 and matrix.blocks == 13
    # each vertex keeps the union of 13 selections of at most 256 terms
    assert matrix.width <= 13 * 256 and statistics["nnz"] == 13 * len(matrix.indices)
    assert statistics["megabytes"] == pytest.approx(matrix.nbytes / 2**20)
    assert "not a geometry image" in " ".join(state.log.skipped)


#: Two 16-bit quantisations of the same coefficient (per-row scales that may differ):
#: half a level of each row's largest entry, 0.5 / 32767 each, plus float32 round-off.
TWO_HALF_LEVELS = 1.0 / 32767 + 1e-6


def test_shared_layout_keeps_every_row_selection_and_more(state):
    rows = prt.precompute(sphere_scene(), samples=SAMPLES, layout="rows",
                          **QUICK_GEOMETRY_KNOBS)
    separate = rows.transfers[0].transfer.dequantised()
    shared = state.transfers[0].transfer.dequantised()
    assert rows.transfers[0].statistics["layout"] == "rows"
    assert separate.rows == shared.rows and shared.nnz > separate.nnz
    dense_shared = shared.to_dense()
    row_of = np.repeat(np.arange(separate.rows), np.diff(separate.indptr))
    kept = dense_shared[row_of, separate.indices]
    largest = np.abs(dense_shared).max(axis=1)[row_of]
    # every coefficient a row kept on its own is there, with its value
    assert np.all(np.abs(kept - separate.values) <= TWO_HALF_LEVELS * largest)
    # and the extra coefficients bring the products closer to the brute force
    material = measured_medium("Marble")
    error_rows = relative_error(vertex_radiance(rows, material), brute_force(rows, material))
    error_shared = relative_error(vertex_radiance(state, material),
                                  brute_force(state, material))
    assert error_shared <= error_rows


def test_linear_in_the_lights(state):
    material = measured_medium("Skin1")
    other = DirectionalLight([0.0, -1.0, -0.2], [1.0, 2.0, 0.5])
    first = vertex_radiance(state, material, (LIGHT,))
    second = vertex_radiance(state, material, (other,))
    both = vertex_radiance(state, material, (LIGHT, other))
    assert np.abs(both - first - second).max() < ROUND_OFF_32 * np.abs(both).max()
    brighter = PointLight(LIGHT.position, 2.5 * LIGHT.intensity)
    scaled = vertex_radiance(state, material, (brighter,))
    assert np.abs(scaled - 2.5 * first).max() < ROUND_OFF_32 * np.abs(scaled).max()


def test_editing_only_reweights_the_cached_vectors(state, monkeypatch):
    calls = []
    kind = type(state.transfers[0].transfer)
    product = kind.product

    def counting(self, vector, out=None):
        calls.append(1)
        return product(self, vector, out)

    monkeypatch.setattr(kind, "product", counting)
    state.render(lights=[LIGHT], material=measured_medium("Skin1"))
    calls.clear()
    for name in ("Skin2", "Potato", "Apple"):
        image = state.render(material=measured_medium(name))
        assert isinstance(image, Image)
    assert calls == []  # same eta 1.3: no product redone
    state.render(material=measured_medium("Marble"))  # eta 1.5: F_t in E changes
    assert len(calls) == 1
    state.render(lights=[PointLight([-3.0, 1.0, 4.0], 50.0)])
    assert len(calls) == 2


def test_render_is_an_image_through_the_camera(state):
    material = measured_medium("Marble")
    image = state.render(lights=[LIGHT], material=material)
    assert image.shape == (32, 32) and image.metadata["producer"] == "prt"
    assert image.rgb[0, 0].tolist() == [0.0, 0.0, 0.0]  # background
    from translucent.scenes import gbuffer

    view = gbuffer(state.scene)
    transfer = state.transfers[0]
    radiance = state.exit_radiance(transfer, material)
    cosine = np.clip(np.einsum("...d,...d->...", view.normal, view.view_direction), 0, 1)
    expected = view.interpolate("sphere", radiance) * (
        fresnel_transmittance(material.eta, cosine) / np.pi)[..., None]
    assert image.rgb == pytest.approx(expected.astype(np.float32), rel=1e-5, abs=1e-7)


def test_opaque_limit_is_a_lambertian_of_albedo_rd(state):
    """A medium whose mean free path is far below the sample spacing reflects locally."""
    transfer = state.transfers[0]
    irradiance = state.irradiance(transfer, (LIGHT,), 1.3)
    vertices = state.scene.objects[0].mesh.vertices * MM_PER_UNIT
    distance = np.linalg.norm(vertices[:, None] - transfer.samples.positions[None] * MM_PER_UNIT,
                              axis=-1)
    kernel = np.exp(-(distance / (prt.LOCAL_KERNEL_WIDTH * np.sqrt(transfer.samples.area))) ** 2)
    local = (kernel / kernel.sum(axis=1, keepdims=True)) @ irradiance
    exact = prt.sample_irradiance(state.scene, prt.IlluminationSamples(
        state.scene.objects[0].mesh.vertices, state.scene.objects[0].mesh.normals, 1.0, 1, 1),
        (LIGHT,), 1.3)
    for sigma_a, sigma_s_prime in ((1e3, 1.0), (0.01, 1e3), (1e-6, 1e3)):
        material = Dipole(sigma_a, sigma_s_prime, 1.3)
        albedo = total_diffuse_reflectance(sigma_a, sigma_s_prime, 1.3)
        radiance = vertex_radiance(state, material)
        assert np.abs(radiance - albedo * local).max() <= \
            LOCAL_VECTOR_TOLERANCE * np.abs(albedo * local).max()
        assert radiance.mean() == pytest.approx((albedo * exact).mean(),
                                                rel=SMOOTHING_TOLERANCE)
    # strongly absorbing: almost nothing comes back
    marble = vertex_radiance(state, measured_medium("Marble"))
    black = vertex_radiance(state, Dipole(1e3, 1.0, 1.3))
    assert np.abs(black).max() < 1e-3 * np.abs(marble).max()


def test_irradiance_of_point_spot_and_directional_lights(state):
    samples = state.transfers[0].samples
    offset = LIGHT.position - samples.positions
    squared = np.einsum("nd,nd->n", offset, offset)
    cosine = np.einsum("nd,nd->n", samples.normals, offset) / np.sqrt(squared)
    expected = np.where(cosine > 0, LIGHT.intensity[0] * fresnel_transmittance(1.3, np.clip(
        cosine, 0, 1)) * cosine / squared, 0.0)
    point = prt.sample_irradiance(state.scene, samples, [LIGHT], 1.3)[:, 0]
    # away from the terminator every sample facing the light sees it; near it the facets
    # of the mesh shadow samples whose interpolated normal still faces the light
    clear = cosine > GRAZING_COSINE
    assert point[clear] == pytest.approx(expected[clear], rel=1e-9)
    assert np.all(point <= expected * (1 + 1e-9))
    axis = -LIGHT.position / np.linalg.norm(LIGHT.position)
    spot = SpotLight(LIGHT.position, axis, LIGHT.intensity, cutoff_angle=8.0, beam_width=6.0)
    spotted = prt.sample_irradiance(state.scene, samples, [spot], 1.3)[:, 0]
    angle = np.degrees(np.arccos(np.clip(-offset @ axis / np.sqrt(squared), -1, 1)))
    assert np.all(spotted[angle >= 8.0] == 0)
    beam = (angle < 6.0) & clear
    assert beam.any() and spotted[beam] == pytest.approx(expected[beam], rel=1e-9)
    sun = DirectionalLight([0.0, 0.0, -1.0], 2.0)
    lit = prt.sample_irradiance(state.scene, samples, [sun], 1.3)[:, 0]
    facing = np.clip(samples.normals[:, 2], 0, 1)
    clear = facing > GRAZING_COSINE
    assert lit[clear] == pytest.approx(2.0 * fresnel_transmittance(1.3, facing[clear])
                                       * facing[clear], rel=1e-9)


@pytest.mark.parametrize("emitter", [
    RectangularAreaLight([0, 0, 8.0], [0.05, 0, 0], [0, -0.05, 0], 1.0),
    SphereAreaLight([0, 0, 8.0], 0.05, 1.0),
])
def test_far_small_emitters_act_as_point_lights(state, emitter):
    samples = state.transfers[0].samples
    centre = np.array([0, 0, 8.0])
    to_light = centre - samples.positions
    if isinstance(emitter, RectangularAreaLight):
        emitter_cosine = np.clip(to_light[:, 2] / np.linalg.norm(to_light, axis=1), 0, None)
        power = emitter.area * emitter_cosine
    else:
        power = np.pi * emitter.radius**2
    area = prt.sample_irradiance(state.scene, samples, [emitter], 1.3)[:, 0]
    point = prt.sample_irradiance(state.scene, samples, [PointLight(centre, 1.0)], 1.3)[:, 0]
    assert np.abs(area - point * power).max() < AREA_LIGHT_TOLERANCE * (point * power).max()


def test_constant_environment_on_a_convex_object(state):
    scene = sphere_scene(lights=[ConstantEnvironment(1.0)])
    environment_state = prt.precompute(scene, samples=1024, **QUICK_GEOMETRY_KNOBS)
    transfer = environment_state.transfers[0]
    irradiance = environment_state.irradiance(transfer, scene.lights, 1.3)[:, 0]
    mu = np.linspace(0, 1, 20001)
    exact = 2 * np.pi * np.trapezoid(fresnel_transmittance(1.3, mu) * mu, mu)
    assert np.abs(irradiance / exact - 1).max() < ENVIRONMENT_SAMPLE_TOLERANCE
    assert irradiance.mean() == pytest.approx(exact, rel=ENVIRONMENT_MEAN_TOLERANCE)
    assert "environment visibility" in environment_state.log.seconds
    # a scene without an environment light never builds it
    state.render(lights=[LIGHT])
    assert "no environment visibility" in state.log.notes["environment"]


def test_fresnel_factors_reproduce_the_hemispherical_integral():
    mu, factors, weights, error = prt.fresnel_cosine_factors()
    assert factors.shape == (prt.FRESNEL_RANK, mu.size)
    for eta in (1.0, 1.3, 2.5):
        exact = np.trapezoid(fresnel_transmittance(eta, mu) * mu, mu)
        approximate = np.trapezoid(weights(eta) @ factors, mu)
        assert approximate == pytest.approx(exact, rel=1e-3)
    assert error < 5e-3


def test_precomputation_is_cached_by_geometry_and_knobs(state):
    relit = sphere_scene(material=measured_medium("Skin1"),
                         lights=[DirectionalLight([0, -1, 0], 1.0)])
    again = prt.precompute(relit, samples=SAMPLES, **QUICK_GEOMETRY_KNOBS)
    assert again.log.notes["cache"]["sphere"] == "hit"
    other_knobs = prt.precompute(relit, samples=1024, seed=7, **QUICK_GEOMETRY_KNOBS)
    assert other_knobs.log.notes["cache"]["sphere"] == "miss"


@pytest.mark.slow  # 16 s; `bench prt --quick` (fast tier) compresses a geometry image too
def test_spatial_compression_on_a_geometry_image():
    mesh = geometry_image(17)
    scene = sphere_scene(material=measured_medium("Skin1"), mesh=mesh)
    automatic = prt.precompute(scene, samples=1024)
    assert automatic.transfers[0].spatial_shape is None
    assert "289 vertices <= 20000" in " ".join(automatic.log.skipped)
    spatial = prt.precompute(scene, samples=1024, spatial="on")
    transfer = spatial.transfers[0]
    assert transfer.spatial_shape == (17, 17)
    assert "CDF 9/7" in spatial.log.notes["spatial"]["sphere"]
    material = measured_medium("Skin1")
    error = relative_error(eq1_vertex_radiance(spatial, material),
                           brute_force(spatial, material))
    assert error < SPATIAL_TARGET
    image = spatial.render(material=material)
    assert np.isfinite(image.rgb).all() and image.rgb.max() > 0
    assert spatial.transfers[0].statistics["layout"] == "rows"  # no shared columns here
    # the first frame after relighting inverts the combined channels; later edits re-weight
    # the inverse-transformed basis vectors (the transform is linear): the same radiance
    lights = (PointLight([-3.0, 2.0, 4.0], 80.0),)
    for name in ("Marble", "Ketchup"):
        edited = measured_medium(name)
        spatial.relight(transfer, lights, edited.eta)
        first = spatial.vertex_radiance(transfer, edited)
        assert transfer.name not in spatial._vertex_vectors
        again = spatial.vertex_radiance(transfer, edited)
        assert spatial._vertex_vectors[transfer.name].shape == (3, 13, 289)
        assert np.abs(again - first).max() <= ROUND_OFF_32 * np.abs(first).max()


def test_approx_command_writes_an_exr(tmp_path, capsys):
    out = tmp_path / "prt.exr"
    code = main(["approx", "prt", "sphere", "--samples", "1024", "--no-progress",
                 "--geometry-cells", "1000", "--geometry-clusters", "48",
                 "--geometry-walks", "2048", "--material", "Skin1", "--out", str(out)])
    assert code == 0 and out.is_file()
    image = Image.read(out)
    assert image.metadata["producer"] == "prt" and image.rgb.max() > 0
    code = main(["approx", "prt", "sphere", "--samples", "1024", "--no-progress",
                 "--geometry", "half_space",
                 "--sigma-a", "0.01", "0.02", "0.03", "--sigma-s-prime", "1", "1", "1",
                 "--eta", "1.4", "--out", str(out)])
    assert code == 0


def test_approx_command_rejects_half_a_material(tmp_path, capsys):
    code = main(["approx", "prt", "sphere", "--samples", "1024", "--sigma-a", "0.1", "0.1",
                 "0.1", "--out", str(tmp_path / "x.exr")])
    assert code == 2
    assert "--sigma-s-prime" in capsys.readouterr().err
    code = main(["approx", "prt", "sphere", "--material", "Jelly", "--out",
                 str(tmp_path / "x.exr")])
    assert code == 2


def test_approx_command_says_what_it_skipped(tmp_path, capsys):
    code = main(["approx", "prt", "sphere", "--samples", "1024", "--no-progress", "--spatial",
                 "on", "--geometry", "half_space", "--out", str(tmp_path / "x.exr")])
    assert code == 0
    assert "skipped: object 'sphere': no spatial compression" in capsys.readouterr().out


def test_approx_command_refuses_a_material_with_a_coefficient_it_would_ignore(tmp_path,
                                                                              capsys):
    code = main(["approx", "prt", "sphere", "--samples", "1024", "--material", "Marble",
                 "--sigma-s-prime", "9", "9", "9", "--out", str(tmp_path / "x.exr")])
    assert code == 2
    assert "--sigma-s-prime" in capsys.readouterr().err
    assert not (tmp_path / "x.exr").exists()


@pytest.mark.parametrize("knobs, message", [
    ({"samples": 1000}, "samples.*parts x 4\\^n"),
    ({"parts": 0}, "parts.*integer"),
    ({"energy": 0.0}, "energy"),
    ({"basis": "fourier"}, "basis.*must be one of 'paper', 'area_normalised'"),
    ({"spatial": "yes"}, "spatial.*must be one of 'auto', 'on', 'off'"),
    ({"selection": "random"}, "selection"),
    ({"layout": "columns"}, "layout.*must be one of 'shared', 'rows'"),
    ({"environment_resolution": 12}, "power of two"),
    ({"sampling_blend": "yes"}, "sampling_blend.*must be true or false"),
    ({"colour": "red"}, "unknown knob"),
])
def test_bad_knobs_are_rejected(knobs, message):
    with pytest.raises(InputError, match=message):
        prt.precompute(sphere_scene(), **knobs)


def test_scenes_it_cannot_render():
    opaque = sphere_scene(material=Lambertian(0.5))
    refusal = prt.applies_to(opaque)
    assert refusal.code == "no_translucent_object"
    assert "no homogeneous translucent object" in str(refusal)
    with pytest.raises(InputError, match="prt method cannot render"):
        prt.precompute(opaque)
    dark = prt.applies_to(sphere_scene(lights=()))
    assert dark.code == "no_light" and "no light" in str(dark)


def test_other_objects_in_view_are_left_black_named_and_not_scored():
    for name in ("bowl", "cornell_block"):
        scene = load_scene(name)
        assert prt.applies_to(scene) is None
        assert prt.scored_objects(scene) == [o.name for o in scene.objects
                                             if o.material.__class__.__name__ == "Dipole"]
    # a diffuse ball beside the translucent sphere, in view
    ball = SceneObject("ball", icosphere(2, radius=0.4, center=(1.2, 0.0, 0.0)),
                       Lambertian(0.5))
    plain = sphere_scene()
    scene = Scene(list(plain.objects) + [ball], list(plain.lights), plain.camera,
                  mm_per_unit=MM_PER_UNIT)
    assert prt.scored_objects(scene) == ["sphere"]
    image = prt.precompute(scene, samples=SAMPLES, **QUICK_GEOMETRY_KNOBS).render()
    from translucent.scenes import gbuffer

    seen = gbuffer(scene).object_id
    assert (seen == 1).any() and (seen == 0).any()
    assert np.all(image.rgb[seen == 1] == 0)  # the ball: black
    assert image.rgb[seen == 0].sum() > 0
    assert any("objects left black" in s and "'ball' (Lambertian)" in s
               for s in image.metadata["skipped"]), image.metadata["skipped"]


def test_bad_materials_are_rejected(state):
    with pytest.raises(InputError, match="Dipole"):
        state.render(material=Lambertian(0.5))
    with pytest.raises(InputError, match="sigma_a"):
        Dipole(-1.0, 1.0, 1.3)



def _inside_grid(basis, sigma_a, sigma_s_prime):
    s_range, a_range = basis.sampling.sigma_s_prime_range, basis.sampling.sigma_a_range
    return (s_range[0] <= sigma_s_prime <= s_range[1]) and (a_range[0] <= sigma_a <= a_range[1])


@pytest.mark.parametrize("basis_name", list(PARAMETERISATIONS))
def test_measured_media_inside_the_grid_are_trusted(basis_name):
    """beta = 0 for every measured channel a basis's grid covers: the paper's method unchanged."""
    basis = dipole_pca_basis(basis_name)
    covered = 0
    for name, (sigma_s_prime, sigma_a, eta) in MEASURED_MEDIA.items():
        for a, s in zip(np.broadcast_to(sigma_a, 3), np.broadcast_to(sigma_s_prime, 3),
                        strict=True):
            if _inside_grid(basis, a, s):
                covered += 1
                _, blend = prt.projection_blend(basis, a, s, eta)
                assert blend == 0, f"{name}: beta {blend} at sigma_a {a}, sigma_s' {s}"
    assert covered >= 30  # all but Spectralon (and Cream on the paper's [0, 5] grid)


@pytest.mark.parametrize("basis_name", list(PARAMETERISATIONS))
def test_trusted_projections_hold_the_profile_energy(basis_name):
    """Wherever beta = 0, residual and energy error are within the blend thresholds."""
    basis = dipole_pca_basis(basis_name)
    sigma_a, sigma_s_prime, eta = (grid.ravel() for grid in np.meshgrid(
        SWEPT_SIGMAS, SWEPT_SIGMAS, np.array([1.0, 1.3, 2.5]), indexing="ij"))
    _, blend = prt.projection_blend(basis, sigma_a, sigma_s_prime, eta)
    _, residual, energy, exact = basis.project_with_energy(sigma_a, sigma_s_prime, eta)
    trusted = blend == 0
    assert trusted.any() and not trusted.all()
    assert residual[trusted].max() <= prt.LOCAL_BLEND_START
    error = np.abs(energy - exact) / np.where(exact > 0, exact, 1.0)
    assert error[trusted].max() <= prt.ENERGY_BLEND_START
    assert np.all((blend >= 0) & (blend <= 1))


def test_small_residuals_with_the_wrong_energy_are_blended():
    # the cases the residual alone trusted: a profile narrower than the paper's 0.1 mm
    # spacing (residual 7.5e-5, K-term energy -204 against 0.073), and the default basis
    # beyond its sigma_a range (residual 0.009, energy 0.098 against 0.073)
    paper = dipole_pca_basis("paper")
    _, residual = paper.project_with_residual(1e3, 1e3, 2.5)
    assert residual < prt.LOCAL_BLEND_START
    assert prt.projection_blend(paper, 1e3, 1e3, 2.5)[1] == 1
    improved = dipole_pca_basis("area_normalised")
    _, residual, energy, exact = improved.project_with_energy(10.0, 10.0, 2.5)
    assert residual < prt.LOCAL_BLEND_START
    expected = np.clip((abs(energy / exact - 1) - prt.ENERGY_BLEND_START)
                       / (prt.ENERGY_BLEND_END - prt.ENERGY_BLEND_START), 0, 1)
    assert 0 < expected
    assert prt.projection_blend(improved, 10.0, 10.0, 2.5)[1] == pytest.approx(expected)


def test_profiles_narrower_than_the_sample_spacing_are_blended():
    """log2 ramp from one mean free path per spacing (0.1 mm) to a quarter of it."""
    paper = dipole_pca_basis("paper")
    spacing = paper.radii[1] - paper.radii[0]
    # sigma_a = 0 keeps the energy right (Spectralon-like): the sampling decides
    sigma_s_prime = np.array([0.5, 1.0, 2.0, 4.0, 8.0]) / spacing
    _, blend = prt.projection_blend(paper, np.zeros(5), sigma_s_prime, 1.3)
    np.testing.assert_allclose(blend, [0.0, 0.0, 0.5, 1.0, 1.0], atol=ROUND_OFF_32)


@pytest.mark.parametrize("eta", [None, 1.0])
def test_sampling_blend_keeps_in_grid_media_at_the_default_density(eta):
    """At 16384 samples on the 10 mm sphere only Spectralon's narrow profile is blended."""
    basis = dipole_pca_basis(prt.DEFAULT_KNOBS["basis"])
    for name, (sigma_s_prime, sigma_a, own_eta) in MEASURED_MEDIA.items():
        sigma_a = np.broadcast_to(sigma_a, 3)
        _, blend = prt.projection_blend(basis, sigma_a, sigma_s_prime,
                                        own_eta if eta is None else eta, DEFAULT_SAMPLE_SPACING)
        if name == "Spectralon":
            assert blend.max() > 0.5  # 56-72 % of its energy within one spacing at eta = 1
        else:
            assert np.all(blend == 0), f"{name}: beta {blend}"


def test_sampling_blend_renders_unresolved_profiles_locally(state):
    """Spectralon at 4096 samples (h = 0.55 mm): almost all local, R_d times the local vector."""
    spectralon = measured_medium("Spectralon")
    spacing = float(np.sqrt(state.transfers[0].samples.area))
    _, blend = prt.projection_blend(state.basis, spectralon.sigma_a,
                                    spectralon.sigma_s_prime, spectralon.eta, spacing)
    weights = state.coefficients(spectralon, spacing)
    albedo = total_diffuse_reflectance(spectralon.sigma_a, spectralon.sigma_s_prime,
                                       spectralon.eta)
    np.testing.assert_allclose(weights[:, -1], blend * albedo, rtol=ROUND_OFF_32)
    assert blend.min() > 0.9
    # off, the projection alone decides: Eq. 5-7 as the paper sums them
    np.testing.assert_array_equal(state.coefficients(spectralon)[:, -1], 0.0)
