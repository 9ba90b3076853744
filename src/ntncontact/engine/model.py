"""The static description of a simulation: bodies stacked into global arrays, loads, supports."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from itertools import accumulate
from typing import Literal

import numpy as np
from numpy.typing import NDArray

from ..ale.motion import AleBody
from ..contact.augmentation import AugmentationTolerances
from ..contact.laws import ContactLaw
from ..contact.surfaces import Interface
from ..fem.assembly import Assembler, MaterialGroup
from ..fem.loads import LoadCase, Prescribed
from ..materials.models import Material
from ..mesh.quadmesh import QuadMesh
from ..solvers.linear import Precision
from .ties import Tie

MeshMotion = Literal["lagrangian", "ale"]


@dataclass(frozen=True)
class Body:
    """One solid: its mesh (reference configuration), material and place in the global arrays."""

    name: str
    mesh: QuadMesh
    material: Material
    node_offset: int
    cell_offset: int
    initial_velocity: tuple[float, float] = (0.0, 0.0)
    initial_angular_velocity: float = 0.0
    mesh_motion: MeshMotion = "lagrangian"

    @property
    def nodes(self) -> NDArray:
        """Global node indices of this body."""
        return np.arange(self.node_offset, self.node_offset + self.mesh.n_nodes)

    @property
    def cells(self) -> NDArray:
        """Global element indices of this body."""
        return np.arange(self.cell_offset, self.cell_offset + self.mesh.n_cells)

    def global_nodes(self, set_name: str) -> NDArray:
        return self.mesh.node_set(set_name) + self.node_offset

    def global_edges(self, set_name: str) -> NDArray:
        return self.mesh.edge_set(set_name) + self.node_offset


@dataclass(frozen=True)
class AnalysisSettings:
    """Time integration and solver controls."""

    kind: Literal["static", "dynamic"] = "dynamic"
    dt: float = 0.01
    t_end: float = 1.0
    mass: Literal["consistent", "lumped"] = "consistent"
    output_interval: float | None = None
    max_cutbacks: int = 4
    newton_rtol: float = 1e-10
    newton_max_iterations: int = 25
    #: Newton of an augmentation that may not be the last stops once |R| <= this x its start
    newton_inexact_augmentations: float = 1e-4
    #: how PARDISO factors Newton's matrices (solvers.linear.LinearSolver's ``precision``)
    factor_precision: Precision = "auto"
    #: modified Newton's kept-factor steps in a row (0: full Newton; NewtonSettings)
    newton_max_reused_steps: int = 4
    energy_conserving: bool = False  # report 5.5: energy multiplier bordering the contact step
    #: dynamic runs: "energy_momentum" (Neo-Hookean internal force by a discrete gradient,
    #: docs/theory.md) or "midpoint" (the report's mid-point rule)
    integrator: Literal["midpoint", "energy_momentum"] = "energy_momentum"
    #: field frames: "vtu" (PVD + VTU files) or "xdmf" (one XDMF + HDF5 time series)
    field_format: Literal["vtu", "xdmf"] = "vtu"
    #: contact.csv's rows: every step's ("steps"), the field frames' steps' ("frames"), none
    contact_output: Literal["steps", "frames", "none"] = "steps"

    def __post_init__(self) -> None:
        # the scenario validation says the same with the file and key; this guards the API
        # (a non-finite or denormal step would overflow the step count or run forever)
        if not (0.0 < self.dt <= self.t_end < math.inf):
            raise ValueError(f"analysis needs 0 < dt <= t_end < inf, got dt = {self.dt!r}, "
                             f"t_end = {self.t_end!r}")
        if not self.t_end / self.dt < math.inf:
            raise ValueError(f"analysis: t_end / dt = {self.t_end!r} / {self.dt!r} overflows")


@dataclass(frozen=True)
class Model:
    """Everything a run needs that does not change with time."""

    bodies: tuple[Body, ...]
    analysis: AnalysisSettings
    loads: LoadCase
    prescribed: tuple[Prescribed, ...]
    X0: NDArray  # stacked reference coordinates (n, 2)
    cells: NDArray  # stacked connectivity in global node numbers (ne, 4)
    assembler: Assembler = field(repr=False)
    interfaces: tuple[ContactInterface, ...] = ()
    ale_bodies: tuple[AleSetup, ...] = ()  # one per body with mesh_motion = "ale"
    ties: tuple[Tie, ...] = ()  # [[tie]] constraints between bodies (ntncontact.engine.ties)

    @property
    def n_nodes(self) -> int:
        return int(self.X0.shape[0])

    @property
    def ndof(self) -> int:
        return 2 * self.n_nodes

    def body(self, name: str) -> Body:
        for b in self.bodies:
            if b.name == name:
                return b
        raise KeyError(f"no body named '{name}' (bodies: {[b.name for b in self.bodies]})")

    def body_of_cell(self) -> NDArray:
        """Body index of each global element."""
        return np.concatenate([np.full(b.mesh.n_cells, i) for i, b in enumerate(self.bodies)])

    def body_of_node(self) -> NDArray:
        """Body index of each global node."""
        return np.concatenate([np.full(b.mesh.n_nodes, i) for i, b in enumerate(self.bodies)])

    def body_at(self, node: int) -> Body:
        """The body of the global node ``node``."""
        return self.bodies[int(self.body_of_node()[node])]


def stack_bodies(
    meshes: list[tuple[str, QuadMesh, Material]],
) -> tuple[list[tuple[str, QuadMesh, Material, int, int]], NDArray, NDArray, Assembler]:
    """Offsets, stacked coordinates and connectivity, and the assembler of all bodies."""
    node_offsets = accumulate((m.n_nodes for _, m, _ in meshes), initial=0)
    cell_offsets = accumulate((m.n_cells for _, m, _ in meshes), initial=0)
    placed = [(*entry, n, c) for entry, n, c in zip(meshes, node_offsets, cell_offsets,
                                                      strict=False)]  # the totals unused
    X0 = np.vstack([m.nodes for _, m, _ in meshes])
    cells = np.vstack([m.cells + off for (_, m, _, off, _) in placed])
    lam = np.concatenate([np.full(m.n_cells, mat.effective_lambda) for _, m, mat in meshes])
    mu = np.concatenate([np.full(m.n_cells, mat.mu) for _, m, mat in meshes])
    rho = np.concatenate([np.full(m.n_cells, mat.density) for _, m, mat in meshes])
    kinds = np.concatenate([np.full(m.n_cells, mat.kind) for _, m, mat in meshes])
    groups = [MaterialGroup(kind, np.flatnonzero(kinds == kind).astype(np.int64))
              for kind in ("linear_elastic", "neo_hookean") if np.any(kinds == kind)]
    return placed, X0, cells, Assembler(cells, len(X0), groups, lam, mu, rho)


@dataclass(frozen=True)
class ContactInterface:
    """One contact interface as the time loop uses it (kernels in :mod:`ntncontact.contact`)."""

    name: str
    interface: Interface
    law: ContactLaw
    persistency: bool
    candidates: NDArray  # surface-1 global nodes that may enter the active set
    release_steps: int
    tolerances: AugmentationTolerances
    max_augmentations: int
    ordered_pairing: bool = False  # distinct partners in surface order (ALE partner surface)
    predicted_detection: bool = False  # penetration tested at x + dt v (see interfaces)
    #: "uzawa" (report 5.4) or "newton" (augmentation.newton_update)
    multiplier_update: str = "uzawa"
    #: augmentation.on_limit = "accept": a step whose augmentations ran out keeps its last one
    accept_unconverged: bool = False
    #: arc length of every surface-2 node along surface 2 in the original mesh: ordered
    #: pairing keeps new pairs' surface-2 nodes half their ORIGINAL distance apart
    reference_arc2: NDArray | None = None
    #: dynamic steps: nodes a solve ends inside surface 2 (approaching) are taken in and the
    #: step solved again (contact.active_set_pass; quasi-static steps always do)
    active_set_pass: bool = False
    #: the smaller of the two surfaces' median edge lengths in the original mesh: the contact
    #: spacing h of ``penalty_factor`` and of the penetration warning (summary.json)
    spacing: float = float("nan")


@dataclass(frozen=True)
class AleSetup:
    """An ALE body: its mesh-motion data and place in the global arrays."""

    body_index: int
    node_offset: int
    n_nodes: int
    motion: AleBody  # local numbering; the first contact surface
    #: the body's other contact surfaces, one AleBody each (``ale.multisurface``)
    more_motions: tuple[AleBody, ...] = ()
    # the remap's exact velocity correction (engine.remap_conservation; ``motion`` then adds
    # no rigid correction of its own): momenta, and "total", "kinetic" or "none" energy
    conserve_momentum: bool = False
    conserve_energy: str = "none"
    #: relabel the particles at the moved nodes so that the remap keeps the strain energy
    #: (``ale.strain_repair``; engine.remap_conservation)
    restore_strain: bool = False

    @property
    def motions(self) -> tuple[AleBody, ...]:
        return (self.motion, *self.more_motions)
