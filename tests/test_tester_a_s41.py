"""Session 41, tester A's findings 3 to 7: warnings and errors that told less than the truth
(an energy blow-up read "off by 0.99", a 6-fold stretch read as a 1.41 rad turn, 40 % linear
strain in silence, a static load without a time function halved 4 times to no avail, and
dynamic-only inputs dropped in static runs)."""

from __future__ import annotations

import numpy as np
import pytest
from helpers import model_from_dict

import ntncontact as ntc
from ntncontact.engine.diagnostics import linear_elastic_measures
from ntncontact.engine.simulation import Simulation, SimulationError
from ntncontact.io.scenario import ScenarioError
from ntncontact.report.run_warnings import result_warnings

#: the tester's mid-point spin (f5_spin.toml, dt = 0.4, t_end = 8): its summary's figures
BLOWN_UP = {"integrator": "midpoint", "outside_ledger": [], "energy_initial": 6.956666666666666,
            "energy_max_relative_variation": 125.31716747405656,
            "energy_balance_max_relative_error": 0.9920834196966506,
            "energy_balance_max_error": 871.7897617278534}


def test_an_energy_blow_up_is_quoted_against_the_initial_energy():
    (line,) = [w for w in result_warnings(BLOWN_UP) if "energy balance is off" in w]
    assert "0.99 of the energy scale" in line  # the documented figure stays
    assert "by 125 times the initial energy E0 = 6.96" in line


def test_a_small_balance_error_is_not_quoted_against_the_initial_energy():
    drift = BLOWN_UP | {"energy_balance_max_error": 0.05, "energy_max_relative_variation": 7e-3,
                        "energy_balance_max_relative_error": 7e-3}
    (line,) = [w for w in result_warnings(drift) if "energy balance is off" in w]
    assert "initial energy" not in line


def cantilever(**load: object) -> dict:
    """A Neo-Hookean cantilever under a tip shear, one load step, Newton cut short at 2
    iterations so that the step fails."""
    return {"analysis": {"kind": "static", "dt": 1.0, "t_end": 1.0,
                         "newton": {"max_iterations": 2}},
            "bodies": [{"name": "beam",
                        "mesh": {"type": "rectangle", "width": 10.0, "height": 1.0,
                                 "nx": 10, "ny": 2},
                        "material": {"model": "neo_hookean", "E": 1000.0, "nu": 0.4,
                                     "density": 1.0},
                        "supports": [{"set": "left", "x": 0.0, "y": 0.0}],
                        "loads": [{"type": "traction", "set": "right",
                                   "vector": [0.0, -0.1]} | load]}]}


def attempts(monkeypatch, data: dict) -> tuple[list[float], str]:
    """The sub-step lengths tried, and the error's message."""
    tried: list[float] = []
    advance = Simulation.advance

    def counted(self, state, h):
        tried.append(h)
        return advance(self, state, h)

    monkeypatch.setattr(Simulation, "advance", counted)
    with pytest.raises(SimulationError) as err:
        Simulation(model_from_dict(data)).run()
    return tried, str(err.value)


def test_a_static_load_without_a_time_function_is_not_halved_in_vain(monkeypatch):
    """Every halving applied the same load from the same start (the tester's |R| 6.756e-4 five
    times), and "the last attempt was t = 0 -> 0.0625" suggested a 16th of it."""
    tried, message = attempts(monkeypatch, cantilever())
    assert tried == [1.0]
    assert "halvings" not in message and "last attempt" not in message
    assert "the step was not halved" in message and "same load" in message
    assert "analysis.newton.max_iterations" in message and "function = {" in message


def test_a_ramped_static_load_is_still_halved(monkeypatch):
    ramp = {"function": {"times": [0.0, 1.0], "values": [0.0, 1.0]}}
    tried, message = attempts(monkeypatch, cantilever(**ramp))
    assert tried[:3] == [1.0, 0.5, 0.25]
    assert "not halved" not in message


def test_the_measures_of_a_drifted_spin_and_a_compression():
    """x = X + t omega x X at omega t = 6 (the tester's block): F = I + 6 W, polar rotation
    atan(6) = 1.41, stretch sqrt(37) = 6.1, Green strain 18; uniaxial 40 % compression:
    Green strain 0.32 and no rotation."""
    model = model_from_dict(cantilever() | {"bodies": [cantilever()["bodies"][0] | {
        "material": {"model": "linear_elastic", "E": 1.0, "nu": 0.3, "density": 1.0}}]})
    X = model.X0
    spun = linear_elastic_measures(model, X, 6.0 * X @ np.array([[0.0, 1.0], [-1.0, 0.0]]))
    assert spun["rotation"] == (pytest.approx(np.arctan(6.0)), "beam")
    assert spun["stretch"][0] == pytest.approx(np.sqrt(37.0))
    assert spun["strain"][0] == pytest.approx(18.0)
    squashed = linear_elastic_measures(model, X, X * [0.0, -0.4])
    assert squashed["rotation"][0] == pytest.approx(0.0, abs=1e-14)
    assert squashed["strain"][0] == pytest.approx(0.32)
    assert squashed["stretch"][0] == pytest.approx(1.0)


#: the tester's spinning block made linear elastic (f4_spinning_block.toml, t = 2)
SPUN = {"integrator": "energy_momentum", "max_linear_elastic_rotation": 1.4056,
        "max_linear_elastic_rotation_at": {"time": 2.0, "body": "block"},
        "max_linear_elastic_stretch": 6.08, "max_linear_elastic_stretch_at": {
            "time": 2.0, "body": "block"}}


def test_a_drifted_spin_is_reported_by_its_stretch_not_as_a_turn():
    (line,) = [w for w in result_warnings(SPUN) if "max_linear_elastic_rotation" in w]
    assert "stretched 6.08-fold" in line and "not how far the body turned" in line
    assert "turned by" not in line and "1 - cos = 0.84" not in line  # the tester's misreading


def test_a_corner_that_turned_and_stretched_a_little_is_reported_as_turned():
    """The block sliding example: 0.205 rad and a stretch of 1.23 at the pushed corner."""
    corner = SPUN | {"max_linear_elastic_rotation": 0.205, "max_linear_elastic_stretch": 1.23}
    (line,) = [w for w in result_warnings(corner) if "max_linear_elastic_rotation" in w]
    assert "turned by 0.205 rad" in line and "largest principal stretch was 1.23" in line
    assert "not how far" not in line


def compressed_block(tmp_path, model: str):
    """The tester's f6_nh_comp.toml: a 4 x 4 block squashed by 40 %, lateral free."""
    path = tmp_path / "squash.toml"
    path.write_text(f"""
[analysis]
kind = "static"
dt = 0.1
t_end = 1.0
[[bodies]]
name = "blk"
mesh = {{ type = "rectangle", width = 1.0, height = 1.0, nx = 4, ny = 4 }}
material = {{ model = "{model}", E = 100.0, nu = 0.3, density = 1.0 }}
supports = [
  {{ set = "bottom", y = 0.0 }},
  {{ set = "left", x = 0.0 }},
  {{ set = "top", y = -0.4, function = {{ times = [0.0, 1.0], values = [0.0, 1.0] }} }},
]
""")
    return ntc.run(ntc.load_scenario(path))


def test_a_linear_block_at_40_percent_strain_is_warned_about(tmp_path):
    with pytest.warns(ntc.PhysicsWarning, match="Green-Lagrange strain of 0.32"):
        summary = compressed_block(tmp_path, "linear_elastic").summary
    assert summary["max_linear_elastic_strain"] == pytest.approx(0.32)
    assert summary["max_linear_elastic_strain_at"] == {"time": 1.0, "body": "blk"}
    assert summary["max_linear_elastic_rotation"] < 1e-12
    (line,) = [w for w in result_warnings(summary) if "max_linear_elastic_strain" in w]
    assert "Green-Lagrange strain of 0.32" in line and 'model = "neo_hookean"' in line
    assert not [w for w in result_warnings(summary) if "max_linear_elastic_rotation" in w]
    assert "max_linear_elastic_strain" not in compressed_block(tmp_path, "neo_hookean").summary


def test_a_strain_below_the_limit_is_not_warned_about():
    """The rod impact example, the report's linear benchmark: 0.067."""
    rod = {"max_linear_elastic_strain": 0.067,
           "max_linear_elastic_strain_at": {"time": 0.2, "body": "rod_left"}}
    assert not [w for w in result_warnings(rod) if "strain" in w]


def test_a_static_run_takes_an_explicit_zero_velocity():
    """A zero initial velocity is what a static run does anyway: refusing it (as this session
    first did) broke files that set it explicitly (tester R, session 41)."""
    data = cantilever(function={"times": [0.0, 1.0], "values": [0.0, 0.01]})
    data["analysis"]["newton"] = {"max_iterations": 25}
    data["bodies"][0]["initial"] = {"velocity": [0.0, 0.0], "angular_velocity": 0.0}
    Simulation(model_from_dict(data)).run()
    data["bodies"][0]["initial"] = {"velocity": [0.0, 1.0]}
    with pytest.raises(ScenarioError, match="initial.velocity"):
        model_from_dict(data)
