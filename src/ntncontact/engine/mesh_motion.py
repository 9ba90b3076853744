"""ALE bodies in the time loop: move each ALE mesh so its contact nodes meet their partners.

Called at every augmentation of a step (report 5.4 step 2) with the ORIGINAL t_n state, the
active pairs and the predicted end-of-step positions of all nodes from the last iterate (see
:mod:`ntncontact.ale.motion` for the operator-split formulation: remap at t_n, then a plain
Lagrangian step, hence no convective term).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray

from ..ale.motion import AleUpdate, move_ale_body
from ..contact import PairState
from ..jit import njit
from .model import AleSetup, Model
from .problem import StepState
from .remap_conservation import conserve_remap


@dataclass(frozen=True)
class MeshMotion:
    """The moved t_n state and, per ALE body, its update (None where nothing moved)."""

    state: StepState
    updates: tuple[AleUpdate | None, ...]
    # per ALE body: (active nodes, partners, wanted positions) the update was made for
    requests: tuple = ()

    @property
    def mismatch(self) -> float:
        return max([u.mismatch for u in self.updates if u is not None] or [0.0])


def _ale_nodes_and_partners(setup: AleSetup, contact: Sequence[PairState]):
    """Active global nodes of this ALE body and their partners, over all interfaces: per
    interface the pairs whose body-2 node is the body's first (the report moves the body-2
    node), then those whose body-1 node is; a node listed again keeps its first partner.
    Compiled (``_body_pairs``, ``_first_occurrences``): called at every augmentation with a
    few pairs, where NumPy's per-call overhead dominated."""
    lo, hi = setup.node_offset, setup.node_offset + setup.n_nodes
    found = [_body_pairs(np.ascontiguousarray(state.pairs, dtype=np.int64), lo, hi)
             for state in contact]
    if len(found) == 1:
        own, partner = found[0]
    elif not found:
        own = partner = np.zeros(0, np.int64)
    else:
        own = np.concatenate([f[0] for f in found])
        partner = np.concatenate([f[1] for f in found])
    first = _first_occurrences(own)
    return own[first], partner[first]


def move_meshes(
    model: Model, base: StepState, contact: Sequence[PairState], x_pred: NDArray, dt: float,
    previous: MeshMotion | None,
) -> MeshMotion:
    """Move every ALE body of ``model`` from the t_n state ``base``.

    ``x_pred`` (n, 2): predicted end-of-step position of the particle at each node of the mesh
    that produced the last iterate (``previous``; the unmoved mesh when None).
    """
    X, d, v, a = (arr.copy() for arr in (base.X, base.d, base.v, base.a))
    updates, requests = [], []
    for i, setup in enumerate(model.ale_bodies):
        nodes, partners = _ale_nodes_and_partners(setup, contact)
        if nodes.size == 0:
            updates.append(None)
            requests.append(None)
            continue
        rows = slice(setup.node_offset, setup.node_offset + setup.n_nodes)
        prev = previous.updates[i] if previous is not None else None
        x_start = prev.x_mesh[nodes - setup.node_offset] if prev is not None else base.x[nodes]
        # where the active node must sit at t_n so that its particle ends on the partner
        wanted = x_pred[partners] - (x_pred[nodes] - x_start)
        request = (nodes, partners, wanted)
        if prev is not None and _same_request(previous.requests[i], request, setup):
            up, request = prev, previous.requests[i]  # the move would be below its tolerance
        else:
            up = move_ale_body(setup.motion, base.X[rows], base.d[rows], base.v[rows],
                               base.a[rows], nodes - setup.node_offset, x_pred[partners],
                               x_pred[nodes], dt, x_start)
            # momenta and energy exactly as the time loop measures them (docs/theory.md)
            up = conserve_remap(model, setup, base.X, base.d, base.v, base.time, up)
        X[rows], d[rows], v[rows], a[rows] = up.X, up.d, up.v, up.a
        updates.append(up)
        requests.append(request)
    return MeshMotion(replace(base, X=X, d=d, v=v, a=a), tuple(updates), tuple(requests))


def _same_request(old, new, setup: AleSetup) -> bool:
    """True if the same pairs want positions within the body's slide tolerance of the last
    request: the move would then change no node by more than that tolerance allows (the later
    augmentations of a step, whose predictions agree to ~1e-10 of an element)."""
    if old is None or not (np.array_equal(old[0], new[0]) and np.array_equal(old[1], new[1])):
        return False
    motion = setup.motion
    return float(np.abs(new[2] - old[2]).max()) <= motion.slide_tolerance * motion.min_spacing


@njit(cache=True)
def _body_pairs(pairs, lo, hi):
    """(own node, partner) of the pairs (m, 2) with a node in [lo, hi): first the pairs whose
    body-2 node (column 1) is there, then those whose body-1 node is, each in pair order."""
    m = pairs.shape[0]
    count = 0
    for side in (1, 0):
        for r in range(m):
            count += lo <= pairs[r, side] < hi
    own = np.empty(count, np.int64)
    partner = np.empty(count, np.int64)
    c = 0
    for side in (1, 0):
        for r in range(m):
            if lo <= pairs[r, side] < hi:
                own[c], partner[c] = pairs[r, side], pairs[r, 1 - side]
                c += 1
    return own, partner


@njit(cache=True)
def _first_occurrences(values):
    """Indices (ascending) of the first occurrence of each value: ``np.sort(np.unique(values,
    return_index=True)[1])``."""
    order = np.argsort(values, kind="mergesort")  # stable: equal values in index order
    keep = np.zeros(values.size, np.bool_)
    for k in range(values.size):
        if k == 0 or values[order[k]] != values[order[k - 1]]:
            keep[order[k]] = True
    return np.flatnonzero(keep)
