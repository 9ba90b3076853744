"""The velocity correction that makes a remap conserve momenta and kinetic energy exactly.

After a remap the nodal velocities v (n, 2) of a body sit on new particles with new masses
M (the scalar nodal mass matrix of the moved mesh, consistent or lumped). The correction is the
smallest change delta, in the mass norm |delta|_M^2 = delta . M delta, of the velocities of the
dofs S that may change (the remapped nodes and their neighbours, supports excluded) such that

    P(v + delta) = P*,  L(v + delta) = L*   (linear, about the origin; G^T M (v + delta) = g*)
    K(v + delta) = K*                        (quadratic; 1/2 (v + delta) . M (v + delta))

with G = [t_x, t_y, rho] the rigid modes (rho_a = e_z x x_a) and the momenta as the time loop
measures them (P = sum M v, L = sum x_a x (M v)_a). Write A = M_SS, B = (M G)_S, b = (M v)_S.

* The linear constraints alone: delta_0 = Phi C^-1 r, Phi = A^-1 B, C = B^T Phi,
  r = g* - G^T M v (the minimal-norm solution; it is A-orthogonal to every z with B^T z = 0).
* The energy: every other admissible change is delta = delta_0 + z with B^T z = 0, and
  K(v + delta) = K(v) + b.delta_0 + |delta_0|^2/2 + <u_N, z>_A + |z|^2/2, where u = A^-1 b and
  u_N = u - Phi C^-1 B^T u is the part of u that carries no momentum. The admissible z with the
  right energy form a sphere about -u_N; its point nearest the origin is z = alpha u_N,
  (1 + alpha)^2 = 1 + 2 k'/|u_N|_A^2, k' = K* - K(v) - b.delta_0 - |delta_0|^2/2.
  With a lumped mass and S the whole body this scales the non-rigid part of the velocity.

The energy cannot be restored when 1 + 2 k'/|u_N|^2 < 0 (the non-rigid motion on S holds less
energy than has to be taken out) or u_N vanishes; the caller then widens S.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from numpy.typing import ArrayLike, NDArray
from scipy.sparse.linalg import splu

__all__ = ["ConservingCorrection", "conserving_correction", "dof_momenta", "rigid_modes"]


def rigid_modes(x: NDArray) -> NDArray[np.float64]:
    """The rigid velocity modes on dofs (2 n, 3): translations x, y and the rotation e_z x x."""
    n = len(x)
    G = np.zeros((2 * n, 3))
    G[0::2, 0] = 1.0
    G[1::2, 1] = 1.0
    G[0::2, 2] = -x[:, 1]
    G[1::2, 2] = x[:, 0]
    return G


def dof_momenta(mass: sp.spmatrix, x: NDArray, v: NDArray) -> tuple[NDArray, float]:
    """(P_x, P_y, L) and the kinetic energy of nodal velocities v with the scalar mass."""
    p = mass @ v
    return rigid_modes(x).T @ p.ravel(), 0.5 * float(np.sum(v * p))


@dataclass(frozen=True)
class ConservingCorrection:
    v: NDArray[np.float64]  # corrected velocities (n, 2)
    energy_restored: bool  # False: only the momenta were restored (see the module doc)
    change: float  # |delta|_M / |v|_M on S: the relative size of the correction


#: SuperLU's settings for a mass block, symmetric positive definite: a symmetric ordering and
#: no pivoting. On a whole block refined 8x (23,698 dofs) 0.18 s a factorization against
#: 0.26 s with the defaults (column ordering, partial pivoting), 30 % less fill.
_SPD_LU = {"permc_spec": "MMD_AT_PLUS_A", "diag_pivot_thresh": 0.0,
           "options": {"SymmetricMode": True}}


def _mass_solver(mass: sp.csr_matrix, dofs: NDArray) -> tuple[sp.spmatrix, Callable]:
    """(A = M_SS on the dofs (2 a + i), a function applying A^-1 to a vector or columns).

    Sparse, for a sparse LU: S is the neighbourhood of a few moved nodes, but the whole body
    when that cannot take the energy (dense, a whole block of 23,698 dofs took ~8 min and
    4.5 GB a factorization). Where S holds both dofs of each of its nodes (no support among
    them) A is the scalar block M_NN for x and y alike, so that block is factored alone (0.11
    s against 0.18 s for the two on that block)."""
    pairs = dofs.reshape(-1, 2) if dofs.size % 2 == 0 else None
    if pairs is None or (pairs[:, 0] % 2).any() or not np.array_equal(pairs[:, 1], pairs[:, 0] + 1):
        A = _dof_block(mass, dofs)
        return A, splu(A, **_SPD_LU).solve
    nodes = pairs[:, 0] // 2
    block = mass[nodes][:, nodes]
    lu = splu(block.tocsc(), **_SPD_LU)

    def solve(rhs: NDArray) -> NDArray:
        # rows 2 a and 2 a + 1 (x and y of node a) become row a of the scalar system
        return lu.solve(rhs.reshape(nodes.size, -1)).reshape(rhs.shape)

    return sp.kron(block, sp.identity(2), format="csr"), solve


def _dof_block(mass: sp.csr_matrix, dofs: NDArray) -> sp.csc_matrix:
    """A = M_SS on any dofs (2 a + i) from the scalar nodal mass: M acts alike on x and y."""
    nodes, where = np.unique(dofs // 2, return_inverse=True)
    block = mass[nodes][:, nodes][where][:, where].tocoo()
    same = dofs[block.row] % 2 == dofs[block.col] % 2
    return sp.csc_matrix((block.data[same], (block.row[same], block.col[same])),
                         shape=(dofs.size, dofs.size))


def _momentum_change(mass: sp.csr_matrix, x: NDArray, p: NDArray, dofs: NDArray, solve,
                     u: NDArray, momenta: ArrayLike) -> tuple[NDArray, NDArray]:
    """(delta_0, u_free): the least mass-norm change on ``dofs`` that gives the momenta
    (P_x, P_y, L about the origin), and u = A^-1 M v with its part along the rigid modes
    removed (the direction an energy change may take without changing the momenta).
    ``p`` = M v (n, 2); ``solve`` applies A^-1."""
    # (M G) on dofs, G the rigid modes: the scalar mass times each node's (2, 3) block
    B = (mass @ rigid_modes(x).reshape(len(x), 6)).reshape(-1, 3)[dofs]
    Phi = solve(B)
    C = B.T @ Phi
    current = np.array([p[:, 0].sum(), p[:, 1].sum(),
                        float(np.sum(x[:, 0] * p[:, 1] - x[:, 1] * p[:, 0]))])
    r = np.asarray(momenta, dtype=float) - current
    return Phi @ np.linalg.solve(C, r), u - Phi @ np.linalg.solve(C, B.T @ u)


def _energy_change(kinetic: float, k0: float, A: sp.spmatrix, b: NDArray, delta: NDArray,
                   u_free: NDArray) -> tuple[NDArray, bool]:
    """(delta, restored): ``delta`` (the momentum change delta_0) plus the step along u_free
    that brings the kinetic energy from k0 to ``kinetic``, and whether it could."""
    # what is left to change once delta_0 is made (A delta_0 is orthogonal to u_free)
    left = kinetic - k0 - float(b @ delta) - 0.5 * float(delta @ (A @ delta))
    norm2 = float(b @ u_free)  # |u_N|_A^2 = u_N . A u = u_N . b
    ratio = 1.0 + 2.0 * left / norm2 if norm2 > 0.0 else -1.0
    if abs(left) <= 1e-14 * max(abs(kinetic), k0):
        # nothing left to change (a body at rest: v = 0 meets K* = 0 and P* = 0), which
        # no velocity change could do when the motion vanishes (u_N = 0)
        return delta, True
    if ratio >= 0.0 and norm2 > 1e-30 * max(abs(k0), 1e-300):
        return delta + (np.sqrt(ratio) - 1.0) * u_free, True
    if ratio < 0.0 and norm2 > 0.0:
        # K* below the least K the momenta allow: give what the motion can (the sphere's
        # point nearest the origin, alpha = -1), so that what is still missing changes
        # continuously with K* and the caller can hand it on (hand_over_energy)
        return delta - u_free, False
    return delta, False


def conserving_correction(mass: sp.spmatrix, x: NDArray, v: NDArray, dofs: NDArray,
                          momenta: NDArray | None, kinetic: float | None
                          ) -> ConservingCorrection:
    """Velocities v (n, 2) changed on ``dofs`` (indices 2 a + i) by the least mass-norm amount
    so that the momenta (P_x, P_y, L about the origin; None: not imposed) and the kinetic
    energy (None: not imposed) take the given values. ``mass`` is the scalar nodal mass (n, n)
    of the configuration x."""
    v = np.asarray(v, dtype=float)
    x = np.asarray(x, dtype=float)
    dofs = np.asarray(dofs, dtype=np.int64)
    if dofs.size == 0:
        return ConservingCorrection(v.copy(), kinetic is None, 0.0)
    mass = sp.csr_matrix(mass)
    # everything from nodal products with the scalar mass (M acts alike on x and y)
    p = mass @ v
    Mv = p.ravel()
    A, solve = _mass_solver(mass, dofs)
    b = Mv[dofs]

    u = solve(b)
    delta, u_free = ((np.zeros(dofs.size), u) if momenta is None
                     else _momentum_change(mass, x, p, dofs, solve, u, momenta))
    restored = kinetic is None
    if kinetic is not None:
        delta, restored = _energy_change(kinetic, 0.5 * float(v.ravel() @ Mv), A, b, delta,
                                         u_free)
    out = v.ravel().copy()
    out[dofs] += delta
    v_sub = v.ravel()[dofs]
    size = float(np.sqrt(max(delta @ (A @ delta), 0.0) / max(float(v_sub @ (A @ v_sub)), 1e-300)))
    return ConservingCorrection(out.reshape(v.shape), restored, size)
