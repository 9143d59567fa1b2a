"""Render a scene with a fast method and write the EXR: ``translucent approx METHOD SCENE [...]``.

Each method adds its own options (``--material``, ``--gamma``, ...) through
``add_approx_arguments(parser)`` in its module, and turns them into a rendered image with
``approx(scene, args) -> Image``.
"""

from __future__ import annotations

import importlib
from pathlib import Path

from ...fast.base import METHODS


def add_arguments(parser):
    """One sub-command per fast method that is built."""
    sub = parser.add_subparsers(dest="method", metavar="METHOD", parser_class=type(parser))
    sub.required = True
    for name, module_name in METHODS.items():
        try:
            module = importlib.import_module(module_name)
        except ModuleNotFoundError as error:
            if error.name == module_name:
                continue
            raise
        if not hasattr(module, "approx"):
            continue
        command = sub.add_parser(name, help=(module.__doc__ or "").strip().split("\n")[0])
        command.add_argument("scene", help="built-in scene name or path to a scene TOML file")
        command.add_argument("--out", "-o", default=None,
                             help="output EXR (default: <scene>_<method>.exr)")
        if hasattr(module, "add_approx_arguments"):
            module.add_approx_arguments(command)
        command.set_defaults(approx_module=module)


def run(args) -> int:
    """Load the scene, check the output path, render with the method, write the EXR atomically."""
    from ...atomic import check_output_file
    from ...errors import InputError
    from ...scenes import load_scene
    from .record import record

    if args.out is not None and Path(args.out).suffix.lower() != ".exr":
        raise InputError("the output must be an OpenEXR file ending in .exr", field="--out",
                         value=args.out)
    scene = load_scene(args.scene)
    out = args.out or f"{scene.name}_{args.method}.exr"
    check_output_file(out, "--out", what="a file name ending in .exr")
    image = args.approx_module.approx(scene, args)
    image.write(out)
    seconds = image.metadata.get("seconds")
    timing = f" in {seconds:.3g} s" if isinstance(seconds, (int, float)) else ""
    print(f"wrote {out} ({image.shape[1]} x {image.shape[0]}){timing}")
    record(args, method=args.method, scene=scene.name, out=str(out),
           width=image.shape[1], height=image.shape[0],
           seconds=seconds if isinstance(seconds, (int, float)) else None,
           stage_seconds=image.metadata.get("stage_seconds", {}),
           skipped=image.metadata.get("skipped", []), notes=image.metadata.get("notes", []))
    return 0
