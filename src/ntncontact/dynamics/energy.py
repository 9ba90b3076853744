"""The energy-conserving Lagrange-multiplier variant (report 5.5), in a form that is solvable.

Report 5.5 borders the mid-point equations with an energy multiplier lambda_E acting along
M a + K d (5.30). At a solution of a contact step without external loads, M a + f_int = -B lambda
(the contact forces), so that column lies in the range of the contact columns and the bordered
system (5.34) is singular; we verified this numerically. We keep the report's idea (one extra
unknown and the discrete energy equation E_{n+1} = E_n appended to the Lagrange-multiplier
system) but let the extra unknown theta relax the geometric constraint of every active pair
towards persistency:

    h_p = (L_c g)_p(x_{n+1/2}) - theta (L_c g)_p(x_n) = 0,   h_E = E_{n+1}(d) - W(d) - E_n = 0,

W the work of the loads over the step, F_{n+1/2} . (x_{n+1} - x_n) as the mid-point rule applies
them (without it a block bouncing under gravity gained 2.8 times the energy it fell with: theta
made the contact forces cancel the loads' work). Friction and moving supports are refused with
this variant (``engine.builder``): their work is not in the equation.

theta = 0 is the exact gap constraint (impenetrable, but closing a residual gap g_n does work);
theta = 1 freezes the tributary-weighted gap over the step, i.e. the persistency condition,
which conserves energy (report 3.3.1). The energy equation picks the theta that conserves
energy exactly (the normal contact forces do no net work); it is not confined to [0, 1]. Contact
forces stay equal and opposite pair forces, so linear and angular momentum are conserved as in
the mid-point rule. E is the kinetic plus strain energy at t_{n+1}:
x_{n+1} = X + 2 d - d_n, v_{n+1} = 4 (d - d_n)/dt - v_n with d = d_{n+1/2}.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
import scipy.sparse as sp
from numpy.typing import NDArray

from ..fem.assembly import Assembler


@dataclass
class EndEnergy:
    """E_{n+1} less the loads' work over the step, as a function of the mid-point unknown
    d = d_{n+1/2}, and its gradient."""

    assembler: Assembler
    mass: sp.csr_matrix  # on dofs
    X: NDArray  # (n, 2) material positions at the nodes for this step
    d_n: NDArray  # (ndof,)
    v_n: NDArray  # (ndof,)
    dt: float
    load: NDArray  # (ndof,) the loads at t_{n+1/2} (dead over the step)
    x_n: NDArray  # (ndof,) the positions at t_n

    def __call__(self, d: NDArray) -> tuple[float, NDArray]:
        v1 = 4.0 * (d - self.d_n) / self.dt - self.v_n  # 2 v_{n+1/2} - v_n
        d1 = 2.0 * d - self.d_n  # d_{n+1}
        f1, _, w1 = self.assembler.internal(self.X, d=d1, need_tangent=False)
        Mv1 = self.mass @ v1
        work = float(self.load @ (self.X.ravel() + d1 - self.x_n))
        return (0.5 * float(v1 @ Mv1) + w1 - work,
                (4.0 / self.dt) * Mv1 + 2.0 * (f1 - self.load))


@dataclass
class EnergyConsistentContact:
    """All Lagrange gap-law interfaces of a step plus theta, as one bordered-system term.

    ``terms`` are the per-interface Lagrange terms (see ``interfaces.LagrangeTerm``), each with
    ``blocks_at(x, lam)`` giving (force, K, h, G, B); ``h_start`` their h at x_n.
    """

    terms: list
    h_start: list[NDArray]
    end_energy: EndEnergy
    energy_n: float
    fixed_theta: float | None = None  # replace the energy equation by theta = fixed_theta

    @property
    def size(self) -> int:
        return sum(t.size for t in self.terms) + 1

    @property
    def initial(self) -> NDArray:
        return np.concatenate([t.initial for t in self.terms] + [np.zeros(1)])

    def split(self, lam: NDArray) -> tuple[list[NDArray], float]:
        """(each term's multipliers, theta) of the term's unknowns ``lam``."""
        return np.split(lam[:-1], np.cumsum([t.size for t in self.terms])[:-1]), float(lam[-1])

    def __call__(self, x_eval, v_eval, rate, x_start, lam):
        lams, theta = self.split(lam)
        force = np.zeros(x_eval.size)
        k_parts, hs, g_parts, b_parts, c_rows, c_vals = [], [], [], [], [], []
        row = 0
        for t, lam_t, h0 in zip(self.terms, lams, self.h_start, strict=True):
            f, (kr, kc, kv), h, (gr, gc, gv), (br, bc, bv) = t(x_eval, v_eval, rate, x_start,
                                                               lam_t)
            force += f
            k_parts.append((kr, kc, kv))
            hs.append(h - theta * h0)
            g_parts.append((gr + row, gc, gv))
            b_parts.append((br, bc + row, bv))
            c_rows.append(row + np.arange(t.size))
            c_vals.append(-h0)
            row += t.size
        if self.fixed_theta is None:
            energy, grad = self.end_energy(x_eval.ravel() - self.end_energy.X.ravel())
            nz = np.flatnonzero(grad)
            g_parts.append((np.full(nz.size, row), nz, grad[nz]))
            hs.append(np.array([energy - self.energy_n]))
        else:  # theta = fixed_theta: a plain row on the multiplier itself
            hs.append(np.array([theta - self.fixed_theta]))
            c_rows.append(np.array([row]))
            c_vals.append(np.array([1.0]))
        k, g, b = (tuple(np.concatenate(p) for p in zip(*parts, strict=True))
                   for parts in (k_parts, g_parts, b_parts))
        crow = np.concatenate(c_rows)
        return (force, k, np.concatenate(hs), g, b,
                (crow, np.full(crow.size, row), np.concatenate(c_vals)))

    def excess(self, d: NDArray) -> float:
        """The energy equation's residual at the mid-point displacements ``d``: E_{n+1} less
        the loads' work, less E_n."""
        return self.end_energy(d)[0] - self.energy_n

    def with_theta(self, theta: float) -> EnergyConsistentContact:
        """The same term with theta held fixed (theta = 1: the persistency condition)."""
        return replace(self, fixed_theta=theta)
