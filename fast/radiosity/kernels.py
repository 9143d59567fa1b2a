"""The compiled CPU loops of translucent radiosity (numba, compiled at first use and cached).

Each is built by a function cached with ``functools.lru_cache`` so that importing the
method does not import numba.
"""

from __future__ import annotations

import functools
import math

import numpy as np

from ...compiled import parallel_njit

#: Below this many form factors scipy's product is as fast as the compiled one.
COMPILED_PRODUCT_ENTRIES = 200_000


@functools.lru_cache(maxsize=1)
def compiled_rgb_product():
    """Compile ``out = A @ x`` for x (P, 3): data (nnz,) shared by R, G, B (F) or (nnz, 3) (S).

    ``data.ndim`` is part of the array type: each layout compiles to its own tight loop (a
    single loop indexing (nnz, 1) data was measured 20-35 % slower on F).
    """
    import numba

    @parallel_njit(fastmath=True, cache=True)
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


@functools.lru_cache(maxsize=1)
def compiled_scatter_product():
    """Compile ``out[positions[r]] += (A @ table)[r]`` for a CSR A and a (K, 3) table.

    A translucency change fills S from an object's cached sample operator (pairs x K) in
    one pass: the (pairs, 3) product is never stored, and the pair rows need not be moved
    to their places in S's data beforehand. ``positions`` must be distinct (rows run in
    parallel). Each entry is summed in the order of scipy's ``A @ table``.
    """
    import numba

    @parallel_njit(cache=True)
    def scatter(indptr, indices, data, table, positions, out):  # pragma: no cover
        for row in numba.prange(len(indptr) - 1):
            red = green = blue = 0.0
            for k in range(indptr[row], indptr[row + 1]):
                column = indices[k]
                value = data[k]
                red += value * table[column, 0]
                green += value * table[column, 1]
                blue += value * table[column, 2]
            target = positions[row]
            out[target, 0] += red
            out[target, 1] += green
            out[target, 2] += blue

    return scatter


@functools.lru_cache(maxsize=1)
def compiled_add_rows():
    """Compile ``out[positions[r]] += values[r]`` for (rows, 3) values and distinct positions.

    One pass where numpy's ``out[positions] += values`` gathers, adds and scatters through
    two temporaries of the values' size (26 M rows on a solid sphere's S).
    """
    import numba

    @parallel_njit(cache=True)
    def add(values, positions, out):  # pragma: no cover - compiled
        for row in numba.prange(len(positions)):
            target = positions[row]
            out[target, 0] += values[row, 0]
            out[target, 1] += values[row, 1]
            out[target, 2] += values[row, 2]

    return add


def add_rows(values, positions, out) -> None:
    """Add ``values`` (rows, 3) to the distinct rows ``positions`` of ``out`` (nnz, 3)."""
    if len(values) != len(positions):
        raise ValueError(f"{len(values)} rows of values for {len(positions)} positions")
    compiled_add_rows()(np.ascontiguousarray(values, dtype=np.float64),
                        np.ascontiguousarray(positions, dtype=np.int64), out)


def scatter_product(operator, table, positions, out) -> None:
    """Add ``operator @ table`` (rows, 3) to the rows ``positions`` of ``out`` (nnz, 3).

    Parameters
    ----------
    operator : scipy.sparse.csr_matrix, shape (rows, K)
    table : ndarray, shape (K, 3)
    positions : ndarray of int, shape (rows,)
        Distinct rows of ``out``.
    out : ndarray of float64, shape (nnz, 3)
        Written in place.
    """
    if operator.shape[0] != len(positions):
        raise ValueError(f"{operator.shape[0]} operator rows for {len(positions)} positions")
    # one compiled specialisation: the operators' own index arrays are int64 / int32
    compiled_scatter_product()(np.ascontiguousarray(operator.indptr, dtype=np.int64),
                               np.ascontiguousarray(operator.indices, dtype=np.int32),
                               np.ascontiguousarray(operator.data, dtype=np.float64),
                               np.ascontiguousarray(table, dtype=np.float64),
                               np.ascontiguousarray(positions, dtype=np.int64), out)


@functools.cache
def compiled_energy_correction():
    """Compile the two passes of :func:`_carry_finite_object_energy` over S's entries."""
    import numba

    @parallel_njit(fastmath=True, cache=True)
    def correct(indptr, indices, data, in_object, area, centroid, normal, z_r, sigma_tr,
                target, applied):  # pragma: no cover - compiled
        size = len(indptr) - 1
        # the weights A_j * fluence, once (in parallel: no entry shares its slot)
        weight = np.zeros((len(indices), 3), np.float32)
        for row in numba.prange(size):
            for k in range(indptr[row], indptr[row + 1]):
                column = indices[k]
                if not in_object[column]:
                    continue
                for c in range(3):
                    if not applied[c]:
                        continue
                    # the fluence of the dipole's real source below the entry patch and of
                    # its mirror image above it (written out: a jitted helper from this
                    # closure would keep the kernel out of numba's on-disk cache)
                    real = image = 0.0
                    for d in range(3):
                        offset = centroid[row, d] - centroid[column, d]
                        real += (offset + z_r[c] * normal[column, d]) ** 2
                        image += (offset - z_r[c] * normal[column, d]) ** 2
                    real = max(math.sqrt(real), 1e-12)
                    image = max(math.sqrt(image), 1e-12)
                    weight[k, c] = area[row] * max(math.exp(-sigma_tr[c] * real) / real
                                                   - math.exp(-sigma_tr[c] * image) / image,
                                                   0.0)
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
    """Compile Eq. 16 summed over each pair's samples, visiting only the materials it crosses.

    A path of ``mix_points`` points crosses at most that many of the M materials, so
    the other terms (each a factor 1) are never evaluated; the segment lookup is
    :meth:`~translucent.materials.profiles.RadialGrid.locate`'s, inlined. The samples are
    grouped by pair (``starts``: pair p owns samples ``starts[p]:starts[p + 1]``), so each
    pair's sum is made in one thread, in sample order, with no per-sample array.
    """
    import numba

    @parallel_njit(fastmath=False, cache=True)
    def mixed(distance, counts, starts, points, weight, zero, tables, max_radius,
              out):  # pragma: no cover - compiled
        samples_k = tables.shape[1]
        materials = tables.shape[0]
        for row in numba.prange(len(starts) - 1):
            if starts[row] == starts[row + 1]:
                continue
            mean0 = mean1 = mean2 = 0.0
            for m in range(materials):
                fraction = counts[row, m] / points
                mean0 += zero[m, 0] * fraction
                mean1 += zero[m, 1] * fraction
                mean2 += zero[m, 2] * fraction
            sum0 = sum1 = sum2 = 0.0
            for i in range(starts[row], starts[row + 1]):
                ratio0 = ratio1 = ratio2 = 1.0
                for m in range(materials):
                    count = counts[row, m]
                    if count == 0:
                        continue
                    fraction = count / points
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
                sum0 += mean0 * ratio0 * weight[i]
                sum1 += mean1 * ratio1 * weight[i]
                sum2 += mean2 * ratio2 * weight[i]
            out[row, 0] = sum0
            out[row, 1] = sum1
            out[row, 2] = sum2

    return mixed


@functools.lru_cache(maxsize=1)
def compiled_shadow_rays():
    """Compile the per-frame loops of :class:`AreaLightShadows` (geometry and rays)."""
    import numba

    @parallel_njit(cache=True)
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

    @parallel_njit(cache=True)
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

    @parallel_njit(cache=True)
    def sort_rows(indptr, order, cols):  # pragma: no cover - compiled
        for row in numba.prange(len(indptr) - 1):
            lo, hi = indptr[row], indptr[row + 1]
            # the runs in which the row's columns arrive
            cut = -1
            runs = 1
            for k in range(lo + 1, hi):
                if cols[order[k]] < cols[order[k - 1]]:
                    runs += 1
                    cut = k
            if runs == 1:
                continue
            entries = order[lo:hi].copy()
            if runs == 2:
                # two sorted runs (S's diagonal, then an object's pairs in column order):
                # one stable merge
                left, right, out = 0, cut - lo, lo
                while left < cut - lo and right < hi - lo:
                    if cols[entries[right]] < cols[entries[left]]:
                        order[out] = entries[right]
                        right += 1
                    else:
                        order[out] = entries[left]
                        left += 1
                    out += 1
                while left < cut - lo:
                    order[out] = entries[left]
                    left += 1
                    out += 1
                while right < hi - lo:
                    order[out] = entries[right]
                    right += 1
                    out += 1
            else:
                ranks = np.argsort(cols[entries], kind="mergesort")
                for k in range(hi - lo):
                    order[lo + k] = entries[ranks[k]]

    @parallel_njit(cache=True)
    def placed(order, cols):  # pragma: no cover - compiled
        position = np.empty(len(order), np.int64)
        sorted_cols = np.empty(len(order), np.int32)
        for k in numba.prange(len(order)):
            position[order[k]] = k
            sorted_cols[k] = cols[order[k]]
        return position, sorted_cols

    return buckets, sort_rows, placed


def csr_order(rows, cols, size: int) -> np.ndarray:
    """Return the stable (row, column) sort of entries: ``np.lexsort((cols, rows))``.

    A counting sort by row, then a stable sort of each row's columns, rows in parallel
    (docs/radiosity.md gives what it saves): a row that arrives as one or two sorted runs
    (S's diagonal, then an object's pairs in column order) is merged in one pass.
    """
    return _row_column_order(rows, cols, size)[1]


def _row_column_order(rows, cols, size: int) -> tuple:
    """Return the CSR row pointers, :func:`csr_order`'s order and the columns as int64."""
    rows = np.ascontiguousarray(rows, dtype=np.int64)
    cols = np.ascontiguousarray(cols, dtype=np.int64)
    buckets, sort_rows, _ = _compiled_csr_order()
    indptr, order = buckets(rows, int(size))
    sort_rows(indptr, order, cols)
    return indptr, order, cols


def csr_pattern(rows, cols, size: int) -> tuple:
    """Return the CSR pattern of entries (rows, cols), and where each entry lands in it.

    Returns
    -------
    indptr : ndarray of int64, shape (size + 1,)
    indices : ndarray of int32
        The columns in (row, column) order (:func:`csr_order`, stable).
    position : ndarray of int64
        ``position[i]``: the place of entry i in ``indices``.
    """
    indptr, order, cols = _row_column_order(rows, cols, size)
    position, indices = _compiled_csr_order()[2](order, cols)
    return indptr, indices, position


@functools.lru_cache(maxsize=1)
def _compiled_samples_per_edge():
    import numba

    @numba.njit(cache=True)
    def counts(distance, radius, most, falloff, beyond):  # pragma: no cover - compiled
        m = np.empty(len(distance), np.int64)
        for pair in range(len(distance)):
            if distance[pair] > beyond * radius[pair]:
                m[pair] = 1
            else:
                value = np.rint(most * np.exp(-distance[pair] / (falloff * radius[pair])))
                m[pair] = int(min(max(value, 1.0), float(most)))
        return m

    return counts


def samples_per_edge(distance, radius, most: int, falloff: float, beyond: float):
    """Return each pair's samples per edge m: ``clip(rint(most exp(-d / (falloff r))), 1, most)``.

    1 where ``d > beyond * r`` (the centroid alone). ``distance`` and ``radius`` (mm) are
    per pair; returns int64.
    """
    return _compiled_samples_per_edge()(np.ascontiguousarray(distance, dtype=np.float64),
                                        np.ascontiguousarray(radius, dtype=np.float64),
                                        int(most), float(falloff), float(beyond))


@functools.lru_cache(maxsize=1)
def _compiled_scattering_samples():
    import numba

    @numba.njit(cache=True)
    def sample_offsets(incident, m, face_start):  # pragma: no cover - compiled
        offsets = np.empty(len(incident) + 1, np.int64)
        offsets[0] = 0
        for pair in range(len(incident)):
            faces = face_start[incident[pair] + 1] - face_start[incident[pair]]
            offsets[pair + 1] = offsets[pair] + faces * m[pair] * m[pair]
        return offsets

    @numba.njit(cache=True)
    def fill(exit_local, incident, m, centroids, face_start, faces, triangles, area, mm,
             table, table_start, offsets, points):  # pragma: no cover - compiled
        weight = np.empty(offsets[-1])
        distance = np.empty(offsets[-1])
        with_points = len(points) == offsets[-1]
        corner = np.empty((3, 3))
        for pair in range(len(incident)):
            sample = offsets[pair]
            count = m[pair] * m[pair]
            first = table_start[m[pair]]
            start = exit_local[pair]
            for entry in range(face_start[incident[pair]], face_start[incident[pair] + 1]):
                face = faces[entry]
                for k in range(3):
                    for d in range(3):
                        corner[k, d] = triangles[face, k, d] * mm
                share = area[face] * mm * mm / count
                for b in range(first, first + count):
                    squared = 0.0
                    for d in range(3):
                        x = (table[b, 0] * corner[0, d] + table[b, 1] * corner[1, d]
                             + table[b, 2] * corner[2, d])
                        if with_points:
                            points[sample, d] = x
                        squared += (x - centroids[start, d]) ** 2
                    weight[sample] = share
                    distance[sample] = math.sqrt(squared)
                    sample += 1
        return weight, distance

    @numba.njit(cache=True)
    def operator(offsets, weight, distance, radius):  # pragma: no cover - compiled
        nodes = len(radius)
        top = radius[nodes - 1]
        pairs = len(offsets) - 1
        mark = np.full(nodes, -1, np.int64)
        indptr = np.zeros(pairs + 1, np.int64)
        for pair in range(pairs):
            used = 0
            for sample in range(offsets[pair], offsets[pair + 1]):
                if not distance[sample] <= top:
                    continue
                # the node of RadialGrid.locate (radii grow as the square of the index);
                # written out: a jitted helper from this closure would keep the kernel
                # out of numba's on-disk cache
                k = min(int(math.sqrt(max(distance[sample], 0.0) / top) * (nodes - 1)),
                        nodes - 2)
                for column in (k, k + 1):
                    if mark[column] != pair:
                        mark[column] = pair
                        used += 1
            indptr[pair + 1] = indptr[pair] + used
        indices = np.empty(indptr[-1], np.int32)
        data = np.empty(indptr[-1])
        value = np.zeros(nodes)
        mark[:] = -1
        for pair in range(pairs):
            lo = indptr[pair]
            used = lo
            for sample in range(offsets[pair], offsets[pair + 1]):
                r = distance[sample]
                if not r <= top:
                    continue
                k = min(int(math.sqrt(max(r, 0.0) / top) * (nodes - 1)), nodes - 2)
                # the float32 offset of RadialGrid.locate
                f = np.float64(np.float32(min(max((r - radius[k]) / (radius[k + 1] - radius[k]),
                                                  0.0), 1.0)))
                for column in (k, k + 1):
                    if mark[column] != pair:
                        mark[column] = pair
                        indices[used] = column
                        used += 1
                value[k] += weight[sample] * (1.0 - f)
                value[k + 1] += weight[sample] * f
            # a few columns a row: an insertion sort allocates nothing
            for entry in range(lo + 1, used):
                column = indices[entry]
                back = entry - 1
                while back >= lo and indices[back] > column:
                    indices[back + 1] = indices[back]
                    back -= 1
                indices[back + 1] = column
            for entry in range(lo, used):
                data[entry] = value[indices[entry]]
                value[indices[entry]] = 0.0
        return indptr, indices, data

    @numba.njit(cache=True)
    def directed(undirected, centroids, radius, cut_off, with_self):  # pragma: no cover
        count = len(centroids)
        start = np.zeros(count + 1, np.int64)
        for pair in range(len(undirected)):
            start[undirected[pair, 0] + 1] += 1
            start[undirected[pair, 1] + 1] += 1
        if with_self:
            for row in range(count):
                start[row + 1] += 1
        for row in range(count):
            start[row + 1] += start[row]
        neighbour = np.empty(start[count], np.int64)
        fill = start[:-1].copy()
        for pair in range(len(undirected)):
            a, b = undirected[pair, 0], undirected[pair, 1]
            neighbour[fill[a]] = b
            fill[a] += 1
            neighbour[fill[b]] = a
            fill[b] += 1
        if with_self:
            for row in range(count):
                neighbour[fill[row]] = row
                fill[row] += 1
        mark = np.full(count, -1, np.int64)
        for row in range(count):
            lo, hi = start[row], start[row + 1]
            length = hi - lo
            if length * max(1.0, math.log2(max(length, 1))) < count:
                # the merge sort of csr_order's rows: one sort compiled for both (and
                # copied back element by element: a slice assignment compiles numba's
                # shape-mismatch message, seconds of compilation)
                entries = neighbour[lo:hi].copy()
                ranks = np.argsort(entries, kind="mergesort")
                for k in range(length):
                    neighbour[lo + k] = entries[ranks[k]]
            else:  # a dense row: a scan of every patch costs less than a sort
                for entry in range(lo, hi):
                    mark[neighbour[entry]] = row
                entry = lo
                for column in range(count):
                    if mark[column] == row:
                        neighbour[entry] = column
                        entry += 1
        exit_local = np.empty(len(neighbour), np.int64)
        incident = np.empty(len(neighbour), np.int64)
        distance = np.empty(len(neighbour))
        kept = 0
        for a in range(count):
            for entry in range(start[a], start[a + 1]):
                b = neighbour[entry]
                squared = 0.0
                for d in range(3):
                    squared += (centroids[a, d] - centroids[b, d]) ** 2
                length = math.sqrt(squared)
                if length <= cut_off + radius[b]:
                    exit_local[kept], incident[kept], distance[kept] = a, b, length
                    kept += 1
        if kept == len(neighbour):  # every candidate within reach (a dense S): no copy
            return exit_local, incident, distance
        return exit_local[:kept].copy(), incident[:kept].copy(), distance[:kept].copy()

    return sample_offsets, fill, operator, directed


def directed_pairs(undirected, centroids_mm, radius_mm, cut_off_mm: float, *,
                   with_self: bool) -> tuple:
    """Both directions of each candidate pair (and each patch with itself) within reach, sorted.

    Pair (a, b) is kept when the centroid distance is at most ``cut_off_mm`` plus the
    radius of the incident patch b: some point of b may lie within the cut-off.

    Parameters
    ----------
    undirected : ndarray of int, shape (n, 2)
        From ``cKDTree.query_pairs``.
    centroids_mm : ndarray, shape (patches, 3)
    radius_mm : ndarray, shape (patches,)
    cut_off_mm : float
    with_self : bool
        Append (a, a) for every patch (the ``"samples"`` self term).

    Returns
    -------
    exit_local, incident_local : ndarray of int64
        The kept pairs sorted by (exit, incident): every later pass over them (samples,
        their operator, its rows moved into S's pattern) then walks memory in order.
    distance : ndarray
        Centroid distance, mm.
    """
    *_, directed = _compiled_scattering_samples()
    return directed(np.ascontiguousarray(undirected, dtype=np.int64).reshape(-1, 2),
                    np.ascontiguousarray(centroids_mm, dtype=np.float64),
                    np.ascontiguousarray(radius_mm, dtype=np.float64), float(cut_off_mm),
                    bool(with_self))


def scattering_samples(exit_local, incident, m, centroids_mm, patches, *, points: bool):
    """Midpoint-rule samples of every pair's incident patch (Sheng et al. 2014, Sect. 5.2).

    Pair p integrates over the triangles of patch ``incident[p]``, each split ``m[p]``
    times per edge (:func:`~translucent.fast.radiosity.optical_distance.subdivision_barycentrics`),
    from the centroid of exit patch ``exit_local[p]``. Samples come in pair order.

    Parameters
    ----------
    exit_local : ndarray of int, shape (pairs,)
        Rows of ``centroids_mm``.
    incident : ndarray of int, shape (pairs,)
        Global patch indices.
    m : ndarray of int, shape (pairs,)
        Splits per triangle edge, >= 1.
    centroids_mm : ndarray, shape (n, 3)
        mm.
    patches : Patches
    points : bool
        Return the sample points too (the voxel distances and nothing else need them).

    Returns
    -------
    offsets : ndarray of int64, shape (pairs + 1,)
        Pair p owns samples ``offsets[p]:offsets[p+1]``.
    weight : ndarray, shape (samples,)
        mm^2, area / m^2.
    distance : ndarray, shape (samples,)
        Euclidean distance from the exit centroid, mm.
    points : ndarray, shape (samples, 3) or (0, 3)
        mm.
    """
    from .optical_distance import subdivision_barycentrics

    sample_offsets, fill, *_ = _compiled_scattering_samples()
    m = np.ascontiguousarray(m, dtype=np.int64)
    incident = np.ascontiguousarray(incident, dtype=np.int64)
    most = int(m.max(initial=1))
    tables = [subdivision_barycentrics(value) for value in range(1, most + 1)]
    table_start = np.zeros(most + 1, np.int64)
    table_start[1:] = np.cumsum([0] + [len(t) for t in tables[:-1]])
    face_start = np.ascontiguousarray(patches.patch_face_start, dtype=np.int64)
    offsets = sample_offsets(incident, m, face_start)
    out = np.empty((offsets[-1] if points else 0, 3))
    weight, distance = fill(np.ascontiguousarray(exit_local, dtype=np.int64), incident, m,
                            np.ascontiguousarray(centroids_mm, dtype=np.float64), face_start,
                            np.ascontiguousarray(patches.patch_faces, dtype=np.int64),
                            np.ascontiguousarray(patches.triangles, dtype=np.float64),
                            np.ascontiguousarray(patches.triangle_area, dtype=np.float64),
                            float(patches.mm_per_unit), np.concatenate(tables), table_start,
                            offsets, out)
    return offsets, weight, distance, out


def sample_operator(offsets, weight, distance, radius) -> tuple:
    """CSR (pairs x K) of the samples' interpolation weights on the profile grid.

    Row p sums ``weight * (1 - f)`` at node k and ``weight * f`` at k + 1 over the samples
    of pair p, ``(k, f)`` as :meth:`~translucent.materials.profiles.RadialGrid.locate`;
    samples beyond the last node (or at ``inf``) are left out. Columns are sorted and
    summed, as ``coo_matrix(...).tocsr()`` with ``sum_duplicates``.

    Returns
    -------
    indptr, indices, data : ndarray
    """
    _, _, operator, *_ = _compiled_scattering_samples()
    return operator(np.ascontiguousarray(offsets, dtype=np.int64),
                    np.ascontiguousarray(weight, dtype=np.float64),
                    np.ascontiguousarray(distance, dtype=np.float64),
                    np.ascontiguousarray(radius, dtype=np.float64))
