r"""Solid heterogeneous media as Mitsuba 3 ``heterogeneous`` media: the volumetric truth.

A :class:`~translucent.materials.solid.SolidMedium` becomes a ``heterogeneous`` medium
whose ``sigma_t`` and ``albedo`` are ``gridvolume`` textures holding the material's own
voxel grid, with ``filter_type = "nearest"`` (a point takes the value of the voxel it lies
in, the lookup of :meth:`SolidMedium.coefficients_at`) and ``to_world`` mapping the unit
cube onto the material's ``bounds``. Mitsuba samples free paths by delta tracking against
the grid's largest extinction (a majorant), so the estimator is unbiased for any field.

Coefficients are per mm in the material and per scene unit here: times
``scene.mm_per_unit`` (as :func:`~translucent.reference.mitsuba_scene.dipole_medium`).
The boundary is ``null`` at eta 1 (index-matched: delta lights reach the medium) and a
``dielectric`` otherwise, whose delta lights are replaced by emitters of finite size as
for a homogeneous medium. A chromatic field is rendered one channel at a time (each
channel's grid grey): Mitsuba's delta tracking of an RGB medium weights two channels by
ratios of extinctions, whose rare large values dominate the variance.
"""

from __future__ import annotations

import numpy as np

from ..backend import mitsuba
from ..materials.solid import SolidMedium
from .mitsuba_scene import ConversionContext, MaterialParts, register_material_converter

__all__ = ["solid_medium_dict"]


def _grid_volume(values: np.ndarray, solid: SolidMedium) -> dict:
    mi = mitsuba()
    low, high = solid.bounds
    to_world = mi.ScalarTransform4f().translate(low.tolist()).scale((high - low).tolist())
    return {"type": "gridvolume", "grid": mi.VolumeGrid(np.ascontiguousarray(values,
                                                                             np.float32)),
            "filter_type": "nearest", "to_world": to_world}


def _channels(values: np.ndarray, channel: int | None) -> np.ndarray:
    """Return the grid's RGB, or one channel repeated three times (a per-channel render)."""
    if channel is None:
        return values
    return np.repeat(values[..., channel:channel + 1], 3, axis=-1)


def solid_medium_dict(solid: SolidMedium, context: ConversionContext) -> dict:
    r"""Return the ``heterogeneous`` medium of ``solid`` per scene unit.

    ``sigma_t`` holds :math:`\sigma_t / \max\sigma_t` and ``scale``
    :math:`\max\sigma_t \cdot` ``mm_per_unit``, so that the grid's largest value is 1 and
    Mitsuba's majorant is exactly the largest extinction.
    """
    sigma_t = _channels(solid.sigma_t, context.channel)
    albedo = _channels(solid.albedo, context.channel)
    peak = float(sigma_t.max())
    return {"type": "heterogeneous", "sigma_t": _grid_volume(sigma_t / peak, solid),
            "albedo": _grid_volume(albedo, solid), "scale": peak * context.scene.mm_per_unit,
            "phase": {"type": "isotropic"}}


def _convert_solid(solid: SolidMedium, context: ConversionContext) -> MaterialParts:
    medium = solid_medium_dict(solid, context)
    albedo = _channels(solid.albedo, context.channel)
    sigma_t = _channels(solid.sigma_t, context.channel)
    chromatic = bool(np.any(sigma_t.max(axis=-1) > sigma_t.min(axis=-1)))
    max_albedo = float(albedo.max())
    description = ("heterogeneous medium, nearest gridvolume: "
                   f"{solid.describe(context.frame_scale)}")
    # delta tracking samples one channel's free paths against the RGB majorant and weights
    # the others by ratios of extinctions: rare huge weights (docs/references.md); a grey
    # render per channel has none
    boundary, blocks = (({"type": "null"}, False) if solid.eta == 1.0 else
                        ({"type": "dielectric", "int_ior": solid.eta, "ext_ior": 1.0}, True))
    return MaterialParts(boundary, medium, blocks, max_albedo, chromatic, description,
                         prefers_per_channel=chromatic)


register_material_converter(SolidMedium, _convert_solid)
