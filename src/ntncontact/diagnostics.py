"""Energies and momenta of a state (report 6.4: E = E_k + E_s, L = sum M v, L_a = sum x x Mv)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from numpy.typing import NDArray


@dataclass(frozen=True)
class Balance:
    kinetic_energy: float
    strain_energy: float
    linear_momentum: tuple[float, float]
    angular_momentum: float

    @property
    def total_energy(self) -> float:
        return self.kinetic_energy + self.strain_energy


def balance(mass: sp.spmatrix, x: NDArray, v: NDArray, strain_energy: float) -> Balance:
    """Kinetic energy 1/2 v.Mv, linear momentum sum_a (Mv)_a, angular momentum about the origin.

    ``mass`` is the scalar (per node) mass matrix, or the mass on the dofs (x_a, y_a
    interleaved: the nodal one times the 2 x 2 identity), ``x`` current positions, ``v``
    velocities. The angular momentum sum_ab M_ab x_a x v_b is the quantity the mid-point rule
    conserves exactly.
    """
    if mass.shape[0] == v.shape[0]:
        p = mass @ v  # nodal momenta (n, 2)
    else:
        p = (mass @ v.ravel()).reshape(v.shape)
    kinetic = 0.5 * float(np.sum(v * p))
    angular = float(np.sum(x[:, 0] * p[:, 1] - x[:, 1] * p[:, 0]))
    return Balance(kinetic, strain_energy, (float(p[:, 0].sum()), float(p[:, 1].sum())), angular)
