"""Constraint treatment per interface and the normal traction law (report 2.2, 2.33-2.34)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np
from numpy.typing import NDArray

__all__ = ["ContactLaw", "Method", "held_pairs", "normal_traction"]

Method = Literal["penalty", "augmented_lagrangian", "lagrange"]
_METHODS = ("penalty", "augmented_lagrangian", "lagrange")


@dataclass(frozen=True)
class ContactLaw:
    """How an interface enforces contact.

    method: "penalty" (lambda_N = 0 always, 2.27), "augmented_lagrangian" (nested
        multiplier updates of report 5.4, 2.30-2.43) or "lagrange" (exact normal multipliers in a
        bordered system; friction stays penalty-regularized with eps_T).
    eps_N: normal penalty (2.27, 2.33-2.34); unused by "lagrange".
    eps_T: tangential penalty (2.35-2.41); friction is off when eps_T or mu is 0.
    mu: Coulomb coefficient mu_f (2.20).
    moment_free: give each pair's force the full variation of its gap and tangential offset,
        F = L_c (t_N dg/dx + t_T ds/dx) with g = (x_i - x_j).n, s = (x_i - x_j).e, instead of
        the report's L_c (t_N n + t_T e) on nodes i and j only. The extra part is a couple on the
        nodes of the normal's chord that cancels the pair's moment (x_i - x_j) x F, so contact
        conserves angular momentum exactly under the mid-point rule (docs/theory.md,
        "Moment-free pair forces").
    """

    method: Method = "augmented_lagrangian"
    eps_N: float = 0.0
    eps_T: float = 0.0
    mu: float = 0.0
    moment_free: bool = False

    def __post_init__(self) -> None:
        if self.method not in _METHODS:
            raise ValueError(f"unknown contact method {self.method!r}; use one of {_METHODS}")
        if min(self.eps_N, self.eps_T, self.mu) < 0.0:
            raise ValueError("eps_N, eps_T and mu must be non-negative")
        if self.method != "lagrange" and self.eps_N <= 0.0:
            raise ValueError(f"method {self.method!r} needs a positive normal penalty eps_N")

    @property
    def frictional(self) -> bool:
        return self.mu > 0.0 and self.eps_T > 0.0

    @property
    def frictionless_augmented(self) -> bool:
        """Frictionless augmented Lagrangian: where pairs may be held (:func:`held_pairs`) and
        multipliers may take Newton updates (``augmentation.newton_update``)."""
        return self.method == "augmented_lagrangian" and not self.frictional

    @property
    def uses_multipliers(self) -> bool:
        return self.method != "penalty"


def normal_traction(
    law: ContactLaw, lambda_N: NDArray[np.float64], measure: NDArray[np.float64]
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """t_N and dt_N/d(measure) per pair.

    measure is g (gap law, 2.33) or gdot (persistency law, 2.34): t_N = <lambda_N + eps_N measure>
    (lambda_N = 0 for penalty). "lagrange": t_N = lambda_N, the multiplier itself, WITHOUT the
    Macaulay bracket, so Newton sees a smooth system; its sign is checked after the solve.

    A pair held by its multiplier (:func:`held_pairs`) takes lambda_N + eps_N measure without
    the bracket as well: within one augmentation's Newton solve its traction may turn tensile,
    and the augmentation test (``augmentation.check_augmentation``) only accepts a solution
    where it has not, so converged tractions are those of the bracketed law.
    """
    if law.method == "lagrange":
        return np.asarray(lambda_N, dtype=float).copy(), np.zeros_like(measure)
    base = 0.0 if law.method == "penalty" else lambda_N
    trial = base + law.eps_N * measure
    # An active pair exactly at the kink (touching, g = 0) takes the pressed branch's
    # derivative: otherwise a body held only by contact has a singular tangent at first touch.
    pressed = (trial >= 0.0) | held_pairs(law, lambda_N)
    return np.where(pressed, trial, 0.0), np.where(pressed, law.eps_N, 0.0)


def held_pairs(law: ContactLaw, lambda_N: NDArray[np.float64]) -> NDArray[np.bool_]:
    """Pairs kept on the pressed branch of the normal law during a Newton solve: frictionless
    augmented-Lagrangian pairs with a positive multiplier (a fixed active set per
    augmentation, a semi-smooth Newton step on the bracket).

    Why: such a pair that starts a solve separating (lambda_N + eps_N gdot < 0 at the initial
    guess) contributes neither force nor stiffness there, so the Newton step drives it deep into
    penetration and its traction jumps to ~10x its value; the line search then backtracks and
    the Jacobian is factored again. On the ring impact (report 6.4) this happened in about a
    third of the fresh Newton steps. Frictional pairs are left bracketed: a tensile t_N would
    flip the sign of the Coulomb limit mu t_N."""
    lambda_N = np.asarray(lambda_N, dtype=float)
    if not law.frictionless_augmented:
        return np.zeros(lambda_N.shape, dtype=bool)
    return lambda_N > 0.0
