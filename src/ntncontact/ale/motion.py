"""The ALE mesh update of one body for one augmentation (report 4.1-4.3, 5.4 step 2).

Formulation: operator split per augmentation. The ALE body's mesh is moved IN THE t_n
CONFIGURATION and the t_n fields are remapped onto the moved nodes; the following Lagrangian
mid-point step then runs on the moved mesh with no convective term.

The update is incremental: a node moves only when a contact node has to slide, and every moved
node costs a remap, i.e. an interpolation that diffuses the fields (numerical dissipation), so
nothing is moved that need not be.

1. Surface relocation (4.1.1, Figs 4.2-4.4). An active contact node at x_n whose particle is
   predicted to end the step at ``x_pred`` (first augmentation: x_n + dt v_n; later ones: the last
   iterate) must hold, at t_{n+1}, the particle that lands on its partner's predicted position
   ``x_target``. With the step increment Delta = x_pred - x_n taken as locally uniform, that
   particle sits now at x_target - Delta; the node slides along its own t_n surface (the
   piecewise-quadratic curve of ``ale.surface``) to the foot of the normal through that point
   (normals from the continuous nodal-tangent field: the closest point is ill-defined within
   O(gap h^2) of a node, where the curve has tiny tangent kinks, and flipped with round-off,
   which broke symmetric problems and made contact nodes chatter). On a straight surface this
   is exactly the arc-length slide s = (x_target - x_pred) . e (e the unit surface tangent); on a
   curved one it is its generalization (the tangent formula is its linearization). The
   normal part of x_target - x_pred is the gap, which contact, not the mesh, closes. A slide
   below ``slide_tolerance`` times the node's smaller adjacent surface spacing is not made: the
   node keeps its position and fields bit for bit (its miss shows in ``mismatch``).
2. Corners and chain ends stay fixed, and a node never slides past one: its slide is clamped so
   that the free segments between it and the break keep on average at least
   ``min_spacing_ratio`` times the smallest reference surface spacing of that stretch (not
   the one at t_n, which ratchets down step after step while a node is held at the
   clamp). Nor does a node leave a break
   behind beyond ``max_stretch`` times the reference length between them, scaled by the
   run's mean stretch at t_n (``ale.surface._stretch_clamp``: an ALE body whose partners
   slide away from its corner would stretch the corner cell without bound). Clamped nodes
   are reported; a pair between two ALE bodies whose node is clamped is then followed by the
   partner instead (``engine.mesh_motion._hold_clamped``). The first clamp bounds the MEAN
   spacing between a node and the break, not each segment: the respacing of item 3 may grade
   those segments down to about half that mean.
3. The other surface nodes follow (``respace``):
   ``"local"`` (default): each moved anchor's slide is absorbed by the fewest neighbouring
   surface segments whose slack suffices, each shrinking or growing in proportion to its slack,
   the room it has before leaving a band [1 - t, 1/(1 - t)] (t = ``spacing_tolerance``, this
   field, not a scenario key) around its ORIGINAL proportion, i.e. its reference length scaled
   by the CURRENT mean stretch of its run between two anchors; nothing beyond moves, and a
   segment at the edge of the band is carried rigidly, so repeated slides one way compress a
   widening neighbourhood instead of crushing one segment. The band is not a bound on the
   segments' lengths against their original ones: a run its anchors keep squeezing has a
   smaller mean at every move, the segments next to the slide are squeezed again against it
   while those beyond keep their length, and a run between a partner and a fixed end can be
   squeezed or stretched as a whole up to the clamps of item 2 (a block dragged its own length
   over a base leaves segments of 0.19x and 3.2x their original length; no respacing could
   keep 0.5x there, only holding the contact nodes back, which would lose node-to-node
   contact).
   ``engine.diagnostics.AleSpacingCheck`` reports a segment outside [1 - t, 1/(1 - t)] of
   its original length (summary.json ``ale_surface_spacing_at``, a run warning). A run whose
   whole slack does not suffice is respaced in the original proportions, restoring the
   grading (``ale.surface.local_slides``; counted in ``AleUpdate.resets``).
   ``"reference"``: every free surface node is respaced between the anchors in the original
   proportions at every update (nodes move whenever the deformed spacing differs from them).
4. The interior follows (``interior``) as far as the mesh quality needs. A cell is acceptable
   when its smallest corner sine is at least ``min_quality`` times that of the same cell in the
   ORIGINAL mesh, or not lower than at t_n (a move never has to repair what it did not spoil).
   ``"minimal"`` (default) tries, in order, until every cell it changes is acceptable:
   (a) nothing: only the surface nodes move (the fewest remaps);
   (b) the surface moves u = x~_n - x_n are extended harmonically into the interior nodes within
   ``smoothing_layers`` element layers of the moved surface nodes (the Laplacian rule on the
   displacement, ``ale.smoothing.harmonic_extension``), every other node, the rest of the
   boundary included, keeping a zero move: untouched regions do not move, and a deformed or
   graded mesh is not dragged towards a smoother's fixed point;
   (c) the interior nodes within those layers are smoothed in position (4.1.2, rule
   ``smoothing``, ``sweeps`` Jacobi sweeps, the whole boundary fixed, inverting moves refused),
   as a slide of several elements (Fig. 4.2) or accumulated shear needs; this also repairs the
   distortion that (a) and (b) let build up. A move whose region holds a cell below
   ``SLIVER_SINE`` at t_n goes to (c) at once, whatever ``interior`` (with ``sweeps`` > 0).
   ``"displacement"`` starts at (b), ``"position"`` always does (c) (the interior then moves at
   every update, since a deformed mesh is no fixed point of the smoother).
   ``AleUpdate.interior`` tells which stage was used.
   A final element the move inverted (current or reference image), or left inverted and made
   worse, raises MeshError naming the body and the element, and the time loop cuts the step
   back (``mesh.quality.check_move``: a corner the material's own deformation turned reflex,
   Gauss points still positive, does not block a move that does not make it worse).
5. Remap (4.3): the fields at t_n are interpolated from the old mesh (nodes at x_n) at the new
   node positions x~_n: X_new = X(x~_n) (the material point now at the node), d = x~_n - X_new,
   v and a likewise ("linear" Q4 of (4.18) or the third-order gradient-enhanced "quadratic"
   interpolant in the spirit of 4.19, see ``ale.remap``). Nodes that did not move keep their
   values exactly. With ``conserve_momentum`` a rigid velocity is added to the remapped nodes
   (to the nodes of the cells around a single remapped node) so that the body's linear and
   angular momentum, with lumped masses from the new X, equal the old ones (METHOD_NOTES: plain
   interpolation drifts).

Because the remap carries the convection, the step needs no convective term (no double
counting: the report's term with c = v - v_hat (4.5-4.6, 5.9) is what the remap replaces). In
this split the node then moves with the material during the Lagrangian step, so its mesh
velocity over the step is v + (x~_n - x_n)/dt and the report's c = v - v_hat equals
-(x~_n - x_n)/dt: ``AleUpdate.mesh_velocity`` (and ``convective``) are diagnostics only.

6. ``convection = "convective_term"`` (opt-in) splits differently: the move remaps only the
   geometry (X, hence d: which particle sits at the node) and leaves v and a at their old nodal
   values (no momentum correction either); the step then adds the report's C(c) v_{n+1/2} with
   c = ``AleUpdate.convective`` held constant (``ale.convective``, wired by
   ``ntncontact.engine.convection``). Remapping v as well would count the convection twice.

Calling it from the time loop (augmentation k): pass the ORIGINAL t_n state of the body every
time (no repeated remapping, hence no accumulated diffusion), ``x_pred`` = the active nodes'
end-of-step positions from the last iterate (x_n + dt v_n for k = 1) and ``x_start`` = the
positions those particles had at t_n, i.e. the active nodes' positions on the mesh that produced
that iterate (``AleUpdate.x_mesh`` of augmentation k - 1; default: the passed x_n). Then
``mesh_velocity`` is already the whole step's. Passing the previously moved state instead also
works (x_start defaults correctly), but remaps twice and the mesh velocities must be summed.

Cost: everything that depends only on the t_n state (the old surface curve, the point locator,
the recovered nodal gradients of the quadratic remap, the old masses and cell qualities) is
built once per t_n state and reused by the following augmentations of the step (the body keeps
the last state's data, recognised by its bytes); the gradients are recovered only at the nodes
a move needs; topology-only structures (and the open chain's breaks) are built once. A move
is a few compiled calls, each beside the code it belongs to: the whole surface move
(``ale.surface.slide_chain``), the changed cells and their acceptance
(``mesh.quality.changed_cells``), the remap's hinted location and interpolation
(``ale.remap``), the hints and the masses of the changed cells (here). What is left in NumPy
per move is mostly the momentum correction (BLAS dot products) and, per t_n state, the surface
curve's arc lengths and the gradient recovery's least-squares fits (LAPACK).
"""

from __future__ import annotations

import copy
from dataclasses import dataclass
from functools import cached_property
from typing import Literal, get_args

import numpy as np
import scipy.sparse as sp
from numpy.typing import ArrayLike, NDArray

from ntncontact.ale.remap import (
    LazyGradients,
    RemapMethod,
    Remapper,
    RemapTopology,
    conservative_velocity_correction,
    momenta,
)
from ntncontact.ale.smoothing import (
    Smoother,
    SmoothingMethod,
    SmoothingResult,
    boundary_node_mask,
    harmonic_extension,
    node_adjacency,
)
from ntncontact.ale.surface import SurfaceCurve, slide_chain
from ntncontact.mesh.boundary import chain_edge_lengths, surface_chain
from ntncontact.mesh.quadmesh import MeshError, QuadMesh, frozen_array
from ntncontact.mesh.quality import (
    cell_min_sines,
    changed_cells,
    check_move,
    min_sines_below,
)

from ..fem.kernels_numba import gauss_jacobian
from ..fem.q4 import DN_GP, N_GP
from ..jit import njit, read_only

__all__ = ["AleBody", "AleMotionError", "AleUpdate", "lumped_masses", "move_ale_body"]

RespaceMethod = Literal["local", "reference"]
InteriorMethod = Literal["minimal", "displacement", "position"]
Convection = Literal["remap", "convective_term"]
_CHOICES = {"smoothing": SmoothingMethod, "remap": RemapMethod, "respace": RespaceMethod,
            "interior": InteriorMethod, "convection": Convection}
# a move below this fraction of the smallest surface spacing is round-off (of the curve
# evaluation, whose arc-length inversion is iterative, or of the sparse solve): such nodes keep
# their old position exactly
_SNAP = 1e-10
_DEGENERATE = 1e-10  # a corner sine at most this: the cell is checked (``check_move``)


class AleMotionError(MeshError):
    """No valid motion of an ALE mesh exists for this step's contact pairs (targets that
    cross, an element that would invert, a node that leaves the old mesh). The time loop cuts
    the step back; if that does not help, its message names the step and the time."""


class AleCrossingError(AleMotionError):
    """Two ALE surface nodes would swap order: the partners they follow cross. ``nodes``:
    the two local nodes, so that the caller can tell whether one of them need not follow."""

    def __init__(self, message: str, nodes: tuple[int, int]) -> None:
        super().__init__(message)
        self.nodes = nodes


@dataclass(frozen=True, eq=False)
class AleBody:
    """Static data of one ALE body: topology, its contact surface chain and the options.

    ``cells`` and ``surface`` use the body's LOCAL node numbers; ``surface`` is the ordered
    contact chain (body on the left), ``corner`` flags its body corners (fixed, curve breaks),
    ``reference_spacing`` the chain's segment lengths in the original mesh (n - 1 segments, n
    when closed; the respacing keeps their proportions). ``density`` (scalar or per cell) only
    weighs the lumped masses of the momentum correction. ``reference_quality`` is the smallest
    corner sine of every cell of the original mesh (``from_mesh`` computes it; default 1, a
    rectangle). The other options are described in the module docstring (items 1-5).
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
    max_stretch: float = 2.0
    density: float | NDArray[np.float64] = 1.0
    name: str = "body"
    respace: RespaceMethod = "local"
    interior: InteriorMethod = "minimal"
    slide_tolerance: float = 1e-8
    spacing_tolerance: float = 0.5
    min_quality: float = 0.5
    reference_quality: NDArray[np.float64] | None = None
    convection: Convection = "remap"

    def __post_init__(self) -> None:
        cells = frozen_array(self.cells, np.int64).reshape(-1, 4)
        surface = frozen_array(self.surface, np.int64).reshape(-1)
        corner = frozen_array(self.corner, np.bool_).reshape(-1)
        spacing = frozen_array(self.reference_spacing, np.float64).reshape(-1)
        n_seg = surface.size if self.closed else surface.size - 1
        if surface.size < (3 if self.closed else 2) or np.unique(surface).size != surface.size:
            raise ValueError(f"{self.name}: the surface chain needs distinct nodes (>= 2)")
        if corner.shape != surface.shape or spacing.shape != (n_seg,):
            raise ValueError(f"{self.name}: corner needs one entry per surface node and "
                             f"reference_spacing {n_seg} positive segment lengths")
        if not np.all(spacing > 0):
            raise ValueError(f"{self.name}: reference_spacing must be positive")
        for key, kind in _CHOICES.items():
            if getattr(self, key) not in get_args(kind):
                raise ValueError(f"{self.name}: {key} must be one of {get_args(kind)}, got "
                                 f"{getattr(self, key)!r}")
        quality = np.ones(len(cells)) if self.reference_quality is None else frozen_array(
            self.reference_quality, np.float64).reshape(-1)
        if quality.shape != (len(cells),):
            raise ValueError(f"{self.name}: reference_quality needs one value per cell")
        object.__setattr__(self, "reference_quality", quality)
        for key in ("min_spacing_ratio", "spacing_tolerance", "min_quality"):
            if not 0.0 < getattr(self, key) < 1.0:
                raise ValueError(f"{self.name}: {key} must lie in (0, 1)")
        if not self.max_stretch > 1.0:
            raise ValueError(f"{self.name}: max_stretch must exceed 1 (inf: no bound)")
        if not 0.0 <= self.slide_tolerance < 1.0:
            raise ValueError(f"{self.name}: slide_tolerance must lie in [0, 1)")
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
        options.setdefault("reference_quality", cell_min_sines(mesh.nodes, mesh.cells))
        return cls(mesh.cells, chain.nodes, chain.closed, corner, mesh.n_nodes,
                   chain_edge_lengths(xy, chain.closed), **options)  # type: ignore[arg-type]

    @cached_property
    def boundary(self) -> NDArray[np.bool_]:
        return boundary_node_mask(self.cells, self.n_nodes)

    @cached_property
    def min_spacing(self) -> float:
        """The smallest reference surface spacing."""
        return float(self.reference_spacing.min())

    @cached_property
    def _smoother(self) -> Smoother:
        return Smoother(self.cells, self.n_nodes, None, self.smoothing, self.name)

    def smoother(self, free: NDArray[np.bool_]) -> Smoother:
        """The body's smoother (neighbour structures built once) freeing only ``free`` nodes."""
        out = copy.copy(self._smoother)
        out.free = free & ~self.boundary
        return out

    @cached_property
    def adjacency(self) -> sp.csr_matrix:
        """Node adjacency through cell edges (the harmonic extension's graph)."""
        return node_adjacency(self.cells, self.n_nodes)

    @cached_property
    def _node_cells(self) -> sp.csr_matrix:
        """Node-cell incidence (n_nodes, n_cells)."""
        cols = np.repeat(np.arange(len(self.cells)), 4)
        return sp.csr_matrix((np.ones(cols.size), (self.cells.ravel(), cols)),
                             shape=(self.n_nodes, len(self.cells)))

    def within_layers(self, seeds: NDArray[np.bool_], layers: int) -> NDArray[np.bool_]:
        """Nodes reachable from the mask ``seeds`` through at most ``layers`` shared cells."""
        mask = seeds.copy()
        for _ in range(layers):
            mask = (self._node_cells @ mask[self.cells].any(axis=1).astype(float)) > 0
        return mask

    @cached_property
    def _surface_index(self) -> NDArray[np.int64]:
        """Chain index of every node (-1 off the contact surface)."""
        where = np.full(self.n_nodes, -1)
        where[self.surface] = np.arange(self.surface.size)
        return where

    @cached_property
    def _open_breaks(self) -> NDArray[np.bool_]:
        """Breaks of the open chain: the corners and both ends (not to be modified)."""
        breaks = self.corner.copy()
        breaks[[0, -1]] = True
        return breaks

    @cached_property
    def _node_cell(self) -> NDArray[np.int64]:
        """One cell around each node (the remap's first guess for a node moved a little)."""
        out = np.full(self.n_nodes, -1)
        out[self.cells.ravel()] = np.repeat(np.arange(len(self.cells)), 4)
        return out

    @cached_property
    def _edge_keys(self) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
        """Sorted keys lo * n + hi of every cell edge and the cell of each."""
        lo = np.minimum(self.cells, np.roll(self.cells, -1, axis=1)).ravel()
        hi = np.maximum(self.cells, np.roll(self.cells, -1, axis=1)).ravel()
        keys = lo * self.n_nodes + hi
        order = np.argsort(keys, kind="stable")
        return keys[order], np.repeat(np.arange(len(self.cells)), 4)[order]

    def segment_cells(self, chain_nodes: NDArray[np.int64]) -> NDArray[np.int64]:
        """The cell owning each segment (boundary edge) of a chain of surface nodes."""
        a, b = chain_nodes[:-1], chain_nodes[1:]
        keys, owner = self._edge_keys
        at = np.searchsorted(keys, np.minimum(a, b) * self.n_nodes + np.maximum(a, b))
        return owner[np.minimum(at, keys.size - 1)]

    @cached_property
    def _remap_topology(self) -> RemapTopology:
        """The remap's cell-only data (boundary edges, gradient-recovery patches)."""
        return RemapTopology(self.cells, self.n_nodes)

    @cached_property
    def cell_density(self) -> NDArray[np.float64]:
        # a contiguous copy, not a broadcast view: _element_masses is compiled for one layout
        # (lumped_masses passes a contiguous array), and a stride-0 view was a second one
        return np.array(np.broadcast_to(np.asarray(self.density, dtype=float),
                                        (len(self.cells),)))

    @cached_property
    def _last_state(self) -> dict:
        return {}

    def _tn_state(self, X: NDArray, d: NDArray, v: NDArray, a: NDArray) -> _TnState:
        """The t_n data of these fields, rebuilt only when the fields change."""
        key = b"".join(np.ascontiguousarray(f).tobytes() for f in (X, d, v, a))
        state = self._last_state.get("tn")
        if state is None or state.key != key:
            state = _TnState(self, key, X, d, v, a)
            self._last_state["tn"] = state
        return state


class _TnState:
    """Data that depend only on one t_n state of a body, shared by the step's augmentations."""

    def __init__(self, body: AleBody, key: bytes, X: NDArray, d: NDArray, v: NDArray,
                 a: NDArray) -> None:
        self.body, self.key = body, key
        self.X, self.v, self.a = X.copy(), v.copy(), a.copy()
        self.x = X + d
        self._curves: dict[int, SurfaceCurve] = {}
        self._owners: dict[int, NDArray[np.int64]] = {}

    def segment_cells(self, chain: _Chain) -> NDArray[np.int64]:
        """The cell owning each segment of the opened chain (one per opening)."""
        start = int(chain.nodes[0])
        if start not in self._owners:
            self._owners[start] = self.body.segment_cells(chain.nodes)
        return self._owners[start]

    def curve(self, chain: _Chain) -> SurfaceCurve:
        """The t_n surface curve of the opened chain (one per opening)."""
        start = int(chain.nodes[0])
        if start not in self._curves:
            self._curves[start] = SurfaceCurve.from_chain(self.x[chain.nodes], chain.breaks)
        return self._curves[start]

    @cached_property
    def fields(self) -> NDArray[np.float64]:
        return np.hstack([self.X, self.v, self.a])

    @cached_property
    def remapper(self) -> Remapper:
        return Remapper(self.x, self.body.cells, topology=self.body._remap_topology)

    @cached_property
    def gradients(self) -> LazyGradients:
        """Recovered where first needed (a move remaps a few points)."""
        return LazyGradients(self.remapper, self.fields)

    @cached_property
    def element_masses(self) -> NDArray[np.float64]:
        body = self.body
        return _element_masses(self.X, body.cells, np.arange(len(body.cells)),
                               body.cell_density, DN_GP, N_GP)

    @cached_property
    def masses(self) -> NDArray[np.float64]:
        return np.bincount(self.body.cells.ravel(), self.element_masses.ravel(), len(self.X))

    def masses_after(self, X_new: NDArray, idx: NDArray[np.int64]) -> NDArray[np.float64]:
        """Lumped masses with the reference images of the cells ``idx`` replaced by those of
        X_new."""
        body = self.body
        return _masses_after(X_new, body.cells, idx, body.cell_density, DN_GP, N_GP,
                             self.element_masses, self.masses)

    @cached_property
    def momenta(self) -> tuple[NDArray[np.float64], float]:
        return momenta(self.masses, self.x, self.v)

    @cached_property
    def quality(self) -> NDArray[np.float64]:
        return cell_min_sines(self.x, self.body.cells)

    @cached_property
    def h_min(self) -> float:
        """Smallest surface spacing at t_n: the length scale of round-off snapping."""
        xy = self.x[self.body.surface]
        return float(chain_edge_lengths(xy, self.body.closed).min())


#: a chain node turning by more than this (degrees) whose curvature is more than
#: KINK_CURVATURE_RATIO times both neighbours' is a kink of a smooth surface, hence a corner
KINK_MIN_DEG = 1.0
KINK_CURVATURE_RATIO = 4.0


def _kinks(xy: NDArray, closed: bool, angle_deg: float) -> NDArray[np.bool_]:
    """Chain nodes where the polygon turns by more than ``angle_deg``, or where it bends
    much more sharply than at both neighbours (a kink of a flat or smooth surface: turn above
    KINK_MIN_DEG, curvature turn / mean adjacent edge above KINK_CURVATURE_RATIO times the
    neighbours'; a discretized arc, graded or not, has nearly equal curvatures). The move
    slides the nodes between corners along a smooth curve through them, which cuts a kink
    it does not know (a foundation bending down by 12 degrees: one remap created 5.4 % of
    the energy and the next step inverted the corner cell). Open ends excluded."""
    before = xy - np.roll(xy, 1, axis=0)
    after = np.roll(xy, -1, axis=0) - xy
    cross = before[:, 0] * after[:, 1] - before[:, 1] * after[:, 0]
    turn = np.abs(np.arctan2(cross, np.einsum("ij,ij->i", before, after)))
    if not closed:
        turn[[0, -1]] = 0.0
    mean_edge = 0.5 * (np.linalg.norm(before, axis=1) + np.linalg.norm(after, axis=1))
    curvature = turn / mean_edge
    sharper = curvature > KINK_CURVATURE_RATIO * np.maximum(np.roll(curvature, 1),
                                                            np.roll(curvature, -1))
    kink = (turn > np.deg2rad(angle_deg)) | ((turn > np.deg2rad(KINK_MIN_DEG)) & sharper)
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
    smoothing: SmoothingResult | None = None  # of the position smoother, when it ran
    interior: str = "none"  # stage used for the interior: none, surface, displacement, position
    # surface nodes around which the interior moved (the moved ones and the step's earlier
    # seeds, ``_move_interior``); None: the interior did not move
    seeds: NDArray[np.bool_] | None = None
    resets: int = 0  # surface runs respaced in the original proportions ("local" respacing)
    # strain energy the remap changed, W after - W before (engine.remap_conservation, with
    # conserve_energy "total" or "kinetic"; 0 with "none")
    remap_strain_change: float = 0.0
    # kinetic energy the velocity correction should have taken out (negative: put in) and
    # could not, the body's velocities being too slow for it (engine.remap_conservation)
    energy_left: float = 0.0

    @property
    def convective(self) -> NDArray[np.float64]:
        """The report's c = v - v_hat (4.5) of this split: -(x~_n - x_n)/dt (diagnostic)."""
        return -self.mesh_velocity


def lumped_masses(X: ArrayLike, cells: ArrayLike, density: ArrayLike = 1.0) -> NDArray:
    """Row-sum lumped nodal masses m_a = sum_e int_{Omega_e^X} rho N_a dA (5.8, 5.13).

    2 x 2 Gauss is exact: N_a det J is at most quadratic in each reference coordinate.
    """
    X = np.ascontiguousarray(X, dtype=float)
    cell_arr = np.ascontiguousarray(cells, dtype=np.int64).reshape(-1, 4)
    rho = np.array(np.broadcast_to(np.asarray(density, dtype=float), (len(cell_arr),)))
    masses = _element_masses(X, cell_arr, np.arange(len(cell_arr)), rho, DN_GP, N_GP)
    return np.bincount(cell_arr.ravel(), masses.ravel(), len(X))


@dataclass(frozen=True)
class _Chain:
    """The surface chain as an open curve: closed chains are cut at a corner or far node."""

    nodes: NDArray[np.int64]  # local nodes in walking order (closed: first repeated at the end)
    breaks: NDArray[np.bool_]
    spacing: NDArray[np.float64]  # reference segment lengths
    position: NDArray[np.int64]  # chain index of each active node

    def __post_init__(self) -> None:
        # read-only views whichever way the chain was opened (an open chain's arrays are the
        # body's frozen ones, a closed chain's new ones): the kernels (slide_chain,
        # _hint_cells) are compiled for one array type, and a second costs ~10 s in a run
        for name in ("nodes", "breaks", "spacing", "position"):
            object.__setattr__(self, name, read_only(getattr(self, name)))


def _open_chain(body: AleBody, active: NDArray) -> _Chain:
    """Open the chain; a closed chain starts at its first corner, else at the node farthest
    (in chain steps) from every active node, which then stays fixed for this update."""
    n = body.surface.size
    pos = body._surface_index[active]
    if np.any(pos < 0):
        raise ValueError(f"{body.name}: active nodes {active[pos < 0].tolist()} are not on the "
                         "ALE contact surface")
    if not body.closed:
        return _Chain(body.surface, body._open_breaks, body.reference_spacing, pos)
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


def _move_surface(
    body: AleBody, tn: _TnState, chain: _Chain, wanted_xy: NDArray
) -> tuple[NDArray, NDArray, NDArray, float, int]:
    """The chain nodes slid along the t_n curve (``ale.surface.slide_chain``); (positions,
    slides per chain node, clamped mask per active node, mismatch, resets).

    The wanted arc length of an active node is the foot of the normal through its wanted point
    (``SurfaceCurve.normal_foot``, the closest point up to O(h^2) kinks), continued past a break
    (corner or chain end) along the node's tangent by the overshoot, so that a target beyond a
    break is seen (and clamped) instead of silently stopping at the break. Slides below the
    tolerance are not made (such nodes get exactly 0); targets are clamped so that the free
    nodes between a node and the breaks around it keep ``min_spacing_ratio`` times the
    smallest segment of that stretch (breaks do not move).
    """
    curve = tn.curve(chain)
    t_start, t_end = curve.tangents
    tol = body.spacing_tolerance
    x, slides, clamped, mismatch, resets, idx, bad = slide_chain(
        tn.x, chain.nodes, curve.points, curve.bulge, curve.node_s, t_start, t_end,
        chain.breaks, chain.spacing, wanted_xy, chain.position, body.slide_tolerance,
        body.min_spacing_ratio, _SNAP, 1.0 - tol, 1.0 / (1.0 - tol), body.respace == "local",
        _SNAP * tn.h_min, body.max_stretch)
    if bad >= 0:
        pair = (int(chain.nodes[idx[bad]]), int(chain.nodes[idx[bad + 1]]))
        raise AleCrossingError(_crossing_message(body, tn.x, *pair), pair)
    return x, slides, clamped, float(mismatch), int(resets)


def _crossing_message(body: AleBody, x: NDArray, a: int, b: int) -> str:
    """Which nodes would swap, where, and what to change (one line). The body does not know
    its partners' spacing: the time loop adds the advice on it where it applies
    (``engine.mesh_motion``)."""
    where = " and ".join(f"({x[n, 0]:.6g}, {x[n, 1]:.6g})" for n in (a, b))
    return (f"body '{body.name}': ALE surface nodes {a} and {b} (at {where}) would swap order: "
            "the contact partners they follow cross, so no valid motion of the ALE mesh "
            "exists; shorten the time step (analysis.dt)")


def _changes(body: AleBody, tn: _TnState, x_new: NDArray) -> tuple[NDArray, NDArray, bool, bool]:
    """(moved nodes, changed cells, acceptable, degenerate) of the move to ``x_new``: every
    changed cell keeps min_quality of its original quality, or does not get worse than at t_n
    (``mesh.quality.changed_cells``)."""
    moved, touched, ok, degenerate = changed_cells(
        x_new, tn.x, body.cells, body.min_quality, body.reference_quality, tn.quality,
        _DEGENERATE)
    return moved, touched, bool(ok), bool(degenerate)


#: the stages of ``_move_interior``, in order (``AleUpdate.interior``)
STAGES = ("none", "surface", "displacement", "position")
#: a cell whose smallest corner sine is below this at t_n (5.7 degrees; the nine examples'
#: ALE bodies stay above 0.29) is a sliver that the material's own motion made and no
#: acceptance test of a move repairs (each compares with t_n). A move whose smoothing
#: region holds one smooths that region in position (stage "position"): under friction the
#: contact-side rows of a sliding ALE body shear while its surface nodes are held under
#: their partners. A sliver the surface nodes shape (a stretched surface segment under a thin
#: row) stays one (docs/theory.md, "Slivers the material made").
SLIVER_SINE = 0.1


def _holds_sliver(body: AleBody, tn: _TnState, seeds: NDArray[np.bool_]) -> bool:
    """Whether a cell holding an interior node within ``smoothing_layers`` of the ``seeds``
    is a sliver at t_n (:data:`SLIVER_SINE`)."""
    if not tn.quality.min() < SLIVER_SINE:
        return False
    free = body.within_layers(seeds, body.smoothing_layers) & ~body.boundary
    return bool(np.any(tn.quality[free[body.cells].any(axis=1)] < SLIVER_SINE))


def _move_interior(
    body: AleBody, tn: _TnState, x_surf: NDArray, least: str = "none",
    least_seeds: NDArray[np.bool_] | None = None,
) -> tuple[NDArray, tuple[NDArray, NDArray, bool, bool], SmoothingResult | None, str, NDArray]:
    """Interior nodes within ``smoothing_layers`` of the moved surface nodes follow them as far
    as needed; (positions, their ``_changes``, position-smoothing result, stage used, seeds:
    the surface nodes the interior moved around).

    ``least`` and ``least_seeds``: the stage and the seeds of the step's previous move, the
    least this one uses. Both are thresholds: which stage a move needs is one on the mesh
    quality, and whether a surface node moves at all is one on its slide. So the surface
    positions of successive augmentations that differ by round-off could alternate between
    moving an interior region and not: a jump of the remapped fields at every other
    augmentation, and the augmentations cycled instead of converging (the disk drop refined
    4x: interior nodes went 2.8e-5 to and fro, report 5.4's test stuck at 3e-6 against
    1e-8)."""
    changes = _changes(body, tn, x_surf)
    seeds = changes[0]  # surface nodes only: x_surf moved no other
    if least_seeds is not None:
        seeds = seeds | (least_seeds & (body._surface_index >= 0))
    if not seeds.any():
        return x_surf, changes, None, "none", seeds
    floor = STAGES.index(least)
    if body.sweeps > 0 and _holds_sliver(body, tn, seeds):
        floor = STAGES.index("position")
    if body.interior == "minimal" and changes[2] and floor <= STAGES.index("surface"):
        return x_surf, changes, None, "surface", seeds
    free = body.within_layers(seeds, body.smoothing_layers) & ~body.boundary
    if body.smoothing_layers <= 0 or not free.any():
        return x_surf, changes, None, "surface", seeds
    if body.interior != "position" and floor <= STAGES.index("displacement"):
        u = harmonic_extension(body.adjacency, x_surf - tn.x, free)
        u[np.linalg.norm(u, axis=1) <= _SNAP * tn.h_min] = 0.0
        x_new = np.where(free[:, None], tn.x + u, x_surf)
        moved = _changes(body, tn, x_new)
        if moved[2] or body.sweeps <= 0:
            return x_new, moved, None, "displacement", seeds
    if body.sweeps <= 0:
        return x_surf, changes, None, "surface", seeds
    result = body.smoother(free).run(x_surf, max_sweeps=body.sweeps, rel_tol=1e-6,
                                     reference=tn.x)
    return result.nodes, _changes(body, tn, result.nodes), result, "position", seeds


def _conserve_momentum(
    tn: _TnState, mass_new: NDArray, x_new: NDArray, v_new: NDArray, moved: NDArray,
    touched: NDArray[np.int64],
) -> tuple[NDArray, tuple[NDArray, float]]:
    """Momentum change of the plain remap and the velocity corrected on the remapped nodes.

    The rigid correction acts on the remapped nodes only (supported nodes elsewhere keep their
    velocity); a single remapped node cannot take a rigid velocity (two momenta, one node), so
    then it acts on the nodes of the cells around it.
    """
    p_old, l_old = tn.momenta
    p_new, l_new = momenta(mass_new, x_new, v_new)
    change = (p_new - p_old, l_new - l_old)
    sub = moved
    if np.count_nonzero(moved) < 2:
        sub = np.zeros_like(moved)
        sub[tn.body.cells[touched].ravel()] = True
    # index arrays once (the same gathered values as with the masks, fewer mask passes)
    rest, sub = np.flatnonzero(~sub), np.flatnonzero(sub)
    p_rest, l_rest = momenta(mass_new[rest], x_new[rest], v_new[rest])
    out = v_new.copy()
    out[sub] = conservative_velocity_correction(mass_new[sub], x_new[sub], v_new[sub],
                                                p_old - p_rest, l_old - l_rest)
    return out, change


def _unchanged(X: NDArray, d: NDArray, v: NDArray, a: NDArray, mismatch: float = 0.0,
               clamped: NDArray | None = None) -> AleUpdate:
    n = len(X)
    return AleUpdate(X.copy(), d.copy(), v.copy(), a.copy(), X + d, np.zeros((n, 2)), mismatch,
                     np.zeros(0, np.int64) if clamped is None else clamped, np.zeros(n, bool),
                     (np.zeros(2), 0.0))


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
    least_interior: str = "none",
    least_seeds: NDArray[np.bool_] | None = None,
) -> AleUpdate:
    """Move the ALE mesh of one body at t_n and remap its t_n fields (see the module doc).

    ``X, d, v, a`` are the body's rows at t_n (local numbering). ``active_local`` are local
    surface nodes in contact; ``x_target`` (k, 2) their partners' predicted end-of-step
    positions, ``x_pred`` (k, 2) the predicted end positions of the particles that were at
    ``x_start`` (k, 2; default: the active nodes' x_n). With no active node, or no slide above
    the tolerance, the input is returned unchanged. Raises MeshError (naming body and element)
    if the move inverts an element of the mesh or its reference image (or makes an inverted one
    worse, ``check_move``), or if two active nodes' targets cross. ``least_interior`` and
    ``least_seeds``: the interior stage and seeds of this step's previous move of the body,
    the least this move uses (``_move_interior``).
    """
    X, d, v, a = (np.asarray(f, dtype=float) for f in (X, d, v, a))
    active = np.asarray(active_local, dtype=np.int64).reshape(-1)
    if active.size == 0:
        return _unchanged(X, d, v, a)
    if len(set(active.tolist())) != active.size:  # a few nodes: cheaper than np.unique
        raise ValueError(f"{body.name}: an active node is listed twice")
    if not dt > 0.0:
        raise ValueError(f"time step must be positive, got {dt}")
    tn = body._tn_state(X, d, v, a)
    x_old = tn.x
    start = x_old[active] if x_start is None else np.asarray(x_start, float).reshape(-1, 2)
    increment = np.asarray(x_pred, dtype=float).reshape(-1, 2) - start
    chain = _open_chain(body, active)
    wanted_xy = np.asarray(x_target, dtype=float).reshape(-1, 2) - increment
    x_surf, slides, clamped, mismatch, resets = _move_surface(body, tn, chain, wanted_xy)
    slid = chain.nodes[slides != 0.0]
    try:
        x_new, (moved, touched, _, degenerate), smoothing, stage, seeds = _move_interior(
            body, tn, x_surf, least_interior, least_seeds)
    except MeshError as err:  # the smoothed interior has an inverted cell
        raise _explained(body, slid, err) from None
    if not moved.any():
        return _unchanged(X, d, v, a, mismatch, active[clamped])
    if degenerate:
        _check_move(body, slid, x_new, x_old, body.name, touched)
    X_new, v_new, a_new = _remapped(body, tn, chain, slides, x_new, moved, (X, v, a))
    if min_sines_below(X_new, body.cells, touched, _DEGENERATE):
        _check_move(body, slid, X_new, X, f"{body.name} (reference image)", touched)
    mass_new = tn.masses_after(X_new, touched)
    v_fixed, change = _conserve_momentum(tn, mass_new, x_new, v_new, moved, touched)
    if body.conserve_momentum and body.convection == "remap":
        v_new = v_fixed
    return AleUpdate(
        X=X_new, d=np.where(moved[:, None], x_new - X_new, d), v=v_new, a=a_new, x_mesh=x_new,
        mesh_velocity=(x_new - x_old) / dt, mismatch=mismatch, clamped=active[clamped],
        moved=moved, momentum_change=change, smoothing=smoothing, interior=stage,
        seeds=seeds, resets=resets,
    )


def _check_move(body: AleBody, slid: NDArray, new: NDArray, old: NDArray, name: str,
                touched: NDArray) -> None:
    """``check_move`` of the cells ``touched``, its error ``_explained``."""
    try:
        check_move(new, old, body.cells, name, touched)
    except MeshError as err:
        raise _explained(body, slid, err) from None


def _explained(body: AleBody, slid: NDArray, err: MeshError) -> MeshError:
    """``err`` (a move refused by ``check_move``), with why and what to change where the cell
    it names holds a surface node this move slid (``slid``): a partner surface that runs on
    through the contact (a disk sliding around the inside of an ALE ring) drags the ALE nodes
    along until a surface cell inverts, which only a Lagrangian body avoids (docs/theory.md,
    "An ALE body under a surface that runs through the contact")."""
    if err.cell < 0 or not np.isin(body.cells[err.cell], slid).any():
        return err
    return MeshError(
        f"{err}, a cell beside the contact-surface nodes this move slid after their "
        "partners: where the partner's surface runs on through the contact (a body "
        "sliding or spinning along this one, around a curved surface or far along a flat "
        "one), its nodes drag this body's along and bunch them up until a cell inverts, "
        f"which no ALE setting or smaller dt prevents; make body '{body.name}' Lagrangian "
        "(mesh_motion = \"lagrangian\")")


def _remapped(body: AleBody, tn: _TnState, chain: _Chain, slides: NDArray, x_new: NDArray,
              moved: NDArray, fields: tuple[NDArray, NDArray, NDArray]
              ) -> tuple[NDArray, NDArray, NDArray]:
    """(X, v, a) on the moved mesh ``x_new``: the t_n fields ``fields`` remapped at the moved
    nodes (``moved``), the others as they were; with the convective term v and a stay (the
    step's C v term convects them, item 6)."""
    X, v, a = fields
    gradients = tn.gradients if body.remap == "quadratic" else None
    # likely old cell of every moved node: for a slid surface node the cell of the segment it
    # landed on, otherwise a cell around its old position
    hint = _hint_cells(body._node_cell, chain.nodes, tn.segment_cells(chain),
                       tn.curve(chain).node_s, slides, moved)
    values = tn.remapper.remap(tn.fields, x_new[moved], body.remap, gradients=gradients,
                               hint=hint)
    X_new, v_new, a_new = X.copy(), v.copy(), a.copy()
    X_new[moved], v_new[moved], a_new[moved] = values[:, :2], values[:, 2:4], values[:, 4:]
    if body.convection == "convective_term":
        v_new[moved], a_new[moved] = v[moved], a[moved]
    return X_new, v_new, a_new


# --- compiled loops of a move: remap hints, masses of the changed cells ----------------------


@njit(cache=True)
def _hint_cells(node_cell, chain_nodes, owner, node_s, slides, moved):
    """Per moved node (in node order) a likely old cell: for a slid chain node the cell owning
    the segment it landed on, otherwise one around its position."""
    hint = node_cell.copy()
    for i in range(slides.size):
        if slides[i] != 0.0:
            seg = np.searchsorted(node_s, node_s[i] + slides[i], side="right") - 1
            hint[chain_nodes[i]] = owner[min(max(seg, 0), owner.size - 1)]
    return hint[np.flatnonzero(moved)]


@njit(cache=True)
def _element_masses(X, cells, which, density, dn, shape):
    """Per cell of ``which`` its 4 lumped nodal masses (``lumped_masses``);
    ``dn`` (g, a, k) natural gradients and ``shape`` (g, a) shape values at the Gauss points,
    ``density`` per cell of ``which``."""
    out = np.zeros((which.size, 4))
    det = np.empty(4)
    for k in range(which.size):
        e = which[k]
        for g in range(4):
            j00, j01, j10, j11 = gauss_jacobian(dn, g, X, cells[e])
            det[g] = (j00 * j11 - j01 * j10) * density[k]
        for a in range(4):
            total = 0.0
            for g in range(4):
                total += det[g] * shape[g, a]
            out[k, a] = total
    return out


@njit(cache=True)
def _masses_after(X, cells, which, density, dn, shape, old_element_masses, masses):
    """``_TnState.masses_after``: the lumped masses ``masses`` with the element masses of the
    cells ``which`` (``old_element_masses`` per cell) replaced by those of X; ``density`` per
    cell. The changes are accumulated as ``np.bincount`` does (from zero, in cell order) and
    then added, so the result is the NumPy expression's bit for bit."""
    dens = np.empty(which.size)
    for k in range(which.size):
        dens[k] = density[which[k]]
    change = _element_masses(X, cells, which, dens, dn, shape)
    add = np.zeros(masses.size)
    for k in range(which.size):
        e = which[k]
        for a in range(4):
            add[cells[e, a]] += change[k, a] - old_element_masses[e, a]
    out = np.empty(masses.size)
    for i in range(masses.size):
        out[i] = masses[i] + add[i]
    return out
