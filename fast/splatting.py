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
* On by default (``profile_upsampling``, :func:`upsampling_profile_factors`; off gives
  Eq. 17 as published): Eq. 17 upsamples the coarse exitance divided by a per-texel
  profile factor and multiplies the fine pixel's own back in, so that material boundaries
  of the texture are not blurred by the coarse levels (the identity for a homogeneous
  material). On the heterogeneous scene it takes the error against brute force from 1.11x
  to 0.995x that of splatting without acceleration, at the same cost.

The loops run compiled (:mod:`translucent.fast.splatting_kernels`, numba): each level is
cut into tiles of 8 x 8 pixels, each sample is binned to the tiles its range can reach
(the disc bounding its projection, less tiles whose bounding box lies out of range), and
each tile evaluates Eq. 8-9 in float32 for its samples, tiles in parallel.

Measured with ``translucent bench splatting`` (heterogeneous scene, 800 x 600, 512^2;
tables and the GPU figures in docs/splatting.md). On this 2-core CPU (load average
0.8-1.3) the defaults render 1.19 frames per second (0.84 s, 1.41 CPU s a frame; 111
million pairs in range, the three splat levels 0.74 s of the frame, level 2 0.53 s),
11.9x faster in wall time (10.0x in CPU time) than without acceleration (14.1 CPU s) at
0.995x its error against brute force (0.0237 vs 0.0238). With Eq. 17 as published the
error is 1.11x (0.0264): the excess is Eq. 17's upsampling across the texture's material
boundaries, where a coarse pixel's texel stands for its children's (upsampled level 2
differs from the same annulus splatted at full resolution by 0.7 % of the frame's energy,
1 % in blue); ``profile_upsampling`` removes it. Five levels with ``level_sampling`` = 1.5:
2.60 frames per second at 0.996x the error (26x faster than no acceleration). The
target of 10 frames per second on this CPU is not reached (3.8x short at equal error). On a GPU
(backend ``"cuda"``, :mod:`.splatting_cuda`) the splats take milliseconds and the frame,
0.21 s on an H100 machine, is bound by the stages that stay on the CPU.

Each change to the frame's code kept its bits unless its commit says otherwise:
rasterising and Eq. 7 as compiled kernels (rows in parallel), the mipmaps, Eq. 17, the
tile layout and each sample's splat window as parallel compiled passes. With another
process busy on the second core, parallel loops wait for their slowest thread: two
threads can then be slower than one (0.106-0.119 s for the buffers against 0.046-0.060).

Units: positions in scene units, profiles in mm^-2 (``scene.mm_per_unit`` converts);
radiance in the units of the lights per scene unit squared, as the reference renders.

References
----------
Chen, Peers, Zhang, Tong: Real-time rendering of deformable heterogeneous translucent
objects using multiresolution splatting. The Visual Computer (2012).
"""

from __future__ import annotations

import argparse
import functools
import math
import time
from dataclasses import dataclass, field

import numpy as np

from ..cache import content_hash
from ..errors import InputError
from ..image import LUMINANCE_WEIGHTS, Image
from ..materials.homogeneous import Dipole
from ..materials.solid import SolidMedium
from ..materials.subedit import SubEditProfiles, subedit_from_dipole
from ..scenes.scene import DirectionalLight, PointLight
from .base import StageLog, refuse_inapplicable, with_defaults
from .solid_inputs import subedit_from_solid

__all__ = [
    "DEFAULT_KNOBS",
    "SurfaceBuffer",
    "SplattingState",
    "applies_to",
    "precompute",
    "approx",
    "add_approx_arguments",
    "minimal_rendering_radius_table",
    "irradiance_mipmap",
    "median_depth_mipmap",
    "select_irradiance_samples",
    "SampleSelector",
    "IrradianceSamples",
    "level_sample_masks",
    "effective_rendering_ranges",
    "splat_level",
    "bilateral_upsample",
    "upsampling_profile_factors",
    "brute_force_exitance",
    "gather_frame",
    "splat_frame",
    "light_view",
    "rendering_radius_table",
    "rasterize_view",
    "RasterView",
    "sampling_range",
    "SAMPLING_RANGES",
    "BACKENDS",
    "MIN_LEVEL_RESOLUTION",
]

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
}
#: The splatting kernels: compiled loops (numba, the default: measured fastest on the CPU,
#: see reports/bench/splatting.py), CUDA (numba.cuda, :mod:`.splatting_cuda`: the same tiles
#: on a GPU), Dr.Jit (LLVM on the CPU, CUDA where a GPU is there) and plain numpy (the
#: reference the others are tested against).
BACKENDS = ("numba", "cuda", "drjit", "numpy")

#: Pairs evaluated at once by the numpy splatting kernel (bounds its memory to ~1 GB).
PAIR_CHUNK = 1 << 21
#: Kernel radii (level pixels) are rounded up to the next of these, so that samples of one
#: bucket share a disc of offsets; ratios of at most 1.25 waste at most ~56 % pairs.
_BUCKET_RATIO = 1.25


# ====================================================================== buffers
@dataclass(frozen=True, eq=False)
class SurfaceBuffer:
    r"""One G-buffer level: what a ray through each pixel hit.

    Parameters
    ----------
    position : ndarray (H, W, 3)
        Hit points, scene units (anything where ``valid`` is False).
    normal : ndarray (H, W, 3)
        Unit shading normals.
    uv : ndarray (H, W, 2)
        Texture coordinates.
    depth : ndarray (H, W)
        Depth along the buffer's axis (camera z or distance from the light), scene units.
    valid : ndarray (H, W) of bool
        True where the ray hit the translucent object.
    footprint : ndarray (H, W)
        Side of the pixel's cross-section perpendicular to the ray at the hit point,
        scene units (its square times the irradiance normal to the ray is the flux the
        pixel receives, Eq. 5-6 of Chen et al. 2012).
    """

    position: np.ndarray
    normal: np.ndarray
    uv: np.ndarray
    depth: np.ndarray
    valid: np.ndarray
    footprint: np.ndarray

    @property
    def shape(self) -> tuple[int, int]:
        """``(H, W)``."""
        return self.valid.shape


@dataclass(frozen=True, eq=False)
class IrradianceLevel:
    r"""One level of the irradiance mipmap (Sect. 4, "Buffer generation").

    ``flux`` (H, W, 3) sums the children's :math:`E\,\Delta A`; ``position``, ``normal``,
    ``uv``, ``cosine`` and ``footprint`` average the valid children (a standard mipmap);
    ``depth_min`` / ``depth_max`` are the min/max mipmap of the light-space depth.
    """

    position: np.ndarray
    normal: np.ndarray
    uv: np.ndarray
    cosine: np.ndarray
    footprint: np.ndarray
    flux: np.ndarray
    depth_min: np.ndarray
    depth_max: np.ndarray
    valid: np.ndarray


def irradiance_mipmap(buffer: SurfaceBuffer, flux: np.ndarray, cosine: np.ndarray,
                      levels: int) -> list[IrradianceLevel]:
    r"""Build the irradiance buffer's mipmap: standard averages plus a min/max depth pyramid.

    Chen et al. 2012, Sect. 4: level 0 is the buffer; each coarser texel averages its
    valid 2 x 2 children (footprint doubled), sums their flux, and keeps the minimum and
    maximum of their depths.

    Parameters
    ----------
    buffer : SurfaceBuffer
        The light-view G-buffer.
    flux : ndarray (H, W, 3)
        :math:`E(x_i)\\,\\Delta A_{x_i}` per pixel (Eq. 5-6), 0 where invalid.
    cosine : ndarray (H, W)
        :math:`|n \\cdot L|` per pixel.
    levels : int
        Number of levels, >= 1.
    """
    from .splatting_kernels import irradiance_level

    valid = buffer.valid
    level = IrradianceLevel(buffer.position, buffer.normal, buffer.uv, cosine,
                            buffer.footprint, np.where(valid[..., None], flux, 0.0),
                            np.where(valid, buffer.depth, np.inf),
                            np.where(valid, buffer.depth, -np.inf), valid)
    pyramid = [level]
    for _ in range(1, levels):
        level = IrradianceLevel(*irradiance_level(
            *(getattr(level, name) for name in ("position", "normal", "uv", "cosine",
                                                "footprint", "flux")),
            level.depth_min, level.depth_max, level.valid))
        pyramid.append(level)
    return pyramid


def median_depth_mipmap(buffer: SurfaceBuffer, levels: int) -> list[SurfaceBuffer]:
    """Build the splatting buffer's mipmap: in each 2 x 2 block, copy the median-depth texel.

    Chen et al. 2012, Sect. 4: a median filter (not an average) keeps sharp geometric
    features. Among the valid children the lower median of the depths is taken; a block
    with no valid child is invalid. ``footprint`` doubles per level.
    """
    from .splatting_kernels import median_depth_level

    pyramid = [buffer]
    for _ in range(1, levels):
        level = pyramid[-1]
        pyramid.append(SurfaceBuffer(*median_depth_level(
            level.position, level.normal, level.uv, level.depth, level.valid,
            level.footprint)))
    return pyramid


# ====================================================================== selection
@dataclass(frozen=True, eq=False)
class IrradianceSamples:
    """The selected irradiance samples: position (N, 3), texel (N,), flux (N, 3), level (N,)."""

    position: np.ndarray
    texel: np.ndarray
    flux: np.ndarray
    level: np.ndarray

    @classmethod
    def concatenate(cls, parts) -> IrradianceSamples:
        """All samples of ``parts`` (e.g. one set per light) in one set."""
        parts = list(parts)
        if not parts:
            return cls(np.zeros((0, 3)), np.zeros(0, np.int64), np.zeros((0, 3)),
                       np.zeros(0, np.int64))
        return cls(*(np.concatenate([getattr(p, name) for p in parts])
                     for name in ("position", "texel", "flux", "level")))

    def __len__(self) -> int:
        return len(self.texel)


def _upsample_mask(mask: np.ndarray, shape) -> np.ndarray:
    return np.repeat(np.repeat(mask, 2, axis=0), 2, axis=1)[: shape[0], : shape[1]]


#: The RGB reading of Eq. 11's :math:`R_{P_x}` (one range per point in the paper):
#: "shortest" channel (every channel sampled at the rate alpha asks), the luminance-weighted
#: mean of the channel ranges, or the "longest" (the range splats are truncated at). Measured
#: on the heterogeneous scene at 800 x 600 (reports/bench/splatting.py): adaptive sampling
#: alone adds no error with "shortest", about 5 % more relative error with "luminance"
#: (35 % fewer samples) and 30 % more with "longest" (60 % fewer samples).
SAMPLING_RANGES = ("shortest", "luminance", "longest")


def sampling_range(material: SubEditProfiles, sampling: str = "shortest") -> np.ndarray:
    r"""Return the per-texel :math:`R_{P_x}` of Eq. 11 of Chen et al. 2012, mm, shape (H, W).

    The paper gives one effective scattering range per point; an RGB profile has one per
    channel (:meth:`~SubEditProfiles.channel_scattering_ranges`), reduced as ``sampling``
    says (:data:`SAMPLING_RANGES`).
    """
    if sampling not in SAMPLING_RANGES:
        raise InputError(f"must be one of {', '.join(map(repr, SAMPLING_RANGES))}",
                         field="sampling_range", value=sampling)
    ranges = material.channel_scattering_ranges()
    if sampling == "shortest":
        return ranges.min(axis=-1)
    if sampling == "longest":
        return ranges.max(axis=-1)
    return ranges @ LUMINANCE_WEIGHTS  # Rec. 709 weights of the channel ranges


class SampleSelector:
    r"""Adaptive irradiance sample selection (Eq. 10-11, Algorithm 1 of Chen et al. 2012).

    Holds the per-texel tests of one frame's irradiance pyramids (one per light), computed
    once, so that the selections of several splatting levels (:func:`level_sample_masks`)
    cost only their coverage scans. A selection is returned as sample ids, flat indices
    into all texels of all pyramids (light by light, each level's texels row-major), so
    that the samples several selections share are recognised (:meth:`samples` builds
    their attributes).

    A texel at level :math:`k \ge 1` passes when
    :math:`z_{max} - z_{min} < z_0` and its sampling rate exceeds the material's,
    :math:`T > M(x) = \alpha R_w / (R_{P_x}|n\cdot L|)`. With a perspective (point light)
    buffer the pixel size :math:`R_w/T` varies, so the test is written per texel as
    :math:`\alpha\,s_k(x) < R_{P_x}|n\cdot L|` with :math:`s_k` the texel's footprint, which
    is Eq. 11 for the paper's orthographic buffer of width :math:`R_w`. The scan is coarse to
    fine: a texel is selected when it passes and no coarser ancestor did (Algorithm 1); every
    valid level-0 texel not covered is selected. ``adaptive=False`` selects all of level 0.

    Parameters
    ----------
    pyramids : list of list of IrradianceLevel
        From :func:`irradiance_mipmap`, one per light.
    material : SubEditProfiles
        :math:`R_{P_x}` comes from its channel ranges (:func:`sampling_range`).
    mm_per_unit : float
        Millimetres per scene unit.
    z0 : float
        Depth-discontinuity threshold, scene units.
    alpha : float
        Scale factor of Eq. 11.
    adaptive : bool
        False selects every valid level-0 texel (the ablation without adaptive sampling).
    sampling : str
        Which per-texel range sets the rate: see :data:`SAMPLING_RANGES`.
    """

    def __init__(self, pyramids, material: SubEditProfiles, *, mm_per_unit: float,
                 z0: float, alpha: float, adaptive: bool = True, sampling: str = "shortest"):
        ranges = sampling_range(material, sampling).reshape(-1) / mm_per_unit
        self.pyramids = [pyramid if adaptive else pyramid[:1] for pyramid in pyramids]
        self._texel, self._passes, self._smooth = [], [], []
        self._offset = []
        offset = 0
        for pyramid in self.pyramids:
            texels, passes, smooth, offsets = [], [], [], []
            for k, level in enumerate(pyramid):
                texel = material.texel_index(level.uv)
                if k == 0:
                    level_passes, level_smooth = level.valid, level.valid
                else:
                    with np.errstate(invalid="ignore"):  # inf - inf on invalid texels
                        level_smooth = level.valid & ((level.depth_max - level.depth_min) < z0)
                    fine_enough = alpha * level.footprint < ranges[texel] * np.abs(level.cosine)
                    level_passes = level_smooth & fine_enough
                texels.append(texel.reshape(-1))
                passes.append(level_passes)
                smooth.append(level_smooth)
                offsets.append(offset)
                offset += level.valid.size
            self._texel.append(texels)
            self._passes.append(passes)
            self._smooth.append(smooth)
            self._offset.append(offsets)
        self.size = offset
        self._spacing = {}
        self._attributes = None

    def select(self, coarse_enough=None) -> np.ndarray:
        """Return the ids of the selected samples (int64, coarsest level first per light).

        ``coarse_enough`` (one list of (H_l, W_l) bool masks per pyramid, optional): texels
        that pass the rate test whatever Eq. 11 says (they still need the depth test), as
        :func:`level_sample_masks` gives for one coarse splatting level.
        """
        ids = []
        for p, pyramid in enumerate(self.pyramids):
            covered = None
            for k in range(len(pyramid) - 1, -1, -1):
                passes = self._passes[p][k]
                if coarse_enough is not None and k > 0:
                    passes = passes | (self._smooth[p][k] & coarse_enough[p][k])
                if covered is not None:
                    covered = _upsample_mask(covered, passes.shape)
                    selected = passes & ~covered
                    covered |= selected
                else:
                    selected = passes
                    covered = passes.copy()
                ids.append(np.flatnonzero(selected) + self._offset[p][k])
        return np.concatenate(ids) if ids else np.zeros(0, np.int64)

    def level_masks(self, camera: CameraModel, level: int, pitch: float) -> list:
        """:func:`level_sample_masks` of every pyramid, its depths and spacings computed once."""
        masks = []
        for p, pyramid in enumerate(self.pyramids):
            if p not in self._spacing:
                self._spacing[p] = [_spacing_and_depth(irradiance, camera)
                                    for irradiance in pyramid]
            masks.append(_coarse_enough(self._spacing[p], camera, level, pitch))
        return masks

    def samples(self, ids: np.ndarray) -> IrradianceSamples:
        """Return the samples with these ids (position, texel, flux, irradiance level)."""
        if self._attributes is None:
            parts = [(level.position.reshape(-1, 3), texel, level.flux.reshape(-1, 3),
                      np.full(level.valid.size, k, np.int64))
                     for pyramid, texels in zip(self.pyramids, self._texel, strict=True)
                     for k, (level, texel) in enumerate(zip(pyramid, texels, strict=True))]
            self._attributes = [np.concatenate(column) for column in zip(*parts, strict=True)]
        # np.take: a third of the time of fancy indexing for the (N, 3) columns
        return IrradianceSamples(*(np.take(column, ids, axis=0)
                                   for column in self._attributes))


def select_irradiance_samples(pyramid: list[IrradianceLevel], material: SubEditProfiles, *,
                              mm_per_unit: float, z0: float, alpha: float,
                              adaptive: bool = True, sampling: str = "shortest",
                              coarse_enough: list | None = None) -> IrradianceSamples:
    r"""Adaptive irradiance sample selection over one pyramid (see :class:`SampleSelector`).

    Parameters
    ----------
    pyramid : list of IrradianceLevel
        From :func:`irradiance_mipmap`.
    material, mm_per_unit, z0, alpha, adaptive, sampling
        As :class:`SampleSelector`.
    coarse_enough : list of ndarray (H_k, W_k) of bool, optional
        Per level, texels that pass the rate test whatever Eq. 11 says (they still need
        the depth test): the samples of one coarse splatting level
        (:func:`level_sample_masks`).
    """
    selector = SampleSelector([pyramid], material, mm_per_unit=mm_per_unit, z0=z0,
                              alpha=alpha, adaptive=adaptive, sampling=sampling)
    return selector.samples(selector.select(None if coarse_enough is None
                                            else [coarse_enough]))


def _spacing_and_depth(irradiance: IrradianceLevel, camera: CameraModel):
    r"""Return texels usable at all, their spacing :math:`s_l/|n\cdot L|`, their camera depth."""
    depth = camera.depth(np.nan_to_num(irradiance.position))
    with np.errstate(divide="ignore", invalid="ignore"):
        spacing = irradiance.footprint / np.abs(irradiance.cosine)
    return irradiance.valid & (depth > 0), spacing, depth


def _coarse_enough(spacing_and_depth, camera: CameraModel, level: int, pitch: float) -> list:
    pixel = (1 << level) * 2.0 * camera.tan_half_fov / camera.width
    return [usable & (spacing <= pitch * pixel * depth)
            for usable, spacing, depth in spacing_and_depth]


def level_sample_masks(pyramid: list[IrradianceLevel], camera: CameraModel, level: int,
                       pitch: float) -> list[np.ndarray]:
    r"""Irradiance texels fine enough for splatting level ``level``: the masks of ``coarse_enough``.

    A texel of irradiance level :math:`l` passes when its spacing on the surface,
    :math:`s_l/|n\cdot L|` (footprint over the cosine, its longer side), is at most
    ``pitch`` times the width of one pixel of splatting level :math:`k` at the texel's
    camera depth, :math:`2^k\,2\tan(\mathrm{fov}/2)\,z/W`. Level :math:`k` renders only
    distances of at least :math:`R^k_{min}`, where Eq. 14 found the profile's integral
    sampled well enough on a grid of its pixels; sampling the irradiance on a grid no
    coarser is the same quadrature from the other end of each pair. Not in Chen et al.
    2012, whose one selection (Eq. 10-11) serves every level; see the module docstring.

    Returns
    -------
    list of ndarray (H_l, W_l) of bool
    """
    return _coarse_enough([_spacing_and_depth(irradiance, camera) for irradiance in pyramid],
                          camera, level, pitch)


# ====================================================================== Eq. 14 lookup table
@dataclass(frozen=True)
class RenderingRadiusTable:
    r"""The minimal effective rendering radius :math:`\bar R(T)` of Eq. 14, tabulated.

    ``resolutions`` (ascending) are values of :math:`T` (pixels across the effective
    scattering range); ``radii`` the normalised :math:`\bar R \in [0, 1]` (non-increasing).
    """

    resolutions: np.ndarray
    radii: np.ndarray

    def __call__(self, resolution) -> np.ndarray:
        r"""Return :math:`\bar R(T)`, linear in :math:`\ln T` (clamped at the ends)."""
        resolution = np.asarray(resolution, np.float64)
        if resolution.size and not (np.isfinite(lowest := resolution.min()) and lowest >= 1e-30
                                    and np.isfinite(resolution.max())):
            resolution = np.clip(np.nan_to_num(resolution, nan=1.0, posinf=1e30), 1e-30, None)
        return np.interp(np.log(resolution), np.log(self.resolutions), self.radii)


#: Fewest pixels of a level across a profile's effective range for the level to render any of
#: it: bilinear upsampling (Eq. 17 of Chen et al. 2012) cannot reconstruct a ring narrower
#: than two of its pixels, however smooth the profile is there.
MIN_LEVEL_RESOLUTION = 2.0


def minimal_rendering_radius_table(mean_profile, epsilon: float = 0.001, *,
                                   resolutions=None, radius_samples: int = 128
                                   ) -> RenderingRadiusTable:
    r"""Tabulate Eq. 14 of Chen et al. 2012: the smallest radius rendered at a resolution.

    For a resolution :math:`T` (pixels across the effective scattering range),
    :math:`\bar R(T)` is the smallest :math:`r` such that the sampled tail
    :math:`\sum_m \bar P(\hat r_m)\hat r_m\,h_m` differs from
    :math:`\int_r^1 \bar P(r) r\,dr` by less than :math:`\varepsilon` for every
    :math:`r' \ge r` (the absolute difference; the paper's set definition read as "from
    here outwards"). The cells are the paper's, :math:`[r + m/T, r + (m+1)/T]` clipped to
    :math:`[r, 1]` (width :math:`h_m`), each sampled at its centre :math:`\hat r_m`, as a
    pixel of the level samples the profile at its centre; no level renders anything below
    :data:`MIN_LEVEL_RESOLUTION` pixels across the range (:math:`\bar R = 1`).

    Why cell centres and not the left ends :math:`r + m/T` of the paper's notation: that
    sum is biased by :math:`\approx (\bar P(r) r + \bar P(1))/(2T)`, a first-order
    artefact of the notation (a pixel stands for the cell around its centre), which at
    :math:`\varepsilon = 0.001` keeps every coarse level unused until the range covers
    about 70 of its pixels. The paper's own scenes (ranges of 0.04-0.35 bounding-sphere
    radii at 800 x 600, so at most ~45 pixels at level 1) then could never use levels 1
    and 2, yet its Table 2 gives them 25-80 % of the splatting time. With cell centres the
    error is the quadrature error of the pixel grid, second order in :math:`1/T`.

    Parameters
    ----------
    mean_profile : callable
        :math:`\bar P(r)` on :math:`r \in [0, 1]` (normalised so that
        :math:`\int_0^1 \bar P r\,dr = 1`), vectorised.
    epsilon : float
        Error tolerance (0.001 in the paper), > 0.
    resolutions : array_like, optional
        Values of :math:`T`; default 37 values from 0.5 to 2048, log-spaced (beyond the
        last one the table's last radius is used, a radius too large: safe, just slower).
    radius_samples : int
        Candidate radii in [0, 1].
    """
    if not np.isfinite(epsilon) or epsilon <= 0:
        raise InputError("must be > 0", field="epsilon", value=epsilon)
    if resolutions is None:
        resolutions = np.geomspace(0.5, 2048.0, 37)
    resolutions = np.asarray(resolutions, dtype=np.float64)
    fine = np.linspace(0.0, 1.0, 2049)
    density = np.asarray(mean_profile(fine), dtype=np.float64) * fine
    tail = np.concatenate([np.cumsum((0.5 * (density[1:] + density[:-1]) / 2048)[::-1])[::-1],
                           [0.0]])  # integral from fine[j] to 1
    candidates = np.linspace(0.0, 1.0, radius_samples + 1)
    integral = np.interp(candidates, fine, tail)
    radii = np.empty(len(resolutions))
    for index, resolution in enumerate(resolutions):
        if resolution < MIN_LEVEL_RESOLUTION:
            radii[index] = 1.0
            continue
        step = 1.0 / resolution
        # cells [r + m/T, r + (m+1)/T] clipped to [r, 1], each sampled at its centre
        count = np.ceil((1.0 - candidates) * resolution - 1e-9).astype(np.int64)
        total = np.zeros_like(candidates)
        for start in range(0, int(count.max()), 4096):
            m = np.arange(start, min(int(count.max()), start + 4096))[None, :]
            lower = candidates[:, None] + m * step
            upper = np.minimum(lower + step, 1.0)
            width = np.where(m < count[:, None], upper - lower, 0.0)
            total += (np.interp(0.5 * (lower + upper), fine, density) * width).sum(axis=1)
        bad = np.abs(total - integral) >= epsilon
        # smallest r with every r' >= r within tolerance
        last_bad = np.flatnonzero(bad)
        radii[index] = 0.0 if len(last_bad) == 0 else min(
            1.0, candidates[min(last_bad[-1] + 1, radius_samples)])
    radii = np.minimum.accumulate(radii)  # finer resolution never needs a larger radius
    return RenderingRadiusTable(resolutions, radii)


# ====================================================================== ranges and splats
@dataclass(frozen=True)
class CameraModel:
    """The pinhole projection of the splatting buffer (the scene camera)."""

    origin: np.ndarray
    forward: np.ndarray
    right: np.ndarray
    up: np.ndarray
    tan_half_fov: float
    width: int
    height: int

    @classmethod
    def from_camera(cls, camera) -> CameraModel:
        """From a :class:`~translucent.scenes.Camera` (horizontal fov, Mitsuba's look-at)."""
        from ..scenes.raycast import camera_frame

        forward, left, up = camera_frame(camera)
        return cls(camera.origin, forward, -left, up, math.tan(math.radians(camera.fov) / 2),
                   camera.width, camera.height)

    def depth(self, points: np.ndarray) -> np.ndarray:
        """Depth z along the view axis (what :meth:`project` returns as z)."""
        return self._along(self._relative(points), self.forward)

    def _relative(self, points):
        points = np.asarray(points, dtype=np.float64)
        return [points[..., c] - self.origin[c] for c in range(3)]

    @staticmethod
    def _along(relative, axis):
        # three products instead of ``relative @ axis``: numpy hands (N, 3) @ (3,) to
        # OpenBLAS, measured 24 ms for a frame's 158 k samples against 0.7 ms, and its idle
        # threads then spin on, charging CPU time to the stages that follow
        return relative[0] * axis[0] + relative[1] * axis[1] + relative[2] * axis[2]

    def project(self, points: np.ndarray, width: int, height: int):
        """Continuous pixel coordinates (x, y) at a level of size width x height, and depth z."""
        relative = self._relative(points)
        z = self._along(relative, self.forward)
        safe = np.where(np.abs(z) > 1e-12, z, 1e-12)
        focal = width / (2.0 * self.tan_half_fov)
        x = self._along(relative, self.right) / safe * focal + 0.5 * width
        y = -self._along(relative, self.up) / safe * focal + 0.5 * height
        return x, y, z


def effective_rendering_ranges(samples: IrradianceSamples, material: SubEditProfiles,
                               table: RenderingRadiusTable, camera: CameraModel, *,
                               mm_per_unit: float, levels: int, multiresolution: bool = True,
                               near: float = 1e-6) -> np.ndarray:
    r"""Eq. 13 of Chen et al. 2012: :math:`[R^k_{min}, R^k_{max})` of each sample at each level.

    :math:`R^k_{min} = R_{P_{x_i}}\bar R(T^k(x_i))` with
    :math:`T^k(x_i) = T^k R_{P_{x_i}} / (2\tan(\mathrm{fov}/2) z(x_i))`, :math:`T^k` the width
    in pixels of splatting level :math:`k`; :math:`R^0_{min} = 0`,
    :math:`R^k_{max} = R^{k+1}_{min}`, :math:`R^{n-1}_{max} = R_{P_{x_i}}`. Without
    multiresolution level 0 takes :math:`[0, R_{P_{x_i}})`.

    Returns
    -------
    ndarray (N, levels + 1)
        Boundaries in scene units: level ``k`` covers ``[out[:, k], out[:, k + 1])``.
    """
    ranges = material.effective_scattering_range.reshape(-1)[samples.texel] / mm_per_unit
    bounds = np.zeros((len(samples), levels + 1))
    bounds[:, levels] = ranges
    if not multiresolution or levels == 1:
        bounds[:, 1:] = ranges[:, None]
        return bounds
    z = np.maximum(np.abs(camera.depth(samples.position)), near)
    for k in range(1, levels):
        width_k = max(1, camera.width >> k)
        resolution = width_k * ranges / (2.0 * camera.tan_half_fov * z)
        bounds[:, k] = ranges * table(resolution)
    for k in range(2, levels):  # running maximum (np.maximum.accumulate along rows is slow)
        np.maximum(bounds[:, k - 1], bounds[:, k], out=bounds[:, k])
    return bounds


@functools.lru_cache(maxsize=64)
def _disc_offsets(radius: int) -> tuple[np.ndarray, np.ndarray]:
    span = np.arange(-radius, radius + 1)
    dx, dy = np.meshgrid(span, span)
    inside = dx * dx + dy * dy <= (radius + 0.75) ** 2
    return dx[inside].astype(np.int64), dy[inside].astype(np.int64)


def _bucket_radii(limit: int) -> np.ndarray:
    radii = [1]
    while radii[-1] < limit:
        radii.append(max(radii[-1] + 1, int(math.ceil(radii[-1] * _BUCKET_RATIO))))
    return np.asarray(radii, dtype=np.int64)


def _evaluate_pairs(table, step_inverse, segments, distance, texel_in, texel_out):
    """sqrt(P_i(d) P_o(d)) for pairs (Eq. 8 with Eq. 9), float32, shape (M, 3); 0 at r >= r_s."""
    position = distance * step_inverse
    inside = position < segments
    position = np.where(inside, position, 0.0)
    k = np.minimum(position.astype(np.int64), segments - 1)
    weight = (position - k)[:, None].astype(np.float32)
    start_i = table[texel_in, k]
    end_i = table[texel_in, k + 1]
    start_o = table[texel_out, k]
    end_o = table[texel_out, k + 1]
    log_value = 0.5 * ((start_i + start_o) + weight * ((end_i + end_o) - (start_i + start_o)))
    value = np.exp(log_value)
    return np.where(inside[:, None], value, 0.0)


def splat_level(samples: IrradianceSamples, bounds_low: np.ndarray, bounds_high: np.ndarray,
                level: SurfaceBuffer, level_texel: np.ndarray, material: SubEditProfiles,
                camera: CameraModel, *, mm_per_unit: float, backend: str = "numpy",
                stats: dict | None = None) -> np.ndarray:
    r"""Splat samples into one splatting level (Eq. 12 of Chen et al. 2012).

    For every sample :math:`x_i` and every valid pixel :math:`x_o` of the level whose
    surface point lies at a distance :math:`d \in [R^k_{min}, R^k_{max})`:
    :math:`B^k(x_o) \mathrel{+}= \sqrt{P_{x_o}(d) P_{x_i}(d)}\,E(x_i)\Delta A_{x_i}`.
    The pixels visited are those of a disc around the sample's projection whose radius
    bounds the projection of a sphere of radius :math:`R^k_{max}` (then the 3D distance
    decides).

    Returns
    -------
    ndarray (H_k, W_k, 3)
        :math:`B^k` in flux per scene unit squared.
    """
    height, width = level.shape
    exitance = np.zeros((height * width, 3), dtype=np.float64)
    if not len(samples) or not level.valid.any():
        return exitance.reshape(height, width, 3)
    from .splatting_kernels import splat_windows

    limit = max(width, height)
    index, centre_x, centre_y, radius, reach_pixels = splat_windows(
        samples.position, samples.flux, bounds_low, bounds_high,
        *(np.asarray(vector, dtype=np.float64) for vector in (
            camera.origin, camera.forward, camera.right, camera.up)),
        float(camera.tan_half_fov), width, height)
    if not len(index):
        return exitance.reshape(height, width, 3)
    scale = float(mm_per_unit) ** 2  # mm^-2 -> per scene unit squared
    kernels = {"numba": None, "cuda": None, "numpy": _NumpyKernel, "drjit": _DrJitKernel}
    if backend not in kernels:
        raise InputError(f"unknown backend; valid: {', '.join(kernels)}", field="backend",
                         value=backend)
    if kernels[backend] is None:
        exitance, pairs = _splat_tiled(samples, bounds_low, bounds_high, level, level_texel,
                                       material, mm_per_unit, scale, index, centre_x,
                                       centre_y, reach_pixels, gpu=backend == "cuda")
        if stats is not None:
            stats["pairs"] = stats.get("pairs", 0) + pairs[0]
            stats["pairs in range"] = stats.get("pairs in range", 0) + pairs[1]
        return exitance
    buckets = _bucket_radii(limit)
    bucket_of = np.searchsorted(buckets, radius.astype(np.int64))
    kernel = kernels[backend](samples, bounds_low, bounds_high, level, level_texel, material,
                              mm_per_unit, scale)
    pairs = 0
    for bucket in np.unique(bucket_of):
        members = bucket_of == bucket
        dx, dy = _disc_offsets(int(buckets[bucket]))
        pairs += int(members.sum()) * len(dx)
        kernel.splat(index[members], np.floor(centre_x[members]).astype(np.int64),
                     np.floor(centre_y[members]).astype(np.int64), dx, dy)
    if stats is not None:
        stats["pairs"] = stats.get("pairs", 0) + pairs
    return kernel.result().reshape(height, width, 3)


def _splat_tiled(samples, bounds_low, bounds_high, level, level_texel, material, mm_per_unit,
                 scale, index, centre_x, centre_y, radius, gpu=False):
    """Run the tiled kernels of :func:`splat_level` (numba on the CPU, or CUDA).

    Samples are binned to tiles (:func:`.splatting_kernels.bin_samples`), then splatted
    (:func:`.splatting_kernels.splat_tiles`); with ``gpu`` both run on the device
    (:func:`.splatting_cuda.bin_and_splat_tiles`).
    """
    from . import splatting_kernels as kernels

    height, width = level.shape
    position, texel, tile_bounds, tiles_y, tiles_x = kernels.tile_layout(
        np.moveaxis(level.position, -1, 0), level_texel, level.valid)
    sample_position = np.ascontiguousarray(np.take(samples.position, index, axis=0).T,
                                           dtype=np.float32)
    low2 = np.square(bounds_low[index]).astype(np.float32)
    high2 = np.square(bounds_high[index]).astype(np.float32)
    window = (centre_x.astype(np.float32), centre_y.astype(np.float32),
              # the surface point of a pixel of a coarser level is one of its finest
              # children's: it projects inside the pixel, within sqrt(2)/2 of its centre;
              # 1e-3 and 1e-5 cover the float32 rounding of the bound
              (radius * (1.0 + 1e-5) + (0.5 * math.sqrt(2.0) + 1e-3)).astype(np.float32))
    profile = (_segment_table(material),
               np.float32(material.segments / (material.r_s / mm_per_unit)), sample_position,
               samples.texel[index].astype(np.int32),
               np.ascontiguousarray(np.take(samples.flux, index, axis=0) * scale,
                                    dtype=np.float32), low2, high2)
    out = np.empty(position.shape, dtype=np.float32)
    if gpu:
        from .splatting_cuda import bin_and_splat_tiles

        used, binned = bin_and_splat_tiles(out, position, texel, tile_bounds, tiles_x,
                                           *profile, *window)
    else:
        start, members = kernels.bin_samples(tile_bounds, tiles_y, tiles_x, sample_position,
                                             *window, low2, high2)
        used = kernels.splat_tiles(out, position, texel, *profile, start, members)
        binned = len(members)
    visited = binned * kernels.TILE ** 2
    return (kernels.untile_float64(out, tiles_x, height, width), [visited, int(used.sum())])


@functools.lru_cache(maxsize=16)
def _segment_table(material: SubEditProfiles) -> np.ndarray:
    from .splatting_kernels import segment_table

    return segment_table(material.flat_log_profile)


class _NumpyKernel:
    """The numpy kernel of :func:`splat_level`: pairs in chunks, accumulated by bincount."""

    def __init__(self, samples, bounds_low, bounds_high, level, level_texel, material,
                 mm_per_unit, scale):
        self.samples = samples
        self.bounds_low = bounds_low
        self.bounds_high = bounds_high
        self.height, self.width = level.shape
        self.valid = level.valid.reshape(-1)
        self.position = level.position.reshape(-1, 3)
        self.texel_out = level_texel.reshape(-1)
        self.material = material
        self.table = material.flat_log_profile.astype(np.float32)
        self.step_inverse = material.segments / (material.r_s / mm_per_unit)
        self.flux = samples.flux * scale
        self.exitance = np.zeros((len(self.valid), 3))

    def splat(self, index, column, row, dx, dy):
        """Splat samples ``index`` centred on pixels (column, row) over offsets (dx, dy)."""
        per_chunk = max(1, PAIR_CHUNK // len(dx))
        for start in range(0, len(index), per_chunk):
            part = slice(start, start + per_chunk)
            sample = np.repeat(index[part], len(dx))
            px = (column[part][:, None] + dx[None, :]).reshape(-1)
            py = (row[part][:, None] + dy[None, :]).reshape(-1)
            inside = (px >= 0) & (px < self.width) & (py >= 0) & (py < self.height)
            sample, px, py = sample[inside], px[inside], py[inside]
            pixel = py * self.width + px
            hit = self.valid[pixel]
            sample, pixel = sample[hit], pixel[hit]
            offset = self.position[pixel] - self.samples.position[sample]
            distance = np.sqrt(np.einsum("ij,ij->i", offset, offset))
            within = (distance >= self.bounds_low[sample]) & (distance < self.bounds_high[sample])
            sample, pixel, distance = sample[within], pixel[within], distance[within]
            if not len(sample):
                continue
            value = _evaluate_pairs(self.table, self.step_inverse, self.material.segments,
                                    distance, self.samples.texel[sample], self.texel_out[pixel])
            weight = value * self.flux[sample]
            for channel in range(3):
                self.exitance[:, channel] += np.bincount(pixel, weights=weight[:, channel],
                                                         minlength=len(self.valid))

    def result(self) -> np.ndarray:
        """Return the accumulated exitance, (H * W, 3)."""
        return self.exitance


@functools.lru_cache(maxsize=1)
def _jit():
    """Dr.Jit and its array types: CUDA where a GPU is usable, else LLVM (libLLVM set up first)."""
    from ..backend import configure_libllvm

    configure_libllvm()
    import drjit as dr

    if dr.has_backend(dr.JitBackend.CUDA):
        import drjit.cuda as types
    elif dr.has_backend(dr.JitBackend.LLVM):
        import drjit.llvm as types
    else:
        raise InputError("Dr.Jit has neither a CUDA nor an LLVM backend here; use "
                         "backend = \"numpy\"", field="backend", value="drjit")
    return dr, types


class _DrJitKernel:
    """The Dr.Jit kernel of :func:`splat_level`: one fused kernel per bucket of samples.

    Each pair (sample, offset) is one lane: gather the pixel's surface point and texel,
    test the distance against :math:`[R^k_{min}, R^k_{max})`, evaluate Eq. 8-9 and
    scatter-add into the exitance (float32 on the device, LLVM on the CPU or CUDA).
    Sizes enter as opaque values so that a kernel compiles once per material layout.
    """

    def __init__(self, samples, bounds_low, bounds_high, level, level_texel, material,
                 mm_per_unit, scale):
        dr, t = _jit()
        self.dr, self.t = dr, t
        self.height, self.width = level.shape
        valid = level.valid.reshape(-1)
        texel = np.where(valid, level_texel.reshape(-1), -1).astype(np.int32)
        position = level.position.reshape(-1, 3).astype(np.float32)
        self.pixel_position = [t.Float(np.ascontiguousarray(position[:, c])) for c in range(3)]
        self.texel_out = t.Int32(texel)
        self.table = t.Float(np.ascontiguousarray(material.flat_log_profile, np.float32)
                             .reshape(-1))
        self.segments = material.segments
        self.step_inverse = material.segments / (material.r_s / mm_per_unit)
        sample_position = samples.position.astype(np.float32)
        self.sample_position = [t.Float(np.ascontiguousarray(sample_position[:, c]))
                                for c in range(3)]
        flux = (samples.flux * scale).astype(np.float32)
        self.flux = [t.Float(np.ascontiguousarray(flux[:, c])) for c in range(3)]
        self.texel_in = t.Int32(samples.texel.astype(np.int32))
        self.low = t.Float(bounds_low.astype(np.float32))
        self.high = t.Float(bounds_high.astype(np.float32))
        self.exitance = [dr.zeros(t.Float, self.height * self.width) for _ in range(3)]

    def splat(self, index, column, row, dx, dy):
        """Splat samples ``index`` centred on pixels (column, row) over offsets (dx, dy)."""
        lanes = len(index) * len(dx)
        for start in range(0, lanes, 1 << 30):  # lane indices stay within UInt32
            self._launch(index, column, row, dx, dy, start, min(lanes, start + (1 << 30)))

    def _launch(self, index, column, row, dx, dy, start, stop):
        dr, t = self.dr, self.t
        count = dr.opaque(t.UInt32, len(dx))
        lane = dr.arange(t.UInt32, stop - start) + dr.opaque(t.UInt32, start)
        local = lane // count
        offset = lane - local * count
        sample = dr.gather(t.UInt32, t.UInt32(index.astype(np.uint32)), local)
        x = dr.gather(t.Int32, t.Int32(column.astype(np.int32)), local) + \
            dr.gather(t.Int32, t.Int32(dx.astype(np.int32)), offset)
        y = dr.gather(t.Int32, t.Int32(row.astype(np.int32)), local) + \
            dr.gather(t.Int32, t.Int32(dy.astype(np.int32)), offset)
        width = dr.opaque(t.Int32, self.width)
        active = (x >= 0) & (x < width) & (y >= 0) & (y < dr.opaque(t.Int32, self.height))
        pixel = t.UInt32(dr.select(active, y * width + x, 0))
        texel_out = dr.gather(t.Int32, self.texel_out, pixel, active)
        active &= texel_out >= 0
        squared = t.Float(0.0)
        for c in range(3):
            difference = dr.gather(t.Float, self.pixel_position[c], pixel, active) - \
                dr.gather(t.Float, self.sample_position[c], sample, active)
            squared = dr.fma(difference, difference, squared)
        distance = dr.sqrt(squared)
        active &= (distance >= dr.gather(t.Float, self.low, sample, active)) & \
            (distance < dr.gather(t.Float, self.high, sample, active))
        position = distance * dr.opaque(t.Float, self.step_inverse)
        segments = dr.opaque(t.Int32, self.segments)
        active &= position < t.Float(segments)
        k = dr.minimum(t.Int32(position), segments - 1)
        weight = position - t.Float(k)
        stride = (segments + 1) * 3
        texel_in = dr.gather(t.Int32, self.texel_in, sample, active)
        base_in = t.UInt32(texel_in * stride + k * 3)
        base_out = t.UInt32(texel_out * stride + k * 3)
        for c in range(3):
            first = dr.gather(t.Float, self.table, base_in + c, active) + \
                dr.gather(t.Float, self.table, base_out + c, active)
            second = dr.gather(t.Float, self.table, base_in + 3 + c, active) + \
                dr.gather(t.Float, self.table, base_out + 3 + c, active)
            value = dr.exp(0.5 * dr.fma(weight, second - first, first)) * \
                dr.gather(t.Float, self.flux[c], sample, active)
            dr.scatter_reduce(dr.ReduceOp.Add, self.exitance[c], value, pixel, active)
        dr.eval(self.exitance)

    def result(self) -> np.ndarray:
        """Return the accumulated exitance, (H * W, 3), float64."""
        return np.stack([np.asarray(channel, dtype=np.float64) for channel in self.exitance],
                        axis=-1)


# ====================================================================== accumulation
def bilateral_upsample(coarse: np.ndarray, coarse_level: SurfaceBuffer,
                       coarse_range: np.ndarray, fine_level: SurfaceBuffer,
                       fine_range: np.ndarray, *, scene_diameter: float, lambda_z: float = 8.0,
                       lambda_m: float = 8.0) -> np.ndarray:
    r"""Eq. 17 of Chen et al. 2012: bilateral upsampling of :math:`B^{k+1}` to level k.

    Each fine pixel averages its four nearest coarse pixels with weights
    :math:`w_p w_z w_m`: bilinear, :math:`e^{-\lambda_z|z_o - z_j|/R_w}` and
    :math:`e^{-\lambda_m|R_{P_o} - R_{P_j}|/R_w}` (the ranges in units of the bounding
    sphere's diameter :math:`R_w`, like the depths, so that the weight is unit-free).
    Invalid coarse pixels weigh 0; a fine pixel none of whose neighbours is valid gets 0.

    Parameters
    ----------
    coarse : ndarray (h, w, 3)
    coarse_level, fine_level : SurfaceBuffer
        The splatting-buffer levels k + 1 and k (depths and validity).
    coarse_range, fine_range : ndarray
        Effective scattering range of each pixel's texel, scene units.
    scene_diameter : float
        :math:`R_w`, scene units.
    """
    from .splatting_kernels import bilateral_upsample_level

    return bilateral_upsample_level(
        np.ascontiguousarray(coarse, dtype=np.float64),
        np.where(coarse_level.valid, coarse_level.depth, 0.0), coarse_level.valid,
        np.asarray(coarse_range, dtype=np.float64),
        np.where(fine_level.valid, fine_level.depth, 0.0), fine_level.valid,
        np.asarray(fine_range, dtype=np.float64), lambda_z / scene_diameter,
        lambda_m / scene_diameter)


def upsampling_profile_factors(material: SubEditProfiles, inner: float) -> np.ndarray:
    r"""Per-texel factors that carry a coarse level's exitance across material boundaries.

    The exitance that levels coarser than k render, :math:`\sum_i
    \sqrt{P_{x_o}(d)P_{x_i}(d)}\,E\Delta A` over :math:`d \ge R^{k+1}_{min}`, carries the
    factor :math:`\sqrt{P_{x_o}(d)}` of the pixel's own texel, which changes abruptly where
    the texture does; Eq. 17 of Chen et al. 2012 interpolates it as if it were smooth.
    Divided by :math:`\sqrt{P_{x_o}(r^*)}` before the upsampling and multiplied by the
    fine pixel's own after it, only the smooth remainder is interpolated. :math:`r^*` is
    the radius that halves the energy of the mean normalised profile :math:`\bar P` (Eq.
    15) over :math:`[\rho, 1]`, in units of the median effective range (the distances the
    coarser levels render, weighted as they contribute). For a homogeneous material the
    factors are equal and the upsampling is Eq. 17's. Not in the paper (the knob
    ``profile_upsampling``, on by default).

    Parameters
    ----------
    material : SubEditProfiles
    inner : float
        :math:`\rho`, the inner edge of the coarser levels' ranges as a fraction of
        :math:`R_P` (the median :math:`R^{k+1}_{min}/R_P` over the samples), in [0, 1]
        (clipped there; NaN reads as 0).

    Returns
    -------
    ndarray (texels, 3)
        :math:`\sqrt{P_x(r^* \operatorname{median} R_P)}`, mm^-1; 1 where the profile is 0
        there.
    """
    grid, cumulative, typical_range = _mean_profile_energy(material)
    inner = float(np.clip(np.nan_to_num(inner), 0.0, 1.0))
    below = np.interp(inner, grid, cumulative)
    if cumulative[-1] - below > 0:
        median = np.interp(0.5 * (below + cumulative[-1]), cumulative, grid)
        median = max(median, inner)
    else:
        median = inner
    factors = np.sqrt(material.profile(median * typical_range, np.arange(material.texel_count)))
    return np.where(factors > 0, factors, 1.0)


#: Points of the table of :math:`\int_0^u \bar P(r)\,r\,dr` over :math:`u \in [0, 1]`
#: (:func:`_mean_profile_energy`), once per material: the halving radius of any
#: :math:`[\rho, 1]` is read off it, instead of evaluating the mean profile at 257 points
#: every level and frame (:func:`upsampling_profile_factors` 7 to 1.5 ms a call on the
#: heterogeneous scene's 16 k texels).
_ENERGY_POINTS = 1025


@functools.lru_cache(maxsize=16)
def _mean_profile_energy(material: SubEditProfiles):
    r"""Return the grid, the energy of the mean normalised profile up to each point, R_P.

    The energy :math:`\int_0^u \bar P(r)\,r\,dr` by the trapezoid rule on
    :data:`_ENERGY_POINTS` points (the halving radius it gives agrees with 8001 points to
    1e-5 of the range on the heterogeneous scene's material; the 257-point left sums this
    replaces were off by up to 4e-3); ``R_P`` is the median effective range, mm.
    """
    grid = np.linspace(0.0, 1.0, _ENERGY_POINTS)
    integrand = material.mean_normalized_profile(grid) * grid
    cumulative = np.concatenate([[0.0], np.cumsum(0.5 * (integrand[1:] + integrand[:-1])
                                                  * np.diff(grid))])
    return grid, cumulative, float(np.median(material.effective_scattering_range))


# ====================================================================== ground truth
def brute_force_exitance(samples: IrradianceSamples, buffer: SurfaceBuffer,
                         material: SubEditProfiles, *, mm_per_unit: float,
                         backend: str = "numba") -> np.ndarray:
    r"""Eq. 5 of Chen et al. 2012 by brute force: every sample to every valid pixel.

    :math:`B(x_o) = \sum_{x_i} \sqrt{P_{x_i}(r)P_{x_o}(r)}E(x_i)\Delta A_{x_i}` over all
    given samples (the finest level, unselected, for the ground truth) with the profile's
    full support :math:`r < r_s`. Cost: pixels x samples.

    Returns
    -------
    ndarray (H, W, 3)
    """
    height, width = buffer.shape
    exitance = np.zeros((height * width, 3))
    pixels = np.flatnonzero(buffer.valid.reshape(-1))
    if not len(pixels) or not len(samples):
        return exitance.reshape(height, width, 3)
    position = buffer.position.reshape(-1, 3)[pixels]
    texel_out = material.texel_index(buffer.uv.reshape(-1, 2)[pixels])
    if backend in ("numba", "cuda"):
        if backend == "cuda":
            from .splatting_cuda import gather_samples
        else:
            from .splatting_kernels import gather_samples

        gathered = np.zeros((len(pixels), 3))
        gather_samples(gathered, np.ascontiguousarray(position.T, dtype=np.float32),
                       texel_out.astype(np.int32), _segment_table(material),
                       np.float32(material.segments / (material.r_s / mm_per_unit)),
                       np.ascontiguousarray(samples.position.T, dtype=np.float32),
                       samples.texel.astype(np.int32),
                       np.ascontiguousarray(samples.flux.T, dtype=np.float32))
        exitance[pixels] = gathered * mm_per_unit**2
        return exitance.reshape(height, width, 3)
    table = material.flat_log_profile.astype(np.float32)
    step_inverse = material.segments / (material.r_s / mm_per_unit)
    per_chunk = max(1, PAIR_CHUNK // len(samples))
    for start in range(0, len(pixels), per_chunk):
        part = slice(start, start + per_chunk)
        offset = position[part][:, None, :] - samples.position[None, :, :]
        distance = np.sqrt(np.einsum("ijk,ijk->ij", offset, offset)).reshape(-1)
        texel_o = np.repeat(texel_out[part], len(samples))
        texel_i = np.tile(samples.texel, len(position[part]))
        value = _evaluate_pairs(table, step_inverse, material.segments, distance, texel_i,
                                texel_o)
        value = value.reshape(-1, len(samples), 3) * samples.flux[None, :, :]
        exitance[pixels[part]] = value.sum(axis=1) * mm_per_unit**2
    return exitance.reshape(height, width, 3)


# ====================================================================== one frame
@dataclass(frozen=True, eq=False)
class LightView:
    r"""An irradiance buffer with what the light delivers to it.

    ``flux`` (H, W, 3): :math:`E(x_i)\Delta A_{x_i}` (Eq. 5-6 of Chen et al. 2012);
    ``cosine`` (H, W): :math:`|n\cdot L|`.
    """

    buffer: SurfaceBuffer
    flux: np.ndarray
    cosine: np.ndarray


def light_view(buffer: SurfaceBuffer, to_light: np.ndarray, normal_irradiance: np.ndarray,
               eta: float) -> LightView:
    r"""Flux per irradiance-buffer pixel, Eq. 5-6 of Chen et al. 2012 for a delta light.

    :math:`E\,\Delta A = F_t(\eta, \cos\theta_i)\,E_\perp\,s^2`: the irradiance
    :math:`E = F_t E_\perp\cos\theta_i` times the pixel's area on the surface
    :math:`\Delta A = s^2/\cos\theta_i`, with :math:`s` the pixel's footprint across the ray
    and :math:`E_\perp` the irradiance on a surface facing the light (:math:`I/d^2` for a
    point light). The cosines cancel, so grazing pixels carry finite flux that
    :math:`F_t \to 0` removes.

    Computed per pixel by :func:`.splatting_kernels.light_flux` (rows in parallel;
    NaN cosines and footprints read as 0, infinite ones as the largest float64, as
    ``numpy.nan_to_num`` did here before), equal to the numpy formula to float64
    round-off (the dot product summed in index order).

    Parameters
    ----------
    buffer : SurfaceBuffer
        The light-view G-buffer.
    to_light : ndarray (H, W, 3) or (3,)
        Unit direction from each hit towards the light.
    normal_irradiance : ndarray (H, W, 3) or (3,)
        :math:`E_\perp` per RGB channel.
    eta : float
        Relative index of refraction.
    """
    from .splatting_kernels import light_flux

    shape = buffer.valid.shape + (3,)
    # broadcast views: the kernel reads them per pixel, nothing is copied
    flux, cosine = light_flux(
        buffer.position, buffer.normal, buffer.valid, buffer.footprint,
        np.broadcast_to(np.asarray(to_light, np.float64), shape),
        np.broadcast_to(np.asarray(normal_irradiance, np.float64), shape), float(eta), False)
    return LightView(buffer, flux, cosine)


@functools.lru_cache(maxsize=16)
def _table_for(material: SubEditProfiles, epsilon: float) -> RenderingRadiusTable:
    return minimal_rendering_radius_table(material.mean_normalized_profile, epsilon)


def rendering_radius_table(material: SubEditProfiles, epsilon: float = 0.001
                           ) -> RenderingRadiusTable:
    """Eq. 14's lookup table for ``material``'s mean profile, computed once per material."""
    return _table_for(material, float(epsilon))


def splat_frame(camera_buffer: SurfaceBuffer, camera: CameraModel, lights: list[LightView],
                material: SubEditProfiles, *, mm_per_unit: float, sphere_radius: float,
                knobs: dict | None = None, log: StageLog | None = None) -> np.ndarray:
    r"""Run steps 2-4 of Chen et al. 2012 on given buffers: radiance by Eq. 5-17 and Eq. 7.

    Parameters
    ----------
    camera_buffer : SurfaceBuffer
        The splatting buffer (level 0), the camera's G-buffer.
    camera : CameraModel
        Its projection.
    lights : list of LightView
        One irradiance buffer per light.
    material : SubEditProfiles
        The object's material.
    mm_per_unit : float
        Millimetres per scene unit.
    sphere_radius : float
        The object's bounding-sphere radius, scene units (z0 and R_w derive from it).
    knobs : dict, optional
        Overrides of :data:`DEFAULT_KNOBS`.
    log : StageLog, optional
        Receives seconds per stage and counts (samples, pairs per level).

    Returns
    -------
    ndarray (H, W, 3)
        Outgoing radiance, :math:`F_t(\\eta, \\cos\\theta_o) B / \\pi` (Eq. 7).
    """
    knobs = {**DEFAULT_KNOBS, **(knobs or {})}
    log = log if log is not None else StageLog()
    levels = max(1, int(knobs["levels"]))
    clock = time.perf_counter()

    def lap(stage):
        nonlocal clock
        now = time.perf_counter()
        log.seconds[stage] = log.seconds.get(stage, 0.0) + now - clock
        clock = now

    splat_levels = levels if knobs["multiresolution"] else 1
    pyramid = median_depth_mipmap(camera_buffer, splat_levels)
    texels = [material.texel_index(level.uv) for level in pyramid]
    ranges_mm = material.effective_scattering_range.reshape(-1)
    lap("splatting buffer mipmap")
    pyramids = [irradiance_mipmap(view.buffer, view.flux, view.cosine,
                                  levels if knobs["adaptive"] else 1) for view in lights]

    selector = SampleSelector(pyramids, material, mm_per_unit=mm_per_unit,
                              z0=knobs["z0"] * sphere_radius, alpha=knobs["alpha"],
                              adaptive=knobs["adaptive"], sampling=knobs["sampling_range"])
    ids = selector.select()
    samples = selector.samples(ids)
    log.notes["samples"] = len(samples)
    log.notes["samples per level"] = np.bincount(samples.level, minlength=levels).tolist()
    per_level = knobs["level_sampling"] > 0 and knobs["adaptive"] and splat_levels > 1
    if per_level:
        level_ids = [ids] + [selector.select(selector.level_masks(
            camera, k, knobs["level_sampling"])) for k in range(1, splat_levels)]
        # a sample's ranges depend on its texel alone: computed once for all the levels
        chosen = np.zeros(selector.size, dtype=bool)
        for level_set in level_ids:
            chosen[level_set] = True
        union = np.flatnonzero(chosen)
        rank = np.cumsum(chosen) - 1
        level_samples = [selector.samples(level_set) for level_set in level_ids]
        log.notes["samples per splatting level"] = [len(s) for s in level_samples]
    else:
        level_samples = [samples] * splat_levels
    lap("irradiance mipmap and selection")
    table = rendering_radius_table(material, knobs["epsilon"])
    bounds = effective_rendering_ranges(selector.samples(union) if per_level else samples,
                                        material, table, camera, mm_per_unit=mm_per_unit,
                                        levels=splat_levels,
                                        multiresolution=knobs["multiresolution"])
    level_bounds = ([np.take(bounds, rank[level_set], axis=0) for level_set in level_ids]
                    if per_level else [bounds] * splat_levels)
    lap("effective rendering ranges")
    exitance = []
    pairs = []
    in_range = []
    for k, level in enumerate(pyramid):
        stats = {}
        exitance.append(splat_level(level_samples[k], level_bounds[k][:, k],
                                    level_bounds[k][:, k + 1],
                                    level, texels[k], material, camera,
                                    mm_per_unit=mm_per_unit, backend=knobs["backend"],
                                    stats=stats))
        pairs.append(stats.get("pairs", 0))
        in_range.append(stats.get("pairs in range"))
        lap(f"splat level {k}")
    log.notes["pairs per level"] = pairs
    log.notes["pairs in range per level"] = in_range
    diameter = 2.0 * sphere_radius
    accumulated = exitance[-1]
    for k in range(len(pyramid) - 2, -1, -1):
        factors = None
        if knobs["profile_upsampling"] and len(samples):
            factors = upsampling_profile_factors(material, float(np.median(
                level_bounds[0][:, k + 1] / np.maximum(level_bounds[0][:, -1], 1e-300))))
            accumulated = accumulated / factors[texels[k + 1]]
        upsampled = bilateral_upsample(
            accumulated, pyramid[k + 1], ranges_mm[texels[k + 1]] / mm_per_unit,
            pyramid[k], ranges_mm[texels[k]] / mm_per_unit, scene_diameter=diameter,
            lambda_z=knobs["lambda_z"], lambda_m=knobs["lambda_m"])
        if factors is None:
            accumulated = exitance[k] + upsampled
        else:
            from .splatting_kernels import add_scaled_by_texel

            accumulated = add_scaled_by_texel(exitance[k], upsampled, factors, texels[k])
    lap("accumulation")
    radiance = _exitant_radiance(accumulated, camera_buffer, camera, material.eta)
    lap("radiance")
    return radiance


def gather_frame(camera_buffer: SurfaceBuffer, camera: CameraModel, lights: list[LightView],
                 material: SubEditProfiles, *, mm_per_unit: float) -> np.ndarray:
    """Render the ground truth of :func:`splat_frame`: Eq. 5 over every finest-level sample.

    Same buffers, same SubEdit material, no selection, no truncation at the effective
    range, no multiresolution (:func:`brute_force_exitance`), then Eq. 7.

    Returns
    -------
    ndarray (H, W, 3)
        Outgoing radiance.
    """
    parts = []
    for view in lights:
        rows, cols = np.nonzero(view.buffer.valid)
        parts.append(IrradianceSamples(view.buffer.position[rows, cols],
                                       material.texel_index(view.buffer.uv[rows, cols]),
                                       view.flux[rows, cols], np.zeros(len(rows), np.int64)))
    exitance = brute_force_exitance(IrradianceSamples.concatenate(parts), camera_buffer,
                                    material, mm_per_unit=mm_per_unit)
    return _exitant_radiance(exitance, camera_buffer, camera, material.eta)


def _exitant_radiance(exitance, buffer: SurfaceBuffer, camera: CameraModel, eta: float):
    r"""Eq. 7 of Chen et al. 2012: :math:`L = F_t(\omega_o) B / \pi` at valid pixels.

    One compiled pass over the pixels (:func:`.splatting_kernels.exitant_radiance`): about
    8 CPU ms for the heterogeneous scene at 800 x 600 on one thread, where numpy on the
    valid pixels took about 30 (medians of 15 calls, four runs, load average about 1).
    """
    from .splatting_kernels import exitant_radiance

    return exitant_radiance(np.asarray(exitance, np.float64), buffer.position, buffer.normal,
                            buffer.valid, np.asarray(camera.origin, np.float64), float(eta))


def as_subedit(material, mesh=None) -> SubEditProfiles:
    """Return the SubEdit profiles of a material.

    Itself, a converted :class:`Dipole`, or the texture derived from a solid medium on
    ``mesh`` (:mod:`.solid_inputs`).
    """
    if isinstance(material, SubEditProfiles):
        return material
    if isinstance(material, Dipole):
        return _converted(material)
    if isinstance(material, SolidMedium):
        if mesh is None:
            raise InputError("a solid medium becomes a SubEdit texture on its object's mesh",
                             field="material", value=material.name)
        return subedit_from_solid(material, mesh).material
    raise InputError("the splatting method renders Dipole, SubEdit or solid materials",
                     field="material", value=type(material).__name__)


_CONVERTED: dict[str, SubEditProfiles] = {}


def _converted(material: Dipole) -> SubEditProfiles:
    key = content_hash(material)
    if key not in _CONVERTED:
        _CONVERTED[key] = subedit_from_dipole(material).profiles
    return _CONVERTED[key]


# ====================================================================== scenes
_LIGHTS = (PointLight, DirectionalLight)
#: Widest irradiance-buffer cone for a point light (degrees): a light inside the object's
#: bounding sphere sees only this cone of it.
MAX_LIGHT_FOV = 160.0
#: Margin of the irradiance buffer around the bounding sphere (no hit falls on its edge).
VIEW_MARGIN = 1.02


#: How an InputError for a scene the method cannot render begins (the reason follows).
_REFUSAL = "the splatting method cannot render this scene"


def _translucent_objects(scene) -> list[int]:
    return [index for index, item in enumerate(scene.objects)
            if isinstance(item.material, (Dipole, SubEditProfiles, SolidMedium))]


def applies_to(scene) -> str | None:
    """None when the method renders ``scene``; otherwise why not.

    It needs a translucent object (Dipole, SubEdit or solid material) and point or directional
    lights only (Chen et al. 2012, Sect. 6: other lights are future work there).
    """
    if not _translucent_objects(scene):
        return "no translucent object (Dipole, SubEdit or solid material) in the scene"
    others = sorted({type(light).__name__ for light in scene.lights
                     if not isinstance(light, _LIGHTS)})
    if others:
        return (f"the method handles point and directional lights only; the scene has "
                f"{', '.join(others)}")
    if not scene.lights:
        return "the scene has no light"
    return None


def _check_knobs(knobs: dict) -> dict:
    merged = with_defaults(knobs, DEFAULT_KNOBS)
    for name in ("irradiance_resolution", "levels"):
        value = merged[name]
        if isinstance(value, bool) or not isinstance(value, int | float | np.number) \
                or not np.isfinite(value) or int(value) != value or not 1 <= value <= 8192:
            raise InputError("must be an integer in [1, 8192]", field=name, value=value)
        merged[name] = int(value)
    if merged["levels"] > 12:
        raise InputError("must be <= 12", field="levels", value=merged["levels"])
    for name in ("z0", "alpha", "epsilon", "lambda_z", "lambda_m", "level_sampling"):
        value = merged[name]
        value = float(value) if isinstance(value, int | float | np.number) \
            and not isinstance(value, bool) else math.nan
        if not np.isfinite(value) or value < 0 or (name == "epsilon" and value == 0):
            raise InputError("must be a finite number >= 0 (epsilon > 0)", field=name,
                             value=merged[name])
        merged[name] = value
    for name, choices in (("backend", BACKENDS), ("sampling_range", SAMPLING_RANGES),
                          ("buffers", ("raster", "mitsuba"))):
        if merged[name] not in choices:
            raise InputError(f"must be one of {', '.join(map(repr, choices))}", field=name,
                             value=merged[name])
    merged["multiresolution"] = bool(merged["multiresolution"])
    merged["profile_upsampling"] = bool(merged["profile_upsampling"])
    merged["adaptive"] = bool(merged["adaptive"])
    return merged


def precompute(scene, **knobs) -> SplattingState:
    """Validate the scene and knobs; nothing geometric is precomputed (Chen et al. 2012).

    The method needs no precomputation: every buffer is rebuilt each frame from the current
    mesh, so a deforming mesh costs nothing extra and nothing can go stale. The only
    tables (the SubEdit conversion of a dipole, Eq. 14's lookup table and the mean
    profile's energy of the profile upsampling) depend on the material alone and are built
    on first use.
    """
    refuse_inapplicable(scene, applies_to(scene), _REFUSAL)
    return SplattingState(scene, _check_knobs(knobs))


def _surface_buffer(gbuffer_view, object_index: int, uv_values, footprint) -> SurfaceBuffer:
    valid = gbuffer_view.hit & (gbuffer_view.object_id == object_index)
    uv = gbuffer_view.interpolate(object_index, uv_values) if uv_values is not None else \
        np.zeros(valid.shape + (2,))
    depth = np.where(valid, gbuffer_view.depth, 0.0)
    return SurfaceBuffer(gbuffer_view.position, gbuffer_view.normal, uv, depth, valid,
                         np.where(valid, footprint, 0.0))


def _perspective_footprint(gbuffer_view) -> np.ndarray:
    """Pixel cross-section side at the hit: d (2 tan(fov/2) / W) cos^1.5 of the off-axis angle."""
    camera = gbuffer_view.camera
    pixel = 2.0 * math.tan(math.radians(camera.fov) / 2.0) / camera.width
    cosine = np.clip(-gbuffer_view.view_direction @ camera.forward, 0.0, 1.0)
    depth = np.where(gbuffer_view.hit, gbuffer_view.depth, 0.0)
    return depth * pixel * cosine**1.5


@dataclass(frozen=True, eq=False)
class RasterView:
    r"""What :func:`rasterize_view` saw: per pixel the first triangle of the scene.

    ``triangle`` (H, W) indexes the scene's faces, objects in order (-1: nothing);
    ``barycentric`` (H, W, 2) weighs its second and third vertices; ``depth`` (H, W) is
    the distance along the ray from the eye (perspective) or image plane (orthographic);
    ``footprint`` (H, W) the side of the pixel's cross-section at that depth, scene units.
    """

    triangle: np.ndarray
    barycentric: np.ndarray
    depth: np.ndarray
    footprint: np.ndarray
    face_offsets: np.ndarray

    def surface(self, scene, object_index: int) -> SurfaceBuffer:
        """Return one object's :class:`SurfaceBuffer` (invalid where another is in front)."""
        from .splatting_kernels import interpolate_surface

        mesh = scene.objects[object_index].mesh
        uv = mesh.uv if mesh.uv is not None else np.zeros((0, 2))
        valid, position, normal, uv, depth, footprint = interpolate_surface(
            self.triangle, self.barycentric, self.depth, self.footprint,
            int(self.face_offsets[object_index]), int(self.face_offsets[object_index + 1]),
            mesh.vertices, mesh.faces, mesh.normals, np.asarray(uv, dtype=np.float64))
        return SurfaceBuffer(position, normal, uv, depth, valid, footprint)


def rasterize_view(scene, *, camera=None, direction=None, size=None, centre=None,
                   extent=None) -> RasterView:
    """Render the G-buffer of a perspective ``camera`` or an orthographic light view.

    Buffer generation of Chen et al. 2012 (Sect. 4) by rasterisation, as the paper does:
    :func:`.splatting_kernels.rasterize` tests each pixel's own ray against the triangles
    of its projected bounding box, so the buffers are those of the ray queries of
    :func:`translucent.scenes.raycast.gbuffer` (perspective) and
    :func:`~translucent.scenes.raycast.gbuffer_orthographic` (``direction``, a square of
    ``size`` pixels and half-width ``extent`` around ``centre``, scene units) up to
    rounding, in milliseconds instead of seconds. The perspective footprint is
    :func:`.splatting_kernels.perspective_footprint`, computed at hit pixels only.
    """
    # the ray-cast G-buffers' own image frames, so that both kinds of buffer agree
    from ..scenes.raycast import NEAR_CLIP, camera_frame, default_up
    from .splatting_kernels import perspective_footprint, rasterize

    meshes = [item.mesh for item in scene.objects]
    vertex_offsets = np.cumsum([0] + [len(m.vertices) for m in meshes])
    face_offsets = np.cumsum([0] + [len(m.faces) for m in meshes])
    vertices = np.concatenate([m.vertices for m in meshes])
    faces = np.concatenate([m.faces + offset
                            for m, offset in zip(meshes, vertex_offsets[:-1], strict=True)])
    if camera is not None:
        forward, left, up = camera_frame(camera)
        tan_x = math.tan(math.radians(camera.fov) / 2.0)
        tan_y = tan_x * camera.height / camera.width
        width, height, eye, orthographic = camera.width, camera.height, camera.origin, False
    else:
        forward = np.asarray(direction, dtype=np.float64)
        forward = forward / np.linalg.norm(forward)
        left = np.cross(default_up(forward), forward)
        left /= np.linalg.norm(left)
        up = np.cross(forward, left)
        tan_x = tan_y = float(extent)
        width = height = int(size)
        lower, upper = vertices.min(axis=0), vertices.max(axis=0)
        behind = float(np.max(np.linalg.norm(vertices - centre, axis=1))) + \
            float(np.linalg.norm(centre - np.clip(centre, lower, upper))) + 1.0
        eye, orthographic = centre - forward * behind, True
    triangle, barycentric, depth = rasterize(
        vertices, faces, np.asarray(eye, np.float64), forward, left, up, tan_x, tan_y,
        width, height, NEAR_CLIP, orthographic)
    if orthographic:
        footprint = np.full((height, width), 2.0 * tan_x / width)
    else:
        footprint = perspective_footprint(triangle, depth, tan_x, tan_y)
    return RasterView(triangle, barycentric, depth, footprint, face_offsets)


@dataclass
class SplattingState:
    """What :func:`precompute` returns: the scene and knobs (no geometric state).

    ``render(lights=None, material=None, scene=None)`` renders a frame; ``scene`` replaces
    the geometry (a deformed mesh) without any precomputation.
    """

    scene: object
    knobs: dict
    log: StageLog = field(default_factory=StageLog)

    def render_ground_truth(self, lights=None, material=None, *, scene=None) -> Image:
        """Render the brute-force ground truth of :meth:`render` (see :func:`gather_frame`).

        Same buffers and material; cost pixels x irradiance samples, so keep both small.
        """
        return self.render(lights, material, scene=scene, _ground_truth=True)

    def render(self, lights=None, material=None, *, scene=None, _ground_truth=False) -> Image:
        """Render one frame with Chen et al. 2012's four steps; see the module docstring.

        Parameters
        ----------
        lights : sequence of PointLight / DirectionalLight, optional
            Replace the scene's lights.
        material : SubEditProfiles or Dipole, optional
            Replace the material of every translucent object.
        scene : Scene, optional
            Render this scene (for example with a deformed mesh) instead of the one given
            to :func:`precompute`.
        """
        scene = self.scene if scene is None else scene
        if lights is not None:
            scene = scene.with_lights(lights)
        if material is not None:
            for index in _translucent_objects(scene):
                scene = scene.with_material(scene.objects[index].name, material)
        refuse_inapplicable(scene, applies_to(scene), _REFUSAL)
        log = StageLog()
        start = time.perf_counter()
        camera_view = self._camera_view(scene)
        camera = CameraModel.from_camera(scene.camera)
        log.seconds["buffer generation"] = time.perf_counter() - start
        radiance = np.zeros((scene.camera.height, scene.camera.width, 3))
        for index in _translucent_objects(scene):
            radiance += self._render_object(scene, index, camera_view, camera, log,
                                            _ground_truth)
        seconds = time.perf_counter() - start
        self.log = log
        producer = "splatting ground truth" if _ground_truth else "splatting"
        return Image(radiance.astype(np.float32), metadata={
            "producer": producer, "knobs": self.knobs, "seconds": seconds,
            "stage_seconds": log.seconds, "notes": log.notes, "skipped": log.skipped})

    def buffers(self, lights=None, *, scene=None):
        """Return the buffers of a frame: the camera's :class:`SurfaceBuffer` and light views.

        For the first translucent object; what :meth:`render` splats, exposed so that a
        benchmark can evaluate the ground truth on a subset of the same pixels.

        Returns
        -------
        tuple
            ``(camera_buffer, camera_model, light_views, material, sphere_radius)``.
        """
        scene = self.scene if scene is None else scene
        if lights is not None:
            scene = scene.with_lights(lights)
        index = _translucent_objects(scene)[0]
        camera_buffer, views, material, radius = self._object_buffers(
            scene, index, self._camera_view(scene))
        return camera_buffer, CameraModel.from_camera(scene.camera), views, material, radius

    def _camera_view(self, scene):
        """Return the camera's buffers: a :class:`RasterView` or a ray-cast G-buffer."""
        if self.knobs["buffers"] == "raster":
            return rasterize_view(scene, camera=scene.camera)
        from ..scenes.raycast import gbuffer

        return gbuffer(scene)

    def _object_buffers(self, scene, index, camera_view):
        item = scene.objects[index]
        material = as_subedit(item.material, item.mesh)
        mesh = item.mesh
        if mesh.uv is None and not material.is_homogeneous:
            raise InputError("a textured SubEdit material needs a mesh with uv coordinates",
                             field=f"objects[{index}].mesh.uv", value=None)
        centre = 0.5 * (mesh.vertices.min(axis=0) + mesh.vertices.max(axis=0))
        radius = float(np.max(np.linalg.norm(mesh.vertices - centre, axis=1)))
        if isinstance(camera_view, RasterView):
            camera_buffer = camera_view.surface(scene, index)
        else:
            camera_buffer = _surface_buffer(camera_view, index, mesh.uv,
                                            _perspective_footprint(camera_view))
        views = [self._light_view(scene, index, light, centre, radius, material.eta)
                 for light in scene.lights]
        return camera_buffer, views, material, radius

    def _render_object(self, scene, index, camera_view, camera, log, ground_truth):
        start = time.perf_counter()
        camera_buffer, views, material, radius = self._object_buffers(scene, index,
                                                                      camera_view)
        log.seconds["buffer generation"] += time.perf_counter() - start
        item = scene.objects[index]
        if isinstance(item.material, SolidMedium):
            log.notes.setdefault("solid medium", {})[item.name] = \
                subedit_from_solid(item.material, item.mesh).note()
        if not camera_buffer.valid.any():
            log.skip(f"object '{scene.objects[index].name}' is out of view: nothing to splat")
            return np.zeros(camera_buffer.shape + (3,))
        if ground_truth:
            return gather_frame(camera_buffer, camera, views, material,
                                mm_per_unit=scene.mm_per_unit)
        return splat_frame(camera_buffer, camera, views, material,
                           mm_per_unit=scene.mm_per_unit, sphere_radius=radius,
                           knobs=self.knobs, log=log)

    def _light_view(self, scene, index, light, centre, radius, eta) -> LightView:
        from ..scenes.raycast import default_up, gbuffer_from_point, gbuffer_orthographic
        from ..scenes.scene import Camera

        size = self.knobs["irradiance_resolution"]
        raster = self.knobs["buffers"] == "raster"
        uv = scene.objects[index].mesh.uv
        if isinstance(light, PointLight):
            towards = centre - light.position
            distance = float(np.linalg.norm(towards))
            if distance <= radius * VIEW_MARGIN:
                fov = MAX_LIGHT_FOV
            else:
                fov = min(MAX_LIGHT_FOV,
                          2.0 * math.degrees(math.asin(radius * VIEW_MARGIN / distance)))
            if distance == 0:
                towards = np.array([0.0, 0.0, -1.0])
            towards = towards / np.linalg.norm(towards)
            if raster:
                buffer = rasterize_view(scene, camera=Camera(
                    light.position, light.position + towards, default_up(towards), fov, size,
                    size)).surface(scene, index)
            else:
                view = gbuffer_from_point(scene, light.position, towards, fov, size)
                buffer = _surface_buffer(view, index, uv, _perspective_footprint(view))
            from .splatting_kernels import light_flux

            flux, cosine = light_flux(
                buffer.position, buffer.normal, buffer.valid, buffer.footprint,
                np.reshape(np.asarray(light.position, np.float64), (1, 1, 3)),
                np.reshape(np.asarray(light.intensity, np.float64), (1, 1, 3)), float(eta),
                True)
            return LightView(buffer, flux, cosine)
        else:
            if raster:
                buffer = rasterize_view(scene, direction=light.direction, size=size,
                                        centre=centre, extent=radius * VIEW_MARGIN
                                        ).surface(scene, index)
            else:
                view = gbuffer_orthographic(scene, light.direction, size, center=centre,
                                            extent=radius * VIEW_MARGIN)
                footprint = np.full(view.shape, math.sqrt(view.pixel_area))
                buffer = _surface_buffer(view, index, uv, footprint)
            to_light = -light.direction
            irradiance = light.irradiance
        return light_view(buffer, to_light, irradiance, eta)


# ====================================================================== command line
def add_approx_arguments(parser) -> None:
    """Options of ``translucent approx splatting SCENE``."""
    parser.add_argument("--irradiance-resolution", type=int,
                        default=DEFAULT_KNOBS["irradiance_resolution"],
                        help="irradiance buffer side in pixels (default 512)")
    parser.add_argument("--levels", type=int, default=DEFAULT_KNOBS["levels"],
                        help="mipmap levels of both buffers (default 3)")
    parser.add_argument("--no-multiresolution", action="store_true",
                        help="splat everything at full resolution (ablation)")
    parser.add_argument("--no-adaptive", action="store_true",
                        help="use every irradiance sample of the finest level (ablation)")
    parser.add_argument("--backend", choices=BACKENDS,
                        default=DEFAULT_KNOBS["backend"], help="splatting kernel")
    parser.add_argument("--level-sampling", type=float,
                        default=DEFAULT_KNOBS["level_sampling"],
                        help="coarse splatting levels take irradiance samples as sparse as "
                             "this many of their pixels (default 0: the paper's one "
                             "selection for every level; on the heterogeneous scene "
                             "--levels 5 --level-sampling 1.5 renders 2.2x faster at the "
                             "same error against brute force: docs/splatting.md)")
    parser.add_argument("--epsilon", type=float, default=DEFAULT_KNOBS["epsilon"],
                        help="error tolerance of Eq. 14, which sets where each coarser "
                             "level takes over (default 0.001; smaller is slower and closer "
                             "to splatting everything at full resolution)")
    parser.add_argument("--sampling-range", choices=SAMPLING_RANGES,
                        default=DEFAULT_KNOBS["sampling_range"],
                        help="which RGB channel's scattering range sets Eq. 11's sampling "
                             "rate (default shortest: every channel sampled as alpha asks)")
    parser.add_argument("--profile-upsampling", action=argparse.BooleanOptionalAction,
                        default=DEFAULT_KNOBS["profile_upsampling"],
                        help="upsample coarse levels divided by each texel's profile factor "
                             "(upsampling_profile_factors; default on; --no-profile-upsampling"
                             ": Eq. 17 as published)")
    parser.add_argument("--material", default=None,
                        help="replace the translucent material: a built-in SubEdit name "
                             "(checker, veined_marble, wax_gradient) or a SubEdit .npz file")


def approx(scene, args) -> Image:
    """Render ``scene`` with the options parsed by :func:`add_approx_arguments`."""
    from ..materials.subedit import BUILTIN_SUBEDIT, builtin_subedit, load_subedit

    knobs = {"irradiance_resolution": args.irradiance_resolution, "levels": args.levels,
             "multiresolution": not args.no_multiresolution, "adaptive": not args.no_adaptive,
             "backend": args.backend, "level_sampling": args.level_sampling,
             "profile_upsampling": args.profile_upsampling, "epsilon": args.epsilon,
             "sampling_range": args.sampling_range}
    material = None
    if args.material:
        material = builtin_subedit(args.material) if args.material in BUILTIN_SUBEDIT \
            else load_subedit(args.material)
    return precompute(scene, **knobs).render(material=material)
