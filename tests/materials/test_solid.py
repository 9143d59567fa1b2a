"""Solid heterogeneous media: the voxel grid, procedural fields, files, quantisation."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from translucent.errors import InputError
from translucent.materials import measured_medium
from translucent.materials.factory import material_from_dict, material_to_dict
from translucent.materials.solid import (
    SOLID_FIELDS,
    SolidMedium,
    checker_solid,
    gradient_solid,
    load_solid,
    quantise_media,
    save_solid,
    solid_from_spec,
    uniform_solid,
    veined_solid,
)


def _grid(shape=(2, 3, 4), value=1.0):
    return np.full(shape + (3,), value)


# ------------------------------------------------------------------------ the grid lookup
def test_a_point_takes_the_value_of_the_voxel_it_lies_in():
    sigma_a = np.zeros((2, 3, 4, 3))
    for z in range(2):
        for y in range(3):
            for x in range(4):
                sigma_a[z, y, x] = [x, y, z]
    solid = SolidMedium(sigma_a, _grid(), ((-1, -1, -1), (1, 1, 1)))
    points = np.array([[-0.99, -0.99, -0.99], [0.01, 0.01, 0.01], [-0.49, 0.34, 0.99],
                       [0.99, 0.99, 0.99], [-0.51, -0.32, -0.01]])
    # voxel i of N covers [i/N, (i+1)/N) of the box: what Mitsuba's nearest gridvolume reads
    expected = [[0, 0, 0], [2, 1, 1], [1, 2, 1], [3, 2, 1], [0, 1, 0]]
    assert np.array_equal(solid.coefficients_at(points)[0], expected)


@settings(max_examples=40, deadline=None)
@given(st.integers(1, 6), st.integers(1, 6), st.integers(1, 6),
       st.lists(st.floats(-0.999, 0.999), min_size=3, max_size=3))
def test_the_lookup_inverts_the_voxel_centres(nz, ny, nx, offset):
    # the centre of every voxel, moved by less than half a voxel, finds that voxel
    bounds = np.array([[-2.0, 0.0, 1.0], [3.0, 0.5, 4.0]])
    values = np.arange(nz * ny * nx, dtype=float).reshape(nz, ny, nx, 1) + 1.0
    solid = SolidMedium(np.repeat(values, 3, axis=-1), _grid((nz, ny, nx)), bounds)
    z, y, x = np.meshgrid(np.arange(nz), np.arange(ny), np.arange(nx), indexing="ij")
    index = np.stack([x, y, z], axis=-1).reshape(-1, 3)
    size = solid.voxel_size
    points = bounds[0] + (index + 0.5 + 0.49 * np.asarray(offset)) * size
    found = solid.coefficients_at(points)[0][:, 0]
    assert np.array_equal(found, values.reshape(-1))


# ------------------------------------------------------------------------ validation
@pytest.mark.parametrize("field, value, words", [
    ("sigma_a", np.nan, "voxel"), ("sigma_s_prime", -1.0, ">= 0"),
    ("sigma_a", np.inf, "finite"),
])
def test_bad_coefficients_name_the_field_and_the_voxel(field, value, words):
    grids = {"sigma_a": _grid(), "sigma_s_prime": _grid()}
    grids[field] = grids[field].copy()
    grids[field][1, 2, 3, 0] = value
    with pytest.raises(InputError) as error:
        SolidMedium(grids["sigma_a"], grids["sigma_s_prime"])
    assert error.value.field == field and words in str(error.value)
    if words == "voxel":
        assert "(1, 2, 3, 0)" in str(error.value)


def test_a_voxel_of_vacuum_a_wrong_shape_and_bad_bounds_are_refused():
    with pytest.raises(InputError, match="vacuum"):
        SolidMedium(_grid(value=0.0), _grid(value=0.0))
    with pytest.raises(InputError, match=r"\(Z, Y, X, 3\)"):
        SolidMedium(np.ones((2, 2, 3)), np.ones((2, 2, 3)))
    with pytest.raises(InputError, match="shape of sigma_a"):
        SolidMedium(_grid((2, 2, 2)), _grid((2, 2, 3)))
    with pytest.raises(InputError, match="maximum must exceed"):
        SolidMedium(_grid(), _grid(), ((0, 0, 0), (1, 0, 1)))
    with pytest.raises(InputError, match=r"\[1, 3\]"):
        SolidMedium(_grid(), _grid(), eta=0.5)


def test_a_grid_that_does_not_cover_the_object_is_an_error_naming_the_file(tmp_path):
    scene_file = tmp_path / "small.toml"
    scene_file.write_text("""
[scene]
name = "small"
[camera]
origin = [0, 0, 5]
target = [0, 0, 0]
width = 8
height = 8
[[objects]]
name = "ball"
mesh = { type = "icosphere", subdivisions = 1, radius = 1.0 }
material = { type = "solid", field = "uniform", bounds = [[-0.5, -1, -1], [1, 1, 1]] }
[[lights]]
type = "point"
position = [3, 3, 3]
intensity = 1.0
""")
    from translucent.scenes import load_scene

    with pytest.raises(InputError) as error:
        load_scene(scene_file)
    assert "does not cover" in str(error.value) and "small.toml" in str(error.value)
    assert "objects[0].material.bounds" in str(error.value)


# ------------------------------------------------------------------------ procedural fields
def test_the_checker_alternates_two_media_cell_by_cell():
    solid = checker_solid("Skin1", "Ketchup", cells=4)
    skin, ketchup = measured_medium("Skin1"), measured_medium("Ketchup")
    centres = -1.0 + (np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [3, 2, 1]]) + 0.5) * 0.5
    sigma_a, sigma_s_prime = solid.coefficients_at(centres)
    for row, odd in zip(range(4), (False, True, False, False), strict=True):
        medium = ketchup if odd else skin
        assert np.array_equal(sigma_a[row], medium.sigma_a)
        assert np.array_equal(sigma_s_prime[row], medium.sigma_s_prime)


def test_the_veins_mix_the_two_media_linearly_and_are_seeded():
    base, vein = measured_medium("Skin2"), measured_medium("Ketchup")
    solid = veined_solid("Skin2", "Ketchup", resolution=16)
    # every voxel lies on the segment between the two media (fraction t in [0, 1])
    t = (solid.sigma_a - base.sigma_a) / (vein.sigma_a - base.sigma_a)
    assert np.all((t > -1e-12) & (t < 1 + 1e-12))
    assert np.allclose(t, t[..., :1])
    assert np.allclose(solid.sigma_s_prime,
                       (1 - t) * base.sigma_s_prime + t * vein.sigma_s_prime)
    assert t.max() > 0.9 and t.min() < 0.1  # both media occur
    same = veined_solid("Skin2", "Ketchup", resolution=16)
    other = veined_solid("Skin2", "Ketchup", resolution=16, seed=8)
    assert np.array_equal(same.sigma_a, solid.sigma_a)
    assert not np.array_equal(other.sigma_a, solid.sigma_a)


def test_the_gradient_runs_from_first_to_second_along_its_axis():
    solid = gradient_solid("Skin1", "Skin2", axis="x", resolution=8)
    low = solid.coefficients_at([[-0.99, 0.0, 0.0]])[1][0]
    high = solid.coefficients_at([[0.99, 0.0, 0.0]])[1][0]
    skin1, skin2 = measured_medium("Skin1"), measured_medium("Skin2")
    assert np.allclose(low, skin1.sigma_s_prime + (skin2.sigma_s_prime - skin1.sigma_s_prime)
                       / 16)
    assert np.allclose(high, skin2.sigma_s_prime - (skin2.sigma_s_prime
                                                    - skin1.sigma_s_prime) / 16)
    with pytest.raises(InputError, match="x, y or z"):
        gradient_solid(axis="w")


def test_the_uniform_field_is_homogeneous_and_the_others_are_not():
    assert uniform_solid("Skin1", resolution=3).is_uniform
    assert not checker_solid().is_uniform
    assert uniform_solid("Skin1").dipole().sigma_a.tolist() == \
        measured_medium("Skin1").sigma_a.tolist()


# ------------------------------------------------------------------------ scene files
def test_every_field_builds_from_a_table_and_round_trips():
    for name in SOLID_FIELDS:
        table = {"type": "solid", "field": name, "eta": 1.0}
        material = material_from_dict(table)
        assert isinstance(material, SolidMedium) and material.eta == 1.0
        again = material_from_dict(material_to_dict(material))
        assert np.array_equal(again.sigma_a, material.sigma_a)


def test_bad_tables_are_errors_naming_the_key():
    with pytest.raises(InputError, match="exactly one of field, file"):
        solid_from_spec({"type": "solid"})
    with pytest.raises(InputError) as error:
        solid_from_spec({"field": "stripes"})
    assert error.value.field == "field"
    with pytest.raises(InputError) as error:
        solid_from_spec({"field": "checker", "first": "Jelly"})
    assert error.value.field == "first" and "Skin1" in str(error.value)
    with pytest.raises(InputError, match="bad option"):
        solid_from_spec({"field": "checker", "seed": 3})


def test_a_grid_file_round_trips_and_a_bad_one_names_the_file(tmp_path):
    solid = veined_solid(resolution=8)
    path = save_solid(tmp_path / "veins.npz", solid)
    loaded = load_solid(path)
    assert np.array_equal(loaded.sigma_a, solid.sigma_a)
    assert np.array_equal(loaded.bounds, solid.bounds) and loaded.eta == solid.eta
    relative = solid_from_spec({"file": "veins.npz", "eta": 1.0}, file=tmp_path / "s.toml")
    assert relative.eta == 1.0

    broken = dict(np.load(path))
    broken["sigma_s_prime"] = broken["sigma_s_prime"].copy()
    broken["sigma_s_prime"][0, 1, 2, 1] = np.nan
    bad = tmp_path / "nan.npz"
    np.savez(bad, **broken)
    with pytest.raises(InputError) as error:
        load_solid(bad)
    assert str(bad) in str(error.value) and error.value.field == "sigma_s_prime"
    assert "(0, 1, 2, 1)" in str(error.value)
    del broken["bounds"]
    np.savez(tmp_path / "nobox.npz", **broken)
    with pytest.raises(InputError, match="missing array"):
        load_solid(tmp_path / "nobox.npz")
    with pytest.raises(InputError, match="no such file"):
        load_solid(tmp_path / "absent.npz")
    (tmp_path / "text.npz").write_text("not numpy")
    with pytest.raises(InputError, match="not a readable"):
        load_solid(tmp_path / "text.npz")


# ------------------------------------------------------------------------ quantisation
def test_a_checker_quantises_exactly_to_its_two_media(rng):
    quantised = quantise_media(checker_solid(), rng.uniform(-1, 1, (500, 3)))
    assert len(quantised.media) == 2 and quantised.max_relative_error == 0.0


@pytest.mark.parametrize("media", [4, 16, 64])
def test_quantising_veins_reports_an_error_it_keeps(rng, media):
    solid = veined_solid(resolution=24)
    points = rng.uniform(-1, 1, (3000, 3))
    quantised = quantise_media(solid, points, max_media=media)
    assert len(quantised.media) == media
    sigma_a, sigma_s_prime = solid.coefficients_at(points)
    given = np.stack([np.concatenate([m.sigma_a, m.sigma_s_prime])
                      for m in quantised.media])[quantised.labels]
    actual = np.concatenate([sigma_a, sigma_s_prime], axis=1)
    error = np.abs(given - actual) / actual
    assert error.max() == pytest.approx(quantised.max_relative_error)


def test_more_media_never_quantise_worse(rng):
    solid = veined_solid(resolution=24)
    points = rng.uniform(-1, 1, (3000, 3))
    errors = [quantise_media(solid, points, max_media=k).max_relative_error
              for k in (2, 8, 32, 128)]
    assert errors == sorted(errors, reverse=True) and errors[-1] < 0.05
