"""The remap's exact conservation of momenta and energy for ALE bodies in the time loop.

``ale.motion`` remaps the t_n fields onto the moved nodes; here the remapped velocities are
corrected (``ale.conservation.conserving_correction``: the least mass-norm change) with the
model's own mass matrix (consistent or lumped, as the step and the history use it), so that the
body's linear and angular momentum and its kinetic energy are those the time loop measures
before the move, to round-off:

* ``conserve_energy = "kinetic"``: K after = K before;
* ``"total"`` (default): K after = K before - (W after - W before), W the strain energy of the
  cells the move changed: the remap then conserves the total energy exactly. The strain energy
  a remap changes is first order in the slide (the nodal values of a C0 field with a kink at a
  loaded node are cut by the interpolation), far above anything a higher-order interpolant
  removes; it goes into the velocities of the same neighbourhood (docs/theory.md, "ALE remap
  that conserves energy").

The correction acts on the free dofs of the nodes of the cells around the remapped nodes, and
on all free dofs of the body when those cannot take the energy.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import scipy.sparse as sp
from numpy.typing import NDArray

from ..ale.conservation import conserving_correction, dof_momenta
from ..ale.motion import AleUpdate
from ..fem.element import element_mass
from ..fem.kernels_numba import NumbaAssembly
from ..fem.loads import dirichlet_values
from .model import AleSetup, Model

__all__ = ["conserve_remap"]


def conserve_remap(model: Model, setup: AleSetup, X: NDArray, d: NDArray, v: NDArray,
                   time: float, update: AleUpdate) -> AleUpdate:
    """``update`` (the body's move from the t_n rows X, d, v) with its velocities corrected."""
    motion = setup.motion
    energy = setup.conserve_energy
    if (not update.moved.any() or motion.convection != "remap"
            or (not setup.conserve_momentum and energy == "none")):
        return update
    rows = slice(setup.node_offset, setup.node_offset + setup.n_nodes)
    lumped = model.analysis.mass == "lumped"
    rho = model.assembler.rho[model.bodies[setup.body_index].cells]
    x_old = X[rows] + d[rows]
    momenta, kinetic = dof_momenta(body_mass(X[rows], motion.cells, rho, lumped), x_old,
                                   v[rows])
    if energy == "total":
        kinetic -= _remap_strain_energy(model, setup, X, d, update)
    touched = update.moved[motion.cells].any(axis=1)
    free = _free_dofs(model, setup, time)
    near = np.zeros(setup.n_nodes, bool)
    near[motion.cells[touched].ravel()] = True
    dofs = np.flatnonzero(np.repeat(near, 2) & free)
    mass = body_mass(update.X, motion.cells, rho, lumped)
    target_momenta = momenta if setup.conserve_momentum else None
    target_kinetic = None if energy == "none" else kinetic
    fixed = conserving_correction(mass, update.x_mesh, update.v, dofs, target_momenta,
                                  target_kinetic)
    if not fixed.energy_restored:  # too little motion around the move: the whole body
        fixed = conserving_correction(mass, update.x_mesh, update.v, np.flatnonzero(free),
                                      target_momenta, target_kinetic)
    return replace(update, v=fixed.v)


def body_mass(X: NDArray, cells: NDArray, rho: NDArray, lumped: bool) -> sp.csr_matrix:
    """The body's scalar nodal mass (consistent, or lumped by row sums) for material
    positions X (the same element masses as the time loop's ``dynamics.mass``)."""
    me = element_mass(X[cells], rho)
    n = len(X)
    if lumped:
        return sp.diags(np.bincount(cells.ravel(), me.sum(axis=2).ravel(), n), format="csr")
    rows = np.repeat(cells, 4, axis=1).ravel()
    cols = np.tile(cells, (1, 4)).ravel()
    return sp.csr_matrix((me.ravel(), (rows, cols)), shape=(n, n))


def _free_dofs(model: Model, setup: AleSetup, time: float) -> NDArray[np.bool_]:
    """Mask of the body's local dofs that no support prescribes."""
    fixed, _ = dirichlet_values(model.prescribed, time, model.ndof)
    lo = 2 * setup.node_offset
    local = fixed[(fixed >= lo) & (fixed < lo + 2 * setup.n_nodes)] - lo
    free = np.ones(2 * setup.n_nodes, bool)
    free[local] = False
    return free


def _remap_strain_energy(model: Model, setup: AleSetup, X: NDArray, d: NDArray,
                         update: AleUpdate) -> float:
    """W after - W before the move over the cells it changed (the others keep theirs)."""
    body = model.bodies[setup.body_index]
    changed = body.cells[update.moved[setup.motion.cells].any(axis=1)]
    rows = slice(setup.node_offset, setup.node_offset + setup.n_nodes)
    X_new, x_new = X.copy(), X + d
    X_new[rows], x_new[rows] = update.X, update.x_mesh
    return (_strain_energy(model, changed, X_new, x_new)
            - _strain_energy(model, changed, X, X + d))


def _strain_energy(model: Model, elements: NDArray, X: NDArray, x: NDArray) -> float:
    asm = model.assembler
    force = np.zeros(asm.ndof)
    total = 0.0
    for group in asm.groups:
        mine = np.intersect1d(group.elements, elements)
        if mine.size:
            kernel = NumbaAssembly(group.kind, asm.cells, mine, threads=1)
            total += kernel.add(np.ascontiguousarray(X), np.ascontiguousarray(x), asm.lam,
                                asm.mu, asm.pattern.entry_map, force, None)
    return total
