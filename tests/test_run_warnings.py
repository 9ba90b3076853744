"""The run's physics warnings (session 39's testers):

- ``ntncontact.run`` was silent where ``ntncontact run`` warned (an oblique impact at dt 0.0025:
  "node 1 ... went 0.0309 inside its partner surface"): both take the lines from
  ``report.run_warnings``, the API as :class:`PhysicsWarning`;
- the penetration advice named a stiffer penalty and a smaller dt whatever the interface; a
  smaller dt made a tester's slide worse, and with equal spacings the depth was detection lag:
  the advice now follows the interface's settings (summary.json ``contact_setup``);
- a mid-point run's ledger off by 6.2 % of the energy was not warned about;
- a penalty interface under the persistency (rate) law sinks without bound under a sustained
  load, and nothing said so.
"""

from __future__ import annotations

import copy
import warnings

import pytest
from helpers import model_from_dict

import ntncontact as ntc
from ntncontact.cli import main
from ntncontact.io.scenario import toml_value
from ntncontact.report.run_warnings import BALANCE_WARNING, result_warnings

#: the tester's oblique impact of a spinning Neo-Hookean block on a free base (freeimpact.toml)
#: at dt 0.0025, up to just past its deepest pair (t = 0.065)
IMPACT = {
    "analysis": {"kind": "dynamic", "dt": 0.0025, "t_end": 0.07, "output_interval": 0.05},
    "bodies": [
        {"name": "block",
         "mesh": {"type": "rectangle", "width": 1.0, "height": 0.5, "nx": 8, "ny": 4,
                  "origin": [-0.5, 0.02]},
         "material": {"model": "neo_hookean", "E": 100.0, "nu": 0.3, "density": 1.0},
         "initial": {"velocity": [2.0, -1.5], "angular_velocity": 1.5}},
        {"name": "base",
         "mesh": {"type": "rectangle", "width": 3.0, "height": 0.5, "nx": 24, "ny": 4,
                  "origin": [-1.5, -0.5]},
         "material": {"model": "neo_hookean", "E": 100.0, "nu": 0.3, "density": 2.0},
         "initial": {"velocity": [-0.5, 0.0]}}],
    "contact": [{"name": "if", "body_1": "block", "surface_1": "bottom", "body_2": "base",
                 "surface_2": "top", "method": "augmented_lagrangian",
                 "penalty_normal": 1000.0, "penalty_tangential": 1000.0}],
}


def _toml(data: dict) -> str:
    """``data`` as a scenario file (the command reads files)."""
    lines = ["[analysis]\n" + "".join(f"{k} = {toml_value(v)}\n"
                                       for k, v in data["analysis"].items())]
    for key in ("bodies", "contact"):
        for entry in data[key]:
            lines.append(f"[[{key}]]\n" + "".join(f"{k} = {toml_value(v)}\n"
                                                  for k, v in entry.items()))
    return "\n".join(lines)


@pytest.mark.slow
def test_the_api_issues_the_warnings_the_command_prints_once(tmp_path, capsys):
    with pytest.warns(ntc.PhysicsWarning) as caught:
        results = ntc.run(ntc.scenario_from_dict(IMPACT))
    lines = [str(w.message) for w in caught if w.category is ntc.PhysicsWarning]
    assert len(lines) == 1 and lines[0].startswith("node 1 of interface 'if' went 0.0309")
    # equal spacings: detection lag, not a mismatch; no smaller dt recommended
    assert "spacings are similar (0.125 and 0.125)" in lines[0]
    assert 'contact.0.detection = "predicted"' in lines[0]
    assert "penalty_normal" not in lines[0]  # the augmented Lagrangian: the depth is the lag
    assert results.summary["integrator"] == "energy_momentum"
    assert results.summary["contact_setup"]["if"]["detection"] == "penetration"
    scenario = tmp_path / "impact.toml"
    scenario.write_text(_toml(IMPACT), encoding="utf-8")
    with warnings.catch_warnings():
        warnings.simplefilter("error", ntc.PhysicsWarning)  # the command issues none of them
        assert main(["run", str(scenario), "--out", str(tmp_path / "out"), "--quiet"]) == 0
    err = capsys.readouterr().err
    assert err.count("warning:") == 1 and f"warning: {lines[0]}" in err


def _penetrated(**setup: object) -> dict:
    """A summary whose deepest pair went 0.3 spacings deep, with the interface's settings."""
    at = {"time": 0.5, "interface": "if", "node": 3, "depth": 0.03, "element_size": 0.1}
    base = {"index": 2, "method": "augmented_lagrangian", "law": "persistency",
            "detection": "penetration", "spacing_1": 0.1, "spacing_2": 0.1,
            "ale_1": False, "ale_2": False}
    return {"max_penetration": 0.03, "max_penetration_at": at,
            "contact_setup": {"if": base | setup}}


def test_the_penetration_advice_names_only_what_applies():
    (lagging,) = result_warnings(_penetrated(), static=False)
    assert "spacings are similar" in lagging and 'contact.2.detection = "predicted"' in lagging
    assert 'mesh_motion = "ale"' in lagging and "penalty_normal" not in lagging
    assert "a smaller dt keep" not in lagging
    # the penalty method, quasi-static: the depth is traction / penalty, no detection lag
    (pressed,) = result_warnings(_penetrated(method="penalty"), static=True)
    assert "contact.2.penalty_normal" in pressed and "detection" not in pressed
    (coarse,) = result_warnings(_penetrated(method="lagrange", detection="predicted",
                                            spacing_1=0.025, ale_2=True), static=False)
    assert "surface_1 (spacing 0.025) is 4 times finer than surface_2 (0.1)" in coarse
    assert "penalty" not in coarse and "detection" not in coarse and "slide" not in coarse
    (unpaired,) = result_warnings(
        _penetrated(spacing_2=0.4) | {"max_penetration_at": None, "max_penetration": 0.01,
                                      "max_penetration_unpaired_at": {
                                          "time": 0.5, "interface": "if", "node": 3,
                                          "depth": 0.03, "element_size": 0.1}},
        static=False)
    assert "in no pair" in unpaired and "4 times finer than surface_2" in unpaired


def test_an_energy_ledger_off_by_percent_is_warned_and_the_midpoint_rule_named():
    summary = {"energy_balance_max_relative_error": 0.062, "energy_balance_max_error": 0.62,
               "integrator": "midpoint"}
    (line,) = result_warnings(summary, static=False)
    assert "0.062 of the energy scale" in line and 'integrator = "energy_momentum"' in line
    assert "mid-point rule" not in result_warnings(summary | {"integrator": "energy_momentum"},
                                                   static=False)[0]
    assert result_warnings(summary, static=True) == []  # the static works are trapezoidal sums
    assert result_warnings(summary | {"integrator": None}) == []  # the summary says static
    quiet = summary | {"energy_balance_max_relative_error": BALANCE_WARNING / 2}
    assert result_warnings(quiet, static=False) == []


def _resting(contact: dict, gravity: bool = True) -> dict:
    """A block resting on a fixed base (dynamic), under gravity or with no load at all."""
    block = {"name": "block",
             "mesh": {"type": "rectangle", "width": 1.0, "height": 0.5, "nx": 4, "ny": 2},
             "material": {"model": "linear_elastic", "E": 100.0, "nu": 0.3, "density": 1.0},
             "initial": {"velocity": [0.0, 0.0 if gravity else -1.0]}}
    if gravity:
        block["loads"] = [{"type": "gravity", "vector": [0.0, -1.0]}]
    base = {"name": "base",
            "mesh": {"type": "rectangle", "width": 1.0, "height": 0.5, "nx": 4, "ny": 2,
                     "origin": [0.0, -0.5]},
            "material": {"model": "linear_elastic", "E": 100.0, "nu": 0.3, "density": 1.0},
            "supports": [{"set": "bottom", "x": 0.0, "y": 0.0}]}
    return {"analysis": {"kind": "dynamic", "dt": 0.05, "t_end": 4.0},
            "bodies": [block, base],
            "contact": [{"name": "rest", "body_1": "block", "surface_1": "bottom",
                         "body_2": "base", "surface_2": "top", "penalty_normal": 100.0}
                        | contact]}


def _build_warnings(data: dict) -> list[str]:
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        model_from_dict(copy.deepcopy(data))
    return [str(w.message) for w in caught if w.category is ntc.PhysicsWarning]


def test_penalty_under_the_rate_law_with_a_sustained_load_is_warned_at_build():
    (line,) = _build_warnings(_resting({"method": "penalty"}))
    assert line.startswith("contact.0 ('rest'): method = \"penalty\" under the persistency law")
    assert "gravity on 'block'" in line and 'method = "augmented_lagrangian"' in line
    assert 'law = "gap"' in line
    # an impact with no load, the gap law, the augmented Lagrangian: nothing to say
    assert _build_warnings(_resting({"method": "penalty"}, gravity=False)) == []
    assert _build_warnings(_resting({"method": "penalty", "law": "gap"})) == []
    assert _build_warnings(_resting({"method": "augmented_lagrangian"})) == []
    # a load that returns to zero before t_end is no sustained load
    ramp = _resting({"method": "penalty"})
    ramp["bodies"][0]["loads"][0]["function"] = {"times": [0.0, 1.0, 2.0],
                                                 "values": [0.0, 1.0, 0.0]}
    assert _build_warnings(ramp) == []
    # a load on a body no interface joins to this one: nothing (a tester's third body); a load
    # on a block stacked on the contact's upper body: warned
    far = _resting({"method": "penalty"}, gravity=False)
    far["bodies"].append({"name": "far", "mesh": {"type": "rectangle", "width": 1.0,
                                                  "height": 0.5, "nx": 2, "ny": 1,
                                                  "origin": [10.0, 0.0]},
                          "material": {"model": "linear_elastic", "E": 100.0, "nu": 0.3,
                                       "density": 1.0},
                          "loads": [{"type": "gravity", "vector": [0.0, -1.0]}]})
    assert _build_warnings(far) == []
    stacked = copy.deepcopy(far)
    stacked["bodies"][2]["mesh"]["origin"] = [0.0, 0.5]
    stacked["contact"].append({"name": "stack", "body_1": "far", "surface_1": "bottom",
                               "body_2": "block", "surface_2": "top",
                               "method": "augmented_lagrangian", "penalty_normal": 100.0})
    (line,) = _build_warnings(stacked)
    assert line.startswith("contact.0 ('rest')") and "gravity on 'far'" in line


def test_the_balance_warning_names_what_the_ledger_leaves_out():
    """A tester's bar driven by a moving support and a disk drop with conserve_energy =
    "kinetic" were told the time integration (or the mid-point rule) made the imbalance,
    which the support's work (8e-12) or the remap's energy (9e-12) closed."""
    summary = {"energy_balance_max_relative_error": 0.0043, "integrator": "midpoint",
               "outside_ledger": ["the work of supports with prescribed motion"]}
    (line,) = result_warnings(summary, static=False)
    assert "leaves out the work of supports with prescribed motion" in line
    assert "energy_momentum" not in line


def test_an_opening_entered_by_predicted_detection_is_explained_as_such():
    summary = {"max_separation_under_traction": 0.00785,
               "max_separation_under_traction_at": {"time": 0.1, "interface": "if",
                                                    "node": 8, "opening": 0.00785,
                                                    "element_size": 0.05},
               "contact_setup": {"if": _penetrated(detection="predicted")["contact_setup"]["if"]}}
    (line,) = result_warnings(summary, static=False)
    assert "entered early" in line and "release_steps" not in line


@pytest.mark.slow
def test_a_sweep_case_records_its_warnings_also_when_skipped(tmp_path):
    from ntncontact.studies.sweep import run_case

    scenario = tmp_path / "impact.toml"
    scenario.write_text(_toml(IMPACT), encoding="utf-8")
    with warnings.catch_warnings():
        warnings.simplefilter("error", ntc.PhysicsWarning)  # recorded, not issued
        rows = [run_case(str(scenario), {"analysis.dt": 0.0025}, str(tmp_path / "case"), {})
                for _ in range(2)]
    assert [row["skipped"] for row in rows] == [False, True]
    for row in rows:
        assert row["warnings"].startswith("node 1 of interface 'if' went 0.0309")


def test_a_failed_run_warns_before_its_error_as_it_was_raised(monkeypatch):
    """The command prints a failed run's warnings before its error; so does the API (the
    step's failure is faked here: the summary so far shows a deep pair)."""
    from ntncontact.engine.simulation import SimulationError
    from ntncontact.io import run_setup

    class Failing:
        def __init__(self, model, observers):
            self.writer = observers[0]

        def run(self, progress=None):
            self.writer.results.summary.update(**_penetrated())
            raise SimulationError("step 3 failed")

    monkeypatch.setattr(run_setup, "Simulation", Failing)
    with pytest.warns(ntc.PhysicsWarning, match="node 3 of interface 'if' went 0.03"):
        with pytest.raises(SimulationError, match="^step 3 failed$") as err:
            ntc.run(ntc.scenario_from_dict(IMPACT))
    assert err.value.__context__ is None and err.value.__cause__ is None


def test_an_opening_under_traction_and_a_linear_body_turned_far_are_warned_about():
    """Session 39's summary keys: a pressed pair open by 0.18 of the spacing (a tester's soft
    block between walls) and a linear elastic element turned by 0.41 rad (the report's
    delamination) each give one line; below their thresholds nothing."""
    opening = {"max_separation_under_traction": 0.022,
               "max_separation_under_traction_at": {"time": 3.77, "interface": "left",
                                                    "node": 36, "opening": 0.022,
                                                    "element_size": 0.125}}
    turned = {"max_linear_elastic_rotation": 0.41,
              "max_linear_elastic_rotation_at": {"time": 14.0, "body": "upper"}}
    lines = result_warnings(opening | turned, static=False)
    assert len(lines) == 2
    assert "node 36 of interface 'left' was pressed across an open gap of 0.022" in lines[0]
    assert "'upper' turned by 0.41 rad" in lines[1] and "1 - cos = 0.083" in lines[1]
    assert "angular momentum" in lines[1]  # a dynamic run: L drifts too
    # a static run (the report's delamination is one) has no momentum to speak of
    static = result_warnings(turned, static=True)
    assert len(static) == 1 and "angular momentum" not in static[0]
    assert "free flight" not in static[0] and "1 - cos = 0.083" in static[0]
    opening["max_separation_under_traction_at"]["opening"] = 0.012  # 0.096 of the spacing
    turned["max_linear_elastic_rotation"] = 0.099
    assert result_warnings(opening | turned, static=False) == []


def test_build_warnings_are_kept_in_the_summary_and_a_sweeps_row(tmp_path, capsys):
    """A tester's sweep case with penalty under the rate law had an empty warnings column,
    though `ntncontact run` printed the build-time warning for it."""
    from ntncontact.studies.sweep import run_case

    scenario = tmp_path / "rest.toml"
    scenario.write_text(_toml(_resting({"method": "penalty"}) | {
        "analysis": {"kind": "dynamic", "dt": 0.05, "t_end": 0.1}}), encoding="utf-8")
    assert main(["run", str(scenario), "--out", str(tmp_path / "run"), "--quiet"]) == 0
    err = capsys.readouterr().err
    assert err.count("cannot carry the sustained gravity") == 1  # printed once
    summary = ntc.read_results(tmp_path / "run").summary
    (kept,) = summary["build_warnings"]
    assert "cannot carry the sustained gravity on 'block'" in kept
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # a worker issues none: they are in the row
        row = run_case(str(scenario), {"analysis.dt": 0.05}, str(tmp_path / "case"), {})
    assert "cannot carry the sustained gravity" in row["warnings"]


def test_a_node_of_a_mesh_file_is_named_by_its_number_in_the_file_too():
    """A tester's 10^4-element gmsh run warned about "node 100", which is node 14745 of the
    user's file."""
    summary = _penetrated()
    summary["max_penetration_at"]["file_node"] = 14745
    (line,) = result_warnings(summary, static=False)
    assert line.startswith("node 3 (file node 14745) of interface 'if' went 0.03")
    summary["max_penetration_at"]["file_node"] = -1  # a generated mesh: no file number
    (line,) = result_warnings(summary, static=False)
    assert line.startswith("node 3 of interface 'if'")


def test_a_dynamic_support_that_starts_away_from_zero_is_warned_about():
    """A tester's bar held at x = 0.01 from t = 0: its nodes jumped in the first step and swung
    between 0 and 0.02, the energy growing 0 -> 2.33. A ramp from 0 is not warned about."""
    data = _resting({"method": "augmented_lagrangian"}, gravity=False)
    data["bodies"][1]["supports"] = [{"set": "bottom", "x": 0.01, "y": 0.0}]
    (line,) = _build_warnings(data)
    assert "supports.0 (set 'bottom'): it prescribes a displacement other than 0 at t = 0" in line
    data["bodies"][1]["supports"][0]["function"] = {"times": [0.0, 1.0], "values": [0.0, 1.0]}
    assert _build_warnings(data) == []


def test_no_penalty_warning_for_a_supported_or_zero_load():
    """False alarms a tester found: the weight of a supported body goes to its supports, and
    gravity [0, 0] is no load."""
    supported = _resting({"method": "penalty"}, gravity=False)
    supported["bodies"][1]["loads"] = [{"type": "gravity", "vector": [0.0, -1.0]}]
    assert _build_warnings(supported) == []
    zero = _resting({"method": "penalty"})
    zero["bodies"][0]["loads"][0]["vector"] = [0.0, 0.0]
    assert _build_warnings(zero) == []
