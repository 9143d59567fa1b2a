"""The compiled CPU loops of translucent radiosity (numba, compiled at first use and cached).

Each is built by a function cached with ``functools.lru_cache`` so that importing the
method does not import numba.
"""

from __future__ import annotations

import functools
import math

import numpy as np

#: Below this many form factors scipy's product is as fast as the compiled one.
COMPILED_PRODUCT_ENTRIES = 200_000


@functools.lru_cache(maxsize=1)
def compiled_rgb_product():
    """Compile ``out = A @ x`` for x (P, 3): data (nnz,) shared by R, G, B (F) or (nnz, 3) (S).

    ``data.ndim`` is part of the array type: each layout compiles to its own tight loop (a
    single loop indexing (nnz, 1) data was measured 20-35 % slower on F).
    """
    import numba

    @numba.njit(parallel=True, fastmath=True, cache=True)
    def product(indptr, indices, data, x, out):  # pragma: no cover - compiled
        for row in numba.prange(len(indptr) - 1):
            red = green = blue = 0.0
            for k in range(indptr[row], indptr[row + 1]):
                column = indices[k]
                if data.ndim == 2:
                    red += data[k, 0] * x[column, 0]
                    green += data[k, 1] * x[column, 1]
                    blue += data[k, 2] * x[column, 2]
                else:
                    value = data[k]
                    red += value * x[column, 0]
                    green += value * x[column, 1]
                    blue += value * x[column, 2]
            out[row, 0], out[row, 1], out[row, 2] = red, green, blue

    return product


@functools.cache
def compiled_energy_correction():
    """Compile the two passes of :func:`_carry_finite_object_energy` over S's entries."""
    import numba

    @numba.njit(inline="always", fastmath=True)
    def fluence(centroid, normal, row, column, z_r, sigma_tr):  # pragma: no cover
        # the dipole's real source below the entry patch and its mirror image above it
        real = image = 0.0
        for d in range(3):
            offset = centroid[row, d] - centroid[column, d]
            real += (offset + z_r * normal[column, d]) ** 2
            image += (offset - z_r * normal[column, d]) ** 2
        real = max(math.sqrt(real), 1e-12)
        image = max(math.sqrt(image), 1e-12)
        return max(math.exp(-sigma_tr * real) / real - math.exp(-sigma_tr * image) / image, 0.0)

    @numba.njit(parallel=True, fastmath=True, cache=True)
    def correct(indptr, indices, data, in_object, area, centroid, normal, z_r, sigma_tr,
                target, applied):  # pragma: no cover - compiled
        size = len(indptr) - 1
        # the weights A_j * fluence, once (in parallel: no entry shares its slot)
        weight = np.zeros((len(indices), 3), np.float32)
        for row in numba.prange(size):
            for k in range(indptr[row], indptr[row + 1]):
                column = indices[k]
                if in_object[column]:
                    for c in range(3):
                        if applied[c]:
                            weight[k, c] = area[row] * fluence(centroid, normal, row, column,
                                                               z_r[c], sigma_tr[c])
        current = np.zeros((size, 3))
        norm = np.zeros((size, 3))
        for row in range(size):  # serial: columns gather from every row
            for k in range(indptr[row], indptr[row + 1]):
                column = indices[k]
                if in_object[column]:
                    for c in range(3):
                        current[column, c] += area[row] * data[k, c]
                        norm[column, c] += weight[k, c]
        for column in range(size):
            for c in range(3):
                current[column, c] /= area[column]
        for row in numba.prange(size):
            for k in range(indptr[row], indptr[row + 1]):
                column = indices[k]
                if not in_object[column]:
                    continue
                for c in range(3):
                    if not applied[c]:
                        continue
                    missing = target[column, c] - current[column, c]
                    if missing > 0.0:
                        if norm[column, c] > 0.0:
                            data[k, c] += missing * area[column] * weight[k, c] \
                                / (area[row] * norm[column, c])
                    elif current[column, c] > 0.0:
                        data[k, c] *= target[column, c] / current[column, c]

    return correct


@functools.lru_cache(maxsize=1)
def compiled_mixed_profile():
    """Compile Eq. 16 per sample, visiting only the materials a path crosses.

    A path of ``mix_points`` points crosses at most that many of the M materials, so
    the other terms (each a factor 1) are never evaluated; the segment lookup is
    :meth:`~translucent.materials.profiles.RadialGrid.locate`'s, inlined.
    """
    import numba

    @numba.njit(parallel=True, fastmath=False, cache=True)
    def mixed(distance, counts, pair, points, weight, zero, tables, max_radius,
              out):  # pragma: no cover - compiled
        samples_k = tables.shape[1]
        materials = tables.shape[0]
        for i in numba.prange(len(distance)):
            row = pair[i]
            mean0 = mean1 = mean2 = 0.0
            ratio0 = ratio1 = ratio2 = 1.0
            for m in range(materials):
                count = counts[row, m]
                if count == 0:
                    continue
                fraction = count / points
                mean0 += zero[m, 0] * fraction
                mean1 += zero[m, 1] * fraction
                mean2 += zero[m, 2] * fraction
                # RadialGrid.locate: nodes r_k = max_radius (k / (K - 1))^2
                r = min(max(fraction * distance[i], 0.0), max_radius)
                position = math.sqrt(r / max_radius) * (samples_k - 1)
                k = min(int(math.floor(position)), samples_k - 2)
                left = max_radius * (k / (samples_k - 1)) ** 2
                right = max_radius * ((k + 1) / (samples_k - 1)) ** 2
                f = min(max((r - left) / (right - left), 0.0), 1.0)
                for c in range(3):
                    value = tables[m, k, c] * (1.0 - f) + tables[m, k + 1, c] * f
                    ratio = value / zero[m, c] if zero[m, c] > 0 else 0.0
                    if c == 0:
                        ratio0 *= ratio
                    elif c == 1:
                        ratio1 *= ratio
                    else:
                        ratio2 *= ratio
            out[i, 0] = mean0 * ratio0 * weight[i]
            out[i, 1] = mean1 * ratio1 * weight[i]
            out[i, 2] = mean2 * ratio2 * weight[i]

    return mixed


@functools.lru_cache(maxsize=1)
def compiled_shadow_rays():
    """Compile the per-frame loops of :class:`AreaLightShadows` (geometry and rays)."""
    import numba

    @numba.njit(parallel=True, cache=True)
    def strengths(points, normals, positions, light_normal, out):  # pragma: no cover
        # the expressions and their order are those of _area_light_irradiance
        for i in numba.prange(len(points)):
            for s in range(len(positions)):
                x = positions[s, 0] - points[i, 0]
                y = positions[s, 1] - points[i, 1]
                z = positions[s, 2] - points[i, 2]
                distance2 = x * x + y * y + z * z
                length = math.sqrt(distance2)
                x, y, z = x / length, y / length, z / length
                cos_point = max(normals[i, 0] * x + normals[i, 1] * y + normals[i, 2] * z, 0.0)
                cos_light = max(-(x * light_normal[0] + y * light_normal[1]
                                  + z * light_normal[2]), 0.0)
                out[i, s] = cos_point * cos_light / distance2

    @numba.njit(parallel=True, cache=True)
    def rays(starts, positions, lit, count, offset,  # pragma: no cover - compiled
             origins, directions, tmax, close):
        # the segment of visible() with normals_a given, written in the engine's float32
        for k in numba.prange(len(lit)):
            i, s = lit[k] // count, lit[k] % count
            x = positions[s, 0] - starts[i, 0]
            y = positions[s, 1] - starts[i, 1]
            z = positions[s, 2] - starts[i, 2]
            length = math.sqrt(x * x + y * y + z * z)
            for d in range(3):
                origins[k, d] = starts[i, d]
            close[k] = length <= 2.0 * offset
            if close[k]:
                # close enough to count as visible (no ray)
                directions[k, 0], directions[k, 1], directions[k, 2] = 0.0, 0.0, 1.0
                tmax[k] = 0.0
            else:
                directions[k, 0], directions[k, 1] = x / length, y / length
                directions[k, 2] = z / length
                tmax[k] = max(length - offset, 0.0)

    return strengths, rays


@functools.lru_cache(maxsize=1)
def _compiled_csr_order():
    import numba

    @numba.njit(cache=True)
    def buckets(rows, size):  # pragma: no cover - compiled
        indptr = np.zeros(size + 1, np.int64)
        for row in rows:
            indptr[row + 1] += 1
        for i in range(size):
            indptr[i + 1] += indptr[i]
        fill = indptr[:-1].copy()
        order = np.empty(len(rows), np.int64)
        for i in range(len(rows)):
            order[fill[rows[i]]] = i
            fill[rows[i]] += 1
        return indptr, order

    @numba.njit(parallel=True, cache=True)
    def sort_rows(indptr, order, cols):  # pragma: no cover - compiled
        for row in numba.prange(len(indptr) - 1):
            lo, hi = indptr[row], indptr[row + 1]
            entries = order[lo:hi].copy()
            order[lo:hi] = entries[np.argsort(cols[entries], kind="mergesort")]

    return buckets, sort_rows


def csr_order(rows, cols, size: int) -> np.ndarray:
    """Return the stable (row, column) sort of entries: ``np.lexsort((cols, rows))``.

    A counting sort by row, then a stable sort of each row's columns, rows in parallel
    (docs/radiosity.md gives what it saves).
    """
    rows = np.ascontiguousarray(rows, dtype=np.int64)
    cols = np.ascontiguousarray(cols, dtype=np.int64)
    buckets, sort_rows = _compiled_csr_order()
    indptr, order = buckets(rows, int(size))
    sort_rows(indptr, order, cols)
    return order
