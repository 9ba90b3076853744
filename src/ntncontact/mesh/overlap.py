"""Points of one body inside another: at t = 0 (bodies placed so that they overlap), and
after every step (boundary nodes on no contact surface, ``engine.diagnostics``).

Node-to-node contact only acts on pairs it detects near the surfaces; bodies that start
interpenetrated pass through each other. The scenario builder therefore refuses them, naming
the depth and the place (docs/scenarios.md, ``[[contact]]``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.spatial import cKDTree

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


def in_elements(points: NDArray, nodes: NDArray, cells: NDArray, slack: float) -> NDArray:
    """Which ``points`` (m, 2) lie in some counter-clockwise quad of ``cells`` (edges included,
    with ``slack`` of length; a valid mesh's quads are convex). Each point is tested against
    the cells whose centroid lies within the largest centroid-corner distance of it (a k-d
    tree): at run time this is called every step on a body's boundary nodes against another
    body of up to 10^5 cells, where testing every pair costs m x cells."""
    found = np.zeros(len(points), bool)
    if len(points) == 0 or len(cells) == 0:
        return found
    corners = nodes[cells]  # (ne, 4, 2)
    low, high = points.min(axis=0) - slack, points.max(axis=0) + slack
    corners = corners[np.all((corners.max(axis=1) >= low) & (corners.min(axis=1) <= high),
                             axis=1)]
    if len(corners) == 0:
        return found
    centroid = corners.mean(axis=1)
    reach = float(np.linalg.norm(corners - centroid[:, None], axis=-1).max()) + slack
    near = cKDTree(points).sparse_distance_matrix(cKDTree(centroid), reach,
                                                  output_type="ndarray")
    if near.size == 0:
        return found
    point, cell = near["i"], near["j"]
    quad = corners[cell]  # (k, 4, 2)
    edges = np.roll(quad, -1, axis=1) - quad
    rel = points[point, None, :] - quad
    # cross / length: the distance inside each edge's line
    cross = edges[..., 0] * rel[..., 1] - edges[..., 1] * rel[..., 0]
    inside = (cross >= -slack * np.linalg.norm(edges, axis=-1)).all(axis=-1)
    found[point[inside]] = True
    return found


def boundary_edges(cells: NDArray) -> NDArray:
    """Edges (k, 2) of the mesh that belong to one element only."""
    edges = np.stack([cells, np.roll(cells, -1, axis=1)], axis=-1).reshape(-1, 2)
    _, index, count = np.unique(np.sort(edges, axis=1), axis=0, return_index=True,
                                return_counts=True)
    return edges[index[count == 1]]


def distance_to_segments(points: NDArray, a: NDArray, b: NDArray) -> NDArray:
    """Distance of each point (m, 2) to the nearest of the segments a[k] -> b[k]."""
    ab = b - a
    out = np.empty(len(points))
    for start in range(0, len(points), CHUNK):
        rel = points[start:start + CHUNK, None, :] - a[None]
        t = np.clip(np.sum(rel * ab, axis=-1) / np.maximum(np.sum(ab * ab, axis=-1), 1e-300),
                    0.0, 1.0)
        gap = rel - t[..., None] * ab[None]
        out[start:start + CHUNK] = np.sqrt(np.min(np.sum(gap * gap, axis=-1), axis=1))
    return out


def edge_size(nodes: NDArray, edges: NDArray) -> float:
    """The median length of the boundary ``edges``: the body's length scale."""
    return float(np.median(np.linalg.norm(nodes[edges[:, 1]] - nodes[edges[:, 0]], axis=1)))


def deepest_overlap(points: NDArray, nodes: NDArray, cells: NDArray,
                    edges: NDArray | None = None, size: float | None = None) -> Overlap | None:
    """The point of ``points`` deepest inside the body (``nodes``, ``cells``), its depth being
    the distance to the body's boundary; None if none is deeper than DEPTH_TOLERANCE x the
    body's ``edge_size``. ``edges``, ``size``: the body's ``boundary_edges(cells)`` and
    ``edge_size``, if kept from an earlier call."""
    edges = boundary_edges(cells) if edges is None else edges
    tolerance = DEPTH_TOLERANCE * (edge_size(nodes, edges) if size is None else size)
    outline = nodes[edges[:, 0]]  # the body's extent (``nodes`` may hold other bodies too)
    low, high = outline.min(axis=0) - tolerance, outline.max(axis=0) + tolerance
    candidates = np.flatnonzero(np.all((points >= low) & (points <= high), axis=1))
    inside = candidates[in_elements(points[candidates], nodes, cells, tolerance)]
    if inside.size == 0:
        return None
    depth = distance_to_segments(points[inside], nodes[edges[:, 0]], nodes[edges[:, 1]])
    worst = int(np.argmax(depth))
    if depth[worst] <= tolerance:
        return None
    index = int(inside[worst])
    return Overlap(index, (float(points[index, 0]), float(points[index, 1])),
                   float(depth[worst]))
