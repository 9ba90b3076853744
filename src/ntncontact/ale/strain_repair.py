"""Restoring the strain energy a remap changed, by relabelling particles at fixed positions.

A remap places nodes at new positions x~ and asks which particle X sits there. Node-to-node
contact loads the surface at nodes, so the C0 field X(x) has a kink at each loaded node, and
the interpolant through a moved node cuts it: the strain energy W changes to first order in
the slide (docs/theory.md, "The strain energy the remap changes"). Which particle sits at a
node near the kink is known only to the remap's own accuracy (the one-sided interpolants of
the cells around a moved node differ by that much); the repair makes, within it, the choice
that keeps W.

At fixed nodal positions x the strain energy is a function of the reference positions X,
and its gradient is the configurational (Eshelby) force

    dW/dX_a = sum_gauss w det(dX/dxi) (psi I - F^T P) . Grad N_a

(psi the stored energy, P the first Piola stress; from dF = -F (dX_a x Grad N_a) and
d det(dX/dxi) = det(dX/dxi) Grad N_a . dX_a). ``restore_strain_energy`` changes X on the
free nodes it is given (the engine gives interior nodes only: the body's reference outline,
hence its mass, stays) by Newton steps on the scalar equation W(X) = W* along the weighted
gradient, delta = beta g / weight: each step is the least weighted-norm change that moves W
by the residual to first order. The positions x, hence every gap, are untouched; the velocity
correction that follows (``ale.conservation``) restores the momenta and kinetic energy with
the repaired masses.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ..fem.kernels_numba import _jacobian_minus_one, _material, gauss_jacobian
from ..fem.q4 import DN_GP, GAUSS_WEIGHTS
from ..jit import njit

__all__ = ["RepairResult", "StrainRepair", "restore_strain_energy"]

_DN = np.ascontiguousarray(DN_GP)
_GW = np.ascontiguousarray(GAUSS_WEIGHTS, dtype=float)
_MAX_ITERATIONS = 30
_HALVINGS = 20


@njit(cache=True, error_model="numpy")
def _energy_and_force(models, X, d, cells, which, lam, mu, want_force, force):
    """Strain energy of the cells ``which`` at reference positions X and displacements d, and
    (``want_force``) their configurational forces dW/dX at fixed x = X + d added into
    ``force`` (n, 2). Returns (energy, ok); ok is False at a non-positive det(dX/dxi) or
    det F (Neo-Hookean)."""
    energy = 0.0
    for k in range(which.size):
        e = which[k]
        model = models[e]
        for g in range(4):
            J00, J01, J10, J11 = gauss_jacobian(_DN, g, X, cells[e])
            det = J00 * J11 - J01 * J10
            if not det > 0.0:
                return energy, False
            r = 1.0 / det
            H00 = H01 = H10 = H11 = 0.0
            Gx = np.empty(4)
            Gy = np.empty(4)
            for a in range(4):
                Gx[a] = (_DN[g, a, 0] * J11 - _DN[g, a, 1] * J10) * r
                Gy[a] = (-_DN[g, a, 0] * J01 + _DN[g, a, 1] * J00) * r
                n = cells[e, a]
                H00 += d[n, 0] * Gx[a]
                H01 += d[n, 0] * Gy[a]
                H10 += d[n, 1] * Gx[a]
                H11 += d[n, 1] * Gy[a]
            if model == 1 and not 1.0 + _jacobian_minus_one(H00, H01, H10, H11) > 0.0:
                return energy, False
            W, P00, P01, P10, P11, _, _, _, _, _ = _material(model, H00, H01, H10, H11,
                                                             lam[e], mu[e])
            w = det * _GW[g]
            energy += w * W
            if not want_force:
                continue
            F00, F01, F10, F11 = 1.0 + H00, H01, H10, 1.0 + H11
            # Eshelby stress psi I - F^T P, (F^T P)_IJ = F_iI P_iJ
            S00 = W - (F00 * P00 + F10 * P10)
            S01 = -(F00 * P01 + F10 * P11)
            S10 = -(F01 * P00 + F11 * P10)
            S11 = W - (F01 * P01 + F11 * P11)
            for a in range(4):
                n = cells[e, a]
                force[n, 0] += w * (S00 * Gx[a] + S01 * Gy[a])
                force[n, 1] += w * (S10 * Gx[a] + S11 * Gy[a])
    return energy, True


@dataclass(frozen=True)
class StrainRepair:
    """One body's cells and material data (local numbering)."""

    cells: NDArray[np.int64]  # (m, 4)
    models: NDArray[np.int64]  # kernel model code per cell
    lam: NDArray[np.float64]
    mu: NDArray[np.float64]

    def energy(self, X: NDArray, d: NDArray, which: NDArray) -> float:
        """Strain energy of the cells ``which``; raises ValueError if one is inverted."""
        value, ok = _energy_and_force(self.models, _c(X), _c(d), self.cells,
                                      np.asarray(which, np.int64), self.lam, self.mu, False,
                                      np.zeros((0, 2)))
        if not ok:
            raise ValueError("inverted element in the strain-energy repair")
        return float(value)

    def energy_and_force(self, X: NDArray, d: NDArray, which: NDArray
                         ) -> tuple[float, NDArray, bool]:
        """(energy, dW/dX at fixed x (n, 2), ok) over the cells ``which``."""
        force = np.zeros((len(X), 2))
        value, ok = _energy_and_force(self.models, _c(X), _c(d), self.cells,
                                      np.asarray(which, np.int64), self.lam, self.mu, True,
                                      force)
        return float(value), force, bool(ok)


def _c(a: NDArray) -> NDArray:
    return np.ascontiguousarray(a, dtype=float)


@dataclass(frozen=True)
class RepairResult:
    X: NDArray[np.float64]  # repaired reference positions (n, 2)
    restored: bool  # W hit its target (False: X returned unrepaired)
    change: float  # max |delta X| over the nodes
    iterations: int


def restore_strain_energy(repair: StrainRepair, X: NDArray, x: NDArray, free: NDArray,
                          weights: NDArray, cells: NDArray, target: float, tolerance: float
                          ) -> RepairResult:
    """Reference positions X (n, 2) changed at fixed positions x on the nodes ``free`` (n,)
    so that the strain energy of the cells ``cells`` takes the value ``target``.

    Newton's method on the scalar equation W(X) = target along the weighted gradient: each
    step is delta = beta g / weight on the free nodes (g = dW/dX at fixed x, ``weights`` (n,)
    > 0 the norm's nodal weights), the least weighted-norm change that moves W by the
    residual to first order, halved until the residual |W - target| decreases and no element
    inverts. Returns X unchanged (restored False) if W cannot reach the target this way (the
    energy gradient vanishes on the free nodes, or the residual stops decreasing: W has a
    minimum on the way).
    """
    X = np.asarray(X, dtype=float)
    x = np.asarray(x, dtype=float)
    mask = np.asarray(free, bool)[:, None] / np.asarray(weights, float)[:, None]
    Xk = X
    energy, g, ok = repair.energy_and_force(Xk, x - Xk, cells)
    if not ok:
        return RepairResult(X, False, 0.0, 0)
    value = energy - target
    for iteration in range(_MAX_ITERATIONS + 1):
        if abs(value) <= tolerance:
            change = float(np.max(np.linalg.norm(Xk - X, axis=1)))
            return RepairResult(Xk, True, change, iteration)
        direction = g * mask
        slope = float(np.sum(g * direction))
        if not slope > 0.0 or iteration == _MAX_ITERATIONS:
            break
        step = -value / slope
        for _ in range(_HALVINGS):
            Xt = Xk + step * direction
            e_t, g_t, ok = repair.energy_and_force(Xt, x - Xt, cells)
            if ok and abs(e_t - target) < abs(value):
                break
            step *= 0.5
        else:
            break
        Xk, g, value = Xt, g_t, e_t - target
    return RepairResult(X, False, 0.0, iteration)
