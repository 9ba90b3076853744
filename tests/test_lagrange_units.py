"""Lagrange multipliers in any stress unit: E, density and loads scaled by one factor s change
no kinematics, so displacements and contact times must agree to round-off and the reported
tractions scale by s. Tester B (session 41) found every ``method = "lagrange"`` run failing
at its first contact step from E ~ 1e10 on ("matrix is numerically singular: 9 pivot(s)
below 1e-12 x the largest"): a static block at E = 1e10, the report's rods at E = 1e11, two
steel rods in SI units (E = 2e11 Pa, rho = 7850). The multiplier unknowns are tractions and
their pivots were O(L_c) against the stiffness's O(E); the pivot check now weighs them at the
stiffness's scale (``solvers/linear.py``, ``_check_pivots``)."""

from __future__ import annotations

import numpy as np
import pytest

from ntncontact import api

RTOL = 1e-10


def pressed_block(s: float) -> dict:
    """A block pressed by p = s onto a held base (E = 100 s and 1000 s), static, lagrange."""
    return {
        "title": "block on base, lagrange",
        "analysis": {"kind": "static", "dt": 0.5, "t_end": 1.0},
        "bodies": [
            {"name": "block",
             "mesh": {"type": "rectangle", "width": 2.0, "height": 1.0, "nx": 4, "ny": 2,
                      "origin": [1.0, 1.0]},
             "material": {"model": "linear_elastic", "E": 100.0 * s, "nu": 0.3,
                          "density": 1.0},
             "loads": [{"type": "pressure", "set": "top", "value": 1.0 * s,
                        "function": {"times": [0.0, 1.0], "values": [0.0, 1.0]}}],
             "supports": [{"set": "corner_top_left", "x": 0.0}]},
            {"name": "base",
             "mesh": {"type": "rectangle", "width": 4.0, "height": 1.0, "nx": 8, "ny": 2,
                      "origin": [0.0, 0.0]},
             "material": {"model": "linear_elastic", "E": 1000.0 * s, "nu": 0.3,
                          "density": 1.0},
             "supports": [{"set": "bottom", "x": 0.0, "y": 0.0}]},
        ],
        "contact": [{"name": "c", "body_1": "block", "surface_1": "bottom", "body_2": "base",
                     "surface_2": "top", "method": "lagrange", "law": "gap"}],
    }


def rods(E: float, density: float, length: float, nx: int = 10, law: str = "persistency") -> dict:
    """Two equal rods, the left one hitting the resting right one at v = 1 on a step
    boundary (dt = 2 h / c, the gap v dt), lagrange; with the gap law energy-conserving
    (report 5.5: one more border column, theta)."""
    c = np.sqrt(E / density)
    dt = 2.0 * length / nx / c
    rod = {"model": "linear_elastic", "E": E, "nu": 0.0, "density": density}
    height = length / 10.0
    return {
        "title": "two rods, lagrange",
        "analysis": {"kind": "dynamic", "dt": dt, "t_end": 12.0 * dt, "mass": "consistent",
                     "output_interval": dt, "energy_conserving": law == "gap"},
        "bodies": [
            {"name": "left", "mesh": {"type": "rectangle", "width": length, "height": height,
                                      "nx": nx, "ny": 1, "origin": [-length - dt, 0.0]},
             "material": rod, "initial": {"velocity": [1.0, 0.0]}},
            {"name": "right", "mesh": {"type": "rectangle", "width": length,
                                       "height": height, "nx": nx, "ny": 1,
                                       "origin": [0.0, 0.0]},
             "material": rod},
        ],
        "contact": [{"name": "ends", "body_1": "left", "surface_1": "right", "body_2": "right",
                     "surface_2": "left", "method": "lagrange", "law": law}],
    }


def run(data: dict) -> api.Results:
    return api.run(api.scenario_from_dict(data), out=None)


def displacement(results: api.Results) -> np.ndarray:
    return results.fields(results.times[-1]).point_data["displacement"]


def assert_same_run(scaled: api.Results, unit: api.Results, s: float,
                    pairs: bool = True) -> None:
    """The same displacements and contact times; tractions and energies times s.
    ``pairs=False``: only displacements and energies (see the gap law's rods)."""
    assert scaled.summary["status"] == "completed"
    u, u1 = displacement(scaled), displacement(unit)
    assert np.abs(u - u1).max() <= RTOL * np.abs(u1).max()
    energy, energy1 = scaled.history["total_energy"], unit.history["total_energy"]
    assert np.abs(energy / s - energy1).max() <= RTOL * energy1.abs().max()
    if not pairs:
        return
    for key in ("contact_start_time", "contact_end_time"):
        assert scaled.summary[key] == pytest.approx(unit.summary[key], rel=RTOL)
    t_n, t_n1 = scaled.contact["normal_traction"], unit.contact["normal_traction"]
    assert len(t_n) == len(t_n1) and t_n1.abs().max() > 0.0
    assert np.abs(t_n / s - t_n1).max() <= RTOL * t_n1.abs().max()


@pytest.mark.parametrize("s", [1e-10, 1e10])
def test_a_static_lagrange_block_is_the_same_in_any_stress_unit(s):
    unit = run(pressed_block(1.0))
    assert unit.summary["status"] == "completed"
    assert_same_run(run(pressed_block(s)), unit, s)


@pytest.mark.parametrize("law", ["persistency", "gap"])
def test_a_lagrange_rod_impact_is_the_same_in_any_stress_unit(law):
    """The report's rods (E = 100, rho = 1) and E = 1e12, rho = 1e10: the same wave speed.
    The gap law's pair enters a step before the touch and carries a round-off multiplier
    there (6e-14 of the peak at s = 1, none at s = 1e10): Lagrange counts any t_N > 0 as
    contact (docs/outputs.md), so its pairs and contact start differ by that step; the
    motion does not."""
    unit = run(rods(100.0, 1.0, 10.0, law=law))
    assert_same_run(run(rods(1e12, 1e10, 10.0, law=law)), unit, 1e10,
                    pairs=law == "persistency")


def test_steel_rods_in_si_units_run_with_lagrange():
    """E = 2e11 Pa, rho = 7850 kg/m^3, L = 1 m: the same run as in a stress unit 1e10 times
    larger, and contact for 2 L / c (one step more: the pair leaves at a step's end)."""
    steel = run(rods(2e11, 7850.0, 1.0))
    assert_same_run(steel, run(rods(20.0, 7.85e-7, 1.0)), 1e10)
    c, dt = np.sqrt(2e11 / 7850.0), 2.0 * 0.1 / np.sqrt(2e11 / 7850.0)
    duration = steel.summary["contact_end_time"] - steel.summary["contact_start_time"]
    assert abs(duration - 2.0 / c) <= 1.01 * dt
