"""Step-level contact procedures over all interfaces: detection, Newton terms, augmentation.

The time loop calls, per step: :func:`detect_all` at the step start, then repeatedly
:func:`contact_terms` (Newton with fixed multipliers), :func:`evaluate_all` and
:func:`augment_all` until converged (report 5.4), then :func:`commit_all`.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from typing import NamedTuple

import numpy as np
import scipy.sparse as sp
from numpy.typing import NDArray

from ..contact import (
    SLIP,
    ContactResult,
    Pairing,
    PairState,
    augment,
    beyond_ends,
    beyond_reach,
    blocks_of,
    check_augmentation,
    closest_pairs,
    commit_step,
    detect,
    entering,
    evaluate_contact,
    facing,
    lagrange_blocks,
    neighbour_pairs,
    ordered_partners,
    pair_gaps,
    rate_roundoff,
    release_mask,
    release_tensile_pairs,
)
from ..contact.evaluate import TOUCH_ROUNDOFF
from .model import ContactInterface


def detect_all(
    interfaces: Sequence[ContactInterface], states: Sequence[PairState], x: NDArray,
    v: NDArray, dt: float,
) -> tuple[PairState, ...]:
    """Release finished pairs and add penetrating, approaching candidates (2.1.4, 3.2).

    With ``predicted`` detection the penetration test uses the positions predicted for the end
    of the step, x + dt v, so that a pair enters the step in which it touches (needed by exact
    gap constraints, which would otherwise close a whole step's penetration at once)."""
    out = []
    for ci, state in zip(interfaces, states, strict=True):
        x = x + dt * v if ci.predicted_detection else x
        tol = touch_tolerance(x, ci)
        state = _kept_where_they_face(x, ci, state)
        release = release_mask(state, ci.persistency, ci.release_steps)
        candidates = _candidates(x, v, dt, ci, _staying(ci, state, release[0]), tol)
        found = detect(state, candidates, x, v, ci.interface, persistency=ci.persistency,
                       release_steps=ci.release_steps, gap_tol=tol,
                       objective=ci.law.moment_free, release=release)
        out.append(found.state)
    return tuple(out)


def _kept_where_they_face(x: NDArray, ci: ContactInterface, state: PairState) -> PairState:
    """The pairs kept from the last step, at the positions ``x``: released where the surface-1
    node lies beyond an end of an open surface 2 (``contact.beyond_ends``: it faces nothing),
    and between Lagrangian bodies paired again, with their history, with the nearest
    surface-2 node where the node no longer faces a segment of its partner. Nothing moves a
    Lagrangian partner with its node, and a pair kept where it entered held a sliding block
    by base nodes up to 2 away, and on past the base's end (an independent tester's case);
    an ALE partner follows its node (the mesh motion), so ALE pairs keep their partners,
    except where it could not (``contact.beyond_reach``: farther from its node than a new
    pair may be, ``ordered_partners``): released, the node is paired afresh by this
    detection, as a new one is (ALE partners are distinct and in surface order, so the
    node it now faces is mostly another's partner: no re-pairing with history). Kept, a
    block sliding 5 of its lengths over an ALE base pressed its trailing corner on a base
    node 4.5 (45 spacings) behind it, the base node clamped by ale.max_stretch (a tester;
    released, no pressed pair is more than 0.265 off).
    Released too where the pair's normal no longer faces its partner's (``contact.facing``):
    a tester's spinning disk rolled away from a block with a pair held 0.66 apart, its
    persistency-law gap frozen and its force pushing on. Not released by their opening: a
    pair entered early by predicted detection holds an opening up to the approach speed
    times dt, which a release at half the partner's chord cut (a tester's rods then touched
    every other step and went 0.5 through each other with the penalty method)."""
    if len(state) == 0:
        return state
    pairing = closest_pairs(x, ci.interface, state.pairs[:, 0])
    keep = ~beyond_ends(x, ci.interface, pairing)
    if not ci.ordered_pairing:
        nearest_edge = ci.interface.surface2.edges()[pairing.segment]
        moved = ~np.any(nearest_edge == state.pairs[:, 1:2], axis=1)
        partners = np.where(moved, pairing.node2, state.pairs[:, 1])
        pairs = np.column_stack([state.pairs[:, 0], partners])
        keep &= ~(moved & _opened(x, ci, state.pairs, pairs, nearest_edge))
        state = replace(state, pairs=pairs)
    elif not ci.interface.surface2.closed:
        # a pair its ALE node could not follow (clamped by ale.max_stretch) is released once
        # out of the reach a new pair must be within; its node is then a free candidate
        keep &= ~beyond_reach(x, ci.interface, state.pairs, ci.reference_arc2)
    # a pair whose normal has turned away from its partner's is no contact either (a
    # spinning disk's node kept pressing a block it had rolled away from)
    return state.take(keep & facing(x, ci.interface, state.pairs))


def _staying(ci: ContactInterface, state: PairState, released: NDArray[np.bool_]
             ) -> PairState:
    """The pairs that detection keeps, whose nodes are no candidates: under the gap law those
    it does not release (``released``, ``contact.release_mask``), so that a released node
    that x puts inside enters again at once (a pair that ended a quasi-static step open and
    penetrated at x + dt v waited for the step's first pass to end: Hertz refined 4x, 13 of
    18 steps). Under the persistency law all of them: it releases a pair by the solve's
    mid-point rate, and the end velocity that detection tests can point the other way (the
    mid-point rule's odd-even mode); a block sliding off an ALE ledge had a pair released and
    taken in afresh at once, and the base was left ringing (its momentum over the free fall
    0.8 -> 3.7 % off, test_sliding_pairs)."""
    return state if ci.persistency else state.take(~released)


#: How much more open than its last partner a pair's new partner may be, in lengths of the
#: surface-2 segment the node faces, and the pair still kept (``_opened``).
REPAIR_OPENING = 0.1


def _opened(x: NDArray, ci: ContactInterface, old: NDArray, new: NDArray,
            segment: NDArray) -> NDArray:
    """Which pairs paired again (``old`` -> ``new`` partners) are open at the new partner by
    more than :data:`REPAIR_OPENING` of the faced segment beyond their old gap. Under the
    persistency law a pressed pair's gap is frozen by gdot = 0, and a node that moves away
    along its turning normal keeps its force at any distance; its new partner's gap shows the
    opening. A tester's ring spinning at 3 rad/s on a Lagrangian obstacle had node 192 paired
    again at every node of the obstacle while it rose 0.46 above it, each time 0.016-0.058
    more open (0.3 open in the end), and pressed with forces of 1-3 throughout. Sliding over
    a flat or evenly curved partner changes the gap by the deformation only."""
    _, old_gap, _ = pair_gaps(x, ci.interface, old)
    _, new_gap, _ = pair_gaps(x, ci.interface, new)
    length = np.linalg.norm(x[segment[:, 1]] - x[segment[:, 0]], axis=1)
    return new_gap < np.minimum(old_gap, 0.0) - REPAIR_OPENING * length


def _candidates(x: NDArray, v: NDArray, dt: float, ci: ContactInterface, state: PairState,
                tol: float) -> NDArray:
    """(C, 2) candidate pairs of the free surface-1 nodes on or behind surface 2. Between
    Lagrangian bodies each takes its nearest surface-2 node, shared or not, as the kept pairs
    share partners (``_kept_where_they_face``); a node already paired does not compete. It
    used to: a tester's block (spacing 0.1) pressed on a foundation (0.15) left two of its
    bottom nodes unpaired for the whole run, tied with a paired neighbour for the same
    foundation node, and they sank 2.7 times deeper than the reported penetration. Nor does
    a free node wait for a free partner: a face of 9 nodes placed touching 6 partner nodes
    entered 6 pairs at step 1 and the other 3 a step later, 8.8e-5 inside (a tester)."""
    near = _near_candidates(x, v, dt, ci, abs(tol))
    free = near[~np.isin(near, state.pairs[:, 0])]
    if ci.ordered_pairing and not ci.interface.surface2.closed:
        return _ordered_candidates(x, ci, state, free)
    return closest_pairs(x, ci.interface, free).pairs


def entered_at_step_end(interfaces: Sequence[ContactInterface], states: Sequence[PairState],
                        x: NDArray, v: NDArray, retake: Sequence[NDArray],
                        let_go: Sequence[NDArray]) -> tuple[PairState, ...] | None:
    """The active sets grown by the surface-1 nodes that a dynamic solve ends inside surface 2
    (and approaching it, under the persistency law), or None if none did: any such node on
    the interfaces with ``active_set_pass``, on every interface those of ``retake`` (per
    interface, the nodes whose pairs the step released because the ALE mesh could not follow
    them, ``mesh_motion.without_unfollowed``; these approaching or not). Never those of
    ``let_go``, whose pairs the step's own solves released (in tension): taken in again they
    would only leave again (a touch on a step boundary under the Lagrange gap law: 5 passes,
    40 Newton iterations).
    Tested at the step's end positions x and velocities v as a predicted detection tests
    them: a gap within round-off of zero is a touch still to come, which the next step start
    takes in. The pairs already active stay as they are.

    Why: detection at the step start (or at x + dt v) misses a node that the step's own
    solution takes inside, and the persistency law then keeps that depth for the whole
    contact (docs/examples.md, "Detection lag"). Quasi-static steps always solve again with
    such nodes (``Simulation.advance``); this is the same pass for dynamic steps."""
    grown, added = [], False
    for ci, state, again, out in zip(interfaces, states, retake, let_go, strict=True):
        if not (ci.active_set_pass or again.size):
            grown.append(state)
            continue
        tol = -abs(touch_tolerance(x, ci))
        candidates = _candidates(x, v, 0.0, ci, state, tol)
        node = candidates[:, 0]
        new = ~np.isin(node, state.pairs[:, 0]) & ~np.isin(node, out)
        if not ci.active_set_pass:
            new &= np.isin(node, again)
        fresh = candidates[new]
        _, gap, rate = pair_gaps(x, ci.interface, fresh, v, ci.law.moment_free)
        # a released pair's node comes back wherever it is inside, approaching or not: the
        # pair was active, and the persistency law releases by the rate over release_steps
        rate_tol = rate_roundoff(x, v, ci.interface, fresh, tol) if v is not None else 0.0
        enter = entering(gap, rate, ci.persistency, tol, rate_tol) | (
            np.isin(fresh[:, 0], again) & entering(gap, rate, False, tol))
        enter &= facing(x, ci.interface, fresh)
        added |= bool(enter.any())
        grown.append(state.concat(PairState.from_pairs(fresh[enter])))
    return tuple(grown) if added else None


def touch_tolerance(x: NDArray, ci: ContactInterface) -> float:
    """How far below zero a gap tested at detection still enters (``detect``'s gap_tol): a gap
    within round-off of zero, :data:`TOUCH_ROUNDOFF` times the largest coordinate of the
    interface's nodes. Under the gap law it enters (the law acts on the gap, so a pair in
    early holds nothing open, and the kernel gives it the pressed branch's stiffness): a
    tester's static block placed on another failed as singular when round-off (a lift of
    1e-12, a rotation of 0.001 degree) left the gaps a hair open. Under the persistency law it is
    decided one way: detected at the step start (``penetration``) it is a touch that has
    happened, so it enters (tol > 0); at the predicted end of the step (``predicted``) it is a
    touch still to come, found with a zero gap at the next step start, so it waits (tol < 0:
    entered now, the pair would keep the step's whole approach as a separation).

    Why: a flat face that touches exactly on a step boundary has gaps of zero whose signs are
    round-off. Tested against zero, some of its nodes entered at that step and the rest one
    step later, by then v dt inside, and gdot = 0 held the two groups v dt apart for the whole
    impact. The fast-sliding blocks (report 6.5) touch at t = 0.048, a step end: refined 8x
    (surface spacing 6.25e-3, contact-side row 2.1e-3) the face became a zig-zag of 6e-3
    amplitude and the contact steps needed 107-315 Newton iterations and 1-4 halvings;
    refined 4x with mu = 0.2 (4 of 33 nodes entered first) the run failed at t = 0.111
    (docs/theory.md, "A touch on a step boundary")."""
    nodes = np.concatenate([ci.interface.surface1.nodes, ci.interface.surface2.nodes])
    tol = TOUCH_ROUNDOFF * float(np.abs(x[nodes]).max())
    # the gap law's force acts on the gap: a pair in early holds nothing open
    return -tol if ci.persistency and ci.predicted_detection else tol


def _near_candidates(x: NDArray, v: NDArray, dt: float, ci: ContactInterface,
                     tol: float = 0.0) -> NDArray:
    """Surface-1 candidates lying on or behind surface 2 (projection gap >= -tol, the touch
    tolerance's size) within one segment length of it plus the distance the node approached
    its nearest surface-2 node in the last step (|v_1 - v_2| dt): far nodes "behind" the
    surface (the far side of a ring)
    are not penetrating, whatever the sign of their gap. Detected at the step start, a touch
    inside the last step has penetrated by up to that approach: with one segment alone, the
    fast-sliding blocks refined 8x (segments 6.25e-3, v dt = 6e-3) left the nodes that had
    gone in 6.6e-3 undetected, and their thin bottom row was crushed (issue 17)."""
    pairing = closest_pairs(x, ci.interface, ci.candidates)
    edges = [s.edges() for s in (ci.interface.surface1, ci.interface.surface2)]
    radius = max(np.linalg.norm(x[e[:, 1]] - x[e[:, 0]], axis=1).max() for e in edges)
    approach = dt * np.linalg.norm(v[pairing.node1] - v[pairing.node2], axis=1)
    keep = ((pairing.projection_gap >= -tol) & _not_in_front(x, ci, pairing, tol)
            & (pairing.distance <= radius + approach) & ~beyond_ends(x, ci.interface, pairing))
    return pairing.node1[keep]


def _not_in_front(x: NDArray, ci: ContactInterface, pairing: Pairing,
                  tol: float) -> NDArray:
    """False for a candidate in front of surface 2 along that surface's own outward normal,
    where its closest point lies inside a segment. The projection gap is measured along the
    candidate's own normal n1, and on a face of body 1 that stands across surface 2 (the
    leading face of a block joined to its bottom, ``surface_1 = "bottom+right"``) n1 runs
    along surface 2: there it is ~0 however far the node is, and the node was paired 0.035
    above the lower block with a traction (fast-sliding blocks, t = 0.039). At a vertex of
    surface 2 a segment's normal does not tell the side (a corner), so the test is left to n1."""
    edges = ci.interface.surface2.edges()[pairing.segment]
    along = x[edges[:, 1]] - x[edges[:, 0]]
    outward = np.column_stack([along[:, 1], -along[:, 0]]) / np.linalg.norm(along, axis=1)[:, None]
    ahead = np.einsum("ij,ij->i", x[pairing.node1] - pairing.point, outward)
    inside_segment = (pairing.xi > 0.0) & (pairing.xi < 1.0)
    return ~(inside_segment & (ahead > tol))


def _ordered_candidates(x: NDArray, ci: ContactInterface, state: PairState,
                        free: NDArray) -> NDArray:
    """Distinct, order-preserving partners for the free candidates (ALE partner surface):
    mutual nearest nodes, the kept pairs competing and bounding the order."""
    partners = ordered_partners(x, ci.interface, free, kept=state.pairs,
                                reference_arc=ci.reference_arc2)
    return np.column_stack([free, partners])[partners >= 0]


def persistent_velocities(interfaces: Sequence[ContactInterface], states: Sequence[PairState],
                          x: NDArray, v: NDArray) -> NDArray:
    """v with the body-1 node of every persistency pair held at the last step's end (t_N > 0)
    given its partner's velocity along the pair normal (gdot = 0 at x): the velocity the step's
    first Newton start advances the nodes with. A fresh pair keeps its approach: zeroing it would
    crush the row behind the node (the ring at speed 50 of test_step_end_inversion).
    The mid-point rule leaves a node held by persistency with the end velocity
    v_{n+1} = 2 v_{n+1/2} - v_n, which flips its normal part from step to step (the odd-even
    mode, docs/examples.md); started from x_n + dt/2 v_n such a node is pushed by v dt/2 into
    its surface element (fast-sliding blocks refined 4x: 3.8 mm of the 3.9 mm contact-side
    row), and the first Newton steps inverted it (docs/theory.md, "Newton start of held
    pairs")."""
    out = np.array(v, dtype=float, copy=True)
    for ci, state in zip(interfaces, states, strict=True):
        if len(state) == 0 or not ci.persistency:
            continue
        held = state.t_N > 0.0  # pressed at the last step's end; a fresh pair keeps its v
        if not held.any():
            continue
        n, _, rate = pair_gaps(x, ci.interface, state.pairs[held], v)
        out[state.pairs[held, 0]] -= rate[:, None] * n
    return out


#: Chain steps along surface 1, beyond each active pair's node, whose pairs' matrix entries
#: are reserved when the union pattern grows (:meth:`ContactNewtonTerm.reserve`). Hertz
#: refined 8x (the zone grows from 1 to 131 pairs in 18 load steps): 8 analyses with a reach
#: of 8 and the nearest partner only, 4 with 16, 4 with 32; 3 with 16 and the nearest
#: partner's chain neighbours too (the two analyses left: the first pass's jump from 1 to 77
#: pairs, and one growth).
RESERVED_REACH = 16
#: ... from this many dofs on, where an analysis is PARDISO's (``solvers.linear``, from
#: 10,000 unknowns; ~0.1-0.45 s each at 46k-124k). Below it SuperLU's or the static LU's
#: analysis costs milliseconds and the reserved entries' fill cost more: the ring impact and
#: the disk drop examples (890 / 764 dofs) took 3-5 % more CPU with them (two runs each).
RESERVED_FROM_DOFS = 10_000


@dataclass
class ContactNewtonTerm:
    """One penalty / augmented-Lagrangian interface's Newton term, multipliers held fixed:
    (x_eval, v_eval, rate, x_start) -> (force, COO tangent). ``last``, if given, receives
    under ``index`` the arguments and result of the latest evaluation."""

    ci: ContactInterface
    state: PairState
    dt: float
    index: int
    last: dict | None = None
    #: the latest evaluations of the whole term, (state, (x_eval, v_eval, rate, x_start,
    #: result)), the most recently used last (``_whole``)
    _recent: list = field(default_factory=list, repr=False)

    def __call__(self, x_eval, v_eval, rate, x_start):
        r = self._whole(x_eval, v_eval, rate, x_start)
        if self.last is not None:
            self.last[self.index] = (x_eval, v_eval, rate, x_start, r)
        return r.force, _DeferredTriplets(r)

    def reserve(self, x_eval, v_eval, rate, x_start) -> tuple[NDArray, NDArray]:
        """(rows, cols) of the tangent entries of the active pairs grown by those that the
        surface-1 nodes within :data:`RESERVED_REACH` chain steps of them would form with
        their nearest surface-2 node or its chain neighbours (``contact.neighbour_pairs``),
        evaluated by the same kernel: the entries a growing contact zone takes next,
        reserved in the union pattern (``fem.sparse``) so that each growth of the zone is not
        a new analysis of the matrix. Asked for only when the pattern grows, and from
        :data:`RESERVED_FROM_DOFS` on. Analyses, Hertz refined 8x: 15 -> 3, 41.5 -> 35 s a
        run (the run's final pattern given from the start: 1 analysis, 34.4 s); the ring
        refined 8x, t <= 0.15: 10 -> 3, 20.3 -> 18.9 s; 4x 8 -> 2. Histories the same to
        round-off (1e-13 of their scales), Newton iterations equal. With ``unpaired_share``
        the entries are widened along both chains (:func:`along_chains`): the share's
        weights couple the nodes of segments with unpaired nodes, which the grown sets lack."""
        if np.size(x_eval) < RESERVED_FROM_DOFS:
            return _NO_NODES, _NO_NODES
        rows, cols = [_NO_NODES], [_NO_NODES]
        for pairs in neighbour_pairs(x_eval, self.ci.interface, self.state.pairs[:, 0],
                                     RESERVED_REACH):
            # with the active pairs: the unpaired nodes' share (contact.transfer) between
            # consecutive pairs is that of the set the zone would grow into
            grown = PairState.from_pairs(np.vstack([self.state.pairs, pairs]))
            try:
                r = self._evaluate(x_eval, v_eval, rate, x_start, grown)
            except (ValueError, FloatingPointError):  # e.g. an undefined normal of a pair
                continue  # that may never form: no entries reserved for it
            r_rows, r_cols, _ = r.triplets()
            rows.append(r_rows)
            cols.append(r_cols)
        rows, cols = np.concatenate(rows), np.concatenate(cols)
        if self.ci.law.unpaired_share:
            rows, cols = along_chains(rows, cols, self.ci.interface, x_eval.shape[0],
                                      SHARE_RESERVED_STEPS)
        return rows, cols

    def opened(self, x_eval: NDArray, x_trial: NDArray, x_start: NDArray) -> NDArray[np.bool_]:
        """Which pairs a quasi-static Newton step from ``x_eval`` to ``x_trial`` opens: taken
        in without a multiplier (a held pair never opens within a solve), pressed at x_eval,
        open at x_trial."""
        before = self._whole(x_eval, None, None, x_start).t_N
        after = self._whole(x_trial, None, None, x_start).t_N
        return (self.state.lambda_N == 0.0) & (before > 0.0) & (after == 0.0)

    def part(self, mask: NDArray[np.bool_], x_eval: NDArray, x_start: NDArray
             ) -> tuple[NDArray, tuple[NDArray, NDArray, NDArray]]:
        """What the pairs ``mask`` add to the force and the COO tangent at ``x_eval``
        (quasi-static): the term less the term without them, since an unpaired share makes
        a pair's force depend on its neighbours in the set."""
        whole = self._whole(x_eval, None, None, x_start)
        rest = self._evaluate(x_eval, None, None, x_start, self.state.take(~mask))
        (r1, c1, v1), (r2, c2, v2) = whole.triplets(), rest.triplets()
        return (whole.force - rest.force,
                (np.concatenate([r1, r2]), np.concatenate([c1, c2]), np.concatenate([v1, -v2])))

    def _whole(self, x_eval, v_eval, rate, x_start) -> ContactResult:
        """The term of all its pairs at these arguments, evaluated once for the latest
        :data:`RECENT_EVALUATIONS` argument sets. A quasi-static Newton iteration evaluates
        it at the same positions for its residual, for its tangent when the residual did not
        build one, and in ``StepProblem.active_set_step`` (which pairs the step opens, what
        they add), and the active-set step's last trial positions are the line search's
        first. Hertz refined 2x, 4x, 8x (benchmarks/scaling.py): 301, 396, 482 -> 197, 229,
        274 evaluations a run (8x: 0.73 -> 0.47 s CPU)."""
        for k, (state, cached) in enumerate(self._recent):
            if state is self.state and _same_arguments(cached, x_eval, v_eval, rate, x_start):
                self._recent.append(self._recent.pop(k))
                return cached[-1]
        r = self._evaluate(x_eval, v_eval, rate, x_start, self.state)
        # copies: the arguments' owner may reuse their arrays
        self._recent.append((self.state, (_copy(x_eval), _copy(v_eval), rate, _copy(x_start),
                                          r)))
        del self._recent[:-RECENT_EVALUATIONS]
        return r

    def _evaluate(self, x_eval, v_eval, rate, x_start, state: PairState) -> ContactResult:
        ci = self.ci
        rate_eval = rate if ci.persistency else None
        return evaluate_contact(x_eval, v_eval if ci.persistency else None, rate_eval,
                                ci.interface, state, ci.law, x_start=x_start, dt=self.dt,
                                deferred_tangent=True)


class _DeferredTriplets(Sequence):
    """(rows, cols, vals) of a contact result, computed when first read: the step problem
    reads them only when it builds a tangent (an unpaired share's mapping is deferred)."""

    def __init__(self, result: ContactResult) -> None:
        self._result = result

    def __len__(self) -> int:
        return 3

    def __getitem__(self, index):
        return self._result.triplets()[index]


_NO_NODES = np.zeros(0, dtype=np.int64)

#: Argument sets whose whole-term evaluation :meth:`ContactNewtonTerm._whole` keeps: the
#: iterate's and the latest trial step's (``active_set_step`` alternates between them)
RECENT_EVALUATIONS = 2


def _copy(a: NDArray | None) -> NDArray | None:
    return None if a is None else np.array(a, copy=True)

#: Chain steps along both surfaces by which :meth:`ContactNewtonTerm.reserve` widens the
#: entries of an interface with ``unpaired_share``: the share's weights move with the nodes
#: of a shared segment and of its pairs' surface-1 neighbours, so its tangent couples nodes a
#: few steps apart in pair sets with unpaired nodes, which the grown sets (every node
#: paired) never form. The ring refined 2x (one skipped ALE node per segment): 3 analyses
#: with 0 steps (reserved 3188 entries, then 3488 more at a second growth), 2 with 1 (5604
#: entries, one growth) or 2 (8132). Segments of several skipped nodes may need more.
SHARE_RESERVED_STEPS = 1


def along_chains(rows: NDArray, cols: NDArray, interface, n_nodes: int, steps: int
                 ) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """The dof entries (rows, cols) and those whose row node, column node or both lie up to
    ``steps`` chain steps from theirs along either surface of ``interface`` (both dofs of
    each node), unique: B P B^T at node level, B the nodes' chain neighbourhoods."""
    links = [np.arange(n_nodes)]
    ends = [np.arange(n_nodes)]
    for surface in (interface.surface1, interface.surface2):
        for k in range(1, min(steps, surface.size - 1) + 1):
            after = np.roll(surface.nodes, -k) if surface.closed else surface.nodes[k:]
            before = surface.nodes[: after.size]
            links += [before, after]
            ends += [after, before]
    near = sp.csr_matrix((np.ones(sum(a.size for a in links)),
                          (np.concatenate(links), np.concatenate(ends))),
                         shape=(n_nodes, n_nodes))
    pattern = sp.csr_matrix((np.ones(rows.size), (rows // 2, cols // 2)),
                            shape=(n_nodes, n_nodes))
    wide = (near @ pattern @ near.T).tocoo()
    comp = np.arange(2)
    node_rows = (2 * wide.row[:, None, None] + comp[:, None]).repeat(2, axis=2)
    node_cols = (2 * wide.col[:, None, None] + comp[None, :]).repeat(2, axis=1)
    return node_rows.ravel().astype(np.int64), node_cols.ravel().astype(np.int64)


def contact_terms(interfaces: Sequence[ContactInterface], states: Sequence[PairState],
                  dt: float, last: dict | None = None) -> list[ContactNewtonTerm]:
    """Newton terms (force, COO tangent) of every interface with its multipliers held fixed.

    ``last``, if given, receives per interface index the arguments and result of the latest
    evaluation, so that :func:`evaluate_all` at the converged point need not repeat it."""
    return [ContactNewtonTerm(ci, state, dt, index, last)
            for index, (ci, state) in enumerate(zip(interfaces, states, strict=True))
            if len(state) and ci.law.method != "lagrange"]


@dataclass
class LagrangeTerm:
    """Exact normal multipliers of one interface as a bordered-system constraint term."""

    ci: ContactInterface
    state: PairState
    dt: float
    order: int = 0  # position among the step's Lagrange interfaces

    @property
    def size(self) -> int:
        return len(self.state)

    @property
    def initial(self) -> NDArray:
        return self.state.lambda_N

    def __call__(self, x, v_eval, rate, x_start, lam):
        ci, st = self.ci, self.state.with_multipliers(lam)
        v, r = (v_eval, rate) if ci.persistency else (None, None)
        res = evaluate_contact(x, v, r, ci.interface, st, ci.law, x_start=x_start, dt=self.dt)
        b = blocks_of(res, ci.law)
        return (res.force, (res.rows, res.cols, res.vals), b.values,
                (b.g_rows, b.g_cols, b.g_vals), (b.b_rows, b.b_cols, b.b_vals))

    def h_at(self, x: NDArray) -> NDArray:
        """The constraint values L_c g at positions x (gap law), e.g. at the step start."""
        return lagrange_blocks(x, None, None, self.ci.interface, self.state, self.ci.law).values


def lagrange_terms(interfaces: Sequence[ContactInterface], states: Sequence[PairState],
                   dt: float) -> list[LagrangeTerm]:
    exact = [(ci, st) for ci, st in zip(interfaces, states, strict=True)
             if ci.law.method == "lagrange" and len(st)]
    return [LagrangeTerm(ci, st, dt, order) for order, (ci, st) in enumerate(exact)]


def with_solved_multipliers(
    interfaces: Sequence[ContactInterface], states: Sequence[PairState],
    multipliers: Sequence[NDArray],
) -> tuple[PairState, ...]:
    """Store the multipliers of a bordered solve in the Lagrange interfaces' states."""
    values = iter(multipliers)
    return tuple(st.with_multipliers(next(values))
                 if ci.law.method == "lagrange" and len(st) else st
                 for ci, st in zip(interfaces, states, strict=True))


def evaluate_all(
    interfaces: Sequence[ContactInterface], states: Sequence[PairState], x_eval: NDArray,
    v_eval: NDArray | None, rate: float | None, x_start: NDArray, dt: float,
    last: dict | None = None,
) -> tuple[ContactResult | None, ...]:
    """Per-pair results at a converged Newton solution (None for an empty active set); taken
    from ``last`` (see :func:`contact_terms`) where it was evaluated at exactly these values."""
    out = []
    for index, (ci, state) in enumerate(zip(interfaces, states, strict=True)):
        if len(state) == 0:
            out.append(None)
            continue
        if last is not None and _same_arguments(last.get(index), x_eval, v_eval, rate, x_start):
            out.append(last[index][-1])
            continue
        out.append(evaluate_contact(x_eval, v_eval if ci.persistency else None,
                                    rate if ci.persistency else None, ci.interface, state,
                                    ci.law, x_start=x_start, dt=dt))
    return tuple(out)


def _same_arguments(cached, x_eval, v_eval, rate, x_start) -> bool:
    if cached is None:
        return False
    x0, v0, rate0, start0, _ = cached

    def same(a, b):
        return (a is None) == (b is None) and (a is None or np.array_equal(a, b))
    return same(x0, x_eval) and same(v0, v_eval) and rate0 == rate and same(start0, x_start)


def augment_all(
    interfaces: Sequence[ContactInterface], states: Sequence[PairState],
    previous: Sequence[ContactResult | None] | None, current: Sequence[ContactResult | None],
) -> tuple[tuple[PairState, ...], bool]:
    """Check report 5.4's convergence test and augment where needed; True when all converged."""
    new_states, done = [], True
    for i, (ci, state, res) in enumerate(zip(interfaces, states, current, strict=True)):
        if res is not None and ci.law.method == "lagrange":
            # exact multipliers: a tensile pair (t_N < 0, 2.14) leaves and the step is re-solved
            kept, tensile = release_tensile_pairs(state, state.lambda_N)
            done &= not tensile.any()
            new_states.append(kept)
            continue
        if res is None or ci.law.method != "augmented_lagrangian":
            new_states.append(state)
            continue
        prev = None if previous is None else previous[i]
        converged = prev is not None and check_augmentation(prev, res, ci.law,
                                                            ci.tolerances).converged
        done &= converged
        new_states.append(state if converged else augment(state, res, ci.law))
    return tuple(new_states), done


class AugmentationFailure(NamedTuple):
    """An interface that failed report 5.4's test at its last augmentation of a step."""

    interface: ContactInterface
    reason: str  # the test's values and tolerances, and which of its parts failed
    halving_helps: bool  # False where no shorter step can pass the test
    #: the failed parts: "gap" ("normal rate" under the persistency law), "slip",
    #: "traction", "stick/slip", "constraint", "tension"
    tests: tuple[str, ...] = ()
    #: pressed pairs stick: their tangential multipliers take Uzawa's update whatever
    #: augmentation.update says (docs/scenarios.md)
    sticking: bool = False


def unconverged_interfaces(
    interfaces: Sequence[ContactInterface], states: Sequence[PairState],
    previous: Sequence[ContactResult | None] | None, current: Sequence[ContactResult | None],
    gap_roundoff: float = 0.0, dt: float = 1.0,
) -> list[AugmentationFailure]:
    """The interfaces that fail report 5.4's test between their last two augmentations
    (Lagrange interfaces: that still release pairs in tension), each with what failed and
    whether a shorter step can help: not with one augmentation allowed, nor with a
    gap_tolerance below the round-off of what it bounds (``gap_roundoff``: that of the gaps,
    :func:`gap_roundoff`; the persistency law's rates 2 gap_roundoff / dt). The message of a
    step whose augmentations ran out."""
    failed = []
    for i, (ci, state, res) in enumerate(zip(interfaces, states, current, strict=True)):
        prev = None if previous is None else previous[i]
        if res is None:
            continue
        if ci.law.method == "lagrange":
            if release_tensile_pairs(state, state.lambda_N)[1].any():
                failed.append(AugmentationFailure(ci, "pairs still released in tension", True,
                                                  ("tension",)))
        elif ci.law.method == "augmented_lagrangian":
            roundoff = gap_roundoff * (2.0 / dt if ci.persistency else 1.0)
            failure = _augmentation_failure(ci, prev, res, roundoff)
            if failure is not None:
                failed.append(failure)
    return failed


def gap_roundoff(x: NDArray) -> float:
    """The round-off of a gap between nodes at the positions x: one ulp of the largest
    coordinate (a tester's block at coordinates up to 4: augmentations changed its gaps by
    2.2e-16 and never met gap_tolerance = 1e-20)."""
    return float(np.finfo(float).eps * np.abs(x).max()) if x.size else 0.0


def _augmentation_failure(ci: ContactInterface, prev: ContactResult | None,
                          res: ContactResult, roundoff: float) -> AugmentationFailure | None:
    """Why an interface failed report 5.4's test (None if it passed): its values against
    their tolerances, the parts that failed (named in the reason), and whether a shorter step
    can help (not where the test cannot be met at all)."""
    if prev is None:
        return AugmentationFailure(ci, "one augmentation only, and the test compares two", False)
    check = check_augmentation(prev, res, ci.law, ci.tolerances)
    if check.converged:
        return None
    tol, frictional = ci.tolerances, ci.law.frictional
    measure = "normal rate" if ci.persistency else "gap"  # report 5.4's test of each law
    out = [f"change of the {measure} {check.normal_change:.3g} (gap_tolerance {tol.normal:.3g})"]
    if frictional:
        out += [f"change of the slip {check.tangential_change:.3g} "
                f"(slip_tolerance {tol.tangential:.3g})",
                f"{check.status_changes} stick/slip switches"]
        if check.slip_excess > tol.slip:
            out.append(f"|t_T| above mu t_N by {check.slip_excess:.3g} of it "
                       f"(traction_tolerance {tol.slip:.3g})")
    if check.tensile_pairs:
        out.append(f"{check.tensile_pairs} pairs in tension")
    tests = _failed_tests(check, tol, frictional, measure)
    pressed = res.t_N > 0.0
    sticking = frictional and bool(np.any(pressed & (res.status != SLIP)))
    reason = ", ".join(out) + f"; failed: the {' and '.join(tests)} test" + (
        "s" if len(tests) > 1 else "")
    if tol.normal < roundoff:
        reason += (f"; gap_tolerance {tol.normal:.3g} is below the round-off of the {measure}s "
                   f"({roundoff:.3g}, one ulp of the coordinates), which no augmentation, "
                   "update rule or shorter step can meet: raise it above that")
    return AugmentationFailure(ci, reason, not tol.normal < roundoff, tests, sticking)


def _failed_tests(check, tol, frictional: bool, measure: str) -> tuple[str, ...]:
    """The parts of report 5.4's test that ``check`` failed, as ``check_augmentation``
    judges them (the advice on a failed step depends on which)."""
    parts = [(measure, check.normal_change > tol.normal),
             ("slip", frictional and check.tangential_change > tol.tangential),
             ("traction", frictional and check.slip_excess > tol.slip),
             ("stick/slip", frictional and check.status_changes > 0),
             ("constraint", tol.constraint is not None
              and check.constraint_violation > tol.constraint),
             ("tension", check.tensile_pairs > 0)]
    return tuple(name for name, failed in parts if failed)


def _friction_advice(ci: ContactInterface, f: AugmentationFailure) -> str:
    """augmentation_advice's for a frictional interface that failed the slip test, or the gap
    test with sticking pairs. Methods without a tangential augmentation have no such test:
    "lagrange" (friction stays penalty-regularized) and "penalty"."""
    options = []
    if f.sticking:  # Uzawa's stick update contracts faster with a stiffer tangential penalty
        options.append(f"a larger penalty_tangential (now {ci.law.eps_T:.4g})")
    if "slip" in f.tests:
        options.append(f"a looser augmentation.slip_tolerance (now {ci.tolerances.tangential:.3g})")
    options.append('method = "lagrange" or "penalty"')
    why = ("sticking pairs' tangential multipliers take Uzawa's update under either "
           "augmentation.update; try " if f.sticking else "try ")
    return why + ", ".join(options[:-1]) + (", or " if len(options) > 1 else "") + options[-1]


def augmentation_advice(failed: Sequence[AugmentationFailure]) -> str:
    """What can make a failed augmented Lagrangian interface pass, by the test it failed
    ("" if nothing to say). ``augmentation.update = "newton"`` speeds up the normal
    multipliers and slipping pairs' traction only: a tester's static block with friction
    (static_tilt, 80 elements, sticking pairs) failed the gap test with it as without, and
    the slip test with eps_T = 500 too. What passed there: a 10x penalty_tangential (the gap
    case), a looser slip_tolerance (the slip case), method "lagrange" or "penalty" (both)."""
    hints: list[str] = []
    for f in failed:
        ci = f.interface
        if ci.law.method != "augmented_lagrangian" or not f.halving_helps:
            continue
        normal = "gap" in f.tests or "normal rate" in f.tests
        if normal and not f.sticking and ci.multiplier_update != "newton":
            # the fast-sliding blocks refined 8x: Uzawa contracts by 0.86 an augmentation on
            # a stiff local mode, Newton updates pass the same steps in <= 18
            hints.append(f"interface {ci.name!r}: Uzawa's update of the normal multipliers "
                         "can converge slowly on a stiff local mode: try augmentation.update "
                         "= \"newton\"")
        if ci.law.frictional and ("slip" in f.tests or (normal and f.sticking)):
            hints.append(f"interface {ci.name!r}: " + _friction_advice(ci, f))
    return "".join(f"; {h}" for h in hints)


def commit_all(
    interfaces: Sequence[ContactInterface], states: Sequence[PairState],
    results: Sequence[ContactResult | None],
) -> tuple[PairState, ...]:
    return tuple(
        state if res is None else commit_step(state, res, ci.law)
        for ci, state, res in zip(interfaces, states, results, strict=True)
    )


def contact_rows(
    interfaces: Sequence[ContactInterface], results: Sequence[ContactResult | None],
    x: NDArray,
) -> dict[str, NDArray]:
    """Columns of contact.csv for the active pairs of every interface."""
    cols: dict[str, list] = {k: [] for k in (
        "interface", "node_1", "node_2", "x", "y", "gap", "gap_rate", "normal_traction",
        "tangential_traction", "normal_force", "tangential_force", "status", "end_gap",
        "normal_x", "normal_y")}
    for ci, res in zip(interfaces, results, strict=True):
        if res is None:
            continue
        n1 = res.pairs[:, 0]
        cols["interface"] += [ci.name] * len(n1)
        cols["status"] += ["slip" if s else "stick" for s in (res.status == 1)]
        for key, val in (("node_1", n1), ("node_2", res.pairs[:, 1]), ("x", x[n1, 0]),
                         ("y", x[n1, 1]), ("gap", res.gap), ("gap_rate", res.gap_rate),
                         ("normal_traction", res.t_N), ("tangential_traction", res.t_T),
                         ("normal_force", res.normal_force),
                         ("tangential_force", res.tangential_force),
                         # the law's gap is the solve's (at t_{n+1/2} in a dynamic step); the
                         # frame shows x
                         ("end_gap", pair_gaps(x, ci.interface, res.pairs)[1]),
                         # the normal the forces act along: without it their resultant cannot
                         # be formed
                         ("normal_x", res.normal[:, 0]), ("normal_y", res.normal[:, 1])):
            cols[key].append(val)
    return {k: (np.concatenate(v) if v and not isinstance(v[0], str) else np.asarray(v))
            for k, v in cols.items()}


def unpaired_shares(
    interfaces: Sequence[ContactInterface], results: Sequence[ContactResult | None],
    x: NDArray,
) -> dict[str, NDArray]:
    """The surface-1 nodes in no pair that carry a share of their neighbouring pairs' forces
    (``unpaired_share``, contact/transfer.py), for the frames: without them a uniformly
    pressed face read 0 ("open") at every third node, and its pressure integrated to 12.5 of
    a load of 20 (tester V). Per node: its share of the pairs' normal and tangential forces
    (the rows of the transfer S^T applied to the pair forces, in the pairs' own directions)
    over its tributary length on surface 1 at ``x``: tractions per current length, as the
    pairs' t_N. contact.csv keeps its pair rows; these are the frames' only."""
    out: dict[str, list] = {"node": [], "normal_traction": [], "tangential_traction": []}
    for ci, res in zip(interfaces, results, strict=True):
        if res is None or res.transfer is None:
            continue
        nodes, normal, tangential = _shares_of(ci, res, x)
        for key, val in (("node", nodes), ("normal_traction", normal),
                         ("tangential_traction", tangential)):
            out[key].append(val)
    return {k: np.concatenate(v) if v else np.zeros(0, np.int64 if k == "node" else float)
            for k, v in out.items()}


def _shares_of(ci: ContactInterface, res: ContactResult, x: NDArray
               ) -> tuple[NDArray[np.int64], NDArray, NDArray]:
    """(nodes, t_N, t_T) of :func:`unpaired_shares` on one interface."""
    transfer, surface = res.transfer, ci.interface.surface1
    pair_of = {int(n): k for k, n in enumerate(res.pairs[:, 0])}
    # rows of S that belong to a surface-1 pair (a finer surface 2 has rows of its own)
    rows = [r for r, n in enumerate(transfer.distributed.tolist()) if n in pair_of]
    paired = [pair_of[int(transfer.distributed[r])] for r in rows]
    weights = transfer.weights[rows]
    normal = weights.T @ res.normal_force[paired]
    tangential = weights.T @ res.tangential_force[paired]
    # the surface-1 nodes the shares reach; a paired node keeps its pair's own traction
    nodes = np.setdiff1d(np.intersect1d(weights.indices, surface.nodes), res.pairs[:, 0])
    k = surface.index_of(nodes)
    length = 0.5 * (np.linalg.norm(x[nodes] - x[surface.prev[k]], axis=1)
                    + np.linalg.norm(x[surface.next[k]] - x[nodes], axis=1))
    return nodes, normal[nodes] / length, tangential[nodes] / length
