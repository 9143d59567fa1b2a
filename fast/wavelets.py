r"""Wavelet numerics shared by the precomputed-transfer methods.

* The orthonormal 2D Haar transform (non-standard decomposition) of square images whose
  side is a power of two, over the last two axes: the illumination dimension of a transfer
  matrix once its samples are laid out on squares (Eq. 8 of Wang et al. 2008). The kernels
  are compiled (numba) so that they also run inside other compiled loops.
* The balanced quadtree layout of Hašan et al. 2006 that puts unstructured surface samples
  on ``m`` squares of side ``2^n``, so that neighbours on the surface are neighbours in the
  image (Sect. 3.2 of Wang et al. 2008, "Transfer compression").
* The CDF 9/7 wavelet (the JPEG 2000 filter; PyWavelets' ``bior4.4``) of per-vertex data on
  a geometry image, for spatial compression (Eq. 9-10 of Wang et al. 2008), by lifting with
  whole-sample symmetric extension: exactly as many coefficients as vertices for any grid
  size (geometry images have odd sides), and fast enough for the editing loop.

References
----------
Wang et al.: Real-time editing and relighting of homogeneous translucent materials. The
Visual Computer 24 (2008), Sect. 3.2.
Hašan, Pellacini, Bala: Direct-to-indirect transfer for cinematic relighting. ACM TOG 25(3)
(2006) (the balanced quadtree over gather samples).
Stollnitz, DeRose, Salesin: Wavelets for computer graphics: a primer (non-standard Haar).
Daubechies, Sweldens: Factoring wavelet transforms into lifting steps. J. Fourier Anal.
Appl. 4 (1998) (the CDF 9/7 lifting constants).
"""

from __future__ import annotations

import math

import numba
import numpy as np

from ..errors import InputError

__all__ = [
    "haar2d_forward",
    "haar2d_forward_in_place",
    "haar2d_inverse",
    "haar2d_inplace",
    "haar2d_support_weights",
    "balanced_split",
    "quadtree_layout",
    "SpatialWavelet",
    "cdf97_levels",
]

#: Lifting constants of the CDF 9/7 wavelet (Daubechies and Sweldens 1998, as in JPEG 2000).
CDF97_ALPHA = -1.586134342059924
CDF97_BETA = -0.052980118572961
CDF97_GAMMA = 0.882911075530934
CDF97_DELTA = 0.443506852043971
CDF97_K = 1.230174104914001
#: Scalings after lifting that reproduce PyWavelets' ``bior4.4`` coefficients exactly away
#: from the borders (low-pass DC gain sqrt(2), the high-pass sign PyWavelets uses).
CDF97_LOW_SCALE = math.sqrt(2.0) / CDF97_K
CDF97_HIGH_SCALE = -CDF97_K / math.sqrt(2.0)

#: A level of the spatial transform is applied while both sides of the remaining
#: low-pass block are at least this long (shorter signals gain nothing from 9-tap filters).
CDF97_MIN_SIDE = 8


# ------------------------------------------------------------------------------- Haar


def _square_side(array: np.ndarray) -> int:
    side = array.shape[-1]
    if array.ndim < 2 or array.shape[-2] != side or side < 1 or side & (side - 1):
        raise InputError("the last two axes must be a square whose side is a power of two",
                         field="shape", value=array.shape)
    return side


@numba.njit(cache=True, nogil=True)
def haar2d_inplace(image, scratch):  # pragma: no cover - compiled
    """Forward orthonormal non-standard 2D Haar of one contiguous (S, S) image, in place.

    ``scratch`` is a float array of at least S * S entries. Compiled; see
    :func:`haar2d_forward`.
    """
    side = image.shape[0]
    while side > 1:
        half = side // 2
        for row in range(half):
            for col in range(half):
                a = image[2 * row, 2 * col]
                b = image[2 * row, 2 * col + 1]
                c = image[2 * row + 1, 2 * col]
                d = image[2 * row + 1, 2 * col + 1]
                scratch[row * side + col] = (a + b + c + d) * 0.5
                scratch[row * side + col + half] = (a - b + c - d) * 0.5
                scratch[(row + half) * side + col] = (a + b - c - d) * 0.5
                scratch[(row + half) * side + col + half] = (a - b - c + d) * 0.5
        for row in range(side):
            for col in range(side):
                image[row, col] = scratch[row * side + col]
        side = half


@numba.njit(cache=True, nogil=True)
def _haar2d_inverse_inplace(image, scratch):  # pragma: no cover - compiled
    full = image.shape[0]
    side = 2
    while side <= full:
        half = side // 2
        for row in range(half):
            for col in range(half):
                average = image[row, col]
                horizontal = image[row, col + half]
                vertical = image[row + half, col]
                diagonal = image[row + half, col + half]
                top = (average + vertical) * 0.5
                bottom = (average - vertical) * 0.5
                top_detail = (horizontal + diagonal) * 0.5
                bottom_detail = (horizontal - diagonal) * 0.5
                scratch[2 * row * side + 2 * col] = top + top_detail
                scratch[2 * row * side + 2 * col + 1] = top - top_detail
                scratch[(2 * row + 1) * side + 2 * col] = bottom + bottom_detail
                scratch[(2 * row + 1) * side + 2 * col + 1] = bottom - bottom_detail
        for row in range(side):
            for col in range(side):
                image[row, col] = scratch[row * side + col]
        side *= 2


@numba.njit(cache=True, nogil=True)
def _haar2d_many(images, inverse):  # pragma: no cover - compiled
    # serial: the per-frame transforms are small, and a parallel loop's start-up costs more
    # than the work on a shared machine (measured 0.01 ms serial, 28 ms on two busy cores)
    side = images.shape[1]
    scratch = np.empty(side * side, dtype=images.dtype)
    for index in range(images.shape[0]):
        if inverse:
            _haar2d_inverse_inplace(images[index], scratch)
        else:
            haar2d_inplace(images[index], scratch)


def _haar2d(array, inverse: bool, copy: bool = True) -> np.ndarray:
    dtype = np.float32 if np.asarray(array).dtype == np.float32 else np.float64
    out = np.array(array, dtype=dtype, copy=True, order="C") if copy else array
    side = _square_side(out)
    if side > 1 and out.size:
        _haar2d_many(out.reshape(-1, side, side), inverse)
    return out


def haar2d_forward_in_place(image: np.ndarray) -> np.ndarray:
    """:func:`haar2d_forward` overwriting ``image`` (C-contiguous float32 or float64); return it.

    For large per-frame arrays, where the copy costs as much as the transform.
    """
    if not (isinstance(image, np.ndarray) and image.flags.c_contiguous
            and image.dtype in (np.float32, np.float64)):
        raise InputError("must be a C-contiguous float32 or float64 array", field="image",
                         value=getattr(image, "dtype", type(image).__name__))
    return _haar2d(image, inverse=False, copy=False)


def haar2d_forward(image) -> np.ndarray:
    r"""Orthonormal non-standard 2D Haar transform over the last two axes.

    Each level replaces the top-left :math:`s \times s` block by its averages
    :math:`(a + b + c + d)/2` (top-left quadrant) and the details
    :math:`(a - b + c - d)/2` (top right), :math:`(a + b - c - d)/2` (bottom left) and
    :math:`(a - b - c + d)/2` (bottom right), down to a single scaling coefficient.
    Orthonormal, so it keeps L2 norms and inner products: Eq. 8 of Wang et al. 2008,
    :math:`T E = (T w')(w E)`, relies on :math:`w' w = I`.

    Parameters
    ----------
    image : array_like, shape (..., S, S)
        S a power of two. float32 stays float32; anything else becomes float64.

    Returns
    -------
    ndarray, shape (..., S, S)
    """
    return _haar2d(image, inverse=False)


def haar2d_inverse(coefficients) -> np.ndarray:
    """Inverse (and transpose) of :func:`haar2d_forward`, over the last two axes.

    Parameters
    ----------
    coefficients : array_like, shape (..., S, S)

    Returns
    -------
    ndarray, shape (..., S, S)
    """
    return _haar2d(coefficients, inverse=True)


def haar2d_support_weights(parts: int, side: int) -> np.ndarray:
    """Square root of the support (in pixels) of each coefficient of :func:`haar2d_forward`.

    For ``parts`` squares of side ``side`` flattened row-major, shape ``(parts * side**2,)``,
    float32: ``side`` for the scaling coefficient and the coarsest details, ``side / 2**j``
    for the details of the block ``max(row, col) in [2**j, 2**(j + 1))``. A Haar function
    with this support has an inner product of at most this times ``max|f|`` with any ``f``.
    """
    index = np.arange(side)
    largest = np.maximum(index[:, None], index[None, :])
    level = np.floor(np.log2(np.maximum(largest, 1))).astype(int)
    weights = (side / 2.0**level).astype(np.float32)
    return np.tile(weights.ravel(), parts)


# ------------------------------------------------------------------- sample layout


def balanced_split(points, parts: int) -> np.ndarray:
    """Split points into ``parts`` groups of equal size by recursive median cuts.

    Each cut is across the longest side of the group's bounding box, with group sizes in
    proportion to the number of parts on either side (the spatial partition of Sect. 3.2 of
    Wang et al. 2008, before the quadtree of each part).

    Parameters
    ----------
    points : array_like, shape (P, D)
        P divisible by ``parts``.
    parts : int, >= 1

    Returns
    -------
    ndarray, shape (parts, P // parts), int64
        Indices of the points of each part.
    """
    points = np.asarray(points, dtype=np.float64)
    if isinstance(parts, bool) or int(parts) != parts or parts < 1 or len(points) % parts:
        raise InputError(f"must be an integer >= 1 dividing the {len(points)} points",
                         field="parts", value=parts)
    per_part = len(points) // int(parts)

    def split(indices, count):
        if count == 1:
            return [indices]
        axis = int(np.ptp(points[indices], axis=0).argmax())
        order = indices[np.argsort(points[indices, axis], kind="stable")]
        left = count // 2
        cut = left * per_part
        return split(order[:cut], left) + split(order[cut:], count - left)

    return np.stack(split(np.arange(len(points)), int(parts)))


def quadtree_layout(points, level: int) -> np.ndarray:
    """Lay ``4**level`` points on a ``2**level`` square by a balanced quadtree (Hašan et al.).

    Every node splits its points into four equal children: in two halves across the longest
    side of its bounding box, then each half across its own longest side; the children take
    the four quadrants of the node's square. Flattening the tree this way keeps points that
    are close on the surface close in the image, which is what makes the Haar coefficients
    of a transfer row sparse.

    Parameters
    ----------
    points : array_like, shape (4**level, D)
    level : int, >= 0

    Returns
    -------
    ndarray, shape (2**level, 2**level), int64
        ``image[row, col]`` is the index of the point placed there.
    """
    points = np.asarray(points, dtype=np.float64)
    if isinstance(level, bool) or int(level) != level or level < 0 \
            or len(points) != 4 ** int(level):
        raise InputError(f"needs 4**level points; got {len(points)}", field="level",
                         value=level)
    level = int(level)
    side = 2 ** level
    # all nodes of one depth are split together: each is a contiguous run of `order`
    order = np.arange(len(points))
    rows = np.zeros(len(points), dtype=np.int64)
    cols = np.zeros(len(points), dtype=np.int64)
    group_size = len(points)
    for depth in range(level):
        for target in (rows, cols):
            group_size //= 2
            groups = order.reshape(-1, 2 * group_size)
            coordinates = points[groups]
            axis = (coordinates.max(axis=1) - coordinates.min(axis=1)).argmax(axis=1)
            key = np.take_along_axis(coordinates, axis[:, None, None], axis=2)[..., 0]
            groups = np.take_along_axis(groups, np.argsort(key, axis=1, kind="stable"), axis=1)
            order = groups.reshape(-1)
            bit = np.tile(np.repeat(np.array([0, 1]), group_size), len(groups))
            target[order] |= bit << (level - 1 - depth)
    image = np.empty((side, side), dtype=np.int64)
    image[rows, cols] = np.arange(len(points))
    return image


# ------------------------------------------------------------------------ CDF 9/7


@numba.njit(cache=True, nogil=True)
def _lift_step(line, first, weight):  # pragma: no cover - compiled
    """``line[i] += weight (line[i-1] + line[i+1])`` for i = first, first + 2, ... (mirrored)."""
    length, channels = line.shape
    for i in range(first, length, 2):
        left = i - 1 if i > 0 else 1
        right = i + 1 if i + 1 < length else length - 2
        for c in range(channels):
            line[i, c] += weight * (line[left, c] + line[right, c])


@numba.njit(cache=True, nogil=True)
def _lift_line(line, scratch, inverse):  # pragma: no cover - compiled
    """CDF 9/7 of one line ``line[n, channels]`` in place (Mallat order: lows, then highs)."""
    length, channels = line.shape
    if length < 2:
        return
    lows = (length + 1) // 2
    if inverse:
        for i in range(length):
            source = i // 2 if i % 2 == 0 else lows + i // 2
            scale = 1.0 / CDF97_LOW_SCALE if i % 2 == 0 else 1.0 / CDF97_HIGH_SCALE
            for c in range(channels):
                scratch[i, c] = line[source, c] * scale
        _lift_step(scratch, 0, -CDF97_DELTA)
        _lift_step(scratch, 1, -CDF97_GAMMA)
        _lift_step(scratch, 0, -CDF97_BETA)
        _lift_step(scratch, 1, -CDF97_ALPHA)
        line[:, :] = scratch[:length, :]
        return
    _lift_step(line, 1, CDF97_ALPHA)
    _lift_step(line, 0, CDF97_BETA)
    _lift_step(line, 1, CDF97_GAMMA)
    _lift_step(line, 0, CDF97_DELTA)
    for i in range(length):
        target = i // 2 if i % 2 == 0 else lows + i // 2
        scale = CDF97_LOW_SCALE if i % 2 == 0 else CDF97_HIGH_SCALE
        for c in range(channels):
            scratch[target, c] = line[i, c] * scale
    line[:, :] = scratch[:length, :]


@numba.njit(cache=True, nogil=True)
def _lift_axis(data, rows, cols, along_rows, inverse):  # pragma: no cover - compiled
    """Lift every line of the top-left ``rows x cols`` block of ``data[R, C, channels]``.

    Serial and free of the GIL: callers parallelise over independent channel blocks with
    threads (a shared machine punishes fine-grained parallel loops on small frames).
    """
    channels = data.shape[2]
    if along_rows:  # lines run down the columns
        scratch = np.empty((rows, channels), dtype=data.dtype)
        line = np.empty((rows, channels), dtype=data.dtype)
        for col in range(cols):
            for i in range(rows):
                for c in range(channels):
                    line[i, c] = data[i, col, c]
            _lift_line(line, scratch, inverse)
            for i in range(rows):
                for c in range(channels):
                    data[i, col, c] = line[i, c]
    else:
        scratch = np.empty((cols, channels), dtype=data.dtype)
        for row in range(rows):
            _lift_line(data[row, :cols, :], scratch, inverse)


def cdf97_levels(shape, min_side: int = CDF97_MIN_SIDE) -> list[tuple[int, int]]:
    """Block sizes ``(rows, cols)`` transformed at each level for a grid of ``shape``."""
    rows, cols = (int(n) for n in shape)
    sizes = []
    while min(rows, cols) >= min_side:
        sizes.append((rows, cols))
        rows, cols = (rows + 1) // 2, (cols + 1) // 2
    return sizes


class SpatialWavelet:
    """Multi-level 2D CDF 9/7 transform of per-vertex data on a geometry image.

    Eq. 9-10 of Wang et al. 2008: spatial compression of the transfer, and the inverse
    transform that ends every frame. Vertices are the cells of a ``rows x cols`` grid in
    row-major order (:attr:`translucent.scenes.Mesh.grid_shape`); the coefficients are
    stored the same way (Mallat layout: low-pass block top-left). Whole-sample symmetric
    extension at the borders (the border of a spherical geometry image is mirrored too),
    so there are exactly as many coefficients as vertices for any size. Away from the
    borders the coefficients equal PyWavelets' ``bior4.4``. Biorthogonal, not orthonormal:
    energies are kept only approximately.

    Parameters
    ----------
    grid_shape : (int, int)
        ``(rows, cols)``, each >= 2.
    min_side : int
        Levels are applied while both sides of the low-pass block are at least this long.
    """

    def __init__(self, grid_shape, min_side: int = CDF97_MIN_SIDE):
        rows, cols = (int(n) for n in grid_shape)
        if rows < 2 or cols < 2:
            raise InputError("a geometry image needs at least 2 x 2 vertices",
                             field="grid_shape", value=grid_shape)
        self.grid_shape = (rows, cols)
        self.level_sizes = cdf97_levels(self.grid_shape, min_side)

    @property
    def size(self) -> int:
        """Number of vertices (and of coefficients)."""
        return self.grid_shape[0] * self.grid_shape[1]

    def _transform(self, values, inverse: bool) -> np.ndarray:
        values = np.asarray(values)
        if values.shape[:1] != (self.size,):
            raise InputError(f"needs one row per vertex of the {self.grid_shape} grid",
                             field="values", value=values.shape)
        dtype = np.float32 if values.dtype == np.float32 else np.float64
        data = np.array(values, dtype=dtype, order="C").reshape(self.grid_shape + (-1,))
        if inverse:
            for rows, cols in reversed(self.level_sizes):
                _lift_axis(data, rows, cols, True, True)
                _lift_axis(data, rows, cols, False, True)
        else:
            for rows, cols in self.level_sizes:
                _lift_axis(data, rows, cols, False, False)
                _lift_axis(data, rows, cols, True, False)
        return data.reshape(values.shape)

    def forward(self, values) -> np.ndarray:
        """Coefficients of per-vertex ``values`` (shape ``(V, ...)``), same shape."""
        return self._transform(values, inverse=False)

    def inverse(self, coefficients) -> np.ndarray:
        """Per-vertex values from ``coefficients`` (shape ``(V, ...)``), same shape."""
        return self._transform(coefficients, inverse=True)
