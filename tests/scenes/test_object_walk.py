"""Photon random walks in an object's mesh (scenes/object_walk.py)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from translucent.errors import InputError
from translucent.materials.homogeneous import Dipole
from translucent.materials.profiles import profile
from translucent.scenes.meshes import box, icosphere
from translucent.scenes.object_diffusion import object_diffusion
from translucent.scenes.object_walk import SURFACE_OFFSET, walk_correction, walk_exits
from translucent.scenes.raycast import RayEngine


def _engine(mesh):
    return RayEngine([mesh])


def _offset(mesh):
    return SURFACE_OFFSET * _engine(mesh).diagonal


def _chandrasekhar_h(albedo: float, nodes: int = 64):
    """H(mu) of isotropic scattering on Gauss-Legendre nodes in (0, 1), by iteration."""
    x, w = np.polynomial.legendre.leggauss(nodes)
    mu, weight = 0.5 * (x + 1.0), 0.5 * w
    h = np.ones(nodes)
    for _ in range(500):
        integral = (weight * h / (mu[:, None] + mu[None, :])).sum(axis=1)
        h = 1.0 / (1.0 - 0.5 * albedo * mu * integral)
    return mu, weight, h


def test_the_h_function_meets_its_zeroth_moment():
    # the solver's own check: int H dmu = 2 (1 - sqrt(1 - albedo)) / albedo
    mu, weight, h = _chandrasekhar_h(0.9)
    assert (weight * h).sum() == pytest.approx(2.0 * (1.0 - np.sqrt(0.1)) / 0.9, rel=1e-6)


@pytest.mark.parametrize("albedo", [0.5, 0.95])
def test_a_thick_box_returns_the_half_spaces_spherical_albedo(albedo):
    """Cosine-distributed entry at eta 1 is isotropic illumination: the light a half-space
    of isotropic scatterers returns is 1 - 2 sqrt(1 - albedo) int H(mu) mu dmu
    (Chandrasekhar), a solution that shares nothing with the walks."""
    mesh = box((400.0, 400.0, 200.0))
    count = 6000
    points = np.tile([[0.0, 0.0, 100.0]], (count, 1))
    normals = np.tile([[0.0, 0.0, 1.0]], (count, 1))
    rng = np.random.default_rng(3)
    # made with half the absorption, weighed for the rest by each path's length
    source, position, _, weight, length, stats = walk_exits(
        _engine(mesh), points, normals, albedo, 1.0, 1, rng, _offset(mesh),
        0.5 * (1.0 - albedo))
    assert stats["leaks"] == 0 and stats["given_up"] == 0
    assert np.all(position[:, 2] > 99.9)  # nothing reaches the other faces
    per_walk = np.bincount(source, weights=weight * np.exp(-0.5 * (1.0 - albedo) * length),
                           minlength=count)
    mu, w, h = _chandrasekhar_h(albedo)
    expected = 1.0 - 2.0 * np.sqrt(1.0 - albedo) * (w * h * mu).sum()
    error = per_walk.std() / np.sqrt(count)
    assert abs(per_walk.mean() - expected) < 4.0 * error, (per_walk.mean(), expected, error)


def test_without_absorption_every_walk_leaves_whole_at_eta_1():
    mesh = icosphere(3, 5.0)
    count = 200
    rng = np.random.default_rng(0)
    points, normals = mesh.vertices[:count], mesh.normals[:count]
    source, _, _, weight, _, stats = walk_exits(_engine(mesh), points, normals, 2.0, 1.0, 1,
                                                rng, _offset(mesh))
    assert stats["given_up"] == 0 and stats["leaks"] == 0
    np.testing.assert_allclose(np.bincount(source, weights=weight, minlength=count), 1.0,
                               rtol=1e-12)


@pytest.mark.parametrize("eta", [0.8, 1.3, 2.5])
def test_without_absorption_the_walks_keep_the_power_behind_a_dielectric(eta):
    # Fresnel reflections lower a walk's weight and Russian roulette restores it on average
    mesh = icosphere(3, 5.0)
    count = 3000
    rng = np.random.default_rng(1)
    index = rng.integers(0, len(mesh.vertices), count)
    source, _, _, weight, _, stats = walk_exits(
        _engine(mesh), mesh.vertices[index], mesh.normals[index], 2.0, eta, 1, rng,
        _offset(mesh))
    per_walk = np.bincount(source, weights=weight, minlength=count)
    assert stats["given_up"] == 0
    assert abs(per_walk.mean() - 1.0) < 4.0 * per_walk.std() / np.sqrt(count)


def _box_case():
    mesh = box((40.0, 40.0, 20.0), subdivisions=8)
    triangles = mesh.vertices[mesh.faces]
    return triangles, object_diffusion(triangles, cells=1000, clusters=96, cache=False)


def test_the_correction_is_the_walks_energy_beyond_the_profiles_on_a_broad_face():
    """Mid-face of a box 40 transport lengths across: what the correction adds to a
    cluster's light, summed over the surface, is the half-space's spherical albedo
    (Chandrasekhar) less the profile's total; with the same walks, another profile's
    correction differs by the two profiles' totals alone."""
    from translucent.scenes.mesh_shape import stratified_surface_points
    from translucent.scenes.object_walk import _triangle_mesh

    triangles, clusters = _box_case()
    albedo = 0.8
    medium = Dipole(np.full(3, 2.0 * (1.0 - albedo)), np.full(3, 2.0 * albedo), 1.0)
    mu, w, h = _chandrasekhar_h(albedo)
    returned = 1.0 - 2.0 * np.sqrt(1.0 - albedo) * (w * h * mu).sum()
    point = clusters.cluster_point
    middle = (np.abs(point[:, 2] - 10.0) < 1e-6) & (np.abs(point[:, :2]) < 8.0).all(axis=1)
    assert middle.sum() >= 2
    points, normals, area = stratified_surface_points(_triangle_mesh(triangles), 65536,
                                                      np.random.default_rng(5))
    exit_area = area / 65536 * np.asarray(clusters.weights(points, normals).sum(axis=0)).ravel()
    added = {}
    for name in ("dipole", "better_dipole"):
        radial = profile(name, medium)
        correction = walk_correction(triangles, clusters, medium, radial, walks=65536,
                                     quadrature=8192, seed=2)
        added[name] = np.einsum("m,mk->k", exit_area, correction[:, :, 0])[middle]
        # about 2,700 walks a cluster: a standard error of 0.006
        np.testing.assert_allclose(added[name], returned - radial.total()[0], atol=0.025)
    totals = {name: profile(name, medium).total()[0] for name in added}
    np.testing.assert_allclose(added["dipole"] - added["better_dipole"],
                               totals["better_dipole"] - totals["dipole"], atol=2e-3)


def test_an_object_s_times_larger_with_coefficients_s_times_smaller_scales_as_one_over_s2():
    # a sphere's clusters are irregular: no point lies as near to a fifth cluster as to
    # its fourth, where rounding would pick another
    mesh = icosphere(3, 8.0)
    triangles = mesh.vertices[mesh.faces]
    clusters = object_diffusion(triangles, cells=1000, clusters=96, cache=False)
    medium = Dipole([0.05, 0.2, 0.5], [1.0, 1.5, 2.0], 1.3)
    base = walk_correction(triangles, clusters, medium, profile("dipole", medium), walks=4096,
                           quadrature=4096, seed=7)
    scale = 3.0
    # the same clusters, scaled (k-means stops at an absolute tolerance: not scale-free)
    larger = dataclasses.replace(clusters, cluster_point=clusters.cluster_point * scale,
                                 spacing=clusters.spacing * scale)
    thinner = Dipole(medium.sigma_a / scale, medium.sigma_s_prime / scale, 1.3)
    scaled = walk_correction(triangles * scale, larger, thinner, profile("dipole", thinner),
                             walks=4096, quadrature=4096, seed=7)
    np.testing.assert_allclose(scaled * scale ** 2, base, rtol=1e-6,
                               atol=1e-6 * np.abs(base).max())


@pytest.mark.parametrize("eta", [0.8, 1.0, 1.3])
def test_walks_enter_as_diffuse_light_refracted_through_the_boundary(eta):
    """The mean cosine inside against a quadrature of F_t(cos_o) cos_o over the outside
    hemisphere mapped by Snell's law; within the critical cone behind a dielectric."""
    from translucent.materials.fresnel import fresnel_transmittance
    from translucent.scenes.object_walk import _diffuse_entry

    normals = np.tile([[0.0, 0.6, 0.8]], (200000, 1))
    direction = _diffuse_entry(normals, eta, np.random.default_rng(4))
    np.testing.assert_allclose(np.linalg.norm(direction, axis=1), 1.0, rtol=1e-12)
    cos_in = -np.einsum("nd,nd->n", direction, normals)
    assert cos_in.min() >= np.sqrt(max(0.0, 1.0 - 1.0 / eta ** 2)) - 1e-12
    x, w = np.polynomial.legendre.leggauss(200)
    cos_out = 0.5 * (x + 1.0)
    density = fresnel_transmittance(eta, cos_out) * cos_out * 0.5 * w
    refracted = np.sqrt(np.maximum(0.0, 1.0 - (1.0 - cos_out ** 2) / eta ** 2))
    expected = (density * refracted).sum() / density.sum()
    assert cos_in.mean() == pytest.approx(expected, abs=4.0 * cos_in.std() / np.sqrt(len(cos_in)))


def test_an_absorption_edit_reweighs_the_walks_a_lower_one_walks_again():
    from translucent.scenes import object_walk

    triangles, clusters = _box_case()
    object_walk._PATHS.clear()
    medium = Dipole([0.1, 0.2, 0.4], [1.0, 1.5, 2.0], 1.3)
    kept = dict(walks=2048, seed=3, cache=False)
    object_walk.walk_response(clusters, triangles, medium, profile("dipole", medium), **kept)
    (paths,) = object_walk._PATHS.values()
    assert [item[3] for item in paths.channels.values()] == pytest.approx([0.05, 0.1, 0.2])
    more = Dipole(medium.sigma_a * 1.5, medium.sigma_s_prime, 1.3)
    edited = object_walk.walk_response(clusters, triangles, more, profile("dipole", more),
                                       **kept)
    assert list(object_walk._PATHS.values()) == [paths]  # no new walks
    np.testing.assert_array_equal(edited, walk_correction(
        triangles, clusters, more, profile("dipole", more), walks=2048, seed=3, paths=paths))
    less = Dipole(medium.sigma_a * 0.4, medium.sigma_s_prime, 1.3)  # below the walks' floor
    with pytest.raises(InputError, match="absorption"):
        paths.transport(0, float(less.sigma_a[0]))
    object_walk.walk_response(clusters, triangles, less, profile("dipole", less), **kept)
    (again,) = object_walk._PATHS.values()
    assert again is not paths and again.serves(less.sigma_a)


def test_the_surface_sums_any_profile_as_a_direct_quadrature_does():
    """The distance histogram against the profile summed pair by pair in numpy, with the
    profile's exact values (the histogram interpolates it linearly in ln r)."""
    from translucent.scenes.mesh_shape import stratified_surface_points
    from translucent.scenes.object_walk import QUADRATURE_ENTRIES, _triangle_mesh, surface_sums

    mesh = icosphere(2, 6.0)
    triangles = mesh.vertices[mesh.faces]
    clusters = object_diffusion(triangles, cells=500, clusters=24, cache=False)
    surface = _triangle_mesh(triangles)
    sums = surface_sums(clusters, surface, 12.0, 1024, np.random.default_rng(9))
    rng = np.random.default_rng(9)  # the same draws, in the same order
    entry, entry_normal, area = stratified_surface_points(surface, QUADRATURE_ENTRIES, rng)
    point, normal, _ = stratified_surface_points(surface, 1024, rng)
    entry_weights = clusters.weights(entry, entry_normal).toarray()
    weights = clusters.weights(point, normal).toarray()
    distance = np.linalg.norm(point[None, :, :] - entry[:, None, :], axis=2)
    for medium in (Dipole([0.01, 0.1, 0.5], [1.0, 1.0, 1.0], 1.3),
                   Dipole([0.05, 0.05, 0.05], [0.2, 2.0, 8.0], 1.0)):
        radial = profile("dipole", medium)
        values = np.where((distance > sums.near)[..., None], radial.reflection(distance), 0.0)
        far = np.stack([(entry_weights.T @ values[:, :, c] @ weights).T for c in range(3)],
                       axis=2) * (area / 1024)
        near = np.einsum("sk,sm->mk", entry_weights, entry_weights)[..., None] \
            * radial.total(max_radius=sums.near)
        expected = (far + near) / entry_weights.sum(axis=0)[None, :, None]
        np.testing.assert_allclose(sums.profile_sum(radial), expected, rtol=2e-3,
                                   atol=2e-3 * np.abs(expected).max())


@pytest.mark.slow  # about 1 min each: a fine grid and a dense quadrature of a wide slab
@pytest.mark.parametrize("medium, thickness", [("Chicken1", 12.0), ("Skin1", 6.0)])
def test_on_a_thin_slab_diffusions_correction_returns_the_multipoles_light(medium, thickness):
    """The profile plus diffusion's correction, summed over each face of an 80 mm wide slab
    from unit power entering at the middle of its top, against the multipole of Donner and
    Jensen 2005 (materials/profiles/slab.py, no shared code): reflection and transmission
    within 0.04 in each channel. The walks' correction is transport's, not the multipole's:
    it returns more light on the lit side (checked as a direction, the figures in
    docs/geometry.md)."""
    from translucent.materials import measured_medium
    from translucent.materials.profiles.slab import SlabProfile
    from translucent.scenes.mesh_shape import stratified_surface_points
    from translucent.scenes.object_walk import _triangle_mesh

    base = measured_medium(medium)
    material = Dipole(base.sigma_a, base.sigma_s_prime, 1.0)
    mesh = box((80.0, 80.0, thickness), subdivisions=40)
    triangles = mesh.vertices[mesh.faces]
    clusters = object_diffusion(triangles, cells=20000, clusters=256, cache=False)
    points, normals, area = stratified_surface_points(_triangle_mesh(triangles), 65536,
                                                      np.random.default_rng(1))
    weights = clusters.weights(points, normals).toarray()
    top, bottom = normals[:, 2] > 0.9, normals[:, 2] < -0.9
    each = area / 65536
    entry = np.array([[0.0, 0.0, thickness / 2]])
    entry_weights = clusters.weights(entry, [[0.0, 0.0, 1.0]]).toarray()[0]
    radial = profile("dipole", material)
    distance = np.linalg.norm(points - entry, axis=1)
    near = 2.0 * np.sqrt(each)
    alone = np.where((distance > near)[:, None], radial.reflection(distance), 0.0) * each

    def faces(correction):
        added = np.einsum("pm,mkc,k->pc", weights, correction, entry_weights) * each
        return (alone[top].sum(0) + radial.total(max_radius=near) + added[top].sum(0),
                alone[bottom].sum(0) + added[bottom].sum(0))

    slab = SlabProfile(material, thickness)
    reflected, transmitted = faces(clusters.response(material.sigma_a,
                                                     material.sigma_s_prime, 1.0))
    np.testing.assert_allclose(reflected, slab.total("reflection"), atol=0.04)
    np.testing.assert_allclose(transmitted, slab.total("transmission"), atol=0.04)
    walked, _ = faces(walk_correction(triangles, clusters, material, radial))
    assert walked[0] > reflected[0]
