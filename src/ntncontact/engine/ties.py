"""Tie constraints between bodies: coincident node pairs held together exactly, x_a = x_b.

A tie pairs each node of one surface (node set) with the coincident node of another, at build
time, and enters the step as Lagrange multipliers of the bordered Newton system
(:class:`ntncontact.engine.problem.ConstraintTerm`): per tied component k the constraint
h_k = x[a_k] - x[b_k] = 0 and the force lam_k on node a, -lam_k on node b (B = G^T). The
multiplier is therefore minus the force the tie exerts on the body-1 node. The constraint is
linear, so its tangent is zero and it adds no stiffness; its forces are equal and opposite, so
a tie conserves linear momentum and, holding x_a = x_b at all times, does no work.

Components whose two dofs are both prescribed are left to the supports (the bordered system
would otherwise get a zero row on the free dofs).

A node of surface 2 with no coincident node on surface 1 but lying on one of its edges (a finer
mesh on the other side of the bond) is held on that edge, x_e = (1 - xi) x_p + xi x_q at its
reference parameter xi: the constraint h = x_e - (1 - xi) x_p - xi x_q, the force lam on e and
-(1 - xi) lam, -xi lam on p and q. Its weights sum to 1 (momentum kept) and its force acts
where the points coincide (no moment, no work). Left free, such nodes broke the patch test: an
independent tester's uniform tension across 2 against 4 element rows gave shear stresses of
0.23 against 1.0 in the finer body.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray
from scipy.spatial import cKDTree


class TieError(ValueError):
    """A tie that cannot be built; the message names the tie, the bodies and the node."""


@dataclass(frozen=True)
class Tie:
    """Paired global nodes of two surfaces and the dof pairs the constraint holds together."""

    name: str
    body_1: str
    body_2: str
    nodes_1: NDArray  # global nodes of surface 1
    nodes_2: NDArray  # the coincident partner of each, global
    dofs_1: NDArray  # tied dofs of body 1 (components prescribed on both sides dropped)
    dofs_2: NDArray
    #: surface-2 nodes held on a surface-1 edge (global), that edge's two nodes (global,
    #: (m, 2)) and the node's parameter on it, per held component (m dofs)
    edge_dofs: NDArray = field(default_factory=lambda: np.zeros(0, np.int64))
    edge_ends: NDArray = field(default_factory=lambda: np.zeros((0, 2), np.int64))
    edge_xi: NDArray = field(default_factory=lambda: np.zeros(0))

    @property
    def size(self) -> int:
        return int(self.dofs_1.size + self.edge_dofs.size)

    def gaps(self, xf: NDArray) -> NDArray:
        """The constraint values h at the flat positions ``xf``: coincident pairs, then the
        nodes held on edges."""
        on_edge = (xf[self.edge_dofs] - (1.0 - self.edge_xi) * xf[self.edge_ends[:, 0]]
                   - self.edge_xi * xf[self.edge_ends[:, 1]])
        return np.concatenate([xf[self.dofs_1] - xf[self.dofs_2], on_edge])

    def gradient(self) -> tuple[NDArray, NDArray, NDArray]:
        """(row, dof, value) triplets of dh/dx."""
        k = np.arange(self.dofs_1.size)
        m = self.dofs_1.size + np.arange(self.edge_dofs.size)
        rows = np.concatenate([k, k, m, m, m])
        cols = np.concatenate([self.dofs_1, self.dofs_2, self.edge_dofs, self.edge_ends[:, 0],
                               self.edge_ends[:, 1]])
        vals = np.concatenate([np.ones(k.size), -np.ones(k.size), np.ones(m.size),
                               self.edge_xi - 1.0, -self.edge_xi])
        return rows, cols, vals


def coincident_partners(X1: NDArray, X2: NDArray, tolerance: float) -> NDArray:
    """Index into X2 of the point within ``tolerance`` of each point of X1; -1 where none is,
    -2 where more than one is (ambiguous)."""
    if len(X2) == 0:
        return np.full(len(X1), -1)
    dist, idx = cKDTree(X2).query(X1, k=[1, 2])  # no second point: distance inf
    out = np.where(dist[:, 0] <= tolerance, idx[:, 0], -1)
    out[dist[:, 1] <= tolerance] = -2
    return out


def pair_tie(name: str, body_1: str, X1: NDArray, nodes_1: NDArray, body_2: str, X2: NDArray,
             nodes_2: NDArray, tolerance: float) -> tuple[NDArray, NDArray]:
    """Pair each global node of ``nodes_1`` (reference positions X1, one row per node) with the
    coincident node of ``nodes_2``; every node needs exactly one distinct partner."""
    partner = coincident_partners(X1, X2, tolerance)
    for code, what in ((-1, "has no coincident node"), (-2, "has several coincident nodes")):
        bad = np.flatnonzero(partner == code)
        if bad.size:
            where = ", ".join(f"({X1[i, 0]:.6g}, {X1[i, 1]:.6g})" for i in bad[:5])
            raise TieError(f"tie '{name}': {bad.size} node(s) of body '{body_1}' {what} on "
                           f"body '{body_2}' within tolerance {tolerance:.3g}, at {where}")
    paired = np.asarray(nodes_2)[partner]
    values, counts = np.unique(paired, return_counts=True)
    if np.any(counts > 1):
        raise TieError(f"tie '{name}': nodes {values[counts > 1].tolist()} of body '{body_2}' "
                       "are the partner of more than one node")
    if np.any(paired == np.asarray(nodes_1)):
        raise TieError(f"tie '{name}': a node cannot be tied to itself (the two surfaces "
                       "share nodes)")
    return np.asarray(nodes_1, dtype=np.int64), paired.astype(np.int64)


def make_tie(name: str, body_1: str, body_2: str, nodes_1: NDArray, nodes_2: NDArray,
             fixed_dofs: NDArray, on_edges: tuple[NDArray, NDArray, NDArray]) -> Tie:
    """The tie of paired nodes, leaving out the components prescribed on both sides;
    ``on_edges``: the surface-2 nodes held on surface-1 edges (global), the edges' end nodes
    (global, (m, 2)) and their parameters (see the module doc)."""
    d1 = (2 * nodes_1[:, None] + np.arange(2)).ravel()
    d2 = (2 * nodes_2[:, None] + np.arange(2)).ravel()
    keep = ~(np.isin(d1, fixed_dofs) & np.isin(d2, fixed_dofs))
    if on_edges[0].size == 0:
        return Tie(name, body_1, body_2, nodes_1, nodes_2, d1[keep], d2[keep])
    nodes, ends, xi = on_edges
    dofs = (2 * nodes[:, None] + np.arange(2)).ravel()
    end_dofs = (2 * np.repeat(ends, 2, axis=0) + np.tile(np.arange(2), len(nodes))[:, None])
    held = ~(np.isin(dofs, fixed_dofs) & np.isin(end_dofs, fixed_dofs).all(axis=1))
    return Tie(name, body_1, body_2, nodes_1, nodes_2, d1[keep], d2[keep], dofs[held],
               end_dofs[held], np.repeat(xi, 2)[held])


@dataclass(frozen=True)
class TieTerm:
    """One tie as a bordered-system constraint term (see :mod:`ntncontact.engine.problem`)."""

    tie: Tie
    # Sorted after every Lagrange contact interface (simulation._lagrange_multipliers sorts the
    # constraint terms by ``order`` and hands the leading ones to the contact interfaces).
    order: float = math.inf

    @property
    def size(self) -> int:
        return self.tie.size

    @property
    def initial(self) -> NDArray:
        return np.zeros(self.size)

    def __call__(self, x_eval: NDArray, v_eval: NDArray | None, rate: float | None,
                 x_start: NDArray, lam: NDArray) -> tuple:
        xf = x_eval.ravel()
        rows, cols, vals = self.tie.gradient()
        force = np.bincount(cols, weights=vals * lam[rows], minlength=xf.size)  # B lam, B = G^T
        empty = (np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0))
        return force, empty, self.tie.gaps(xf), (rows, cols, vals), (cols, rows, vals)


def tie_terms(ties: Sequence[Tie]) -> list[TieTerm]:
    """Constraint terms of the ties that hold at least one component."""
    return [TieTerm(t) for t in ties if t.size]


def tie_forces(constraints: Sequence, multipliers: Sequence[NDArray]) -> dict[str, NDArray]:
    """Force each tie exerts on its body-1 nodes, (n_pairs, 2) per tie name, from the constraint
    terms of a step problem and their multipliers (``StepProblem.multipliers``). Components
    left to the supports are zero."""
    out = {}
    for term, lam in zip(constraints, multipliers, strict=True):
        if isinstance(term, TieTerm):
            tie = term.tie
            rows, cols, vals = tie.gradient()
            f = np.bincount(cols, weights=-vals * lam[rows],
                            minlength=2 * (max(int(cols.max()) // 2, int(tie.nodes_1.max())) + 1))
            out[tie.name] = f.reshape(-1, 2)[tie.nodes_1]  # body 1's nodes: pairs and edge ends
    return out


def tie_violation(ties: Sequence[Tie], x: NDArray) -> float:
    """Largest distance between tied nodes at positions x (n, 2)."""
    gaps = [np.linalg.norm(x[t.nodes_1] - x[t.nodes_2], axis=1).max() for t in ties
            if t.nodes_1.size]
    for t in ties:
        if t.edge_dofs.size:  # per node held on an edge: the distance to its place there
            squared = np.bincount(t.edge_dofs // 2, weights=t.gaps(x.ravel())[t.dofs_1.size:] ** 2)
            gaps.append(float(np.sqrt(squared.max())))
    return float(max(gaps, default=0.0))


def held_on_edges(X_free: NDArray, X1: NDArray, edges: NDArray, tolerance: float
                  ) -> tuple[NDArray, NDArray]:
    """For each point of ``X_free`` (surface-2 nodes without a coincident node), the index of
    the surface-1 edge (``edges``: (m, 2) rows into ``X1``) it lies on within ``tolerance``,
    -1 where none, and its parameter xi on that edge."""
    if len(X_free) == 0 or len(edges) == 0:
        return np.full(len(X_free), -1), np.zeros(len(X_free))
    a, b = X1[edges[:, 0]], X1[edges[:, 1]]
    ab = b - a
    rel = X_free[:, None, :] - a[None, :, :]
    xi = np.clip(np.einsum("psi,si->ps", rel, ab) / np.einsum("si,si->s", ab, ab), 0.0, 1.0)
    dist = np.linalg.norm(rel - xi[..., None] * ab[None], axis=2)
    nearest = np.argmin(dist, axis=1)
    rows = np.arange(len(X_free))
    return np.where(dist[rows, nearest] <= tolerance, nearest, -1), xi[rows, nearest]


#: The vertex that stands for every prescribed dof in ``redundant_tie``: a tied component whose
#: two dofs are both held by supports is left out (``make_tie``), so two ties reaching the
#: supports from one node hold it twice.
GROUND = -1


def _root(parent: dict[int, int], dof: int) -> int:
    """The union-find root of ``dof`` (halving the path as it goes)."""
    while parent.get(dof, dof) != dof:
        parent[dof] = parent.get(parent[dof], parent[dof])
        dof = parent[dof]
    return dof


def _route(links: dict[int, list[tuple[int, str]]], start: int, goal: int
           ) -> tuple[list[str], bool]:
    """The names of the ties along the chain of tied pairs from ``start`` to ``goal``
    (breadth first; the two are known to be joined), and whether it passes the supports
    (``GROUND``)."""
    came: dict[int, tuple[int, str] | None] = {start: None}
    queue = [start]
    while queue and goal not in came:
        here = queue.pop(0)
        for there, name in links.get(here, []):
            if there not in came:
                came[there] = (here, name)
                queue.append(there)
    names, grounded, step = [], GROUND in (start, goal), came.get(goal)
    while step is not None:
        names.append(step[1])
        grounded |= step[0] == GROUND
        step = came[step[0]]
    return list(dict.fromkeys(reversed(names))), grounded


@dataclass(frozen=True)
class Redundant:
    """A tied pair whose constraint the ties before it already impose."""

    tie: str  # the tie of the pair that closes the loop
    node_1: int  # its global nodes
    node_2: int
    route: list[str]  # the ties that already join the two
    supports: bool  # the chain passes through prescribed dofs


def redundant_tie(ties: Sequence[Tie], fixed_dofs: NDArray) -> Redundant | None:
    """The first tied pair whose two dofs the earlier pairs already join (three parts tied
    around one corner: A-B, C-B and A-C hold the corner node's x_A = x_C twice), or None.
    Its constraint row is a combination of the others', so the bordered system is singular
    (a tester's T-junction: "SuperLU: Factor is exactly singular" after every halving).
    Prescribed dofs count as one vertex: a node tied to two supported nodes is held twice.
    Nodes held on edges are left out (their rows mix three nodes)."""
    fixed = set(np.asarray(fixed_dofs).tolist())
    parent: dict[int, int] = {}
    links: dict[int, list[tuple[int, str]]] = {}
    for tie in ties:
        for d1, d2 in zip(tie.dofs_1.tolist(), tie.dofs_2.tolist(), strict=True):
            u, w = (GROUND if d in fixed else d for d in (d1, d2))
            if _root(parent, u) == _root(parent, w):
                return Redundant(tie.name, d1 // 2, d2 // 2, *_route(links, u, w))
            parent[_root(parent, u)] = _root(parent, w)
            links.setdefault(u, []).append((w, tie.name))
            links.setdefault(w, []).append((u, tie.name))
    return None


def tied_partner(ties: Sequence[Tie], candidates: NDArray, partners: NDArray
                 ) -> tuple[int, int, list[str]] | None:
    """A node of ``candidates`` that a chain of tied pairs joins to a node of ``partners``
    (both global), as (candidate, partner, the ties along the chain), or None. The two
    coincide, so an exact (Lagrange) contact pair between them repeats the ties' constraint:
    the delamination example's crack tips with ``method = "lagrange"`` and no ``exclude``
    ended "SuperLU: Factor is exactly singular" after 6 halvings."""
    parent: dict[int, int] = {}
    links: dict[int, list[tuple[int, str]]] = {}
    for tie in ties:
        for a, b in zip(tie.nodes_1.tolist(), tie.nodes_2.tolist(), strict=True):
            parent[_root(parent, a)] = _root(parent, b)
            links.setdefault(a, []).append((b, tie.name))
            links.setdefault(b, []).append((a, tie.name))
    if not links:
        return None
    reached = {_root(parent, p): p for p in partners.tolist() if p in links}
    for a in candidates.tolist():
        p = reached.get(_root(parent, a)) if a in links else None
        if p is not None and p != a:
            return a, p, _route(links, a, p)[0]
    return None
