"""Stability of transfer compression at extreme ratios: Haar, nonlinear cut, quantisation.

The path a transfer row takes in the precomputed-transfer method (Sect. 3.2 of Wang et al.
2008): a float32 orthonormal 2D Haar transform (:func:`~translucent.fast.wavelets.
haar2d_forward`), a cut to its k largest coefficients (:func:`~translucent.fast.
sparse_transport.nonlinear_approximation`), 16-bit quantisation with 16-bit column indices
(14/18 bits beyond 2^16 columns), and back. Rows are constant, a single delta, uniform
random and log-uniform over 1e-30 .. 1e30 with random signs; k runs from 1 term to all of
them; rows have 2^8, 2^16 and 2^18 samples (the last needs the 18-bit indices).

The bound is a theorem for an orthonormal transform: the reconstruction error is at most
the norm of the dropped coefficients plus the quantisation error of the kept ones (half a
step each, a step being the row's largest kept magnitude over the top level) plus the
float32 rounding of the two transforms. The product of a quantised matrix with an RGB
vector (Eq. 8) is judged against the same product in float64 of the values the words
stand for.
"""

from __future__ import annotations

import numpy as np

from ...errors import InputError
from ...fast.sparse_transport import MAX_COLUMNS, index_bits_for, nonlinear_approximation
from ...fast.wavelets import (
    CDF97_ALPHA,
    CDF97_BETA,
    CDF97_DELTA,
    CDF97_GAMMA,
    SpatialWavelet,
    haar2d_forward,
    haar2d_inverse,
)
from . import StressResult, count_nonfinite, stress_kernel

#: Sides of the Haar squares: 2^8, 2^16 (the last 16-bit index) and 2^18 samples.
SIDES = (16, 256, 512)
ROW_KINDS = ("constant", "delta", "random", "dynamic range 1e-30..1e30")

#: float32 unit roundoff.
FLOAT32_ROUNDOFF = 2.0**-24
#: One level of the 2D Haar transform forms (a +- b +- c +- d) / 2: three roundings on a
#: sum bounded by 2 |(a, b, c, d)|, in four outputs, so at most 6 u |x| per level in norm;
#: forward and inverse: 12 u |x| per level.
HAAR_ROUNDING_PER_LEVEL = 12 * FLOAT32_ROUNDOFF


def term_counts(size: int) -> tuple[int, ...]:
    """Kept terms swept for a row of ``size`` samples: 1 .. all."""
    return tuple(sorted({1, 2, 16, max(1, size // 4), size}))


def make_row(kind: str, size: int, rng) -> np.ndarray:
    """Return a float32 test row of ``size`` samples of the given kind."""
    if kind == "constant":
        return np.full(size, 0.7, dtype=np.float32)
    if kind == "delta":
        row = np.zeros(size, dtype=np.float32)
        row[int(rng.integers(size))] = 1.0
        return row
    if kind == "random":
        return rng.uniform(0.0, 1.0, size).astype(np.float32)
    signs = rng.choice([-1.0, 1.0], size)
    return (signs * 10.0 ** rng.uniform(-30.0, 30.0, size)).astype(np.float32)


def _compress(row: np.ndarray, side: int, terms: int):
    """Haar, keep ``terms``, quantise, dequantise, inverse Haar; returns the pieces."""
    coefficients = haar2d_forward(row.reshape(1, side, side)).reshape(1, -1)
    kept = nonlinear_approximation(coefficients, 1.0, terms)
    quantised = kept.quantised()
    restored = quantised.dequantised()
    reconstruction = haar2d_inverse(restored.to_dense().reshape(1, side, side)).reshape(-1)
    return coefficients.reshape(-1), kept, quantised, restored, reconstruction


def _compression_bound(row, coefficients, kept, quantised, side) -> float:
    """Dropped-coefficient norm + quantisation + float32 Haar rounding (absolute, float64)."""
    x = row.astype(np.float64)
    c = coefficients.astype(np.float64)
    mask = np.ones(c.size, dtype=bool)
    mask[kept.indices] = False
    dropped = float(np.sqrt((c[mask] ** 2).sum()))
    value_max = float((1 << (31 - quantised.index_bits)) - 1)
    step = float(np.abs(kept.values.astype(np.float64)).max(initial=0.0)) / value_max
    kept_norm = float(np.linalg.norm(kept.values.astype(np.float64)))
    # half a level per kept value, plus float32 rounding of the scale and of level x scale
    quantisation = np.sqrt(kept.nnz) * step / 2 + 2 * FLOAT32_ROUNDOFF * kept_norm
    levels = int(np.log2(side))
    return dropped + quantisation + HAAR_ROUNDING_PER_LEVEL * levels * float(np.linalg.norm(x))


def _product_check(quantised, restored, rng):
    """Return (relative error, relative bound) of the packed RGB product against float64."""
    vector = rng.uniform(0.0, 1.0, (quantised.columns, 3)).astype(np.float32)
    product = quantised.product(vector).astype(np.float64)
    values = restored.values.astype(np.float64)
    exact = np.zeros(3)
    magnitude = np.zeros(3)
    if restored.nnz:
        exact = values @ vector[restored.indices].astype(np.float64)
        magnitude = np.abs(values) @ vector[restored.indices].astype(np.float64)
    # float32 sums of nnz terms in any order (gamma_n), the level x vector products and the
    # final scaling: (nnz + 2) u sum |terms| (Higham, Sect. 3.1)
    n = restored.nnz + 2
    bound = n * FLOAT32_ROUNDOFF / (1 - n * FLOAT32_ROUNDOFF) * magnitude
    return product.reshape(-1), exact, bound


@stress_kernel("wavelet compression at extreme ratios")
def wavelet_compression(sides=SIDES, kinds=ROW_KINDS, seed: int = 0) -> StressResult:
    """Haar + nonlinear cut + quantisation of extreme rows, against the orthonormal bound.

    Parameters
    ----------
    sides : sequence of int
        Sides of the Haar squares (powers of two); rows have ``side**2`` samples.
    kinds : sequence of str
        Among :data:`ROW_KINDS`.
    seed : int
    """
    rng = np.random.default_rng(seed)
    result = StressResult(evaluations=0, bound=1.0, against="orthonormal-transform bound",
                          notes="|x - x~| within |dropped coefficients| + quantisation "
                                "(half a step per kept term) + float32 Haar rounding; products "
                                "within gamma_(nnz+2) sum|terms|; negative counts corrupted "
                                "indices, bound-breaking products and a refused-size check "
                                "that did not refuse")
    worst = -1.0
    for side in sides:
        size = side * side
        for kind in kinds:
            row = make_row(kind, size, rng)
            norm = float(np.linalg.norm(row.astype(np.float64)))
            for terms in term_counts(size):
                coefficients, kept, quantised, restored, reconstruction = _compress(row, side,
                                                                                    terms)
                result.evaluations += size + kept.nnz
                count_nonfinite(coefficients, result, negative=False)
                count_nonfinite(reconstruction, result, negative=False)
                corrupted = int((restored.indices != kept.indices).sum())
                result.negative += corrupted
                error = float(np.linalg.norm(reconstruction.astype(np.float64) - row))
                bound = _compression_bound(row, coefficients, kept, quantised, side)
                product, exact, product_bound = _product_check(quantised, restored, rng)
                count_nonfinite(product, result, negative=False)
                product_breaks = int((np.abs(product - exact) > product_bound).sum())
                result.negative += product_breaks
                case = {"samples": size, "row": kind, "terms": terms, "kept": kept.nnz,
                        "index_bits": quantised.index_bits,
                        "relative_error": error / norm if norm else error,
                        "relative_bound": bound / norm if norm else bound,
                        "corrupted_indices": corrupted, "product_bound_breaks": product_breaks}
                result.details.append(case)
                ratio = error / bound if bound > 0 else (0.0 if error == 0 else np.inf)
                if ratio > worst:
                    worst = ratio
                    result.worst_relative_error = case["relative_error"]
                    result.bound = case["relative_bound"]
                    result.worst_at = {k: case[k] for k in ("samples", "row", "terms")}
    try:
        index_bits_for(MAX_COLUMNS + 1)
        result.negative += 1
        result.details.append({"columns": MAX_COLUMNS + 1, "outcome": "accepted"})
    except InputError as error:
        result.details.append({"columns": MAX_COLUMNS + 1, "outcome": "refused",
                               "message": str(error)})
    return result


# ------------------------------------------------------------------ spatial CDF 9/7

#: Geometry-image grids of the spatial sweep: odd and even sides, 2 levels each, small
#: enough for the dense SVD of the inverse transform that gives the bound.
SPATIAL_GRIDS = ((17, 40), (24, 24))
#: Lifting weights of one 1D CDF 9/7 pass (Daubechies and Sweldens 1998).
LIFTING_WEIGHTS = (CDF97_ALPHA, CDF97_BETA, CDF97_GAMMA, CDF97_DELTA)


def lifting_rounding_bound(levels: int) -> float:
    r"""Worst-case relative float32 rounding of a forward and inverse CDF 9/7 transform.

    A lifting step :math:`x_i \mathrel{+}= w(x_{i-1} + x_{i+1})` rounds three times on at
    most :math:`(1 + 2|w|)` times the line's norm, and scales the norm by up to
    :math:`1 + 2|w|`; one 1D pass of four steps and a scaling therefore rounds by at most
    :math:`u\,(1 + \sum_s 3(1 + 2|w_s|))\prod_s(1 + 2|w_s|)` of its input norm, and a level
    runs two passes (rows and columns), forward and inverse. A crude bound (the measured
    error is ~1e3 times smaller); what it catches is NaN, overflow and lost indices.
    """
    growth = float(np.prod([1.0 + 2.0 * abs(w) for w in LIFTING_WEIGHTS]))
    per_pass = (1.0 + sum(3.0 * (1.0 + 2.0 * abs(w)) for w in LIFTING_WEIGHTS)) * growth
    return 2 * 2 * levels * FLOAT32_ROUNDOFF * per_pass


def _largest(coefficients: np.ndarray, terms: int) -> np.ndarray:
    """Keep the ``terms`` largest magnitudes of every column, zero the rest."""
    if terms >= len(coefficients):
        return coefficients.copy()
    order = np.argsort(-np.abs(coefficients), axis=0, kind="stable")
    kept = np.zeros_like(coefficients)
    rows = order[:terms]
    columns = np.arange(coefficients.shape[1])[None, :]
    kept[rows, columns] = coefficients[rows, columns]
    return kept


@stress_kernel("spatial CDF 9/7 compression at extreme ratios")
def spatial_compression(grids=SPATIAL_GRIDS, kinds=ROW_KINDS, seed: int = 0) -> StressResult:
    r"""Per-vertex data on a geometry image: CDF 9/7, k largest coefficients, inverse.

    The float64 path is judged against :math:`\sigma_{max}(W^{-1})` times the norm of the
    dropped coefficients (the transform is biorthogonal, not orthonormal: its inverse's
    largest singular value, computed from the dense matrix, replaces Parseval); the float32
    path, all coefficients kept, against :func:`lifting_rounding_bound`.

    Parameters
    ----------
    grids : sequence of (int, int)
        Geometry-image shapes (rows, cols).
    kinds : sequence of str
        Among :data:`ROW_KINDS`, one channel each.
    seed : int
    """
    rng = np.random.default_rng(seed)
    result = StressResult(evaluations=0, bound=1.0, against="biorthogonal-transform bound",
                          notes="|x - x~| within sigma_max(W^-1) |dropped| (float64, plus "
                                "its lifting rounding) and the float32 round trip within the "
                                "lifting rounding bound; the case closest to its bound is "
                                "shown")
    worst = -1.0
    for shape in grids:
        wavelet = SpatialWavelet(shape)
        size = wavelet.size
        inverse_norm = float(np.sqrt(np.linalg.eigvalsh(
            (lambda m: m.T @ m)(wavelet.inverse(np.eye(size))))[-1]))
        values = np.stack([make_row(kind, size, rng).astype(np.float64) for kind in kinds],
                          axis=1)
        norms = np.linalg.norm(values, axis=0)
        coefficients = wavelet.forward(values)
        single = wavelet.inverse(wavelet.forward(values.astype(np.float32)))
        count_nonfinite(coefficients, result, negative=False)
        count_nonfinite(single, result, negative=False)
        float32_error = np.linalg.norm(single.astype(np.float64) - values, axis=0) / norms
        float32_bound = lifting_rounding_bound(len(wavelet.level_sizes)) * inverse_norm
        # the same rounding analysis with float64's unit roundoff
        float64_rounding = float32_bound * (np.finfo(np.float64).eps / 2) / FLOAT32_ROUNDOFF
        for c, kind in enumerate(kinds):
            case = {"grid": list(shape), "row": kind, "terms": size,
                    "relative_error": float(float32_error[c]), "relative_bound": float32_bound,
                    "precision": "float32"}
            result.details.append(case)
            if float32_error[c] / float32_bound > worst:
                worst = float32_error[c] / float32_bound
                result.worst_relative_error, result.bound = case["relative_error"], float32_bound
                result.worst_at = {k: case[k] for k in ("grid", "row", "terms", "precision")}
        for terms in sorted({1, 16, size // 4, size}):
            kept = _largest(coefficients, terms)
            reconstruction = wavelet.inverse(kept)
            result.evaluations += reconstruction.size + coefficients.size
            count_nonfinite(reconstruction, result, negative=False)
            errors = np.linalg.norm(reconstruction - values, axis=0) / norms
            bounds = inverse_norm * np.linalg.norm(coefficients - kept, axis=0) / norms \
                + float64_rounding
            for c, kind in enumerate(kinds):
                case = {"grid": list(shape), "row": kind, "terms": terms,
                        "relative_error": float(errors[c]),
                        "relative_bound": float(bounds[c]), "precision": "float64"}
                result.details.append(case)
                if errors[c] / bounds[c] > worst:
                    worst = errors[c] / bounds[c]
                    result.worst_relative_error = case["relative_error"]
                    result.bound = case["relative_bound"]
                    result.worst_at = {k: case[k] for k in ("grid", "row", "terms",
                                                            "precision")}
    return result
