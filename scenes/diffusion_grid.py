r"""The finite-volume grid of a closed object, for diffusion in the object's own shape.

Cell-centred voxels whose centres lie inside the surface (a generalised winding number
decides the voxels the surface passes through), the faces they share, and their faces on
the surface with the surface's point and normal there. The diffusion equation of the
dipole (Jensen et al. 2001: :math:`D = 1/(3\sigma'_t)`, the extrapolated boundary
:math:`z_b = 2AD`) is discretised on it by the escape probability of translucent
radiosity's finite-object energy (:mod:`translucent.fast.radiosity.diffusion_escape`) and by
the geometry correction every method shares (:mod:`translucent.scenes.object_diffusion`).

Lengths in mm, coefficients in mm^-1.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numba
import numpy as np
from scipy import ndimage, sparse
from scipy.spatial import cKDTree

from ..errors import InputError
from ..materials.dipole import (
    dipole_boundary_factor,
    effective_transport_coefficient,
    mean_free_path,
)
from .voxels import surface_voxels

__all__ = [
    "DiffusionGrid",
    "boundary_conductance",
    "diffusion_grid",
    "diffusion_terms",
]


@dataclass(eq=False)
class DiffusionGrid:
    r"""Cells of a voxel grid whose centres lie inside a closed object, with their faces.

    Parameters
    ----------
    origin : ndarray, shape (3,)
        Corner of voxel (0, 0, 0), mm.
    voxel_size : float
        Edge length h, mm.
    node_of : ndarray of int32, shape (nx, ny, nz)
        Cell index of each voxel, -1 outside.
    centers : ndarray, shape (N, 3)
        Cell centres, mm.
    pairs : ndarray of int64, shape (M, 2)
        Cells sharing a face.
    boundary_area : ndarray, shape (N,)
        Area (mm^2) of each cell's faces on the surface, each staircase face weighted by
        :math:`1/\|n\|_1` of the surface normal there.
    face_cell : ndarray of int64, shape (B,), optional
        The cell of each face on the surface (one per open face of an interior cell).
    face_point : ndarray, shape (B, 3), optional
        Where the face stands for the surface: its centre projected onto the plane of the
        nearest triangle, mm.
    face_normal : ndarray, shape (B, 3), optional
        That triangle's outward unit normal.
    face_area : ndarray, shape (B,), optional
        The face's weighted area (its share of ``boundary_area``), mm^2.
    """

    origin: np.ndarray
    voxel_size: float
    node_of: np.ndarray
    centers: np.ndarray
    pairs: np.ndarray
    boundary_area: np.ndarray
    face_cell: np.ndarray | None = None
    face_point: np.ndarray | None = None
    face_normal: np.ndarray | None = None
    face_area: np.ndarray | None = None

    @property
    def cells(self) -> int:
        """Number of interior cells."""
        return len(self.centers)

    @functools.cached_property
    def adjacency(self) -> tuple[sparse.csr_matrix, np.ndarray]:
        """Cells sharing a face as a symmetric 0/1 matrix, and each cell's count of them.

        Material-independent: built once, reused by every escape solve of the grid.
        """
        n = self.cells
        i, j = self.pairs[:, 0], self.pairs[:, 1]
        matrix = sparse.coo_matrix((np.ones(len(i)), (i, j)), shape=(n, n))
        matrix = (matrix + matrix.T).tocsr()
        return matrix, np.asarray(matrix.sum(axis=1)).ravel()

    def interpolate(self, values: np.ndarray, points, *, inside: np.ndarray | None = None,
                    ) -> np.ndarray:
        """Trilinear interpolation of cell values at ``points`` (mm) over interior cells only.

        Corners outside the object are left out and the weights renormalised; a point with
        no interior corner takes its nearest cell's value. ``inside``, when given (bool,
        one per point), is set True where some corner was interior.
        """
        points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        values = np.asarray(values, dtype=np.float64)
        local = (points - self.origin) / self.voxel_size - 0.5
        base = np.floor(local).astype(np.int64)
        frac = local - base
        shape = np.array(self.node_of.shape)
        total = np.zeros((len(points),) + values.shape[1:])
        weight_sum = np.zeros(len(points))
        for corner in np.ndindex(2, 2, 2):
            ijk = base + np.array(corner)
            valid = ((ijk >= 0) & (ijk < shape)).all(axis=1)
            cell = np.full(len(points), -1, dtype=np.int64)
            cell[valid] = self.node_of[tuple(ijk[valid].T)]
            weight = np.prod(np.where(np.array(corner) == 1, frac, 1.0 - frac), axis=1)
            weight = np.where(cell >= 0, weight, 0.0)
            total += weight.reshape((-1,) + (1,) * (values.ndim - 1)) * values[np.maximum(cell, 0)]
            weight_sum += weight
        missing = weight_sum <= 1e-12
        if inside is not None:
            inside[:] = ~missing
        if missing.any():
            _, nearest = cKDTree(self.centers).query(points[missing])
            total[missing] = values[nearest]
            weight_sum[missing] = 1.0
        return total / weight_sum.reshape((-1,) + (1,) * (values.ndim - 1))


@numba.njit(cache=True)
def _winding_numbers(points, triangles):  # pragma: no cover - compiled
    """Generalised winding number of a closed mesh at each point (van Oosterom-Strackee)."""
    out = np.zeros(len(points))
    for p in range(len(points)):
        total = 0.0
        for t in range(len(triangles)):
            ax = triangles[t, 0, 0] - points[p, 0]
            ay = triangles[t, 0, 1] - points[p, 1]
            az = triangles[t, 0, 2] - points[p, 2]
            bx = triangles[t, 1, 0] - points[p, 0]
            by = triangles[t, 1, 1] - points[p, 1]
            bz = triangles[t, 1, 2] - points[p, 2]
            cx = triangles[t, 2, 0] - points[p, 0]
            cy = triangles[t, 2, 1] - points[p, 1]
            cz = triangles[t, 2, 2] - points[p, 2]
            la = math.sqrt(ax * ax + ay * ay + az * az)
            lb = math.sqrt(bx * bx + by * by + bz * bz)
            lc = math.sqrt(cx * cx + cy * cy + cz * cz)
            det = ax * (by * cz - bz * cy) - ay * (bx * cz - bz * cx) + az * (bx * cy - by * cx)
            div = (la * lb * lc + (ax * bx + ay * by + az * bz) * lc
                   + (bx * cx + by * cy + bz * cz) * la + (cx * ax + cy * ay + cz * az) * lb)
            total += 2.0 * math.atan2(det, div)
        out[p] = total / (4.0 * math.pi)
    return out


def diffusion_grid(triangles, voxel_size: float) -> DiffusionGrid:
    """Build the finite-volume grid of a closed object.

    Parameters
    ----------
    triangles : ndarray, shape (F, 3, 3)
        The closed surface, mm, counter-clockwise seen from outside.
    voxel_size : float
        mm, > 0.

    Returns
    -------
    DiffusionGrid

    Raises
    ------
    InputError
        No cell centre lies inside (the object is thinner than a voxel).
    """
    triangles = np.ascontiguousarray(triangles, dtype=np.float64)
    origin, on_surface = surface_voxels(triangles, voxel_size)
    inside = ndimage.binary_fill_holes(on_surface)
    # voxels the surface passes through: their centre may lie on either side
    candidates = np.argwhere(on_surface)
    centres = origin + (candidates + 0.5) * voxel_size
    # either orientation: the magnitude is 1 inside a closed surface, 0 outside
    keep = np.abs(_winding_numbers(centres, triangles)) > 0.5
    inside[tuple(candidates[~keep].T)] = False
    ijk = np.argwhere(inside)
    if len(ijk) == 0:
        raise InputError("no voxel centre lies inside the object: use smaller voxels",
                         field="voxel_size", value=voxel_size)
    node_of = np.full(inside.shape, -1, dtype=np.int32)
    node_of[tuple(ijk.T)] = np.arange(len(ijk), dtype=np.int32)
    centers = origin + (ijk + 0.5) * voxel_size
    # the surface normal near each boundary face, from the nearest triangle centroid
    face_normal = np.cross(triangles[:, 1] - triangles[:, 0], triangles[:, 2] - triangles[:, 0])
    face_normal /= np.maximum(np.linalg.norm(face_normal, axis=1, keepdims=True), 1e-300)
    tree = cKDTree(triangles.mean(axis=1))
    pairs = []
    boundary_area = np.zeros(len(ijk))
    faces = {"cell": [], "centre": [], "triangle": [], "area": []}
    shape = np.array(inside.shape)
    for axis in range(3):
        for step in (-1, 1):
            offset = np.zeros(3, dtype=np.int64)
            offset[axis] = step
            neighbour = ijk + offset
            valid = ((neighbour >= 0) & (neighbour < shape)).all(axis=1)
            other = np.full(len(ijk), -1, dtype=np.int64)
            other[valid] = node_of[tuple(neighbour[valid].T)]
            if step == 1:
                joined = np.flatnonzero(other >= 0)
                pairs.append(np.stack([joined, other[joined]], axis=1))
            open_face = np.flatnonzero(other < 0)
            if len(open_face):
                centre = centers[open_face] + 0.5 * voxel_size * offset
                _, nearest = tree.query(centre)
                norm1 = np.abs(face_normal[nearest]).sum(axis=1)
                boundary_area[open_face] += voxel_size ** 2 / norm1
                faces["cell"].append(open_face)
                faces["centre"].append(centre)
                faces["triangle"].append(nearest)
                faces["area"].append(voxel_size ** 2 / norm1)
    face_cell, centre, triangle, area = (np.concatenate(faces[key]) for key in
                                         ("cell", "centre", "triangle", "area"))
    normal = face_normal[triangle]
    # the face centre moved along the normal onto the nearest triangle's plane
    height = np.einsum("fd,fd->f", centre - triangles[triangle, 0], normal)
    return DiffusionGrid(origin, float(voxel_size), node_of, centers,
                         np.concatenate(pairs).astype(np.int64), boundary_area,
                         face_cell.astype(np.int64), centre - height[:, None] * normal,
                         normal, area)


def diffusion_terms(sigma_a, sigma_s_prime, eta):
    """sigma_a, D, z_b = 2AD, z_r = 1/sigma'_t and sigma_tr per channel (mm, mm^-1)."""
    sigma_a = np.asarray(sigma_a, dtype=np.float64).reshape(-1)
    sigma_s_prime = np.asarray(sigma_s_prime, dtype=np.float64).reshape(-1)
    if not (np.all(sigma_a > 0) and np.all(sigma_s_prime > 0)):
        raise InputError("the escape probability needs sigma_a > 0 and sigma_s' > 0 mm^-1",
                         field="sigma_a, sigma_s_prime",
                         value=f"{sigma_a.tolist()}, {sigma_s_prime.tolist()}")
    source_depth = mean_free_path(sigma_a, sigma_s_prime)
    diffusion = source_depth / 3.0
    extrapolation = 2.0 * float(dipole_boundary_factor(eta)) * diffusion
    sigma_tr = effective_transport_coefficient(sigma_a, sigma_s_prime)
    return sigma_a, diffusion, extrapolation, source_depth, sigma_tr


def boundary_conductance(diffusion, extrapolation, h):
    """Flux per unit area and unit (e_cell - 1) through a Robin face half a cell away."""
    return 2.0 * diffusion / (h + 2.0 * extrapolation)
