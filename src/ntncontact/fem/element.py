"""Q4 element mass matrices (report 5.1.3); the internal force, tangent and strain energy are
computed by the compiled kernel in :mod:`ntncontact.fem.kernels_numba`."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from .q4 import DN_GP, GAUSS_WEIGHTS, N_GP, reference_gradients

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

