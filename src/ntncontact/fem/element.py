"""Vectorized Q4 element kernels: internal force, tangent, strain energy, mass (report 5.1.3)."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from ..materials.models import MaterialKind, stress_and_tangent
from .q4 import (
    DN_GP,
    GAUSS_WEIGHTS,
    N_GP,
    InvertedElementError,
    check_current_jacobian,
    kinematics,
    reference_gradients,
)

#: Elements processed per chunk: bounds temporary memory (~8 kB per element) at large sizes.
CHUNK = 32768


def element_force_tangent(
    kind: MaterialKind,
    X_e: NDArray,
    x_e: NDArray,
    lam: NDArray,
    mu: NDArray,
    need_tangent: bool = True,
) -> tuple[NDArray, NDArray | None, NDArray]:
    """Internal force f_e (ne, 8), tangent K_e (ne, 8, 8) and strain energy (ne,) of Q4 elements.

    Total Lagrangian over each element's reference image X_e: f_ai = int P_iJ dN_a/dX_J dV and
    K_aibk = int dN_a/dX_J A_iJkL dN_b/dX_L dV (report (5.10)); dof order (a, i) -> 2 a + i.
    """
    ne = X_e.shape[0]
    f = np.empty((ne, 8))
    K = np.empty((ne, 8, 8)) if need_tangent else None
    W = np.empty(ne)
    for start in range(0, ne, CHUNK):
        sl = slice(start, min(start + CHUNK, ne))
        try:
            kin = kinematics(X_e[sl], x_e[sl])
            if kind == "neo_hookean":
                check_current_jacobian(kin.F)
        except InvertedElementError as err:  # the index is local to the chunk
            raise renumbered(err, start + err.element) from None
        P, A, Wd = stress_and_tangent(kind, kin.F, lam[sl, None], mu[sl, None])
        gw = kin.grad * kin.weight[..., None, None]
        f[sl] = np.einsum("egiJ,egaJ->eai", P, gw).reshape(-1, 8)
        W[sl] = np.einsum("eg,eg->e", Wd, kin.weight)
        if K is not None:
            AG = np.einsum("egiJkL,egbL->egiJbk", A, kin.grad)
            K[sl] = np.einsum("egaJ,egiJbk->eaibk", gw, AG).reshape(-1, 8, 8)
    return f, K, W


def renumbered(err: InvertedElementError, element: int) -> InvertedElementError:
    """The same inversion error naming ``element`` instead (chunk or group index made global)."""
    where = "current configuration" if "current" in str(err) else "reference configuration"
    return InvertedElementError(element, err.value, where)


#: N_a N_b at each Gauss point, (4, 16): the mass is a weighted sum of these
_NN_GP = np.einsum("ga,gb->gab", N_GP, N_GP).reshape(len(N_GP), 16)


def element_mass(X_e: NDArray, rho: NDArray) -> NDArray:
    """Consistent scalar mass matrices m_ab = int rho0 N_a N_b dV, shape (ne, 4, 4) (5.8).

    Only det(dX/dxi) is needed (not the gradients): ALE runs rebuild the mass per move."""
    J = np.matmul(np.swapaxes(X_e, 1, 2)[:, None], DN_GP[None])  # (ne, g, i, j) = dX_i/dxi_j
    det = J[..., 0, 0] * J[..., 1, 1] - J[..., 0, 1] * J[..., 1, 0]
    if np.any(det <= 0.0):
        reference_gradients(X_e)  # raises InvertedElementError naming the element
    weight = det * GAUSS_WEIGHTS * rho[:, None]
    return (weight @ _NN_GP).reshape(len(X_e), 4, 4)

