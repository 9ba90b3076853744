"""The state a run starts from: each body's initial rigid velocity, and its supports' own."""

from __future__ import annotations

import warnings

import numpy as np
from numpy.typing import NDArray

from .diagnostics import PhysicsWarning
from .model import Body, Model
from .problem import StepState


def initial_state(model: Model) -> StepState:
    """Reference configuration at rest, but for each body's initial rigid velocity
    (translation + spin about its centre of mass); the supported dofs move as their supports
    prescribe (:func:`_supports_prescribe`)."""
    n = model.n_nodes
    v = _rigid_velocities(model)
    _supports_prescribe(model, v)
    return StepState(0, 0.0, model.X0.copy(), np.zeros((n, 2)), v, np.zeros((n, 2)))


def _rigid_velocities(model: Model) -> NDArray:
    """(n, 2): every body's initial rigid velocity at its nodes (row-sum masses assembled
    once, and only where a body spins)."""
    v = np.zeros((model.n_nodes, 2))
    spinning = any(body.initial_angular_velocity for body in model.bodies)
    mass = model.assembler.nodal_mass(model.X0, True).diagonal() if spinning else None
    for body in model.bodies:
        v[body.nodes] = _rigid_velocity(model.X0, body, mass)
    return v


def _rigid_velocity(X: NDArray, body: Body, mass: NDArray | None) -> NDArray:
    """v = v0 + omega x (X - centre), the centre of mass (row-sum masses): about the node
    centroid, a tester's "pure spin" of a graded mesh drifted at 0.42 (momentum 0.21 of a
    0.5 mass)."""
    nodes, omega = body.nodes, body.initial_angular_velocity
    v = np.broadcast_to(np.asarray(body.initial_velocity, float), (len(nodes), 2)).copy()
    if omega:
        centre = mass[nodes] @ X[nodes] / mass[nodes].sum()
        r = X[nodes] - centre
        v += omega * np.column_stack([-r[:, 1], r[:, 0]])
    return v


def _supports_prescribe(model: Model, v: NDArray) -> None:
    """Supported dofs start at their supports' rate, values x s'(0) (0 for a held node): kept,
    a held node's given velocity flipped sign every step (the mid-point rule, v_n+1 = -v_n),
    and a tester's bar counted 2.5 % of its energy in nodes that did not move and saw its
    reaction alternate -4, -16 (:func:`warn_overridden_velocities` says so at build time)."""
    flat = v.reshape(-1)
    for support in model.prescribed:
        flat[support.dofs] = support.values * support.function.rate(0.0)


def warn_overridden_velocities(model: Model) -> None:
    """A warning per body whose given initial velocity its supports override."""
    given = _rigid_velocities(model)
    started = given.copy()
    _supports_prescribe(model, started)
    for body in model.bodies:
        moved = (started[body.nodes] != given[body.nodes]) & (given[body.nodes] != 0.0)
        if moved.any():
            warnings.warn(f"body '{body.name}': {int(moved.any(axis=1).sum())} supported "
                          "node(s) start at their supports' velocity (a held node at rest), not "
                          "at the body's initial velocity", PhysicsWarning, stacklevel=3)
