"""Session 41, tester A's findings 3 to 7: warnings and errors that told less than the truth
(an energy blow-up read "off by 0.99", a 6-fold stretch read as a 1.41 rad turn, 40 % linear
strain in silence, a static load without a time function halved 4 times to no avail, and
dynamic-only inputs dropped in static runs)."""

from __future__ import annotations

import pytest
from helpers import model_from_dict

from ntncontact.engine.simulation import Simulation, SimulationError
from ntncontact.report.run_warnings import result_warnings

#: the tester's mid-point spin (f5_spin.toml, dt = 0.4, t_end = 8): its summary's figures
BLOWN_UP = {"integrator": "midpoint", "outside_ledger": [], "energy_initial": 6.956666666666666,
            "energy_max_relative_variation": 125.31716747405656,
            "energy_balance_max_relative_error": 0.9920834196966506,
            "energy_balance_max_error": 871.7897617278534}


def test_an_energy_blow_up_is_quoted_against_the_initial_energy():
    (line,) = [w for w in result_warnings(BLOWN_UP) if "energy balance is off" in w]
    assert "0.99 of the energy scale" in line  # the documented figure stays
    assert "125 times the initial energy E0 = 6.96" in line


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
