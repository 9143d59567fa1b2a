import numpy as np
import pytest
from scipy import sparse
from translucent.errors import InputError
from translucent.fast import radiosity
from translucent.fast.radiosity import (
    COMPONENTS,
    ConvergenceError,
    ScatteringMatrix,
    applies_to,
    direct_irradiance,
    precompute,
    scattering_geometry,
    scattering_matrix,
    solve_radiosity,
)
from translucent.fast.radiosity import method as radiosity_method
from translucent.fast.radiosity.form_factors import build_patches, sphere_form_factors
from translucent.materials import Lambertian, measured_medium
from translucent.materials.profiles import (
    DipoleProfile,
    MixedProfiles,
    RadialProfile,
    TabulatedProfile,
    TwoExponentialProfile,
)
from translucent.scenes import (
    Camera,
    ConstantEnvironment,
    DirectionalLight,
    Mesh,
    PointLight,
    RectangularAreaLight,
    Scene,
    SceneObject,
    SphereAreaLight,
    SpotLight,
    box,
    icosphere,
    plane,
)

#: Solves to machine precision use this relative residual; float64 sparse products then
#: agree with closed forms to 1e-9.
TIGHT = 1e-12

#: The same float64 products evaluated twice in a different summation order: round-off,
#: amplified by at most 1 / tolerance where a residual is a small difference.
RECOMPUTED_RTOL = 1e-9

#: Relative resolution of the float32 images (two float64 images of the same frame, solved
#: twice to the same B up to round-off, agree to it after rounding).
FLOAT32_EPS = float(np.finfo(np.float32).eps)

#: B through T against a tight iterative solve, relative to B's largest entry: T and the
#: product are float32 (6e-8 relative per entry and per addition); 1e-5 leaves margin.
TRANSFER_RTOL = 1e-5

#: Mixing two identical exponential materials with Eq. 16 is exact for the functions; the
#: tables interpolate linearly on a 2048-node quadratic grid: 1e-6 relative measured.
MIXING_RTOL = 1e-5

#: Area lights and environments are integrated with stratified samples; these tests put
#: them where the integrand is smooth, 64 samples reach 1e-3.
LIGHT_RTOL = 2e-3

#: 4 against 16 stratified samples of a 0.6 x 0.6 light 2 units above a 4 x 4 floor: the
#: floor's total irradiance differs by the quadrature error of the coarser set, 0.07 %
#: measured; 2 % leaves room for other seeds.
DIFFUSE_SAMPLES_RTOL = 0.02

CAMERA = Camera([0.0, 1.0, 4.0], [0.0, 0.5, 0.0], width=16, height=16)


def _inside_sphere(albedo, subdivisions=2):
    outside = icosphere(subdivisions, 1.0)
    inside = Mesh(outside.vertices, outside.faces[:, ::-1], -outside.normals, name="inside")
    return Scene([SceneObject("sphere", inside, Lambertian(albedo))], [], CAMERA)


def _diagonal(values):
    values = np.asarray(values, dtype=np.float64)
    count = len(values)
    return ScatteringMatrix(np.arange(count + 1), np.arange(count), values)


def _block_scene(material=None, lights=None):
    floor = plane(4.0, 4.0, subdivisions=4, name="floor")
    block = box((1.0, 1.0, 1.0), (0.0, 0.5, 0.0), subdivisions=2, name="block")
    material = measured_medium("Skin1") if material is None else material
    lights = (PointLight([1.0, 3.0, 1.0], 20.0),) if lights is None else lights
    return Scene([SceneObject("floor", floor, Lambertian([0.7, 0.5, 0.3])),
                  SceneObject("block", block, material)], lights, CAMERA, mm_per_unit=10.0)


_STATES: dict = {}


def _block_state(**knobs):
    """One precomputation of the block scene per knob set (the tests only read it)."""
    key = tuple(sorted(knobs.items()))
    if key not in _STATES:
        _STATES[key] = precompute(_block_scene(), rays_per_patch=64, **knobs)
    return _STATES[key]


# ---------------------------------------------------------------------------------------
# the closed sphere: classical radiosity (S = P) against its closed form


@pytest.mark.parametrize("solver", radiosity.SOLVERS)
def test_closed_sphere_uniform_emission_gives_e_over_one_minus_rho(solver):
    scene = _inside_sphere(0.6)
    patches = build_patches(scene)
    F = sparse.csr_matrix(sphere_form_factors(patches.area))
    albedo = np.array([0.2, 0.6, 0.9])
    emission = np.ones((len(patches), 3))
    B, info = solve_radiosity(_diagonal(np.tile(albedo, (len(patches), 1))), F, emission,
                              solver=solver, tolerance=TIGHT)
    assert B == pytest.approx(emission / (1.0 - albedo), rel=1e-9)
    assert info["iterations"] >= 1


@pytest.mark.parametrize("solver", radiosity.SOLVERS)
def test_closed_sphere_any_emission_matches_the_closed_form(solver, rng):
    # F_ij = A_j / A for every i: B = L + rho / (1 - rho) <L>_A
    scene = _inside_sphere(0.5, subdivisions=2)
    patches = build_patches(scene)
    F = sparse.csr_matrix(sphere_form_factors(patches.area))
    rho = 0.7
    emission = rng.random((len(patches), 3))
    B, _ = solve_radiosity(_diagonal(np.full((len(patches), 3), rho)), F, emission,
                           solver=solver, tolerance=TIGHT)
    mean = patches.area @ emission / patches.area.sum()
    assert B == pytest.approx(emission + rho / (1 - rho) * mean, rel=1e-9)


def test_precomputed_sphere_with_ray_cast_form_factors_reaches_the_tolerance():
    rho = 0.8
    state = precompute(_inside_sphere(rho), rays_per_patch=64)
    irradiance = np.ones((len(state.patches), 3))
    B, info = state.solve(irradiance)
    # every ray inside a closed sphere hits: row sums are 1 and the uniform solution is
    # exact; the Jacobi stop leaves an error below the tolerance
    expected = rho / (1 - rho)
    assert np.all(np.abs(B / expected - 1) <= state.knobs["tolerance"])
    assert max(info["residual"]) <= state.knobs["tolerance"]
    assert 1 <= info["iterations"] <= 40


def test_near_the_limit_jacobi_needs_many_iterations_and_krylov_few():
    scene = _inside_sphere(0.99, subdivisions=1)
    patches = build_patches(scene)
    F = sparse.csr_matrix(sphere_form_factors(patches.area))
    S = _diagonal(np.full((len(patches), 3), 0.99))
    emission = np.ones((len(patches), 3))
    B, info = solve_radiosity(S, F, emission, solver="jacobi", tolerance=5e-3)
    # the Jacobi residual falls as rho^k: log(0.005) / log(0.99) = 527 steps
    assert 520 <= info["iterations"] <= 535
    assert B == pytest.approx(100.0 * emission, rel=5e-3)
    B, info = solve_radiosity(S, F, emission, solver="gmres", tolerance=5e-3)
    assert info["iterations"] <= 5
    assert B == pytest.approx(100.0 * emission, rel=5e-3)


def test_iteration_that_cannot_converge_raises_with_the_residual():
    scene = _inside_sphere(0.99, subdivisions=1)
    patches = build_patches(scene)
    F = sparse.csr_matrix(sphere_form_factors(patches.area))
    S = _diagonal(np.full((len(patches), 3), 0.99))
    with pytest.raises(ConvergenceError, match="after 50 iterations.*close to 1") as error:
        solve_radiosity(S, F, np.ones((len(patches), 3)), max_iterations=50)
    assert error.value.residual > 5e-3
    assert error.value.iterations == 50


def test_divergent_iteration_is_stopped_not_returned():
    scene = _inside_sphere(0.5, subdivisions=1)
    patches = build_patches(scene)
    F = sparse.csr_matrix(sphere_form_factors(patches.area))
    S = _diagonal(np.full((len(patches), 3), 1.5))  # unphysical: spectral radius 1.5
    with pytest.raises(ConvergenceError, match="diverges"):
        solve_radiosity(S, F, np.ones((len(patches), 3)))


def test_compiled_form_factor_product_matches_scipy(rng):
    from translucent.fast.radiosity import COMPILED_PRODUCT_ENTRIES, form_factor_product

    size = 2000
    entries = 2 * COMPILED_PRODUCT_ENTRIES
    F = sparse.csr_matrix((rng.random(entries).astype(np.float32),
                           (rng.integers(0, size, entries), rng.integers(0, size, entries))),
                          shape=(size, size))
    B = rng.random((size, 3))
    assert F.nnz >= COMPILED_PRODUCT_ENTRIES
    assert form_factor_product(F, B) == pytest.approx(F.astype(np.float64) @ B, rel=1e-12)


def test_compiled_scattering_product_matches_scipy(rng):
    from translucent.fast.radiosity import COMPILED_PRODUCT_ENTRIES

    size = 2000
    entries = 2 * COMPILED_PRODUCT_ENTRIES
    pattern = sparse.csr_matrix((np.ones(entries), (rng.integers(0, size, entries),
                                                   rng.integers(0, size, entries))),
                                shape=(size, size))
    S = ScatteringMatrix(pattern.indptr, pattern.indices, rng.random((pattern.nnz, 3)))
    B = rng.random((size, 3))
    assert len(S.indices) >= COMPILED_PRODUCT_ENTRIES
    expected = np.stack([S.channel(c) @ B[:, c] for c in range(3)], axis=1)
    assert S.dot(B) == pytest.approx(expected, rel=1e-12)


def test_jacobi_returns_the_exact_residual_and_form_factor_product_of_its_answer():
    """The check of the returned B is its own residual; F B comes with it for the image."""
    patches = build_patches(_inside_sphere(0.5))
    F = sparse.csr_matrix(sphere_form_factors(patches.area))
    S = _diagonal(np.tile([0.8, 0.5, 0.2], (len(patches), 1)))
    emission = np.outer(np.linspace(1.0, 2.0, len(patches)), [1.0, 1.0, 1.0])
    B, info = solve_radiosity(S, F, emission, solver="jacobi", tolerance=5e-3)
    residual = emission - B + S.dot(F @ B)
    expected = np.linalg.norm(residual, axis=0) / np.linalg.norm(emission, axis=0)
    assert info["residual"] == pytest.approx(expected, rel=RECOMPUTED_RTOL)
    assert max(info["residual"]) <= 5e-3
    assert info["global_irradiance"] == pytest.approx(F @ B, rel=RECOMPUTED_RTOL)


# ---------------------------------------------------------------------------------------
# the scattering factors


def test_polar_self_term_integrates_a_constant_profile_to_the_patch_area():
    scene = Scene([SceneObject("sheet", plane(4.0, 4.0, subdivisions=3),
                               TabulatedProfile([0.0, 100.0], [1.0, 1.0]))], [], CAMERA,
                  mm_per_unit=10.0)
    patches = build_patches(scene)
    geometry = scattering_geometry(scene, patches, [0], max_distance_mm=60.0,
                                   knobs=dict(radiosity.DEFAULT_KNOBS))
    S = scattering_matrix(geometry, scene, patches)
    assert S.channel(0).diagonal() == pytest.approx(patches.area * 100.0, rel=1e-10)


def test_translucency_change_only_reindexes_the_profiles():
    state = _block_state()
    fresh = precompute(_block_scene(measured_medium("Marble")), rays_per_patch=64,
                       max_distance_mm=state.knobs["max_distance_mm"])
    seconds = state.set_material(measured_medium("Marble"))
    assert seconds >= 0
    assert np.array_equal(state.S.indices, fresh.S.indices)
    assert np.allclose(state.S.data, fresh.S.data, rtol=1e-12, atol=0)
    state.set_material(measured_medium("Skin1"))


def test_a_material_that_breaks_energy_conservation_is_refused():
    # total reflectance 2 pi (0.05 + 0.2) = 1.57 > 1
    bright = TwoExponentialProfile(0.05, 1.0, 0.2, 1.0, name="too bright")
    with pytest.raises(InputError, match="convergence condition of Eq. 15.*'block'.*must be < 1"):
        precompute(_block_scene(bright), rays_per_patch=16, max_distance_mm=20.0)


def test_without_inter_reflection_an_energy_excess_is_rendered_and_reported():
    # Eq. 15 guards the series of Eq. 14; a lone convex block has none (B = SE), so the
    # profile's own excess is the model's and is rendered as it is, flagged in the report
    bright = TwoExponentialProfile(0.05, 1.0, 0.2, 1.0, name="too bright")
    block = box((1.0, 1.0, 1.0), subdivisions=2, name="block")
    scene = Scene([SceneObject("block", block, bright)], (PointLight([1.0, 3.0, 1.0], 20.0),),
                  CAMERA, mm_per_unit=10.0)
    state = precompute(scene, rays_per_patch=16, max_distance_mm=20.0)
    assert state.form_factors is None
    assert state.convergence["energy_conserving"] is False
    assert state.convergence["inter_reflects"] is False
    assert state.convergence["max_scattering_column_sum"] > 1.2
    assert any("energy condition of Eq. 15" in sentence for sentence in state.log.skipped)
    irradiance = state.patch_irradiance()
    B, info = state.solve(irradiance)
    assert info["iterations"] == 0 and np.isfinite(B).all()
    assert np.array_equal(B, state.S.dot(irradiance))


def test_nan_or_negative_profiles_are_refused():
    class Negative(RadialProfile):
        name = "negative"

        def reflection(self, r):
            return np.full(np.shape(r) + (3,), -1e-3)

        def cache_key(self):
            return {"type": "negative"}

    with pytest.raises(InputError, match="profile 'negative' values must be >= 0"):
        precompute(_block_scene(Negative()), rays_per_patch=16, max_distance_mm=20.0)


def test_identical_materials_mix_into_the_homogeneous_one():
    profile = TwoExponentialProfile(0.01, 0.4)
    homogeneous = precompute(_block_scene(profile), rays_per_patch=16, max_distance_mm=40.0)
    faces = len(_block_scene().object("block").mesh.faces)
    labels = np.arange(faces) % 2  # a checkerboard of two identical materials
    mixed = precompute(_block_scene(MixedProfiles([profile, profile], labels)),
                       rays_per_patch=16, max_distance_mm=40.0)
    assert np.allclose(mixed.S.data, homogeneous.S.data, rtol=MIXING_RTOL, atol=1e-12)


def test_checkerboard_of_two_materials_lies_between_them():
    faint, strong = TwoExponentialProfile(0.005, 0.5), TwoExponentialProfile(0.02, 0.5)
    faces = len(_block_scene().object("block").mesh.faces)
    mixed = precompute(_block_scene(MixedProfiles([faint, strong], np.arange(faces) % 2)),
                       rays_per_patch=16, max_distance_mm=40.0)
    low = precompute(_block_scene(faint), rays_per_patch=16, max_distance_mm=40.0)
    high = precompute(_block_scene(strong), rays_per_patch=16, max_distance_mm=40.0)
    assert np.all(mixed.S.data >= low.S.data * (1 - MIXING_RTOL))
    assert np.all(mixed.S.data <= high.S.data * (1 + MIXING_RTOL))
    assert np.any(mixed.S.data > low.S.data * 1.5)


# ---------------------------------------------------------------------------------------
# solving on a translucent scene


def test_radiosity_is_linear_in_the_irradiance(rng):
    state = _block_state()
    first, second = rng.random((2, len(state.patches), 3))
    solve = {"solver": "gmres", "tolerance": TIGHT}
    B1, _ = solve_radiosity(state.S, state.form_factors, state.S.dot(first), **solve)
    B2, _ = solve_radiosity(state.S, state.form_factors, state.S.dot(second), **solve)
    B, _ = solve_radiosity(state.S, state.form_factors, state.S.dot(2 * first + 3 * second),
                           **solve)
    assert B == pytest.approx(2 * B1 + 3 * B2, rel=1e-9)


def test_precomputed_transfer_matches_the_iterative_solution():
    state = _block_state()
    irradiance = state.patch_irradiance()
    reference, _ = solve_radiosity(state.S, state.form_factors, state.S.dot(irradiance),
                                   solver="gmres", tolerance=TIGHT)
    assert state.transfer_fits()
    assert state.precompute_transfer() > 0
    B, info = state.solve(irradiance)
    assert info["solver"] == "transfer"
    assert B == pytest.approx(reference, rel=TRANSFER_RTOL, abs=TRANSFER_RTOL * reference.max())
    state.set_material(measured_medium("Skin1"))
    assert state.transfer is None  # a new material invalidates T


#: Power column sums of S against their target (profile total x gain): the two branches
#: of the correction (light added, or the column scaled down) both land on it exactly, so
#: only round-off remains.
GAIN_TARGET_RTOL = 1e-9


def test_finite_object_energy_brings_columns_to_the_diffusion_gain():
    from translucent.fast.radiosity.diffusion_escape import (
        finite_object_gain,
        source_escape_probability,
    )

    state, plain = _block_state(), _block_state(finite_object_energy=False)
    patches = state.patches
    members = patches.of_object(1)
    material = state.scene.objects[1].material
    gain = finite_object_gain(state.geometry.objects[1].diffusion,
                              patches.centroid[members] * patches.mm_per_unit,
                              patches.normal[members], material.sigma_a,
                              material.sigma_s_prime, material.eta)
    # a 10 mm Skin1 cube: 1/sigma_tr is 3.7 mm in red, the cube re-emits more
    assert np.all(gain > 1.0)
    profile = DipoleProfile(material)
    ceiling = profile.entry * source_escape_probability(material.sigma_a,
                                                        material.sigma_s_prime, material.eta)
    target = np.minimum(profile.total(), ceiling)[None, :] * gain
    sums = state.S.power_column_sums(patches.area)[members]
    assert sums == pytest.approx(target, rel=GAIN_TARGET_RTOL)
    assert np.all(sums > plain.S.power_column_sums(patches.area)[members])
    assert np.all(state.S.data >= 0.0)
    # the floor's diagonal S = P is untouched
    floor = patches.of_object(0)
    diagonal = state.geometry.diagonal_position[floor]
    assert np.array_equal(state.S.data[diagonal], plain.S.data[diagonal])


def test_added_light_leaves_away_from_the_entry_face():
    state, plain = _block_state(), _block_state(finite_object_energy=False)
    patches = state.patches
    members = patches.of_object(1)
    top = members[patches.normal[members, 1] > 0.99]
    entry = top[np.argmin(np.linalg.norm(patches.centroid[top] - [0.0, 1.0, 0.0], axis=1))]
    added = (state.S.channel(0)[:, [entry]] - plain.S.channel(0)[:, [entry]]).toarray().ravel()
    power = added * patches.area
    # the half-space already has the entry face: its fluence there is ~0
    assert power[top].sum() < 0.2 * power[members].sum()


def test_finite_object_energy_leaves_a_large_object_alone():
    from translucent.materials import Dipole

    # 1/sigma_tr = 0.17 mm in a 10 mm cube: the gain is 1 to within the cube's edges
    dense = Dipole([1.0, 1.0, 1.0], [10.0, 10.0, 10.0], 1.0, name="dense")
    state = precompute(_block_scene(dense), rays_per_patch=16)
    members = state.patches.of_object(1)
    sums = state.S.power_column_sums(state.patches.area)[members]
    assert sums == pytest.approx(np.broadcast_to(DipoleProfile(dense).total(), sums.shape),
                                 rel=0.01)


def test_finite_object_energy_never_exceeds_the_escape_probability():
    from translucent.fast.radiosity.diffusion_escape import (
        finite_object_gain,
        source_escape_probability,
    )
    from translucent.materials import Dipole

    # eta 1.5 and reduced albedo 0.7, where the dipole's total exceeds the half-space's
    # escape probability from the source depth (1.24x): a 4 mm cube lets out almost all of
    # the light diffusion carries, so R_d x gain would create energy
    medium = Dipole([3.0 / 7.0] * 3, [1.0] * 3, 1.5, name="reflective boundary")
    scene = _block_scene(medium)
    scene = Scene(scene.objects, scene.lights, CAMERA, mm_per_unit=4.0)
    state = precompute(scene, rays_per_patch=16)
    patches = state.patches
    members = patches.of_object(1)
    profile = DipoleProfile(medium)
    gain = finite_object_gain(state.geometry.objects[1].diffusion,
                              patches.centroid[members] * patches.mm_per_unit,
                              patches.normal[members], medium.sigma_a, medium.sigma_s_prime,
                              medium.eta)
    ceiling = profile.entry * source_escape_probability(medium.sigma_a, medium.sigma_s_prime,
                                                        medium.eta)
    assert np.any(profile.total() * gain > ceiling * gain)  # the ceiling is what binds
    sums = state.S.power_column_sums(patches.area)[members]
    assert np.all(sums <= profile.entry * 1.0)
    assert sums == pytest.approx(ceiling[None, :] * gain, rel=GAIN_TARGET_RTOL)


def test_a_channel_without_absorption_keeps_the_dipoles_columns():
    from translucent.materials import Dipole

    # no diffusion length in red: the dipole returns all of it already
    medium = Dipole([0.0, 0.01, 0.1], [1.0, 1.0, 1.0], 1.3, name="clear in red")
    on = precompute(_block_scene(medium), rays_per_patch=16)
    off = precompute(_block_scene(medium), rays_per_patch=16, finite_object_energy=False)
    assert np.array_equal(on.S.data[:, 0], off.S.data[:, 0])
    assert np.all(on.S.data[:, 1:].sum(axis=0) > off.S.data[:, 1:].sum(axis=0))


def test_finite_object_knobs_are_checked():
    with pytest.raises(InputError, match="finite_object_energy"):
        precompute(_block_scene(), finite_object_energy="yes")
    with pytest.raises(InputError, match="diffusion_voxels_per_axis"):
        precompute(_block_scene(), diffusion_voxels_per_axis=2)


def test_convergence_report_names_the_worst_patch():
    # the semi-infinite dipole (the 10 mm Skin1 cube's finite-object gain lifts its red
    # column sums to 0.70, level with the floor)
    state = _block_state(finite_object_energy=False)
    report = state.convergence
    sums = state.S.power_column_sums(state.patches.area)
    assert report["max_scattering_column_sum"] == pytest.approx(sums.max())
    assert report["object"] == "floor"  # albedo 0.7 beats Skin1's 0.4 total reflectance
    assert sums[state.patches.of_object(1)].max() < 0.5
    assert 0 < report["max_scattering_column_sum"] < 1
    assert report["max_form_factor_row_sum"] <= 1.0 + 1e-6
    assert report["channel"] in "RGB"


def test_single_convex_object_skips_form_factors_and_returns_se():
    block = box((1.0, 1.0, 1.0), subdivisions=2)
    scene = Scene([SceneObject("block", block, measured_medium("Skin1"))],
                  (PointLight([1.0, 3.0, 1.0], 20.0),), CAMERA, mm_per_unit=10.0)
    state = precompute(scene)
    assert state.form_factors is None
    assert any("no form factors" in sentence for sentence in state.log.skipped)
    assert any("no voxel grid" in sentence for sentence in state.log.skipped)
    irradiance = state.patch_irradiance()
    B, info = state.solve(irradiance)
    assert info["iterations"] == 0
    assert np.array_equal(B, state.S.dot(irradiance))


def test_precompute_is_cached_by_geometry_not_material():
    first = precompute(_block_scene(), rays_per_patch=16, max_distance_mm=21.5)
    assert first.log.notes["cache"] == "miss"
    again = precompute(_block_scene(measured_medium("Marble")), rays_per_patch=16,
                       max_distance_mm=21.5)
    assert again.log.notes["cache"] == "hit"
    assert again.S.data[:, 0].sum() != pytest.approx(first.S.data[:, 0].sum())


def test_a_precomputation_over_the_cache_entry_limit_is_not_kept_and_says_so():
    from translucent.cache import limited_entries, private_cache

    with private_cache():
        with limited_entries(1000):
            first = precompute(_block_scene(), rays_per_patch=16, max_distance_mm=21.5)
        assert first.log.notes["cache"] == "miss"
        assert any("not kept in the cache" in sentence and "TRANSLUCENT_CACHE_MAX_ENTRY_BYTES"
                   in sentence for sentence in first.log.skipped)
        again = precompute(_block_scene(), rays_per_patch=16, max_distance_mm=21.5)
        assert again.log.notes["cache"] == "miss"  # nothing had been written
        assert not any("not kept" in sentence for sentence in again.log.skipped)
        assert precompute(_block_scene(), rays_per_patch=16,
                          max_distance_mm=21.5).log.notes["cache"] == "hit"


def test_bad_knobs_are_reported():
    with pytest.raises(InputError, match="unknown knob.*rays_per_patch"):
        precompute(_block_scene(), rays=3)
    with pytest.raises(InputError, match="solver.*must be one of 'jacobi', 'gmres', 'bicgstab'"):
        precompute(_block_scene(), solver="newton")
    with pytest.raises(InputError, match="transfer.*must be one of 'auto', 'never'"):
        precompute(_block_scene(), transfer="always")
    with pytest.raises(InputError, match="self_term.*must be one of 'polar', 'samples'"):
        precompute(_block_scene(), self_term="exact")
    with pytest.raises(InputError, match="max_distance_mm.*must be > 0 mm"):
        precompute(_block_scene(), max_distance_mm=-1.0)
    with pytest.raises(InputError, match="component.*unknown component"):
        _block_state().solve(np.zeros((len(_block_state().patches), 3)), "all")
    with pytest.raises(InputError, match="diffuse_light_samples.*must be None or an integer "
                                         ">= 1"):
        precompute(_block_scene(), diffuse_light_samples=0)
    with pytest.raises(InputError, match="shadow_ray_engine.*must be one of 'auto', "
                                         "'embree', 'mitsuba'"):
        precompute(_block_scene(), shadow_ray_engine="optix")


def test_fewer_diffuse_light_samples_leave_the_translucent_patches_alone():
    light = [RectangularAreaLight([0.0, 2.0, 0.0], [0.3, 0.0, 0.0], [0.0, 0.0, 0.3], 10.0)]
    state = precompute(_block_scene(lights=light), rays_per_patch=64)
    full = state.patch_irradiance()
    state.knobs["diffuse_light_samples"] = 4
    fewer = state.patch_irradiance()
    block = state.patches.of_object(1)
    floor = state.patches.of_object(0)
    assert np.array_equal(fewer[block], full[block])
    assert not np.array_equal(fewer[floor], full[floor])
    # per patch they differ (up to 9 % of the largest value, at the shadow's edge); summed
    # over the floor, as the form factors sum them, they agree
    assert fewer[floor].sum() == pytest.approx(full[floor].sum(), rel=DIFFUSE_SAMPLES_RTOL)


def test_applies_to_names_what_it_cannot_do():
    assert applies_to(_block_scene()) is None
    classical = applies_to(_inside_sphere(0.5))
    assert classical.code == "no_translucent_object"
    assert "no translucent object" in str(classical)
    scene = _block_scene(material="a glossy paint")
    refusal = applies_to(scene)
    assert refusal.code == "unsupported_material"
    assert "object 'block' has a str material" in str(refusal)


# ---------------------------------------------------------------------------------------
# lights and images


def test_point_spot_and_directional_irradiance_are_exact():
    scene = _block_scene()
    point = np.array([[1.5, 0.0, 1.5]])
    up = np.array([[0.0, 1.0, 0.0]])
    above = np.array([1.5, 2.0, 1.5])
    E = direct_irradiance(scene, point, up, lights=[PointLight(above, [4.0, 8.0, 12.0])])
    assert E[0] == pytest.approx(np.array([4.0, 8.0, 12.0]) / 4.0)
    spot = SpotLight(above, [0.0, -1.0, 0.0], 4.0, cutoff_angle=30.0, beam_width=20.0)
    assert direct_irradiance(scene, point, up, lights=[spot])[0] == pytest.approx([1.0] * 3)
    tilted = SpotLight(above, [np.tan(np.radians(25.0)), -1.0, 0.0], 4.0, cutoff_angle=30.0,
                       beam_width=20.0)
    # 25 degrees off axis: half-way through Mitsuba's linear angular falloff
    assert direct_irradiance(scene, point, up, lights=[tilted])[0] == pytest.approx([0.5] * 3)
    sun = DirectionalLight([0.0, -1.0, -1.0], 3.0)
    assert direct_irradiance(scene, point, up, lights=[sun])[0] == \
        pytest.approx([3.0 / np.sqrt(2)] * 3)


def test_the_block_casts_a_shadow():
    scene = _block_scene()
    behind = np.array([[0.0, 0.0, -1.0]])
    light = PointLight([0.0, 2.0, 2.0], 10.0)
    assert direct_irradiance(scene, behind, [[0.0, 1.0, 0.0]], lights=[light])[0] == \
        pytest.approx([0.0] * 3)


def test_area_and_environment_irradiance_match_closed_forms():
    scene = Scene([SceneObject("floor", plane(4.0, 4.0), Lambertian(0.5))], [], CAMERA)
    point, up = np.array([[0.0, 0.0, 0.0]]), np.array([[0.0, 1.0, 0.0]])
    # a small square 3 units above, facing down: E ~ L A / d^2
    square = RectangularAreaLight([0.0, 3.0, 0.0], [0.01, 0.0, 0.0], [0.0, 0.0, 0.01], 2.0)
    expected = 2.0 * square.area / 9.0
    E = direct_irradiance(scene, point, up, lights=[square], samples=64)
    assert E[0] == pytest.approx([expected] * 3, rel=LIGHT_RTOL)
    # a sphere of radius R at distance d straight up: E = pi L (R / d)^2
    ball = SphereAreaLight([0.0, 3.0, 0.0], 0.5, 2.0)
    E = direct_irradiance(scene, point, up, lights=[ball], samples=64)
    assert E[0] == pytest.approx([np.pi * 2.0 * (0.5 / 3.0) ** 2] * 3, rel=LIGHT_RTOL)
    # an unoccluded hemisphere of constant radiance: E = pi L
    E = direct_irradiance(scene, point, up, lights=[ConstantEnvironment(0.5)], samples=64)
    assert E[0] == pytest.approx([np.pi * 0.5] * 3, rel=1e-9)


def _area_lit_block_scene():
    light = RectangularAreaLight([0.3, 2.0, 0.2], [0.4, 0.0, 0.0], [0.0, 0.0, 0.4], 10.0)
    return _block_scene(lights=[light, RectangularAreaLight([-1.0, 1.5, 1.0], [0.2, 0.0, 0.0],
                                                            [0.0, -0.1, 0.2], 4.0)])


@pytest.mark.parametrize("samples", [1, 5, 16])
def test_relighting_shadow_rays_give_the_irradiance_of_direct_irradiance(samples):
    scene = _area_lit_block_scene()
    patches = build_patches(scene)
    points = patches.centroid + 1e-6 * patches.radius[:, None] * patches.normal
    general = direct_irradiance(scene, points, patches.normal, samples=samples, seed=3)
    shadows = radiosity.AreaLightShadows(scene, points, patches.normal)
    fast = shadows.irradiance(scene.lights, samples, seed=3)
    # the same samples and rays: equal up to the order of the sums; the block shadows part
    # of the floor (some floor patches get only a share of the light)
    assert np.abs(fast - general).max() <= RECOMPUTED_RTOL * np.abs(general).max()
    floor = general[patches.of_object(0), 0]
    assert (floor == 0).any() and (floor > 0).mean() > 0.5
    assert radiosity.AreaLightShadows.handles(scene.lights)
    assert not radiosity.AreaLightShadows.handles([PointLight([0.0, 2.0, 0.0], 1.0)])


def test_relighting_shadow_rays_agree_between_ray_engines():
    scene = _area_lit_block_scene()
    patches = build_patches(scene)
    points = patches.centroid + 1e-6 * patches.radius[:, None] * patches.normal
    answers = [radiosity.AreaLightShadows(scene, points, patches.normal, engine).irradiance(
        scene.lights, 16, seed=0) for engine in ("auto", "mitsuba")]
    # the engines differ only on rays within float32 resolution of an edge
    # (tests/scenes/test_raycast.py): at most one of the 16 samples of a few patches
    differ = np.abs(answers[0] - answers[1]).max(axis=1) > RECOMPUTED_RTOL * answers[0].max()
    assert differ.mean() < 0.01


def test_image_weights_are_the_vertex_averages_interpolated():
    state = _block_state()
    scene = state._scene_with_materials()
    operators = state._image_operators(scene)
    gb = state._gbuffer()
    B = np.random.default_rng(5).uniform(0.0, 1.0, size=(len(state.patches), 3))
    for kind, index in (("diffuse", 0), ("translucent", 1)):
        pixels = operators[kind]
        assert set(gb.object_id.reshape(-1)[pixels]) == {index}
        expected = gb.interpolate(index, state.patches.vertex_values(index,
                                                                     scene.objects[index].mesh,
                                                                     B)).reshape(-1, 3)[pixels]
        got = operators[f"{kind}_weights"] @ B
        assert np.abs(got - expected).max() <= RECOMPUTED_RTOL * np.abs(expected).max()
    # every pixel that sees a surface is drawn once
    drawn = np.concatenate([operators["diffuse"], operators["translucent"]])
    assert len(set(drawn)) == len(drawn) == gb.hit.sum()


def test_area_lit_image_equals_the_general_path(monkeypatch):
    state = precompute(_area_lit_block_scene(), rays_per_patch=64, transfer="never")
    image = state.render()
    assert image.metadata["irradiance_seconds"] > 0
    B, _ = state.solve(state.patch_irradiance())
    fast = state.image(B)
    # the same frame with every light through direct_irradiance
    monkeypatch.setattr(radiosity.AreaLightShadows, "handles", staticmethod(lambda lights: False))
    general = state.image(B)
    assert np.abs(fast - general).max() <= RECOMPUTED_RTOL * np.abs(general).max()
    # render() composes the same image (stored in float32)
    assert np.abs(image.rgb - fast).max() <= FLOAT32_EPS * np.abs(fast).max()


def test_render_and_bounce_decomposition():
    state = _block_state()
    image = state.render()
    assert image.rgb.shape == (16, 16, 3)
    assert np.all(np.isfinite(image.rgb)) and np.all(image.rgb >= 0)
    assert image.metadata["producer"] == "radiosity"
    parts = state.components()
    assert tuple(parts) == COMPONENTS
    floor = state._gbuffer().mask("floor")
    # without inter-reflection a diffuse floor sees only the lights: identical images
    assert np.array_equal(parts["direct"].rgb[floor], parts["subsurface"].rgb[floor])
    # inter-reflection only adds light
    assert np.all(parts["both"].rgb[floor] >= parts["direct"].rgb[floor] - 1e-7)
    assert parts["both"].rgb.mean() > parts["direct"].rgb.mean()


def test_relighting_with_new_lights_changes_only_the_lighting(monkeypatch):
    from translucent.fast.radiosity import state as state_module

    # a build estimated free pays at once: the first relighting computes T
    monkeypatch.setattr(state_module, "transfer_seconds_estimate", lambda patches: 0.0)
    state = _block_state()
    state.set_material(measured_medium("Skin1"))
    dim = state.render(lights=[PointLight([1.0, 3.0, 1.0], 10.0)])
    assert state.transfer is not None and dim.metadata["transfer_seconds"] > 0
    bright = state.render(lights=[PointLight([1.0, 3.0, 1.0], 20.0)])
    assert bright.metadata["solver"] == "transfer"
    assert bright.rgb == pytest.approx(2.0 * dim.rgb, rel=1e-4, abs=1e-7)


def test_transfer_is_built_once_the_solves_have_cost_its_build(monkeypatch):
    """The ski-rental rule of transfer="auto": iterate until the solves add up to T's build."""
    from translucent.fast.radiosity import state as state_module

    state = precompute(_block_scene(), rays_per_patch=64)
    state.render()
    spent = state._solve_seconds
    assert spent > 0
    # a build estimated dear: every relighting iterates
    monkeypatch.setattr(state_module, "transfer_seconds_estimate", lambda patches: 1e9)
    frames = [state.render(lights=[PointLight([1.0, 3.0, 1.0], 10.0 + k)]) for k in range(3)]
    assert state.transfer is None
    assert all(f.metadata["solver"] == "jacobi" for f in frames)
    assert "transfer_seconds" not in frames[-1].metadata
    # the page says why the frames iterate, once
    said = [s for s in state.log.skipped if s.startswith("T not built yet")]
    assert len(said) == 1 and "ski-rental" in said[0]
    monkeypatch.setattr(state_module, "transfer_seconds_estimate",
                        lambda patches: state._solve_seconds)
    built = state.render(lights=[PointLight([1.0, 3.0, 1.0], 20.0)])
    assert built.metadata["solver"] == "transfer" and built.metadata["transfer_seconds"] > 0
    # a material change drops T and starts the count again
    state.set_material(measured_medium("Skin1"))
    assert state.transfer is None and state._solve_seconds == 0.0


def test_transfer_never_pays_without_form_factors(monkeypatch):
    from translucent.fast.radiosity import state as state_module

    monkeypatch.setattr(state_module, "transfer_seconds_estimate", lambda patches: 0.0)
    block = box((1.0, 1.0, 1.0), subdivisions=2)
    state = precompute(Scene([SceneObject("block", block, measured_medium("Skin1"))],
                             (PointLight([1.0, 3.0, 1.0], 20.0),), CAMERA, mm_per_unit=10.0))
    assert state.form_factors is None
    state.render(lights=[PointLight([0.0, 3.0, 0.0], 10.0)])
    # T would be S itself: one sparse product already applies it
    assert state.transfer is None and not state.transfer_pays()


def test_transfer_estimate_scales_as_the_cube_of_the_patches():
    from translucent.fast.radiosity.solve import transfer_seconds_estimate

    small = transfer_seconds_estimate(1000)
    assert small > 0 and np.isfinite(small)
    assert transfer_seconds_estimate(2000) == pytest.approx(8 * small, rel=1e-12)


def test_warm_start_projects_on_earlier_frames_and_is_dropped_with_the_material():
    state = precompute(_block_scene(), rays_per_patch=64, transfer="never")
    first = state.patch_irradiance([PointLight([1.0, 3.0, 1.0], 20.0)])
    second = state.patch_irradiance([PointLight([-1.0, 2.0, 0.5], 20.0)])
    B_first, cold = state.solve(first)
    B_second, _ = state.solve(second)
    # a combination of earlier lights is answered by the earlier solutions: the first
    # product already passes the residual test
    B, info = state.solve(2.0 * first + 3.0 * second)
    assert info["warm_start"] and info["iterations"] == 1 < cold["iterations"]
    assert max(info["residual"]) <= state.knobs["tolerance"]
    # the guess passed unchanged: exactly the combination of the earlier solutions
    assert np.abs(B - (2.0 * B_first + 3.0 * B_second)).max() <= \
        RECOMPUTED_RTOL * np.abs(B).max()
    state.set_material(measured_medium("Skin2"))
    assert state._frames == []
    state.forget_frames()
    _, info = state.solve(first)
    assert not info["warm_start"] and info["iterations"] == cold["iterations"]


def test_approx_command_writes_an_exr(tmp_path):
    from translucent.image import read_exr
    from translucent.reports.cli import main

    scene_file = tmp_path / "tiny.toml"
    scene_file.write_text("""
[scene]
name = "tiny"
mm_per_unit = 10.0

[camera]
origin = [0.0, 1.0, 4.0]
target = [0.0, 0.5, 0.0]
width = 12
height = 12

[[objects]]
name = "floor"
mesh = { type = "plane", width = 4.0, depth = 4.0, subdivisions = 2 }
material = { type = "lambertian", albedo = 0.5 }

[[objects]]
name = "block"
mesh = { type = "box", size = [1.0, 1.0, 1.0], center = [0.0, 0.5, 0.0], subdivisions = 1 }
material = { type = "measured", name = "Skin1" }

[[lights]]
type = "point"
position = [1.0, 3.0, 1.0]
intensity = 20.0
""")
    out = tmp_path / "tiny.exr"
    code = main(["approx", "radiosity", str(scene_file), "--out", str(out), "--rays", "16",
                 "--material", "Marble", "--component", "subsurface"])
    assert code == 0
    image = read_exr(out)
    assert image.rgb.shape == (12, 12, 3)
    assert image.metadata["component"] == "subsurface"
    # the paper's semi-infinite dipole: the 10 mm Marble cube re-emits less
    semi = tmp_path / "semi.exr"
    assert main(["approx", "radiosity", str(scene_file), "--out", str(semi), "--rays", "16",
                 "--material", "Marble", "--component", "subsurface", "--semi-infinite"]) == 0
    assert read_exr(semi).rgb.sum() < image.rgb.sum()
    assert main(["approx", "radiosity", str(scene_file), "--material", "Unobtainium"]) == 2
    table = tmp_path / "measured.csv"
    table.write_text("r_mm,R\n0,0.02\n2,0.004\n8,0\n")  # total reflectance 0.52
    assert main(["approx", "radiosity", str(scene_file), "--out", str(out), "--rays", "16",
                 "--material", str(table)]) == 0


def test_form_factor_rays_are_checked_where_no_form_factors_are_needed():
    # a single convex object needs no form factors, but a bad count is still bad input
    block = box((1.0, 1.0, 1.0), subdivisions=1)
    scene = Scene([SceneObject("block", block, measured_medium("Skin1"))],
                  (PointLight([1.0, 3.0, 1.0], 20.0),), CAMERA, mm_per_unit=10.0)
    for rays in (0, -3, 2.5):
        with pytest.raises(InputError, match="rays_per_patch.*must be an integer >= 1"):
            precompute(scene, rays_per_patch=rays)


def test_an_infinite_cut_off_is_named_as_the_knob():
    with pytest.raises(InputError, match=r"max_distance_mm = inf: must be a finite"):
        precompute(_block_scene(), max_distance_mm=float("inf"))


def test_approx_refuses_a_material_no_object_would_take(tmp_path, capsys, monkeypatch):
    from translucent.reports.cli import main

    def never(*args, **kwargs):
        raise AssertionError("precomputed with --material ignored")

    monkeypatch.setattr(radiosity_method, "precompute", never)
    assert main(["approx", "radiosity", "furnace_sphere", "--material", "Marble", "--out",
                 str(tmp_path / "f.exr")]) == 2
    assert "material = 'Marble': no translucent object" in capsys.readouterr().err
    assert not any(tmp_path.iterdir())


#: The float32 transfer T against a float64 solve of (I - SF) T = S, relative to T's
#: largest entry: float32 solves of this diagonally dominant system keep ~1e-7 (measured
#: 5.6e-7 on the bowl); 1e-5 leaves margin and is far below the solver tolerance.
TRANSFER_SYSTEM_RTOL = 1e-5


def test_the_transfer_solves_its_system():
    from translucent.fast.radiosity.solve import transfer_matrix

    state = _block_state()
    assert state.form_factors is not None
    T = transfer_matrix(state.S, state.form_factors)
    F = state.form_factors.toarray()
    for c in range(3):
        S_c = state.S.channel(c).toarray()
        exact = np.linalg.solve(np.eye(len(S_c)) - S_c @ F, S_c)
        assert T[c].dtype == np.float32
        assert np.abs(T[c] - exact).max() <= TRANSFER_SYSTEM_RTOL * np.abs(exact).max()
    # nothing inter-reflects without form factors: T is S itself
    alone = transfer_matrix(state.S, None)
    for c in range(3):
        np.testing.assert_array_equal(alone[c], state.S.channel(c).toarray().astype(np.float32))
