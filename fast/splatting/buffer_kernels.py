r"""Compiled kernels that make the splatting method's buffers (Chen et al. 2012, Sect. 4).

* :func:`rasterize`: the G-buffers themselves, a z-buffer over the scene's triangles
  whose per-pixel test is the exact ray-triangle intersection of the pixel's ray, in
  parallel over bands of rows; :func:`interpolate_surface`, :func:`perspective_footprint`
  the buffers' attributes;
* :func:`median_depth_level`, :func:`irradiance_level`: one level of the splatting
  buffer's median-depth mipmap and of the irradiance buffer's mipmap;
* :func:`bilateral_upsample_level`: Eq. 17; :func:`add_scaled_by_texel` the scattering
  factors per texel;
* :func:`light_flux` Eq. 5-6 and :func:`exitant_radiance` Eq. 7 per pixel, fused (no
  whole-image numpy temporaries), rows in parallel.

The splat itself is :mod:`translucent.fast.splatting.backend_numba`.

References
----------
Chen, Peers, Zhang, Tong: Real-time rendering of deformable heterogeneous translucent
objects using multiresolution splatting. The Visual Computer (2012).
Möller, Trumbore: Fast, minimum storage ray-triangle intersection. JGT 2(1) (1997).
"""

from __future__ import annotations

import math

import numba
import numpy as np

from ...compiled import parallel_njit
from ...materials.fresnel import fresnel_transmittance_scalar
from .backend_numba import prefix_sum

__all__ = [
    "median_depth_level",
    "irradiance_level",
    "bilateral_upsample_level",
    "add_scaled_by_texel",
    "rasterize",
    "interpolate_surface",
    "perspective_footprint",
    "fresnel_transmittance_at",
    "light_flux",
    "exitant_radiance",
]

#: Image rows per band of :func:`rasterize`, the unit of its parallel loop.
RASTER_BAND_ROWS = 4
#: Pixels by which :func:`rasterize` widens each triangle's projected outline before it
#: tests a pixel's ray: the projection and Möller-Trumbore's decisions both round at about
#: 1e-13 pixels (float64 eps times coordinates of 1e3 pixels), so no hit is lost.
RASTER_SPAN_MARGIN = 0.01


# ====================================================================== mipmaps
@numba.njit(cache=True)
def _median_child(depth, valid, row, col):
    """Child offset (0-3, row-major in the 2 x 2 block) of the lower-median valid depth."""
    height, width = valid.shape
    order = np.empty(4, np.int64)
    keys = np.empty(4, np.float64)
    count = 0
    for child in range(4):
        y = 2 * row + child // 2
        x = 2 * col + child % 2
        if y < height and x < width and valid[y, x]:
            # insertion sort, stable: equal depths keep the children's order
            slot = count
            while slot > 0 and keys[slot - 1] > depth[y, x]:
                keys[slot] = keys[slot - 1]
                order[slot] = order[slot - 1]
                slot -= 1
            keys[slot] = depth[y, x]
            order[slot] = child
            count += 1
    if count == 0:
        return -1
    return order[(count - 1) // 2]


@parallel_njit(cache=True)
def median_depth_level(position, normal, uv, depth, valid, footprint):
    """One level of the splatting buffer's mipmap: the median-depth texel of each 2 x 2 block.

    Sect. 4 of Chen et al. 2012. Among the valid children the lower median depth is
    copied (ties keep the children's row-major order); a block without a valid child is
    invalid and copies its first child. The footprint doubles.

    Returns
    -------
    tuple
        ``position, normal, uv, depth, valid, footprint`` of the coarser level.
    """
    height = (valid.shape[0] + 1) // 2
    width = (valid.shape[1] + 1) // 2
    out_position = np.zeros((height, width, 3), position.dtype)
    out_normal = np.zeros((height, width, 3), normal.dtype)
    out_uv = np.zeros((height, width, 2), uv.dtype)
    out_depth = np.zeros((height, width), depth.dtype)
    out_valid = np.zeros((height, width), np.bool_)
    out_footprint = np.zeros((height, width), footprint.dtype)
    for row in numba.prange(height):  # rows are independent: the same bits on any threads
        for col in range(width):
            child = _median_child(depth, valid, row, col)
            out_valid[row, col] = child >= 0
            child = max(child, 0)
            y = min(2 * row + child // 2, valid.shape[0] - 1)
            x = min(2 * col + child % 2, valid.shape[1] - 1)
            for c in range(3):
                out_position[row, col, c] = position[y, x, c]
                out_normal[row, col, c] = normal[y, x, c]
            out_uv[row, col, 0] = uv[y, x, 0]
            out_uv[row, col, 1] = uv[y, x, 1]
            out_depth[row, col] = depth[y, x]
            out_footprint[row, col] = 2.0 * footprint[y, x]
    return out_position, out_normal, out_uv, out_depth, out_valid, out_footprint


@parallel_njit(cache=True)
def irradiance_level(position, normal, uv, cosine, footprint, flux, depth_min, depth_max,
                     valid):
    """One level of the irradiance buffer's mipmap (Sect. 4 of Chen et al. 2012).

    Position, normal (renormalised), uv, cosine and footprint average the valid children
    (a standard mipmap; the footprint then doubles); flux sums them; the depth range is
    the min / max of the children's (a min/max mipmap). Those six inputs are read as
    ``numpy.nan_to_num`` of them, in float64.

    Returns
    -------
    tuple
        The nine arrays of the coarser level, in the order of the arguments.
    """
    height = (valid.shape[0] + 1) // 2
    width = (valid.shape[1] + 1) // 2
    out_position = np.zeros((height, width, 3))
    out_normal = np.zeros((height, width, 3))
    out_uv = np.zeros((height, width, 2))
    out_cosine = np.zeros((height, width))
    out_footprint = np.zeros((height, width))
    out_flux = np.zeros((height, width, 3))
    out_min = np.full((height, width), np.inf)
    out_max = np.full((height, width), -np.inf)
    out_valid = np.zeros((height, width), np.bool_)
    for row in numba.prange(height):  # rows are independent: the same bits on any threads
        for col in range(width):
            count = 0
            for child in range(4):
                y = 2 * row + child // 2
                x = 2 * col + child % 2
                if y >= valid.shape[0] or x >= valid.shape[1]:
                    continue
                for c in range(3):
                    out_flux[row, col, c] += _finite(flux[y, x, c])
                out_min[row, col] = min(out_min[row, col], depth_min[y, x])
                out_max[row, col] = max(out_max[row, col], depth_max[y, x])
                if not valid[y, x]:
                    continue
                count += 1
                for c in range(3):
                    out_position[row, col, c] += _finite(position[y, x, c])
                    out_normal[row, col, c] += _finite(normal[y, x, c])
                out_uv[row, col, 0] += _finite(uv[y, x, 0])
                out_uv[row, col, 1] += _finite(uv[y, x, 1])
                out_cosine[row, col] += _finite(cosine[y, x])
                out_footprint[row, col] += _finite(footprint[y, x])
            if count == 0:
                continue
            out_valid[row, col] = True
            scale = 1.0 / count
            length = 0.0
            for c in range(3):
                out_position[row, col, c] *= scale
                out_normal[row, col, c] *= scale
                length += out_normal[row, col, c] ** 2
            length = math.sqrt(length)
            for c in range(3):
                out_normal[row, col, c] = out_normal[row, col, c] / length if length > 0 \
                    else 0.0
            out_uv[row, col, 0] *= scale
            out_uv[row, col, 1] *= scale
            out_cosine[row, col] *= scale
            out_footprint[row, col] *= 2.0 * scale
    return (out_position, out_normal, out_uv, out_cosine, out_footprint, out_flux, out_min,
            out_max, out_valid)


# ====================================================================== accumulation
@parallel_njit(fastmath=True, cache=True)
def bilateral_upsample_level(coarse, coarse_depth, coarse_valid, coarse_range, fine_depth,
                             fine_valid, fine_range, depth_scale, range_scale):
    r"""Eq. 17 of Chen et al. 2012: bilateral upsampling of :math:`B^{k+1}` to level k.

    Each valid fine pixel averages its four nearest coarse pixels with weights
    :math:`w_p e^{-\lambda_z |z_o - z_j|/R_w} e^{-\lambda_m |R_{P_o} - R_{P_j}|/R_w}`
    (``depth_scale`` and ``range_scale`` are :math:`\lambda/R_w`); invalid coarse pixels
    weigh 0; a fine pixel with no valid neighbour gets 0.

    Returns
    -------
    ndarray (H, W, 3)
    """
    height, width = fine_valid.shape
    coarse_height, coarse_width = coarse_valid.shape
    out = np.zeros((height, width, 3))
    for row in numba.prange(height):  # rows are independent: the same bits on any threads
        fy = (row + 0.5) / 2.0 - 0.5
        y0 = min(max(int(math.floor(fy)), 0), coarse_height - 1)
        y1 = min(y0 + 1, coarse_height - 1)
        ty = min(max(fy - math.floor(fy), 0.0), 1.0)
        for col in range(width):
            if not fine_valid[row, col]:
                continue
            fx = (col + 0.5) / 2.0 - 0.5
            x0 = min(max(int(math.floor(fx)), 0), coarse_width - 1)
            x1 = min(x0 + 1, coarse_width - 1)
            tx = min(max(fx - math.floor(fx), 0.0), 1.0)
            total0 = 0.0
            total1 = 0.0
            total2 = 0.0
            weights = 0.0
            for corner in range(4):
                y = y0 if corner < 2 else y1
                x = x0 if corner % 2 == 0 else x1
                if not coarse_valid[y, x]:
                    continue
                w = (1.0 - ty if corner < 2 else ty) * (1.0 - tx if corner % 2 == 0 else tx)
                w *= math.exp(-depth_scale * abs(fine_depth[row, col] - coarse_depth[y, x])
                              - range_scale * abs(fine_range[row, col] - coarse_range[y, x]))
                total0 += w * coarse[y, x, 0]
                total1 += w * coarse[y, x, 1]
                total2 += w * coarse[y, x, 2]
                weights += w
            if weights > 1e-30:
                out[row, col, 0] = total0 / weights
                out[row, col, 1] = total1 / weights
                out[row, col, 2] = total2 / weights
    return out


@parallel_njit(cache=True)
def add_scaled_by_texel(exitance, upsampled, factors, texel):
    """Return ``exitance + factors[texel] * upsampled`` (H, W, 3), in parallel over rows.

    The last step of the profile upsampling of Eq. 17 (see
    :func:`translucent.fast.splatting.upsampling_profile_factors`) without the (H, W, 3)
    gather of the factors; not fastmath, so the same bits as the numpy expression.
    """
    height, width = texel.shape
    out = np.empty((height, width, 3))
    for y in numba.prange(height):
        for x in range(width):
            t = texel[y, x]
            for c in range(3):
                out[y, x, c] = exitance[y, x, c] + factors[t, c] * upsampled[y, x, c]
    return out


# ====================================================================== G-buffers
@numba.njit(cache=True)
def _spread(count):
    """``range(count)`` in bit-reversed order: any run of consecutive entries spreads over it.

    numba's ``prange`` gives each thread one consecutive chunk of the iterations; taken in
    this order (0, 4, 2, 6, 1, 5, 3, 7 for eight), each chunk holds rows from the whole
    image, whatever the number of threads, not one thread the empty sky and another the
    object.
    """
    bits = 0
    while (1 << bits) < count:
        bits += 1
    order = np.empty(count, np.int64)
    at = 0
    for index in range(1 << bits):
        reversed_index = 0
        for bit in range(bits):
            reversed_index |= ((index >> bit) & 1) << (bits - 1 - bit)
        if reversed_index < count:
            order[at] = reversed_index
            at += 1
    return order


@numba.njit(cache=True)
def _triangle_box(a, b, c, eye, forward, left, up, tan_x, tan_y, width, height, near,
                  orthographic, projected):
    """Pixel rows and columns ``(y_first, y_last, x_first, x_last)`` a triangle may cover.

    The whole image for a triangle crossing the near plane (``projected[0]`` is then NaN);
    ``y_first = -1`` for one wholly off the image. ``projected`` (9,) receives the corners'
    continuous pixel coordinates (column, row: pixel centres at integers), then each
    edge's columns per row (edge ``k`` from corner ``k`` to ``k + 1``; 0 if horizontal).
    """
    col_low = 1e300
    col_high = -1e300
    row_low = 1e300
    row_high = -1e300
    for corner in range(3):
        p = a if corner == 0 else (b if corner == 1 else c)
        rx = p[0] - eye[0]
        ry = p[1] - eye[1]
        rz = p[2] - eye[2]
        along = rx * forward[0] + ry * forward[1] + rz * forward[2]
        across = rx * left[0] + ry * left[1] + rz * left[2]
        upward = rx * up[0] + ry * up[1] + rz * up[2]
        if not orthographic:
            if along <= near:
                projected[0] = np.nan
                return 0, height - 1, 0, width - 1
            across /= along
            upward /= along
        col = (1.0 - across / tan_x) * 0.5 * width - 0.5
        row = (1.0 - upward / tan_y) * 0.5 * height - 0.5
        projected[2 * corner] = col
        projected[2 * corner + 1] = row
        col_low = min(col_low, col)
        col_high = max(col_high, col)
        row_low = min(row_low, row)
        row_high = max(row_high, row)
    for edge in range(3):
        other = (edge + 1) % 3
        rise = projected[2 * other + 1] - projected[2 * edge + 1]
        projected[6 + edge] = (projected[2 * other] - projected[2 * edge]) / rise \
            if rise != 0.0 else 0.0
    if col_high < -1 or row_high < -1 or col_low > width or row_low > height:
        return -1, -1, -1, -1
    return (max(int(math.floor(row_low)), 0), min(int(math.ceil(row_high)), height - 1),
            max(int(math.floor(col_low)), 0), min(int(math.ceil(col_high)), width - 1))


@numba.njit(inline="always", cache=True)
def _row_span(projected, row, margin):
    """Columns ``(low, high)`` of a projected triangle within ``margin`` of a pixel row.

    The extent in x of the triangle cut by the strip ``|y - row| <= margin``, found on its
    edges (the cut is convex, its corners lie on the edges); ``low > high`` if none. Each
    edge is cut with its slope (:func:`_triangle_box`): no division per row.
    """
    low = math.inf
    high = -math.inf
    for edge in range(3):
        other = (edge + 1) % 3
        px, py = projected[2 * edge], projected[2 * edge + 1]
        qx, qy = projected[2 * other], projected[2 * other + 1]
        bottom = max(min(py, qy), row - margin)
        top = min(max(py, qy), row + margin)
        if bottom > top:
            continue
        if py == qy:
            low = min(low, px, qx)
            high = max(high, px, qx)
            continue
        x_bottom = px + (bottom - py) * projected[6 + edge]
        x_top = px + (top - py) * projected[6 + edge]
        low = min(low, x_bottom, x_top)
        high = max(high, x_bottom, x_top)
    return low, high


@numba.njit(inline="always", cache=True)
def _ray_hit(ox, oy, oz, dx, dy, dz, a, e1x, e1y, e1z, e2x, e2y, e2z, start, depth,
             barycentric, y, x):
    """Möller-Trumbore: record a hit nearer than ``depth[y, x]`` and return whether one was."""
    px = dy * e2z - dz * e2y
    py = dz * e2x - dx * e2z
    pz = dx * e2y - dy * e2x
    det = e1x * px + e1y * py + e1z * pz
    if abs(det) < 1e-300:
        return False
    inverse = 1.0 / det
    tx = ox - a[0]
    ty = oy - a[1]
    tz = oz - a[2]
    u = (tx * px + ty * py + tz * pz) * inverse
    if u < 0.0 or u > 1.0:
        return False
    qx = ty * e1z - tz * e1y
    qy = tz * e1x - tx * e1z
    qz = tx * e1y - ty * e1x
    v = (dx * qx + dy * qy + dz * qz) * inverse
    if v < 0.0 or u + v > 1.0:
        return False
    t = (e2x * qx + e2y * qy + e2z * qz) * inverse
    if t < start or t >= depth[y, x]:
        return False
    depth[y, x] = t
    barycentric[y, x, 0] = u
    barycentric[y, x, 1] = v
    return True


@parallel_njit(cache=True)
def rasterize(vertices, faces, eye, forward, left, up, tan_x, tan_y, width, height, near,
              orthographic, band_rows=RASTER_BAND_ROWS, span_margin=RASTER_SPAN_MARGIN):
    r"""Find the first triangle seen through each pixel: a z-buffer with exact ray tests.

    For each triangle, the pixels of its projected bounding box are tested with the
    pixel's own ray (Möller-Trumbore, float64), exactly the rays of
    :func:`translucent.scenes.gbuffer.camera_rays` (perspective: from ``eye`` through the
    pixel centres, starting at the near plane ``near`` along ``forward``; orthographic:
    parallel to ``forward`` from the image plane through ``eye``, half-widths ``tan_x``,
    ``tan_y`` in scene units). Edges are inclusive, so no ray slips between two triangles;
    the nearer hit wins, the lower triangle index on a tie.

    In parallel over bands of ``band_rows`` image rows: the triangles' boxes are computed
    first (in parallel), binned to the bands they overlap (a counting sort that keeps
    triangle order), then each band tests its own triangles, in index order, on its own
    rows. Every pixel therefore sees the same triangles in the same order as a single
    pass over all triangles (``band_rows >= height``), and the result is the same bits
    whatever the band size or the number of threads. In each row a triangle tests only
    the columns within ``span_margin`` pixels of its projected outline (the whole box
    where it crosses the near plane, or for ``span_margin < 0``): a pixel farther out
    cannot pass the ray test, so the bits are those of the whole box (tested).

    Measured on the heterogeneous scene's 800 x 600 camera buffer (18432 triangles, one
    thread, CPU ms, machine shared): the serial loop over triangles with one ray table
    for the image 37-38; banded 29; testing only the outline's columns 23 (1.85 M ray
    tests to 0.50 M, for 0.25 M pixels that see the object's front and back); each band
    building its own ray table (no 15 MB table) 20; each edge cut with its slope rather
    than two divisions per edge and row 14-15. The bands run in bit-reversed order
    (:func:`_spread`).

    Returns
    -------
    triangle : ndarray (H, W) int64
        Index into ``faces``; -1 where nothing is hit.
    barycentric : ndarray (H, W, 2)
        Weights of the triangle's second and third vertices.
    depth : ndarray (H, W)
        Distance from the eye (perspective) or the image plane along the ray.
    """
    # filled band by band inside the parallel loop, so that memory is first touched there
    triangle = np.empty((height, width), np.int64)
    barycentric = np.empty((height, width, 2))
    depth = np.empty((height, width))
    count = faces.shape[0]
    box = np.empty((count, 4), np.int64)
    projected = np.empty((count, 9))
    for f in numba.prange(count):
        y_first, y_last, x_first, x_last = _triangle_box(
            vertices[faces[f, 0]], vertices[faces[f, 1]], vertices[faces[f, 2]], eye,
            forward, left, up, tan_x, tan_y, width, height, near, orthographic,
            projected[f])
        box[f, 0] = y_first
        box[f, 1] = y_last
        box[f, 2] = x_first
        box[f, 3] = x_last
    bands = (height + band_rows - 1) // band_rows
    band_start = np.zeros(bands + 1, np.int64)
    for f in range(count):
        if box[f, 0] >= 0:
            for band in range(box[f, 0] // band_rows, box[f, 1] // band_rows + 1):
                band_start[band + 1] += 1
    prefix_sum(band_start)
    members = np.empty(band_start[-1], np.int32)
    cursor = band_start[:-1].copy()
    for f in range(count):
        if box[f, 0] >= 0:
            for band in range(box[f, 0] // band_rows, box[f, 1] // band_rows + 1):
                members[cursor[band]] = f
                cursor[band] += 1
    order = _spread(bands)
    for i in numba.prange(bands):
        band = order[i]
        first_row = band * band_rows
        last_row = min(first_row + band_rows, height)
        triangle[first_row:last_row] = -1
        barycentric[first_row:last_row] = 0.0
        depth[first_row:last_row] = np.inf
        if band_start[band] == band_start[band + 1]:
            continue
        # each pixel's unit direction and near-plane distance, computed once for the band
        # rather than for every triangle whose box covers the pixel (the same operations,
        # so the same bits); a band's table stays in the cache
        ray = np.empty((0 if orthographic else last_row - first_row, width, 4))
        for row in range(ray.shape[0]):
            sy = tan_y * (1.0 - 2.0 * (first_row + row + 0.5) / height)
            for x in range(width):
                sx = tan_x * (1.0 - 2.0 * (x + 0.5) / width)
                dx = forward[0] + sx * left[0] + sy * up[0]
                dy = forward[1] + sx * left[1] + sy * up[1]
                dz = forward[2] + sx * left[2] + sy * up[2]
                norm = 1.0 / math.sqrt(dx * dx + dy * dy + dz * dz)
                dx *= norm
                dy *= norm
                dz *= norm
                ray[row, x, 0] = dx
                ray[row, x, 1] = dy
                ray[row, x, 2] = dz
                ray[row, x, 3] = near / (dx * forward[0] + dy * forward[1] + dz * forward[2])
        for j in range(band_start[band], band_start[band + 1]):
            f = members[j]
            a = vertices[faces[f, 0]]
            b = vertices[faces[f, 1]]
            c = vertices[faces[f, 2]]
            e1x = b[0] - a[0]
            e1y = b[1] - a[1]
            e1z = b[2] - a[2]
            e2x = c[0] - a[0]
            e2y = c[1] - a[1]
            e2z = c[2] - a[2]
            spans = span_margin >= 0.0 and not math.isnan(projected[f, 0])
            for y in range(max(box[f, 0], band * band_rows),
                           min(box[f, 1], band * band_rows + band_rows - 1) + 1):
                x_first, x_last = box[f, 2], box[f, 3]
                if spans:
                    low, high = _row_span(projected[f], y, span_margin)
                    if low > high:
                        continue
                    x_first = max(x_first, int(math.ceil(low - span_margin)))
                    x_last = min(x_last, int(math.floor(high + span_margin)))
                sy = tan_y * (1.0 - 2.0 * (y + 0.5) / height)
                for x in range(x_first, x_last + 1):
                    if orthographic:
                        sx = tan_x * (1.0 - 2.0 * (x + 0.5) / width)
                        ox = eye[0] + sx * left[0] + sy * up[0]
                        oy = eye[1] + sx * left[1] + sy * up[1]
                        oz = eye[2] + sx * left[2] + sy * up[2]
                        dx, dy, dz = forward[0], forward[1], forward[2]
                        start = 0.0
                    else:
                        ox, oy, oz = eye[0], eye[1], eye[2]
                        row = y - first_row
                        dx, dy, dz = ray[row, x, 0], ray[row, x, 1], ray[row, x, 2]
                        start = ray[row, x, 3]
                    if _ray_hit(ox, oy, oz, dx, dy, dz, a, e1x, e1y, e1z, e2x, e2y, e2z,
                                start, depth, barycentric, y, x):
                        triangle[y, x] = f
    return triangle, barycentric, depth


@parallel_njit(cache=True)
def interpolate_surface(triangle, barycentric, depth, footprint, first_face, last_face,
                        vertices, faces, normals, uv):
    """Surface attributes of the pixels whose triangle lies in ``[first_face, last_face)``.

    Position and uv are interpolated with the barycentrics; the shading normal is the
    normalised interpolated vertex normal (the face normal where those cancel), as in
    :mod:`translucent.scenes.raycast`. ``faces`` index ``vertices`` of this object alone.
    ``depth`` and ``footprint`` (H, W) are copied at the object's pixels, zero elsewhere.
    Rows in parallel.

    Returns
    -------
    tuple
        ``valid (H, W) bool, position (H, W, 3), normal (H, W, 3), uv (H, W, 2),
        depth (H, W), footprint (H, W)``.
    """
    height, width = triangle.shape
    # every element written once inside the parallel loop (no serial np.zeros first), the
    # normal kept in registers until it is normalised: 8.9 to 6.5 CPU ms at 800 x 600
    valid = np.empty((height, width), np.bool_)
    position = np.empty((height, width, 3))
    normal = np.empty((height, width, 3))
    out_uv = np.empty((height, width, 2))
    out_depth = np.empty((height, width))
    out_footprint = np.empty((height, width))
    has_uv = uv.shape[0] == vertices.shape[0]
    rows = _spread(height)
    for i in numba.prange(height):
        y = rows[i]
        for x in range(width):
            f = triangle[y, x]
            if f < first_face or f >= last_face:
                valid[y, x] = False
                for c in range(3):
                    position[y, x, c] = 0.0
                    normal[y, x, c] = 0.0
                out_uv[y, x, 0] = 0.0
                out_uv[y, x, 1] = 0.0
                out_depth[y, x] = 0.0
                out_footprint[y, x] = 0.0
                continue
            f -= first_face
            valid[y, x] = True
            out_depth[y, x] = depth[y, x]
            out_footprint[y, x] = footprint[y, x]
            b1 = barycentric[y, x, 0]
            b2 = barycentric[y, x, 1]
            b0 = 1.0 - b1 - b2
            i0, i1, i2 = faces[f, 0], faces[f, 1], faces[f, 2]
            for c in range(3):
                position[y, x, c] = b0 * vertices[i0, c] + b1 * vertices[i1, c] + \
                    b2 * vertices[i2, c]
            n0 = b0 * normals[i0, 0] + b1 * normals[i1, 0] + b2 * normals[i2, 0]
            n1 = b0 * normals[i0, 1] + b1 * normals[i1, 1] + b2 * normals[i2, 1]
            n2 = b0 * normals[i0, 2] + b1 * normals[i1, 2] + b2 * normals[i2, 2]
            length = math.sqrt(n0 * n0 + n1 * n1 + n2 * n2)
            if not length > 1e-12:
                e1x = vertices[i1, 0] - vertices[i0, 0]
                e1y = vertices[i1, 1] - vertices[i0, 1]
                e1z = vertices[i1, 2] - vertices[i0, 2]
                e2x = vertices[i2, 0] - vertices[i0, 0]
                e2y = vertices[i2, 1] - vertices[i0, 1]
                e2z = vertices[i2, 2] - vertices[i0, 2]
                n0 = e1y * e2z - e1z * e2y
                n1 = e1z * e2x - e1x * e2z
                n2 = e1x * e2y - e1y * e2x
                length = math.sqrt(n0 * n0 + n1 * n1 + n2 * n2)
            normal[y, x, 0] = n0 / length
            normal[y, x, 1] = n1 / length
            normal[y, x, 2] = n2 / length
            for c in range(2):
                out_uv[y, x, c] = b0 * uv[i0, c] + b1 * uv[i1, c] + b2 * uv[i2, c] \
                    if has_uv else 0.0
    return valid, position, normal, out_uv, out_depth, out_footprint


@parallel_njit(cache=True)
def perspective_footprint(triangle, depth, tan_x, tan_y):
    r"""Side of each pixel's cross-section perpendicular to its ray at the hit, scene units.

    :math:`s = d\,(2\tan(\mathrm{fov}_x/2)/W)\cos^{3/2}\theta` with :math:`d` the distance
    along the ray and :math:`\theta` the ray's angle to the optical axis (the pixel's solid
    angle :math:`(2\tan/W)^2\cos^3\theta` times :math:`d^2`); zero where ``triangle`` is -1.
    The pixel centres are those of :func:`rasterize`. Rows in parallel.
    """
    height, width = triangle.shape
    footprint = np.empty((height, width))
    pixel = 2.0 * tan_x / width
    rows = _spread(height)
    for i in numba.prange(height):
        y = rows[i]
        footprint[y] = 0.0
        sy = tan_y * (1.0 - 2.0 * (y + 0.5) / height)
        for x in range(width):
            if triangle[y, x] >= 0:
                sx = tan_x * (1.0 - 2.0 * (x + 0.5) / width)
                cosine = 1.0 / math.sqrt(1.0 + sx ** 2 + sy ** 2)
                # cos^1.5 as cos sqrt(cos): within an ulp of pow, and 10x cheaper
                footprint[y, x] = depth[y, x] * pixel * (cosine * math.sqrt(cosine))
    return footprint


@numba.njit(inline="always", cache=True)
def _clip_unit(value):
    """``numpy.clip(value, 0, 1)``, NaN kept."""
    if value < 0.0:
        return 0.0
    if value > 1.0:
        return 1.0
    return value


@numba.njit(inline="always", cache=True)
def _finite(value):
    """``numpy.nan_to_num``: NaN to 0, infinities to the largest finite float64."""
    if math.isnan(value):
        return 0.0
    if value == math.inf:
        return 1.7976931348623157e308
    if value == -math.inf:
        return -1.7976931348623157e308
    return value


#: Fresnel transmittance of one cosine, compiled from the materials' own function (the
#: physics written once: :func:`translucent.materials.fresnel.fresnel_transmittance_scalar`).
fresnel_transmittance_at = numba.njit(cache=True)(fresnel_transmittance_scalar)


@parallel_njit(cache=True)
def light_flux(position, normal, valid, footprint, light, power, eta, point):
    r"""Flux and cosine per irradiance-buffer pixel of a delta light, Eq. 5-6 of Chen et al.

    :math:`E\,\Delta A = F_t(\eta, |n\cdot L|)\,E_\perp\,s^2` and :math:`|n\cdot L|`
    (clipped to [0, 1]) at valid pixels, zero elsewhere; NaN cosines and footprints read
    as 0 (see :func:`translucent.fast.splatting.light_view`). Rows in parallel.

    Parameters
    ----------
    position, normal : ndarray (H, W, 3)
        The buffer's hits and unit normals, scene units.
    valid : ndarray (H, W) of bool
    footprint : ndarray (H, W)
        :math:`s`, scene units.
    light, power : ndarray (H, W, 3) or (1, 1, 3)
        With ``point`` False: the unit direction :math:`L` to the light and :math:`E_\perp`
        per pixel (broadcast views are fine). With ``point`` True, shape (1, 1, 3): the
        light's position and intensity :math:`I`, and per pixel
        :math:`L = (p_l - x)/|p_l - x|`, :math:`E_\perp = I/|p_l - x|^2` (squared distance
        at least 1e-300).
    eta : float
        Relative index of refraction.
    point : bool

    Returns
    -------
    tuple
        ``flux (H, W, 3), cosine (H, W)``.
    """
    height, width = valid.shape
    flux = np.empty((height, width, 3))
    cosine = np.empty((height, width))
    rows = _spread(height)
    for i in numba.prange(height):
        y = rows[i]
        flux[y] = 0.0
        cosine[y] = 0.0
        for x in range(width):
            if not valid[y, x]:
                continue
            if point:
                lx = light[0, 0, 0] - position[y, x, 0]
                ly = light[0, 0, 1] - position[y, x, 1]
                lz = light[0, 0, 2] - position[y, x, 2]
                squared = max(lx * lx + ly * ly + lz * lz, 1e-300)
                distance = math.sqrt(squared)
                lx /= distance
                ly /= distance
                lz /= distance
                e0 = power[0, 0, 0] / squared
                e1 = power[0, 0, 1] / squared
                e2 = power[0, 0, 2] / squared
            else:
                lx, ly, lz = light[y, x, 0], light[y, x, 1], light[y, x, 2]
                e0, e1, e2 = power[y, x, 0], power[y, x, 1], power[y, x, 2]
            incidence = _clip_unit(_finite(abs(normal[y, x, 0] * lx + normal[y, x, 1] * ly +
                                               normal[y, x, 2] * lz)))
            cosine[y, x] = incidence
            weight = fresnel_transmittance_at(eta, incidence) * _finite(footprint[y, x]) ** 2
            flux[y, x, 0] = weight * e0
            flux[y, x, 1] = weight * e1
            flux[y, x, 2] = weight * e2
    return flux, cosine


@parallel_njit(cache=True)
def exitant_radiance(exitance, position, normal, valid, origin, eta):
    r"""Eq. 7 of Chen et al. 2012: :math:`L = F_t(\eta, |n\cdot\omega_o|)\,B/\pi` at valid pixels.

    ``exitance`` :math:`B` (H, W, 3), ``origin`` the camera's centre (scene units); zero
    at invalid pixels, NaN read as 0 and infinities as the largest float64 (see
    :func:`translucent.fast.splatting.frame.exitant_radiance_of`). Rows in parallel.
    """
    height, width = valid.shape
    radiance = np.empty((height, width, 3))
    rows = _spread(height)
    for i in numba.prange(height):
        y = rows[i]
        radiance[y] = 0.0
        for x in range(width):
            if not valid[y, x]:
                continue
            dx = origin[0] - position[y, x, 0]
            dy = origin[1] - position[y, x, 1]
            dz = origin[2] - position[y, x, 2]
            length = max(math.sqrt(dx * dx + dy * dy + dz * dz), 1e-300)
            dot = normal[y, x, 0] * (dx / length) + normal[y, x, 1] * (dy / length) + \
                normal[y, x, 2] * (dz / length)
            transmittance = fresnel_transmittance_at(eta, _finite(_clip_unit(abs(dot))))
            for c in range(3):
                radiance[y, x, c] = _finite(transmittance * exitance[y, x, c] / math.pi)
    return radiance
