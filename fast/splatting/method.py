"""The fast-method contract of splatting: command-line options and approx."""

from __future__ import annotations

from ...image import Image
from .knobs import KNOBS
from .state import precompute


def add_approx_arguments(parser) -> None:
    """Options of ``translucent approx splatting SCENE``."""
    parser.add_argument("--material", default=None,
                        help="replace the translucent material: a built-in SubEdit name "
                             "(checker, veined_marble, wax_gradient) or a SubEdit .npz file")
    KNOBS.add_arguments(parser)


def approx(scene, args) -> Image:
    """Render ``scene`` with the options parsed by :func:`add_approx_arguments`."""
    from ...materials.subedit import BUILTIN_SUBEDIT, builtin_subedit, load_subedit

    knobs = KNOBS.from_arguments(args)
    material = None
    if args.material:
        material = builtin_subedit(args.material) if args.material in BUILTIN_SUBEDIT \
            else load_subedit(args.material)
    return precompute(scene, **knobs).render(material=material)
