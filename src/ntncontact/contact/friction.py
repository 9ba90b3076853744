"""Non-classical Coulomb friction in augmented Lagrangian form: return mapping (2.35)-(2.43).

In 2D the tangential traction is a scalar t_T along the pair's tangent e (2.7), so
trial/|trial| is a sign. The trial traction is

    t_T^trial = t_T,n + dLambda_T + eps_T * s,     (2.41)

with s = gdot_T (rate law, 2.10) or s = delta g_T, the tangential relative displacement since the
step start (gap law). The pair slips if phi = |t^trial| - mu t_N > 0 (2.42-2.43), and then
t_T = mu t_N sign(t^trial) (2.39).

Direction-reversal rule (report 3.3.2): a pair whose trial traction would slip AGAINST its
current tangential motion (s * t^trial < 0) has reversed its sliding direction relative to the
traction it carried from the previous step; the report lets it stick for that step
(gdot_T taken as 0). It is flagged STICK, and its traction is kept in the Coulomb cone,
t_T = mu t_N sign(t^trial). With this rule every SLIP pair has t_T * s >= 0, so the
frictional dissipation (3.18) is non-negative by construction. A reversal that overshoots (the
trial already points along the new motion) slips in the new direction and dissipates.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

__all__ = ["STICK", "SLIP", "ReturnMapping", "frictional_dissipation", "return_mapping"]

STICK = np.int8(0)
SLIP = np.int8(1)


@dataclass(frozen=True)
class ReturnMapping:
    """Result of the return mapping for P pairs.

    t_T = traction; d_t_T = d_slip * d(slip measure) + d_normal * d(t_N) gives its derivative
    (d_slip = eps_T for stick, 0 otherwise; d_normal = mu sign(trial) where the cone is active).
    """

    traction: NDArray[np.float64]
    trial: NDArray[np.float64]
    status: NDArray[np.int8]
    reversed: NDArray[np.bool_]
    d_slip: NDArray[np.float64]
    d_normal: NDArray[np.float64]


def return_mapping(
    t_prev: NDArray[np.float64],
    dlambda: NDArray[np.float64],
    slip_measure: NDArray[np.float64],
    t_N: NDArray[np.float64],
    mu: float,
    eps_T: float,
) -> ReturnMapping:
    """Coulomb return mapping (2.39)-(2.43) with the reversal rule of 3.3.2 (module doc).

    With ``mu == 0`` or ``eps_T == 0`` the interface is frictionless: t_T = 0, status SLIP.
    """
    p = np.shape(t_N)
    if mu == 0.0 or eps_T == 0.0:
        zero = np.zeros(p)
        return ReturnMapping(zero, zero, np.full(p, SLIP), np.zeros(p, bool), zero, zero)
    trial = t_prev + dlambda + eps_T * slip_measure
    limit = mu * t_N
    # an unloaded pair (t_N = 0) carries no friction: treat it as sliding, not as stuck at 0;
    # except at trial = 0 (first touch, no slip yet), where the stick branch's stiffness keeps
    # a body held only by friction from being singular in its first Newton iteration
    beyond = (np.abs(trial) > limit) | ((limit <= 0.0) & (trial != 0.0))
    # trial beyond the cone yet pointing against the motion: the sliding direction reversed
    reversed_ = beyond & (slip_measure * trial < 0.0)
    slip = beyond & ~reversed_
    sign = np.sign(trial)
    traction = np.where(beyond, limit * sign, trial)
    d_slip = np.where(beyond, 0.0, eps_T)
    d_normal = np.where(beyond, mu * sign, 0.0)
    status = np.where(slip, SLIP, STICK).astype(np.int8)
    return ReturnMapping(traction, trial, status, reversed_, d_slip, d_normal)


def frictional_dissipation(
    traction: NDArray[np.float64],
    slip_measure: NDArray[np.float64],
    length: NDArray[np.float64],
    status: NDArray[np.int8],
    dt: float | None = None,
) -> float:
    """Work dissipated by friction over the step, sum over SLIP pairs of t_T delta g_T L_c
    (3.17)-(3.18). Under the rate law ``slip_measure`` is gdot_T and delta g_T = gdot_T dt.

    STICK pairs are not counted: the report treats them as not sliding (gdot_T = 0, 3.3.2);
    the regularized elastic part eps_T of their motion is stored, not dissipated.
    """
    increment = slip_measure * (1.0 if dt is None else dt)
    return float(np.sum(np.where(status == SLIP, traction * increment * length, 0.0)))
