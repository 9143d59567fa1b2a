"""The knobs of the BRDF-editing method (Nguyen et al. 2010).

One spec serves validation, the cache key, the ``translucent approx brdf_pca`` flags and the
quality ladders.
"""

from __future__ import annotations

import math

from ...errors import InputError
from ..knobs import Knob, KnobSpec

__all__ = ["DEFAULT_KNOBS", "FORMAT_VERSION", "KNOBS", "LADDERS", "QUICK_KNOBS"]

#: Bumped when the stored precomputation changes meaning (cache key).
FORMAT_VERSION = 3

def _power_of_four(value: int) -> int:
    if value & (value - 1) or int(round(math.log2(value))) % 2:
        raise InputError("must be a power of 4 (the gather samples fill the square of the "
                         "quadtree layout of Hasan et al. 2006): 256, 1024, 4096, 16384, "
                         "65536, ...", field="gather_samples", value=value)
    return value


#: The knobs of :func:`precompute` (Nguyen et al. 2010): validation, cache key,
#: ``translucent approx brdf_pca`` flags and the quality ladder all come from here.
KNOBS = KnobSpec([
    Knob("gather_samples", 16384, "gather samples: 16k in the paper's Cornell box, 64k "
         "elsewhere (Sect. 7.2); a power of 4", kind="int", low=16, high=1 << 22,
         check=_power_of_four),
    Knob("glossy_ratio", 1.0 / 6.0, "glossy gather samples per diffuse one (Sect. 5.1)",
         kind="float", low=0.0, high=1.0),
    Knob("glossy_exponent", 200.0, "e of Eq. 16, 'usually set to 200'", kind="float",
         low=1.0, high=1e5),
    Knob("n_basis", 6, "K, basis BRDFs besides the mean (6 in every scene of Table 5)",
         kind="int", low=1, high=32, flags=("--basis",)),
    Knob("bounces", 2, "n of Eq. 17: bounces among gather samples", kind="int", low=0,
         high=64),
    Knob("subarea", True, "sub-area sampling (Sects. 3.2, 5.1)", kind="bool"),
    Knob("subarea_max", 64, "most points per sub-area disk", kind="int", low=1, high=4096),
    Knob("subarea_tolerance", 0.02, "convergence of the sub-area estimate", kind="float",
         low=0.0, high=1.0),
    Knob("area_samples_per_gather", 8, "uniform surface samples per gather sample for the "
         "areas |A_g|", kind="int", low=1, high=256),
    # Haar coefficients kept per view-sample row of T (over all K + 1 bases), of D, per
    # gather-sample row of M_s, and per row of a frozen c^T T^w
    Knob("transfer_coefficients", 512, "Haar coefficients per view-sample row of T",
         kind="int", low=1, high=1 << 20),
    Knob("diffuse_coefficients", 96, "Haar coefficients per row of D", kind="int", low=1,
         high=1 << 20),
    Knob("gather_coefficients", 96, "Haar coefficients per gather-sample row of M_s",
         kind="int", low=1, high=1 << 20),
    Knob("frozen_coefficients", 192, "Haar coefficients per row of a frozen c^T T^w",
         kind="int", low=1, high=1 << 20),
    Knob("light_samples", 16, "samples per area light for direct lighting", kind="int",
         low=1, high=4096),
    # each block starts a few threaded kernels, whose start-up a large block amortises
    # (measured: docs/brdf_pca.md)
    Knob("block_pairs", 1 << 22, "(view sample, gather sample) pairs per block of the "
         "transfer computation", kind="int", low=1 << 10, high=1 << 26),
    Knob("seed", 0, "random seed of the samples", kind="int", low=0, high=2**31 - 1),
    # run time only (not in the cache key): how the light that reaches a gather sample
    # directly leaves it (docs/brdf_pca.md, "Gather samples that reflect by their BRDF")
    Knob("gather_reflection", "lambertian", "how a gather sample reflects the light that "
         "reaches it directly: 'lambertian', its diffuse term (Sect. 5.2), or 'brdf', its "
         "whole BRDF towards each block of pixels", kind="choice",
         choices=("lambertian", "brdf"), keyed=False),
    Knob("reflection_blocks", 256, "blocks of pixels towards which a gather sample's BRDF "
         "is evaluated (gather_reflection 'brdf'): squares of about view samples / blocks "
         "pixels, split by object", kind="int", low=1, high=1 << 20, keyed=False),
], ladders={
    # gather samples (Sect. 5.1), PCA basis BRDFs (Sect. 4) and Haar coefficients kept per
    # transfer row (Sect. 3.4)
    "gather samples, PCA and wavelet terms": [
        {"gather_samples": 1024, "n_basis": 1, "transfer_coefficients": 64},
        {"gather_samples": 4096, "n_basis": 2, "transfer_coefficients": 128},
        {"gather_samples": 4096, "n_basis": 4, "transfer_coefficients": 256},
        {},
    ],
    # beyond the paper: gather samples that reflect their direct light by their BRDF, the
    # model that removes most of the Lambertian gather's error (docs/brdf_pca.md)
    "gather reflection": [
        {},
        {"gather_reflection": "brdf"},
        {"gather_reflection": "brdf", "reflection_blocks": 1024},
    ],
})

#: The knobs of :func:`precompute` and their defaults.
DEFAULT_KNOBS = KNOBS.defaults

#: Quality ladders of ``bench tradeoff`` and the report.
LADDERS = KNOBS.ladders

#: Cheap knobs for smoke runs and the conformance checks (fast.conformance).
QUICK_KNOBS = dict(gather_samples=256, bounces=1, transfer_coefficients=96,
                   diffuse_coefficients=48, gather_coefficients=48, frozen_coefficients=48,
                   light_samples=4, block_pairs=1 << 14)



# ---------------------------------------------------------------------------------------
