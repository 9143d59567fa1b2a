"""Stability of the material kernels: the dipole profile, its total reflectance, Fresnel.

Sweeps cover sigma in [1e-6, 1e3] mm^-1, r in [0, 1e3] mm and eta in [1, 2.5]; float32 is
checked against float64 and float64 against mpmath at 50 digits on a sub-grid.
"""

from __future__ import annotations

import numpy as np

from ...materials.dipole import dipole_reflectance_profile, total_diffuse_reflectance
from ...materials.fresnel import fresnel_transmittance
from . import StressResult, count_nonfinite, stress_kernel

SIGMAS = np.geomspace(1e-6, 1e3, 19)
DISTANCES = np.concatenate([[0.0], np.geomspace(1e-4, 1e3, 29)])
ETAS = np.array([1.0, 1.3, 1.5, 2.0, 2.5])

#: float32 has a 6e-8 unit roundoff; the profile's exponent e^{-sigma_tr d} multiplies the
#: relative rounding of its argument by sigma_tr d, so the error bound grows with it. We
#: judge only values above float32's smallest normal (1.2e-38) and with sigma_tr d <= 80,
#: where 1e-4 relative is the roundoff times that amplification with a safety factor of 20.
FLOAT32_BOUND = 1e-4
#: float64 against 50-digit mpmath: the roundoff 1.1e-16 amplified by sigma_tr d <= 700
#: and the cancellation-free sum of two positive terms: 1e-12 is a generous bound.
MPMATH_BOUND = 1e-12
#: float32 F_t: cos_t = sqrt(1 - sin^2_t) turns a roundoff of 6e-8 in sin^2_t into 2.4e-4
#: in cos_t right at the critical angle (infinite slope); 1e-3 absolute allows for it.
FRESNEL_FLOAT32_BOUND = 1e-3


def _profile_grid(dtype):
    # inputs rounded to float32 first, so both precisions see the same numbers
    r, sigma_a, sigma_s_prime, eta = (x.astype(np.float32).astype(np.float64) for x in
                                      np.meshgrid(DISTANCES, SIGMAS, SIGMAS, ETAS, indexing="ij"))
    return (r, sigma_a, sigma_s_prime, eta), dipole_reflectance_profile(
        r.astype(dtype), sigma_a.astype(dtype), sigma_s_prime.astype(dtype), eta.astype(dtype))


@stress_kernel("dipole profile float32 vs float64")
def dipole_profile_float32() -> StressResult:
    """R_d(r) over the whole grid in float32, against float64."""
    (r, sigma_a, sigma_s_prime, _), p64 = _profile_grid(np.float64)
    _, p32 = _profile_grid(np.float32)
    result = StressResult(evaluations=2 * p64.size, bound=FLOAT32_BOUND, against="float64",
                          notes="float32 roundoff amplified by sigma_tr d <= 80")
    count_nonfinite(p64, result)
    count_nonfinite(p32, result)
    sigma_tr = np.sqrt(3 * sigma_a * (sigma_a + sigma_s_prime))
    exponent = sigma_tr * np.hypot(r, 1 / (sigma_a + sigma_s_prime))
    judged = (p64 > np.finfo(np.float32).tiny * 1e3) & (exponent <= 80)
    error = np.abs(p32.astype(np.float64) - p64) / np.where(judged, p64, 1.0)
    error = np.where(judged, error, 0.0)
    worst = np.unravel_index(np.argmax(error), error.shape)
    result.worst_relative_error = float(error[worst])
    result.worst_at = {"r_mm": float(r[worst]), "sigma_a": float(sigma_a[worst]),
                       "sigma_s_prime": float(sigma_s_prime[worst])}
    return result


@stress_kernel("dipole profile float64 vs mpmath")
def dipole_profile_mpmath() -> StressResult:
    """R_d(r) in float64 against the same formula in 50-digit mpmath on a sub-grid."""
    import mpmath

    mpmath.mp.dps = 50
    result = StressResult(evaluations=0, bound=MPMATH_BOUND, against="mpmath, 50 digits",
                          notes="float64 roundoff amplified by sigma_tr d <= 700")
    worst = 0.0
    for r in DISTANCES[::4]:
        for sigma_a in SIGMAS[::3]:
            for sigma_s_prime in SIGMAS[::3]:
                for eta in ETAS[::2]:
                    value = float(dipole_reflectance_profile(r, sigma_a, sigma_s_prime, eta))
                    exact = _mp_profile(mpmath, r, sigma_a, sigma_s_prime, eta)
                    result.evaluations += 1
                    count_nonfinite(np.array([value]), result)
                    if exact > 1e-300:
                        error = abs(value - float(exact)) / float(exact)
                        if error > worst:
                            worst = error
                            result.worst_at = {"r_mm": r, "sigma_a": sigma_a,
                                               "sigma_s_prime": sigma_s_prime, "eta": eta}
    result.worst_relative_error = worst
    return result


def _mp_profile(mpmath, r, sigma_a, sigma_s_prime, eta):
    mpf = mpmath.mpf
    r, sigma_a, sigma_s_prime, eta = (mpf(float(x)) for x in (r, sigma_a, sigma_s_prime, eta))
    sigma_t_prime = sigma_a + sigma_s_prime
    albedo = sigma_s_prime / sigma_t_prime
    sigma_tr = mpmath.sqrt(3 * sigma_a * sigma_t_prime)
    fdr = -mpf("1.440") / eta**2 + mpf("0.710") / eta + mpf("0.668") + mpf("0.0636") * eta
    boundary = (1 + fdr) / (1 - fdr)
    z_r = 1 / sigma_t_prime
    z_v = z_r * (1 + 4 * boundary / 3)
    total = mpf(0)
    for z in (z_r, z_v):
        d = mpmath.sqrt(r * r + z * z)
        total += z * (sigma_tr + 1 / d) * mpmath.exp(-sigma_tr * d) / (d * d)
    return albedo / (4 * mpmath.pi) * total


@stress_kernel("total diffuse reflectance")
def total_reflectance() -> StressResult:
    """Check the closed-form R_d in [0, 1] everywhere, float32 against float64."""
    sigma_a, sigma_s_prime, eta = np.meshgrid(SIGMAS, SIGMAS, ETAS, indexing="ij")
    sigma_a, sigma_s_prime, eta = (x.astype(np.float32) for x in (sigma_a, sigma_s_prime, eta))
    r64 = total_diffuse_reflectance(sigma_a.astype(np.float64), sigma_s_prime.astype(np.float64),
                                    eta.astype(np.float64))
    r32 = total_diffuse_reflectance(sigma_a, sigma_s_prime, eta)
    result = StressResult(evaluations=2 * r64.size, bound=FLOAT32_BOUND, against="float64",
                          notes="float32 roundoff in exp(-sqrt(3(1 - albedo))) near albedo 1")
    count_nonfinite(r64, result)
    count_nonfinite(r32, result)
    result.negative += int((r64 > 1).sum())  # counted as out of range with the negatives
    judged = r64 > 1e-30
    error = np.where(judged, np.abs(r32 - r64) / np.where(judged, r64, 1), 0)
    result.worst_relative_error = float(error.max())
    return result


@stress_kernel("Fresnel transmittance")
def fresnel() -> StressResult:
    """F_t in [0, 1] for eta in [0.2, 3] and every cosine, float32 against float64."""
    eta, cos = np.meshgrid(np.linspace(0.2, 3.0, 57), np.linspace(0.0, 1.0, 1001), indexing="ij")
    eta, cos = eta.astype(np.float32), cos.astype(np.float32)
    # float64 at the same (float32-rounded) inputs: what is left is the kernel's own error
    t64 = fresnel_transmittance(eta.astype(np.float64), cos.astype(np.float64))
    t32 = fresnel_transmittance(eta, cos)
    result = StressResult(evaluations=2 * t64.size, bound=FRESNEL_FLOAT32_BOUND,
                          against="float64 at the same inputs",
                          notes="absolute error; float32 roundoff in cos_t near the critical "
                                "angle, where F_t has an infinite slope")
    count_nonfinite(t64, result)
    count_nonfinite(t32, result)
    result.negative += int((t64 > 1).sum())
    result.worst_relative_error = float(np.abs(t32 - t64).max())
    return result
