"""The ALE convective term C v of report (5.7)/(5.9): f_a = sum_e int rho0 N_a (c . grad_x v) dV0.

C_ab = int rho N_a c . grad_x N_b dV (report 2.4.2, (5.9)), integrated over each element's
reference (X) image with 2 x 2 Gauss since rho dV = rho0 dV0; the spatial gradient is
grad_x N = grad_X N F^-1 with F = dx/dX of the evaluation configuration x. The convective
velocity c is nodal and interpolated with N. The report holds c constant during an iteration
(the remark after (5.13)), so no derivative with respect to c is formed.

Element derivatives (s_b = c . grad_x N_b, G_ik = (grad_x v)_ik, W = rho0 w_g det J):
    df_ai/dv_bj = C_ab delta_ij,
    df_ai/dx_dl = -sum_g W N_a s_d G_il      (from d grad_x N_b / dx_dl = -grad_x N_l grad_x N_d).
The element quantities are vectorized over elements; assembly uses the Q4 dof order 2 a + i.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ..fem.assembly import element_dofs
from ..fem.q4 import N_GP, deformation_gradient, reference_gradients

__all__ = ["ConvectiveForce", "convective_force"]

Triplets = tuple[NDArray, NDArray, NDArray]


@dataclass(frozen=True)
class ConvectiveForce:
    """The assembled convective force (ndof,) and COO triplets of its derivatives."""

    force: NDArray
    d_x: Triplets
    d_v: Triplets


def _spatial(X_e: NDArray, x_e: NDArray) -> tuple[NDArray, NDArray]:
    """grad_x N (ne, g, 4, 2) and reference weights det(dX/dxi) w_g (ne, g)."""
    grad, weight = reference_gradients(X_e)
    F = deformation_gradient(grad, x_e)
    det = F[..., 0, 0] * F[..., 1, 1] - F[..., 0, 1] * F[..., 1, 0]
    Finv = np.empty_like(F)
    Finv[..., 0, 0] = F[..., 1, 1] / det
    Finv[..., 1, 1] = F[..., 0, 0] / det
    Finv[..., 0, 1] = -F[..., 0, 1] / det
    Finv[..., 1, 0] = -F[..., 1, 0] / det
    # dN/dx_k = dN/dX_J (F^-1)_Jk: the chain rule through X(x)
    return np.einsum("egbJ,egJk->egbk", grad, Finv), weight


def _triplets(edofs: NDArray, Ke: NDArray) -> Triplets:
    k = edofs.shape[1]
    rows = np.repeat(edofs, k, axis=1).ravel()
    cols = np.tile(edofs, (1, k)).ravel()
    return rows, cols, Ke.ravel()


def convective_force(
    X: NDArray, x: NDArray, v: NDArray, c: NDArray, cells: NDArray, rho: NDArray
) -> ConvectiveForce:
    """f = C(c) v over the listed ``cells`` (global node numbers, (ne, 4)), rho0 per cell.

    X, x, v, c are nodal (n, 2) arrays of all nodes; the force has 2 n entries and the
    derivative triplets use global dofs 2 node + i.
    """
    cells = np.asarray(cells, dtype=np.int64).reshape(-1, 4)
    v_e = v[cells]
    gx, w = _spatial(X[cells], x[cells])
    # rho0 w N_a (e, g, a): rho0 dV0 = rho dV at each Gauss point; s_b = c . grad_x N_b
    WN = (w * np.asarray(rho, float)[:, None])[..., None] * N_GP
    s = np.einsum("egk,egbk->egb", np.einsum("ga,eak->egk", N_GP, c[cells]), gx)
    WNs = np.einsum("ega,egd->egad", WN, s)
    C = WNs.sum(axis=1)  # C_e (e, 4, 4)
    f = np.einsum("eab,ebi->eai", C, v_e).reshape(-1, 8)
    df_dv = np.einsum("eab,ij->eaibj", C, np.eye(2)).reshape(-1, 8, 8)
    G = np.einsum("ebi,egbk->egik", v_e, gx)  # grad_x v
    df_dx = -np.einsum("egad,egil->eaidl", WNs, G).reshape(-1, 8, 8)
    edofs = element_dofs(cells)
    force = np.bincount(edofs.ravel(), weights=f.ravel(), minlength=2 * len(X))
    return ConvectiveForce(force, _triplets(edofs, df_dx), _triplets(edofs, df_dv))
