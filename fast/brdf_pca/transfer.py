"""The precomputation of BRDF editing with global illumination (Nguyen et al. 2010).

The gather samples laid out as a wavelet square, the transfer rows of Sects. 3-5 and the
multi-bounce gather matrix; :func:`translucent.fast.brdf_pca.precompute` caches the result.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numba
import numpy as np
import scipy.sparse

from ...errors import InputError
from ...materials.brdf_pca import PCABasis, build_pca_basis
from ...materials.brdfs import (
    GAMMA_RANGES,
    MODEL_CODES,
    AnalyticBRDF,
    edited_term,
    uses_half_angle,
)
from ...materials.homogeneous import Lambertian
from ...scenes.lighting import tangent_frames
from ..base import StageLog, StageProgress
from ..sparse_transport import QuantisedRows, SparseRows, nonlinear_approximation, product_rgb
from ..wavelets import haar2d_forward, haar2d_support_weights, quadtree_layout
from .kernels import (
    disk_estimate,
    transfer_rows,
)
from .lighting import (
    gather_pair_bits,
    gather_pair_visibility,
    hemisphere_directions,
    occluded_rays,
    oriented_normals,
    pair_visibility,
    scene_ray_engine,
)

# ---------------------------------------------------------------------------------------
# wavelets over gather samples


#: Gather samples lie on a square of side 2^L by the balanced quadtree of Hašan et al. 2006
#: (:func:`~translucent.fast.wavelets.quadtree_layout`); normals enter the split with this
#: weight times the extent of the samples, so that a split separates two walls meeting at
#: a corner before it cuts a wall.
NORMAL_WEIGHT = 0.25


def _gather_layout(positions, normals) -> np.ndarray:
    """Order of the gather samples row by row over their quadtree square (4^L of them)."""
    level = int(round(math.log(len(positions), 4)))
    extent = float(np.ptp(positions, axis=0).max()) or 1.0
    features = np.concatenate([positions, NORMAL_WEIGHT * extent * normals], axis=1)
    return quadtree_layout(features, level).reshape(-1)


def haar_rows(rows: np.ndarray) -> np.ndarray:
    """Non-standard 2D Haar of rows laid out on the gather square (the last axis)."""
    side = int(round(math.sqrt(rows.shape[-1])))
    shape = rows.shape
    return haar2d_forward(rows.reshape(shape[:-1] + (side, side))).reshape(shape)


def _support_weights(columns: int) -> np.ndarray:
    side = int(round(math.sqrt(columns)))
    return haar2d_support_weights(1, side).astype(np.float32)


def _select(rows: np.ndarray, keep: int, weights: np.ndarray) -> SparseRows:
    """Keep the ``keep`` coefficients of each row largest in magnitude times support.

    Weighting by the square root of a Haar function's support (its largest possible inner
    product with the lighting, Ng et al. 2003's area weighting) keeps the coarse terms
    that carry the product: they are small but meet most of a smooth lighting vector
    (the energy kept, measured against magnitude alone: docs/brdf_pca.md).
    """
    selected = nonlinear_approximation(np.ascontiguousarray(rows * weights,
                                                            dtype=np.float32), 1.0, keep)
    values = selected.values / weights[selected.indices]
    return SparseRows(selected.indptr, selected.indices, values.astype(np.float32),
                      selected.columns)


#: The product of :class:`~translucent.fast.sparse_transport.QuantisedRows` with an RGB
#: vector, compiled without threads for the interactive path: the product is short, and on
#: a loaded machine waking a thread team costs more than the whole serial product
#: (measured: docs/brdf_pca.md). Not cached on disk: the cache is keyed by the Python
#: function, whose threaded build it would load instead.
_product_serial = numba.njit(cache=False)(product_rgb.py_func)


def quantised_product(matrix: QuantisedRows, vector) -> np.ndarray:
    """Multiply quantised rows by an RGB vector: one row of the product per row."""
    out = np.empty((matrix.rows, 3), dtype=np.float32)
    _product_serial(matrix.indptr, matrix.packed, matrix.scales, matrix.index_bits, vector, out)
    return out


def sparse_to_scipy(rows: SparseRows) -> scipy.sparse.csr_matrix:
    """Return the rows as a scipy CSR matrix."""
    return scipy.sparse.csr_matrix((rows.values, rows.indices, rows.indptr),
                                   shape=(rows.rows, rows.columns))


def truncate_rows(matrix: scipy.sparse.csr_matrix, keep: int) -> SparseRows:
    """Keep ``keep`` entries of each row of a CSR matrix of Haar coefficients (:func:`_select`)."""
    parts = []
    weights = _support_weights(matrix.shape[1])
    block = max(1, (1 << 22) // max(matrix.shape[1], 1))
    for start in range(0, matrix.shape[0], block):
        dense = matrix[start:start + block].toarray().astype(np.float32)
        parts.append(_select(dense, keep, weights))
    return SparseRows.concatenate(parts)


def material_parameters(material, basis: PCABasis):
    """Return the scalars and tables a compiled kernel needs for one glossy material."""
    grid = basis.delta
    return (MODEL_CODES[material.model], float(material.f0), float(material.lafortune_c[0]),
            float(material.lafortune_c[1]), float(grid[0]), float(grid[1] - grid[0]),
            np.ascontiguousarray(basis.basis_matrix(), dtype=np.float64))


def disk_transfer(material: AnalyticBRDF, basis: PCABasis, x, n_x, out, position, normal,
                  area, *, points: int, tolerance: float = 0.0, key: int = 0) -> np.ndarray:
    r"""Sub-area estimate of :math:`T_{j,g}(x)` for one pair (Eq. 3, Sect. 5.1).

    The disk :math:`K_g` of area ``area`` centred at ``position`` with normal ``normal``
    is sampled uniformly (R2 points through the concentric map) and
    :math:`|A_g| \langle f_F b_j \cos\theta_x \cos\theta_q / r^2 \rangle` returned for
    j = 0..K; visibility is the gather sample's (not tested here).

    Parameters
    ----------
    material : AnalyticBRDF
    basis : PCABasis
    x, n_x, out : (3,) arrays
        View sample position, unit normal and unit direction to the eye.
    position, normal : (3,) arrays
        Gather sample and its unit normal.
    area : float
        :math:`|A_g|`, scene units squared.
    points : int
        Most points (rounds of :data:`SUBAREA_ROUND`).
    tolerance : float
        Stop when the mean of basis 0 changes by less than this between rounds (0: use
        every point).
    key : int
        Picks the random shift of the sequence.

    Returns
    -------
    ndarray, shape (K + 1,)
    """
    model, f0, c_xy, c_z, grid0, step, matrix = material_parameters(material, basis)
    normal = np.asarray(normal, dtype=np.float64)
    first, second = (v[0] for v in tangent_frames(normal[None]))
    sums = np.empty(matrix.shape[1])
    values = np.empty(matrix.shape[1])
    disk_estimate(np.asarray(x, np.float64), np.asarray(n_x, np.float64),
                   np.asarray(out, np.float64), np.asarray(position, np.float64), normal,
                   float(area), first, second, model, f0, c_xy, c_z, grid0, step, matrix,
                   int(points), float(tolerance), int(key), sums, values)
    return sums


def is_glossy_material(material) -> bool:
    """Return True for an analytic BRDF (a material the method edits)."""
    return isinstance(material, AnalyticBRDF)



def diffuse_albedo(material) -> np.ndarray:
    """Return the diffuse albedo of a Lambertian or an analytic BRDF, per channel."""
    if isinstance(material, Lambertian):
        return np.asarray(material.albedo, dtype=np.float64)
    return np.asarray(material.rho_d, dtype=np.float64)



# ---------------------------------------------------------------------------------------
# the precomputation


@dataclass
class Precomputation:
    r"""What :func:`precompute` stores (kept in the ``brdf_pca`` cache: :mod:`translucent.entries`).

    Attributes
    ----------
    shape : (int, int)
        Image height and width.
    pixel : ndarray of int64, (P,)
        Flat pixel index of each view sample.
    view_position, view_normal, view_out : ndarray, (P, 3)
        Position (scene units), unit normal facing the eye, unit direction to the eye.
    view_object : ndarray of int64, (P,)
    gather_position, gather_normal : ndarray, (G, 3)
        Gather samples row by row over their quadtree square (Hašan et al. 2006); normals
        face the side the sample was seen from.
    gather_area : ndarray, (G,)
        :math:`|A_g|`, scene units squared.
    gather_object : ndarray of int64, (G,)
    gather_glossy : ndarray of bool, (G,)
        Found by a glossy reflection (Eq. 16).
    columns : int
        G, a power of 4: the gather square's side squared.
    diffuse : QuantisedRows, (P, columns)
        :math:`D^w`.
    gather : QuantisedRows, (G, columns)
        :math:`M_s^w` without the albedo :math:`\rho_d(g)/\pi` of the receiving sample.
    transfer : dict
        object index -> (rows, list of K + 1 QuantisedRows): the object's view samples
        (indices into the view arrays) and :math:`T_j^w` for j = 0..K.
    bases : dict
        object index -> :class:`~translucent.materials.brdf_pca.PCABasis`.
    budgets : dict
        object index -> coefficients kept per row of each :math:`T_j^w`.
    knobs : dict
    log : StageLog
    """

    shape: tuple
    pixel: np.ndarray
    view_position: np.ndarray
    view_normal: np.ndarray
    view_out: np.ndarray
    view_object: np.ndarray
    gather_position: np.ndarray
    gather_normal: np.ndarray
    gather_area: np.ndarray
    gather_object: np.ndarray
    gather_glossy: np.ndarray
    columns: int
    diffuse: QuantisedRows
    gather: QuantisedRows
    transfer: dict
    bases: dict
    budgets: dict
    knobs: dict
    log: StageLog = field(default_factory=StageLog)


def _view_samples(scene):
    from ...scenes.gbuffer import gbuffer

    buffer = gbuffer(scene)
    pixel = np.flatnonzero(buffer.hit.reshape(-1))
    out = buffer.view_direction.reshape(-1, 3)[pixel]
    normal = oriented_normals(buffer.normal.reshape(-1, 3)[pixel], out)
    return (buffer.shape, pixel, buffer.position.reshape(-1, 3)[pixel], normal, out,
            buffer.object_id.reshape(-1)[pixel])


def _shoot_gather_samples(scene, view, glossy_view, count, knobs, rng, log):
    """Backward photon shooting from the eye (Sect. 5.1): second hits of reflected rays."""
    from ...scenes.raycast import trace

    _, _, position, normal, out, _ = view
    glossy_count = int(round(count * knobs["glossy_ratio"] / (1.0 + knobs["glossy_ratio"])))
    if not glossy_view.any():
        glossy_count = 0
    wanted = {"diffuse": count - glossy_count, "glossy": glossy_count}
    candidates = {"diffuse": np.arange(len(position)), "glossy": np.flatnonzero(glossy_view)}
    _, offset = scene_ray_engine(scene)
    parts = []
    for kind in ("diffuse", "glossy"):
        have = 0
        for _ in range(12):
            need = wanted[kind] - have
            if need <= 0:
                break
            shots = rng.choice(candidates[kind], size=int(need * 1.5) + 16)
            n = normal[shots]
            if kind == "diffuse":
                directions = hemisphere_directions(n, rng)
            else:
                mirror = 2.0 * np.einsum("ij,ij->i", out[shots], n)[:, None] * n - out[shots]
                directions = hemisphere_directions(n, rng, knobs["glossy_exponent"], mirror)
            above = np.einsum("ij,ij->i", directions, n) > 0
            shots, directions = shots[above], directions[above]
            hits = trace(scene, position[shots] + offset * normal[shots], directions)
            keep = np.flatnonzero(hits.hit)[:need]
            parts.append((hits.position[keep],
                          oriented_normals(hits.shading_normal[keep], -directions[keep]),
                          hits.object_id[keep], np.full(len(keep), kind == "glossy")))
            have += len(keep)
        if have < wanted[kind]:
            log.notes[f"{kind}_gather_shortfall"] = wanted[kind] - have
    if sum(len(p[0]) for p in parts) == 0:
        raise InputError("no gather sample found: no ray reflected from the visible surfaces "
                         "hits another surface", field="scene", value=scene.name)
    return tuple(np.concatenate([p[i] for p in parts]) for i in range(4))


def _gather_areas(scene, positions, normals, per_gather: int, rng) -> np.ndarray:
    """:math:`|A_g|` from uniform surface samples given to the nearest gather sample.

    At least one sample per triangle (Sect. 5.1); a sample goes to the nearest of the 8
    nearest gather samples whose plane it shares (|n_s . n_g| > 0.5) within three gather
    spacings, and is dropped when none qualifies (a surface no gather sample represents)
    or when it does not see that gather sample: floor hidden under a box would otherwise
    swell the disks of the gather samples around the box.
    """
    from scipy.spatial import cKDTree

    areas = [o.mesh.face_areas for o in scene.objects]
    total = float(sum(a.sum() for a in areas))
    budget = per_gather * len(positions)
    sample_points, sample_normals, sample_weights = [], [], []
    for obj, face_area in zip(scene.objects, areas, strict=True):
        counts = np.maximum(1, np.round(budget * face_area / total).astype(np.int64))
        faces = np.repeat(np.arange(len(face_area)), counts)
        r1, r2 = rng.random(len(faces)), rng.random(len(faces))
        root = np.sqrt(r1)
        weights = np.stack([1.0 - root, root * (1.0 - r2), root * r2], axis=1)
        corners = obj.mesh.vertices[obj.mesh.faces[faces]]
        sample_points.append(np.einsum("nk,nkd->nd", weights, corners))
        sample_normals.append(obj.mesh.face_normals[faces])
        sample_weights.append((face_area / counts)[faces])
    points = np.concatenate(sample_points)
    point_normals = np.concatenate(sample_normals)
    weights = np.concatenate(sample_weights)
    spacing = math.sqrt(total / len(positions))
    neighbours = min(8, len(positions))
    distance, index = cKDTree(positions).query(points, k=neighbours)
    distance, index = distance.reshape(len(points), -1), index.reshape(len(points), -1)
    coplanar = np.abs(np.einsum("nd,nkd->nk", point_normals, normals[index])) > 0.5
    usable = coplanar & (distance <= 3.0 * spacing)
    owner = index[np.arange(len(points)), np.argmax(usable, axis=1)]
    assigned = np.flatnonzero(usable.any(axis=1))
    # a sample and its gather sample lie on one plane: lift both ends to the side the
    # gather sample faces (choosing the side by the sign of a near-zero dot product, as
    # for points that face each other, would often pierce the surface between them)
    engine, offset = scene_ray_engine(scene)
    lift = offset * normals[owner[assigned]]
    start = points[assigned] + lift
    segment = positions[owner[assigned]] + lift - start
    length = np.linalg.norm(segment, axis=1)
    direction = segment / np.maximum(length, 1e-300)[:, None]
    direction[length == 0] = (0.0, 0.0, 1.0)
    seen = ~occluded_rays(engine, start.T.astype(np.float32), direction.T.astype(np.float32),
                      np.maximum(length - offset, 0.0).astype(np.float32))
    assigned = assigned[seen]
    area = np.bincount(owner[assigned], weights=weights[assigned], minlength=len(positions))
    # a gather sample no surface sample chose still stands for one sample's area
    return np.maximum(area, total / max(len(points), 1))


def _narrowest_lobe(basis: PCABasis) -> float:
    """Solid angle (sr) of the narrowest lobe of the editing range, in light directions."""
    model = basis.model
    low, high = GAMMA_RANGES[model]
    gamma = low if model in ("ward", "ward_duer", "cook_torrance") else high
    if uses_half_angle(model):
        values = edited_term(model, gamma, basis.delta)
        width = basis.delta[np.argmax(values < values[0] / math.e)]
        return math.pi * (2.0 * width) ** 2  # light directions turn twice as fast as H
    width = math.acos(math.exp(-1.0 / gamma))
    return math.pi * width**2


def _budgets(basis: PCABasis, total: int) -> list[int]:
    """Coefficients per row of T_0..T_K: proportional to the eigenvalues (Sect. 7.2).

    The mean b_0 counts as important as b_1, and no basis gets fewer than 1/(4 (K + 1)) of
    the total (the paper's Cornell floor: 250, 150, 150, 100, 100, 100, 100).
    """
    eigen = basis.eigenvalues
    weights = np.concatenate([[eigen[0]], eigen])
    floor = max(1, total // (4 * len(weights)))
    shares = np.floor((total - floor * len(weights)) * weights / weights.sum()) + floor
    return [int(s) for s in shares]


def _haar_select(rows: np.ndarray, keep: int) -> SparseRows:
    """Haar-transform dense rows over the gather square and keep ``keep`` coefficients."""
    return _select(haar_rows(rows), keep, _support_weights(rows.shape[-1]))


def _transfer(scene, view, gather, columns, knobs, bases, log):
    """D^w for every view sample and T_j^w for those of glossy objects, block by block."""
    _, _, x_all, n_all, out_all, obj_all = view
    positions, normals, area = gather
    count = len(positions)
    first, second = tangent_frames(normals)
    engine, offset = scene_ray_engine(scene)
    block = max(1, knobs["block_pairs"] // count)
    diffuse_parts, transfer, budgets, subarea_points = [], {}, {}, 0
    order = np.argsort(obj_all, kind="stable")
    for index, obj in enumerate(scene.objects):
        members = order[obj_all[order] == index]
        if len(members) == 0:
            continue
        glossy = index in bases
        if glossy:
            basis = bases[index]
            budgets[index] = _budgets(basis, knobs["transfer_coefficients"])
            parameters = material_parameters(obj.material, basis)
            lobe = _narrowest_lobe(basis)
            pieces = [[] for _ in range(basis.size + 1)]
        else:
            parameters = (0, 0.0, 0.0, 0.0, 0.0, 1.0, np.zeros((2, 1)))
            lobe = 1.0
        for start in range(0, len(members), block):
            rows = members[start:start + block]
            x, n_x, out = x_all[rows], n_all[rows], out_all[rows]
            starts, pair_columns, seen = pair_visibility(engine, offset, x, n_x, positions,
                                                          normals)
            diffuse = np.zeros((len(rows), columns), dtype=np.float32)
            bases_count = parameters[6].shape[1]
            rows_glossy = np.zeros((len(rows), bases_count, columns) if glossy else (1, 1, 1),
                                   dtype=np.float32)
            used = np.zeros(len(rows), dtype=np.int64)
            transfer_rows(x, n_x, out, positions, normals, area, first, second, starts,
                           pair_columns, seen, diffuse, rows_glossy, glossy, *parameters,
                           lobe, knobs["subarea"], knobs["subarea_max"],
                           knobs["subarea_tolerance"], int(rows[0]), used)
            subarea_points += int(used.sum())
            diffuse_parts.append((rows, _haar_select(diffuse, knobs["diffuse_coefficients"])))
            if glossy:
                for j in range(bases_count):
                    pieces[j].append(_haar_select(np.ascontiguousarray(rows_glossy[:, j]),
                                                  budgets[index][j]))
        if glossy:
            transfer[index] = (members, [SparseRows.concatenate(p).quantised()
                                         for p in pieces])
    # D rows back in view-sample order
    member_order = np.concatenate([p[0] for p in diffuse_parts])
    stacked = sparse_to_scipy(SparseRows.concatenate([p[1] for p in diffuse_parts]))
    inverse = np.empty(len(member_order), dtype=np.int64)
    inverse[member_order] = np.arange(len(member_order))
    reordered = stacked[inverse]
    diffuse = SparseRows(reordered.indptr.astype(np.int64), reordered.indices.astype(np.int32),
                         reordered.data.astype(np.float32), columns)
    log.notes["subarea_points"] = subarea_points
    return diffuse.quantised(), transfer, budgets


def _gather_matrix(scene, gather, columns, knobs) -> QuantisedRows:
    """M_s^w without the receiving albedo: gather-to-gather diffuse transfer (Sect. 5.2)."""
    positions, normals, area = gather
    count = len(positions)
    engine, offset = scene_ray_engine(scene)
    block = max(1, knobs["block_pairs"] // count)
    parts = []
    parameters = (0, 0.0, 0.0, 0.0, 0.0, 1.0, np.zeros((2, 1)))
    known = gather_pair_bits(count)
    for start in range(0, count, block):
        stop = min(count, start + block)
        x, n_x = positions[start:stop], normals[start:stop]
        starts, pair_columns, seen = gather_pair_visibility(engine, offset, positions,
                                                             normals, start, stop, known)
        rows = np.zeros((stop - start, columns), dtype=np.float32)
        transfer_rows(x, n_x, n_x, positions, normals, area, normals, normals, starts,
                       pair_columns, seen, rows, np.zeros((1, 1, 1), dtype=np.float32), False,
                       *parameters, 1.0, False, 1, 0.0, start,
                       np.zeros(stop - start, dtype=np.int64))
        parts.append(_haar_select(rows, knobs["gather_coefficients"]))
    return SparseRows.concatenate(parts).quantised()


def compute_precomputation(scene, knobs) -> Precomputation:
    """Compute the gather samples, bases and compressed transfers (uncached)."""
    log = StageLog()
    with StageProgress(log, "brdf_pca precomputation", stages=6) as progress:
        return _compute_stages(scene, knobs, log, progress)


def _compute_stages(scene, knobs, log: StageLog, progress: StageProgress) -> Precomputation:
    rng = np.random.default_rng(knobs["seed"])
    with progress.stage("view_samples"):
        view = _view_samples(scene)
    shape, pixel, _, _, _, obj = view
    if len(pixel) == 0:
        raise InputError("the camera sees no surface", field="camera", value=scene.name)
    glossy_objects = [i for i, o in enumerate(scene.objects) if is_glossy_material(o.material)]
    diffuse_names = [o.name for o in scene.objects if not is_glossy_material(o.material)]
    if diffuse_names:
        log.skip(f"no PCA transfer for objects without an analytic BRDF: "
                 f"{', '.join(diffuse_names)} (diffuse transfer D only)")
    with progress.stage("gather_samples"):
        positions, normals, objects, glossy = _shoot_gather_samples(
            scene, view, np.isin(obj, glossy_objects), knobs["gather_samples"], knobs, rng,
            log)
    with progress.stage("gather_areas"):
        area = _gather_areas(scene, positions, normals, knobs["area_samples_per_gather"], rng)
    columns = knobs["gather_samples"]
    missing = columns - len(positions)
    if missing > 0:
        # rays that left the scene: fill the square with copies that stand for no area
        copies = rng.integers(0, len(positions), missing)
        positions, normals = np.concatenate([positions, positions[copies]]), \
            np.concatenate([normals, normals[copies]])
        objects, glossy = np.concatenate([objects, objects[copies]]), \
            np.concatenate([glossy, np.zeros(missing, dtype=bool)])
        area = np.concatenate([area, np.zeros(missing)])
    order = _gather_layout(positions, normals)
    positions, normals, objects, glossy, area = (positions[order], normals[order],
                                                 objects[order], glossy[order], area[order])
    with progress.stage("pca_bases"):
        bases = {i: build_pca_basis(scene.objects[i].material.model, knobs["n_basis"])
                 for i in glossy_objects}
    if not knobs["subarea"]:
        log.skip("no sub-area sampling: switched off by the subarea knob")
    gather = (positions, normals, area)
    with progress.stage("transfer"):
        diffuse, transfer, budgets = _transfer(scene, view, gather, columns, knobs, bases, log)
    with progress.stage("gather_matrix"):
        if knobs["bounces"] == 0:
            log.skip("no multi-bounce series: bounces = 0 (one bounce of indirect light only)")
            empty = SparseRows(np.zeros(len(positions) + 1, dtype=np.int64),
                               np.zeros(0, dtype=np.int32), np.zeros(0, dtype=np.float32),
                               columns)
            matrix = empty.quantised()
        else:
            matrix = _gather_matrix(scene, gather, columns, knobs)
    log.notes.update(view_samples=len(pixel), gather_samples=len(positions),
                     glossy_gather_samples=int(glossy.sum()), columns=columns,
                     budgets={scene.objects[i].name: b for i, b in budgets.items()})
    return Precomputation(shape, pixel, view[2], view[3], view[4], obj, positions, normals,
                          area, objects, glossy, columns, diffuse, matrix, transfer, bases,
                          budgets, dict(knobs), log)
