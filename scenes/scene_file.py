"""The TOML scene format: reading, writing, and the built-in catalogue.

A scene file has four parts (every key, its unit and default: ``docs/scene-format.md``)::

    [scene]        name, description, mm_per_unit
    [camera]       origin, target, up, fov, width, height
    [[objects]]    name, mesh = {type = "icosphere", ...} or {file = "x.obj", ...},
                   material = {type = "measured", name = "marble"}
    [[lights]]     type = "point" | "spot" | "directional" | "rect" | "sphere" |
                   "constant_env" | "image_env", and that type's keys

An unknown key anywhere is an error naming the file and the key (and listing the valid
ones). Relative paths (mesh files, environment maps) are relative to the scene file.

Every built-in scene is one file in ``scenes/catalogue/``: adding a ``.toml`` file there
adds a scene.

Public API (stable): :func:`load_scene`, :func:`builtin_scene_names`,
:func:`builtin_scene_descriptions`, :func:`builtin_scene_path`, :func:`scene_from_dict`,
:func:`loads_scene`, :func:`save_scene`, :func:`scene_to_toml`, :data:`LIGHT_TYPES`,
:data:`CATALOGUE_DIR`.
"""

from __future__ import annotations

import functools
import os
from dataclasses import fields
from pathlib import Path

import numpy as np

from ..errors import InputError
from ..materials.factory import material_from_dict, material_to_dict
from ..tomlio import parse_toml, toml_value, tomllib
from .meshes import MESH_GENERATORS, cornell_box, load_mesh, rotation_matrix, save_mesh
from .scene import (
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
)

__all__ = [
    "CATALOGUE_DIR",
    "LIGHT_TYPES",
    "builtin_scene_descriptions",
    "builtin_scene_names",
    "builtin_scene_path",
    "load_scene",
    "loads_scene",
    "save_scene",
    "scene_from_dict",
    "scene_to_toml",
]

#: The folder of the built-in scenes, one TOML file each.
CATALOGUE_DIR = Path(__file__).with_name("catalogue")

#: ``type`` of a ``[[lights]]`` entry -> light class.
LIGHT_TYPES = {
    "point": PointLight,
    "spot": SpotLight,
    "directional": DirectionalLight,
    "rect": RectangularAreaLight,
    "sphere": SphereAreaLight,
    "constant_env": ConstantEnvironment,
    "image_env": ImageEnvironment,
}

SCENE_KEYS = ("name", "description", "mm_per_unit")
CAMERA_KEYS = ("origin", "target", "up", "fov", "width", "height")
OBJECT_KEYS = ("name", "mesh", "material")
TOP_LEVEL_KEYS = ("scene", "camera", "objects", "lights")
#: Keys of a mesh table besides the generator's own parameters.
TRANSFORM_KEYS = ("scale", "rotate", "translate")
#: Keys of a mesh table that hold a string (all others hold numbers).
MESH_STRING_KEYS = ("type", "file", "part", "shape", "normal")


def _check_keys(table, allowed, *, file, field):
    """Raise InputError for a non-table or for a key not in ``allowed``."""
    if not isinstance(table, dict):
        raise InputError("must be a table", file=file, field=field, value=table)
    for key in table:
        if key not in allowed:
            raise InputError(f"unknown key; valid keys: {', '.join(allowed)}", file=file,
                             field=f"{field}.{key}" if field else key, value=table[key])


def _check_types(table: dict, string_keys, *, file, field):
    """Raise InputError for a string where a number belongs, or the other way round.

    Every key of the scene, camera, mesh and light tables holds a number or a list of
    numbers, except ``string_keys`` (type names, file paths, ...), which hold a string.
    """
    for key, value in table.items():
        where = f"{field}.{key}" if field else key
        if key in string_keys:
            if not isinstance(value, str):
                raise InputError("must be a string", file=file, field=where, value=value)
            continue
        items = value if isinstance(value, list) else [value]
        if not all(isinstance(item, (int, float)) and not isinstance(item, bool)
                   for item in items):
            raise InputError("must be a number or a list of numbers", file=file, field=where,
                             value=value)


def _rewrap(error: InputError, *, file, prefix: str) -> InputError:
    """Place the same complaint in the scene file (``prefix``: where the table sits)."""
    inner = error.field
    if inner and prefix and inner.startswith(prefix.split(".")[0] + "."):
        where = inner  # already qualified (the camera's own messages say camera.fov)
    else:
        where = f"{prefix}.{inner}" if inner and prefix else (inner or prefix)
    return InputError(error.reason, file=file, field=where, value=error.value)


# ---------------------------------------------------------------------------------------
# reading


def _mesh(table: dict, name: str, *, file, field: str, base_dir: Path):
    """Build a mesh from ``{type = ...}`` or ``{file = ...}`` plus the transform keys."""
    if not isinstance(table, dict):
        raise InputError("must be a table with 'type' (procedural) or 'file'", file=file,
                         field=field, value=table)
    if ("type" in table) == ("file" in table):
        raise InputError("give exactly one of 'type' (procedural mesh) or 'file'", file=file,
                         field=field, value=sorted(table))
    _check_types(table, MESH_STRING_KEYS, file=file, field=field)
    parameters = {key: value for key, value in table.items()
                  if key not in TRANSFORM_KEYS + ("type", "file")}
    if "file" in table:
        _check_keys(parameters, (), file=file, field=field)
        mesh_path = Path(table["file"])
        if not mesh_path.is_absolute():
            mesh_path = base_dir / mesh_path
        try:
            mesh = load_mesh(mesh_path, name=name)
        except InputError as error:
            raise InputError(f"{error.reason} (loaded for {field} of {file})",
                             file=error.file, field=error.field, value=error.value) from error
    else:
        kind = table["type"]
        generators = {**MESH_GENERATORS, "cornell_box": cornell_box}
        if kind not in generators:
            raise InputError(f"unknown mesh type; valid: {', '.join(generators)}", file=file,
                             field=f"{field}.type", value=kind)
        import inspect

        accepted = [p for p in inspect.signature(generators[kind]).parameters if p != "name"]
        if kind == "cornell_box":
            accepted.append("part")
        _check_keys(parameters, tuple(accepted) + TRANSFORM_KEYS + ("type",), file=file,
                    field=field)
        arguments = {key: tuple(v) if isinstance(v, list) else v
                     for key, v in parameters.items()}
        try:
            if kind == "cornell_box":
                part = arguments.pop("part", None)
                parts = cornell_box(**arguments)
                if part not in parts:
                    raise InputError(f"must be one of {', '.join(parts)}", field="part",
                                     value=part)
                mesh = parts[part]
                mesh = type(mesh)(mesh.vertices, mesh.faces, mesh.normals, mesh.uv,
                                  mesh.grid_shape, name)
            else:
                mesh = generators[kind](**arguments, name=name)
        except InputError as error:
            raise _rewrap(error, file=file, prefix=field) from error
        except TypeError as error:  # a list where a number belongs, and the like
            raise InputError(f"bad parameters ({error})", file=file, field=field,
                             value=parameters) from error
    return _transform(mesh, table, file=file, field=field)


def _transform(mesh, table: dict, *, file, field: str):
    if not any(key in table for key in TRANSFORM_KEYS):
        return mesh
    try:
        scale = np.asarray(table.get("scale", 1.0), dtype=np.float64)
        if scale.shape not in ((), (3,)) or not np.isfinite(scale).all() or (scale <= 0).any():
            raise InputError("must be a number or [sx, sy, sz], each > 0", field="scale",
                             value=table.get("scale"))
        linear = rotation_matrix(table.get("rotate", (0.0, 0.0, 0.0))) \
            @ np.diag(np.broadcast_to(scale, (3,)))
        translate = np.asarray(table.get("translate", (0.0, 0.0, 0.0)), dtype=np.float64)
        if translate.shape != (3,) or not np.isfinite(translate).all():
            raise InputError("must be a finite 3-vector", field="translate",
                             value=table.get("translate"))
        return mesh.transformed(linear, translate=translate)
    except (InputError, ValueError) as error:
        if not isinstance(error, InputError):
            error = InputError(str(error), field="transform")
        raise _rewrap(error, file=file, prefix=field) from error


def _light(table: dict, *, file, field: str, base_dir: Path):
    if not isinstance(table, dict):
        raise InputError("must be a table with a 'type'", file=file, field=field, value=table)
    kind = table.get("type")
    if kind not in LIGHT_TYPES:
        raise InputError(f"unknown light type; valid: {', '.join(LIGHT_TYPES)}", file=file,
                         field=f"{field}.type", value=kind)
    cls = LIGHT_TYPES[kind]
    accepted = [f.name for f in fields(cls)]
    if cls is ImageEnvironment:
        accepted = ["file" if key == "radiance" else key for key in accepted]
    _check_keys(table, ("type", *accepted), file=file, field=field)
    _check_types(table, ("type", "file"), file=file, field=field)
    arguments = {key: value for key, value in table.items() if key != "type"}
    if cls is ImageEnvironment:
        if "file" not in arguments:
            raise InputError("an image_env light needs file (an EXR in latitude-longitude "
                             "layout)", file=file, field=f"{field}.file")
        image_path = Path(arguments.pop("file"))
        arguments["radiance"] = image_path if image_path.is_absolute() else base_dir / image_path
    try:
        return cls(**arguments)
    except InputError as error:
        if error.file is not None and cls is ImageEnvironment:
            raise  # the EXR's own complaint names the EXR
        raise _rewrap(error, file=file, prefix=field) from error
    except TypeError as error:  # a required key missing
        raise InputError(f"incomplete {kind} light ({error}); keys: {', '.join(accepted)}",
                         file=file, field=field) from error


def scene_from_dict(table: dict, *, file=None, base_dir=None) -> Scene:
    """Build a :class:`Scene` from a parsed scene file.

    Parameters
    ----------
    table : dict
        The parsed TOML (see the module docstring and ``docs/scene-format.md``).
    file : str or os.PathLike, optional
        Where it came from, for error messages; also the scene's ``source``.
    base_dir : str or os.PathLike, optional
        Folder that relative paths start from (default: the file's folder, else the
        working directory).

    Returns
    -------
    Scene

    Raises
    ------
    InputError
        Any unknown key, missing key or invalid value, naming the file and the key.
    """
    base = Path(base_dir) if base_dir is not None else \
        (Path(file).parent if file is not None else Path.cwd())
    _check_keys(table, TOP_LEVEL_KEYS, file=file, field="")
    header = table.get("scene", {})
    _check_keys(header, SCENE_KEYS, file=file, field="scene")
    _check_types(header, ("name", "description"), file=file, field="scene")
    if "camera" not in table:
        raise InputError("a scene needs a [camera] table (origin, target, ...)", file=file,
                         field="camera")
    camera_table = table["camera"]
    _check_keys(camera_table, CAMERA_KEYS, file=file, field="camera")
    _check_types(camera_table, (), file=file, field="camera")
    try:
        camera = Camera(**camera_table)
    except InputError as error:
        raise _rewrap(error, file=file, prefix="camera") from error
    except TypeError as error:
        missing = [key for key in ("origin", "target") if key not in camera_table]
        if missing:
            raise InputError("the camera needs origin and target", file=file,
                             field=f"camera.{missing[0]}") from error
        raise InputError(f"a camera value is not of its type ({error})", file=file,
                         field="camera", value=camera_table) from error
    object_tables = table.get("objects", [])
    if not isinstance(object_tables, list) or not object_tables:
        raise InputError("a scene needs at least one [[objects]] entry", file=file,
                         field="objects", value=object_tables)
    objects = []
    for index, entry in enumerate(object_tables):
        field = f"objects[{index}]"
        _check_keys(entry, OBJECT_KEYS, file=file, field=field)
        for key in OBJECT_KEYS:
            if key not in entry:
                raise InputError(f"an object needs {', '.join(OBJECT_KEYS)}", file=file,
                                 field=f"{field}.{key}")
        name = entry["name"]
        if not isinstance(name, str) or not name:
            raise InputError("must be a non-empty string", file=file, field=f"{field}.name",
                             value=name)
        mesh = _mesh(entry["mesh"], name, file=file, field=f"{field}.mesh", base_dir=base)
        material = material_from_dict(entry["material"], file=file, field=f"{field}.material",
                                      base_dir=base)
        objects.append(SceneObject(name, mesh, material))
    light_tables = table.get("lights", [])
    if not isinstance(light_tables, list):
        raise InputError("must be an array of tables ([[lights]])", file=file, field="lights",
                         value=light_tables)
    lights = [_light(entry, file=file, field=f"lights[{index}]", base_dir=base)
              for index, entry in enumerate(light_tables)]
    default_name = Path(file).stem if file is not None else "scene"
    try:
        return Scene(tuple(objects), tuple(lights), camera,
                     header.get("mm_per_unit", 1.0), header.get("name", default_name),
                     header.get("description", ""), None if file is None else str(file))
    except InputError as error:
        prefix = "scene" if error.field == "mm_per_unit" else ""
        raise _rewrap(error, file=file, prefix=prefix) from error


def loads_scene(text: str, *, file=None, base_dir=None) -> Scene:
    """Parse scene-file text (TOML) into a :class:`Scene` (see :func:`scene_from_dict`)."""
    return scene_from_dict(parse_toml(text, file=file), file=file, base_dir=base_dir)


def _stamp(path: Path):
    """``(modification time, size)`` of a file, or None when it cannot be read."""
    try:
        stat = path.stat()
    except (OSError, ValueError):  # missing, a name too long, a NUL: loading says which
        return None
    return stat.st_mtime_ns, stat.st_size


def _referenced_file_stamps(path: Path) -> tuple:
    """Stamps of the files a scene file names (meshes, textures, environment maps).

    A scene loaded before one of them changed must not be served from the cache. A file
    that does not parse gives no stamps: loading it raises anyway.
    """
    try:
        table = parse_toml(path.read_text(encoding="utf-8"), file=path)
    except (OSError, UnicodeDecodeError, InputError):
        return ()
    tables = []
    for entry in table.get("objects", []) if isinstance(table.get("objects"), list) else []:
        if isinstance(entry, dict):
            tables += [entry.get("mesh"), entry.get("material")]
    lights = table.get("lights")
    tables += lights if isinstance(lights, list) else []
    stamps = []
    for item in tables:
        if isinstance(item, dict) and isinstance(item.get("file"), str):
            referenced = path.parent / item["file"]
            stamps.append((str(referenced), _stamp(referenced)))
    return tuple(stamps)


@functools.lru_cache(maxsize=16)
def _load_file(path: str, modified_ns: int, size: int, referenced: tuple = ()) -> Scene:
    # keyed by modification time and size, of the file and of the files it names: an
    # edited file, or a scene whose mesh or texture was rewritten, is read again
    try:
        text = Path(path).read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as error:
        raise InputError(f"cannot read the scene file ({error})", file=path) from error
    return loads_scene(text, file=path)


def builtin_scene_path(name: str) -> Path:
    """Return the catalogue file of built-in scene ``name`` (case-insensitive).

    Raises
    ------
    InputError
        For an unknown name; the message lists the built-in scenes.
    """
    lookup = {candidate.lower(): candidate for candidate in builtin_scene_names()}
    key = lookup.get(str(name).strip().lower())
    if key is None:
        raise InputError(f"no such built-in scene (and no such file); built-in scenes: "
                         f"{', '.join(builtin_scene_names())}", field="scene", value=name)
    return CATALOGUE_DIR / f"{key}.toml"


def load_scene(name_or_path) -> Scene:
    """Load a built-in scene by name, or a scene file by path.

    Parameters
    ----------
    name_or_path : str or os.PathLike
        A name from :func:`builtin_scene_names` (``"sphere"``), or the path of a TOML
        scene file (anything that exists as a file, contains a path separator or ends in
        ``.toml``).

    Returns
    -------
    Scene
        Loading the same unchanged file again (the mesh, texture and environment files
        it names unchanged too) returns the same (immutable) object, so geometry-keyed
        caches (ray engines, precomputations) are shared.

    Raises
    ------
    InputError
        Unknown name (listing the built-in scenes), missing file, or anything wrong in the
        file (naming the file and key).
    """
    from ..atomic import check_input_file, note_input

    text = os.fspath(name_or_path)
    looks_like_path = isinstance(name_or_path, os.PathLike) or os.sep in text \
        or text.lower().endswith(".toml") or os.path.isfile(text)
    path = Path(text) if looks_like_path else builtin_scene_path(text)
    check_input_file(path, "scene", what="scene file")
    stat = path.stat()
    referenced = _referenced_file_stamps(path)
    scene = _load_file(str(path.resolve()), stat.st_mtime_ns, stat.st_size, referenced)
    # what an output of the command must never replace: the file and those it names
    note_input(path, "scene")
    for name, _ in referenced:
        note_input(name, f"a file {path.name} names")
    return scene


def builtin_scene_names() -> list[str]:
    """Names of the built-in scenes (the ``.toml`` files in :data:`CATALOGUE_DIR`), sorted."""
    return sorted(path.stem for path in CATALOGUE_DIR.glob("*.toml"))


def builtin_scene_descriptions() -> dict[str, str]:
    """``name -> one-line description`` of every built-in scene, without building meshes."""
    out = {}
    for name in builtin_scene_names():
        path = CATALOGUE_DIR / f"{name}.toml"
        try:
            header = tomllib.loads(path.read_text(encoding="utf-8")).get("scene", {})
        except tomllib.TOMLDecodeError as error:
            raise InputError(f"not valid TOML ({error})", file=path) from error
        out[name] = str(header.get("description", "")).strip().split("\n")[0]
    return out


# ---------------------------------------------------------------------------------------
# writing


def _table_lines(header: str, table: dict) -> list[str]:
    return [header] + [f"{key} = {toml_value(value)}" for key, value in table.items()] + [""]


def _light_table(light, *, environment_file: Path | None) -> dict:
    kind = next(name for name, cls in LIGHT_TYPES.items() if isinstance(light, cls))
    table = {"type": kind}
    for item in fields(light):
        value = getattr(light, item.name)
        if isinstance(light, ImageEnvironment) and item.name == "radiance":
            table["file"] = environment_file.name
            continue
        table[item.name] = value
    return table


def scene_to_toml(scene: Scene, mesh_files: dict[str, str],
                  environment_files: dict[int, str] | None = None) -> str:
    """Write the scene-file text of ``scene``, each object's mesh named by a file.

    Parameters
    ----------
    scene : Scene
    mesh_files : dict of str to str
        Object name -> mesh file name (relative to the scene file).
    environment_files : dict of int to str, optional
        Light index -> EXR file name, for image environments.

    Returns
    -------
    str
        TOML text that :func:`loads_scene` reads back to the same scene.
    """
    environment_files = environment_files or {}
    lines = _table_lines("[scene]", {"name": scene.name, "description": scene.description,
                                     "mm_per_unit": scene.mm_per_unit})
    camera = scene.camera
    lines += _table_lines("[camera]", {key: getattr(camera, key) for key in CAMERA_KEYS})
    for item in scene.objects:
        lines += _table_lines("[[objects]]", {"name": item.name,
                                              "mesh": {"file": mesh_files[item.name]},
                                              "material": material_to_dict(item.material)})
    for index, light in enumerate(scene.lights):
        target = environment_files.get(index)
        lines += _table_lines("[[lights]]", _light_table(
            light, environment_file=None if target is None else Path(target)))
    return "\n".join(lines)


def save_scene(scene: Scene, path) -> Path:
    """Write ``scene`` as a scene file, its meshes (``.npz``) and environment maps beside it.

    Meshes are written exactly (``<stem>.<object>.npz``; characters other than letters,
    digits, ``-`` and ``_`` become ``_``, and a name that then clashes with an earlier
    object's gets ``-<index>``), so a scene whose geometry was
    deformed or generated in code can be stored and loaded back unchanged. All files are
    written atomically.

    Parameters
    ----------
    scene : Scene
    path : str or os.PathLike
        The ``.toml`` file to write.

    Returns
    -------
    pathlib.Path
        ``path``.
    """
    from ..atomic import atomic_write_text
    from ..image import Image

    path = Path(path)
    mesh_files = {}
    taken = set()
    for index, item in enumerate(scene.objects):
        safe = "".join(c if c.isalnum() or c in "-_" else "_" for c in item.name)
        stem = safe
        while safe.lower() in taken:  # "a b" and "a_b" (or "A" and "a") would share a file
            safe = f"{stem}-{index}"
            index += len(scene.objects)
        taken.add(safe.lower())
        mesh_files[item.name] = f"{path.stem}.{safe}.npz"
    environment_files = {index: f"{path.stem}.environment{index}.exr"
                         for index, light in enumerate(scene.lights)
                         if isinstance(light, ImageEnvironment)}
    # the text first: a material that cannot be written refuses before any file is made
    text = scene_to_toml(scene, mesh_files, environment_files)
    for item in scene.objects:
        save_mesh(item.mesh, path.parent / mesh_files[item.name])
    for index, name in environment_files.items():
        Image(scene.lights[index].radiance).write(path.parent / name)
    return atomic_write_text(path, text)
