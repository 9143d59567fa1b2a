"""Voxels a closed or open surface passes through, the start of every voxel grid of an object.

Shared by the optical distances of translucent radiosity
(:mod:`translucent.fast.radiosity.optical_distance`) and the diffusion grid of an object's
own shape (:mod:`translucent.scenes.diffusion_grid`). Lengths in the caller's unit (mm
throughout the suite's callers).
"""

from __future__ import annotations

import numpy as np

from ..errors import InputError

__all__ = ["SURFACE_POINTS_PER_VOXEL", "subdivision_barycentrics", "surface_voxels"]

#: Surface points per voxel edge when the surface is voxelised: spacing a third of a voxel
#: leaves no 6-connected gap for the fill to leak through.
SURFACE_POINTS_PER_VOXEL = 3


def subdivision_barycentrics(m: int) -> np.ndarray:
    """Centroids of the m^2 equal-area sub-triangles of a triangle split m times per edge.

    The midpoint rule on them integrates a smooth function over the triangle with weights
    ``area / m^2`` each; ``m = 1`` is the centroid alone. Used for the distance-dependent
    sampling of the scattering factors (Sheng et al. 2014, Sect. 5.2).

    Returns
    -------
    ndarray, shape (m*m, 3)
        Barycentric coordinates (rows sum to 1).
    """
    if int(m) != m or m < 1:
        raise InputError("must be an integer >= 1", field="m", value=m)
    m = int(m)
    a, b = np.meshgrid(np.arange(m), np.arange(m), indexing="ij")
    up = (a + b) <= m - 1
    down = (a + b) <= m - 2
    first = np.concatenate([(a[up] + 1 / 3) / m, (a[down] + 2 / 3) / m])
    second = np.concatenate([(b[up] + 1 / 3) / m, (b[down] + 2 / 3) / m])
    return np.stack([1.0 - first - second, first, second], axis=1)



def surface_voxels(triangles, voxel_size: float) -> tuple[np.ndarray, np.ndarray]:
    """Mark the voxels a surface passes through (dense point samples of every triangle).

    Parameters
    ----------
    triangles : ndarray, shape (F, 3, 3)
        Triangle corners, mm.
    voxel_size : float
        mm, > 0.

    Returns
    -------
    origin : ndarray, shape (3,)
        Corner of voxel (0, 0, 0), mm: one voxel of margin below the surface's box.
    occupied : ndarray of bool, shape (nx, ny, nz)
    """
    triangles = np.asarray(triangles, dtype=np.float64)
    if not voxel_size > 0:
        raise InputError("must be > 0 mm", field="voxel_size", value=voxel_size)
    lower = triangles.reshape(-1, 3).min(axis=0) - voxel_size
    upper = triangles.reshape(-1, 3).max(axis=0) + voxel_size
    shape = np.ceil((upper - lower) / voxel_size).astype(np.int64) + 1
    occupied = np.zeros(tuple(shape), dtype=bool)
    edge = np.linalg.norm(triangles - np.roll(triangles, 1, axis=1), axis=2).max(axis=1)
    splits = np.maximum(1, np.ceil(edge / voxel_size * SURFACE_POINTS_PER_VOXEL)).astype(int)
    for m in np.unique(splits):
        rows = triangles[splits == m]
        weights = np.concatenate([subdivision_barycentrics(int(m)), np.eye(3)])
        points = np.einsum("sk,fkd->fsd", weights, rows).reshape(-1, 3)
        ijk = np.floor((points - lower) / voxel_size).astype(np.int64)
        occupied[ijk[:, 0], ijk[:, 1], ijk[:, 2]] = True
    return lower, occupied
