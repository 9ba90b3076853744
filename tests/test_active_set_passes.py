"""Quasi-static active-set passes (issue 18): a pass ends at the first unconverged augmentation
whose solution shows new penetrating pairs (the first too, with or without multipliers, on
augmented-Lagrangian interfaces), and the step's next pass takes
them in from there, instead of converging the augmentations of an active set that is known
to be incomplete.

Hertz mesh 1 (the contact zone grows by new pairs at its edge in most load steps), frictionless
and with the report's mu = 0.3, against the same runs with every pass converged first (the
code before this change).
"""

from __future__ import annotations

import numpy as np
import pytest
from helpers import Recorder, model_from_example, released_nodes_wait, same_pressed_pairs

from ntncontact.engine.simulation import Simulation


def _run(monkeypatch, overrides: list[str], early: bool):
    """(simulation, records, passes) of Hertz mesh 1; passes: per _solve_step call its step,
    number of pairs, augmentations, and whether it stopped early for new pairs."""
    passes = []
    solve_step = Simulation._solve_step

    def spy(self, state, contact, dt, start=None, may_grow=False):
        solved = solve_step(self, state, contact, dt, start, may_grow and early)
        carried = any(bool(np.any(c.lambda_N > 0.0)) for c in contact)
        passes.append((state.step, sum(len(c) for c in contact), solved.augmentations,
                       solved.grown, carried))
        return solved

    monkeypatch.setattr(Simulation, "_solve_step", spy)
    # with released pairs kept out of their detection (test_hertz_passes.py): taken in again
    # at once, they leave mesh 1 no step after the first whose pass shows new pairs
    released_nodes_wait(monkeypatch)
    records = Recorder()
    sim = Simulation(model_from_example("hertz.toml", overrides), [records])
    sim.run()
    monkeypatch.undo()
    return sim, records, passes


@pytest.mark.parametrize("friction", [0.0, 0.3])
def test_a_pass_ends_when_an_augmentation_shows_new_pairs(monkeypatch, friction):
    overrides = ["analysis.t_end=4", f"contact.0.friction={friction}"]
    new, rec_new, passes_new = _run(monkeypatch, overrides, early=True)
    old, rec_old, passes_old = _run(monkeypatch, overrides, early=False)
    stopped = [p for p in passes_new if p[3] is not None]
    assert stopped, "Hertz mesh 1 takes new pairs in within its first load steps"
    for step, pairs, augmentations, grown, _carried in stopped:
        assert sum(len(g) for g in grown) > pairs  # it stopped because pairs were added
        # ... before the augmentations converged (the old passes of the step took more)
        assert augmentations < min(p[2] for p in passes_old if p[0] == step)
    # both kinds occur, each at its first augmentation: the first contact (no multipliers)
    # and the steps after it (the probe of a pass whose pairs carry multipliers)
    assert any(p[2] == 1 and not p[4] for p in stopped), stopped
    assert any(p[2] == 1 and p[4] for p in stopped), stopped
    iterations = [sum(r.newton_iterations for r in rec.records) for rec in (rec_new, rec_old)]
    assert iterations[0] < iterations[1], iterations
    # The same converged steps, to the Newton tolerance (1e-10 of the forces in play): the
    # same pressed pairs, displacements and pair forces (measured: 3e-14 and 1e-12 relative;
    # the last pass of a step starts from nearly the same point either way).
    scale = np.abs(old.state.d).max()
    np.testing.assert_allclose(new.state.d, old.state.d, rtol=0, atol=1e-9 * scale)
    for rows_a, rows_b, pressed_a in same_pressed_pairs(rec_new.records, rec_old.records):
        force_a = dict(zip(rows_a["node_1"], rows_a["normal_force"], strict=True))
        force_b = dict(zip(rows_b["node_1"], rows_b["normal_force"], strict=True))
        largest = np.abs(rows_b["normal_force"]).max()
        for node in pressed_a:
            assert abs(force_a[node] - force_b[node]) <= 1e-8 * largest
