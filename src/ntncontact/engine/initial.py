"""The state a run starts from: each body's initial rigid velocity, and its supports' own;
the build-time warnings where these disagree with the supports or the ties."""

from __future__ import annotations

import warnings

import numpy as np
from numpy.typing import NDArray

from .diagnostics import PhysicsWarning
from .model import Body, Model
from .problem import StepState
from .ties import Tie


def initial_state(model: Model) -> StepState:
    """Reference configuration at rest, but for each body's initial rigid velocity
    (translation + spin about its centre of mass); the supported dofs move as their supports
    prescribe (:func:`_started_velocities`)."""
    n = model.n_nodes
    v = _started_velocities(model)
    return StepState(0, 0.0, model.X0.copy(), np.zeros((n, 2)), v, np.zeros((n, 2)))


def _rigid_velocities(model: Model) -> NDArray:
    """(n, 2): every body's initial rigid velocity at its nodes (row-sum masses assembled
    once, and only where a body spins)."""
    v = np.zeros((model.n_nodes, 2))
    spinning = any(body.initial_angular_velocity for body in model.bodies)
    centres = _mass_centres(model) if spinning else {}
    for body in model.bodies:
        v[body.nodes] = _rigid_velocity(model.X0, body, centres.get(body.name))
    return v


def _rigid_velocity(X: NDArray, body: Body, centre: NDArray | None) -> NDArray:
    """v = v0 + omega x (X - centre), the centre of mass (row-sum masses): about the node
    centroid, a tester's "pure spin" of a graded mesh drifted at 0.42 (momentum 0.21 of a
    0.5 mass)."""
    nodes, omega = body.nodes, body.initial_angular_velocity
    v = np.broadcast_to(np.asarray(body.initial_velocity, float), (len(nodes), 2)).copy()
    if omega:
        r = X[nodes] - centre
        v += omega * np.column_stack([-r[:, 1], r[:, 0]])
    return v


def _started_velocities(model: Model) -> NDArray:
    """The rigid velocities with the supported dofs at their supports' rate, values x s'(0)
    (0 for a held node): kept, a held node's given velocity flipped sign every step (the
    mid-point rule, v_n+1 = -v_n), and a tester's bar counted 2.5 % of its energy in nodes
    that did not move and saw its reaction alternate -4, -16
    (:func:`warn_overridden_velocities` says so at build time)."""
    v = _rigid_velocities(model)
    flat = v.reshape(-1)
    for support in model.prescribed:
        flat[support.dofs] = support.values * support.function.rate(0.0)
    return v


def warn_overridden_velocities(model: Model) -> None:
    """A warning per body whose given initial velocity its supports override. Velocities
    below 1e-9 of the body's largest count as rest: a spinning pin held at its centre node
    was warned about, its centre's velocity from the spin being -1e-16 (the centre of mass's
    round-off; tester Z)."""
    given, started = _rigid_velocities(model), _started_velocities(model)
    for body in model.bodies:
        tol = 1e-9 * float(np.abs(given[body.nodes]).max(initial=0.0))
        moved = (np.abs(started[body.nodes] - given[body.nodes]) > tol) \
            & (np.abs(given[body.nodes]) > tol)
        if moved.any():
            warnings.warn(f"body '{body.name}': {int(moved.any(axis=1).sum())} supported "
                          "node(s) start at their supports' velocity (a held node at rest), not "
                          "at the body's initial velocity", PhysicsWarning, stacklevel=3)


def warn_tied_velocities(model: Model) -> None:
    """A warning per tie whose nodes start with different velocities. The tie holds the
    positions, never the velocities: an independent tester's two tied parts, each given
    ``initial.angular_velocity`` = 1.5 (each spins about its own centre of mass), kept
    |v_a - v_b| = 0.45 at their tied nodes at every one of 50 frames (the mid-point rule's
    alternating velocity mode), a spurious kinetic energy for the whole run, in silence."""
    started = _started_velocities(model)
    for tie in model.ties:
        gap, node = _largest_velocity_difference(tie, started.reshape(-1))
        scale = max(float(np.abs(started[tie.nodes_1]).max(initial=0.0)), 1e-300)
        if gap <= 1e-9 * scale:
            continue
        at = tuple(round(float(c), 6) for c in model.X0[node])
        warnings.warn(
            f"tie '{tie.name}' (bodies '{tie.body_1}' and '{tie.body_2}'): its nodes start with "
            f"velocities up to {gap:.3g} apart (largest at the node at {at}); "
            "the tie holds their positions but never removes that difference, which stays in "
            "the velocities and the kinetic energy for the whole run. "
            + _common_motion_advice(model, tie), PhysicsWarning, stacklevel=3)


def _common_motion_advice(model: Model, tie: Tie) -> str:
    """How to start tied parts as one body: the same initial velocity, or, where a part
    spins, the velocities of one rigid spin about the assembly's centre."""
    bodies = {body.name: body for body in model.bodies}
    if not any(bodies[name].initial_angular_velocity for name in (tie.body_1, tie.body_2)):
        return "Give the tied parts the same initial.velocity"
    centres = _mass_centres(model)
    where = ", ".join(f"'{name}' {tuple(round(float(c), 6) for c in centres[name])}"
                      for name in (tie.body_1, tie.body_2))
    return ("Each body's initial.angular_velocity spins it about its own centre of mass (here "
            + where + "): for a common spin omega about the assembly's centre c, give each "
            "part the same angular_velocity and velocity = v + omega x (c_part - c), i.e. "
            "(v_x - omega (y_part - y_c), v_y + omega (x_part - x_c))")


def _largest_velocity_difference(tie: Tie, vf: NDArray) -> tuple[float, int]:
    """(|v_a - v_b| at the tied node where it is largest, that node (global)):
    coincident pairs, and the nodes held on an edge against the edge's point."""
    diff = np.concatenate([vf[tie.dofs_1] - vf[tie.dofs_2],
                           vf[tie.edge_dofs] - (1.0 - tie.edge_xi) * vf[tie.edge_ends[:, 0]]
                           - tie.edge_xi * vf[tie.edge_ends[:, 1]]])
    nodes = np.concatenate([tie.dofs_1, tie.edge_dofs]) // 2
    if not nodes.size:
        return 0.0, -1
    unique, inverse = np.unique(nodes, return_inverse=True)
    size = np.sqrt(np.bincount(inverse, weights=diff * diff))
    return float(size.max()), int(unique[int(np.argmax(size))])


def _mass_centres(model: Model) -> dict[str, NDArray]:
    """Each body's centre of mass in the reference configuration (row-sum masses), about
    which its ``initial.angular_velocity`` spins it."""
    mass = model.assembler.nodal_mass(model.X0, True).diagonal()
    return {body.name: mass[body.nodes] @ model.X0[body.nodes] / mass[body.nodes].sum()
            for body in model.bodies}
