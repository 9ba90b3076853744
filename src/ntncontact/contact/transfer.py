"""The share of unpaired surface nodes: node-to-node pairs between surfaces of unequal node counts.

Node-to-node pairs carry point forces. Where one surface has more nodes than the other in the
contact zone, some of its nodes lie between two paired nodes and get no pair: the traction on
that surface is lumped onto the paired nodes only, and a uniform pressure is not transmitted as
one (issue 16's patch test: 6 % with an ALE body, 13 % without). Here each such segment of the
finer surface takes its share with the weights of a dual mortar method (docs/theory.md,
"Unequal node counts"): over a coarse segment between two consecutive pairs a, b, parametrised
by xi in [0, 1] along the finer surface's arc length, the pressure node a of the coarse side has
the dual shape function psi_a = 2 - 3 xi (psi_b = 3 xi - 1), biorthogonal to the hats:
int psi_a N_b = 0, int psi_a N_a = int N_a. The finer surface's node q then receives the share

    w_aq = sum over a's segments of (H / L_c,a) int_0^1 psi_a N_q dxi

of pair a's force (H the segment's length on surface 1, L_c,a the pair's tributary length), and
the pair's point on that surface is sum_q w_aq x_q. Where a segment has no unpaired node
between its pairs (equal counts), w is the identity: the pairs stay node to node.

The transfer is a map S(x) of the node positions: the contact kernel is evaluated at
x_c = S x (and v_c = S v, x_start_c = S x_start), and its force comes back as S^T f. The weights
are taken at the evaluated positions and move with them, so the tangent is S^T K S plus the
weights' own terms S^T K_a (dS/dx) a (a = x, v, x_start, with the kernel's partial tangents)
and (dS/dx)^T f (:meth:`Transfer.weight_terms`; docs/theory.md, "Unequal node counts").
Without them (S^T K S only, exact only where the arc-length parameters of the finer surface do
not change) a sheared flat surface gave FD vs J 1e-3 and linear Newton. dS/dx is taken per
shared segment in closed form on its few nodes (lengths, arc-length parameters, the dual-hat
integrals' derivative); the kernel returns its partial tangents in the same call as the force.
Both, and the mapping of the tangent, wait until a tangent is built (``Transfer.derivative``,
``ContactResult.triplets``): most evaluations are residuals.
Not included: the weights' part of a gap-restoring pair's first-step offset g_n(S x_start)/dt
(rate law), one step per pair.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property
from typing import NamedTuple

import numpy as np
import scipy.sparse as sp
from numpy.typing import NDArray

from .surfaces import ContactSurface, Interface

__all__ = ["Transfer", "unpaired_share"]


class ShareBlock(NamedTuple):
    """d W / d x of G shared segments with chains of m nodes, dense on each segment's few
    local nodes (its chain and its two pairs' surface-1 (prev, node, next)): ``value``
    (G, local dofs, 2 pairs, m + 1) is d W_rq / d x_k for the pair's row r = ``rows`` (G, 2)
    (index into ``distributed``), q = ``nodes`` (G, 2, m + 1) (the chain, then the row's own
    node) and k = ``dofs`` (G, local dofs). Repeated local nodes add up when summed."""

    rows: NDArray[np.int64]
    nodes: NDArray[np.int64]
    dofs: NDArray[np.int64]
    value: NDArray[np.float64]


@dataclass(frozen=True)
class Transfer:
    """The kernel's view of an interface whose pairs have unpaired nodes between them.

    surface1: surface 1 without its unpaired nodes between consecutive pairs (the pairs' chain:
        tributary lengths and normals from the paired nodes). S, x_c = S x, is the identity
    but on the ``distributed`` nodes (sorted), whose rows are ``weights`` (node level, CSR,
    one row per distributed node, columns: all nodes). S is applied on those rows only: an
    (ndof, ndof) sparse S made every contact evaluation O(ndof) (kron, S^T K S: 23 ms per
    evaluation at ring k = 8, 8 % of a contact step, issue 18)."""

    surface1: ContactSurface
    distributed: NDArray[np.int64]
    weights: sp.csr_matrix
    #: the positions and the shared segments [(chain, its two pairs' (row node, surface-1
    #: node))] the weights were taken from, for :attr:`derivative`; None: weights held fixed
    x: NDArray[np.float64] | None = None
    segments: list[tuple[NDArray, NDArray]] | None = None

    @cached_property
    def derivative(self) -> tuple[ShareBlock, ...] | None:
        """d W / d x by groups of shared segments (:class:`ShareBlock`): the weights move with
        the surfaces (arc-length parameters, span, tributary lengths). Computed on first use:
        most evaluations are residuals that never map a tangent back."""
        if self.segments is None:
            return None
        return _share_derivatives(self.x, self.surface1, self.segments, self.distributed)

    def positions(self, x: NDArray[np.float64] | None) -> NDArray[np.float64] | None:
        if x is None:
            return None
        out = np.array(x, dtype=float).reshape(-1, 2)
        out[self.distributed] = self.weights @ out  # right side read before the write
        return out.reshape(np.shape(x))

    def force(self, force: NDArray[np.float64]) -> NDArray[np.float64]:
        """S^T f."""
        out = np.array(force, dtype=float).reshape(-1, 2)
        shared = out[self.distributed].copy()
        out[self.distributed] = 0.0
        out += self.weights.T @ shared
        return out.reshape(np.shape(force))

    def tangent(self, rows: NDArray, cols: NDArray, vals: NDArray,
                moving: list[tuple[NDArray, NDArray]] | None = None,
                kernel_force: NDArray[np.float64] | None = None
                ) -> tuple[NDArray[np.int64], NDArray[np.int64], NDArray[np.float64]]:
        """S^T K S of a COO K (dofs), with ``moving`` plus the weights' own terms
        (:meth:`weight_terms` of ``moving`` and ``kernel_force``), summed into unique sorted
        entries."""
        extra = [] if moving is None else [self.weight_terms(rows, cols, moving, kernel_force)]
        rows, cols, vals = self._expand(rows, cols, vals)  # S^T K: K's rows spread
        cols, rows, vals = self._expand(cols, rows, vals)  # (S^T K) S: its columns spread
        return _summed([(rows, cols, vals), *extra], self.weights.shape[1] * 2)

    def weight_terms(self, rows: NDArray, cols: NDArray,
                     moving: list[tuple[NDArray, NDArray]], kernel_force: NDArray[np.float64]
                     ) -> tuple[NDArray[np.int64], NDArray[np.int64], NDArray[np.float64]]:
        """The tangent's terms from the weights' own dependence on x (dof entries, unsummed):
        S^T sum K_a (dS/dx) a over ``moving`` [(K_a's values on rows, cols; a)], the kernel's
        partial derivatives with respect to its weighted inputs S a (positions: a = x; rates:
        v), and (dS/dx)^T f, f the kernel's force (before ``force``). Without them Newton on
        a sheared surface went linear (FD vs J 1e-3, 52 iterations for 19 in a static step)."""
        if self.derivative is None:
            return _EMPTY
        k_rows, k_cols, k_vals = self._expand(*self._through(rows, cols, moving))  # S^T K D
        f = np.asarray(kernel_force, dtype=float).reshape(-1, 2)
        out_rows, out_cols, out_vals = [k_rows], [k_cols], [k_vals]
        for block in self.derivative:  # (dW_rq/dx_k) f_r on q's dofs: (G, dof, pair, q, i)
            f_r = f[self.distributed[block.rows]]  # (G, 2, 2)
            vals = block.value[..., None] * f_r[:, None, :, None, :]
            out_rows.append(np.broadcast_to((2 * block.nodes[..., None] + _COMP)[:, None],
                                            vals.shape).ravel())
            out_cols.append(np.broadcast_to(block.dofs[:, :, None, None, None],
                                            vals.shape).ravel())
            out_vals.append(vals.ravel())
        return np.concatenate(out_rows), np.concatenate(out_cols), np.concatenate(out_vals)

    def _through(self, rows: NDArray, cols: NDArray, moving: list[tuple[NDArray, NDArray]]
                 ) -> tuple[NDArray[np.int64], NDArray[np.int64], NDArray[np.float64]]:
        """sum A_a D_a over ``moving`` [(A_a's values on the COO places rows, cols (dofs);
        a)]: D_a = (dS/dx) a, the change of the weighted points S a as the weights move,
        nonzero on the distributed nodes' rows only. One product [A_1 A_2 ..] [D_1; D_2; ..]:
        the parts share their places, and each product's fixed cost is SciPy's."""
        rows, cols = np.asarray(rows, np.int64), np.asarray(cols, np.int64)
        n_dist = self.distributed.size
        at = np.minimum(np.searchsorted(self.distributed, cols // 2), n_dist - 1)
        hit = self.distributed[at] == cols // 2
        if not hit.any():
            return _EMPTY
        wanted = 2 * at[hit] + cols[hit] % 2  # A's hit column as a row of D
        a_cols, a_vals, d_rows, d_cols, d_vals = [], [], [], [], []
        for part, (vals, a) in enumerate(moving):
            offset = 2 * n_dist * part  # part's rows of the stacked D
            a_cols.append(wanted + offset)
            a_vals.append(np.asarray(vals, dtype=float)[hit])
            a = np.asarray(a, dtype=float).reshape(-1, 2)
            # D_a: row (distributed r, component i), column k: sum_q a_q,i dW_rq/dx_k, dense
            # per segment in NumPy (scipy's sparse products per block cost more than the rest)
            for block in self.derivative:
                d_a = np.einsum("gdpq,gpqi->gpid", block.value, a[block.nodes])  # (G,2,2,dof)
                d_rows.append(np.broadcast_to((2 * block.rows[..., None] + _COMP + offset)
                                              [..., None], d_a.shape).ravel())
                d_cols.append(np.broadcast_to(block.dofs[:, None, None], d_a.shape).ravel())
                d_vals.append(d_a.ravel())
        return _product(np.tile(rows[hit], len(moving)), np.concatenate(a_cols),
                        np.concatenate(a_vals), np.concatenate(d_rows), np.concatenate(d_cols),
                        np.concatenate(d_vals), (2 * n_dist * len(moving), 2 * a.shape[0]))

    def columns(self, rows: NDArray, cols: NDArray, vals: NDArray, n_rows: int,
                moving: list[tuple[NDArray, NDArray]] | None = None
                ) -> tuple[NDArray[np.int64], NDArray[np.int64], NDArray[np.float64]]:
        """A (n_rows, ndof) COO block G_c as G_c S, plus sum G_a (dS/dx) a over ``moving``
        (as in :meth:`weight_terms`) for a block that is a derivative with respect to x."""
        parts = [] if not moving or self.derivative is None else [
            self._through(rows, cols, moving)]
        cols, rows, vals = self._expand(cols, rows, vals)
        return _summed([(rows, cols, vals), *parts], self.weights.shape[1] * 2)

    def _expand(self, index: NDArray, other: NDArray, vals: NDArray
                ) -> tuple[NDArray[np.int64], NDArray[np.int64], NDArray[np.float64]]:
        """Entries (index, other, v) whose ``index`` dof is on a distributed node r replaced by
        (dof of node q, same component, other, W_rq v) for the nodes q of W's row r: the
        product S^T A on A's row index (or A S on its column index)."""
        index, other = np.asarray(index, np.int64), np.asarray(other, np.int64)
        vals = np.asarray(vals, dtype=float)
        node, component = index // 2, index % 2
        at = np.minimum(np.searchsorted(self.distributed, node), self.distributed.size - 1)
        hit = self.distributed[at] == node
        w = self.weights
        start, count = w.indptr[at[hit]], np.diff(w.indptr)[at[hit]]
        # for each hit entry, the positions start .. start + count - 1 of W's row
        repeat = np.repeat(np.arange(count.size), count)
        offset = np.arange(repeat.size) - np.repeat(np.cumsum(count) - count, count)
        entries = start[repeat] + offset
        keep = ~hit
        return (np.concatenate([index[keep], 2 * w.indices[entries].astype(np.int64)
                                + component[hit][repeat]]),
                np.concatenate([other[keep], other[hit][repeat]]),
                np.concatenate([vals[keep], vals[hit][repeat] * w.data[entries]]))


_EMPTY = (np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0))
_COMP = np.arange(2)


def _product(a_rows: NDArray, a_cols: NDArray, a_vals: NDArray, b_rows: NDArray,
             b_cols: NDArray, b_vals: NDArray, b_shape: tuple[int, int]
             ) -> tuple[NDArray[np.int64], NDArray[np.int64], NDArray[np.float64]]:
    """A B of two COO matrices as unique entries sorted by row then column, those whose
    products sum to exactly zero kept (a pattern that moved with the values would be a new
    analysis of the Newton matrix). Each A entry times each entry of its B row, summed
    afterwards, was 26k entries for 2k sums at a refined slide (k = 4) and cost 8 ms a
    tangent in the sort; SciPy's product sums as it goes, but drops the zeros, so the
    pattern is that of a second product of the structures (positive: no cancellation)."""
    n_rows = int(a_rows.max(initial=-1)) + 1
    a = sp.csr_matrix((a_vals, (a_rows, a_cols)), shape=(n_rows, b_shape[0]))
    b = sp.csr_matrix((b_vals, (b_rows, b_cols)), shape=b_shape)
    values = (a @ b).tocoo()
    pattern = (_ones(a) @ _ones(b)).tocoo()
    keys = pattern.row.astype(np.int64) * b_shape[1] + pattern.col
    order = np.argsort(keys)
    keys = keys[order]
    out = np.zeros(keys.size, dtype=values.data.dtype)
    out[np.searchsorted(keys, values.row.astype(np.int64) * b_shape[1] + values.col)] = \
        values.data
    return keys // b_shape[1], keys % b_shape[1], out


def _ones(m: sp.csr_matrix) -> sp.csr_matrix:
    """m's structure with ones (duplicates summed: positive)."""
    return sp.csr_matrix((np.ones(m.data.size), m.indices, m.indptr), shape=m.shape)


def _summed(parts: list[tuple[NDArray, NDArray, NDArray]], n_cols: int
            ) -> tuple[NDArray[np.int64], NDArray[np.int64], NDArray[np.float64]]:
    """The COO entries of ``parts`` [(rows, cols, vals)] with equal (row, col) summed, sorted
    by row then column."""
    rows, cols, vals = (np.concatenate(item) for item in zip(*parts, strict=True))
    keys = rows * n_cols + cols
    unique, inverse = np.unique(keys, return_inverse=True)  # sorting path (small arrays)
    return unique // n_cols, unique % n_cols, np.bincount(inverse, weights=vals,
                                                          minlength=unique.size)


def _dual_hat_integrals(xi: NDArray) -> NDArray:
    """(..., 2, m) int_0^1 psi N_q dxi for psi_a = 2 - 3 xi, psi_b = 3 xi - 1 and the hats N_q
    of the nodes at xi (..., m) (0 = xi_0 < ... < xi_{m-1} = 1); Simpson's rule is exact for
    the products. Leading axes: segments batched (``_group_derivative``), one chain at a
    time by :func:`_dual_hat_chain`, so the tangent's shares are the residual's bits."""
    chains = np.asarray(xi, dtype=float).reshape(-1, xi.shape[-1]).tolist()
    return np.array([_dual_hat_chain(chain) for chain in chains]).reshape(
        xi.shape[:-1] + (2, xi.shape[-1]))


_DUAL_HATS = (lambda t: 2.0 - 3.0 * t, lambda t: 3.0 * t - 1.0)


def _dual_hat_chain(xi: list[float]) -> list[list[float]]:
    """:func:`_dual_hat_integrals` of one chain in Python floats: unpaired_share takes it per
    shared segment at every contact evaluation, where indexing 0-d arrays (xi[..., lo]) made
    it 3.6x slower (12 -> 44 us a chain, +1.1 s of 17 s of CPU at a refined slide, k = 4); a
    NumPy form batched over segments cost 21 us on a chain of 5 nodes, this loop 5."""
    m = len(xi)
    out = [[0.0] * m, [0.0] * m]
    for lo in range(m - 1):
        a, b = xi[lo], xi[lo + 1]
        mid, h = 0.5 * (a + b), b - a
        for side, psi in enumerate(_DUAL_HATS):
            out[side][lo] += h / 6.0 * (psi(a) + 4.0 * psi(mid) * 0.5)
            out[side][lo + 1] += h / 6.0 * (4.0 * psi(mid) * 0.5 + psi(b))
    return out


def _shared_segments(surface_s: ContactSurface, surface_o: ContactSurface, pos_s: NDArray,
                     pos_o: NDArray) -> list[tuple[int, int]]:
    """(pair a, pair b) consecutive along surface s with unpaired nodes between them while
    their partners on the other surface are chain neighbours: one coarse segment facing
    several segments of s."""
    n_s, n_o = surface_s.size, surface_o.size
    order = np.argsort(pos_s, kind="stable")
    a, b = order[:-1], order[1:]
    if surface_s.closed and order.size > 2:
        a, b = np.append(a, order[-1]), np.append(b, order[0])
    elif surface_s.closed and order.size == 2 and (pos_s[b] - pos_s[a]) % n_s > n_s // 2:
        # two pairs on a closed surface have two arcs between them: the short one faces the
        # partner (pairs at a disk's chain positions 0 and 23 of 24 are neighbours across
        # the chain's start; the long arc's 22 nodes were taken as unpaired between them)
        a, b = b, a
    between = (pos_s[b] - pos_s[a]) % n_s
    step = np.abs(pos_o[b] - pos_o[a])
    neighbours = (step == 1) | (surface_o.closed & (step == n_o - 1))
    keep = (between >= 2) & neighbours
    return list(zip(a[keep].tolist(), b[keep].tolist(), strict=True))


def _tributary(x: NDArray, surface: ContactSurface, nodes: NDArray) -> NDArray:
    k = surface.index_of(nodes)
    back = np.linalg.norm(x[nodes] - x[surface.prev[k]], axis=1)
    ahead = np.linalg.norm(x[surface.next[k]] - x[nodes], axis=1)
    return 0.5 * (back + ahead)


def unpaired_share(x: NDArray[np.float64], interface: Interface,
                   pairs: NDArray[np.int64]) -> Transfer | None:
    """The transfer of ``pairs`` at positions ``x``, or None where every segment between two
    consecutive pairs is a single segment on both surfaces (node to node, nothing to share)."""
    pairs = np.asarray(pairs, dtype=np.int64).reshape(-1, 2)
    if len(pairs) < 2:
        return None
    surfaces = (interface.surface1, interface.surface2)
    pos = [surfaces[s].index_of(pairs[:, s]) for s in range(2)]
    found = [(s, a, b) for s in range(2) for a, b in
             _shared_segments(surfaces[s], surfaces[1 - s], pos[s], pos[1 - s])]
    if not found:
        return None
    surface1 = _without_inner_nodes(interface.surface1, pos[0],
                                    [(a, b) for s, a, b in found if s == 0])
    length = _tributary(x, surface1, pairs[:, 0])
    weights: dict[int, dict[int, float]] = {}  # distributed node -> {node: weight}
    segments: list[tuple[NDArray, NDArray]] = []  # (chain, its two pairs' nodes (2, 2))
    for s, a, b in found:
        chain = _inner_chain(surfaces[s], pos[s][a], pos[s][b])
        arc = np.concatenate(([0.0], np.cumsum(np.linalg.norm(np.diff(x[chain], axis=0),
                                                              axis=1))))
        share = _dual_hat_integrals(arc / arc[-1])
        span = np.linalg.norm(x[pairs[a, 0]] - x[pairs[b, 0]])
        for side, p in enumerate((a, b)):
            scale = span / length[p]
            row = weights.setdefault(int(pairs[p, s]), {int(pairs[p, s]): 1.0})
            row[int(pairs[p, s])] -= 0.5 * scale  # this half of L_c no longer stays on the node
            for node, w in zip(chain.tolist(), (scale * share[side]).tolist(), strict=True):
                row[node] = row.get(node, 0.0) + w
        segments.append((chain, pairs[[a, b]][:, [s, 0]]))
    if any(np.count_nonzero(pairs[:, s] == node) > 1 for s in range(2) for node in weights):
        return None  # a node paired twice has no single weighted point
    distributed, matrix = _weights(x.shape[0], weights)
    return Transfer(surface1, distributed, matrix, np.array(x, dtype=float), segments)


def _dual_hat_jacobian(xi: NDArray) -> NDArray:
    """(..., 2, m, m) d/d xi_t of :func:`_dual_hat_integrals` (xi (..., m)): on [a, b], h = b - a,
    psi = alpha + beta t, the left node gets h/6 (3 alpha + beta (2a + b)), the right one
    h/6 (3 alpha + beta (a + 2b))."""
    m = xi.shape[-1]
    out = np.zeros(xi.shape[:-1] + (2, m, m))
    for lo in range(m - 1):
        a, b = xi[..., lo], xi[..., lo + 1]
        h = b - a
        for side, (alpha, beta) in enumerate(((2.0, -3.0), (-1.0, 3.0))):
            left, right = 3.0 * alpha + beta * (2.0 * a + b), 3.0 * alpha + beta * (a + 2.0 * b)
            out[..., side, lo, lo] += -left / 6.0 + h * beta / 3.0
            out[..., side, lo, lo + 1] += left / 6.0 + h * beta / 6.0
            out[..., side, lo + 1, lo] += -right / 6.0 + h * beta / 6.0
            out[..., side, lo + 1, lo + 1] += right / 6.0 + h * beta / 3.0
    return out


def _length_and_unit(d: NDArray) -> tuple[NDArray, NDArray]:
    """|d| over the last axis and d/|d|, whose derivative |d| has: 0 where |d| = 0 (an open
    chain's end is its own prev or next: a side of zero length, not one of slope 1)."""
    length = np.sqrt(np.sum(d * d, axis=-1))
    unit = np.divide(d, length[..., None], out=np.zeros_like(d), where=length[..., None] > 0.0)
    return length, unit


def _share_derivatives(x: NDArray, surface1: ContactSurface,
                       segments: list[tuple[NDArray, NDArray]], distributed: NDArray
                       ) -> tuple[ShareBlock, ...]:
    """d W / d x of the shared segments, batched over the segments of equal chain length
    (:class:`ShareBlock`); closed form (tests/test_transfer_tangent.py checks it against the
    complex step to round-off)."""
    groups: dict[int, list[int]] = {}
    for g, (chain, _) in enumerate(segments):
        groups.setdefault(chain.size, []).append(g)
    return tuple(_group_derivative(x, surface1, [segments[g] for g in members], distributed)
                 for members in groups.values())


def _group_derivative(x: NDArray, surface1: ContactSurface,
                      segments: list[tuple[NDArray, NDArray]], distributed: NDArray
                      ) -> ShareBlock:
    """:func:`_share_derivatives` of G segments whose chains have the same length m. The row
    of pair p holds scale_p share_pq on the chain's nodes q and -scale_p / 2 on its own node
    (:func:`unpaired_share`), scale_p = span / L_c,p: both factors move."""
    chains = np.array([chain for chain, _ in segments])  # (G, m)
    ends = np.array([nodes for _, nodes in segments])  # (G, 2 pairs, (row node, surface 1))
    k = surface1.index_of(ends[:, :, 1].ravel())
    around = np.stack((surface1.prev[k], ends[:, :, 1].ravel(), surface1.next[k]),
                      axis=1).reshape(-1, 2, 3)  # each pair's surface-1 (prev, node, next)
    n_seg, m = chains.shape
    n = m + 6  # local nodes: the chain, then around
    # share (G, 2, m) from the arc-length parameters xi and its gradient (G, 2, m, m, 2)
    seg, unit = _length_and_unit(np.diff(x[chains], axis=1))  # (G, m - 1)
    arc = np.concatenate((np.zeros((n_seg, 1)), np.cumsum(seg, axis=1)), axis=1)
    xi = arc / arc[:, -1:]
    j = np.arange(m - 1)
    d_seg = np.zeros((n_seg, m - 1, m, 2))  # d seg_j / d x_t of the chain's nodes
    d_seg[:, j, j], d_seg[:, j, j + 1] = -unit, unit
    d_xi_d_seg = ((j[None, :] < np.arange(m)[:, None]) - xi[:, :, None]) / arc[:, -1:, None]
    d_xi = np.einsum("gkj,gjtc->gktc", d_xi_d_seg, d_seg)
    share = _dual_hat_integrals(xi)
    d_share = np.einsum("gsnk,gktc->gsntc", _dual_hat_jacobian(xi), d_xi)
    # scale (G, 2) and its gradient (G, 2, n, 2) on the local nodes
    span, span_unit = _length_and_unit(x[around[:, 0, 1]] - x[around[:, 1, 1]])
    back, back_unit = _length_and_unit(x[around[..., 1]] - x[around[..., 0]])  # (G, 2)
    ahead, ahead_unit = _length_and_unit(x[around[..., 2]] - x[around[..., 1]])
    tributary = 0.5 * (back + ahead)
    scale = span[:, None] / tributary
    d_span = np.zeros((n_seg, n, 2))
    d_span[:, m + 1], d_span[:, m + 4] = span_unit, -span_unit
    d_tributary = np.zeros((n_seg, 2, n, 2))
    for p in range(2):
        d_tributary[:, p, m + 3 * p] = -0.5 * back_unit[:, p]
        d_tributary[:, p, m + 3 * p + 1] = 0.5 * (back_unit[:, p] - ahead_unit[:, p])
        d_tributary[:, p, m + 3 * p + 2] = 0.5 * ahead_unit[:, p]
    d_scale = (d_span[:, None] - scale[..., None, None] * d_tributary) / tributary[..., None, None]
    # d (scale share_q) on the chain's nodes, d (-scale / 2) on the row's own node
    value = np.zeros((n_seg, 2, m + 1, n, 2))
    value[:, :, :m, :m] = scale[..., None, None, None] * d_share
    value[:, :, :m] += share[..., None, None] * d_scale[:, :, None]
    value[:, :, m] = -0.5 * d_scale
    nodes = np.hstack((chains, around.reshape(n_seg, 6)))  # (G, n)
    return ShareBlock(
        rows=np.searchsorted(distributed, ends[:, :, 0]),
        nodes=np.concatenate((np.repeat(chains[:, None], 2, axis=1), ends[:, :, :1]), axis=-1),
        dofs=(2 * nodes[:, :, None] + _COMP).reshape(n_seg, 2 * n),
        value=value.transpose(0, 3, 4, 1, 2).reshape(n_seg, 2 * n, 2, m + 1))


def _inner_chain(surface: ContactSurface, start: int, stop: int) -> NDArray[np.int64]:
    """Global nodes from chain position start to stop inclusive (wrapping on a closed chain)."""
    span = (stop - start) % surface.size
    return surface.nodes[(start + np.arange(span + 1)) % surface.size]


def _without_inner_nodes(surface: ContactSurface, pos: NDArray,
                         links: list[tuple[int, int]]) -> ContactSurface:
    if not links:
        return surface
    inner = [_inner_chain(surface, pos[a], pos[b])[1:-1] for a, b in links]
    drop = np.isin(surface.nodes, np.concatenate(inner)) & ~surface.corner
    return ContactSurface(surface.nodes[~drop], surface.closed, surface.corner[~drop],
                          surface.partner_normal)


def _weights(n_nodes: int, weights: dict[int, dict[int, float]]
             ) -> tuple[NDArray[np.int64], sp.csr_matrix]:
    """The distributed nodes (sorted) and their rows of S (node level, CSR)."""
    distributed = np.array(sorted(weights), dtype=np.int64)
    rows = [np.full(len(weights[node]), k) for k, node in enumerate(distributed.tolist())]
    cols = [np.fromiter(weights[node], np.int64) for node in distributed.tolist()]
    vals = [np.fromiter(weights[node].values(), float) for node in distributed.tolist()]
    matrix = sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
                           shape=(distributed.size, n_nodes))
    matrix.sum_duplicates()
    return distributed, matrix
