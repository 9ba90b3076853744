"""The ALE mesh update of one body for one augmentation (report 4.1-4.3, 5.4 step 2).

Formulation: operator split per augmentation. The ALE body's mesh is moved IN THE t_n
CONFIGURATION and the t_n fields are remapped onto the moved nodes; the following Lagrangian
mid-point step then runs on the moved mesh with no convective term.

1. Surface relocation (4.1.1, Figs 4.2-4.4). An active contact node at x_n whose particle is
   predicted to end the step at ``x_pred`` (first augmentation: x_n + dt v_n; later ones: the last
   iterate) must hold, at t_{n+1}, the particle that lands on its partner's predicted position
   ``x_target``. With the step increment Delta = x_pred - x_n taken as locally uniform, that
   particle sits now at x_target - Delta; the node slides along its own t_n surface (the
   piecewise-quadratic curve of ``ale.surface``) to the closest point. On a straight surface this
   is exactly the arc-length slide s = (x_target - x_pred) . e (e the unit surface tangent); on a
   curved one it is its exact generalization (the tangent formula is its linearization). The
   normal part of x_target - x_pred is the gap, which contact, not the mesh, closes.
2. Corners and chain ends stay fixed, and a node never slides past one: its slide is clamped so
   that the free nodes between it and the break keep at least ``min_spacing_ratio`` times the
   smallest surface spacing of that stretch; clamped nodes are reported.
3. The other surface nodes of the chain are respaced between the anchors (breaks, moved active
   nodes) in the proportions of the ORIGINAL mesh's surface spacing, so the grading is kept.
4. Interior nodes within ``smoothing_layers`` element layers of the moved surface nodes are
   smoothed (4.1.2) with the whole boundary fixed; the rest keeps its grading. The smoother
   refuses inverting moves; a final inverted element (current or reference image) raises
   MeshError naming the body and the element, and the time loop cuts the step back.
5. Remap (4.3): the fields at t_n are interpolated from the old mesh (nodes at x_n) at the new
   node positions x~_n: X_new = X(x~_n) (the material point now at the node), d = x~_n - X_new,
   v and a likewise ("linear" Q4 of (4.18) or the "quadratic" patch fit in the spirit of 4.19).
   Nodes that did not move keep their values exactly. With ``conserve_momentum`` a rigid velocity
   is added to the remapped nodes so that the body's linear and angular momentum, with lumped
   masses from the new X, equal the old ones (METHOD_NOTES: plain interpolation drifts).

Because the remap carries the convection, the step needs no convective term (no double
counting: the report's term with c = v - v_hat (4.5-4.6, 5.9) is what the remap replaces). In
this split the node then moves with the material during the Lagrangian step, so its mesh
velocity over the step is v + (x~_n - x_n)/dt and the report's c = v - v_hat equals
-(x~_n - x_n)/dt: ``AleUpdate.mesh_velocity`` (and ``convective``) are diagnostics only.

Calling it from the time loop (augmentation k): pass the ORIGINAL t_n state of the body every
time (no repeated remapping, hence no accumulated diffusion), ``x_pred`` = the active nodes'
end-of-step positions from the last iterate (x_n + dt v_n for k = 1) and ``x_start`` = the
positions those particles had at t_n, i.e. the active nodes' positions on the mesh that produced
that iterate (``AleUpdate.x_mesh`` of augmentation k - 1; default: the passed x_n). Then
``mesh_velocity`` is already the whole step's. Passing the previously moved state instead also
works (x_start defaults correctly), but remaps twice and the mesh velocities must be summed.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass
from functools import cached_property

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ntncontact.ale.remap import (
    RemapMethod,
    Remapper,
    conservative_velocity_correction,
    momenta,
)
from ntncontact.ale.smoothing import (
    Smoother,
    SmoothingMethod,
    SmoothingResult,
    boundary_node_mask,
    nodes_within_layers,
)
from ntncontact.ale.surface import SurfaceCurve, respace_surface
from ntncontact.mesh.boundary import chain_edge_lengths, surface_chain
from ntncontact.mesh.quadmesh import MeshError, QuadMesh
from ntncontact.mesh.quality import check_elements

__all__ = ["AleBody", "AleUpdate", "lumped_masses", "move_ale_body"]

_SMOOTHING = ("laplacian", "angle", "weighted_angle")
_REMAP = ("linear", "quadratic")
# a surface move below this fraction of the smallest surface spacing is round-off of the curve
# evaluation (point_at inverts arc length by Newton): such nodes keep their old position exactly
_SNAP = 1e-10
# 2 x 2 Gauss points (weights 1) and the Q4 corner signs
_XI = np.array([[-1.0, -1.0], [1.0, -1.0], [1.0, 1.0], [-1.0, 1.0]])
_GP = _XI / np.sqrt(3.0)


def _frozen(values: ArrayLike, dtype: type) -> NDArray:
    out = np.array(values, dtype=dtype, copy=True)
    out.setflags(write=False)
    return out


@dataclass(frozen=True, eq=False)
class AleBody:
    """Static data of one ALE body: topology, its contact surface chain and the options.

    ``cells`` and ``surface`` use the body's LOCAL node numbers; ``surface`` is the ordered
    contact chain (body on the left), ``corner`` flags its body corners (fixed, curve breaks),
    ``reference_spacing`` the chain's segment lengths in the original mesh (n - 1 segments, n
    when closed; the respacing keeps their proportions). ``density`` (scalar or per cell) only
    weighs the lumped masses of the momentum correction.
    """

    cells: NDArray[np.int64]
    surface: NDArray[np.int64]
    closed: bool
    corner: NDArray[np.bool_]
    n_nodes: int
    reference_spacing: NDArray[np.float64]
    smoothing: SmoothingMethod = "laplacian"
    smoothing_layers: int = 3
    sweeps: int = 10
    remap: RemapMethod = "linear"
    conserve_momentum: bool = True
    min_spacing_ratio: float = 0.25
    density: float | NDArray[np.float64] = 1.0
    name: str = "body"

    def __post_init__(self) -> None:
        cells = _frozen(self.cells, np.int64).reshape(-1, 4)
        surface = _frozen(self.surface, np.int64).reshape(-1)
        corner = _frozen(self.corner, np.bool_).reshape(-1)
        spacing = _frozen(self.reference_spacing, np.float64).reshape(-1)
        n_seg = surface.size if self.closed else surface.size - 1
        if surface.size < (3 if self.closed else 2) or np.unique(surface).size != surface.size:
            raise ValueError(f"{self.name}: the surface chain needs distinct nodes (>= 2)")
        if corner.shape != surface.shape or spacing.shape != (n_seg,):
            raise ValueError(f"{self.name}: corner needs one entry per surface node and "
                             f"reference_spacing {n_seg} positive segment lengths")
        if not np.all(spacing > 0):
            raise ValueError(f"{self.name}: reference_spacing must be positive")
        if self.smoothing not in _SMOOTHING or self.remap not in _REMAP:
            raise ValueError(f"{self.name}: smoothing must be one of {_SMOOTHING} and remap one "
                             f"of {_REMAP}, got {self.smoothing!r}, {self.remap!r}")
        if not 0.0 < self.min_spacing_ratio < 1.0:
            raise ValueError(f"{self.name}: min_spacing_ratio must lie in (0, 1)")
        for key, value in (("cells", cells), ("surface", surface), ("corner", corner),
                           ("reference_spacing", spacing)):
            object.__setattr__(self, key, value)

    @classmethod
    def from_mesh(
        cls,
        mesh: QuadMesh,
        surface_name: str,
        corner_nodes: ArrayLike = (),
        corner_angle_deg: float | None = 30.0,
        **options: object,
    ) -> AleBody:
        """From a body's mesh (local numbering) and the name of its contact edge set.

        Corners are the local ``corner_nodes`` on the chain plus, unless ``corner_angle_deg``
        is None, the chain nodes where the original surface turns by more than that angle.
        ``options`` are the remaining fields (smoothing, remap, density, ...).
        """
        chain = surface_chain(mesh, surface_name)
        xy = mesh.nodes[chain.nodes]
        corner = np.isin(chain.nodes, np.asarray(corner_nodes, dtype=np.int64))
        if corner_angle_deg is not None:
            corner |= _kinks(xy, chain.closed, corner_angle_deg)
        options.setdefault("name", mesh.name)
        return cls(mesh.cells, chain.nodes, chain.closed, corner, mesh.n_nodes,
                   chain_edge_lengths(xy, chain.closed), **options)  # type: ignore[arg-type]

    @cached_property
    def boundary(self) -> NDArray[np.bool_]:
        return boundary_node_mask(self.cells, self.n_nodes)

    @cached_property
    def _smoother(self) -> Smoother:
        return Smoother(self.cells, self.n_nodes, None, self.smoothing, self.name)

    def smoother(self, free: NDArray[np.bool_]) -> Smoother:
        """The body's smoother (neighbour structures built once) freeing only ``free`` nodes."""
        out = copy.copy(self._smoother)
        out.free = free & ~self.boundary
        return out

    @cached_property
    def cell_density(self) -> NDArray[np.float64]:
        return np.broadcast_to(np.asarray(self.density, dtype=float), (len(self.cells),))


def _kinks(xy: NDArray, closed: bool, angle_deg: float) -> NDArray[np.bool_]:
    """Chain nodes where the polygon turns by more than ``angle_deg`` (open ends excluded)."""
    before = xy - np.roll(xy, 1, axis=0)
    after = np.roll(xy, -1, axis=0) - xy
    cross = before[:, 0] * after[:, 1] - before[:, 1] * after[:, 0]
    turn = np.abs(np.arctan2(cross, np.einsum("ij,ij->i", before, after)))
    kink = turn > np.deg2rad(angle_deg)
    if not closed:
        kink[[0, -1]] = False
    return kink


@dataclass(frozen=True)
class AleUpdate:
    """The body's t_n fields on the moved mesh (local rows) and diagnostics of the move."""

    X: NDArray[np.float64]
    d: NDArray[np.float64]
    v: NDArray[np.float64]
    a: NDArray[np.float64]
    x_mesh: NDArray[np.float64]  # node positions x~_n after the move (= X + d)
    mesh_velocity: NDArray[np.float64]  # (x~_n - x_n) / dt
    mismatch: float  # max distance along the surface: active node's predicted end vs target
    clamped: NDArray[np.int64]  # local active nodes whose slide was clamped at a break
    moved: NDArray[np.bool_]  # nodes whose fields were remapped
    momentum_change: tuple[NDArray[np.float64], float]  # of the plain remap (before correction)
    smoothing: SmoothingResult | None = None

    @property
    def convective(self) -> NDArray[np.float64]:
        """The report's c = v - v_hat (4.5) of this split: -(x~_n - x_n)/dt (diagnostic)."""
        return -self.mesh_velocity


def lumped_masses(X: ArrayLike, cells: ArrayLike, density: ArrayLike = 1.0) -> NDArray:
    """Row-sum lumped nodal masses m_a = sum_e int_{Omega_e^X} rho N_a dA (5.8, 5.13).

    2 x 2 Gauss is exact: N_a det J is at most quadratic in each reference coordinate.
    """
    X = np.asarray(X, dtype=float)
    cell_arr = np.asarray(cells, dtype=np.int64).reshape(-1, 4)
    xe = X[cell_arr]
    dn = 0.25 * np.stack([_XI[:, 0] * (1.0 + _XI[:, 1] * _GP[:, 1:2]),
                          _XI[:, 1] * (1.0 + _XI[:, 0] * _GP[:, 0:1])], axis=-1)  # (g, a, k)
    jac = np.einsum("gak,eai->egik", dn, xe)
    det = jac[..., 0, 0] * jac[..., 1, 1] - jac[..., 0, 1] * jac[..., 1, 0]
    shape = 0.25 * (1.0 + _GP[:, None, 0] * _XI[:, 0]) * (1.0 + _GP[:, None, 1] * _XI[:, 1])
    rho = np.broadcast_to(np.asarray(density, dtype=float), (len(cell_arr),))
    me = np.einsum("eg,ga->ea", det * rho[:, None], shape)
    return np.bincount(cell_arr.ravel(), me.ravel(), len(X))


@dataclass(frozen=True)
class _Chain:
    """The surface chain as an open curve: closed chains are cut at a corner or far node."""

    nodes: NDArray[np.int64]  # local nodes in walking order (closed: first repeated at the end)
    breaks: NDArray[np.bool_]
    spacing: NDArray[np.float64]  # reference segment lengths
    position: NDArray[np.int64]  # chain index of each active node


def _open_chain(body: AleBody, active: NDArray) -> _Chain:
    """Open the chain; a closed chain starts at its first corner, else at the node farthest
    (in chain steps) from every active node, which then stays fixed for this update."""
    n = body.surface.size
    where = np.full(body.n_nodes, -1)
    where[body.surface] = np.arange(n)
    pos = where[active]
    if np.any(pos < 0):
        raise ValueError(f"{body.name}: active nodes {active[pos < 0].tolist()} are not on the "
                         "ALE contact surface")
    if not body.closed:
        breaks = body.corner.copy()
        breaks[[0, -1]] = True
        return _Chain(body.surface, breaks, body.reference_spacing, pos)
    if body.corner.any():
        start = int(np.argmax(body.corner))
    else:
        steps = np.abs(np.arange(n)[:, None] - pos[None, :])
        start = int(np.argmax(np.minimum(steps, n - steps).min(axis=1)))
    order = np.roll(np.arange(n), -start)
    breaks = np.append(body.corner[order], True)
    breaks[0] = True
    nodes = np.append(body.surface[order], body.surface[start])
    return _Chain(nodes, breaks, np.roll(body.reference_spacing, -start), (pos - start) % n)


def _clamp_slides(
    node_s: NDArray, breaks: NDArray, pos: NDArray, wanted: NDArray, ratio: float
) -> tuple[NDArray, NDArray]:
    """Arc-length targets kept between the neighbouring breaks; (targets, clamped mask).

    Between a node and a break b the free nodes keep at least ``ratio`` times the smallest
    segment of the stretch between the two breaks around the node; breaks do not move.
    """
    brk = np.flatnonzero(breaks)
    run_min = np.minimum.reduceat(np.diff(node_s), brk[:-1])
    j = np.searchsorted(brk, pos)
    on_break = brk[np.minimum(j, brk.size - 1)] == pos
    run = np.clip(j - 1, 0, brk.size - 2)
    b0, b1 = brk[run], brk[run + 1]
    h = ratio * run_min[run]
    lo = np.minimum(node_s[b0] + (pos - b0) * h, node_s[pos])
    hi = np.maximum(node_s[b1] - (b1 - pos) * h, node_s[pos])
    target = np.where(on_break, node_s[pos], np.clip(wanted, lo, hi))
    clamped = np.abs(target - wanted) > _SNAP * run_min[run]
    return target, clamped


def _check_anchor_order(chain: _Chain, node_s: NDArray, targets: NDArray, name: str) -> None:
    """MeshError if anchor targets (active nodes, breaks) are not strictly increasing."""
    anchor = chain.breaks.copy()
    anchor[chain.position] = True
    s = node_s.copy()
    s[chain.position] = targets
    idx = np.flatnonzero(anchor)
    bad = np.flatnonzero(np.diff(s[idx]) <= 0.0)
    if bad.size:
        a, b = chain.nodes[idx[bad[0]]], chain.nodes[idx[bad[0] + 1]]
        raise MeshError(f"body '{name}': surface nodes {a} and {b} would swap order (their "
                        "contact targets cross); cannot move the ALE mesh")


def _wanted_arc(curve: SurfaceCurve, points: NDArray, tangents: NDArray) -> NDArray:
    """Arc-length parameter where each point wants its node: the closest point of the curve,
    continued past a break (corner or chain end) along ``tangents`` by the overshoot, so that a
    target beyond a break is seen (and clamped) instead of silently stopping at the break."""
    s = curve.project(points)
    h_min = np.diff(curve.node_s).min()
    gap = np.abs(s[:, None] - curve.node_s[curve.breaks][None, :]).min(axis=1)
    residual = points - curve.point_at(s)
    over = np.einsum("ij,ij->i", residual, tangents)
    return s + np.where(gap <= _SNAP * h_min, over, 0.0)


def _relocate_surface(
    body: AleBody, x_old: NDArray, chain: _Chain, wanted_xy: NDArray
) -> tuple[NDArray, NDArray]:
    """New positions of all nodes after moving the surface only; (x, clamped mask per active)."""
    curve = SurfaceCurve.from_chain(x_old[chain.nodes], chain.breaks)
    tangents = curve.tangent_at(curve.node_s[chain.position])
    wanted = _wanted_arc(curve, wanted_xy, tangents)
    targets, clamped = _clamp_slides(curve.node_s, chain.breaks, chain.position, wanted,
                                     body.min_spacing_ratio)
    _check_anchor_order(chain, curve.node_s, targets, body.name)
    anchors = np.zeros(chain.nodes.size, bool)
    anchors[chain.position] = True
    s_all = np.zeros(chain.nodes.size)
    s_all[chain.position] = targets
    new_xy = respace_surface(curve.points, anchors, s_all, chain.breaks, chain.spacing)
    h_min = np.diff(curve.node_s).min()
    still = (np.linalg.norm(new_xy - curve.points, axis=1) <= _SNAP * h_min) | chain.breaks
    new_xy[still] = curve.points[still]
    x_new = x_old.copy()
    x_new[chain.nodes] = new_xy
    return x_new, clamped


def _smooth_interior(
    body: AleBody, x_old: NDArray, x_surf: NDArray
) -> tuple[NDArray, SmoothingResult | None]:
    """Smooth the interior nodes within ``smoothing_layers`` of the moved surface nodes."""
    seeds = np.flatnonzero(np.any(x_surf != x_old, axis=1))
    if seeds.size == 0 or body.smoothing_layers <= 0 or body.sweeps <= 0:
        return x_surf, None
    free = nodes_within_layers(body.cells, body.n_nodes, seeds, body.smoothing_layers)
    smoother = body.smoother(free)
    if not smoother.free.any():
        return x_surf, None
    result = smoother.run(x_surf, max_sweeps=body.sweeps, rel_tol=1e-6)
    return result.nodes, result


def _conserve_momentum(
    masses: tuple[NDArray, NDArray], x: tuple[NDArray, NDArray], v_old: NDArray,
    v_new: NDArray, moved: NDArray,
) -> tuple[NDArray, tuple[NDArray, float]]:
    """Momentum change of the plain remap and the velocity corrected on the remapped nodes.

    The rigid correction acts on the remapped nodes only (supported nodes elsewhere keep their
    velocity); with fewer than two remapped nodes it acts on the whole body.
    """
    p_old, l_old = momenta(masses[0], x[0], v_old)
    p_new, l_new = momenta(masses[1], x[1], v_new)
    change = (p_new - p_old, l_new - l_old)
    sub = moved if np.count_nonzero(moved) >= 2 else np.ones_like(moved)
    p_rest, l_rest = momenta(masses[1][~sub], x[1][~sub], v_new[~sub])
    out = v_new.copy()
    out[sub] = conservative_velocity_correction(masses[1][sub], x[1][sub], v_new[sub],
                                                p_old - p_rest, l_old - l_rest)
    return out, change


def _mismatch(x_new: NDArray, chain: _Chain, wanted_xy: NDArray) -> float:
    """Largest distance along the moved surface between an active node and where its target
    wants it (x_target - Delta): the tangential miss of the predicted end position. The normal
    part is the gap, which the contact law (not the mesh) closes."""
    curve = SurfaceCurve.from_chain(x_new[chain.nodes], chain.breaks)
    s_node = curve.node_s[chain.position]
    wanted = _wanted_arc(curve, wanted_xy, curve.tangent_at(s_node))
    return float(np.max(np.abs(wanted - s_node), initial=0.0))


def _remap(
    body: AleBody, x_old: NDArray, points: NDArray, moved: NDArray, fields: tuple
) -> tuple[NDArray, NDArray, NDArray]:
    """Old (X, v, a) interpolated at the moved nodes' new positions (4.18); others copied."""
    out = tuple(f.copy() for f in fields)
    if moved.any():
        values = Remapper(x_old, body.cells).remap(np.hstack(fields), points, body.remap)
        for f, part in zip(out, np.split(values, len(fields), axis=1), strict=True):
            f[moved] = part
    return out  # type: ignore[return-value]


def _unchanged(X: NDArray, d: NDArray, v: NDArray, a: NDArray) -> AleUpdate:
    n = len(X)
    return AleUpdate(X.copy(), d.copy(), v.copy(), a.copy(), X + d, np.zeros((n, 2)), 0.0,
                     np.zeros(0, np.int64), np.zeros(n, bool), (np.zeros(2), 0.0))


def move_ale_body(
    body: AleBody,
    X: ArrayLike,
    d: ArrayLike,
    v: ArrayLike,
    a: ArrayLike,
    active_local: ArrayLike,
    x_target: ArrayLike,
    x_pred: ArrayLike,
    dt: float,
    x_start: ArrayLike | None = None,
) -> AleUpdate:
    """Move the ALE mesh of one body at t_n and remap its t_n fields (see the module doc).

    ``X, d, v, a`` are the body's rows at t_n (local numbering). ``active_local`` are local
    surface nodes in contact; ``x_target`` (k, 2) their partners' predicted end-of-step
    positions, ``x_pred`` (k, 2) the predicted end positions of the particles that were at
    ``x_start`` (k, 2; default: the active nodes' x_n). With no active node the input is
    returned unchanged. Raises MeshError (naming body and element) if the moved mesh or its
    reference image has an inverted element, or if two active nodes' targets cross.
    """
    X, d, v, a = (np.asarray(f, dtype=float) for f in (X, d, v, a))
    active = np.asarray(active_local, dtype=np.int64).reshape(-1)
    if active.size == 0:
        return _unchanged(X, d, v, a)
    if np.unique(active).size != active.size:
        raise ValueError(f"{body.name}: an active node is listed twice")
    if not dt > 0.0:
        raise ValueError(f"time step must be positive, got {dt}")
    x_old = X + d
    start = x_old[active] if x_start is None else np.asarray(x_start, float).reshape(-1, 2)
    increment = np.asarray(x_pred, dtype=float).reshape(-1, 2) - start
    chain = _open_chain(body, active)
    wanted_xy = np.asarray(x_target, dtype=float).reshape(-1, 2) - increment
    x_surf, clamped = _relocate_surface(body, x_old, chain, wanted_xy)
    x_new, smoothing = _smooth_interior(body, x_old, x_surf)
    check_elements(x_new, body.cells, body.name)
    moved = np.any(x_new != x_old, axis=1)
    X_new, v_new, a_new = _remap(body, x_old, x_new[moved], moved, (X, v, a))
    check_elements(X_new, body.cells, f"{body.name} (reference image)")
    masses = (lumped_masses(X, body.cells, body.cell_density),
              lumped_masses(X_new, body.cells, body.cell_density))
    v_fixed, change = _conserve_momentum(masses, (x_old, x_new), v, v_new, moved)
    if body.conserve_momentum and moved.any():
        v_new = v_fixed
    return AleUpdate(
        X=X_new, d=np.where(moved[:, None], x_new - X_new, d), v=v_new, a=a_new, x_mesh=x_new,
        mesh_velocity=(x_new - x_old) / dt,
        mismatch=_mismatch(x_new, chain, wanted_xy),
        clamped=active[clamped], moved=moved, momentum_change=change, smoothing=smoothing,
    )
