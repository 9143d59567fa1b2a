"""Write a scene for another renderer: ``translucent export SCENE --format mitsuba|blender``.

``mitsuba``: Mitsuba 3 XML with its meshes (PLY), volumes and environment maps, converted
as the references are (:func:`translucent.reference.mitsuba_export.export_mitsuba`), so a
renderer that reads it sees the camera, media, BSDFs and lights the suite's reference was
rendered from. Render it, then score the images with ``translucent report --images DIR``.

``blender``: the scene as Blender Cycles is given it by ``translucent report --renderers
cycles`` (:func:`translucent.reference.peers.blender.describe_scene`, ``--mode`` choosing
how media are given): ``scene.json``, ``build_cycles.py`` that builds and renders it in
Blender (``blender --background --python build_cycles.py -- scene.json``), and, where a
Python with ``bpy`` is found (``TRANSLUCENT_BPY_PYTHON``), ``scene.blend`` to open.
"""

from __future__ import annotations

from ...errors import InputError
from .record import record

#: The formats written.
FORMATS = ("mitsuba", "blender")


def add_arguments(parser):
    """``SCENE --format mitsuba [--out DIR] [--spp N] [--integrator NAME]``."""
    parser.add_argument("scene", help="built-in scene name or path to a scene TOML file")
    parser.add_argument("--format", default="mitsuba", help=f"one of {', '.join(FORMATS)}")
    parser.add_argument("--out", "-o", default=None,
                        help="folder of the files (default: <scene>_<format>)")
    parser.add_argument("--spp", type=int, default=64,
                        help="the sampler's samples per pixel written into the file")
    parser.add_argument("--integrator", default=None,
                        help="volpath, volpathmis, volpath_mnee, path or bssrdf_path "
                             "(default: the reference's own choice)")
    parser.add_argument("--mode", default=None,
                        help="with --format blender: how media are given to Cycles: volume "
                             "(default), burley, random_walk or random_walk_skin")
    parser.add_argument("--profile", default=None, metavar="NAME",
                        help="with --integrator bssrdf_path: the radial profile of the "
                             "translucent objects (its tables are written beside the XML)")


def run(args) -> int:
    """Convert the scene and write the files; say what a reader needs to know."""
    from ...reference.mitsuba_export import SUITE_PLUGINS, export_mitsuba
    from ...scenes import load_scene

    if args.format not in FORMATS:
        raise InputError(f"unknown format; valid: {', '.join(FORMATS)}", field="--format",
                         value=args.format)
    given = {"--integrator": args.integrator, "--profile": args.profile} \
        if args.format == "blender" else {"--mode": args.mode}
    for field, value in given.items():
        if value is not None:
            raise InputError(f"does not go with --format {args.format}", field=field,
                             value=value)
    from ...reference.model_keys import parse_model_key

    if args.profile is not None and parse_model_key(args.profile)[1]:
        raise InputError("the object's geometry is added by the suite's own render "
                         "(translucent render --integrator bssrdf_path), not by a Mitsuba "
                         f"file: export --profile {parse_model_key(args.profile)[0]}",
                         field="--profile", value=args.profile)
    import os
    from pathlib import Path

    from ...atomic import check_output_folder, output_folder, safe_file_name
    from ...staging import staged_outputs

    scene = load_scene(args.scene)
    # a name from the scene file: never a path out of the working folder
    out = Path(args.out or f"{safe_file_name(scene.name)}_{args.format}")
    if os.path.exists(out) and not os.path.isdir(out):  # export_mitsuba's words, at once
        raise InputError("must be a folder (or a path where one can be made)", field="--out",
                         value=str(out))
    check_output_folder(out, "--out")
    # written beside --out and moved in when complete: a failure (a full disk: Mitsuba's
    # and NumPy's writers say so in their own words) leaves none of the files, and no
    # folder made for them
    if args.format == "blender":
        return _export_blender(scene, out, args)
    with staged_outputs(out, field="--out") as staging, \
            output_folder(staging, field="--out", value=str(out)):
        written = export_mitsuba(scene, staging, spp=args.spp, integrator=args.integrator,
                                 profile=args.profile)
    path = out / written.relative_to(staging)
    text = path.read_text()
    plugins = sorted(p for p in SUITE_PLUGINS if f'type="{p}"' in text)
    print(f"wrote {path}")
    for plugin in plugins:
        print(f"note: {plugin} is a plugin of translucent; load the file after "
              "translucent.reference.mitsuba_export.register_suite_plugins()")
    record(args, scene=scene.name, format=args.format, out=str(path), suite_plugins=plugins)
    return 0


def _export_blender(scene, out, args) -> int:
    """Write the Cycles description, its build script and, with ``bpy``, the ``.blend``."""
    import shutil
    import tempfile
    from pathlib import Path

    from ...atomic import output_folder
    from ...reference.peers import blender, cycles
    from ...staging import staged_outputs

    mode = args.mode or "volume"
    if mode not in blender.MODES:
        raise InputError(f"unknown Cycles mode; valid: {', '.join(blender.MODES)}",
                         field="--mode", value=mode)
    description = blender.describe_scene(scene, renders=[(args.spp, 0)], output="renders",
                                         mode=mode)
    missing = cycles.available()
    with staged_outputs(out, field="--out") as staging, \
            output_folder(staging, field="--out", value=str(out)):
        blender.write_description(description, staging)
        shutil.copyfile(blender.WORKER, Path(staging) / "build_cycles.py")
        if missing is None:
            with tempfile.TemporaryDirectory(prefix="translucent-cycles-") as folder:
                blend = {**description, "renders": [], "output": str(Path(folder) / "r"),
                         "save_blend": str(Path(staging).resolve() / "scene.blend")}
                try:
                    blender.run_worker(blend, Path(folder))
                except RuntimeError as error:
                    raise InputError(f"Blender could not build the scene: {error}",
                                     field=blender.BPY_PYTHON_VARIABLE,
                                     value=blender.bpy_python()) from None
    print(f"wrote {out / 'scene.json'} and {out / 'build_cycles.py'}"
          + (f" and {out / 'scene.blend'}" if missing is None else ""))
    print(f"render it: cd {out} && blender --background --python build_cycles.py -- "
          "scene.json (each render in renders/render_<k>.npy, radiance in the suite's units)")
    if missing is not None:
        print(f"note: no scene.blend: {missing}")
    record(args, scene=scene.name, format=args.format, mode=mode, out=str(out))
    return 0
