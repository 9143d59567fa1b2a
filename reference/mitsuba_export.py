"""A scene written as Mitsuba 3 XML with its meshes: what any renderer that reads it renders.

:func:`export_mitsuba` converts a scene as the references do
(:func:`~translucent.reference.mitsuba_scene.convert_scene`: the same camera, media,
BSDFs, lights and integrator) and writes ``<scene>.xml`` beside ``meshes/*.ply``,
``volumes/*.vol`` (heterogeneous media) and ``textures/*.exr`` (environment maps), with
paths relative to the XML. ``mitsuba.load_file`` renders it to the suite's reference
(tested with the z-test against the committed references).

Three plugins of the suite are Python code registered at run time, not part of Mitsuba:
the analytic BRDFs of :mod:`translucent.reference.brdf_plugins`, the ``volpath_mnee``
integrator and the ``bssrdf_path`` integrator (its profile tables are written to
``profiles/*.npz``, which the XML names). A file that uses them says so in its header
comment; load it after :func:`register_suite_plugins` has registered them.

Lengths are those of the rendering frame (:mod:`translucent.scenes.frame`), which the header
comment states: the scene moved and scaled so that Mitsuba's float32 ray offsets do not
depend on the scene's unit.
"""

from __future__ import annotations

import os
import re
import xml.etree.ElementTree as ElementTree
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import InputError

__all__ = ["SUITE_PLUGINS", "export_mitsuba", "register_suite_plugins"]

#: Plugin type -> the XML tag of its kind, for every plugin the converter emits.
TAGS = {
    "scene": "scene", "volpath": "integrator", "volpathmis": "integrator",
    "volpath_mnee": "integrator", "path": "integrator", "bssrdf_path": "integrator",
    "perspective": "sensor",
    "hdrfilm": "film", "independent": "sampler", "box": "rfilter", "gaussian": "rfilter",
    "diffuse": "bsdf", "twosided": "bsdf", "dielectric": "bsdf", "null": "bsdf",
    "roughdielectric": "bsdf", "translucent_analytic_brdf": "bsdf", "homogeneous": "medium",
    "heterogeneous": "medium", "isotropic": "phase", "hg": "phase", "point": "emitter",
    "spot": "emitter", "directional": "emitter", "area": "emitter", "envmap": "emitter",
    "constant": "emitter", "gridvolume": "volume", "constvolume": "volume",
    "bitmap": "texture", "sphere": "shape", "rectangle": "shape", "ply": "shape",
    "obj": "shape",
}

#: Plugins of the suite (Python, registered at run time) and what registers them.
SUITE_PLUGINS = {"translucent_analytic_brdf": "translucent.reference.brdf_plugins",
                 "volpath_mnee": "translucent.reference.manifold_nee",
                 "bssrdf_path": "translucent.reference.bssrdf_path"}

#: Why a chromatic medium of long walks is written with ``volpathmis``: its references are
#: rendered one channel at a time with ``volpath``, which one RGB file cannot ask for, and
#: Mitsuba's ``volpath`` in RGB is biased for such media (measured on the Cornell block's
#: Skimmilk at 32 and 128 spp x 16: 2.6 and 2.2 % dark in red against the per-channel
#: reference, z = -15 and -7.9), while ``volpathmis`` (spectral MIS) agrees with it (z <= 1.1
#: on the Cornell block and the Marble sphere).
RGB_VOLPATH_NOTE = ("volpathmis, not volpath: the suite renders this chromatic medium one "
                    "channel at a time with volpath; in one RGB render volpath is biased for "
                    "it and volpathmis is not")

#: Parameters that are positions (written as <point>); other 3-vectors are <vector>.
POINTS = {"position", "origin", "target", "center", "centre"}


def register_suite_plugins() -> None:
    """Register the suite's Python plugins with Mitsuba (before loading an exported file)."""
    from .brdf_plugins import register_plugin
    from .bssrdf_path import register as register_bssrdf
    from .manifold_nee import register

    register_plugin()
    for register_integrator in (register, register_bssrdf):
        try:
            register_integrator()
        except InputError:
            pass  # a variant without JIT cannot run them; the other plugins still work


class _Writer:
    def __init__(self, folder: Path):
        self.folder = folder
        self.files: list[Path] = []
        self.suite_plugins: set[str] = set()
        self.shape = "scene"  # the shape whose plugins are being written (names volumes)

    def _file(self, kind: str, name: str, suffix: str) -> tuple[Path, str]:
        slug = re.sub(r"[^A-Za-z0-9_.-]+", "_", name).strip("._") or kind
        relative, count = f"{kind}/{slug}{suffix}", 2
        while self.folder / relative in self.files:  # two media each with a sigma_t grid
            relative, count = f"{kind}/{slug}-{count}{suffix}", count + 1
        path = self.folder / relative
        path.parent.mkdir(parents=True, exist_ok=True)
        self.files.append(path)
        return path, relative

    def plugin(self, parent, key: str | None, value: dict, *, top: bool = False):
        kind = value.get("type")
        if kind not in TAGS:
            raise InputError(f"cannot write this Mitsuba plugin as XML; known: "
                             f"{', '.join(sorted(TAGS))}", field=key or "scene", value=kind)
        if kind in SUITE_PLUGINS:
            self.suite_plugins.add(kind)
        element = ElementTree.SubElement(parent, TAGS[kind], {"type": kind})
        if key is not None:
            element.set("id" if top else "name", key)
        for name, item in value.items():
            if name == "type":
                continue
            if kind == "gridvolume" and name == "grid":
                path, relative = self._file("volumes", f"{self.shape}_{key or 'grid'}", ".vol")
                item.write(str(path))
                self.value(element, "filename", relative)
            elif kind == "envmap" and name == "bitmap":
                path, relative = self._file("textures", key or "environment", ".exr")
                item.write(str(path))
                self.value(element, "filename", relative)
            else:
                self.value(element, name, item)
        return element

    def mesh(self, parent, key: str, mesh, props: dict):
        self.shape = key
        path, relative = self._file("meshes", key, ".ply")
        mesh.write_ply(str(path))
        element = ElementTree.SubElement(parent, "shape", {"type": "ply", "id": key})
        self.value(element, "filename", relative)
        for name, item in props.items():
            self.value(element, name, item)

    def value(self, parent, name: str, item: Any) -> None:
        from ..backend import mitsuba

        mi = mitsuba()
        if isinstance(item, dict):
            if item.get("type") == "rgb":
                values = np.atleast_1d(np.asarray(item["value"], dtype=float))
                ElementTree.SubElement(parent, "rgb", {"name": name,
                                                       "value": _numbers(values)})
            else:
                self.plugin(parent, name, item)
        elif isinstance(item, bool):
            ElementTree.SubElement(parent, "boolean",
                                   {"name": name, "value": "true" if item else "false"})
        elif isinstance(item, (int, np.integer)):
            ElementTree.SubElement(parent, "integer", {"name": name, "value": str(int(item))})
        elif isinstance(item, (float, np.floating)):
            ElementTree.SubElement(parent, "float", {"name": name, "value": repr(float(item))})
        elif isinstance(item, str):
            ElementTree.SubElement(parent, "string", {"name": name, "value": item})
        elif isinstance(item, (mi.ScalarTransform4f, getattr(mi, "ScalarAffineTransform4f",
                                                             mi.ScalarTransform4f))):
            transform = ElementTree.SubElement(parent, "transform", {"name": name})
            ElementTree.SubElement(transform, "matrix",
                                   {"value": _numbers(np.asarray(item.matrix).ravel())})
        else:
            values = np.asarray(item, dtype=float)
            if values.shape == (3,):
                ElementTree.SubElement(parent, "point" if name in POINTS else "vector",
                                       {"name": name, "value": _numbers(values)})
            elif values.shape == ():
                ElementTree.SubElement(parent, "float",
                                       {"name": name, "value": repr(float(values))})
            else:
                raise InputError("cannot write this value as a Mitsuba XML property",
                                 field=name, value=type(item).__name__)


def _numbers(values) -> str:
    return ", ".join(repr(float(v)) for v in np.ravel(values))


def export_mitsuba(scene, out, *, spp: int = 64, integrator: str | None = None,
                   profile: str | None = None) -> Path:
    """Write ``scene`` as Mitsuba 3 XML with its meshes into the folder ``out``.

    Parameters
    ----------
    scene : Scene
    out : str or PathLike
        A folder (created); ``<scene name>.xml`` and the ``meshes/``, ``volumes/`` and
        ``textures/`` it refers to are written there. Files of the same names are
        replaced; nothing is left half-written on an error.
    spp : int
        The sampler's samples per pixel (a renderer may override it).
    integrator : str, optional
        As :func:`~translucent.reference.mitsuba_scene.convert_scene`: default the
        reference's own choice for one RGB render (``volpathmis`` for a chromatic medium,
        which the references may render one channel at a time: :data:`RGB_VOLPATH_NOTE`).
    profile : str, optional
        With ``bssrdf_path``: the profile; its tables are written to ``profiles/`` beside
        the XML, which the integrator names.

    Returns
    -------
    Path
        The XML file.

    Raises
    ------
    InputError
        A scene the converter refuses, or a plugin or value that has no XML form.

    Examples
    --------
    >>> import tempfile, translucent
    >>> from translucent.reference.mitsuba_export import export_mitsuba
    >>> folder = tempfile.mkdtemp()
    >>> path = export_mitsuba(translucent.load_scene("sphere"), folder)
    >>> path.name, sorted(p.name for p in (path.parent / "meshes").iterdir())
    ('sphere.xml', ['object_sphere.ply'])
    """
    import shutil
    import tempfile

    from ..atomic import (
        atomic_write_text,
        check_output_folder,
        claim_output,
        make_output_folder,
        safe_file_name,
    )
    from ..errors import check_count
    from .mitsuba_scene import convert_scene
    from .render import MAX_SAMPLES_PER_RENDER

    spp = check_count(spp, "spp")
    pixels = scene.camera.width * scene.camera.height
    if spp * pixels > MAX_SAMPLES_PER_RENDER:  # what Mitsuba could not render
        raise InputError(f"{pixels:,} pixels x {spp} spp exceed the {MAX_SAMPLES_PER_RENDER:,} "
                         f"samples Mitsuba numbers in 32 bits: give at most "
                         f"{MAX_SAMPLES_PER_RENDER // pixels}", field="spp", value=spp)
    out = Path(out)
    if os.path.exists(out) and not out.is_dir():  # a name too long: check_output_folder
        raise InputError("must be a folder (or a path where one can be made)", field="--out",
                         value=str(out))
    check_output_folder(out, "--out")
    conversion = convert_scene(scene, spp=spp, integrator=integrator, profile=profile)
    notes = []
    if integrator is None and conversion.per_channel_recommended \
            and conversion.integrator == "volpathmis":
        # one RGB file cannot be rendered one channel at a time, as the references of such
        # media are: it says which estimator stands in
        notes.append(RGB_VOLPATH_NOTE)
    make_output_folder(out, field="--out", value=str(out))
    staging = Path(tempfile.mkdtemp(prefix=".export-", dir=out))
    try:
        writer = _Writer(staging)
        if conversion.profile:  # bssrdf_path: the profile tables, in a file the XML names
            from .bssrdf_tables import registered_tables

            props = conversion.scene_dict["integrator"]
            path, relative = writer._file("profiles", scene.name, ".npz")
            registered_tables(props["tables"]).save(path)
            conversion.scene_dict["integrator"] = {**props, "tables": relative}
        root = ElementTree.Element("scene", {"version": "3.0.0"})
        for key, item in conversion.scene_dict.items():
            if key == "type":
                continue
            if key in conversion.shape_props:
                writer.mesh(root, key, item, conversion.shape_props[key])
            elif isinstance(item, dict):
                writer.plugin(root, key, item, top=True)
            else:
                raise InputError("cannot write this scene entry as XML", field=key,
                                 value=type(item).__name__)
        ElementTree.indent(root)
        header = [f"translucent scene {scene.name!r} for Mitsuba 3",
                  f"integrator {conversion.integrator}"
                  + ("" if notes else ", as the suite's references")] + notes
        header += [f"light: {sentence}" for sentence in conversion.substitutions]
        frame = conversion.frame
        header.append(f"lengths in the rendering frame x' = (x - {list(frame.origin)}) * "
                      f"{frame.scale:g} of the scene's units (translucent.scenes.frame: "
                      "float32 ray offsets independent of the unit)")
        for plugin in sorted(writer.suite_plugins):
            header.append(f"{plugin} is a plugin of translucent: load this file after "
                          "translucent.reference.mitsuba_export.register_suite_plugins()")
        comments = "".join(f"<!-- {line.replace('--', '-')} -->\n" for line in header)
        text = comments + ElementTree.tostring(root, encoding="unicode") + "\n"
        xml_path = out / f"{safe_file_name(scene.name, fallback='scene')}.xml"
        targets = [out / path.relative_to(staging) for path in writer.files]
        for target in targets + [xml_path]:  # none of them may be an input of the scene
            claim_output(target, "--out")
        for path, target in zip(writer.files, targets, strict=True):
            target.parent.mkdir(parents=True, exist_ok=True)
            path.replace(target)
        atomic_write_text(xml_path, text)
    finally:
        shutil.rmtree(staging, ignore_errors=True)
    return xml_path
