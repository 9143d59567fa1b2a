"""volpath_mnee's seeded solves: several refraction paths through a ball lens (SMS).

Seeded solves (Zeltner et al. 2020) must add every refraction point the straight start
misses, and none at eta = 1; the conversion asks for them on concave boundaries only.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

mi_module = pytest.importorskip("mitsuba")

from manifold_scenes import POINT, jit_mitsuba, medium, sphere_scene  # noqa: E402
from translucent.reference import manifold_nee  # noqa: E402


@pytest.fixture(scope="module")
def mi():
    return jit_mitsuba()


def _ball_lens(mi, eta):
    from translucent.scenes.meshes import icosphere
    from translucent.scenes.raycast import to_mitsuba_mesh

    shape = to_mitsuba_mesh(icosphere(5, 1.0), "ball",
                            props={"bsdf": {"type": "dielectric", "int_ior": eta},
                                   "interior": medium()})
    scene = mi.load_dict({
        "type": "scene", "integrator": {"type": "volpath_mnee", "seeded_solutions": True},
        "ball": shape, "light": {"type": "point", "position": [0.0, 0.0, 4.0],
                                 "intensity": {"type": "rgb", "value": [1.0, 1.0, 1.0]}}})
    integrator = scene.integrator()
    integrator.prepare_scene(scene)
    return scene, integrator


def _all_refraction_points(mi, scene, integrator, v, starts=20000):
    """Every refraction point from ``v`` to the light: solves from a Fibonacci sphere of starts."""

    k = np.arange(starts) + 0.5
    phi = math.pi * (3.0 - math.sqrt(5.0)) * k
    z = 1.0 - 2.0 * k / starts
    r = np.sqrt(1.0 - z * z)
    d = mi.Vector3f(r * np.cos(phi), r * np.sin(phi), z)
    vertex = mi.Point3f(*[np.full(starts, c) for c in v])
    light = mi.Point3f(0.0, 0.0, 4.0) + 0.0 * vertex
    start, usable = integrator.exit_point(scene, vertex, d, mi.Bool(True))
    eta = integrator.boundary_eta(start, usable)
    si, converged = integrator.solve(scene, vertex, start, light, mi.Bool(False), eta,
                                     usable & (eta > 0.0))
    good = np.array(converged & integrator.refracts(si, vertex, light, mi.Bool(False)))
    points = []
    for point in np.array(si.p).T[good]:
        if all(np.linalg.norm(point - q) > 1e-3 * (np.linalg.norm(point - v) + 2.0)
               for q in points):
            points.append(point)
    return points


@pytest.mark.parametrize("vertex, every", [((0.035, 0.0, -0.9), 3), ((0.0, 0.0, 0.0), 1)])
def test_seeded_solves_add_every_refraction_point_the_straight_start_misses(mi, vertex, every):
    """A glass-like ball lens (eta 2.4) focuses a point light inside, near its far side.

    Past that caustic a medium vertex sees the light along three refracted paths (found
    here by solves from 20000 starts); the solve from the straight line finds one. The
    seeded estimate (found ? trials : 0) must average the count of the others, 2: each
    found point weighted by its estimated inverse probability (weighting by 1 instead
    would give the fraction of seeds that found one, 0.58). At the centre there is one
    path, which the straight start finds: the seeded estimate is exactly 0.
    """
    import drjit as dr

    scene, integrator = _ball_lens(mi, 2.4)
    points = _all_refraction_points(mi, scene, integrator, np.array(vertex))
    assert len(points) == every
    lanes = 100_000
    v = mi.Point3f(*[dr.full(mi.Float, c, lanes) for c in vertex])
    light = mi.Point3f(0.0, 0.0, 4.0) + 0.0 * v
    first, leaves = integrator.exit_point(scene, v, dr.normalize(light - v), mi.Bool(True))
    eta = integrator.boundary_eta(first, leaves)
    known, converged = integrator.solve(scene, v, first, light, mi.Bool(False), eta, eta > 0.0)
    valid = converged & integrator.refracts(known, v, light, mi.Bool(False))
    assert np.array(valid).all()
    sampler = mi.load_dict({"type": "independent"})
    sampler.seed(7, lanes)
    other, found, trials, capped = integrator.other_solution(
        scene, sampler, v, known, valid, light, mi.Bool(False), eta, eta > 0.0)
    found = np.array(found)
    weight = np.where(found, np.array(trials), 0.0)
    assert not np.array(capped).any()
    expected = every - 1
    standard_error = weight.std() / math.sqrt(lanes)
    assert abs(weight.mean() - expected) < 4.0 * standard_error + 1e-12, \
        (weight.mean(), standard_error)
    if expected:
        assert standard_error < 0.05 * expected  # tells 2 from 0.58 or 1
        # every point it found is one of the others
        found_points = np.array(other.p).T[found]
        straight = np.array(known.p).T[0]
        others = [p for p in points if np.linalg.norm(p - straight) > 1e-2]
        assert len(others) == expected
        nearest = np.min([np.linalg.norm(found_points - p, axis=1) for p in others], axis=0)
        assert nearest.max() < 1e-2


@pytest.mark.slow  # 9 s; the fast tier keeps the seeded solves' added refraction points
def test_at_eta_one_seeded_solves_find_no_other_path(mi):
    """Without refraction the only path is the straight line: a seeded solve never adds one."""
    seeded = sphere_scene(mi, "volpath_mnee", {"type": "dielectric", "int_ior": 1.0}, POINT,
                           8, seeded_solutions=True)
    mi.render(seeded, spp=64, seed=1)
    counted = manifold_nee.counts(seeded)
    assert counted["solved"] > 1000
    assert counted["seeded_found"] == 0 and counted["trials_capped"] == 0, counted


def test_the_conversion_seeds_solves_on_concave_boundaries_only(mi):
    import dataclasses

    from translucent.reference.mitsuba_scene import convert_scene
    from translucent.scenes import load_scene
    from translucent.scenes.meshes import torus

    convex = convert_scene(load_scene("sphere_dielectric"), spp=4)
    assert "seeded_solutions" not in convex.scene_dict["integrator"]
    scene = load_scene("sphere_dielectric")
    ring = dataclasses.replace(scene.objects[0], mesh=torus(1.0, 0.4, subdivisions=24))
    concave = convert_scene(dataclasses.replace(scene, objects=[ring]), spp=4)
    assert concave.scene_dict["integrator"]["seeded_solutions"] is True
    assert any("specular manifold sampling" in note and repr(ring.name) in note
               for note in concave.substitutions)
