"""Static-pattern LU (solvers/static_lu.py) and its use by LinearSolver for small systems.

Accuracy: a stable LU gives a backward error of a modest multiple of eps; the tolerances below
(relative residual <= 1e-12, agreement with SuperLU <= 1e-10 relative for matrices with
condition numbers <= ~1e4) leave room for the n ~ 100-900 accumulated round-offs while still
catching any wrong entry of the fill pattern (which gives O(1) errors).
"""

from pathlib import Path

import numpy as np
import pytest
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from test_linear_solver import (
    block,
    saddle_point_matrix,
    spd_matrix,
    structurally_unsymmetric_matrix,
    supported,
    unsymmetric_matrix,
)

from ntncontact.solvers import linear, static_lu
from ntncontact.solvers.linear import LinearSolver, LinearSolverError

#: The tangent of examples/ring_impact.toml after 30 steps (7 contact pairs; 890 unknowns),
#: saved with ``benchmarks/static_lu.py``'s ``ring_matrix(30)``.
RING_MATRIX = Path(__file__).parent / "data" / "ring_impact_tangent.npz"


def relative_residual(A, x, b):
    return np.linalg.norm(A @ x - b) / (abs(A).max() * np.linalg.norm(x) + np.linalg.norm(b))


def random_fe_like(n_nodes=60, seed=0, symmetric=True):
    """A random 2-dof-per-node matrix on a mesh-like symmetric pattern (neighbours within a
    ring of nodes plus random long links), diagonally dominant so it needs no pivoting."""
    rng = np.random.default_rng(seed)
    pairs = [(i, (i + d) % n_nodes) for i in range(n_nodes) for d in (1, 2, 7)]
    pairs += [tuple(rng.integers(0, n_nodes, 2)) for _ in range(n_nodes // 2)]
    i, j = np.array(pairs).T
    node = sp.coo_matrix((np.ones(len(i)), (i, j)), shape=(n_nodes, n_nodes))
    node = ((node + node.T + sp.eye(n_nodes)) != 0).astype(float)
    pattern = sp.csr_matrix(sp.kron(node, np.ones((2, 2))))
    values = pattern.copy()
    values.data = rng.uniform(-1.0, 1.0, values.nnz)
    A = values @ values.T if symmetric else values  # SPD for symmetric (denser pattern)
    A = sp.csr_matrix(A)
    A = A + sp.diags(abs(A).sum(axis=1).A1 + 1.0)  # dominant diagonal
    return sp.csr_matrix(A)


def static_solver(A):
    """A solver that has analysed A's pattern (first factorization: SuperLU) and factored it
    with the static LU (second)."""
    solver = LinearSolver("static")
    solver.factorize(A)
    return solver, solver.factorize(A)


def ring_matrix():
    return sp.csr_matrix(sp.load_npz(RING_MATRIX))


#: Matrices on which SuperLU keeps every diagonal pivot (so the static LU is used).
MATRICES = {
    "spd_block": spd_matrix,
    "structurally_unsymmetric": structurally_unsymmetric_matrix,
    "random_spd": lambda: random_fe_like(symmetric=True),
    "random_unsymmetric": lambda: random_fe_like(symmetric=False, seed=3),
    "ring": ring_matrix,
}


@pytest.mark.parametrize("name", list(MATRICES))
def test_static_lu_agrees_with_superlu_and_dense(name):
    A = MATRICES[name]()
    solver, factor = static_solver(A)
    assert solver.stats.fallbacks == 0
    assert solver._impls[None].static is not None  # the second factorization was static
    b = np.random.default_rng(1).standard_normal(A.shape[0])
    x = factor(b)
    assert relative_residual(A, x, b) <= 1e-12
    reference = spla.splu(sp.csc_matrix(A)).solve(b)
    assert np.abs(x - reference).max() <= 1e-10 * np.abs(reference).max()
    if A.shape[0] <= 300:
        dense = np.linalg.solve(A.toarray(), b)
        assert np.abs(x - dense).max() <= 1e-10 * np.abs(dense).max()


@pytest.mark.parametrize("name", list(MATRICES) + ["unsymmetric_block"])
def test_static_lu_is_used_exactly_when_superlu_keeps_the_diagonal(name):
    """The pivot test is SuperLU's (diag_pivot_thresh): the static LU falls back exactly for
    the matrices on which SuperLU interchanges rows (the unsymmetric block: 21 columns), and
    the solution is accurate either way."""
    A = unsymmetric_matrix() if name == "unsymmetric_block" else MATRICES[name]()
    solver, factor = static_solver(A)
    p = solver._impls[None].perm
    lu = spla.splu(sp.csc_matrix(A[p][:, p]), permc_spec="NATURAL",
                   diag_pivot_thresh=linear.DIAG_PIVOT_THRESH, options={"SymmetricMode": True})
    superlu_pivots = bool(np.any(lu.perm_r != np.arange(A.shape[0])))
    assert solver.stats.fallbacks == int(superlu_pivots) == (name == "unsymmetric_block")
    b = np.random.default_rng(4).standard_normal(A.shape[0])
    assert relative_residual(A, factor(b), b) <= 1e-12


def test_fill_pattern_is_the_exact_lu_pattern():
    """L + U of the static LU hold exactly the entries of a dense LU without pivoting of the
    permuted matrix (up to numerical cancellation, absent for random values)."""
    A = random_fe_like(n_nodes=30, symmetric=False, seed=5)
    perm = np.random.default_rng(0).permutation(A.shape[0])
    symbolic = static_lu.analyse(A.indptr, A.indices, perm)
    factor = static_lu.factorize(symbolic, A.data, 0.0, 0.0)
    Ap = A[perm][:, perm].toarray()
    n = len(Ap)
    L, U = np.eye(n), Ap.copy()
    for k in range(n):  # dense Doolittle without pivoting
        L[k + 1:, k] = U[k + 1:, k] / U[k, k]
        U[k + 1:] -= np.outer(L[k + 1:, k], U[k])
    dense_lower = set(zip(*np.nonzero(np.abs(np.tril(L, -1)) > 1e-14), strict=True))
    l_ptr, l_rows = symbolic.l_ptr.astype(int), symbolic.l_rows.astype(int)
    u_ptr, u_rows = symbolic.u_ptr.astype(int), symbolic.u_rows.astype(int)
    static_lower = {(int(i), j) for j in range(n) for i in l_rows[l_ptr[j]:l_ptr[j + 1]]}
    assert dense_lower == static_lower
    static_L = sp.csc_matrix((factor.l_vals, l_rows, l_ptr), shape=(n, n))
    static_U = sp.csc_matrix((factor.u_vals, u_rows, u_ptr), shape=(n, n))
    np.testing.assert_allclose(static_L.toarray(), np.tril(L, -1), atol=1e-12)
    np.testing.assert_allclose(static_U.toarray() + np.diag(factor.diag), np.triu(U),
                               atol=1e-12 * np.abs(U).max())


def test_several_right_hand_sides():
    A = random_fe_like(symmetric=False, seed=3)
    solver, factor = static_solver(A)
    B = np.random.default_rng(2).standard_normal((A.shape[0], 4))
    X = factor(B)
    assert X.shape == B.shape
    for k in range(4):
        np.testing.assert_array_equal(X[:, k], factor(B[:, k]))  # same sweeps, column by column
        assert relative_residual(A, X[:, k], B[:, k]) <= 1e-12
    X = factor(np.asfortranarray(B))
    assert relative_residual(A, X[:, 2], B[:, 2]) <= 1e-12


def test_a_matrix_needing_pivoting_falls_back_to_superlu():
    """Same pattern, but a diagonal entry made tiny: the static LU rejects the pivot (below
    DIAG_PIVOT_THRESH of its column), SuperLU pivots, and the solution is still accurate; a
    well-behaved matrix afterwards takes the static path again."""
    A = spd_matrix()
    solver = LinearSolver("static")
    solver.factorize(A)
    tiny = A.copy()
    rows = np.repeat(np.arange(A.shape[0]), np.diff(A.indptr))
    tiny.data[(rows == 5) & (A.indices == 5)] = 1e-9 * abs(A).max()
    b = np.random.default_rng(3).standard_normal(A.shape[0])
    x = solver.factorize(tiny)(b)
    assert solver.stats.fallbacks == 1 and solver._impls[None].static is None
    assert relative_residual(tiny, x, b) <= 1e-12
    dense = np.linalg.solve(tiny.toarray(), b)
    assert np.abs(x - dense).max() <= 1e-8 * np.abs(dense).max()
    solver.factorize(A)
    assert solver._impls[None].static is not None and solver.stats.fallbacks == 1


def test_saddle_point_pattern_is_left_to_superlu():
    """A zero diagonal block without entries: no static LU for that pattern, solved by SuperLU."""
    A = saddle_point_matrix()
    solver = LinearSolver("static")
    b = np.ones(A.shape[0])
    for _ in range(3):
        x = solver.solve(A, b)
        assert relative_residual(A, x, b) <= 1e-12
    impl = solver._impls[None]
    assert impl.symbolic is None and not impl.usable and solver.stats.fallbacks == 0


def test_explicit_zero_diagonal_stops_trying_after_repeated_fallbacks():
    A = sp.lil_matrix(saddle_point_matrix())
    n = A.shape[0]
    for i in range(n - 5, n):
        A[i, i] = 1.0  # stored, then zeroed: the pattern has a full diagonal
    A = sp.csr_matrix(A)
    rows = np.repeat(np.arange(n), np.diff(A.indptr))
    A.data[(rows >= n - 5) & (A.indices == rows)] = 0.0
    solver = LinearSolver("static")
    b = np.ones(n)
    for _ in range(2 + linear.MAX_CONSECUTIVE_FALLBACKS):
        x = solver.solve(A, b)
        assert relative_residual(A, x, b) <= 1e-12
    assert solver.stats.fallbacks == linear.MAX_CONSECUTIVE_FALLBACKS
    assert not solver._impls[None].usable


@pytest.mark.parametrize("backend", ["static", "auto"])
def test_singular_matrix_raises(backend):
    K, _ = block(kind="neo_hookean", stretch=0.1)  # no supports: rigid modes
    with pytest.raises(LinearSolverError, match="singular"):
        LinearSolver(backend).solve(K, np.ones(K.shape[0]))
    solver = LinearSolver(backend)
    A = spd_matrix()
    b = np.ones(A.shape[0])
    solver.solve(A, b)
    solver.solve(A, b)  # static
    singular = A.copy()
    rows = np.repeat(np.arange(A.shape[0]), np.diff(A.indptr))
    singular.data[(rows == 0) | (A.indices == 0)] = 0.0  # dof 0 loses its stiffness
    with pytest.raises(LinearSolverError, match="singular"):
        solver.solve(singular, b)
    assert relative_residual(A, solver.solve(A, b), b) <= 1e-12  # still usable


def test_analysis_is_done_once_per_pattern():
    solver = LinearSolver("auto")
    b = np.ones(spd_matrix().shape[0])
    for stretch in (0.0, 0.05, 0.1, 0.15):  # Newton-like: same pattern, new values
        K, nodes = block(stretch=stretch)
        A = supported(K, nodes)
        assert relative_residual(A, solver.solve(A, b), b) <= 1e-12
    impl = solver._impls[None]
    assert isinstance(impl, linear._StaticLUBackend)
    assert (solver.stats.analyses, solver.stats.factorizations, solver.stats.solves,
            solver.stats.fallbacks) == (1, 4, 4, 0)
    symbolic = impl.symbolic
    K, nodes = block(stretch=0.2)
    solver.solve(supported(K, nodes), b)
    assert impl.symbolic is symbolic  # not recomputed
    A = random_fe_like()  # a new pattern
    solver.solve(A, np.ones(A.shape[0]))
    assert solver.stats.analyses == 2


def test_an_old_factor_still_solves_after_a_newer_factorization():
    """Modified Newton keeps a factor while later matrices are factored: each static factor
    owns its values."""
    solver = LinearSolver("static")
    K0, nodes = block(stretch=0.05)
    K1, _ = block(stretch=0.15)
    A0, A1 = supported(K0, nodes), supported(K1, nodes)
    solver.factorize(A0)  # analysis
    factor0 = solver.factorize(A0)
    b = np.linspace(1.0, 2.0, A0.shape[0])
    x0 = factor0(b)
    factor1 = solver.factorize(A1)
    factor2 = solver.factorize(A1)
    assert factor0.valid and solver.stats.fallbacks == 0
    np.testing.assert_array_equal(factor0(b), x0)
    assert relative_residual(A0, factor0(b), b) <= 1e-12
    assert relative_residual(A1, factor1(b), b) <= 1e-12
    assert relative_residual(A1, factor2(b), b) <= 1e-12


def test_backend_selection():
    small = spd_matrix()
    b = np.ones(small.shape[0])
    for backend, kind in (("auto", linear._StaticLUBackend), ("static", linear._StaticLUBackend),
                          ("superlu", linear._SuperLUBackend)):
        solver = LinearSolver(backend)
        solver.solve(small, b)
        assert type(solver._impls[None]) is kind
    assert LinearSolver("static").backend == "static"
