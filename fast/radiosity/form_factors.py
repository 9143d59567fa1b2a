r"""Patches and form factors for translucent radiosity (Sheng et al. 2014, Sect. 2.1, 5.1).

The scene is cut into patches (its triangles, or coplanar neighbouring triangles merged),
each with an area, a centroid and a normal. The form factor :math:`F_{ij}` is the fraction
of the energy leaving patch i diffusely that arrives at patch j directly; with it the
irradiance of patch i is :math:`E_i = \sum_j F_{ij} B_j` (Eq. 10-12), which is how the
matrix F enters :math:`B = (I - SF)^{-1} SE` (Eq. 14).

The paper renders a hemicube at each centroid (Sect. 5.1). Here the equivalent estimate
is made by ray casting through :mod:`translucent.scenes.raycast`: from uniformly
distributed points of each patch, cosine-distributed directions (stratified); the
fraction of rays whose first hit is patch j is an unbiased estimate of the area-averaged
:math:`F_{ij}`, and the row sums never exceed 1 (energy is conserved by construction).
Entries below a threshold are dropped (the paper thresholds small fractions too, Sect.
6.4); the dropped energy is reported.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import numpy as np
from scipy import sparse

from ...errors import InputError
from ...scenes.lighting import stratified_cosine_directions
from ...scenes.mesh_shape import is_convex

__all__ = [
    "Patches",
    "build_patches",
    "first_hit_patches",
    "form_factors",
    "needs_form_factors",
    "sphere_form_factors",
    "stratified_cosine_directions",
]

#: Two triangles are coplanar (mergeable) when their normals differ by less than this
#: angle and each lies within this fraction of the patch size off the other's plane.
COPLANAR_DEGREES = 0.5
COPLANAR_OFFSET = 1e-6

#: Fraction of the form-factor energy (mean row sum) a threshold may drop before
#: :func:`form_factors` warns: the inter-reflected light changes by about as much, ten times
#: the radiosity solver's 0.5 % tolerance (a choice, not a measurement).
DROPPED_ENERGY_WARNING = 0.05

#: Ray origins are moved this fraction of the patch size along the normal, so that a ray
#: does not hit the patch it starts on through round-off.
RAY_OFFSET = 1e-4


@dataclass(frozen=True, eq=False)
class Patches:
    """The radiosity patches of a scene.

    Parameters
    ----------
    object_names : tuple of str
        The scene's objects, in order.
    object_of : ndarray of int, shape (P,)
        Object index of each patch.
    face_offset : ndarray of int, shape (objects + 1,)
        Global face index of each object's first face (faces are numbered object by object).
    face_patch : ndarray of int, shape (F,)
        Patch of each global face.
    patch_face_start : ndarray of int, shape (P + 1,)
        CSR pointers into ``patch_faces``.
    patch_faces : ndarray of int, shape (F,)
        Global faces of each patch, patch by patch.
    triangles : ndarray, shape (F, 3, 3)
        Triangle corners, scene units.
    triangle_area : ndarray, shape (F,)
        Scene units^2.
    area : ndarray, shape (P,)
        Scene units^2.
    centroid : ndarray, shape (P, 3)
        Area-weighted centroid, scene units.
    normal : ndarray, shape (P, 3)
        Unit normal (area-weighted mean of its triangles'), scene units.
    radius : ndarray, shape (P,)
        Largest distance from the centroid to a corner, scene units.
    mm_per_unit : float
    twin : ndarray of int, shape (P,)
        The patch on the other side of the same triangles (two-sided thin sheets), or -1.
    face_back_patch : ndarray of int, shape (F,)
        The back patch of each global face, or -1 where the face is one-sided.
    """

    object_names: tuple
    object_of: np.ndarray
    face_offset: np.ndarray
    face_patch: np.ndarray
    patch_face_start: np.ndarray
    patch_faces: np.ndarray
    triangles: np.ndarray
    triangle_area: np.ndarray
    area: np.ndarray
    centroid: np.ndarray
    normal: np.ndarray
    radius: np.ndarray
    mm_per_unit: float
    twin: np.ndarray | None = None
    face_back_patch: np.ndarray | None = None

    def __post_init__(self):
        if self.twin is None:
            object.__setattr__(self, "twin", np.full(len(self.area), -1, dtype=np.int64))
        if self.face_back_patch is None:
            object.__setattr__(self, "face_back_patch",
                               np.full(len(self.face_patch), -1, dtype=np.int64))

    @property
    def is_back(self) -> np.ndarray:
        """True for the back patches of two-sided sheets, shape (P,)."""
        return (self.twin >= 0) & (np.arange(len(self.area)) > self.twin)

    def __len__(self) -> int:
        return len(self.area)

    def of_object(self, index: int) -> np.ndarray:
        """Patch indices of object ``index``."""
        return np.flatnonzero(self.object_of == index)

    def faces_of(self, patches) -> tuple[np.ndarray, np.ndarray]:
        """``(row, face)``: every global face of the given patches, with the row of its patch."""
        patches = np.asarray(patches)
        counts = self.patch_face_start[patches + 1] - self.patch_face_start[patches]
        rows = np.repeat(np.arange(len(patches)), counts)
        starts = np.repeat(self.patch_face_start[patches], counts)
        within = np.arange(len(rows)) - np.repeat(np.cumsum(counts) - counts, counts)
        return rows, self.patch_faces[starts + within]

    def vertex_average(self, object_index: int, mesh, *, back: bool = False
                       ) -> sparse.csr_matrix:
        """Return the linear map from per-patch values to one object's vertices (area-weighted).

        Row ``v`` holds, for every patch, the area of the triangles around vertex ``v`` it
        owns divided by the area of all of them, so ``vertex_average(...) @ values`` is
        :meth:`vertex_values`; the image operators of the radiosity renderer build on it.

        Parameters
        ----------
        object_index : int
        mesh : Mesh
            The object's mesh.
        back : bool
            Take the back patches of a two-sided sheet.

        Returns
        -------
        scipy.sparse.csr_matrix, shape (V, P)
        """
        start, stop = self.face_offset[object_index], self.face_offset[object_index + 1]
        owner = (self.face_back_patch if back else self.face_patch)[start:stop]
        area = np.tile(self.triangle_area[start:stop], 3)
        corners = np.asarray(mesh.faces).T.ravel()
        count = len(mesh.vertices)
        vertex_area = np.bincount(corners, area, minlength=count)
        return sparse.csr_matrix(
            (area / np.maximum(vertex_area, 1e-300)[corners], (corners, np.tile(owner, 3))),
            shape=(count, len(self)))

    def vertex_values(self, object_index: int, mesh, values, *, back: bool = False
                      ) -> np.ndarray:
        """Per-patch values of one object averaged to its vertices (area-weighted).

        Sheng et al. 2014 compose the image from per-patch radiosity; interpolating the
        vertex averages over each triangle removes the faceting.

        Parameters
        ----------
        object_index : int
        mesh : Mesh
            The object's mesh.
        values : ndarray, shape (P, C)
            Per-patch values for the whole scene.
        back : bool
            Take the back patches of a two-sided sheet.

        Returns
        -------
        ndarray, shape (V, C)
        """
        return self.vertex_average(object_index, mesh, back=back) @ np.asarray(values)

    def sample_points(self, patches, per_patch: int, rng) -> tuple[np.ndarray, np.ndarray]:
        """Uniform random points on the given patches: ``(rows, points)`` in scene units.

        Each patch gets ``per_patch`` points spread over its triangles by area.
        """
        patches = np.asarray(patches)
        rows = np.repeat(np.arange(len(patches)), per_patch)
        owner = patches[rows]
        # pick a triangle of the patch with probability proportional to its area
        start = self.patch_face_start[owner]
        count = self.patch_face_start[owner + 1] - start
        faces = self.patch_faces[start]
        multi = np.flatnonzero(count > 1)
        if len(multi):
            cumulative = np.cumsum(self.triangle_area[self.patch_faces])
            base = np.where(start > 0, cumulative[start - 1], 0.0)
            u = rng.random(len(multi)) * self.area[owner[multi]]
            faces[multi] = self.patch_faces[np.searchsorted(cumulative, base[multi] + u,
                                                            side="right")
                                            .clip(start[multi], start[multi] + count[multi] - 1)]
        r1, r2 = rng.random(len(rows)), rng.random(len(rows))
        root = np.sqrt(r1)
        corners = self.triangles[faces]
        points = (corners[:, 0] * (1 - root)[:, None] + corners[:, 1] * (root * (1 - r2))[:, None]
                  + corners[:, 2] * (root * r2)[:, None])
        return rows, points


def _face_adjacency(faces) -> list[list[int]]:
    edges = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    owner = np.tile(np.arange(len(faces)), 3)
    edges = np.sort(edges, axis=1)
    order = np.lexsort((edges[:, 1], edges[:, 0]))
    edges, owner = edges[order], owner[order]
    same = (edges[1:] == edges[:-1]).all(axis=1)
    neighbours: list[list[int]] = [[] for _ in range(len(faces))]
    for a, b in zip(owner[:-1][same], owner[1:][same], strict=True):
        neighbours[a].append(b)
        neighbours[b].append(a)
    return neighbours


def _merge_coplanar(mesh, max_triangles: int) -> np.ndarray:
    """Patch label of each face: coplanar edge-neighbours grouped, at most ``max_triangles``."""
    faces = mesh.faces
    normals = mesh.face_normals
    centroids = mesh.face_centroids
    size = float(np.ptp(mesh.vertices, axis=0).max())
    cos_limit = np.cos(np.radians(COPLANAR_DEGREES))
    neighbours = _face_adjacency(faces)
    label = np.full(len(faces), -1, dtype=np.int64)
    next_label = 0
    for seed in range(len(faces)):
        if label[seed] >= 0:
            continue
        label[seed] = next_label
        members, frontier = 1, [seed]
        while frontier and members < max_triangles:
            face = frontier.pop(0)
            for other in neighbours[face]:
                if members >= max_triangles:
                    break
                if label[other] >= 0 or normals[other] @ normals[seed] < cos_limit:
                    continue
                if abs((centroids[other] - centroids[seed]) @ normals[seed]) > \
                        COPLANAR_OFFSET * size:
                    continue
                label[other] = next_label
                members += 1
                frontier.append(other)
        next_label += 1
    return label


def build_patches(scene, *, triangles_per_patch: int = 1, two_sided=()) -> Patches:
    """Cut a scene into radiosity patches.

    Parameters
    ----------
    scene : Scene
    triangles_per_patch : int
        1: every triangle is a patch (the paper's polygons). More: coplanar
        edge-neighbours are merged greedily up to this many triangles (2 turns the grids
        of the Cornell box into quads), fewer patches for the same geometry.
    two_sided : iterable of int
        Objects that are thin sheets: each of their patches gets a twin facing the other
        way (the two faces of a rose petal, Sheng et al. 2014, Sect. 6.1). The back
        patches follow all front patches.

    Returns
    -------
    Patches
    """
    if int(triangles_per_patch) != triangles_per_patch or triangles_per_patch < 1:
        raise InputError("must be an integer >= 1", field="triangles_per_patch",
                         value=triangles_per_patch)
    labels, triangles, offsets = [], [], [0]
    next_patch = 0
    object_of = []
    for index, obj in enumerate(scene.objects):
        mesh = obj.mesh
        if triangles_per_patch == 1:
            label = np.arange(len(mesh.faces))
        else:
            label = _merge_coplanar(mesh, int(triangles_per_patch))
        count = int(label.max()) + 1
        labels.append(label + next_patch)
        object_of.append(np.full(count, index))
        next_patch += count
        triangles.append(mesh.vertices[mesh.faces])
        offsets.append(offsets[-1] + len(mesh.faces))
    face_patch = np.concatenate(labels)
    triangles = np.concatenate(triangles)
    cross = np.cross(triangles[:, 1] - triangles[:, 0], triangles[:, 2] - triangles[:, 0])
    triangle_area = 0.5 * np.linalg.norm(cross, axis=1)
    patches = next_patch
    order = np.argsort(face_patch, kind="stable")
    start = np.concatenate([[0], np.cumsum(np.bincount(face_patch, minlength=patches))])
    area = np.bincount(face_patch, triangle_area, minlength=patches)
    centroid = np.stack([np.bincount(face_patch, triangle_area * triangles.mean(axis=1)[:, k],
                                     minlength=patches) for k in range(3)], axis=1)
    centroid /= area[:, None]
    normal = np.stack([np.bincount(face_patch, 0.5 * cross[:, k], minlength=patches)
                       for k in range(3)], axis=1)
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    corner_distance = np.linalg.norm(triangles - centroid[face_patch][:, None], axis=2).max(axis=1)
    radius = np.zeros(patches)
    np.maximum.at(radius, face_patch, corner_distance)
    object_of = np.concatenate(object_of)
    twin = np.full(patches, -1, dtype=np.int64)
    face_back_patch = np.full(len(face_patch), -1, dtype=np.int64)
    sheets = sorted(set(int(i) for i in two_sided))
    if sheets:
        front = np.flatnonzero(np.isin(object_of, sheets))
        back = np.arange(patches, patches + len(front))
        twin = np.concatenate([twin, front])
        twin[front] = back
        faces = np.flatnonzero(np.isin(face_patch, front))
        mapping = np.full(patches, -1, dtype=np.int64)
        mapping[front] = back
        face_back_patch[faces] = mapping[face_patch[faces]]
        counts = np.diff(start)[front]
        extra_faces = np.concatenate([order[start[p]:start[p + 1]] for p in front])
        start = np.concatenate([start, start[-1] + np.cumsum(counts)])
        order = np.concatenate([order, extra_faces])
        area, radius = np.concatenate([area, area[front]]), np.concatenate([radius, radius[front]])
        centroid = np.concatenate([centroid, centroid[front]])
        normal = np.concatenate([normal, -normal[front]])
        object_of = np.concatenate([object_of, object_of[front]])
    return Patches(tuple(o.name for o in scene.objects), object_of,
                   np.array(offsets), face_patch, start, order, triangles, triangle_area,
                   area, centroid, normal, radius, float(scene.mm_per_unit), twin,
                   face_back_patch)


def needs_form_factors(scene) -> str | None:
    """None when some patch may see another; otherwise the reason none can.

    A single closed convex object sees nothing of itself and there is nothing else:
    F = 0 and B = SE (Sheng et al. 2014, Eq. 14 with F = 0).
    """
    if len(scene.objects) == 1:
        mesh = scene.objects[0].mesh
        if is_convex(mesh.vertices, mesh.faces):
            return (f"no form factors: the scene is one convex object ('{scene.objects[0].name}')"
                    ", no patch sees another (F = 0, B = SE)")
    return None


def form_factors(scene, patches: Patches, *, rays_per_patch: int = 256,
                 threshold: float = 0.0, seed: int = 0, batch: int = 1 << 20,
                 trace=None, rows=None) -> tuple[sparse.csr_matrix, dict]:
    r"""Form factors :math:`F_{ij}` by ray casting (Sheng et al. 2014, Sect. 5.1, Eq. 1).

    For each patch, ``rays_per_patch`` rays leave uniformly distributed points of the
    patch in stratified cosine-distributed directions; :math:`F_{ij}` is the fraction whose
    first hit is a front face of patch j. Entries below ``threshold`` are dropped.

    Parameters
    ----------
    scene : Scene
    patches : Patches
    rays_per_patch : int
        Rays from each patch, >= 1; the smallest non-zero entry is ``1 / rays_per_patch``.
    threshold : float
        Entries below it are set to 0 (the paper's thresholding of small fractions). A
        ray-cast entry is a count of rays times ``1 / rays_per_patch``, and most of a row's
        energy sits in entries hit by one or two rays: on the 25,080-patch Cornell box (256
        rays) a threshold of 1.5 / 256 keeps 3 % of the entries and changes B by 47 %
        (``translucent bench radiosity``). Unlike the paper's hemicube factors, small
        ray-cast entries are not small transport; a threshold that drops more than
        :data:`DROPPED_ENERGY_WARNING` of the energy warns.
    seed : int
        Seed of the ray directions and origins.
    batch : int
        Rays per ray query.
    trace : callable, optional
        The ray query, ``trace(scene, origins, directions)``; defaults to
        :func:`translucent.scenes.raycast.trace`.
    rows : array_like of int, optional
        Cast from these patches only (default all); the other rows are empty.

    Returns
    -------
    F : scipy.sparse.csr_matrix, shape (P, P), float32
        Row i holds :math:`F_{ij}`; row sums <= 1.
    facts : dict
        ``rays``, ``hits``, ``entries``, ``dropped_entries``, ``dropped_energy`` (the mean
        row-sum lost to the threshold), ``bytes``.
    """
    if int(rays_per_patch) != rays_per_patch or rays_per_patch < 1:
        raise InputError("must be an integer >= 1", field="rays_per_patch",
                         value=rays_per_patch)
    if not 0.0 <= float(threshold) < 1.0:
        raise InputError("must be in [0, 1)", field="form_factor_threshold", value=threshold)
    if trace is None:
        from ...scenes.raycast import trace
    rng = np.random.default_rng(seed)
    count = len(patches)
    sources = np.arange(count) if rows is None else np.asarray(rows, dtype=np.int64)
    rays = int(rays_per_patch)
    rows_all, cols_all = [], []
    per_batch = max(1, batch // rays)
    for start in range(0, len(sources), per_batch):
        chunk = sources[start:start + per_batch]
        rows, origins = patches.sample_points(chunk, rays, rng)
        normals = patches.normal[chunk]
        directions = stratified_cosine_directions(normals, rays, rng).reshape(-1, 3)
        offset = RAY_OFFSET * patches.radius[chunk][rows][:, None] * normals[rows]
        hit_patch = first_hit_patches(scene, patches, origins + offset, directions, trace)
        valid = hit_patch >= 0
        rows_all.append(chunk[rows[valid]])
        cols_all.append(hit_patch[valid])
    rows, cols = (np.concatenate(rows_all), np.concatenate(cols_all)) if rows_all else \
        (np.zeros(0, np.int64), np.zeros(0, np.int64))
    matrix = sparse.coo_matrix((np.full(len(rows), 1.0 / rays), (rows, cols)),
                               shape=(count, count)).tocsr()
    matrix.sum_duplicates()
    row_sum_before = np.asarray(matrix.sum(axis=1)).ravel()
    entries = matrix.nnz
    if threshold > 0:
        matrix.data[matrix.data < threshold] = 0.0
        matrix.eliminate_zeros()
    row_sum_after = np.asarray(matrix.sum(axis=1)).ravel()
    matrix = matrix.astype(np.float32)
    facts = {"rays": len(sources) * rays, "hits": int(len(rows)), "entries": int(matrix.nnz),
             "dropped_entries": int(entries - matrix.nnz),
             "dropped_energy": float(np.mean(row_sum_before - row_sum_after)),
             "max_row_sum": float(row_sum_after.max()) if count else 0.0,
             "bytes": int(matrix.data.nbytes + matrix.indices.nbytes + matrix.indptr.nbytes)}
    lost = facts["dropped_energy"] / max(float(np.mean(row_sum_before)), 1e-300)
    if threshold > 0 and lost > DROPPED_ENERGY_WARNING:
        warnings.warn(f"form_factor_threshold = {threshold:g} drops {lost:.1%} of the "
                      f"form-factor energy (mean row sum): ray-cast entries are multiples of "
                      f"1 / rays_per_patch = {1.0 / rays:.4g}, and the far field is carried by "
                      "single-ray entries; lower the threshold or cast more rays",
                      stacklevel=2)
    return matrix, facts


def first_hit_patches(scene, patches: Patches, origins, directions, trace) -> np.ndarray:
    """Patch of the first front-face hit of each ray, -1 for a miss or a back face."""
    hits = trace(scene, origins, directions)
    found = np.asarray(hits.hit, dtype=bool)
    patch = np.full(len(origins), -1, dtype=np.int64)
    if not found.any():
        return patch
    obj = np.asarray(hits.object_id)[found]
    face = np.asarray(hits.triangle_id)[found]
    global_face = patches.face_offset[obj] + face
    front = np.einsum("ij,ij->i", np.asarray(hits.geometric_normal)[found],
                      directions[found]) < 0
    # light enters a patch on its front side only: a ray reaching a back face is absorbed,
    # unless the face belongs to a two-sided sheet, whose back patch receives it
    hit_patch = np.where(front, patches.face_patch[global_face],
                         patches.face_back_patch[global_face])
    patch[np.flatnonzero(found)] = hit_patch
    return patch


def sphere_form_factors(areas) -> np.ndarray:
    r"""Exact form factors inside a closed sphere: :math:`F_{ij} = A_j / \sum_k A_k`.

    Every point of a sphere's interior sees every patch with the same solid-angle-weighted
    share, its area over the sphere's (Goral et al. 1984; Cohen and Wallace 1993); the
    diagonal is included (a concave patch sees itself). The closed-form check of the
    radiosity solver (Sheng et al. 2014, Eq. 2 with S = P). Dense, shape (P, P).
    """
    areas = np.asarray(areas, dtype=np.float64)
    return np.broadcast_to(areas / areas.sum(), (len(areas), len(areas))).copy()
