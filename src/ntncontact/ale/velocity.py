"""Mesh and convective velocities of an ALE mesh over one step (report 4.1.1, eqs. 4.1-4.6)."""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = ["convective_velocity", "mesh_velocity"]


def mesh_velocity(x_mesh_old: ArrayLike, x_mesh_new: ArrayLike, dt: float) -> NDArray[np.float64]:
    """v_hat = d_hat / dt, the mesh displacement of each node over the step (4.3-4.4).

    For a Lagrangian node the mesh displacement is its material displacement (4.3), so v_hat
    equals its material velocity (4.1) and its convective velocity vanishes.
    """
    if not dt > 0.0:
        raise ValueError(f"time step must be positive, got {dt}")
    old, new = np.asarray(x_mesh_old, dtype=float), np.asarray(x_mesh_new, dtype=float)
    if old.shape != new.shape:
        raise ValueError(f"mesh positions differ in shape: {old.shape} vs {new.shape}")
    return (new - old) / dt


def convective_velocity(v_material: ArrayLike, v_mesh: ArrayLike) -> NDArray[np.float64]:
    """c = v - v_hat (4.5); inside the iteration, v is the last iterate's velocity (4.6)."""
    return np.asarray(v_material, dtype=float) - np.asarray(v_mesh, dtype=float)
