"""Surfaces, nodal normals, tributary lengths, gap and gap-rate signs on hand-made cases."""

from __future__ import annotations

import numpy as np
import pytest
from contact_reference import pair_kinematics

from ntncontact.contact import ContactSurface, Interface, corner_mask
from ntncontact.mesh.boundary import SurfaceChain, chord_normals

EPS = 1e-14  # round-off for O(1) coordinates


def stacked_blocks(penetration: float):
    """Body 1 (nodes 0-2) above, its bottom surface walking +x (normal -y);
    body 2 (nodes 3-5) below, its top surface walking -x (normal +y)."""
    x = np.array([[0.0, -penetration], [1.0, -penetration], [3.0, -penetration],
                  [0.0, 0.0], [1.0, 0.0], [3.0, 0.0]])
    interface = Interface(ContactSurface([0, 1, 2]), ContactSurface([5, 4, 3]))
    return x, interface, np.array([[0, 3], [1, 4], [2, 5]])


def test_normals_tangents_and_lengths_open_chain():
    x, interface, pairs = stacked_blocks(0.1)
    kin = pair_kinematics(x, interface, pairs)
    np.testing.assert_allclose(kin.normal, [[0, -1]] * 3, atol=EPS)
    # e = m x n = (-n_y, n_x): along the walking direction of surface 1
    np.testing.assert_allclose(kin.tangent, [[1, 0]] * 3, atol=EPS)
    # L_c = (L_{i-1,i} + L_{i,i+1})/2, one-sided at the ends (5.5)
    np.testing.assert_allclose(kin.length, [0.5, 1.5, 1.0], rtol=EPS)
    np.testing.assert_allclose(chord_normals(x[interface.surface2.nodes], False), [[0, 1]] * 3,
                               atol=EPS)


def test_gap_and_gap_rate_signs():
    """g = (x1 - x2) . n1 > 0 is penetration (2.4); gdot > 0 is approach (2.9, 2.1.4)."""
    x, interface, pairs = stacked_blocks(0.1)
    v = np.zeros_like(x)
    v[:3] = [0.5, -2.0]  # body 1 moving down onto body 2
    kin = pair_kinematics(x, interface, pairs, v, rate_factor=10.0)
    np.testing.assert_allclose(kin.gap, 0.1, rtol=EPS)
    np.testing.assert_allclose(kin.gap_rate, 2.0, rtol=EPS)
    np.testing.assert_allclose(kin.slip_measure, 0.5, rtol=EPS)  # gdot_T = (v1 - v2) . e
    x_sep, _, _ = stacked_blocks(-0.2)
    kin = pair_kinematics(x_sep, interface, pairs, -v, rate_factor=10.0)
    assert np.all(kin.gap < 0.0) and np.all(kin.gap_rate < 0.0)


def test_tangential_increment_under_gap_law():
    x, interface, pairs = stacked_blocks(0.0)
    x_start = x.copy()
    x_start[4] += [0.3, 0.0]  # body-2 node 4 was further right: relative slip of node 1 is -0.3
    kin = pair_kinematics(x, interface, pairs, x_start=x_start)
    np.testing.assert_allclose(kin.slip_measure, [0.0, 0.3, 0.0], atol=EPS)


def test_corner_takes_negated_partner_normal():
    """Report 6.6: a tilted block touching with a corner uses -n2 there."""
    x = np.array([[0.0, 0.2], [1.0, -0.1], [2.0, 0.3],  # a kinked body-1 surface, corner at 1
                  [2.0, 0.0], [1.0, 0.0], [0.0, 0.0]])  # flat body 2 walking -x
    s1 = ContactSurface([0, 1, 2], corner=[False, True, False])
    interface = Interface(s1, ContactSurface([3, 4, 5]))
    kin = pair_kinematics(x, interface, np.array([[1, 4]]))
    np.testing.assert_allclose(kin.normal, [[0.0, -1.0]], atol=EPS)
    np.testing.assert_allclose(kin.gap, [0.1], rtol=EPS)
    np.testing.assert_array_equal(corner_mask(x, s1, 30.0), [False, True, False])
    plain = Interface(ContactSurface([0, 1, 2]), ContactSurface([3, 4, 5]))
    chord = x[2] - x[0]
    expected = np.array([chord[1], -chord[0]]) / np.linalg.norm(chord)
    np.testing.assert_allclose(pair_kinematics(x, plain, np.array([[1, 4]])).normal[0],
                               expected, atol=EPS)


def test_closed_square_normals_and_corners():
    x = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])  # CCW: body inside
    s = ContactSurface([0, 1, 2, 3], closed=True)
    diag = np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]]) / np.sqrt(2.0)
    np.testing.assert_allclose(chord_normals(x[s.nodes], True), diag, atol=EPS)
    assert corner_mask(x, s, 30.0).all()
    assert not corner_mask(x, s, 95.0).any()


def test_surface_from_mesh_chain_and_lookup():
    chain = SurfaceChain(np.array([2, 0, 1]), closed=False)
    s = ContactSurface.from_chain(chain, offset=10, corner_nodes=[12])
    np.testing.assert_array_equal(s.nodes, [12, 10, 11])
    np.testing.assert_array_equal(s.corner, [True, False, False])
    np.testing.assert_array_equal(s.index_of([11, 12]), [2, 0])
    np.testing.assert_array_equal(s.prev, [12, 12, 10])
    np.testing.assert_array_equal(s.next, [10, 11, 11])
    with pytest.raises(ValueError):
        s.index_of([3])
    with pytest.raises(ValueError):
        Interface(s, ContactSurface([11, 20]))
