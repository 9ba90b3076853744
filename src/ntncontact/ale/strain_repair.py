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

from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray

from ..fem.kernels_numba import (
    _DETA,
    _DXI,
    _comb4,
    _jacobian_minus_one,
    _material,
    gauss_jacobian,
)
from ..fem.q4 import DN_GP, GAUSS_WEIGHTS
from ..jit import njit, read_only

__all__ = ["RepairResult", "StrainRepair", "restore_strain_energy"]

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
            J00, J01, J10, J11 = gauss_jacobian(DN_GP, g, X, cells[e])
            det = J00 * J11 - J01 * J10
            if not det > 0.0:
                return energy, False
            r = 1.0 / det
            # tuples, not arrays: two small arrays a Gauss point were heap allocations that
            # took ~half of this kernel's time (fast sliding refined 8x)
            Gx = _comb4(_DXI[g], _DETA[g], J11 * r, -J10 * r)
            Gy = _comb4(_DXI[g], _DETA[g], -J01 * r, J00 * r)
            H00 = H01 = H10 = H11 = 0.0
            for a in range(4):
                n = cells[e, a]
                H00 += d[n, 0] * Gx[a]
                H01 += d[n, 0] * Gy[a]
                H10 += d[n, 1] * Gx[a]
                H11 += d[n, 1] * Gy[a]
            if model == 1 and not 1.0 + _jacobian_minus_one(H00, H01, H10, H11) > 0.0:
                return energy, False
            W, P00, P01, P10, P11, _, _, _, _, _ = _material(model, H00, H01, H10, H11,
                                                             lam[e], mu[e])
            w = det * GAUSS_WEIGHTS[g]
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

    def __post_init__(self) -> None:
        # read-only views: the body's repair holds its mesh's frozen cells, the local one of a
        # neighbourhood new arrays, and Numba compiled _energy_and_force once for each
        for name in ("cells", "models", "lam", "mu"):
            object.__setattr__(self, name, read_only(getattr(self, name)))

    def energy(self, X: NDArray, d: NDArray, which: NDArray) -> float:
        """Strain energy of the cells ``which``; raises ValueError if one is inverted."""
        value, _, ok = self.energy_and_force(X, d, which, want_force=False)
        if not ok:
            raise ValueError("inverted element in the strain-energy repair")
        return value

    def around(self, which: NDArray) -> tuple[StrainRepair, NDArray, NDArray]:
        """(this repair on the cells ``which`` alone, numbered on their nodes; those nodes;
        the cells' indices in it). The repair's arrays then have the size of the cells
        around the move, not of the body: at the fast-sliding blocks refined 8x the
        full-size arrays of each trial step were about half of the repair's time."""
        which = np.asarray(which, np.int64)
        nodes, local = np.unique(self.cells[which], return_inverse=True)
        sub = StrainRepair(local.reshape(-1, 4).astype(np.int64), self.models[which],
                           self.lam[which], self.mu[which])
        return sub, nodes, np.arange(which.size, dtype=np.int64)

    def energy_and_force(self, X: NDArray, d: NDArray, which: NDArray, want_force: bool = True
                         ) -> tuple[float, NDArray, bool]:
        """(energy, dW/dX at fixed x (n, 2), ok) over the cells ``which``; without
        ``want_force`` the force is an empty (0, 2) array (not computed)."""
        force = np.zeros((len(X) if want_force else 0, 2))
        value, ok = _energy_and_force(self.models, _c(X), _c(d), self.cells,
                                      np.asarray(which, np.int64), self.lam, self.mu,
                                      want_force, force)
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
                          weights: NDArray, cells: NDArray, target: float, tolerance: float,
                          round_off: float = 0.0) -> RepairResult:
    """Reference positions X (n, 2) changed at fixed positions x on the nodes ``free`` (n,)
    so that the strain energy of the cells ``cells`` takes the value ``target``.

    Newton's method on the scalar equation W(X) = target: the first step is
    delta = beta g / weight on the free nodes (g = dW/dX at fixed x, ``weights`` (n,) > 0 the
    norm's nodal weights), the least weighted-norm change that moves W by the residual to
    first order. Where the full step overshoots (W curves along g more than the residual's
    size: the interior's configurational forces are small), the step is shortened to the
    root of a quadratic fitted through the trial, else halved, until the residual
    |W - target| decreases and no element inverts; after a shortened step the next direction
    is conjugate to the last (Polak-Ribiere in the 1/weight metric), so the steps stop
    zig-zagging across W's curved valley (against halving along g alone, the fast-sliding
    blocks refined 4x: 69 of 118 repairs restored instead of 55 of 127). Returns X
    unchanged (restored False) if W cannot reach the target this way (the energy gradient
    vanishes on the free nodes, or the residual stops decreasing: W has a minimum on the
    way), unless the residual where it stopped is at most ``round_off``: W's round-off floor.
    At fixed x a one-ulp change of X changes d = x - X, hence W, by the nodal force times
    that ulp, which can exceed ``tolerance``: a Newton that converged quadratically to that
    floor then ground on by ~1e-20 an iteration, and whether it crossed the tolerance before
    giving up was the round-off's draw, which made a run depend on its frame.
    """
    X = np.asarray(X, dtype=float)
    local, nodes, which = repair.around(cells)
    # positions from a whole-number point near the nodes (subtracted exactly): at |x| ~ 100
    # the round-off of x - X kept W from its target in a quarter of the repairs
    origin = np.round(X[nodes].mean(axis=0))
    result = _restore(local, X[nodes] - origin, np.asarray(x, dtype=float)[nodes] - origin,
                      np.asarray(free, bool)[nodes], np.asarray(weights, float)[nodes], which,
                      target, (tolerance, round_off))
    if not result.restored:
        return replace(result, X=X)
    repaired = X.copy()
    repaired[nodes] = result.X + origin
    return replace(result, X=repaired)


def _restore(repair: StrainRepair, X: NDArray, x: NDArray, free: NDArray, weights: NDArray,
             cells: NDArray, target: float, tolerances: tuple[float, float]) -> RepairResult:
    """:func:`restore_strain_energy` on arrays of the nodes of ``cells`` only (``repair``
    numbered on them); ``tolerances``: (tolerance, round_off)."""
    tolerance, round_off = tolerances
    metric = free[:, None] / weights[:, None]
    Xk = X
    energy, g, ok = repair.energy_and_force(Xk, x - Xk, cells)
    if not ok:
        return RepairResult(X, False, 0.0, 0)
    value, last = energy - target, None
    for iteration in range(_MAX_ITERATIONS + 1):
        if abs(value) <= tolerance:
            change = float(np.max(np.linalg.norm(Xk - X, axis=1)))
            return RepairResult(Xk, True, change, iteration)
        z = g * metric
        if not float(np.sum(g * z)) > 0.0 or iteration == _MAX_ITERATIONS:
            break
        direction = _direction(value, g, z, last)
        found = _search(repair, Xk, x, cells, target, value, g, direction)
        if found is None:
            break
        # after Newton's full step the next direction is the plain one again
        last = None if found.full else (direction, z, g)
        Xk, g, value = found.X, found.force, found.energy - target
    if abs(value) <= round_off:  # stopped at W's round-off floor: as restored as it gets
        return RepairResult(Xk, True, float(np.max(np.linalg.norm(Xk - X, axis=1))), iteration)
    return RepairResult(X, False, 0.0, iteration)


def _direction(value: float, g: NDArray, z: NDArray, last: tuple | None) -> NDArray:
    """The step's direction: -sign(value) z (z = the gradient g in the 1/weight metric), made
    conjugate to the last direction (Polak-Ribiere, beta >= 0) when ``last`` = (direction,
    z, g) of a shortened step is given and the result still decreases |value|."""
    sign = 1.0 if value > 0.0 else -1.0
    plain = -sign * z
    if last is None:
        return plain
    d_last, z_last, g_last = last
    beta = max(0.0, float(np.sum(z * (g - g_last))) / float(np.sum(z_last * g_last)))
    conjugate = plain + beta * d_last
    return conjugate if sign * float(np.sum(g * conjugate)) < 0.0 else plain


@dataclass(frozen=True)
class _Trial:
    X: NDArray
    energy: float
    force: NDArray
    full: bool  # Newton's full step was taken


def _search(repair: StrainRepair, Xk: NDArray, x: NDArray, cells: NDArray, target: float,
            value: float, g: NDArray, direction: NDArray) -> _Trial | None:
    """The first step along ``direction`` that decreases |W - target| without inverting an
    element: Newton's full step, then the root (else the minimum) of the quadratic in the
    step length through the residual, its slope and the first trial, then halvings. None if
    none of _HALVINGS trials does."""
    sign = 1.0 if value > 0.0 else -1.0
    slope = sign * float(np.sum(g * direction))  # d|W - target| / ds < 0
    residual = abs(value)
    s = full = residual / -slope
    fitted = False
    for _ in range(_HALVINGS):
        Xt = Xk + s * direction
        energy, force, ok = repair.energy_and_force(Xt, x - Xt, cells)
        if ok and abs(energy - target) < residual:
            return _Trial(Xt, energy, force, s == full)
        if ok and not fitted:
            fitted = True
            shorter = _quadratic_step(residual, slope, s, sign * (energy - target))
            if 0.0 < shorter < s:
                s = shorter
                continue
        s *= 0.5
    return None


def _quadratic_step(psi0: float, slope: float, s: float, psi: float) -> float:
    """The smaller root of psi0 + slope t + c t^2 = 0 fitted through psi at t = s (signed:
    psi < 0 past the target), or its minimum where it has no root; 0 if not convex."""
    c = (psi - psi0 - slope * s) / (s * s)
    if not c > 0.0:
        return 0.0
    disc = slope * slope - 4.0 * c * psi0
    return (-slope - np.sqrt(disc)) / (2.0 * c) if disc >= 0.0 else -slope / (2.0 * c)
