"""The knobs of PRT editing and relighting (Wang et al. 2008) and the checks on them."""

from __future__ import annotations

import math

import numpy as np

from ...errors import InputError
from ...materials.dipole_pca import (
    PARAMETERISATIONS,
    DipolePCABasis,
    dipole_pca_basis,
)
from ..base import with_defaults
from ..sparse_transport import (
    check_approximation,
)

#: Knobs of :func:`precompute` and their defaults.
DEFAULT_KNOBS: dict = {
    # illumination samples per translucent object: parts x 4^n
    "samples": 16384,
    "parts": 4,
    # the R_d basis (materials.dipole_pca): parameterisation, K, and the eta it samples
    "basis": "area_normalised",
    "basis_terms": 12,
    "basis_eta": 1.3,
    # pass 1: Haar coefficients kept per transfer row (energy fraction, term budget)
    "energy": 0.9999,
    "terms": 256,
    # rank the coefficients of the basis rows by magnitude (the paper) or by magnitude x
    # sqrt(support) (the local kernel row is always ranked by support)
    "selection": "magnitude",
    # storage of the first pass: "shared" (the K + 1 rows of a vertex keep the union of
    # their kept columns, so a relighting product gathers each column once) or "rows" (each
    # row its own columns, the paper's layout; always so after the spatial pass)
    "layout": "shared",
    # pass 2: CDF 9/7 spatial compression: "auto" (geometry images above
    # spatial_min_vertices), "on" (any geometry image) or "off"
    "spatial": "auto",
    "spatial_min_vertices": 20000,
    "spatial_first_terms": 1024,
    "spatial_energy": 0.999,
    "spatial_terms": 256,
    # environment lighting: visibility directions (res x 2 res) and terms kept per sample
    "environment_resolution": 16,
    "environment_terms": 64,
    # shadow rays per area light and sample
    "area_light_samples": 16,
    "seed": 0,
    # blend profiles the illumination samples cannot resolve into the local vector
    # (SAMPLING_BLEND_START; rendering only, not part of the cache key); False: Eq. 5-7 as
    # the paper sums them, whatever the sample spacing
    "sampling_blend": True,
    # execution only (not part of the cache key)
    "workers": 2,
    "progress": True,
}

#: Cheap knobs for smoke runs and the conformance checks (fast.conformance): 256
#: illumination samples (4 parts x 8 x 8) on one core.
QUICK_KNOBS: dict = {"samples": 256, "workers": 1}

#: Knobs that change how, not what, is computed: left out of the cache key.
EXECUTION_KNOBS = ("workers", "progress")

#: Knobs read when rendering, not when precomputing: left out of the cache key too.
RENDER_KNOBS = ("sampling_blend",)
UNKEYED_KNOBS = EXECUTION_KNOBS + RENDER_KNOBS

#: Bump when the precomputed data change meaning, so that old cache entries miss.
PRT_VERSION = 7

#: Vertices per block of the first pass (one progress-bar step; memory ~ K x block x terms).
VERTICES_PER_BLOCK = 256

#: Width of the local kernel (a Gaussian over the samples around each vertex, normalised to
#: sum 1) in units of the sample spacing sqrt(area per sample): wide enough to average a few
#: samples, narrow enough to follow shadow edges.
LOCAL_KERNEL_WIDTH = 1.0

#: Blend towards the local (opaque-limit) model when the basis misses more than
#: LOCAL_BLEND_START of a profile (relative L2 in the sampling's norm: the measured media
#: miss at most 0.0065 with the default 12 terms, so they are never blended), fully local
#: when it misses LOCAL_BLEND_END (the projection then oscillates with negative lobes of
#: several per cent of the peak).
LOCAL_BLEND_START = 0.02
LOCAL_BLEND_END = 0.2

#: A small residual is not enough: a profile narrower than the basis's sample spacing is
#: seen by a handful of samples, and its K-term reconstruction can hold any energy between
#: them (paper basis, sigma' = 1e3 mm^-1: residual 7.5e-5, energy -204 against 0.073).
#: The projection's energy 2 pi int R r dr over [0, 65] mm must also agree with the exact
#: profile's: blending starts at a relative error of ENERGY_BLEND_START, above the worst of
#: the 36 measured profiles on either preset basis (0.067 paper, 0.057 area_normalised, both
#: Spectralon green), and is complete at ENERGY_BLEND_END.
ENERGY_BLEND_START = 0.1
ENERGY_BLEND_END = 0.5

#: A profile whose reduced mean free path (the depth z_r of its real source, the distance
#: over which it falls from its peak) is shorter than the spacing of the basis's first two
#: distances is sampled too coarsely for the residual to mean anything, and multiple
#: scattering there is local (the paper's "more appropriate to handle using the diffuse
#: BRDF model", Sect. 4 of Wang et al. 2008). Blending starts when the mean free path is
#: one spacing and is complete RESOLUTION_BLEND_OCTAVES octaves below (a quarter spacing:
#: the profile then falls to a few per cent of its peak before the second sample). The
#: measured media inside the paper's grid have mean free paths >= 0.19 mm (twice its
#: 0.1 mm spacing); the area-normalised basis's first spacing is 3e-4 mm.
RESOLUTION_BLEND_OCTAVES = 2.0

#: The transfer sums a profile over the illumination samples (Eq. 5-7 of Wang et al. 2008),
#: a quadrature of spacing h = sqrt(area per sample). The part of the profile's energy
#: within h of a vertex falls on a handful of samples, whose positions then decide the
#: result: a blotchy surface (Spectralon on the 10 mm sphere at 16384 samples, h = 0.28 mm,
#: 56-72 % of its energy within h at eta = 1: relMSE 0.125 against the path-traced
#: reference, 0.005 when rendered fully local). Blending by that fraction starts at
#: SAMPLING_BLEND_START, above the in-grid measured media there (at most 0.41, Cream at
#: eta = 1), and is complete at SAMPLING_BLEND_END.
SAMPLING_BLEND_START = 0.45
SAMPLING_BLEND_END = 0.65

#: Columns per block of the spatial pass (dense block: vertices x columns x 4 bytes).
SPATIAL_COLUMNS_PER_BLOCK = 256

#: Rank of the separable approximation of F_t(eta, mu) mu used by environment lighting.
#: Measured over eta in [1, 3]: 4 terms reproduce it to 3.4e-3 of its peak pointwise and its
#: cosine-weighted hemispherical integral to 2.1e-4 (3 terms: 1.0e-2 and 1.7e-3).
FRESNEL_RANK = 4


# ------------------------------------------------------------------------ knobs


def check_knobs(knobs: dict) -> dict:
    """Return ``knobs`` merged with :data:`DEFAULT_KNOBS`, each checked (InputError naming it)."""
    merged = with_defaults(knobs, DEFAULT_KNOBS)
    integers = {"samples": (1, 1 << 18), "parts": (1, 4096), "basis_terms": (1, 32),
                "terms": (1, 1 << 18), "spatial_min_vertices": (0, 10**9),
                "spatial_first_terms": (1, 1 << 18), "spatial_terms": (1, 1 << 18),
                "environment_resolution": (2, 256), "environment_terms": (1, 1 << 17),
                "area_light_samples": (1, 4096), "seed": (0, 2**32 - 1), "workers": (1, 256)}
    for name, (low, high) in integers.items():
        value = merged[name]
        if isinstance(value, bool) or not isinstance(value, (int, np.integer)) \
                or not low <= value <= high:
            raise InputError(f"must be an integer in [{low}, {high}]", field=name, value=value)
        merged[name] = int(value)
    quadtree_level(merged["samples"], merged["parts"])
    resolution = merged["environment_resolution"]
    if resolution & (resolution - 1):
        raise InputError("must be a power of two", field="environment_resolution",
                         value=resolution)
    if merged["basis"] not in PARAMETERISATIONS:
        raise InputError(f"unknown basis; valid: {', '.join(PARAMETERISATIONS)}",
                         field="basis", value=merged["basis"])
    if merged["layout"] not in ("shared", "rows"):
        raise InputError("must be 'shared' or 'rows'", field="layout", value=merged["layout"])
    if merged["selection"] not in ("magnitude", "support"):
        raise InputError("must be 'magnitude' or 'support'", field="selection",
                         value=merged["selection"])
    if merged["spatial"] not in ("auto", "on", "off"):
        raise InputError("must be 'auto', 'on' or 'off'", field="spatial",
                         value=merged["spatial"])
    merged["energy"], _ = check_approximation(merged["energy"], merged["terms"])
    merged["spatial_energy"], _ = check_approximation(merged["spatial_energy"],
                                                      merged["spatial_terms"])
    eta = float(merged["basis_eta"])
    if not 1.0 <= eta <= 3.0:
        raise InputError("must be in [1, 3]", field="basis_eta", value=merged["basis_eta"])
    merged["basis_eta"] = eta
    merged["progress"] = bool(merged["progress"])
    if not isinstance(merged["sampling_blend"], (bool, np.bool_)):
        raise InputError("must be True or False", field="sampling_blend",
                         value=merged["sampling_blend"])
    merged["sampling_blend"] = bool(merged["sampling_blend"])
    return merged


def quadtree_level(count: int, parts: int) -> int:
    """Return n with ``count = parts x 4^n`` (the quadtree layout of every part), else raise."""
    per_part = count // parts
    level = round(math.log(max(per_part, 1), 4))
    if count % parts or 4 ** level != per_part:
        valid = ", ".join(str(parts * 4 ** n) for n in range(2, 9))
        raise InputError(f"must be parts x 4^n (with parts = {parts}: {valid}, ...)",
                         field="samples", value=count)
    return level


def pca_basis_for(knobs: dict) -> DipolePCABasis:
    """Return the dipole PCA basis the knobs name (parameterisation, eta, terms)."""
    return dipole_pca_basis(knobs["basis"], eta=knobs["basis_eta"], terms=knobs["basis_terms"])
