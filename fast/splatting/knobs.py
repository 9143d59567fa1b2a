"""Knobs and constants of the splatting method."""

from __future__ import annotations

from ..base import Refusal
from ..indirect_light import indirect_light_knobs
from ..knobs import (
    RADIAL_AVERAGE,
    UNSUPPORTED_PROFILE,
    Knob,
    KnobSpec,
    directional_profile_names,
    profile_knob,
)
from ..object_geometry import QUICK_GEOMETRY_KNOBS, geometry_knobs

#: The splatting kernels: compiled loops (numba, the default: measured fastest on the CPU,
#: see reports/bench/splatting.py), CUDA (numba.cuda, :mod:`.backend_cuda`: the same tiles
#: on a GPU), Dr.Jit (LLVM on the CPU, CUDA where a GPU is there) and plain numpy (the
#: reference the others are tested against).
BACKENDS = ("numba", "cuda", "drjit", "numpy")

#: The most point emitters one area light may become (each is an irradiance buffer a frame).
MAX_AREA_LIGHT_POINTS = 256

#: The RGB reading of Eq. 11's :math:`R_{P_x}` (one range per point in the paper):
#: "shortest" channel (every channel sampled at the rate alpha asks), the luminance-weighted
#: mean of the channel ranges, or the "longest" (the range splats are truncated at). Measured
#: on the heterogeneous scene at 800 x 600 (reports/bench/splatting.py): adaptive sampling
#: alone adds no error with "shortest", about 5 % more relative error with "luminance"
#: (35 % fewer samples) and 30 % more with "longest" (60 % fewer samples).
SAMPLING_RANGES = ("shortest", "luminance", "longest")

#: The profiles splatting cannot take, and why: SubEdit profiles are radial (Eq. 8-9 of
#: Chen et al. 2012), so a directional profile stands in only as its radial average.
PROFILE_REFUSALS = {
    name: Refusal(UNSUPPORTED_PROFILE, f"splatting cannot take profile {name!r}: it depends on "
                  "the incident direction, and the SubEdit profiles it splats (Chen et al. "
                  f"2012, Eq. 8-9) are functions of the distance alone; {name + RADIAL_AVERAGE!r} "
                  "is its radial average")
    for name in directional_profile_names()}

#: The knobs of the method (Chen et al. 2012, Sect. 4 and 5): validation, the
#: ``translucent approx splatting`` flags and the quality ladders all come from here.
#: Only the indirect light's gather is precomputed, keyed by its own knobs, so no knob is
#: part of the method's cache key.
KNOBS = KnobSpec([
    Knob("irradiance_resolution", 512, "irradiance buffer side in pixels (Sect. 4)",
         kind="int", low=1, high=8192, ladder=(64, 128, 256)),
    Knob("levels", 3, "mipmap levels of both buffers (Sect. 5)", kind="int", low=1, high=12),
    Knob("multiresolution", True, "splat distant contributions at coarser levels; off: "
         "everything at full resolution (ablation)", kind="bool"),
    Knob("adaptive", True, "adaptive irradiance sample selection; off: every sample of the "
         "finest level (ablation)", kind="bool"),
    Knob("z0", 0.03, "depth-discontinuity threshold, x bounding-sphere radius", kind="float",
         low=0.0),
    Knob("alpha", 15.0, "sampling-rate scale of Eq. 11", kind="float", low=0.0),
    Knob("epsilon", 0.001, "error tolerance of Eq. 14, which sets where each coarser level "
         "takes over (smaller: slower, closer to splatting everything at full resolution)",
         kind="float", positive=True),
    Knob("lambda_z", 8.0, "depth sharpness of Eq. 17", kind="float", low=0.0),
    Knob("lambda_m", 8.0, "material sharpness of Eq. 17", kind="float", low=0.0),
    Knob("backend", "numba", "splatting kernel", kind="choice", choices=BACKENDS),
    Knob("buffers", "raster", "G-buffers: z-buffer raster or Mitsuba ray queries",
         kind="choice", choices=("raster", "mitsuba")),
    Knob("sampling_range", "shortest", "which RGB channel's scattering range sets Eq. 11's "
         "sampling rate (shortest: every channel sampled as alpha asks)", kind="choice",
         choices=SAMPLING_RANGES),
    Knob("level_sampling", 0.0, "> 0: coarse splatting levels take irradiance samples as "
         "sparse as this many of their pixels (0: the paper's one selection for every "
         "level; docs/splatting.md)", kind="float", low=0.0),
    Knob("profile_upsampling", True, "upsample coarse levels divided by each texel's "
         "profile factor (off: Eq. 17 as published)", kind="bool"),
    Knob("range_energy", 0.99, "energy fraction of each profile within its effective "
         "scattering range, where splats stop (Eq. 11 has 0.95)", kind="float",
         positive=True, high=1.0),
    Knob("area_light_points", 4, "point emitters an area light becomes (emitters.py)",
         kind="int", low=1, high=MAX_AREA_LIGHT_POINTS),
    profile_knob(PROFILE_REFUSALS, keyed=False, help="radial profile a Dipole material, or "
                 "each medium of a solid one, is converted to SubEdit from (SubEdit "
                 "materials keep theirs)"),
    # the light the scene's diffuse surfaces bounce onto the object (fast.indirect_light),
    # splatted from six axis views of the object; "off" is Eq. 5-6 as the paper
    *indirect_light_knobs(),
    # the object's own shape: diffusion's correction of the half-space profile
    # (fast.object_geometry); "half_space" is the paper's profile alone
    *geometry_knobs(),
    Knob("indirect_resolution", 128, "side in pixels of the six axis views that carry the "
         "indirect light", kind="int", low=1, high=8192),
], ladders={
    "levels": [{"levels": 5}, {"levels": 4}, {}, {"levels": 2}],
    # coarse levels splatted from irradiance samples as sparse as their pixels (the
    # fastest settings at equal error on the heterogeneous scene: docs/splatting.md)
    "levels and level sampling": [
        {"levels": 5, "level_sampling": 2.0}, {"levels": 5, "level_sampling": 1.5},
        {"levels": 5, "level_sampling": 1.0}, {},
    ],
})

#: The knobs of the method and their defaults.
DEFAULT_KNOBS: dict = KNOBS.defaults

#: Quality ladders of ``bench tradeoff`` and the report (the irradiance resolution
#: first: the report takes the cheap end of the first ladder).
LADDERS: dict = {"irradiance resolution": KNOBS.ladders["irradiance_resolution"],
                 **{name: points for name, points in KNOBS.ladders.items()
                    if name != "irradiance_resolution"}}

#: Cheap knobs for smoke runs and the conformance checks (fast.conformance).
QUICK_KNOBS: dict = {"irradiance_resolution": 64, "indirect_resolution": 32,
                     "indirect_rays": 16, "indirect_patch_rays": 64,
                     **QUICK_GEOMETRY_KNOBS}


#: Pairs evaluated at once by the numpy splatting kernel (bounds its memory to ~1 GB).
PAIR_CHUNK = 1 << 21
#: Kernel radii (level pixels) are rounded up to the next of these, so that samples of one
#: bucket share a disc of offsets; ratios of at most 1.25 waste at most ~56 % pairs.
BUCKET_RATIO = 1.25



#: How a heterogeneous object's media are mixed between two points: the geometric mean of
#: the profiles of the media at the entry and the exit point (Chen et al. 2012, Eq. 8).
HETEROGENEOUS_RULE = "geometric_mean"
