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
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = [
    "SurfaceCurve",
    "point_at",
    "project_to_surface",
    "relocate_surface_nodes",
    "respace_surface",
]

# 8-point Gauss-Legendre on [0, 1]: |x'(u)| is the root of a quadratic in u, smooth on a segment
_GAUSS_X, _GAUSS_W = np.polynomial.legendre.leggauss(8)
_GAUSS_U = 0.5 * (_GAUSS_X + 1.0)
_GAUSS_W = 0.5 * _GAUSS_W


def _break_mask(n: int, corner_mask: ArrayLike | None) -> NDArray[np.bool_]:
    brk = np.zeros(n, bool) if corner_mask is None else np.asarray(corner_mask, bool).copy()
    if brk.shape != (n,):
        raise ValueError(f"corner mask must have shape ({n},), got {brk.shape}")
    brk[[0, -1]] = True
    return brk


def _bulges(points: NDArray, breaks: NDArray) -> NDArray:
    """q_i of every segment: h_i^2 times the mean second divided difference at its smooth ends."""
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
        points = np.asarray(chain_xy, dtype=float)
        if points.ndim != 2 or points.shape[1] != 2 or len(points) < 2:
            raise ValueError(f"a surface chain needs shape (n >= 2, 2), got {points.shape}")
        breaks = _break_mask(len(points), corner_mask)
        bulge = _bulges(points, breaks)
        seg = np.arange(len(points) - 1)
        partial = cls(points, breaks, bulge, np.zeros(len(points)))
        lengths = partial._arc(seg, np.ones(len(seg)))
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
        """Segment index and local parameter u of arc-length positions s (clamped to the chain)."""
        s = np.clip(s, 0.0, self.length)
        seg = np.clip(np.searchsorted(self.node_s, s, side="right") - 1, 0, len(self.bulge) - 1)
        ds = s - self.node_s[seg]
        seg_len = np.diff(self.node_s)[seg]
        u = np.divide(ds, seg_len, out=np.zeros_like(ds), where=seg_len > 0)
        for _ in range(6):  # Newton on arc(u) = ds; |x'| varies slowly so this converges fast
            _, dx = self._eval(seg, u)
            speed = np.linalg.norm(dx, axis=-1)
            step = np.divide(self._arc(seg, u) - ds, speed, out=np.zeros_like(u), where=speed > 0)
            u = np.clip(u - step, 0.0, 1.0)
        return seg, u

    def point_at(self, s: ArrayLike) -> NDArray[np.float64]:
        """Positions (p, 2) at arc-length parameters s (values outside [0, L] are clamped)."""
        s_arr = np.atleast_1d(np.asarray(s, dtype=float))
        seg, u = self._segment_of(s_arr)
        return self._eval(seg, u)[0]

    def tangent_at(self, s: ArrayLike) -> NDArray[np.float64]:
        """Unit tangents (p, 2) in the chain direction at arc-length parameters s."""
        seg, u = self._segment_of(np.atleast_1d(np.asarray(s, dtype=float)))
        dx = self._eval(seg, u)[1]
        return dx / np.linalg.norm(dx, axis=-1, keepdims=True)

    def project(self, points: ArrayLike) -> NDArray[np.float64]:
        """Arc-length parameter of the closest point on the curve to each point (p,)."""
        pts = np.atleast_2d(np.asarray(points, dtype=float))
        n_seg = len(self.bulge)
        seg = np.broadcast_to(np.arange(n_seg), (len(pts), n_seg))
        # coarse sampling on every segment, then Newton on d|x(u) - p|^2/du = 0 per segment
        samples = np.linspace(0.0, 1.0, 9)
        xs, _ = self._eval(seg[..., None], np.broadcast_to(samples, (*seg.shape, 9)))
        dist = np.linalg.norm(xs - pts[:, None, None, :], axis=-1)
        u = samples[np.argmin(dist, axis=-1)]
        for _ in range(5):
            x, dx = self._eval(seg, u)
            r = x - pts[:, None, :]
            grad = np.einsum("psi,psi->ps", r, dx)
            hess = np.einsum("psi,psi->ps", dx, dx) + 2.0 * np.einsum("psi,si->ps", r, self.bulge)
            ok = hess > 0  # away from a convex well keep the sampled value
            u = np.clip(np.where(ok, u - grad / np.where(ok, hess, 1.0), u), 0.0, 1.0)
        d = np.linalg.norm(self._eval(seg, u)[0] - pts[:, None, :], axis=-1)
        best = np.argmin(d, axis=1)
        rows = np.arange(len(pts))
        return self.node_s[best] + self._arc(best, u[rows, best])


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
