"""Ray queries through Mitsuba: trace, G-buffers, visibility, against analytic geometry."""

import math

import numpy as np
import pytest
from hypothesis import assume, example, given, settings
from hypothesis import strategies as st
from translucent.errors import InputError
from translucent.materials import Lambertian
from translucent.scenes import Camera, PointLight, Scene, SceneObject, load_scene
from translucent.scenes.gbuffer import (
    camera_rays,
    gbuffer,
    gbuffer_from_point,
    gbuffer_orthographic,
    project,
)
from translucent.scenes.meshes import box, icosphere, plane
from translucent.scenes.raycast import (
    NEAR_CLIP,
    embree_available,
    perspective_sensor_dict,
    ray_engine,
    to_mitsuba_mesh,
    trace,
    visibility_matrix,
    visible,
)

#: Mitsuba intersects in float32: distances and positions carry a relative error of a few
#: float32 ulps (1.2e-7 each) of the coordinates involved (scenes here span ~10 units).
FLOAT32 = 1e-5

#: Barycentric interpolation in float64 of float64 values: a few ulps.
FLOAT64 = 1e-12

GREY = Lambertian(0.5)


def one_object_scene(mesh, camera=None):
    camera = camera or Camera([0.0, 0.0, 5.0], [0.0, 0.0, 0.0], fov=40.0, width=48, height=40)
    return Scene((SceneObject("thing", mesh, GREY),), (PointLight([0, 5, 5], 1.0),), camera)


@pytest.fixture(scope="module")
def sphere_scene():
    return one_object_scene(icosphere(4, radius=1.0, center=(0.2, -0.1, 0.0)))


def sphere_bounds(mesh):
    """The inscribed radius (closest face plane) and circumscribed radius of an icosphere."""
    center = mesh.vertices.mean(axis=0)
    inscribed = np.min(np.einsum("ij,ij->i", mesh.face_normals, mesh.face_centroids - center))
    return center, inscribed, np.linalg.norm(mesh.vertices - center, axis=1).max()


def ray_sphere(origins, directions, center, radius):
    """Distance to the first intersection with a sphere (inf on a miss); unit directions."""
    oc = origins - center
    b = np.einsum("ij,ij->i", oc, directions)
    c = np.einsum("ij,ij->i", oc, oc) - radius**2
    disc = b**2 - c
    with np.errstate(invalid="ignore"):
        return np.where(disc >= 0, -b - np.sqrt(np.maximum(disc, 0)), np.inf)


def test_trace_agrees_with_analytic_sphere_intersection(sphere_scene, rng):
    mesh = sphere_scene.objects[0].mesh
    center, inscribed, radius = sphere_bounds(mesh)
    origins = center + rng.normal(size=(4000, 3)) * 0.3 + [0.0, 0.0, 4.0]
    aim = center + rng.uniform(-1.3, 1.3, size=(4000, 3))
    directions = aim - origins
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    hits = trace(sphere_scene, origins, directions)
    t_outer = ray_sphere(origins, directions, center, radius)
    t_inner = ray_sphere(origins, directions, center, inscribed)
    # every ray through the inscribed sphere hits; none that misses the circumscribed one
    assert hits.hit[np.isfinite(t_inner)].all()
    assert not hits.hit[~np.isfinite(t_outer)].any()
    # the polyhedron lies between the two spheres, so does each hit
    h = hits.hit & np.isfinite(t_inner)
    assert (hits.t[h] >= t_outer[h] * (1 - FLOAT32)).all()
    assert (hits.t[h] <= t_inner[h] * (1 + FLOAT32)).all()
    np.testing.assert_allclose(hits.position[hits.hit],
                               origins[hits.hit] + hits.t[hits.hit, None]
                               * directions[hits.hit], atol=FLOAT32 * 5)
    # normals: the shading normal is the interpolated exact normal; both stay within the
    # angle a triangle spans (its longest edge over the radius) of the analytic normal
    analytic = hits.position[h] - center
    analytic /= np.linalg.norm(analytic, axis=1, keepdims=True)
    edges = mesh.vertices[mesh.faces] - np.roll(mesh.vertices[mesh.faces], 1, axis=1)
    spread = np.linalg.norm(edges, axis=2).max() / inscribed
    for normals in (hits.shading_normal[h], hits.geometric_normal[h]):
        angle = np.arccos(np.clip(np.einsum("ij,ij->i", normals, analytic), -1, 1))
        assert angle.max() <= spread
    assert (hits.object_id[hits.hit] == 0).all() and (hits.object_id[~hits.hit] == -1).all()
    np.testing.assert_allclose(hits.barycentrics[hits.hit].sum(axis=1), 1.0, atol=FLOAT64)


def test_trace_flat_faces_is_exact_to_float32(rng):
    scene = one_object_scene(box((4.0, 2.0, 4.0), subdivisions=5))
    # tilts of at most 0.1 over 4 units of drop keep every ray on the top side
    origins = rng.uniform(-1.5, 1.5, size=(500, 3)) * [1, 0, 1] + [0.0, 5.0, 0.0]
    tilt = rng.uniform(-0.1, 0.1, size=(500, 3)) * [1, 0, 1]
    directions = tilt + [0.0, -1.0, 0.0]
    unit = directions / np.linalg.norm(directions, axis=1, keepdims=True)
    hits = trace(scene, origins, directions)
    assert hits.hit.all()
    np.testing.assert_allclose(hits.t, (5.0 - 1.0) / -unit[:, 1], rtol=FLOAT32)
    np.testing.assert_allclose(hits.position[:, 1], 1.0, atol=FLOAT32)
    np.testing.assert_allclose(hits.geometric_normal, [[0.0, 1.0, 0.0]] * 500, atol=FLOAT64)


def test_trace_tmax_and_bad_input(sphere_scene):
    origin = [0.2, -0.1, 5.0]
    hits = trace(sphere_scene, [origin, origin], [0.0, 0.0, -1.0], tmax=[3.9, 4.1])
    assert hits.hit.tolist() == [False, True]
    with pytest.raises(InputError, match=r"origins = .*must be finite"):
        trace(sphere_scene, [[np.nan, 0.0, 0.0]], [0.0, 0.0, 1.0])
    with pytest.raises(InputError, match=r"directions = 0: ray directions must be non-zero"):
        trace(sphere_scene, [0.0, 0.0, 5.0], [0.0, 0.0, 0.0])
    with pytest.raises(InputError, match=r"tmax = -1\.0: tmax must be >= 0"):
        trace(sphere_scene, [0.0, 0.0, 5.0], [0.0, 0.0, -1.0], tmax=-1.0)
    with pytest.raises(InputError, match=r"origins = .*shape \(N, 3\)"):
        trace(sphere_scene, [[0.0, 0.0]], [0.0, 0.0, -1.0])


@settings(max_examples=30, deadline=None)
@given(st.floats(-0.6, 0.6), st.floats(-0.6, 0.6), st.floats(-0.4, 0.4), st.floats(-0.4, 0.4))
@example(0.0, 0.3, 0.0, 0.3)  # inside, near the edge
def test_trace_barycentrics_match_a_plane_point(x, z, tilt_x, tilt_z):
    scene = PLANE_SCENE
    origin = np.array([x, 2.0, z])
    hits = trace(scene, origin, [tilt_x, -1.0, tilt_z])
    expected = origin + 2.0 * np.array([tilt_x, -1.0, tilt_z])  # reaches y = 0 at t' = 2
    edge = max(abs(expected[0]), abs(expected[2]))
    # a ray through the plane's very edge (x = 0, z = 1/3, tilt 1/3 reaches z = 1) may hit
    # or miss in float32: either answer is right there
    assume(abs(edge - 1.0) > FLOAT32)
    assert hits.hit[0] == (edge < 1.0)
    if hits.hit[0]:
        mesh = scene.objects[0].mesh
        corners = mesh.vertices[mesh.faces[hits.triangle_id[0]]]
        np.testing.assert_allclose(hits.barycentrics[0] @ corners, expected, atol=FLOAT32)


PLANE_SCENE = one_object_scene(plane(2.0, 2.0, subdivisions=4))


# --- G-buffers ------------------------------------------------------------------------


def test_camera_rays_are_those_of_the_mitsuba_sensor():
    from translucent.backend import mitsuba

    mi = mitsuba()
    camera = Camera([1.0, 2.0, 3.0], [0.2, -0.1, 0.3], [0.1, 1.0, 0.2], fov=50.0, width=7,
                    height=5)
    sensor = mi.load_dict(perspective_sensor_dict(camera))
    row, col = np.meshgrid(np.arange(5), np.arange(7), indexing="ij")
    centres = np.stack([(col.ravel() + 0.5) / 7, (row.ravel() + 0.5) / 5]).astype(np.float32)
    ray, _ = sensor.sample_ray(0.0, 0.5, mi.Point2f(centres), mi.Point2f(0.5, 0.5))
    origin, directions = camera_rays(camera)
    np.testing.assert_allclose(ray.d.numpy().T.reshape(5, 7, 3), directions, atol=FLOAT32)
    # the sensor starts its rays on the near clip plane
    start = NEAR_CLIP / (directions @ camera.forward)
    np.testing.assert_allclose(ray.o.numpy().T.reshape(5, 7, 3),
                               origin + start[..., None] * directions, atol=FLOAT32)


def test_gbuffer_object_mask_matches_a_mitsuba_render():
    """Each object an emitter of radiance (1, k + 1, (k + 1)^2): pixels whose samples all
    hit one object (coverage 1, no spread in k) must show that object at their centre."""
    from translucent.backend import mitsuba

    mi = mitsuba()
    scene = load_scene("cornell_block")
    shapes = {}
    for k, item in enumerate(scene.objects):
        emitter = {"type": "area", "radiance": {"type": "rgb",
                                                "value": [1.0, k + 1.0, (k + 1.0) ** 2]}}
        shapes[f"object{k}"] = to_mitsuba_mesh(item.mesh, props={
            "emitter": emitter, "bsdf": {"type": "diffuse", "reflectance": 0.0}})
    render = np.array(mi.render(mi.load_dict({
        "type": "scene", "integrator": {"type": "direct"},
        "sensor": perspective_sensor_dict(scene.camera, spp=16, sampler="stratified"),
        **shapes})))
    buffer = gbuffer(scene)
    coverage = render[..., 0]
    full, empty = coverage > 1 - 1e-4, coverage < 1e-4
    assert buffer.hit[full].all() and not buffer.hit[empty].any()
    mean_id = render[..., 1] / np.maximum(coverage, 1e-9)
    second = render[..., 2] / np.maximum(coverage, 1e-9)
    pure = full & (np.abs(second - mean_id**2) < 1e-3)  # variance of k + 1 is zero
    assert pure.mean() > 0.8
    np.testing.assert_array_equal(np.round(mean_id[pure]) - 1, buffer.object_id[pure])


def test_gbuffer_depth_and_normal_against_the_analytic_sphere(sphere_scene):
    mesh = sphere_scene.objects[0].mesh
    center, inscribed, radius = sphere_bounds(mesh)
    buffer = gbuffer(sphere_scene)
    origin, directions = camera_rays(sphere_scene.camera)
    flat = directions.reshape(-1, 3)
    t_outer = ray_sphere(np.broadcast_to(origin, flat.shape), flat, center, radius)
    t_inner = ray_sphere(np.broadcast_to(origin, flat.shape), flat, center, inscribed)
    t_outer, t_inner = t_outer.reshape(buffer.shape), t_inner.reshape(buffer.shape)
    assert buffer.hit[np.isfinite(t_inner)].all()
    assert not buffer.hit[~np.isfinite(t_outer)].any()
    inside = np.isfinite(t_inner)
    assert (buffer.depth[inside] >= t_outer[inside] * (1 - FLOAT32)).all()
    assert (buffer.depth[inside] <= t_inner[inside] * (1 + FLOAT32)).all()
    assert np.isinf(buffer.depth[~buffer.hit]).all()
    np.testing.assert_allclose(buffer.position[buffer.hit],
                               origin + buffer.depth[buffer.hit, None]
                               * directions[buffer.hit], atol=5 * FLOAT32)
    analytic = buffer.position[buffer.hit] - center
    analytic /= np.linalg.norm(analytic, axis=1, keepdims=True)
    cosine = np.einsum("ij,ij->i", buffer.normal[buffer.hit], analytic)
    # interpolated exact normals: within a triangle's angular size (about 0.1 rad here)
    assert cosine.min() > math.cos(0.1)
    np.testing.assert_allclose(buffer.view_direction, -directions)
    assert buffer.shape == (40, 48)


def test_interpolate_reproduces_linear_functions_exactly(rng):
    scene = load_scene("cornell_block")
    buffer = gbuffer(scene)
    gradient = rng.normal(size=(3, 2))
    offset = rng.normal(size=2)
    values = {o.name: o.mesh.vertices @ gradient + offset for o in scene.objects}
    for name, vertex_values in values.items():
        image = buffer.interpolate(name, vertex_values, fill=-7.0)
        mask = buffer.mask(name)
        assert mask.any()
        np.testing.assert_allclose(image[mask], buffer.position[mask] @ gradient + offset,
                                   atol=FLOAT64 * 10)
        assert (image[~mask] == -7.0).all()
    combined = buffer.interpolate_all(values)
    np.testing.assert_allclose(combined[buffer.hit], buffer.position[buffer.hit] @ gradient
                               + offset, atol=FLOAT64 * 10)
    assert (combined[~buffer.hit] == 0).all()
    scalar = buffer.interpolate(0, np.ones(len(scene.objects[0].mesh.vertices)))
    assert scalar.shape == buffer.shape and set(np.unique(scalar)) <= {0.0, 1.0}


def test_interpolate_checks_its_input(sphere_scene):
    buffer = gbuffer(sphere_scene)
    with pytest.raises(InputError, match=r"vertex_values = \(3,\): needs one value per "
                                         r"vertex of 'thing' \(2562\)"):
        buffer.interpolate("thing", np.zeros(3))
    with pytest.raises(InputError, match=r"object_name = 'cube': no such object; objects: "
                                         r"thing"):
        buffer.interpolate("cube", np.zeros(2562))


def test_orthographic_gbuffer_sees_the_sphere_disc(sphere_scene):
    mesh = sphere_scene.objects[0].mesh
    center, inscribed, radius = sphere_bounds(mesh)
    size = 96
    buffer = gbuffer_orthographic(sphere_scene, [0.3, -1.0, 0.2], size)
    assert buffer.camera is None
    pixel = math.sqrt(buffer.pixel_area)
    # the silhouette lies between the discs of radius r_in and R; pixels cut by the
    # outline add at most its perimeter times a pixel
    area = buffer.hit.sum() * buffer.pixel_area
    assert math.pi * inscribed**2 - 2 * math.pi * radius * pixel <= area
    assert area <= math.pi * radius**2 + 2 * math.pi * radius * pixel
    direction = np.array([0.3, -1.0, 0.2]) / np.linalg.norm([0.3, -1.0, 0.2])
    np.testing.assert_allclose(buffer.view_direction[0, 0], -direction)
    # all rays are parallel: the nearest surface is a sphere radius in front of the centre
    nearest = buffer.position[buffer.hit] @ direction
    assert nearest.min() == pytest.approx(center @ direction - radius, abs=2 * pixel)


def test_gbuffer_from_point_looks_along_the_direction(sphere_scene):
    center = sphere_scene.objects[0].mesh.vertices.mean(axis=0)
    eye = np.array([3.0, 4.0, 4.0])
    buffer = gbuffer_from_point(sphere_scene, eye, center - eye, 30.0, 17)
    _, inscribed, radius = sphere_bounds(sphere_scene.objects[0].mesh)
    distance = np.linalg.norm(center - eye)
    assert distance - radius <= buffer.depth[8, 8] <= distance - inscribed
    assert buffer.camera.width == 17 and buffer.hit[8, 8]
    with pytest.raises(InputError, match=r"size = 0: must be an integer"):
        gbuffer_from_point(sphere_scene, eye, center - eye, 30.0, 0)


@settings(max_examples=25, deadline=None)
@given(st.floats(10.0, 120.0), st.integers(1, 40), st.integers(1, 40),
       st.tuples(*[st.floats(-3.0, 3.0)] * 3))
def test_project_inverts_camera_rays(fov, width, height, target):
    if np.linalg.norm(np.subtract(target, (0.5, 1.0, 6.0))) < 0.1:
        return
    try:
        camera = Camera([0.5, 1.0, 6.0], target, [0.0, 1.0, 0.0], fov, width, height)
    except InputError:  # up parallel to the view: not a camera
        return
    origin, directions = camera_rays(camera)
    xy, in_front = project(camera, origin + 3.0 * directions)
    assert in_front.all()
    row, col = np.meshgrid(np.arange(height), np.arange(width), indexing="ij")
    np.testing.assert_allclose(xy, np.stack([col + 0.5, row + 0.5], axis=-1), atol=1e-9)


# --- visibility -----------------------------------------------------------------------


def occluder_scene():
    # a 2 x 2 square at y = 0 facing up, between points above and below it
    return one_object_scene(plane(2.0, 2.0, subdivisions=3))


def test_visible_against_an_analytic_occluder(rng):
    scene = occluder_scene()
    above = rng.uniform(-2.0, 2.0, size=(3000, 3)) * [1, 0, 1] + [0.0, 1.0, 0.0]
    below = rng.uniform(-2.0, 2.0, size=(3000, 3)) * [1, 0, 1] + [0.0, -1.0, 0.0]
    seen = visible(scene, above, below)
    crossing = (above + below) / 2  # where the segment meets y = 0
    inside = np.max(np.abs(crossing[:, [0, 2]]), axis=1)
    margin = FLOAT32 * 10
    assert not seen[inside < 1.0 - margin].any()
    assert seen[inside > 1.0 + margin].all()
    # the same pairs, both above the square: nothing between them
    assert visible(scene, above, above[::-1] + [0.0, 0.5, 0.0]).all()


def test_visible_surface_points_with_normals_do_not_shadow_themselves(rng):
    scene = load_scene("cornell_block")
    floor = scene.object("floor").mesh
    ceiling = scene.object("ceiling").mesh
    a = floor.vertices[rng.integers(0, len(floor.vertices), 400)] * [0.95, 1, 0.95]
    b = ceiling.vertices[rng.integers(0, len(ceiling.vertices), 400)] * [0.95, 1, 0.95]
    seen = visible(scene, a, b, normals_a=[0.0, 1.0, 0.0], normals_b=[0.0, -1.0, 0.0])
    # the only thing between floor and ceiling is the block: segments that keep clear of
    # its bounding box are free, and some pass through it
    block = scene.object("block").mesh
    assert seen[~passes_near(block, a, b)].all()
    assert not seen.all()
    # on the floor, surface points see each other along it (unless the block is between)
    along = visible(scene, a, a[::-1], normals_a=[0.0, 1.0, 0.0], normals_b=[0.0, 1.0, 0.0])
    clear = ~passes_near(block, a, a[::-1])
    assert clear.sum() > 100 and along[clear].all()


def passes_near(mesh, a, b, margin=0.01):
    """Whether the segments a-b come within ``margin`` of the mesh's bounding box."""
    lower, upper = mesh.bounds
    steps = np.linspace(0.0, 1.0, 400)[None, :, None]
    path = a[:, None, :] + steps * (b - a)[:, None, :]
    return ((path >= lower - margin) & (path <= upper + margin)).all(axis=2).any(axis=1)


def test_visibility_matrix_equals_pairwise_visible(rng):
    scene = occluder_scene()
    a = rng.uniform(-2.0, 2.0, size=(30, 3)) * [1, 0, 1] + [0.0, 1.0, 0.0]
    b = rng.uniform(-2.0, 2.0, size=(20, 3)) * [1, 0, 1] + [0.0, -1.0, 0.0]
    matrix = visibility_matrix(scene, a, b)
    pairs = visible(scene, np.repeat(a, len(b), axis=0), np.tile(b, (len(a), 1)))
    np.testing.assert_array_equal(matrix, pairs.reshape(len(a), len(b)))
    assert matrix.any() and not matrix.all()


# --- the engine cache -----------------------------------------------------------------


def test_engine_is_shared_by_geometry_and_rebuilt_for_new_meshes(sphere_scene):
    engine = ray_engine(sphere_scene)
    assert ray_engine(sphere_scene) is engine
    assert ray_engine(sphere_scene.with_lights([])) is engine
    assert ray_engine(sphere_scene.with_material("thing", Lambertian(0.1))) is engine
    mesh = sphere_scene.objects[0].mesh
    deformed = sphere_scene.objects[0].mesh.transformed(scale=1.5)
    moved = Scene((SceneObject("thing", deformed, GREY),), (), sphere_scene.camera)
    assert ray_engine(moved) is not engine
    # the deformed sphere is hit earlier along the axis
    origin = mesh.vertices.mean(axis=0) + [0.0, 0.0, 5.0]
    assert trace(moved, origin, [0, 0, -1]).t[0] < trace(sphere_scene, origin, [0, 0, -1]).t[0]


# --- the two engines ----------------------------------------------------------------------

#: A ray may hit or miss differently in the two engines only when it passes within float32
#: resolution of an edge: its hit point's smallest barycentric is then below a few float32
#: ulps of the coordinates over the edge length (scenes here span ~2 units, edges ~0.1).
EDGE_BARYCENTRIC = 1e-4


def two_object_scene():
    return Scene((SceneObject("ball", icosphere(3, radius=0.6, center=(0.3, 0.2, 0.0)), GREY),
                  SceneObject("crate", box((1.0, 0.8, 1.2), center=(-0.6, -0.3, 0.2)), GREY)),
                 (PointLight([0, 5, 5], 1.0),),
                 Camera([0.0, 0.0, 5.0], [0.0, 0.0, 0.0], fov=40.0, width=8, height=8))


@pytest.mark.skipif(not embree_available(), reason="embreex is not installed")
def test_embree_and_mitsuba_engines_agree_on_random_rays(rng):
    scene = two_object_scene()
    embree, mitsuba = ray_engine(scene, "embree"), ray_engine(scene, "mitsuba")
    assert (embree.engine, mitsuba.engine) == ("embree", "mitsuba")
    origins = rng.uniform(-2.0, 2.0, size=(20000, 3))
    directions = rng.uniform(-1.0, 1.0, size=(20000, 3)) - origins  # towards the objects
    tmax = rng.uniform(0.5, 4.0, size=20000)
    first, second = embree.trace(origins, directions, tmax), mitsuba.trace(origins, directions,
                                                                          tmax)
    assert 0.2 < first.hit.mean() < 0.8
    differ = (first.hit != second.hit) | (first.triangle_id != second.triangle_id) \
        | (first.object_id != second.object_id)
    # the rays that differ graze an edge in whichever engine hit something
    for hits in (first, second):
        grazing = differ & hits.hit
        assert (hits.barycentrics[grazing].min(axis=1) < EDGE_BARYCENTRIC).all()
    assert differ.mean() < 1e-3
    both = first.hit & second.hit & ~differ
    np.testing.assert_allclose(first.t[both], second.t[both], rtol=FLOAT32, atol=FLOAT32)
    np.testing.assert_allclose(first.barycentrics[both], second.barycentrics[both],
                               atol=EDGE_BARYCENTRIC)
    # shadow rays (any hit before tmax): the same answers as each other and as the closest
    # hit, up to grazing rays (the closest-hit query retries misses tilted, see trace)
    blocked = embree.occluded(origins, directions, tmax)
    assert (blocked != mitsuba.occluded(origins, directions, tmax)).mean() < 1e-3
    assert (blocked != first.hit).mean() < 1e-3


def test_engine_choice_and_its_errors(monkeypatch, sphere_scene):
    assert ray_engine(sphere_scene, "mitsuba").engine == "mitsuba"
    assert ray_engine(sphere_scene, "auto").engine == ("embree" if embree_available()
                                                       else "mitsuba")
    with pytest.raises(InputError, match=r"unknown ray engine; valid: auto, embree, mitsuba"):
        ray_engine(sphere_scene, "optix")
    monkeypatch.setenv("TRANSLUCENT_RAY_ENGINE", "mitsuba")
    assert ray_engine(sphere_scene).engine == "mitsuba"
    monkeypatch.setenv("TRANSLUCENT_RAY_ENGINE", "cuda")
    with pytest.raises(InputError, match=r"TRANSLUCENT_RAY_ENGINE.*unknown ray engine"):
        ray_engine(sphere_scene)


@pytest.mark.parametrize("name", ["mitsuba"] + (["embree"] if embree_available() else []))
def test_occluded_unit_answers_as_occluded_for_a_checked_batch(name, sphere_scene, rng):
    engine = ray_engine(sphere_scene, name)
    origins = rng.uniform(-3.0, 3.0, size=(5000, 3))
    directions = rng.uniform(-1.0, 1.0, size=(5000, 3)) - origins
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    tmax = rng.uniform(0.5, 6.0, size=5000)
    blocked = engine.occluded(origins, directions, tmax)
    assert 0.1 < blocked.mean() < 0.9
    # the same rays, already float32: passed to the engine without a copy or a check
    unit = engine.occluded_unit(origins.astype(np.float32), directions.astype(np.float32),
                                tmax.astype(np.float32))
    assert np.array_equal(unit, blocked)


def test_trace_refuses_tmax_of_another_length_and_non_numeric_rays(sphere_scene):
    origins = np.array([[0.0, 0.0, 5.0]] * 3)
    with pytest.raises(InputError,
                       match=r"tmax = \(2,\): tmax must be one value, or one per ray \(3\)"):
        trace(sphere_scene, origins, [0.0, 0.0, -1.0], tmax=[1.0, 2.0])
    with pytest.raises(InputError, match=r"directions = 'down': must be numbers"):
        trace(sphere_scene, origins, "down")
