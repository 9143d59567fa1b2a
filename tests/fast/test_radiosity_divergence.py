"""solve_radiosity refuses a material whose series (Eq. 14 of Sheng et al. 2014) diverges."""

import numpy as np
import pytest
from scipy import sparse
from translucent.fast.radiosity import ConvergenceError, ScatteringMatrix, solve_radiosity

PATCHES = 16


def closed_sphere(rho):
    """Inside a sphere every patch sees every other in proportion to its area: F_ij = A_j / A."""
    area = np.random.default_rng(1).uniform(0.5, 2.0, PATCHES)
    form_factors = sparse.csr_matrix(np.tile(area / area.sum(), (PATCHES, 1)))
    scattering = ScatteringMatrix(np.arange(PATCHES + 1), np.arange(PATCHES),
                                  np.full((PATCHES, 3), rho))
    return scattering, form_factors, area / area.sum()


@pytest.mark.parametrize("solver", ["gmres", "bicgstab"])
def test_krylov_solvers_refuse_albedo_above_one(solver):
    # (I - SF) is invertible at rho = 1.01, but its solution is negative: not a radiosity
    scattering, form_factors, _ = closed_sphere(1.01)
    with pytest.raises(ConvergenceError, match="negative radiosity.*diverges"):
        solve_radiosity(scattering, form_factors, np.ones((PATCHES, 3)), solver=solver)


@pytest.mark.parametrize("solver", ["jacobi", "gmres", "bicgstab"])
def test_closed_sphere_below_one_is_still_solved(solver):
    rho = 0.9
    scattering, form_factors, _ = closed_sphere(rho)
    source = np.ones((PATCHES, 3))
    radiosity, _ = solve_radiosity(scattering, form_factors, source, solver=solver,
                                   tolerance=1e-10)
    # B = E / (1 - rho) exactly; the tolerance 1e-10 on the residual, times the condition
    # number 1 / (1 - rho) = 10, bounds the error
    np.testing.assert_allclose(radiosity, source / (1.0 - rho), rtol=1e-8)
