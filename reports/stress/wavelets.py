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
from ...fast.wavelets import haar2d_forward, haar2d_inverse
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
