"""Per-pair contact history carried from step to step (active set, multipliers, friction)."""

from __future__ import annotations

from dataclasses import dataclass, fields, replace

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = ["PairState"]


@dataclass(frozen=True)
class PairState:
    """The active set and its per-pair history; arrays aligned with ``pairs`` (P, 2).

    pairs: (node1 on surface 1, node2 on surface 2), global node indices; node1 is unique.
    lambda_N: normal multipliers used in the current step (traction units; 0 for penalty;
        the unknown multipliers themselves for "lagrange").
    dlambda_T: tangential multiplier increment Delta lambda_T of the current step (2.40).
    t_T: converged tangential traction at the step start, t_T,n (scalar along e).
    t_N, gap, gap_rate, slip: converged values of the last committed step (release test and
        direction-reversal rule); gap_rate is NaN when unknown.
    release_count: consecutive committed steps with t_N = 0 while separating (3.2).
    """

    pairs: NDArray[np.int64]
    lambda_N: NDArray[np.float64]
    dlambda_T: NDArray[np.float64]
    t_T: NDArray[np.float64]
    t_N: NDArray[np.float64]
    gap: NDArray[np.float64]
    gap_rate: NDArray[np.float64]
    slip: NDArray[np.bool_]
    release_count: NDArray[np.int64]

    def __post_init__(self) -> None:
        pairs = np.asarray(self.pairs, dtype=np.int64).reshape(-1, 2)
        object.__setattr__(self, "pairs", pairs)
        for f in fields(self)[1:]:
            value = np.asarray(getattr(self, f.name))
            if value.shape != (len(pairs),):
                raise ValueError(f"PairState.{f.name} must have shape ({len(pairs)},)")
        if np.unique(pairs[:, 0]).size != len(pairs):
            raise ValueError("a surface-1 node appears in two pairs")

    @classmethod
    def from_pairs(cls, pairs: ArrayLike) -> PairState:
        """Fresh pairs: no multipliers, no friction history."""
        pairs = np.asarray(pairs, dtype=np.int64).reshape(-1, 2)
        zero = np.zeros(len(pairs))
        return cls(pairs, zero, zero, zero, zero, zero, np.full(len(pairs), np.nan),
                   np.zeros(len(pairs), bool), np.zeros(len(pairs), np.int64))

    @classmethod
    def empty(cls) -> PairState:
        return cls.from_pairs(np.zeros((0, 2), np.int64))

    def __len__(self) -> int:
        return int(self.pairs.shape[0])

    def take(self, index: ArrayLike) -> PairState:
        """The pairs selected by an index or boolean mask, with their history."""
        return PairState(*(np.asarray(getattr(self, f.name))[index] for f in fields(self)))

    def concat(self, other: PairState) -> PairState:
        return PairState(*(np.concatenate((getattr(self, f.name), getattr(other, f.name)))
                           for f in fields(self)))

    def with_multipliers(self, lambda_N: ArrayLike) -> PairState:
        """Same pairs with new normal multipliers (what a Lagrange solver iterates on)."""
        return replace(self, lambda_N=np.asarray(lambda_N, dtype=float))
