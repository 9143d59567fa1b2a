"""Convergence (Eq. 15) and solving of the radiosity system (Sheng et al. 2014, Eq. 14)."""

from __future__ import annotations

import functools
import time

import numpy as np
from scipy.sparse import linalg as sparse_linalg

from ...errors import InputError
from .form_factors import Patches
from .kernels import COMPILED_PRODUCT_ENTRIES, compiled_rgb_product
from .knobs import DIVERGENCE_FACTOR, SOLVERS, ConvergenceError
from .scattering import ScatteringMatrix


def form_factor_bounds(F, patches: Patches) -> dict:
    """Row sums and power-form column sums of F, the F half of the bound of Eq. 15."""
    if F is None or F.nnz == 0:
        return {"max_form_factor_row_sum": 0.0, "max_form_factor_power_column_sum": 0.0}
    power = (F.T @ patches.area) / patches.area
    return {"max_form_factor_row_sum": float(np.asarray(F.sum(axis=1)).max()),
            "max_form_factor_power_column_sum": float(power.max())}


def check_convergence(S: ScatteringMatrix, F, patches: Patches, *,
                      form_factor_facts: dict | None = None) -> dict:
    r"""Check the convergence condition of Sheng et al. 2014, Eq. 15, before solving.

    :math:`\|S\|_1 < 1` in power form: the energy leaving every patch through the material
    is less than what enters it. With :math:`\|F\| \le 1` (row sums of ray-cast form
    factors never exceed 1) the spectral radius of :math:`SF` is below
    :math:`\max_i\sum_j A_j S_{ji}/A_i \cdot \max_j \sum_k A_k F_{kj}/A_j`.

    The condition guards the series of Eq. 14, :math:`B = \sum_k (SF)^k SE`. Without form
    factors (one convex object: nothing inter-reflects) there is no series, :math:`B = SE`,
    and a column sum at or above 1 is then the material's own energy, not a divergence: a
    published profile may reflect more than it receives (photon beam diffusion's total
    reaches 1.08 at albedo 1, eta = 1), and so may a heterogeneous mix of profiles
    (Eq. 16). The method renders it as it is and reports ``energy_conserving`` False.

    Returns
    -------
    dict
        ``max_scattering_column_sum`` (and where: ``patch``, ``object``, ``channel``),
        ``max_form_factor_row_sum``, ``max_form_factor_power_column_sum``,
        ``spectral_radius_bound``, ``energy_conserving`` (every column sum below 1) and
        ``inter_reflects`` (F has entries: the series of Eq. 14 is summed).

    Raises
    ------
    InputError
        When a column sum of S reaches 1 and F has entries: the material returns more
        light than it receives and the series of Eq. 14 is not guaranteed to converge.
        The message names the object, patch, channel and value.
    """
    sums = S.power_column_sums(patches.area)
    patch, channel = np.unravel_index(int(np.argmax(sums)), sums.shape)
    largest = float(sums[patch, channel])
    object_name = patches.object_names[patches.object_of[patch]]
    report = {"max_scattering_column_sum": largest, "patch": int(patch),
              "object": object_name, "channel": "RGB"[channel]}
    report.update(form_factor_facts if form_factor_facts is not None
                  else form_factor_bounds(F, patches))
    report["spectral_radius_bound"] = largest * report["max_form_factor_power_column_sum"]
    report["energy_conserving"] = largest < 1.0
    report["inter_reflects"] = F is not None and F.nnz > 0
    if not np.isfinite(largest) or (largest >= 1.0 and report["inter_reflects"]):
        if getattr(S, "blocks", ()):
            raise InputError(
                f"the geometry correction breaks the convergence condition of Eq. 15 (Sheng "
                f"et al. 2014): patch {patch} of '{object_name}' sends {largest:.4f} of the "
                f"light it receives back out in channel {'RGB'[channel]} (must be < 1); "
                "the correction is made at the clusters' scale and this object folds at a "
                "smaller one -- use geometry half_space (with finite_object_energy)",
                field="geometry", value=largest)
        raise InputError(
            f"the scattering factors break the convergence condition of Eq. 15 (Sheng et al. "
            f"2014): patch {patch} of '{object_name}' sends {largest:.4f} of the light it "
            f"receives back out in channel {'RGB'[channel]} (must be < 1); the material "
            "reflects more energy than it receives -- check its profile (total reflectance "
            "< 1) and the cut-off max_d", field="material", value=largest)
    return report


def form_factor_product(F, B) -> np.ndarray:
    """``F @ B`` for the three channels of B (P, 3) in one pass over F.

    The product of every Jacobi iteration (Sheng et al. 2014, Sect. 5.3): a compiled,
    multi-threaded loop reads each form factor once for R, G and B; scipy's product
    casts the float32 matrix for a float64 right-hand side and is 1.5 to 3 times slower
    on large F (measured in the radiosity bench).
    """
    if F.nnz < COMPILED_PRODUCT_ENTRIES:
        return np.asarray(F @ B)
    out = np.empty((F.shape[0], 3))
    compiled_rgb_product()(F.indptr, F.indices, F.data,
                            np.ascontiguousarray(B, np.float64), out)
    return out


def _relative_residual(S: ScatteringMatrix, F, B, source):
    """Relative residual per channel of B and the product F B it needed (None without F)."""
    global_irradiance = form_factor_product(F, B) if F is not None else None
    residual = source - B + S.dot(global_irradiance) if F is not None else source - B
    norm = np.linalg.norm(source, axis=0)
    return np.linalg.norm(residual, axis=0) / np.where(norm > 0, norm, 1.0), global_irradiance


def solve_radiosity(S: ScatteringMatrix, F, source, *, solver: str = "jacobi",
                    tolerance: float = 5e-3, max_iterations: int = 2000,
                    initial=None) -> tuple[np.ndarray, dict]:
    r"""Solve :math:`(I - SF)B = \text{source}` (Sheng et al. 2014, Eq. 14, Sect. 5.3).

    ``source`` is :math:`SE`, or any right-hand side (an emission L in the classical
    :math:`S = P` case, Eq. 2).

    Parameters
    ----------
    S : ScatteringMatrix
    F : scipy.sparse matrix or None
        Form factors (None: no inter-reflection, B = source).
    source : ndarray, shape (P, 3)
    solver : str
        ``"jacobi"`` (:math:`B \leftarrow \text{source} + SFB`), ``"gmres"`` or
        ``"bicgstab"``.
    tolerance : float
        Relative residual :math:`\|\text{source} - (I - SF)B\| / \|\text{source}\|` per
        channel (0.5 % in the paper).
    max_iterations : int
    initial : ndarray, shape (P, 3), optional
        Starting guess (default: the source, the first bounce). The stopping rule is the
        residual of the iterate, so a good guess saves iterations and changes nothing else.

    Returns
    -------
    B : ndarray, shape (P, 3)
    info : dict
        ``iterations`` (the largest over channels; matrix-vector products of SF for
        Krylov methods), ``residual`` (per channel, recomputed), ``solver``.

    Raises
    ------
    ConvergenceError
        When the residual does not reach ``tolerance`` in ``max_iterations``, becomes
        non-finite or grows by :data:`DIVERGENCE_FACTOR`, or when a non-negative source
        gives a negative radiosity (a Krylov solver converges to the solution of
        :math:`(I - SF)B = \text{source}` even where the series of Eq. 14 diverges,
        spectral radius of SF >= 1): no garbage is returned.
    """
    if solver not in SOLVERS:
        raise InputError(f"unknown solver; valid: {', '.join(SOLVERS)}", field="solver",
                         value=solver)
    source = np.asarray(source, dtype=np.float64)
    if F is None or F.nnz == 0:
        return source.copy(), {"iterations": 0, "residual": [0.0, 0.0, 0.0], "solver": solver}
    start = source if initial is None else np.asarray(initial, dtype=np.float64)
    if solver == "jacobi":
        B, iterations, residual, global_irradiance = _jacobi(S, F, source, tolerance,
                                                             max_iterations, start)
    else:
        B, iterations = _krylov(S, F, source, solver, tolerance, max_iterations, start)
        residual, global_irradiance = _relative_residual(S, F, B, source)
    if (source >= 0).all() and (B < -tolerance * np.abs(B).max(axis=0)).any():
        raise ConvergenceError(f"{solver} returned a negative radiosity for a non-negative source:"
                               " the series of Eq. 14 diverges (spectral radius of SF >= 1)",
                               residual=float(residual.max()), iterations=int(iterations))
    return B, {"iterations": int(iterations), "residual": residual.tolist(), "solver": solver,
               "global_irradiance": global_irradiance}


def _jacobi(S, F, source, tolerance, max_iterations, start):
    r"""Jacobi sweeps; return B, the products of SF, the residual and F B of that B.

    The sweep from :math:`B_k` computes :math:`B_{k+1} = \text{source} + SFB_k`, whose
    change :math:`B_{k+1} - B_k` is exactly the residual of :math:`B_k`: the iterate that
    passes the test is returned with its :math:`FB_k` (the image's inter-reflected
    irradiance), so no product is spent on checking or on the image.
    """
    B = start.copy()
    norm = np.linalg.norm(source, axis=0)
    norm = np.where(norm > 0, norm, 1.0)
    smallest = np.inf
    largest = np.inf
    for iteration in range(1, max_iterations + 1):
        global_irradiance = form_factor_product(F, B)
        updated = source + S.dot(global_irradiance)
        residual = np.linalg.norm(updated - B, axis=0) / norm
        largest = float(residual.max())
        if not np.isfinite(largest) or largest > DIVERGENCE_FACTOR * smallest:
            raise ConvergenceError(f"Jacobi iteration diverges: relative residual {largest:.3g}"
                                   f" after {iteration} iterations (smallest {smallest:.3g})",
                                   residual=largest, iterations=iteration)
        if largest <= tolerance:
            return B, iteration, residual, global_irradiance
        smallest = min(smallest, largest)
        B = updated
    raise ConvergenceError(f"Jacobi iteration reached a relative residual of {largest:.3g}"
                           f" after {max_iterations} iterations, above the tolerance "
                           f"{tolerance:g}: the spectral radius of SF is close to 1 (albedo near "
                           "1); raise max_iterations or use solver='gmres'",
                           residual=largest, iterations=max_iterations)


def _krylov(S, F, source, solver, tolerance, max_iterations, start):
    size = len(source)
    B = np.zeros_like(source)
    most = 0
    method = sparse_linalg.gmres if solver == "gmres" else sparse_linalg.bicgstab
    for c in range(3):
        products = [0]

        def matvec(x, c=c, products=products):
            products[0] += 1
            return x - S.channel_dot(c, F @ x)

        operator = sparse_linalg.LinearOperator((size, size), matvec=matvec, dtype=np.float64)
        if not np.any(source[:, c]):
            continue
        solution, status = method(operator, source[:, c], x0=start[:, c].copy(),
                                  rtol=tolerance, atol=0.0, maxiter=max_iterations)
        if status != 0 or not np.all(np.isfinite(solution)):
            residual = float(np.linalg.norm(source[:, c] - matvec(solution))
                             / np.linalg.norm(source[:, c]))
            raise ConvergenceError(f"{solver} stopped with status {status} in channel "
                                   f"{'RGB'[c]} at relative residual {residual:.3g}",
                                   residual=residual, iterations=products[0])
        B[:, c] = solution
        most = max(most, products[0])
    return B, most


def transfer_matrix(S: ScatteringMatrix, F) -> list[np.ndarray]:
    r"""Compute the relighting operator :math:`T = (I - SF)^{-1}S` per channel (float32).

    Sheng et al. 2014, Sect. 6.4: with T, relighting is :math:`B = TE`, one matrix-vector
    product per channel. Costs :math:`O(P^3)` time and :math:`3P^2` floats. Without form
    factors (one convex object: nothing inter-reflects) :math:`T = S`. The system is built
    and solved in float32, the precision T is kept in: :math:`I - SF` is diagonally
    dominant (every row of SF sums to an albedo below 1), and the float32 solve agrees with
    the float64 one to a relative 2.4e-7 of T's largest entry (measured on the bowl), at
    half the time. :math:`SF` is formed as :math:`(F^T S^T)^T` with F sparse: a ray-cast
    row of F holds at most ``rays_per_patch`` entries, so the product costs
    :math:`P \cdot \mathrm{nnz}(F)` where a dense product costs :math:`2P^3`.
    """
    import scipy.linalg

    if F is None:
        return [S.dense_channel(c) for c in range(3)]
    size = len(S.indptr) - 1
    F_transposed = F.T.tocsr().astype(np.float32)
    out = []
    for c in range(3):
        S_c = S.dense_channel(c)
        # (F^T S^T)^T = S F, in Fortran order: LAPACK's own, so the solve copies nothing
        system = np.asfortranarray(-(F_transposed @ S_c.T).T)
        system[np.diag_indices(size)] += 1.0
        out.append(scipy.linalg.solve(system, S_c, overwrite_a=True, overwrite_b=True,
                                      check_finite=False))
    return out


#: Patches of the system timed once a process by :func:`transfer_seconds_estimate`: small
#: enough to cost milliseconds, large enough for LAPACK's blocked kernels.
TRANSFER_CALIBRATION_PATCHES = 384


@functools.lru_cache(maxsize=1)
def _solve_seconds_per_cubed_patch() -> float:
    """Seconds of one float32 :func:`transfer_matrix` channel solve per :math:`P^3`, measured.

    The best of three solves of a diagonally dominant ``TRANSFER_CALIBRATION_PATCHES``
    system with as many right-hand sides, in this process's BLAS threads.
    """
    import scipy.linalg

    n = TRANSFER_CALIBRATION_PATCHES
    rng = np.random.default_rng(0)
    best = np.inf
    for _ in range(3):
        system = np.eye(n, dtype=np.float32) - rng.random((n, n), dtype=np.float32) / n
        right = rng.random((n, n), dtype=np.float32)
        started = time.perf_counter()
        scipy.linalg.solve(system, right, overwrite_a=True, overwrite_b=True,
                           check_finite=False)
        best = min(best, time.perf_counter() - started)
    return best / n**3


def transfer_seconds_estimate(patches: int) -> float:
    """Estimated seconds of :func:`transfer_matrix` with form factors for ``patches`` patches.

    Three channel solves of :math:`O(P^3)`, scaled from a small solve timed once in this
    process (:data:`TRANSFER_CALIBRATION_PATCHES`). Small systems run below the blocked
    kernels' peak rate, so this overestimates large ones (measured on the bowl's 3872
    patches: docs/radiosity.md).
    """
    return 3 * _solve_seconds_per_cubed_patch() * float(patches) ** 3
