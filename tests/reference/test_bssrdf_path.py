"""bssrdf_path shown correct three independent ways, and its place in the reference.

0. Its tables: the profile it renders is each profile's own to a stated tolerance, and the
   exit term is normalised.
1. A large flat slab under a narrow spot beam, seen straight down: annulus by annulus the
   radiance equals the profile convolved with the beam's entering irradiance, times the
   exit term (``bssrdf_checks.slab_exitance``, a numpy quadrature).
2. A sphere under a point light: per pixel, a brute-force quadrature of the same BSSRDF
   over the mesh's surface with the same light and shadows (``bssrdf_checks``).
3. With the photon random walk's own table as the profile, a thick slab lit by a diffuse
   disk and seen straight down gives ``volpath``'s image of the medium: by reciprocity the
   radiance leaving a point along the normal under diffuse light is the exitance that a
   normal beam at that point gives, which is what the table holds.

The fast tier renders each with a few thousand samples per pixel region; the ``slow`` tier
with enough to resolve a 2 % difference.
"""

from __future__ import annotations

import math

import bssrdf_checks
import numpy as np
import pytest
from translucent.errors import InputError
from translucent.materials import Dipole
from translucent.materials.profiles import PROFILE_NAMES, profile

mi_module = pytest.importorskip("mitsuba")

from translucent.reference.bssrdf_tables import (  # noqa: E402
    PROBE_ENERGY_FRACTION,
    build_tables,
    translucent_objects,
)
from translucent.reference.mitsuba_scene import convert_scene  # noqa: E402
from translucent.scenes import Camera, Scene, SceneObject, SpotLight  # noqa: E402
from translucent.scenes.meshes import slab  # noqa: E402

#: Largest accepted |z| of an annulus's or a summed difference (two-sided p of 6e-5).
GLOBAL_Z = 4.0

#: The tables against each profile's own evaluation, inside the radius holding 99.9 % of
#: a channel's energy, relative to the profile's largest value there: the density's
#: linear interpolation between nodes a log-step of 0.0068 apart (measured up to 2e-4).
TABLE_TOLERANCE = 1e-3

#: A medium of about 1 mm mean free path, absorbing more in blue, at eta 1.3.
MEDIUM = Dipole(sigma_a=[0.05, 0.1, 0.2], sigma_s_prime=[1.0, 1.0, 1.0], eta=1.3,
                name="test medium")


@pytest.fixture(scope="module")
def mi(bssrdf_mi):
    return bssrdf_mi


def _camera():
    return Camera(origin=[0.0, 100.0, 0.0], target=[0.0, 0.0, 0.0], up=[0.0, 0.0, -1.0],
                  fov=10.0, width=8, height=8)


def _slab_scene(material, lights, half_width=40.0, thickness=30.0):
    mesh = slab(2 * half_width, 2 * half_width, thickness, center=(0.0, -thickness / 2, 0.0),
                subdivisions=8)
    return Scene([SceneObject("slab", mesh, material)], lights, _camera(), mm_per_unit=1.0,
                 name="slab")


def _orthographic(mi, frame, extent, size, spp=16):
    """A sensor looking straight down on y = 0, seeing [-extent, extent]^2 (mm of the scene,
    put in the conversion's ``frame``)."""
    transform = mi.ScalarTransform4f
    to_world = transform(frame.matrix()) \
        @ transform().look_at(origin=[0.0, 20.0, 0.0], target=[0.0, 0.0, 0.0],
                              up=[0.0, 0.0, 1.0]) \
        @ transform().scale([extent, extent, 1.0])
    return {"type": "orthographic", "to_world": to_world,
            "film": {"type": "hdrfilm", "width": size, "height": size,
                     "rfilter": {"type": "box"}},
            "sampler": {"type": "independent", "sample_count": spp}}


def _pixel_positions(mi, scene, frame, size, supersample=4):
    """(x, z) of ``supersample``^2 points in each pixel, (size, size, S, 2), from the sensor
    (in the scene's units: ``frame`` is the conversion's)."""
    offsets = (np.arange(supersample) + 0.5) / supersample
    u = ((np.arange(size)[:, None] + offsets[None, :]) / size).ravel()
    sx, sy = np.meshgrid(u, u)
    sensor = scene.sensors()[0]
    rays, _ = sensor.sample_ray(0.0, 0.5, mi.Point2f(sx.ravel(), sy.ravel()), mi.Point2f(0.5))
    origins = frame.to_scene(np.stack([np.array(rays.o.x), np.array(rays.o.y),
                                       np.array(rays.o.z)], axis=-1))
    positions = origins[:, [0, 2]]
    positions = positions.reshape(size, supersample, size, supersample, 2)
    return positions.transpose(0, 2, 1, 3, 4).reshape(size, size, -1, 2)


def _passes(mi, scene, spp, passes, seed=0):
    """Each pass's image, float64 (passes, H, W, 3)."""
    return np.array([np.array(mi.render(scene, spp=spp, seed=seed + k))[..., :3]
                     for k in range(passes)], dtype=np.float64)


# --------------------------------------------------------------------------- 0. tables
@pytest.mark.parametrize("name", PROFILE_NAMES)
def test_the_tables_hold_each_profile(name):
    scene = _slab_scene(MEDIUM, [])
    objects = translucent_objects(scene, name, ["object_slab"])
    tables = build_tables(objects, 1.0)
    radial = objects[0].profile
    reach = radial.radius_containing(0.999)
    for c in range(3):
        r = np.geomspace(1e-4 * reach[c], reach[c], 2000)
        expected = radial.reflection(r)[:, c]
        got = tables.reflectance(0, r)[:, c]
        error = np.abs(got - expected).max() / expected.max()
        assert error < TABLE_TOLERANCE, (name, c, error)
    assert np.all(tables.max_radius >= reach)


def test_the_device_lookups_read_the_tables(mi):
    import drjit as dr
    from translucent.reference.bssrdf_profile import ProfileLookup

    scene = _slab_scene(MEDIUM, [])
    tables = build_tables(translucent_objects(scene, "better_dipole", ["object_slab"]), 1.0)
    lookup = ProfileLookup(tables)
    for c in range(3):
        reach = tables.max_radius[c]
        r = np.geomspace(1e-6 * reach, reach, 5000)
        got = np.array(lookup.density_at(mi.UInt32(c), mi.Float(r), mi.Bool(True)))
        expected = np.interp(r, tables.radius[c], tables.density[c])
        assert np.abs(got - expected).max() < 1e-5 * tables.density[c].max()
        # sampled radii follow the table's own inverse CDF: quantiles agree to float32's
        # resolution of the cumulative (worst in the last 1e-4 of the energy)
        u = (np.arange(20000) + 0.5) / 20000
        sampled = np.array(lookup.sample_radius(mi.UInt32(c), mi.Float(u), mi.Bool(True)))
        own = profile("better_dipole", MEDIUM).sample_radius(u, c)
        assert np.abs(sampled / own - 1.0).max() < 1e-3
    dr.eval()


def test_the_exit_term_is_normalised():
    # its cosine-weighted integral over the outside hemisphere is 1
    from translucent.reference.bssrdf_tables import exit_normalisation

    for eta in (1.0, 1.3, 1.5):
        assert abs(exit_normalisation(eta) / bssrdf_checks.exit_normalisation(eta) - 1) < 1e-6


# --------------------------------------------------------------------------- 1. the slab
SPOT = SpotLight(position=[0.0, 50.0, 0.0], direction=[0.0, -1.0, 0.0], intensity=2500.0,
                 cutoff_angle=1.5, beam_width=1.0)


def _slab_check(mi, name, size, extent, spp, passes, edges, resolution=0.05):
    scene = _slab_scene(MEDIUM, [SPOT])
    conversion = convert_scene(scene, integrator="bssrdf_path", profile=name)
    mitsuba_scene = mi.load_dict({**conversion.scene_dict,
                                  "sensor": _orthographic(mi, conversion.frame, extent,
                                                                      size)})
    images = _passes(mi, mitsuba_scene, spp, passes)
    positions = _pixel_positions(mi, mitsuba_scene, conversion.frame, size)
    rho = np.linalg.norm(positions, axis=-1)  # (size, size, S)
    radial = profile(name, MEDIUM, radial=True)
    reach = radial.radius_containing(PROBE_ENERGY_FRACTION).max()
    grid = np.linspace(0.0, rho.max() * 1.001, 64)
    exitance = bssrdf_checks.slab_exitance(grid, radial, SPOT, MEDIUM.eta, reach)
    expected = np.stack([np.interp(rho, grid, exitance[:, c]) for c in range(3)], -1)
    expected = expected.mean(axis=2) * bssrdf_checks.exit_term(1.0, MEDIUM.eta)
    centre = np.linalg.norm(positions.mean(axis=2), axis=-1)
    annulus = np.digitize(centre, edges) - 1
    for k in range(len(edges) - 1):
        inside = annulus == k
        assert inside.sum() >= 4
        per_pass = images[:, inside].mean(axis=1)  # (passes, 3)
        mean = per_pass.mean(axis=0)
        error = per_pass.std(axis=0, ddof=1) / math.sqrt(passes)
        target = expected[inside].mean(axis=0)
        z = (mean - target) / error
        assert np.abs(z).max() < GLOBAL_Z, (k, mean / target, z)
    # and the test can tell a wrong normalisation
    total = images.mean(axis=(1, 2))
    error = total.std(axis=0, ddof=1) / math.sqrt(passes)
    assert (resolution * expected.mean(axis=(0, 1)) / error).min() > GLOBAL_Z


def test_a_slab_under_a_beam_gives_the_profile(mi):
    _slab_check(mi, "better_dipole", 16, 4.0, 256, 16, [0.0, 0.5, 1.0, 2.0, 3.0, 4.5])


@pytest.mark.slow
@pytest.mark.parametrize("name", ["photon_beam_diffusion", "burley_dmfp", "random_walk",
                                  "directional_dipole"])
def test_a_slab_under_a_beam_gives_the_profile_converged(mi, name):
    _slab_check(mi, name, 32, 4.0, 1024, 16, [0.0, 0.25, 0.5, 0.75, 1.0, 1.5, 2.0, 2.5, 3.0,
                                              4.0, 5.0], resolution=0.02)


# --------------------------------------------------------------------------- 2. the sphere
def _sphere_scene(material, size, subdivisions=4):
    from translucent.scenes import PointLight
    from translucent.scenes.meshes import icosphere

    camera = Camera(origin=[0.0, 0.0, 5.0], target=[0.0, 0.0, 0.0], up=[0.0, 1.0, 0.0],
                    fov=30.0, width=size, height=size)
    light = PointLight(position=[3.0, 4.0, 4.0], intensity=100.0)
    return Scene([SceneObject("sphere", icosphere(subdivisions, 1.0), material)], [light],
                 camera, mm_per_unit=10.0, name="sphere")


def _sphere_check(mi, name, size, spp, passes, subdivide, supersample):
    scene = _sphere_scene(MEDIUM, size)
    conversion = convert_scene(scene, integrator="bssrdf_path", profile=name)
    images = _passes(mi, mi.load_dict(conversion.scene_dict), spp, passes)
    radial = profile(name, MEDIUM, radial=True)
    cut = radial.radius_containing(PROBE_ENERGY_FRACTION).max()
    expected, coverage = bssrdf_checks.sphere_radiance(
        scene, 0, radial.reflection, MEDIUM.eta, scene.lights[0], subdivide, supersample, cut)
    return bssrdf_checks.assert_images_match_quadrature(images, expected, coverage,
                                                        global_z=GLOBAL_Z)


def test_a_sphere_under_a_point_light_is_the_surface_integral(mi):
    _sphere_check(mi, "better_dipole", 8, 256, 16, 3, 4)


@pytest.mark.slow
@pytest.mark.parametrize("name", ["dipole", "quantized_diffusion", "burley_cycles"])
def test_a_sphere_under_a_point_light_is_the_surface_integral_converged(mi, name):
    _sphere_check(mi, name, 24, 1024, 16, 4, 4)


# --------------------------------------------------------------------------- 3. the walk
#: Isotropic scattering (the walk table's), one extinction of 1 mm^-1 in every channel (so
#: that volpath's free flights weigh no channel against another), eta 1.3.
WALK_MEDIUM = Dipole(sigma_a=[0.02, 0.05, 0.1], sigma_s_prime=[0.98, 0.95, 0.9], eta=1.3,
                     g=0.0, name="walk medium")

#: Height of the lighting disk above the slab (mm): the incident radiance is uniform over
#: every direction at the points below it but for a band of this width at its edge.
DISK_HEIGHT = 0.01


def _disk_lit_slab(mi, integrator, profile_name, size, extent, radius=2.0):
    from translucent.scenes import PointLight

    # the point light only makes the scene whole; the disk replaces it below
    scene = _slab_scene(WALK_MEDIUM, [PointLight(position=[0.0, 50.0, 0.0], intensity=1.0)],
                        half_width=30.0, thickness=30.0)
    conversion = convert_scene(scene, integrator=integrator, profile=profile_name)
    entries = {k: v for k, v in conversion.scene_dict.items() if not k.startswith("light_")}
    transform = mi.ScalarTransform4f()
    # a disk facing down that lets every ray through (null BSDF): the camera sees the slab
    entries["disk"] = {
        "type": "disk",
        "to_world": mi.ScalarTransform4f(conversion.frame.matrix())
        @ transform.translate([0.0, DISK_HEIGHT, 0.0])
        @ transform.rotate([1.0, 0.0, 0.0], 90.0) @ transform.scale(radius),
        "emitter": {"type": "area", "radiance": {"type": "rgb", "value": [1.0, 1.0, 1.0]}},
        "bsdf": {"type": "null"}}
    entries["sensor"] = _orthographic(mi, conversion.frame, extent, size)
    return mi.load_dict(entries)


def _walk_check(mi, size, spp_bssrdf, spp_volpath, passes, resolution=0.05):
    from translucent.image import Image
    from translucent.reports.metrics.statistics import z_test_known_variance

    first = _passes(mi, _disk_lit_slab(mi, "bssrdf_path", "random_walk", size, 4.0),
                    spp_bssrdf, passes)
    second = _passes(mi, _disk_lit_slab(mi, "volpath", None, size, 4.0), spp_volpath, passes,
                     seed=1000)
    means = first.mean(axis=0), second.mean(axis=0)
    variances = first.var(axis=0, ddof=1) / passes, second.var(axis=0, ddof=1) / passes
    result = z_test_known_variance(Image(means[0], variances[0]), Image(means[1], variances[1]),
                                   passes=(passes, passes))
    assert result.passed, result.summary()
    spread = np.sqrt((variances[0] + variances[1]).sum(axis=(0, 1)))
    z = (means[0] - means[1]).sum(axis=(0, 1)) / spread
    assert np.abs(z).max() < GLOBAL_Z, (z, means[0].sum(axis=(0, 1)) / means[1].sum(axis=(0, 1)))
    # the far field too: the pixels outside the disk, where only the profile's tail is lit
    outside = np.linalg.norm(np.stack(np.meshgrid(*[np.linspace(-1, 1, size)] * 2), -1),
                             axis=-1) * 4.0 > 2.5
    far = (means[0] - means[1])[outside].sum(axis=0) / np.sqrt(
        (variances[0] + variances[1])[outside].sum(axis=0))
    assert np.abs(far).max() < GLOBAL_Z, far
    assert (resolution * means[1].sum(axis=(0, 1)) / spread).min() > GLOBAL_Z, \
        f"too noisy to tell {resolution:.0%}"


def test_with_the_walk_table_it_gives_what_volpath_gives(mi):
    _walk_check(mi, 12, 128, 128, 8)


@pytest.mark.slow
def test_with_the_walk_table_it_gives_what_volpath_gives_converged(mi):
    _walk_check(mi, 24, 1024, 1024, 16, resolution=0.02)


# --------------------------------------------------------------------------- other lights
def _uniform_light_check(mi, light, expected_factor, spp=64, passes=8, size=8):
    """A slab under light uniform over its top, seen straight down: a closed-form radiance."""
    from translucent.image import Image
    from translucent.reports.metrics.statistics import z_test_known_variance

    conversion = convert_scene(_slab_scene(MEDIUM, [light]), integrator="bssrdf_path",
                               profile="better_dipole")
    sensor = _orthographic(mi, conversion.frame, 4.0, size)
    scene = mi.load_dict({**conversion.scene_dict, "sensor": sensor})
    images = _passes(mi, scene, spp, passes)
    total = profile("better_dipole", MEDIUM).total()
    expected = np.broadcast_to(expected_factor(total), images.shape[1:])
    mean, variance = images.mean(axis=0), images.var(axis=0, ddof=1) / passes
    result = z_test_known_variance(Image(mean, variance), Image(expected, np.zeros_like(mean)),
                                   passes=(passes, None))
    assert result.passed, result.summary()
    z = (mean - expected).sum(axis=(0, 1)) / np.sqrt(variance.sum(axis=(0, 1)))
    assert np.abs(z).max() < GLOBAL_Z, (z, mean.mean(axis=(0, 1)) / expected[0, 0])
    resolved = 0.05 * expected.sum(axis=(0, 1)) / np.sqrt(variance.sum(axis=(0, 1)))
    assert resolved.min() > GLOBAL_Z, "too noisy to tell 5 %"


def test_a_constant_environment_gives_the_total_reflectance(mi):
    # L = L0 (F_r(1) + F_t(1) E): the exit term's normalisation cancels pi (1 - F_dr)
    from translucent.scenes import ConstantEnvironment

    reflect = bssrdf_checks.fresnel(1.0, MEDIUM.eta)
    _uniform_light_check(mi, ConstantEnvironment(1.0),
                         lambda total: reflect + (1.0 - reflect) * total)


@pytest.mark.parametrize("degrees", [0.0, 50.0])
def test_a_directional_light_gives_the_total_reflectance(mi, degrees):
    # L = S_w(normal) F_t(cos theta) E cos theta total: no specular reflection is seen
    from translucent.scenes import DirectionalLight

    theta = math.radians(degrees)
    light = DirectionalLight(direction=[math.sin(theta), -math.cos(theta), 0.0],
                             irradiance=2.0)
    entering = 2.0 * math.cos(theta) * (1.0 - bssrdf_checks.fresnel(math.cos(theta),
                                                                     MEDIUM.eta))
    _uniform_light_check(mi, light, lambda total: bssrdf_checks.exit_term(1.0, MEDIUM.eta)
                         * entering * total)


# --------------------------------------------------------------------------- every profile
@pytest.mark.parametrize("name", PROFILE_NAMES)
def test_every_profile_renders(mi, name):
    scene = _sphere_scene(MEDIUM, 8, subdivisions=3)
    conversion = convert_scene(scene, integrator="bssrdf_path", profile=name)
    image = np.array(mi.render(mi.load_dict(conversion.scene_dict), spp=16))[..., :3]
    assert np.isfinite(image).all()
    assert (image >= 0).all()
    assert image[..., 0].max() > 0 and image[..., 2].max() > 0
    assert conversion.profile["name"] == name
    assert set(conversion.profile["objects"]) == {"sphere"}


def test_the_directional_dipole_is_evaluated_with_each_incident_direction(mi):
    # on a plane, the device's closed form is the profile's own evaluate(x, y) at every angle
    from translucent.materials.profiles import DirectionalDipoleProfile
    from translucent.reference.bssrdf_profile import ProfileLookup

    scene = _slab_scene(MEDIUM, [])
    objects = translucent_objects(scene, "directional_dipole", ["object_slab"])
    lookup = ProfileLookup(build_tables(objects, 1.0))
    rng = np.random.default_rng(7)
    x, y = rng.uniform(-3.0, 3.0, (2, 400))
    for degrees in (0.0, 30.0, 60.0, 80.0):
        theta = math.radians(degrees)
        # light from -x, above the plane z = 0 of normal +z
        wi = np.array([-math.sin(theta), 0.0, math.cos(theta)])
        d = mi.Vector3f(x, y, np.zeros_like(x))
        got = np.array(lookup.directional_reflectance(
            mi.UInt32(0), d, mi.Vector3f(0.0, 0.0, 1.0), mi.Vector3f(*map(float, wi)),
            mi.Float(MEDIUM.eta), mi.Bool(True))).T  # (channels, N) -> (N, channels)
        expected = DirectionalDipoleProfile(MEDIUM, theta).evaluate(x, y)
        scale = np.abs(expected).max(axis=0)
        assert np.abs(got - expected).max(axis=0).max() < 1e-4 * scale.max(), degrees


# --------------------------------------------------------------------------- bad input
def test_an_unknown_profile_is_refused_with_the_valid_ones():
    with pytest.raises(InputError, match="unknown profile; valid: dipole") as error:
        convert_scene(_sphere_scene(MEDIUM, 8), integrator="bssrdf_path", profile="dipol")
    assert error.value.field == "profile" and error.value.value == "dipol"


def test_a_profile_goes_with_bssrdf_path_and_bssrdf_path_needs_one():
    scene = _sphere_scene(MEDIUM, 8)
    with pytest.raises(InputError, match="needs a profile"):
        convert_scene(scene, integrator="bssrdf_path")
    with pytest.raises(InputError, match="goes with integrator bssrdf_path"):
        convert_scene(scene, integrator="volpath", profile="dipole")


def test_an_open_translucent_mesh_is_refused():
    from translucent.scenes import Mesh, PointLight

    vertices = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [1.0, 0.0, -1.0]])
    faces = np.array([[0, 1, 2], [1, 3, 2]])
    sheet = Mesh(vertices, faces, name="sheet")
    scene = Scene([SceneObject("sheet", sheet, MEDIUM)],
                  [PointLight(position=[0.0, 5.0, 0.0], intensity=1.0)], _camera(),
                  source="sheet.toml")
    with pytest.raises(InputError, match="probe rays") as error:
        convert_scene(scene, integrator="bssrdf_path", profile="dipole")
    assert error.value.field == "objects[0].mesh" and error.value.file == "sheet.toml"


def test_a_profile_that_refuses_the_medium_names_the_object():
    # the walk table covers eta 1 to 2
    dense = Dipole(sigma_a=[0.1] * 3, sigma_s_prime=[1.0] * 3, eta=2.5)
    with pytest.raises(InputError, match="refuses this medium") as error:
        convert_scene(_sphere_scene(dense, 8), integrator="bssrdf_path", profile="random_walk")
    assert error.value.field == "objects[0].material"


def test_a_profile_that_is_not_radial_is_refused(monkeypatch):
    from translucent.materials.profiles import registry

    class Anisotropic:
        directional = True
        model = "anisotropic"
        name = "anisotropic"

    entry = registry.ProfileEntry(lambda medium: Anisotropic(), "a test", directional=True)
    monkeypatch.setitem(registry.PROFILES, "anisotropic", entry)
    monkeypatch.setattr("translucent.reference.bssrdf_tables.PROFILE_NAMES",
                        (*PROFILE_NAMES, "anisotropic"))
    with pytest.raises(InputError, match="radial") as error:
        translucent_objects(_sphere_scene(MEDIUM, 8), "anisotropic", ["object_sphere"])
    assert "objects[0].material" in error.value.field


def test_a_heterogeneous_medium_is_refused():
    from translucent.reference.mitsuba_scene import MaterialParts, register_material_converter

    class Cloud:
        def cache_key(self):
            return {"type": "cloud"}

    register_material_converter(Cloud, lambda material, context: MaterialParts(
        {"type": "null"}, {"type": "homogeneous"}))
    scene = Scene([SceneObject("cloud", _sphere_scene(MEDIUM, 8).objects[0].mesh, Cloud())],
                  _sphere_scene(MEDIUM, 8).lights, _camera())
    with pytest.raises(InputError, match="radial profile") as error:
        convert_scene(scene, integrator="bssrdf_path", profile="dipole")
    assert error.value.field == "objects[0].material"
