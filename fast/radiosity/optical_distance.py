r"""Shortest optical distances through a translucent object (Sheng et al. 2014, Sect. 4, 5.2).

Subsurface light between two surface points is parametrised by the length of the shortest
path *inside* the object, not the straight line (which may leave a concave object; the
part outside is inter-reflection, carried by the form factors). The paper builds a uniform
voxel grid over the object, marks the interior voxels, and runs Dijkstra on the graph of
interior voxels, stopping beyond the cut-off max_d; two points in the same voxel use their
Euclidean distance.

Here the voxel grid is built by marking the voxels the surface passes through (dense
point samples of every triangle) and filling the enclosed region
(:func:`scipy.ndimage.binary_fill_holes`) -- equivalent to the paper's ray-casting inside
test for a closed mesh, and it keeps an open or thin surface as a connected shell. The
graph joins each occupied voxel to its 26 neighbours with Euclidean edge lengths, and
:func:`scipy.sparse.csgraph.dijkstra` with ``limit=max_d`` is the early termination. A
segment whose every voxel is occupied is inside the object: its Euclidean length is the
distance (this also covers the paper's same-voxel rule); otherwise the graph distance is
used, never less than the Euclidean one. For a convex closed object the straight segment
is always inside, so no grid is built at all
(:func:`~translucent.scenes.mesh_shape.is_convex`).

All lengths in this module are in mm.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np
from scipy import ndimage, sparse
from scipy.sparse.csgraph import dijkstra
from scipy.spatial import cKDTree

from ...compiled import parallel_njit
from ...scenes.voxels import subdivision_barycentrics, surface_voxels

__all__ = [
    "VoxelGrid",
    "optical_distances",
    "subdivision_barycentrics",
    "surface_voxels",
    "voxelize",
]

#: Points per voxel edge along a segment when testing whether it stays inside.
SEGMENT_POINTS_PER_VOXEL = 2

#: Dijkstra sources per batch: the distance block is sources x voxels float64.
DIJKSTRA_BATCH_BYTES = 64 * 2**20


@dataclass(frozen=True, eq=False)
class VoxelGrid:
    """Occupied voxels of one object and the graph joining 26-neighbours.

    Parameters
    ----------
    origin : ndarray, shape (3,)
        Corner of voxel (0, 0, 0), mm.
    voxel_size : float
        Edge length, mm.
    node_of : ndarray of int32, shape (nx, ny, nz)
        Graph node of each voxel, -1 where empty.
    centers : ndarray, shape (N, 3)
        Node centres, mm.
    graph : scipy.sparse.csr_matrix, shape (N, N)
        Symmetric edge lengths (mm) between neighbouring occupied voxels.
    """

    origin: np.ndarray
    voxel_size: float
    node_of: np.ndarray
    centers: np.ndarray
    graph: sparse.csr_matrix

    @property
    def nodes(self) -> int:
        """Number of occupied voxels."""
        return len(self.centers)

    def voxel_index(self, points) -> np.ndarray:
        """Integer voxel coordinates of ``points`` (mm), shape (M, 3), clipped to the grid."""
        index = np.floor((np.asarray(points) - self.origin) / self.voxel_size).astype(np.int64)
        return np.clip(index, 0, np.array(self.node_of.shape) - 1)

    def node(self, points) -> np.ndarray:
        """Graph node of each point (mm): its voxel's, or the nearest occupied one."""
        ijk = self.voxel_index(points)
        nodes = self.node_of[ijk[:, 0], ijk[:, 1], ijk[:, 2]].astype(np.int64)
        missing = nodes < 0
        if missing.any():
            _, nearest = cKDTree(self.centers).query(np.asarray(points)[missing])
            nodes[missing] = nearest
        return nodes

    def segment_inside(self, starts, ends) -> np.ndarray:
        """Return True where every voxel along the segment ``start -> end`` (mm) is occupied.

        The segment is tested at :data:`SEGMENT_POINTS_PER_VOXEL` points per voxel edge
        (both ends included), each point in its voxel clipped to the grid; a compiled loop
        stops at the first empty voxel (most segments between the sides of a concave
        object leave it within a few voxels). The bowl's 5.3 million pairs took 80 s as one
        vectorised test of every point, most of the scattering step.
        """
        starts = np.ascontiguousarray(starts, dtype=np.float64).reshape(-1, 3)
        ends = np.ascontiguousarray(ends, dtype=np.float64).reshape(-1, 3)
        inside = np.ones(len(starts), dtype=bool)
        if len(starts):
            _compiled_segment_test()(starts, ends, np.asarray(self.origin, dtype=np.float64),
                                     float(self.voxel_size), self.node_of,
                                     float(SEGMENT_POINTS_PER_VOXEL), inside)
        return inside


@functools.lru_cache(maxsize=1)
def _compiled_segment_test():
    import numba

    @parallel_njit(cache=True)
    def segment_test(starts, ends, origin, size, node_of, per_voxel,
                     inside):  # pragma: no cover - compiled
        nx, ny, nz = node_of.shape
        for row in numba.prange(len(starts)):
            dx = ends[row, 0] - starts[row, 0]
            dy = ends[row, 1] - starts[row, 1]
            dz = ends[row, 2] - starts[row, 2]
            steps = int(np.ceil(np.sqrt(dx * dx + dy * dy + dz * dz) / size * per_voxel))
            for step in range(steps + 1):
                t = step / steps if steps > 0 else 0.0
                i = min(max(int(np.floor((starts[row, 0] + t * dx - origin[0]) / size)), 0),
                        nx - 1)
                j = min(max(int(np.floor((starts[row, 1] + t * dy - origin[1]) / size)), 0),
                        ny - 1)
                k = min(max(int(np.floor((starts[row, 2] + t * dz - origin[2]) / size)), 0),
                        nz - 1)
                if node_of[i, j, k] < 0:
                    inside[row] = False
                    break

    return segment_test


def voxelize(triangles, voxel_size: float, *, fill: bool = True) -> VoxelGrid:
    """Voxelise a surface (and, when ``fill``, the volume it encloses).

    Parameters
    ----------
    triangles : ndarray, shape (F, 3, 3)
        Triangle corners, mm.
    voxel_size : float
        mm, > 0. It must be smaller than the narrowest gap of a concavity, or the gap is
        bridged (the resolution limit of the paper's grid as well).
    fill : bool
        Fill the enclosed interior (for a closed surface); a thin open sheet stays a shell.

    Returns
    -------
    VoxelGrid
    """
    lower, occupied = surface_voxels(triangles, voxel_size)
    if fill:
        occupied = ndimage.binary_fill_holes(occupied)
    shape = np.array(occupied.shape)
    node_of = np.full(occupied.shape, -1, dtype=np.int32)
    ijk = np.argwhere(occupied)
    node_of[tuple(ijk.T)] = np.arange(len(ijk), dtype=np.int32)
    centers = lower + (ijk + 0.5) * voxel_size
    rows, cols, lengths = [], [], []
    offsets = [(i, j, k) for i in (-1, 0, 1) for j in (-1, 0, 1) for k in (-1, 0, 1)
               if (i, j, k) > (0, 0, 0)]
    for offset in offsets:
        neighbour = ijk + np.array(offset)
        valid = ((neighbour >= 0) & (neighbour < shape)).all(axis=1)
        target = np.full(len(ijk), -1, dtype=np.int64)
        target[valid] = node_of[tuple(neighbour[valid].T)]
        keep = target >= 0
        rows.append(np.flatnonzero(keep))
        cols.append(target[keep])
        lengths.append(np.full(int(keep.sum()), voxel_size * np.linalg.norm(offset)))
    rows, cols, lengths = (np.concatenate(a) for a in (rows, cols, lengths))
    graph = sparse.coo_matrix((np.concatenate([lengths, lengths]),
                               (np.concatenate([rows, cols]), np.concatenate([cols, rows]))),
                              shape=(len(ijk), len(ijk))).tocsr()
    return VoxelGrid(lower, float(voxel_size), node_of, centers, graph)


def optical_distances(grid: VoxelGrid | None, starts, ends, max_distance: float, *,
                      inside=None) -> np.ndarray:
    """Shortest distance inside the object between point pairs, inf beyond ``max_distance``.

    Sheng et al. 2014, Sect. 5.2: Euclidean where the segment stays inside (always, when
    ``grid`` is None: a convex object); otherwise Dijkstra over the voxel graph from the
    start voxel, stopped at ``max_distance`` (early termination) and batched so each
    source voxel is searched once.

    Parameters
    ----------
    grid : VoxelGrid or None
        None for a convex object.
    starts, ends : ndarray, shape (M, 3)
        Pair end points, mm. Batches are formed by the start's voxel, so pass the side
        with fewer distinct points (the exit centroids) as ``starts``.
    max_distance : float
        The cut-off max_d, mm.
    inside : ndarray of bool, shape (M,), optional
        Known answers of :meth:`VoxelGrid.segment_inside` (for example one test per patch
        pair shared by its samples); tested here when omitted.

    Returns
    -------
    ndarray, shape (M,)
        mm; ``inf`` where the distance exceeds ``max_distance``.
    """
    starts = np.asarray(starts, dtype=np.float64)
    ends = np.asarray(ends, dtype=np.float64)
    distance = np.linalg.norm(ends - starts, axis=1)
    if grid is None or len(starts) == 0:
        return np.where(distance <= max_distance, distance, np.inf)
    outside = ~(grid.segment_inside(starts, ends) if inside is None else np.asarray(inside))
    rows = np.flatnonzero(outside & (distance <= max_distance))
    if len(rows):
        source = grid.node(starts[rows])
        target = grid.node(ends[rows])
        order = np.argsort(source, kind="stable")
        rows, source, target = rows[order], source[order], target[order]
        unique_sources, first = np.unique(source, return_index=True)
        batch = max(1, DIJKSTRA_BATCH_BYTES // (8 * grid.nodes))
        for start in range(0, len(unique_sources), batch):
            chunk = unique_sources[start:start + batch]
            table = dijkstra(grid.graph, directed=True, indices=chunk, limit=max_distance)
            lo = first[start]
            hi = first[start + batch] if start + batch < len(unique_sources) else len(source)
            row_in_chunk = np.searchsorted(chunk, source[lo:hi])
            graph_distance = table[row_in_chunk, target[lo:hi]]
            distance[rows[lo:hi]] = np.maximum(distance[rows[lo:hi]], graph_distance)
    return np.where(distance <= max_distance, distance, np.inf)
