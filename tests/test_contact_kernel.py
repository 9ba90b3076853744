"""The compiled contact kernel (:func:`evaluate_contact`) against its NumPy oracle
(tests/contact_reference.py) on random configurations covering every branch.

Tolerance 1e-12 relative: both evaluate the same formulas in the same order (they agree bit for
bit on this machine); only the summation order of forces on a node shared by several pairs, and
of the dissipation, may differ, by a few ulps of the largest term.
"""

from __future__ import annotations

from dataclasses import replace

import contact_reference as reference
import numpy as np
import pytest
from contact_reference import pair_kinematics

from ntncontact.contact import (
    SLIP,
    STICK,
    ContactLaw,
    ContactSurface,
    Interface,
    PairState,
    evaluate_contact,
)

RTOL = 1e-12
FIELDS = ("gap", "gap_rate", "slip_measure", "t_N", "t_T", "trial_T", "length", "normal",
          "tangent")


def random_interface(rng, n: int, closed2: bool, partner_ends: bool):
    """Wavy surface 1 (open, random corners incl. its ends) above surface 2; pairs drawn from
    all surface-1 nodes, partners random (repeated) or the last ones (chain ends of surface 2)."""
    base = np.arange(n, dtype=float)
    x1 = np.column_stack((base, np.full(n, -0.05))) + 0.05 * rng.standard_normal((n, 2))
    x2 = np.column_stack((base + 0.3 * rng.random(), np.zeros(n))) + 0.05 * rng.standard_normal(
        (n, 2))
    x = np.vstack((x1, x2, [[0.5 * n, -3.0]]))
    corner = rng.random(n) < 0.3
    corner[[0, -1]] = rng.random(2) < 0.5
    s1 = ContactSurface(np.arange(n), corner=corner)
    nodes2 = np.arange(2 * n - 1, n - 1, -1)
    s2 = ContactSurface(np.append(nodes2, 2 * n) if closed2 else nodes2, closed=closed2)
    node1 = rng.permutation(n)[: max(1, int(0.8 * n))]
    node2 = n + (np.where(rng.random(node1.size) < 0.3, rng.integers(0, n, node1.size),
                          n - 1 - node1) if not partner_ends else
                 rng.choice([0, n - 1], node1.size))
    return x, Interface(s1, s2), np.column_stack((node1, node2))


def random_state(rng, x, v, rate_factor, interface, pairs, law, x_start):
    """Multipliers and friction history putting pairs in every branch: unloaded (t_N = 0),
    stick, slip along and against the motion (reversal), trial near 0."""
    p = len(pairs)
    state = PairState.from_pairs(pairs)
    kin = pair_kinematics(x, interface, pairs, v, rate_factor, x_start,
                          objective=law.moment_free)
    measure = kin.gap_rate if rate_factor is not None else kin.gap
    scale = max(float(np.max(np.abs(law.eps_N * measure))), 1.0)
    lam = rng.uniform(-0.5, 2.0, p) * scale
    t_N = np.maximum(lam + law.eps_N * measure, 0.0)
    pushes = law.eps_T * kin.slip_measure
    dlam = rng.normal(0.0, 0.1, p) * scale
    cone = law.mu * t_N
    kind = rng.integers(0, 4, p)
    t_prev = np.select(
        [kind == 0, kind == 1, kind == 2],
        [rng.uniform(-0.9, 0.9, p) * cone - pushes - dlam,
         np.sign(kin.slip_measure) * rng.uniform(1.1, 3.0, p) * (cone + 1.0) - dlam,
         -np.sign(kin.slip_measure) * (3.0 * cone + 2.0 * np.abs(pushes) + 1.0) - dlam],
        -pushes - dlam)  # trial = 0 (up to round-off)
    return replace(state, lambda_N=lam, dlambda_T=dlam, t_T=t_prev)


def assert_same(fast, ref):
    scale = max(float(np.max(np.abs(ref.force), initial=0.0)), 1e-300)
    np.testing.assert_allclose(fast.force, ref.force, rtol=RTOL, atol=RTOL * scale)
    k_fast, k_ref = fast.tangent_matrix(), ref.tangent_matrix()
    k_scale = max(float(np.max(np.abs(k_ref.data), initial=0.0)), 1e-300)
    assert abs(k_fast - k_ref).max() <= RTOL * k_scale if k_ref.nnz else k_fast.nnz == 0
    for name in FIELDS:
        a, b = np.asarray(getattr(fast, name)), np.asarray(getattr(ref, name))
        assert a.shape == b.shape, name
        np.testing.assert_allclose(a, b, rtol=RTOL, atol=RTOL * max(np.max(np.abs(b),
                                                                            initial=0.0), 1.0),
                                   err_msg=name)
    np.testing.assert_array_equal(fast.status, ref.status)
    assert fast.status.dtype == ref.status.dtype
    np.testing.assert_allclose(fast.dissipation, ref.dissipation, rtol=RTOL,
                               atol=RTOL * max(abs(ref.dissipation), 1e-300))
    assert fast.rate_law == ref.rate_law


def both(*args, **kwargs):
    return evaluate_contact(*args, **kwargs), reference.evaluate_contact(*args, **kwargs)


METHODS = ["penalty", "augmented_lagrangian", "lagrange"]


@pytest.mark.parametrize("seed", range(6))
@pytest.mark.parametrize("method", METHODS)
@pytest.mark.parametrize("rate_law", [False, True])
@pytest.mark.parametrize("friction", ["none", "coulomb"])
@pytest.mark.parametrize("moment_free", [False, True])
def test_random_configurations(seed, method, rate_law, friction, moment_free):
    rng = np.random.default_rng([seed, METHODS.index(method), rate_law, friction == "none"])
    n = int(rng.integers(3, 40))
    x, interface, pairs = random_interface(rng, n, closed2=bool(seed % 2),
                                           partner_ends=seed == 4)
    v = rng.normal(0.0, 0.5, x.shape) + [0.5, -1.0] * (np.arange(len(x)) < n)[:, None]
    x_start = x + rng.normal(0.0, 0.05, x.shape)
    rate_factor = 2.0 / rng.uniform(0.001, 0.1) if rate_law else None
    mu, eps_T = (0.0, 0.0) if friction == "none" else (rng.uniform(0.1, 0.8), 10.0 ** rng.uniform(
        0, 3))
    law = ContactLaw(method, eps_N=0.0 if method == "lagrange" else 10.0 ** rng.uniform(0, 4),
                     eps_T=eps_T, mu=mu, moment_free=moment_free)
    state = random_state(rng, x, v, rate_factor, interface, pairs, law, x_start)
    fast, ref = both(x, v, rate_factor, interface, state, law, x_start=x_start,
                     dt=rng.uniform(0.001, 0.1) if seed % 3 else None)
    assert_same(fast, ref)
    if friction == "coulomb" and method != "lagrange" and seed < 4 and not moment_free:
        # every branch was reached across pairs (reversed pairs are STICK beyond the cone);
        # the objective rates of the moment-free law move these few draws off some branches,
        # which test_contact_tangent.py sets up one by one
        beyond = np.abs(ref.t_T) < np.abs(ref.trial_T)
        assert np.any(ref.status == SLIP) and np.any((ref.status == STICK) & ~beyond)
        assert np.any((ref.status == STICK) & beyond) and np.any(ref.t_N == 0.0)


@pytest.mark.parametrize("with_v", [False, True])
@pytest.mark.parametrize("with_start", [False, True])
def test_gap_law_optional_inputs(with_v, with_start):
    """Gap law: gap rate reported only with v (NaN otherwise), slip 0 without x_start."""
    rng = np.random.default_rng(11)
    x, interface, pairs = random_interface(rng, 12, closed2=False, partner_ends=False)
    v = rng.normal(size=x.shape) if with_v else None
    x_start = x - 0.02 if with_start else None
    law = ContactLaw("augmented_lagrangian", eps_N=50.0, eps_T=20.0 if with_start else 0.0,
                     mu=0.3)
    state = random_state(rng, x, v, None, interface, pairs, law, x_start)
    fast, ref = both(x, v, None, interface, state, law, x_start=x_start)
    assert_same(fast, ref)
    assert np.isnan(fast.gap_rate).all() != with_v


def test_empty_active_set():
    rng = np.random.default_rng(12)
    x, interface, _ = random_interface(rng, 5, closed2=False, partner_ends=False)
    law = ContactLaw("penalty", eps_N=10.0)
    fast, ref = both(x, None, None, interface, PairState.empty(), law)
    assert_same(fast, ref)
    assert fast.vals.size == 0 and not fast.force.any()


def test_bad_input_errors():
    """Bad input raises a ValueError that names the problem."""
    x = np.array([[0.0, 0.0], [1.0, 0.0], [2.0, 0.0], [1.0, -0.1], [0.0, -0.1]])
    interface = Interface(ContactSurface([0, 1, 2]), ContactSurface([3, 4]))
    law = ContactLaw("penalty", eps_N=10.0)
    with pytest.raises(ValueError, match="not on this contact surface"):
        evaluate_contact(x, None, None, interface, PairState.from_pairs([[1, 2]]), law)
    x_bad = x.copy()
    x_bad[2] = x_bad[0]  # node 1's chain neighbours coincide
    with pytest.raises(ValueError, match="contact normal is undefined"):
        evaluate_contact(x_bad, None, None, interface, PairState.from_pairs([[1, 3]]), law)
    with pytest.raises(ValueError, match="rate law needs velocities"):
        evaluate_contact(x, None, 20.0, interface, PairState.from_pairs([[1, 3]]), law)
