"""Sparse LU on a fixed sparsity pattern without row interchanges, compiled with Numba.

Why: the contact problems of the examples are small (ring impact: 890 unknowns, 13 860
entries) and keep one sparsity pattern over hundreds of factorizations (``fem/sparse.py``
keeps a union pattern). SuperLU redoes its symbolic work (column etree, supernode and panel
detection, memory expansion) at every ``splu`` call, which for such matrices costs as much as
the arithmetic (~325 000 multiply-adds): ``gstrf`` takes ~1.1 ms and ``splu`` 1.2-1.7 ms. Here
the fill pattern of L and U, and the map from the CSR data of A to the permuted matrix, are
computed once per pattern; a factorization is then one left-looking sweep over that pattern and
a solve two triangular sweeps, with no allocation but the factor's value arrays. Measured on
the ring impact's tangent through ``LinearSolver`` (``benchmarks/static_lu.py``, noisy 2-core
machine): factorization 0.37-0.61 ms against SuperLU's 1.03-1.22 ms (the compiled sweep
alone 0.31 ms), solve 0.03-0.06 ms against 0.10-0.13 ms; the whole ring impact's time loop
3.85 -> 3.34 s and 5.37 -> 4.38 s (minima of interleaved runs), same results to round-off.
Details in ``benchmarks/README.md``.

- Ordering: the symmetric permutation ``perm`` (the matrix factored is ``A[perm][:, perm]``) is
  supplied by the caller; ``LinearSolver`` takes SuperLU's MMD(A^T + A) column ordering from the
  first factorization of a pattern, the one its SuperLU path reuses, so both paths eliminate
  in the same order with the same pivots and agree to round-off.
- Fill: the pattern of S = Ap + Ap^T + I (structurally unsymmetric patterns are symmetrized;
  the absent entries are zeros) gives L's rows by the elimination tree (``ereach``), and
  pattern(U) = pattern(L)^T. Without row interchanges this holds every possible entry.
- Pivots: column k is accepted when |u_kk| >= ``threshold`` max_i>=k |a_ik^(k)| over its
  updated column, i.e. exactly when SuperLU with ``diag_pivot_thresh = threshold`` keeps the
  diagonal; otherwise (and for a zero, non-finite, or relatively tiny pivot: see
  ``singular_rtol``) :func:`factorize` returns None and the caller falls back to a pivoting LU.
  With the threshold, every multiplier is bounded by 1/threshold as in threshold partial
  pivoting.

The kernels are plain functions of arrays (float64 values, right-hand sides as C-contiguous
(n, m) arrays), so each has one compiled signature, cached on disk. The numerical kernels
index with uint64 arrays: Numba then drops the test for negative (wrap-around) indices on every
gather and scatter, which made the factorization 1.6x faster (0.50 -> 0.31 ms on the ring
tangent) with bit-identical results.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from numpy.typing import NDArray

from ..jit import njit

__all__ = ["StaticFactor", "StaticSymbolic", "analyse", "factorize", "permuted_csc"]


@dataclass(frozen=True)
class StaticSymbolic:
    """The pattern part of an LU of ``A[perm][:, perm]``, shared by all its factors.

    ``a_*``: CSC of the permuted matrix, each entry's position in the CSR data of A (gather);
    ``l_*``: strictly lower L by columns; ``u_*``: strictly upper U by columns; rows ascending.
    All index arrays are uint64 (module doc).
    """

    n: int
    perm: NDArray[np.uint64]
    a_ptr: NDArray[np.uint64]
    a_rows: NDArray[np.uint64]
    a_gather: NDArray[np.uint64]
    l_ptr: NDArray[np.uint64]
    l_rows: NDArray[np.uint64]
    u_ptr: NDArray[np.uint64]
    u_rows: NDArray[np.uint64]


@dataclass(frozen=True)
class StaticFactor:
    """L (unit lower), U of one matrix: own value arrays, so it survives later factorizations."""

    symbolic: StaticSymbolic
    l_vals: NDArray[np.float64]
    u_vals: NDArray[np.float64]
    diag: NDArray[np.float64]

    def solve(self, b: NDArray) -> NDArray:
        """x with A x = b, for b of shape (n,) or (n, k)."""
        s = self.symbolic
        rhs = np.ascontiguousarray(b, dtype=np.float64)
        x = _solve_kernel(rhs.reshape(s.n, -1), s.perm, s.l_ptr, s.l_rows, self.l_vals,
                          s.u_ptr, s.u_rows, self.u_vals, self.diag)
        return x.reshape(rhs.shape)


def analyse(indptr: NDArray, indices: NDArray, perm: NDArray) -> StaticSymbolic | None:
    """Symbolic LU of the CSR pattern (indptr, indices) permuted symmetrically by ``perm``;
    None when a diagonal entry is structurally absent (saddle-point blocks: they need
    pivoting, so such patterns are left to a pivoting LU)."""
    n = len(indptr) - 1
    perm = np.asarray(perm, dtype=np.int64)
    a_ptr, a_rows, gather = permuted_csc(indptr, indices, perm)
    ones = sp.csc_matrix((np.ones(a_rows.size), a_rows, a_ptr), shape=(n, n))
    if np.any(ones.diagonal() == 0):
        return None
    sym = sp.csc_matrix(ones + ones.T)  # symmetric pattern with the diagonal, indices sorted
    sym.sort_indices()
    s_ptr, s_rows = sym.indptr.astype(np.int64), sym.indices.astype(np.int64)
    parent = _etree(s_ptr, s_rows)
    u_ptr, u_rows = _upper_pattern(s_ptr, s_rows, parent)
    # pattern(L) = pattern(U)^T: U's CSC read as CSR is U^T, whose CSC has its rows ascending
    lower = sp.csr_matrix((np.ones(u_rows.size), u_rows, u_ptr), shape=(n, n)).tocsc()
    l_ptr, l_rows = lower.indptr, lower.indices
    index_arrays = (perm, a_ptr, a_rows, gather, l_ptr, l_rows, u_ptr, u_rows)
    return StaticSymbolic(n, *(a.astype(np.uint64) for a in index_arrays))


def permuted_csc(indptr: NDArray, indices: NDArray, perm: NDArray
                 ) -> tuple[NDArray, NDArray, NDArray[np.int64]]:
    """CSC structure (indptr, row indices sorted) of A[perm][:, perm] for the CSR pattern
    (indptr, indices) of A, and per entry its position in A's CSR data (the gather map)."""
    n = len(indptr) - 1
    # positions + 1 as values: the permuted CSC keeps, per entry, where it is in A's data
    tracer = sp.csr_matrix((np.arange(1.0, len(indices) + 1), indices, indptr), shape=(n, n))
    permuted = sp.csc_matrix(tracer[perm][:, perm])
    permuted.sort_indices()
    return permuted.indptr, permuted.indices, permuted.data.astype(np.int64) - 1


def factorize(symbolic: StaticSymbolic, data: NDArray, threshold: float,
              singular_rtol: float) -> StaticFactor | None:
    """LU of the matrix with CSR values ``data`` on the analysed pattern, or None if a pivot
    fails the threshold test, is zero or not finite, or some pivot is at most
    ``singular_rtol`` times the largest (numerically singular: leave the verdict to the
    pivoting LU)."""
    s = symbolic
    l_vals = np.empty(len(s.l_rows))
    u_vals = np.empty(len(s.u_rows))
    diag = np.empty(s.n)
    ok = _factor_kernel(np.ascontiguousarray(data, dtype=np.float64), s.a_ptr, s.a_rows,
                        s.a_gather, s.l_ptr, s.l_rows, s.u_ptr, s.u_rows, l_vals, u_vals, diag,
                        threshold, singular_rtol)
    return StaticFactor(s, l_vals, u_vals, diag) if ok else None


# ---------------------------------------------------------------- symbolic kernels


@njit(cache=True)
def _etree(s_ptr: NDArray, s_rows: NDArray) -> NDArray:
    """Elimination tree of a symmetric CSC pattern (Liu's algorithm, path compression)."""
    n = len(s_ptr) - 1
    parent = np.full(n, -1, dtype=np.int64)
    ancestor = np.full(n, -1, dtype=np.int64)
    for k in range(n):
        for p in range(s_ptr[k], s_ptr[k + 1]):
            i = s_rows[p]
            while i != -1 and i < k:  # climb from i to the root of its subtree, compressing
                nxt = ancestor[i]
                ancestor[i] = k
                if nxt == -1:
                    parent[i] = k
                i = nxt
    return parent


@njit(cache=True)
def _upper_pattern(s_ptr: NDArray, s_rows: NDArray, parent: NDArray
                   ) -> tuple[NDArray, NDArray]:
    """Strictly upper pattern of U by columns: column k holds the rows j < k reached from the
    entries S[j, k] by climbing the elimination tree up to k (row k of L, transposed)."""
    n = len(s_ptr) - 1
    mark = np.full(n, -1, dtype=np.int64)
    counts = np.zeros(n + 1, dtype=np.int64)
    rows = np.empty(16 * n + 16, dtype=np.int64)
    size = 0
    for k in range(n):
        mark[k] = k
        start = size
        for p in range(s_ptr[k], s_ptr[k + 1]):
            j = s_rows[p]
            while j < k and mark[j] != k:
                mark[j] = k
                if size == len(rows):
                    grown = np.empty(2 * len(rows), dtype=np.int64)
                    grown[:size] = rows[:size]
                    rows = grown
                rows[size] = j
                size += 1
                j = parent[j]
        rows[start:size] = np.sort(rows[start:size])  # ascending: a topological order
        counts[k + 1] = size
    return counts, rows[:size].copy()


# ---------------------------------------------------------------- numerical kernels


@njit(cache=True)
def _factor_kernel(data, a_ptr, a_rows, a_gather, l_ptr, l_rows, u_ptr, u_rows,
                   l_vals, u_vals, diag, threshold, singular_rtol) -> bool:
    """Left-looking LU, column by column: scatter column k of A, apply the earlier columns
    of L that U[:, k] selects, test the pivot, scale into L. False as soon as a pivot fails."""
    n = len(a_ptr) - 1
    x = np.zeros(n)  # dense work column; only the pattern's entries are touched and reset
    largest = 0.0
    for k in range(n):
        for p in range(a_ptr[k], a_ptr[k + 1]):
            x[a_rows[p]] = data[a_gather[p]]
        for q in range(u_ptr[k], u_ptr[k + 1]):
            j = u_rows[q]
            ujk = x[j]
            x[j] = 0.0
            u_vals[q] = ujk
            for r in range(l_ptr[j], l_ptr[j + 1]):
                x[l_rows[r]] -= l_vals[r] * ujk
        pivot = x[k]
        x[k] = 0.0
        column_max = abs(pivot)
        for r in range(l_ptr[k], l_ptr[k + 1]):
            column_max = max(column_max, abs(x[l_rows[r]]))
        if not (np.isfinite(pivot) and pivot != 0.0 and abs(pivot) >= threshold * column_max):
            x[:] = 0.0
            return False
        inverse = 1.0 / pivot  # SuperLU scales its L column by the reciprocal too
        for r in range(l_ptr[k], l_ptr[k + 1]):
            i = l_rows[r]
            l_vals[r] = x[i] * inverse
            x[i] = 0.0
        diag[k] = pivot
        largest = max(largest, abs(pivot))
    smallest = np.min(np.abs(diag)) if n else 0.0
    return smallest > singular_rtol * largest


@njit(cache=True)
def _solve_kernel(b, perm, l_ptr, l_rows, l_vals, u_ptr, u_rows, u_vals, diag):
    """x with A x = b for b (n, m): forward and backward sweeps on A[perm][:, perm], one
    right-hand side at a time in a contiguous work vector (the sweeps' inner loops stay
    scalar gathers; m is 1 in Newton steps)."""
    n, m = b.shape
    x = np.empty((n, m))
    y = np.empty(n)
    for c in range(m):
        for i in range(n):
            y[i] = b[perm[i], c]
        for j in range(n):  # L y = b[perm], L unit lower by columns
            yj = y[j]
            for r in range(l_ptr[j], l_ptr[j + 1]):
                y[l_rows[r]] -= l_vals[r] * yj
        for j in range(n - 1, -1, -1):  # U y = y, U by columns, last column first
            yj = y[j] / diag[j]
            y[j] = yj
            for q in range(u_ptr[j], u_ptr[j + 1]):
                y[u_rows[q]] -= u_vals[q] * yj
        for i in range(n):
            x[perm[i], c] = y[i]
    return x
