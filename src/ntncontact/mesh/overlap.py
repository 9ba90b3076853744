"""Points of one body inside another: at t = 0 (bodies placed so that they overlap), and
after every step (boundary nodes on no contact surface, ``engine.diagnostics``).

Node-to-node contact only acts on pairs it detects near the surfaces; bodies that start
interpenetrated pass through each other. The scenario builder therefore refuses them, naming
the depth and the place (docs/scenarios.md, ``[[contact]]``): a surface node inside the other
body, or, where the bodies' edges lie along each other's and no node is inside, the side of a
surface edge (``deepest_overlap``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.spatial import cKDTree

from ntncontact.mesh.boundary import ball_pairs, boundary_edges, chord_normals

#: A point deeper than this fraction of the body's median edge length below its boundary is an
#: overlap: surfaces that touch (up to round-off) are not.
DEPTH_TOLERANCE = 1e-6

#: Points tested against all candidate elements at once (bounds the temporary arrays).
CHUNK = 512


@dataclass(frozen=True)
class Overlap:
    """The deepest point found inside the other body."""

    point: int  # index into the points given
    position: tuple[float, float]
    depth: float  # distance to the other body's boundary
    #: True: no point is inside, but the body's side of the surface edge from ``point`` to the
    #: next point is (bodies whose edges lie along each other's); ``position`` is ``point``'s
    #: and ``depth`` is measured along the edge's inward normal from its midpoint to where that
    #: normal leaves the other body
    edge: bool = False


def _inside_pairs(points: NDArray, nodes: NDArray, cells: NDArray,
                  slack: float) -> tuple[NDArray, NDArray]:
    """The (point, cell) index pairs of ``points`` (m, 2) inside counter-clockwise quads of
    ``cells`` (edges included, with ``slack`` of length; a valid mesh's quads are convex).
    Each point is tested against the cells in the points' bounding box whose centroid lies
    within the largest centroid-corner distance of it (a k-d tree): at run time this is
    called every step on a body's boundary nodes against another body of up to 10^5 cells,
    where testing every pair costs m x cells."""
    none = (np.zeros(0, np.int64), np.zeros(0, np.int64))
    if len(points) == 0 or len(cells) == 0:
        return none
    corners = nodes[cells]  # (ne, 4, 2)
    low, high = points.min(axis=0) - slack, points.max(axis=0) + slack
    c0, c1, c2, c3 = corners[:, 0], corners[:, 1], corners[:, 2], corners[:, 3]
    kept = np.flatnonzero(np.all(
        (np.maximum(np.maximum(c0, c1), np.maximum(c2, c3)) >= low)
        & (np.minimum(np.minimum(c0, c1), np.minimum(c2, c3)) <= high), axis=1))
    if len(kept) == 0:
        return none
    corners = corners[kept]
    centroid = _centroids(corners)
    reach = _largest_radius(corners, centroid) + slack
    # an unbalanced tree builds faster; the pairs within reach are the same
    near = cKDTree(points).sparse_distance_matrix(cKDTree(centroid, balanced_tree=False),
                                                  reach, output_type="ndarray")
    if near.size == 0:
        return none
    point, cell = near["i"], near["j"]
    quad = corners[cell]  # (k, 4, 2)
    edges = np.roll(quad, -1, axis=1) - quad
    rel = points[point, None, :] - quad
    # cross / length: the distance inside each edge's line
    cross = edges[..., 0] * rel[..., 1] - edges[..., 1] * rel[..., 0]
    inside = (cross >= -slack * np.linalg.norm(edges, axis=-1)).all(axis=-1)
    return point[inside], kept[cell[inside]]


def _centroids(corners: NDArray) -> NDArray:
    """The mean of each cell's four corners (ne, 2), as ``corners.mean(axis=1)`` gives it to
    the bit, the four slices added in the same order: the reduction over the middle axis
    took 4 times as long (4.4 ms for 51 000 cells, run every step)."""
    return (corners[:, 0] + corners[:, 1] + corners[:, 2] + corners[:, 3]) / 4


def _largest_radius(corners: NDArray, centroid: NDArray) -> float:
    """The largest distance from a cell's centroid to its corners: the root of the largest
    square (the root is monotonic and correctly rounded, so this is the largest of the
    ``np.linalg.norm`` values to the bit), at half their cost."""
    d = corners - centroid[:, None]
    return float(np.sqrt(np.max(d[..., 0] * d[..., 0] + d[..., 1] * d[..., 1])))


def distance_to_segments(points: NDArray, a: NDArray, b: NDArray) -> NDArray:
    """Distance of each point (m, 2) to the nearest of the segments a[k] -> b[k].

    Only the segments that can be nearest are measured: a point's nearest segment lies no
    farther than d1, the distance to the segment of its nearest midpoint, so its midpoint lies
    within d1 + half the longest segment (a k-d tree of the midpoints). Measuring every pair
    cost m x k: 9.7 s of a 4,000-node layer's build that touches its base (every surface node
    is inside within the tolerance), 34 s at 8,000. The distances are those of every pair's
    (``_pair_distances``), so the minimum is the same to the bit."""
    points = np.asarray(points, dtype=float)
    out = np.full(len(points), np.inf)
    if len(points) == 0 or len(a) == 0:
        return out
    finite = np.flatnonzero(np.isfinite(points).all(axis=1))
    rest = np.setdiff1d(np.arange(len(points)), finite)
    if rest.size:  # no ball around a point that is not finite: every segment (NaN out)
        out[rest] = np.sqrt(np.min(_pair_distances(
            points[np.repeat(rest, len(a))], np.tile(a, (rest.size, 1)),
            np.tile(b, (rest.size, 1))).reshape(rest.size, -1), axis=1))
    if finite.size == 0:
        return out
    middle = 0.5 * (a + b)
    reach = 0.5 * float(np.max(np.linalg.norm(b - a, axis=1)))
    tree = cKDTree(middle)
    _, first = tree.query(points[finite])
    upper = np.sqrt(_pair_distances(points[finite], a[first], b[first]))
    # round-off in either distance must not drop the nearest segment: a relative margin
    radius = (upper + reach) * (1.0 + 1e-9) + 1e-300
    for start in range(0, finite.size, CHUNK):
        block = finite[start:start + CHUNK]
        which, seg = ball_pairs(tree, points[block], radius[start:start + CHUNK], sort=False)
        squared = _pair_distances(points[block][which], a[seg], b[seg])
        best = np.full(len(block), np.inf)
        np.minimum.at(best, which, squared)
        out[block] = np.sqrt(best)
    return out


def _pair_distances(points: NDArray, a: NDArray, b: NDArray) -> NDArray:
    """Squared distance of each point (..., 2) to its segment a -> b (broadcast)."""
    ab = b - a
    rel = points - a
    t = np.clip(np.sum(rel * ab, axis=-1) / np.maximum(np.sum(ab * ab, axis=-1), 1e-300),
                0.0, 1.0)
    gap = rel - t[..., None] * ab
    return np.sum(gap * gap, axis=-1)


def edge_size(nodes: NDArray, edges: NDArray) -> float:
    """The median length of the boundary ``edges``: the body's length scale."""
    return float(np.median(np.linalg.norm(nodes[edges[:, 1]] - nodes[edges[:, 0]], axis=1)))


def ray_exit(origins: NDArray, directions: NDArray, a: NDArray, b: NDArray) -> NDArray:
    """Distance from each of ``origins`` (m, 2) along its unit ``directions`` (m, 2) to the
    first of the segments a[k] -> b[k] it meets (inf if none): from a point inside a body,
    where it leaves the body through its boundary segments. Costs m x k, in chunks."""
    ab = b - a
    out = np.empty(len(origins))
    for start in range(0, len(origins), CHUNK):
        o, d = origins[start:start + CHUNK, None, :], directions[start:start + CHUNK, None, :]
        rel = a[None] - o  # (c, k, 2)
        denom = d[..., 0] * ab[None, :, 1] - d[..., 1] * ab[None, :, 0]
        with np.errstate(divide="ignore", invalid="ignore"):
            t = (rel[..., 0] * ab[None, :, 1] - rel[..., 1] * ab[None, :, 0]) / denom
            u = (rel[..., 0] * d[..., 1] - rel[..., 1] * d[..., 0]) / denom
        hit = (denom != 0.0) & (t >= 0.0) & (u >= 0.0) & (u <= 1.0)
        out[start:start + CHUNK] = np.where(hit, t, np.inf).min(axis=1)
    return out


#: The side of a surface edge is tested this fraction of the edge's length inside its body
#: (well inside the element next to the edge, well above DEPTH_TOLERANCE of the other body).
INSET = 1e-3


def _inside_deeper_than(points: NDArray, nodes: NDArray, cells: NDArray, edges: NDArray,
                        tolerance: float) -> tuple[NDArray, NDArray]:
    """The indices of ``points`` inside the body deeper than ``tolerance`` below its boundary
    ``edges``, and their depths."""
    outline = nodes[edges[:, 0]]  # the body's extent (``nodes`` may hold other bodies too)
    low, high = outline.min(axis=0) - tolerance, outline.max(axis=0) + tolerance
    candidates = np.flatnonzero(np.all((points >= low) & (points <= high), axis=1))
    inside = np.unique(candidates[_inside_pairs(points[candidates], nodes, cells, tolerance)[0]])
    if inside.size == 0:
        return inside, np.zeros(0)
    depth = distance_to_segments(points[inside], nodes[edges[:, 0]], nodes[edges[:, 1]])
    deep = depth > tolerance
    return inside[deep], depth[deep]


def deepest_overlap(points: NDArray, nodes: NDArray, cells: NDArray,
                    edges: NDArray | None = None, size: float | None = None, *,
                    chain: bool = False) -> Overlap | None:
    """Where the body (``nodes``, ``cells``) overlaps the ``points``' body, or None.

    ``chain`` (as the scenario builder calls it): ``points`` are a contact surface, an ordered
    chain of boundary nodes walked with their body on the left (each two consecutive points an
    element edge, ``ContactSurface.nodes``; a closed one with its first point repeated at the
    end); False (the default): a mere set of points (``engine.diagnostics``), of which only
    the first test below is made.

    1. The point of ``points`` deepest inside the body, its depth being the distance to the
       body's boundary, if one is deeper than DEPTH_TOLERANCE x the body's ``edge_size``.
    2. Else, on a chain: bodies whose edges lie along each other's overlap with every node on
       the other's boundary (depth 0: two rods on top of each other, or overlapping by a
       length, one element thick). So the side of each surface edge is tested too: the point
       INSET x its length inside the edge's midpoint (inside the element next to it). The edge
       whose point is deeper than the tolerance inside the body, and deepest along the edge's
       inward normal (from the midpoint to where the normal leaves the body), is the overlap
       (``Overlap.edge``). Bodies that touch along an edge, or at a node, have their sides
       apart: their points are outside.

    ``edges``, ``size``: the body's ``boundary_edges(cells)`` and ``edge_size``, if kept from an
    earlier call. Cost: each test gathers the cells in the points' bounding box (linear in
    the cells), finds the candidates among them with a k-d tree (``_inside_pairs``), then the
    distances of the points inside to the nearby boundary edges (a k-d tree,
    ``distance_to_segments``; every surface node of bodies that touch is inside within the
    tolerance); the depths along the normals (edges inside x boundary edges, ``ray_exit``)
    only on an overlap (CPU time: 28 ms a call for a 241-node surface on a 250 x 100-cell
    block, ``edges`` given)."""
    edges = boundary_edges(cells) if edges is None else edges
    tolerance = DEPTH_TOLERANCE * (edge_size(nodes, edges) if size is None else size)
    inside, depth = _inside_deeper_than(points, nodes, cells, edges, tolerance)
    if inside.size:
        worst = int(np.argmax(depth))
        index = int(inside[worst])
        return Overlap(index, (float(points[index, 0]), float(points[index, 1])),
                       float(depth[worst]))
    if not chain or len(points) < 2:
        return None
    tangent = points[1:] - points[:-1]
    length = np.linalg.norm(tangent, axis=1)
    keep = np.flatnonzero(length > 0.0)
    normal = np.stack([-tangent[keep, 1], tangent[keep, 0]], axis=1) / length[keep, None]
    middle = 0.5 * (points[keep] + points[keep + 1])
    inset = INSET * length[keep, None]
    inside, _ = _inside_deeper_than(middle + inset * normal, nodes, cells, edges, tolerance)
    if inside.size == 0:
        return None
    beyond = ray_exit(middle[inside] + inset[inside] * normal[inside], normal[inside],
                      nodes[edges[:, 0]], nodes[edges[:, 1]])
    along = inset[inside, 0] + np.where(np.isfinite(beyond), beyond, 0.0)
    worst = int(np.argmax(along))
    index = int(keep[inside[worst]])
    return Overlap(index, (float(points[index, 0]), float(points[index, 1])),
                   float(along[worst]), edge=True)


def deepest_self_overlap(boundary: NDArray, nodes: NDArray, cells: NDArray, edges: NDArray,
                         size: float) -> Overlap | None:
    """The boundary node of a body deepest inside one of that body's own cells that does not
    have it as a corner, or None: the body has passed through itself (a thin ring folded
    by an impact), which no contact surface resists (self contact is not modelled).

    ``boundary``: the body's boundary nodes (indices into ``nodes``), ``cells`` its cells,
    ``edges`` its ``boundary_edges`` and ``size`` their ``edge_size``. A node is never inside
    a cell of a valid, unfolded mesh that it is not a corner of (up to the DEPTH_TOLERANCE x
    ``size`` slack). The depth is the distance to the body's boundary edges away from the
    node: those with an end on one of the node's own cells are left out, since the node lies
    on them. ``Overlap.point`` indexes ``boundary``."""
    tolerance = DEPTH_TOLERANCE * size
    point, cell = _inside_pairs(nodes[boundary], nodes, cells, tolerance)
    foreign = ~np.any(cells[cell] == boundary[point, None], axis=1)
    point = np.unique(point[foreign])
    best: Overlap | None = None
    for p in point:  # few: nodes of a fold only
        node = boundary[p]
        local = np.unique(cells[np.any(cells == node, axis=1)])
        away = edges[~np.isin(edges, local).any(axis=1)]
        if len(away) == 0:
            continue
        depth = float(distance_to_segments(nodes[[node]], nodes[away[:, 0]],
                                           nodes[away[:, 1]])[0])
        if depth > tolerance and (best is None or depth > best.depth):
            best = Overlap(int(p), (float(nodes[node, 0]), float(nodes[node, 1])), depth)
    return best


def self_clearance(boundary: NDArray, nodes: NDArray, cells: NDArray) -> float:
    """The smallest distance from a boundary node to a cell it is not a corner of, capped at
    two cell radii (the largest centroid-corner distance): a deformation that changes no
    distance between points of the body by this much cannot put a boundary node inside such
    a cell (``deepest_self_overlap`` then finds none).

    Only the pairs that can be nearest are measured: a cell is at least its centroid's
    distance minus its own radius away, so with ``bound`` the distance of some such pair
    (each node's nearest centroids), a cell counts only within ``bound`` + its radius, in
    classes of cells of like radius (``_by_radius``): a single search within three times the
    largest radius measured 200 000 pairs a call on a graded mesh (Hertz refined 8x)."""
    corners = nodes[cells]
    centroid = corners.mean(axis=1)
    radii = np.linalg.norm(corners - centroid[:, None], axis=-1).max(axis=1)
    cap = 2.0 * float(radii.max())
    if len(boundary) == 0:
        return cap
    points = cKDTree(nodes[boundary])
    _, first = cKDTree(centroid).query(nodes[boundary], k=min(NEAREST_CELLS, len(cells)))
    first = first.reshape(len(boundary), -1)
    point = np.repeat(np.arange(len(boundary)), first.shape[1])
    bound = min(cap, _foreign_distance(boundary, nodes, cells, corners, point,
                                       first.reshape(-1)))
    clearance = bound
    for group in _by_radius(radii):
        # round-off in either distance must not drop the nearest cell: a relative margin
        reach = (bound + float(radii[group].max())) * (1.0 + 1e-9) + 1e-300
        near = points.sparse_distance_matrix(cKDTree(centroid[group]), reach,
                                             output_type="ndarray")
        clearance = min(clearance, _foreign_distance(boundary, nodes, cells, corners,
                                                     near["i"], group[near["j"]]))
    return clearance


#: Centroids nearest each boundary node whose cells give ``self_clearance`` its first bound
NEAREST_CELLS = 8


def _by_radius(radii: NDArray) -> list[NDArray]:
    """The cells in classes whose radii are within a factor of two of each other (a graded
    mesh's few sizes): each class is searched within its own largest radius."""
    level = np.floor(np.log2(np.maximum(radii, 1e-300) / max(float(radii.max()), 1e-300)))
    order = np.argsort(level, kind="stable")
    cuts = np.flatnonzero(np.diff(level[order])) + 1
    return np.split(order, cuts)


def _foreign_distance(boundary: NDArray, nodes: NDArray, cells: NDArray, corners: NDArray,
                      point: NDArray, cell: NDArray) -> float:
    """The smallest distance from boundary node ``point`` (index into ``boundary``) to the
    edges of ``cell``, over the pairs whose cell does not have the node as a corner (inf
    with none)."""
    foreign = ~np.any(cells[cell] == boundary[point, None], axis=1)
    point, cell = point[foreign], cell[foreign]
    clearance = np.inf
    for start in range(0, len(point), CHUNK):  # the distance to the quad's four edges
        quad = corners[cell[start:start + CHUNK]]
        squared = _pair_distances(nodes[boundary[point[start:start + CHUNK]], None, :], quad,
                                  np.roll(quad, -1, axis=1))
        clearance = min(clearance, float(np.sqrt(squared).min()))
    return clearance


def rigid_deviation(reference: NDArray, current: NDArray) -> float:
    """How far the points ``current`` (n, 2) are at most from a rigid motion of ``reference``
    (the rotation about the centroids that best fits them in least squares): distances
    between points of the body changed by at most twice this."""
    a = reference - reference.mean(axis=0)
    b = current - current.mean(axis=0)
    angle = np.arctan2(np.sum(a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]), np.sum(a * b))
    c, s = np.cos(angle), np.sin(angle)
    turned = np.stack([c * a[:, 0] - s * a[:, 1], s * a[:, 0] + c * a[:, 1]], axis=1)
    return float(np.sqrt(np.sum((b - turned) ** 2, axis=1)).max())


#: Surface-1 nodes nearest the partner surface that ``facing_away`` looks at, and the cosine
#: between their normals and their nearest partners' above which the two point the same way
FACING_NODES, SAME_WAY = 3, 0.5


def facing_away(xy1: NDArray, closed1: bool, xy2: NDArray, closed2: bool) -> int | None:
    """Whether surface 1 (chain ``xy1``) and surface 2 face away from each other, as the index
    of surface 1's node nearest surface 2, or None. At the FACING_NODES surface-1 nodes
    nearest surface 2, the node's outward normal and its nearest partner node's point the same
    way (cosine > SAME_WAY) and the partner lies behind one of the two surfaces: the face on
    the far side of a body was named, and the run would complete with one body inside the
    other. Surfaces that face each other, near or far, have their nearest points in front of
    both and their normals opposed."""
    distance, partner = cKDTree(xy2).query(xy1)
    nearest = np.argsort(distance, kind="stable")[:FACING_NODES]
    n1, n2 = chord_normals(xy1, closed1)[nearest], chord_normals(xy2, closed2)[partner[nearest]]
    ahead = xy2[partner[nearest]] - xy1[nearest]
    behind = (np.sum(ahead * n1, axis=1) < 0.0) | (np.sum(-ahead * n2, axis=1) < 0.0)
    same_way = np.sum(n1 * n2, axis=1) > SAME_WAY
    return int(nearest[0]) if bool(np.all(same_way & behind)) else None
