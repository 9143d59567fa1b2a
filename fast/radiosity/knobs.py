"""Knobs, constants and the convergence error of translucent radiosity."""

from __future__ import annotations

FORMAT_VERSION = 5

#: Knobs of :func:`precompute` and their defaults.
DEFAULT_KNOBS: dict = {
    # patches and form factors
    "triangles_per_patch": 1,        # 1: triangles; n > 1: coplanar neighbours merged
    "rays_per_patch": 256,           # form-factor rays from each patch
    "form_factor_threshold": 0.0,    # F entries below this are dropped
    # scattering factors
    "max_distance_mm": None,         # max_d; None: where every profile keeps 99.9 %
    "profile_energy_cutoff": 1e-3,   # energy fraction beyond max_d when it is derived
    "self_samples": 100,             # samples on a patch's nearest neighbours (m^2)
    "sample_falloff": 2.0,           # m falls as exp(-distance / (this x patch radius))
    "centroid_beyond": 8.0,          # centroid only beyond this many patch radii
    "self_term": "polar",            # "polar" (exact profile integral) or "samples"
    "voxels_per_axis": 48,           # voxel grid of a concave object, along its longest side
    "profile_samples": 2048,         # radial grid nodes of the tabulated profiles
    "mix_points": 8,                 # points along a path for heterogeneous fractions
    "sheet_thickness_mm": None,      # thin (open) translucent sheets: slab thickness
    "finite_object_energy": True,    # S columns carry the object's diffusion escape (gain)
    "diffusion_voxels_per_axis": 32,  # its finite-volume grid, along the longest side
    # solving and lighting
    "solver": "jacobi",              # "jacobi", "gmres" or "bicgstab"
    "tolerance": 5e-3,               # relative residual (the paper's 0.5 %)
    "max_iterations": 2000,
    "warm_start": True,              # start from the earlier frames' solutions
    "transfer": "auto",              # "auto": T at the first relighting when it fits; "never"
    "transfer_budget_mb": 512,       # T fits when 3 P^2 float32 do (P <= 6,688 at 512 MB)
    "light_samples": 16,             # samples per area light / environment per point
    "diffuse_light_samples": None,   # per diffuse patch (its E feeds only F B); None: as above
    "shadow_ray_engine": "auto",     # relighting's shadow rays: "auto", "embree", "mitsuba"
    "seed": 0,
}

#: Cheap knobs for smoke runs and the conformance checks (fast.conformance): few
#: form-factor rays, and a tight solve, so that relighting through T and an iterative
#: solve agree far below the checks' tolerance.
QUICK_KNOBS: dict = {"rays_per_patch": 16, "tolerance": 1e-7}

#: Knobs that only steer solving and lighting: not part of the precomputation's cache key.
RUNTIME_KNOBS = ("solver", "tolerance", "max_iterations", "warm_start", "transfer",
                 "transfer_budget_mb", "light_samples", "diffuse_light_samples",
                 "shadow_ray_engine")

#: The iterative solvers.
SOLVERS = ("jacobi", "gmres", "bicgstab")

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


