"""Shape facts of a triangle mesh: seams, closedness, volume, convexity, points on its area.

Used where a method or a reference needs to know whether an object is closed (an inside is
defined) or convex (a straight segment between two surface points stays inside, and no
point outside sees the object twice).
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import ConvexHull

__all__ = ["CONVEX_VOLUME_TOLERANCE", "WELD_TOLERANCE", "closed_surface", "is_convex",
           "mesh_volume", "stratified_surface_points", "welded_faces"]

#: A closed mesh is convex when its volume is within this fraction of its convex hull's:
#: flat-faced meshes reach 1e-12; a dent of one face in a 1000-face sphere changes the
#: volume by about 1e-4.
CONVEX_VOLUME_TOLERANCE = 1e-6

#: Vertices closer than this fraction of the mesh size are the same vertex (seams).
WELD_TOLERANCE = 1e-9


def welded_faces(vertices, faces) -> np.ndarray:
    """Re-index faces so that vertices at the same position share one index.

    Positions agree to :data:`WELD_TOLERANCE` of the mesh size; meshes built from separate
    grids (a box's six sides) duplicate the vertices along their seams.
    """
    vertices = np.asarray(vertices, dtype=np.float64)
    scale = max(float(np.ptp(vertices, axis=0).max()), 1e-300)
    keys = np.round(vertices / (scale * WELD_TOLERANCE)).astype(np.int64)
    _, inverse = np.unique(keys, axis=0, return_inverse=True)
    return inverse.ravel()[np.asarray(faces)]


def closed_surface(faces, vertices=None) -> bool:
    """Return True when every edge of the triangle mesh is shared by exactly two faces.

    With ``vertices``, coincident vertices are welded first (:func:`welded_faces`).
    """
    faces = np.asarray(faces) if vertices is None else welded_faces(vertices, faces)
    edges = np.sort(np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]]),
                    axis=1)
    _, counts = np.unique(edges, axis=0, return_counts=True)
    return bool((counts == 2).all())


def mesh_volume(vertices, faces) -> float:
    """Signed volume enclosed by a closed, outward-wound triangle mesh (divergence theorem)."""
    v = np.asarray(vertices, dtype=np.float64)[np.asarray(faces)]
    return float(np.einsum("ij,ij->i", v[:, 0], np.cross(v[:, 1], v[:, 2])).sum() / 6.0)


def is_convex(vertices, faces) -> bool:
    """Return True for a closed mesh whose volume equals its convex hull's.

    Then every straight segment between two surface points lies inside, the shortest
    optical path is the Euclidean distance (Sheng et al. 2014, Sect. 4: "for a convex
    object, this path is simply the euclidean distance"), and nothing outside sees the
    object twice.
    """
    if not closed_surface(faces, vertices):
        return False
    volume = mesh_volume(vertices, faces)
    if volume <= 0:
        return False
    try:
        hull = ConvexHull(np.asarray(vertices, dtype=np.float64)).volume
    except Exception:  # flat or degenerate point sets have no hull volume
        return False
    return abs(hull - volume) <= CONVEX_VOLUME_TOLERANCE * hull


def stratified_surface_points(mesh, count: int, rng) -> tuple[np.ndarray, np.ndarray, float]:
    """Spread ``count`` points uniformly over a mesh's area, stratified along its faces.

    One point in each of ``count`` equal strata of the faces' cumulative area, uniform
    within its triangle, with the interpolated vertex normal (the face's where that
    vanishes).

    Parameters
    ----------
    mesh : Mesh
    count : int
    rng : numpy.random.Generator
        Three arrays of ``count`` draws, in this order.

    Returns
    -------
    positions, normals : ndarray, shape (count, 3)
        The mesh's units; unit normals.
    total : float
        The mesh's area, its units squared (each point stands for ``total / count``).
    """
    areas = mesh.face_areas
    cumulative = np.cumsum(areas)
    total = float(cumulative[-1])
    strata = (np.arange(count) + rng.random(count)) * (total / count)
    face = np.minimum(np.searchsorted(cumulative, strata, side="right"), len(areas) - 1)
    root = np.sqrt(rng.random(count))
    second = rng.random(count)
    weights = np.stack([1.0 - root, root * (1.0 - second), root * second], axis=1)
    corners = mesh.faces[face]
    positions = np.einsum("nk,nkd->nd", weights, mesh.vertices[corners])
    normals = np.einsum("nk,nkd->nd", weights, mesh.normals[corners])
    length = np.linalg.norm(normals, axis=1, keepdims=True)
    normals = np.where(length > 1e-12, normals / np.maximum(length, 1e-300),
                       mesh.face_normals[face])
    return positions, normals, total
