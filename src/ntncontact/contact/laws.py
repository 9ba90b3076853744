"""Constraint treatment per interface and the normal traction law (report 2.2, 2.33-2.34)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

__all__ = ["ContactLaw", "Method"]

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
    gap_restoring: under the persistency law, a pair's first step constrains gdot + g_n/dt
        instead of gdot (g_n its gap at the step start), so that it ends that step touching:
        the gap of a pair detected one step late (or early) is not frozen for the impact.
    unpaired_share: where one surface has nodes between two consecutive pairs that get no pair
        of their own (unequal node counts), they take their share of the pairs' forces by dual
        mortar weights (``contact/transfer.py``); False: the report's point forces on the pairs.
    """

    method: Method = "augmented_lagrangian"
    eps_N: float = 0.0
    eps_T: float = 0.0
    mu: float = 0.0
    moment_free: bool = False
    gap_restoring: bool = False
    unpaired_share: bool = False

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
        """Frictionless augmented Lagrangian: where pairs may be held on the pressed branch
        (``evaluate._normal_traction``) and quasi-static multipliers may be extrapolated
        (``augmentation.extrapolated_update``)."""
        return self.method == "augmented_lagrangian" and not self.frictional
