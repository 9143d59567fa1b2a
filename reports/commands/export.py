"""Write a scene for another renderer: ``translucent export SCENE --format mitsuba [--out DIR]``.

``mitsuba``: Mitsuba 3 XML with its meshes (PLY), volumes and environment maps, converted
as the references are (:func:`translucent.reference.mitsuba_export.export_mitsuba`), so a
renderer that reads it sees the camera, media, BSDFs and lights the suite's reference was
rendered from. Render it, then score the images with ``translucent report --images DIR``.
"""

from __future__ import annotations

from ...errors import InputError
from .record import record

#: The formats written.
FORMATS = ("mitsuba",)


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
