"""The mass matrix of a model whose ALE bodies change their particles at the nodes.

An ALE move gives some nodes new material positions X, which changes the element masses
(5.8, integrated over each element's X-image) of the cells around them and nothing else.
:class:`MovingMass` keeps the mass in the stiffness pattern (so 4/dt^2 M + K is a sum of data
arrays), rebuilds only the element masses of cells whose nodes moved, and sums them in the same
order as a full rebuild (the result is the same to the last bit).
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from numpy.typing import NDArray

from ..fem.assembly import Assembler


class MovingMass:
    """Dof mass of all elements; ``moving_cells`` (those of the ALE bodies) may change."""

    def __init__(self, assembler: Assembler, X: NDArray, lumped: bool,
                 moving_cells: NDArray) -> None:
        self.assembler, self.lumped = assembler, lumped
        self.cells = np.asarray(moving_cells, dtype=np.int64)
        fixed = np.setdiff1d(np.arange(len(assembler.cells)), self.cells)
        self._fixed_data = assembler.dof_mass_data(assembler.element_masses(X, fixed), lumped,
                                                   fixed)
        self._cell_nodes = assembler.cells[self.cells]
        self._nodes = np.unique(self._cell_nodes)
        self._X = X[self._nodes].copy()
        self._element = assembler.element_masses(X, self.cells)
        self._matrix = self._build()

    def matrix(self, X: NDArray) -> sp.csr_matrix:
        """The mass for material positions X (n_nodes, 2); reused while they are unchanged."""
        X_now = X[self._nodes]
        moved = np.any(X_now != self._X, axis=1)
        if not moved.any():
            return self._matrix
        changed = np.zeros(self.assembler.n_nodes, dtype=bool)
        changed[self._nodes[moved]] = True
        cells = np.flatnonzero(changed[self._cell_nodes].any(axis=1))
        self._element[cells] = self.assembler.element_masses(X, self.cells[cells])
        self._X = X_now.copy()
        self._matrix = self._build()
        return self._matrix

    def _build(self) -> sp.csr_matrix:
        moving = self.assembler.dof_mass_data(self._element, self.lumped, self.cells)
        return self.assembler.pattern_matrix(self._fixed_data + moving)
