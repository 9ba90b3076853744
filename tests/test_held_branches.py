"""Pairs held on one branch of the normal law within a Newton solve (issue 18).

Frictionless augmented Lagrangian: t_N = <lambda_N + eps_N g> is not re-decided inside Newton.
Each pair is held PRESSED (t_N = lambda_N + eps_N g, unbracketed) or OPEN (t_N = 0) for a
whole solve; ``hold_branches`` decides the undecided pairs at the solve's start, ``augment``
switches the pairs the bracket disagrees with at the solution, and the augmentation test
accepts neither tensile pressed pairs nor penetrating open ones, so the converged answer is the
bracket's. The spring-against-wall problem of test_contact_augmentation, then Hertz mesh 1.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from helpers import Recorder, model_from_example
from test_contact_augmentation import (
    FREE,
    HEIGHT,
    K_SPRING,
    LOAD,
    NEWTON_TOL,
    NW,
    setup,
    solve_lagrange,
    spring_residual,
)

from ntncontact.contact import (
    AugmentationTolerances,
    ContactLaw,
    PairState,
    augment,
    check_augmentation,
    evaluate_contact,
    hold_branches,
)
from ntncontact.contact.state import OPEN, PRESSED, UNDECIDED
from ntncontact.engine import interfaces, simulation
from ntncontact.engine.simulation import Simulation

LAW = ContactLaw("augmented_lagrangian", eps_N=200.0)


def _placed(depths):
    """Body-1 nodes at the given depths below the wall (negative: clear of it)."""
    x, anchors, interface, pairs = setup()
    x[:3] = x[3:] - np.asarray(depths)[:, None] * NW
    return x, anchors, interface, pairs


def _pair_rows(res, pair):
    """The tangent entries of one pair's force rows (node i of the pair)."""
    rows = 2 * res.pairs[pair, 0] + np.arange(2)
    return res.vals[np.isin(res.rows, rows)]


def test_open_pairs_carry_nothing_and_pressed_pairs_keep_their_stiffness():
    x, _, interface, pairs = _placed([0.01, 0.01, 0.01])  # all three penetrate
    state = replace(PairState.from_pairs(pairs), branch=[OPEN, PRESSED, UNDECIDED])
    res = evaluate_contact(x, None, None, interface, state, LAW)
    np.testing.assert_allclose(res.gap, 0.01, rtol=1e-12)
    np.testing.assert_allclose(res.t_N, [0.0, 2.0, 2.0], rtol=1e-12)
    assert np.abs(_pair_rows(res, 0)).max() == 0.0  # held open: no stiffness either
    assert np.abs(_pair_rows(res, 1)).max() > 0.0
    x, *_ = _placed([-0.01, -0.01, -0.01])  # all three clear
    res = evaluate_contact(x, None, None, interface, state, LAW)
    np.testing.assert_allclose(res.t_N, [0.0, -2.0, 0.0], rtol=1e-12)  # pressed: tensile
    assert np.abs(_pair_rows(res, 1)).max() > 0.0
    assert np.abs(_pair_rows(res, 2)).max() == 0.0  # undecided: the bracket, as before


def test_hold_branches_decides_the_undecided_pairs_at_the_start():
    x, _, interface, pairs = _placed([0.01, -0.01, -0.01])  # in, clear, clear
    state = PairState.from_pairs(pairs).with_multipliers(np.array([0.0, 5.0, 0.0]))
    res = evaluate_contact(x, None, None, interface, state, LAW)
    held = hold_branches(state, res, LAW)
    # penetrating: pressed; a multiplier holds the pair pressed (as the kernel did); clear: open
    np.testing.assert_array_equal(held.branch, [PRESSED, PRESSED, OPEN])
    np.testing.assert_array_equal(held.lambda_N, state.lambda_N)
    clear, *_ = _placed([-0.01, -0.01, -0.01])
    again = hold_branches(held, evaluate_contact(clear, None, None, interface, held, LAW), LAW)
    assert again is held  # decided pairs are left to the augmentation loop
    frictional = ContactLaw("augmented_lagrangian", eps_N=200.0, eps_T=5.0, mu=0.2)
    assert hold_branches(state, res, frictional) is state  # friction: the bracket, as before


def test_inconsistent_branches_are_not_converged_and_switch():
    x, _, interface, pairs = _placed([0.01, -0.01, 1e-9])  # in, clear, just touching
    state = replace(PairState.from_pairs(pairs).with_multipliers(np.array([0.0, 1.0, 0.0])),
                    branch=[OPEN, PRESSED, OPEN])  # decided at another configuration
    res = evaluate_contact(x, None, None, interface, state, LAW)
    tol = AugmentationTolerances(normal=1e-6, tangential=1.0)
    check = check_augmentation(res, res, LAW, tol)
    # pair 0 penetrates while open, pair 1 pulls while pressed; pair 2's 1e-9 is within tol
    assert not check.converged
    assert (check.penetrating_open_pairs, check.tensile_pairs) == (1, 1)
    new = augment(state, res, LAW)
    np.testing.assert_array_equal(new.branch, [PRESSED, OPEN, PRESSED])
    np.testing.assert_array_equal(new.lambda_N, 0.0)
    res = evaluate_contact(x, None, None, interface, new, LAW)
    np.testing.assert_allclose(res.t_N, 200.0 * res.gap * [1.0, 0.0, 1.0], rtol=1e-12)
    assert res.gap[0] > 0.0 and res.gap[2] > 0.0


def _newton(x, anchors, interface, state):
    """Newton on the body-1 dofs with ``state`` fixed; also the pairs that carried a traction
    at each iterate (the branch a pair is on, since a pressed pair's t_N is not 0 here)."""
    x = x.copy()
    k_springs = np.diag(np.repeat(K_SPRING, 2))
    loaded = []
    for _ in range(30):
        res = evaluate_contact(x, None, None, interface, state, LAW)
        loaded.append(res.t_N != 0.0)
        r = (spring_residual(x, anchors) + res.force)[FREE]
        if np.linalg.norm(r) < NEWTON_TOL * np.linalg.norm(LOAD):
            return x, res, loaded
        jac = k_springs + res.tangent_matrix().toarray()[np.ix_(FREE, FREE)]
        x[:3] -= np.linalg.solve(jac, r).reshape(-1, 2)
    raise AssertionError("Newton did not converge")


@pytest.mark.parametrize("depth", [-HEIGHT, -0.5 * HEIGHT, 1e-3])
def test_augmentation_loop_with_held_branches_reaches_the_lagrange_solution(depth):
    """Starting clear of the wall, every pair is held open in the first solve, which drives it
    deep into the wall; the loop presses it, and then converges as before to the exact
    solution (starting inside, pressed from the first solve). No pair changes branch inside a
    solve."""
    x0, anchors, interface, pairs = _placed([depth] * 3)
    x_exact, lam_exact = solve_lagrange(x0, anchors, interface, pairs)
    state = PairState.from_pairs(pairs)
    tol = AugmentationTolerances(normal=1e-10, tangential=1.0)
    x, previous, switches = x0, None, 0
    for _ in range(40):
        state = hold_branches(state, evaluate_contact(x, None, None, interface, state, LAW), LAW)
        x, res, loaded = _newton(x, anchors, interface, state)
        switches += sum(np.count_nonzero(a != b) for a, b in zip(loaded, loaded[1:]))
        if previous is not None and check_augmentation(previous, res, LAW, tol).converged:
            break
        previous, state = res, augment(state, res, LAW)
    else:
        raise AssertionError("the augmentations did not converge")
    assert switches == 0
    assert np.all(state.branch == PRESSED)
    np.testing.assert_allclose(res.t_N, lam_exact, rtol=1e-6)
    np.testing.assert_allclose(x[:3], x_exact[:3], rtol=0, atol=1e-8)


def _hertz(steps: int):
    return model_from_example("hertz.toml", [f"analysis.t_end={steps}"])


def _run_hertz(monkeypatch, steps: int, old: bool):
    """Hertz mesh 1 over ``steps`` load steps, recording per Newton solve which pairs were on
    the pressed branch at each evaluation; ``old``: the bracket decided inside Newton for the pairs
    without a multiplier, and every active-set pass ran its augmentations to convergence (the
    code before this change)."""
    solves: list[list[np.ndarray]] = []
    inside = [False]  # only the evaluations of Newton's own residuals count
    newton, evaluate = simulation.newton, interfaces.evaluate_contact

    def spy_newton(*args, **kwargs):
        solves.append([])
        inside[0] = True
        try:
            return newton(*args, **kwargs)
        finally:
            inside[0] = False

    def spy_evaluate(*args, **kwargs):
        res = evaluate(*args, **kwargs)
        if inside[0]:  # a pair on the pressed branch has stiffness (its 48 tangent entries)
            solves[-1].append(np.abs(res.vals).reshape(len(res.pairs), -1).max(axis=1) > 0.0)
        return res

    monkeypatch.setattr(simulation, "newton", spy_newton)
    monkeypatch.setattr(interfaces, "evaluate_contact", spy_evaluate)
    if old:
        solve_step = Simulation._solve_step
        monkeypatch.setattr(simulation, "hold_branches", lambda state, res, law: state)
        monkeypatch.setattr("ntncontact.contact.augmentation.bracket_branches",
                            lambda state, res, law: np.zeros(len(state), np.int8))
        monkeypatch.setattr(Simulation, "_solve_step",
                            lambda self, s, c, dt, start=None, may_grow=False:
                            solve_step(self, s, c, dt, start))
    records = Recorder()
    sim = Simulation(_hertz(steps), [records])
    sim.run()
    monkeypatch.undo()
    switched = sum(1 for masks in solves
                   if any(m.shape == masks[0].shape and np.any(m != masks[0]) for m in masks))
    iterations = sum(r.newton_iterations for r in records.records)
    return sim, switched, iterations, records


def test_hertz_pairs_hold_their_branch_within_newton_and_converge_alike(monkeypatch):
    """Hertz mesh 1, 4 load steps (new pairs at the edge of the growing contact zone): with the
    bracket inside Newton some solves switch pairs; with held branches none does. Both converge
    to the same state within the augmentation test's tolerance: the gap tolerance 1e-7 allows
    multiplier differences of eps_N 1e-7 = 0.1 (p0 = 3239 at full load); displacements within
    1e-6 of their largest (0.7)."""
    new, switched_new, its_new, rec_new = _run_hertz(monkeypatch, 4, old=False)
    old, switched_old, its_old, rec_old = _run_hertz(monkeypatch, 4, old=True)
    assert switched_old > 0
    assert switched_new == 0
    assert its_new < its_old
    scale = np.abs(old.state.d).max()
    np.testing.assert_allclose(new.state.d, old.state.d, rtol=0, atol=1e-6 * scale)
    for a, b in zip(rec_new.records[1:], rec_old.records[1:], strict=True):
        rows_a, rows_b = a.extra["contact_rows"], b.extra["contact_rows"]
        pressed_a = rows_a["normal_traction"] > 0.0
        pressed_b = rows_b["normal_traction"] > 0.0
        np.testing.assert_array_equal(np.sort(rows_a["node_1"][pressed_a]),
                                      np.sort(rows_b["node_1"][pressed_b]))
        force_a = dict(zip(rows_a["node_1"], rows_a["normal_force"], strict=True))
        force_b = dict(zip(rows_b["node_1"], rows_b["normal_force"], strict=True))
        for node in rows_a["node_1"][pressed_a]:
            assert abs(force_a[node] - force_b[node]) <= 1.0  # N per unit thickness; L_c ~ 6
