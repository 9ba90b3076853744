"""ALE bodies with several contact surfaces, and pairs whose two bodies are both ALE.

Several surfaces (one :class:`AleBody` per surface, all on the same mesh): the active nodes are
split by the surface they lie on, and the surfaces are moved one after the other, each by
:func:`move_ale_body` from the fields the previous one left. Each surface follows only its own
partners. A move frees only its own surface's nodes and interior nodes (the rest of the
boundary, the other surfaces included, keeps its place), so the surfaces do not disturb each
other; where their smoothing layers overlap (near a shared corner) the fields of a node moved by
both are interpolated twice. A node shared by two surfaces (a corner, the end of both open
chains) is a break of both chains: it never moves, and the nodes of either surface clamp before
it (``ale.motion`` item 2). Linear and angular momentum are kept by every move, hence by all.

Both bodies ALE: a pair whose two nodes both belong to ALE bodies meets at the mass-weighted
mid-point of the two particles' predicted end positions, x_meet = (m_a x_a + m_b x_b) /
(m_a + m_b) with the nodes' lumped masses: the slides that bring both to one point with the
least mass-weighted squared slide, sum m s^2 (docs/theory.md, "Several surfaces, both bodies
ALE"). A Lagrangian partner is the limit of an infinite mass, so the single-ALE rule is its
special case. The engine's use (a meeting point fixed per step, aims corrected by the last
miss) is in ``engine.mesh_motion``.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ntncontact.ale.motion import STAGES, AleBody, AleUpdate, move_ale_body

__all__ = ["check_surfaces", "meeting_points", "move_ale_surfaces", "surface_of_nodes"]


def check_surfaces(motions: Sequence[AleBody], names: Sequence[str]) -> None:
    """Raise ValueError if two surfaces of one body share a node that is not an end of both
    open chains (a shared corner): such a node would have two surfaces to slide on."""
    for i in range(len(motions)):
        for j in range(i + 1, len(motions)):
            a, b = motions[i], motions[j]
            shared = np.intersect1d(a.surface, b.surface)
            ends = np.intersect1d(_fixed_ends(a), _fixed_ends(b))
            inner = np.setdiff1d(shared, ends)
            if inner.size:
                raise ValueError(
                    f"contact surfaces '{names[i]}' and '{names[j]}' share the nodes "
                    f"{inner.tolist()[:6]} other than a common end; an ALE body's surfaces may "
                    "meet only at their end points (split them there)")


def _fixed_ends(motion: AleBody) -> NDArray[np.int64]:
    """Nodes of the chain that never slide: its ends (open chain) and its corners."""
    fixed = motion.surface[motion.corner]
    if not motion.closed:
        fixed = np.concatenate([fixed, motion.surface[[0, -1]]])
    return fixed


def surface_of_nodes(motions: Sequence[AleBody], active: NDArray[np.int64]) -> NDArray[np.int64]:
    """Index of the surface each active local node is moved with: the first surface whose
    chain holds it (a shared corner is a break of all of them, so it stays fixed anyway);
    -1 for a node on none."""
    out = np.full(active.size, -1, dtype=np.int64)
    for k in range(len(motions) - 1, -1, -1):
        index = motions[k]._surface_index[active]
        out[index >= 0] = k
    return out


def move_ale_surfaces(
    motions: Sequence[AleBody],
    X: ArrayLike,
    d: ArrayLike,
    v: ArrayLike,
    a: ArrayLike,
    active_local: ArrayLike,
    x_target: ArrayLike,
    x_pred: ArrayLike,
    dt: float,
    x_start: ArrayLike | None = None,
    least_interior: str = "none",
    least_seeds: NDArray[np.bool_] | None = None,
) -> AleUpdate:
    """:func:`move_ale_body` for a body with several contact surfaces (same arguments; the
    active nodes may lie on any of them). The surfaces move in order, each from the fields the
    previous move left; the result is one update from the given t_n fields (its mesh velocity,
    moved mask, mismatch and clamped nodes cover all surfaces)."""
    X, d, v, a = (np.asarray(f, dtype=float) for f in (X, d, v, a))
    active = np.asarray(active_local, dtype=np.int64).reshape(-1)
    target = np.asarray(x_target, dtype=float).reshape(-1, 2)
    pred = np.asarray(x_pred, dtype=float).reshape(-1, 2)
    start = (X + d)[active] if x_start is None else np.asarray(x_start, float).reshape(-1, 2)
    which = surface_of_nodes(motions, active)
    if np.any(which < 0):
        raise ValueError(f"{motions[0].name}: active nodes {active[which < 0].tolist()} are "
                         "on none of the ALE contact surfaces")
    fields = (X, d, v, a)
    updates: list[AleUpdate] = []
    for k, motion in enumerate(motions):
        mine = which == k
        if not mine.any():
            continue
        update = move_ale_body(motion, *fields, active[mine], target[mine], pred[mine], dt,
                               start[mine], least_interior, least_seeds)
        updates.append(update)
        fields = (update.X, update.d, update.v, update.a)
    if not updates:
        return move_ale_body(motions[0], X, d, v, a, active[:0], target[:0], pred[:0], dt)
    return _combined(updates, X + d, dt)


def _combined(updates: list[AleUpdate], x_old: NDArray, dt: float) -> AleUpdate:
    """One update from a chain of moves: the last fields, the whole move's mesh velocity."""
    last = updates[-1]
    moved = np.logical_or.reduce([u.moved for u in updates])
    momentum = (sum(u.momentum_change[0] for u in updates),
                sum(u.momentum_change[1] for u in updates))
    return replace(
        last, mesh_velocity=(last.x_mesh - x_old) / dt, moved=moved,
        mismatch=max(u.mismatch for u in updates),
        clamped=np.concatenate([u.clamped for u in updates]), momentum_change=momentum,
        resets=sum(u.resets for u in updates),
        interior=max((u.interior for u in updates), key=STAGES.index),
        seeds=_union([u.seeds for u in updates]))


def _union(masks: list[NDArray | None]) -> NDArray | None:
    """Elementwise or of the masks that are not None (None if all are)."""
    given = [m for m in masks if m is not None]
    return np.logical_or.reduce(given) if given else None


def meeting_points(x_own: NDArray, x_partner: NDArray, m_own: NDArray,
                   m_partner: NDArray) -> NDArray[np.float64]:
    """The mass-weighted mid-points (p, 2) of pairs of predicted positions (module doc)."""
    w = np.asarray(m_own, float) / (np.asarray(m_own, float) + np.asarray(m_partner, float))
    return w[:, None] * np.asarray(x_own, float) + (1.0 - w[:, None]) * np.asarray(x_partner,
                                                                                   float)
