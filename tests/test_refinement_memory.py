"""A single-precision factor's refinement of many columns holds few arrays of their size
(issue 18, memory): the ring refined 8x peaked in the multiplier sensitivity's 37-column
refined solve, with ~6 arrays of the right-hand side's size alive at once."""

import tracemalloc

import numpy as np
import pytest
import scipy.sparse as sp

from ntncontact.solvers import linear
from ntncontact.solvers.linear import LinearSolver, pardiso_available

pytestmark = pytest.mark.skipif(not pardiso_available(), reason="pypardiso not installed")


def shifted_laplacian(k: int = 120) -> sp.csr_matrix:
    """A 2D grid Laplacian shifted by 1e-3: cond ~1e4, so a single factor's solutions need
    refinement sweeps to reach 1e-6."""
    T = sp.diags([-1.0, 2.0, -1.0], [-1, 0, 1], shape=(k, k))
    return sp.csr_matrix(sp.kronsum(T, T) + 1e-3 * sp.eye(k * k))


def test_a_refined_solve_of_many_columns_holds_under_three_of_their_arrays():
    A = shifted_laplacian()
    B = np.asfortranarray(np.random.default_rng(6).standard_normal((A.shape[0], 24)))
    solver = LinearSolver("pardiso", precision="single")
    factor = solver.factorize(A)
    tracemalloc.start()
    try:
        X = factor(B)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert solver.stats.refinements > 0  # the sweeps are what this measures
    assert np.all(np.linalg.norm(B - A @ X, axis=0)
                  <= linear.MIXED_RTOL * np.linalg.norm(B, axis=0))
    # x, the rounded residual and PARDISO's single-precision result and its copy: ~2.6
    # (the residual, its squares and conjugate, the solve's double result and a gather: 5.6)
    assert peak <= 3.0 * B.nbytes


@pytest.mark.parametrize("columns", [1, 2, 9, 10, 17, 33, 37, 64])
@pytest.mark.parametrize("order", ["C", "F"])
@pytest.mark.parametrize("rows", [3, 4096, 20_011])
def test_the_column_norms_are_numpys_to_the_bit(columns, order, rows):
    r = np.asarray(np.random.default_rng(columns).standard_normal((rows, columns))
                   * np.logspace(-3, 3, columns), order=order)
    assert np.array_equal(linear._column_norms(r), np.linalg.norm(r, axis=0))
