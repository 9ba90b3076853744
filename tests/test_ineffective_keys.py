"""Keys an interface's method or friction never reads are warned of at the build, once each,
and summary.json's contact_penalties gives only the penalties the run used (tester B, F4: a
penalty run with an augmentation table, and Lagrange runs at penalty_normal = 1000 and 10,
were identical to runs without, and the summary said 1000 and 10 were used)."""

import copy
import warnings

import pytest

import ntncontact as ntc
from ntncontact import api
from ntncontact.cli import main
from ntncontact.engine.builder import _warn_ineffective_keys as warn_ineffective_keys
from ntncontact.io.scenario import toml_value


def pressed_block(contact: dict) -> dict:
    """A 2 x 1 block under a ramped pressure on a fixed foundation, matching meshes (static)."""
    ramp = {"times": [0.0, 1.0], "values": [0.0, 1.0]}
    return {
        "analysis": {"kind": "static", "dt": 0.5, "t_end": 1.0},
        "bodies": [
            {"name": "block",
             "mesh": {"type": "rectangle", "width": 2.0, "height": 1.0, "nx": 4, "ny": 2},
             "material": {"model": "linear_elastic", "E": 100.0, "nu": 0.3, "density": 2.0},
             "supports": [{"set": "left", "x": 0.0}],
             "loads": [{"type": "pressure", "set": "top", "value": 5.0, "function": ramp}]},
            {"name": "base",
             "mesh": {"type": "rectangle", "width": 2.0, "height": 1.0, "nx": 4, "ny": 2,
                      "origin": [0.0, -1.0]},
             "material": {"model": "linear_elastic", "E": 1000.0, "nu": 0.3, "density": 1.0},
             "supports": [{"set": "bottom", "x": 0.0, "y": 0.0}]}],
        "contact": [{"name": "press", "body_1": "block", "surface_1": "bottom",
                     "body_2": "base", "surface_2": "top"} | contact],
    }


def ineffective(contact: dict) -> list[str]:
    """The warnings of :func:`warn_ineffective_keys` for the pressed block with ``contact``."""
    config = api.scenario_from_dict(pressed_block(copy.deepcopy(contact))).config
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        warn_ineffective_keys(config)
    assert all(w.category is ntc.PhysicsWarning for w in caught)
    return [str(w.message) for w in caught]


AL = {"method": "augmented_lagrangian", "penalty_normal": 1e4}


@pytest.mark.parametrize(("contact", "keys", "why"), [
    ({"method": "penalty", "penalty_normal": 1e4,
      "augmentation": {"max_iterations": 5, "update": "newton"}},
     ["augmentation.max_iterations", "augmentation.update"], 'method = "penalty"'),
    ({"method": "lagrange", "penalty_normal": 1000.0}, ["penalty_normal = 1000.0"],
     'method = "lagrange"'),
    ({"method": "lagrange", "penalty_factor": 10.0}, ["penalty_factor = 10.0"],
     "without friction"),
    ({"method": "lagrange", "friction": 0.3, "penalty_tangential": 5.0,
      "penalty_factor": 10.0}, ["penalty_factor = 10.0"], "penalty_tangential gives"),
    ({"method": "lagrange", "augmentation": {"gap_tolerance": 1e-9, "update": "newton",
                                             "max_iterations": 3}},
     ["augmentation.gap_tolerance", "augmentation.update"], "not augmented"),
    (AL | {"augmentation": {"slip_tolerance": 1e-7, "traction_tolerance": 1e-6}},
     ["augmentation.slip_tolerance", "augmentation.traction_tolerance"], "frictionless"),
])
def test_each_key_without_effect_is_warned_once_naming_it_and_the_interface(contact, keys, why):
    (line,) = ineffective(contact)
    assert line.startswith("contact.0 ('press'): ")
    for key in keys:
        assert line.count(key) == 1
    assert why in line and "no effect" in line


def test_keys_the_method_reads_are_not_warned_of():
    assert ineffective(AL | {"augmentation": {"max_iterations": 5, "update": "newton"}}) == []
    assert ineffective(AL | {"friction": 0.3, "penalty_tangential": 1e3,
                             "augmentation": {"slip_tolerance": 1e-7}}) == []
    # Lagrange's passes that release tensile pairs are bounded by these
    assert ineffective({"method": "lagrange",
                        "augmentation": {"max_iterations": 3, "on_limit": "accept"}}) == []
    assert ineffective({"method": "lagrange", "penalty_normal": 0.0}) == []
    # with friction and no penalty_tangential, the factor gives Lagrange its eps_T
    assert ineffective({"method": "lagrange", "friction": 0.3, "penalty_factor": 10.0}) == []
    # a frictionless file kept ready for --set contact.0.friction: not noise
    assert ineffective(AL | {"penalty_tangential": 1e3}) == []
    assert ineffective({"method": "penalty", "penalty_normal": 1e4}) == []


def test_a_run_keeps_the_warning_and_reports_only_the_penalties_it_used():
    scenario = api.scenario_from_dict(pressed_block({"method": "lagrange",
                                                     "penalty_normal": 1000.0}))
    with pytest.warns(ntc.PhysicsWarning, match="penalty_normal = 1000.0 has no effect"):
        results = api.run(scenario, out=None)
    (line,) = results.summary["build_warnings"]
    assert line.startswith("contact.0 ('press'): penalty_normal = 1000.0")
    assert results.summary["contact_penalties"]["press"] == {"normal": None, "tangential": None}
    friction = scenario.with_overrides({"contact.0.friction": 0.2,
                                        "contact.0.penalty_tangential": 50.0,
                                        "contact.0.penalty_normal": 0.0,
                                        # the report's forces leave a net moment of 0.2 % of
                                        # their scale here (warned since session 42)
                                        "contact.0.moment_free": True})
    with warnings.catch_warnings():
        warnings.simplefilter("error", ntc.PhysicsWarning)  # nothing to say of this one
        results = api.run(friction, out=None)
    assert results.summary["build_warnings"] == []
    assert results.summary["contact_penalties"]["press"] == {"normal": None,
                                                             "tangential": 50.0}


def test_the_command_prints_it_once_and_keeps_it_in_the_summary(tmp_path, capsys):
    scenario = tmp_path / "press.toml"
    data = pressed_block({"method": "penalty", "penalty_normal": 1e4,
                          "augmentation": {"max_iterations": 5}})
    text = "\n".join(f"{key} = {toml_value(value)}" for key, value in data.items())
    scenario.write_text(text, encoding="utf-8")
    assert main(["run", str(scenario), "--out", str(tmp_path / "run"), "--quiet"]) == 0
    err = capsys.readouterr().err
    assert err.count("augmentation.max_iterations has no effect") == 1
    summary = ntc.read_results(tmp_path / "run").summary
    (kept,) = summary["build_warnings"]
    assert "augmentation.max_iterations has no effect with method = \"penalty\"" in kept
    assert summary["contact_penalties"]["press"] == {"normal": 1e4, "tangential": None}
