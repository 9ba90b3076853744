"""ALE bodies in the time loop: move each ALE mesh so its contact nodes meet their partners.

Called at every augmentation of a step (report 5.4 step 2) with the ORIGINAL t_n state, the
active pairs and the predicted end-of-step positions of all nodes from the last iterate (see
:mod:`ntncontact.ale.motion` for the operator-split formulation: remap at t_n, then a plain
Lagrangian step, hence no convective term).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field, replace

import numpy as np
from numpy.typing import NDArray

from ..ale.motion import AleCrossingError, AleMotionError, AleUpdate, lumped_masses, move_ale_body
from ..ale.multisurface import meeting_points, move_ale_surfaces, surface_of_nodes
from ..contact import PairState, pair_gaps
from ..jit import njit
from ..mesh.boundary import chain_edge_lengths
from ..mesh.quadmesh import MeshError
from .model import AleSetup, Model
from .problem import StepState
from .remap_conservation import conserve_remap, hand_over_energy

#: Active ALE nodes end their step on their partners to this fraction of the surface spacing
#: (``mesh_settled``): the augmentations go on until the mesh motion settles this far.
SETTLED = 1e-7
#: a pair whose predicted gap exceeds this fraction of the ALE surface's smallest spacing
#: slides along the ALE surface's own normal, not the pair's (``_request``)
DEEP = 0.5


@dataclass(frozen=True)
class MeshMotion:
    """The moved t_n state and, per ALE body, its update (None where nothing moved)."""

    state: StepState
    updates: tuple[AleUpdate | None, ...]
    # per ALE body: (active nodes, partners, wanted positions) the update was made for
    requests: tuple = ()
    #: meeting points of the step's pairs between two ALE bodies, (node, node) -> (2,) array
    meetings: dict = field(default_factory=dict)
    #: (ALE node, partner) -> whether the pair slides as a deep one (``_request``), decided
    #: at the pair's first request of the step
    deep: dict = field(default_factory=dict)
    #: (ALE node, partner) of the step's open pairs that are not followed: their partners
    #: crossed a neighbour's (``_move_body``), so their nodes are respaced instead
    unfollowed: frozenset = frozenset()
    #: kinetic energy the remaps' conservation could neither take from the ALE bodies nor
    #: hand over to a Lagrangian one (``hand_over_energy``): what the total energy gained
    unreturned_energy: float = 0.0

    @property
    def mismatch(self) -> float:
        return max([u.mismatch for u in self.updates if u is not None] or [0.0])

    @property
    def remap_strain_change(self) -> float:
        """Strain energy the remaps changed (W after - W before, summed over the bodies)."""
        return sum(u.remap_strain_change for u in self.updates if u is not None)


def _ale_nodes_and_partners(setup: AleSetup, contact: Sequence[PairState]):
    """Active global nodes of this ALE body and their partners, over all interfaces: per
    interface the pairs whose body-2 node is the body's first (the report moves the body-2
    node), then those whose body-1 node is; a node listed again keeps its first partner.
    Compiled (``_body_pairs``, ``_first_occurrences``): called at every augmentation with a
    few pairs, where NumPy's per-call overhead dominated."""
    lo, hi = setup.node_offset, setup.node_offset + setup.n_nodes
    found = [_body_pairs(np.ascontiguousarray(state.pairs, dtype=np.int64), lo, hi)
             for state in contact]
    none = [np.zeros(0, np.int64)]
    own = np.concatenate([f[0] for f in found] or none)
    partner = np.concatenate([f[1] for f in found] or none)
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
    masses = _AleMasses(model, base, dict(previous.meetings) if previous is not None else {})
    deep = dict(previous.deep) if previous is not None else {}
    unfollowed = set(previous.unfollowed) if previous is not None else set()
    for i, setup in enumerate(model.ale_bodies):
        nodes, partners = _ale_nodes_and_partners(setup, contact)
        last = ((previous.updates[i], previous.requests[i]) if previous is not None
                else (None, None))
        up, request = _move_body(model, setup, base, last, contact, nodes, partners, x_pred,
                                 dt, (masses, deep, unfollowed)) or (None, None)
        updates.append(up)
        requests.append(request)
        if up is not None:
            rows = slice(setup.node_offset, setup.node_offset + setup.n_nodes)
            X[rows], d[rows], v[rows], a[rows] = up.X, up.d, up.v, up.a
    left = sum(up.energy_left for up in updates if up is not None)
    if left != 0.0:  # an ALE body too slow to give back what its remap changed
        owner = model.body_of_node()
        partners = frozenset(int(b) for request in requests if request is not None
                             for b in np.unique(owner[request[1]]))
        v, left = hand_over_energy(model, base.time, X, X + d, v, left, partners)
    return MeshMotion(replace(base, X=X, d=d, v=v, a=a), tuple(updates), tuple(requests),
                      masses.meetings, deep, frozenset(unfollowed), left)


def without_unfollowed(contact: Sequence[PairState], unfollowed: frozenset
                       ) -> tuple[PairState, ...] | None:
    """The active sets less the pairs the mesh motion does not follow, or None if it follows
    them all. An unfollowed pair cannot end node to node, so it must carry no force: it was
    open at the prediction, but under the persistency law a pair's traction goes by its rate,
    not its gap (the 4x fast sliding, mu = 0.2, t = 0.141: 11.2 of traction on a pair 0.5 of
    the spacing off node to node), and a pair predicted open can end closed (t = 0.123: 83).
    So the step is solved again without them: they are released (docs/theory.md, "Partners
    that cross"), and detection takes their nodes in again where they touch."""
    if not unfollowed:
        return None
    keys = unfollowed | {(b, a) for a, b in unfollowed}
    kept = [np.array([(int(a), int(b)) not in keys for a, b in state.pairs], bool)
            for state in contact]
    if all(k.all() for k in kept):
        return None
    return tuple(state.take(k) for state, k in zip(contact, kept, strict=True))


def _move_body(model: Model, setup: AleSetup, base: StepState, last: tuple,
               contact: Sequence[PairState], nodes: NDArray, partners: NDArray,
               x_pred: NDArray, dt: float, step: tuple) -> tuple[AleUpdate, tuple] | None:
    """(update, request) of one ALE body, or None with no pair to follow. ``last``: the
    body's previous (update, request) in this step; ``step``: the step's decisions so far
    (masses and meeting points, deep pairs, unfollowed pairs), which this call extends.

    Where the partners of two ALE nodes cross (a partner that lifts off and passes a
    neighbour held in place, as the leading corner of a block sliding with friction), no
    motion keeps both nodes under their partners. An open pair (predicted gap < 0) carries
    no force along its normal, so its node need not follow: it is dropped from the move for
    the rest of the step and respaced between the nodes that do follow (docs/theory.md,
    "Partners at any spacing ratio"), and the caller releases it (``without_unfollowed``).
    A crossing between pressed pairs still raises."""
    masses, deep, unfollowed = step
    prev, prev_request = last
    rows = slice(setup.node_offset, setup.node_offset + setup.n_nodes)
    while True:
        own, partner = _followed(nodes, partners, unfollowed)
        if own.size == 0:
            return None
        targets, meet = _targets(masses, own, partner, x_pred)
        x_start, request, is_open = _request(model, setup, base, prev, contact, own, partner,
                                             x_pred, targets, meet, deep)
        if prev is not None and _same_request(prev_request, request, setup):
            return prev, prev_request  # the move would be below its tolerance
        # the target as the move takes it: wanted = target - (end - start)
        target = request[2] + x_pred[own] - x_start
        try:
            up = _moved(setup, base, rows, own, target, x_pred[own], dt, x_start, prev)
        except AleCrossingError as err:
            crossing = (np.isin(own - setup.node_offset, err.nodes) & is_open
                        & ~_pressed(model, contact, own, partner))
            if not crossing.any():
                raise _crossing_with_partners(err, model, base, own - setup.node_offset,
                                              partner, x_pred, setup.node_offset) from None
            unfollowed.update(zip(own[crossing].tolist(), partner[crossing].tolist(), strict=True))
            continue
        _hold_clamped(masses, own, partner, up.clamped + setup.node_offset)
        # momenta and energy exactly as the time loop measures them (docs/theory.md)
        return conserve_remap(model, setup, base.X, base.d, base.v, base.time, up,
                              own - setup.node_offset), request


#: a partner surface shortened below this fraction of its reference length between two
#: crossing partners is reported as crushed (4x fast sliding with mu = 0.2: 2 %)
_CRUSHED = 0.1


def _pressed(model: Model, contact: Sequence[PairState], own: NDArray, partner: NDArray
             ) -> NDArray:
    """Which of the pairs (own, partner) carry force. A multiplier keeps force on a pair under
    either law (t_N = <lambda + eps g> or <lambda + eps gdot>). Under the gap law the
    predicted gap tells the rest; under the persistency law it does not: the traction goes by
    the rate, so a pair with traction at t_n is pressed, and a chattering corner's prediction
    misleads (the 4x fast sliding, mu = 0.2, t = 0.120: the corner pair, 241 of traction,
    predicted 5e-3 open)."""
    force = {}
    for ci, state in zip(model.interfaces, contact, strict=True):
        carries = state.lambda_N > 0.0
        if ci.persistency:
            carries = carries | (state.t_N > 0.0)
        for (a, b), c in zip(state.pairs.tolist(), carries.tolist(), strict=True):
            force[(a, b)] = force[(b, a)] = c
    keys = zip(own.tolist(), partner.tolist(), strict=True)
    return np.array([force.get(key, False) for key in keys], bool)


def _crossing_with_partners(err: AleCrossingError, model: Model, base: StepState,
                            local: NDArray, partners: NDArray, x_pred: NDArray, offset: int
                            ) -> AleCrossingError:
    """``err`` with what its partners did. Where the partner body's surface between the two
    partners is crushed (shorter than ``_CRUSHED`` of its reference length at the step start
    or at its end), its own mesh folds there (as a block's leading corner held by friction:
    fast sliding refined 4x, mu = 0.2), which no ALE motion can follow: the message says so,
    instead of only suggesting a finer ALE surface or a smaller dt."""
    found = [np.flatnonzero(local == n) for n in err.nodes]
    if any(f.size == 0 for f in found):
        return err
    pa, pb = (int(partners[f[0]]) for f in found)
    reference = float(np.linalg.norm(model.X0[pb] - model.X0[pa]))
    x_start = base.X + base.d
    now = min(np.linalg.norm(x_start[pb] - x_start[pa]), np.linalg.norm(x_pred[pb] - x_pred[pa]))
    if not now < _CRUSHED * reference:
        return _with_spacing_advice(err, model, int(local[found[0][0]]) + offset, pa)
    body = model.body_at(pa)
    where = " and ".join(f"({x_start[n, 0]:.6g}, {x_start[n, 1]:.6g})" for n in (pa, pb))
    message = (f"{err}. But their partners, nodes {pa - body.node_offset} and "
               f"{pb - body.node_offset} of body '{body.name}' (at {where}), are "
               f"{now / reference:.1%} of their reference distance apart: that body's surface "
               "folds between them and its elements there are crushed (for example a sharp "
               "corner held by friction, which folds sooner on finer meshes). If a smaller dt "
               "fails at the same time, the fold is the body's response, not the ALE's: if the "
               "face beside the corner comes down onto this body, join it to the contact "
               "surface (for example surface_1 = \"bottom+right\"); if its corner cell lies "
               f"flat, make body '{body.name}' ALE as well (its mesh then moves too; "
               "docs/examples.md, \"Refined meshes\"); else round the corner, lower the "
               "friction, or use a coarser mesh there")
    return AleCrossingError(message, err.nodes)


#: an ALE surface up to this many times coarser than its partner gives each ALE node one
#: partner nearby (docs/theory.md, "Partners at any spacing ratio")
_COARSER = 2.0


def _with_spacing_advice(err: AleCrossingError, model: Model, node: int, partner: int
                         ) -> AleCrossingError:
    """``err`` with the advice to refine the ALE surface (or coarsen the partner) where the
    ALE surface of global ``node`` is more than ``_COARSER`` times coarser than the surface of
    its ``partner`` (median edge lengths in the original mesh): only then do several partner
    nodes share an ALE node's reach. A tester's spinning ALE disk in a ring (spacings 0.098
    and 0.098) was told to refine anyway; halving dt was what helped."""
    ale, other = _median_spacing(model, node), _median_spacing(model, partner)
    if not ale > _COARSER * other:
        return err
    return AleCrossingError(
        f"{err}, or refine the ALE surface to at most {_COARSER:g}x the partner surface's "
        f"spacing (now {ale:.3g} against {other:.3g}; or coarsen the partner) so that each "
        "ALE node has one partner nearby", err.nodes)


def _median_spacing(model: Model, node: int) -> float:
    """Median edge length, in the original mesh, of the first contact surface that holds
    global ``node`` (NaN on none)."""
    for ci in model.interfaces:
        for surface in (ci.interface.surface1, ci.interface.surface2):
            if node in surface.nodes:
                return float(np.median(chain_edge_lengths(model.X0[surface.nodes],
                                                          surface.closed)))
    return float("nan")


class _AleMasses:
    """Which global nodes belong to an ALE body, (built when first asked) the lumped masses
    of the ALE bodies' nodes on the t_n reference coordinates, and the step's meeting points
    of pairs between two ALE bodies."""

    def __init__(self, model: Model, base: StepState, meetings: dict) -> None:
        self.model, self.base, self.meetings = model, base, meetings
        self.is_ale = _on_ale(model)
        self._mass: NDArray | None = None

    @property
    def mass(self) -> NDArray:
        if self._mass is None:
            self._mass = np.zeros(len(self.base.X))
            for setup in self.model.ale_bodies:
                rows = slice(setup.node_offset, setup.node_offset + setup.n_nodes)
                self._mass[rows] = lumped_masses(self.base.X[rows], setup.motion.cells,
                                                 setup.motion.cell_density)
        return self._mass


def _followed(nodes: NDArray, partners: NDArray, unfollowed: set | frozenset
              ) -> tuple[NDArray, NDArray]:
    """The (nodes, partners) of the pairs the mesh follows: all but the step's unfollowed."""
    if not unfollowed:
        return nodes, partners
    follow = np.array([(int(n), int(p)) not in unfollowed
                       for n, p in zip(nodes, partners, strict=True)], bool)
    return nodes[follow], partners[follow]


def _targets(masses: _AleMasses, nodes: NDArray, partners: NDArray, x_pred: NDArray
             ) -> tuple[NDArray, NDArray[np.bool_]]:
    """Where each active node's particle must end, and which pairs meet at a point between two
    ALE bodies: on its partner's predicted position, or, when the partner is on an ALE body
    too, at the two particles' mass-weighted mid-point (``ale.multisurface``; both bodies'
    nodes then meet there). A pair held by one of its nodes (``_hold_clamped``) is one with
    a Lagrangian partner: the held node stays, the other follows it."""
    targets = x_pred[partners]
    meet = masses.is_ale[partners].copy()
    for k in np.flatnonzero(meet):
        held = masses.meetings.get(("held", _pair_key(nodes[k], partners[k])))
        if held is not None:
            meet[k] = False
            targets[k] = x_pred[held]
    both = np.flatnonzero(meet)
    if both.size == 0:
        return targets, meet
    # The meeting point is fixed for the step when the pair first appears (from that
    # augmentation's predictions): each body then converges to it like a single ALE body to
    # a Lagrangian partner. Recomputed from every iterate it drifted by the two bodies'
    # landing errors (each slides along its own surface's normals) at every augmentation,
    # and the augmentations did not converge (docs/theory.md, "Several surfaces, both bodies
    # ALE").
    keys = [_pair_key(a, b) for a, b in zip(nodes[both], partners[both], strict=True)]
    new = [k for k, key in zip(both, keys, strict=True) if key not in masses.meetings]
    if new:
        m = masses.mass
        new = np.array(new)
        points = meeting_points(x_pred[nodes[new]], x_pred[partners[new]], m[nodes[new]],
                                m[partners[new]])
        for k, point in zip(new, points, strict=True):
            masses.meetings[_pair_key(nodes[k], partners[k])] = point
    for k, key in zip(both, keys, strict=True):
        targets[k] = masses.meetings[key]
    return targets, meet


def _pair_key(a: int, b: int) -> tuple[int, int]:
    """A pair's key in the step's meeting records: its two global nodes, either order."""
    return int(min(a, b)), int(max(a, b))


def _hold_clamped(masses: _AleMasses, own: NDArray, partner: NDArray, clamped: NDArray
                  ) -> None:
    """Mark the pairs between two ALE bodies whose node on this body was clamped (before a
    break, or by the stretch bound): for the rest of the step that node stays, as if on a
    Lagrangian body, and its partner follows it (``_targets``), so the partner body takes
    the slide this one cannot make and the pair stays node to node."""
    if clamped.size == 0:
        return
    held = np.isin(own, clamped) & masses.is_ale[partner]
    for a, b in zip(own[held].tolist(), partner[held].tolist(), strict=True):
        masses.meetings.setdefault(("held", _pair_key(a, b)), a)  # one side holds


def _request(model: Model, setup: AleSetup, base: StepState, prev: AleUpdate | None,
             contact: Sequence[PairState], nodes: NDArray, partners: NDArray, x_pred: NDArray,
             targets: NDArray, both_ale: NDArray, deep: dict) -> tuple[NDArray, tuple, NDArray]:
    """(t_n positions of the active nodes' particles, the move's request: active nodes,
    partners and where each node must sit at t_n so that its particle ends on its partner,
    which pairs are open: predicted gap < 0).

    Node to node means no offset across the contact normal n (the pair's normal at the end
    of the step, as the contact kernel takes it); the offset along n is the gap, which
    contact, not the mesh, closes. So the node slides along its t_n surface by the predicted
    end offset's part across n, measured along the surface's end-of-step chord and laid on
    its t_n chord (the surface may turn over the step). At the fixed point of the
    augmentations (``mesh_settled``) that part vanishes. ``targets``: where each particle must
    end (``_targets``); a pair between two ALE bodies (``both_ale``) slides its node to its
    meeting point across its own surface's normal, as an open pair (below). ``deep``: the
    step's (node, partner) -> deep decisions so far; a pair met first here is entered."""
    x_start = prev.x_mesh[nodes - setup.node_offset] if prev is not None else base.x[nodes]
    x_mesh = base.x if prev is None else _placed(base.x, prev.x_mesh, setup)
    normal = _contact_normals(model, contact, x_pred, nodes)
    offset = targets - x_pred[nodes]
    chord_start, chord_end = (_surface_chords(setup, nodes, y) for y in (x_mesh, x_pred))
    # a predicted end deeper than DEEP x the spacing inside the body (a first step at high
    # speed) is no contact configuration, and the pair normal there no line of action: the
    # node then slides by the offset along its own surface, as the normal foot gives it
    # an open pair (predicted gap < 0) carries no force along n: its node then sits under
    # its partner along the ALE surface's own normal. So does a node meeting a node of
    # another ALE body: the point lies between the two surfaces, and each node's particle
    # lands at the foot of its own surface's normal from it; the slide is the tangential miss
    # alone, so the next augmentation's slide is what the last one left (aimed with the
    # whole offset and a miss correction beside it, the two corrections added up and the
    # landing overshot: 12 augmentations a contact step instead of 7, fast sliding, mu 0.2)
    own = np.column_stack([chord_end[:, 1], -chord_end[:, 0]])
    along_n = np.einsum("ij,ij->i", offset, normal)  # the predicted gap
    keep = (along_n >= 0.0) & ~_deep_pairs(deep, nodes, partners,
                                            along_n > DEEP * setup.motion.min_spacing)
    slides_own = ~keep | both_ale
    normal[slides_own] = own[slides_own]
    across = offset - np.einsum("ij,ij->i", offset, normal)[:, None] * normal
    slide = np.einsum("ij,ij->i", across, chord_end)
    wanted = x_start + slide[:, None] * chord_start
    return x_start, (nodes, partners, wanted), along_n < 0.0


def _deep_pairs(deep: dict, nodes: NDArray, partners: NDArray, now: NDArray) -> NDArray:
    """Which pairs slide as deep ones: as each pair was found (``now``) at its first request
    of the step. The two slides differ by the gap's part along the surface, a jump at the
    threshold: a pair whose gap persists near DEEP x the spacing (the fast-sliding blocks
    refined 4x: 6.0e-3 and 6.3e-3 about 6.25e-3) flipped between them at every augmentation,
    its node's request by 1.4e-3 back and forth, and the augmentations never converged. The
    first request of a step, from the t_n velocities, sees a high-speed first step deepest."""
    out = np.empty(nodes.size, bool)
    for k, (node, partner) in enumerate(zip(nodes.tolist(), partners.tolist(), strict=True)):
        out[k] = deep.setdefault((node, partner), bool(now[k]))
    return out


def _contact_normals(model: Model, contact: Sequence[PairState], x: NDArray,
                     nodes: NDArray) -> NDArray:
    """The contact normal at ``x`` of the pair of every active node (its first pair, as in
    ``_ale_nodes_and_partners``)."""
    out = np.full((len(x), 2), np.nan)
    for ci, state in reversed(list(zip(model.interfaces, contact, strict=True))):
        if len(state):
            normal, _, _ = pair_gaps(x, ci.interface, state.pairs)
            for side in (0, 1):  # the report moves the body-2 node: its pair comes first
                # oriented so that (partner - node) . n is the gap g (> 0: penetration)
                out[state.pairs[::-1, side]] = normal[::-1] if side == 1 else -normal[::-1]
    return out[nodes]


def _surface_chords(setup: AleSetup, nodes: NDArray, x: NDArray) -> NDArray:
    """Unit chord between the two chain neighbours of every active node at ``x``, on the
    contact surface the node is moved with (``ale.multisurface.surface_of_nodes``)."""
    local = nodes - setup.node_offset
    which = np.maximum(surface_of_nodes(setup.motions, local), 0)
    chord = np.zeros((nodes.size, 2))
    for s, body in enumerate(setup.motions):
        on = which == s
        n = body.surface.size
        k = body._surface_index[local[on]]
        if body.closed:
            before, after = body.surface[(k - 1) % n], body.surface[(k + 1) % n]
        else:
            before = body.surface[np.maximum(k - 1, 0)]
            after = body.surface[np.minimum(k + 1, n - 1)]
        chord[on] = x[after + setup.node_offset] - x[before + setup.node_offset]
    return chord / np.linalg.norm(chord, axis=1)[:, None]


def _placed(x: NDArray, body_x: NDArray, setup: AleSetup) -> NDArray:
    """``x`` with the ALE body's rows replaced by ``body_x``."""
    out = x.copy()
    out[setup.node_offset:setup.node_offset + setup.n_nodes] = body_x
    return out


def mesh_settled(model: Model, base: StepState, contact: Sequence[PairState],
                 x_pred: NDArray, motion: MeshMotion | None) -> bool:
    """True if moving the meshes again for the end-of-step positions ``x_pred`` of the last
    solution would move no active node by more than :data:`SETTLED` of its body's smallest
    surface spacing. The move of an augmentation is made for the previous solution's
    prediction, and a sliding node's particle does not land exactly on its partner until
    this fixed point settles (the multipliers' test does not see tangential changes)."""
    if motion is None:
        return True
    masses = _AleMasses(model, base, dict(motion.meetings))  # a copy: nothing is recorded
    deep = dict(motion.deep)
    for i, setup in enumerate(model.ale_bodies):
        nodes, partners = _ale_nodes_and_partners(setup, contact)
        nodes, partners = _followed(nodes, partners, motion.unfollowed)
        old = motion.requests[i] if i < len(motion.requests) else None
        if old is None or nodes.size == 0:
            if nodes.size:
                return False
            continue
        targets, meet = _targets(masses, nodes, partners, x_pred)
        _, new, _ = _request(model, setup, base, motion.updates[i], contact, nodes, partners,
                             x_pred, targets, meet, deep)
        if _request_change(old, new) > SETTLED * setup.motion.min_spacing:
            return False
    return True


def _moved(setup: AleSetup, base: StepState, rows: slice, nodes: NDArray, x_target: NDArray,
           x_end: NDArray, dt: float, x_start: NDArray, previous: AleUpdate | None
           ) -> AleUpdate:
    """``move_ale_body`` (``move_ale_surfaces`` for several contact surfaces) on the body's
    rows, its interior stage and seeds at least those of ``previous``, the step's previous
    move of the body (so the augmentations cannot cycle between stages or smoothed regions);
    any mesh failure of the move (an inverted element, a node outside the old mesh) is an
    AleMotionError, which the time loop cuts back."""
    move = move_ale_surfaces if setup.more_motions else move_ale_body
    least = (previous.interior, previous.seeds) if previous is not None else ("none", None)
    try:
        return move(setup.motions if setup.more_motions else setup.motion, base.X[rows],
                    base.d[rows], base.v[rows], base.a[rows], nodes - setup.node_offset,
                    x_target, x_end, dt, x_start, *least)
    except AleMotionError:
        raise
    except MeshError as err:
        raise AleMotionError(f"ALE mesh motion: {err}") from err


def _same_request(old, new, setup: AleSetup) -> bool:
    """True if the same pairs want positions within the body's slide tolerance of the last
    request: the move would then change no node by more than that tolerance allows (the later
    augmentations of a step, whose predictions agree to ~1e-10 of an element)."""
    spacing = min(m.min_spacing for m in setup.motions)
    return old is not None and _request_change(old, new) <= setup.motion.slide_tolerance * spacing


def _request_change(old: tuple, new: tuple) -> float:
    """How far the positions of two requests (nodes, partners, positions) differ at the most;
    infinite where their pairs differ."""
    if not (np.array_equal(old[0], new[0]) and np.array_equal(old[1], new[1])):
        return np.inf
    return float(np.abs(new[2] - old[2]).max())


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


def end_of_step_mismatch(model: Model, results: Sequence, x: NDArray) -> tuple[float, dict | None]:
    """The largest offset across the line of action (the pair's normal at the step's end
    positions ``x``) between a pressed pair's nodes where one of them is an ALE node: what
    the mesh motion did not follow; and where (``_mismatch_place``; None with no such pair).
    The motion's own ``mismatch`` is its prediction's miss when it moved, which the step's
    last solve may leave behind: with the penalty method (one move a step) a tester's ALE
    patch test read 0 while its corner pair ended 5.2e-3 apart. It also counts the pairs that
    carry no traction (a tester's row of blocks, one ALE: 0.0657 at t = 0.114 on a pair with
    no force, waiting for its release; 0.0634 over the pressed ones), so it is not taken."""
    on_ale = _on_ale(model)
    worst, where = 0.0, None
    for ci, result in zip(model.interfaces, results, strict=True):
        if result is None:  # an interface without pairs
            continue
        take = (result.t_N > 0.0) & (on_ale[result.pairs[:, 0]] | on_ale[result.pairs[:, 1]])
        if take.any():
            pairs = result.pairs[take]
            normal = pair_gaps(x, ci.interface, pairs)[0]
            w = x[pairs[:, 0]] - x[pairs[:, 1]]
            across = np.abs(w[:, 0] * normal[:, 1] - w[:, 1] * normal[:, 0])
            k = int(np.argmax(across))
            if across[k] > worst:
                worst, where = float(across[k]), (ci.name, pairs[k])
    if where is None:
        return worst, None
    return worst, _mismatch_place(model, where[0], where[1], on_ale)


def _on_ale(model: Model) -> NDArray[np.bool_]:
    """Which global nodes belong to an ALE body."""
    return np.isin(model.body_of_node(), [setup.body_index for setup in model.ale_bodies])


def _mismatch_place(model: Model, interface: str, pair: NDArray, on_ale: NDArray) -> dict:
    """Where an ALE mismatch is (summary.json ``max_ale_mismatch_at``): the interface, the ALE
    node (global, its body and body-local number; the pair's body-2 node where both are ALE,
    the one the report moves) and its partner, and whether the ALE node is a fixed point of
    its ALE surface (a corner or a chain end, ``fixed_end``): there nothing slides, and the
    mismatch is a partner node off the ALE surface's grid that no motion can reach."""
    a, b = int(pair[0]), int(pair[1])
    node, partner = (b, a) if on_ale[b] else (a, b)
    ale, other = model.body_at(node), model.body_at(partner)
    return {"interface": interface, "node": node, "body": ale.name,
            "body_node": node - ale.node_offset, "partner": partner,
            "partner_body": other.name, "partner_body_node": partner - other.node_offset,
            "fixed_end": _fixed_on_surface(model, node)}


def _fixed_on_surface(model: Model, node: int) -> bool:
    """Whether global ``node`` of an ALE body is a break of the ALE surface it moves with (a
    corner, or an end of an open chain): such a node never moves along its surface."""
    for setup in model.ale_bodies:
        local = node - setup.node_offset
        if not 0 <= local < setup.n_nodes:
            continue
        which = int(surface_of_nodes(setup.motions, np.array([local], np.int64))[0])
        if which < 0:
            return False
        body = setup.motions[which]
        k = int(body._surface_index[local])
        return bool(body.corner[k]) or (not body.closed and k in (0, body.surface.size - 1))
    return False
