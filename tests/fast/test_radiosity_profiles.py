"""The knob ``profile`` of translucent radiosity: which radial profile fills S."""

import numpy as np
import pytest
from translucent.cache import private_cache
from translucent.errors import InputError
from translucent.fast import radiosity
from translucent.fast.conformance import tiny_sphere_text
from translucent.fast.knobs import radial_profile
from translucent.fast.radiosity import precompute, scattering_geometry, scattering_matrix
from translucent.fast.radiosity.form_factors import build_patches
from translucent.materials import measured_medium
from translucent.materials.profiles import diffuse_entry_transmittance
from translucent.reports.cli import main
from translucent.scenes import Camera, PointLight, Scene, SceneObject, loads_scene, plane

#: A flat sheet's middle column of S against the profile's total within max_d: the
#: default sampling under-integrates a convex profile by 0.6 % on 4 mm cells
#: (tests/fast/test_radiosity_sheets.py); 1.5 % leaves room for the exit-at-centroid
#: approximation of Eq. 8.
SHEET_ENERGY_RTOL = 0.015

#: Profiles whose Skin1 totals differ from the dipole's by several times that tolerance in
#: at least one channel (docs/profiles.md gives the totals).
DISTINCT = ("better_dipole", "quantized_diffusion", "burley_cycles", "random_walk")

#: An edited state against a fresh precomputation with the new material: the same S and
#: solves to a 1e-9 residual, rendered in float32.
EDIT_RTOL = 1e-6

CAMERA = Camera([0.0, 1.0, 4.0], [0.0, 0.5, 0.0], width=12, height=12)
QUICK = {"rays_per_patch": 16}


def _sphere():
    return loads_scene(tiny_sphere_text("profile_sphere", size=12))


def test_the_dipole_profile_is_the_default_bit_for_bit():
    scene = _sphere()
    with private_cache():
        default = precompute(scene, **QUICK)
        named = precompute(scene, profile="dipole", **QUICK)
        assert np.array_equal(named.S.data, default.S.data)
        assert np.array_equal(named.render().rgb, default.render().rgb)
        assert named.log.notes["profile"] == "dipole"


@pytest.mark.parametrize("name", DISTINCT)
def test_s_columns_carry_the_chosen_profiles_total(name):
    # the middle of a 64 mm sheet returns the profile's energy within max_d, times the
    # diffuse entry transmittance: the chosen profile's, not the dipole's
    medium = measured_medium("Skin1")
    max_d = 30.0
    scene = Scene([SceneObject("sheet", plane(64.0, 64.0, subdivisions=16), medium)], [],
                  CAMERA)
    patches = build_patches(scene)
    geometry = scattering_geometry(scene, patches, [0], max_distance_mm=max_d,
                                   knobs=dict(radiosity.DEFAULT_KNOBS))
    middle = np.argmin(np.linalg.norm(patches.centroid, axis=1))
    sums = scattering_matrix(geometry, scene, patches, profile=name).power_column_sums(
        patches.area)[middle]
    entry = diffuse_entry_transmittance(medium.eta)
    expected = entry * radial_profile(name, medium).total(max_radius=max_d)
    dipole = entry * radial_profile("dipole", medium).total(max_radius=max_d)
    assert sums == pytest.approx(expected, rel=SHEET_ENERGY_RTOL)
    assert np.max(np.abs(expected / dipole - 1.0)) > 3 * SHEET_ENERGY_RTOL


def test_the_profile_is_read_at_render_time_and_keys_only_its_cut_off():
    scene = _sphere()
    with private_cache():
        first = precompute(scene, max_distance_mm=20.0, **QUICK)
        other = precompute(scene, max_distance_mm=20.0, profile="better_dipole", **QUICK)
        assert other.log.notes["cache"] == "hit"  # the same geometry
        derived = precompute(scene, profile="burley_searchlight", **QUICK)
        assert derived.log.notes["cache"] == "miss"  # its own cut-off max_d
        assert derived.knobs["max_distance_mm"] != first.knobs["max_distance_mm"]
        image, changed = first.render().rgb, other.render().rgb
    assert np.all(np.isfinite(changed))
    assert not np.allclose(changed, image, rtol=0.01)
    assert other.log.notes["profile"] == "better_dipole"
    # the finite-object gain is the dipole's: another profile is used as it is, and says so
    assert any("finite_object_energy" in s and "better_dipole" in s
               for s in other.log.skipped)


def test_an_edit_goes_through_the_chosen_profile():
    scene = _sphere()
    marble = measured_medium("Marble")
    # one cut-off for both (derived, it would follow each material) and a tight solve
    knobs = {**QUICK, "profile": "random_walk", "max_distance_mm": 30.0, "tolerance": 1e-9}
    with private_cache():
        state = precompute(scene, **knobs)
        edited = state.render(material=marble).rgb
        fresh = precompute(scene.with_material("sphere", marble), **knobs).render().rgb
    assert edited == pytest.approx(fresh, rel=EDIT_RTOL)


def test_a_directional_profile_is_refused_naming_it_and_its_average_is_taken():
    scene = _sphere()
    with pytest.raises(InputError, match="profile = 'directional_dipole': radiosity cannot "
                                         "take profile 'directional_dipole'.*incident direction"):
        precompute(scene, profile="directional_dipole", **QUICK)
    with private_cache():
        image = precompute(scene, profile="directional_dipole_average", **QUICK).render().rgb
    assert np.all(np.isfinite(image)) and image.max() > 0


def test_a_thin_sheet_takes_only_the_dipoles_slab():
    sheet = plane(6.0, 6.0, (0.0, 1.0, 0.0), subdivisions=2, name="sheet")
    scene = Scene([SceneObject("sheet", sheet, measured_medium("Skin1"))],
                  (PointLight([0.0, 4.0, 0.0], 50.0),), CAMERA, mm_per_unit=10.0)
    with private_cache(), pytest.raises(InputError, match="'sheet' is a thin .*'better_dipole' "
                                                          "has no transmission"):
        precompute(scene, sheet_thickness_mm=2.0, profile="better_dipole", **QUICK)


def test_approx_takes_the_profile_flag(tmp_path, capsys):
    scene = tmp_path / "profile_sphere.toml"
    scene.write_text(tiny_sphere_text("profile_sphere", size=8))
    out = tmp_path / "out.exr"
    with private_cache():
        assert main(["approx", "radiosity", str(scene), "--out", str(out), "--rays", "16",
                     "--profile", "burley_dmfp", "--no-progress"]) == 0
        assert out.is_file()
        capsys.readouterr()
        assert main(["approx", "radiosity", str(scene), "--out", str(tmp_path / "no.exr"),
                     "--profile", "directional_dipole", "--no-progress"]) == 2
    assert "radiosity cannot take profile 'directional_dipole'" in capsys.readouterr().err
    assert not (tmp_path / "no.exr").exists()
