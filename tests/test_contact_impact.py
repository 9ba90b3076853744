"""The step-level procedure of report 5.4 on the smallest impact: two point masses (a body-1
surface of two nodes) hitting a rigid wall with the persistency law and the mid-point rule.

With lumped masses and no other forces, persistency (v_{n+1/2} . n = 0) makes the normal
velocity flip exactly in one step, v_{n+1} = 2 v_{n+1/2} - v_n, so kinetic energy is conserved
(3.3.1); then t_N vanishes while the pair separates and it is released after two steps (3.2).
"""

from __future__ import annotations

import numpy as np

from ntncontact.contact import (
    AugmentationTolerances,
    ContactLaw,
    ContactSurface,
    Interface,
    PairState,
    augment,
    check_augmentation,
    closest_pairs,
    commit_step,
    detect,
    evaluate_contact,
)

DT = 0.1
MASS = 1.0
LAW = ContactLaw("augmented_lagrangian", eps_N=100.0)
# gdot is driven to ~0 geometrically (factor ~0.3 per augmentation); 1e-11 is far below
# the energy tolerance below yet well above round-off of O(1) velocities.
TOL = AugmentationTolerances(normal=1e-11, tangential=1.0)
INTERFACE = Interface(ContactSurface([0, 1]), ContactSurface([2, 3]))
BODY1 = np.arange(2)


def newton_midpoint(x_n, v_n, state):
    """Solve M a_{n+1/2} + f_c(x_{n+1/2}, v_{n+1/2}) = 0 for x_{n+1/2} (body 1 only)."""
    x = x_n + 0.5 * DT * v_n
    free = np.arange(4)
    for _ in range(30):
        v = 2.0 * (x - x_n) / DT
        res = evaluate_contact(x, v, 2.0 / DT, INTERFACE, state, LAW)
        accel = 4.0 * (x - x_n) / DT**2 - 2.0 * v_n / DT
        r = (MASS * accel.ravel() + res.force)[free]
        if np.linalg.norm(r) < 1e-12:
            return x, res
        jac = 4.0 * MASS / DT**2 * np.eye(4) + res.tangent_matrix().toarray()[np.ix_(free, free)]
        x[BODY1] -= np.linalg.solve(jac, r).reshape(-1, 2)
    raise AssertionError("Newton did not converge")


def step(x_n, v_n, state):
    """One step of report 5.4: detection, then Newton + augmentation until converged."""
    candidates = closest_pairs(x_n, INTERFACE).pairs
    det = detect(state, candidates, x_n, v_n, INTERFACE)
    state, previous = det.state, None
    for _ in range(60):
        x_mid, res = newton_midpoint(x_n, v_n, state)
        if previous is not None and check_augmentation(previous, res, LAW, TOL).converged:
            break
        state, previous = augment(state, res, LAW), res
    else:
        raise AssertionError("augmentation did not converge")
    v_mid = 2.0 * (x_mid - x_n) / DT
    return 2.0 * x_mid - x_n, 2.0 * v_mid - v_n, commit_step(state, res, LAW), res, det


def test_point_masses_bounce_elastically_and_release():
    x = np.array([[0.0, 0.05], [1.0, 0.05], [1.0, 0.0], [0.0, 0.0]])  # wall nodes 2, 3 fixed
    v = np.zeros_like(x)
    v[BODY1] = [0.3, -1.0]
    energy0 = 0.5 * MASS * np.sum(v[BODY1] ** 2)
    state = PairState.empty()
    history = []
    for _ in range(6):
        x, v, state, res, det = step(x, v, state)
        history.append((len(det.state), det.added.size, det.released.size, res.t_N.copy()))
    sizes = [h[0] for h in history]
    # enters at step 2 (penetrating, approaching); steps 3 and 4 end with t_N = 0 while
    # separating, so the pairs are released at the start of step 5 (release_steps = 2)
    assert sizes == [0, 2, 2, 2, 0, 0]
    assert history[1][1] == 2 and history[4][2] == 2
    assert np.all(history[1][3] > 0.0)  # the impact step carries pressure
    assert all(not h[3].any() for h in history[2:4])  # afterwards t_N vanishes
    np.testing.assert_allclose(v[BODY1], [[0.3, 1.0]] * 2, atol=1e-9)  # normal velocity flipped
    energy = 0.5 * MASS * np.sum(v[BODY1] ** 2)
    assert abs(energy - energy0) < 1e-9 * energy0  # persistency conserves energy (3.16)
