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

from .kinematics import pair_gaps
from .surfaces import Interface

__all__ = ["Pairing", "closest_pairs"]

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
    """Closest segment index, local coordinate and distance for every query point."""
    if len(q) * len(a) <= BRUTE_FORCE_PAIRS:
        return _closest_of_all_segments(q, a, b)
    from scipy.spatial import cKDTree  # only for large interfaces (~0.08 s to import)

    mid = 0.5 * (a + b)
    hits = cKDTree(mid).query_ball_point(q, radius)
    counts = np.fromiter((len(h) for h in hits), dtype=np.int64, count=len(hits))
    owner = np.repeat(np.arange(len(q)), counts)
    seg = np.fromiter((s for h in hits for s in h), dtype=np.int64, count=int(counts.sum()))
    ab = b[seg] - a[seg]
    xi = np.clip(np.einsum("ij,ij->i", q[owner] - a[seg], ab) / np.einsum("ij,ij->i", ab, ab),
                 0.0, 1.0)
    dist = np.linalg.norm(q[owner] - (a[seg] + xi[:, None] * ab), axis=1)
    order = np.lexsort((seg, dist, owner))  # per owner: smallest distance, then lowest segment
    first = order[np.r_[0, np.flatnonzero(np.diff(owner[order])) + 1]]
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
        from scipy.spatial import cKDTree

        distance, k = cKDTree(nodes).query(q)
        return distance, np.asarray(k, dtype=np.int64)
    d2 = ((q[:, None, :] - nodes[None, :, :]) ** 2).sum(axis=2)
    k = np.argmin(d2, axis=1)
    return np.sqrt(d2[np.arange(len(q)), k]), k


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


def ordered_partners(
    x: NDArray[np.float64], interface: Interface, node1: ArrayLike, taken: ArrayLike = ()
) -> NDArray[np.int64]:
    """Distinct surface-2 partners for ``node1``, in the same order along both surfaces.

    For node-to-node contact with an ALE partner surface, nearest-node pairing can give two
    nodes the same partner (graded or coarser partner meshes). This picks strictly increasing
    chain positions j_1 < ... < j_m for the candidates sorted along surface 2 (by their closest
    projection) minimizing the summed distances |x1_i - x2_{j_i}| (dynamic programming, O(m N)).
    Nodes in ``taken`` are not used. Open partner surfaces only; returns -1 where no partner
    can be assigned (more candidates than free nodes).
    """
    node1 = np.asarray(node1, dtype=np.int64)
    s2 = interface.surface2
    out = np.full(node1.size, -1, dtype=np.int64)
    if node1.size == 0:
        return out
    proj = closest_pairs(x, interface, candidates=node1)
    order = np.argsort(proj.segment + proj.xi, kind="stable")
    dist = np.linalg.norm(x[node1[order], None, :] - x[s2.nodes][None, :, :], axis=2)
    dist[:, np.isin(s2.nodes, np.asarray(taken, dtype=np.int64))] = np.inf
    m, n = dist.shape
    if m > n:
        return out
    cost = np.full((m, n), np.inf)
    choice = np.zeros((m, n), dtype=np.int64)
    cost[0] = dist[0]
    for i in range(1, m):  # loop over candidates (a handful per step), vectorized over nodes
        best = np.minimum.accumulate(cost[i - 1])
        arg = _running_argmin(cost[i - 1])
        cost[i, 1:] = best[:-1] + dist[i, 1:]
        choice[i, 1:] = arg[:-1]
    if not np.isfinite(cost[-1].min()):
        return out
    j = int(np.argmin(cost[-1]))
    picks = np.empty(m, dtype=np.int64)
    for i in range(m - 1, -1, -1):
        picks[i] = j
        j = choice[i, j]
    out[order] = s2.nodes[picks]
    return out


def _running_argmin(values: NDArray[np.float64]) -> NDArray[np.int64]:
    """Index of the minimum of values[:k+1] for every k."""
    idx = np.arange(values.size)
    best = np.minimum.accumulate(values)
    is_new = values <= best
    return np.maximum.accumulate(np.where(is_new, idx, 0))
