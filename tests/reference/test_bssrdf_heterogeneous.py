"""bssrdf_path with a heterogeneous object: each method's mixing rule rendered exactly.

Checked three ways, as the homogeneous BSSRDF is (test_bssrdf_path.py):

1. The homogeneous limit: a uniform solid medium renders as its Dipole, bit for bit; two
   media a millionth apart render as one medium through the geometric mean's own code
   (Eq. 16 does not reduce so: its product of partial profiles is not the profile).
2. The rules' values on the device against the materials' numpy functions
   (:func:`~translucent.materials.profiles.geometric_mean_profile`,
   :func:`~translucent.materials.profiles.mixed_profile`), and their reciprocity: each rule
   gives the same value with entry and exit exchanged.
3. A sphere of two media under a point light: per pixel, a brute-force quadrature of the
   rule over the mesh's surface (``bssrdf_checks.sphere_radiance``: numpy, its own Fresnel
   terms, no integrator code).
"""

from __future__ import annotations

import bssrdf_checks
import numpy as np
import pytest
from translucent.errors import InputError
from translucent.materials import Dipole
from translucent.materials.profiles import (
    HETEROGENEOUS_RULES,
    geometric_mean_profile,
    mixed_profile,
    profile,
    segment_average_profile,
)
from translucent.materials.solid import SolidMedium, quantise_media

pytest.importorskip("mitsuba")

from translucent.reference.bssrdf_tables import (  # noqa: E402
    PROBE_ENERGY_FRACTION,
    RULE_MAX_MEDIA,
    SEGMENT_POINTS,
    build_tables,
    translucent_objects,
)
from translucent.reference.mitsuba_scene import convert_scene  # noqa: E402
from translucent.scenes import Camera, PointLight, Scene, SceneObject  # noqa: E402
from translucent.scenes.meshes import icosphere  # noqa: E402

#: Largest accepted |z| of a summed difference (two-sided p of 6e-5).
GLOBAL_Z = 4.0

#: Two media at eta 1.3: about 1 mm mean free path, and a tenth of it absorbing less (its
#: profile narrower near the entry, as far-reaching): different enough that the two rules
#: render the boundary differently beyond the fast tier's noise.
FIRST = Dipole(sigma_a=[0.05, 0.1, 0.2], sigma_s_prime=[1.0, 1.0, 1.0], eta=1.3, g=0.0,
               name="first")
SECOND = Dipole(sigma_a=[0.01, 0.02, 0.05], sigma_s_prime=[10.0, 10.0, 10.0], eta=1.3, g=0.0,
                name="second")


@pytest.fixture(scope="module")
def mi(bssrdf_mi):
    return bssrdf_mi


def _halves(first: Dipole, second: Dipole, cells: int = 8) -> SolidMedium:
    """The unit sphere's box, ``first`` where x < 0 and ``second`` where x > 0 (scene units)."""
    shape = (cells, cells, cells, 3)
    x = (np.arange(cells) + 0.5) / cells * 2.0 - 1.0
    right = (x > 0)[None, None, :, None]
    return SolidMedium(sigma_a=np.where(right, second.sigma_a, first.sigma_a) * np.ones(shape),
                       sigma_s_prime=np.where(right, second.sigma_s_prime,
                                              first.sigma_s_prime) * np.ones(shape),
                       bounds=np.array([[-1.05] * 3, [1.05] * 3]), eta=first.eta,
                       name="halves")


def _sphere_scene(material, size):
    camera = Camera(origin=[0.0, 0.0, 5.0], target=[0.0, 0.0, 0.0], up=[0.0, 1.0, 0.0],
                    fov=30.0, width=size, height=size)
    light = PointLight(position=[3.0, 4.0, 4.0], intensity=100.0)
    return Scene([SceneObject("sphere", icosphere(4, 1.0), material)], [light], camera,
                 mm_per_unit=10.0, name="sphere")


def _render(mi, scene, key, spp, passes, seed=0):
    conversion = convert_scene(scene, integrator="bssrdf_path", profile=key)
    loaded = mi.load_dict(conversion.scene_dict)
    return np.array([np.array(mi.render(loaded, spp=spp, seed=seed + k))[..., :3]
                     for k in range(passes)], dtype=np.float64)


# ---------------------------------------------------------------- 1. the homogeneous limit
@pytest.mark.parametrize("rule", [None, *HETEROGENEOUS_RULES])
def test_a_uniform_solid_medium_renders_as_its_dipole_bit_for_bit(mi, rule):
    uniform = _halves(FIRST, FIRST)
    key = "dipole" if rule is None else f"dipole+{rule}"
    solid = _render(mi, _sphere_scene(uniform, 8), key, 16, 1)
    homogeneous = _render(mi, _sphere_scene(uniform.dipole(), 8), "dipole", 16, 1)
    assert solid.max() > 0
    assert np.array_equal(solid, homogeneous)


def test_two_media_a_millionth_apart_render_as_one_by_the_geometric_mean(mi):
    # segment_mix does not reduce so: across a boundary between equal media Eq. 16 gives
    # S(f_1 r) S(f_2 r) / S(0), not S(r) (its device values are checked against
    # mixed_profile below; docs/heterogeneous.md measures the difference)
    close = Dipole(FIRST.sigma_a * (1 + 1e-6), FIRST.sigma_s_prime, eta=FIRST.eta, g=0.0)
    mixed = _render(mi, _sphere_scene(_halves(FIRST, close), 8), "dipole+geometric_mean", 64,
                    1)
    homogeneous = _render(mi, _sphere_scene(FIRST, 8), "dipole", 64, 1)
    # the same random numbers: the rule's code, not the noise, is what could differ
    total = mixed.sum(axis=(0, 1, 2)), homogeneous.sum(axis=(0, 1, 2))
    assert np.allclose(total[0], total[1], rtol=1e-3), total


# ------------------------------------------------------- 2. the rules' values, reciprocity
def _lookup_values(mi, tables, pairs_entry, pairs_exit, r):
    import drjit as dr
    from translucent.reference.bssrdf_profile import ProfileLookup

    lookup = ProfileLookup(tables)

    def points(values):
        return mi.Point3f(*[mi.Float(values[:, a].astype(np.float32)) for a in range(3)])

    count = len(r)
    value = lookup.mixed_reflectance(mi.UInt32(np.zeros(count, np.uint32)),
                                     points(pairs_exit), points(pairs_entry),
                                     mi.Float(r.astype(np.float32)), mi.Bool(True))
    dr.eval(value)
    return np.stack([np.array(value[c]) for c in range(3)], axis=-1).astype(np.float64)


@pytest.mark.parametrize("rule", list(HETEROGENEOUS_RULES))
def test_the_rules_on_the_device_are_the_materials_own_and_reciprocal(mi, rule):
    solid = _halves(FIRST, SECOND)
    scene = _sphere_scene(solid, 8)
    found = translucent_objects(scene, "dipole", ["sphere"], rule=rule)
    tables = build_tables(found, scene.mm_per_unit)
    rng = np.random.default_rng(3)
    directions = rng.normal(size=(2, 400, 3))
    entry, exit_ = directions / np.linalg.norm(directions, axis=-1, keepdims=True)
    r = np.linalg.norm(exit_ - entry, axis=-1) * scene.mm_per_unit
    forward = _lookup_values(mi, tables, entry, exit_, r)
    backward = _lookup_values(mi, tables, exit_, entry, r)
    assert np.allclose(forward, backward, rtol=1e-5, atol=0), "not reciprocal"
    # numpy: the media as quantised, each profile's own evaluation, the rule's function
    quantised = quantise_media(solid, solid.voxel_centres(), max_media=RULE_MAX_MEDIA[rule])
    labels = quantised.labels.reshape(solid.shape)
    media = [profile("dipole", medium) for medium in quantised.media]

    def label(points):
        return labels[solid.voxel_index(points)]

    at = np.stack([m.reflection(r) for m in media], axis=-2)  # (N, M, 3)
    if rule == "geometric_mean":
        rows = np.arange(len(r))
        expected = geometric_mean_profile(at[rows, label(entry)], at[rows, label(exit_)])
    else:
        t = (np.arange(SEGMENT_POINTS) + 0.5) / SEGMENT_POINTS
        along = entry[:, None] + (exit_ - entry)[:, None] * t[None, :, None]
        counts = np.stack([(label(along) == m).sum(axis=1) for m in range(len(media))], -1)
        fractions = counts / SEGMENT_POINTS
        if rule == "segment_average":
            expected = segment_average_profile(
                np.stack([m.sigma_a for m in quantised.media]),
                np.stack([m.sigma_s_prime for m in quantised.media]), fractions, r,
                solid.eta)
        else:
            zero = np.stack([m.reflection(np.zeros(1))[0] for m in media])
            partial = np.stack([m.reflection(fractions[:, k] * r)
                                for k, m in enumerate(media)], axis=-2)
            expected = mixed_profile(zero, partial, fractions)
    # both rules' values are cut where the object's probe balls end (every medium's reach)
    cut = max(m.radius_containing(PROBE_ENERGY_FRACTION).max() for m in media)
    expected = np.where((r <= cut)[:, None], expected, 0.0)
    crossing = label(entry) != label(exit_)
    assert crossing.sum() > 50  # the pairs put both media to work
    # the tables' interpolation of each profile (test_bssrdf_path: under 1e-3), in float32
    assert np.allclose(forward, expected, rtol=3e-3, atol=1e-6 * expected.max())


# ----------------------------------------------------------------- 3. the surface integral
def _rule_values(solid, rule, name):
    """``pair_values`` and ``exit_profile`` of ``sphere_radiance`` for ``rule`` (numpy)."""
    quantised = quantise_media(solid, solid.voxel_centres(), max_media=RULE_MAX_MEDIA[rule])
    labels = quantised.labels.reshape(solid.shape)
    media = [profile(name, medium, radial=True) for medium in quantised.media]

    def label(points):
        return labels[solid.voxel_index(points)]

    def pair_values(xo, xi, r):
        at = np.stack([m.reflection(r) for m in media], axis=-2)  # (K, P, M, 3)
        k, p = np.indices(r.shape)
        if rule == "geometric_mean":
            return geometric_mean_profile(at[k, p, label(xi)[None, :]],
                                          at[k, p, label(xo)[:, None]])
        # the medium is two halves split at x = 0 (a voxel face): a midpoint's label is its
        # side, so the fractions are counts of midpoints with x > 0 (no voxel lookups)
        t = (np.arange(SEGMENT_POINTS) + 0.5) / SEGMENT_POINTS
        right = np.zeros(r.shape)
        for step in t:
            right += (xi[None, :, 0] + (xo[:, None, 0] - xi[None, :, 0]) * step) > 0
        sides = label(np.array([[-0.5, 0.0, 0.0], [0.5, 0.0, 0.0]]))
        fractions = np.zeros(r.shape + (len(media),))
        fractions[..., sides[1]] = right / SEGMENT_POINTS
        fractions[..., sides[0]] += 1.0 - right / SEGMENT_POINTS
        if rule == "segment_average":
            return segment_average_profile(
                np.stack([m.sigma_a for m in quantised.media]),
                np.stack([m.sigma_s_prime for m in quantised.media]), fractions, r, solid.eta)
        zero = np.stack([m.reflection(np.zeros(1))[0] for m in media])
        partial = np.stack([m.reflection(fractions[..., j] * r) for j, m in enumerate(media)],
                           axis=-2)
        return mixed_profile(zero, partial, fractions)

    return media, pair_values


_RENDERS: dict = {}


def _two_media_passes(mi, rule, size, spp, passes):
    """The two-media sphere's passes by ``rule`` (kept: two tests read the fast tier's)."""
    key = (rule, size, spp, passes)
    if key not in _RENDERS:
        _RENDERS[key] = _render(mi, _sphere_scene(_halves(FIRST, SECOND), size),
                                f"dipole+{rule}", spp, passes)
    return _RENDERS[key]


def _surface_integral_check(mi, rule, size, spp, passes, subdivide, supersample):
    solid = _halves(FIRST, SECOND)
    scene = _sphere_scene(solid, size)
    images = _two_media_passes(mi, rule, size, spp, passes)
    media, pair_values = _rule_values(solid, rule, "dipole")
    cut = max(m.radius_containing(PROBE_ENERGY_FRACTION).max() for m in media)
    expected, coverage = bssrdf_checks.sphere_radiance(
        scene, 0, [m.reflection for m in media], solid.eta, scene.lights[0], subdivide,
        supersample, cut, pair_values=pair_values)
    bssrdf_checks.assert_images_match_quadrature(images, expected, coverage,
                                                 global_z=GLOBAL_Z)


@pytest.mark.parametrize("rule", [
    "geometric_mean",
    pytest.param("segment_mix", marks=pytest.mark.slow),  # 8 s; geometric_mean stays fast
    pytest.param("segment_average", marks=pytest.mark.slow)])  # no method's: slow tier
def test_a_two_media_sphere_is_the_surface_integral_of_the_rule(mi, rule):
    _surface_integral_check(mi, rule, 8, 256, 16, 2, 4)


@pytest.mark.slow
@pytest.mark.parametrize("rule", list(HETEROGENEOUS_RULES))
def test_a_two_media_sphere_is_the_surface_integral_of_the_rule_converged(mi, rule):
    _surface_integral_check(mi, rule, 16, 1024, 16, 4, 4)


def test_the_methods_rules_render_differently(mi):
    from translucent.image import Image
    from translucent.reports.metrics.statistics import z_test_known_variance

    images = [_two_media_passes(mi, rule, 8, 256, 16)
              for rule in ("geometric_mean", "segment_mix")]
    means = [Image(p.mean(axis=0), p.var(axis=0, ddof=1) / len(p)) for p in images]
    result = z_test_known_variance(*means, passes=(16, 16))
    assert not result.passed, result.summary()


def test_segment_average_takes_the_dipole_alone():
    scene = _sphere_scene(_halves(FIRST, SECOND), 8)
    with pytest.raises(InputError, match="classical dipole"):
        translucent_objects(scene, "better_dipole", ["sphere"], rule="segment_average")


# ------------------------------------------------------------------------------ refusals
def test_a_heterogeneous_medium_without_a_rule_is_refused_with_the_rules():
    scene = _sphere_scene(_halves(FIRST, SECOND), 8)
    with pytest.raises(InputError, match="segment_mix") as error:
        convert_scene(scene, integrator="bssrdf_path", profile="dipole")
    assert error.value.field == "objects[0].material"


def test_an_unknown_rule_is_an_unknown_profile():
    scene = _sphere_scene(_halves(FIRST, SECOND), 8)
    with pytest.raises(InputError, match="unknown profile"):
        convert_scene(scene, integrator="bssrdf_path", profile="dipole+nearest")


def test_a_directional_profile_is_refused_for_a_heterogeneous_object():
    scene = _sphere_scene(_halves(FIRST, SECOND), 8)
    with pytest.raises(InputError, match="incident direction"):
        translucent_objects(scene, "directional_dipole", ["sphere"], rule="geometric_mean")
