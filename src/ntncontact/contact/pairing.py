"""Pairing by closest projection (report 2.1.1, Fig. 2.2) and node-to-node partners.

For every candidate node of surface 1 the closest point of surface 2 (a point on one of its
segments) and the nearest node of surface 2 are found with k-d trees: the nearest-node distance
d bounds the closest-point distance, and any segment holding a point within d has its midpoint
within d + (longest segment)/2, so a ball query on segment midpoints finds every segment that
can hold the closest point. Small interfaces (at most :data:`BRUTE_FORCE_PAIRS` candidate-
segment combinations, e.g. the ring impact's 48 x 40) compare every combination instead: the
same answer (same distances, same tie-breaking) without building trees, ~5x faster there.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.spatial import cKDTree

from ..mesh.boundary import ball_pairs
from .kinematics import pair_gaps
from .surfaces import Interface

__all__ = ["Pairing", "beyond_ends", "beyond_reach", "closest_pairs", "neighbour_pairs"]

#: Up to this many (candidate, segment) combinations the closest points are found by comparing
#: all of them (module doc); beyond it the k-d trees, whose cost grows like C log S, win.
BRUTE_FORCE_PAIRS = 20_000


@dataclass(frozen=True)
class Pairing:
    """Closest partners of the candidate surface-1 nodes ``node1`` (C,).

    node2: nearest surface-2 node (the node-to-node partner); node_distance: |x1 - x_node2|.
    segment: index into ``interface.surface2.edges()`` of the closest segment; xi in [0, 1]
    its local coordinate; point: the closest point; distance: |x1 - point|.
    gap: node-to-node gap (x1 - x_node2) . n1 (2.4, n1 as in the contact kernels, corners
    included); projection_gap: (x1 - point) . n1. shared: node2 also nearest to another node1.
    """

    node1: NDArray[np.int64]
    node2: NDArray[np.int64]
    node_distance: NDArray[np.float64]
    segment: NDArray[np.int64]
    xi: NDArray[np.float64]
    point: NDArray[np.float64]
    distance: NDArray[np.float64]
    gap: NDArray[np.float64]
    projection_gap: NDArray[np.float64]
    shared: NDArray[np.bool_]

    @property
    def pairs(self) -> NDArray[np.int64]:
        """(C, 2) node-to-node candidate pairs for :func:`~ntncontact.contact.detection.detect`."""
        return np.column_stack((self.node1, self.node2))


def _closest_on_segments(
    q: NDArray, a: NDArray, b: NDArray, radius: NDArray
) -> tuple[NDArray, NDArray, NDArray]:
    """Closest segment index, local coordinate and distance for every query point. Of equal
    distances the lowest segment wins, found by a minimum per query (the hits come grouped
    by query) rather than a sort: 1,021 queries and segments 1.5 -> 1.1 ms, 16,021 25 -> 16 ms
    (CPU; both about linear, the ball query and its flattening dominating)."""
    if len(q) * len(a) <= BRUTE_FORCE_PAIRS:
        return _closest_of_all_segments(q, a, b)
    owner, seg = ball_pairs(cKDTree(0.5 * (a + b)), q, radius, sort=True)
    ab = b[seg] - a[seg]
    xi = np.clip(np.einsum("ij,ij->i", q[owner] - a[seg], ab) / np.einsum("ij,ij->i", ab, ab),
                 0.0, 1.0)
    dist = np.linalg.norm(q[owner] - (a[seg] + xi[:, None] * ab), axis=1)
    # every query has a hit (its nearest node's segment), so the groups start at these rows
    start = np.flatnonzero(np.r_[True, owner[1:] != owner[:-1]])
    nearest = dist == np.minimum.reduceat(dist, start)[owner]
    lowest = np.minimum.reduceat(np.where(nearest, seg, len(a)), start)
    first = np.flatnonzero(nearest & (seg == lowest[owner]))
    return seg[first], xi[first], dist[first]


def _closest_of_all_segments(q: NDArray, a: NDArray, b: NDArray
                             ) -> tuple[NDArray, NDArray, NDArray]:
    """:func:`_closest_on_segments` comparing every segment (a superset of the ball query's,
    so the same answer): the same arithmetic per combination, and argmin keeps the lowest
    segment among equal distances as the lexsort does."""
    ab = b - a  # (S, 2)
    rel = q[:, None, :] - a[None, :, :]  # (C, S, 2)
    xi = np.clip(np.einsum("csi,si->cs", rel, ab) / np.einsum("si,si->s", ab, ab), 0.0, 1.0)
    dist = np.linalg.norm(q[:, None, :] - (a[None] + xi[..., None] * ab[None]), axis=2)
    seg = np.argmin(dist, axis=1)
    rows = np.arange(len(q))
    return seg, xi[rows, seg], dist[rows, seg]


def _nearest_nodes(q: NDArray, nodes: NDArray) -> tuple[NDArray, NDArray[np.int64]]:
    """Distance to and index of the nearest of ``nodes`` for every query point; of equally
    near nodes the k-d tree may return any, the comparison of all the first."""
    if len(q) * len(nodes) > BRUTE_FORCE_PAIRS:
        distance, k = cKDTree(nodes).query(q)
        return distance, np.asarray(k, dtype=np.int64)
    d2 = ((q[:, None, :] - nodes[None, :, :]) ** 2).sum(axis=2)
    k = np.argmin(d2, axis=1)
    return np.sqrt(d2[np.arange(len(q)), k]), k


#: a node whose closest point on an open surface 2 is one of its ends, and which lies beyond
#: that end by more than this fraction of the end segment (and than its own longest segment
#: on surface 1), faces no part of the surface
BEYOND_END = 0.5


def beyond_ends(x: NDArray[np.float64], interface: Interface, pairing: Pairing
                ) -> NDArray[np.bool_]:
    """Which of the pairing's surface-1 nodes lie beyond an end of an open surface 2, along
    the end segment, by more than BEYOND_END of it and more than the node's own longest
    segment on surface 1: no segment of either surface then joins the node to surface 2, and
    it faces nothing that can hold it. A pair kept there held a block that had slid off its
    base 1.5 past the end (an independent tester's case: its nodes rested on base nodes 2
    away). Within its own segment a node still holds the partner's end: a coarse floor's
    node just past a block's corner is what carries that corner (a block in a corner, its
    floor's node 0.06 past the block's end with floor segments of 0.11: released at the
    block's half segment, 0.05, the corner sank 1.3e-3)."""
    s1, s2 = interface.surface1, interface.surface2
    if s2.closed or len(pairing.node1) == 0:
        return np.zeros(len(pairing.node1), bool)
    edges = s2.edges()
    a, b = x[edges[pairing.segment, 0]], x[edges[pairing.segment, 1]]
    length = np.linalg.norm(b - a, axis=1)
    # signed distance beyond the segment's end point (negative: beyond its start point)
    along = np.einsum("ij,ij->i", x[pairing.node1] - pairing.point, b - a) / length
    k = s1.index_of(pairing.node1)
    own = np.maximum(np.linalg.norm(x[s1.prev[k]] - x[pairing.node1], axis=1),
                     np.linalg.norm(x[s1.next[k]] - x[pairing.node1], axis=1))
    reach = np.maximum(BEYOND_END * length, own)
    at_start = (pairing.segment == 0) & (pairing.xi <= 0.0)
    at_end = (pairing.segment == len(edges) - 1) & (pairing.xi >= 1.0)
    return (at_start & (along < -reach)) | (at_end & (along > reach))


def _empty_pairing() -> Pairing:
    i, f = np.zeros(0, np.int64), np.zeros(0)
    return Pairing(i, i, f, i, f, np.zeros((0, 2)), f, f, f, np.zeros(0, bool))


def closest_pairs(
    x: NDArray[np.float64],
    interface: Interface,
    candidates: ArrayLike | None = None,
    exclude: ArrayLike = (),
    unique: bool = False,
) -> Pairing:
    """Closest projection and nearest node on surface 2 of the candidate surface-1 nodes.

    candidates: global surface-1 nodes (default: all of surface 1); exclude: nodes to skip
    (e.g. body corners kept out of the contact interface, report 6.1).
    unique: keep, for each surface-2 node claimed by several candidates, only the closest one
    (node-to-node pairing needs distinct partners; the others wait for the ALE motion).
    """
    s1, s2 = interface.surface1, interface.surface2
    node1 = s1.nodes if candidates is None else np.asarray(candidates, dtype=np.int64)
    node1 = node1[~np.isin(node1, np.asarray(exclude, dtype=np.int64))]
    if node1.size == 0:
        return _empty_pairing()
    q = x[node1]
    node_distance, k = _nearest_nodes(q, x[s2.nodes])
    node2 = s2.nodes[k]
    edges = s2.edges()
    a, b = x[edges[:, 0]], x[edges[:, 1]]
    half = 0.5 * np.max(np.linalg.norm(b - a, axis=1))
    radius = node_distance + half * (1.0 + 1e-12) + 1e-300  # round-off margin only
    seg, xi, dist = _closest_on_segments(q, a, b, radius)
    if unique and node1.size:
        order = np.lexsort((node_distance, node2))
        keep = np.zeros(node1.size, bool)
        keep[order[np.r_[0, np.flatnonzero(np.diff(node2[order])) + 1]]] = True
        node1, node2, node_distance = node1[keep], node2[keep], node_distance[keep]
        seg, xi, dist = seg[keep], xi[keep], dist[keep]
    point = a[seg] + xi[:, None] * (b[seg] - a[seg])
    normal, gap, _ = pair_gaps(x, interface, np.column_stack((node1, node2)))
    proj_gap = np.einsum("ij,ij->i", x[node1] - point, normal)
    _, inv, cnt = np.unique(node2, return_inverse=True, return_counts=True)
    return Pairing(node1, node2, np.asarray(node_distance, float), seg, xi, point, dist,
                   gap, proj_gap, cnt[inv.reshape(-1)] > 1)


#: Two new pairs, or a new and a kept pair, may bring their surface-2 nodes no closer than
#: this fraction of their present distance along surface 2: the same band the ALE respacing
#: keeps (``ale.motion``, spacing_tolerance = 0.5), so pairing never squeezes the ALE surface.
MIN_MATCHED_SPACING = 0.5


def neighbour_pairs(x: NDArray[np.float64], interface: Interface, active: ArrayLike,
                    reach: int) -> tuple[NDArray[np.int64], ...]:
    """The pairs that the surface-1 nodes within ``reach`` chain steps of the ``active`` ones
    (not active themselves) would form with their nearest surface-2 node at x, and with its
    predecessor and its successor along surface 2 (three (P, 2) arrays, each with distinct
    surface-1 nodes): the pairs a growing contact zone takes in next, whose matrix entries
    the union pattern reserves (``fem.sparse``). The chain neighbours stand in for the
    partner the ALE motion or the ordered pairing may give instead of the nearest node."""
    s1, s2 = interface.surface1, interface.surface2
    active = np.asarray(active, dtype=np.int64)
    if active.size == 0 or reach < 1:
        return ()
    around = (s1.index_of(active)[:, None] + np.arange(-reach, reach + 1)).ravel()
    around = around % s1.size if s1.closed else around[(around >= 0) & (around < s1.size)]
    nodes = np.setdiff1d(s1.nodes[around], active)
    nearest = closest_pairs(x, interface, nodes).node2
    at = s2.index_of(nearest)
    return tuple(np.column_stack([nodes, partner]) for partner in (nearest, s2.prev[at],
                                                                     s2.next[at]))


def ordered_partners(
    x: NDArray[np.float64], interface: Interface, node1: ArrayLike, taken: ArrayLike = (),
    kept: ArrayLike = (), reference_arc: ArrayLike | None = None,
) -> NDArray[np.int64]:
    """Distinct surface-2 partners for the free candidates ``node1``, in the same order along
    both surfaces, for node-to-node contact with an ALE surface at any spacing ratio; -1 where a
    candidate stays unpaired. Open partner surfaces only.

    Rule (docs/theory.md, "Partners at any spacing ratio"): among the pairs (i, j) whose nodes
    lie within reach, |x_i - x_j| <= r_ij = the longer of the two nodes' longest adjacent
    segments (surface 2's counted at no more than :data:`REACH_STRETCH` times their length in
    ``reference_arc``, ``_surface2_reach``),
    choose an order-preserving matching (candidates ordered by their closest
    projection on surface 2, surface-2 nodes by their chain index) with the most pairs and,
    of those, the largest summed closeness 1 - |x_i - x_j| / r_ij: every node that can be
    matched is, each to its nearest partner where the order allows. Consecutive matched
    pairs, the kept pairs ``kept`` ((k, 2), which bound the order and whose surface-2 nodes
    are taken, as are ``taken``) included, must leave their surface-2 nodes at least
    :data:`MIN_MATCHED_SPACING` of their distance along surface 2 in ``reference_arc`` (the
    arc length of every surface-2 node in the original mesh; default: at x). Measured on the
    original mesh, repeated pairings cannot creep: a finer partner rolling over the ALE
    surface does not pull one ALE node per partner node into its wake. So a
    partner finer than the ALE surface gets one node per ALE node and its other nodes stay
    unpaired; a coarser one gets one ALE node per partner node and the other ALE nodes are
    respaced between them by the mesh motion.
    Dynamic programming over the admissible pairs (a few per candidate), about linear in the
    surface (:func:`_nearby_pairs`, :func:`_preceding_for_sure`): the tester's layer of 1,000 /
    2,000 / 4,000 surface nodes 110 / 701 / 2,200 ms -> 49 / 91 / 182 ms CPU, same partners.
    """
    node1 = np.asarray(node1, dtype=np.int64)
    out = np.full(node1.size, -1, dtype=np.int64)
    kept_pairs = np.asarray(kept, dtype=np.int64).reshape(-1, 2)
    if node1.size == 0:
        return out
    s2 = interface.surface2.nodes
    arc2 = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(x[s2], axis=0), axis=1))])
    proj = closest_pairs(x, interface, candidates=np.concatenate([node1, kept_pairs[:, 0]]))
    edges2 = interface.surface2.edges()
    along = arc2[proj.segment] + proj.xi * np.linalg.norm(
        x[edges2[proj.segment, 1]] - x[edges2[proj.segment, 0]], axis=1)
    depth = np.maximum(proj.projection_gap[: node1.size], 0.0)
    cand, j, weight = _admissible_pairs(x, interface, node1, taken, kept_pairs, s2, depth,
                                        reference_arc)
    kept_j = interface.surface2.index_of(kept_pairs[:, 1])
    spacing_arc = arc2 if reference_arc is None else np.asarray(reference_arc, dtype=float)
    picks = _best_matching(along[: node1.size], arc2, spacing_arc, cand, j, weight,
                           along[node1.size:], kept_j)
    out[cand[picks]] = s2[j[picks]]
    return out


def _longest_adjacent_segment(x: NDArray, surface) -> NDArray[np.float64]:
    """Per node of ``surface`` (chain order) the length of its longer adjacent segment."""
    edges = surface.edges()
    return _longer_of_segments(np.linalg.norm(x[edges[:, 1]] - x[edges[:, 0]], axis=1),
                               surface.size)


def _longer_of_segments(length: NDArray, n_nodes: int) -> NDArray[np.float64]:
    """Per chain node the longer of its adjacent segments' ``length`` (segment k joins chain
    nodes k and k + 1, the last one of a closed chain node 0)."""
    out = np.zeros(n_nodes)
    k = np.arange(length.size)
    np.maximum.at(out, k, length)
    np.maximum.at(out, (k + 1) % n_nodes, length)
    return out


#: How far from an ALE surface's node, in its longer adjacent segment of the original mesh,
#: a partner may be and still pair with it (``_surface2_reach``). The mesh motion stretches
#: a segment to reach a new partner (the disk drop's block: a node 1.26 of its original
#: spacing away, across a segment stretched to 2.1 of it), but one it stretched behind a
#: partner it could not follow is no reach.
REACH_STRETCH = 2.0


def _surface2_reach(x: NDArray, interface: Interface, reference_arc: ArrayLike | None
                    ) -> NDArray[np.float64]:
    """Per surface-2 node (chain order) its reach: its longer adjacent segment, counted at no
    more than :data:`REACH_STRETCH` times its length in ``reference_arc`` (the original mesh;
    None: as it is at x). A segment the ALE mesh motion stretched behind a partner it could
    not follow (clamped by ``ale.max_stretch``) does not extend the reach: with the stretched
    length a tester's block, sliding 5 of its lengths over an ALE base, kept its trailing
    corner pressed on a base node 4.5 (45 spacings) behind it, and a block on a base stretched
    to 4x paired its corner with the base's fixed chain end 0.64 away (spacing 0.1 / 0.17)."""
    reach = _longest_adjacent_segment(x, interface.surface2)
    if reference_arc is None:
        return reach
    arc = np.asarray(reference_arc, dtype=float)
    return np.minimum(reach, REACH_STRETCH * _longer_of_segments(np.diff(arc), arc.size))


def beyond_reach(x: NDArray[np.float64], interface: Interface, pairs: ArrayLike,
                 reference_arc: ArrayLike | None = None) -> NDArray[np.bool_]:
    """Which pairs (P, 2) of an ordered (ALE) interface ``ordered_partners`` would not admit:
    their nodes farther apart, beyond the surface-1 node's depth behind surface 2, than the
    longer of the two nodes' reaches. Open partner surfaces only. A kept pair whose ALE node
    could not follow its partner is no node-to-node pair: detection releases it and pairs
    its node afresh, as it pairs a new one (``engine.interfaces._kept_where_they_face``)."""
    pairs = np.asarray(pairs, dtype=np.int64).reshape(-1, 2)
    if pairs.size == 0:
        return np.zeros(0, bool)
    s1, s2 = interface.surface1, interface.surface2
    reach1 = _longest_adjacent_segment(x, s1)[s1.index_of(pairs[:, 0])]
    reach2 = _surface2_reach(x, interface, reference_arc)[s2.index_of(pairs[:, 1])]
    depth = np.maximum(closest_pairs(x, interface, pairs[:, 0]).projection_gap, 0.0)
    dist = np.linalg.norm(x[pairs[:, 0]] - x[pairs[:, 1]], axis=1) - depth
    return dist > np.maximum(reach1, reach2)


def _admissible_pairs(x: NDArray, interface: Interface, node1: NDArray, taken: ArrayLike,
                      kept: NDArray, s2: NDArray, depth: NDArray | None = None,
                      reference_arc: ArrayLike | None = None
                      ) -> tuple[NDArray, NDArray, NDArray]:
    """(candidate index, surface-2 chain index, weight) of the pairs within reach whose
    surface-2 node is free: weight 1 + closeness / (C + 1) for C candidates, so that a
    matching with more pairs always weighs more, and of equally many the closer one.

    ``depth`` (C,): how far each candidate lies behind surface 2 (its projection gap, >= 0).
    Reach and closeness take the distance beyond it, |x_i - x_j| - depth_i (the offset
    along the surface for a flat one): across the surface the distance is the gap, which
    contact closes, not the mesh. With the full distance, the fast-sliding blocks refined 8x
    (segments 6.25e-3) left unpaired the nodes that one step had taken 6.0-6.6e-3 deep
    (v dt = 6e-3), and their thin bottom row was crushed (issue 17)."""
    reach1 = _longest_adjacent_segment(x, interface.surface1)[
        interface.surface1.index_of(node1)]
    reach2 = _longest_adjacent_segment(x, interface.surface2)
    capped2 = _surface2_reach(x, interface, reference_arc)
    behind = np.zeros(node1.size) if depth is None else np.asarray(depth, dtype=float)
    cand, j = _nearby_pairs(x[node1], x[s2], behind + np.maximum(reach1, reach2.max()))
    dist = np.linalg.norm(x[node1][cand] - x[s2][j], axis=1)
    if depth is not None:
        dist = np.maximum(dist - behind[cand], 0.0)
    reach = np.maximum(reach1[cand], reach2[j])
    busy = np.isin(s2, np.concatenate([np.asarray(taken, np.int64).reshape(-1), kept[:, 1]]))
    # the capped reach only bounds which pairs are admitted; closeness keeps the segments
    within = (dist <= np.maximum(reach1[cand], capped2[j])) & (dist <= reach) & ~busy[j]
    cand, j, dist, reach = cand[within], j[within], dist[within], reach[within]
    closeness = 1.0 - dist / reach
    return cand, j, 1.0 + closeness / (node1.size + 1.0)


def _nearby_pairs(q: NDArray, nodes: NDArray, radius: NDArray
                  ) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """(query, node) index pairs, in row-major order, that include all within ``radius`` of
    each other (a round-off margin more: the caller tests the pairs exactly). Comparing all
    of them made ``_admissible_pairs`` n^2 (the tester's layer of 2,000 and 4,000 surface
    nodes: 0.76 and 2.76 s with ``_interval_matching``); a ball query is n log n."""
    if len(q) * len(nodes) <= BRUTE_FORCE_PAIRS:
        return np.divmod(np.arange(len(q) * len(nodes), dtype=np.int64), len(nodes))
    return ball_pairs(cKDTree(nodes), q, radius * (1.0 + 1e-9) + 1e-300, sort=True)


def _best_matching(along: NDArray, arc2: NDArray, spacing_arc: NDArray, cand: NDArray,
                   j: NDArray, weight: NDArray, kept_along: NDArray, kept_j: NDArray
                   ) -> NDArray[np.int64]:
    """Indices into the admissible pairs of the best order-preserving matching (see
    ``ordered_partners``): between each two consecutive kept pairs (and beyond the outer
    ones) a longest-path DP over the pairs sorted along surface 2. ``arc2``: the surface-2
    nodes' arc lengths at x, ``spacing_arc`` those the spacing rule measures."""
    order = np.argsort(kept_j)
    bounds_j = np.concatenate([[-1], kept_j[order], [arc2.size]])
    bounds_along = np.concatenate([[-np.inf], kept_along[order], [np.inf]])
    bounds_arc = np.concatenate([[-np.inf], spacing_arc[kept_j[order]], [np.inf]])
    # each pair's interval by a search of the bounds: one scan of all the pairs per kept
    # pair was n^2 once most of a long interface is kept
    k = np.searchsorted(bounds_j, j, side="right") - 1
    between = np.clip(k, 0, bounds_j.size - 2)
    inside = np.flatnonzero((k >= 0) & (k < bounds_j.size - 1) & (j > bounds_j[between])
                            & (along[cand] > bounds_along[between])
                            & (along[cand] < bounds_along[between + 1]))
    inside = inside[np.argsort(k[inside], kind="stable")]
    picks = []
    for group in np.split(inside, np.flatnonzero(np.diff(k[inside])) + 1):
        if group.size:
            b = k[group[0]]
            left = (bounds_along[b], bounds_arc[b])
            right = (bounds_along[b + 1], bounds_arc[b + 1])
            picks += _interval_matching(group, along[cand], spacing_arc[j], j, cand, weight,
                                        left, right)
    return np.asarray(picks, dtype=np.int64)


def _interval_matching(pairs: NDArray, along: NDArray, arc: NDArray, j: NDArray, cand: NDArray,
                       weight: NDArray, left: tuple, right: tuple) -> list[int]:
    """The DP of ``_best_matching`` on the admissible ``pairs`` between two anchors (left and
    right: (position of the partner along surface 2, arc length of the surface-2 node), each
    infinite where there is none)."""

    def spaced(a_along, a_arc, b_along, b_arc):  # b follows a: far enough apart on surface 2
        with np.errstate(invalid="ignore"):
            return ~(b_along - a_along < MIN_MATCHED_SPACING * (b_arc - a_arc))

    pairs = pairs[np.lexsort((j[pairs], along[pairs]))]
    p_along, p_arc, p_j, p_cand = along[pairs], arc[pairs], j[pairs], cand[pairs]
    best = np.where(spaced(left[0], left[1], p_along, p_arc), weight[pairs], -np.inf)
    back = np.full(pairs.size, -1, dtype=np.int64)
    start = _preceding_for_sure(p_along, p_arc, p_j)
    top = np.zeros(pairs.size, dtype=np.int64)  # first index of the largest best[:q + 1]
    for q in range(pairs.size):
        t = start[q]
        prev = t + np.flatnonzero((p_cand[t:q] != p_cand[q]) & (p_j[t:q] < p_j[q])
                                  & (p_along[t:q] < p_along[q])
                                  & spaced(p_along[t:q], p_arc[t:q], p_along[q], p_arc[q]))
        k = top[t - 1] if t > 0 else -1  # of equal best the lowest index, as argmax over all
        if prev.size and (k < 0 or best[prev].max() > best[k]):
            k = prev[np.argmax(best[prev])]
        if k >= 0 and best[k] + weight[pairs[q]] > best[q]:
            best[q], back[q] = best[k] + weight[pairs[q]], k
        top[q] = q if q == 0 or best[q] > best[top[q - 1]] else top[q - 1]
    best[~spaced(p_along, p_arc, right[0], right[1])] = -np.inf
    if not np.any(best > 0.0):
        return []
    q, out = int(np.argmax(best)), []
    while q >= 0:
        out.append(int(pairs[q]))
        q = int(back[q])
    return out


def _preceding_for_sure(along: NDArray, arc: NDArray, j: NDArray) -> NDArray[np.int64]:
    """For each pair q of the sorted ones, how many of the first pairs may precede it in the
    matching whatever they are: a lower position along surface 2 (so another candidate), a
    lower surface-2 node and, with a round-off margin, the spacing rule
    along_q - along_k >= MIN_MATCHED_SPACING (arc_q - arc_k). The DP takes the best of those
    as a running maximum and tests only the pairs after them (a few candidates' worth): each
    pair tested all the earlier ones, n^2 in a long interface (the tester's layer: 0.76 s at
    2,000 surface nodes, 2.76 s at 4,000)."""
    scale = np.max(np.abs(along), initial=0.0) + np.max(np.abs(arc), initial=0.0)
    if not np.isfinite(scale):
        return np.zeros(along.size, dtype=np.int64)
    lower = np.searchsorted(along, along, side="left")
    lower_j = np.searchsorted(np.maximum.accumulate(j), j, side="left")
    h = along - MIN_MATCHED_SPACING * arc
    spaced = np.searchsorted(np.maximum.accumulate(h), h - 1e-12 * scale, side="right")
    return np.minimum(np.minimum(lower, lower_j), spaced)
