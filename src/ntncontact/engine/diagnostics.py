"""Energies and momenta of a state (report 6.4: E = E_k + E_s, L = sum M v, L_a = sum x x Mv),
the check that no element is inverted at the end of a step, the search for boundary nodes
inside another body off the contact surfaces, and the ALE bodies' worst degraded cell."""

from __future__ import annotations

import warnings
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass
from itertools import permutations
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from ..contact.kinematics import UndefinedNormalError
from ..fem.loads import dirichlet_values
from ..fem.q4 import DN_GP, InvertedElementError, shape_gradients
from ..mesh.boundary import boundary_edges
from ..mesh.overlap import (
    deepest_overlap,
    deepest_self_overlap,
    edge_size,
    rigid_deviation,
    self_clearance,
)
from ..mesh.quality import cell_min_sines, corner_angles_deg
from ..solvers.newton import NewtonError

if TYPE_CHECKING:
    import scipy.sparse as sp

    from .model import Model


#: A linear elastic body's element turned by more than this (radians) is reported: its small
#: strain then holds the rotation's second-order stretch, 1 - cos(theta) = 0.5 % here, which
#: the linear model takes for a strain without stress or energy
LINEAR_ROTATION_LIMIT = 0.1

#: (8, 4): a cell's nodal values v (a, i) flattened -> the entries (i, j) of dv/dxi at the
#: centre, sum_a v_ai dN_a/dxi_j
_SPREAD_CENTRE = np.einsum("aj,ik->aikj", shape_gradients(np.zeros(1), np.zeros(1))[0],
                           np.eye(2)).reshape(8, 4)


#: a linear elastic body's largest principal Green-Lagrange strain above this (in magnitude) is
#: reported: there the linear stress is no longer that of a finite-strain law. A tester's block
#: (f6_nh_comp.toml, lateral free) at a Green strain of 0.05 (5.1 % compression) carries a linear
#: reaction 4.4 % below the Neo-Hookean one, at 0.095 (10 %) 8.8 % below, at 0.32 (40 %) 38 %
#: below (43.96 against 71.46). 0.1 leaves the report's rod impact (0.067, its 1D linear
#: benchmark) alone; the block sliding and the delamination reach 0.27 and 0.29 at contact
#: corners
LINEAR_STRAIN_LIMIT = 0.1


def linear_elastic_measures(model: Model, X: NDArray, d: NDArray) -> dict[str, tuple[float, str]]:
    """The largest figures of the element centres of the linear elastic bodies, each as
    (value, body), (0, "") without such bodies, from F = I + du/dX there:

    - ``rotation``: the polar rotation, theta = atan2(F21 - F12, F11 + F22) (radians).
      Small-strain elasticity is not rotation-invariant: a tester's spinning block made linear
      elastic kept its energy and momentum while it stretched from 1 x 0.5 to 4 x 6.5 with
      zero stress, and nothing said so;
    - ``stretch``: the largest principal stretch, sqrt of the largest eigenvalue of F^T F.
      The rotation alone cannot tell how far such a body went: its nodes fly off on straight
      lines, F = I + t W, whose polar rotation atan(omega t) stays below pi/2 (1.41 rad after
      a 6 rad spin, whose stretch is 6.1);
    - ``strain``: the largest principal Green-Lagrange strain, in magnitude (objective: 0 in a
      rigid rotation), above LINEAR_STRAIN_LIMIT of which the linear stress is not a
      finite-strain one.

    One F for all three, in closed form on the elements' columns (the 2 x 2 inverse and
    products written out): 2.8 ms a call at 6 x 10^4 elements, against 35 ms by
    ``np.linalg.inv`` and ``einsum`` on stacked 2 x 2 matrices (session 52; the gathers
    of X and d add ~8 ms either way)."""
    found = {key: (0.0, "") for key in ("rotation", "stretch", "strain")}
    for body in model.bodies:
        if body.material.kind != "linear_elastic":
            continue
        cells = model.cells[body.cells]
        if not len(cells):
            continue
        # J = dX/dxi and G = du/dxi at the centre, row-major entries as columns
        (j00, j01, j10, j11), (g00, g01, g10, g11) = (
            (v[cells].reshape(len(cells), 8) @ _SPREAD_CENTRE).T for v in (X, d))
        det = j00 * j11 - j01 * j10
        f00, f01 = 1.0 + (g00 * j11 - g01 * j10) / det, (g01 * j00 - g00 * j01) / det  # I + G J^-1
        f10, f11 = (g10 * j11 - g11 * j10) / det, 1.0 + (g11 * j00 - g10 * j01) / det
        c00, c11, c01 = f00**2 + f10**2, f01**2 + f11**2, f00 * f01 + f10 * f11  # F^T F
        # its eigenvalues (the stretches^2) mean +- root; root = sqrt(mean^2 - det C) without
        # the cancellation that left ~1e-8 of an equal stretch's 2 (sqrt of the round-off)
        mean, root = 0.5 * (c00 + c11), np.hypot(0.5 * (c00 - c11), c01)
        figures = {"rotation": np.abs(np.arctan2(f10 - f01, f00 + f11)),
                   "stretch": np.sqrt(mean + root),
                   "strain": 0.5 * np.maximum(np.abs(mean + root - 1.0),
                                              np.abs(mean - root - 1.0))}
        for key, values in figures.items():
            if values.max() > found[key][0]:
                found[key] = (float(values.max()), body.name)
    return found


class PhysicsWarning(UserWarning):
    """A run whose results are doubtful for a physical reason (penetration, energy gained,
    a law that cannot carry the load): ``ntncontact.run`` issues one per line the command
    prints as ``warning: ...``, so that they can be filtered (``warnings.simplefilter``)."""


@contextmanager
def warnings_noted() -> Iterator[list[str]]:
    """The warnings issued inside, as lines in the yielded list (summary.json
    ``build_warnings``), issued again on leaving, so that the command prints them and Python
    callers see them as before: a sweep's row recorded the summary's warnings only, and lost
    those of the model's build (a tester's penalty under the rate law)."""
    noted: list[str] = []
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        yield noted
    for warning in caught:
        noted.append(str(warning.message))
        warnings.warn_explicit(warning.message, warning.category, warning.filename,
                               warning.lineno)


@dataclass(frozen=True)
class Balance:
    kinetic_energy: float
    strain_energy: float
    linear_momentum: tuple[float, float]
    angular_momentum: float

    @property
    def total_energy(self) -> float:
        return self.kinetic_energy + self.strain_energy


def balance(mass: sp.spmatrix, x: NDArray, v: NDArray, strain_energy: float) -> Balance:
    """Kinetic energy 1/2 v.Mv, linear momentum sum_a (Mv)_a, angular momentum about the origin.

    ``mass`` is the scalar (per node) mass matrix, or the mass on the dofs (x_a, y_a
    interleaved: the nodal one times the 2 x 2 identity), ``x`` current positions, ``v``
    velocities. The angular momentum sum_ab M_ab x_a x v_b is the quantity the mid-point rule
    conserves exactly.
    """
    if mass.shape[0] == v.shape[0]:
        p = mass @ v  # nodal momenta (n, 2)
    else:
        p = (mass @ v.ravel()).reshape(v.shape)
    kinetic = 0.5 * float(np.sum(v * p))
    angular = float(np.sum(x[:, 0] * p[:, 1] - x[:, 1] * p[:, 0]))
    return Balance(kinetic, strain_energy, (float(p[:, 0].sum()), float(p[:, 1].sum())), angular)


def energy_balance(total: NDArray, external_work: NDArray,
                   contact_work: NDArray | float = 0.0) -> tuple[NDArray, float]:
    """The energy balance error B_n = E_n - E_0 - W_ext,n - W_contact,n at every output step
    (cumulative works, as history.csv has them) and its scale S: the largest magnitude any of
    E, W_ext and W_contact reached. B / S is the relative error. The scale is not E_0: a body
    may start at rest (E_0 = 0), and loads may pump many times E_0 into it; the error of a
    ledger is relative to the largest energy it carries."""
    total = np.asarray(total, float)
    external = np.broadcast_to(np.asarray(external_work, float), total.shape)
    contact = np.broadcast_to(np.asarray(contact_work, float), total.shape)
    error = total - total[0] - external - contact
    scale = float(max(np.abs(total).max(), np.abs(external).max(), np.abs(contact).max()))
    return error, scale


class EnergyAudit:
    """Running energy statistics of a run for summary.json (see :func:`energy_balance`):

    - ``energy_balance_max_relative_error``: max_n |B_n| / S, the headline figure: it stays
      small with loads and contact when the time integration is sound;
    - ``energy_balance_max_error``: max_n |B_n|;
    - ``energy_max_change``: max_n |E_n - E_0|, the raw change of the energy E = kinetic +
      strain, which loads and contact change by design (``energy_max_relative_variation``
      keeps its old meaning, this divided by |E_0|).
    """

    KEYS = ("energy_balance_max_relative_error", "energy_balance_max_error", "energy_max_change")

    def __init__(self) -> None:
        self.initial: float | None = None
        self.scale = self.max_error = self.max_change = 0.0

    def add(self, total_energy: float, external_work: float,
            contact_work: float = 0.0) -> dict[str, float | None]:
        """Take one step's energy and cumulative works; return the summary fields."""
        if self.initial is None:
            self.initial = float(total_energy)
        change = float(total_energy) - self.initial
        self.max_change = max(self.max_change, abs(change))
        self.max_error = max(self.max_error,
                             abs(change - float(external_work) - float(contact_work)))
        self.scale = max(self.scale, abs(float(total_energy)), abs(float(external_work)),
                         abs(float(contact_work)))
        relative = self.max_error / self.scale if self.scale > 0.0 else None
        return dict(zip(self.KEYS, (relative, self.max_error, self.max_change), strict=True))


#: dN_a/dxi_j at the Gauss points as a (node a, Gauss point g * direction j) matrix.
_DN_BY_NODE = DN_GP.transpose(1, 0, 2).reshape(4, 8)


class InvertedAtStepEnd(InvertedElementError):
    """An element inverted in the configuration a converged step ends in. It is an
    :class:`InvertedElementError`, so the step is cut back like a failed Newton solve."""

    def __init__(self, model: Model, element: int, value: float, time: float) -> None:
        body = model.bodies[int(model.body_of_cell()[element])]
        self.body, self.local = body.name, int(element) - body.cell_offset
        self.element, self.value, self.time = int(element), float(value), float(time)
        label = element_label(model, self.element)
        ValueError.__init__(
            self, f"{label} is inverted at the end of the step to t = {self.time:.6g} "
            f"(det J = {self.value:.3e} at a quadrature point)")


def element_label(model: Model, element: int) -> str:
    """A global element named as a user finds it: its body, its number there, the number of
    the file it was read from, and its centre in the reference mesh (run errors named only
    the package's 0-based numbers, which a gmsh file numbers otherwise and no viewer shows)."""
    body = model.bodies[int(model.body_of_cell()[element])]
    local = element - body.cell_offset
    numbers = f"global element {element}"
    ids = body.mesh.file_element_ids
    if ids is not None and ids[local] >= 0:
        numbers += f", file element {int(ids[local])}"
    centre = body.mesh.nodes[body.mesh.cells[local]].mean(axis=0)
    return (f"element {local} of body '{body.name}' ({numbers}; centred at "
            f"({centre[0]:.6g}, {centre[1]:.6g}) in the reference mesh)")


def check_end_of_step(model: Model, x: NDArray, time: float) -> None:
    """Raise :class:`InvertedAtStepEnd` for the element with the smallest det J <= 0 at the
    2 x 2 Gauss points of the end-of-step positions ``x`` (n, 2). The step's solve evaluates
    the mid-point configuration only, and x_{n+1} = 2 x_{n+1/2} - x_n can invert an element
    that the mid-point configuration leaves valid."""
    # J[e, i, g, j] = dx_i / dxi_j at Gauss point g: one matrix product (4x faster than the
    # equivalent einsum on the ring impact's 352 elements: 0.4 against 1.4 ms under load)
    J = np.matmul(x[model.cells].transpose(0, 2, 1), _DN_BY_NODE).reshape(-1, 2, 4, 2)
    det = (J[:, 0, :, 0] * J[:, 1, :, 1] - J[:, 0, :, 1] * J[:, 1, :, 0]).min(axis=1)
    bad = ~(det > 0.0)  # NaN positions too
    if not bad.any():
        return
    element = int(np.flatnonzero(bad)[np.argmin(np.nan_to_num(det[bad], nan=-np.inf))])
    raise InvertedAtStepEnd(model, element, float(det[element]), time)


def named_failure(model: Model, err: BaseException) -> str:
    """The message of a step's failure; an inverted element found by the solve (numbered
    globally), or by every trial of its line search, is named once, by its body and its
    number there (the global message with the body appended read "element 4 is inverted
    ...: element 4 of body 'block'")."""
    inverted = err.__cause__ if isinstance(err, NewtonError) else err
    if isinstance(inverted, UndefinedNormalError):
        return str(err).replace(str(inverted), _named_normal(model, inverted))
    if isinstance(inverted, InvertedElementError) \
            and not isinstance(inverted, InvertedAtStepEnd) \
            and 0 <= inverted.element < len(model.cells):
        named = inverted.named(element_label(model, inverted.element))
        return str(err).replace(str(inverted), named)
    columns = getattr(inverted, "columns", None)
    if columns is not None:
        return f"{err}{_singular_where(model, np.asarray(columns))}"
    return f"{err}{_friction_hint(model, err)}"


def _named_normal(model: Model, err: UndefinedNormalError) -> str:
    """An undefined contact normal named by its interface and the bodies' own node numbers,
    with the place where the chain neighbours coincide."""
    def node(n: int) -> str:
        body = model.body_at(n)
        ids = body.mesh.file_node_ids
        local = n - body.node_offset
        file = f" (file node {int(ids[local])})" if ids is not None and ids[local] >= 0 else ""
        return f"node {local} of body '{body.name}'{file}"

    names = [ci.name for ci in model.interfaces
             if np.isin(err.node, ci.interface.surface1.nodes)
             and np.isin(err.partner, ci.interface.surface2.nodes)]
    where = f"interface '{names[0]}': " if names else ""
    place = ("" if err.position is None
             else f" at ({err.position[0]:.6g}, {err.position[1]:.6g})")
    return (f"{where}a contact normal is undefined: the chain neighbours {node(err.chord[0])} "
            f"and {node(err.chord[1])} coincide{place} (the normal of the pair "
            f"{node(err.node)} - {node(err.partner)}; a crushed contact surface, or a body of "
            "zero size)")


def _friction_hint(model: Model, err: BaseException) -> str:
    """Why Newton may not converge with friction: with a stiff tangential penalty the pairs'
    stick and slip can cycle from iteration to iteration (Hertz with mu = 0.3 and no
    cut-backs: |R| 2e4 after 40 iterations at step 10 with penalty_tangential 1e6, by either
    method, and it converges with 1e5; a tester's Cattaneo-Mindlin case with exact normal
    multipliers cycled between |R| 0.5 and 300, where the augmented Lagrangian converged:
    the multipliers move the Coulomb cap mu t_N at every iteration). A tangential penalty
    below :data:`SOFT_TANGENTIAL` of the normal one is not called stiff (a tester's 0.01 was)."""
    frictional = [ci for ci in model.interfaces if ci.law.frictional]
    if not isinstance(err, NewtonError) or not frictional:
        return ""
    ci = frictional[0]
    if ci.law.method == "lagrange":  # no normal penalty to measure eps_T against
        cure = ("the exact normal multipliers move the Coulomb cap at every iteration; "
                "method = \"augmented_lagrangian\" (its cap moves between augmentations "
                f"only), or a softer penalty_tangential ({ci.law.eps_T:.3g}), may converge")
    elif ci.law.eps_T >= SOFT_TANGENTIAL * ci.law.eps_N:
        cure = (f"with a stiff penalty_tangential ({ci.law.eps_T:.3g}) the pairs' stick "
                "and slip can cycle in Newton; a softer one may converge")
    else:
        return ""
    return f" (interface '{ci.name}' has friction: {cure})"


#: A tangential penalty below this fraction of the normal one is soft for ``_friction_hint``.
SOFT_TANGENTIAL = 0.01


def _singular_where(model: Model, columns: NDArray) -> str:
    """Where a singular matrix leaves a motion free: the bodies and directions of the free
    dofs it moves (``columns``: the Newton matrix's first unknowns are the dofs no support
    prescribes, in order; the rest are multipliers). A tester's unsupported static block was
    reported without a body."""
    fixed, _ = dirichlet_values(model.prescribed, 0.0, model.ndof)
    free = np.setdiff1d(np.arange(model.ndof), fixed)
    dofs = free[columns[columns < free.size]]
    if not dofs.size:
        return ""
    of_node = model.body_of_node()[dofs // 2]
    parts = [f"'{model.bodies[int(b)].name}' "
             f"({' and '.join(sorted({'xy'[d % 2] for d in dofs[of_node == b]}))})"
             for b in np.unique(of_node)]
    light = [_lost_inertia(model, model.bodies[int(b)]) for b in np.unique(of_node)]
    return (f": the free motion moves the dofs of body {', '.join(parts)}"
            + "".join(f"; {note}" for note in light if note))


#: A body's inertia rho h^2/dt^2 below this fraction of its stiffness (~E) is lost to the
#: stiffness's round-off: the matrix is singular as if the body had no mass (a tester's
#: density 1e-300 was reported with the supports as the only cause).
LOST_INERTIA = 1e-14


def _lost_inertia(model: Model, body) -> str:
    """A note when a dynamic body's inertia is lost to round-off in the step's matrix (what
    held its free motions), naming its density; "" otherwise."""
    material = body.material
    stiffness = material.mu * 2.0 + material.lam
    if model.analysis.kind != "dynamic" or not stiffness > 0.0:
        return ""
    nodes = body.mesh.nodes
    size = float(np.ptp(nodes, axis=0).max()) / max(np.sqrt(body.mesh.n_cells), 1.0)
    inertia = material.density * size**2 / model.analysis.dt**2
    if not inertia < LOST_INERTIA * stiffness:
        return ""
    return (f"body '{body.name}' has an inertia (density h^2/dt^2 = {inertia:.3g}) lost to "
            f"the round-off of its stiffness ({stiffness:.3g}): check the units of its "
            f"density ({material.density:.3g})")


@dataclass(frozen=True)
class ContactMoment:
    """The net moment of one interface's contact forces (the worst interface's, 0.0 and no
    interface when none carries force): ``relative`` = |moment| / (``force`` ``length``)."""

    relative: float = 0.0
    interface: str = ""
    moment: float = 0.0  # about the origin, signed as the reactions' (history.csv): see below
    force: float = 0.0  # sum over the nodes of |f|
    length: float = 0.0  # the largest extent of the nodes that carry force


def contact_moment(interfaces: Sequence, results: Sequence, x: NDArray) -> ContactMoment:
    """The worst interface's net moment of its contact forces (summary.json
    ``max_contact_moment_imbalance``). The forces of an interface act between its two bodies
    only, so they should exert no net moment; the report's pair force (``moment_free =
    false``) of a pair whose nodes are offset along the surface is not along the line that
    joins them, and its couple is taken up by the supports: a tester's static press on a
    non-matching Lagrangian base read a reaction moment of 79.88 where the loads needed
    78.06, with force reactions exact and no warning. The sum over the nodes of x_i x f_i of
    ``ContactResult.force`` (the pair nodes and those the transfer spread the forces to,
    ``x``: where the solve evaluated them) is taken about the loaded nodes' centroid (the net
    force is zero, so the point does not matter, and coordinates far from the origin add no
    round-off) and divided by the sum of |f_i| times the loaded nodes' largest extent.
    ``moment`` is the same sum about the origin, in the residual's sign, which the support
    reactions use: in a static step it is the reactions' moment plus the loads'."""
    worst = ContactMoment()
    for ci, res in zip(interfaces, results, strict=True):
        if res is None:
            continue
        f = np.asarray(res.force).reshape(-1, 2)
        loaded = np.flatnonzero(np.any(f != 0.0, axis=1))
        if loaded.size < 2:
            continue
        f, p = f[loaded], x[loaded]
        force, length = float(np.linalg.norm(f, axis=1).sum()), float(np.ptp(p, axis=0).max())
        if force == 0.0 or length == 0.0:
            continue
        q = p - p.mean(axis=0)
        about_centroid = float(np.sum(q[:, 0] * f[:, 1] - q[:, 1] * f[:, 0]))
        relative = abs(about_centroid) / (force * length)
        if relative > worst.relative or not worst.interface:  # 0 exactly is a measure too
            moment = float(np.sum(p[:, 0] * f[:, 1] - p[:, 1] * f[:, 0]))
            worst = ContactMoment(relative, ci.name, moment, force, length)
    return worst


NO_NODES = np.zeros(0, np.int64)


@dataclass(frozen=True)
class OffSurfacePenetration:
    """The deepest boundary node of a body inside another body, among the nodes on none of
    that pair of bodies' contact surfaces (depth 0.0 and no node when none)."""

    depth: float = 0.0
    body: str = ""
    node: int = -1  # local to ``body``
    other: str = ""
    size: float = 1.0  # the other body's median boundary edge (reference): depth's scale
    joined: bool = True  # False: no contact interface joins the two bodies


class PenetrationCheck:
    """Finds what contact cannot see (summary.json ``max_penetration_off_surfaces``): a
    boundary node of one body inside another body, while the node is on none of the contact
    surfaces between the two. Contact acts on its surfaces only, so such a node passes
    through unresisted: a face that is no contact surface rolling into the partner (the
    fast-sliding blocks refined 2x with mu = 0.3: the leading face 0.023 deep, a run that
    otherwise completes), or two bodies that no interface joins at all (a body named in the
    wrong ``[[contact]]``). Tied bodies are joined, not checked. Penetration at the surfaces is
    the pairs' (``max_penetration``). Measured cost: 0.13 ms a step on the ring impact, 0.7 %
    of its run (of the fast-sliding blocks' too); a pair of bodies apart costs a bounding-box
    test. The test is ``mesh.overlap.deepest_overlap``."""

    def __init__(self, model: Model) -> None:
        outline = [_outline(model, body) for body in model.bodies]
        boundary = [np.unique(edges) for _, edges, _ in outline]
        covered = _surfaces_between(model)
        # (body, partner, its nodes on no surface facing the partner, the partner's cells,
        # edges and edge size, whether an interface joins the two)
        self._tests = []
        for a, b in _pairs_to_check(model, covered):
            facing = np.concatenate(covered.get((a, b), [NO_NODES]))
            self._tests.append((model.bodies[a], model.bodies[b],
                                np.setdiff1d(boundary[a], facing), *outline[b], (a, b) in covered))
        self._outline = {body.name: nodes for body, nodes in zip(model.bodies, boundary,
                                                                 strict=True)}

    def deepest(self, x: NDArray) -> OffSurfacePenetration:
        """The deepest such node at the positions ``x``."""
        worst = OffSurfacePenetration()
        boxes = {}  # per body: the bounding box of its boundary nodes at x
        for body, partner, nodes, cells, edges, size, joined in self._tests:
            if nodes.size == 0 or not _boxes_meet(boxes, body, partner, x, self._outline):
                continue
            found = deepest_overlap(x[nodes], x, cells, edges, size)
            if found is not None and found.depth > worst.depth:
                worst = OffSurfacePenetration(found.depth, body.name,
                                              int(nodes[found.point]) - body.node_offset,
                                              partner.name, size, joined)
        return worst


@dataclass(frozen=True)
class UnpairedPenetration:
    """The deepest surface-1 node in no pair inside its interface's partner body (depth 0.0
    and no node when none)."""

    depth: float = 0.0
    interface: str = ""
    node: int = -1  # global, as in contact.csv


class UnpairedCheck:
    """Finds the contact-surface nodes that no pair holds and that lie inside the partner
    body (summary.json ``max_penetration_unpaired``): a surface finer than its partner has
    nodes between the pairs (an ALE partner's ordered pairing gives one partner node each,
    docs/theory.md "Partners at any spacing ratio"), and nothing resists them. A tester's
    puck five times finer than its ALE foundation had such nodes 41 % deeper than the deepest
    pair, which was all ``max_penetration`` reported. The test is ``deepest_overlap``, as for
    the nodes off the surfaces. Measured cost with every ring node unpaired and 0.1 inside
    the obstacle (its worst case): 0.33 ms a step on the ring impact (1.7 % of its step),
    4.8 ms refined 8x (0.7 %)."""

    def __init__(self, model: Model) -> None:
        # (name, candidates, partner cells, partner edges, partner edge size)
        self._tests = [(ci.name, np.asarray(ci.candidates, np.int64),
                        *_outline(model, model.body_at(ci.interface.surface2.nodes[0])))
                       for ci in model.interfaces]

    def deepest(self, x: NDArray, states) -> UnpairedPenetration:
        """The deepest such node at the positions ``x`` with the interfaces' pairs ``states``."""
        return _deepest_inside(x, [(name, nodes[~np.isin(nodes, state.pairs[:, 0])], *rest)
                                   for (name, nodes, *rest), state in zip(self._tests, states,
                                                                          strict=True)])


class SurfaceTwoCheck:
    """Finds the surface-2 nodes inside surface 1's body (summary.json
    ``max_penetration_surface_2``), the mirror of :class:`UnpairedCheck`: a pair's depth is
    measured at its surface-1 node along that node's normal, so a sharp corner on surface 2
    cutting into a flat surface 1 between its nodes showed in no key (a tester's 45-degree
    square's corner 0.0445 below the block's top, 0.71 of the spacing, with
    ``max_penetration`` 0.0). All surface-2 nodes are tested, paired or not: the warning
    compares the deepest with the pairs'. Measured cost (CPU): 0.23 ms a step on the ring
    impact (0.9 % of its step), 0.20 ms on the disk drop (0.7 %)."""

    def __init__(self, model: Model) -> None:
        # (name, surface-2 nodes, partner cells, partner edges, edge size)
        self._tests = [(ci.name, np.unique(ci.interface.surface2.nodes),
                        *_outline(model, model.body_at(ci.interface.surface1.nodes[0])))
                       for ci in model.interfaces]

    def deepest(self, x: NDArray) -> UnpairedPenetration:
        """The deepest surface-2 node inside its interface's surface-1 body at ``x`` (the
        interface and the global node, as :class:`UnpairedCheck` gives them)."""
        return _deepest_inside(x, self._tests)


def _outline(model: Model, body) -> tuple[NDArray, NDArray, float]:
    """A body's cells and boundary edges (global nodes) and its median boundary edge."""
    edges = boundary_edges(body.mesh.cells) + body.node_offset
    return model.cells[body.cells], edges, edge_size(model.X0, edges)


def _deepest_inside(x: NDArray, tests: list) -> UnpairedPenetration:
    """The deepest node of the tests (interface name, nodes, and the cells, edges and edge
    size of the body they are tested against) inside that body at ``x``."""
    worst = UnpairedPenetration()
    for name, nodes, cells, edges, size in tests:
        found = deepest_overlap(x[nodes], x, cells, edges, size) if nodes.size else None
        if found is not None and found.depth > worst.depth:
            worst = UnpairedPenetration(found.depth, name, int(nodes[found.point]))
    return worst


@dataclass(frozen=True)
class SelfPenetration:
    """The deepest boundary node of a body inside one of its own cells (depth 0.0 and no node
    when none)."""

    depth: float = 0.0
    body: str = ""
    node: int = -1  # global, as the other checks' file_node needs it
    size: float = 1.0  # the body's median boundary edge (reference): depth's scale


class SelfCrossingCheck:
    """Finds a body that passed through itself (summary.json ``max_self_penetration``): a
    boundary node inside one of the body's own cells that it is not a corner of
    (``mesh.overlap.deepest_self_overlap``). Self contact is not modelled, so a tester's thin
    ring folded by a fast impact (15 % of c) crossed itself into a figure-eight, 80 of its
    nodes inside its own cells, and the run completed with an energy balance of 3e-12 and no
    word of it.

    A body is searched only when its nodes moved farther from a rigid motion of the last
    configuration found clean than half that configuration's clearance (its boundary nodes'
    distance to the cells they are not corners of): distances then changed too little for a
    fold (``mesh.overlap.rigid_deviation``, ``self_clearance``). Measured cost (CPU): 0.22 ms
    a step on the ring impact (0.9 % of its step; searching every body every step took
    0.73 ms, 3.1 %), 0.33 ms on the disk drop (1.2 %: the disk never needs a search, its ALE
    block's sliding mesh often does).

    A clean search makes its configuration the new reference only when the body moved less
    than the old reference's half clearance a step on average since that reference: a body
    that deforms more than that each step (Hertz's cylinder: its contact zone's cells are
    small, its load steps large) is searched the next step whatever the reference, and
    measuring its clearance every step cost more than the search (Hertz refined 8x: 48 ms a
    step against the search's 24, 2.1 s steps). The old reference stays valid: it was found
    clean and its clearance measured, so skipping against it stays safe; which steps are
    searched changes, what a search finds does not."""

    def __init__(self, model: Model) -> None:
        # per body: it, its nodes, boundary nodes, cells, boundary edges, edge size (global
        # numbers), and the reference: a clean configuration of its nodes with half its
        # clearance, and the steps checked since it was taken
        self._tests = []
        self._clean: list[tuple[NDArray, float]] = []
        self._steps: list[int] = []
        for body in model.bodies:
            cells, edges, size = _outline(model, body)
            boundary = np.unique(edges)
            self._tests.append((body, np.unique(cells), boundary, cells, edges, size))
            self._clean.append(self._clearance(model.X0, boundary, cells))
            self._steps.append(0)

    @staticmethod
    def _clearance(x: NDArray, boundary: NDArray, cells: NDArray) -> tuple[NDArray, float]:
        """A clean configuration of the body's nodes and half its clearance."""
        nodes = np.unique(cells)
        return x[nodes].copy(), 0.5 * self_clearance(boundary, x, cells)

    def deepest(self, x: NDArray) -> SelfPenetration:
        """The deepest such node at the positions ``x``."""
        worst = SelfPenetration()
        for k, (body, nodes, boundary, cells, edges, size) in enumerate(self._tests):
            reference, reach = self._clean[k]
            self._steps[k] += 1
            deviation = rigid_deviation(reference, x[nodes])
            if deviation < reach:
                continue  # no distance in the body changed enough to fold it
            found = deepest_self_overlap(boundary, x, cells, edges, size)
            if found is None:
                if deviation < reach * self._steps[k]:  # slow enough: a reference pays
                    self._clean[k] = self._clearance(x, boundary, cells)
                    self._steps[k] = 0
            elif found.depth > worst.depth:
                worst = SelfPenetration(found.depth, body.name, int(boundary[found.point]),
                                        size)
        return worst


def _boxes_meet(boxes: dict, body, partner, x: NDArray, outline: dict) -> bool:
    """Whether the bounding boxes of the two bodies' boundary nodes at ``x`` overlap: bodies
    apart cost this test only (many bodies make many pairs)."""
    for b in (body, partner):
        if b.name not in boxes:
            points = x[outline[b.name]]
            boxes[b.name] = (points.min(axis=0), points.max(axis=0))
    (low_1, high_1), (low_2, high_2) = boxes[body.name], boxes[partner.name]
    return bool(np.all(low_1 <= high_2) and np.all(low_2 <= high_1))


def _surfaces_between(model: Model) -> dict[tuple[int, int], list]:
    """(body, partner) -> the body's contact-surface nodes facing the partner, per interface."""
    owner = model.body_of_node()
    covered: dict[tuple[int, int], list] = {}
    for ci in model.interfaces:
        s1, s2 = ci.interface.surface1.nodes, ci.interface.surface2.nodes
        b1, b2 = int(owner[s1[0]]), int(owner[s2[0]])
        covered.setdefault((b1, b2), []).append(s1)
        covered.setdefault((b2, b1), []).append(s2)
    return covered


def _pairs_to_check(model: Model, covered: dict) -> list[tuple[int, int]]:
    """Every ordered pair of distinct bodies but those tied and joined by no interface
    (their boundaries meet along the tie)."""
    index = {body.name: k for k, body in enumerate(model.bodies)}
    tied = {(index[t.body_1], index[t.body_2]) for t in model.ties}
    tied |= {(b, a) for a, b in tied}
    return [(a, b) for a, b in permutations(range(len(model.bodies)), 2)
            if (a, b) in covered or (a, b) not in tied]


#: an ALE body's cell with a corner below this angle (degrees), or above 180 minus it, is a
#: sliver worth a warning: a tester's angle-smoothed base ended at 1.08 / 179.8 deg (a cell
#: 0.01 thick, 0.9 long) and at 10.3 / 179.9 in silence, while the examples' ALE bodies keep
#: 17.4 deg or more (the fast-sliding blocks' lower block at the end, 42.5 or more in the
#: others) and the Laplacian rule kept that tester's base at 22.5
ALE_ANGLE_LIMIT = 10.0

#: a cell the user gave below ALE_ANGLE_LIMIT is reported only when its smallest corner sine
#: fell below this fraction of its initial one: the mesh motion made it worse, while the
#: material's own jitter about a skewed given shape is not news
ALE_DEGRADE_FRACTION = 0.9


@dataclass(frozen=True)
class DegradedCell:
    """The worst cell of the ALE bodies below their quality limit (``AleQualityCheck``):
    its smallest corner sine, body, body-local cell number, centroid, the corner angle
    farthest from 90 degrees now and at t = 0, and the body's ``ale.smoothing`` and
    ``ale.smoothing_layers`` (the warning advises what the body does not use already)."""

    sine: float
    body: str
    cell: int
    centroid: tuple[float, float]
    angle: float
    initial_angle: float
    smoothing: str
    smoothing_layers: int


def _worst_angle(x: NDArray, cell: NDArray) -> float:
    """The corner angle (degrees) of one cell farthest from 90: the sliver's 1 or 179."""
    angles = corner_angles_deg(x, cell.reshape(1, 4))[0]
    return float(angles[np.argmax(np.abs(angles - 90.0))])


class AleQualityCheck:
    """Finds the ALE bodies' worst cell whose smallest corner sine is below sin(ALE_ANGLE_LIMIT)
    and below ALE_DEGRADE_FRACTION of its own at t = 0 (summary.json
    ``ale_mesh_degraded_at``): the final ``mesh_quality`` alone drew nobody's eye to a base
    the angle-based smoothing had flattened to 1 deg (a tester), nor to the worst of a run
    that recovered by its end. One compiled sine per cell of the ALE bodies a step."""

    def __init__(self, model: Model) -> None:
        self._X0 = model.X0
        self._tests = []  # per ALE body: it, its cells (global nodes), their limits
        for setup in model.ale_bodies:
            body = model.bodies[setup.body_index]
            cells = np.ascontiguousarray(model.cells[body.cells])
            limit = np.minimum(np.sin(np.radians(ALE_ANGLE_LIMIT)),
                               ALE_DEGRADE_FRACTION * cell_min_sines(model.X0, cells))
            self._tests.append((body, setup.motion, cells, limit))

    def worst(self, x: NDArray) -> DegradedCell | None:
        """The worst cell below its limit at the positions ``x`` (None: none is)."""
        worst = None
        for body, motion, cells, limit in self._tests:
            sines = cell_min_sines(x, cells)
            low = np.flatnonzero(sines < limit)
            if not low.size:
                continue
            k = int(low[np.argmin(sines[low])])
            if worst is not None and sines[k] >= worst.sine:
                continue
            centre = x[cells[k]].mean(axis=0)
            worst = DegradedCell(float(sines[k]), body.name, k,
                                 (float(centre[0]), float(centre[1])),
                                 _worst_angle(x, cells[k]), _worst_angle(self._X0, cells[k]),
                                 motion.smoothing, motion.smoothing_layers)
        return worst


@dataclass(frozen=True)
class SpacedSegment:
    """The ALE contact-surface segment farthest from its original length on one side
    (``AleSpacingCheck``): current / original length (``ratio``), the body, its two
    body-local nodes, the midpoint, both lengths and the band it left."""

    ratio: float
    body: str
    nodes: tuple[int, int]
    midpoint: tuple[float, float]
    length: float
    reference_length: float
    band: tuple[float, float]


class AleSpacingCheck:
    """Finds the ALE contact-surface segments squeezed below ``1 - t`` or stretched above
    ``1 / (1 - t)`` of their ORIGINAL length (t = ``AleBody.spacing_tolerance``, 0.5,
    summary.json ``ale_surface_spacing_at``). The local respacing keeps that band only
    around each run's current mean stretch and only within one move, so a partner dragged
    along the surface bunches the nodes ahead of it and spreads those behind: a tester's
    block dragged its own length over an ALE base left segments of 0.20x and 3.2x, in
    silence (docs/theory.md, "How far the ALE respacing keeps the surface spacing"). The run
    warning waits for the band's square (``report.run_warnings._surface_spacing``): the
    examples leave the band itself a little where their bodies deform."""

    def __init__(self, model: Model) -> None:
        self._tests = []  # per surface: body name, chain (global), segment ends, reference, band
        for setup in model.ale_bodies:
            name = model.bodies[setup.body_index].name
            for motion in (setup.motion, *setup.more_motions):
                chain = motion.surface
                ends = np.roll(chain, -1) if motion.closed else chain[1:]
                starts = chain if motion.closed else chain[:-1]
                tol = motion.spacing_tolerance
                self._tests.append((name, setup.node_offset, starts, ends,
                                    motion.reference_spacing, (1.0 - tol, 1.0 / (1.0 - tol))))

    def extremes(self, x: NDArray) -> tuple[SpacedSegment | None, SpacedSegment | None]:
        """The most squeezed segment below its band and the most stretched above it at the
        positions ``x`` (None where every segment is inside)."""
        short = long = None
        for name, offset, starts, ends, ref, band in self._tests:
            a, b = x[starts + offset], x[ends + offset]
            ratio = np.hypot(*(b - a).T) / ref
            k, j = int(np.argmin(ratio)), int(np.argmax(ratio))
            if ratio[k] < band[0] and (short is None or ratio[k] < short.ratio):
                short = self._segment(name, a, b, starts, ends, ref, ratio, k, band)
            if ratio[j] > band[1] and (long is None or ratio[j] > long.ratio):
                long = self._segment(name, a, b, starts, ends, ref, ratio, j, band)
        return short, long

    @staticmethod
    def _segment(name: str, a: NDArray, b: NDArray, starts: NDArray, ends: NDArray,
                 ref: NDArray, ratio: NDArray, k: int, band: tuple[float, float],
                 ) -> SpacedSegment:
        mid = 0.5 * (a[k] + b[k])
        return SpacedSegment(float(ratio[k]), name, (int(starts[k]), int(ends[k])),
                             (float(mid[0]), float(mid[1])), float(ratio[k] * ref[k]),
                             float(ref[k]), band)
