"""The quasi-static active-set step (``StepProblem.active_set_step``) on a geometry beyond the
report's: a stiff flat punch placed on an elastic block and pressed off-centre, by a uniform
pressure on its top and a point load at its right corner, resultant at e = 3/8 of its width
from its axis. Beyond e = w/4 a rigid punch on an elastic half-space lifts off: the pressure
of a tilted punch touching over a length c, sqrt((c - s) / s) from its pressed edge, has its
resultant at c / 4 from that edge, so c = 4 (w/2 - e) = w/2 here. Every face node enters at
t = 0 (the faces touch), and the first load step's Newton iterations open the left half of
the face: let go of one a few at a time before the active-set step, all at once with it.

Against the same run with the step left out (the code before it): fewer Newton iterations
and factorizations, the same converged contact, and the punch's equilibrium.
"""

from __future__ import annotations

import numpy as np
from helpers import Recorder, model_from_dict, same_converged_contact

from ntncontact.engine.problem import StepProblem
from ntncontact.engine.simulation import Simulation
from ntncontact.solvers.linear import LinearSolver

WIDTH, HEIGHT, ELEMENTS = 2.0, 0.5, 24  # the punch, its face's elements
PRESSURE, CORNER_LOAD = 10.0, 60.0  # on its top; downward at its top right corner
STEPS = 4  # the load ramped over them
SUPPORT = np.array([-0.5 * WIDTH, HEIGHT])  # its top left corner, held horizontally


def _punch() -> dict:
    ramp = {"times": [0.0, float(STEPS)], "values": [0.0, 1.0]}
    return {
        "analysis": {"kind": "static", "dt": 1.0, "t_end": float(STEPS)},
        "bodies": [
            {"name": "punch",
             "mesh": {"type": "rectangle", "width": WIDTH, "height": HEIGHT, "nx": ELEMENTS,
                      "ny": 3, "origin": [-0.5 * WIDTH, 0.0]},
             "material": {"model": "linear_elastic", "E": 1e5, "nu": 0.3, "density": 1.0},
             "supports": [{"set": "corner_top_left", "x": 0.0}],
             "loads": [{"type": "pressure", "set": "top", "value": PRESSURE, "function": ramp},
                       {"type": "point", "set": "corner_top_right",
                        "vector": [0.0, -CORNER_LOAD], "function": ramp}]},
            {"name": "block",
             "mesh": {"type": "rectangle", "width": 3 * WIDTH, "height": 4 * HEIGHT,
                      "nx": 3 * ELEMENTS, "ny": 10, "origin": [-1.5 * WIDTH, -4 * HEIGHT]},
             "material": {"model": "linear_elastic", "E": 1e3, "nu": 0.3, "density": 1.0},
             "supports": [{"set": "bottom", "x": 0.0, "y": 0.0}]},
        ],
        "contact": [{"body_1": "punch", "surface_1": "bottom", "body_2": "block",
                     "surface_2": "top", "method": "augmented_lagrangian",
                     "penalty_factor": 10.0,
                     "augmentation": {"max_iterations": 30, "gap_tolerance": 1e-8}}],
    }


def _run(monkeypatch, active_set: bool):
    """(simulation, records, factorizations, Newton steps the active-set step corrected)."""
    corrected = []
    original = StepProblem.active_set_step

    def counted(self, *args):
        step = original(self, *args)
        corrected.append(step is not None)
        return step

    monkeypatch.setattr(StepProblem, "active_set_step",
                        counted if active_set else (lambda self, *args: None))
    solver = LinearSolver()
    records = Recorder()
    sim = Simulation(model_from_dict(_punch()), [records], linear_solve=solver.solve)
    sim.run()
    monkeypatch.undo()
    return sim, records.records, solver.stats.factorizations, sum(corrected)


def test_an_off_centre_punch_lets_go_of_its_lifted_side_at_once(monkeypatch):
    new, rec_new, factored_new, corrected = _run(monkeypatch, active_set=True)
    old, rec_old, factored_old, _ = _run(monkeypatch, active_set=False)
    assert corrected > 0
    iterations = [sum(r.newton_iterations for r in rec) for rec in (rec_new, rec_old)]
    assert iterations[0] < iterations[1], iterations
    assert factored_new < factored_old, (factored_new, factored_old)
    same_converged_contact(new, rec_new, old, rec_old, atol=1e-8)
    for record in rec_new[1:]:
        _check_equilibrium(new, record)
        _check_contact_zone(new, record)


def _check_equilibrium(sim: Simulation, record) -> None:
    """The pair forces on the punch balance the loads: their vertical resultant, and their
    moment about the support, whose reaction is horizontal (about the reference positions: a
    linear elastic body's internal forces have no moment about them)."""
    rows = record.extra["contact_rows"]
    force = -rows["normal_force"][:, None] * np.column_stack([rows["normal_x"], rows["normal_y"]])
    arm = sim.model.X0[rows["node_1"].astype(np.int64)] - SUPPORT
    scale = record.state.time / STEPS
    load = scale * (PRESSURE * WIDTH + CORNER_LOAD)
    # the pressure's resultant acts at the face's middle, the corner load a width from it
    moment = scale * (PRESSURE * WIDTH * 0.5 * WIDTH + CORNER_LOAD * WIDTH)
    np.testing.assert_allclose(force[:, 1].sum(), load, rtol=1e-6)
    np.testing.assert_allclose((arm[:, 0] * force[:, 1] - arm[:, 1] * force[:, 0]).sum(), moment,
                               rtol=1e-6)


def _check_contact_zone(sim: Simulation, record) -> None:
    """The pressed nodes are the face's right half, c = 4 (w/2 - e) = w/2 from the loaded
    edge (module docstring), to within a spacing: one run of consecutive nodes."""
    rows = record.extra["contact_rows"]
    pressed = rows["node_1"][rows["normal_traction"] > 0.0].astype(np.int64)
    X = np.sort(sim.model.X0[pressed, 0])
    spacing = WIDTH / ELEMENTS
    np.testing.assert_allclose(np.diff(X), spacing, rtol=1e-9)  # no gap in the zone
    eccentricity = CORNER_LOAD * 0.5 * WIDTH / (PRESSURE * WIDTH + CORNER_LOAD)
    assert X[-1] == 0.5 * WIDTH  # the loaded edge
    assert abs((X[-1] - X[0]) - 4.0 * (0.5 * WIDTH - eccentricity)) <= spacing, X
