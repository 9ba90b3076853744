"""Remapping nodal fields from the old mesh onto moved nodes (report 4.3, eqs. 4.18-4.19).

Point location uses a k-d tree over old cell centroids; the candidate cells of every point are
tested at once with a vectorized Newton inversion of the bilinear map. Points slightly outside the
old mesh (a surface node moved along the curved surface of ``ale.surface`` bulges out of the old
polygonal boundary by O(h^2 curvature)) are clamped to the nearest point of the nearest cell.

Two interpolants: ``"linear"`` is the Q4 interpolation of (4.18); ``"quadratic"`` is a
least-squares complete quadratic over the patch of the containing cell and its node neighbours, a
higher-order option in the spirit of (4.19) that reproduces quadratic fields exactly. Points that
coincide with an old node take its value exactly, so unmoved nodes keep their fields.

Plain interpolation does not conserve momentum; ``conservative_velocity_correction`` adds the
rigid-body velocity that restores the linear and angular momentum (METHOD_NOTES, ALE bookkeeping).
"""

from __future__ import annotations

from typing import Literal, NamedTuple

import numpy as np
import scipy.sparse as sp
from numpy.typing import ArrayLike, NDArray
from scipy.spatial import cKDTree

from ntncontact.mesh.quadmesh import MeshError

__all__ = [
    "PointLocation",
    "Remapper",
    "conservative_velocity_correction",
    "inverse_bilinear",
    "momenta",
    "q4_shape",
    "remap_fields",
]

RemapMethod = Literal["linear", "quadratic"]
# reference coordinates of the CCW Q4 corners
_XI = np.array([[-1.0, -1.0], [1.0, -1.0], [1.0, 1.0], [-1.0, 1.0]])
_INSIDE_TOL = 1e-9  # reference-coordinate slack for points on a shared edge (round-off)


def q4_shape(xi: ArrayLike) -> NDArray[np.float64]:
    """Bilinear shape functions N_a(xi, eta) = (1 + xi_a xi)(1 + eta_a eta)/4, shape (p, 4)."""
    xi = np.asarray(xi, dtype=float)
    return 0.25 * (1.0 + xi[..., None, 0] * _XI[:, 0]) * (1.0 + xi[..., None, 1] * _XI[:, 1])


def inverse_bilinear(
    cell_xy: NDArray, points: NDArray, iterations: int = 12
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Reference coordinates of points in Q4 cells by Newton, vectorized over leading axes.

    ``cell_xy`` (..., 4, 2), ``points`` (..., 2). Returns (xi, residual distance). The map is
    written x = a0 + a1 xi + a2 eta + a3 xi eta; iterates are kept in [-4, 4] so that far-away
    candidate cells cannot overflow.
    """
    x0, x1, x2, x3 = (cell_xy[..., a, :] for a in range(4))
    a0 = 0.25 * (x0 + x1 + x2 + x3) - points
    a1, a2 = 0.25 * (-x0 + x1 + x2 - x3), 0.25 * (-x0 - x1 + x2 + x3)
    a3 = 0.25 * (x0 - x1 + x2 - x3)
    xi, eta = np.zeros(points.shape[:-1]), np.zeros(points.shape[:-1])
    for _ in range(iterations):
        r = a0 + a1 * xi[..., None] + a2 * eta[..., None] + a3 * (xi * eta)[..., None]
        g1, g2 = a1 + a3 * eta[..., None], a2 + a3 * xi[..., None]  # columns of dx/dxi
        det = g1[..., 0] * g2[..., 1] - g1[..., 1] * g2[..., 0]
        det = np.where(np.abs(det) > 0, det, 1.0)
        xi = np.clip(xi - (g2[..., 1] * r[..., 0] - g2[..., 0] * r[..., 1]) / det, -4.0, 4.0)
        eta = np.clip(eta - (g1[..., 0] * r[..., 1] - g1[..., 1] * r[..., 0]) / det, -4.0, 4.0)
    r = a0 + a1 * xi[..., None] + a2 * eta[..., None] + a3 * (xi * eta)[..., None]
    return np.stack([xi, eta], axis=-1), np.linalg.norm(r, axis=-1)


def _nearest_on_boundary(cell_xy: NDArray, points: NDArray) -> tuple[NDArray, NDArray]:
    """Closest point of each cell's boundary to each point: (distance, xi) over leading axes."""
    a, b = cell_xy, np.roll(cell_xy, -1, axis=-2)  # the 4 straight edges a -> b
    d = b - a
    t = np.einsum("...ei,...ei->...e", points[..., None, :] - a, d)
    t = np.clip(t / np.maximum(np.einsum("...ei,...ei->...e", d, d), 1e-300), 0.0, 1.0)
    dist = np.linalg.norm(a + t[..., None] * d - points[..., None, :], axis=-1)
    edge = np.argmin(dist, axis=-1)
    te = np.take_along_axis(t, edge[..., None], axis=-1)[..., 0]
    start, end = _XI[edge], _XI[(edge + 1) % 4]  # the bilinear map is linear along an edge
    return np.min(dist, axis=-1), start + te[..., None] * (end - start)


class PointLocation(NamedTuple):
    cell: NDArray[np.int64]  # containing (or nearest) old cell of each point
    xi: NDArray[np.float64]  # reference coordinates in that cell, (p, 2)
    clamped: NDArray[np.bool_]  # the point was outside the old mesh and moved onto it


class Remapper:
    """Locator and interpolator on one old mesh; build once per old mesh."""

    def __init__(self, nodes: ArrayLike, cells: ArrayLike, candidates: int = 8) -> None:
        self.nodes = np.asarray(nodes, dtype=float)
        self.cells = np.asarray(cells, dtype=np.int64).reshape(-1, 4)
        xc = self.nodes[self.cells]
        self._cell_xy = xc
        self._tree = cKDTree(xc.mean(axis=1))
        self._node_tree = cKDTree(self.nodes)
        d1, d2 = xc[:, 2] - xc[:, 0], xc[:, 3] - xc[:, 1]
        area = 0.5 * (d1[:, 0] * d2[:, 1] - d1[:, 1] * d2[:, 0])
        self.cell_size = np.sqrt(np.abs(area))  # sqrt(area): the length scale of a cell
        self._k = min(candidates, len(self.cells))
        self._patches: NDArray[np.int64] | None = None

    def _search(self, points: NDArray, k: int) -> tuple[NDArray, NDArray, NDArray]:
        """Candidates (p, k), their xi and whether each candidate contains its point."""
        _, cand = self._tree.query(points, k=k)
        cand = cand.reshape(len(points), k)
        xi, res = inverse_bilinear(self._cell_xy[cand], points[:, None, :])
        inside = (np.max(np.abs(xi), axis=-1) <= 1.0 + _INSIDE_TOL) & (
            res <= 1e-9 * self.cell_size[cand]
        )
        return cand, xi, inside

    def locate(self, points: ArrayLike, outside_tol: float = 0.1) -> PointLocation:
        """Containing cells and reference coordinates of points.

        A point outside every cell is clamped onto the nearest cell boundary if it is within
        ``outside_tol`` times that cell's size; farther points raise MeshError.
        """
        pts = np.atleast_2d(np.asarray(points, dtype=float))
        n = len(pts)
        cell, xi = np.full(n, -1), np.zeros((n, 2))
        todo = np.arange(n)
        # nearest few centroids first, then a wider search for the rest
        for k in (min(4, self._k), self._k, min(4 * self._k, len(self.cells))):
            if todo.size == 0:
                break
            cand, cxi, inside = self._search(pts[todo], k)
            hit = inside.any(axis=1)
            first = np.argmax(inside, axis=1)[hit]  # nearest-centroid containing cell
            cell[todo[hit]] = cand[hit, first]
            xi[todo[hit]] = cxi[hit, first]
            todo = todo[~hit]
        clamped = np.zeros(n, bool)
        if todo.size:
            self._clamp(pts, todo, cell, xi, outside_tol)
            clamped[todo] = True
        return PointLocation(cell, xi, clamped)

    def _clamp(
        self, pts: NDArray, todo: NDArray, cell: NDArray, xi: NDArray, outside_tol: float
    ) -> None:
        """Fill cell and xi of outside points with the nearest boundary point of nearby cells."""
        _, cand = self._tree.query(pts[todo], k=self._k)
        cand = cand.reshape(len(todo), self._k)
        dist, bxi = _nearest_on_boundary(self._cell_xy[cand], pts[todo][:, None, :])
        best = np.argmin(dist, axis=1)
        rows = np.arange(len(todo))
        far = dist[rows, best] > outside_tol * self.cell_size[cand[rows, best]]
        if far.any():
            i = int(np.flatnonzero(far)[0])
            raise MeshError(
                f"point {pts[todo[i]].tolist()} lies {dist[i, best[i]]:.3g} outside the old "
                f"mesh (nearest cell {int(cand[i, best[i]])}); cannot remap it"
            )
        cell[todo] = cand[rows, best]
        xi[todo] = bxi[rows, best]

    def remap(
        self,
        fields: ArrayLike,
        points: ArrayLike,
        method: RemapMethod = "linear",
        outside_tol: float = 0.1,
    ) -> NDArray[np.float64]:
        """Old nodal fields (n,) or (n, k) evaluated at new points, (p,) or (p, k)."""
        f = np.asarray(fields, dtype=float)
        f2 = f.reshape(len(self.nodes), -1)
        pts = np.atleast_2d(np.asarray(points, dtype=float))
        loc = self.locate(pts, outside_tol)
        out = np.einsum("pa,pak->pk", q4_shape(loc.xi), f2[self.cells[loc.cell]])
        if method == "quadratic":
            quad, ok = self._quadratic(f2, pts, loc)
            out[ok] = quad[ok]
        elif method != "linear":
            raise ValueError(f"unknown remap method {method!r}; use 'linear' or 'quadratic'")
        # an unmoved node keeps its own value exactly (the least-squares fit does not interpolate)
        dist, node = self._node_tree.query(pts)
        same = dist <= 1e-12 * self.cell_size[loc.cell]
        out[same] = f2[node[same]]
        return out.reshape((len(pts), *f.shape[1:]))

    def _patch_nodes(self) -> NDArray[np.int64]:
        """Per cell, the nodes of the cells sharing a node with it, padded with -1, (m, maxp)."""
        if self._patches is None:
            m, n = len(self.cells), len(self.nodes)
            rows = np.repeat(np.arange(m), 4)
            inc = sp.csr_matrix((np.ones(4 * m), (rows, self.cells.ravel())), shape=(m, n))
            patch = ((inc @ inc.T) @ inc).tocsr()
            patch.sort_indices()
            lengths = np.diff(patch.indptr)
            padded = np.full((m, lengths.max()), -1, dtype=np.int64)
            cols = np.arange(patch.nnz) - np.repeat(patch.indptr[:-1], lengths)
            padded[np.repeat(np.arange(m), lengths), cols] = patch.indices
            self._patches = padded
        return self._patches

    def _quadratic(self, f2: NDArray, pts: NDArray, loc: PointLocation) -> tuple[NDArray, NDArray]:
        """Least-squares quadratic over each point's patch, evaluated at the point (4.19)."""
        patch = self._patch_nodes()[loc.cell]  # (p, maxp)
        valid = patch >= 0
        h = self.cell_size[loc.cell][:, None]
        d = (self.nodes[np.where(valid, patch, 0)] - pts[:, None, :]) / h[..., None]
        dx, dy = d[..., 0], d[..., 1]
        basis = np.stack([np.ones_like(dx), dx, dy, dx * dx, dx * dy, dy * dy], axis=-1)
        basis *= valid[..., None]  # padding rows drop out of the fit
        u, s, vt = np.linalg.svd(basis, full_matrices=False)
        # full rank 6; otherwise (too few or collinear patch nodes) keep the linear value
        ok = (s.shape[1] == 6) & (s[:, -1] > 1e-8 * s[:, 0])
        inv_s = np.where(s > 1e-8 * s[:, :1], 1.0 / np.where(s > 0, s, 1.0), 0.0)
        vals = f2[np.where(valid, patch, 0)] * valid[..., None]
        coeff = np.einsum("pji,pj,pqj,pqk->pik", vt, inv_s, u, vals)
        return coeff[:, 0, :], ok  # value of the fit at the point (local origin)


def remap_fields(
    old_nodes: ArrayLike,
    old_cells: ArrayLike,
    fields: ArrayLike,
    points: ArrayLike,
    method: RemapMethod = "linear",
    outside_tol: float = 0.1,
) -> NDArray[np.float64]:
    """Evaluate old nodal fields at new points (see ``Remapper.remap``)."""
    return Remapper(old_nodes, old_cells).remap(fields, points, method, outside_tol)


def momenta(masses: ArrayLike, x: ArrayLike, v: ArrayLike) -> tuple[NDArray[np.float64], float]:
    """Linear momentum sum m v (2,) and angular momentum sum m (x cross v) about the origin."""
    m = np.asarray(masses, dtype=float)
    xa, va = np.asarray(x, dtype=float), np.asarray(v, dtype=float)
    linear = m @ va
    angular = float(m @ (xa[:, 0] * va[:, 1] - xa[:, 1] * va[:, 0]))
    return linear, angular


def conservative_velocity_correction(
    masses_new: ArrayLike,
    x_new: ArrayLike,
    v_new: ArrayLike,
    target_linear: ArrayLike,
    target_angular: float,
) -> NDArray[np.float64]:
    """Add a rigid velocity a + w e_z x (x - x_c) so that momenta equal the targets.

    With M = sum m, x_c the centre of mass and I = sum m |x - x_c|^2: a = (P* - P) / M restores
    the linear momentum and w = (L* - L - M x_c x a) / I the angular momentum about the origin
    (a rotation about x_c adds no linear momentum). ``masses_new`` are nodal (lumped or
    row-sum) masses; for a consistent mass matrix the linear momentum is still exact with row
    sums, while the angular momentum is exact for the lumped definition used here.
    """
    m = np.asarray(masses_new, dtype=float)
    x, v = np.asarray(x_new, dtype=float), np.asarray(v_new, dtype=float)
    total = m.sum()
    centre = m @ x / total
    linear, angular = momenta(m, x, v)
    a = (np.asarray(target_linear, dtype=float) - linear) / total
    r = x - centre
    inertia = m @ np.einsum("ni,ni->n", r, r)
    torque_of_a = total * (centre[0] * a[1] - centre[1] * a[0])
    omega = (target_angular - angular - torque_of_a) / inertia if inertia > 0 else 0.0
    return v + a + omega * np.column_stack([-r[:, 1], r[:, 0]])
