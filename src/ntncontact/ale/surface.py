"""Moving surface nodes along their own surface (report 4.1.1, Figs 4.2-4.3).

An ordered chain of surface nodes is represented by a continuous piecewise-quadratic curve that
interpolates the nodes. Segment i (nodes i -> i+1) is

    x(u) = x_i + u (x_{i+1} - x_i) + u (u - 1) q_i,   u in [0, 1],

where the "bulge" q_i is the average of the second terms of the two parabolas through
(i-1, i, i+1) and (i, i+1, i+2), built with chord-length parameters (Newton form: the second
divided difference times h_i^2). This is the quadratic path of Fig. 4.3 (through a node and its two
chain neighbours) made independent of which node moves, so a node may travel over several
segments in one step. At a corner (flagged) or at a chain end the parabola centred there is not
used, so the curve does not bend around a corner; a segment between two breaks is straight.
The error of the curve against a smooth surface is O(h^3).

The chain is open: its end nodes are breaks and are never moved by ``respace_surface``. For a
closed boundary with corners, start and end the chain at a corner.

``respace_surface`` places every free node between the anchors in given proportions, so nodes move
whenever the current spacing differs from those proportions, slide or no slide. ``local_slides``
is the incremental alternative used by the ALE update: it spreads each anchor's slide over as few
neighbouring segments as keep the spacing within a tolerance of the original proportions and
moves nothing else (see its docstring).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ntncontact.ale import kernels_numba as _kernels

__all__ = [
    "SurfaceCurve",
    "local_slides",
    "point_at",
    "project_to_surface",
    "relocate_surface_nodes",
    "respace_surface",
]

# 8-point Gauss-Legendre on [0, 1]: |x'(u)| is the root of a quadratic in u, smooth on a segment
_GAUSS_X, _GAUSS_W = np.polynomial.legendre.leggauss(8)
_GAUSS_U = 0.5 * (_GAUSS_X + 1.0)
_GAUSS_W = 0.5 * _GAUSS_W
_CONVERGED = 1e-14  # Newton updates of a local parameter u in [0, 1] below this: round-off


def _break_mask(n: int, corner_mask: ArrayLike | None) -> NDArray[np.bool_]:
    brk = np.zeros(n, bool) if corner_mask is None else np.asarray(corner_mask, bool).copy()
    if brk.shape != (n,):
        raise ValueError(f"corner mask must have shape ({n},), got {brk.shape}")
    brk[[0, -1]] = True
    return brk


def _bulges(points: NDArray, breaks: NDArray) -> NDArray:
    """q_i of every segment: h_i^2 times the mean second divided difference at its smooth ends
    (the NumPy form of ``kernels_numba.bulges``, which ``SurfaceCurve.from_chain`` uses)."""
    chord = np.diff(points, axis=0)
    h = np.linalg.norm(chord, axis=1)
    slope = chord / np.where(h > 0, h, 1.0)[:, None]
    d2 = np.zeros_like(points)
    d2[1:-1] = (slope[1:] - slope[:-1]) / np.maximum(h[1:] + h[:-1], np.finfo(float).tiny)[:, None]
    smooth = ~breaks
    left, right = smooth[:-1], smooth[1:]
    total = d2[:-1] * left[:, None] + d2[1:] * right[:, None]
    count = np.maximum(left.astype(int) + right, 1)
    return (h**2 / count)[:, None] * total


@dataclass(frozen=True)
class SurfaceCurve:
    """Arc-length parametrized piecewise-quadratic interpolant of an ordered surface chain."""

    points: NDArray[np.float64]
    breaks: NDArray[np.bool_]
    bulge: NDArray[np.float64]
    node_s: NDArray[np.float64]

    @classmethod
    def from_chain(cls, chain_xy: ArrayLike, corner_mask: ArrayLike | None = None) -> SurfaceCurve:
        """Build the curve; ``corner_mask`` flags body corners (segment breaks)."""
        points = np.ascontiguousarray(chain_xy, dtype=float)
        if points.ndim != 2 or points.shape[1] != 2 or len(points) < 2:
            raise ValueError(f"a surface chain needs shape (n >= 2, 2), got {points.shape}")
        breaks = _break_mask(len(points), corner_mask)
        # built once per t_n state of an ALE body: the elementwise parts compiled (the same
        # operations as ``_bulges`` and ``_arc(seg, 1)``), the quadrature's sum left to NumPy
        # (a BLAS product, whose summation order a loop cannot reproduce)
        bulge = _kernels.bulges(points, breaks)
        lengths = _kernels.segment_speeds(points, bulge, _GAUSS_U) @ _GAUSS_W
        return cls(points, breaks, bulge, np.concatenate([[0.0], np.cumsum(lengths)]))

    @property
    def length(self) -> float:
        return float(self.node_s[-1])

    def _eval(self, seg: NDArray, u: NDArray) -> tuple[NDArray, NDArray]:
        """Position and derivative dx/du on segments ``seg`` at local parameters ``u``."""
        x0, d, q = self.points[seg], self.points[seg + 1] - self.points[seg], self.bulge[seg]
        uu = u[..., None]
        return x0 + uu * d + uu * (uu - 1.0) * q, d + (2.0 * uu - 1.0) * q

    def _arc(self, seg: NDArray, u: NDArray) -> NDArray:
        """Arc length from the start of segment ``seg`` to local parameter ``u`` (Gauss)."""
        uq = u[..., None] * _GAUSS_U
        _, dx = self._eval(np.broadcast_to(seg[..., None], uq.shape), uq)
        return u * (np.linalg.norm(dx, axis=-1) @ _GAUSS_W)

    def _segment_of(self, s: NDArray) -> tuple[NDArray, NDArray]:
        """Segment index and local parameter u of arc-length positions s (clamped to the chain):
        Newton on arc(u) = ds from the chord estimate (compiled: ``kernels_numba``)."""
        s_flat = np.ascontiguousarray(s, dtype=float).reshape(-1)
        seg, u = _kernels.segment_of(self.points, self.bulge, self.node_s, s_flat, _GAUSS_U,
                                     _GAUSS_W)
        return seg.reshape(np.shape(s)), u.reshape(np.shape(s))

    def point_at(self, s: ArrayLike) -> NDArray[np.float64]:
        """Positions (p, 2) at arc-length parameters s (values outside [0, L] are clamped)."""
        s_arr = np.ascontiguousarray(np.atleast_1d(np.asarray(s, dtype=float)).reshape(-1))
        return _kernels.point_at(self.points, self.bulge, self.node_s, s_arr, _GAUSS_U,
                                 _GAUSS_W)

    def tangent_at(self, s: ArrayLike) -> NDArray[np.float64]:
        """Unit tangents (p, 2) in the chain direction at arc-length parameters s."""
        seg, u = self._segment_of(np.atleast_1d(np.asarray(s, dtype=float)))
        dx = self._eval(seg, u)[1]
        return dx / np.linalg.norm(dx, axis=-1, keepdims=True)

    def node_tangents(self, nodes: ArrayLike) -> NDArray[np.float64]:
        """Unit tangents (p, 2) of the continuous tangent field at chain nodes: the mean of the
        two segments' one-sided tangents at a smooth node, the adjacent segment's at a break
        (see ``normal_foot``)."""
        i = np.asarray(nodes, dtype=np.int64).reshape(-1)
        start, end = self._end_tangents()
        last = i == len(self.points) - 1
        return np.where(last[:, None], end[np.maximum(i - 1, 0)],
                        start[np.minimum(i, len(start) - 1)])

    def project(self, points: ArrayLike) -> NDArray[np.float64]:
        """Arc-length parameter of the closest point on the curve to each point (p,)."""
        return self.closest(points)[0]

    def closest(self, points: ArrayLike) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Arc-length parameters (p,) and positions (p, 2) of the closest curve points."""
        pts = np.atleast_2d(np.asarray(points, dtype=float))
        n_seg = len(self.bulge)
        # coarse sampling on every segment, then Newton on d|x(u) - p|^2/du = 0 on the few
        # segments with the closest samples
        samples = np.linspace(0.0, 1.0, 9)
        all_seg = np.broadcast_to(np.arange(n_seg), (len(pts), n_seg))
        xs, _ = self._eval(all_seg[..., None], np.broadcast_to(samples, (*all_seg.shape, 9)))
        dist = np.linalg.norm(xs - pts[:, None, None, :], axis=-1)
        nearest = dist.min(axis=-1)
        keep = min(3, n_seg)
        seg = np.argsort(nearest, axis=1, kind="stable")[:, :keep]
        u = samples[np.take_along_axis(np.argmin(dist, axis=-1), seg, axis=1)]
        for _ in range(5):
            x, dx = self._eval(seg, u)
            r = x - pts[:, None, :]
            grad = np.einsum("psi,psi->ps", r, dx)
            hess = np.einsum("psi,psi->ps", dx, dx) + 2.0 * np.einsum(
                "psi,psi->ps", r, self.bulge[seg])
            ok = hess > 0  # away from a convex well keep the sampled value
            new = np.clip(np.where(ok, u - grad / np.where(ok, hess, 1.0), u), 0.0, 1.0)
            done = not np.any(np.abs(new - u) > _CONVERGED)
            u = new
            if done:
                break
        foot = self._eval(seg, u)[0]
        best = np.argmin(np.linalg.norm(foot - pts[:, None, :], axis=-1), axis=1)
        rows = np.arange(len(pts))
        best_seg, best_u = seg[rows, best], u[rows, best]
        return self.node_s[best_seg] + self._arc(best_seg, best_u), foot[rows, best]

    def _end_tangents(self) -> tuple[NDArray, NDArray]:
        """``_tangents`` (kept per curve: they depend on the curve only)."""
        return self._tangents

    @cached_property
    def _tangents(self) -> tuple[NDArray, NDArray]:
        """Unit tangents at the start and end of every segment from the continuous nodal
        tangent field: at a smooth node the normalized mean of the two segments' one-sided
        tangents (so both segments share it), at a break the segment's own (compiled:
        ``kernels_numba.end_tangents``, the same operations)."""
        start, end = _kernels.end_tangents(self.points, self.bulge, self.breaks)
        start.setflags(write=False)
        end.setflags(write=False)
        return start, end

    def normal_foot(self, points: ArrayLike) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Arc-length parameters (p,) and positions (p, 2) of the curve points whose normal
        passes through each point, the normal taken from the continuous tangent field that
        interpolates linearly (in u) between the nodal tangents of ``_end_tangents``.

        Unlike the closest point this is well defined and smooth at the nodes: the averaged
        parabolas leave O(h^2) tangent kinks at the nodes, so a point at distance g straight
        off a node of a curved chain can have two closest points about g times the kink angle
        either side of it, and the choice between them flips with round-off. On a straight
        chain both coincide with the orthogonal projection. A point beyond a break (no normal
        through it on the adjacent segment) gets the break.
        """
        pts = np.ascontiguousarray(np.atleast_2d(np.asarray(points, dtype=float)))
        t_start, t_end = self._tangents
        # per point: the 3 segments with the closest samples, Newton on the bracketed
        # f(u) = (p - x(u)) . t(u) (bisection when it leaves the bracket), nearest root wins
        return _kernels.normal_foot(self.points, self.bulge, self.node_s, t_start, t_end, pts,
                                    _GAUSS_U, _GAUSS_W)


def point_at(
    chain_xy: ArrayLike, s: ArrayLike, corner_mask: ArrayLike | None = None
) -> NDArray[np.float64]:
    """Positions on the chain's piecewise-quadratic surface at arc-length parameters s."""
    return SurfaceCurve.from_chain(chain_xy, corner_mask).point_at(s)


def project_to_surface(
    chain_xy: ArrayLike, points: ArrayLike, corner_mask: ArrayLike | None = None
) -> NDArray[np.float64]:
    """Arc-length parameter of the closest point on the chain's surface for each point."""
    return SurfaceCurve.from_chain(chain_xy, corner_mask).project(points)


def respace_surface(
    chain_xy: ArrayLike,
    anchor_mask: ArrayLike,
    anchor_targets_s: ArrayLike,
    corner_mask: ArrayLike | None = None,
    spacing: ArrayLike | None = None,
) -> NDArray[np.float64]:
    """Reposition the free chain nodes between anchors along the old surface (report 4.1.1).

    Anchors are the nodes of ``anchor_mask`` (moved to arc-length targets ``anchor_targets_s``,
    given either per chain node (n,) or per anchor in chain order), plus the corners and chain
    ends, which stay where they are. Between consecutive anchors the free nodes are distributed
    in the proportions of ``spacing`` (n - 1 segment lengths; default: the current arc lengths,
    i.e. the old relative spacing; pass ones for equal spacing or the initial mesh's lengths to
    keep a grading). The map from old to new parameter is monotone, so order is preserved even
    when an anchor jumps over several old nodes (Fig. 4.2); every node stays on the old curve.
    """
    curve = SurfaceCurve.from_chain(chain_xy, corner_mask)
    n = len(curve.points)
    anchors = np.asarray(anchor_mask, bool)
    targets = np.asarray(anchor_targets_s, dtype=float).reshape(-1)
    s_new_anchor = curve.node_s.copy()
    s_new_anchor[anchors] = targets[anchors] if targets.shape == (n,) else targets
    fixed = anchors | curve.breaks
    idx = np.flatnonzero(fixed)
    if np.any(np.diff(s_new_anchor[idx]) <= 0.0):
        bad = idx[1:][np.diff(s_new_anchor[idx]) <= 0.0][0]
        raise ValueError(
            f"surface anchors out of order at chain node {bad}: an anchor target would pass "
            "another anchor, a corner or a chain end"
        )
    ref = curve.node_s if spacing is None else np.concatenate([[0.0], np.cumsum(spacing)])
    s_new = np.interp(ref, ref[idx], s_new_anchor[idx])
    return curve.point_at(s_new)


def relocate_surface_nodes(
    chain_xy: ArrayLike,
    active: ArrayLike,
    targets_xy: ArrayLike,
    corner_mask: ArrayLike | None = None,
    spacing: ArrayLike | None = None,
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Move chain nodes ``active`` (indices) to the surface points closest to ``targets_xy``.

    The other non-corner nodes are respaced between the anchors (``respace_surface``). Returns
    the new chain positions and the arc-length parameters of the active nodes' new positions.
    """
    curve = SurfaceCurve.from_chain(chain_xy, corner_mask)
    active_idx = np.asarray(active, dtype=np.int64).reshape(-1)
    s_active = curve.project(np.asarray(targets_xy, dtype=float).reshape(-1, 2))
    mask = np.zeros(len(curve.points), bool)
    mask[active_idx] = True
    targets = np.zeros(len(curve.points))
    targets[active_idx] = s_active
    new_xy = respace_surface(curve.points, mask, targets, curve.breaks, spacing)
    return new_xy, s_active


def local_slides(
    node_s: ArrayLike,
    reference_spacing: ArrayLike,
    anchors: ArrayLike,
    anchor_slides: ArrayLike,
    tolerance: float = 0.5,
) -> tuple[NDArray[np.float64], int]:
    """Arc-length slides of all chain nodes given the slides of the anchors; (slides, resets).

    ``node_s`` are the nodes' current arc-length positions, ``reference_spacing`` the n - 1
    segment lengths of the original mesh, ``anchors`` increasing chain indices (including both
    chain ends and every corner, which should slide 0) and ``anchor_slides`` their slides. A
    segment's target length is its reference length scaled by the current stretch of its run
    (the stretch between two consecutive anchors); its length must stay in the band
    [1 - t, 1 / (1 - t)] times that (t = ``tolerance``), and its slack is how far it may still
    shrink (or grow) inside the band. Per run between anchors a < b:

    * both slides zero: nothing moves (slides exactly 0);
    * otherwise each moving anchor's slide is absorbed by the fewest segments next to it (a
      "buffer") whose slack suffices, each shrinking or growing in proportion to its slack (a
      segment already at the edge of the band is carried along rigidly); nodes beyond the
      buffers do not move. Repeated slides the same way thus compress a neighbourhood that
      widens as it saturates, and never push a segment out of the band;
    * if the two buffers would overlap, the run's length change is shared by all its segments
      the same way (equal slides: a rigid shift of the run);
    * if the run's slack does not suffice (only when it was already outside the band, or the
      slide is larger than the band allows), the run is respaced in the reference proportions;
      ``resets`` counts these runs.
    """
    s = np.asarray(node_s, dtype=float)
    ref = np.asarray(reference_spacing, dtype=float)
    idx = np.asarray(anchors, dtype=np.int64).reshape(-1)
    slide = np.asarray(anchor_slides, dtype=float).reshape(-1)
    if not 0.0 < tolerance < 1.0:
        raise ValueError(f"tolerance must lie in (0, 1), got {tolerance}")
    if idx.shape != slide.shape or ref.shape != (s.size - 1,) or np.any(np.diff(idx) <= 0):
        raise ValueError("anchors must be increasing chain indices with one slide each and "
                         "reference_spacing must have one length per segment")
    lo, hi = 1.0 - tolerance, 1.0 / (1.0 - tolerance)
    # compiled loop over the runs (``kernels_numba.local_slides``)
    out, resets = _kernels.local_slides(np.ascontiguousarray(s), np.ascontiguousarray(ref),
                                        np.ascontiguousarray(idx), np.ascontiguousarray(slide),
                                        lo, hi)
    return out, int(resets)
