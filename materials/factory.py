"""Materials from tables (scene files, command lines): a registry of material types.

A material table names its ``type`` and that type's keys, for example::

    {type = "measured", name = "marble"}
    {type = "measured", name = "marble", eta = 1.0}   # the table's medium, index-matched
    {type = "dipole", sigma_a = [0.0021, 0.0041, 0.0071], sigma_s_prime = [2.19, 2.62, 3.0],
     eta = 1.5, g = 0}
    {type = "lambertian", albedo = [0.8, 0.8, 0.8]}

Other modules add their own types with :func:`register_material_type` (for example
``"analytic_brdf"`` and ``"subedit"``); a scene file can use a type as soon as the module
that registers it has been imported. The keys a type accepts are its constructor's
keyword parameters, so an unknown key is reported with the list of valid ones.

Public API (stable): :data:`MATERIAL_TYPES`, :func:`register_material_type`,
:func:`material_from_dict`, :func:`material_to_dict`.
"""

from __future__ import annotations

import importlib
import inspect
import os
import pkgutil
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable

import numpy as np

from ..errors import InputError
from .catalogue import canonical_medium_name, measured_medium
from .homogeneous import Dipole, Lambertian

__all__ = [
    "MATERIAL_TYPES",
    "MaterialType",
    "material_from_dict",
    "material_to_dict",
    "register_material_type",
    "register_spec_type",
]


@dataclass(frozen=True)
class MaterialType:
    """One entry of the registry.

    Parameters
    ----------
    name : str
        The ``type`` value in a table.
    constructor : callable
        Called with the table's other keys as keyword arguments; returns the material.
    keys : tuple of str
        The keys the table may hold (besides ``type``).
    required : tuple of str
        Keys without a default.
    material_class : type, optional
        The class the constructor returns, so that :func:`material_to_dict` finds the type
        of a material.
    to_dict : callable, optional
        ``material -> table`` (without ``type``), the inverse of ``constructor``.
    path_keys : tuple of str
        Keys whose values are file paths: relative ones are read from the folder of the
        file the table came from (:func:`material_from_dict`).
    """

    name: str
    constructor: Callable[..., Any]
    keys: tuple[str, ...]
    required: tuple[str, ...]
    material_class: type | None = None
    to_dict: Callable[[Any], dict] | None = None
    path_keys: tuple[str, ...] = ()


#: type name -> MaterialType. Add entries with :func:`register_material_type`.
MATERIAL_TYPES: dict[str, MaterialType] = {}



def register_material_type(name: str, constructor: Callable[..., Any], *,
                           material_class: type | None = None,
                           to_dict: Callable[[Any], dict] | None = None,
                           keys=None, path_keys=()) -> MaterialType:
    """Add a material type to :data:`MATERIAL_TYPES` (replacing one of the same name).

    Parameters
    ----------
    name : str
        The ``type`` value tables use, lower case (``"analytic_brdf"``).
    constructor : callable
        Builds the material from keyword arguments (a class or a function); it validates
        them and raises :class:`~translucent.errors.InputError` (or ``ValueError``)
        naming the field.
    material_class : type, optional
        The class of what ``constructor`` returns (default: ``constructor`` itself when
        it is a class).
    to_dict : callable, optional
        ``material -> dict`` of the keys that rebuild it; used when a scene is written
        back to a file. A ``type`` in the dict overrides ``name`` (a measured medium is
        written as ``{type = "measured", name = ...}``). Default: the constructor's
        parameters read as attributes of the material.
    keys : iterable of str, optional
        The accepted keys (default: the constructor's keyword parameters).
    path_keys : iterable of str, optional
        Accepted keys that hold file paths; :func:`material_from_dict` hands the
        constructor these resolved against the table's folder.

    Returns
    -------
    MaterialType
    """
    if not isinstance(name, str) or not name or name != name.lower():
        raise InputError("a material type name must be a non-empty lower-case string",
                         field="type", value=name)
    parameters = inspect.signature(constructor).parameters.values()
    named = [p for p in parameters if p.kind in (p.POSITIONAL_OR_KEYWORD, p.KEYWORD_ONLY)]
    accepted = tuple(keys) if keys is not None else tuple(p.name for p in named)
    required = tuple(p.name for p in named if p.default is p.empty and p.name in accepted)
    if material_class is None and isinstance(constructor, type):
        material_class = constructor
    entry = MaterialType(name, constructor, accepted, required, material_class, to_dict,
                         tuple(path_keys))
    MATERIAL_TYPES[name] = entry
    return entry


def register_spec_type(name: str, from_spec: Callable[[dict], Any], material_class: type, *,
                       keys, path_keys=(), save_hint: str) -> MaterialType:
    """Register a type whose material is built from its whole table (a "spec").

    ``from_spec(table)`` builds the material; the table is kept on it, so that
    :func:`material_to_dict` writes back exactly what built it. A material of that class
    made in code has no table: writing it raises :class:`InputError` with ``save_hint``
    (how to save it to a file a table can name).
    """
    def constructor(**table):
        material = from_spec(table)
        material.__dict__["_spec"] = dict(table)  # what rebuilds it, for material_to_dict
        return material

    def to_dict(material) -> dict:
        spec = material.__dict__.get("_spec")
        if spec is None:
            raise InputError(save_hint, field="material", value=getattr(material, "name", ""))
        return dict(spec)

    return register_material_type(name, constructor, material_class=material_class,
                                  to_dict=to_dict, keys=keys, path_keys=path_keys)


def spec_file_path(value, file, what: str) -> Path:
    """Return the path a table's ``file`` key names, relative to the table's own file.

    ``what`` says what the file holds ("a .npz grid"), for the error on a non-string.
    """
    if not isinstance(value, (str, Path)):
        raise InputError(f"must be a string (the path of {what})", file=file, field="file",
                         value=value)
    path = Path(value)
    if file is not None and not path.is_absolute():
        path = Path(file).parent / path
    return path


def _load_plugins() -> None:
    """Import every module of this package, so that the types they register are known.

    A scene file can then name a type (``"subedit"``) without its caller importing the
    module that registers it.
    """
    package = importlib.import_module(__package__)
    for module in pkgutil.iter_modules(package.__path__):
        importlib.import_module(f"{__package__}.{module.name}")


def material_from_dict(table: dict, *, file=None, field: str = "material", base_dir=None):
    """Build a material from a table such as ``{type = "measured", name = "marble"}``.

    Parameters
    ----------
    table : dict
        ``type`` (a key of :data:`MATERIAL_TYPES`) and that type's keys. Coefficients in
        mm^-1, as the material classes take them.
    file : str or os.PathLike, optional
        The file the table came from (error messages).
    field : str
        Where the table sits in that file (``"objects[2].material"``); error messages
        name ``field.key``.
    base_dir : str or os.PathLike, optional
        Folder that relative paths (the type's ``path_keys``) start from; default the
        folder of ``file``, else the current folder.

    Returns
    -------
    object
        The material (:class:`~translucent.materials.Dipole`,
        :class:`~translucent.materials.Lambertian`, ...).

    Raises
    ------
    InputError
        Not a table, missing or unknown ``type`` (the message lists the valid types), an
        unknown or missing key (the message lists the valid keys), or a value the
        material rejects.
    """
    if not isinstance(table, dict):
        raise InputError("must be a table such as {type = \"measured\", name = \"marble\"}",
                         file=file, field=field, value=table)
    kind = table.get("type")
    if kind not in MATERIAL_TYPES:
        _load_plugins()
    if kind not in MATERIAL_TYPES:
        raise InputError(f"unknown material type; valid: {', '.join(sorted(MATERIAL_TYPES))}",
                         file=file, field=f"{field}.type", value=kind)
    entry = MATERIAL_TYPES[kind]
    arguments = {key: value for key, value in table.items() if key != "type"}
    unknown = [key for key in arguments if key not in entry.keys]
    if unknown:
        raise InputError(f"unknown key for a {kind} material; valid keys: "
                         f"{', '.join(('type',) + entry.keys)}", file=file,
                         field=f"{field}.{unknown[0]}", value=arguments[unknown[0]])
    missing = [key for key in entry.required if key not in arguments]
    if missing:
        raise InputError(f"a {kind} material needs {', '.join(missing)}", file=file,
                         field=f"{field}.{missing[0]}")
    if entry.path_keys:
        base = Path(base_dir) if base_dir is not None else \
            (Path(file).parent if file is not None else None)
        for key in entry.path_keys:
            value = arguments.get(key)
            if base is not None and isinstance(value, str | os.PathLike) \
                    and not Path(value).is_absolute():
                arguments[key] = str(base / value)
    try:
        return entry.constructor(**arguments)
    except InputError as error:
        where = f"{field}.{error.field}" if error.field else field
        raise InputError(error.reason, file=file, field=where, value=error.value) from error
    except (TypeError, ValueError) as error:
        raise InputError(str(error), file=file, field=field, value=table) from error


def material_to_dict(material) -> dict:
    """Return the table that :func:`material_from_dict` turns back into ``material``.

    Parameters
    ----------
    material : object
        An instance of a registered material class.

    Returns
    -------
    dict
        ``type`` and the keys, with arrays as lists of floats.

    Raises
    ------
    InputError
        When no registered type has the material's class.
    """
    entry = _type_of(material)
    if entry is None:
        _load_plugins()
        entry = _type_of(material)
    if entry is not None:
        if entry.to_dict is not None:
            values = entry.to_dict(material)
        else:
            values = {key: getattr(material, key) for key in entry.keys
                      if hasattr(material, key)}
        values = {"type": entry.name, **values}
        return {key: _plain(value) for key, value in values.items()}
    raise InputError("no registered material type builds this class; registered: "
                     f"{', '.join(sorted(MATERIAL_TYPES))}", field="material",
                     value=type(material).__name__)


def _type_of(material) -> MaterialType | None:
    for entry in MATERIAL_TYPES.values():
        if entry.material_class is not None and type(material) is entry.material_class:
            return entry
    return None


def _plain(value):
    """Numbers and lists of numbers as TOML can hold them."""
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, np.generic):
        return value.item()
    return value


def _measured(name: str, eta: float | None = None) -> Dipole:
    """Build a measured medium; ``eta`` replaces the table's index (1.0: index-matched)."""
    try:
        medium = measured_medium(name)
    except InputError as error:
        raise InputError(error.reason, field="name", value=name) from error
    if eta is None:
        return medium
    try:
        return Dipole(medium.sigma_a, medium.sigma_s_prime, eta=eta, g=medium.g,
                      name=medium.name)
    except InputError as error:
        raise InputError(error.reason, field="eta", value=eta) from error


def _dipole_to_dict(material: Dipole) -> dict:
    # either table's media (Jensen et al. 2001, Narasimhan et al. 2006) by their own spelling
    key = canonical_medium_name(material.name) if material.name else None
    if key is not None:
        table = measured_medium(key)
        same = (np.array_equal(material.sigma_a, table.sigma_a)
                and np.array_equal(material.sigma_s_prime, table.sigma_s_prime)
                and material.g == table.g)
        if same and material.eta == table.eta:
            return {"type": "measured", "name": key}
        if same:
            return {"type": "measured", "name": key, "eta": material.eta}
    out = {"sigma_a": material.sigma_a, "sigma_s_prime": material.sigma_s_prime,
           "eta": material.eta, "g": material.g}
    if material.name:
        out["name"] = material.name
    return out


def _lambertian_to_dict(material: Lambertian) -> dict:
    out = {"albedo": material.albedo}
    if material.name:
        out["name"] = material.name
    return out


register_material_type("measured", _measured, keys=("name", "eta"))
register_material_type("dipole", Dipole, to_dict=_dipole_to_dict)
register_material_type("lambertian", Lambertian, to_dict=_lambertian_to_dict)
