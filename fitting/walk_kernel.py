r"""The photon random walk as one Dr.Jit kernel (LLVM backend): the same walk, compiled.

The numpy walk of :mod:`translucent.fitting.random_walk` pays numpy's per-call overhead at
every step, and in a high-albedo medium the last photons wander for tens of thousands of
steps (the diffusion time to the kill radius grows like its square in transport lengths).
Here each photon's whole walk is one iteration of a symbolic ``drjit.while_loop`` that
Dr.Jit compiles once (through LLVM) and runs over all photons in SIMD lanes; exits are
added to the tallies with ``drjit.scatter_reduce``. The physics, the estimators and the
scoring are those of the numpy walk (see its module docstring); the tests run both
against the same published values.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["drjit_available", "walk_channel_drjit", "walk_exits"]


def drjit_available() -> bool:
    """Tell whether Dr.Jit's LLVM backend works here (set up as the suite does for Mitsuba)."""
    try:
        from ..backend import configure_libllvm

        configure_libllvm()
        import drjit as dr

        return bool(dr.has_backend(dr.JitBackend.LLVM))
    except Exception:  # no library, no backend: the numpy walk is used instead
        return False


def walk_channel_drjit(rng, photons, sigma_a, sigma_s, g, eta, thickness, beam_radius,
                       r_kill, edges, batches, film, rotations):
    """Trace one channel; returns what the numpy ``_walk_channel`` returns.

    The kernel only walks: every exit (position, entry point, weight, side, photon) is
    appended to a buffer through an atomic counter, and the buffer is scored afterwards by
    :func:`~translucent.fitting.walk_scoring.score_exits`, the numpy walk's own scoring. A
    buffer that overflows is enlarged and the (deterministic) walk run again.

    Parameters
    ----------
    rng : numpy.random.Generator
        Seeds the kernel's PCG32 streams and draws the film rotations.
    photons, sigma_a, sigma_s, g, eta, thickness, beam_radius, r_kill, edges, batches,
    film, rotations
        As the numpy walk.

    Returns
    -------
    (ndarray (2, batches, bins), ndarray (2, batches), float, ndarray or None)
        Radial sums per side and batch, totals per side and batch, weight lost at the kill
        radius, film sums (flat, H * W) or None.
    """
    from .walk_scoring import score_exits

    n_bins = edges.size - 1
    radial = np.zeros((2, batches, n_bins))
    totals = np.zeros((2, batches))
    film_sum = None if film is None else np.zeros(film.shape[0] * film.shape[1])
    if sigma_a + sigma_s <= 0:
        return radial, totals, 0.0, film_sum
    exits, lost = walk_exits(int(rng.integers(2**63)), photons, sigma_a, sigma_s, g, eta,
                             thickness, beam_radius, r_kill)
    x, y, x0, y0, weight, side, photon = exits
    batch = photon % batches
    for which in (0, 1):
        chosen = side == which
        if chosen.any():
            score_exits(rng, which, x[chosen] - x0[chosen], y[chosen] - y0[chosen],
                        x0[chosen], y0[chosen], weight[chosen], batch[chosen], edges, film,
                        rotations, radial, totals, film_sum)
    return radial, totals, lost, film_sum


def walk_exits(seed, photons, sigma_a, sigma_s, g, eta, thickness, beam_radius, r_kill, *,
               interactions: bool = False):
    """Run the compiled walk and return every exit, the buffer enlarged until they fit.

    Parameters
    ----------
    seed : int
        Seeds the PCG32 streams (one per photon): the walk is deterministic, so a buffer
        that overflowed is enlarged and the same walk run again.
    photons, sigma_a, sigma_s, g, eta, thickness, beam_radius, r_kill
        As the numpy walk.
    interactions : bool
        Also return each exit's number of scattering events.

    Returns
    -------
    (list of ndarray, float)
        ``x, y, x0, y0, weight, side, photon`` (and ``scatterings``) of the exits, and the
        weight lost at the kill radius.
    """
    capacity = EXITS_PER_PHOTON * photons
    while True:
        arrays, count, lost = _run_kernel(seed, photons, sigma_a, sigma_s, g, eta, thickness,
                                          beam_radius, r_kill, capacity,
                                          interactions=interactions)
        if count <= capacity:
            # the kernel appends exits through an atomic counter, in whatever order the
            # lanes reach it; ordered by photon (each photon's own exits stay in the order
            # it made them), the scoring that follows draws the same rotation for the same
            # exit every run, so one seed gives one capture
            photon = arrays[6][:count]
            order = np.argsort(photon, kind="stable")
            return [array[:count][order] for array in arrays], lost
        capacity = int(count * 1.25) + 1


#: Initial exit-buffer size per photon (an exit is each partial transmission through a
#: boundary; with eta > 1 a photon leaves in several parts).
EXITS_PER_PHOTON = 12


def _run_kernel(seed, photons, sigma_a, sigma_s, g, eta, thickness, beam_radius, r_kill,
                capacity, *, interactions: bool = False):
    """Run the compiled walk; returns the exit buffer (numpy), the exit count, lost weight.

    With ``interactions``, the buffer gains an eighth array: the number of scattering
    events each exit's path had (what reweights a walk to another albedo).
    """
    import drjit as dr
    from drjit.llvm import PCG32, Float64, UInt32, UInt64

    sigma_t = sigma_a + sigma_s
    albedo = sigma_s / sigma_t
    depth = math.inf if thickness is None else float(thickness)
    index = dr.arange(UInt32, photons)
    rng = PCG32(size=photons, initstate=UInt64(seed), initseq=UInt64(index))
    sigma_beam = 0.5 * beam_radius
    x0 = Float64(rng.next_float64_normal() * sigma_beam)
    y0 = Float64(rng.next_float64_normal() * sigma_beam)
    buffers = [dr.zeros(Float64, capacity) for _ in range(5)]  # x, y, x0, y0, weight
    side_buffer = dr.zeros(UInt32, capacity)
    photon_buffer = dr.zeros(UInt32, capacity)
    scatter_buffer = dr.zeros(UInt32, capacity if interactions else 1)
    counter = dr.zeros(UInt32, 1)
    lost = dr.zeros(Float64, 1)
    eta2 = eta * eta

    def cond(rng, x, y, z, ux, uy, uz, w, n):
        return w > 0

    def body(rng, x, y, z, ux, uy, uz, w, n):
        step = -dr.log(1.0 - rng.next_float64()) / sigma_t
        to_boundary = dr.select(uz > 0, (depth - z) / uz,
                                dr.select(uz < 0, -z / uz, math.inf))
        hit = step >= to_boundary
        travel = dr.minimum(step, to_boundary)
        x = x + travel * ux
        y = y + travel * uy
        z = dr.select(hit, dr.select(uz > 0, depth, 0.0), z + travel * uz)
        # exact Fresnel from inside (relative index 1 / eta), total internal reflection
        cos_i = dr.abs(uz)
        sin2_t = (1.0 - cos_i * cos_i) * eta2
        cos_t = dr.sqrt(dr.maximum(1.0 - sin2_t, 0.0))
        inv = 1.0 / eta
        r_s = (cos_i - inv * cos_t) / (cos_i + inv * cos_t)
        r_p = (inv * cos_i - cos_t) / (inv * cos_i + cos_t)
        reflect = dr.select(sin2_t >= 1.0, 1.0, 0.5 * (r_s * r_s + r_p * r_p))
        leaving = w * (1.0 - reflect)
        exiting = hit & (leaving > 0)
        slot = dr.scatter_inc(counter, UInt32(0), active=exiting)
        store = exiting & (slot < capacity)
        for buffer, value in zip(buffers, (x, y, x0, y0, leaving), strict=True):
            dr.scatter(buffer, value, slot, active=store)
        dr.scatter(side_buffer, dr.select(uz > 0, UInt32(1), UInt32(0)), slot, active=store)
        dr.scatter(photon_buffer, index, slot, active=store)
        if interactions:
            dr.scatter(scatter_buffer, n, slot, active=store)
        # Henyey-Greenstein scattering (MCML's rotation formulas)
        xi = rng.next_float64()
        if g == 0.0:
            cos_s = 2.0 * xi - 1.0
        else:
            ratio = (1.0 - g * g) / (1.0 - g + 2.0 * g * xi)
            cos_s = dr.clip((1.0 + g * g - ratio * ratio) / (2.0 * g), -1.0, 1.0)
        sin_s = dr.sqrt(dr.maximum(1.0 - cos_s * cos_s, 0.0))
        sin_p, cos_p = dr.sincos(2.0 * math.pi * rng.next_float64())
        vertical = dr.abs(uz) > 0.99999
        temp = dr.sqrt(dr.maximum(1.0 - uz * uz, 1e-300))
        a = sin_s / temp
        new_x = dr.select(vertical, sin_s * cos_p, a * (ux * uz * cos_p - uy * sin_p) + ux * cos_s)
        new_y = dr.select(vertical, sin_s * sin_p, a * (uy * uz * cos_p + ux * sin_p) + uy * cos_s)
        new_z = dr.select(vertical, dr.sign(uz) * cos_s, uz * cos_s - sin_s * cos_p * temp)
        ux = dr.select(hit, ux, new_x)
        uy = dr.select(hit, uy, new_y)
        uz = dr.select(hit, -uz, new_z)
        w = dr.select(hit, w * reflect, w * albedo)
        n = dr.select(hit, n, n + 1)
        # Russian roulette on light photons (unbiased)
        survive = rng.next_float64() < 0.1
        w = dr.select(w < 1e-4, dr.select(survive, w * 10.0, 0.0), w)
        far = (w > 0) & ((dr.abs(x) > r_kill) | (dr.abs(y) > r_kill) | (z > r_kill))
        dr.scatter_reduce(dr.ReduceOp.Add, lost, w, UInt32(0), active=far)
        w = dr.select(far, 0.0, w)
        return rng, x, y, z, ux, uy, uz, w, n

    state = (rng, Float64(x0), Float64(y0), dr.zeros(Float64, photons),
             dr.zeros(Float64, photons), dr.zeros(Float64, photons),
             dr.full(Float64, 1.0, photons), dr.full(Float64, 1.0, photons),
             dr.zeros(UInt32, photons))
    dr.while_loop(state=state, cond=cond, body=body)
    dr.eval(buffers, side_buffer, photon_buffer, scatter_buffer, counter, lost)
    count = int(np.asarray(counter)[0])
    arrays = [np.asarray(b, dtype=np.float64) for b in buffers]
    arrays += [np.asarray(side_buffer, dtype=np.int64), np.asarray(photon_buffer, dtype=np.int64)]
    if interactions:
        arrays.append(np.asarray(scatter_buffer, dtype=np.int64))
    return arrays, count, float(np.asarray(lost)[0])
