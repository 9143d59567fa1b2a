r"""BRDF editing and relighting with global illumination by PCA (Nguyen et al. 2010).

The direct-to-indirect transfer of Hašan et al. 2006, extended as Nguyen et al. 2010 do:

* **View samples** :math:`X` are the pixels of the camera's G-buffer; **gather samples**
  :math:`G` are found by backward photon shooting (Sect. 5.1): a ray leaves the eye
  through a random pixel, reflects at the first hit (uniformly over the hemisphere for
  *diffuse* gather samples, with density :math:`\propto (\omega_o\cdot R(\omega_s))^e`,
  :math:`e = 200`, about the mirror direction of a glossy pixel for *glossy* ones, one
  glossy to six diffuse) and its second hit is a gather sample. The area :math:`|A_g|`
  a gather sample stands for is estimated from uniform surface samples, each given to the
  nearest gather sample (Sect. 5.1, "Sub-area samples").
* The glossy lobe of every object with an analytic BRDF is linearised (Sect. 4,
  :mod:`translucent.materials.brdf_pca`): :math:`f = \rho_d/\pi + \rho_s f_F
  \sum_{j=0}^K c_j(\gamma) b_j(\delta)` with :math:`c_0 = 1`.
* The **glossy transfer** :math:`T_{j,g}(x)` (Eqs. 4 and 7) of basis BRDF
  :math:`f_j = b_j f_F` from gather sample :math:`g` to view sample :math:`x` treats
  :math:`g` as a disk :math:`K_g` of area :math:`|A_g|`; where the disk subtends more
  than the narrowest lobe of the editing range, **sub-area samples** drawn uniformly on
  the disk refine it (Eq. 3 with the pdf :math:`r^2 / (|A_g| |N_g\cdot\omega|)`), stopping
  when the estimate has converged (Sect. 5.1). Visibility and radiance are the gather
  sample's (Eq. 4).
* The **diffuse transfer** :math:`D_g(x) = V \cos\theta_x \cos\theta_g |A_g| /
  (r^2 + |A_g|/\pi)` (the disk's cosine-weighted solid angle, bounded as the disk comes
  close) and the **single-bounce gather matrix** :math:`M_s` between gather samples under
  the Lambertian assumption of Sect. 5.2.
* Every row of :math:`T`, :math:`D` and :math:`M_s` is Haar-transformed over the gather
  samples, laid out on a square by the balanced quadtree of Hašan et al. 2006 (so that
  neighbours on the square are neighbours on the surfaces), and only its largest
  coefficients, weighted by the square root of their support, are kept (Sect. 3.4); the
  budget of basis :math:`j` in :math:`T` is proportional to its eigenvalue (Sect. 7.2).
  Rows are
  stored row-indexed (Sect. 6.1) as 16-bit values with 16-bit indices
  (:class:`~translucent.fast.sparse_transport.QuantisedRows`).
* At run time (Eqs. 9 and 17): direct lighting :math:`L_d` on gather samples,
  :math:`L^w = \sum_{n=0}^{N} L_n^w` with :math:`L_n = \rho_d/\pi \odot M_s^w L_{n-1}^w`,
  then per pixel :math:`\rho_d/\pi\, D^w(x) L^w + \rho_s \sum_j c_j(\gamma) T_j^w(x) L^w`
  plus the exact direct lighting of the pixel.
* **Editing** one object's :math:`\gamma` changes only :math:`\mathbf{c}(\gamma)` (Eq. 15)
  and that object's pixels; the products :math:`T_j^w L^w` are kept while the lights stay.
  **Freezing** (Sect. 6.2) replaces the :math:`K+1` rows of an object that is not being
  edited by the single row :math:`\mathbf{c}^T T^w(x)`, truncated again.
* **Relighting** recomputes :math:`L_d`, the series and the frozen products.

Objects without an analytic BRDF get no PCA transfer (only :math:`D`); the run says so in
its :class:`~translucent.fast.base.StageLog`.

The per-pair work of the precomputation (front-facing tests, shadow rays, the transfer
with its sub-area disks, Haar transform and coefficient selection) runs in compiled,
threaded kernels; shadow rays go through the scene's Mitsuba ray engine
(:mod:`translucent.scenes.raycast`). The fixed terms and PCA variables of
:mod:`translucent.materials.brdfs` are compiled again here, per pair, and tested equal.

Limitations inherited from the paper (Table 1): gather samples reflect as Lambertian
surfaces, so light reflected by a glossy surface after the first one (a glossy highlight
seen in a glossy floor, the caustic a glossy floor throws on a wall) is missing; the
camera is fixed. :func:`translucent.reference.brdf_plugins.render_lambertian_gather`
path-traces exactly this transport, the limit the method converges to. Environment lights
are not supported.

References
----------
C. H. Nguyen, M.-H. Kyung, J.-H. Lee, S.-W. Nam: A PCA decomposition for real-time BRDF
editing and relighting with global illumination. Computer Graphics Forum 29(4), 2010.
M. Hašan, F. Pellacini, K. Bala: Direct-to-indirect transfer for cinematic relighting. ACM
TOG 25(3), 2006.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numba
import numpy as np
import scipy.sparse

from ..errors import InputError
from ..image import Image
from ..materials.brdf_pca import PCABasis, build_pca_basis
from ..materials.brdfs import (
    COSINE_FLOOR,
    GAMMA_RANGES,
    MODELS,
    AnalyticBRDF,
    edited_term,
    fixed_term,
    pca_variable,
    uses_half_angle,
)
from ..materials.homogeneous import Lambertian
from ..scenes.scene import (
    ConstantEnvironment,
    DirectionalLight,
    ImageEnvironment,
    PointLight,
    RectangularAreaLight,
    SphereAreaLight,
    SpotLight,
)
from .base import StageLog, StageProgress, refuse_inapplicable, with_defaults
from .sparse_transport import QuantisedRows, SparseRows, _product_rgb, nonlinear_approximation
from .wavelets import haar2d_forward, haar2d_support_weights, quadtree_layout

__all__ = [
    "DEFAULT_KNOBS",
    "BRDFPCAState",
    "Precomputation",
    "add_approx_arguments",
    "applies_to",
    "approx",
    "disk_transfer",
    "precompute",
]

#: Bumped when the stored precomputation changes meaning (cache key).
FORMAT_VERSION = 3

#: The knobs of :func:`precompute` and their defaults.
DEFAULT_KNOBS = {
    # gather samples: 16k in the paper's Cornell box, 64k elsewhere (Sect. 7.2); a power
    # of 4 (they fill the square of the quadtree layout)
    "gather_samples": 16384,
    # one glossy gather sample to six diffuse ones (Sect. 5.1)
    "glossy_ratio": 1.0 / 6.0,
    # e of Eq. 16, "usually set to 200"
    "glossy_exponent": 200.0,
    # K, basis BRDFs besides the mean (6 in every scene of Table 5)
    "n_basis": 6,
    # n of Eq. 17: bounces among gather samples ("two-bounce diffuse" in Figs. 6, 7)
    "bounces": 2,
    # sub-area sampling (Sects. 3.2, 5.1): on/off, most points per disk, convergence
    "subarea": True,
    "subarea_max": 64,
    "subarea_tolerance": 0.02,
    # uniform surface samples per gather sample for the areas |A_g|
    "area_samples_per_gather": 8,
    # Haar coefficients kept per view-sample row of T (over all K + 1 bases), of D, per
    # gather-sample row of M_s, and per row of a frozen c^T T^w
    "transfer_coefficients": 512,
    "diffuse_coefficients": 96,
    "gather_coefficients": 96,
    "frozen_coefficients": 192,
    # samples per area light for direct lighting
    "light_samples": 16,
    # (view sample, gather sample) pairs per block of the transfer computation: each block
    # starts a few threaded kernels, which costs ~25 ms on a loaded machine
    "block_pairs": 1 << 22,
    "seed": 0,
}

#: Sub-area samples are drawn in rounds of this many; convergence is judged between rounds.
SUBAREA_ROUND = 8

#: |M_g| allowed per solid angle of the narrowest lobe: 16 points (4 x 4) across a lobe
#: resolve its peak; pairs whose disk subtends less than 1/16 of a lobe keep one point.
SUBAREA_DENSITY = 16.0

#: Model codes of the compiled kernels, in the order of :data:`MODELS`.
MODEL_CODES = {name: code for code, name in enumerate(MODELS)}
_BP, _W, _WD, _LA, _CT, _AS = range(6)

#: Roberts' R2 sequence (powers of the plastic number): a 2D low-discrepancy sequence whose
#: every prefix is well spread, so sub-area points can be added until convergence. Each
#: pair shifts it by its own hashed offset (Cranley-Patterson rotation).
_PLASTIC = 1.324717957244746
_R2_X, _R2_Y = 1.0 / _PLASTIC, 1.0 / _PLASTIC**2

_SQRT_HALF = math.sqrt(0.5)


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


def _haar_rows(rows: np.ndarray) -> np.ndarray:
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
    that carry the product: measured on the glossy Cornell box, the indirect light of D^w
    with 96 of 4096 terms kept 96 % of its energy this way against 92 % by magnitude
    alone (and 85 % with a 1D Haar over a Z-order curve).
    """
    selected = nonlinear_approximation(np.ascontiguousarray(rows * weights,
                                                            dtype=np.float32), 1.0, keep)
    values = selected.values / weights[selected.indices]
    return SparseRows(selected.indptr, selected.indices, values.astype(np.float32),
                      selected.columns)


#: The product of :class:`~translucent.fast.sparse_transport.QuantisedRows` with an RGB
#: vector, compiled without threads for the interactive path: its rows take a few
#: milliseconds, and on a loaded machine waking a thread team costs more than that
#: (measured on 2 shared cores: 25 ms per threaded call whatever its size, against 5 ms
#: serial for 20k rows of 96). Not cached on disk: the cache is keyed by the Python
#: function, whose threaded build it would load instead.
_product_serial = numba.njit(cache=False)(_product_rgb.py_func)


def _product(matrix: QuantisedRows, vector) -> np.ndarray:
    out = np.empty((matrix.rows, 3), dtype=np.float32)
    _product_serial(matrix.indptr, matrix.packed, matrix.scales, matrix.index_bits, vector, out)
    return out


def _sparse_to_scipy(rows: SparseRows) -> scipy.sparse.csr_matrix:
    return scipy.sparse.csr_matrix((rows.values, rows.indices, rows.indptr),
                                   shape=(rows.rows, rows.columns))


def _truncate(matrix: scipy.sparse.csr_matrix, keep: int) -> SparseRows:
    """Keep ``keep`` entries of each row of a CSR matrix of Haar coefficients (:func:`_select`)."""
    parts = []
    weights = _support_weights(matrix.shape[1])
    block = max(1, (1 << 22) // max(matrix.shape[1], 1))
    for start in range(0, matrix.shape[0], block):
        dense = matrix[start:start + block].toarray().astype(np.float32)
        parts.append(_select(dense, keep, weights))
    return SparseRows.concatenate(parts)


# ---------------------------------------------------------------------------------------
# compiled BRDF terms (the formulas of translucent.materials.brdfs, per pair)


@numba.njit(cache=True, nogil=True)
def _fixed_scalar(model, cos_l, cos_v, l_dot_v, f0):  # pragma: no cover - compiled
    """:func:`translucent.materials.brdfs.fixed_term` for one pair (Table 4)."""
    if model == _BP or model == _LA:
        return 1.0
    nl = max(cos_l, COSINE_FLOOR)
    nv = max(cos_v, COSINE_FLOOR)
    if model == _W:
        return 1.0 / math.sqrt(nl * nv)
    if model == _WD:
        return 1.0 / (nl * nv)
    length = math.sqrt(max(2.0 + 2.0 * l_dot_v, COSINE_FLOOR * COSINE_FLOOR))
    v_dot_h = max(0.5 * length, COSINE_FLOOR)
    one_minus = 1.0 - min(max(v_dot_h, 0.0), 1.0)
    fresnel = f0 + (1.0 - f0) * (one_minus * one_minus) * (one_minus * one_minus) * one_minus
    if model == _AS:
        return fresnel / (v_dot_h * max(nl, nv))
    n_dot_h = max((nl + nv) / length, COSINE_FLOOR)
    shadowing = min(1.0, min(2.0 * n_dot_h * nv / v_dot_h, 2.0 * n_dot_h * nl / v_dot_h))
    cos4 = (n_dot_h * n_dot_h) * (n_dot_h * n_dot_h)
    return shadowing * fresnel / ((nl * nv) * cos4)


@numba.njit(cache=True, nogil=True)
def _variable_scalar(model, cos_l, cos_v, l_dot_v, c_xy, c_z):  # pragma: no cover
    """:func:`translucent.materials.brdfs.pca_variable` for one pair."""
    if model == _LA:
        product = cos_l * cos_v
        return (c_xy * (l_dot_v - product) + c_z * product) / max(abs(c_xy), abs(c_z))
    length = math.sqrt(max(2.0 + 2.0 * l_dot_v, COSINE_FLOOR * COSINE_FLOOR))
    return min(max((cos_l + cos_v) / length, 0.0), 1.0)


@numba.njit(cache=True, nogil=True)
def _glossy_basis(model, cos_l, cos_v, l_dot_v, f0, c_xy, c_z, grid0, step, matrix,
                  out):  # pragma: no cover - compiled
    """Write f_F b_j (j = 0..K) of one direction pair into ``out`` (Eq. 6, Table 4)."""
    count = out.shape[0]
    if cos_l <= 0.0 or cos_v <= 0.0:
        for j in range(count):
            out[j] = 0.0
        return
    variable = _variable_scalar(model, cos_l, cos_v, l_dot_v, c_xy, c_z)
    if model == _LA:
        if variable <= 0.0:
            for j in range(count):
                out[j] = 0.0
            return
        delta = variable
    else:
        delta = math.acos(variable)
    fixed = _fixed_scalar(model, cos_l, cos_v, l_dot_v, f0)
    last = matrix.shape[0] - 1
    position = min(max((delta - grid0) / step, 0.0), float(last))
    index = min(int(position), last - 1)
    fraction = position - index
    for j in range(count):
        out[j] = fixed * (matrix[index, j] * (1.0 - fraction) + matrix[index + 1, j] * fraction)


# ---------------------------------------------------------------------------------------
# pairs, rays and transfer rows (compiled)


@numba.njit(cache=True, nogil=True)
def _front_facing(x, n_x, positions, normals, b, g):  # pragma: no cover - compiled
    """Whether view sample b and gather sample g are in front of each other."""
    dx = positions[g, 0] - x[b, 0]
    dy = positions[g, 1] - x[b, 1]
    dz = positions[g, 2] - x[b, 2]
    facing = dx * n_x[b, 0] + dy * n_x[b, 1] + dz * n_x[b, 2]
    back = dx * normals[g, 0] + dy * normals[g, 1] + dz * normals[g, 2]
    return facing > 0.0 and back < 0.0


@numba.njit(cache=True, parallel=True)
def _front_counts(x, n_x, positions, normals, counts):  # pragma: no cover - compiled
    for b in numba.prange(x.shape[0]):
        found = 0
        for g in range(positions.shape[0]):
            if _front_facing(x, n_x, positions, normals, b, g):
                found += 1
        counts[b] = found


@numba.njit(cache=True, parallel=True)
def _front_rays(x, n_x, positions, normals, offset, starts, columns, origins, directions,
                reach):  # pragma: no cover - compiled
    """Fill the shadow rays of the front-facing pairs of a block.

    Both ends move ``offset`` along their normals, the convention of
    :func:`translucent.scenes.raycast.visible`.
    """
    for b in numba.prange(x.shape[0]):
        k = starts[b]
        for g in range(positions.shape[0]):
            if not _front_facing(x, n_x, positions, normals, b, g):
                continue
            ox = x[b, 0] + offset * n_x[b, 0]
            oy = x[b, 1] + offset * n_x[b, 1]
            oz = x[b, 2] + offset * n_x[b, 2]
            ex = positions[g, 0] + offset * normals[g, 0] - ox
            ey = positions[g, 1] + offset * normals[g, 1] - oy
            ez = positions[g, 2] + offset * normals[g, 2] - oz
            length = math.sqrt(ex * ex + ey * ey + ez * ez)
            columns[k] = g
            origins[0, k] = ox
            origins[1, k] = oy
            origins[2, k] = oz
            if length <= 2.0 * offset:
                directions[0, k] = 0.0
                directions[1, k] = 0.0
                directions[2, k] = 1.0
                reach[k] = 0.0
            else:
                directions[0, k] = ex / length
                directions[1, k] = ey / length
                directions[2, k] = ez / length
                reach[k] = length - offset
            k += 1


@numba.njit(cache=True, nogil=True)
def _hash_unit(key):  # pragma: no cover - compiled
    """Two numbers in [0, 1) from an integer key (splitmix64)."""
    z = np.uint64(key) + np.uint64(0x9E3779B97F4A7C15)
    z = (z ^ (z >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
    z = (z ^ (z >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
    z = z ^ (z >> np.uint64(31))
    return (float(z >> np.uint64(40)) / 16777216.0,
            float((z >> np.uint64(16)) & np.uint64(0xFFFFFF)) / 16777216.0)


@numba.njit(cache=True, nogil=True)
def _concentric_disk(u, v):  # pragma: no cover - compiled
    """Shirley-Chiu map of the unit square onto the unit disk (area-preserving)."""
    a = 2.0 * u - 1.0
    b = 2.0 * v - 1.0
    if a == 0.0 and b == 0.0:
        return 0.0, 0.0
    if abs(a) > abs(b):
        radius = a
        angle = 0.25 * math.pi * (b / a)
    else:
        radius = b
        angle = 0.5 * math.pi - 0.25 * math.pi * (a / b)
    return radius * math.cos(angle), radius * math.sin(angle)


@numba.njit(cache=True, nogil=True)
def _disk_estimate(x, n_x, out, g_pos, g_nor, area, first, second, model, f0, c_xy, c_z,
                   grid0, step, matrix, budget, tolerance, key, sums,
                   values):  # pragma: no cover - compiled
    """Estimate Eq. 3 with points of the disk K_g; return the number of points used.

    ``sums`` receives the mean of f_F b_j cos cos |A_g| / r^2 over them.
    """
    radius = math.sqrt(area / math.pi)
    min_r2 = area / (math.pi * budget)
    count = sums.shape[0]
    for j in range(count):
        sums[j] = 0.0
    cos_v = out[0] * n_x[0] + out[1] * n_x[1] + out[2] * n_x[2]
    shift_u, shift_v = _hash_unit(key)
    used = 0
    previous = np.nan
    while used < budget:
        for _ in range(SUBAREA_ROUND):
            u = (shift_u + used * _R2_X) % 1.0
            v = (shift_v + used * _R2_Y) % 1.0
            px, py = _concentric_disk(u, v)
            qx = g_pos[0] + radius * (px * first[0] + py * second[0]) - x[0]
            qy = g_pos[1] + radius * (px * first[1] + py * second[1]) - x[1]
            qz = g_pos[2] + radius * (px * first[2] + py * second[2]) - x[2]
            r2 = qx * qx + qy * qy + qz * qz
            used += 1
            if r2 <= 0.0:
                continue
            inverse = 1.0 / math.sqrt(r2)
            wx, wy, wz = qx * inverse, qy * inverse, qz * inverse
            cos_x = wx * n_x[0] + wy * n_x[1] + wz * n_x[2]
            cos_q = -(wx * g_nor[0] + wy * g_nor[1] + wz * g_nor[2])
            if cos_x <= 0.0 or cos_q <= 0.0:
                continue
            geometry = cos_x * cos_q * area / max(r2, min_r2)
            l_dot_v = wx * out[0] + wy * out[1] + wz * out[2]
            _glossy_basis(model, cos_x, cos_v, l_dot_v, f0, c_xy, c_z, grid0, step, matrix,
                          values)
            for j in range(count):
                sums[j] += geometry * values[j]
        mean = sums[0] / used
        if abs(mean - previous) <= tolerance * max(abs(mean), 1e-300):
            break
        previous = mean
    for j in range(count):
        sums[j] /= used
    return used


@numba.njit(cache=True, parallel=True)
def _transfer_rows(x, n_x, out, positions, normals, area, first, second, starts, columns,
                   seen, diffuse, glossy_rows, is_glossy, model, f0, c_xy, c_z, grid0, step,
                   matrix, lobe, subarea, subarea_max, tolerance, row_offset,
                   used):  # pragma: no cover - compiled
    """D (and, for glossy rows, T_j) of every visible front-facing pair of a block."""
    count = positions.shape[0]
    bases = matrix.shape[1]
    for b in numba.prange(x.shape[0]):
        values = np.empty(bases)
        sums = np.empty(bases)
        cos_v = out[b, 0] * n_x[b, 0] + out[b, 1] * n_x[b, 1] + out[b, 2] * n_x[b, 2]
        total_used = 0
        for k in range(starts[b], starts[b + 1]):
            if not seen[k]:
                continue
            g = columns[k]
            dx = positions[g, 0] - x[b, 0]
            dy = positions[g, 1] - x[b, 1]
            dz = positions[g, 2] - x[b, 2]
            r2 = dx * dx + dy * dy + dz * dz
            inverse = 1.0 / math.sqrt(r2)
            wx, wy, wz = dx * inverse, dy * inverse, dz * inverse
            cos_x = wx * n_x[b, 0] + wy * n_x[b, 1] + wz * n_x[b, 2]
            cos_g = -(wx * normals[g, 0] + wy * normals[g, 1] + wz * normals[g, 2])
            # the disk's cosine-weighted solid angle, bounded as the disk comes close
            factor = cos_x * cos_g * area[g] / (r2 + area[g] / math.pi)
            diffuse[b, g] = factor
            if not is_glossy:
                continue
            l_dot_v = wx * out[b, 0] + wy * out[b, 1] + wz * out[b, 2]
            budget = 1
            if subarea:
                solid_angle = area[g] * cos_g / r2
                budget = min(subarea_max, int(math.ceil(SUBAREA_DENSITY * solid_angle / lobe)))
            if budget > 1:
                used_here = _disk_estimate(x[b], n_x[b], out[b], positions[g], normals[g],
                                           area[g], first[g], second[g], model, f0, c_xy,
                                           c_z, grid0, step, matrix, budget, tolerance,
                                           (row_offset + b) * count + g,
                                           sums, values)
                total_used += used_here
                for j in range(bases):
                    glossy_rows[b, j, g] = sums[j]
            else:
                _glossy_basis(model, cos_x, cos_v, l_dot_v, f0, c_xy, c_z, grid0, step,
                              matrix, values)
                for j in range(bases):
                    glossy_rows[b, j, g] = factor * values[j]
        used[b] = total_used


def _material_parameters(material, basis: PCABasis):
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
    model, f0, c_xy, c_z, grid0, step, matrix = _material_parameters(material, basis)
    normal = np.asarray(normal, dtype=np.float64)
    first, second = (v[0] for v in _tangent_frames(normal[None]))
    sums = np.empty(matrix.shape[1])
    values = np.empty(matrix.shape[1])
    _disk_estimate(np.asarray(x, np.float64), np.asarray(n_x, np.float64),
                   np.asarray(out, np.float64), np.asarray(position, np.float64), normal,
                   float(area), first, second, model, f0, c_xy, c_z, grid0, step, matrix,
                   int(points), float(tolerance), int(key), sums, values)
    return sums


# ---------------------------------------------------------------------------------------
# geometry helpers


def _oriented(normals, towards):
    """Flip unit normals to the side of the unit vectors ``towards``."""
    side = np.where(np.einsum("...d,...d->...", normals, towards) < 0, -1.0, 1.0)
    return normals * side[..., None]


def _tangent_frames(normals):
    helper = np.where(np.abs(normals[:, :1]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])
    first = np.cross(normals, helper)
    first /= np.linalg.norm(first, axis=1, keepdims=True)
    return first, np.cross(normals, first)


def _hemisphere_directions(normals, rng, exponent=None, axes=None):
    """Directions about ``normals``: uniform (exponent None) or power-cosine about ``axes``."""
    count = len(normals)
    u1, u2 = rng.random(count), rng.random(count)
    cos_t = u1 if exponent is None else u1 ** (1.0 / (exponent + 1.0))
    sin_t = np.sqrt(np.clip(1.0 - cos_t**2, 0.0, None))
    phi = 2.0 * math.pi * u2
    centre = normals if axes is None else axes
    first, second = _tangent_frames(centre)
    return (cos_t[:, None] * centre + (sin_t * np.cos(phi))[:, None] * first
            + (sin_t * np.sin(phi))[:, None] * second)


def _engine(scene):
    from ..scenes.raycast import OFFSET_FRACTION, ray_engine

    engine = ray_engine(scene)
    return engine, engine.diagonal * OFFSET_FRACTION


def _occluded(engine, origins, directions, reach) -> np.ndarray:
    """Any-hit tests of rays given as (3, N) float32 arrays, through the scene's engine."""
    # (N, 3) views of the (3, N) arrays: the Mitsuba engine's rays take their transposes,
    # so a batch within one of its calls is not copied
    return engine.occluded_unit(origins.T, directions.T, reach)


def _pair_visibility(engine, offset, x, n_x, positions, normals):
    """Front-facing (view, gather) pairs of a block and whether each is unoccluded.

    Returns ``starts`` (B + 1,), the gather index of each pair and its visibility.
    """
    counts = np.zeros(len(x), dtype=np.int64)
    _front_counts(x, n_x, positions, normals, counts)
    starts = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
    total = int(starts[-1])
    columns = np.empty(total, dtype=np.int64)
    origins = np.empty((3, total), dtype=np.float32)
    directions = np.empty((3, total), dtype=np.float32)
    reach = np.empty(total, dtype=np.float32)
    _front_rays(x, n_x, positions, normals, offset, starts, columns, origins, directions, reach)
    seen = ~_occluded(engine, origins, directions, reach) | (reach == 0)
    return starts, columns, seen


# ---------------------------------------------------------------------------------------
# lights


def _check_lights(lights) -> None:
    for index, light in enumerate(lights):
        if isinstance(light, (ConstantEnvironment, ImageEnvironment)):
            raise InputError("environment lights are not supported by the BRDF-editing method "
                             "(point, spot, directional, rect and sphere lights are)",
                             field=f"lights[{index}]", value=type(light).__name__)
        if not isinstance(light, (PointLight, SpotLight, DirectionalLight,
                                  RectangularAreaLight, SphereAreaLight)):
            raise InputError("unknown light type", field=f"lights[{index}]",
                             value=type(light).__name__)


def _emitter_points(light, count: int, rng):
    """Return fixed sample points of a light: positions, RGB weights, emitter normals."""
    if isinstance(light, (PointLight, SpotLight)):
        return light.position[None], light.intensity[None], None
    if isinstance(light, RectangularAreaLight):
        side = int(math.ceil(math.sqrt(count)))
        cells = np.arange(side * side)[:count]
        u = (cells % side + rng.random(count)) / side * 2.0 - 1.0
        v = (cells // side + rng.random(count)) / side * 2.0 - 1.0
        positions = light.center + u[:, None] * light.u_axis + v[:, None] * light.v_axis
        weights = np.broadcast_to(light.radiance * light.area / count, (count, 3))
        return positions, weights, np.broadcast_to(light.normal, (count, 3))
    # sphere: stratified uniform points on the surface, each 1/count of its area
    z = 1.0 - 2.0 * (np.arange(count) + rng.random(count)) / count
    phi = 2.0 * math.pi * rng.random(count)
    radial = np.sqrt(np.clip(1.0 - z**2, 0.0, None))
    outward = np.stack([radial * np.cos(phi), radial * np.sin(phi), z], axis=1)
    weights = np.broadcast_to(light.radiance * 4.0 * math.pi * light.radius**2 / count,
                              (count, 3))
    return light.center + light.radius * outward, weights, outward


def _shadowed(engine, offset, points, normals, wi, reach, lit) -> np.ndarray:
    rows = np.flatnonzero(lit)
    origins = (points[rows] + offset * normals[rows]).T.astype(np.float32)
    blocked = np.zeros(len(points), dtype=bool)
    if len(rows):
        limit = np.maximum(reach[rows] - offset, 0.0) if np.ndim(reach) else \
            np.full(len(rows), np.float32(np.finfo(np.float32).max))
        blocked[rows] = _occluded(engine, origins, wi[rows].T.astype(np.float32),
                                  limit.astype(np.float32))
    return blocked


def _direct_samples(scene, lights, points, normals, samples: int, seed: int):
    r"""Per point and light sample: the direction to the light and the irradiance it brings.

    Returns ``(wi, irradiance)`` of shapes (N, S, 3): the reflected radiance towards
    :math:`\omega_o` is :math:`\sum_s f(\omega_{i,s}, \omega_o) E_s`, shadows included.
    Point, spot (Mitsuba's linear falloff) and directional lights are exact; rectangles
    and spheres use ``samples`` fixed stratified points each.
    """
    engine, offset = _engine(scene)
    rng = np.random.default_rng(seed)
    directions, irradiance = [], []
    for light in lights:
        if isinstance(light, DirectionalLight):
            wi = np.ascontiguousarray(np.broadcast_to(-light.direction, points.shape))
            strength = np.clip(normals @ -light.direction, 0.0, None)
            strength[_shadowed(engine, offset, points, normals, wi, np.inf, strength > 0)] = 0
            directions.append(wi[:, None])
            irradiance.append((strength[:, None] * light.irradiance)[:, None])
            continue
        positions, weights, emitter_normals = _emitter_points(light, samples, rng)
        for k, position in enumerate(positions):
            to_light = position - points
            distance = np.sqrt(np.maximum(np.einsum("ij,ij->i", to_light, to_light), 1e-300))
            wi = to_light / distance[:, None]
            strength = np.clip(np.einsum("ij,ij->i", normals, wi), 0.0, None) / distance**2
            if emitter_normals is not None:
                strength = strength * np.clip(-(wi @ emitter_normals[k]), 0.0, None)
            if isinstance(light, SpotLight):
                strength = strength * light.falloff(-wi)
            strength[_shadowed(engine, offset, points, normals, wi, distance, strength > 0)] = 0
            directions.append(wi[:, None])
            irradiance.append((strength[:, None] * weights[k])[:, None])
    if not directions:
        empty = np.zeros((len(points), 0, 3))
        return empty, empty
    return np.concatenate(directions, axis=1), np.concatenate(irradiance, axis=1)


# ---------------------------------------------------------------------------------------
# materials and knobs


def _is_glossy(material) -> bool:
    return isinstance(material, AnalyticBRDF)


def _diffuse_albedo(material) -> np.ndarray:
    if isinstance(material, Lambertian):
        return np.asarray(material.albedo, dtype=np.float64)
    return np.asarray(material.rho_d, dtype=np.float64)


def applies_to(scene) -> str | None:
    """None when every object is Lambertian or an analytic BRDF and one is an analytic BRDF.

    Nguyen et al. 2010 edit analytic BRDFs of opaque surfaces lit by point-like and area
    lights; translucent media, environment lights and scenes with nothing to edit are not
    theirs.
    """
    for obj in scene.objects:
        if not isinstance(obj.material, (AnalyticBRDF, Lambertian)):
            return (f"object '{obj.name}' has a {type(obj.material).__name__} material; the "
                    "BRDF-editing method takes opaque surfaces (Lambertian or analytic BRDFs)")
    if not any(_is_glossy(o.material) for o in scene.objects):
        return "no object has an analytic BRDF: there is nothing to edit"
    try:
        _check_lights(scene.lights)
    except InputError as error:
        return str(error)
    return None


#: Integer knobs and their accepted ranges.
_INTEGER_KNOBS = {"gather_samples": (16, 1 << 22), "n_basis": (1, 32), "bounces": (0, 64),
                  "subarea_max": (1, 4096), "area_samples_per_gather": (1, 256),
                  "transfer_coefficients": (1, 1 << 20), "diffuse_coefficients": (1, 1 << 20),
                  "gather_coefficients": (1, 1 << 20), "frozen_coefficients": (1, 1 << 20),
                  "light_samples": (1, 4096), "block_pairs": (1 << 10, 1 << 26),
                  "seed": (0, 2**31 - 1)}

#: Real knobs and their accepted ranges.
_REAL_KNOBS = {"glossy_ratio": (0.0, 1.0), "glossy_exponent": (1.0, 1e5),
               "subarea_tolerance": (0.0, 1.0)}


def _resolve_knobs(knobs: dict) -> dict:
    resolved = with_defaults(knobs, DEFAULT_KNOBS)
    for name, (low, high) in _INTEGER_KNOBS.items():
        value = resolved[name]
        if isinstance(value, bool) or not isinstance(value, (int, np.integer, float)) \
                or int(value) != value or not low <= int(value) <= high:
            raise InputError(f"must be an integer in [{low}, {high}]", field=name, value=value)
        resolved[name] = int(value)
    gathers = resolved["gather_samples"]
    if gathers & (gathers - 1) or int(round(math.log2(gathers))) % 2:
        raise InputError("must be a power of 4 (the gather samples fill the square of the "
                         "quadtree layout of Hasan et al. 2006): 256, 1024, 4096, 16384, "
                         "65536, ...", field="gather_samples", value=gathers)
    for name, (low, high) in _REAL_KNOBS.items():
        value = float(resolved[name])
        if not (math.isfinite(value) and low <= value <= high):
            raise InputError(f"must be in [{low:g}, {high:g}]", field=name,
                             value=resolved[name])
        resolved[name] = value
    if not isinstance(resolved["subarea"], (bool, np.bool_)):
        raise InputError("must be true or false", field="subarea", value=resolved["subarea"])
    resolved["subarea"] = bool(resolved["subarea"])
    return resolved


def _structure_key(scene) -> list:
    """Return what the precomputation depends on besides geometry and camera.

    Which objects are glossy and their fixed-term parameters: never gamma, rho_s, rho_d
    or the lights.
    """
    out = []
    for obj in scene.objects:
        material = obj.material
        if _is_glossy(material):
            out.append([obj.name, material.model, material.f0, list(material.lafortune_c)])
        else:
            out.append([obj.name, "diffuse"])
    return out


# ---------------------------------------------------------------------------------------
# the precomputation


@dataclass
class Precomputation:
    r"""What :func:`precompute` stores (pickled in the ``brdf_pca`` cache).

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
    from ..scenes.raycast import gbuffer

    buffer = gbuffer(scene)
    pixel = np.flatnonzero(buffer.hit.reshape(-1))
    out = buffer.view_direction.reshape(-1, 3)[pixel]
    normal = _oriented(buffer.normal.reshape(-1, 3)[pixel], out)
    return (buffer.shape, pixel, buffer.position.reshape(-1, 3)[pixel], normal, out,
            buffer.object_id.reshape(-1)[pixel])


def _shoot_gather_samples(scene, view, glossy_view, count, knobs, rng, log):
    """Backward photon shooting from the eye (Sect. 5.1): second hits of reflected rays."""
    from ..scenes.raycast import trace

    _, _, position, normal, out, _ = view
    glossy_count = int(round(count * knobs["glossy_ratio"] / (1.0 + knobs["glossy_ratio"])))
    if not glossy_view.any():
        glossy_count = 0
    wanted = {"diffuse": count - glossy_count, "glossy": glossy_count}
    candidates = {"diffuse": np.arange(len(position)), "glossy": np.flatnonzero(glossy_view)}
    _, offset = _engine(scene)
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
                directions = _hemisphere_directions(n, rng)
            else:
                mirror = 2.0 * np.einsum("ij,ij->i", out[shots], n)[:, None] * n - out[shots]
                directions = _hemisphere_directions(n, rng, knobs["glossy_exponent"], mirror)
            above = np.einsum("ij,ij->i", directions, n) > 0
            shots, directions = shots[above], directions[above]
            hits = trace(scene, position[shots] + offset * normal[shots], directions)
            keep = np.flatnonzero(hits.hit)[:need]
            parts.append((hits.position[keep],
                          _oriented(hits.shading_normal[keep], -directions[keep]),
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
    engine, offset = _engine(scene)
    lift = offset * normals[owner[assigned]]
    start = points[assigned] + lift
    segment = positions[owner[assigned]] + lift - start
    length = np.linalg.norm(segment, axis=1)
    direction = segment / np.maximum(length, 1e-300)[:, None]
    direction[length == 0] = (0.0, 0.0, 1.0)
    seen = ~_occluded(engine, start.T.astype(np.float32), direction.T.astype(np.float32),
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
    return _select(_haar_rows(rows), keep, _support_weights(rows.shape[-1]))


def _transfer(scene, view, gather, columns, knobs, bases, log):
    """D^w for every view sample and T_j^w for those of glossy objects, block by block."""
    _, _, x_all, n_all, out_all, obj_all = view
    positions, normals, area = gather
    count = len(positions)
    first, second = _tangent_frames(normals)
    engine, offset = _engine(scene)
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
            parameters = _material_parameters(obj.material, basis)
            lobe = _narrowest_lobe(basis)
            pieces = [[] for _ in range(basis.size + 1)]
        else:
            parameters = (0, 0.0, 0.0, 0.0, 0.0, 1.0, np.zeros((2, 1)))
            lobe = 1.0
        for start in range(0, len(members), block):
            rows = members[start:start + block]
            x, n_x, out = x_all[rows], n_all[rows], out_all[rows]
            starts, pair_columns, seen = _pair_visibility(engine, offset, x, n_x, positions,
                                                          normals)
            diffuse = np.zeros((len(rows), columns), dtype=np.float32)
            bases_count = parameters[6].shape[1]
            rows_glossy = np.zeros((len(rows), bases_count, columns) if glossy else (1, 1, 1),
                                   dtype=np.float32)
            used = np.zeros(len(rows), dtype=np.int64)
            _transfer_rows(x, n_x, out, positions, normals, area, first, second, starts,
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
    stacked = _sparse_to_scipy(SparseRows.concatenate([p[1] for p in diffuse_parts]))
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
    engine, offset = _engine(scene)
    block = max(1, knobs["block_pairs"] // count)
    parts = []
    parameters = (0, 0.0, 0.0, 0.0, 0.0, 1.0, np.zeros((2, 1)))
    for start in range(0, count, block):
        stop = min(count, start + block)
        x, n_x = positions[start:stop], normals[start:stop]
        starts, pair_columns, seen = _pair_visibility(engine, offset, x, n_x, positions,
                                                      normals)
        rows = np.zeros((stop - start, columns), dtype=np.float32)
        _transfer_rows(x, n_x, n_x, positions, normals, area, normals, normals, starts,
                       pair_columns, seen, rows, np.zeros((1, 1, 1), dtype=np.float32), False,
                       *parameters, 1.0, False, 1, 0.0, start,
                       np.zeros(stop - start, dtype=np.int64))
        parts.append(_haar_select(rows, knobs["gather_coefficients"]))
    return SparseRows.concatenate(parts).quantised()


def _compute(scene, knobs) -> Precomputation:
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
    glossy_objects = [i for i, o in enumerate(scene.objects) if _is_glossy(o.material)]
    diffuse_names = [o.name for o in scene.objects if not _is_glossy(o.material)]
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


def precompute(scene, **knobs) -> BRDFPCAState:
    r"""Precompute the transfers of Sects. 3-5 of Nguyen et al. 2010; cached on disk.

    The cache key holds the geometry, the camera, the knobs and which objects carry which
    BRDF model (and its fixed-term parameters ``f0``, ``lafortune_c``) -- never gamma,
    :math:`\rho_s`, :math:`\rho_d` or the lights, which the state edits interactively.

    Parameters
    ----------
    scene : Scene
    **knobs
        See :data:`DEFAULT_KNOBS`.

    Returns
    -------
    BRDFPCAState

    Raises
    ------
    InputError
        When the method does not apply (:func:`applies_to`), or a knob is unknown or out
        of range.
    """
    from ..cache import Cache, content_hash

    refuse_inapplicable(scene, applies_to(scene), "the BRDF-editing method does not apply")
    resolved = _resolve_knobs(knobs)
    key = content_hash("brdf_pca", FORMAT_VERSION, scene.geometry_key(),
                       scene.camera.cache_key(), resolved, _structure_key(scene))
    cache = Cache("brdf_pca")
    stored = cache.load_pickle(key)
    if isinstance(stored, Precomputation):
        stored.log.notes["cache"] = "hit"
        return BRDFPCAState(scene, stored)
    started = time.perf_counter()
    data = _compute(scene, resolved)
    data.log.seconds["total"] = time.perf_counter() - started
    data.log.notes["cache"] = "miss"
    cache.store_pickle(key, data)
    return BRDFPCAState(scene, data)


# ---------------------------------------------------------------------------------------
# the interactive state


def _combine(matrices, coefficients) -> scipy.sparse.csr_matrix:
    combined = None
    for weight, matrix in zip(coefficients, matrices, strict=True):
        term = _sparse_to_scipy(matrix.dequantised()) * float(weight)
        combined = term if combined is None else combined + term
    return combined.tocsr()


class BRDFPCAState:
    r"""The result of :func:`precompute`: edits gamma per object and relights interactively.

    Parameters
    ----------
    scene : Scene
        Its lights and materials are the starting point of editing.
    data : Precomputation

    Attributes
    ----------
    materials : dict
        object name -> current material.
    lights : tuple
    frozen : dict
        object name -> (gamma, frozen rows :math:`\mathbf{c}(\gamma)^T T^w`), Sect. 6.2.
    log : StageLog
    """

    def __init__(self, scene, data: Precomputation):
        self.scene = scene
        self.data = data
        self.log = data.log
        self.knobs = data.knobs
        self.materials = {o.name: o.material for o in scene.objects}
        self.frozen: dict = {}
        self._transfer = {scene.objects[i].name: matrices
                          for i, (_, matrices) in data.transfer.items()}
        self._members = {scene.objects[i].name: rows for i, (rows, _) in data.transfer.items()}
        self._index = {o.name: i for i, o in enumerate(scene.objects)}
        self.lights = tuple(scene.lights)
        self._lit = False
        self._products: dict = {}
        self._glossy_parts: dict = {}
        self._coefficients: dict = {}
        self._albedos: dict = {}

    @property
    def glossy_objects(self) -> list[str]:
        """Names of the objects whose gamma can be edited."""
        return list(self._members)

    def coefficients(self, name) -> np.ndarray:
        r"""Return :math:`\mathbf{c}(\gamma)` of object ``name`` (Eqs. 13, 15), cached by gamma."""
        material = self.materials[name]
        cached = self._coefficients.get(name)
        if cached is None or cached[0] != material.gamma:
            basis = self.data.bases[self._index[name]]
            cached = (material.gamma, basis.coefficients(material.gamma))
            self._coefficients[name] = cached
        return cached[1]

    # -- lighting ----------------------------------------------------------------------
    def _albedo(self, which: str) -> np.ndarray:
        r"""Return :math:`\rho_d/\pi` of every gather (``which="gather"``) or view sample."""
        table = np.array([_diffuse_albedo(self.materials[o.name]) for o in self.scene.objects])
        key = table.tobytes()
        cached = self._albedos.get(which)
        if cached is None or cached[0] != key:
            objects = self.data.gather_object if which == "gather" else self.data.view_object
            cached = (key, (table[objects] / math.pi).astype(np.float32))
            self._albedos[which] = cached
        return cached[1]

    def _wavelet(self, values) -> np.ndarray:
        """Return :math:`L^w`: radiance per gather sample (G, 3) in Haar coefficients."""
        return np.ascontiguousarray(_haar_rows(np.ascontiguousarray(values.T,
                                                                    dtype=np.float32)).T)

    def _relight(self):
        """Compute direct lighting, the Eq. 17 series and the view-sample caches (relight)."""
        data = self.data
        samples, seed = self.knobs["light_samples"], self.knobs["seed"]
        _, gather_e = _direct_samples(self.scene, self.lights, data.gather_position,
                                      data.gather_normal, samples, seed)
        albedo_g = self._albedo("gather")
        direct_g = albedo_g * gather_e.sum(axis=1).astype(np.float32)
        total, current = direct_g.copy(), direct_g
        count = len(direct_g)
        for _ in range(self.knobs["bounces"]):        # Eq. 17
            current = albedo_g * _product(data.gather, self._wavelet(current))[:count]
            total += current
        self._radiance_w = self._wavelet(total)
        wi, view_e = _direct_samples(self.scene, self.lights, data.view_position,
                                     data.view_normal, samples, seed + 1)
        albedo_x = self._albedo("view")
        direct = albedo_x * view_e.sum(axis=1)
        indirect = albedo_x * _product(data.diffuse, self._radiance_w)
        self._parts = {"direct": direct, "indirect": indirect, "all": direct + indirect}
        self._view_lighting = {}
        for name, rows in self._members.items():
            material = self.materials[name]
            n_x, out = data.view_normal[rows], data.view_out[rows]
            cos_l = np.einsum("psd,pd->ps", wi[rows], n_x)
            cos_v = np.einsum("pd,pd->p", out, n_x)[:, None]
            l_dot_v = np.einsum("psd,pd->ps", wi[rows], out)
            fixed = fixed_term(material.model, cos_l, cos_v, l_dot_v, f0=material.f0)
            variable = pca_variable(material.model, cos_l, cos_v, l_dot_v,
                                    lafortune_c=material.lafortune_c)
            weight = np.where((cos_l > 0) & (cos_v > 0), fixed, 0.0)[..., None] * view_e[rows]
            self._view_lighting[name] = (variable, weight)
        self._products = {}
        self._glossy_parts = {}
        self._lit = True

    def _glossy(self, name) -> dict:
        """Glossy radiance of object ``name``'s view samples: exact direct, and Eq. 9.

        Cached for the current gamma and lights: an edit recomputes only the edited
        object. While the lights stay, the products :math:`T_j^w L^w` are kept, so a new
        gamma costs one weighted sum of K + 1 vectors per pixel.
        """
        material = self.materials[name]
        cached = self._glossy_parts.get(name)
        key = (material.gamma, tuple(material.rho_s), name in self.frozen)
        if cached is not None and cached[0] == key:
            return cached[1]
        variable, weight = self._view_lighting[name]
        if uses_half_angle(material.model):
            lobe = edited_term(material.model, material.gamma, None, cos_delta=variable)
        else:
            lobe = edited_term(material.model, material.gamma, variable)
        direct = np.einsum("ps,psc->pc", lobe, weight)
        frozen = name in self.frozen
        products = self._products.get(name)
        if products is None:
            products = (_product(self.frozen[name][1], self._radiance_w) if frozen else
                        np.stack([_product(m, self._radiance_w) for m in self._transfer[name]]))
            self._products[name] = products
        indirect = (products if frozen else
                    np.einsum("j,jpc->pc", self.coefficients(name), products))
        parts = {"direct": material.rho_s * direct, "indirect": material.rho_s * indirect}
        parts["all"] = parts["direct"] + parts["indirect"]
        self._glossy_parts[name] = (key, parts)
        return parts

    def _compose(self, component="all") -> np.ndarray:
        data = self.data
        values = self._parts[component].copy()
        for name, rows in self._members.items():
            values[rows] += self._glossy(name)[component]
        image = np.zeros((data.shape[0] * data.shape[1], 3), dtype=np.float32)
        image[data.pixel] = values
        return image.reshape(data.shape[0], data.shape[1], 3)

    # -- the interactive API -------------------------------------------------------------
    def _set_materials(self, material):
        if material is None:
            return
        glossy = self.glossy_objects
        if isinstance(material, dict):
            updates = material
        elif len(glossy) == 1:
            updates = {glossy[0]: material}
        else:
            raise InputError("several objects have an analytic BRDF: pass a dict "
                             f"{{object name: material}} (objects: {', '.join(glossy)})",
                             field="material", value=type(material).__name__)
        albedo_changed = False
        for name, new in updates.items():
            if name not in self.materials:
                raise InputError(f"no such object; objects: {', '.join(self.materials)}",
                                 field="material", value=name)
            old = self.materials[name]
            same_kind = _is_glossy(old) == _is_glossy(new) and (not _is_glossy(old) or (
                old.model == new.model and old.f0 == new.f0
                and old.lafortune_c == new.lafortune_c))
            if not same_kind:
                raise InputError("only gamma, rho_s and rho_d can change without a new "
                                 "precomputation (the model, f0 and the Lafortune lobe are "
                                 "fixed terms)", field=f"material[{name!r}]",
                                 value=getattr(new, "model", type(new).__name__))
            albedo_changed |= not np.array_equal(_diffuse_albedo(old), _diffuse_albedo(new))
            self.materials[name] = new
            if name in self.frozen and self.frozen[name][0] != new.gamma:
                self.unfreeze(name)
        if albedo_changed:
            self._lit = False

    def render(self, lights=None, material=None, *, component: str = "all") -> Image:
        """Render with new lights and/or materials (None keeps the current ones).

        Parameters
        ----------
        lights : sequence of lights, optional
            Relighting: new direct lighting on gather and view samples, a new series.
        material : AnalyticBRDF or dict, optional
            Editing: one material (when one object has an analytic BRDF) or
            ``{object name: material}``; gamma, rho_s and rho_d may change (rho_d of
            any object also changes the light among gather samples).
        component : {"all", "direct", "indirect"}
            The whole image, the direct lighting of the pixels only, or the light that
            reaches them through gather samples only.

        Returns
        -------
        Image
        """
        started = time.perf_counter()
        if component not in ("all", "direct", "indirect"):
            raise InputError("must be 'all', 'direct' or 'indirect'", field="component",
                             value=component)
        if lights is not None:
            lights = tuple(lights)
            _check_lights(lights)
            self.lights = lights
            self._lit = False
        self._set_materials(material)
        if not self._lit:
            self._relight()
        rgb = self._compose(component)
        return Image(rgb, metadata={
            "producer": "brdf_pca", "scene": self.scene.name, "component": component,
            "knobs": self.knobs, "seconds": time.perf_counter() - started,
            "gamma": {name: self.materials[name].gamma for name in self._members},
            "frozen": sorted(self.frozen), "skipped": list(self.log.skipped)})

    def _check_editable(self, name: str, field_name: str) -> None:
        if name not in self._members:
            raise InputError("not an object with an analytic BRDF; editable: "
                             f"{', '.join(self._members)}", field=field_name, value=name)

    def edit(self, object_name: str, gamma: float) -> Image:
        """Set one object's gamma and render: only that object's pixels change (Sect. 6.2)."""
        self._check_editable(object_name, "object")
        material = self.materials[object_name].with_gamma(gamma)
        return self.render(material={object_name: material})

    def relight(self, lights) -> Image:
        """Render with new lights (frozen objects stay frozen)."""
        return self.render(lights=lights)

    def freeze(self, editing: str | None = None) -> float:
        r"""Freeze every glossy object but ``editing`` (Sect. 6.2); return the seconds taken.

        A frozen object's K + 1 rows per view sample become the one row
        :math:`\mathbf{c}(\gamma)^T T^w(x)`, truncated again to ``frozen_coefficients``;
        ``editing=None`` freezes them all (the light-editing mode).
        """
        started = time.perf_counter()
        if editing is not None:
            self._check_editable(editing, "editing")
            self.unfreeze(editing)
        for name, matrices in self._transfer.items():
            if name == editing or name in self.frozen:
                continue
            combined = _combine(matrices, self.coefficients(name))
            rows = _truncate(combined, self.knobs["frozen_coefficients"])
            self.frozen[name] = (self.materials[name].gamma, rows.quantised())
            self._products.pop(name, None)
            self._glossy_parts.pop(name, None)
        return time.perf_counter() - started

    def unfreeze(self, name: str) -> None:
        """Bring back object ``name``'s K + 1 rows (to edit it again)."""
        self.frozen.pop(name, None)
        self._products.pop(name, None)
        self._glossy_parts.pop(name, None)

    def storage_bytes(self) -> dict:
        """Bytes of the matrices the interactive path reads (T^w: unfrozen rows and frozen ones)."""
        transfer = sum(m.nbytes for name, ms in self._transfer.items()
                       if name not in self.frozen for m in ms)
        transfer += sum(rows.nbytes for _, rows in self.frozen.values())
        diffuse, gather = self.data.diffuse.nbytes, self.data.gather.nbytes
        return {"transfer": transfer, "diffuse": diffuse, "gather": gather,
                "total": transfer + diffuse + gather}


# ---------------------------------------------------------------------------------------
# command line


def add_approx_arguments(parser) -> None:
    """Add the options of ``translucent approx brdf_pca SCENE``."""
    parser.add_argument("--object", default=None,
                        help="object whose gamma to set (default: the only glossy object)")
    parser.add_argument("--gamma", type=float, default=None,
                        help="editing parameter of --object, in its model's range")
    parser.add_argument("--gather-samples", type=int, default=DEFAULT_KNOBS["gather_samples"])
    parser.add_argument("--bounces", type=int, default=DEFAULT_KNOBS["bounces"],
                        help="n of Eq. 17: bounces among gather samples")
    parser.add_argument("--basis", type=int, default=DEFAULT_KNOBS["n_basis"],
                        help="K, basis BRDFs besides the mean")
    parser.add_argument("--no-subarea", action="store_true", help="switch sub-area sampling off")


def approx(scene, args) -> Image:
    """Precompute (or load) and render ``scene`` for ``translucent approx brdf_pca``."""
    started = time.perf_counter()
    # the edit is checked against the scene before the (slow) precomputation
    glossy = [o.name for o in scene.objects if _is_glossy(o.material)]
    name = args.object
    if name is None and args.gamma is not None:
        if len(glossy) != 1:
            raise InputError("several objects have an analytic BRDF: name one with --object "
                             f"({', '.join(glossy)})", field="object", value=None)
        name = glossy[0]
    if name is not None and args.gamma is None:
        raise InputError("--object needs --gamma", field="gamma", value=None)
    if name is not None:
        if name not in glossy:
            raise InputError(f"not an object with an analytic BRDF; editable: "
                             f"{', '.join(glossy)}", field="object", value=name)
        scene.object(name).material.with_gamma(args.gamma)  # range-checked
    state = precompute(scene, gather_samples=args.gather_samples, bounces=args.bounces,
                       n_basis=args.basis, subarea=not args.no_subarea)
    image = state.edit(name, args.gamma) if name is not None else state.render()
    for sentence in state.log.skipped:
        print(f"skipped: {sentence}")
    return image.with_metadata(seconds=time.perf_counter() - started,
                               precompute_seconds=dict(state.log.seconds))
