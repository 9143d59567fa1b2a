"""Stability of the dipole PCA projection for profiles outside the sampled coefficient grid.

The basis of Sect. 3.1 of Wang et al. 2008 is built from profiles over a bounded grid of
coefficients (``[0, 5]`` mm^-1 for the paper's sampling, ``[1e-4, 25]`` mm^-1 for the
area-normalised one). These sweeps project profiles with sigma_a and sigma_s' over
``[1e-6, 1e3]`` mm^-1 and eta over ``[1, 2.5]`` onto both preset bases and check what the
editing loop relies on: finite coefficients, finite reconstructions, a projection that never
holds more energy than its profile (Bessel's inequality), float32 coefficients that
reconstruct what float64 ones do, and a profile energy that matches the exact one wherever
the precomputed-transfer method trusts the projection.
"""

from __future__ import annotations

import functools

import numpy as np

from ...fast.prt import projection_blend
from ...materials.catalogue import MEASURED_MEDIA
from ...materials.dipole import dipole_reflectance_profile
from ...materials.dipole_pca import dipole_pca_basis
from . import StressResult, count_nonfinite, stress_kernel

SIGMAS = np.geomspace(1e-6, 1e3, 19)
ETAS = (1.0, 1.3, 1.5, 2.0, 2.5)
BASES = ("paper", "area_normalised")

#: float32 unit roundoff.
FLOAT32_ROUNDOFF = 2.0**-24
#: Slack on Bessel's inequality |s|^2 <= |w R_d|^2: both sides are float64 sums of at most
#: 650 positive terms, each with a relative rounding of ~1e-16; 1e-10 is far above that.
BESSEL_SLACK = 1e-10
#: The energy of a projection the method trusts (residual below LOCAL_BLEND_START) may be off
#: by at most this many times the worst energy error of the 36 measured profiles, which lie
#: inside the grid and are what the basis is built for: outside the grid a trusted
#: projection should be about as good as inside it.
TRUSTED_ENERGY_FACTOR = 2.0
#: Distances of the energy integrals: with r = R t^2 the first step is 4e-6 mm, well inside
#: the narrowest profile swept (mean free path 5e-4 mm at 1e3 mm^-1).
ENERGY_RADII = 4001


def float32_reconstruction_bound(terms: int) -> float:
    r"""Relative L2 bound of a float32 reconstruction :math:`U s` of K terms.

    Rounding the coefficients and the orthonormal vectors to float32 changes :math:`U s` by
    at most :math:`u(1 + \sqrt K)\lVert s\rVert`, the K-term float32 dot products add
    :math:`\gamma_K\sqrt K\lVert s\rVert` with :math:`\gamma_K = Ku/(1 - Ku)` (Higham,
    Accuracy and Stability of Numerical Algorithms, Sect. 3.1), and :math:`\lVert U s\rVert =
    \lVert s\rVert` (orthonormal columns).
    """
    u = FLOAT32_ROUNDOFF
    gamma = terms * u / (1.0 - terms * u)
    return u * (1.0 + np.sqrt(terms)) + gamma * np.sqrt(terms)


def _grid(sigmas, etas):
    sigma_a, sigma_s_prime, eta = np.meshgrid(np.asarray(sigmas, np.float64),
                                              np.asarray(sigmas, np.float64),
                                              np.asarray(etas, np.float64), indexing="ij")
    return sigma_a.ravel(), sigma_s_prime.ravel(), eta.ravel()


def _where(index, sigma_a, sigma_s_prime, eta, **extra) -> dict:
    return {"sigma_a": float(sigma_a[index]), "sigma_s_prime": float(sigma_s_prime[index]),
            "eta": float(eta[index]), **extra}


@stress_kernel("dipole PCA projection float32 vs float64")
def pca_float32(sigmas=SIGMAS, etas=ETAS, bases=BASES) -> StressResult:
    """Coefficients and sampled reconstructions of both bases, float32 against float64.

    Parameters
    ----------
    sigmas : array_like
        sigma_a and sigma_s' values swept (every pair), mm^-1.
    etas : sequence of float
        Relative indices of refraction.
    bases : sequence of str
        Preset parameterisations.
    """
    sigma_a, sigma_s_prime, eta = _grid(sigmas, etas)
    result = StressResult(evaluations=0, against="float64",
                          notes="float32 rounding of coefficients and vectors plus K-term "
                                "float32 dot products, relative to |s| (orthonormal U)")
    bound = 0.0
    for name in bases:
        basis = dipole_pca_basis(name)
        bound = max(bound, float32_reconstruction_bound(basis.terms))
        coefficients = basis.project(sigma_a, sigma_s_prime, eta)
        vectors = basis.vectors[:, : basis.terms]
        exact = coefficients @ vectors.T
        single = coefficients.astype(np.float32) @ vectors.astype(np.float32).T
        result.evaluations += coefficients.size + 2 * exact.size
        count_nonfinite(coefficients, result, negative=False)
        count_nonfinite(single, result, negative=False)
        count_nonfinite(exact, result, negative=False)
        norm = np.linalg.norm(coefficients, axis=-1)
        error = np.linalg.norm(single.astype(np.float64) - exact, axis=-1)
        relative = np.divide(error, norm, out=np.zeros_like(error), where=norm > 0)
        worst = int(np.argmax(relative))
        result.details.append({"basis": name, "worst_relative_l2": float(relative[worst]),
                               "bound": float32_reconstruction_bound(basis.terms),
                               "largest_coefficient": float(np.abs(coefficients).max())})
        if relative[worst] > result.worst_relative_error:
            result.worst_relative_error = float(relative[worst])
            result.worst_at = _where(worst, sigma_a, sigma_s_prime, eta, basis=name)
    result.bound = bound
    return result


def _energies(basis, sigma_a, sigma_s_prime, eta):
    """Energies 2 pi int R r dr over [0, radius_max] of the K-term and the exact profiles."""
    coefficients, residual = basis.project_with_residual(sigma_a, sigma_s_prime, eta)
    # distances dense near 0 (where dense media put their energy), trapezoid weights of r dr
    radii = basis.sampling.radius_max * np.linspace(0.0, 1.0, ENERGY_RADII) ** 2
    measure = radii * np.gradient(radii)
    exact = dipole_reflectance_profile(radii[:, None], sigma_a, sigma_s_prime, eta)
    reconstruction = basis.evaluate(radii) @ coefficients.T
    exact_energy = 2.0 * np.pi * (exact * measure[:, None]).sum(axis=0)
    energy = coefficients @ basis.area_moments
    return coefficients, residual, reconstruction, energy, exact_energy


def _relative(value, exact):
    return np.abs(value - exact) / np.where(exact > 0, exact, 1.0)


def pca_energy(basis_name: str, sigmas=SIGMAS, etas=ETAS) -> StressResult:
    """Energy of the K-term profile against the exact one where the projection is trusted.

    Parameters
    ----------
    basis_name : str
        A preset parameterisation.
    sigmas, etas
        As :func:`pca_float32`.
    """
    sigma_a, sigma_s_prime, eta = _grid(sigmas, etas)
    basis = dipole_pca_basis(basis_name)
    coefficients, residual, reconstruction, energy, exact_energy = _energies(
        basis, sigma_a, sigma_s_prime, eta)
    # the in-grid reference: the measured media, each with its own eta
    media = np.array([(a, s, e) for s_prime, a_all, e in MEASURED_MEDIA.values()
                      for a, s in zip(np.broadcast_to(a_all, 3), np.broadcast_to(s_prime, 3),
                                      strict=True)])
    *_, media_energy, media_exact = _energies(basis, media[:, 0], media[:, 1], media[:, 2])
    measured_worst = float(_relative(media_energy, media_exact).max())
    result = StressResult(
        evaluations=coefficients.size + reconstruction.size,
        bound=TRUSTED_ENERGY_FACTOR * measured_worst,
        against="exact profile energy 2 pi int R_d r dr over [0, 65] mm",
        notes="energy error of projections the method trusts (blend weight 0 in "
              "fast.prt.projection_blend: residual, energy and sampling agree),"
              f" at most {TRUSTED_ENERGY_FACTOR:g} x the worst of the 36 measured profiles "
              f"({measured_worst:.3g}); negative counts projections holding more energy than "
              "their profile (Bessel's inequality)")
    count_nonfinite(coefficients, result, negative=False)
    count_nonfinite(reconstruction, result, negative=False)
    # Bessel's inequality: an orthogonal projection never holds more than the profile
    sampled = dipole_reflectance_profile(basis.radii, sigma_a[:, None], sigma_s_prime[:, None],
                                         eta[:, None])
    profile_energy = ((sampled * basis.weights) ** 2).sum(axis=-1)
    excess = (coefficients**2).sum(axis=-1) - profile_energy * (1.0 + BESSEL_SLACK)
    result.negative += int((excess > 0).sum())
    relative = _relative(energy, exact_energy)
    trusted = projection_blend(basis, sigma_a, sigma_s_prime, eta)[1] == 0
    judged = np.where(trusted, relative, 0.0)
    worst = int(np.argmax(judged))
    peak = np.abs(reconstruction).max(axis=0)
    lobe = np.clip(-reconstruction.min(axis=0), 0.0, None) / np.where(peak > 0, peak, 1.0)
    lobe_worst = int(np.argmax(np.where(trusted, lobe, 0.0)))
    breaking = trusted & (relative > result.bound)
    result.worst_relative_error = float(judged[worst])
    result.worst_at = _where(worst, sigma_a, sigma_s_prime, eta, residual=float(residual[worst]),
                             energy=float(energy[worst]), exact_energy=float(exact_energy[worst]))
    result.details.append({
        "cases": int(relative.size), "trusted": int(trusted.sum()),
        "measured_media_worst_energy_error": measured_worst,
        "trusted_breaking_bound": int(breaking.sum()),
        "trusted_breaking_sigma_a": sorted({float(v) for v in sigma_a[breaking]}),
        "trusted_breaking_sigma_s_prime": sorted({float(v) for v in sigma_s_prime[breaking]}),
        "trusted_worst_negative_lobe_over_peak": float(lobe[lobe_worst]),
        "trusted_worst_negative_lobe_at": _where(lobe_worst, sigma_a, sigma_s_prime, eta,
                                                 residual=float(residual[lobe_worst])),
        "untrusted_worst_energy_error": float(np.where(trusted, 0.0, relative).max()),
        "bessel_violations": int((excess > 0).sum())})
    return result


for _name in BASES:
    stress_kernel(f"dipole PCA energy outside the grid ({_name})")(
        functools.partial(pca_energy, _name))
