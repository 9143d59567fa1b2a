"""The TOML scene format, the built-in catalogue and `translucent scenes`."""

import shutil
import textwrap

import numpy as np
import pytest
from translucent.cache import content_hash
from translucent.errors import InputError
from translucent.materials import Dipole, Lambertian
from translucent.reports.cli import main
from translucent.scenes import (
    ConstantEnvironment,
    ImageEnvironment,
    builtin_scene_descriptions,
    builtin_scene_names,
    load_scene,
    loads_scene,
    save_scene,
)
from translucent.scenes import scene_file as scene_file_module

REQUIRED_SCENES = ("sphere", "cornell_block", "bowl", "slab_beam", "furnace_sphere")

MINIMAL = """
[scene]
name = "tiny"
description = "one sphere"
mm_per_unit = 2.0

[camera]
origin = [0.0, 0.0, 4.0]
target = [0.0, 0.0, 0.0]
width = 16
height = 12

[[objects]]
name = "ball"
mesh = { type = "icosphere", subdivisions = 1, radius = 1.0 }
material = { type = "measured", name = "marble" }

[[lights]]
type = "point"
position = [1.0, 2.0, 3.0]
intensity = [1.0, 2.0, 3.0]
"""


def with_lines(text, old, new):
    assert old in text
    return text.replace(old, new)


def test_minimal_scene_loads_with_defaults():
    scene = loads_scene(MINIMAL)
    assert scene.name == "tiny" and scene.mm_per_unit == 2.0
    assert scene.camera.fov == 40.0 and scene.camera.width == 16
    np.testing.assert_allclose(scene.camera.up, [0.0, 1.0, 0.0])
    ball = scene.object("ball")
    assert isinstance(ball.material, Dipole) and ball.material.name == "Marble"
    assert len(ball.mesh.vertices) == 42
    np.testing.assert_allclose(scene.lights[0].intensity, [1.0, 2.0, 3.0])


@pytest.mark.parametrize("name", REQUIRED_SCENES)
def test_required_builtin_scenes_load_small(name):
    scene = load_scene(name)
    assert scene.name == name
    assert scene.description
    # CI renders stay fast: 64 x 64 to 128 x 128
    assert 64 <= scene.camera.width <= 128 and 64 <= scene.camera.height <= 128
    assert scene.source.endswith(f"{name}.toml")


def test_builtin_scene_contents():
    assert set(REQUIRED_SCENES) <= set(builtin_scene_names())
    cornell = load_scene("cornell_block")
    block = cornell.object("block")
    lower, upper = block.mesh.bounds
    extent_mm = (upper - lower) * cornell.mm_per_unit
    assert 20.0 <= extent_mm.min() and extent_mm.max() <= 100.0  # a few cm
    assert isinstance(block.material, Dipole)
    assert {o.name for o in cornell.objects} >= {"floor", "ceiling", "back_wall",
                                                  "left_wall", "right_wall"}
    furnace = load_scene("furnace_sphere")
    assert isinstance(furnace.objects[0].material, Lambertian)
    assert isinstance(furnace.lights[0], ConstantEnvironment)
    bowl = load_scene("bowl")
    kinds = {type(o.material) for o in bowl.objects}
    assert kinds == {Dipole, Lambertian}


def test_descriptions_are_read_without_building_meshes():
    descriptions = builtin_scene_descriptions()
    assert list(descriptions) == builtin_scene_names()
    assert all(descriptions[name] == load_scene(name).description.split("\n")[0]
               for name in REQUIRED_SCENES)


@pytest.mark.parametrize("name", REQUIRED_SCENES)
def test_save_and_load_round_trip(name, tmp_path):
    scene = load_scene(name)
    path = save_scene(scene, tmp_path / f"{name}.toml")
    back = load_scene(path)
    assert content_hash(back.cache_key()) == content_hash(scene.cache_key())
    assert (back.name, back.description) == (scene.name, scene.description)


def test_image_environment_round_trip(tmp_path):
    radiance = np.random.default_rng(1).uniform(0, 2, (8, 16, 3)).astype(np.float32)
    scene = loads_scene(MINIMAL).with_lights([ImageEnvironment(radiance, scale=0.5)])
    path = save_scene(scene, tmp_path / "env.toml")
    back = load_scene(path)
    np.testing.assert_array_equal(back.lights[0].radiance, radiance)
    assert back.lights[0].scale == 0.5


def test_load_scene_is_cached_until_the_file_changes(tmp_path):
    path = tmp_path / "tiny.toml"
    path.write_text(MINIMAL)
    first = load_scene(path)
    assert load_scene(str(path)) is first
    path.write_text(with_lines(MINIMAL, "mm_per_unit = 2.0", "mm_per_unit = 3.0"))
    assert load_scene(path).mm_per_unit == 3.0


def test_adding_a_toml_file_adds_a_builtin_scene(tmp_path, monkeypatch):
    catalogue = tmp_path / "catalogue"
    shutil.copytree(scene_file_module.CATALOGUE_DIR, catalogue)
    (catalogue / "tiny.toml").write_text(MINIMAL)
    monkeypatch.setattr(scene_file_module, "CATALOGUE_DIR", catalogue)
    assert "tiny" in builtin_scene_names()
    assert load_scene("TINY").name == "tiny"
    assert builtin_scene_descriptions()["tiny"] == "one sphere"


def test_mesh_file_paths_and_transforms(tmp_path):
    from translucent.scenes.meshes import box, save_mesh

    save_mesh(box((2.0, 1.0, 1.0)), tmp_path / "meshes" / "brick.obj")
    text = with_lines(MINIMAL, 'mesh = { type = "icosphere", subdivisions = 1, radius = 1.0 }',
                      'mesh = { file = "meshes/brick.obj", scale = 2.0, '
                      'rotate = [0.0, 90.0, 0.0], translate = [0.0, 1.0, 0.0] }')
    path = tmp_path / "brick.toml"
    path.write_text(text)
    lower, upper = load_scene(path).object("ball").mesh.bounds
    # a 2 x 1 x 1 brick, doubled, turned a quarter about y (x -> -z), lifted by 1
    np.testing.assert_allclose(lower, [-1.0, 0.0, -2.0], atol=1e-12)
    np.testing.assert_allclose(upper, [1.0, 2.0, 2.0], atol=1e-12)



def test_subedit_texture_file_is_relative_to_the_scene_file(tmp_path, monkeypatch):
    from translucent.materials.subedit import builtin_subedit, load_subedit, save_subedit

    texture = load_subedit(save_subedit(tmp_path / "textures" / "checker.npz",
                                        builtin_subedit("checker", resolution=4)))
    text = with_lines(MINIMAL, 'material = { type = "measured", name = "marble" }',
                      'material = { type = "subedit", file = "textures/checker.npz" }')
    path = tmp_path / "scenes" / "textured.toml"
    path.parent.mkdir()
    path.write_text(text.replace('"textures/', '"../textures/'))
    elsewhere = tmp_path / "elsewhere" / "deeper"  # ../textures does not exist from here
    elsewhere.mkdir(parents=True)
    monkeypatch.chdir(elsewhere)
    material = load_scene(path).object("ball").material
    np.testing.assert_array_equal(material.log_profile, texture.log_profile)
    # written elsewhere, the scene still finds its texture
    back = load_scene(save_scene(load_scene(path), tmp_path / "copy" / "copy.toml"))
    np.testing.assert_array_equal(back.object("ball").material.log_profile,
                                  texture.log_profile)
    # a missing texture names the scene file and the material's key
    path.write_text(text.replace('"textures/', '"../missing/'))
    with pytest.raises(InputError) as error:
        load_scene(path)
    assert "textured.toml" in str(error.value) and "objects[0].material.file" in str(error.value)

def test_cornell_box_part_and_generator_parameters():
    text = with_lines(MINIMAL, 'mesh = { type = "icosphere", subdivisions = 1, radius = 1.0 }',
                      'mesh = { type = "cornell_box", part = "left_wall", size = 4.0 }')
    wall = loads_scene(text).object("ball").mesh
    assert wall.name == "ball"
    np.testing.assert_allclose(wall.face_normals[0], [1.0, 0.0, 0.0])
    np.testing.assert_allclose(wall.bounds[0], [-2.0, 0.0, -2.0])


# --- bad input: each names the file and the key ----------------------------------------


BAD = {
    "unknown top-level key": (("[scene]", "[scenery]\nx = 1\n[scene]"),
                              r"bad\.toml: scenery = .*unknown key; valid keys: scene, camera"),
    "unknown scene key": (('mm_per_unit = 2.0', 'mm_per_unit = 2.0\ncolour = "red"'),
                          r"bad\.toml: scene\.colour = 'red': unknown key; valid keys: name"),
    "unknown camera key": (("width = 16", "width = 16\nzoom = 2"),
                           r"camera\.zoom = 2: unknown key; valid keys: origin, target, up"),
    "camera target equals origin": (("target = [0.0, 0.0, 0.0]", "target = [0.0, 0.0, 4.0]"),
                                    r"bad\.toml: camera\.target = \[0\.0, 0\.0, 4\.0\]: "
                                    r"camera looks nowhere"),
    "camera fov out of range": (("width = 16", "width = 16\nfov = 190"),
                                r"camera\.fov = 190: must be in \(0, 180\) degrees"),
    "unknown object key": (('name = "ball"', 'name = "ball"\nshadow = false'),
                           r"objects\[0\]\.shadow = False: unknown key; valid keys: name, mesh"),
    "unknown mesh type": (('type = "icosphere"', 'type = "teapot"'),
                          r"objects\[0\]\.mesh\.type = 'teapot': unknown mesh type; valid: "
                          r"icosphere, box"),
    "unknown mesh parameter": (("radius = 1.0 }", "radius = 1.0, radios = 2 }"),
                               r"objects\[0\]\.mesh\.radios = 2: unknown key; valid keys: "
                               r"subdivisions, radius, center, frequency"),
    "bad mesh parameter": (("radius = 1.0 }", "radius = -1.0 }"),
                           r"objects\[0\]\.mesh\.radius = -1\.0: must be > 0"),
    "mesh with type and file": (("radius = 1.0 }", 'radius = 1.0, file = "x.obj" }'),
                                r"objects\[0\]\.mesh = .*exactly one of 'type'"),
    "unknown material": (('name = "marble"', 'name = "marmalade"'),
                         r"objects\[0\]\.material\.name = 'marmalade': unknown measured "
                         r"material; valid names: Apple"),
    "unknown material type": (('type = "measured"', 'type = "jade"'),
                              r"objects\[0\]\.material\.type = 'jade': unknown material type; "
                              r"valid: .*dipole, .*lambertian, measured"),
    "unknown material key": (('name = "marble" }', 'name = "marble", g = 0.4 }'),
                             r"objects\[0\]\.material\.g = 0\.4: unknown key for a measured "
                             r"material; valid keys: type, name, eta"),
    "unknown light type": (('type = "point"', 'type = "laser"'),
                           r"lights\[0\]\.type = 'laser': unknown light type; valid: point, "
                           r"spot, directional, rect, sphere, constant_env, image_env"),
    "unknown light key": (("intensity = [1.0, 2.0, 3.0]", "intensity = 1.0\ncolour = 2"),
                          r"lights\[0\]\.colour = 2: unknown key; valid keys: type, position, "
                          r"intensity"),
    "negative light intensity": (("intensity = [1.0, 2.0, 3.0]", "intensity = -1.0"),
                                 r"lights\[0\]\.intensity = -1\.0: must be >= 0"),
    "missing light key": (("intensity = [1.0, 2.0, 3.0]", ""),
                          r"lights\[0\]: incomplete point light"),
    "negative mm_per_unit": (("mm_per_unit = 2.0", "mm_per_unit = -2.0"),
                             r"scene\.mm_per_unit = -2\.0: must be > 0"),
    "duplicate object": (("[[lights]]", '[[objects]]\nname = "ball"\nmesh = { type = "box" }\n'
                          'material = { type = "lambertian", albedo = 0.5 }\n[[lights]]'),
                         r"objects = \['ball', 'ball'\]: object names must be unique"),
    "object without material": (('material = { type = "measured", name = "marble" }', ""),
                                r"objects\[0\]\.material: an object needs name, mesh, material"),
    "invalid TOML": (("[camera]", "[camera"), r"bad\.toml: not valid TOML"),
}


@pytest.mark.parametrize("case", list(BAD))
def test_bad_scene_files_name_file_and_key(case, tmp_path):
    (old, new), match = BAD[case]
    path = tmp_path / "bad.toml"
    path.write_text(with_lines(MINIMAL, old, new))
    with pytest.raises(InputError, match=match):
        load_scene(path)


def test_missing_camera_and_objects():
    without_camera = MINIMAL.split("[camera]")[0] + "[[objects]]" + \
        MINIMAL.split("[[objects]]")[1]
    with pytest.raises(InputError, match=r"camera: a scene needs a \[camera\] table"):
        loads_scene(without_camera, file="nocam.toml")
    without_objects = MINIMAL.split("[[objects]]")[0]
    with pytest.raises(InputError, match=r"objects = \[\]: a scene needs at least one"):
        loads_scene(without_objects)


def write_obj(path, vertices, faces):
    lines = [f"v {x} {y} {z}" for x, y, z in vertices]
    lines += [f"f {a + 1} {b + 1} {c + 1}" for a, b, c in faces]
    path.write_text("\n".join(lines) + "\n")


@pytest.mark.parametrize("vertices, match", [
    ([(0, 0, 0), (1, 0, 0), (0, "nan", 0)], r"broken\.obj: vertices\[2\] = .*NaN or Inf"),
    ([(0, 0, 0), (1, 0, 0), (2, 0, 0)], r"broken\.obj: faces\[0\] = .*zero area"),
])
def test_bad_mesh_file_named_with_the_scene_key(vertices, match, tmp_path):
    write_obj(tmp_path / "broken.obj", vertices, [(0, 1, 2)])
    path = tmp_path / "scene.toml"
    path.write_text(with_lines(MINIMAL, 'type = "icosphere", subdivisions = 1, radius = 1.0',
                               'file = "broken.obj"'))
    with pytest.raises(InputError, match=match + r".*objects\[0\]\.mesh of .*scene\.toml"):
        load_scene(path)


def test_unknown_builtin_name_lists_the_catalogue():
    with pytest.raises(InputError, match=r"scene = 'spher': no such built-in scene.*"
                                         r"bowl, cornell_block"):
        load_scene("spher")
    with pytest.raises(InputError, match=r"nowhere\.toml: scene = .*no such scene file"):
        load_scene("nowhere.toml")


# --- the command line -----------------------------------------------------------------


def test_scenes_command_lists_one_line_each(capsys):
    assert main(["scenes"]) == 0
    lines = capsys.readouterr().out.strip().splitlines()
    assert len(lines) == len(builtin_scene_names())
    descriptions = builtin_scene_descriptions()
    for line, name in zip(lines, builtin_scene_names(), strict=True):
        label, description = line.split(":", 1)
        assert label == name and description.strip() == descriptions[name]


def test_scenes_command_show_and_bad_name(capsys):
    assert main(["scenes", "--show", "cornell_block"]) == 0
    out = capsys.readouterr().out
    assert "object block: 230 vertices" in out and "RectangularAreaLight" in out
    assert main(["scenes", "--show", "nosuch"]) == 2
    assert "no such built-in scene" in capsys.readouterr().err


def test_scene_text_with_comments_is_documented_format():
    # the example in docs/scene-format.md loads as written
    from pathlib import Path

    # docs/ lives in the repository beside tests/, not in the installed package
    docs = Path(__file__).resolve().parents[2] / "docs" / "scene-format.md"
    text = docs.read_text()
    example = text.split("```toml", 1)[1].split("```", 1)[0]
    scene = loads_scene(textwrap.dedent(example))
    assert scene.objects and scene.lights


def test_save_scene_keeps_objects_whose_names_differ_only_in_odd_characters(tmp_path):
    scene = loads_scene(with_lines(
        MINIMAL, "[[lights]]",
        '[[objects]]\nname = "ball!"\nmesh = { type = "icosphere", subdivisions = 1, '
        'radius = 3.0 }\nmaterial = { type = "lambertian", albedo = 0.5 }\n'
        '[[objects]]\nname = "ball_"\nmesh = { type = "box", size = 0.5 }\n'
        'material = { type = "lambertian", albedo = 0.5 }\n[[lights]]'))
    back = load_scene(save_scene(scene, tmp_path / "three.toml"))
    for name in ("ball", "ball!", "ball_"):
        np.testing.assert_array_equal(back.object(name).mesh.vertices,
                                      scene.object(name).mesh.vertices)


WRONG_TYPES = {
    "camera width as a string": (("width = 16", 'width = "wide"'),
                                 r"bad\.toml: camera\.width = 'wide': must be a number"),
    "camera width as a boolean": (("width = 16", "width = true"),
                                  r"camera\.width = True: must be a number"),
    "camera fov as a string": (("width = 16", 'width = 16\nfov = "35"'),
                               r"camera\.fov = '35': must be a number"),
    "camera up with a string": (("width = 16", 'width = 16\nup = ["a", 1.0, 0.0]'),
                                r"camera\.up = \['a', 1\.0, 0\.0\]: must be a number"),
    "mm_per_unit as a string": (("mm_per_unit = 2.0", 'mm_per_unit = "2 mm"'),
                                r"scene\.mm_per_unit = '2 mm': must be a number"),
    "mesh radius as a string": (("radius = 1.0 }", 'radius = "1" }'),
                                r"objects\[0\]\.mesh\.radius = '1': must be a number"),
    "mesh file as a number": (('type = "icosphere", subdivisions = 1, radius = 1.0', "file = 3"),
                              r"objects\[0\]\.mesh\.file = 3: must be a string"),
    "light intensity as a string": (("intensity = [1.0, 2.0, 3.0]", 'intensity = "bright"'),
                                    r"lights\[0\]\.intensity = 'bright': must be a number"),
    "environment file as a number": (('type = "point"\nposition = [1.0, 2.0, 3.0]\n'
                                      'intensity = [1.0, 2.0, 3.0]',
                                      'type = "image_env"\nfile = 1'),
                                     r"lights\[0\]\.file = 1: must be a string"),
}


@pytest.mark.parametrize("case", list(WRONG_TYPES))
def test_values_of_the_wrong_type_name_file_and_key(case, tmp_path):
    (old, new), match = WRONG_TYPES[case]
    path = tmp_path / "bad.toml"
    path.write_text(with_lines(MINIMAL, old, new))
    with pytest.raises(InputError, match=match):
        load_scene(path)


@pytest.mark.parametrize("value", ["nan", "inf", "-inf"])
def test_camera_size_not_finite_names_the_key(value):
    with pytest.raises(InputError, match=r"camera\.height = -?(nan|inf): must be an integer"):
        loads_scene(with_lines(MINIMAL, "height = 12", f"height = {value}"))


def test_load_scene_reads_again_when_a_mesh_file_it_names_changes(tmp_path):
    from translucent.scenes.meshes import box, save_mesh

    save_mesh(box(1.0), tmp_path / "brick.npz")
    path = tmp_path / "brick.toml"
    path.write_text(with_lines(MINIMAL, 'type = "icosphere", subdivisions = 1, radius = 1.0',
                               'file = "brick.npz"'))
    assert np.ptp(load_scene(path).object("ball").mesh.vertices[:, 0]) == 1.0
    save_mesh(box((3.0, 1.0, 1.0)), tmp_path / "brick.npz")  # the scene file is unchanged
    assert np.ptp(load_scene(path).object("ball").mesh.vertices[:, 0]) == 3.0


def test_save_scene_writes_nothing_when_a_material_cannot_be_written(tmp_path):
    from translucent.materials.subedit import SubEditProfiles

    scene = loads_scene(MINIMAL)
    scene = scene.with_material("ball", SubEditProfiles(np.zeros((3, 3)), 1.0))
    with pytest.raises(InputError, match="made in code"):
        save_scene(scene, tmp_path / "out" / "made.toml")
    assert not (tmp_path / "out").exists() or not any((tmp_path / "out").iterdir())
