"""A quasi-static step's detection takes in again, at once, the pairs it releases where they
penetrate at x_n + dt v_n (``interfaces.detect_all``, ``detection = "predicted"``). It used to
test only the nodes not paired before the release: a pair that ended the last step open and
was inside again at x + dt v waited for the step's first pass to stop at its probe, one pass
more (Hertz mesh 1: steps 2 and 4; refined 4x: 13 of 18 steps).

Hertz mesh 1 against the same run with released nodes kept out of their detection (the code
before this change, ``helpers.released_nodes_wait``).
"""

from __future__ import annotations

from helpers import Recorder, model_from_example, released_nodes_wait, same_converged_contact

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
    # the same converged steps (measured: pair forces 1.2e-8 of the largest apart, the other
    # path's last augmentation landing elsewhere within the augmentation test)
    same_converged_contact(new, rec_new.records, old, rec_old.records, atol=1e-9)
