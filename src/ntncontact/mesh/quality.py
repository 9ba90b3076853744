"""Quality measures of Q4 meshes: edge lengths, corner angles, corner Jacobians (report 4.2).

All measures are vectorized over cells; the smallest corner sines and the acceptance test of
cells changed by a mesh move (the ALE update's, ``ale.motion``) are compiled loops, since they
run on a few cells per move. ``quality_statistics`` reproduces the quantities of the
report's Table 4.1 (minimum/maximum/average/variance of edge lengths and interior angles), with
the population variance defined just below that table.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ntncontact.mesh.quadmesh import MeshError, QuadMesh, cell_edges, unique_pairs

from ..jit import njit

__all__ = [
    "cell_min_sines",
    "changed_cells",
    "check_elements",
    "check_move",
    "corner_angles_deg",
    "corner_jacobians",
    "min_sines_below",
    "edge_lengths",
    "quality_statistics",
    "unique_edges",
]


def _nodes_cells(
    mesh_or_nodes: QuadMesh | ArrayLike, cells: ArrayLike | None = None
) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
    """Accept either a QuadMesh or a (nodes, cells) pair."""
    if isinstance(mesh_or_nodes, QuadMesh):
        return mesh_or_nodes.nodes, mesh_or_nodes.cells
    if cells is None:
        raise TypeError("pass a QuadMesh or both nodes and cells")
    return np.asarray(mesh_or_nodes, dtype=float), np.asarray(cells, dtype=np.int64).reshape(-1, 4)


def unique_edges(cells: ArrayLike) -> NDArray[np.int64]:
    """Undirected edges of a Q4 mesh, each once, as sorted node pairs (e, 2)."""
    pairs = cell_edges(np.asarray(cells, dtype=np.int64).reshape(-1, 4))
    return unique_pairs(np.sort(pairs, axis=1))


def edge_lengths(mesh_or_nodes: QuadMesh | ArrayLike, cells: ArrayLike | None = None) -> NDArray:
    """Lengths of the unique edges (an edge shared by two cells is counted once)."""
    nodes, cell_arr = _nodes_cells(mesh_or_nodes, cells)
    edges = unique_edges(cell_arr)
    return np.linalg.norm(nodes[edges[:, 1]] - nodes[edges[:, 0]], axis=1)


def _corner_vectors(nodes: NDArray, cells: NDArray) -> tuple[NDArray, NDArray, NDArray]:
    """At each corner k: a = x_{k+1} - x_k (to the next node), b = x_{k-1} - x_k (previous)
    and the corner Jacobian cross(a, b)."""
    x = nodes[cells]  # (m, 4, 2)
    a, b = np.roll(x, -1, axis=1) - x, np.roll(x, 1, axis=1) - x
    return a, b, a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]


def corner_jacobians(
    mesh_or_nodes: QuadMesh | ArrayLike, cells: ArrayLike | None = None
) -> NDArray[np.float64]:
    """Signed corner Jacobians (m, 4): cross(x_{k+1} - x_k, x_{k-1} - x_k).

    Positive at every corner of a convex counter-clockwise cell; equals 4 det(dx/dxi) of the
    bilinear map evaluated at that corner. A non-positive value flags inversion or collapse.
    """
    return _corner_vectors(*_nodes_cells(mesh_or_nodes, cells))[2]


def corner_angles_deg(
    mesh_or_nodes: QuadMesh | ArrayLike, cells: ArrayLike | None = None
) -> NDArray[np.float64]:
    """Interior angle (degrees, in [0, 360)) at each of the 4 corners of each cell, (m, 4).

    Measured counter-clockwise from the edge to the next node to the edge to the previous node,
    so a reflex corner of a non-convex (but valid CCW) cell reads above 180 and the four angles of
    any simple CCW quadrilateral sum to 360.
    """
    a, b, cross = _corner_vectors(*_nodes_cells(mesh_or_nodes, cells))
    return np.mod(np.degrees(np.arctan2(cross, np.einsum("...i,...i->...", a, b))), 360.0)


def cell_min_sines(nodes: ArrayLike, cells: ArrayLike) -> NDArray[np.float64]:
    """Smallest corner sine (corner Jacobian over the two edge lengths) of every cell, (m,):
    1 for a rectangle, <= 0 for an inverted or degenerate corner."""
    cell_arr = np.ascontiguousarray(cells, dtype=np.int64).reshape(-1, 4)
    return _min_sines(np.ascontiguousarray(nodes, dtype=float), cell_arr,
                      np.arange(len(cell_arr)))


@njit(cache=True)
def _min_sines(nodes, cells, which):
    """``cell_min_sines`` of the cells ``which`` (a zero-length edge counts as -1)."""
    out = np.empty(which.size)
    for k in range(which.size):
        e = which[k]
        low = np.inf
        for c in range(4):
            i, j, h = cells[e, c], cells[e, (c + 1) % 4], cells[e, (c + 3) % 4]
            a0, a1 = nodes[j, 0] - nodes[i, 0], nodes[j, 1] - nodes[i, 1]
            b0, b1 = nodes[h, 0] - nodes[i, 0], nodes[h, 1] - nodes[i, 1]
            cross = a0 * b1 - a1 * b0
            scale = np.sqrt((a0 * a0 + a1 * a1) * (b0 * b0 + b1 * b1))
            low = min(low, cross / scale if scale > 0 else -1.0)
        out[k] = low
    return out


@njit(cache=True)
def min_sines_below(nodes, cells, which, tol):
    """True if a cell of ``which`` has a corner sine at most ``tol`` (NaN: False)."""
    q = _min_sines(nodes, cells, which)
    for k in range(q.size):
        if q[k] <= tol:
            return True
    return False


@njit(cache=True)
def changed_cells(x_new, x_old, cells, min_quality, reference_quality, old_quality, tol):
    """The cells a move from ``x_old`` to ``x_new`` changes and whether it may be kept:
    (moved nodes mask, changed cells, acceptable, degenerate). Acceptable: every changed cell
    keeps ``min_quality`` of its ``reference_quality`` or does not get worse than its
    ``old_quality`` (a move need not repair what it did not spoil); degenerate: one has a
    corner sine at most ``tol``."""
    n, m = x_new.shape[0], cells.shape[0]
    moved = np.zeros(n, np.bool_)
    for i in range(n):
        moved[i] = x_new[i, 0] != x_old[i, 0] or x_new[i, 1] != x_old[i, 1]
    touched = np.zeros(m, np.bool_)
    for e in range(m):
        for c in range(4):
            touched[e] = touched[e] or moved[cells[e, c]]
    which = np.flatnonzero(touched)
    q = _min_sines(x_new, cells, which)
    acceptable, degenerate = True, False
    for k in range(which.size):
        a, b = min_quality * reference_quality[which[k]], old_quality[which[k]]
        # np.minimum propagates NaN: q >= NaN fails
        if np.isnan(a) or np.isnan(b) or not q[k] >= min(a, b):
            acceptable = False
        degenerate = degenerate or q[k] <= tol
    return moved, which, acceptable, degenerate


def quality_statistics(
    mesh_or_nodes: QuadMesh | ArrayLike, cells: ArrayLike | None = None
) -> dict[str, float]:
    """Table 4.1 measures of a mesh.

    Edge statistics are over the population of unique edges; angle statistics over the
    population of all 4 m interior corner angles (degrees). Variances are population variances
    (divide by the count), as defined below the report's Table 4.1. The average angle of a valid
    quadrilateral mesh is exactly 90 degrees since each cell's angles sum to 360.
    """
    lengths = edge_lengths(mesh_or_nodes, cells)
    angles = corner_angles_deg(mesh_or_nodes, cells).ravel()
    return {
        "min_edge": float(lengths.min()),
        "max_edge": float(lengths.max()),
        "average_edge": float(lengths.mean()),
        "variance_edge": float(lengths.var()),
        "min_angle_deg": float(angles.min()),
        "max_angle_deg": float(angles.max()),
        "average_angle_deg": float(angles.mean()),
        "variance_angle": float(angles.var()),
    }


def check_elements(
    mesh_or_nodes: QuadMesh | ArrayLike,
    cells: ArrayLike | None = None,
    body_name: str | None = None,
    rel_tol: float = 1e-10,
    which: ArrayLike | None = None,
) -> None:
    """Raise MeshError naming the first inverted or degenerate element, its corner and the body.

    A corner is inverted when its corner Jacobian is negative, and degenerate when it is at most
    ``rel_tol * |a| |b|`` (sine of the corner angle below ``rel_tol``, or a zero-length edge).
    The corner reported is the one with the smallest scaled Jacobian in that element.
    ``which``: check only these cells (their numbers are the ones reported). A mesh read from a
    file is named by the file's element and node numbers (:func:`_element_text`).
    """
    if body_name is None:
        body_name = mesh_or_nodes.name if isinstance(mesh_or_nodes, QuadMesh) else "body"
    nodes, cell_arr = _nodes_cells(mesh_or_nodes, cells)
    numbers = np.arange(len(cell_arr)) if which is None else np.asarray(which, np.int64)
    cell_arr = cell_arr[numbers]
    a, b, jac = _corner_vectors(nodes, cell_arr)
    scale = np.linalg.norm(a, axis=-1) * np.linalg.norm(b, axis=-1)
    bad = ~(jac > rel_tol * scale)  # also catches NaN coordinates
    if not bad.any():
        return
    elem = int(np.flatnonzero(bad.any(axis=1))[0])
    with np.errstate(divide="ignore", invalid="ignore"):
        scaled = np.where(scale[elem] > 0, jac[elem] / scale[elem], -np.inf)
    corner = int(np.argmin(np.nan_to_num(scaled, nan=-np.inf)))
    kind = "inverted" if jac[elem, corner] < 0 else "degenerate"
    element, node = _element_text(mesh_or_nodes, int(numbers[elem]),
                                  int(cell_arr[elem, corner]))
    raise MeshError(f"body '{body_name}': {element} is {kind} "
                    f"(corner Jacobian {jac[elem, corner]:.3g} at {node})", int(numbers[elem]))


def _element_text(mesh: QuadMesh | ArrayLike, elem: int, node: int) -> tuple[str, str]:
    """("element E", "node N") by the mesh's indices, or ("file element E", "file node N") by
    the numbers of the file it was read from (which are what a user looks for in the file)."""
    if isinstance(mesh, QuadMesh) and mesh.file_element_ids is not None \
            and mesh.file_node_ids is not None:
        file_elem, file_node = int(mesh.file_element_ids[elem]), int(mesh.file_node_ids[node])
        if file_elem >= 0 and file_node >= 0:
            return f"file element {file_elem}", f"file node {file_node}"
    return f"element {elem}", f"node {node}"


def check_move(new: ArrayLike, old: ArrayLike, cells: ArrayLike, body_name: str,
               which: ArrayLike | None = None, rel_tol: float = 1e-10) -> None:
    """``check_elements`` for a mesh move from the nodes ``old`` to ``new``: raise MeshError
    naming the first of the cells ``which`` (default all) that the move leaves inverted or
    degenerate *and* worse than it was (its smallest corner sine lower, ``cell_min_sines``).

    A cell the material's own deformation had already turned past 180 degrees at a corner,
    with its Gauss points still positive (the step's check), is not the move's doing: refusing
    every move of its nodes, even those that make it better, stopped a run whatever the step,
    while accepted the cell recovers within a step."""
    cell_arr = np.ascontiguousarray(cells, dtype=np.int64).reshape(-1, 4)
    which = (np.arange(len(cell_arr)) if which is None
             else np.ascontiguousarray(which, dtype=np.int64).reshape(-1))
    new, old = (np.ascontiguousarray(x, dtype=float) for x in (new, old))
    q_new = _min_sines(new, cell_arr, which)
    low = ~(q_new > rel_tol)  # NaN counts as degenerate
    if not low.any():
        return
    worse = which[low][~(q_new[low] >= _min_sines(old, cell_arr, which[low]))]
    if worse.size:
        check_elements(new, cell_arr, body_name, rel_tol, which=worse)
