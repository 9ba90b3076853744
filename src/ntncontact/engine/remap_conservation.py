"""The remap's exact conservation of momenta and energy for ALE bodies in the time loop.

``ale.motion`` remaps the t_n fields onto the moved nodes; here the remapped velocities are
corrected (``ale.conservation.conserving_correction``: the least mass-norm change) with the
model's own mass matrix (consistent or lumped, as the step and the history use it), so that the
body's linear and angular momentum and its kinetic energy are those the time loop measures
before the move, to round-off:

* ``restore_strain_energy`` (default): before the velocities, the reference positions X of
  the interior nodes around the move are changed at fixed positions x so that the strain
  energy W is the one before the move (``ale.strain_repair``: which particle sits at a node
  near the kink that a point-loaded contact node puts into the field is known only to the
  remap's accuracy, and the repair chooses within it). The strain energy a remap changes is
  first order in the slide (the nodal values of a C0 field with a kink at a loaded node are
  cut by the interpolation), far above anything a higher-order interpolant removes
  (docs/theory.md, "The strain energy the remap changes");
* ``conserve_energy = "total"`` (default): K after = K before - (W after - W before), W over
  the cells the move changed: the strain energy the remap changed (all of it without the
  repair, what the repair could not restore with it) goes into the velocities of the same
  neighbourhood, so E is exact. With the repair that is only the rare unrestorable move, so
  the velocities are not kicked where the repair works;
* ``"kinetic"``: K after = K before, so with the repair the remap keeps K and W, hence E,
  each to round-off where the repair restores W, and leaves E changed where it does not
  (a block between linear ALE walls over 7 s: +1.1 % E0, after 30 episodes).

The correction acts on the free dofs of the nodes of the cells around the remapped nodes and
around the step's active contact nodes (slid or not: ``_correction_nodes``), and on all free
dofs of the body when those cannot take the energy.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
import scipy.sparse as sp
from numpy.typing import NDArray

from ..ale.conservation import conserving_correction, dof_momenta
from ..ale.motion import AleUpdate
from ..ale.strain_repair import RepairResult, StrainRepair, restore_strain_energy
from ..fem.assembly import CsrPattern
from ..fem.kernels_numba import MODEL_CODES, NumbaAssembly
from ..fem.loads import dirichlet_values
from ..fem.q4 import element_mass
from .model import AleSetup, Model

__all__ = ["conserve_remap", "hand_over_energy"]

#: the repaired strain energy matches its target to this fraction of the body's
REPAIR_RTOL = 1e-12
#: a repair whose Newton stops (no step decreases the residual) within this fraction of the
#: body's strain energy has reached W's round-off floor and counts as restored
#: (``ale.strain_repair.restore_strain_energy``); the rest goes to the velocities as any
#: strain change does, so E stays exact
REPAIR_ROUND_OFF = 1e-9
#: the repair relabels interior nodes up to this many cell layers from the moved nodes
REPAIR_LAYERS = 3


def conserve_remap(model: Model, setup: AleSetup, X: NDArray, d: NDArray, v: NDArray,
                   time: float, update: AleUpdate, active: NDArray) -> AleUpdate:
    """``update`` (the body's move from the t_n rows X, d, v) with its velocities corrected.

    ``active``: the body's local contact nodes the move was made for. The correction then
    also acts around them (``_correction_nodes``) whether or not they slid, so that it does
    not jump when a node's slide crosses zero."""
    motion = setup.motion
    energy = setup.conserve_energy
    if (not update.moved.any() or motion.convection != "remap"
            or (not setup.conserve_momentum and energy == "none")):
        return update
    body = _body_data(model, setup)
    old = body.old_state(X, d, v)
    touched = np.flatnonzero(update.moved[motion.cells].any(axis=1))
    free = _free_mask(model, setup.node_offset, setup.n_nodes, time)
    changed = touched
    dynamic = model.analysis.kind == "dynamic"
    if setup.restore_strain and dynamic:  # a static step re-solves equilibrium on the new mesh
        update, changed = body.restore_strain(old, X, d, update, touched, free, active)
    kinetic = old.kinetic
    # measured in both energy modes: "total" hands it to the velocities, "kinetic" leaves it
    # in E, and history.csv's ale_remap_energy shows it either way
    strain_change = 0.0 if energy == "none" else \
        body.strain_energy(X, d, update) - old.strain_energy
    if not dynamic:  # no velocities to correct, only the books
        return replace(update, remap_strain_change=strain_change)
    if energy == "total":
        kinetic -= strain_change
    near = _correction_nodes(setup, touched, active)
    dofs = np.flatnonzero(np.repeat(near, 2) & free)
    mass = body.mass_after(old, update.X, changed)
    target_momenta = old.momenta if setup.conserve_momentum else None
    target_kinetic = None if energy == "none" else kinetic
    fixed = conserving_correction(mass, update.x_mesh, update.v, dofs, target_momenta,
                                  target_kinetic)
    if not fixed.energy_restored:  # too little motion around the move: the whole body
        fixed = conserving_correction(mass, update.x_mesh, update.v, np.flatnonzero(free),
                                      target_momenta, target_kinetic)
    left = 0.0
    if target_kinetic is not None and not fixed.energy_restored:  # the body is too slow
        left = dof_momenta(mass, update.x_mesh, fixed.v)[1] - target_kinetic
    return replace(update, v=fixed.v, remap_strain_change=strain_change, energy_left=left)


def hand_over_energy(model: Model, time: float, X: NDArray, x: NDArray, v: NDArray,
                     left: float, partners: frozenset[int] = frozenset()
                     ) -> tuple[NDArray, float]:
    """(v, what is still left) with ``left`` (the kinetic energy the ALE bodies' remap
    corrections could not take out; negative: put in) taken from the velocities of one
    Lagrangian body, its momenta kept (the least mass-norm change): the bodies in contact
    with the ALE bodies (indices ``partners``) before any other, each group with the most
    kinetic energy first. Its momenta kept, a body can give only its kinetic energy beyond its
    rigid motion: one moving or spinning nearly rigidly has almost none to give, however fast
    (the unreturned-energy warning says so). A supported ALE body nearly at rest cannot give
    back what its remap
    added to its strain energy: the disk drop's block when a third pair's node joins the
    dimple under the rolling disk (W + 1.17e-3, the block's K 1.12e-3), and the ledger gained
    it; the rolling disk gives the 7.6e-5 left (its nodal velocities change by at most 0.010,
    0.4 % of its largest speed 2.68)."""
    ale = {setup.body_index for setup in model.ale_bodies}
    lumped = model.analysis.mass == "lumped"
    candidates = []
    for index, body in enumerate(model.bodies):
        if index in ale:
            continue
        rows = slice(body.node_offset, body.node_offset + body.mesh.n_nodes)
        mass = body_mass(X[rows], body.mesh.cells, model.assembler.rho[body.cells], lumped)
        momenta, kinetic = dof_momenta(mass, x[rows], v[rows])
        candidates.append((index, kinetic, rows, mass, momenta))
    out = v.copy()
    for _, kinetic, rows, mass, momenta in sorted(
            candidates, key=lambda c: (c[0] not in partners, -c[1])):
        free = _free_mask(model, rows.start, rows.stop - rows.start, time)
        fixed = conserving_correction(mass, x[rows], v[rows], np.flatnonzero(free), momenta,
                                      kinetic - left)
        if fixed.energy_restored:
            out[rows] = fixed.v
            return out, 0.0
    return out, left


def _correction_nodes(setup: AleSetup, touched: NDArray, active: NDArray | None
                      ) -> NDArray[np.bool_]:
    """Mask of the nodes whose velocities the correction may change: those of the cells the
    move changed and, with ``active``, those of the cells around every node that an
    arbitrarily small slide of the active nodes moves (the active nodes themselves; with
    ``interior`` other than "minimal" also the interior nodes within ``smoothing_layers``).

    Why: the set must not depend on which nodes moved by exactly zero. A sticking pair that
    stays node to node (moment-free forces: its objective slip rate vanishes) wants a slide of
    ~0 +- the solver's noise; its node then moves (remapped, its cells corrected) in one
    augmentation and not at all (slide below ``ale.slide_tolerance``) in the next. With the
    cells taken from the moved nodes only, the correction's velocities then jumped by up to
    2e-3 around the node (tilted blocks, mu = 10, step 35), the normal rates by 3e-6, and the
    augmentations cycled without converging (docs/theory.md, "Moment-free pair forces")."""
    motion = setup.motion
    near = np.zeros(setup.n_nodes, bool)
    near[motion.cells[touched].ravel()] = True
    if active is None or np.size(active) == 0:
        return near
    seeds = np.zeros(setup.n_nodes, bool)
    seeds[np.asarray(active, dtype=np.int64)] = True
    layers = max(m.smoothing_layers if m.interior != "minimal" else 0 for m in setup.motions)
    return near | motion.within_layers(seeds, layers + 1)


def body_mass(X: NDArray, cells: NDArray, rho: NDArray, lumped: bool) -> sp.csr_matrix:
    """The body's scalar nodal mass (consistent, or lumped by row sums) for material
    positions X (the same element masses as the time loop's ``dynamics.mass``)."""
    return _assemble_mass(element_mass(X[cells], rho), cells, len(X), lumped)


def _assemble_mass(me: NDArray, cells: NDArray, n: int, lumped: bool,
                   pattern: CsrPattern | None = None) -> sp.csr_matrix:
    if lumped:
        return sp.diags(np.bincount(cells.ravel(), me.sum(axis=2).ravel(), n), format="csr")
    return (pattern or CsrPattern.from_element_dofs(cells, n)).matrix(me)


@dataclass(frozen=True)
class _OldState:
    """What one t_n state of a body gives every augmentation of its step."""

    key: bytes
    element_masses: NDArray
    mass: sp.csr_matrix
    momenta: NDArray
    kinetic: float
    strain_energy: float


class _BodyData:
    """Per ALE body: its cells, densities and strain-energy kernels, and its last t_n state
    (the augmentations of a step move the same t_n state again)."""

    def __init__(self, model: Model, setup: AleSetup) -> None:
        self.model, self.setup = model, setup
        self.rows = slice(setup.node_offset, setup.node_offset + setup.n_nodes)
        self.cells = setup.motion.cells
        global_cells = model.bodies[setup.body_index].cells
        self.rho = model.assembler.rho[global_cells]
        self.lumped = model.analysis.mass == "lumped"
        self.pattern = CsrPattern.from_element_dofs(self.cells, setup.n_nodes)
        asm = model.assembler
        self.kernels = [NumbaAssembly(g.kind, asm.cells, mine, threads=1)
                        for g in asm.groups
                        if (mine := np.intersect1d(g.elements, global_cells)).size]
        self.last: _OldState | None = None
        models = np.zeros(len(global_cells), np.int64)
        for g in asm.groups:
            models[np.isin(global_cells, g.elements)] = MODEL_CODES[g.kind]
        self.repair = StrainRepair(np.ascontiguousarray(self.cells, dtype=np.int64), models,
                                   np.ascontiguousarray(asm.lam[global_cells]),
                                   np.ascontiguousarray(asm.mu[global_cells]))
        self.last_repair: RepairResult | None = None

    def old_state(self, X: NDArray, d: NDArray, v: NDArray) -> _OldState:
        rows = self.rows
        key = b"".join(np.ascontiguousarray(f[rows]).tobytes() for f in (X, d, v))
        if self.last is None or self.last.key != key:
            me = element_mass(X[rows][self.cells], self.rho)
            mass = _assemble_mass(me, self.cells, self.setup.n_nodes, self.lumped,
                                  self.pattern)
            momenta, kinetic = dof_momenta(mass, X[rows] + d[rows], v[rows])
            self.last = _OldState(key, me, mass, momenta, kinetic,
                                  self._energy(X, d))
        return self.last

    def restore_strain(self, old: _OldState, X: NDArray, d: NDArray, update: AleUpdate,
                       touched: NDArray, free: NDArray, active: NDArray
                       ) -> tuple[AleUpdate, NDArray]:
        """``update`` with the reference positions of the interior nodes around the move
        changed at fixed positions so that the strain energy is the one before the move
        (``ale.strain_repair``), and the cells whose reference image changed. The nodes are
        the free interior nodes of the cells around the moved nodes and the ``active``
        contact nodes, widened by a layer of cells while W cannot reach its target on them
        (up to ``REPAIR_LAYERS``).

        Why the active nodes too: as for the velocity correction (``_correction_nodes``),
        the nodes relabelled must not depend on which slides were exactly zero. A sticking
        pair's node wants a slide of ~0 +- the solver's noise, made in one augmentation
        (above ``ale.slide_tolerance``) and dropped in the next; with the nodes taken around
        the moved ones only, the relabel jumped between the two sets (tilted blocks,
        mu = 10, step 35: |delta| 4.43e-6 and 4.80e-6) and the augmentations cycled."""
        setup, cells = self.setup, self.cells
        X_old, d_old = X[self.rows], d[self.rows]
        free_node = free.reshape(-1, 2).all(axis=1) & ~setup.motion.boundary
        weights = self._nodal_area(X_old)
        seeds = update.moved.copy()
        seeds[np.asarray(active, dtype=np.int64)] = True
        result = None
        for layers in range(1, REPAIR_LAYERS + 1):
            allowed = setup.motion.within_layers(seeds, layers) & free_node
            if not allowed.any():
                continue
            around = np.flatnonzero((allowed | update.moved)[cells].any(axis=1))
            target = self.repair.energy(X_old, d_old, around)
            scale = max(abs(target), abs(old.strain_energy), 1e-300)
            result = restore_strain_energy(self.repair, update.X, update.x_mesh, allowed,
                                           weights, around, target, REPAIR_RTOL * scale,
                                           REPAIR_ROUND_OFF * scale)
            if result.restored:
                break
        self.last_repair = result
        if result is None or not result.restored:
            return update, touched
        X_new = result.X
        return replace(update, X=X_new, d=update.x_mesh - X_new), np.union1d(touched, around)

    def _nodal_area(self, X_local: NDArray) -> NDArray:
        """Lumped reference areas of the nodes (the repair's norm weights)."""
        xc = X_local[self.cells]
        d1, d2 = xc[:, 2] - xc[:, 0], xc[:, 3] - xc[:, 1]
        area = 0.5 * np.abs(d1[:, 0] * d2[:, 1] - d1[:, 1] * d2[:, 0])
        out = np.bincount(self.cells.ravel(), np.repeat(area / 4.0, 4), self.setup.n_nodes)
        return np.where(out > 0.0, out, 1.0)

    def mass_after(self, old: _OldState, X_local: NDArray, touched: NDArray) -> sp.csr_matrix:
        """The body's mass with the cells ``touched`` on their new reference images."""
        me = old.element_masses.copy()
        me[touched] = element_mass(X_local[self.cells[touched]], self.rho[touched])
        return _assemble_mass(me, self.cells, self.setup.n_nodes, self.lumped, self.pattern)

    def strain_energy(self, X: NDArray, d: NDArray, update: AleUpdate) -> float:
        """The body's strain energy on the moved mesh."""
        X_new, d_new = X.copy(), d.copy()
        X_new[self.rows], d_new[self.rows] = update.X, update.d
        return self._energy(X_new, d_new)

    def _energy(self, X: NDArray, d: NDArray) -> float:
        asm = self.model.assembler
        force = np.zeros(asm.ndof)
        X, d = np.ascontiguousarray(X), np.ascontiguousarray(d)
        return sum(k.add(X, d, asm.lam, asm.mu, asm.pattern.entry_map, force, None)
                   for k in self.kernels)


def _body_data(model: Model, setup: AleSetup) -> _BodyData:
    """The body's data, built once and kept with the body's mesh-motion state (so it lives
    as long as the model)."""
    kept = setup.motion._last_state.get("conservation")
    if kept is None or kept.setup is not setup or kept.model is not model:
        kept = _BodyData(model, setup)
        setup.motion._last_state["conservation"] = kept
    return kept


def _free_mask(model: Model, node_offset: int, n_nodes: int, time: float) -> NDArray[np.bool_]:
    """Mask of the local dofs of the body at ``node_offset`` that no support prescribes."""
    fixed, _ = dirichlet_values(model.prescribed, time, model.ndof)
    return ~np.isin(np.arange(2 * node_offset, 2 * (node_offset + n_nodes)), fixed)
