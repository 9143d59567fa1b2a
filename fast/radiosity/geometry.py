"""Scattering geometry: distances, samples and profile indices (Sheng et al. 2014, Sect. 5.2).

Material independent: a change of translucency re-tabulates the profile and indexes
into what is stored here.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np
from scipy import sparse
from scipy.spatial import cKDTree

from ...errors import InputError
from ...materials.profiles import (
    MixedProfiles,
    RadialGrid,
)
from ...scenes.mesh_shape import closed_surface, is_convex
from ..base import StageLog
from .diffusion_escape import (
    DiffusionGrid,
    diffusion_grid,
    voxel_size_for,
)
from .form_factors import Patches
from .kernels import (
    csr_pattern,
    directed_pairs,
    sample_operator,
    samples_per_edge,
    scattering_samples,
)
from .knobs import POLAR_NODES
from .optical_distance import optical_distances, voxelize


@dataclass(eq=False)
class ObjectScattering:
    """The cached scattering samples of one translucent object.

    Parameters
    ----------
    object_index : int
    patches : ndarray of int
        Its global (front) patch indices.
    blocks : list of (str, ndarray, ndarray)
        ``(kind, pair_position, self_position)``: where the pairs and the patches' own
        terms land in the data of S, and which profile (``"reflection"`` or
        ``"transmission"``) fills them. One block for a solid object; four for a two-sided
        sheet (front-front and back-back by reflection, across by transmission, Sheng et
        al. 2014, Sect. 6.1).
    sample_operator : scipy.sparse.csr_matrix, shape (pairs, K)
        Interpolation weights (mm^2) of every sample onto the profile grid: the S entries
        of the pairs are ``sample_operator @ table``, added at each block's
        ``pair_position`` in one compiled pass
        (:func:`~translucent.fast.radiosity.kernels.scatter_product`).
    self_cumulative, self_segment : scipy.sparse.csr_matrix, shape (patches, K)
        The polar self term: ``self_cumulative @ C + self_segment @ table`` with C the
        cumulative radial integral of the table (None when ``self_term="samples"``),
        added at each block's ``self_position``.
    samples : dict or None
        Heterogeneous objects only: ``pair``, ``weight`` (mm^2), ``distance`` (mm), and
        ``fractions`` (pairs x materials), ``patch_label``.
    diffusion : DiffusionGrid or None
        The finite-volume grid of a closed object when the knob ``finite_object_energy``
        is on (:mod:`translucent.fast.radiosity.diffusion_escape`).
    facts : dict
        Counts and timings for the report.
    """

    object_index: int
    patches: np.ndarray
    blocks: list
    sample_operator: sparse.csr_matrix | None
    self_cumulative: sparse.csr_matrix | None
    self_segment: sparse.csr_matrix | None
    samples: dict | None
    facts: dict = field(default_factory=dict)
    diffusion: DiffusionGrid | None = None


@dataclass(eq=False)
class ScatteringGeometry:
    """Everything S needs that does not depend on the material (Sheng et al. 2014, Sect. 5.2).

    Parameters
    ----------
    indptr, indices : ndarray
        The CSR pattern of S (rows: exit patch j, columns: incident patch i), diagonal
        included for every patch.
    diagonal_position : ndarray of int, shape (P,)
        Position of each patch's diagonal entry in the data.
    grid : RadialGrid
        The profile grid; its ``max_radius`` is the cut-off max_d (mm).
    objects : dict of int to ObjectScattering
        The translucent objects.
    sheets : tuple of int
        The translucent objects that are thin two-sided sheets.
    sheet_thickness_mm : float or None
        Thickness that turns a Dipole on a sheet into a :class:`SlabProfile`.
    """

    indptr: np.ndarray
    indices: np.ndarray
    diagonal_position: np.ndarray
    grid: RadialGrid
    objects: dict
    sheets: tuple = ()
    sheet_thickness_mm: float | None = None

    @property
    def nnz(self) -> int:
        """Stored entries of S (per channel)."""
        return len(self.indices)

    @property
    def bytes(self) -> int:
        """Memory held by the cached operators and pattern."""
        total = self.indptr.nbytes + self.indices.nbytes + self.diagonal_position.nbytes
        for item in self.objects.values():
            matrices = [item.sample_operator, item.self_cumulative, item.self_segment]
            for matrix in matrices:
                if matrix is not None:
                    total += matrix.data.nbytes + matrix.indices.nbytes + matrix.indptr.nbytes
            total += sum(a.nbytes + b.nbytes for _, a, b in item.blocks)
            if item.samples:
                total += sum(np.asarray(v).nbytes for v in item.samples.values())
        return int(total)


def _samples_per_edge(distance, radius, knobs) -> np.ndarray:
    r"""M (samples = m^2) for each pair: Sheng et al. 2014, Sect. 5.2, decreasing with distance.

    :math:`m = \mathrm{clip}(\mathrm{rint}(m_0 e^{-d / (f r)}), 1, m_0)`, 1 beyond
    ``centroid_beyond`` radii; compiled (one pass, no temporaries of the pairs' size).
    """
    most = max(1, int(round(math.sqrt(knobs["self_samples"]))))
    return samples_per_edge(distance, radius, most, knobs["sample_falloff"],
                            knobs["centroid_beyond"])


def _polar_self_nodes(patches: Patches, members: np.ndarray):
    r"""Nodes of the polar integral of :math:`s(|x - c|)` over each patch about its centroid.

    :math:`\int_{A} s(|x-c|)\,dA = \sum_{\text{edges}} \pm\int C(\rho(\varphi))\,d\varphi` with
    :math:`C(\rho) = \int_0^\rho s(r) r\,dr`; along an edge at distance h from c,
    :math:`d\varphi = h\,ds / (h^2 + s^2)` and :math:`\rho = \sqrt{h^2 + s^2}`.

    Returns
    -------
    rows : ndarray of int
        Index into ``members``.
    rho : ndarray
        mm.
    weight : ndarray
        Radians (signed).
    """
    mm = patches.mm_per_unit
    rows, faces = patches.faces_of(members)
    corners = patches.triangles[faces] * mm
    center = patches.centroid[members][rows] * mm
    normal = patches.normal[members][rows]
    nodes, weights = np.polynomial.legendre.leggauss(POLAR_NODES)
    t, w = 0.5 * (nodes + 1.0), 0.5 * weights
    out_rows, out_rho, out_weight = [], [], []
    for edge in range(3):
        a, b = corners[:, edge], corners[:, (edge + 1) % 3]
        direction = b - a
        length = np.linalg.norm(direction, axis=1)
        unit = direction / length[:, None]
        s_a = np.einsum("ij,ij->i", a - center, unit)
        foot = a - s_a[:, None] * unit
        h = np.linalg.norm(foot - center, axis=1)
        orientation = np.sign(np.einsum("ij,ij->i", np.cross(a - center, b - center), normal))
        keep = (h > 1e-12 * length) & (orientation != 0)
        s = s_a[:, None] + length[:, None] * t[None, :]
        rho = np.sqrt(h[:, None] ** 2 + s**2)
        weight = orientation[:, None] * h[:, None] / rho**2 * length[:, None] * w[None, :]
        out_rows.append(np.repeat(rows[keep], len(t)))
        out_rho.append(rho[keep].ravel())
        out_weight.append(weight[keep].ravel())
    return np.concatenate(out_rows), np.concatenate(out_rho), np.concatenate(out_weight)


def _self_operators(grid: RadialGrid, count: int, rows, rho, weight):
    r"""Sparse operators of the polar self term on the profile grid (exact for the table).

    :math:`C(\rho) = C_k + h_k[s_k a(f) + s_{k+1} b(f)]` on segment k at offset f, with
    :math:`a = r_k(f - f^2/2) + h_k(f^2/2 - f^3/3)`, :math:`b = r_k f^2/2 + h_k f^3/3`.
    """
    # radii at or beyond max_d land on the last segment with f = 1: C(max_d) exactly
    k, f = grid.locate(rho)
    f = f.astype(np.float64)
    radius = grid.radius
    left = radius[k]
    h = radius[k + 1] - left
    a = h * (left * (f - f * f / 2) + h * (f * f / 2 - f**3 / 3))
    b = h * (left * f * f / 2 + h * f**3 / 3)
    shape = (count, grid.samples)
    cumulative = sparse.coo_matrix((weight, (rows, k)), shape=shape).tocsr()
    segment = sparse.coo_matrix((np.concatenate([weight * a, weight * b]),
                                 (np.concatenate([rows, rows]), np.concatenate([k, k + 1]))),
                                shape=shape).tocsr()
    return cumulative, segment


def pair_fractions(centroids_mm, face_centroids_mm, face_labels, exit_local, incident_local,
                    materials: int, points: int, volume_labels=None,
                    mm_per_unit: float = 1.0) -> np.ndarray:
    """Fraction of the segment between two patch centroids inside each material.

    The material at a point is ``volume_labels(point)`` where the object has a volume
    (a solid medium; points in scene units), otherwise that of the nearest surface face
    (the paper's checkerboard block is labelled on its surface).

    Returns
    -------
    ndarray of uint8, shape (pairs, materials)
        How many of the ``points`` along each segment lie in each material: the fraction
        times ``points``, stored as counts (a byte per pair and material, where float64
        fractions of all pairs of a 4608-patch sphere with 16 materials took 2.7 GB).
    """
    if hasattr(volume_labels, "counts_along"):  # a voxel grid: compiled, no point arrays
        return volume_labels.counts_along(centroids_mm, exit_local, incident_local, points,
                                          materials, scale=mm_per_unit)
    if volume_labels is None:
        tree = cKDTree(face_centroids_mm)
    t = (np.arange(points) + 0.5) / points
    fractions = np.zeros((len(exit_local), materials), dtype=np.uint8)
    chunk = max(1, (1 << 20) // points)
    for start in range(0, len(exit_local), chunk):
        stop = min(len(exit_local), start + chunk)
        a = centroids_mm[exit_local[start:stop]]
        b = centroids_mm[incident_local[start:stop]]
        along = a[:, None] + t[None, :, None] * (b - a)[:, None]
        if volume_labels is None:
            _, nearest = tree.query(along.reshape(-1, 3))
            labels = face_labels[nearest].reshape(stop - start, points)
        else:
            labels = volume_labels(along.reshape(-1, 3) / mm_per_unit).reshape(stop - start,
                                                                                points)
        # one count of every (pair, material), not one comparison of every point per
        # material
        rows = np.repeat(np.arange(stop - start), points) * materials
        fractions[start:stop] = np.bincount(rows + labels.reshape(-1),
                                            minlength=(stop - start) * materials
                                            ).reshape(stop - start, materials)
    return fractions


def _gathered(parts, size: int) -> np.ndarray:
    """Concatenate ``source[index]`` (``source`` where index is None) of every part, int64."""
    out = np.empty(size, dtype=np.int64)
    start = 0
    for source, index in parts:
        count = len(source) if index is None else len(index)
        if index is None:
            out[start:start + count] = source
        else:
            # indices are in range: "clip" only spares take's buffered copy of the result
            np.take(source, index, out=out[start:start + count], mode="clip")
        start += count
    return out


def scattering_geometry(scene, patches: Patches, translucent: list[int], *,
                        max_distance_mm: float, knobs: dict, log: StageLog | None = None,
                        sheet_thickness_mm: float | None = None) -> ScatteringGeometry:
    """Distances, samples and profile indices of every scattering factor (Sect. 5.2).

    Parameters
    ----------
    scene : Scene
    patches : Patches
    translucent : list of int
        Indices of the translucent objects (the others get a diagonal S = P).
    max_distance_mm : float
        The cut-off max_d, mm.
    knobs : dict
        :data:`DEFAULT_KNOBS` entries ``self_samples``, ``sample_falloff``,
        ``centroid_beyond``, ``self_term``, ``voxels_per_axis``, ``profile_samples``,
        ``mix_points``, ``finite_object_energy``, ``diffusion_voxels_per_axis``.
    log : StageLog, optional
        Receives what was skipped (voxel grids of convex objects) and the timings.
    sheet_thickness_mm : float, optional
        Thickness of the thin sheets (objects whose patches have twins, see
        :func:`~translucent.fast.radiosity.form_factors.build_patches`): a Dipole on a sheet becomes
        the reflection and transmission of a slab this thick.

    Returns
    -------
    ScatteringGeometry
    """
    log = log if log is not None else StageLog()
    grid = RadialGrid(max_distance_mm, knobs["profile_samples"])
    mm = patches.mm_per_unit
    # every block of entries of the pattern, as (patches, index into them or None) for its
    # rows and its columns: gathered once into the pattern's arrays at the end, with no
    # temporary array a block
    rows_all = [(np.arange(len(patches)), None)]
    cols_all = [(np.arange(len(patches)), None)]
    # every block of entries appended to the pattern: (object, kind, pairs, self) slices
    segments: dict = {}
    filled = [len(patches)]

    def append(rows, cols, row_index=None, col_index=None):
        rows_all.append((rows, row_index))
        cols_all.append((cols, col_index))
        filled.append(filled[-1] + len(rows if row_index is None else row_index))
        return filled[-2], filled[-1]

    sheets = []
    per_object = []
    for index in translucent:
        obj = scene.objects[index]
        started = time.perf_counter()
        members = patches.of_object(index)
        members = members[~patches.is_back[members]]
        twins = patches.twin[members]
        if (twins >= 0).any():
            sheets.append(index)
        centroids = patches.centroid[members] * mm
        radius = patches.radius[members] * mm
        mesh = obj.mesh
        facts = {"patches": int(len(members))}
        if is_convex(mesh.vertices, mesh.faces):
            voxels = None
            log.skip(f"no voxel grid for '{obj.name}': a convex object, the shortest path "
                     "inside is the straight line (Euclidean distance)")
        else:
            size = float(np.ptp(mesh.vertices, axis=0).max()) * mm
            voxels = voxelize(mesh.vertices[mesh.faces] * mm, size / knobs["voxels_per_axis"],
                              fill=closed_surface(mesh.faces, mesh.vertices))
            facts["voxels"] = int(voxels.nodes)
            facts["voxel_size_mm"] = float(voxels.voxel_size)
        tree = cKDTree(centroids)
        reach = max_distance_mm + float(radius.max())
        undirected = tree.query_pairs(reach, output_type="ndarray")
        exit_local, incident_local, delta = directed_pairs(
            undirected, centroids, radius, max_distance_mm,
            with_self=knobs["self_term"] == "samples")
        m = _samples_per_edge(delta, radius[incident_local], knobs)
        # compiled, in pair order: the arrays hold a sample per pair of a whole sphere
        offsets, sample_weight, sample_distance, sample_points = scattering_samples(
            exit_local, members[incident_local], m, centroids, patches,
            points=voxels is not None)
        sample_pair = None
        if voxels is not None:
            sample_pair = np.repeat(np.arange(len(exit_local)), np.diff(offsets))
            # one inside test per patch pair, shared by its samples (voxel resolution
            # anyway); one call for every sample: each exit voxel's Dijkstra search runs once
            pair_inside = voxels.segment_inside(centroids[exit_local], centroids[incident_local])
            sample_distance = optical_distances(voxels, centroids[exit_local[sample_pair]],
                                                sample_points, max_distance_mm,
                                                inside=pair_inside[sample_pair])
            del sample_points
        indptr, indices, data = sample_operator(offsets, sample_weight, sample_distance,
                                                grid.radius)
        operator = sparse.csr_matrix((data, indices, indptr),
                                     shape=(len(exit_local), grid.samples))
        inside = sample_distance <= max_distance_mm
        kept_samples = int(np.count_nonzero(inside))
        self_cumulative = self_segment = None
        if knobs["self_term"] == "polar":
            rows, rho, weight = _polar_self_nodes(patches, members)
            self_cumulative, self_segment = _self_operators(grid, len(members), rows,
                                                            np.minimum(rho, max_distance_mm),
                                                            weight)
        samples = None
        if isinstance(obj.material, MixedProfiles):
            material = obj.material
            if len(material.face_labels) != len(mesh.faces):
                raise InputError(f"needs one label per face of '{obj.name}' "
                                 f"({len(mesh.faces)})", field="face_labels",
                                 value=len(material.face_labels))
            start = patches.face_offset[index]
            first_face = patches.patch_faces[patches.patch_face_start[members]] - start
            if sample_pair is None:
                sample_pair = np.repeat(np.arange(len(exit_local)), np.diff(offsets))
            samples = {
                "pair": sample_pair[inside], "weight": sample_weight[inside],
                "distance": sample_distance[inside],
                "fractions": pair_fractions(centroids, mesh.face_centroids * mm,
                                             material.face_labels, exit_local, incident_local,
                                             len(material.profiles), knobs["mix_points"],
                                             material.volume_labels, mm),
                "mix_points": knobs["mix_points"],
                "patch_label": material.face_labels[first_face],
            }
        blocks = [("reflection", append(members, members, exit_local, incident_local), None)]
        if index in sheets:
            # the same samples serve both faces: same side by reflection, across by
            # transmission (Sheng et al. 2014, Sect. 6.1, the petals)
            blocks.append(("reflection", append(twins, twins, exit_local, incident_local),
                           "twin-twin"))
            blocks.append(("transmission", append(members, twins, exit_local, incident_local),
                           append(members, twins)))
            blocks.append(("transmission", append(twins, members, exit_local, incident_local),
                           append(twins, members)))
        segments[index] = blocks
        diffusion = None
        if knobs["finite_object_energy"] and index not in sheets:
            triangles = mesh.vertices[mesh.faces] * mm
            voxel = voxel_size_for(triangles, knobs["diffusion_voxels_per_axis"])
            try:
                diffusion = diffusion_grid(triangles, voxel)
                facts["diffusion_cells"] = int(diffusion.cells)
            except InputError:
                log.skip(f"no finite-object energy for '{obj.name}': no cell of the "
                         f"diffusion grid ({voxel:.3g} mm) lies inside it; raise "
                         "diffusion_voxels_per_axis")
        facts.update({"pairs": int(len(exit_local)), "samples": kept_samples,
                      "seconds": time.perf_counter() - started})
        per_object.append((index, members, len(exit_local), operator, self_cumulative,
                           self_segment, samples, facts, diffusion))
        log.seconds[f"scattering '{obj.name}'"] = facts["seconds"]
        log.notes.setdefault("scattering", {})[obj.name] = facts
    indptr, indices, position = csr_pattern(_gathered(rows_all, filled[-1]),
                                            _gathered(cols_all, filled[-1]), len(patches))
    rows_all.clear()
    cols_all.clear()
    diagonal = position[:len(patches)]
    objects = {}
    for index, members, _, operator, self_c, self_s, samples, facts, diffusion in per_object:
        blocks = []
        for kind, (lo, hi), own in segments[index]:
            if own is None:
                own_position = diagonal[members]
            elif own == "twin-twin":
                own_position = diagonal[patches.twin[members]]
            else:
                own_position = position[own[0]:own[1]]
            blocks.append((kind, position[lo:hi], own_position))
        objects[index] = ObjectScattering(index, members, blocks, operator, self_c, self_s,
                                          samples, facts, diffusion)
    return ScatteringGeometry(indptr, indices, diagonal, grid, objects, tuple(sheets),
                              sheet_thickness_mm)


