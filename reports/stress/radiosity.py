r"""Stability of the radiosity solvers near the convergence limit of Sheng et al. 2014.

The test scene is the inside of a closed sphere cut into patches of random areas: every
patch sees every other in proportion to its area, :math:`F_{ij} = A_j / A` (the rows sum to
1, and so do the power-form columns), and the material is a Lambertian albedo
:math:`\rho`, :math:`S = \rho I`, whose column sums are :math:`\rho`. Eq. 14 then has the
closed form :math:`B = s + \rho m\,\mathbf 1` with :math:`m = a\cdot s / (1 - \rho \sum a)`
and :math:`a` a row of F (for a uniform source, :math:`B = s / (1 - \rho)`), the exact
answer each solver is compared with. Albedos approach and pass 1 (0.9 .. 1.01): below 1 a
solver must reach its tolerance or refuse with :class:`~translucent.fast.radiosity.
ConvergenceError`; at and above 1 :func:`~translucent.fast.radiosity.check_convergence`
must refuse with :class:`~translucent.errors.InputError`, and the solvers, called directly,
must refuse wherever the spectral radius of SF (:math:`\rho\sum a`, which the float32
rounding of F moves by ~1e-8) reaches 1. No NaN, no Inf and no result where a refusal is
due.
"""

from __future__ import annotations

import types

import numpy as np
from scipy import sparse

from ...errors import InputError
from ...fast.radiosity import (
    SOLVERS,
    ConvergenceError,
    ScatteringMatrix,
    check_convergence,
    solve_radiosity,
)
from . import StressResult, count_nonfinite, stress_kernel

ALBEDOS = (0.9, 0.99, 0.999, 1.0 - 1e-6, 1.0, 1.01)
#: The paper's 0.5 % relative residual, and a tight one.
SOLVER_TOLERANCES = (5e-3, 1e-10)
#: Patches of the sphere: enough for a dense F of 16,384 entries, few enough that the 2,000
#: Jacobi iterations of a refusal take about a second on a shared 2-core machine.
PATCHES = 128
#: Slack on the forward-error bound: the bound is a theorem in exact arithmetic; the
#: rounding of the residual itself is added to it (see :func:`_forward_error_bound`).
BOUND_SLACK = 1.01


def closed_sphere(patches: int, seed: int = 0):
    """Form factors (float32 CSR, as the method stores them) and the patches of a sphere."""
    area = np.random.default_rng(seed).uniform(0.5, 2.0, patches)
    form_factors = sparse.csr_matrix(np.tile((area / area.sum()).astype(np.float32),
                                             (patches, 1)))
    info = types.SimpleNamespace(area=area, object_names=("sphere",),
                                 object_of=np.zeros(patches, dtype=np.int64))
    return form_factors, info


def exact_radiosity(rho: float, row: np.ndarray, source: np.ndarray) -> np.ndarray:
    r"""Return the closed form of Eq. 14 in the closed sphere, :math:`B = s + \rho m`.

    :math:`m = a\cdot s/(1 - \rho\sum a)` with :math:`a` a row of F.

    Computed in extended precision: :math:`1 - \rho\sum a` cancels all but 6 digits at
    :math:`\rho = 1 - 10^{-6}`, which would leave a float64 reference wrong by 1e-10.
    """
    rho, row, source = np.longdouble(rho), row.astype(np.longdouble), source.astype(np.longdouble)
    return (source + rho * (row @ source) / (1 - rho * row.sum())).astype(np.float64)


def _residual_rounding(source, radiosity, matrix_norm):
    r"""Float64 rounding of a measured relative residual, per channel.

    :math:`P u (\lVert s\rVert + \lVert M\rVert\,\lVert B\rVert) / \lVert s\rVert` for
    :math:`r = s - MB`, a matrix-vector product of P terms (Higham, Accuracy and Stability of
    Numerical Algorithms, Sect. 3.5). Near albedo 1, :math:`\lVert B\rVert / \lVert s\rVert`
    reaches :math:`1/(1 - \rho)`, and so does this floor.
    """
    source_norm = np.linalg.norm(source, axis=0)
    return len(source) * np.finfo(np.float64).eps / 2 * (
        1.0 + matrix_norm * np.linalg.norm(radiosity, axis=0) / source_norm)


def _outcome(result: StressResult, rho, solver, tolerance, form_factors, row, source, norms):
    """Solve one case directly (no convergence check); return its row and error / bound."""
    scattering = ScatteringMatrix(np.arange(len(row) + 1), np.arange(len(row)),
                                  np.full((len(row), 3), rho))
    case = {"albedo": rho, "solver": solver, "tolerance": tolerance}
    try:
        radiosity, info = solve_radiosity(scattering, form_factors, source, solver=solver,
                                          tolerance=tolerance)
    except ConvergenceError as error:
        case.update(outcome="refused", iterations=error.iterations,
                    residual=float(error.residual), message=str(error))
        return case, 0.0
    result.evaluations += radiosity.size
    count_nonfinite(radiosity, result)
    case.update(outcome="solved", iterations=info["iterations"], residual=max(info["residual"]))
    # rho sum(a) is the spectral radius of SF here: float32 form factors whose rows sum to
    # just below 1 keep the series convergent even at rho = 1 (B is then ~1e8 s, but right)
    if np.longdouble(rho) * row.astype(np.longdouble).sum() >= 1:
        # a result where the series of Eq. 14 diverges is garbage whatever its residual
        result.negative += 1
        case["garbage"] = True
        return case, 0.0
    exact = exact_radiosity(rho, row, source)
    inverse_norm, matrix_norm = norms
    errors = np.linalg.norm(radiosity - exact, axis=0) / np.linalg.norm(exact, axis=0)
    rounding = _residual_rounding(source, radiosity, matrix_norm)
    # forward error: |B - B*| <= |M^-1| |r|, with |r| = (residual + its rounding) |s|
    bounds = BOUND_SLACK * inverse_norm * (np.asarray(info["residual"]) + rounding) \
        * np.linalg.norm(source, axis=0) / np.linalg.norm(exact, axis=0)
    channel = int(np.argmax(errors / bounds))
    error, bound = float(errors[channel]), float(bounds[channel])
    case.update(relative_error=error, bound=bound, inverse_norm=inverse_norm,
                residual_rounding=float(rounding.max()))
    if (np.asarray(info["residual"]) > BOUND_SLACK * tolerance + rounding).any():
        result.negative += 1  # returned without reaching the tolerance it was asked for
        case["tolerance_missed"] = True
    return case, error / bound


@stress_kernel("radiosity near the convergence limit")
def radiosity_limit(albedos=ALBEDOS, patches: int = PATCHES, solvers=SOLVERS,
                    tolerances=SOLVER_TOLERANCES) -> StressResult:
    """Every solver at every albedo and tolerance on the closed sphere, against Eq. 14.

    Parameters
    ----------
    albedos : sequence of float
        Albedos rho (the column sums of S), dimensionless.
    patches : int
        Patches of the sphere.
    solvers : sequence of str
        Among ``radiosity.SOLVERS``.
    tolerances : sequence of float
        Relative residuals asked of the solvers.
    """
    form_factors, info = closed_sphere(patches)
    row = form_factors[0].toarray().ravel().astype(np.float64)
    sources = np.random.default_rng(1).uniform(0.0, 1.0, (patches, 3))
    sources[:, 0] = 1.0  # channel R uniform: B = E / (1 - rho) exactly
    result = StressResult(evaluations=0, bound=1.0, against="closed form of Eq. 14",
                          notes="relative error of B within |(I - SF)^-1|_2 x (relative "
                                "residual + its float64 rounding) x |s| / |B| (forward error "
                                "from the residual; the case closest to its bound is shown); "
                                "negative counts "
                                "results returned where a refusal is due, wrong verdicts of "
                                "check_convergence and missed tolerances")
    dense = form_factors.toarray().astype(np.float64)
    worst = -1.0
    for rho in albedos:
        scattering = ScatteringMatrix(np.arange(patches + 1), np.arange(patches),
                                      np.full((patches, 3), rho))
        try:
            report = check_convergence(scattering, form_factors, info)
            verdict = {"albedo": rho, "check_convergence": "accepted",
                       "spectral_radius_bound": report["spectral_radius_bound"]}
        except InputError as error:
            verdict = {"albedo": rho, "check_convergence": "refused", "message": str(error)}
        if (verdict["check_convergence"] == "refused") != (rho >= 1.0):
            result.negative += 1
            verdict["wrong_verdict"] = True
        result.details.append(verdict)
        singular = np.linalg.svd(np.eye(patches) - rho * dense, compute_uv=False)
        norms = (1.0 / float(singular[-1]), float(singular[0]))
        for solver in solvers:
            for tolerance in tolerances:
                case, ratio = _outcome(result, rho, solver, tolerance, form_factors, row,
                                       sources, norms)
                result.details.append(case)
                if ratio > worst:
                    worst = ratio
                    result.worst_relative_error = case.get("relative_error", 0.0)
                    result.bound = case.get("bound", 1.0)
                    result.worst_at = {k: case[k] for k in ("albedo", "solver", "tolerance")}
    return result
