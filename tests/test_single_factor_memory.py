"""A single-precision PARDISO factor refines against the caller's matrix (issue 18, session
45): it keeps no double copy of the values (8 bytes an entry beside its own 4-byte factor)."""

import numpy as np
import pytest
from test_linear_solver import unsymmetric_matrix
from test_solve_accuracy import ill_conditioned

from ntncontact.solvers.linear import LinearSolver, pardiso_available

pytestmark = pytest.mark.skipif(not pardiso_available(), reason="pypardiso not installed")


@pytest.mark.parametrize("matrix", [ill_conditioned, unsymmetric_matrix])
def test_the_refinement_reads_the_callers_values_and_meets_its_bound(matrix):
    A = matrix()
    b = np.random.default_rng(5).standard_normal(A.shape[0])
    solver = LinearSolver("pardiso", precision="single")
    x = solver.factorize(A)(b)
    (backend,) = solver._impls.values()
    assert np.shares_memory(backend.factored_matrix.data, A.data)  # no copy kept
    assert np.linalg.norm(b - A @ x) <= 1e-6 * np.linalg.norm(b)
    assert solver.stats.double_fallbacks == 0


def test_a_factor_holds_no_matrix_once_the_solver_moves_on():
    """The factored matrix is let go when the next one is factored (not held beside it)."""
    A = ill_conditioned()
    solver = LinearSolver("pardiso", precision="single")
    solver.factorize(A)
    B = ill_conditioned(shift=2e-3)
    solver.factorize(B)
    (backend,) = solver._impls.values()
    assert np.shares_memory(backend.factored_matrix.data, B.data)
    assert not np.shares_memory(backend.factored_matrix.data, A.data)
