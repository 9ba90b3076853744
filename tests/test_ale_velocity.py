"""Mesh and convective velocities."""

import numpy as np
import pytest

from ntncontact.ale.velocity import convective_velocity, mesh_velocity


def test_mesh_velocity_is_mesh_displacement_over_dt():
    old = np.array([[0.0, 0.0], [1.0, 0.0]])
    new = np.array([[0.02, 0.0], [1.0, -0.01]])
    # exact binary fractions apart from the division: round-off only
    np.testing.assert_allclose(mesh_velocity(old, new, 0.01), [[2.0, 0.0], [0.0, -1.0]], atol=1e-12)


def test_lagrangian_node_has_zero_convective_velocity_and_ale_node_does_not():
    old = np.array([[0.0, 0.0], [1.0, 0.0]])
    v = np.array([[1.0, 0.5], [1.0, 0.5]])
    dt = 0.1
    new = old + dt * v
    new[1, 0] += 0.05  # node 1 additionally slid along the surface (ALE)
    c = convective_velocity(v, mesh_velocity(old, new, dt))
    np.testing.assert_allclose(c[0], 0.0, atol=1e-12)
    np.testing.assert_allclose(c[1], [-0.5, 0.0], atol=1e-12)


def test_invalid_inputs_rejected():
    with pytest.raises(ValueError, match="positive"):
        mesh_velocity(np.zeros((2, 2)), np.zeros((2, 2)), 0.0)
    with pytest.raises(ValueError, match="shape"):
        mesh_velocity(np.zeros((2, 2)), np.zeros((3, 2)), 1.0)
