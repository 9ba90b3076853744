"""Central finite-difference checks of the contact force tangent and the Lagrange blocks.

Tolerance: relative error < 1e-6 as required. With a perturbation h = 1e-6 on coordinates of
order 1, central differences carry a truncation error ~h^2 |f'''| ~ 1e-12 and a round-off
error ~eps |f| / h ~ 1e-10 relative, four orders below the tolerance; a dropped term (e.g. the
normal's or L_c's derivative) produces errors of order 1e-2 to 1 (see the broken-kernel test).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from contact_reference import pair_kinematics
from helpers import lagrange_matrices

from ntncontact.contact import (
    SLIP,
    STICK,
    ContactLaw,
    ContactSurface,
    Interface,
    PairState,
    evaluate_contact,
    lagrange_blocks,
)

H = 1e-6
TOL = 1e-6


def strips(seed: int, n: int = 5, closed2: bool = False, corner_first: bool = False):
    """Body 1 above (surface walks +x, normal ~ -y), body 2 below (walks -x, normal ~ +y),
    node-to-node pairs with a small penetration and a random shape perturbation."""
    rng = np.random.default_rng(seed)
    base = np.arange(n, dtype=float)
    x1 = np.column_stack((base, np.full(n, -0.05))) + 0.03 * rng.standard_normal((n, 2))
    x2 = np.column_stack((base + 0.02, np.zeros(n))) + 0.03 * rng.standard_normal((n, 2))
    extra = np.array([[2.0, -3.0]])  # closes body 2's surface into a loop when closed2
    x = np.vstack((x1, x2, extra))
    corner = np.zeros(n, bool)
    corner[0] = corner_first
    s1 = ContactSurface(np.arange(n), corner=corner)
    nodes2 = np.arange(2 * n - 1, n - 1, -1)
    s2 = ContactSurface(np.append(nodes2, 2 * n) if closed2 else nodes2, closed=closed2)
    pairs = np.column_stack((np.arange(n), n + np.arange(n)))
    return x, Interface(s1, s2), pairs


def velocities(x: np.ndarray, seed: int) -> np.ndarray:
    """Body 1 approaching downward and sliding along +x, body 2 nearly at rest."""
    rng = np.random.default_rng(seed + 100)
    v = 0.1 * rng.standard_normal(x.shape)
    v[:5] += np.array([0.7, -1.0])
    return v


def fd_tangent(x0, v0, rate_factor, interface, state, law, x_start=None):
    """(analytic, central-difference) d force / d x_eval, v following x with rate_factor."""
    def force(x):
        v = None if v0 is None else v0 + (rate_factor or 0.0) * (x - x0)
        return evaluate_contact(x, v, rate_factor, interface, state, law, x_start=x_start).force

    res = evaluate_contact(x0, v0, rate_factor, interface, state, law, x_start=x_start)
    ndof = x0.size
    fd = np.zeros((ndof, ndof))
    for dof in range(ndof):
        step = np.zeros(ndof)
        step[dof] = H
        fd[:, dof] = (force(x0 + step.reshape(-1, 2)) - force(x0 - step.reshape(-1, 2))) / (2 * H)
    return res, res.tangent_matrix().toarray(), fd


def rel_error(k: np.ndarray, fd: np.ndarray) -> float:
    return float(np.max(np.abs(k - fd)) / np.max(np.abs(fd)))


def friction_history(x, v, rate_factor, interface, pairs, law, kinds, x_start=None, lam=3.0):
    """A state whose previous tangential tractions put each pair in the requested branch."""
    state = PairState.from_pairs(pairs)
    state = replace(state, lambda_N=np.broadcast_to(lam, len(pairs)).astype(float))
    kin = pair_kinematics(x, interface, pairs, v, rate_factor, x_start,
                          objective=law.moment_free)
    measure = kin.gap_rate if rate_factor is not None else kin.gap
    t_N = np.maximum(state.lambda_N + law.eps_N * measure, 0.0)
    assert np.all(t_N > 0.1)  # pressed pairs only: the branches below are then well separated
    m = kin.slip_measure
    cone = law.mu * t_N
    pushes = law.eps_T * m
    t_prev = np.select(
        [kinds == "stick", kinds == "slip", kinds == "reversed"],
        [0.3 * cone - pushes,  # trial = 0.3 cone, well inside
         np.sign(m) * 2.0 * cone,  # trial beyond the cone along the motion
         -np.sign(m) * (3.0 * cone + 2.0 * np.abs(pushes))],  # beyond, against the motion
    )
    return replace(state, t_T=t_prev, slip=kinds != "stick")


@pytest.mark.parametrize("moment_free", [False, True])
@pytest.mark.parametrize("method", ["penalty", "augmented_lagrangian", "lagrange"])
@pytest.mark.parametrize("rate_factor", [None, 20.0])
def test_normal_only_tangent(method, rate_factor, moment_free):
    x, interface, pairs = strips(1)
    v = velocities(x, 1)
    law = ContactLaw(method, eps_N=0.0 if method == "lagrange" else 50.0,
                     moment_free=moment_free)
    state = replace(PairState.from_pairs(pairs), lambda_N=np.linspace(0.2, 1.0, len(pairs)))
    res, k, fd = fd_tangent(x, v if rate_factor else None, rate_factor, interface, state, law)
    assert np.all(res.t_N > 0.0)  # every pair pressed: no kink of <.> at the base point
    assert rel_error(k, fd) < TOL


@pytest.mark.parametrize("moment_free", [False, True])
@pytest.mark.parametrize("rate_factor", [None, 20.0])
@pytest.mark.parametrize("kind", ["stick", "slip", "reversed", "mixed"])
def test_friction_tangent(rate_factor, kind, moment_free):
    x, interface, pairs = strips(2)
    v = velocities(x, 2) if rate_factor else None
    x_start = None if rate_factor else x + np.array([-0.05, 0.02]) * (np.arange(len(x)) < 5)[:,
                                                                                           None]
    law = ContactLaw("augmented_lagrangian", eps_N=40.0, eps_T=30.0, mu=0.4,
                     moment_free=moment_free)
    kinds = np.array(["stick", "slip", "reversed", "slip", "stick"]) if kind == "mixed" else \
        np.full(len(pairs), kind)
    state = friction_history(x, v, rate_factor, interface, pairs, law, kinds, x_start)
    res, k, fd = fd_tangent(x, v, rate_factor, interface, state, law, x_start)
    expected = np.where(kinds == "slip", SLIP, STICK)
    np.testing.assert_array_equal(res.status, expected)
    assert rel_error(k, fd) < TOL


@pytest.mark.parametrize("moment_free", [False, True])
@pytest.mark.parametrize("rate_factor", [None, 20.0])
def test_corner_and_closed_chain_tangent(rate_factor, moment_free):
    """Corner node 0 takes -n2 of its partner (derivatives w.r.t. surface-2 nodes); body 2's
    surface is closed so its partner normals wrap around."""
    x, interface, pairs = strips(3, closed2=True, corner_first=True)
    v = velocities(x, 3) if rate_factor else None
    x_start = None if rate_factor else x - 0.01 * np.arange(x.size).reshape(-1, 2)
    law = ContactLaw("augmented_lagrangian", eps_N=40.0, eps_T=30.0, mu=0.4,
                     moment_free=moment_free)
    kinds = np.array(["slip", "stick", "slip", "stick", "slip"])
    state = friction_history(x, v, rate_factor, interface, pairs, law, kinds, x_start)
    res, k, fd = fd_tangent(x, v, rate_factor, interface, state, law, x_start)
    j = pairs[0, 1]
    k2 = interface.surface2.index_of([j])[0]
    chord = x[interface.surface2.next[k2]] - x[interface.surface2.prev[k2]]
    n2 = np.array([chord[1], -chord[0]]) / np.linalg.norm(chord)
    np.testing.assert_allclose(res.normal[0], -n2, atol=1e-14)  # round-off of one chord
    assert rel_error(k, fd) < TOL


def test_dropping_normal_derivative_is_detected():
    """The FD check can fail: the report's tangent (5.23), without dn/dx and dL_c/dx, is off."""
    x, interface, pairs = strips(4)
    law = ContactLaw("augmented_lagrangian", eps_N=50.0)
    state = replace(PairState.from_pairs(pairs), lambda_N=np.full(len(pairs), 2.0))
    res, k, fd = fd_tangent(x, None, None, interface, state, law)
    approx = np.zeros_like(k)
    for p, (i, j) in enumerate(pairs):  # eps_N L_c n_c^T n_c only
        nc = np.zeros(x.size)
        nc[2 * i:2 * i + 2], nc[2 * j:2 * j + 2] = res.normal[p], -res.normal[p]
        approx += 50.0 * res.length[p] * np.outer(nc, nc)
    assert rel_error(approx, fd) > 1e-3
    assert rel_error(k, fd) < TOL


@pytest.mark.parametrize("moment_free", [False, True])
@pytest.mark.parametrize("rate_factor", [None, 20.0])
def test_lagrange_blocks_fd(rate_factor, moment_free):
    """G = dh/dx and B = d force/d t_N by central differences (slipping pairs included)."""
    x, interface, pairs = strips(5, corner_first=True)
    v = velocities(x, 5) if rate_factor else None
    x_start = None if rate_factor else x + 0.02
    law = ContactLaw("lagrange", eps_T=30.0, mu=0.3, moment_free=moment_free)
    kinds = np.array(["slip", "stick", "slip", "stick", "stick"])
    lam = np.linspace(2.0, 4.0, len(pairs))
    state = friction_history(x, v, rate_factor, interface, pairs, law, kinds, x_start, lam)
    blocks = lagrange_blocks(x, v, rate_factor, interface, state, law, x_start)
    g_mat, b_mat = lagrange_matrices(blocks, x.size)

    def h_of(xx):
        vv = None if v is None else v + (rate_factor or 0.0) * (xx - x)
        return lagrange_blocks(xx, vv, rate_factor, interface, state, law, x_start).values

    def f_of(lm):
        s = state.with_multipliers(lm)
        return evaluate_contact(x, v, rate_factor, interface, s, law, x_start=x_start).force

    g_fd = np.column_stack([(h_of(x + H * e.reshape(-1, 2)) - h_of(x - H * e.reshape(-1, 2)))
                            / (2 * H) for e in np.eye(x.size)])
    b_fd = np.column_stack([(f_of(lam + H * e) - f_of(lam - H * e)) / (2 * H)
                            for e in np.eye(len(lam))])
    assert rel_error(g_mat.toarray(), g_fd) < TOL
    assert rel_error(b_mat.toarray(), b_fd) < TOL
    res = evaluate_contact(x, v, rate_factor, interface, state, law, x_start=x_start)
    np.testing.assert_array_equal(res.t_N, lam)  # lagrange: t_N is the multiplier itself
    assert np.any(res.status == SLIP) and np.any(res.status == STICK)


@pytest.mark.parametrize("moment_free", [False, True])
def test_rotation_and_translation_covariance(moment_free):
    """Rotating and translating the configuration rotates forces and keeps tractions."""
    x, interface, pairs = strips(6)
    v = velocities(x, 6)
    law = ContactLaw("augmented_lagrangian", eps_N=40.0, eps_T=30.0, mu=0.4,
                     moment_free=moment_free)
    kinds = np.array(["slip", "stick", "slip", "stick", "reversed"])
    state = friction_history(x, v, 20.0, interface, pairs, law, kinds)
    a = 0.7
    rot = np.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]])
    base = evaluate_contact(x, v, 20.0, interface, state, law)
    moved = evaluate_contact(x @ rot.T + [3.0, -1.0], v @ rot.T, 20.0, interface, state, law)
    # round-off of O(10) numbers times a few operations
    np.testing.assert_allclose(moved.t_N, base.t_N, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(moved.t_T, base.t_T, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(moved.force.reshape(-1, 2), base.force.reshape(-1, 2) @ rot.T,
                               rtol=1e-12, atol=1e-12)


def test_force_balance_and_signs():
    """Action = reaction per pair; a pressed body 1 above is pushed up (+y), body 2 down."""
    x, interface, pairs = strips(7)
    law = ContactLaw("penalty", eps_N=10.0)
    res = evaluate_contact(x, None, None, interface, PairState.from_pairs(pairs), law)
    f = res.force.reshape(-1, 2)
    np.testing.assert_allclose(f.sum(axis=0), 0.0, atol=1e-13)  # round-off of O(1) sums
    pressed = res.t_N > 0.0
    assert np.count_nonzero(pressed) >= 3
    # residual R = f_int - f_ext + f_c: the contact load on body 1 is -f_c, i.e. upward
    assert np.all(-f[pairs[pressed, 0], 1] > 0.0) and np.all(-f[pairs[pressed, 1], 1] < 0.0)
    assert not f[pairs[~pressed]].any()
    np.testing.assert_allclose(res.normal_force, res.t_N * res.length)


def test_empty_active_set():
    x, interface, _ = strips(8)
    law = ContactLaw("penalty", eps_N=10.0)
    res = evaluate_contact(x, None, None, interface, PairState.empty(), law)
    assert res.force.shape == (x.size,) and not res.force.any() and res.vals.size == 0
