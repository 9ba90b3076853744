"""PARDISO's general mode and its weighted matching (issue 18, session 45): the matching is
computed from the values at the analysis and kept by every later factorization of the pattern,
so it is only asked for where pivots need it (a zero diagonal: bordered systems)."""

import numpy as np
import pytest
import scipy.sparse as sp
from test_linear_solver import saddle_point_matrix, unsymmetric_matrix

from ntncontact.solvers.linear import LinearSolver, pardiso_available

pytestmark = pytest.mark.skipif(not pardiso_available(), reason="pypardiso not installed")

#: what a solve may leave: the first solution, no refinement sweep
FIRST_SOLVE = 1.0


def first_solution(matrices, b, precision):
    """The solution of the last matrix's system from its factor, with the pattern analysed on
    the first matrix (as a run analyses its first Jacobian and factors the later ones)."""
    solver = LinearSolver("pardiso", symmetric=False, precision=precision)
    for A in matrices:
        factor = solver.factorize(A)
    return factor(b, FIRST_SOLVE), solver


@pytest.mark.parametrize("precision", ["single", "double"])
@pytest.mark.parametrize("seed", [1, 2, 3])
def test_a_factor_does_not_depend_on_the_matrix_its_pattern_was_analysed_with(precision, seed):
    """The ring refined 8x analysed its general mode on its first contact Jacobian, nearly
    symmetric, and kept that matching for the later ones, unsymmetric in a fifth of their
    rows: their single factors' first solutions left 8e-6 |b| (median; up to 1.6e-3) where a
    fresh analysis of each leaves 3e-7. A tangent with its diagonal is now factored the same
    whichever matrix of its pattern came first: bit for bit the factor of a fresh analysis."""
    A = unsymmetric_matrix(seed)
    first_jacobian = sp.csr_matrix((A + A.T) / 2)  # nearly symmetric, as before the friction
    b = np.random.default_rng(seed).standard_normal(A.shape[0])
    after_another, _ = first_solution([first_jacobian, A], b, precision)
    fresh, _ = first_solution([A], b, precision)
    np.testing.assert_array_equal(after_another, fresh)


def test_a_bordered_matrix_keeps_the_matching_its_zero_diagonal_needs():
    """Lagrange multipliers' zero diagonal block: without the matching PARDISO perturbs their
    pivots (and the single factor was called singular); with it the single factor solves."""
    A = saddle_point_matrix()
    A = sp.csr_matrix(A + sp.csr_matrix(([1e-3], ([0], [1])), shape=A.shape))  # unsymmetric
    b = np.random.default_rng(0).standard_normal(A.shape[0])
    solver = LinearSolver("pardiso", symmetric=False, precision="single")
    x = solver.solve(A, b)
    assert np.linalg.norm(b - A @ x) <= 1e-6 * np.linalg.norm(b)
    assert solver.stats.double_fallbacks == 0 and solver.stats.analyses == 1
