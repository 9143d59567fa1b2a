"""Adaptive irradiance sample selection (Chen et al. 2012, Eq. 10-11)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ...errors import InputError
from ...image import LUMINANCE_WEIGHTS
from ...materials.subedit import SubEditProfiles
from .buffers import CameraModel, IrradianceLevel
from .knobs import SAMPLING_RANGES


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


