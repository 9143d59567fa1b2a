"""One frame: light views, splatting and gathering (Chen et al. 2012, Sect. 5)."""

from __future__ import annotations

import functools
import time
from dataclasses import dataclass

import numpy as np

from ...cache import content_hash
from ...errors import InputError
from ...materials.homogeneous import Dipole
from ...materials.solid import SolidMedium
from ...materials.subedit import SubEditProfiles, subedit_from_dipole, subedit_from_profile
from ..base import StageLog
from ..knobs import DEFAULT_PROFILE, radial_profile
from ..solid_inputs import subedit_from_solid
from .accumulation import bilateral_upsample, upsampling_profile_factors
from .buffers import CameraModel, SurfaceBuffer, irradiance_mipmap, median_depth_mipmap
from .ground_truth import brute_force_exitance
from .knobs import DEFAULT_KNOBS
from .radius_table import RenderingRadiusTable, minimal_rendering_radius_table
from .selection import IrradianceSamples, SampleSelector
from .splats import effective_rendering_ranges, splat_level


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

    Computed per pixel by :func:`.buffer_kernels.light_flux` (rows in parallel;
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
    from .buffer_kernels import light_flux

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
            from .buffer_kernels import add_scaled_by_texel

            accumulated = add_scaled_by_texel(exitance[k], upsampled, factors, texels[k])
    lap("accumulation")
    radiance = exitant_radiance_of(accumulated, camera_buffer, camera, material.eta)
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
    return exitant_radiance_of(exitance, camera_buffer, camera, material.eta)


def exitant_radiance_of(exitance, buffer: SurfaceBuffer, camera: CameraModel, eta: float):
    r"""Eq. 7 of Chen et al. 2012: :math:`L = F_t(\omega_o) B / \pi` at valid pixels.

    One compiled pass over the pixels
    (:func:`.buffer_kernels.exitant_radiance`), no whole-image temporaries
    (docs/splatting.md gives its time against numpy's).
    """
    from .buffer_kernels import exitant_radiance

    return exitant_radiance(np.asarray(exitance, np.float64), buffer.position, buffer.normal,
                            buffer.valid, np.asarray(camera.origin, np.float64), float(eta))


def as_subedit(material, mesh=None, profile: str = DEFAULT_PROFILE) -> SubEditProfiles:
    """Return the SubEdit profiles of a material.

    Itself, a converted :class:`Dipole` (its radial profile ``profile``, a value of the
    knob, :func:`~translucent.fast.knobs.radial_profile`; the classical dipole by default),
    or the texture derived from a solid medium on ``mesh`` (:mod:`.solid_inputs`, each
    medium's radial profile ``profile``).
    """
    if isinstance(material, SubEditProfiles):
        return material
    if isinstance(material, Dipole):
        return _converted(material, profile)
    if isinstance(material, SolidMedium):
        if mesh is None:
            raise InputError("a solid medium becomes a SubEdit texture on its object's mesh",
                             field="material", value=material.name)
        return subedit_from_solid(material, mesh, profile=profile).material
    raise InputError("the splatting method renders Dipole, SubEdit or solid materials",
                     field="material", value=type(material).__name__)


_CONVERTED: dict[str, SubEditProfiles] = {}


def _converted(material: Dipole, profile: str = DEFAULT_PROFILE) -> SubEditProfiles:
    key = content_hash(material, profile)
    if key not in _CONVERTED:
        if profile == DEFAULT_PROFILE:
            conversion = subedit_from_dipole(material)
        else:
            # every registered profile is per unit power entering, as the dipole's R_d:
            # F_t at entry and exit stay Eq. 5-7's
            conversion = subedit_from_profile(radial_profile(profile, material), material.eta,
                                              name=material.name)
        _CONVERTED[key] = conversion.profiles
    return _CONVERTED[key]


