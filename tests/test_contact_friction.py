"""Coulomb return mapping (2.39)-(2.43), the reversal rule (3.3.2) and dissipation (3.18).

The return mapping's properties are tested on the NumPy oracle (tests/contact_reference.py),
which test_contact_kernel.py shows equal to the compiled kernel in every branch; the tests
through evaluate_contact run the kernel itself."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from contact_reference import frictional_dissipation, return_mapping

from ntncontact.contact import (
    SLIP,
    STICK,
    ContactLaw,
    ContactSurface,
    Interface,
    PairState,
    commit_step,
    evaluate_contact,
)


def random_inputs(seed: int, n: int = 2000):
    rng = np.random.default_rng(seed)
    t_N = np.where(rng.random(n) < 0.1, 0.0, rng.exponential(1.0, n))  # some unloaded pairs
    return (rng.normal(0.0, 0.5, n), rng.normal(0.0, 0.2, n), rng.normal(0.0, 0.05, n), t_N)


@pytest.mark.parametrize("seed", [0, 1])
def test_cone_bound_and_branches(seed):
    t_prev, dlam, m, t_N = random_inputs(seed)
    mu, eps_T = 0.3, 20.0
    rm = return_mapping(t_prev, dlam, m, t_N, mu, eps_T)
    np.testing.assert_array_equal(rm.trial, t_prev + dlam + eps_T * m)  # (2.41)
    assert np.all(np.abs(rm.traction) <= mu * t_N)  # |t_T| <= mu t_N holds exactly
    inside = np.abs(rm.trial) <= mu * t_N
    inside &= t_N > 0.0
    np.testing.assert_array_equal(rm.traction[inside], rm.trial[inside])  # stick: t = trial
    np.testing.assert_array_equal(rm.status[inside], STICK)
    out = ~inside
    np.testing.assert_array_equal(rm.traction[out], mu * t_N[out] * np.sign(rm.trial[out]))
    slip = rm.status == SLIP
    assert np.all(rm.traction[slip] * m[slip] >= 0.0)  # slip never works against the motion
    assert rm.reversed.any() and slip.any() and inside.any()  # every branch exercised
    np.testing.assert_array_equal(rm.status[rm.reversed], STICK)
    assert np.all(rm.trial[rm.reversed] * m[rm.reversed] < 0.0)
    length = np.random.default_rng(seed + 7).uniform(0.1, 1.0, t_N.size)
    assert frictional_dissipation(rm.traction, m, length, rm.status) >= 0.0
    assert frictional_dissipation(rm.traction, m, length, rm.status, dt=0.01) >= 0.0


def test_frictionless_interface():
    t_prev, dlam, m, t_N = random_inputs(2, 50)
    for mu, eps_T in [(0.0, 10.0), (0.3, 0.0)]:
        rm = return_mapping(t_prev, dlam, m, t_N, mu, eps_T)
        assert not rm.traction.any() and np.all(rm.status == SLIP)
        assert not rm.d_slip.any() and not rm.d_normal.any()


def test_direction_reversal_sequence():
    """Slip to the right; the motion reverses while t_N drops: stick for that step
    (classical return mapping would slip to the right against the motion); then slip left."""
    mu, eps_T = 0.5, 10.0
    step1 = return_mapping(np.array([0.0]), np.array([0.0]), np.array([0.2]), np.array([1.0]),
                           mu, eps_T)
    assert step1.status[0] == SLIP and step1.traction[0] == pytest.approx(0.5)
    step2 = return_mapping(step1.traction, np.array([0.0]), np.array([-0.01]),
                           np.array([0.6]), mu, eps_T)
    # trial 0.5 - 0.1 = 0.4 > mu t_N = 0.3, yet the motion is to the left: reversed
    assert step2.reversed[0] and step2.status[0] == STICK
    assert step2.traction[0] == pytest.approx(0.3)  # held in the cone
    step3 = return_mapping(step2.traction, np.array([0.0]), np.array([-0.2]), np.array([0.6]),
                           mu, eps_T)
    assert step3.status[0] == SLIP and step3.traction[0] == pytest.approx(-0.3)
    # an overshooting reversal already points along the new motion: it slips and dissipates
    over = return_mapping(np.array([0.5]), np.array([0.0]), np.array([-0.2]), np.array([1.0]),
                          mu, eps_T)
    assert over.status[0] == SLIP and not over.reversed[0] and over.traction[0] < 0.0


def test_dissipation_over_a_sliding_history():
    """A pair driven back and forth with varying pressure: non-negative work every step."""
    rng = np.random.default_rng(5)
    mu, eps_T, t_prev = 0.4, 15.0, np.zeros(1)
    total = 0.0
    for k in range(400):
        m = np.array([0.05 * np.sin(0.1 * k) + 0.01 * rng.standard_normal()])
        t_N = np.array([1.0 + 0.8 * np.sin(0.37 * k)])
        rm = return_mapping(t_prev, np.zeros(1), m, t_N, mu, eps_T)
        step = frictional_dissipation(rm.traction, m, np.ones(1), rm.status)
        assert step >= 0.0
        total += step
        t_prev = rm.traction
    assert total > 0.0  # the history does slide


def test_evaluate_contact_dissipation():
    """The ContactResult's dissipation is sum_slip t_T gdot_T dt L_c (3.17-3.18), dt = 2/rf."""
    x = np.array([[0.0, -0.05], [1.0, -0.05], [2.0, -0.05], [2.0, 0.0], [1.0, 0.0], [0.0, 0.0]])
    v = np.zeros_like(x)
    v[:3] = [[3.0, -1.0], [0.01, -1.0], [-3.0, -1.0]]
    interface = Interface(ContactSurface([0, 1, 2]), ContactSurface([3, 4, 5]))
    state = PairState.from_pairs([[0, 5], [1, 4], [2, 3]])
    law = ContactLaw("penalty", eps_N=10.0, eps_T=5.0, mu=0.3)
    res = evaluate_contact(x, v, 20.0, interface, state, law)
    np.testing.assert_array_equal(res.status, [SLIP, STICK, SLIP])
    expected = np.sum((res.t_T * res.slip_measure * 0.1 * res.length)[[0, 2]])
    assert res.dissipation == pytest.approx(expected, rel=1e-14) and res.dissipation > 0.0
    committed = commit_step(state, res, law)
    np.testing.assert_array_equal(committed.t_T, res.t_T)
    np.testing.assert_array_equal(committed.slip, [True, False, True])
    assert not committed.lambda_N.any()  # penalty keeps lambda_N = 0
    al = replace(law, method="augmented_lagrangian")
    np.testing.assert_array_equal(commit_step(state, res, al).lambda_N, res.t_N)
