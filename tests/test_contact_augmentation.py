"""Augmented Lagrangian iterations and the exact Lagrange (bordered) solution on a small
spring-against-wall problem (report 2.2, 5.4).

Body 1: three nodes on a straight surface, each tied by a zero-length spring (stiffness k_i) to
an anchor a height h above a tilted rigid wall, pushed into the wall and along it. Body 2: the
wall's three fixed nodes. Gap law, frictionless, node-to-node pairs.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from helpers import lagrange_matrices

from ntncontact.contact import (
    AugmentationTolerances,
    ContactLaw,
    ContactSurface,
    Interface,
    PairState,
    augment,
    check_augmentation,
    evaluate_contact,
    extrapolated_update,
    lagrange_blocks,
    max_contraction,
    newton_update,
)
from ntncontact.contact.friction import SLIP

THETA = 0.3
D = np.array([np.cos(THETA), np.sin(THETA)])  # wall direction
NW = np.array([-np.sin(THETA), np.cos(THETA)])  # wall outward normal (towards body 1)
K_SPRING = np.array([10.0, 14.0, 8.0])
HEIGHT = 0.1
LOAD = -3.0 * NW + 0.4 * D  # per node: into the wall and along it
NEWTON_TOL = 1e-12  # relative residual; the problem is O(1), so this is near round-off


def setup():
    s = np.arange(3.0)
    wall = s[:, None] * D
    anchors = wall + HEIGHT * NW
    x = np.vstack((anchors, wall))
    interface = Interface(ContactSurface([0, 1, 2]), ContactSurface([5, 4, 3]))
    pairs = np.array([[0, 3], [1, 4], [2, 5]])
    return x, anchors, interface, pairs


def spring_residual(x, anchors):
    r = np.zeros_like(x)
    r[:3] = K_SPRING[:, None] * (x[:3] - anchors) - LOAD
    return r.ravel()


FREE = np.arange(6)  # body-1 dofs; the wall is fixed


def solve_fixed_multipliers(x, anchors, interface, state, law, x_start=None):
    """Newton on the body-1 dofs with the contact multipliers of ``state`` held fixed;
    ``x_start``: the step's start, from which friction measures the slip (gap law)."""
    x = x.copy()
    k_springs = np.diag(np.repeat(K_SPRING, 2))
    for _ in range(30):
        res = evaluate_contact(x, None, None, interface, state, law, x_start=x_start)
        r = (spring_residual(x, anchors) + res.force)[FREE]
        if np.linalg.norm(r) < NEWTON_TOL * np.linalg.norm(LOAD):
            return x, res
        jac = k_springs + res.tangent_matrix().toarray()[np.ix_(FREE, FREE)]
        x[:3] -= np.linalg.solve(jac, r).reshape(-1, 2)
    raise AssertionError("Newton did not converge")


def solve_lagrange(x, anchors, interface, pairs, law=None):
    """Newton on the bordered system [[K + K_c, B], [G, 0]] (module lagrange); ``law``: a
    "lagrange" law (default frictionless), whose friction measures the slip from ``x``."""
    law, x_start = law or ContactLaw("lagrange"), x
    x = x.copy()
    lam = np.zeros(len(pairs))
    k_springs = np.diag(np.repeat(K_SPRING, 2))
    for _ in range(30):
        state = PairState.from_pairs(pairs).with_multipliers(lam)
        res = evaluate_contact(x, None, None, interface, state, law, x_start=x_start)
        blocks = lagrange_blocks(x, None, None, interface, state, law, x_start)
        g_mat, b_mat = lagrange_matrices(blocks, x.size)
        r = np.concatenate(((spring_residual(x, anchors) + res.force)[FREE], blocks.values))
        if np.linalg.norm(r) < NEWTON_TOL * np.linalg.norm(LOAD):
            return x, lam
        top = np.hstack((k_springs + res.tangent_matrix().toarray()[np.ix_(FREE, FREE)],
                         b_mat.toarray()[FREE]))
        bottom = np.hstack((g_mat.toarray()[:, FREE], np.zeros((len(pairs), len(pairs)))))
        step = np.linalg.solve(np.vstack((top, bottom)), -r)
        x[:3] += step[:6].reshape(-1, 2)
        lam += step[6:]
    raise AssertionError("bordered Newton did not converge")


def test_lagrange_solution_is_exact():
    x0, anchors, interface, pairs = setup()
    x, lam = solve_lagrange(x0, anchors, interface, pairs)
    res = evaluate_contact(x, None, None, interface,
                           PairState.from_pairs(pairs).with_multipliers(lam),
                           ContactLaw("lagrange"))
    assert np.max(np.abs(res.gap)) < 1e-12  # constraint met to Newton's round-off level
    assert np.all(lam > 0.0)  # every pair in compression: the active set is right
    # global balance normal to the wall: spring forces + load + contact = 0
    normal_load = np.sum((LOAD - K_SPRING[:, None] * (x[:3] - anchors)) @ NW)
    np.testing.assert_allclose(np.sum(res.normal_force), -normal_load, rtol=1e-10)


@pytest.mark.parametrize("eps_N", [20.0, 200.0])
def test_augmentation_converges_to_lagrange(eps_N):
    x0, anchors, interface, pairs = setup()
    x_exact, lam_exact = solve_lagrange(x0, anchors, interface, pairs)
    law = ContactLaw("augmented_lagrangian", eps_N=eps_N)
    state = PairState.from_pairs(pairs)
    gaps, errors, results = [], [], []
    for _ in range(12):
        x, res = solve_fixed_multipliers(x0, anchors, interface, state, law)
        gaps.append(np.max(res.gap))
        errors.append(np.max(np.abs(res.t_N - lam_exact)))
        results.append(res)
        state = augment(state, res, law)
    gaps, errors = np.array(gaps), np.array(errors)
    assert np.all(gaps > 0.0)  # penalty-type methods never over-correct here
    assert np.all(np.diff(gaps) < 0.0)  # each augmentation reduces the penetration
    assert np.all(np.diff(errors) < 0.0)  # and moves the tractions toward the exact ones
    # linear contraction ~ k / (k + eps_N L_c) <= 14/(14 + 10) per iteration for eps_N = 20
    assert gaps[-1] < 1e-3 * gaps[0]
    np.testing.assert_allclose(x[:3], x_exact[:3], atol=10 * gaps[-1])
    tol = AugmentationTolerances(normal=1e-3 * gaps[0], tangential=1e-12)
    assert check_augmentation(results[-2], results[-1], law, tol).converged
    assert not check_augmentation(results[0], results[1], law, tol).converged


def test_penalty_does_not_augment():
    x0, anchors, interface, pairs = setup()
    law = ContactLaw("penalty", eps_N=20.0)
    _, res = solve_fixed_multipliers(x0, anchors, interface, PairState.from_pairs(pairs), law)
    assert np.max(res.gap) > 0.01  # a penalty solution penetrates visibly at this eps_N
    with pytest.raises(ValueError):
        augment(PairState.from_pairs(pairs), res, law)


def test_augment_tangential_update():
    """dlambda_T <- t_T^(k) - t_T,n (report 5.4 step 4.2), lambda_N <- t_N^(k) (step 4.1)."""
    x0, anchors, interface, pairs = setup()
    law = ContactLaw("augmented_lagrangian", eps_N=20.0, eps_T=5.0, mu=0.2)
    state = PairState.from_pairs(pairs)
    x = x0.copy()
    x[:3] = x0[3:] - 0.03 * NW  # pressed: t_N = eps_N 0.03 = 0.6, cone mu t_N = 0.12
    x_start = x.copy()
    x_start[:3] -= np.array([0.01, 0.05, 0.005])[:, None] * D  # trials 0.05, 0.25, 0.025
    res = evaluate_contact(x, None, None, interface, state, law, x_start=x_start)
    new = augment(state, res, law)
    np.testing.assert_array_equal(new.lambda_N, res.t_N)
    np.testing.assert_array_equal(new.dlambda_T, res.t_T - state.t_T)
    again = evaluate_contact(x, None, None, interface, new, law, x_start=x_start)
    stick = res.status == 0
    np.testing.assert_array_equal(stick, [True, False, True])
    # a sticking pair's trial grows by eps_T delta g_T at the same configuration
    np.testing.assert_allclose(again.trial_T[stick], res.t_T[stick]
                               + law.eps_T * res.slip_measure[stick], rtol=1e-14, atol=1e-14)


def first_newton_step(x, anchors, interface, state, law):
    """The first iterate of solve_fixed_multipliers from x."""
    res = evaluate_contact(x, None, None, interface, state, law)
    r = (spring_residual(x, anchors) + res.force)[FREE]
    jac = np.diag(np.repeat(K_SPRING, 2)) + res.tangent_matrix().toarray()[np.ix_(FREE, FREE)]
    x = x.copy()
    x[:3] -= np.linalg.solve(jac, r).reshape(-1, 2)
    return x


def test_pairs_with_a_multiplier_stay_on_the_pressed_branch():
    """laws.held_pairs: starting 0.1 clear of the wall, a frictionless augmented pair with
    lambda_N > 0 keeps t_N = lambda_N + eps_N g (tensile there) and its stiffness, so the first
    Newton step gets the penetration (~0.01) within 0.002; a bracketed pair has neither there,
    and the first step goes to where the springs alone balance the load, 0.1-0.26 deep, ten
    times the solution's penetration."""
    x0, anchors, interface, pairs = setup()
    law = ContactLaw("augmented_lagrangian", eps_N=200.0)
    held = PairState.from_pairs(pairs).with_multipliers(np.full(3, 1.0))
    res = evaluate_contact(x0, None, None, interface, held, law)
    np.testing.assert_allclose(res.gap, -HEIGHT, rtol=1e-12)
    np.testing.assert_allclose(res.t_N, 1.0 - 200.0 * HEIGHT, rtol=1e-12)  # tensile
    assert np.abs(res.vals).max() > 0.0
    _, solution = solve_fixed_multipliers(x0, anchors, interface, held, law)
    x1 = first_newton_step(x0, anchors, interface, held, law)
    gap_1 = evaluate_contact(x1, None, None, interface, held, law).gap
    assert np.abs(gap_1 - solution.gap).max() < 0.02 * HEIGHT
    # without a multiplier (lambda_N = 0), or with friction, the bracket applies: t_N = 0
    bracketed = PairState.from_pairs(pairs)
    frictional = ContactLaw("augmented_lagrangian", eps_N=200.0, eps_T=5.0, mu=0.2)
    for state, other in ((bracketed, law), (held, frictional)):
        res = evaluate_contact(x0, None, None, interface, state, other, x_start=x0)
        np.testing.assert_array_equal(res.t_N, 0.0)
    res = evaluate_contact(x0, None, None, interface, bracketed, law)
    np.testing.assert_array_equal(res.vals, 0.0)  # no normal stiffness either
    _, solution = solve_fixed_multipliers(x0, anchors, interface, bracketed, law)
    x1 = first_newton_step(x0, anchors, interface, bracketed, law)
    np.testing.assert_allclose(x1[:3], anchors + LOAD / K_SPRING[:, None], rtol=1e-12)
    gap_1 = evaluate_contact(x1, None, None, interface, bracketed, law).gap
    assert np.all(gap_1 > 5.0 * solution.gap)


def test_tensile_held_pairs_are_released_and_not_converged():
    """A held pair that comes out tensile is not converged (its solve used a traction the
    bracketed law does not allow) and its next multiplier is 0."""
    x0, anchors, interface, pairs = setup()
    law = ContactLaw("augmented_lagrangian", eps_N=200.0)
    state = PairState.from_pairs(pairs).with_multipliers(np.array([1.0, 30.0, 1.0]))
    x = x0.copy()
    x[:3] = x0[3:] + np.array([0.01, -0.001, 0.01])[:, None] * NW  # clear, in, clear
    res = evaluate_contact(x, None, None, interface, state, law)
    np.testing.assert_allclose(res.t_N, state.lambda_N + 200.0 * res.gap, rtol=1e-12)
    np.testing.assert_array_equal(res.t_N < 0.0, [True, False, True])
    new = augment(state, res, law)
    np.testing.assert_array_equal(new.lambda_N, np.maximum(res.t_N, 0.0))
    tol = AugmentationTolerances(normal=1.0, tangential=1.0)  # changes alone would pass
    check = check_augmentation(res, res, law, tol)
    assert not check.converged and check.tensile_pairs == 2
    pressed = evaluate_contact(x, None, None, interface, new, law)
    check = check_augmentation(pressed, pressed, law, tol)
    assert check.converged and check.tensile_pairs == 0


def sensitivity(x, interface, state, law, res, x_start=None, blocks_law=None):
    """S = G A^-1 B of contact.newton_update over the pressed pairs, A the Newton matrix;
    G and B of ``blocks_law`` (default ``law``)."""
    pressed = res.t_N > 0.0
    jac = np.diag(np.repeat(K_SPRING, 2)) + res.tangent_matrix().toarray()[np.ix_(FREE, FREE)]
    g_mat, b_mat = lagrange_matrices(lagrange_blocks(x, None, None, interface, state,
                                                     blocks_law or law, x_start), x.size)
    response = np.linalg.solve(jac, b_mat.toarray()[FREE][:, pressed])
    return g_mat.toarray()[pressed][:, FREE] @ response


def test_newton_update_converges_faster_than_uzawa():
    """Both updates go to the exact (Lagrange) tractions; Uzawa's error shrinks by a constant
    factor (~k / (k + eps_N L_c) ~ 0.4 at eps_N = 20), Newton's quadratically (the springs are
    linear; only the normal's rotation is not)."""
    x0, anchors, interface, pairs = setup()
    _, lam_exact = solve_lagrange(x0, anchors, interface, pairs)
    law = ContactLaw("augmented_lagrangian", eps_N=20.0)
    errors = {}
    for update in ("uzawa", "newton"):
        state, errors[update] = PairState.from_pairs(pairs), []
        for _ in range(4):
            x, res = solve_fixed_multipliers(x0, anchors, interface, state, law)
            errors[update].append(np.abs(res.t_N - lam_exact).max())
            uzawa = augment(state, res, law)
            if update == "newton":
                uzawa = newton_update(state, uzawa, res, sensitivity(x, interface, state, law,
                                                                     res))
            state = uzawa
    uzawa, newton = np.array(errors["uzawa"]), np.array(errors["newton"])
    np.testing.assert_allclose(uzawa[1:] / uzawa[:-1], 0.5, atol=0.05)  # measured 0.50-0.503
    # measured 2.0, 2.6e-2, 9.2e-6, 1.6e-12: each error below the square of the one before
    assert np.all(newton[2:] < newton[1:-1] ** 2)
    assert newton[3] < 1e-10 * newton[0]


def _frictional_errors(law, blocks_law, exact, augmentations):
    """Max |t_N - exact| per augmentation of Newton updates whose S takes G and B from
    ``blocks_law`` (None: Uzawa updates), and the last result."""
    x0, anchors, interface, pairs = setup()
    state, errors = PairState.from_pairs(pairs), []
    for _ in range(augmentations):
        x, res = solve_fixed_multipliers(x0, anchors, interface, state, law, x_start=x0)
        errors.append(np.abs(res.t_N - exact).max())
        uzawa = augment(state, res, law)
        if blocks_law is not None:
            uzawa = newton_update(state, uzawa, res, sensitivity(x, interface, state, law, res,
                                                                 x0, blocks_law))
        state = uzawa
    return np.array(errors), res


def test_newton_update_with_slipping_pairs_converges_quadratically():
    """With friction a slipping pair's tangential traction is mu t_N, so its normal multiplier
    moves both: S takes that in through B's column L_c (n + mu sign(trial) e)
    (``lagrange.blocks_of``). With mu = 0.05 every pair slips (trials 0.46-0.73 against cones
    0.08-0.22 at the solution). Exact: the bordered (Lagrange) solution with the same friction.
    Measured: Uzawa 0.499 an augmentation; Newton 2.0, 3.7e-2, 2.3e-5, 8.8e-12 (each error
    below the square of the one before); Newton with B and G of the frictionless law, which
    leave the friction's share out, only linearly (0.009-0.015 an augmentation, 2.9e-6 after
    the fourth)."""
    x0, anchors, interface, pairs = setup()
    exact_law = ContactLaw("lagrange", eps_T=20.0, mu=0.05)
    x_exact, exact = solve_lagrange(x0, anchors, interface, pairs, exact_law)
    check = evaluate_contact(x_exact, None, None, interface,
                             PairState.from_pairs(pairs).with_multipliers(exact), exact_law,
                             x_start=x0)
    np.testing.assert_array_equal(check.status, SLIP)  # the set-up: every pair slips
    law = ContactLaw("augmented_lagrangian", eps_N=20.0, eps_T=20.0, mu=0.05)
    uzawa, _ = _frictional_errors(law, None, exact, 6)
    newton, last = _frictional_errors(law, law, exact, 4)
    frictionless, _ = _frictional_errors(law, ContactLaw("augmented_lagrangian", eps_N=20.0),
                                         exact, 4)
    np.testing.assert_allclose(uzawa[1:] / uzawa[:-1], 0.5, atol=0.05)
    assert np.all(newton[2:] < newton[1:-1] ** 2)
    assert newton[3] < 1e-10 * newton[0]
    np.testing.assert_array_equal(last.status, SLIP)
    np.testing.assert_allclose(last.t_T, 0.05 * last.t_N * np.sign(last.t_T), rtol=1e-12)
    ratios = frictionless[1:] / frictionless[:-1]
    assert np.all((ratios > 0.005) & (ratios < 0.03))  # a constant rate: linear
    assert frictionless[3] > 1e5 * newton[3]


@pytest.mark.parametrize("mu", [0.0, 0.3])
def test_tangential_tests_apply_with_friction_only(mu):
    """Two augmentations whose pairs moved only along the wall: the same gaps and tractions,
    a different slip. Without friction no multiplier acts along the surface, so the step is
    converged; with friction TOL2 still asks the slip to settle."""
    x0, anchors, interface, pairs = setup()
    law = ContactLaw("augmented_lagrangian", eps_N=200.0, eps_T=200.0 if mu else 0.0, mu=mu)
    state = PairState.from_pairs(pairs).with_multipliers(np.full(3, 5.0))
    x = x0.copy()
    x[:3] = x0[3:] - 0.001 * NW  # pressed a little into the wall
    slid = x.copy()
    slid[:3] += 0.01 * D  # along the wall: the gaps do not change
    before = evaluate_contact(x, None, None, interface, state, law, x_start=x0)
    after = evaluate_contact(slid, None, None, interface, state, law, x_start=x0)
    tol = AugmentationTolerances(normal=1e-10, tangential=1e-6)
    check = check_augmentation(before, after, law, tol)
    assert check.normal_change <= 1e-12 and check.tangential_change > 1e-3  # the set-up
    assert check.converged is (mu == 0.0)


def _uzawa_errors(eps_N: float, extrapolate: bool) -> tuple[np.ndarray, list]:
    """Max |t_N - exact| per augmentation (4), and the states each update gave."""
    x0, anchors, interface, pairs = setup()
    _, lam_exact = solve_lagrange(x0, anchors, interface, pairs)
    law = ContactLaw("augmented_lagrangian", eps_N=eps_N)
    state, previous, errors, updates = PairState.from_pairs(pairs), None, [], []
    for _ in range(4):
        _, res = solve_fixed_multipliers(x0, anchors, interface, state, law)
        errors.append(np.abs(res.t_N - lam_exact).max())
        uzawa = augment(state, res, law)
        new = (extrapolated_update(uzawa, res, previous, law)
               if extrapolate and previous is not None else uzawa)
        updates.append((uzawa, new))
        state, previous = new, res
    return np.array(errors), updates


def test_extrapolated_update_takes_the_rest_of_the_uzawa_sequence():
    """With a stiff penalty the Uzawa error shrinks by a constant factor (0.092 here); the
    extrapolation from the second augmentation on removes most of what is left (measured:
    3.3e-4 against 3.1e-3 at the third, 2.9e-5 against 2.9e-4 at the fourth; the three
    springs contract at different rates, so not all of it)."""
    uzawa, _ = _uzawa_errors(200.0, extrapolate=False)
    faster, _ = _uzawa_errors(200.0, extrapolate=True)
    np.testing.assert_array_equal(faster[:2], uzawa[:2])  # nothing to extrapolate from yet
    assert np.all(uzawa[1:] / uzawa[:-1] > 0.05)  # a contraction worth extrapolating
    assert faster[2] < 0.2 * uzawa[2] and faster[3] < 0.2 * uzawa[3], (faster, uzawa)


def test_extrapolated_update_leaves_slow_contractions_alone():
    """A contraction of 0.5 or more (soft penalty): the tail would exceed the Uzawa step
    itself, so the Uzawa multipliers are kept (measured contraction 0.78-0.80)."""
    uzawa, _ = _uzawa_errors(5.0, extrapolate=False)
    assert np.all(uzawa[2:] / uzawa[1:-1] > 0.5)
    _, updates = _uzawa_errors(5.0, extrapolate=True)
    assert all(new is plain for plain, new in updates)


def test_max_contraction_measures_the_uzawa_rate():
    """The ratio of the pressed pairs' largest gaps between two augmentations follows the
    Uzawa error's contraction (0.05-0.2 with this penalty, see above) and is 0 where no pair
    was pressed before; results of different active sets are refused."""
    x0, anchors, interface, pairs = setup()
    law = ContactLaw("augmented_lagrangian", eps_N=200.0)
    state, results = PairState.from_pairs(pairs), []
    for _ in range(3):
        _, res = solve_fixed_multipliers(x0, anchors, interface, state, law)
        results.append(res)
        state = augment(state, res, law)
    first, second, third = results
    both = (third.t_N > 0) & (second.t_N > 0)
    expected = np.abs(third.normal_measure[both]).max() / np.abs(second.normal_measure[both]).max()
    assert max_contraction(third, second) == pytest.approx(expected, rel=1e-15)
    assert 0.05 < max_contraction(third, second) < 0.2
    released = replace(second, t_N=np.zeros_like(second.t_N))
    assert max_contraction(third, released) == 0.0
    with pytest.raises(ValueError, match="share the active set"):
        max_contraction(third, replace(second, pairs=second.pairs[::-1]))
