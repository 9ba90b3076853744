"""LinearSolver: accuracy on SPD, indefinite and unsymmetric systems, reuse, singular detection."""

import os

import numpy as np
import pytest
import scipy.sparse as sp

from ntncontact.fem.assembly import Assembler, MaterialGroup
from ntncontact.solvers import linear
from ntncontact.solvers.linear import LinearSolver, LinearSolverError, pardiso_available

BACKENDS = [
    "superlu",
    pytest.param("pardiso", marks=pytest.mark.skipif(not pardiso_available(),
                                                     reason="pypardiso not installed")),
]
EPS = np.finfo(float).eps
#: factorizations of one matrix compared bit for bit on two PARDISO threads
REPEATS = 24


def block(nx=12, ny=8, kind="neo_hookean", stretch=0.1, seed=0):
    """Tangent of a distorted Q4 block under a finite homogeneous deformation, and its nodes."""
    rng = np.random.default_rng(seed)
    xs, ys = np.meshgrid(np.linspace(0, 1.5, nx + 1), np.linspace(0, 1.0, ny + 1))
    nodes = np.column_stack([xs.ravel(), ys.ravel()])
    nodes += 0.2 * rng.uniform(-1, 1, nodes.shape) / max(nx, ny)
    i, j = np.meshgrid(np.arange(nx), np.arange(ny))
    n0 = (j * (nx + 1) + i).ravel()
    cells = np.column_stack([n0, n0 + 1, n0 + nx + 2, n0 + nx + 1])
    ne = len(cells)
    asm = Assembler(cells, len(nodes), [MaterialGroup(kind, np.arange(ne))],
                    np.full(ne, 2.0), np.full(ne, 1.0), np.ones(ne))
    _, K, _ = asm.internal(nodes, d=stretch * nodes @ np.array([[1.0, 0.5], [0.0, -0.8]]).T)
    return K, nodes


def supported(K, nodes):
    """Eliminate the dofs of the nodes on the bottom edge (a clamped block)."""
    free = np.flatnonzero(np.repeat(nodes[:, 1] > 0.02, 2))
    return sp.csr_matrix(K[free][:, free])


def spd_matrix():
    K, nodes = block(stretch=0.0, kind="linear_elastic")
    return supported(K, nodes)


def indefinite_matrix():
    """Supported stiffness shifted past its lowest eigenvalues: symmetric, both signs."""
    A = spd_matrix()
    lowest = np.linalg.eigvalsh(A.toarray())[:20]
    shift = 0.5 * (lowest[9] + lowest[10])  # midway between two eigenvalues: well conditioned
    return sp.csr_matrix(A - shift * sp.eye(A.shape[0]))


def saddle_point_matrix():
    """[[K, B^T], [B, 0]]: Lagrange multipliers tying 5 dof pairs (zero diagonal block)."""
    K = spd_matrix()
    n = K.shape[0]
    rows = np.repeat(np.arange(5), 2)
    cols = np.column_stack([np.arange(5) * 7, np.arange(5) * 7 + 40]).ravel()
    B = sp.csr_matrix((np.tile([1.0, -1.0], 5), (rows, cols)), shape=(5, n))
    return sp.bmat([[K, B.T], [B, None]], format="csr")


def unsymmetric_matrix(seed=1):
    """Neo-Hookean tangent plus an unsymmetric part on its own pattern (friction-like)."""
    K, nodes = block(stretch=0.15)
    A = supported(K, nodes)
    rng = np.random.default_rng(seed)
    A.data = A.data + 0.3 * np.abs(A.data).max() * rng.uniform(-1, 1, A.nnz) * (A.data != 0)
    return A


def structurally_unsymmetric_matrix():
    """Supported stiffness plus one coupling entry without its mirror (a one-sided constraint)."""
    A = spd_matrix().tolil()
    n = A.shape[0]
    A[0, n - 1] = 0.1 * abs(A).max()
    return sp.csr_matrix(A)


def assert_accurate(A, b, x):
    """Backward error at round-off level; forward error bounded by cond(A) eps."""
    dense = A.toarray()
    backward = np.linalg.norm(A @ x - b) / (np.linalg.norm(dense, 2) * np.linalg.norm(x))
    assert backward < 1e3 * EPS  # a stable direct solve: a modest multiple of eps
    exact = np.linalg.solve(dense, b)
    forward = np.linalg.norm(x - exact) / np.linalg.norm(exact)
    assert forward < 1e3 * EPS * np.linalg.cond(dense)


MATRICES = {
    "spd": spd_matrix,
    "indefinite": indefinite_matrix,
    "saddle_point": saddle_point_matrix,
    "unsymmetric": unsymmetric_matrix,
    "structurally_unsymmetric": structurally_unsymmetric_matrix,
}


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("name", list(MATRICES))
def test_solution_is_accurate(backend, name):
    A = MATRICES[name]()
    if name == "indefinite":
        eig = np.linalg.eigvalsh(A.toarray())
        assert eig.min() < 0 < eig.max()  # the test matrix really is indefinite
    if name.endswith("unsymmetric"):
        assert abs(A - A.T).max() > 0.05 * abs(A).max()
    b = np.random.default_rng(2).standard_normal(A.shape[0])
    assert_accurate(A, b, LinearSolver(backend).solve(A, b))


@pytest.mark.parametrize("backend", BACKENDS)
def test_several_right_hand_sides(backend):
    A = unsymmetric_matrix()
    B = np.random.default_rng(3).standard_normal((A.shape[0], 3))
    X = LinearSolver(backend).solve(A, B)
    assert X.shape == B.shape
    for k in range(3):
        assert_accurate(A, B[:, k], X[:, k])


@pytest.mark.parametrize("backend", BACKENDS)
def test_analysis_is_reused_while_the_pattern_holds(backend):
    solver = LinearSolver(backend)
    b = np.ones(spd_matrix().shape[0])
    for stretch in (0.0, 0.05, 0.1):  # Newton-like sequence: same pattern, new values
        K, nodes = block(stretch=stretch)
        A = supported(K, nodes)
        assert_accurate(A, b, solver.solve(A, b))
    assert solver.stats.analyses == 1 and solver.stats.factorizations == 3
    A = saddle_point_matrix()  # a new pattern (as when contact pairs change)
    b2 = np.ones(A.shape[0])
    assert_accurate(A, b2, solver.solve(A, b2))
    assert solver.stats.analyses == 2


@pytest.mark.parametrize("backend", BACKENDS)
def test_symmetry_is_detected_per_matrix(backend):
    """The same pattern alternately with symmetric and unsymmetric values."""
    solver = LinearSolver(backend)
    sym = spd_matrix()
    unsym = unsymmetric_matrix()
    assert np.array_equal(sym.indices, unsym.indices)
    b = np.random.default_rng(4).standard_normal(sym.shape[0])
    for A in (sym, unsym, sym, unsym):
        assert_accurate(A, b, solver.solve(A, b))
    # each mode's analysis is kept: PARDISO analyses once per mode, SuperLU once
    assert solver.stats.analyses == (2 if solver.backend == "pardiso" else 1)


@pytest.mark.skipif(not pardiso_available(), reason="pypardiso not installed")
def test_pardiso_frees_the_idle_modes_factor_and_keeps_its_analysis():
    """Factoring in one symmetry mode frees the other mode's L and U (phase 0): at most one
    factor is held, and the next factorization in that mode (no new analysis) gives the same
    bits as before."""
    solver = LinearSolver("pardiso")
    sym, unsym = spd_matrix(), unsymmetric_matrix()
    b = np.random.default_rng(5).standard_normal(sym.shape[0])
    first = solver.solve(sym, b)
    solver.solve(unsym, b)
    assert [impl.factored for impl in solver._impls.values()] == [False, True]
    assert np.array_equal(solver.solve(sym, b), first)
    assert [impl.factored for impl in solver._impls.values()] == [True, False]
    assert solver.stats.analyses == 2


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("kind", ["linear_elastic", "neo_hookean"])
def test_unsupported_body_is_singular(backend, kind):
    """No supports: rigid translations (and for linear elasticity the rotation) are free."""
    K, _ = block(kind=kind, stretch=0.1)
    with pytest.raises(LinearSolverError, match="singular"):
        LinearSolver(backend).solve(K, np.ones(K.shape[0]))


@pytest.mark.parametrize("backend", [*BACKENDS, "static"])
def test_singular_with_a_balanced_load_is_detected(backend):
    """A body free to translate under a load with no resultant (a right-hand side in the
    matrix's range): the solution does not grow, so only the pivots tell. Before the pivots
    were read at a pattern's first factorization, a static run of a block supported in y
    only, pressed on its top, completed with the block shifted in x by round-off."""
    K, _ = block(kind="linear_elastic", stretch=0.0)
    balanced = K @ np.random.default_rng(3).standard_normal(K.shape[0])
    with pytest.raises(LinearSolverError, match="numerically singular"):
        LinearSolver(backend).solve(K, balanced)


def test_static_lu_refers_a_singular_matrix_of_a_known_pattern_to_the_pivot_check():
    """The static LU rejects the tiny pivot of a matrix whose pattern was analysed on a
    regular one; SuperLU's factor then has its pivots read, whatever the right-hand side."""
    solver = LinearSolver("static")
    A = spd_matrix()
    assert_accurate(A, np.ones(A.shape[0]), solver.solve(A, np.ones(A.shape[0])))
    singular = A.copy()
    rows = np.repeat(np.arange(A.shape[0]), np.diff(A.indptr))
    singular.data[(rows == 0) | (A.indices == 0)] = 0.0  # dof 0 loses its stiffness
    singular.data[(rows == 0) & (A.indices == 0)] = 1e-20 * np.abs(A.data).max()
    balanced = np.ones(A.shape[0])
    balanced[0] = 0.0  # no load on the free dof: the solution does not grow
    with pytest.raises(LinearSolverError, match="numerically singular"):
        solver.solve(singular, balanced)


@pytest.mark.parametrize("backend", BACKENDS)
def test_singular_after_reuse_is_detected(backend):
    """A singular matrix with a pattern analysed before (its support then removed)."""
    solver = LinearSolver(backend)
    A = spd_matrix()
    b = np.ones(A.shape[0])
    solver.solve(A, b)
    singular = A.copy()
    rows = np.repeat(np.arange(A.shape[0]), np.diff(A.indptr))
    singular.data[(rows == 0) | (A.indices == 0)] = 0.0  # dof 0 loses its stiffness
    with pytest.raises(LinearSolverError, match="singular"):
        solver.solve(singular, b)
    assert_accurate(A, b, solver.solve(A, b))  # still usable after the failure


def test_superlu_pivots_are_read_only_for_growing_solutions():
    """Reading U's pivots is the costly part of a small SuperLU solve: a well-conditioned
    matrix needs it only at its pattern's first factorization, a singular one is caught at
    its first solve, and an ill-conditioned but regular one passes the check and is solved."""
    solver = LinearSolver("superlu")
    A = spd_matrix()
    b = np.ones(A.shape[0])
    for _ in range(3):
        assert_accurate(A, b, solver.solve(A, b))
    assert solver.stats.pivot_checks == 1  # the pattern's first factorization
    K, _ = block(kind="neo_hookean", stretch=0.1)
    with pytest.raises(LinearSolverError, match="numerically singular"):
        LinearSolver("superlu").solve(K, np.ones(K.shape[0]))
    scaling = np.ones(A.shape[0])
    scaling[0] = 1e-5  # D A D: dof 0 in other units; x_0 grows by 1e5, its pivot falls by 1e10
    weak = sp.csr_matrix(sp.diags(scaling) @ A @ sp.diags(scaling))
    factor = solver.factorize(weak)
    x = factor(b)
    assert solver.stats.pivot_checks == 2
    assert np.allclose(weak @ x, b, rtol=0, atol=1e-6 * np.abs(x).max())


def test_bad_input_is_reported():
    solver = LinearSolver("superlu")
    with pytest.raises(LinearSolverError, match="square"):
        solver.solve(sp.csr_matrix(np.ones((2, 3))), np.ones(2))
    with pytest.raises(LinearSolverError, match="row 1 is empty"):
        solver.solve(sp.csr_matrix(np.array([[1.0, 0.0], [0.0, 0.0]])), np.ones(2))
    with pytest.raises(LinearSolverError, match="non-finite"):
        solver.solve(sp.csr_matrix(np.array([[1.0, 0.0], [0.0, np.nan]])), np.ones(2))
    with pytest.raises(ValueError, match="unknown"):
        LinearSolver("umfpack")


def test_auto_prefers_pardiso_when_installed():
    assert LinearSolver().backend == ("pardiso" if pardiso_available() else "superlu")


def test_auto_uses_superlu_for_small_systems():
    from ntncontact.solvers import linear

    solver = LinearSolver()
    n = 50
    A = sp.diags([2.0 * np.ones(n), -np.ones(n - 1), -np.ones(n - 1)], [0, 1, -1], format="csr")
    x = solver.solve(A, np.ones(n))
    np.testing.assert_allclose(A @ x, np.ones(n), rtol=1e-12)
    assert n < linear.PARDISO_MIN_UNKNOWNS
    assert all(isinstance(i, linear._SuperLUBackend) for i in solver._impls.values())


@pytest.mark.parametrize("backend", BACKENDS)
def test_a_kept_factor_solves_later_right_hand_sides(backend):
    """factorize(): the factor of A keeps solving A x = b while it is valid; a PARDISO factor
    (held in the solver's handle) is invalidated by the next factorization, a SuperLU one is not."""
    solver = LinearSolver(backend)
    K0, nodes = block(stretch=0.0)
    K1, _ = block(stretch=0.1)
    A0, A1 = supported(K0, nodes), supported(K1, nodes)
    b = np.linspace(1.0, 2.0, A0.shape[0])
    factor0 = solver.factorize(A0)
    assert_accurate(A0, b, factor0(b))
    factor1 = solver.factorize(A1)
    assert_accurate(A1, b, factor1(b))
    if backend == "superlu":
        assert factor0.valid
        assert_accurate(A0, b, factor0(b))
    else:
        assert not factor0.valid
        with pytest.raises(LinearSolverError, match="replaced"):
            factor0(b)
    with pytest.raises(LinearSolverError, match="rows"):
        factor1(b[:-1])


def test_pardiso_threads_are_chosen_for_the_machine(monkeypatch):
    """One thread on 2 cores (a second saves ~5 % and PARDISO on two threads does not repeat
    its answers), half the cores up to MAX_THREADS on a larger machine; MKL_NUM_THREADS,
    else OMP_NUM_THREADS (Dask's workers set both to 1), wins if set."""
    from ntncontact import threads
    from ntncontact.solvers import linear

    monkeypatch.delenv("MKL_NUM_THREADS", raising=False)
    monkeypatch.delenv("OMP_NUM_THREADS", raising=False)
    assert linear.pardiso_threads(1) == linear.pardiso_threads(2) == 1
    assert linear.pardiso_threads(4) == 2
    assert linear.pardiso_threads(16) == threads.MAX_THREADS == 8
    assert linear.pardiso_threads(64) == 8
    assert linear.pardiso_threads() >= 1
    monkeypatch.setenv("OMP_NUM_THREADS", "3")
    assert linear.pardiso_threads(2) == 3
    monkeypatch.setenv("MKL_NUM_THREADS", "2")
    assert linear.pardiso_threads(16) == 2
    monkeypatch.setenv("MKL_NUM_THREADS", "zero")  # not a count: ignored
    assert linear.pardiso_threads(16) == 3


@pytest.mark.skipif(not pardiso_available(), reason="pypardiso not installed")
def test_pardiso_on_two_threads_repeats_its_answer_bit_for_bit(monkeypatch):
    """Without PARDISO's reproducibility mode two threads gave 2 distinct answers in 40
    factorizations of one 45 000-unknown matrix. With it (on for several threads) every
    factorization of the same matrix gives the same bits (a whole run on two threads still
    does not repeat itself: see linear.pardiso_threads)."""
    monkeypatch.setenv("MKL_NUM_THREADS", "2")
    rng = np.random.default_rng(3)
    n = 30_000  # a 2D 5-point Laplacian, unsymmetric by a convective term, plus a shift
    side = int(np.sqrt(n))
    lap = sp.kronsum(sp.diags([-1.0, 2.0, -1.0], [-1, 0, 1], (side, side)),
                     sp.diags([-1.0, 2.5, -1.5], [-1, 0, 1], (side, side)), format="csr")
    A = (lap + sp.eye(side * side)).tocsr()
    b = rng.standard_normal(side * side)
    answers = {LinearSolver("pardiso").factorize(A.copy())(b).tobytes() for _ in range(REPEATS)}
    assert len(answers) == 1


@pytest.mark.skipif(not pardiso_available(), reason="pypardiso not installed")
def test_pardiso_runs_on_the_chosen_threads(monkeypatch):
    """Every PARDISO call runs with MKL limited to pardiso_threads(), and MKL's own setting
    is restored after it (threadpoolctl)."""
    from pypardiso import PyPardisoSolver

    from ntncontact.solvers import linear

    seen = []
    real = PyPardisoSolver._call_pardiso

    def spy(self, A, b):
        seen.append(linear._mkl_controller().info()[0]["num_threads"])
        return real(self, A, b)

    assert LinearSolver("pardiso").backend == "pardiso"  # MKL loaded
    before = linear._mkl_controller().info()[0]["num_threads"]
    monkeypatch.setattr(linear, "pardiso_threads", lambda cores=None: 1)
    monkeypatch.setattr(PyPardisoSolver, "_call_pardiso", spy)
    A = spd_matrix()
    b = np.ones(A.shape[0])
    solver = LinearSolver("pardiso")
    assert_accurate(A, b, solver.solve(A, b))
    assert seen == [1, 1, 1]  # analysis, factorization, solve
    assert linear._mkl_controller().info()[0]["num_threads"] == before


@pytest.mark.skipif(not pardiso_available(), reason="pypardiso not installed")
def test_pardiso_handles_are_reused_across_patterns(monkeypatch):
    """A new sparsity pattern releases PARDISO's memory and takes the released solver object
    up again with a fresh handle (building one searches the disk for mkl_rt): one object for
    a run of pattern changes in one mode, two for the symmetric and the general mode, and
    every solution as accurate as from a new object."""
    import pypardiso

    from ntncontact.solvers import linear

    built = []

    class Counted(pypardiso.PyPardisoSolver):
        def __init__(self, *args, **kwargs):
            built.append(self)
            super().__init__(*args, **kwargs)

    monkeypatch.setattr(pypardiso, "PyPardisoSolver", Counted)
    monkeypatch.setattr(linear, "_IDLE_PARDISO", [])
    solver = LinearSolver("pardiso")
    # general mode, the pattern changing at every matrix
    for A in [unsymmetric_matrix(1), structurally_unsymmetric_matrix(), unsymmetric_matrix(2),
              structurally_unsymmetric_matrix(), unsymmetric_matrix(3)]:
        b = np.linspace(1.0, 2.0, A.shape[0])
        assert_accurate(A, b, solver.solve(A, b))
    assert len(built) == 1
    spd, unsym = spd_matrix(), unsymmetric_matrix(4)
    assert linear._Pattern(spd).matches(unsym)
    assert_accurate(spd, np.ones(spd.shape[0]), solver.solve(spd, np.ones(spd.shape[0])))
    # the same pattern in the other mode keeps the first mode's analysis: a second object
    assert_accurate(unsym, np.ones(unsym.shape[0]), solver.solve(unsym, np.ones(unsym.shape[0])))
    assert len(built) == 2
    del solver
    assert len(linear._IDLE_PARDISO) == 2  # released with the solver, for the next one


@pytest.mark.skipif(not pardiso_available(), reason="pypardiso not installed")
def test_pypardiso_is_told_where_mkl_rt_is(monkeypatch):
    """pypardiso searches the whole environment for mkl_rt (a recursive glob, 0.2 s here) at
    every solver it builds unless PYPARDISO_MKL_RT names it: the package sets it from the mkl
    wheel's file list, so a new solver object searches nothing and still solves; a path the
    user set is left as it is."""
    import pypardiso.pardiso_wrapper as wrapper

    from ntncontact.solvers import linear

    monkeypatch.delenv(linear.MKL_RT_VARIABLE, raising=False)
    linear._point_pypardiso_at_mkl_rt()
    path = os.environ.get(linear.MKL_RT_VARIABLE)
    assert path and "mkl_rt" in os.path.basename(path) and os.path.isfile(path)

    def no_search(*args, **kwargs):
        raise AssertionError("pypardiso searched for mkl_rt")

    monkeypatch.setattr(wrapper, "find_library", no_search)
    monkeypatch.setattr(wrapper.glob, "glob", no_search)
    monkeypatch.setattr(linear, "_IDLE_PARDISO", [])  # a new object, built now
    A = unsymmetric_matrix(5)
    b = np.linspace(1.0, 2.0, A.shape[0])
    assert_accurate(A, b, LinearSolver("pardiso").solve(A, b))

    monkeypatch.setenv(linear.MKL_RT_VARIABLE, "/the/users/own/libmkl_rt.so")
    linear._point_pypardiso_at_mkl_rt()
    assert os.environ[linear.MKL_RT_VARIABLE] == "/the/users/own/libmkl_rt.so"


# --- PARDISO in single precision, refined in double (issue 18) ---------------------------

def relative_residuals(A, b, x):
    return np.linalg.norm(b - A @ x, axis=0) / np.linalg.norm(b, axis=0)


@pytest.mark.skipif(not pardiso_available(), reason="pypardiso not installed")
@pytest.mark.parametrize("name", list(MATRICES))
def test_a_single_precision_factor_is_refined_to_the_residual_bound(name):
    """Each column's residual is within MIXED_RTOL of its right-hand side, for every kind of
    matrix the solver meets; one column at a time and several at once give the same bound.
    A single factor alone leaves ~1e-7 to 1e-4 on these (cond up to ~1e4), so the bound
    is the refinement's."""
    A = MATRICES[name]()
    B = np.random.default_rng(6).standard_normal((A.shape[0], 3))
    solver = LinearSolver("pardiso", precision="single")
    X = solver.solve(A, B)
    assert all(impl.single for impl in solver._impls.values())
    assert np.all(relative_residuals(A, B, X) <= linear.MIXED_RTOL)
    x = solver.solve(A, B[:, 0])
    assert relative_residuals(A, B[:, 0], x) <= linear.MIXED_RTOL
    exact = np.linalg.solve(A.toarray(), B[:, 0])
    cond = np.linalg.cond(A.toarray())
    assert np.linalg.norm(x - exact) <= 10 * linear.MIXED_RTOL * cond * np.linalg.norm(exact)
    assert solver.stats.double_fallbacks == 0


@pytest.mark.skipif(not pardiso_available(), reason="pypardiso not installed")
def test_auto_precision_factors_in_single_from_the_threshold(monkeypatch):
    """"auto": double below MIXED_MIN_UNKNOWNS (round-off accuracy), single from it (the
    residual bound); "double" never factors in single."""
    A = unsymmetric_matrix()
    b = np.random.default_rng(7).standard_normal(A.shape[0])
    below = LinearSolver("pardiso")
    assert_accurate(A, b, below.solve(A, b))
    assert not any(impl.single for impl in below._impls.values())
    monkeypatch.setattr(linear, "MIXED_MIN_UNKNOWNS", A.shape[0])
    above = LinearSolver("pardiso")
    x = above.solve(A, b)
    assert all(impl.single for impl in above._impls.values())
    assert relative_residuals(A, b, x) <= linear.MIXED_RTOL
    assert [impl.pardiso.get_iparm(28) for impl in above._impls.values()] == [1]
    forced = LinearSolver("pardiso", precision="double")
    assert_accurate(A, b, forced.solve(A, b))
    assert not any(impl.single for impl in forced._impls.values())
    with pytest.raises(ValueError, match="precision"):
        LinearSolver(precision="half")


def nearly_singular_matrix():
    """The supported stiffness shifted to within 1e-7 of one of its eigenvalues: cond 2.8e8, so
    a single-precision factor (cond x 6e-8 >> 1) cannot be refined, while a double one solves
    it (from ~1e-9, cond ~3e10, PARDISO perturbs a pivot in double too)."""
    A = spd_matrix()
    lowest = np.linalg.eigvalsh(A.toarray())[:12]
    return sp.csr_matrix(A - lowest[10] * (1.0 - 1e-7) * sp.eye(A.shape[0]))


@pytest.mark.skipif(not pardiso_available(), reason="pypardiso not installed")
def test_a_matrix_single_precision_cannot_solve_is_factored_again_in_double():
    """The refinement does not converge: the matrix is factored again in double (a new
    analysis), the solution is the direct solve's, and the mode stays in double."""
    A = nearly_singular_matrix()
    b = np.random.default_rng(8).standard_normal(A.shape[0])
    solver = LinearSolver("pardiso", precision="single")
    factor = solver.factorize(A)
    x = factor(b)
    assert solver.stats.double_fallbacks == 1
    assert solver.stats.refinements == linear.MAX_REFINEMENTS
    assert factor.valid
    assert_accurate(A, b, x)
    assert not any(impl.single for impl in solver._impls.values())
    assert_accurate(A, b, solver.solve(A, b))  # later factorizations in double at once
    assert solver.stats.double_fallbacks == 1 and solver.stats.refinements == 3


@pytest.mark.skipif(not pardiso_available(), reason="pypardiso not installed")
def test_a_non_finite_right_hand_side_is_reported_and_keeps_single_precision():
    A = unsymmetric_matrix()
    solver = LinearSolver("pardiso", precision="single")
    factor = solver.factorize(A)
    b = np.ones(A.shape[0])
    b[3] = np.nan
    with pytest.raises(LinearSolverError, match="not finite"):
        factor(b)
    assert solver.stats.double_fallbacks == 0
    assert all(impl.single for impl in solver._impls.values())
    x = factor(np.ones(A.shape[0]))
    assert relative_residuals(A, np.ones(A.shape[0]), x) <= linear.MIXED_RTOL


def bordered(stress: float, free: bool = False, redundant: bool = False):
    """The bordered Newton matrix of exact contact constraints as ``engine/problem.py`` builds
    it: stiffness x ``stress`` (E in another stress unit), 5 constraints tying dof pairs with
    columns B of O(L_c) = 0.25 (untouched by the unit) and rows G = B^T scaled to the largest
    diagonal stiffness k (``StepProblem._balanced_rows``). ``free``: an unsupported block (a
    rigid motion the constraints do not hold); ``redundant``: the first constraint twice."""
    K, nodes = block(stretch=0.0, kind="linear_elastic")
    K = stress * (K if free else supported(K, nodes))
    n, m = K.shape[0], 6 if redundant else 5
    pairs = np.r_[np.arange(5), 0][:m]
    rows = np.repeat(np.arange(m), 2)
    cols = np.column_stack([pairs * 7, pairs * 7 + 40]).ravel()
    B = sp.csr_matrix((np.tile([0.25, -0.25], m), (rows, cols)), shape=(m, n)).T
    k = np.abs(K.diagonal()).max()
    G = sp.diags(np.full(m, k / np.hypot(0.25, 0.25))) @ B.T
    return sp.bmat([[K, B], [G, None]], format="csr"), k / np.hypot(0.25, 0.25)


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("stress", [1e-10, 1e-6, 1e6, 1e10, 1e12])
def test_a_bordered_system_solves_alike_in_any_stress_unit(backend, stress):
    """Scaling E (and the loads) changes only the units of the answer: the same displacements,
    multipliers x ``stress``. Before, the multiplier pivots (Schur complement ~ L_c, the
    stiffness's ~ E) fell below PIVOT_RTOL x the largest from E ~ 1e10 on and SuperLU's
    check called the matrix singular (tester B, session 41: lagrange contact of steel in SI
    units failed at its first contact step); an LU is the same with the multiplier columns
    scaled, so the check now weighs their pivots so (``_check_pivots``)."""
    rng = np.random.default_rng(5)
    A1, r1 = bordered(1.0)
    n = A1.shape[0] - 5
    f, h = rng.standard_normal(n), 0.01 * rng.standard_normal(5)
    x1 = LinearSolver(backend, check_pivots=True).solve(A1, np.r_[f, r1 * h])
    A, r = bordered(stress)
    x = LinearSolver(backend, check_pivots=True).solve(A, np.r_[stress * f, r * h])
    assert np.allclose(x[:n], x1[:n], rtol=1e-10, atol=1e-10 * np.abs(x1[:n]).max())
    assert np.allclose(x[n:], stress * x1[n:], rtol=1e-10)


@pytest.mark.parametrize("stress", [1.0, 1e12])
@pytest.mark.parametrize("case", ["free", "redundant"])
def test_a_singular_bordered_system_is_still_detected(stress, case):
    """The weighted check still finds a rigid motion the constraints leave free, and a
    constraint given twice (its multipliers then undetermined), in any unit."""
    A, r = bordered(stress, **{case: True})
    b = A @ np.random.default_rng(2).standard_normal(A.shape[0])  # in the range: no growth
    with pytest.raises(LinearSolverError, match="singular"):
        LinearSolver("superlu", check_pivots=True).solve(A, b)
