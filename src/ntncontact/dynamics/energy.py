"""The energy-conserving variant of report 5.5: one more multiplier lambda_E per step.

Unknowns d = d_{n+1/2}, the contact multipliers, and lambda_E. The mid-point equations are
bordered as in (5.30)/(5.34):

    R(d) + lambda_E (M a_{n+1/2}(d) + f_int(x_{n+1/2})) = 0,
    h_E(d) = E_{n+1}(d) - E_n = 0,

with E = 1/2 v.Mv + W the total (kinetic + strain) energy and E_{n+1} evaluated at
x_{n+1} = X + 2 d - d_n, v_{n+1} = 4 (d - d_n)/dt - v_n. The first line is
(1 + lambda_E)(M a + f_int) + f_contact - f_ext = 0: lambda_E rescales the contact impulse just
enough to conserve the energy exactly, and since contact forces come in equal and opposite pairs
linear and angular momentum stay conserved. The report writes E at n +- 1/2 and the linear K d;
we use the end-of-step energies and the nonlinear f_int so that the constraint is exact for
Neo-Hookean bodies (external loads are zero in the report's derivation; they are allowed here,
but then E_n is not conserved by the physics and the variant should not be used).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from numpy.typing import NDArray

from ..fem.assembly import Assembler
from .midpoint import inertia_factor, midpoint_acceleration


@dataclass
class EnergyConstraint:
    """A bordered-system constraint term (see ``problem.ConstraintTerm``) with one multiplier."""

    assembler: Assembler
    mass: sp.csr_matrix  # on dofs
    X: NDArray  # (n, 2) material positions at the nodes for this step
    d_n: NDArray  # (ndof,)
    v_n: NDArray  # (ndof,)
    dt: float
    energy_n: float
    lambda_start: float = 0.0

    size: int = 1

    @property
    def initial(self) -> NDArray:
        return np.array([self.lambda_start])

    def end_energy(self, d: NDArray) -> tuple[float, NDArray]:
        """E_{n+1}(d) and its gradient with respect to d = d_{n+1/2}."""
        v1 = 4.0 * (d - self.d_n) / self.dt - self.v_n  # 2 v_{n+1/2} - v_n
        x1 = self.X.ravel() + 2.0 * d - self.d_n
        f1, _, w1 = self.assembler.internal(self.X, x1.reshape(-1, 2), need_tangent=False)
        Mv1 = self.mass @ v1
        return 0.5 * float(v1 @ Mv1) + w1, (4.0 / self.dt) * Mv1 + 2.0 * f1

    def __call__(self, x_eval, v_eval, rate, x_start, lam):
        d = x_eval.ravel() - self.X.ravel()
        lam_e = float(lam[0])
        f_int, K, _ = self.assembler.internal(self.X, x_eval)
        inertia = self.mass @ midpoint_acceleration(d, self.d_n, self.v_n, self.dt)
        column = inertia + f_int  # d(force)/d(lambda_E)
        tangent = (lam_e * (K + inertia_factor(self.dt) * self.mass)).tocoo()
        energy, grad = self.end_energy(d)
        rows = np.flatnonzero(grad)
        cols = np.flatnonzero(column)
        return (
            lam_e * column,
            (tangent.row, tangent.col, tangent.data),
            np.array([energy - self.energy_n]),
            (np.zeros(rows.size, dtype=np.int64), rows, grad[rows]),
            (cols, np.zeros(cols.size, dtype=np.int64), column[cols]),
        )
