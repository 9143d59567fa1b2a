import numpy as np
import pytest
from translucent.errors import InputError
from translucent.fast.radiosity.form_factors import (
    DROPPED_ENERGY_WARNING,
    build_patches,
    form_factors,
    needs_form_factors,
    sphere_form_factors,
    stratified_cosine_directions,
)
from translucent.materials import Lambertian, measured_medium
from translucent.scenes import (
    Camera,
    Mesh,
    Scene,
    SceneObject,
    bowl,
    box,
    icosphere,
    plane,
)

#: Monte Carlo form factors: an entry estimated from N rays has a standard error of
#: sqrt(F (1 - F) / N); tests allow 5 standard errors (a false failure once in 1.7 million).
SIGMAS = 5.0

#: Two parallel unit squares one unit apart: F = 0.19982 (Howell's catalogue of
#: configuration factors, C-11; Cohen and Wallace 1993, Table 2.1).
PARALLEL_SQUARES = 0.19982

CAMERA = Camera([0.0, 0.0, 5.0], [0.0, 0.0, 0.0], width=8, height=8)


#: The same float64 sums taken in another order: round-off only.
SUM_ORDER_RTOL = 1e-12


def _inside_sphere(subdivisions=2):
    outside = icosphere(subdivisions, 1.0)
    inside = Mesh(outside.vertices, outside.faces[:, ::-1], -outside.normals, name="inside")
    return Scene([SceneObject("sphere", inside, Lambertian(0.5))], [], CAMERA)


def test_patches_cover_every_triangle_once():
    scene = Scene([SceneObject("a", box((1, 2, 3), subdivisions=2), Lambertian(0.5)),
                   SceneObject("b", plane(4, 4, subdivisions=3), Lambertian(0.2))], [], CAMERA)
    patches = build_patches(scene)
    area = sum(o.mesh.area for o in scene.objects)
    assert patches.area.sum() == pytest.approx(area)
    assert len(patches) == sum(len(o.mesh.faces) for o in scene.objects)
    assert np.allclose(np.linalg.norm(patches.normal, axis=1), 1.0)
    assert set(np.unique(patches.object_of)) == {0, 1}
    rows, faces = patches.faces_of(np.arange(len(patches)))
    assert np.array_equal(np.sort(faces), np.arange(len(patches)))


def test_merging_coplanar_triangles_keeps_area_and_makes_quads():
    scene = Scene([SceneObject("floor", plane(2, 2, subdivisions=4), Lambertian(0.5))], [],
                  CAMERA)
    quads = build_patches(scene, triangles_per_patch=2)
    assert len(quads) == 16
    assert quads.area.sum() == pytest.approx(4.0)
    assert np.allclose(quads.area, 0.25)
    # each centroid is the centre of a grid cell
    cells = (quads.centroid[:, [0, 2]] + 1.0) / 0.5
    assert np.allclose(cells % 1.0, 0.5)


def test_merging_never_joins_faces_of_different_planes():
    scene = Scene([SceneObject("cube", box((1, 1, 1), subdivisions=1), Lambertian(0.5))], [],
                  CAMERA)
    merged = build_patches(scene, triangles_per_patch=8)
    assert len(merged) == 6
    assert np.allclose(merged.area, 1.0)


def test_patch_values_average_to_vertices():
    scene = Scene([SceneObject("floor", plane(2, 2, subdivisions=2), Lambertian(0.5))], [],
                  CAMERA)
    patches = build_patches(scene)
    constant = np.full((len(patches), 3), 2.5)
    vertex = patches.vertex_values(0, scene.objects[0].mesh, constant)
    assert np.allclose(vertex, 2.5)


def test_vertex_values_are_the_area_weighted_mean_of_the_faces_around(rng):
    mesh = icosphere(1)
    scene = Scene([SceneObject("ball", mesh, Lambertian(0.5))], [], CAMERA)
    patches = build_patches(scene)
    values = rng.random((len(patches), 3))
    vertex = patches.vertex_values(0, mesh, values)
    area = patches.triangle_area
    for index in rng.integers(0, len(mesh.vertices), 5):
        around = np.flatnonzero((mesh.faces == index).any(axis=1))
        expected = area[around] @ values[patches.face_patch[around]] / area[around].sum()
        assert vertex[index] == pytest.approx(expected, rel=SUM_ORDER_RTOL)


def test_patch_sample_points_lie_on_their_patch(rng):
    scene = Scene([SceneObject("floor", plane(2, 2, subdivisions=2), Lambertian(0.5))], [],
                  CAMERA)
    patches = build_patches(scene, triangles_per_patch=2)
    rows, points = patches.sample_points(np.arange(len(patches)), 50, rng)
    assert np.allclose(points[:, 1], 0.0)
    # a quad of the 2 x 2 grid spans one cell: every point within its patch's radius
    distance = np.linalg.norm(points - patches.centroid[rows], axis=1)
    assert np.all(distance <= patches.radius[rows] + 1e-12)


def test_bad_triangles_per_patch():
    with pytest.raises(InputError, match="triangles_per_patch.*integer >= 1"):
        build_patches(_inside_sphere(1), triangles_per_patch=0)


def test_cosine_directions_are_cosine_distributed(rng):
    normals = np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 0.0]])
    directions = stratified_cosine_directions(normals, 4096, rng)
    cosine = np.einsum("nkd,nd->nk", directions, normals)
    assert np.allclose(np.linalg.norm(directions, axis=-1), 1.0)
    assert np.all(cosine >= 0)
    # E[cos] = 2/3 under p = cos / pi; stratification makes the error far below 1/sqrt(N)
    assert cosine.mean(axis=1) == pytest.approx([2 / 3, 2 / 3], abs=SIGMAS * 0.236 / 64)


def test_sphere_interior_form_factors_match_the_closed_form():
    scene = _inside_sphere(2)
    patches = build_patches(scene)
    rays = 1024
    F, facts = form_factors(scene, patches, rays_per_patch=rays, seed=3)
    exact = sphere_form_factors(patches.area)
    # a closed sphere: every ray hits, every row sums to exactly 1
    assert np.allclose(np.asarray(F.sum(axis=1)).ravel(), 1.0, atol=1e-6)
    assert facts["hits"] == facts["rays"]
    dense = F.toarray()
    error = np.sqrt(exact * (1 - exact) / rays)
    assert np.all(np.abs(dense - exact) <= SIGMAS * error + 1.0 / rays)
    # averaged over the rows, each column is the area share to a few per mille
    column = dense.mean(axis=0)
    assert np.all(np.abs(column - exact[0]) <= SIGMAS * error[0] / np.sqrt(len(patches)))


def test_parallel_unit_squares_match_the_catalogue_value():
    bottom = plane(1.0, 1.0, (0, 0, 0), subdivisions=2, normal="+y", name="bottom")
    top = plane(1.0, 1.0, (0, 1, 0), subdivisions=2, normal="-y", name="top")
    scene = Scene([SceneObject("bottom", bottom, Lambertian(0.5)),
                   SceneObject("top", top, Lambertian(0.5))], [], CAMERA)
    patches = build_patches(scene)
    rays = 4096
    F, _ = form_factors(scene, patches, rays_per_patch=rays, seed=1)
    lower, upper = patches.of_object(0), patches.of_object(1)
    # the form factor of the whole bottom square to the whole top one: area-weighted rows
    total = (patches.area[lower] @ F[lower][:, upper].toarray()).sum() / patches.area[lower].sum()
    standard_error = np.sqrt(PARALLEL_SQUARES * (1 - PARALLEL_SQUARES) / (rays * len(lower)))
    assert total == pytest.approx(PARALLEL_SQUARES, abs=SIGMAS * standard_error)
    # reciprocity, A_i F_ij = A_j F_ji, holds for the totals of two equal squares
    back = (patches.area[upper] @ F[upper][:, lower].toarray()).sum() / patches.area[upper].sum()
    assert back == pytest.approx(total, abs=2 * SIGMAS * standard_error)


def test_threshold_drops_small_entries_and_reports_the_energy():
    scene = _inside_sphere(1)
    patches = build_patches(scene)
    full, _ = form_factors(scene, patches, rays_per_patch=256, seed=2)
    # every entry of an 80-patch sphere is near 1 / 80, below 0.02: most energy goes
    with pytest.warns(UserWarning, match="form_factor_threshold = 0.02 drops"):
        cut, facts = form_factors(scene, patches, rays_per_patch=256, seed=2, threshold=0.02)
    assert cut.nnz < full.nnz
    assert cut.data.min() >= 0.02
    lost = full.sum() / len(patches) - cut.sum() / len(patches)
    assert facts["dropped_energy"] == pytest.approx(lost, rel=1e-5)
    assert facts["dropped_entries"] == full.nnz - cut.nnz


def test_a_threshold_above_one_ray_drops_the_far_field_and_warns():
    # 1,280 patches, 64 rays each: nearly every entry is a single ray's 1 / 64
    scene = _inside_sphere(3)
    patches = build_patches(scene)
    with pytest.warns(UserWarning, match="drops .*% of the form-factor energy.*1 / "
                                         "rays_per_patch = 0.01562"):
        _, facts = form_factors(scene, patches, rays_per_patch=64, seed=1, threshold=1.5 / 64)
    assert facts["dropped_energy"] > DROPPED_ENERGY_WARNING


def test_form_factor_knobs_are_checked():
    scene = _inside_sphere(1)
    patches = build_patches(scene)
    with pytest.raises(InputError, match="rays_per_patch.*integer >= 1"):
        form_factors(scene, patches, rays_per_patch=0)
    with pytest.raises(InputError, match="form_factor_threshold.*in \\[0, 1\\)"):
        form_factors(scene, patches, threshold=1.5)


def test_back_faces_absorb():
    # two squares facing away from each other: nothing is exchanged
    a = plane(1.0, 1.0, (0, 0, 0), normal="-y", name="a")
    b = plane(1.0, 1.0, (0, 1, 0), normal="+y", name="b")
    scene = Scene([SceneObject("a", a, Lambertian(0.5)), SceneObject("b", b, Lambertian(0.5))],
                  [], CAMERA)
    F, _ = form_factors(scene, build_patches(scene), rays_per_patch=64)
    assert F.nnz == 0


def test_single_convex_object_needs_no_form_factors():
    block = Scene([SceneObject("block", box((1, 2, 1), subdivisions=2),
                               measured_medium("Marble"))], [], CAMERA)
    assert "one convex object ('block')" in needs_form_factors(block)
    bowl_scene = Scene([SceneObject("bowl", bowl(1.0, 0.1, subdivisions=12),
                                    measured_medium("Marble"))], [], CAMERA)
    assert needs_form_factors(bowl_scene) is None
    assert needs_form_factors(_inside_sphere(1)) is None


def test_two_sided_sheets_get_twin_patches_that_receive_from_behind():
    sheet = plane(2.0, 2.0, (0, 1, 0), subdivisions=2, normal="+y", name="sheet")
    floor = plane(4.0, 4.0, (0, 0, 0), subdivisions=2, normal="+y", name="floor")
    scene = Scene([SceneObject("sheet", sheet, measured_medium("Skin1")),
                   SceneObject("floor", floor, Lambertian(0.5))], [], CAMERA)
    patches = build_patches(scene, two_sided=[0])
    front = np.flatnonzero((patches.object_of == 0) & ~patches.is_back)
    back = patches.twin[front]
    assert len(patches) == 2 * len(front) + len(floor.faces)
    assert np.array_equal(patches.twin[back], front)
    assert np.allclose(patches.normal[back], -patches.normal[front])
    assert np.allclose(patches.area[back], patches.area[front])
    F, _ = form_factors(scene, patches, rays_per_patch=256, seed=4)
    lower = patches.of_object(1)
    # the floor looks up at the sheet's underside: its rays land on the back patches
    seen = F[lower].tocsc()
    assert seen[:, back].sum() > 0
    assert seen[:, front].sum() == 0
