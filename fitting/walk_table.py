r"""Building the photon random walk's profile table (the evaluator is in materials).

The table itself, what it holds and how it is read, is
:mod:`translucent.materials.profiles.random_walk`, where the methods and the fitter share
it; this module traces the walks that fill it, with the compiled kernel of
:mod:`translucent.fitting.walk_kernel`, and re-exports the evaluator's names for the fitter.

How it is built (:func:`build_table`). Photons walk in units of the mean free path
(exact Fresnel boundary, implicit absorption, Russian roulette). With :math:`\sigma_t = 1`
the walk's geometry does not depend on the albedo: a path with ``n`` scattering events
carries :math:`\alpha^n`. A walk at a base albedo :math:`\alpha_b` is therefore reweighted
to any :math:`\alpha \le \alpha_b` by :math:`(\alpha / \alpha_b)^n`, which is unbiased
(roulette included) and bounded by 1; each tabulated albedo is served by the smallest base
at or above it (:data:`BASE_ALBEDOS`). Exits are binned into rings of :math:`\hat r`
(:data:`~translucent.materials.profiles.random_walk.RINGS_PER_DECADE` per decade) in
independent batches for the standard errors. ``python -m translucent.fitting.walk_table``
rebuilds the shipped ``materials/data/walk_profiles.npz``.
"""

from __future__ import annotations

import math
import time
from pathlib import Path

import numpy as np

from ..errors import InputError
from ..materials.profiles.random_walk import (
    MAX_RELATIVE_SE,
    TABLE_ETAS,
    TABLE_PATH,
    WalkProfileTable,
    asymptotic_attenuation,
    attenuation_grid,
    load_table,
    ring_edges,
    single_scattering,
)

__all__ = [
    "BASE_ALBEDOS",
    "MAX_RELATIVE_SE",
    "TABLE_ETAS",
    "TABLE_PATH",
    "WalkProfileTable",
    "asymptotic_attenuation",
    "attenuation_grid",
    "build_table",
    "load_table",
    "ring_edges",
    "save_table",
    "single_scattering",
]

#: Base albedos of the walks (each tabulated albedo is reweighted from the smallest base at
#: or above it; the reweighting factor (alpha / alpha_b)^n stays near 1 for the paths that
#: matter).
BASE_ALBEDOS = (1.0, 0.999, 0.99, 0.96, 0.88, 0.7, 0.4)
#: Photons traced at each base albedo (per eta) and per kernel call.
PHOTONS = 2_000_000
CHUNK = 400_000
BATCHES = 10
#: Kill radius of the walks, in mean free paths (the table ends at 64).
KILL_RADIUS = 160.0


def _power_law_correction(ring_mean, edges):
    """Ratio of each ring's value at its geometric centre to its mean, from the local slope.

    For a profile ``r^p`` across a ring the ratio is exact; ``p`` is the slope of
    ln(mean) against ln(centre) between the neighbouring rings.
    """
    inner, outer = edges[1:-1], edges[2:]
    centre = np.sqrt(inner * outer)
    with np.errstate(divide="ignore", invalid="ignore"):
        log_mean = np.log(ring_mean[..., 1:])
        slope = np.gradient(log_mean, np.log(centre), axis=-1)
    slope = np.where(np.isfinite(slope), slope, 0.0)
    k = outer / inner
    q = slope + 2.0
    # mean of r^p over the ring / r^p at its centre
    with np.errstate(divide="ignore", invalid="ignore"):
        general = 2.0 * (k ** q - 1.0) / (q * (k ** 2 - 1.0)) / k ** (0.5 * slope)
    at_minus_two = 2.0 * np.log(k) / (k ** 2 - 1.0) * k
    ratio_mean = np.where(np.abs(q) < 1e-6, at_minus_two, general)
    return 1.0 / ratio_mean


def _single_scattering_rings(edges, eta) -> np.ndarray:
    """Ring means of :func:`single_scattering` (Gauss-Legendre in r over each ring)."""
    nodes, weights = np.polynomial.legendre.leggauss(12)
    inner, outer = edges[:-1], edges[1:]
    half = 0.5 * (outer - inner)
    radius = (0.5 * (outer + inner))[:, None] + half[:, None] * nodes[None, :]
    values = single_scattering(radius, eta)
    # the integrand r R is finite at 0, so the first ring needs no special rule
    integral = np.sum(weights[None, :] * half[:, None] * radius * values, axis=1)
    return 2.0 * integral / (outer ** 2 - inner ** 2)


def _walk_rings(eta, base, photons, edges, seed, progress_bar=None):
    """Walk ``photons`` at albedo ``base`` (sigma_t = 1); returns exits as numpy arrays.

    Yields ``(ring, batch, weight, scatterings)`` of the exits through the lit surface
    after two or more scatterings (one is :func:`single_scattering`), within the last ring
    edge, one chunk of photons at a time.
    """
    from .walk_kernel import walk_exits

    done = 0
    rng = np.random.default_rng(seed)
    while done < photons:
        count = min(CHUNK, photons - done)
        arrays, _lost = walk_exits(int(rng.integers(2**63)), count, 1.0 - base, base, 0.0,
                                   float(eta), None, 0.0, KILL_RADIUS, interactions=True)
        x, y, x0, y0, weight, side, photon, scatterings = arrays
        radius = np.hypot(x - x0, y - y0)
        ring = np.searchsorted(edges, radius, side="right") - 1
        keep = (side == 0) & (ring < edges.size - 1) & (scatterings >= 2)
        yield ring[keep], (photon[keep] + done) % BATCHES, weight[keep], scatterings[keep]
        done += count
        if progress_bar is not None:
            progress_bar.update(count)


def build_table(*, photons: int = PHOTONS, etas=TABLE_ETAS, seed: int = 2026,
                progress: bool = False) -> dict[str, np.ndarray]:
    """Trace the walks and tabulate the reduced profiles (see the module docstring).

    Parameters
    ----------
    photons : int
        Photons per base albedo and eta.
    etas : sequence of float
        Relative indices to tabulate.
    seed : int
    progress : bool
        Show a progress bar over photons (stderr).

    Returns
    -------
    dict
        Arrays ``etas`` (E,), ``attenuation`` (S,), ``edges`` (K + 1,), ``ln_profile``
        (E, S, K) = ln(R_hat / alpha') at the ring centres, ``relative_se`` (E, S, K),
        ``cumulative`` (E, S, K + 1) = the exitance inside each edge per entering photon,
        ``photons``, ``seconds``.
    """
    began = time.perf_counter()
    photons = int(photons)
    if photons < 10 * BATCHES:
        raise InputError(f"need at least {10 * BATCHES} photons", field="photons",
                         value=photons)
    edges = ring_edges()
    rings = edges.size - 1
    area = np.pi * (edges[1:] ** 2 - edges[:-1] ** 2)
    s = attenuation_grid()
    albedo = 1.0 - s ** 2 / 3.0
    bases = np.asarray(BASE_ALBEDOS)
    served_by = np.array([bases[bases >= a - 1e-12].min() for a in albedo])
    etas = np.asarray(etas, dtype=np.float64)
    ln_profile = np.empty((etas.size, s.size, rings))
    relative_se = np.empty_like(ln_profile)
    cumulative = np.zeros((etas.size, s.size, rings + 1))
    bar = None
    if progress:
        from tqdm.auto import tqdm

        bar = tqdm(total=photons * len(bases) * etas.size, desc="walk table", unit="photon",
                   unit_scale=True, leave=False)
    try:
        for e, eta in enumerate(etas):
            sums = np.zeros((s.size, BATCHES, rings))
            for b, base in enumerate(bases):
                targets = np.flatnonzero(served_by == base)
                if targets.size == 0:
                    continue
                log_ratio = np.log(albedo[targets] / base)
                walks = _walk_rings(eta, base, photons, edges,
                                    seed + 1000 * e + b, bar)
                for ring, batch, weight, scatterings in walks:
                    flat = batch * rings + ring
                    for t, lr in zip(targets, log_ratio, strict=True):
                        reweighted = weight * np.exp(scatterings * lr)
                        sums[t] += np.bincount(flat, reweighted,
                                               minlength=BATCHES * rings).reshape(BATCHES, rings)
            per_batch = sums / (photons / BATCHES)
            mean = per_batch.mean(axis=1)
            se = per_batch.std(axis=1, ddof=1) / math.sqrt(BATCHES)
            single = _single_scattering_rings(edges, eta)
            ring_mean = mean / area + albedo[:, None] * single[None, :]
            with np.errstate(divide="ignore", invalid="ignore"):
                relative_se[e] = np.where(ring_mean > 0, se / area / ring_mean, np.inf)
            centre_values = ring_mean.copy()
            centre_values[:, 1:] *= _power_law_correction(ring_mean, edges)
            with np.errstate(divide="ignore"):
                ln_profile[e] = np.log(centre_values) - np.log(albedo)[:, None]
            cumulative[e, :, 1:] = np.cumsum(ring_mean * area, axis=1)
    finally:
        if bar is not None:
            bar.close()
    return {"etas": etas, "attenuation": s, "edges": edges, "ln_profile": ln_profile,
            "relative_se": relative_se, "cumulative": cumulative,
            "photons": np.array(photons), "seconds": np.array(time.perf_counter() - began)}


def save_table(table: dict[str, np.ndarray], path: Path = TABLE_PATH) -> None:
    """Write ``table`` as a compressed ``.npz`` (atomically)."""
    from ..atomic import atomic_path

    path.parent.mkdir(parents=True, exist_ok=True)
    with atomic_path(path) as temporary:
        with open(temporary, "wb") as handle:
            np.savez_compressed(handle, **table)


if __name__ == "__main__":  # rebuild the shipped table (about 40 CPU minutes)
    save_table(build_table(progress=True))
