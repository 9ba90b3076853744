"""Global assembly over all elements of all bodies with a CSR pattern computed once."""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np
import scipy.sparse as sp
from numpy.typing import NDArray

from ..materials.models import MaterialKind
from .kernels_numba import NumbaAssembly
from .q4 import element_mass
from .sparse import row_starts


def element_dofs(cells: NDArray) -> NDArray:
    """Global dofs of each element in (a, i) order: 2 * node + i, shape (ne, 8)."""
    return (2 * cells[:, :, None] + np.arange(2)).reshape(len(cells), 8)


@dataclass(frozen=True)
class CsrPattern:
    """Sparsity pattern of element matrices and where each element entry lands in ``data``."""

    indptr: NDArray
    indices: NDArray
    #: (ne * k * k,) position of each element entry in the CSR data array; int32 while the
    #: positions fit (half of int64's 512 bytes an element for Q4 dofs; issue 18, memory)
    entry_map: NDArray
    shape: tuple[int, int]

    @classmethod
    def from_element_dofs(cls, edofs: NDArray, ndof: int) -> CsrPattern:
        k = edofs.shape[1]
        rows = np.repeat(edofs, k, axis=1).ravel()
        cols = np.tile(edofs, (1, k)).ravel()
        keys = rows.astype(np.int64) * ndof + cols
        unique, entry_map = np.unique(keys, return_inverse=True)
        position = np.int32 if unique.size < 2**31 else np.int64
        return cls(row_starts(unique, (ndof, ndof)), (unique % ndof).astype(np.int32),
                   entry_map.astype(position), (ndof, ndof))

    def of_dofs(self, cells: NDArray) -> CsrPattern:
        """The pattern of the elements' dofs (``element_dofs(cells)``, 2 a + i) from this
        pattern of their nodes (``from_element_dofs(cells, n_nodes)``), the same arrays as
        ``from_element_dofs(element_dofs(cells), 2 n_nodes)`` without its sort of 64 keys an
        element: node a's row of neighbours b becomes rows 2a and 2a + 1, each 2b, 2b + 1 for
        every b (a 250 x 250 mesh: 0.95 s by the sort, 0.04 s so)."""
        n = self.shape[0]
        start = self.indptr[:-1].astype(np.int64)
        degree = np.diff(self.indptr).astype(np.int64)
        indptr = np.empty(2 * n + 1, dtype=np.int64)
        indptr[0:-1:2], indptr[1::2] = 4 * start, 4 * start + 2 * degree
        indptr[-1] = 4 * self.indices.size
        row = np.repeat(np.arange(n), degree)  # the node row of each node entry
        # node entry g (place g - start[a] of row a) -> 2 start[a] + 2 g in dof row 2a
        first = 2 * start[row] + 2 * np.arange(self.indices.size, dtype=np.int64)
        indices = np.empty(4 * self.indices.size, dtype=self.indices.dtype)
        for i in range(2):  # row 2a + i (2 degree[a] further on): 2b then 2b + 1
            at = first + 2 * i * degree[row]
            indices[at], indices[at + 1] = 2 * self.indices, 2 * self.indices + 1
        # node entry (e, alpha, beta) at place m of row a -> dof entry (e, 2 alpha + i,
        # 2 beta + j) at 2 start[a] + 2 i degree[a] + 2 m + j
        node_map = self.entry_map.reshape(-1, 4, 1, 4, 1).astype(np.int64)
        a = np.asarray(cells, dtype=np.int64)[:, :, None, None, None]
        i = np.arange(2).reshape(1, 1, 2, 1, 1)
        j = np.arange(2).reshape(1, 1, 1, 1, 2)
        entry = 2 * start[a] + 2 * i * degree[a] + 2 * node_map + j
        position = np.int32 if indices.size < 2**31 else np.int64
        return CsrPattern(indptr, indices, entry.reshape(-1).astype(position),
                          (2 * n, 2 * n))

    @property
    def nnz(self) -> int:
        return int(self.indices.size)

    def matrix(self, element_matrices: NDArray) -> sp.csr_matrix:
        """Sum element matrices (ne, k, k) into a CSR matrix with this pattern."""
        data = np.bincount(self.entry_map, weights=element_matrices.ravel(), minlength=self.nnz)
        return sp.csr_matrix((data, self.indices, self.indptr), shape=self.shape)


@dataclass(frozen=True)
class MaterialGroup:
    """Elements sharing one constitutive model."""

    kind: MaterialKind
    elements: NDArray  # element indices into the global cell array


class Assembler:
    """Assembles internal force, tangent and mass for a fixed topology.

    ``cells`` are global node indices (bodies stacked), ``lam``/``mu``/``rho`` per element.
    """

    def __init__(
        self,
        cells: NDArray,
        n_nodes: int,
        groups: list[MaterialGroup],
        lam: NDArray,
        mu: NDArray,
        rho: NDArray,
    ) -> None:
        self.cells = np.asarray(cells, dtype=np.int64)
        self.n_nodes = int(n_nodes)
        self.ndof = 2 * self.n_nodes
        self.groups = groups
        self.lam, self.mu, self.rho = (np.asarray(a, dtype=float) for a in (lam, mu, rho))
        self.edofs = element_dofs(self.cells)
        self.node_pattern = CsrPattern.from_element_dofs(self.cells, self.n_nodes)
        self.pattern = self.node_pattern.of_dofs(self.cells)

    def internal(
        self, X: NDArray, *, d: NDArray, need_tangent: bool = True,
        d_start: NDArray | None = None, spare: int = 0,
    ) -> tuple[NDArray, sp.csr_matrix | None, float]:
        """Internal force vector, tangent stiffness (CSR) and total strain energy at the
        nodal displacements ``d`` from the reference positions ``X`` (x = X + d), from the
        compiled kernel adding straight into the CSR data.

        The displacement, not x, is the argument: F = I + Grad d keeps the stresses' round-off
        relative to the stresses (from x it would be eps E L / h, L the size of x). Keyword
        only, so that no caller passes positions by mistake.
        ``d_start`` = d_n with d = d_{n+1/2}: the energy-momentum scheme's force of the
        Neo-Hookean elements and its tangent with respect to d.
        ``spare``: the tangent's data are the head of an array this many entries longer
        (``fem.sparse.TripletUnion`` spreads them into its pattern there, in place)."""
        X = np.ascontiguousarray(X, dtype=float)
        d = np.ascontiguousarray(np.reshape(d, (-1, 2)), dtype=float)
        if d_start is not None:
            d_start = np.reshape(d_start, (-1, 2))
        force = np.zeros(self.ndof)
        nnz = self.pattern.nnz
        data = np.zeros(nnz + spare)[:nnz] if need_tangent else None
        energy = 0.0
        for kernel in self._numba_groups:
            energy += kernel.add(X, d, self.lam, self.mu, self.pattern.entry_map, force, data,
                                 d_start)
        if data is None:
            return force, None, energy
        return force, self.pattern_matrix(data), energy

    @cached_property
    def _numba_groups(self) -> list:
        return [NumbaAssembly(g.kind, self.cells, g.elements) for g in self.groups]

    @cached_property
    def _csr_indptr(self) -> NDArray:
        """``pattern.indptr`` in the index type of ``pattern.indices``: SciPy then builds the
        CSR matrix without converting it (int64 indptr + int32 indices: 33 us, same: 14 us on
        the ring's 890 rows). The matrix gets the same arrays either way."""
        return self.pattern.indptr.astype(self.pattern.indices.dtype)

    def nodal_mass(self, X: NDArray, lumped: bool) -> sp.csr_matrix:
        """Scalar (per node) mass matrix: consistent (5.8) or lumped by row sums (5.13)."""
        me = element_mass(X[self.cells], self.rho)
        if lumped:
            diag = np.bincount(self.cells.ravel(), weights=me.sum(axis=2).ravel(),
                               minlength=self.n_nodes)
            return sp.diags(diag, format="csr")
        return self.node_pattern.matrix(me)

    def mass(self, X: NDArray, lumped: bool) -> sp.csr_matrix:
        """Mass matrix on dofs: the scalar mass repeated for x and y."""
        return sp.kron(self.nodal_mass(X, lumped), sp.eye(2), format="csr")

    def element_masses(self, X: NDArray, elements: NDArray) -> NDArray:
        """Consistent scalar element masses (ne, 4, 4) of ``elements``."""
        return element_mass(X[self.cells[elements]], self.rho[elements])

    def dof_mass_data(self, element_masses: NDArray, lumped: bool,
                      elements: NDArray) -> NDArray:
        """The CSR data (stiffness pattern) of the dof mass of ``elements`` from their scalar
        element masses: ALE runs rebuild only their moving bodies' part."""
        me = element_masses
        if lumped:
            me = me.sum(axis=2)[:, :, None] * np.eye(4)
        blocks = np.zeros((len(me), 4, 2, 4, 2))
        blocks[:, :, 0, :, 0] = me
        blocks[:, :, 1, :, 1] = me
        entries = self.pattern.entry_map.reshape(len(self.cells), -1)[elements].ravel()
        return np.bincount(entries, weights=blocks.ravel(), minlength=self.pattern.nnz)

    def pattern_matrix(self, data: NDArray) -> sp.csr_matrix:
        """A CSR matrix with the stiffness pattern and these data."""
        p = self.pattern
        # a fresh indptr per matrix, as SciPy's conversion of the int64 one used to give
        return sp.csr_matrix((data, p.indices, self._csr_indptr.copy()), shape=p.shape)
