"""Surface buffers and the irradiance mipmap (Chen et al. 2012, Sect. 4-5)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


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
    from .buffer_kernels import irradiance_level

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
    from .buffer_kernels import median_depth_level

    pyramid = [buffer]
    for _ in range(1, levels):
        level = pyramid[-1]
        pyramid.append(SurfaceBuffer(*median_depth_level(
            level.position, level.normal, level.uv, level.depth, level.valid,
            level.footprint)))
    return pyramid


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
        from ...scenes.gbuffer import camera_frame

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
