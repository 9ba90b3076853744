"""Where Newton starts a step (issue 18): quasi-static steps from the positions the contact
detection predicted, and an active-set re-pass from the previous pass's solution."""

import numpy as np
from helpers import (
    Recorder,
    SubStepCounting,
    model_from_dict,
    model_from_example,
    released_nodes_wait,
)

from ntncontact.engine.problem import StepProblem, StepState
from ntncontact.engine.simulation import Simulation


def _strip(kind: str):
    analysis = {"kind": kind, "dt": 0.1, "t_end": 0.2}
    return model_from_dict({
        "analysis": analysis,
        "bodies": [{
            "name": "strip",
            "mesh": {"type": "rectangle", "width": 2.0, "height": 1.0, "nx": 3, "ny": 2},
            "material": {"model": "neo_hookean", "lambda": 3.0, "mu": 2.0, "density": 1.0},
            "supports": [{"set": "left", "x": 0.0, "y": 0.0}],
        }],
    })


def _state(model, seed: int) -> StepState:
    rng = np.random.default_rng(seed)
    n = model.n_nodes
    d, v = 1e-2 * rng.standard_normal((n, 2)), rng.standard_normal((n, 2))
    return StepState(3, 0.3, model.X0.copy(), d, v, np.zeros((n, 2)))


def test_quasi_static_newton_starts_at_the_detections_prediction():
    model = _strip("static")
    state = _state(model, 1)
    problem = StepProblem(model, state, 0.1)
    predicted = (state.d + 0.1 * state.v).ravel()  # x_pred = x_n + dt v_n, as detect_all uses
    np.testing.assert_array_equal(problem.initial_guess(), predicted[problem.free_dofs])
    assert problem.fixed_dofs.size > 0  # the supported dofs are left out


def test_dynamic_newton_start_is_the_mid_point_of_the_prediction():
    model = _strip("dynamic")
    state = _state(model, 2)
    mass = model.assembler.nodal_mass(model.X0, False)
    problem = StepProblem(model, state, 0.1, mass)
    expected = (state.d + 0.05 * state.v).ravel()  # d_{n+1/2} of x_pred
    np.testing.assert_array_equal(problem.initial_guess(), expected[problem.free_dofs])


def _hertz(steps: int):
    return model_from_example("hertz.toml", [f"analysis.t_end={steps}"])


def test_active_set_re_pass_starts_from_the_previous_pass(monkeypatch):
    """Hertz mesh 1: steps 1, 2 and 4 take new penetrating pairs in and re-solve. Each re-pass
    must start from the solution of the pass before it, and need fewer Newton iterations in
    all than re-passes started from the step's start, for the same converged state. Without
    the released pairs taken in again at detection (test_hertz_passes.py), which leave mesh 1 only
    step 1's re-pass."""
    passes: list[tuple] = []
    solve_step = Simulation._solve_step
    released_nodes_wait(monkeypatch)

    def spy(self, state, contact, dt, start=None, may_grow=False):
        solved = solve_step(self, state, contact, dt, start, may_grow)
        passes.append((state.step, start, solved))
        return solved

    monkeypatch.setattr(Simulation, "_solve_step", spy)
    warm_records = Recorder()
    warm = Simulation(_hertz(4), [warm_records])
    warm.run()
    by_step: dict[int, list] = {}
    for step, start, solved in passes:
        by_step.setdefault(step, []).append((start, solved))
    re_passed = [runs for runs in by_step.values() if len(runs) > 1]
    assert len(re_passed) >= 2
    for runs in re_passed:
        assert runs[0][0] is None
        for (_, before), (start, _) in zip(runs, runs[1:], strict=False):
            np.testing.assert_array_equal(start[0], before.d.ravel())
            np.testing.assert_array_equal(start[1], before.state.d)

    def cold(self, state, contact, dt, start=None, may_grow=False):  # from the step's start
        return solve_step(self, state, contact, dt, None, may_grow)

    monkeypatch.setattr(Simulation, "_solve_step", cold)
    cold_records = Recorder()
    cold_sim = Simulation(_hertz(4), [cold_records])
    cold_sim.run()

    def iterations(recorder):
        return sum(r.newton_iterations for r in recorder.records)

    assert iterations(warm_records) < iterations(cold_records)
    # the same converged state, to the Newton tolerance (1e-10 of the forces in play)
    scale = np.abs(warm.state.d).max()
    np.testing.assert_allclose(warm.state.d, cold_sim.state.d, rtol=0, atol=1e-7 * scale)


def _thin_rows():
    """The fast-sliding blocks (report 6.5) with the upper block refined 8x in y only (1,524
    elements): its contact-side row is 2.1e-3 thick, a third of a step's approach |v| dt."""
    return model_from_example("blocks_fast_sliding.toml",
                              ["bodies.0.mesh.ny=168", "analysis.t_end=0.072"])


def test_dynamic_steps_start_from_the_last_mid_point_velocity():
    """The mid-point rule's end velocity v_n = 2 v_{n-1/2} - v_{n-1} carries its odd-even mode
    where contact holds a velocity constraint: the pressed rows' normal velocities flip by
    about 2 |v| from step to step, the mid-point velocities do not. A step's first Newton
    start advances the nodes with v_{n-1/2} = v_n - h/2 a_n (h the sub-step that ended at the
    state): from x_n + dt/2 v_n the thin rows of these blocks started inverted and 9 of 45
    sub-step attempts to t = 0.072 failed; now none does."""
    rec = Recorder()
    sim = SubStepCounting(_thin_rows())
    sim.observers.append(rec)
    sim.run()
    assert [a for a in sim.attempts if not a[2]] == []
    assert len(sim.attempts) == 24
    # the start velocity is the last step's mid-point velocity, (x_n - x_{n-1}) / h, on the
    # Lagrangian block (the ALE block's nodes carry other particles after each step's move)
    before, last = rec.records[-2].state, rec.records[-1].state
    upper = sim.model.bodies[0].nodes
    mid = (last.x[upper] - before.x[upper]) / sim._last_substep
    start = sim._start_velocity(last)
    scale = np.abs(mid).max()
    np.testing.assert_allclose(start[upper], mid, rtol=0, atol=1e-12 * scale)
    # ... which differs from v_n where contact holds the rows: by ~2 |v| at the pressed face
    bottom = sim.model.interfaces[0].interface.surface1.nodes
    assert np.abs(last.v[bottom, 1] - start[bottom, 1]).max() > 1.0
