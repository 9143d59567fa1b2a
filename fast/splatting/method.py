"""The fast-method contract of splatting: command-line options and approx."""

from __future__ import annotations

import argparse

from ...image import Image
from .knobs import BACKENDS, DEFAULT_KNOBS
from .selection import SAMPLING_RANGES
from .state import precompute


def add_approx_arguments(parser) -> None:
    """Options of ``translucent approx splatting SCENE``."""
    parser.add_argument("--irradiance-resolution", type=int,
                        default=DEFAULT_KNOBS["irradiance_resolution"],
                        help="irradiance buffer side in pixels (default 512)")
    parser.add_argument("--levels", type=int, default=DEFAULT_KNOBS["levels"],
                        help="mipmap levels of both buffers (default 3)")
    parser.add_argument("--no-multiresolution", action="store_true",
                        help="splat everything at full resolution (ablation)")
    parser.add_argument("--no-adaptive", action="store_true",
                        help="use every irradiance sample of the finest level (ablation)")
    parser.add_argument("--backend", choices=BACKENDS,
                        default=DEFAULT_KNOBS["backend"], help="splatting kernel")
    parser.add_argument("--level-sampling", type=float,
                        default=DEFAULT_KNOBS["level_sampling"],
                        help="coarse splatting levels take irradiance samples as sparse as "
                             "this many of their pixels (default 0: the paper's one "
                             "selection for every level; on the heterogeneous scene "
                             "--levels 5 --level-sampling 1.5 renders 2.2x faster at the "
                             "same error against brute force: docs/splatting.md)")
    parser.add_argument("--epsilon", type=float, default=DEFAULT_KNOBS["epsilon"],
                        help="error tolerance of Eq. 14, which sets where each coarser "
                             "level takes over (default 0.001; smaller is slower and closer "
                             "to splatting everything at full resolution)")
    parser.add_argument("--sampling-range", choices=SAMPLING_RANGES,
                        default=DEFAULT_KNOBS["sampling_range"],
                        help="which RGB channel's scattering range sets Eq. 11's sampling "
                             "rate (default shortest: every channel sampled as alpha asks)")
    parser.add_argument("--profile-upsampling", action=argparse.BooleanOptionalAction,
                        default=DEFAULT_KNOBS["profile_upsampling"],
                        help="upsample coarse levels divided by each texel's profile factor "
                             "(upsampling_profile_factors; default on; --no-profile-upsampling"
                             ": Eq. 17 as published)")
    parser.add_argument("--material", default=None,
                        help="replace the translucent material: a built-in SubEdit name "
                             "(checker, veined_marble, wax_gradient) or a SubEdit .npz file")


def approx(scene, args) -> Image:
    """Render ``scene`` with the options parsed by :func:`add_approx_arguments`."""
    from ...materials.subedit import BUILTIN_SUBEDIT, builtin_subedit, load_subedit

    knobs = {"irradiance_resolution": args.irradiance_resolution, "levels": args.levels,
             "multiresolution": not args.no_multiresolution, "adaptive": not args.no_adaptive,
             "backend": args.backend, "level_sampling": args.level_sampling,
             "profile_upsampling": args.profile_upsampling, "epsilon": args.epsilon,
             "sampling_range": args.sampling_range}
    material = None
    if args.material:
        material = builtin_subedit(args.material) if args.material in BUILTIN_SUBEDIT \
            else load_subedit(args.material)
    return precompute(scene, **knobs).render(material=material)
