"""The knobs of PRT editing and relighting (Wang et al. 2008) and the checks on them."""

from __future__ import annotations

import math

from ...errors import InputError
from ...materials.dipole_pca import (
    DEFAULT_SIGMA_SAMPLES,
    PARAMETERISATIONS,
    DipolePCABasis,
    dipole_pca_basis,
)
from ..base import Refusal
from ..indirect_light import indirect_light_knobs
from ..knobs import (
    DEFAULT_PROFILE,
    RADIAL_AVERAGE,
    UNSUPPORTED_PROFILE,
    Knob,
    KnobSpec,
    directional_profile_names,
    profile_knob,
)
from ..object_geometry import QUICK_GEOMETRY_KNOBS, geometry_knobs
from .profile_basis import family_basis


def _quadtree(knobs: dict) -> None:
    quadtree_level(knobs["samples"], knobs["parts"])


def _power_of_two(value: int) -> int:
    if value & (value - 1):
        raise InputError("must be a power of two", field="environment_resolution", value=value)
    return value


#: The profiles PRT cannot take, and why. A directional profile is not a function of the
#: distance (Eq. 2 of Wang et al. 2008). A profile's basis is built from one profile per
#: medium of the basis's grid; PRT takes the profiles whose basis at the default grid
#: builds within the bound docs/prt.md states (its measured build times), and quantized
#: diffusion, several times slower to make than any other, is refused.
PROFILE_REFUSALS = {
    **{name: Refusal(UNSUPPORTED_PROFILE, f"prt cannot take profile {name!r}: it depends on "
                     "the incident direction, and the PCA basis of Wang et al. 2008 (Eq. 4) "
                     f"expands a function of the distance alone; {name + RADIAL_AVERAGE!r} is "
                     "its radial average") for name in directional_profile_names()},
    "quantized_diffusion": Refusal(
        UNSUPPORTED_PROFILE, "prt cannot take profile 'quantized_diffusion': its PCA basis "
        "(Wang et al. 2008, Sect. 3.1: one profile per medium of a 256 x 256 grid, each 200 "
        "time-quantized Gaussians a channel) takes several times longer to build than any "
        "profile prt takes, beyond the bound of docs/prt.md"),
}

#: The knobs of :func:`precompute` (Wang et al. 2008): validation, cache key,
#: ``translucent approx prt`` flags and the quality ladder all come from here.
KNOBS = KnobSpec([
    Knob("samples", 16384, "illumination samples per translucent object: parts x 4^n",
         kind="int", low=1, high=1 << 18),
    Knob("parts", 4, "quadtree parts m of the illumination samples", kind="int", low=1,
         high=4096),
    # the vertices radiance is computed at (fast/prt/exit_vertices.py): None derives them
    Knob("exit_subdivisions", None, "midpoint subdivisions of the object's mesh for the "
         "vertices radiance is computed at (default: while an edge spans two diffusion "
         "lengths and eight sample spacings)", kind="int", low=0, high=3, optional=True),
    Knob("basis", "area_normalised", "R_d basis parameterisation (materials.dipole_pca)",
         kind="choice", choices=tuple(PARAMETERISATIONS)),
    Knob("basis_terms", 12, "K, PCA terms of R_d", kind="int", low=1, high=32),
    Knob("basis_eta", 1.3, "the eta the basis samples", kind="float", low=1.0, high=3.0),
    Knob("basis_samples", DEFAULT_SIGMA_SAMPLES, "samples per axis of the basis's "
         "(sigma_s', sigma_a) grid (the shipped dipole bases: 256)", kind="int", low=2,
         high=1024),
    # the transfer is made of the basis functions: another profile is another precomputation
    profile_knob(PROFILE_REFUSALS, keyed=True, help="radial profile whose family the PCA "
                 "basis expands (Sect. 3.1), made from each Dipole material"),
    # pass 1: Haar coefficients kept per transfer row
    Knob("energy", 0.9999, "energy fraction kept per transfer row", kind="float",
         positive=True, high=1.0),
    Knob("terms", 256, "Haar terms kept per transfer row", kind="int", low=1, high=1 << 18),
    Knob("selection", "magnitude", "rank the basis rows' coefficients by magnitude (the "
         "paper) or by magnitude x sqrt(support)", kind="choice",
         choices=("magnitude", "support")),
    Knob("layout", "shared", "first pass storage: the K + 1 rows of a vertex share their "
         "columns, or each row its own (the paper's)", kind="choice",
         choices=("shared", "rows")),
    # pass 2: CDF 9/7 spatial compression
    Knob("spatial", "auto", "CDF 9/7 spatial compression: auto (geometry images above "
         "spatial_min_vertices), on or off", kind="choice", choices=("auto", "on", "off")),
    Knob("spatial_min_vertices", 20000, "vertices above which auto compresses", kind="int",
         low=0, high=10**9),
    Knob("spatial_first_terms", 1024, "terms per row kept for the spatial pass", kind="int",
         low=1, high=1 << 18),
    Knob("spatial_energy", 0.999, "energy fraction kept by the spatial pass", kind="float",
         positive=True, high=1.0),
    Knob("spatial_terms", 256, "terms per row after the spatial pass", kind="int", low=1,
         high=1 << 18),
    # environment lighting
    Knob("environment_resolution", 16, "visibility directions res x 2 res (a power of two)",
         kind="int", low=2, high=256, check=_power_of_two),
    Knob("environment_terms", 64, "environment terms kept per sample", kind="int", low=1,
         high=1 << 17),
    Knob("area_light_samples", 16, "samples per area light (shadow rays per sample)",
         kind="int", low=1, high=4096),
    Knob("seed", 0, "random seed of the samples", kind="int", low=0, high=2**32 - 1),
    # the light the scene's diffuse surfaces bounce onto the object, gathered at the
    # illumination samples (fast.indirect_light); "off" is Eq. 6 as the paper
    *indirect_light_knobs(),
    # the object's own shape: diffusion's correction of the half-space profile
    # (fast.object_geometry); "half_space" is the paper's profile alone
    *geometry_knobs(),
    # rendering only: profiles the illumination samples cannot resolve go to the local
    # vector (SAMPLING_BLEND_START); False: Eq. 5-7 as the paper sums them
    Knob("sampling_blend", True, "blend profiles the samples cannot resolve into the local "
         "vector", kind="bool", keyed=False),
    # how, not what
    Knob("workers", 2, "threads of the transfer computation", kind="int", low=1, high=256,
         keyed=False),
], checks=[_quadtree], ladders={
    # illumination samples (parts x 4^n), PCA terms of the profile basis (Eq. 4) and Haar
    # terms kept per transfer row (Eq. 8)
    "samples, PCA and wavelet terms": [
        {"samples": 1024, "basis_terms": 4, "terms": 32},
        {"samples": 4096, "basis_terms": 8, "terms": 64},
        {"samples": 16384, "basis_terms": 8, "terms": 128},
        {},
    ],
})

#: Knobs of :func:`precompute` and their defaults.
DEFAULT_KNOBS: dict = KNOBS.defaults

#: Quality ladders of ``bench tradeoff`` and the report.
LADDERS: dict = KNOBS.ladders

#: Cheap knobs for smoke runs and the conformance checks (fast.conformance): 256
#: illumination samples (4 parts x 8 x 8) on one core, and a basis over a 16 x 16 grid
#: of media (another profile's basis then builds in about a second).
QUICK_KNOBS: dict = {"samples": 256, "workers": 1, "basis_samples": 16, "indirect_rays": 16,
                     "indirect_patch_rays": 64, **QUICK_GEOMETRY_KNOBS}

#: Knobs read when rendering, or that change how and not what is computed: left out of
#: the cache key.
UNKEYED_KNOBS = KNOBS.unkeyed

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
    return KNOBS.resolve(knobs)


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
    """Return the PCA basis the knobs name: profile, parameterisation, eta, grid, terms."""
    return basis_and_facts(knobs)[0]


def basis_and_facts(knobs: dict) -> tuple[DipolePCABasis, dict]:
    """Return the PCA basis the knobs name and how it was had (empty for the dipole's).

    The dipole's basis ships with the suite at the default grid
    (:func:`~translucent.materials.dipole_pca.dipole_pca_basis`); another profile's is
    built over its own family on the same sampling, and cached
    (:func:`~translucent.fast.prt.profile_basis.family_basis`).
    """
    if knobs["profile"] == DEFAULT_PROFILE:
        return dipole_pca_basis(knobs["basis"], eta=knobs["basis_eta"],
                                terms=knobs["basis_terms"],
                                sigma_samples=knobs["basis_samples"]), {}
    return family_basis(knobs["profile"], knobs["basis"], knobs["basis_eta"],
                        knobs["basis_samples"], knobs["basis_terms"])
