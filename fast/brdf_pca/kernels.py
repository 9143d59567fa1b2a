"""The compiled loops of BRDF editing with global illumination (Nguyen et al. 2010).

The per-pair BRDF terms (the formulas of :mod:`translucent.materials.brdfs`, compiled),
the front-facing pair counts and rays, and the transfer rows with their sub-area estimate
(Sect. 5.1). :mod:`translucent.fast.brdf_pca` assembles the precomputation from them.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from ...compiled import parallel_njit
from ...materials.brdfs import (
    MODEL_CODES,
    fixed_term_scalar,
    pca_variable_scalar,
)

#: Sub-area samples are drawn in rounds of this many; convergence is judged between rounds.
SUBAREA_ROUND = 8

#: |M_g| allowed per solid angle of the narrowest lobe: 16 points (4 x 4) across a lobe
#: resolve its peak; pairs whose disk subtends less than 1/16 of a lobe keep one point.
SUBAREA_DENSITY = 16.0

_LA = MODEL_CODES["lafortune"]

#: Roberts' R2 sequence (powers of the plastic number): a 2D low-discrepancy sequence whose
#: every prefix is well spread, so sub-area points can be added until convergence. Each
#: pair shifts it by its own hashed offset (Cranley-Patterson rotation).
_PLASTIC = 1.324717957244746
_R2_X, _R2_Y = 1.0 / _PLASTIC, 1.0 / _PLASTIC**2

_SQRT_HALF = math.sqrt(0.5)


# ---------------------------------------------------------------------------------------
# compiled BRDF terms (the formulas of translucent.materials.brdfs, per pair)


#: The per-pair terms, compiled from the very functions of materials.brdfs.
_fixed_scalar = numba.njit(cache=True, nogil=True)(fixed_term_scalar)
_variable_scalar = numba.njit(cache=True, nogil=True)(pca_variable_scalar)


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


@parallel_njit(cache=True)
def front_counts(x, n_x, positions, normals, counts):  # pragma: no cover - compiled
    """Count, for each point ``x[b]``, the samples it and they face (into ``counts``)."""
    for b in numba.prange(x.shape[0]):
        found = 0
        for g in range(positions.shape[0]):
            if _front_facing(x, n_x, positions, normals, b, g):
                found += 1
        counts[b] = found


@numba.njit(cache=True, nogil=True)
def _shadow_ray(x, n_x, positions, normals, b, g, offset, k, origins, directions,
                reach):  # pragma: no cover - compiled
    """Fill ray k from x[b] to positions[g], both ends ``offset`` along their normals."""
    ox = x[b, 0] + offset * n_x[b, 0]
    oy = x[b, 1] + offset * n_x[b, 1]
    oz = x[b, 2] + offset * n_x[b, 2]
    ex = positions[g, 0] + offset * normals[g, 0] - ox
    ey = positions[g, 1] + offset * normals[g, 1] - oy
    ez = positions[g, 2] + offset * normals[g, 2] - oz
    length = math.sqrt(ex * ex + ey * ey + ez * ez)
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


@parallel_njit(cache=True)
def front_rays(x, n_x, positions, normals, offset, starts, columns, origins, directions,
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
            columns[k] = g
            _shadow_ray(x, n_x, positions, normals, b, g, offset, k, origins, directions,
                        reach)
            k += 1


@parallel_njit(cache=True)
def gather_front_counts(positions, normals, first, counts, later):  # pragma: no cover
    """Count the front-facing pairs of gather rows ``first + b`` and those with a later gather.

    Into ``counts`` and ``later``.
    """
    for b in numba.prange(counts.shape[0]):
        row = first + b
        found = 0
        after = 0
        for g in range(positions.shape[0]):
            if _front_facing(positions, normals, positions, normals, row, g):
                found += 1
                if g > row:
                    after += 1
        counts[b] = found
        later[b] = after


@parallel_njit(cache=True)
def gather_front_rays(positions, normals, offset, first, starts, later_starts, columns,
                      traced, origins, directions, reach):  # pragma: no cover - compiled
    """Fill the pairs of gather rows ``first + b``, and rays for those with a later gather.

    ``traced[k]`` is the ray of pair k, or -1 when its gather comes earlier: that pair's
    answer is the reversed pair's (:func:`gather_visibility`).
    """
    for b in numba.prange(starts.shape[0] - 1):
        row = first + b
        k = starts[b]
        u = later_starts[b]
        for g in range(positions.shape[0]):
            if not _front_facing(positions, normals, positions, normals, row, g):
                continue
            columns[k] = g
            if g > row:
                _shadow_ray(positions, normals, positions, normals, row, g, offset, u,
                            origins, directions, reach)
                traced[k] = u
                u += 1
            else:
                traced[k] = -1
            k += 1


@numba.njit(cache=True, nogil=True)
def _pair_bit(i, j):  # pragma: no cover - compiled
    """Return the bit of the unordered pair i < j: j (j - 1) / 2 + i, a triangle by rows."""
    return np.int64(j) * (np.int64(j) - 1) // 2 + np.int64(i)


@numba.njit(cache=True, nogil=True)
def gather_visibility(first, starts, columns, traced, blocked, reach, known,
                      seen):  # pragma: no cover - compiled
    """Each pair's visibility: traced (and kept in the bitset ``known``) or read back.

    Rows run in order, so a pair with an earlier gather g reads the bit that row g wrote
    (in an earlier block, or earlier in this one). Serial: rows share bytes of ``known``.
    """
    for b in range(starts.shape[0] - 1):
        row = first + b
        for k in range(starts[b], starts[b + 1]):
            u = traced[k]
            g = columns[k]
            if u >= 0:
                visible = (not blocked[u]) or reach[u] == 0.0
                seen[k] = visible
                if visible:
                    bit = _pair_bit(row, g)
                    known[bit >> 3] |= np.uint8(1) << np.uint8(bit & 7)
            else:
                bit = _pair_bit(g, row)
                seen[k] = ((known[bit >> 3] >> np.uint8(bit & 7)) & np.uint8(1)) == 1


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
def disk_estimate(x, n_x, out, g_pos, g_nor, area, first, second, model, f0, c_xy, c_z,
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


@parallel_njit(cache=True)
def transfer_rows(x, n_x, out, positions, normals, area, first, second, starts, columns,
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
                used_here = disk_estimate(x[b], n_x[b], out[b], positions[g], normals[g],
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


# ---------------------------------------------------------------------------------------
# the gather samples' BRDF reflection of their direct light (gather_reflection "brdf")


@parallel_njit(cache=True)
def block_reflection(centres, block_radius, positions, normals, disk, columns, light, brought,
                     coefficients, guard, model, f0, c_xy, c_z, grid0, step, matrix,
                     out):  # pragma: no cover - compiled
    """Add each gather sample's glossy reflection of its direct light towards each block.

    ``out[b, c, columns[n]] += sum_s sum_j c_j f_F b_j(light[n, s], towards b) brought[n, s, c]``
    for the gather samples ``n`` of one object (``brought``: irradiance times rho_s), the
    direction towards block ``b`` being its centre's. A gather sample closer to the centre
    than ``guard`` times the block's radius plus its disk's radius sends nothing: there the
    direction to the centre stands for none of the block's view samples.
    """
    count = coefficients.shape[0]
    for b in numba.prange(centres.shape[0]):
        values = np.empty(count)
        for n in range(positions.shape[0]):
            dx = centres[b, 0] - positions[n, 0]
            dy = centres[b, 1] - positions[n, 1]
            dz = centres[b, 2] - positions[n, 2]
            distance = math.sqrt(dx * dx + dy * dy + dz * dz)
            if distance <= guard * (block_radius[b] + disk[n]) or distance == 0.0:
                continue
            dx /= distance
            dy /= distance
            dz /= distance
            cos_v = dx * normals[n, 0] + dy * normals[n, 1] + dz * normals[n, 2]
            if cos_v <= 0.0:
                continue
            red = 0.0
            green = 0.0
            blue = 0.0
            for s in range(light.shape[1]):
                cos_l = (light[n, s, 0] * normals[n, 0] + light[n, s, 1] * normals[n, 1]
                         + light[n, s, 2] * normals[n, 2])
                if cos_l <= 0.0:
                    continue
                l_dot_v = light[n, s, 0] * dx + light[n, s, 1] * dy + light[n, s, 2] * dz
                _glossy_basis(model, cos_l, cos_v, l_dot_v, f0, c_xy, c_z, grid0, step,
                              matrix, values)
                lobe = 0.0
                for j in range(count):
                    lobe += coefficients[j] * values[j]
                red += lobe * brought[n, s, 0]
                green += lobe * brought[n, s, 1]
                blue += lobe * brought[n, s, 2]
            column = columns[n]
            out[b, 0, column] += red
            out[b, 1, column] += green
            out[b, 2, column] += blue
