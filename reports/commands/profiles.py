"""List the scattering profiles, one line each (``name: description``).

``--show NAME`` describes one profile of a medium (``--medium``, a measured medium's name,
Marble by default): its source, how its parameters follow from the medium, their values,
its total diffuse reflectance and the radius holding 99 % of its energy.
"""

from __future__ import annotations


def add_arguments(parser):
    """``--show NAME`` and ``--medium MEDIUM``."""
    parser.add_argument("--show", metavar="NAME", default=None,
                        help="describe one profile (a name from the list)")
    parser.add_argument("--medium", metavar="MEDIUM", default="Marble",
                        help="measured medium for --show (Jensen et al. 2001; default Marble)")


def run(args) -> int:
    """Print the profiles, or the description of one."""
    from ...materials.profiles import profile, profile_descriptions
    from .record import record

    if args.show is None:
        descriptions = profile_descriptions()
        width = max(len(name) for name in descriptions)
        for name, description in descriptions.items():
            print(f"{name + ':':<{width + 1}} {description}")
        record(args, profiles=[{"name": name, "description": description}
                               for name, description in descriptions.items()])
        return 0
    made = profile(args.show, args.medium, radial=True)
    radius = made.radius_containing(0.99)
    print(made.describe())
    print(f"  radius holding 99 % = [{', '.join(f'{v:.6g}' for v in radius)}] mm")
    record(args, profile={"name": args.show, "medium": args.medium,
                          "total": made.total().tolist(),
                          "radius_99_mm": radius.tolist(),
                          "parameters": {key: [list(map(float, values)), unit] for key, (
                              values, unit) in made.parameters().items()}})
    return 0
