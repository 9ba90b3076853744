"""Implicit mid-point rule kinematics (report (3.2)-(3.3)); the unknown is d_{n+1/2}."""

from __future__ import annotations

from numpy.typing import NDArray


def midpoint_velocity(d_half: NDArray, d_n: NDArray, dt: float) -> NDArray:
    """v_{n+1/2} = 2 (d_{n+1/2} - d_n) / dt."""
    return 2.0 * (d_half - d_n) / dt


def midpoint_acceleration(d_half: NDArray, d_n: NDArray, v_n: NDArray, dt: float) -> NDArray:
    """a_{n+1/2} = (2/dt) (2 (d_{n+1/2} - d_n)/dt - v_n)."""
    return (2.0 / dt) * (midpoint_velocity(d_half, d_n, dt) - v_n)


def end_of_step(
    d_half: NDArray, d_n: NDArray, v_n: NDArray, dt: float,
    prescribed: tuple[NDArray, NDArray] | None = None,
) -> tuple[NDArray, NDArray, NDArray]:
    """d_{n+1} = 2 d_{n+1/2} - d_n, v_{n+1} = 2 v_{n+1/2} - v_n, a_{n+1} = a_{n+1/2}.

    ``prescribed`` (dofs, their velocities at t_{n+1}): those dofs take their motion's own
    velocity, and a = (v_{n+1} - v_n) / dt (:func:`prescribed_acceleration`). The rule's
    v_{n+1} = 2 v_{n+1/2} - v_n there flipped sign every step after a kink of the motion
    (a rod end stopped at t = 0.2: v = +-0.1, a = +-40 for ever, docs/theory.md)."""
    v_half = midpoint_velocity(d_half, d_n, dt)
    d1, v1, a1 = 2.0 * d_half - d_n, 2.0 * v_half - v_n, (2.0 / dt) * (v_half - v_n)
    if prescribed is not None and prescribed[0].size:
        dofs, rates = prescribed
        shape = v1.shape
        v1, a1 = v1.reshape(-1), a1.reshape(-1)
        v1[dofs] = rates
        a1[dofs] = prescribed_acceleration(v_n.reshape(-1)[dofs], rates, dt)
        v1, a1 = v1.reshape(shape), a1.reshape(shape)
    return d1, v1, a1


def prescribed_acceleration(v_n: NDArray, v_next: NDArray, dt: float) -> NDArray:
    """a_{n+1/2} = (v_{n+1} - v_n) / dt of dofs whose v_{n+1} is prescribed: the mean
    acceleration of the step, as the rule's a_{n+1/2} is of a free dof, so that
    (v_n + v_{n+1})/2 . M a_{n+1/2} dt stays the kinetic energy's change (docs/theory.md)."""
    return (v_next - v_n) / dt


#: d(v_{n+1/2}) / d(d_{n+1/2}) = 2/dt and d(a_{n+1/2}) / d(d_{n+1/2}) = 4/dt^2.
def velocity_factor(dt: float) -> float:
    return 2.0 / dt


def inertia_factor(dt: float) -> float:
    return 4.0 / (dt * dt)
