"""Remapping nodal fields from the old mesh onto moved nodes (report 4.3, eqs. 4.18-4.19).

Point location tries a hinted cell per point first (the ALE update knows where a moved node
came from) and otherwise uses a k-d tree over old cell centroids (the nearest few, then every
cell whose centroid is close enough for the point to lie in it: in a strongly sheared cell the
point can be farther from its cell's centroid than from dozens of others); the candidate cells
of every point are tested at once with a Newton inversion of the bilinear map. Points
slightly outside the old mesh (a surface node moved along the curved surface of
``ale.surface`` bulges out of the old polygonal boundary by O(h^2 curvature)) are clamped to
the nearest point of the nearest cell.

Two interpolants:

* ``"linear"``: the Q4 interpolation of (4.18), second order (error h^2 f''/8 at most);
* ``"quadratic"``: the gradient-enhanced Q4 interpolant, in the spirit of (4.19),

      f(p) = sum_a N_a(xi) [f_a + 1/2 g_a . (p - x_a)],

  with nodal gradients g_a recovered by a least-squares quadratic fit over each node's two-ring
  of nodes (a linear fit where the patch cannot carry a quadratic). Writing f_a and g_a as
  Taylor expansions about p shows that the quadratic terms cancel exactly, so it reproduces
  every quadratic field on ANY bilinear quad (not only parallelograms), interpolates the nodal
  values (N_a(x_b) = delta_ab and the correction vanishes at the nodes), and is continuous
  across cell edges (on an edge only the edge's two nodes contribute): a node moved by delta
  takes a value that tends to its own as delta -> 0 (a patch fit evaluated at the point would
  replace the value of a node moved by any amount with a smoothed one: an energy jump at every
  update).

Points that coincide with an old node take its value exactly, so unmoved nodes keep their
fields.

Plain interpolation does not conserve momentum; ``conservative_velocity_correction`` adds the
rigid-body velocity that restores the linear and angular momentum (METHOD_NOTES, ALE bookkeeping).
"""

from __future__ import annotations

from functools import cached_property
from typing import Any, Literal, NamedTuple, get_args

import numpy as np
import scipy.sparse as sp
from numpy.typing import ArrayLike, NDArray
from scipy.spatial import cKDTree

from ntncontact.mesh.quadmesh import MeshError, unique_pairs

from ..fem.q4 import CORNERS
from ..jit import njit

__all__ = [
    "LazyGradients",
    "PointLocation",
    "Remapper",
    "conservative_velocity_correction",
    "inverse_bilinear",
    "momenta",
    "two_ring_patches",
]

RemapMethod = Literal["linear", "quadratic"]
_INSIDE_TOL = 1e-9  # reference-coordinate slack for points on a shared edge (round-off)
_SAME_NODE = 1e-12  # a point this close (times the cell size) to an old node takes its value


def inverse_bilinear(
    cell_xy: NDArray, points: NDArray, iterations: int = 12
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Reference coordinates of points in Q4 cells by Newton, vectorized over leading axes.

    ``cell_xy`` (..., 4, 2), ``points`` (..., 2). Returns (xi, residual distance). The map is
    written x = a0 + a1 xi + a2 eta + a3 xi eta; iterates are kept in [-4, 4] so that far-away
    candidate cells cannot overflow.
    """
    cell_xy, points = np.asarray(cell_xy, dtype=float), np.asarray(points, dtype=float)
    lead = np.broadcast_shapes(cell_xy.shape[:-2], points.shape[:-1])
    # C-contiguous and writable whatever the inputs: np.broadcast_to's read-only view is a
    # second Numba type, compiled again inside a run
    cells = np.require(np.broadcast_to(cell_xy, (*lead, 4, 2)).reshape(-1, 4, 2),
                       requirements=["C", "W"])
    pts = np.require(np.broadcast_to(points, (*lead, 2)).reshape(-1, 2), requirements=["C", "W"])
    xi, res = _inverse_bilinear(cells, pts, iterations)  # until every point has converged
    return xi.reshape(*lead, 2), res.reshape(lead)


class RemapTopology:
    """What a Remapper needs from the cells alone: the outer (boundary) cell edges and the
    two-ring node patches of the gradient recovery (built on first use)."""

    def __init__(self, cells: ArrayLike, n_nodes: int) -> None:
        cells = np.asarray(cells, dtype=np.int64).reshape(-1, 4)
        self.cells, self.n_nodes = cells, n_nodes
        keys = np.sort(np.stack([cells, np.roll(cells, -1, axis=1)], -1), -1)
        _, inverse, counts = unique_pairs(keys, return_inverse=True, return_counts=True)
        self.outer_edge = (counts[inverse.reshape(-1)] == 1).reshape(-1, 4)

    @cached_property
    def patches(self) -> tuple[NDArray[np.int64], NDArray]:
        return two_ring_patches(self.cells, self.n_nodes)


class PointLocation(NamedTuple):
    cell: NDArray[np.int64]  # containing (or nearest) old cell of each point
    xi: NDArray[np.float64]  # reference coordinates in that cell, (p, 2)
    clamped: NDArray[np.bool_]  # the point was outside the old mesh and moved onto it


class Remapper:
    """Locator and interpolator on one old mesh; build once per old mesh."""

    def __init__(self, nodes: ArrayLike, cells: ArrayLike, candidates: int = 8,
                 topology: RemapTopology | None = None) -> None:
        """``topology``: ``RemapTopology(cells, len(nodes))`` if kept from another mesh with
        the same cells (it depends on the cells only)."""
        self.nodes = np.asarray(nodes, dtype=float)
        self.cells = np.asarray(cells, dtype=np.int64).reshape(-1, 4)
        xc = self.nodes[self.cells]
        self._cell_xy = xc
        self._topology = topology or RemapTopology(self.cells, len(self.nodes))
        self._outer_edge = self._topology.outer_edge
        d1, d2 = xc[:, 2] - xc[:, 0], xc[:, 3] - xc[:, 1]
        area = 0.5 * (d1[:, 0] * d2[:, 1] - d1[:, 1] * d2[:, 0])
        self.cell_size = np.sqrt(np.abs(area))  # sqrt(area): the length scale of a cell
        self._k = min(candidates, len(self.cells))

    # the search structures are built on first use: a hinted ALE move rarely needs them
    @cached_property
    def _tree(self) -> Any:
        return cKDTree(self._cell_xy.mean(axis=1))

    @cached_property
    def _boxes(self) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        return self._cell_xy.min(axis=1), self._cell_xy.max(axis=1)

    @cached_property
    def _reach(self) -> float:
        """The largest distance from a cell's centroid to one of its corners: a point inside a
        cell lies within this distance of that cell's centroid (the distance to the centroid
        is convex, so its maximum over the cell is at a corner)."""
        xc = self._cell_xy
        return float(np.max(np.linalg.norm(xc - xc.mean(axis=1)[:, None, :], axis=-1)))

    def _nearest(self, points: NDArray, k: int) -> NDArray[np.int64]:
        """The k cells with the nearest centroids of each point, nearest first, (p, k)."""
        return self._tree.query(points, k=k)[1].reshape(len(points), k)

    def _within(self, points: NDArray, radius: float) -> NDArray[np.int64]:
        """Every cell whose centroid lies within ``radius`` of each point, nearest first (at
        least the nearest cell; rows padded by repeating their farthest cell), (p, width)."""
        found = self._tree.query_ball_point(points, radius)
        centroid = self._cell_xy.mean(axis=1)
        rows = []
        for p, near in zip(points, found, strict=True):
            near = np.asarray(near, dtype=np.int64)
            if near.size == 0:
                near = self._nearest(p[None, :], 1)[0]
            dist = np.linalg.norm(centroid[near] - p, axis=1)
            rows.append(near[np.argsort(dist, kind="stable")])
        width = max(row.size for row in rows)
        return np.array([np.pad(row, (0, width - row.size), mode="edge") for row in rows])

    def _search(self, points: NDArray, cand: NDArray[np.int64]) -> tuple[NDArray, NDArray]:
        """Containing cell (or -1) and its xi for each point among its candidate cells
        ``cand`` (p, k), nearest centroids first.

        Only candidates whose bounding box holds the point are inverted; among containing
        cells the one with the nearest centroid wins.
        """
        slack = (_INSIDE_TOL * self.cell_size[cand])[..., None]
        p = points[:, None, :]
        lo, hi = self._boxes
        inbox = np.all((p >= lo[cand] - slack) & (p <= hi[cand] + slack), axis=-1)
        row, col = np.nonzero(inbox)  # row-major: nearest candidates first
        cell, xi = np.full(len(points), -1), np.zeros((len(points), 2))
        if row.size == 0:
            return cell, xi
        cells = cand[row, col]
        found, res = inverse_bilinear(self._cell_xy[cells], points[row])
        inside = (np.max(np.abs(found), axis=-1) <= 1.0 + _INSIDE_TOL) & (
            res <= 1e-9 * self.cell_size[cells]
        )
        hit_rows, first = np.unique(row[inside], return_index=True)
        cell[hit_rows] = cells[inside][first]
        xi[hit_rows] = found[inside][first]
        return cell, xi

    def locate(
        self, points: ArrayLike, outside_tol: float = 0.1, hint: ArrayLike | None = None
    ) -> PointLocation:
        """Containing cells and reference coordinates of points.

        A point outside every cell is clamped onto the nearest cell boundary if it is within
        ``outside_tol`` times that cell's size; farther points raise MeshError. ``hint`` (p,)
        optionally names a likely cell per point (-1: none), tried first: a point inside it is
        taken, and so is a point just outside one of its edges on the mesh boundary (clamped
        onto that edge, as for a surface node slid along a convex surface); all other points
        are searched for.
        """
        pts = np.atleast_2d(np.asarray(points, dtype=float))
        n = len(pts)
        if hint is not None:  # the kernel's misses are -1, xi = 0, not clamped, as below
            cell, xi, clamped = _locate_in_hints(
                self._cell_xy, self.cell_size, self._outer_edge, np.ascontiguousarray(pts),
                np.asarray(hint, dtype=np.int64).reshape(n), outside_tol, _INSIDE_TOL, 12)
        else:
            cell, xi, clamped = np.full(n, -1), np.zeros((n, 2)), np.zeros(n, bool)
        todo = np.flatnonzero(cell < 0)
        if todo.size == 0:  # every hint held (the ALE update's usual case)
            return PointLocation(cell, xi, clamped)
        # nearest few centroids first, then a wider search, then every cell that can hold the
        # point: a strongly sheared cell's centroid can lie farther from a point inside it than
        # dozens of other cells' centroids
        for rule in (min(4, self._k), min(4 * self._k, len(self.cells)), None):
            if todo.size == 0:
                break
            cand = (self._within(pts[todo], self._reach) if rule is None
                    else self._nearest(pts[todo], rule))
            found, found_xi = self._search(pts[todo], cand)
            hit = found >= 0
            cell[todo[hit]] = found[hit]
            xi[todo[hit]] = found_xi[hit]
            todo = todo[~hit]
        if todo.size:
            self._clamp(pts, todo, cell, xi, outside_tol)
            clamped[todo] = True
        return PointLocation(cell, xi, clamped)

    def _clamp(
        self, pts: NDArray, todo: NDArray, cell: NDArray, xi: NDArray, outside_tol: float
    ) -> None:
        """Fill cell and xi of outside points with the nearest boundary point of nearby cells:
        the cells with the nearest centroids, else every cell within the reach of the point
        (its boundary can be that close only if its centroid is within ``_reach`` plus the
        tolerance)."""
        cand = self._nearest(pts[todo], self._k)
        best_cell, best_xi, dist = self._nearest_boundary(pts[todo], cand)
        far = dist > outside_tol * self.cell_size[best_cell]
        if far.any():
            radius = self._reach + outside_tol * float(self.cell_size.max())
            again = self._nearest_boundary(pts[todo[far]], self._within(pts[todo[far]], radius))
            best_cell[far], best_xi[far], dist[far] = again
            far = dist > outside_tol * self.cell_size[best_cell]
        if far.any():
            i = int(np.flatnonzero(far)[0])
            raise MeshError(
                f"point {pts[todo[i]].tolist()} lies {dist[i]:.3g} outside the old mesh "
                f"(nearest cell {int(best_cell[i])}); cannot remap it"
            )
        cell[todo] = best_cell
        xi[todo] = best_xi

    def _nearest_boundary(self, pts: NDArray, cand: NDArray[np.int64]
                          ) -> tuple[NDArray, NDArray, NDArray]:
        """Per point the candidate cell with the nearest boundary point: (cell, xi, distance)."""
        dist, bxi = _nearest_on_boundaries(self._cell_xy, cand, np.ascontiguousarray(pts))
        best = np.argmin(dist, axis=1)
        rows = np.arange(len(pts))
        return cand[rows, best], bxi[rows, best], dist[rows, best]

    def remap(
        self,
        fields: ArrayLike,
        points: ArrayLike,
        method: RemapMethod = "linear",
        gradients: LazyGradients | None = None,
        hint: ArrayLike | None = None,
    ) -> NDArray[np.float64]:
        """Old nodal fields (n,) or (n, k) evaluated at new points, (p,) or (p, k).

        ``gradients``, only for "quadratic": a ``LazyGradients`` of these fields on this
        remapper (default: recovered at the located cells' nodes). ``hint``: likely cells of
        the points (see ``locate``).
        """
        if method not in get_args(RemapMethod):
            raise ValueError(f"unknown remap method {method!r}; use 'linear' or 'quadratic'")
        f = np.asarray(fields, dtype=float)
        f2 = f.reshape(len(self.nodes), -1)
        pts = np.atleast_2d(np.asarray(points, dtype=float))
        loc = self.locate(pts, hint=hint)
        nodes = self.cells[loc.cell]  # (p, 4)
        g = np.zeros((0, 4, f2.shape[1], 2))  # "linear": not read
        if method == "quadratic":
            if gradients is None:
                g = self.nodal_gradients(f2, nodes.ravel()).reshape(*nodes.shape, -1, 2)
            else:
                g = gradients.at(nodes)
        # sum_a N_a f_a, and for "quadratic" + 1/2 sum_a N_a g_a . (p - x_a) + 1/2 sum_a N_a
        # g_a . (p - x(xi)) (a clamped point lies off its cell: continue linearly to it)
        # ... and a point on an old node keeps that node's value exactly (no round-off of the
        # interpolation; the node is a corner of the located cell: no node search needed)
        out = _interpolate_at_nodes(
            self.nodes, self.cells, np.ascontiguousarray(f2), loc.cell,
            np.ascontiguousarray(loc.xi), np.ascontiguousarray(pts),
            np.ascontiguousarray(g, dtype=float), method == "quadratic", self.cell_size,
            _SAME_NODE)
        return out.reshape((len(pts), *f.shape[1:]))

    def _gradient_operators(
        self, nodes: NDArray[np.int64]
    ) -> tuple[NDArray[np.int64], NDArray[np.float64]]:
        """Per node of ``nodes`` its two-ring patch (padded with -1) and the rows
        G (p, 2, maxp) with g_a = G_a (f_patch - f_a): least squares of
        f_j - f_a = g.d + d.H d / 2 over the patch (d = x_j - x_a), or of g.d alone where the
        patch does not determine a quadratic. Each node's rows depend on its own patch only."""
        patch, lengths = self._topology.patches
        patch, lengths, centre = patch[nodes], lengths[nodes], self.nodes[nodes]
        valid = patch >= 0
        d = (self.nodes[np.where(valid, patch, 0)] - centre[:, None, :]) * valid[..., None]
        scale = np.sqrt(np.sum(d**2, axis=(1, 2)) / np.maximum(lengths, 1))
        scale = np.where(scale > 0, scale, 1.0)
        ds = d / scale[:, None, None]
        dx, dy = ds[..., 0], ds[..., 1]
        quad = np.stack([dx, dy, 0.5 * dx * dx, dx * dy, 0.5 * dy * dy], axis=-1)
        ops = np.zeros((len(patch), 2, patch.shape[1]))
        # the quadratic fit where the patch determines it, else the linear one: the linear fit
        # is made only for the nodes left (none in a mesh two or more cells across), with the
        # same per-node operations (each node's SVD and pseudo-inverse are its own)
        rows = np.arange(len(patch))
        for basis, terms in ((quad, 5), (ds, 2)):
            u, sv, vt = np.linalg.svd(basis[rows], full_matrices=False)
            ok = (lengths[rows] >= terms) & (sv[:, -1] > 1e-8 * sv[:, 0])
            inv = np.where(sv > 1e-8 * sv[:, :1], 1.0 / np.where(sv > 0, sv, 1.0), 0.0)
            pinv = np.einsum("nji,nj,nqj->niq", vt, inv, u)  # (n, terms, width)
            ops[rows[ok]] = pinv[ok, :2, :] / scale[rows[ok], None, None]
            rows = rows[~ok]
            if rows.size == 0:
                break
        return patch, ops

    def nodal_gradients(self, fields: ArrayLike, nodes: ArrayLike) -> NDArray[np.float64]:
        """Recovered gradients (p, k, 2) at the nodes ``nodes`` (p,) of nodal fields (n,) or
        (n, k): exact for quadratic fields wherever the two-ring patch carries a quadratic
        (every node of a mesh at least two cells across), exact for linear fields everywhere
        else."""
        f2 = np.asarray(fields, dtype=float).reshape(len(self.nodes), -1)
        idx = np.asarray(nodes, dtype=np.int64).reshape(-1)
        patch, ops = self._gradient_operators(idx)
        diff = (f2[np.where(patch >= 0, patch, 0)] - f2[idx][:, None, :]) * (patch >= 0)[..., None]
        return np.einsum("niq,nqk->nki", ops, diff)


class LazyGradients:
    """Nodal gradients of fixed fields on one Remapper, recovered only at the nodes asked for
    and kept: a move remaps a few points, which need the gradients of a few cells' nodes."""

    def __init__(self, remapper: Remapper, fields: ArrayLike) -> None:
        self.remapper = remapper
        self.fields = np.asarray(fields, dtype=float).reshape(len(remapper.nodes), -1)
        self._values = np.zeros((len(remapper.nodes), self.fields.shape[1], 2))
        self._known = np.zeros(len(remapper.nodes), bool)

    def at(self, nodes: NDArray[np.int64]) -> NDArray[np.float64]:
        """Gradients of the nodes ``nodes`` (any shape s), (*s, k, 2)."""
        known = self._known[nodes]
        if not known.all():  # the later augmentations of a step mostly find them all known
            missing = np.unique(nodes[~known])
            self._values[missing] = self.remapper.nodal_gradients(self.fields, missing)
            self._known[missing] = True
        return self._values[nodes]


def two_ring_patches(cells: ArrayLike, n_nodes: int) -> tuple[NDArray[np.int64], NDArray]:
    """Per node the sorted nodes within two cells of it, padded with -1 to a common width,
    and their counts: ((n, width), (n,)). Topology only."""
    cell_arr = np.asarray(cells, dtype=np.int64).reshape(-1, 4)
    m, n = len(cell_arr), n_nodes
    rows = np.repeat(np.arange(m), 4)
    inc = sp.csr_matrix((np.ones(4 * m), (rows, cell_arr.ravel())), shape=(m, n))
    ring = (inc.T @ inc).tocsr()
    ring = (ring @ ring).tocsr()  # nodes within two cells of each node
    ring.setdiag(0)
    ring.eliminate_zeros()
    ring.sort_indices()
    lengths = np.diff(ring.indptr)
    width = max(int(lengths.max(initial=0)), 1)
    patch = np.full((n, width), -1, dtype=np.int64)
    cols = np.arange(ring.nnz) - np.repeat(ring.indptr[:-1], lengths)
    patch[np.repeat(np.arange(n), lengths), cols] = ring.indices
    return patch, lengths


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
    # omega e_z x r = omega (-r_y, r_x); rounding is symmetric, so negating omega r_y after the
    # product gives the same bits as omega (-r_y) (and spares the column_stack)
    spin = omega * r[:, ::-1]
    spin[:, 0] = -spin[:, 0]
    return v + a + spin


# --- compiled loops: Newton inversion, hinted location, interpolation ----------------------

@njit(cache=True)
def _inverse_bilinear(cell_xy, points, iterations):
    """Reference coordinates (m, 2) and residual distances (m,) of points in Q4 cells
    (``inverse_bilinear`` for (m, 4, 2) cells and (m, 2) points)."""
    m = points.shape[0]
    a = np.empty((m, 4, 2))  # a0 (minus the point), a1, a2, a3 of x = a0 + a1 xi + ...
    for e in range(m):
        for i in range(2):
            x0, x1, x2, x3 = cell_xy[e, 0, i], cell_xy[e, 1, i], cell_xy[e, 2, i], cell_xy[e, 3, i]
            a[e, 0, i] = 0.25 * (x0 + x1 + x2 + x3) - points[e, i]
            a[e, 1, i] = 0.25 * (-x0 + x1 + x2 - x3)
            a[e, 2, i] = 0.25 * (-x0 - x1 + x2 + x3)
            a[e, 3, i] = 0.25 * (x0 - x1 + x2 - x3)
    xi = np.zeros((m, 2))
    for _ in range(iterations):
        change = 0.0
        for e in range(m):
            x, y = xi[e, 0], xi[e, 1]
            xy = x * y
            r0 = a[e, 0, 0] + a[e, 1, 0] * x + a[e, 2, 0] * y + a[e, 3, 0] * xy
            r1 = a[e, 0, 1] + a[e, 1, 1] * x + a[e, 2, 1] * y + a[e, 3, 1] * xy
            g10, g11 = a[e, 1, 0] + a[e, 3, 0] * y, a[e, 1, 1] + a[e, 3, 1] * y
            g20, g21 = a[e, 2, 0] + a[e, 3, 0] * x, a[e, 2, 1] + a[e, 3, 1] * x
            det = g10 * g21 - g11 * g20
            if not np.abs(det) > 0:
                det = 1.0
            nx = min(max(x - (g21 * r0 - g20 * r1) / det, -4.0), 4.0)
            ny = min(max(y - (g10 * r1 - g11 * r0) / det, -4.0), 4.0)
            change = max(change, np.abs(nx - x), np.abs(ny - y))
            xi[e, 0], xi[e, 1] = nx, ny
        if change <= 1e-15:  # converged to round-off of O(1) reference coordinates
            break
    res = np.empty(m)
    for e in range(m):
        x, y = xi[e, 0], xi[e, 1]
        xy = x * y
        r0 = a[e, 0, 0] + a[e, 1, 0] * x + a[e, 2, 0] * y + a[e, 3, 0] * xy
        r1 = a[e, 0, 1] + a[e, 1, 1] * x + a[e, 2, 1] * y + a[e, 3, 1] * xy
        res[e] = np.sqrt(r0 * r0 + r1 * r1)
    return xi, res


@njit(cache=True)
def _nearest_on_cell_boundary(cell_xy, e, p0, p1):
    """Closest point of cell e's straight edges to (p0, p1); (distance, xi0, xi1, local edge
    k, which runs from corner k to corner k + 1: the bilinear map is linear along it)."""
    best_dist, best_t, edge = np.inf, 0.0, 0
    for k in range(4):
        a0, a1 = cell_xy[e, k, 0], cell_xy[e, k, 1]
        d0, d1 = cell_xy[e, (k + 1) % 4, 0] - a0, cell_xy[e, (k + 1) % 4, 1] - a1
        t = (p0 - a0) * d0 + (p1 - a1) * d1
        t = min(max(t / max(d0 * d0 + d1 * d1, 1e-300), 0.0), 1.0)
        r0, r1 = a0 + t * d0 - p0, a1 + t * d1 - p1
        dist = np.sqrt(r0 * r0 + r1 * r1)
        if k == 0 or dist < best_dist:  # argmin: the first minimum
            best_dist, best_t, edge = dist, t, k
    s0, s1 = CORNERS[edge, 0], CORNERS[edge, 1]
    e0, e1 = CORNERS[(edge + 1) % 4, 0], CORNERS[(edge + 1) % 4, 1]
    return best_dist, s0 + best_t * (e0 - s0), s1 + best_t * (e1 - s1), edge


@njit(cache=True)
def _nearest_on_boundaries(cell_xy, cand, pts):
    """Per point i and candidate cell cand[i, c]: the distance to that cell's boundary and the
    reference coordinates of the closest boundary point; ((p, k), (p, k, 2))."""
    p, k = cand.shape
    dist = np.empty((p, k))
    xi = np.empty((p, k, 2))
    for i in range(p):
        for c in range(k):
            dist[i, c], xi[i, c, 0], xi[i, c, 1], _ = _nearest_on_cell_boundary(
                cell_xy, cand[i, c], pts[i, 0], pts[i, 1])
    return dist, xi


@njit(cache=True)
def _locate_in_hints(cell_xy, cell_size, outer_edge, pts, hint, outside_tol, inside_tol,
                    iterations):
    """(cell or -1, xi, clamped) of points found in their hint cell (``Remapper.locate``) or
    just outside one of its mesh-boundary edges (clamped onto it). The hinted points are
    inverted as one batch (the Newton loop stops for the whole batch)."""
    n = pts.shape[0]
    cell = np.full(n, -1, np.int64)
    xi = np.zeros((n, 2))
    clamped = np.zeros(n, np.bool_)
    which = np.flatnonzero(hint >= 0)
    count = which.size
    batch_xy = np.empty((count, 4, 2))
    batch_pts = np.empty((count, 2))
    for c in range(count):
        batch_xy[c] = cell_xy[hint[which[c]]]
        batch_pts[c] = pts[which[c]]
    found, res = _inverse_bilinear(batch_xy, batch_pts, iterations)
    for c in range(count):
        i, h = which[c], hint[which[c]]
        if (max(np.abs(found[c, 0]), np.abs(found[c, 1])) <= 1.0 + inside_tol
                and res[c] <= 1e-9 * cell_size[h]):
            cell[i], xi[i, 0], xi[i, 1] = h, found[c, 0], found[c, 1]
            continue
        p0, p1 = pts[i, 0], pts[i, 1]
        dist, x0, x1, edge = _nearest_on_cell_boundary(cell_xy, h, p0, p1)
        a0, a1 = cell_xy[h, edge, 0], cell_xy[h, edge, 1]
        b0, b1 = cell_xy[h, (edge + 1) % 4, 0], cell_xy[h, (edge + 1) % 4, 1]
        outward = (b0 - a0) * (p1 - a1) - (b1 - a1) * (p0 - a0) < 0.0  # right of a -> b
        if outer_edge[h, edge] and outward and dist <= outside_tol * cell_size[h]:
            cell[i], xi[i, 0], xi[i, 1], clamped[i] = h, x0, x1, True
    return cell, xi, clamped


@njit(cache=True)
def _interpolate(nodes, cells, fields, cell, xi, pts, gradients, quadratic):
    """``Remapper.remap``'s interpolant at located points: Q4 values (4.18) and, if
    ``quadratic``, the gradient-enhanced terms with ``gradients`` (p, 4, k, 2) of the cells'
    nodes. Summed per point over the corners (the order of the NumPy einsums it replaced;
    the two gradient terms over the corners of per-corner sums over the two coordinates)."""
    p, k = pts.shape[0], fields.shape[1]
    out = np.zeros((p, k))
    shape = np.empty(4)
    for q in range(p):
        e = cell[q]
        for a in range(4):
            shape[a] = 0.25 * (1.0 + xi[q, 0] * CORNERS[a, 0]) * (
                1.0 + xi[q, 1] * CORNERS[a, 1])
        for j in range(k):
            total = 0.0
            for a in range(4):
                total += shape[a] * fields[cells[e, a], j]
            out[q, j] = total
        if not quadratic:
            continue
        off0, off1 = 0.0, 0.0  # p - x(xi): a clamped point lies off its cell
        for a in range(4):
            off0 += shape[a] * nodes[cells[e, a], 0]
            off1 += shape[a] * nodes[cells[e, a], 1]
        off0, off1 = pts[q, 0] - off0, pts[q, 1] - off1
        for j in range(k):
            near = 0.0
            for a in range(4):
                n = cells[e, a]
                g0, g1 = gradients[q, a, j, 0], gradients[q, a, j, 1]
                near += shape[a] * g0 * (pts[q, 0] - nodes[n, 0]) + shape[a] * g1 * (
                    pts[q, 1] - nodes[n, 1])
            out[q, j] = out[q, j] + 0.5 * near
        for j in range(k):
            far = 0.0
            for a in range(4):
                g0, g1 = gradients[q, a, j, 0], gradients[q, a, j, 1]
                far += shape[a] * g0 * off0 + shape[a] * g1 * off1
            out[q, j] = out[q, j] + 0.5 * far
    return out


@njit(cache=True)
def _interpolate_at_nodes(nodes, cells, fields, cell, xi, pts, gradients, quadratic, cell_size,
                         same_node):
    """``interpolate``, except that a point within ``same_node`` times its cell's size of a
    corner of its cell takes that node's values exactly (``Remapper.remap``: unmoved nodes keep
    their fields). In a conforming mesh a point on an old node is located in a cell with that
    node as a corner (inside, or clamped onto its boundary), so the corners are the only
    candidates: this replaces a k-d tree query over all nodes, with the same distance
    (sqrt(d0^2 + d1^2)) and the same test."""
    out = _interpolate(nodes, cells, fields, cell, xi, pts, gradients, quadratic)
    for q in range(pts.shape[0]):
        e = cell[q]
        best, near = np.inf, -1
        for a in range(4):
            n = cells[e, a]
            d0, d1 = pts[q, 0] - nodes[n, 0], pts[q, 1] - nodes[n, 1]
            dist = np.sqrt(d0 * d0 + d1 * d1)
            if dist < best:
                best, near = dist, n
        if best <= same_node * cell_size[e]:
            for j in range(fields.shape[1]):
                out[q, j] = fields[near, j]
    return out
