"""Boundary edges, ordered surface chains, nodal outward normals and tributary lengths.

Orientation convention (shared with :class:`QuadMesh`): an edge ``(a, b)`` has the body on its
left, so its outward normal is ``rot(-90)(x_b - x_a) = (dy, -dx) / length`` (report 2.1, the
outward unit normal ``n1`` used in the gap 2.4).
"""

from __future__ import annotations

from dataclasses import dataclass
from itertools import chain

import numpy as np
from numpy.typing import NDArray
from scipy.spatial import cKDTree

from ntncontact.mesh.quadmesh import MeshError, QuadMesh, cell_edges, unique_pairs

__all__ = [
    "SurfaceChain",
    "ball_pairs",
    "boundary_edges",
    "chain_edge_lengths",
    "chain_from_edges",
    "chord_normals",
    "hanging_nodes",
    "nodes_inside_cells",
    "nodal_tributary_lengths",
    "surface_chain",
]


@dataclass(frozen=True)
class SurfaceChain:
    """Surface nodes in walking order (body on the left); a closed loop lists each node once."""

    nodes: NDArray[np.int64]
    closed: bool


def boundary_edges(mesh: QuadMesh | NDArray[np.int64]) -> NDArray[np.int64]:
    """Edges used by exactly one cell, oriented with the body on the left, in cell order;
    ``mesh`` a :class:`QuadMesh` or its cells (ne, 4).

    Raises :class:`MeshError` when an edge is shared by more than two cells or twice in the
    same direction (overlapping or inverted cells), since then "boundary" is meaningless.
    """
    cells, name = (mesh.cells, mesh.name) if isinstance(mesh, QuadMesh) else (mesh, "mesh")
    edges = cell_edges(cells)
    keys = np.sort(edges, axis=1)
    _, first, inverse, counts = unique_pairs(
        keys, return_index=True, return_inverse=True, return_counts=True
    )
    inverse = inverse.reshape(-1)
    if np.any(counts > 2):
        bad = keys[first[counts > 2][0]]
        raise MeshError(f"{name}: edge {tuple(bad)} is shared by more than two cells")
    # an interior edge must be traversed once in each direction by its two cells
    twice = counts[inverse] == 2
    forward = np.bincount(inverse[twice], weights=(edges[twice, 0] < edges[twice, 1]),
                          minlength=counts.size)
    if np.any(forward[counts == 2] != 1):
        bad = keys[first[(counts == 2) & (forward != 1)][0]]
        raise MeshError(
            f"{name}: edge {tuple(bad)} is traversed in the same direction by both of its"
            " cells (an inverted or clockwise cell)"
        )
    return edges[np.sort(first[counts == 1])]


#: a boundary node within this fraction of an edge's length of the edge's interior hangs on
#: it: gmsh puts a hanging node on a straight shared line to round-off (1e-16), while a slot
#: between two faces of a body is a real gap, however thin. A node on a curved shared line
#: sits off the coarse side's chord by the sagitta (about L / 8R of the edge) and is not caught.
HANGING_RTOL = 1e-9


def hanging_nodes(mesh: QuadMesh, rtol: float = HANGING_RTOL) -> NDArray[np.int64]:
    """Rows ``(node, a, b)``: a boundary node lying inside boundary edge ``(a, b)`` of the same
    mesh (a T-junction: a finer part's node on a coarser part's edge, only the corners merged).

    Nothing joins such a node to the edge, so the mesh holds a crack that opens under load.
    Each edge looks only at the boundary nodes within its half-length of its midpoint (a k-d
    tree): 0.6 s for a 10^5-cell strip 10^5 x 1 (its 2 x 10^5 boundary edges).
    """
    edges = boundary_edges(mesh)
    if edges.shape[0] == 0:
        return np.zeros((0, 3), np.int64)
    on_boundary = np.unique(edges)
    start, end = mesh.nodes[edges[:, 0]], mesh.nodes[edges[:, 1]]
    along = end - start
    length = np.hypot(along[:, 0], along[:, 1])
    node, edge = _nodes_near(mesh.nodes, on_boundary, 0.5 * (start + end),
                             0.5 * length * (1.0 + rtol))
    keep = (node != edges[edge, 0]) & (node != edges[edge, 1])
    node, edge = node[keep], edge[keep]
    offset = mesh.nodes[node] - start[edge]
    t = np.einsum("ij,ij->i", offset, along[edge]) / length[edge] ** 2
    across = np.abs(offset[:, 0] * along[edge, 1] - offset[:, 1] * along[edge, 0]) / length[edge]
    inside = (t > rtol) & (t < 1.0 - rtol) & (across <= rtol * length[edge])
    return np.column_stack((node[inside], edges[edge[inside]])).astype(np.int64)


def nodes_inside_cells(mesh: QuadMesh, rtol: float = HANGING_RTOL) -> NDArray[np.int64]:
    """Rows ``(node, cell)``: a boundary node strictly inside a cell of the same mesh that it
    is not a corner of, by more than ``rtol`` of the cell's edges. A conforming mesh has none;
    a T-junction on a curved shared line has: the finer part's node sits on the arc, off the
    coarser cell's chord by the sagitta and inside that cell when the coarser part lies on
    the arc's convex side (:func:`hanging_nodes` sees straight edges only). Each cell looks
    for boundary nodes within its own centroid-corner reach (a k-d tree over the boundary
    nodes)."""
    edges = boundary_edges(mesh)
    if edges.shape[0] == 0:
        return np.zeros((0, 2), np.int64)
    on_boundary = np.unique(edges)
    corners = mesh.nodes[mesh.cells]  # (ne, 4, 2), counter-clockwise
    centroid = corners.mean(axis=1)
    reach = np.linalg.norm(corners - centroid[:, None], axis=-1).max(axis=1)
    node, cell = _nodes_near(mesh.nodes, on_boundary, centroid, reach)
    keep = ~np.any(mesh.cells[cell] == node[:, None], axis=1)
    node, cell = node[keep], cell[keep]
    quad = corners[cell]
    sides = np.roll(quad, -1, axis=1) - quad
    rel = mesh.nodes[node][:, None, :] - quad
    cross = sides[..., 0] * rel[..., 1] - sides[..., 1] * rel[..., 0]  # |side| x distance in
    inside = (cross > rtol * np.einsum("kij,kij->ki", sides, sides)).all(axis=1)
    return np.column_stack((node[inside], cell[inside])).astype(np.int64)


def _nodes_near(nodes: NDArray, candidates: NDArray[np.int64], centres: NDArray,
                radii: NDArray) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """(node, centre index) pairs: each of ``candidates`` within its centre's radius (a k-d
    tree over the candidates), flattened for vectorized tests."""
    centre, found = ball_pairs(cKDTree(nodes[candidates]), centres, radii)
    return candidates[found], centre


def ball_pairs(tree: cKDTree, centres: NDArray, radii: NDArray | float,
               sort: bool | None = None) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """(centre index, point index) of every point of ``tree`` within its centre's radius,
    grouped by centre in order (``sort``: cKDTree's ``return_sorted``; True: each ball's
    points by index), flattened for vectorized tests."""
    hits = tree.query_ball_point(centres, radii, return_sorted=sort)
    counts = np.fromiter(map(len, hits), np.int64, count=len(hits))
    found = np.fromiter(chain.from_iterable(hits), np.int64, count=counts.sum())
    return np.repeat(np.arange(len(hits)), counts), found


def chain_from_edges(edges: NDArray[np.int64], label: str = "edges") -> SurfaceChain:
    """Order oriented edges head to tail into one simple chain (open or closed).

    Raises :class:`MeshError` when the edges branch, are inconsistently oriented, or form more
    than one piece. Setup-time code: the walk is sequential by nature.
    """
    edges = np.asarray(edges, dtype=np.int64).reshape(-1, 2)
    if edges.shape[0] == 0:
        raise MeshError(f"{label}: no edges to chain")
    starts, ends = edges[:, 0], edges[:, 1]
    if np.unique(starts).size != starts.size or np.unique(ends).size != ends.size:
        raise MeshError(f"{label}: a node starts or ends two edges (branching or opposite "
                        "orientation); not a single simple chain")
    successor = dict(zip(starts.tolist(), ends.tolist(), strict=True))
    heads = np.setdiff1d(starts, ends)
    if heads.size > 1:
        raise MeshError(f"{label}: edges form {heads.size} separate pieces, not one chain")
    closed = heads.size == 0
    node = int(heads[0]) if not closed else int(starts[0])
    order = [node]
    for _ in range(edges.shape[0]):
        node = successor.get(node, -1)
        if node < 0 or node == order[0]:
            break
        order.append(node)
    n_expected = edges.shape[0] if closed else edges.shape[0] + 1
    if len(order) != n_expected:
        raise MeshError(f"{label}: edges form more than one piece (a loop plus other edges)")
    return SurfaceChain(np.asarray(order, dtype=np.int64), bool(closed))


def surface_chain(mesh: QuadMesh, edge_set_name: str) -> SurfaceChain:
    """The nodes of edge set ``edge_set_name`` in walking order, body on the left."""
    return chain_from_edges(mesh.edge_set(edge_set_name), f"{mesh.name}: edge set "
                                                          f"'{edge_set_name}'")


def chain_edge_lengths(xy: NDArray[np.float64], closed: bool) -> NDArray[np.float64]:
    """Lengths of the chain's edges ``x_{i+1} - x_i``: ``n - 1`` for an open chain, ``n``
    for a closed one (the closing edge included)."""
    xy = np.asarray(xy, dtype=float)
    if xy.ndim != 2 or xy.shape[1] != 2 or xy.shape[0] < 2:
        raise MeshError(f"a chain needs coordinates of shape (n >= 2, 2), got {xy.shape}")
    nxt = np.roll(xy, -1, axis=0) if closed else xy[1:]
    return np.linalg.norm(nxt - (xy if closed else xy[:-1]), axis=1)


def nodal_tributary_lengths(xy: NDArray[np.float64], closed: bool) -> NDArray[np.float64]:
    """Length attributed to each node, ``L_c = (L_{i-1,i} + L_{i,i+1}) / 2`` (report 5.5-5.6);
    end nodes of an open chain get half of their single edge."""
    half = 0.5 * chain_edge_lengths(xy, closed)
    if closed:
        return half + np.roll(half, 1)
    return np.concatenate((half, [0.0])) + np.concatenate(([0.0], half))


def chord_normals(xy: NDArray[np.float64], closed: bool) -> NDArray[np.float64]:
    """Nodal outward unit normals ``rot(-90)(x_next - x_prev)/|.|`` of an ordered chain's
    coordinates ``xy`` (n, 2), body on the left (report 2.1.1): one-sided at the ends of an
    open chain, zero where a node's neighbours coincide; corners are NOT replaced here (report
    6.6)."""
    xy = np.asarray(xy, dtype=float)
    after, before = np.roll(xy, -1, axis=0), np.roll(xy, 1, axis=0)
    if not closed:
        after[-1], before[0] = xy[-1], xy[0]
    chord = after - before
    length = np.maximum(np.linalg.norm(chord, axis=1), 1e-300)  # coincident neighbours: 0
    return np.column_stack((chord[:, 1], -chord[:, 0])) / length[:, None]
