"""Scene -> Mitsuba conversion: coefficients, boundaries, integrators, lights, substitutions."""

import dataclasses
import math

import numpy as np
import pytest
from translucent.backend import mitsuba
from translucent.errors import InputError
from translucent.materials import Dipole, Lambertian, measured_medium
from translucent.reference import (
    MaterialParts,
    convert_scene,
    register_material_converter,
    to_mitsuba_dict,
)
from translucent.reference.delta_lights import (
    EnvironmentParts,
    lat_long_directions,
    nearest_surface_distance,
)
from translucent.reference.mitsuba_scene import NO_RUSSIAN_ROULETTE
from translucent.scenes import (
    Camera,
    ConstantEnvironment,
    DirectionalLight,
    ImageEnvironment,
    PointLight,
    RectangularAreaLight,
    Scene,
    SceneObject,
    SphereAreaLight,
    SpotLight,
    icosphere,
)

#: Mitsuba stores colours and scales in float32: 1e-6 relative is its rounding.
FLOAT32_RTOL = 1e-6

CAMERA = Camera(origin=[0, 0, 4], target=[0, 0, 0], fov=40, width=8, height=6)


def _scene(material, lights=None, mm_per_unit=1.0):
    lights = (ConstantEnvironment(1.0),) if lights is None else lights
    return Scene((SceneObject("ball", icosphere(1), material),), lights, CAMERA,
                 mm_per_unit=mm_per_unit)


def _loaded(scene, **options):
    return mitsuba().load_dict(to_mitsuba_dict(scene, **options))


def _param(params, suffix):
    (key,) = [k for k in params.keys() if k.endswith(suffix)]
    return params[key]


def _rgb(value):
    return np.array(value, dtype=np.float64).ravel()


# ------------------------------------------------------------------------ materials


def test_dipole_medium_is_per_scene_unit():
    material = Dipole(sigma_a=[0.01, 0.02, 0.04], sigma_s_prime=[1.0, 2.0, 3.0], eta=1.3, g=0.5)
    mm_per_unit = 7.0
    scene = _scene(material, mm_per_unit=mm_per_unit)
    params = mitsuba().traverse(_loaded(scene))
    scale = float(_param(params, "interior_medium.scale"))
    sigma_t_rgb = _rgb(_param(params, "interior_medium.sigma_t.value.value"))
    albedo = _rgb(_param(params, "interior_medium.albedo.value.value"))
    sigma_s = material.sigma_s_prime / (1 - material.g)
    # per unit of the rendering frame: frame_scale of them to a scene unit
    frame_scale = convert_scene(scene).frame.scale
    expected_sigma_t = (material.sigma_a + sigma_s) * mm_per_unit / frame_scale
    np.testing.assert_allclose(scale * sigma_t_rgb, expected_sigma_t, rtol=FLOAT32_RTOL)
    np.testing.assert_allclose(albedo, sigma_s / (material.sigma_a + sigma_s),
                               rtol=FLOAT32_RTOL)
    assert float(_param(params, "bsdf.eta")) == pytest.approx(1.3, rel=FLOAT32_RTOL)


def test_dipole_phase_function_is_henyey_greenstein_with_g():
    material = Dipole(sigma_a=0.01, sigma_s_prime=1.0, eta=1.3, g=0.8)
    shape = [s for s in _loaded(_scene(material)).shapes() if s.interior_medium()][0]
    text = str(shape.interior_medium().phase_function())
    assert text.startswith("HGPhaseFunction") and "g = [0.8]" in text


def test_index_matched_dipole_has_a_null_boundary():
    conversion = convert_scene(_scene(Dipole(0.01, 1.0, eta=1.0)))
    shape = _loaded(_scene(Dipole(0.01, 1.0, eta=1.0))).shapes()[0]
    assert "Null" in type(shape.bsdf()).__name__ or "Null" in str(shape.bsdf())
    assert conversion.integrator == "volpath"


def test_a_chromatic_medium_renders_with_spectral_mis_in_rgb():
    # RGB volpath's ratio-of-transmittances weights are heavy-tailed (RGB_ESTIMATOR_NOTE)
    skin = dataclasses.replace(measured_medium("Skin1"), eta=1.0)
    assert convert_scene(_scene(skin)).integrator == "volpathmis"
    # one channel at a time the medium is grey: volpath, exact there
    assert convert_scene(_scene(skin), channel=0).integrator == "volpath"
    assert convert_scene(_scene(Dipole(0.01, 1.0, eta=1.0))).integrator == "volpath"
    # asked for, volpath stays
    assert convert_scene(_scene(skin), integrator="volpath").integrator == "volpath"


def test_lambertian_is_two_sided_diffuse():
    params = mitsuba().traverse(_loaded(_scene(Lambertian([0.2, 0.4, 0.6]))))
    np.testing.assert_allclose(_rgb(_param(params, "reflectance.value")), [0.2, 0.4, 0.6],
                               rtol=FLOAT32_RTOL)
    assert convert_scene(_scene(Lambertian(0.5))).integrator == "path"


def test_per_channel_conversion_repeats_one_channel():
    material = measured_medium("Ketchup")
    params = mitsuba().traverse(_loaded(_scene(material), channel=1))
    scale = float(_param(params, "interior_medium.scale"))
    sigma_t = scale * _rgb(_param(params, "interior_medium.sigma_t.value.value"))
    frame_scale = convert_scene(_scene(material)).frame.scale
    np.testing.assert_allclose(sigma_t * frame_scale, np.full(3, material.sigma_t[1]),
                               rtol=FLOAT32_RTOL)


def test_unknown_material_names_the_object():
    class Chalk:
        pass

    with pytest.raises(InputError, match=r"objects\['ball'\]\.material.*no Mitsuba conversion "
                                         r"for material type Chalk; known: .*Dipole"):
        convert_scene(_scene(Chalk()))


def test_registered_converter_is_used():
    class Mirror:
        pass

    register_material_converter(Mirror, lambda material, context: MaterialParts(
        {"type": "conductor"}))
    shape = _loaded(_scene(Mirror())).shapes()[0]
    assert "Conductor" in str(shape.bsdf())


def test_converter_must_be_callable():
    with pytest.raises(InputError, match="converter.*must be callable"):
        register_material_converter(Lambertian, "not a function")


# ---------------------------------------------------------------------- integrators


def test_path_integrator_is_refused_for_media():
    with pytest.raises(InputError, match="integrator = 'path'.*ignores media"):
        convert_scene(_scene(measured_medium("Skin1")), integrator="path")


def test_unknown_integrator_lists_the_valid_ones():
    with pytest.raises(InputError, match="integrator = 'bdpt'.*valid: volpath, volpathmis, "
                                         "volpath_mnee, path"):
        convert_scene(_scene(Lambertian(0.5)), integrator="bdpt")


@pytest.mark.parametrize(("field", "options"), [
    ("channel", {"channel": 3}), ("spp", {"spp": 0}), ("max_depth", {"max_depth": 0}),
    ("rr_depth", {"rr_depth": 0}), ("delta_light_size", {"delta_light_size": 0.7})])
def test_bad_options_are_refused(field, options):
    with pytest.raises(InputError, match=f"{field} = "):
        convert_scene(_scene(Lambertian(0.5)), **options)


def test_russian_roulette_is_off_only_for_albedo_near_one():
    assert convert_scene(_scene(measured_medium("Marble"))).rr_depth == NO_RUSSIAN_ROULETTE
    assert convert_scene(_scene(measured_medium("Ketchup"))).rr_depth == 5
    assert convert_scene(_scene(Lambertian(0.9))).rr_depth == 5
    assert convert_scene(_scene(Lambertian(0.9)), rr_depth=12).rr_depth == 12


def test_per_channel_is_recommended_for_chromatic_media_of_high_albedo():
    assert convert_scene(_scene(measured_medium("Marble"))).per_channel_recommended
    assert not convert_scene(_scene(measured_medium("Skin1"))).per_channel_recommended
    grey = Dipole(sigma_a=0.0, sigma_s_prime=2.0)
    assert not convert_scene(_scene(grey)).per_channel_recommended
    assert not convert_scene(_scene(measured_medium("Marble")),
                             channel=0).per_channel_recommended


def test_max_depth_defaults_to_unbounded():
    conversion = convert_scene(_scene(measured_medium("Skin1")))
    assert conversion.max_depth == -1
    assert conversion.scene_dict["integrator"]["max_depth"] == -1


def test_sensor_is_the_gbuffer_camera():
    sensor = _loaded(_scene(Lambertian(0.5))).sensors()[0]
    assert tuple(sensor.film().size()) == (CAMERA.width, CAMERA.height)
    assert float(mitsuba().traverse(sensor)["x_fov"][0]) == pytest.approx(CAMERA.fov)


# --------------------------------------------------------------------------- lights


def test_every_light_type_loads():
    environment = np.ones((8, 16, 3), np.float32)
    lights = (PointLight([0, 3, 0], 2.0), SpotLight([0, 3, 0], [0, -1, 0], 2.0),
              DirectionalLight([0, -1, 0], 1.0),
              RectangularAreaLight([0, 3, 0], [1, 0, 0], [0, 0, -1], 1.0),
              SphereAreaLight([3, 0, 0], 0.5, 1.0), ImageEnvironment(environment))
    scene = _loaded(_scene(Lambertian(0.5), lights))
    assert len(scene.emitters()) == len(lights)


def test_delta_lights_are_kept_without_a_dielectric_medium():
    lights = (PointLight([0, 3, 0], 2.0),)
    for material in (Lambertian(0.5), Dipole(0.01, 1.0, eta=1.0)):
        conversion = convert_scene(_scene(material, lights))
        assert conversion.substitutions == []
        assert conversion.scene_dict["light_0"]["type"] == "point"


def test_point_light_becomes_a_sphere_of_the_same_intensity():
    intensity = np.array([2.0, 3.0, 4.0])
    position = np.array([0.0, 3.0, 0.0])
    scene = _scene(measured_medium("Skin1"), (PointLight(position, intensity),))
    # the stand-in of volpath (volpath_mnee, the default here, reaches the light itself)
    conversion = convert_scene(scene, delta_light_size=0.1, integrator="volpath")
    (note,) = conversion.substitutions
    assert note.startswith("light_0 (point light -> sphere emitter")
    emitter = conversion.scene_dict["light_0_emitter"]
    distance = nearest_surface_distance(scene, position)
    assert distance == pytest.approx(2.0, rel=0.01)  # icosphere(1) nearly touches radius 1
    # the note speaks in the scene's units, the dictionary in the rendering frame's
    assert f"radius {0.1 * distance:.4g} units" in note
    frame_scale = conversion.frame.scale
    radius = emitter["radius"] / frame_scale
    assert radius == pytest.approx(0.1 * distance)
    radiance = np.array(emitter["emitter"]["radiance"]["value"])
    # a uniform sphere has intensity pi r^2 L in every direction (r^2 L in frame units^2:
    # the frame's intensity is frame_scale^2 the scene's)
    np.testing.assert_allclose(math.pi * radius ** 2 * radiance, intensity)


def test_spot_light_shade_opens_over_the_cone():
    light = SpotLight([0, 3, 0], [0, -1, 0], 2.0, cutoff_angle=30.0, beam_width=20.0)
    scene = _scene(measured_medium("Skin1"), (light,))
    conversion = convert_scene(scene, integrator="volpath")
    assert "spot light -> sphere emitter" in conversion.substitutions[0]
    loaded = mitsuba().load_dict(conversion.scene_dict)
    mi = mitsuba()
    # rays from the emitter's centre: open within the fall-off band's middle (25 degrees)
    angles = np.radians([0.0, 20.0, 24.0, 26.0, 40.0, 120.0])
    directions = np.stack([np.sin(angles), -np.cos(angles), np.zeros_like(angles)])
    # the note's scene units -> the frame's
    shade_radius = conversion.frame.scale * float(
        conversion.substitutions[0].split("shade of radius ")[1].split()[0])
    emitter_radius = conversion.scene_dict["light_0_emitter"]["radius"]
    assert emitter_radius < shade_radius
    # start just outside the emitter sphere, stop just beyond the shade
    origins = conversion.frame.point(light.position)[:, None] + 1.01 * emitter_radius * directions
    rays = mi.Ray3f(mi.Point3f(origins), mi.Vector3f(directions))
    rays.maxt = 1.01 * shade_radius
    blocked = np.array(loaded.ray_test(rays))
    np.testing.assert_array_equal(blocked, [False, False, False, True, True, True])


def test_directional_light_becomes_a_sun_of_the_same_irradiance():
    irradiance = np.array([1.0, 2.0, 3.0])
    light = DirectionalLight([0.3, -1.0, 0.2], irradiance)
    environment = EnvironmentParts()
    note = environment.add_sun(light, size=0.1)
    assert "angular radius 5.74 degrees" in note
    radiance = environment.radiance_map()
    mi = mitsuba()
    emitter = mi.load_dict({"type": "envmap", "bitmap": mi.Bitmap(radiance)})
    # integrate Mitsuba's own interpolated map over a fine grid around the sun
    height, width = 1025, 2048
    directions, solid_angles = lat_long_directions(height, width)
    sun = -light.direction
    cosine = np.clip(directions @ sun, 0, None)
    near = cosine > math.cos(math.radians(10.0))
    si = mi.SurfaceInteraction3f()
    si.wi = mi.Vector3f(-directions[near].T)
    values = np.array(emitter.eval(si)).T
    measured = (values * (cosine[near] * solid_angles[near])[:, None]).sum(0)
    # the bilinear interpolation is integrated here by a 4x finer rule: 1 % covers it
    np.testing.assert_allclose(measured, irradiance, rtol=0.01)


def test_two_image_environments_must_share_a_resolution():
    lights = (ImageEnvironment(np.ones((8, 16, 3))), ImageEnvironment(np.ones((4, 8, 3))))
    with pytest.raises(InputError, match="one resolution"):
        convert_scene(_scene(Lambertian(0.5), lights))


def test_constant_environments_add_up():
    lights = (ConstantEnvironment(1.0), ConstantEnvironment([0.5, 1.0, 2.0]))
    entry = convert_scene(_scene(Lambertian(0.5), lights)).scene_dict["environment"]
    assert entry["radiance"]["value"] == [1.5, 2.0, 3.0]


def test_delta_light_on_a_surface_is_refused():
    on_surface = icosphere(1).vertices[0]
    scene = _scene(measured_medium("Skin1"), (PointLight(on_surface, 1.0),))
    with pytest.raises(InputError, match="delta light on a surface"):
        convert_scene(scene, integrator="volpath")  # the stand-in needs a distance


@pytest.mark.parametrize(("field", "options"), [
    ("max_depth", {"max_depth": float("nan")}),
    ("max_depth", {"max_depth": "deep"}),
    ("rr_depth", {"rr_depth": float("inf")}),
    ("channel", {"channel": 1.0}),
    ("channel", {"channel": True}),
])
def test_options_of_the_wrong_type_are_refused(field, options):
    with pytest.raises(InputError, match=f"{field} = "):
        convert_scene(_scene(Lambertian(0.5)), **options)
