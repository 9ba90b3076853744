"""Contact detection and release (report 2.1.4, 3.2).

Called once at the start of a step with the committed state of the previous step:
- an active pair is released when its normal traction vanished, t_N <= 0, and
  * persistency law: it separates, gdot < 0, for ``release_steps`` consecutive committed steps
    (the gap stays roughly frozen under persistency, so its sign says nothing, 3.2);
  * gap law: its gap opened, g < 0 (Kuhn-Tucker 2.14-2.16);
- a candidate whose surface-1 node is not active becomes active on penetration, g >= -gap_tol,
  with approach gdot > 0, i.e. (v2 - v1) . n < 0 (persistency law), or on g >= -gap_tol alone
  (gap law, "changes from negative to zero or positive", 2.1.4).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray

from .kinematics import facing, pair_gaps, rate_roundoff
from .state import PairState
from .surfaces import Interface

__all__ = ["Detection", "detect", "entering", "release_mask"]


@dataclass(frozen=True)
class Detection:
    """The updated active set and which surface-1 nodes entered or left it."""

    state: PairState
    added: NDArray[np.int64]
    released: NDArray[np.int64]


def entering(gap: NDArray[np.float64], gap_rate: NDArray[np.float64] | None,
             persistency: bool, gap_tol: float = 0.0,
             rate_tol: NDArray[np.float64] | float = 0.0) -> NDArray[np.bool_]:
    """Which candidate pairs enter the active set: penetrating (gap >= -gap_tol) and, under
    the persistency law, approaching (gdot > 0) or touching at rest (|gap| <= gap_tol and
    |gdot| <= ``rate_tol``, its round-off, :func:`rate_roundoff`: bodies placed touching at
    t = 0, at rest or sliding along each other, which a load then presses together; taken one
    step late, a block resting under gravity kept the step's fall, g dt^2 / 2, as penetration
    for the whole run). A node deeper than that with no approach is not taken: the far side of
    a ring lies "behind" its partner surface too."""
    enter = gap >= -gap_tol
    if persistency:
        # |gap_tol|: with predicted detection gap_tol < 0 (a touch to come waits), but a pair
        # touching at rest is a touch that has happened (a tester's block placed on another
        # under gravity fell a step first, and kept g dt^2 / 2 inside for the whole run)
        at_rest = ((np.abs(gap_rate) <= rate_tol)  # type: ignore[arg-type]
                   & (np.abs(gap) <= abs(gap_tol)))
        enter = (enter & (gap_rate > 0.0)) | at_rest  # type: ignore[operator]
    return enter


def release_mask(
    state: PairState, persistency: bool, release_steps: int = 2
) -> tuple[NDArray[np.bool_], NDArray[np.int64]]:
    """(released, updated release counters) for the committed pairs of ``state``."""
    vanished = state.t_N <= 0.0
    if not persistency:
        released = vanished & (state.gap < 0.0)
        return released, np.zeros(len(state), np.int64)
    separating = vanished & (state.gap_rate < 0.0)  # NaN (unknown) counts as not separating
    count = np.where(separating, state.release_count + 1, 0)
    return count >= release_steps, count


def detect(
    state: PairState,
    candidates: NDArray[np.int64],
    x: NDArray[np.float64],
    v: NDArray[np.float64] | None,
    interface: Interface,
    *,
    persistency: bool = True,
    release_steps: int = 2,
    gap_tol: float = 0.0,
    objective: bool = False,
    release: tuple[NDArray[np.bool_], NDArray[np.int64]] | None = None,
) -> Detection:
    """Release and add pairs (module docstring). ``candidates`` (C, 2) come from
    :func:`~ntncontact.contact.pairing.closest_pairs` at the step-start positions ``x`` and
    velocities ``v``. Kept pairs keep their partner and history; new pairs start fresh and are
    appended after the kept ones. ``objective``: the approach test takes the moment-free law's
    rate dg/dx . v (``ContactLaw.moment_free``), the rate that the law and the release test of
    the same pair then see; with the report's rate a pair could enter as approaching and be
    counted as separating in its first step. ``release``: :func:`release_mask` of ``state``
    with these arguments, where the caller has it (``interfaces.detect_all``, which needs it
    for its candidates)."""
    if release_steps < 1:
        raise ValueError("release_steps must be >= 1")
    if release is None:
        release = release_mask(state, persistency, release_steps)
    released, count = release
    kept = replace(state.take(~released), release_count=count[~released])
    candidates = np.asarray(candidates, dtype=np.int64).reshape(-1, 2)
    fresh = candidates[~np.isin(candidates[:, 0], kept.pairs[:, 0])]
    if persistency and v is None:
        raise ValueError("detection under the persistency law needs velocities v")
    _, gap, gap_rate = pair_gaps(x, interface, fresh, v, objective)
    rate_tol = 0.0 if v is None else rate_roundoff(x, v, interface, fresh, gap_tol)
    new = fresh[entering(gap, gap_rate, persistency, gap_tol, rate_tol)
                & facing(x, interface, fresh)]
    return Detection(kept.concat(PairState.from_pairs(new)), new[:, 0].copy(),
                     state.pairs[released, 0].copy())
