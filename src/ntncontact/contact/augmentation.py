"""Nested augmented-Lagrangian updates and their stopping test (report 5.4, steps 4.1-4.2), and
the history a converged step commits (:func:`commit_step`, step 1's multiplier prediction).

Per step: Newton converges with the multipliers of ``state`` fixed, giving a ContactResult r_k;
if :func:`check_augmentation` (r_{k-1}, r_k) is not converged, ``state = augment(state, r_k)``
and the ALE motion + Newton are repeated.

Update (Uzawa):   lambda_N <- <lambda_N + eps_N gdot> = <t_N^(k)>        (5.4 step 4.1)
                  dlambda_T <- t_T^(k) - t_T,n                           (5.4 step 4.2)
The tangential update covers both branches of 4.2: on a sticking pair t_T^(k) = t_T,n + dlambda_T
+ eps_T gdot_T, so dlambda_T grows by eps_T gdot_T; on a slipping pair t_T^(k) = mu t_N^(k)
trial/|trial|, so dlambda_T = mu lambda_N^(k) trial/|trial| - t_T,n.
A pair held on the pressed branch during the solve (``laws.held_pairs``) may come out with a
tensile t_N^(k) < 0: it is not converged, and its multiplier drops to 0 (the bracket).

Newton update (optional): the Uzawa update is a fixed-point iteration whose error
shrinks by a constant factor per augmentation (~0.03 on the ring impact of report 6.4). Solving
instead for the multipliers that make the constraints h = L_c gdot (or L_c g) of the pressed
pairs vanish to first order, with the sensitivity S = dh/dlambda of the converged solve,
converges as fast as S is exact (:func:`newton_update`). The test of step 4 and its tolerances
are unchanged, so the converged step is the same up to them. With friction a slipping pair's
tangential traction is mu t_N: its normal multiplier moves both tractions, and S carries that
through B (``lagrange.blocks_of``); sticking pairs' tangential multipliers keep Uzawa's update.
Fast-sliding blocks refined 8x, both blocks ALE, from t = 0.096: one step in 10 augmentations and
32 Newton iterations, where Uzawa contracted by 0.86 an augmentation, ran out at 60 and was cut
back (163 iterations).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray

from .evaluate import ContactResult
from .friction import SLIP
from .laws import ContactLaw
from .state import PairState

__all__ = ["AugmentationCheck", "AugmentationTolerances", "augment", "check_augmentation",
           "commit_step", "extrapolated_update", "max_contraction", "newton_update",
           "pressed_in_both"]

#: :func:`extrapolated_update` acts only on a measured contraction below this: beyond it the
#: geometric tail rho / (1 - rho) of a step would be larger than the Uzawa step itself
MAX_EXTRAPOLATED_RATE = 0.5


def augment(state: PairState, result: ContactResult, law: ContactLaw) -> PairState:
    """Multipliers for the next augmentation from the converged Newton result (module doc)."""
    if law.method != "augmented_lagrangian":
        raise ValueError(f"augment() applies to 'augmented_lagrangian', not {law.method!r}")
    if not np.array_equal(result.pairs, state.pairs):
        raise ValueError("result and state describe different active sets")
    return replace(state, lambda_N=np.maximum(result.t_N, 0.0),
                   dlambda_T=result.t_T - state.t_T)


def newton_update(used: PairState, uzawa: PairState, result: ContactResult,
                  sensitivity: NDArray) -> PairState:
    """``uzawa`` (``augment(used, result)``) with the pressed pairs' (t_N > 0) normal
    multipliers from a Newton step on h(lambda) = 0: lambda + S^-1 h, kept >= 0.

    sensitivity: S = -dh/dlambda over the pressed pairs, G A^-1 B with A the Newton matrix of
    the solve, G = dh/dx and B = d force/d lambda (``lagrange.lagrange_blocks``; on a slipping
    pair with its friction mu t_N), h = L_c gdot (rate law) or L_c g. A pair that is not
    pressed keeps the Uzawa value, 0."""
    pressed = result.t_N > 0.0
    h = result.length[pressed] * result.normal_measure[pressed]
    lam = uzawa.lambda_N.copy()
    lam[pressed] = np.maximum(used.lambda_N[pressed] + np.linalg.solve(sensitivity, h), 0.0)
    return replace(uzawa, lambda_N=lam)


def pressed_in_both(current: ContactResult, previous: ContactResult) -> NDArray:
    """The pairs pressed (t_N > 0) in two augmentations of one step, whose normal measures
    compare: the pairs that show how fast a multiplier update contracts."""
    if not np.array_equal(current.pairs, previous.pairs):
        raise ValueError("augmentations of one step must share the active set")
    return (current.t_N > 0.0) & (previous.t_N > 0.0)


def max_contraction(current: ContactResult, previous: ContactResult) -> float:
    """max |m_k| / max |m_{k-1}| over :func:`pressed_in_both` (m the normal measure), 0 if
    none was measured: the last update's contraction as a ratio of maxima, the measure of
    the error an inexact solve may leave (``Simulation._adapted_early_ratio``)."""
    both = pressed_in_both(current, previous)
    last = np.abs(previous.normal_measure[both]).max(initial=0.0)
    return float(np.abs(current.normal_measure[both]).max() / last) if last > 0.0 else 0.0


def extrapolated_update(uzawa: PairState, current: ContactResult, previous: ContactResult,
                        law: ContactLaw) -> PairState:
    """``uzawa`` (``augment`` of ``current``) with the pairs pressed in both augmentations
    taking the rest of the Uzawa sequence at once (Aitken's extrapolation).

    An Uzawa update adds eps_N m_k (m the normal measure, the gap under the gap law); while
    one mode of the multiplier error dominates, each update is rho times the last, rho =
    m_k . m_{k-1} / |m_{k-1}|^2 over those pairs, and the updates still to come sum to
    eps_N m_k rho / (1 - rho). rho grows with the mesh (~E / (eps_N h): Hertz ~0.003 at
    k = 1, ~0.027 at k = 4), which is why refined meshes need more augmentations. Applied only
    for 0 < rho < MAX_EXTRAPOLATED_RATE; the multipliers stay >= 0, and report 5.4's test
    decides convergence as before."""
    both = pressed_in_both(current, previous)
    m, m_prev = current.normal_measure[both], previous.normal_measure[both]
    norm_prev = float(m_prev @ m_prev)
    rho = float(m @ m_prev) / norm_prev if norm_prev > 0.0 else 0.0
    if not 0.0 < rho < MAX_EXTRAPOLATED_RATE:
        return uzawa
    lam = uzawa.lambda_N.copy()
    lam[both] = np.maximum(lam[both] + law.eps_N * m * (rho / (1.0 - rho)), 0.0)
    return replace(uzawa, lambda_N=lam)


@dataclass(frozen=True)
class AugmentationTolerances:
    """normal: TOL1 on max |change of gdot| (of g under the gap law);
    tangential: TOL2 on max |change of gdot_T| (of delta g_T);
    slip: relative slack in |t_T| <= mu t_N (report 5.4 step 4, third test);
    constraint: optional bound on max |gdot| (|g|) over pressed pairs (t_N > 0), i.e. on the
    constraint violation itself, which the report's change test only implies."""

    normal: float
    tangential: float
    slip: float = 1e-10
    constraint: float | None = None


@dataclass(frozen=True)
class AugmentationCheck:
    normal_change: float
    tangential_change: float
    slip_excess: float
    status_changes: int
    constraint_violation: float
    converged: bool
    #: pairs held on the pressed branch whose traction came out tensile (laws.held_pairs)
    tensile_pairs: int = 0


def _max_abs(values: np.ndarray) -> float:
    return float(np.max(np.abs(values))) if values.size else 0.0


def check_augmentation(
    previous: ContactResult, current: ContactResult, law: ContactLaw,
    tol: AugmentationTolerances,
) -> AugmentationCheck:
    """Report 5.4 step 4 between two successive augmentations of one step.

    Also requires the stick/slip status to be unchanged, since a status switch means the
    multipliers were built for a different friction branch, and no tensile traction (a pair
    held by its multiplier during the solve, ``laws.held_pairs``, that wants to separate).
    The tangential tests (TOL2, the slip slack, the status) apply to frictional laws only:
    without friction there is no tangential multiplier to augment (ring impact: 714 -> 665
    augmentations, the largest energy variation 1.525444e-3 -> 1.525445e-3).
    """
    if not np.array_equal(previous.pairs, current.pairs):
        raise ValueError("augmentations of one step must share the active set")
    normal = _max_abs(current.normal_measure - previous.normal_measure)
    tangential = _max_abs(current.slip_measure - previous.slip_measure)
    scale = np.maximum(law.mu * current.t_N, np.finfo(float).tiny)
    slip_excess = _max_abs(np.maximum(np.abs(current.t_T) - law.mu * current.t_N, 0.0) / scale)
    changes = int(np.count_nonzero((current.status == SLIP) != (previous.status == SLIP)))
    pressed = current.t_N > 0.0
    violation = _max_abs(current.normal_measure[pressed])
    tensile = int(np.count_nonzero(current.t_N < 0.0))
    # Without friction no multiplier acts along the surface: the tangential tests would only
    # ask the solution to settle further, for nothing an augmentation changes.
    tangential_ok = not law.frictional or (
        tangential <= tol.tangential and slip_excess <= tol.slip and changes == 0)
    ok = (normal <= tol.normal and tangential_ok
          and (tol.constraint is None or violation <= tol.constraint) and tensile == 0)
    return AugmentationCheck(normal, tangential, slip_excess, changes, violation, bool(ok),
                             tensile)


def commit_step(state: PairState, result: ContactResult, law: ContactLaw) -> PairState:
    """History after a converged step: t_T,n+1 = t_T, the release data, and the multiplier
    prediction of the next step, lambda_N = t_N (report 5.4 step 1: <lambda + eps gdot_{n-1/2}>
    is the converged t_N); penalty keeps lambda_N = 0. dlambda_T restarts at 0."""
    lam = np.zeros(len(state)) if law.method == "penalty" else result.t_N.copy()
    return replace(
        state, lambda_N=lam, dlambda_T=np.zeros(len(state)), t_T=result.t_T.copy(),
        t_N=result.t_N.copy(), gap=result.gap.copy(), gap_rate=result.gap_rate.copy(),
        slip=result.status == SLIP,
    )
