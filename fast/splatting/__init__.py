r"""Multiresolution image-space splatting of heterogeneous translucent objects (Chen et al. 2012).

Every frame is computed from the current geometry, so a deforming mesh needs no
precomputation (``precompute`` only validates the scene and builds, per material, the
lookup table of Eq. 14, which depends on the material alone). Four steps (Sect. 4):

1. *Buffer generation.* An irradiance buffer (G-buffer seen from the light, 512 x 512 by
   default) with a standard mipmap plus a min/max depth mipmap, and a splatting buffer (the
   camera's G-buffer) with a median-depth mipmap. Both are rasterised
   (:func:`rasterize_view`: a z-buffer whose per-pixel test is the pixel's exact ray, so
   the buffers are those of :mod:`translucent.scenes.raycast`'s ray queries, which the
   knob ``buffers = "mitsuba"`` still uses).
2. *Adaptive irradiance sample selection* (Eq. 10-11, Algorithm 1), with the RGB reading
   of the per-point range chosen by ``sampling_range`` (:data:`SAMPLING_RANGES`).
3. *Multiresolution splatting* (Eq. 12-14) with the minimal effective rendering radius
   looked up in a table computed once per material (:func:`minimal_rendering_radius_table`,
   which samples each pixel cell at its centre: see there why).
4. *Splat accumulation* by bilateral upsampling (Eq. 17), then :math:`F_t/\pi` (Eq. 7).

Where a frame's sample-pixel pairs come from (heterogeneous scene, 800 x 600, 512^2
irradiance buffer, epsilon = 0.001). Eq. 13 gives every sample one annulus
:math:`[R^k_{min}, R^k_{max})` at *every* level, the annuli disjoint ("different
nonoverlapping scattering ranges", Sect. 4), so a sample is splatted at all three levels,
not at one chosen per sample. Its range :math:`R_P` (8.8-10.6 mm here, 0.22-0.26 of the
bounding-sphere radius) spans a median 79 pixels at level 0, so :math:`T^1 \approx 39` and
:math:`T^2 \approx 20` pixels, where Eq. 14's table gives :math:`\bar R = 0.10` and
:math:`0.21`. Per level (median projected radii, pairs in range per sample, 158 k samples):
level 0 renders 0-8 pixels (94 pairs), level 1 4-8 of its pixels (61), level 2 4-20 of its
pixels (546): level 2 holds 96 % of each disc's area, hence three quarters of the pairs,
although it has 16 times fewer pixels than level 0. This is the paper's method (its
Table 2 gives level 2 two thirds of the time for its longest ranges, the Bird). Read with
the left-end sums of the paper's notation instead of cell centres, Eq. 14 would keep the
coarse levels unused below about 70 pixels across the range (see
:func:`minimal_rendering_radius_table`), and every pair would be splatted at level 0.

Departures from the paper, each a knob or documented where it is made:

* Eq. 14's sums sample each cell at its centre (:func:`minimal_rendering_radius_table`);
  no level renders a range narrower than :data:`MIN_LEVEL_RESOLUTION` of its pixels.
* Eq. 11 with a perspective (point-light) irradiance buffer is tested per texel with its
  footprint (:func:`select_irradiance_samples`); its RGB range is read as ``sampling_range``
  says (:data:`SAMPLING_RANGES`), and splats stop at the longest channel's range so that
  every channel keeps 95 % of its energy.
* Eq. 17's material weight measures :math:`|R_{P_o} - R_{P_j}|` in units of :math:`R_w`,
  like the depth weight, so that :math:`\lambda_m` is unit-free.
* Optional, off by default (``level_sampling``, :func:`level_sample_masks`): each coarse
  splatting level may take irradiance samples as sparse as its own pixels. The paper
  selects once for all levels, though it mentions running the selection "several times
  ... to generate splatting kernels for each scale".
* The knob ``profile`` (the dipole by default, the paper's) converts another registered
  radial profile of each Dipole material to SubEdit
  (:func:`~translucent.materials.subedit.subedit_from_profile`).
* On by default (``profile_upsampling``, :func:`upsampling_profile_factors`; off gives
  Eq. 17 as published): Eq. 17 upsamples the coarse exitance divided by a per-texel
  profile factor and multiplies the fine pixel's own back in, so that material boundaries
  of the texture are not blurred by the coarse levels (the identity for a homogeneous
  material). A texel's factor is its profile integrated over the distances the coarser
  levels render (against the texture's mean profile), so that a texture finer than a
  coarse pixel, with media of very different reach under it, keeps its energy.

The loops run compiled (:mod:`translucent.fast.splatting.backend_numba`, numba): each level is
cut into tiles of 8 x 8 pixels, each sample is binned to the tiles its range can reach
(the disc bounding its projection, less tiles whose bounding box lies out of range), and
each tile evaluates Eq. 8-9 in float32 for its samples, tiles in parallel.

The measured speed and error of the defaults are in docs/splatting.md.

Units: positions in scene units, profiles in mm^-2 (``scene.mm_per_unit`` converts);
radiance in the units of the lights per scene unit squared, as the reference renders.

References
----------
Chen, Peers, Zhang, Tong: Real-time rendering of deformable heterogeneous translucent
objects using multiresolution splatting. The Visual Computer (2012).

The package, one concept a module: :mod:`.knobs`, :mod:`.buffers` (surface buffers, the
irradiance mipmap, the camera model), :mod:`.selection` (Eq. 10-11), :mod:`.radius_table`
(Eq. 14), :mod:`.splats` (Eq. 12-15 and the numpy and Dr.Jit kernels), :mod:`.accumulation`
(Eq. 17), :mod:`.ground_truth` (brute force), :mod:`.frame`, :mod:`.state` and
:mod:`.method`; the compiled CPU loops are :mod:`translucent.fast.splatting.backend_numba` (the
splat) and :mod:`translucent.fast.splatting.buffer_kernels` (the buffers), the CUDA ones
:mod:`translucent.fast.splatting.backend_cuda`.
"""

from .accumulation import bilateral_upsample, upsampling_profile_factors
from .buffers import (
    CameraModel,
    IrradianceLevel,
    SurfaceBuffer,
    irradiance_mipmap,
    median_depth_mipmap,
)
from .frame import LightView, gather_frame, light_view, rendering_radius_table, splat_frame
from .ground_truth import brute_force_exitance
from .knobs import (
    BACKENDS,
    DEFAULT_KNOBS,
    HETEROGENEOUS_RULE,
    KNOBS,
    LADDERS,
    QUICK_KNOBS,
    SAMPLING_RANGES,
)
from .method import add_approx_arguments, applies_to, approx, precompute, scored_objects
from .radius_table import MIN_LEVEL_RESOLUTION, RenderingRadiusTable, minimal_rendering_radius_table
from .selection import (
    IrradianceSamples,
    SampleSelector,
    level_sample_masks,
    sampling_range,
    select_irradiance_samples,
)
from .splats import effective_rendering_ranges, splat_level
from .state import RasterView, SplattingState, rasterize_view

__all__ = [
    "BACKENDS",
    "CameraModel",
    "DEFAULT_KNOBS",
    "HETEROGENEOUS_RULE",
    "KNOBS",
    "LADDERS",
    "QUICK_KNOBS",
    "IrradianceLevel",
    "IrradianceSamples",
    "LightView",
    "MIN_LEVEL_RESOLUTION",
    "RasterView",
    "RenderingRadiusTable",
    "SAMPLING_RANGES",
    "SampleSelector",
    "SplattingState",
    "SurfaceBuffer",
    "add_approx_arguments",
    "applies_to",
    "scored_objects",
    "approx",
    "bilateral_upsample",
    "brute_force_exitance",
    "effective_rendering_ranges",
    "gather_frame",
    "irradiance_mipmap",
    "level_sample_masks",
    "light_view",
    "median_depth_mipmap",
    "minimal_rendering_radius_table",
    "precompute",
    "rasterize_view",
    "rendering_radius_table",
    "sampling_range",
    "select_irradiance_samples",
    "splat_frame",
    "splat_level",
    "upsampling_profile_factors",
]
