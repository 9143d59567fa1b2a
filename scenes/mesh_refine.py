"""Finer vertices on the same surface: midpoint subdivision of a triangle mesh.

A method that computes radiance at the vertices and interpolates it linearly across each
triangle (PRT, Wang et al. 2008) resolves no detail finer than the mesh: where a profile
falls off within one edge, the chord between two vertices lies above the curve. Splitting
every triangle into four at its edge midpoints puts more vertices on the *same* flat
triangles (the surface, and so every ray hit, is unchanged), with no T-junctions: each
edge is split once, and its two triangles share the midpoint.

Examples
--------
>>> from translucent.scenes import box
>>> cube = box((1.0, 1.0, 1.0))
>>> finer = subdivide_midpoints(cube, 1)
>>> len(cube.faces), len(finer.faces), bool(abs(finer.area - cube.area) < 1e-12)
(12, 48, True)
"""

from __future__ import annotations

import numpy as np

from .scene import Mesh

__all__ = ["edge_lengths", "subdivide_midpoints"]


def edge_lengths(mesh: Mesh) -> np.ndarray:
    """Return the length of each triangle's three edges, (F, 3), scene units."""
    corners = mesh.vertices[mesh.faces]
    return np.linalg.norm(corners[:, [1, 2, 0]] - corners, axis=2)


def _split_once(vertices, faces, normals, uv):
    """One level: every edge split at its midpoint, every triangle into four."""
    edges = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    keyed = np.sort(edges, axis=1)
    unique, inverse = np.unique(keyed, axis=0, return_inverse=True)
    inverse = inverse.reshape(-1)
    start = len(vertices)
    middle = start + inverse.reshape(3, -1).T  # (F, 3): midpoints of edges 01, 12, 20
    vertices = np.concatenate([vertices, 0.5 * (vertices[unique[:, 0]]
                                                + vertices[unique[:, 1]])])
    if normals is not None:
        added = normals[unique[:, 0]] + normals[unique[:, 1]]
        length = np.linalg.norm(added, axis=1, keepdims=True)
        # opposite normals (a seam of a two-sided sheet) keep the first one
        added = np.where(length > 1e-12, added / np.maximum(length, 1e-300),
                         normals[unique[:, 0]])
        normals = np.concatenate([normals, added])
    if uv is not None:
        uv = np.concatenate([uv, 0.5 * (uv[unique[:, 0]] + uv[unique[:, 1]])])
    a, b, c = faces.T
    ab, bc, ca = middle.T
    faces = np.concatenate([np.stack([a, ab, ca], axis=1), np.stack([ab, b, bc], axis=1),
                            np.stack([ca, bc, c], axis=1), np.stack([ab, bc, ca], axis=1)])
    return vertices, faces, normals, uv


def subdivide_midpoints(mesh: Mesh, levels: int) -> Mesh:
    """Return ``mesh`` with every triangle split into ``4 ** levels``, the surface unchanged.

    Parameters
    ----------
    mesh : Mesh
    levels : int
        Midpoint subdivisions, >= 0 (0 returns ``mesh`` itself).

    Returns
    -------
    Mesh
        The old vertices first, in their order; new vertices at edge midpoints, with
        normals the normalised mean of the edge's two (a curved mesh's shading stays
        smooth) and uv their mean. A geometry image's grid is not kept.
    """
    levels = int(levels)
    if levels <= 0:
        return mesh
    vertices = np.asarray(mesh.vertices, dtype=np.float64)
    faces = np.asarray(mesh.faces, dtype=np.int64)
    normals = None if mesh.normals is None else np.asarray(mesh.normals, dtype=np.float64)
    uv = None if mesh.uv is None else np.asarray(mesh.uv, dtype=np.float64)
    for _ in range(levels):
        vertices, faces, normals, uv = _split_once(vertices, faces, normals, uv)
    return Mesh(vertices, faces, normals, uv, name=mesh.name)
