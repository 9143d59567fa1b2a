"""Knobs and constants of the splatting method."""

from __future__ import annotations

#: The knobs of the method and their defaults (Chen et al. 2012, Sect. 4 and 5).
DEFAULT_KNOBS: dict = {
    "irradiance_resolution": 512,   # irradiance buffer side, pixels (Sect. 4)
    "levels": 3,                    # mipmap levels of both buffers (Sect. 5)
    "multiresolution": True,        # splat distant contributions at coarser levels
    "adaptive": True,               # adaptive irradiance sample selection
    "z0": 0.03,                     # depth-discontinuity threshold, x bounding-sphere radius
    "alpha": 15.0,                  # sampling-rate scale of Eq. 11
    "epsilon": 0.001,               # error tolerance of Eq. 14
    "lambda_z": 8.0,                # depth sharpness of Eq. 17
    "lambda_m": 8.0,                # material sharpness of Eq. 17
    "backend": "numba",             # splatting kernel, one of BACKENDS
    "buffers": "raster",            # G-buffers: "raster" (z-buffer) or "mitsuba" (ray queries)
    "sampling_range": "shortest",   # RGB reading of Eq. 11's range, one of SAMPLING_RANGES
    "level_sampling": 0.0,          # > 0: coarser samples for coarse splatting levels (pixels)
    "profile_upsampling": True,     # Eq. 17 on B / sqrt(P_o): see upsampling_profile_factors
    "area_light_points": 4,         # point emitters an area light becomes (emitters.py)
}

#: Cheap knobs for smoke runs and the conformance checks (fast.conformance).
QUICK_KNOBS: dict = {"irradiance_resolution": 64}
#: The splatting kernels: compiled loops (numba, the default: measured fastest on the CPU,
#: see reports/bench/splatting.py), CUDA (numba.cuda, :mod:`.splatting_cuda`: the same tiles
#: on a GPU), Dr.Jit (LLVM on the CPU, CUDA where a GPU is there) and plain numpy (the
#: reference the others are tested against).
BACKENDS = ("numba", "cuda", "drjit", "numpy")

#: The most point emitters one area light may become (each is an irradiance buffer a frame).
MAX_AREA_LIGHT_POINTS = 256

#: Pairs evaluated at once by the numpy splatting kernel (bounds its memory to ~1 GB).
PAIR_CHUNK = 1 << 21
#: Kernel radii (level pixels) are rounded up to the next of these, so that samples of one
#: bucket share a disc of offsets; ratios of at most 1.25 waste at most ~56 % pairs.
BUCKET_RATIO = 1.25


