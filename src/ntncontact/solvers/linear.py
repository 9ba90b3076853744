"""Sparse direct solver for Newton steps: reuses the symbolic analysis while the pattern holds.

Three backends:

- ``"pardiso"``: Intel MKL PARDISO through ``pypardiso`` (the ``fast`` extra), its
  ``PyPardisoSolver`` object. The ordering (METIS) and symbolic factorization are computed
  once per sparsity pattern; each further matrix with that pattern only costs a numerical
  factorization. That is the one thing pypardiso's ``factorize`` cannot give (it always runs
  phase 12, analysis included): measured on Q4 tangents here, phase 12 costs 2.0-2.2x phase
  22 (symmetric: 398 against 203 ms at 20 160 dofs, 8.5 against 3.8 s at 200 500 dofs, one
  thread), so the phases are set with pypardiso's ``set_phase`` and run by its
  ``_call_pardiso``. Symmetric matrices use the symmetric indefinite mode (Bunch-Kaufman),
  which is valid for the Neo-Hookean tangent away from equilibrium; unsymmetric ones
  (friction, convective terms) the general mode with scaling and weighted matching. Threads:
  :func:`pardiso_threads`. From :data:`MIXED_MIN_UNKNOWNS` unknowns it factors in single
  precision and refines each solution in double (:class:`_PardisoBackend`, "Precision").
- ``"superlu"``: SciPy's SuperLU, always available. The MMD(A^T + A) column ordering is computed
  once per pattern and reused by factoring the symmetrically permuted matrix in natural order.
- ``"static"``: for small systems, the same ordering but a compiled LU without row
  interchanges on the fill pattern computed once per sparsity pattern
  (:mod:`ntncontact.solvers.static_lu`); SuperLU does the first factorization of a pattern
  (which gives the ordering) and every factorization whose pivots the static LU rejects
  (``SolverStats.fallbacks``). Ring impact tangent (890 unknowns): 0.4-0.6 ms per
  factorization against 1.0-1.2 ms for SuperLU, solves 2-3x faster; the ring run's time loop
  13-18 % shorter (see ``benchmarks/README.md``). Against PARDISO (``benchmarks/static_lu.py``,
  the same tangent, this session under a load of 12 on 2 cores): factorization 2.2 ms
  against SuperLU's 9.9 and PARDISO's 5.8 (4.5x and 2.6x), solve 0.29 ms against 1.0 and
  1.3 (3.5x and 4.5x). It is kept for that margin: at least 2x on both against either.

``"auto"`` uses ``"static"`` below :data:`SMALL_SYSTEM` unknowns, SuperLU up to
:data:`PARDISO_MIN_UNKNOWNS`, and above it PARDISO when it loads: on a 2-core machine it was
~20x faster than SuperLU on a 200 000-dof Q4 tangent (see ``benchmarks/README.md``). A
singular matrix (e.g. a body without supports in a quasi-static problem) raises
:class:`LinearSolverError`.
"""

from __future__ import annotations

import ctypes
import importlib.metadata
import os
import sys
import warnings
from dataclasses import dataclass
from functools import lru_cache
from types import ModuleType
from typing import Literal, get_args

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from numpy.typing import NDArray
from threadpoolctl import ThreadpoolController

from ..threads import MAX_THREADS, available_cores, threads_from_environment
from . import static_lu

Backend = Literal["auto", "pardiso", "superlu", "static"]
Precision = Literal["auto", "single", "double"]

#: |A - A^T| <= SYMMETRY_RTOL max|A| counts as symmetric (assembly round-off is ~1e-16).
SYMMETRY_RTOL = 1e-12
#: A pivot below PIVOT_RTOL times the largest one marks SuperLU's factor as singular: rigid
#: modes give ~1e-15, while penalty/stiffness contrasts of 1e8 stay far above it.
PIVOT_RTOL = 1e-12
#: SuperLU's pivots are checked at the first factorization of a pattern, at a factorization
#: whose pivots the static LU rejected, and when a solution grows like the inverse of a tiny
#: pivot, |x| max|A| > PIVOT_CHECK_GROWTH |b| (see ``_SuperLUBackend.solver``). The growth
#: alone missed a static body free to slide under a self-balanced load (a right-hand side
#: orthogonal to the rigid mode: the run completed, the body shifted by round-off); the
#: examples' smallest pivots are 1.5e-8 (block sliding) to 9e-3 of the largest, that body's
#: 2e-16. Small systems have every SuperLU factor checked (the static LU's fallbacks, and
#: patterns it leaves to SuperLU: ties and Lagrange multipliers): the delamination example's
#: 946 checks cost 0.16 of 7.6 s of CPU. A quasi-static run checks every factor
#: (``LinearSolver(check_pivots=True)``): a tester's Hertz cylinder, free in y and unloaded to
#: zero, lost its last pairs and moved by 0.987 in one Newton step (R's round-off along the
#: free motion over its pivot) with no error; the growth test passed, |x| max|A| ~ 1e8 ~
#: 1e6 |b|.
PIVOT_CHECK_GROWTH = 1e6
#: what a singular matrix usually means, for the error both backends raise
SINGULAR_CAUSES = ("(a body whose supports leave a rigid motion free, in a static run also "
                   "one held only by contact pairs that all slip, as under a tangential load "
                   "above the friction's limit, or that all opened, as at zero load, or one "
                   "placed apart from its partner, held by nothing until it touches (start it "
                   "touching, or support it); a mechanism, or coincident nodes that split a "
                   "mesh?)")
#: Pivot or entry magnitudes past which a "singular" matrix is one out of the floating-point
#: range rather than one with a free motion: a true free motion leaves a pivot of round-off
#: size (~1e-16 of the largest) or zero, while density 1e-300, E 1e300 or a penalty 1e300
#: (a tester's fuzzing) left pivots 1e-290 of the largest, or a largest of 1e300.
OUT_OF_RANGE_RATIO = 1e-100
OUT_OF_RANGE_LARGEST = 1e150
#: the cause of a singular matrix whose scale is out of range
RANGE_CAUSE = ("(values out of the floating-point range, {}: check the units and scale of E, "
               "density and the contact penalties; no rigid motion need be free)")
#: SuperLU keeps a diagonal pivot at least this fraction of the largest entry of its column
#: (partial pivoting otherwise); the static LU accepts a pivot on the same test, so it takes
#: the pivots SuperLU would and falls back to SuperLU where SuperLU would interchange rows.
DIAG_PIVOT_THRESH = 0.1
#: The static LU stops being tried for a pattern after this many fallbacks in a row (a
#: bordered system whose zero diagonal block always needs pivoting).
MAX_CONSECUTIVE_FALLBACKS = 3


class LinearSolverError(RuntimeError):
    """The linear system cannot be solved: singular matrix, bad input or backend failure.
    ``columns``: the matrix's columns that the free motion moves, where known (SuperLU), so that the
    caller can name the bodies they belong to."""

    def __init__(self, message: str, columns: NDArray | None = None) -> None:
        super().__init__(message)
        self.columns = columns


@lru_cache(maxsize=1)
def pardiso_available() -> bool:
    """True if MKL PARDISO can be loaded (``pip install pypardiso``)."""
    _point_pypardiso_at_mkl_rt()  # the threading layer was pinned at this module's import
    try:
        import pypardiso  # it loads mkl_rt, or raises ImportError
    except (ImportError, OSError):  # not installed, or a broken MKL installation
        return False
    _select_threading_layer(pypardiso)
    return True


#: pypardiso's own setting for where mkl_rt is (read by every ``PyPardisoSolver()``)
MKL_RT_VARIABLE = "PYPARDISO_MKL_RT"


def _point_pypardiso_at_mkl_rt() -> None:
    """Set :data:`MKL_RT_VARIABLE` to the ``mkl`` wheel's mkl_rt, unless the user set it.

    Why: pypardiso asks ctypes' ``find_library``, which does not see the wheel's copy (it lies
    in the environment's ``lib/``), and then globs ``sys.prefix`` recursively, at its import
    (it builds a solver there) and at every ``PyPardisoSolver()``: 0.2 s each in this
    project's .venv, more in a larger environment. A run on PARDISO builds one or two, so
    that was ~0.5 s of each (ring refined 4x, 30 steps: 6.01 -> 5.49 s a run, 3 pairs).
    The wheel's own file list names the library (3 ms to read)."""
    if os.environ.get(MKL_RT_VARIABLE):
        return
    try:
        files = importlib.metadata.files("mkl") or []
    except importlib.metadata.PackageNotFoundError:  # MKL from elsewhere: pypardiso searches
        return
    found = sorted((str(f.locate()) for f in files if "mkl_rt" in f.name), key=len)
    found = [path for path in found if os.path.isfile(path)]
    if found:  # the shortest first, as pypardiso orders its own matches
        os.environ[MKL_RT_VARIABLE] = os.path.realpath(found[0])


#: MKL's own setting for the OpenMP runtime its threads run on (read when mkl_rt loads)
MKL_THREADING_VARIABLE = "MKL_THREADING_LAYER"


def _pin_mkl_threading_layer() -> None:
    """Set :data:`MKL_THREADING_VARIABLE` to GNU (libgomp, the runtime of Numba's OpenMP
    threading layer), unless the user set it or libgomp cannot be loaded.

    Why: mkl_rt picks its layer when it loads, from the OpenMP runtime already in the
    process: GNU after Numba's kernels had run, Intel's libiomp5 before them (a script or
    test that asked for PARDISO first). PARDISO's answers differ in the last bits between
    the two layers, also on one thread, so the same run gave two histories depending on the
    import order, and a restart by the command line of a run begun in Python differed from
    it (ring refined 4x: 5 of 5 kill-and-restart tries; with GNU pinned, both orders give
    the command line's bits). It also spares the process a second OpenMP runtime."""
    if os.environ.get(MKL_THREADING_VARIABLE) or not sys.platform.startswith("linux"):
        return
    try:
        ctypes.CDLL("libgomp.so.1")
    except OSError:  # no GNU OpenMP runtime: MKL keeps its default
        return
    os.environ[MKL_THREADING_VARIABLE] = "GNU"


#: MKL's codes of its threading layers (mkl_service.h), by their MKL_THREADING_LAYER names
_MKL_LAYERS = {"INTEL": 0, "SEQUENTIAL": 1, "PGI": 2, "GNU": 3, "TBB": 4}


def _select_threading_layer(pypardiso: ModuleType) -> None:
    """Select :data:`MKL_THREADING_VARIABLE`'s layer in the mkl_rt pypardiso loaded
    (``MKL_Set_Threading_Layer``, which holds while no MKL function has run yet).

    Why: mkl_rt reads the variable when it loads, and pypardiso loads it at its import. A
    script that imported pypardiso before asking ntncontact for PARDISO ran MKL on Intel's
    OpenMP runtime beside Numba's GNU one: other bits (hertz_factor refined 4x: 124 against
    125 Newton iterations) and ~30 % more CPU (15.4 against 11.8 s: two runtimes' threads)."""
    code = _MKL_LAYERS.get(os.environ.get(MKL_THREADING_VARIABLE, "").upper())
    library = getattr(getattr(pypardiso, "ps", None), "libmkl", None)  # its module's solver
    select = getattr(library, "MKL_Set_Threading_Layer", None)
    if code is None or select is None:
        return
    select.argtypes, select.restype = [ctypes.c_int], ctypes.c_int
    in_effect = select(code)
    if in_effect != code:  # MKL ran before: its layer is fixed for this process
        names = {value: name for name, value in _MKL_LAYERS.items()}
        warnings.warn(
            f"MKL already runs on its {names.get(in_effect, in_effect)} threading layer (it was "
            f"used before ntncontact was imported), not {MKL_THREADING_VARIABLE}="
            f"{names[code]}: PARDISO's results may differ in the last bits from a run started "
            "by the command line, and two OpenMP runtimes share the cores. Import ntncontact "
            f"first, or set {MKL_THREADING_VARIABLE}=GNU before Python starts.",
            RuntimeWarning, stacklevel=2)


#: PARDISO threads on a machine with at most this many cores: one (see pardiso_threads).
FEW_CORES = 2


def pardiso_threads(cores: int | None = None) -> int:
    """MKL threads for PARDISO: ``MKL_NUM_THREADS``, else ``OMP_NUM_THREADS`` (MKL's own
    order), else one thread on a machine of at most :data:`FEW_CORES` cores and half the
    cores, at most :data:`ntncontact.threads.MAX_THREADS`, on a larger one.

    Why one on 2 cores: a second thread saved only ~5 % of a refined step in session 30 (ring 8x
    0.707 -> 0.671 s, Hertz 8x 2.668 -> 2.538 s, with the BLAS serial, ``benchmarks/scaling.py
    --threads``), and with single-precision factors (session 44, quiet machine, load ~1) it costs:
    ring 8x 0.83 -> 0.96 s a step, Hertz 8x 2.21 -> 2.62 s; and PARDISO on several threads does not
    repeat its answers bit for bit, even in its reproducible mode (:func:`_pardiso_iparm`): the ring
    refined 4x, killed and restarted, differed from the uninterrupted run in 3 of 11 tries on two
    threads, in 1 of 19 on one. On a larger machine the threads pay more (the nested-dissection tree
    of a 2D mesh of 10^5 unknowns keeps up to ~8 busy), and a bit-for-bit restart there needs
    ``MKL_NUM_THREADS=1``."""
    requested = threads_from_environment("MKL_NUM_THREADS", "OMP_NUM_THREADS")
    if requested is not None:
        return requested
    cores = available_cores() if cores is None else cores
    return 1 if cores <= FEW_CORES else min(cores // 2, MAX_THREADS)


@lru_cache(maxsize=1)
def _mkl_controller() -> ThreadpoolController:
    """threadpoolctl's handle on the MKL that pypardiso loaded (created once it is loaded)."""
    return ThreadpoolController().select(internal_api="mkl")


@dataclass
class SolverStats:
    """Counts of the expensive steps, to check that the symbolic analysis is reused."""

    analyses: int = 0
    factorizations: int = 0
    solves: int = 0
    pivot_checks: int = 0  # SuperLU factors whose pivots were inspected (PIVOT_CHECK_GROWTH)
    fallbacks: int = 0  # static-LU factorizations redone by SuperLU (a pivot needed pivoting)
    refinements: int = 0  # solves with a single-precision factor added by refinement sweeps
    double_fallbacks: int = 0  # single-precision PARDISO factors redone in double


class _Pattern:
    """A CSR sparsity pattern with the index maps the backends need (computed once)."""

    def __init__(self, A: sp.csr_matrix) -> None:
        self.n = A.shape[0]
        self.indptr = A.indptr.copy()
        self.indices = A.indices.copy()
        # positions and rows as int32 where they fit, and no int32 copy of int32 arrays: these
        # maps are kept for the run, and the temporaries of their making were the largest
        # transient of a Hertz k = 8 step (77 MB over 2.1 M entries with int64 and a float
        # tracer; issue 18, memory)
        position = np.int32 if self.indices.size < 2**31 else np.int64
        rows = np.repeat(np.arange(self.n, dtype=position), np.diff(self.indptr))
        self.transpose = _transpose_map(self.indptr, self.indices, self.n, position)
        # entries kept in symmetric mode
        self.upper = np.flatnonzero(self.indices >= rows).astype(position)
        self.upper_indptr = np.zeros(self.n + 1, dtype=np.int32)
        self.upper_indptr[1:] = np.cumsum(np.bincount(rows[self.upper], minlength=self.n))
        self.upper_indices = self.indices[self.upper].astype(np.int32)
        self.indptr32 = self.indptr.astype(np.int32, copy=False)
        self.indices32 = self.indices.astype(np.int32, copy=False)
        # position of each row's diagonal entry, -1 where the pattern has none (the zero
        # block of a bordered system): for the border columns of ``column_weights``
        on_diagonal = np.flatnonzero(self.indices == rows)
        self.diagonal = np.full(self.n, -1, dtype=np.int64)
        self.diagonal[rows[on_diagonal]] = on_diagonal

    def matches(self, A: sp.csr_matrix) -> bool:
        return (A.shape[0] == self.n and A.nnz == self.indices.size
                and np.array_equal(A.indptr, self.indptr)
                and np.array_equal(A.indices, self.indices))

    def column_weights(self, data: NDArray) -> NDArray | None:
        """Per column, the factor that brings a border column (zero diagonal: a contact or tie
        multiplier, or theta) to the largest diagonal entry (the stiffness), NaN for the other
        columns; None without border columns. Its pivots are then weighed as those of A W
        (see ``_check_pivots``)."""
        diagonal = np.where(self.diagonal >= 0, data[self.diagonal], 0.0)
        border = diagonal == 0.0
        if not border.any():
            return None
        in_border = border[self.indices]
        column_max = np.zeros(self.n)
        np.maximum.at(column_max, self.indices[in_border], np.abs(data[in_border]))
        stiffness = np.abs(diagonal).max(initial=0.0)
        weights = np.ones(self.n)
        scaled = border & (column_max > 0.0) & (stiffness > 0.0)
        weights[scaled] = stiffness / column_max[scaled]
        weights[~border] = np.nan  # not a border column: its pivot is read as it is
        return weights

    def is_symmetric(self, data: NDArray) -> bool:
        """Structurally symmetric and |A_ij - A_ji| <= SYMMETRY_RTOL max|A|."""
        if self.transpose is None:
            return False
        scale = max(data.max(initial=0.0), -data.min(initial=0.0))  # max |A|, no copy
        largest = 0.0  # max |A_ij - A_ji|, a chunk of entries at a time (no nnz temporary)
        for start in range(0, data.size, VALUE_CHUNK):
            stop = start + VALUE_CHUNK
            difference = data[self.transpose[start:stop]]
            np.subtract(data[start:stop], difference, out=difference)
            np.abs(difference, out=difference)
            largest = max(largest, difference.max(initial=0.0))
        return bool(largest <= SYMMETRY_RTOL * scale)


def _transpose_map(indptr: NDArray, indices: NDArray, n: int,
                   dtype: type = np.int64) -> NDArray | None:
    """Position of entry (j, i) for each entry (i, j) of a sorted CSR pattern, or None if some
    (j, i) is structurally absent. Transposes a matrix holding entry positions (SciPy's C++,
    on integer data of ``dtype``: exact, and no float copy to convert)."""
    nnz = indices.size
    tracer = sp.csr_matrix((np.arange(nnz, dtype=dtype), indices, indptr), shape=(n, n))
    transposed = tracer.T.tocsr()  # sorted indices
    if not (np.array_equal(transposed.indptr, indptr)
            and np.array_equal(transposed.indices, indices)):
        return None
    return transposed.data.astype(dtype, copy=False)


#: Below this many unknowns "auto" uses SuperLU even when PARDISO is installed: PARDISO's
#: per-call overhead (~5 ms, threads) dominates small contact problems (ring impact: 800 dofs).
PARDISO_MIN_UNKNOWNS = 10_000

#: From this many unknowns precision "auto" factors in single precision (PARDISO only):
#: where the factorization, not Python, is a Newton step's cost.
MIXED_MIN_UNKNOWNS = 10_000
#: A solution from a single-precision factor is refined in double until |b - A x| <= MIXED_RTOL |b|
#: (per column), unless the caller states what it needs (``Factorization(b, rtol)``: Newton's
#: forcing term, the multiplier sensitivity). Why 1e-6: the strictest ratio the Newton loop works
#: with is the inexact augmentations' 1e-4 of their start (kept-factor steps need 0.1), so the
#: linear residual stays two orders below it. Measured at k = 8 (benchmarks/README.md, session 32):
#: Hertz 134 -> 137 Newton iterations, the ring and the fast-sliding blocks the same counts. A
#: single factor's first solve leaves ~2-3e-7 |b| as a rule, so 1e-7 (Hertz 134, 159 sweeps) and
#: 1e-8 (134, 187) ask a sweep of nearly every solve and the ring then runs slower than in double
#: (21.4 against 19.2 s); no check at all gives Hertz 141.
MIXED_RTOL = 1e-6
#: Refinement sweeps before a single-precision factor is judged too inaccurate for its matrix
#: (about cond(A) x 6e-8 >= 1): it is then factored again in double, and stays so.
MAX_REFINEMENTS = 3


class Factorization:
    """A factored matrix: call it with b (n,) or (n, k) for the solution of A x = b."""

    def __init__(self, owner: LinearSolver, n: int, solve, generation: int | None = None) -> None:
        # a PARDISO factor has a generation, and its ``solve`` takes the caller's rtol
        self.owner, self.n, self._solve, self.generation = owner, n, solve, generation

    @property
    def valid(self) -> bool:
        """False once a PARDISO factor was replaced by a later factorization of its solver."""
        return self.generation is None or self.generation == self.owner._generation

    def __call__(self, b: NDArray, rtol: float = MIXED_RTOL) -> NDArray:
        """x with |b - A x| <= rtol |b| in each column of b. ``rtol`` is what the caller needs
        from a single-precision factor's refinement (:meth:`_PardisoBackend.solve`): a Newton
        step its forcing term (``newton.forcing_term``), the multiplier sensitivity a loose
        one; the default, :data:`MIXED_RTOL`, for everything else. A double factor's
        solution is at round-off whatever ``rtol``."""
        b = np.asarray(b, dtype=float)
        if b.shape[0] != self.n:
            raise LinearSolverError(f"right-hand side has {b.shape[0]} rows, matrix has {self.n}")
        if not self.valid:
            raise LinearSolverError("this factorization was replaced by a later one")
        if self.n == 0:
            return np.zeros_like(b)
        x = self._solve(b) if self.generation is None else self._solve(b, rtol)
        self.owner.stats.solves += 1
        if not np.all(np.isfinite(x)):
            raise LinearSolverError("the solution is not finite: the matrix is singular")
        return x


class LinearSolver:
    """Solves A x = b for a sequence of sparse matrices, reusing the analysis of their pattern.

    ``backend``: "auto" (the static LU below :data:`SMALL_SYSTEM` unknowns, PARDISO if
    available and the system has at least :data:`PARDISO_MIN_UNKNOWNS` unknowns, else
    SuperLU), "pardiso", "superlu" (SuperLU only) or "static" (the static LU at any size).
    ``symmetric``: None detects symmetry from the values at each call; True/False forces it
    (True uses the upper triangle only). ``precision``: how PARDISO factors, "single" (a
    single-precision factor, each solution refined in double to a residual of
    :data:`MIXED_RTOL` |b|), "double" (solutions at round-off), or "auto" (single from
    :data:`MIXED_MIN_UNKNOWNS` unknowns). SuperLU and the static LU always factor in double.
    ``check_pivots``: check every SuperLU factor's pivots before its first solve, not only
    when a solution grows (see :data:`PIVOT_CHECK_GROWTH`): for quasi-static runs, where no
    mass holds a body that contact lets go.
    """

    def __init__(self, backend: Backend = "auto", symmetric: bool | None = None,
                 precision: Precision = "auto", check_pivots: bool = False) -> None:
        self._pattern: _Pattern | None = None
        # one factorization per symmetry mode (PARDISO), so alternating modes keep both analyses
        self._impls: dict[bool | None, _PardisoBackend | _SuperLUBackend] = {}
        if backend not in get_args(Backend):
            raise ValueError(f"unknown linear solver backend '{backend}'")
        if precision not in get_args(Precision):
            raise ValueError(f"unknown factor precision '{precision}'")
        self.precision = precision
        self._auto = backend == "auto"
        if backend == "pardiso" and not pardiso_available():
            raise LinearSolverError("PARDISO requested but pypardiso/MKL is not installed")
        self._backend = None if self._auto else backend
        self.symmetric = symmetric
        self.check_pivots = check_pivots
        self.stats = SolverStats()
        self._generation = 0  # counts factorizations: a PARDISO factor is valid until the next

    @property
    def backend(self) -> str:
        """"pardiso", "superlu" or "static" (if forced); "auto" looks for MKL only when first
        asked (loading it takes ~0.6 s, which small problems, never solved by PARDISO, need not
        pay)."""
        if self._backend is None:
            self._backend = "pardiso" if pardiso_available() else "superlu"
        return self._backend

    def solve(self, A: sp.spmatrix, b: NDArray) -> NDArray:
        """Solution of A x = b (b of shape (n,) or (n, k)); raises :class:`LinearSolverError`."""
        return self.factorize(A)(b)

    def factorize(self, A: sp.spmatrix) -> Factorization:
        """Factor A once to solve for many right-hand sides, later ones included (modified
        Newton): the result stays valid until this solver factors another matrix with PARDISO
        (whose factor lives in the shared handle); SuperLU and static-LU factors are kept by the
        result (each static factor has its own value arrays). A single-precision PARDISO factor
        refines its solutions against A's own values (no copy is kept): change no value of A
        while its factorization is in use."""
        A = _canonical_csr(A)
        if self._pattern is None or not self._pattern.matches(A):
            self._release()
            self._pattern = _Pattern(A)
        if A.shape[0] == 0:
            return Factorization(self, 0, lambda b: np.zeros_like(b))
        backend = self._backend_for(A.shape[0])
        symmetric = None  # an LU serves both (and its key in _impls; n fixes the LU's kind)
        if backend == "pardiso":
            symmetric = (self._pattern.is_symmetric(A.data) if self.symmetric is None
                         else self.symmetric)
        impl = self._impls.get(symmetric)
        if impl is None:
            if backend == "pardiso":
                single = self.precision == "single" or (self.precision == "auto"
                                                       and A.shape[0] >= MIXED_MIN_UNKNOWNS)
                impl = _PardisoBackend(self._pattern, symmetric, self.stats, single=single)
            else:
                impl = _BACKEND_CLASSES[backend](self._pattern, symmetric, self.stats)
            self._impls[symmetric] = impl
        for other in self._impls.values():
            if other is not impl:  # its factor is dead from now on (Factorization.valid)
                other.release_factor()
        impl.factor(A.data)
        if self.check_pivots and isinstance(impl, _SuperLUBackend):
            impl.unchecked = True
        self._generation += 1
        return Factorization(self, A.shape[0], impl.solver(),
                             self._generation if backend == "pardiso" else None)

    def analysis_state(self) -> tuple[dict, dict[str, NDArray]]:
        """What decides how the next matrix is factored, for a restart checkpoint (JSON
        values, arrays): the last pattern and, per SuperLU/static-LU mode, its ordering and
        the static LU's fallback record, and per PARDISO mode the values its analysis was made
        with. Without them a restarted run would factor its first matrix by SuperLU where the
        uninterrupted run reuses the static LU, or with another PARDISO scaling: other
        round-off."""
        if self._pattern is None:
            return {}, {}
        modes, arrays = [], {"indptr": self._pattern.indptr, "indices": self._pattern.indices}
        for key, impl in self._impls.items():
            if isinstance(impl, _PardisoBackend) and impl.analysis_values is not None:
                arrays[f"pardiso_values_{len(modes)}"] = impl.analysis_values
                modes.append({"symmetric": key, "pardiso": True, "single": impl.single})
            if isinstance(impl, _SuperLUBackend) and impl.perm is not None:
                arrays[f"perm_{len(modes)}"] = impl.perm
                modes.append({"symmetric": key, "static": isinstance(impl, _StaticLUBackend),
                              "usable": getattr(impl, "usable", True),
                              "fallbacks_in_a_row": getattr(impl, "fallbacks_in_a_row", 0)})
        return {"n": self._pattern.n, "modes": modes}, arrays

    def restore_analysis(self, info: dict, arrays: dict[str, NDArray]) -> None:
        """Take up :meth:`analysis_state`'s values (the orderings are not recomputed)."""
        self._release()
        self._pattern = None
        if not info:
            return
        n, indices = int(info["n"]), arrays["indices"]
        self._pattern = _Pattern(sp.csr_matrix((np.zeros(indices.size), indices,
                                                arrays["indptr"]), shape=(n, n)))
        for index, mode in enumerate(info["modes"]):
            if mode.get("pardiso"):
                if pardiso_available():  # else the run goes on with another solver
                    impl = _PardisoBackend(self._pattern, mode["symmetric"], self.stats,
                                           single=bool(mode.get("single", False)))
                    impl.restored_values = np.asarray(arrays[f"pardiso_values_{index}"])
                    self._impls[mode["symmetric"]] = impl
                continue
            kind = _StaticLUBackend if mode["static"] else _SuperLUBackend
            impl = kind(self._pattern, mode["symmetric"], self.stats)
            impl.perm = np.asarray(arrays[f"perm_{index}"])
            p = self._pattern
            impl.permuted = static_lu.permuted_csc(p.indptr, p.indices, impl.perm)
            if isinstance(impl, _StaticLUBackend):
                impl.symbolic = static_lu.analyse(p.indptr, p.indices, impl.perm)
                impl.usable = bool(mode["usable"]) and impl.symbolic is not None
                impl.fallbacks_in_a_row = int(mode["fallbacks_in_a_row"])
            self._impls[mode["symmetric"]] = impl

    def _backend_for(self, n: int) -> str:
        if not self._auto:
            return self.backend
        if n < SMALL_SYSTEM:
            return "static"
        return "superlu" if n < PARDISO_MIN_UNKNOWNS else self.backend

    def _release(self) -> None:
        for impl in self._impls.values():
            impl.release()
        self._impls = {}

    def __del__(self) -> None:
        try:
            self._release()
        except Exception:  # interpreter shutdown: MKL may already be unloaded
            pass


def _canonical_csr(A: sp.spmatrix) -> sp.csr_matrix:
    """Square float64 CSR with sorted, unique indices and finite values."""
    if not sp.issparse(A):
        raise LinearSolverError(f"expected a sparse matrix, got {type(A).__name__}")
    if A.shape[0] != A.shape[1]:
        raise LinearSolverError(f"matrix must be square, got shape {A.shape}")
    A = sp.csr_matrix(A, dtype=float)
    if not A.has_canonical_format:
        A = A.copy()
        A.sum_duplicates()  # also sorts the indices
    if not np.all(np.isfinite(A.data)):
        raise LinearSolverError("matrix has non-finite entries")
    empty = np.flatnonzero(np.diff(A.indptr) == 0)
    if empty.size:
        raise LinearSolverError(f"matrix is singular: row {empty[0]} is empty")
    return A


#: Below this many unknowns SuperLU gets no supernode relaxation and panels of one column:
#: 1.7x faster factorizations of the ring impact's 890-dof tangent (0.9 ms against 1.5 ms),
#: while from a few thousand unknowns on the supernodes pay (3280 dofs: 133 ms against 144).
SMALL_SYSTEM = 2000


class _SuperLUBackend:
    """SuperLU with the MMD(A^T+A) ordering computed at the first factorization of a pattern."""

    def __init__(self, pattern: _Pattern, symmetric: bool, stats: SolverStats) -> None:
        self.pattern, self.stats = pattern, stats
        self.perm: NDArray | None = None  # symmetric permutation p: later factors are of A[p][:, p]
        self.lu: spla.SuperLU | None = None
        self.lu_is_permuted = False
        self.scale = 0.0  # max |A| of the current factor
        self.unchecked = False  # the factor's pivots are to be checked before its first use
        self.weights: NDArray | None = None  # the factor's border-column weights, if any

    def factor(self, data: NDArray) -> None:
        p = self.pattern
        # SymmetricMode: FE patterns are symmetric, so prefer diagonal pivots (keeps the ordering)
        kwargs = {"diag_pivot_thresh": DIAG_PIVOT_THRESH, "options": {"SymmetricMode": True}}
        if p.n < SMALL_SYSTEM:
            kwargs |= {"relax": 1, "panel_size": 1}
        try:
            if self.perm is None:
                A = sp.csc_matrix(sp.csr_matrix((data, p.indices, p.indptr), shape=(p.n, p.n)))
                self.lu = spla.splu(A, permc_spec="MMD_AT_PLUS_A", **kwargs)
                self.perm = np.argsort(self.lu.perm_c)
                self.permuted = static_lu.permuted_csc(p.indptr, p.indices, self.perm)
                self.lu_is_permuted = False
                self.stats.analyses += 1
                self.unchecked = True
            else:
                indptr, indices, gather = self.permuted
                Ap = sp.csc_matrix((data[gather], indices, indptr), shape=(p.n, p.n))
                self.lu = spla.splu(Ap, permc_spec="NATURAL", **kwargs)
                self.lu_is_permuted = True
        except RuntimeError as err:  # "Factor is exactly singular"
            raise LinearSolverError(f"SuperLU: {err}: the matrix is singular") from None
        self.stats.factorizations += 1
        self.scale = float(np.abs(data).max(initial=0.0))
        self.weights = p.column_weights(data)
        if self.weights is not None and self.lu_is_permuted:
            self.weights = self.weights[self.perm]  # the factor's column c is A's perm[c]

    def solver(self):
        """The solve of the current factor, which keeps working after later factorizations.

        Its pivots are checked (at most once) when a solution grows like the inverse of a tiny
        pivot: reading them costs ~0.4 ms (SciPy copies U into a matrix), a third of a small
        factorization, and a well-conditioned solve cannot hide one. They are checked before
        the first use of a factor that ``unchecked`` marks (see PIVOT_CHECK_GROWTH)."""
        lu, perm, scale, stats, weights = self.lu, self.perm, self.scale, self.stats, self.weights
        if self.unchecked:
            self.unchecked = False
            stats.pivot_checks += 1
            _check_pivots(lu, perm if self.lu_is_permuted else None, weights)  # raises if singular
        permuted, checked = self.lu_is_permuted, []

        def solve(b: NDArray) -> NDArray:
            if permuted:
                x = np.empty_like(b)
                x[perm] = lu.solve(np.ascontiguousarray(b[perm]))
            else:
                x = lu.solve(b)
            if not checked and (np.abs(x).max(initial=0.0) * scale
                                > PIVOT_CHECK_GROWTH * np.abs(b).max(initial=0.0)):
                stats.pivot_checks += 1
                _check_pivots(lu, perm if permuted else None, weights)  # raises if singular
                checked.append(True)
            return x
        return solve

    def release(self) -> None:
        self.lu = None

    def release_factor(self) -> None:
        """Nothing: a SuperLU or static-LU factor belongs to the Factorization that solves
        with it, which stays valid after later factorizations."""


class _StaticLUBackend(_SuperLUBackend):
    """The static LU (:mod:`static_lu`) on SuperLU's ordering; SuperLU factors the first
    matrix of a pattern (the analysis), patterns without a full diagonal, and any matrix whose
    pivots the static LU rejects (zero, non-finite, below DIAG_PIVOT_THRESH of its column,
    or below PIVOT_RTOL of the largest: SuperLU then decides about singularity as before)."""

    def __init__(self, pattern: _Pattern, symmetric: bool, stats: SolverStats) -> None:
        super().__init__(pattern, symmetric, stats)
        self.symbolic: static_lu.StaticSymbolic | None = None
        self.usable = True  # False: the pattern is left to SuperLU
        self.fallbacks_in_a_row = 0
        self.static: static_lu.StaticFactor | None = None  # the current factor, if static

    def factor(self, data: NDArray) -> None:
        self.static = None
        if self.perm is None:  # first matrix of the pattern: SuperLU's ordering, then ours
            super().factor(data)
            p = self.pattern
            self.symbolic = static_lu.analyse(p.indptr, p.indices, self.perm)
            self.usable = self.symbolic is not None
            return
        if self.usable:
            self.static = static_lu.factorize(self.symbolic, data, DIAG_PIVOT_THRESH,
                                              PIVOT_RTOL)
        if self.static is not None:
            self.stats.factorizations += 1
            self.fallbacks_in_a_row = 0
            return
        if self.usable:
            self.stats.fallbacks += 1
            self.fallbacks_in_a_row += 1
            self.usable = self.fallbacks_in_a_row < MAX_CONSECUTIVE_FALLBACKS
        super().factor(data)
        self.unchecked = True  # a rejected pivot, or a pattern left to SuperLU: maybe singular

    def solver(self):
        return super().solver() if self.static is None else self.static.solve

    def release(self) -> None:
        super().release()
        self.static = None


def _check_pivots(lu: spla.SuperLU, perm: NDArray | None = None,
                  weights: NDArray | None = None) -> None:
    """Raise for a factor with tiny pivots. ``perm``: the factor is of A[perm][:, perm].

    ``weights`` (``_Pattern.column_weights``, in the factored matrix's column order): the
    pivots of border columns are read times their weight, i.e. as the pivots of A W, the
    multipliers rescaled to the stiffness (an LU with partial pivoting is the same up to that
    column scale, so the solve needs no change). Unweighed, a multiplier pivot is O(L_c)
    (traction unknowns, rows in force units) against the stiffness's O(E): steel in SI units
    (E = 2e11) was called singular at its first Lagrange contact step (tester B, session 41).
    The largest pivot is taken over the other columns (the stiffness's), which at a small
    stress unit no longer lets the multipliers' O(L_c) set the bar for the stiffness."""
    d = np.abs(lu.U.diagonal())
    largest = d.max(initial=0.0)
    if weights is not None:
        weights = weights[np.argsort(lu.perm_c)]  # U's column k is the factor's perm_c^-1[k]
        border = ~np.isnan(weights)
        if (~border).any():
            largest = d[~border].max()
        d = d * np.where(border, weights, 1.0)
    small = np.flatnonzero(~(d > PIVOT_RTOL * largest))  # NaN pivots too
    if small.size:  # pivots out of the floating-point range (_out_of_range), else a free motion
        scale = _out_of_range(d, largest)
        raise LinearSolverError(
            f"matrix is numerically singular: {small.size} pivot(s) below {PIVOT_RTOL:g} x "
            f"the largest {RANGE_CAUSE.format(scale) if scale else SINGULAR_CAUSES}",
            columns=None if scale else np.unique(np.concatenate(
                [_null_columns(lu, k, perm) for k in small[:4]])))


def _out_of_range(pivots: NDArray, largest: float) -> str:
    """What puts a singular factor's pivots out of the floating-point range ("" if nothing
    does: then a motion is free, :data:`SINGULAR_CAUSES`)."""
    if not (np.isfinite(pivots).all() and np.isfinite(largest)):
        return "the matrix holds inf or NaN"
    if largest > OUT_OF_RANGE_LARGEST:
        return f"pivots up to {largest:.3g}"
    tiny = pivots[pivots > 0.0]
    if tiny.size and tiny.min() < OUT_OF_RANGE_RATIO * largest:
        return f"pivots from {tiny.min():.3g} to {largest:.3g}"
    return ""


def _null_columns(lu: spla.SuperLU, k: int, perm: NDArray | None) -> NDArray[np.int64]:
    """The matrix's columns where the motion that its tiny pivot ``k`` leaves free is large
    (at least a tenth of its largest). U z = 0 with z_k = 1 and z zero beyond k (the rows
    above k back-substituted); since Pr A Pc = L U, A z[perm_c] = 0 (for a factor of
    A[perm][:, perm], the motion y has y[perm] = z[perm_c]). The pivot's own column is only
    where the elimination met that motion: two testers' free bodies (a cylinder free to turn,
    a block slipping on every pair) were named by their fully held partners'."""
    U = lu.U.tocsc()
    z = np.zeros(U.shape[0])
    z[k] = 1.0
    if k:
        z[:k] = spla.spsolve_triangular(U[:k, :k].tocsr(), -U[:k, [k]].toarray().ravel(),
                                        lower=False)
    y = np.empty_like(z)
    y[np.arange(z.size) if perm is None else perm] = np.abs(z[lu.perm_c])
    return np.flatnonzero(y >= 0.1 * y.max())


class _PardisoBackend:
    """MKL PARDISO through pypardiso's solver object (its location of mkl_rt, its ctypes
    prototypes, its handle and iparm): analysis (phase 11) once per pattern, numerical
    factorization (22) per matrix, solve (33). Symmetric matrices pass their upper triangle
    (mtype -2). The phases are driven with ``set_phase`` and the solver's ``_call_pardiso``:
    pypardiso's ``factorize`` always runs phase 12, i.e. the METIS ordering and symbolic
    factorization again with every matrix, which doubles a Newton factorization (module doc).
    Every call runs on :func:`pardiso_threads` MKL threads.

    Precision. With ``single``, PARDISO factors the values rounded to single precision (parameter
    28) and each solution is refined in double against the double matrix (:meth:`_refined`, to the
    caller's rtol, by default :data:`MIXED_RTOL`); a matrix the single factor cannot solve so
    (perturbed pivots, or no convergence in :data:`MAX_REFINEMENTS` sweeps) is factored again in
    double, as is every later one. Measured on Hertz refined 8x (123 178 unknowns, 2.2 M entries,
    one thread): a factorization 0.38 -> 0.25 s, the factor's memory 163 -> 81 MB, a solve 29 -> 26
    ms; the whole run 35.4 -> 29.4 s (ring 8x window 19.2 -> 17.3 s), with one refinement sweep in
    about a third of Hertz's solves and few of the ring's."""

    def __init__(self, pattern: _Pattern, symmetric: bool, stats: SolverStats,
                 single: bool = False) -> None:
        self.pattern, self.symmetric, self.stats = pattern, symmetric, stats
        self.single = single
        self.pardiso = _pardiso_handle(mtype=-2 if symmetric else 11)
        self.threads = pardiso_threads()
        for one_based, value in _pardiso_iparm(symmetric, self.threads, single).items():
            self.pardiso.set_iparm(one_based, value)
        indptr, indices = ((pattern.upper_indptr, pattern.upper_indices) if symmetric
                           else (pattern.indptr32, pattern.indices32))
        self.matrix = sp.csr_matrix((np.zeros(indices.size), indices, indptr),
                                    shape=(pattern.n, pattern.n))
        self.analysed = False
        self.factored = False  # PARDISO holds a numerical factor (L and U) of this handle
        #: the values the analysis was made with (its scaling and matching depend on them), for
        #: a restart checkpoint; and a restored run's, for its first analysis
        self.analysis_values: NDArray | None = None
        self.restored_values: NDArray | None = None
        #: the factored matrix in double (all entries), for a single factor's refinement: the
        #: caller's values themselves, not a copy (8 bytes an entry, beside the factor's 4)
        self.factored_matrix: sp.csr_matrix | None = None

    def factor(self, data: NDArray) -> None:
        self.factored_matrix = None  # the last matrix is not held beyond its factor
        values = _factor_values(data, self.pattern.upper if self.symmetric else None,
                                np.float32 if self.single else np.float64)
        if self.single:  # the caller's values, not a copy (LinearSolver.factorize)
            p = self.pattern
            self.factored_matrix = sp.csr_matrix((data, p.indices, p.indptr), shape=(p.n, p.n),
                                                 copy=False)
        fresh = not self.analysed
        if fresh:
            restored, self.restored_values = self.restored_values, None
            self._analyse(values if restored is None else restored)
        self.matrix.data = values
        self._call(22)
        self.factored = True
        self.stats.factorizations += 1
        if self._perturbed() and not fresh:
            # the reused analysis (its matching/scaling) may no longer suit the values: redo it
            self._analyse(values)
            self._call(22)
            self.stats.factorizations += 1
        if self._perturbed() and self.single:  # maybe single precision's doing
            self._to_double()
            return
        if self._perturbed():
            nonzero = np.abs(values[values != 0.0])
            scale = _out_of_range(nonzero, float(nonzero.max(initial=0.0)))
            raise LinearSolverError(
                f"matrix is numerically singular: PARDISO perturbed {self._perturbed()} "
                f"pivot(s) {RANGE_CAUSE.format(scale) if scale else SINGULAR_CAUSES}")

    def _perturbed(self) -> int:
        return int(self.pardiso.get_iparm(14))  # perturbed pivots of the last factorization

    def _analyse(self, values: NDArray) -> None:
        """Phase 11: the ordering and symbolic factorization, and the scaling and weighted
        matching, which depend on the values. So the values are kept: a restarted run that
        analysed its own first matrix instead factored with another scaling, and its
        history differed in the last bits (the ring refined 4x on one thread: 1 restart in
        3 before, 1 in 19 after)."""
        self.matrix.data = values
        self._call(11)
        self.analysis_values = np.array(values, copy=True)
        self.analysed = True
        self.stats.analyses += 1

    def solver(self):
        return self.solve

    def solve(self, b: NDArray, rtol: float = MIXED_RTOL) -> NDArray:
        """x with |b - A x| <= rtol |b| per column (from a double factor: at round-off)."""
        if not self.single:
            return self._call(33, np.asfortranarray(b))
        if not np.all(np.isfinite(b)):  # no reason to leave single: reported as not finite
            return self._single_solve(b).astype(float)
        x = self._refined(b, rtol)
        if x is None:
            self._to_double()
            return self._call(33, np.asfortranarray(b))
        return x

    def _single_solve(self, b: NDArray) -> NDArray:
        """The single factor's solution, in single precision (added to a double x as it is:
        the conversion is exact, and no double copy is made)."""
        return self._call(33, np.asfortranarray(b, dtype=np.float32))

    def _refined(self, b: NDArray, rtol: float) -> NDArray | None:
        """x with |b - A x| <= rtol |b| in each column, from the single factor and refinement
        sweeps x += A_single^-1 (b - A x) with the residual in double (a matvec, a fifth of a
        solve), each sweep over the columns still above their limit only (a sensitivity's
        64 columns had a sweep of all for a few); None if :data:`MAX_REFINEMENTS` sweeps do
        not get there. Besides b and x, a sweep holds about one array of b's size at a time:
        the residual is formed in place, its norms a few columns at a time, and it is let go
        once rounded for the solve (the ring refined 8x held ~6 arrays of 37 columns of
        46,530 unknowns here, its run's peak memory; issue 18)."""
        A = self.factored_matrix
        x = self._single_solve(b).astype(float)
        limit = rtol * _column_norms(b)
        for sweep in range(MAX_REFINEMENTS + 1):
            r = A @ x
            np.subtract(b, r, out=r)
            above = ~(_column_norms(r) <= limit)  # True for NaN: then in double
            if not above.any():
                return x
            if sweep < MAX_REFINEMENTS:
                every = b.ndim == 1 or above.all()
                r = np.asfortranarray(r if every else r[:, above], dtype=np.float32)
                if every:
                    x += self._single_solve(r)
                else:
                    x[:, above] += self._single_solve(r)
                self.stats.refinements += 1
        return None

    def _to_double(self) -> None:
        """Factor the current matrix again in double, with a new analysis (the precision is
        fixed at the analysis), and keep double for this mode from now on."""
        data = self.factored_matrix.data
        self.single, self.factored_matrix = False, None
        with _mkl_controller().limit(limits=self.threads):
            self.pardiso.free_memory(everything=True)
        self.pardiso.pt[:] = 0  # a fresh handle, as before PARDISO's first call
        self.pardiso.set_iparm(28, 0)
        self.analysed = self.factored = False
        self.stats.double_fallbacks += 1
        self.factor(data)

    def _call(self, phase: int, b: NDArray | None = None) -> NDArray:
        self.pardiso.set_phase(phase)
        try:
            with _mkl_controller().limit(limits=self.threads):
                return self.pardiso._call_pardiso(self.matrix, np.zeros(1) if b is None else b)
        except Exception as err:  # pypardiso's PyPardisoError (an error code)
            code = getattr(err, "value", None)
            if code is None:
                raise
            what = _PARDISO_ERRORS.get(code, "unknown error")
            raise LinearSolverError(f"PARDISO failed in phase {phase} with error {code}: "
                                    f"{what}") from None

    def release_factor(self) -> None:
        """Free the numerical factor (phase 0) and keep the analysis, which the next
        factorization in this mode (phase 22) reuses with the same result. Called when the
        solver factors in the other symmetry mode: the ring refined 8x held its free-flight
        symmetric factor (48 MB) beside the contact steps' general one (82 MB)."""
        if self.factored:
            self.factored = False
            with _mkl_controller().limit(limits=self.threads):
                self.pardiso.free_memory(everything=False)  # L and U only (phase 0)
            self.factored_matrix = None

    def release(self) -> None:
        if self.pardiso is None:
            return
        self.factored = False
        self.analysis_values = self.factored_matrix = None
        if self.analysed:
            self.analysed = False
            with _mkl_controller().limit(limits=self.threads):
                self.pardiso.free_memory(everything=True)  # all of PARDISO's memory (phase -1)
        _IDLE_PARDISO.append(self.pardiso)
        self.pardiso = None


#: entries :meth:`_Pattern.is_symmetric` and :func:`_factor_values` work on at a time
VALUE_CHUNK = 1 << 16


def _factor_values(data: NDArray, kept: NDArray | None, dtype: type) -> NDArray:
    """``data[kept]`` (all of data if None) in ``dtype``, a chunk at a time: no double
    temporary of the entries kept (half the matrix's size in symmetric mode) beside the
    caller's matrix and the previous one (issue 18, memory). The caller's own array when it
    is already all in ``dtype``."""
    if kept is None and data.dtype == dtype and data.flags.c_contiguous:
        return data
    size = data.size if kept is None else kept.size
    values = np.empty(size, dtype=dtype)
    for start in range(0, size, VALUE_CHUNK):
        stop = min(start + VALUE_CHUNK, size)
        values[start:stop] = data[start:stop] if kept is None else data[kept[start:stop]]
    return values


#: :func:`_column_norms` squares this many columns (F order) or rows (C order) at a time
NORM_COLUMNS = 8
NORM_ROWS = 4096


def _column_norms(r: NDArray) -> NDArray:
    """``np.linalg.norm(r, axis=0)``, the same bits, with a temporary of a few columns or rows
    (the norm squares all of r at once, and makes a conjugate copy of it first). NumPy sums
    each column of an F-order block pairwise, so F-order r goes by blocks of columns, none
    one column wide (a lone column of a C-order block is summed pairwise too); it sums the
    rows of a C-order array one after the other, so C-order r goes by blocks of rows, each
    carrying the sums so far in its first row."""
    if r.ndim == 1 or r.shape[1] <= 1 or r.shape[0] == 0:
        return np.linalg.norm(r, axis=0)
    if r.flags.f_contiguous and r.shape[1] > NORM_COLUMNS + 1:
        starts = list(range(0, r.shape[1], NORM_COLUMNS))
        if r.shape[1] - starts[-1] == 1:
            starts.pop()  # the last column joins the block before it
        ends = starts[1:] + [r.shape[1]]
        return np.concatenate([np.linalg.norm(r[:, j:k], axis=0)
                               for j, k in zip(starts, ends, strict=True)])
    if r.flags.c_contiguous and r.shape[0] > NORM_ROWS:
        sums = None
        for start in range(0, r.shape[0], NORM_ROWS):
            squares = np.square(r[start:start + NORM_ROWS])
            if sums is not None:
                squares[0] += sums
            sums = np.add.reduce(squares, axis=0)
        return np.sqrt(sums)
    return np.linalg.norm(r, axis=0)


#: PyPardisoSolver objects whose PARDISO memory was released, for the next pattern or solver:
#: building one makes pypardiso search sys.prefix recursively for mkl_rt where
#: PYPARDISO_MKL_RT is not set (:func:`_point_pypardiso_at_mkl_rt` sets it for the mkl wheel;
#: an MKL from elsewhere is searched for), 0.5-1.2 s per new pattern at ring k = 8 before
#: either (issue 18: 8.6 s of an 18-step run with 6 analyses).
_IDLE_PARDISO: list = []


def _pardiso_handle(mtype: int):
    """A PyPardisoSolver for matrices of type ``mtype`` with a fresh handle (pt all zero, as
    PARDISO requires before its first call), reused from :data:`_IDLE_PARDISO` if one waits."""
    if _IDLE_PARDISO:
        solver = _IDLE_PARDISO.pop()
    else:
        from pypardiso import PyPardisoSolver  # pardiso_available() found it

        solver = PyPardisoSolver()
    solver.pt[:] = 0
    solver.iparm[:] = 0
    solver.set_matrix_type(mtype)
    solver.set_phase(13)
    return solver


def _pardiso_iparm(symmetric: bool, threads: int, single: bool = False) -> dict[int, int]:
    """PARDISO parameters by their 1-based number, as pypardiso's ``set_iparm`` and the MKL
    manual count them (pypardiso passes one-based indices itself).

    On several threads PARDISO's answer changes from call to call unless its conditional
    numerical reproducibility mode is on (parameter 34 = the thread count): 2 distinct
    solutions in 40 factorizations of the same 45 000-unknown matrix on 2 threads without it,
    1 with it, for +0-8 % factorization time. So it is on; it does not make a whole run
    repeat itself bit for bit, though (see :func:`pardiso_threads`)."""
    return {
        1: 1,  # use the values below, not the defaults
        2: 2,  # METIS nested-dissection ordering
        10: 8 if symmetric else 13,  # pivot perturbation 1e-8 / 1e-13 (the MKL defaults)
        11: 1,  # scaling ...
        13: 1,  # ... and weighted matching: robust for indefinite / unsymmetric tangents
        21: 1,  # Bunch-Kaufman pivoting (symmetric indefinite)
        28: 1 if single else 0,  # the values, factor and right-hand sides in single precision
        34: threads if threads > 1 else 0,  # reproducible results on `threads` threads
    }


_PARDISO_ERRORS = {
    -1: "input inconsistent", -2: "not enough memory", -3: "reordering problem",
    -4: "zero pivot (numerically singular matrix)", -5: "unclassified internal error",
    -6: "reordering failed", -7: "diagonal matrix is singular", -8: "32-bit integer overflow",
}


_BACKEND_CLASSES = {"superlu": _SuperLUBackend, "static": _StaticLUBackend}


# Pinned when ntncontact is imported, not only when PARDISO is first asked for: a script may
# load mkl_rt itself (pypardiso does at its import) after importing ntncontact, or before, and
# the first MKL call (threadpoolctl's look at it when a run starts) fixes the layer for good.
_pin_mkl_threading_layer()
if "pypardiso" in sys.modules:  # loaded before the pin: select the layer in it (see above)
    _select_threading_layer(sys.modules["pypardiso"])
