"""Knobs, constants and the convergence error of translucent radiosity."""

from __future__ import annotations

from ...errors import InputError
from ...scenes.raycast import RAY_ENGINES
from ..base import Refusal
from ..knobs import (
    RADIAL_AVERAGE,
    UNSUPPORTED_PROFILE,
    Knob,
    KnobSpec,
    directional_profile_names,
    profile_knob,
)
from ..object_geometry import QUICK_GEOMETRY_KNOBS, geometry_knobs

FORMAT_VERSION = 6

#: The iterative solvers.
SOLVERS = ("jacobi", "gmres", "bicgstab")


#: Values of the knob ``boundary``: how the lights' direct light enters a translucent object
#: behind a dielectric and how its exitance leaves (the inter-reflected light F B, diffuse,
#: always enters with T_in).
BOUNDARY_TERMS = ("directional", "diffuse")


def _no_more_than_a_byte(value):
    if value > 255:
        raise InputError("must be <= 255 (points per segment are counted in a byte)",
                         field="mix_points", value=value)
    return value


#: The profiles radiosity cannot take, and why: S holds a function of the distance alone
#: (Sheng et al. 2014, Eq. 8), so a directional profile stands in only as its radial average.
PROFILE_REFUSALS = {
    name: Refusal(UNSUPPORTED_PROFILE, f"radiosity cannot take profile {name!r}: it depends on "
                  "the incident direction, and the scattering factors of Eq. 8 (Sheng et al. "
                  f"2014) are a function of the distance alone; {name + RADIAL_AVERAGE!r} is "
                  "its radial average")
    for name in directional_profile_names()}

#: The knobs of :func:`precompute` (Sheng et al. 2014, Sect. 5): validation, cache key,
#: ``translucent approx radiosity`` flags and the quality ladder all come from here.
KNOBS = KnobSpec([
    # patches and form factors
    Knob("triangles_per_patch", 1, "1: triangles; n > 1: coplanar neighbours merged",
         kind="int", low=1),
    Knob("rays_per_patch", 256, "form-factor rays from each patch", kind="int", low=1,
         flags=("--rays",)),
    Knob("form_factor_threshold", 0.0, "F entries below this are dropped", kind="float",
         low=0.0),
    # scattering factors
    Knob("max_distance_mm", None, "scattering cut-off max_d (default: where every profile "
         "keeps 1 - profile_energy_cutoff of its energy)", kind="float", positive=True,
         unit="mm", optional=True, flags=("--max-distance",)),
    Knob("profile_energy_cutoff", 1e-3, "energy fraction beyond max_d when it is derived",
         kind="float", positive=True, high=1.0),
    Knob("self_samples", 100, "samples on a patch's nearest neighbours (m^2)", kind="int",
         low=1),
    Knob("sample_falloff", 2.0, "m falls as exp(-distance / (this x patch radius))",
         kind="float", positive=True),
    Knob("centroid_beyond", 8.0, "centroid only beyond this many patch radii", kind="float",
         positive=True),
    # S is filled from the materials at every translucency change, never cached: only the
    # cut-off max_d derived from the profile enters the key (as max_distance_mm)
    profile_knob(PROFILE_REFUSALS, keyed=False, help="radial profile S is filled from, made "
                 "from each Dipole material (times its diffuse entry transmittance)"),
    Knob("self_term", "polar", "the self term: exact profile integral or samples",
         kind="choice", choices=("polar", "samples")),
    Knob("voxels_per_axis", 48, "voxel grid of a concave object, along its longest side",
         kind="int", low=1),
    Knob("profile_samples", 2048, "radial grid nodes of the tabulated profiles", kind="int",
         low=1),
    Knob("mix_points", 8, "points along a path for heterogeneous fractions", kind="int",
         low=1, check=_no_more_than_a_byte),
    Knob("sheet_thickness_mm", None, "thin (open) translucent sheets: slab thickness",
         kind="float", positive=True, unit="mm", optional=True),
    Knob("finite_object_energy", True, "S columns carry the object's diffusion escape "
         "(gain) of the dipole; off: the dipole as the paper uses it; with a geometry other "
         "than half_space the geometry's correction takes its place", kind="bool"),
    Knob("diffusion_voxels_per_axis", 32, "its finite-volume grid, along the longest side",
         kind="int", low=4),
    # solving and lighting: read every frame, not part of the cache key
    # the object's own shape (fast.object_geometry), added to S as a low-rank block
    *geometry_knobs(default="half_space"),
    Knob("solver", "jacobi", "the iterative solver", kind="choice", choices=SOLVERS,
         keyed=False),
    Knob("tolerance", 5e-3, "relative residual (the paper's 0.5 %)", kind="float",
         positive=True, keyed=False),
    Knob("max_iterations", 2000, "most iterations of a solve", kind="int", low=1,
         keyed=False),
    Knob("warm_start", True, "start from the earlier frames' solutions", kind="bool",
         keyed=False),
    Knob("transfer", "auto", "auto: T at a relighting once the solves have cost its "
         "estimated build and it fits; never",
         kind="choice", choices=("auto", "never"), keyed=False),
    Knob("transfer_budget_mb", 512, "T fits when 3 P^2 float32 do (P <= 6,688 at 512 MB)",
         kind="float", positive=True, unit="MB", keyed=False),
    Knob("light_samples", 16, "samples per area light / environment per point", kind="int",
         low=1, keyed=False),
    Knob("boundary", "directional", "Fresnel of a dielectric boundary: directional (F_t at "
         "each light sample's angle in, at the camera's out) or diffuse (T_in in, a "
         "Lambertian exit: the paper's Sect. 3.2)", kind="choice", choices=BOUNDARY_TERMS,
         keyed=False),
    Knob("diffuse_light_samples", None, "per diffuse patch (its E feeds only F B); None: as "
         "light_samples", kind="int", low=1, optional=True, keyed=False),
    Knob("shadow_ray_engine", "auto", "relighting's shadow rays", kind="choice",
         choices=RAY_ENGINES, keyed=False),
    Knob("seed", 0, "random seed of rays and samples", kind="int", low=0, high=2**32 - 1),
], ladders={
    # samples of the scattering integral, the profile cut-off, form-factor rays and the
    # solver's relative residual (Sheng et al. 2014, Sect. 5.2-5.3)
    "scattering samples, cut-off, rays, solver tolerance": [
        {"self_samples": 4, "profile_energy_cutoff": 0.1, "rays_per_patch": 32,
         "tolerance": 0.05},
        {"self_samples": 16, "profile_energy_cutoff": 0.03, "rays_per_patch": 64,
         "tolerance": 0.02},
        {"self_samples": 36, "profile_energy_cutoff": 0.01, "rays_per_patch": 128,
         "tolerance": 0.01},
        {},
    ],
})

#: Knobs of :func:`precompute` and their defaults.
DEFAULT_KNOBS: dict = KNOBS.defaults

#: Quality ladders of ``bench tradeoff`` and the report.
LADDERS: dict = KNOBS.ladders

#: Cheap knobs for smoke runs and the conformance checks (fast.conformance): few
#: form-factor rays, and a tight solve, so that relighting through T and an iterative
#: solve agree far below the checks' tolerance.
QUICK_KNOBS: dict = {"rays_per_patch": 16, "tolerance": 1e-7, **QUICK_GEOMETRY_KNOBS}

#: The knobs that leave the profile a half-space's alone (fast.conformance's geometry
#: check): no geometry correction and no finite-object energy.
HALF_SPACE_KNOBS: dict = {"geometry": "half_space", "finite_object_energy": False}

#: Knobs that only steer solving and lighting: not part of the precomputation's cache key.
RUNTIME_KNOBS = KNOBS.unkeyed

#: The bounce decomposition of Sheng et al. 2014, Fig. 6.
COMPONENTS = ("direct", "interreflection", "subsurface", "both")

#: Gauss-Legendre nodes per triangle edge for the polar self term: the integrand along an
#: edge is C(sqrt(h^2 + s^2)) h / (h^2 + s^2), smooth; 8 nodes integrate a constant
#: profile over a triangle to 1e-12 and the dipole to 1e-6.
POLAR_NODES = 8

#: Earlier frames whose solutions start a relighting solve (:meth:`RadiosityState.solve`):
#: on the bench's sliding light, 6 frames cut the Jacobi products per frame from 3 (the last
#: frame's inter-reflection alone) to 2.
WARM_START_FRAMES = 6

#: Residual growth (over the smallest seen) that stops an iteration as diverging.
DIVERGENCE_FACTOR = 1e3


class ConvergenceError(RuntimeError):
    """The radiosity iteration did not reach its tolerance; carries the numbers.

    Attributes
    ----------
    residual : float
        The relative residual reached.
    iterations : int
    """

    def __init__(self, message: str, *, residual: float, iterations: int):
        super().__init__(message)
        self.residual = residual
        self.iterations = iterations



#: How a heterogeneous object's media are mixed between two points: the media along the
#: segment between them, by the fraction of its length in each (Sheng et al. 2014, Eq. 16).
HETEROGENEOUS_RULE = "segment_mix"
