"""Render a reference image of a scene with Mitsuba 3: ``translucent render SCENE [...]``.

SCENE is a built-in scene name (``translucent scenes`` lists them) or the path of a TOML
scene file. The image is the mean of ``--passes`` independent renders of ``--spp`` samples
per pixel each, written as OpenEXR with the per-pixel variance of the mean in the
``variance.R/G/B`` channels and the provenance (scene hash, spp, passes, seconds, variant,
Mitsuba version, integrator, light substitutions) in the header. References are cached by
content: the same scene and settings are never rendered twice (``--no-cache`` renders
anyway). Exit code 2 on bad input (unknown scene, bad counts, bad scene file), with no
output file left behind.

``--integrator bssrdf_path --profile NAME`` renders each translucent object by a radial
profile instead of its medium (:mod:`translucent.reference.bssrdf_path`: the profile's own
exact image); the header names the profile and each object's. ``NAME+RULE`` renders a
solid medium by a rule that mixes its media's profiles
(:data:`~translucent.materials.profiles.HETEROGENEOUS_RULES`).

``--target-rse R [--target-p99 P] [--budget SECONDS]`` renders progressively instead:
independent passes of ``--spp`` samples are added until the median relative standard error
over the lit pixels is at most R (and the 99th percentile at most P), or until the budget is
spent; which of the two ended it, and the figures reached, are printed and stored in the
header. An interrupted progressive render resumes from its last pass when run again. A
reference whose median relative standard error stays above 5 % is warned about.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from ...atomic import check_output_file, output_folder, safe_file_name
from ...errors import InputError


def add_arguments(parser):
    """Add the scene, the sample counts, the integrator and the output path."""
    from ...reference.mitsuba_scene import INTEGRATORS

    parser.add_argument("scene", help="built-in scene name or path to a scene TOML file")
    parser.add_argument("--spp", type=int, default=64, help="samples per pixel of each pass "
                        "(default 64)")
    parser.add_argument("--passes", type=int, default=4, help="independent passes; their "
                        "spread gives the variance (default 4)")
    parser.add_argument("--seed", type=int, default=0, help="picks the passes' seeds "
                        "(default 0)")
    parser.add_argument("--integrator", choices=INTEGRATORS, default=None,
                        help="default: volpath_mnee where a point, spot or directional "
                        "light meets a dielectric boundary around a medium (manifold "
                        "next-event estimation), volpathmis with other chromatic media in RGB, "
                        "volpath with other media, path without; "
                        "volpath there replaces such lights by small emitters; bssrdf_path "
                        "renders translucent objects by --profile")
    parser.add_argument("--profile", default=None, metavar="NAME",
                        help="with --integrator bssrdf_path: the radial profile each "
                        "translucent object is rendered with (translucent profiles lists "
                        "them); NAME+walk (by photon random walks, the methods' default) "
                        "or NAME+geometry (by diffusion) adds the object's own shape as PRT "
                        "and splatting do (docs/geometry.md); NAME+geometric_mean, "
                        "NAME+segment_mix or NAME+segment_average mixes the media of a "
                        "solid (heterogeneous) object by that rule (docs/heterogeneous.md)")
    parser.add_argument("--per-channel", action=argparse.BooleanOptionalAction, default=None,
                        help="render R, G and B separately (media of one channel each); "
                        "default: where a medium is chromatic and of albedo near 1, as the "
                        "reference recommends")
    parser.add_argument("--target-rse", type=float, default=None, metavar="R",
                        help="render progressively until the median relative standard error "
                        "over the lit pixels is at most R, in (0, 1), e.g. 0.01")
    parser.add_argument("--target-p99", type=float, default=None, metavar="P",
                        help="with --target-rse: also the 99th percentile at most P")
    parser.add_argument("--budget", type=float, default=None, metavar="SECONDS",
                        help="with --target-rse: stop when the next pass would exceed this "
                        "many seconds of rendering")
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")
    parser.add_argument("--no-cache", action="store_true",
                        help="render even when the reference is cached, and do not cache it")
    parser.add_argument("--out", "-o", default=None,
                        help="output EXR (default: <scene>_reference.exr)")


def run(args) -> int:
    """Load the scene, render the reference (or take it from the cache), write the EXR."""
    from ...reference.render import check_noise_target
    from ...scenes import load_scene

    progressive = args.target_rse is not None
    if not progressive:
        for field, value in (("--target-p99", args.target_p99), ("--budget", args.budget)):
            if value is not None:
                raise InputError("goes with --target-rse", field=field, value=value)
    else:
        check_noise_target(args.target_rse, args.target_p99, args.budget)
        if args.passes != 4:
            raise InputError("with --target-rse the passes are counted by the target; "
                             "leave --passes out", field="--passes", value=args.passes)
    if args.out is not None and Path(args.out).suffix.lower() != ".exr":
        raise InputError("the output must be an OpenEXR file ending in .exr", field="--out",
                         value=args.out)
    scene = load_scene(args.scene)
    out = check_output_file(args.out or f"{safe_file_name(scene.name)}_reference.exr", "--out",
                            what="a file name ending in .exr")
    # made before rendering: a folder that cannot be made would lose the whole render; a
    # refused, failed (a full disk) or interrupted render leaves no folder made for it
    with output_folder(out.parent, field="--out", value=str(out), create=True,
                       what="the output folder"):
        return _render_and_write(args, scene, out, progressive)


def _render_and_write(args, scene, out: Path, progressive: bool) -> int:
    import sys

    from ...noise import reference_noise_warning
    from ...reference import render
    from ...reference.render import render_to_target

    common = dict(spp=args.spp, seed=args.seed, integrator=args.integrator,
                  profile=args.profile,
                  per_channel=args.per_channel, cache=not args.no_cache,
                  progress=not args.no_progress)
    if progressive:
        image = render_to_target(scene, target_rse=args.target_rse,
                                 target_p99_rse=args.target_p99,
                                 budget_seconds=args.budget, **common)
    else:
        image = render(scene, passes=args.passes, **common)
    image.write(out)
    meta = image.metadata
    print(f"wrote {out} ({image.shape[1]} x {image.shape[0]}, {meta['spp']} spp x "
          f"{meta['passes']} passes, {meta['integrator']}; rendered in "
          f"{meta['seconds']:.3g} s)")
    if meta.get("profile"):
        objects = ", ".join(f"{k}: {v}" for k, v in meta["profile"]["objects"].items())
        shape = " with the object's geometry" if meta.get("geometry") else ""
        print(f"  profile {meta['profile']['name']}{shape} ({objects})")
    if progressive:
        from ...noise import NoiseSummary

        print(f"  {meta['stopped']}: relative standard error "
              f"{NoiseSummary(**meta['noise']).text()}")
    for note in meta.get("substitutions", []):
        label = "lights" if "manifold next-event" in note else "substituted"
        print(f"  {label}: {note}")
    counted = meta.get("manifold_nee")
    if counted and counted.get("connections"):
        lost = counted["not_converged"] / counted["connections"]
        print(f"  manifold connections: {counted['connections']}, solved "
              f"{counted['solved']}, not converged {counted['not_converged']} "
              f"({100 * lost:.2g} %: no refraction path, or the solve failed), not a "
              f"refraction {counted['not_refraction']}")
        if counted.get("seeded_found") or counted.get("trials_capped"):
            print(f"  seeded solves (specular manifold sampling): "
                  f"{counted.get('seeded_found', 0)} further refraction points, "
                  f"{counted.get('trials_capped', 0)} of them with the trial count cut")
    warning = reference_noise_warning(image.rgb, image.variance)
    if warning:
        print(f"warning: {warning}", file=sys.stderr)
    from ...noise import noise_summary
    from .record import record

    record(args, scene=scene.name, out=str(out), width=image.shape[1], height=image.shape[0],
           noise=(noise_summary(image.rgb, image.variance).as_dict()
                  if image.variance is not None else None),
           reference_warning=warning or None,
           header={key: meta.get(key) for key in (
               "spp", "passes", "seconds", "integrator", "variant", "mitsuba", "per_channel",
               "stopped", "substitutions", "manifold_nee", "scene_hash", "profile")})
    return 0
