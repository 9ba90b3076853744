"""The contact forces' net moment (summary.json ``max_contact_moment_imbalance``,
``engine.diagnostics.contact_moment``) and its warning (tester X, finding 5): a static press
on a non-matching Lagrangian base with the report's pair forces (moment_free = false) read a
reaction moment of 79.88 where the loads need 78.06, the force reactions exact, and only
sometimes a warning (none at nx = 31, -1.3 %). The forces between two bodies then exert a net
moment that the supports take up; moment_free = true balances it."""

import copy

import numpy as np
import pytest
from helpers import EXAMPLES

from ntncontact import api
from ntncontact.engine.builder import build_model
from ntncontact.engine.simulation import Simulation
from ntncontact.io.results import ResultWriter
from ntncontact.report.run_warnings import MOMENT_WARNING, result_warnings

RAMP_1 = {"times": [0.0, 1.0], "values": [0.0, 1.0]}
RAMP_2 = {"times": [1.0, 2.0], "values": [0.0, 1.0]}

#: tester X's press17.toml, coarser and in fewer load steps: a block pressed (p = 50), then
#: pushed sideways (20 on its left face) while it sticks (mu = 0.5) on a base whose surface
#: spacing (0.51) does not match the block's (0.2)
PRESS = {
    "analysis": {"kind": "static", "dt": 0.25, "t_end": 2.0},
    "bodies": [
        {"name": "block",
         "mesh": {"type": "rectangle", "width": 1.0, "height": 0.5, "nx": 5, "ny": 2,
                  "origin": [1.0, 0.0]},
         "material": {"model": "neo_hookean", "E": 1000.0, "nu": 0.3, "density": 1.0},
         "loads": [{"type": "pressure", "set": "top", "value": 50.0, "function": RAMP_1},
                   {"type": "traction", "set": "left", "vector": [20.0, 0.0],
                    "function": RAMP_2}]},
        {"name": "base",
         "mesh": {"type": "rectangle", "width": 3.06, "height": 0.5, "nx": 6, "ny": 2,
                  "origin": [0.0, -0.5]},
         "material": {"model": "neo_hookean", "E": 5000.0, "nu": 0.3, "density": 1.0},
         "supports": [{"set": "bottom", "x": 0.0, "y": 0.0}]}],
    "contact": [{"name": "c", "body_1": "block", "surface_1": "bottom", "body_2": "base",
                 "surface_2": "top", "method": "augmented_lagrangian", "law": "gap",
                 "penalty_normal": 1e5, "penalty_tangential": 1e5, "friction": 0.5}],
}


class MomentCheck:
    """Per step: the diagnostic's moment, and the reactions' moment plus the loads' moment
    about the origin at the step's end positions (the supports take up the rest)."""

    def __init__(self) -> None:
        self.steps = []

    def on_step(self, model, record) -> None:
        found = record.extra.get("contact_moment")
        if found is None or found.interface == "":
            return
        s = record.state
        load = model.loads(s.time, model.ndof, s.X).reshape(-1, 2)
        loads_moment = float(np.sum(s.x[:, 0] * load[:, 1] - s.x[:, 1] * load[:, 0]))
        reaction = record.extra["reaction_base_bottom_moment"]
        self.steps.append((found, reaction + loads_moment, reaction))

    def on_finish(self, status, error) -> None:
        assert status == "completed", error


@pytest.fixture(scope="module", params=[False, True], ids=["report_forces", "moment_free"])
def press(request):
    """(moment_free, per-step checks, summary) of the press."""
    data = copy.deepcopy(PRESS)
    data["contact"][0]["moment_free"] = request.param
    scenario = api.scenario_from_dict(data)
    model = build_model(scenario.config, scenario.base_dir)
    check, writer = MomentCheck(), ResultWriter(None, model)
    Simulation(model, [check, writer]).run()
    return request.param, check.steps, dict(writer.results.summary.data)


def test_the_imbalance_is_what_the_supports_take_up(press):
    """Static equilibrium: the reactions' moment plus the loads' is the contact forces' net
    moment, at every step; the summary keeps the largest relative one and where."""
    moment_free, steps, summary = press
    assert len(steps) >= 7  # the first load step may carry no force yet
    for found, taken_up, reaction in steps:
        assert found.moment == pytest.approx(taken_up, abs=1e-6 * abs(reaction))
    worst = max(steps, key=lambda step: step[0].relative)[0]
    assert summary["max_contact_moment_imbalance"] == worst.relative
    at = summary["max_contact_moment_imbalance_at"]
    assert at["interface"] == "c" and at["moment"] == worst.moment
    assert at["step"] in range(1, 9) and at["time"] == pytest.approx(0.25 * at["step"])
    warned = [line for line in result_warnings(summary, static=True)
              if "max_contact_moment_imbalance" in line]
    if moment_free:  # round-off: the supports balance the loads
        assert summary["max_contact_moment_imbalance"] < 1e-12
        assert abs(at["moment"] if at else 0.0) < 1e-10 * abs(steps[-1][2])
        assert not warned
    else:  # the report's forces: a couple of ~2 % of the loads' moment
        assert summary["max_contact_moment_imbalance"] > 10 * MOMENT_WARNING
        assert abs(steps[-1][0].moment) > 0.005 * abs(steps[-1][2])
        [line] = warned
        assert "interface 'c'" in line and "moment_free = true" in line


def test_the_keys_are_in_an_example_summary():
    """Every run with contact has the keys (an example cut to one step)."""
    scenario = api.load_scenario(EXAMPLES / "block_sliding.toml", ["analysis.t_end=0.25"])
    summary = api.run(scenario).summary
    assert summary["max_contact_moment_imbalance"] >= 0.0
    assert "max_contact_moment_imbalance_at" in summary


def test_a_moment_of_exactly_zero_is_measured():
    """Forces along the line that joins their nodes: the net moment is 0.0 exactly, and the
    interface was still measured (a moment-free press on one machine had 3 of its 8 steps at
    exactly 0.0, which the diagnostic and the summary took for steps without contact)."""
    from types import SimpleNamespace

    from ntncontact.engine.diagnostics import contact_moment

    x = np.array([[0.0, 0.0], [0.0, 1.0]])
    result = SimpleNamespace(force=np.array([0.0, 1.0, 0.0, -1.0]))
    found = contact_moment([SimpleNamespace(name="c")], [result], x)
    assert found.interface == "c" and found.relative == 0.0 and found.moment == 0.0
