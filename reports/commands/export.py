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
                        help="volpath, volpathmis, volpath_mnee or path (default: the "
                             "reference's own choice)")


def run(args) -> int:
    """Convert the scene and write the files; say what a reader needs to know."""
    from ...reference.mitsuba_export import SUITE_PLUGINS, export_mitsuba
    from ...scenes import load_scene

    if args.format not in FORMATS:
        raise InputError(f"unknown format; valid: {', '.join(FORMATS)}", field="--format",
                         value=args.format)
    scene = load_scene(args.scene)
    out = args.out or f"{scene.name}_{args.format}"
    path = export_mitsuba(scene, out, spp=args.spp, integrator=args.integrator)
    text = path.read_text()
    plugins = sorted(p for p in SUITE_PLUGINS if f'type="{p}"' in text)
    print(f"wrote {path}")
    for plugin in plugins:
        print(f"note: {plugin} is a plugin of translucent; load the file after "
              "translucent.reference.mitsuba_export.register_suite_plugins()")
    record(args, scene=scene.name, format=args.format, out=str(path), suite_plugins=plugins)
    return 0
