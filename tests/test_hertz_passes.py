"""A quasi-static step's detection takes in again, at once, the pairs it releases where they
penetrate at x_n + dt v_n (``interfaces.detect_all``, ``detection = "predicted"``). It used to
test only the nodes not paired before the release: a pair that ended the last step open and
was inside again at x + dt v waited for the step's first pass to stop at its probe, one pass
more (Hertz mesh 1: steps 2 and 4; refined 4x: 13 of 18 steps).

Hertz mesh 1 against the same run with released nodes kept out of their detection (the code
before this change, ``helpers.released_nodes_wait``).
"""

from __future__ import annotations

import numpy as np
from helpers import Recorder, model_from_example, released_nodes_wait, same_pressed_pairs

from ntncontact.engine.simulation import Simulation


def _run(monkeypatch, retaken: bool):
    """(simulation, records, passes per step) of Hertz mesh 1's first five load steps."""
    passes: dict[int, int] = {}
    solve_step = Simulation._solve_step
    depth = [0]

    def spy(self, state, contact, dt, start=None, may_grow=False):
        depth[0] += 1  # a pass solved again without unfollowed pairs is still one pass
        try:
            return solve_step(self, state, contact, dt, start, may_grow)
        finally:
            depth[0] -= 1
            if depth[0] == 0:
                passes[state.step + 1] = passes.get(state.step + 1, 0) + 1

    monkeypatch.setattr(Simulation, "_solve_step", spy)
    if not retaken:
        released_nodes_wait(monkeypatch)
    records = Recorder()
    sim = Simulation(model_from_example("hertz.toml", ["analysis.t_end=5"]), [records])
    sim.run()
    monkeypatch.undo()
    return sim, records, passes


def test_released_pairs_penetrating_at_the_newton_start_enter_with_the_first_pass(monkeypatch):
    new, rec_new, passes_new = _run(monkeypatch, retaken=True)
    old, rec_old, passes_old = _run(monkeypatch, retaken=False)
    # step 1 starts from rest (v = 0: nothing is predicted) and grows its one pair; after it
    # every step finds its active set at the start (the old code: 2 passes in steps 2 and 4)
    assert passes_new == {1: 2, 2: 1, 3: 1, 4: 1, 5: 1}, passes_new
    assert sum(passes_old.values()) > sum(passes_new.values()), passes_old
    iterations = [sum(r.newton_iterations for r in rec.records) for rec in (rec_new, rec_old)]
    assert iterations[0] <= iterations[1], iterations
    # The same converged steps: displacements to the Newton tolerance, the same pressed pairs,
    # and their tractions to what the augmentation test fixes them to, eps_N x the gap
    # tolerance (the test stops where the gaps change by less than it; measured 1.2e-8 of the
    # largest force, the other path's last augmentation landing elsewhere within the test)
    scale = np.abs(old.state.d).max()
    np.testing.assert_allclose(new.state.d, old.state.d, rtol=0, atol=1e-9 * scale)
    ci = new.model.interfaces[0]
    bound = ci.law.eps_N * ci.tolerances.normal
    for rows_a, rows_b, pressed_a in same_pressed_pairs(rec_new.records, rec_old.records):
        traction_a = dict(zip(rows_a["node_1"], rows_a["normal_traction"], strict=True))
        traction_b = dict(zip(rows_b["node_1"], rows_b["normal_traction"], strict=True))
        for node in pressed_a:
            assert abs(traction_a[node] - traction_b[node]) <= bound
