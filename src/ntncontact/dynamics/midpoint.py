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
    d_half: NDArray, d_n: NDArray, v_n: NDArray, dt: float
) -> tuple[NDArray, NDArray, NDArray]:
    """d_{n+1} = 2 d_{n+1/2} - d_n, v_{n+1} = 2 v_{n+1/2} - v_n, a_{n+1} = a_{n+1/2}."""
    v_half = midpoint_velocity(d_half, d_n, dt)
    return 2.0 * d_half - d_n, 2.0 * v_half - v_n, (2.0 / dt) * (v_half - v_n)


#: d(v_{n+1/2}) / d(d_{n+1/2}) = 2/dt and d(a_{n+1/2}) / d(d_{n+1/2}) = 4/dt^2.
def velocity_factor(dt: float) -> float:
    return 2.0 / dt


def inertia_factor(dt: float) -> float:
    return 4.0 / (dt * dt)
