"""Render a scene with a fast method and write the EXR: ``translucent approx METHOD SCENE [...]``.

Each built-in method adds its own options (``--material``, ``--gamma``, ...) through
``add_approx_arguments(parser)`` in its module, and turns them into a rendered image with
``approx(scene, args) -> Image``. A registered method without them
(:mod:`translucent.fast.registry`) gets a flag per knob of its ``KNOBS`` spec
(:class:`~translucent.fast.knobs.KnobSpec`), or without one ``--knob NAME=VALUE``,
checked against its ``DEFAULT_KNOBS``; it is rendered by ``precompute(scene, **knobs).render()``.
"""

from __future__ import annotations

import time
from pathlib import Path

from ...errors import InputError
from ...fast.base import METHODS, method


def add_arguments(parser):
    """One sub-command per registered fast method that is built and follows the contract."""
    sub = parser.add_subparsers(dest="method", metavar="METHOD", parser_class=type(parser))
    sub.required = True
    for name in METHODS:
        try:
            module = method(name)
        except InputError:
            continue  # not installed, or not a method: `report` and `approx` name why when asked
        command = sub.add_parser(name, help=(module.__doc__ or "").strip().split("\n")[0])
        command.add_argument("scene", help="built-in scene name or path to a scene TOML file")
        command.add_argument("--out", "-o", default=None,
                             help="output EXR (default: <scene>_<method>.exr)")
        if hasattr(module, "approx"):
            if hasattr(module, "add_approx_arguments"):
                module.add_approx_arguments(command)
        elif _knob_spec(module) is not None:  # a flag per declared knob
            _knob_spec(module).add_arguments(command)
        else:
            knobs = ", ".join(f"{k} (default {v!r})" for k, v in module.DEFAULT_KNOBS.items())
            command.add_argument("--knob", action="append", default=[], metavar="NAME=VALUE",
                                 help=f"a knob of precompute, repeatable: {knobs or 'none'}")
        command.set_defaults(approx_module=module)


def knob_value(text: str, defaults: dict) -> tuple[str, object]:
    """Parse ``NAME=VALUE`` into a knob, the value read as the type of the knob's default.

    Raises
    ------
    InputError
        No ``=``, an unknown knob (the valid ones listed) or a value that is not of the
        default's type (``true``/``false`` for booleans).

    Examples
    --------
    >>> knob_value("samples=64", {"samples": 16})
    ('samples', 64)
    >>> knob_value("shadows=false", {"shadows": True})
    ('shadows', False)
    """
    name, equals, raw = text.partition("=")
    name, raw = name.strip(), raw.strip()
    if not equals or not name:
        raise InputError("must be NAME=VALUE", field="--knob", value=text)
    if name not in defaults:
        raise InputError(f"unknown knob; valid: {', '.join(defaults) or 'none'}",
                         field="--knob", value=text)
    default = defaults[name]
    try:
        if isinstance(default, bool):
            if raw.lower() not in ("true", "false"):
                raise ValueError(raw)
            return name, raw.lower() == "true"
        if isinstance(default, int):
            return name, int(raw)
        if isinstance(default, float):
            return name, float(raw)
    except ValueError as error:
        raise InputError(f"must be a {type(default).__name__}, as the default {default!r}",
                         field=f"--knob {name}", value=raw) from error
    if default is None and raw.lower() in ("none", "null"):
        return name, None
    return name, raw


def _knob_spec(module):
    """Return the method's :class:`~translucent.fast.knobs.KnobSpec`, or None."""
    from ...fast.knobs import KnobSpec

    spec = getattr(module, "KNOBS", None)
    return spec if isinstance(spec, KnobSpec) else None


def _render_with_knobs(module, scene, args):
    spec = _knob_spec(module)
    knobs = spec.from_arguments(args) if spec is not None else \
        dict(knob_value(text, module.DEFAULT_KNOBS) for text in args.knob)
    started = time.perf_counter()
    image = module.precompute(scene, **knobs).render()
    image.metadata.setdefault("seconds", time.perf_counter() - started)
    return image


def run(args) -> int:
    """Load the scene, check the output path, render with the method, write the EXR atomically."""
    from ...atomic import check_output_file, safe_file_name
    from ...errors import InputError
    from ...scenes import load_scene
    from .record import record

    if args.out is not None and Path(args.out).suffix.lower() != ".exr":
        raise InputError("the output must be an OpenEXR file ending in .exr", field="--out",
                         value=args.out)
    scene = load_scene(args.scene)
    out = args.out or f"{safe_file_name(scene.name)}_{args.method}.exr"
    check_output_file(out, "--out", what="a file name ending in .exr")
    module = args.approx_module
    image = module.approx(scene, args) if hasattr(module, "approx") else \
        _render_with_knobs(module, scene, args)
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
