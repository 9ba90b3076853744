"""summary.json ``max_separation_under_traction``: the widest open gap of a pair that carries
a normal traction (docs/scenarios.md). Under the persistency law a pair that opened in a step
without traction and was pressed again before its release holds that opening: an independent
tester's bars of unequal impedance (E 400 against 100) open by 1.1e-3 at t = 1.2 and then
carry the contact force across the opening until t = 2.0, which nothing reported."""

from __future__ import annotations

import pytest

import ntncontact as ntc


def bars(hard: float) -> dict:
    """Two bars, 80 elements each, the left one (modulus ``hard``) hitting the right (100)."""
    def bar(name: str, E: float, x0: float, v: float) -> dict:
        return {"name": name, "mesh": {"type": "rectangle", "width": 10.0, "height": 1.0,
                                       "nx": 80, "ny": 1, "origin": [x0, 0.0]},
                "material": {"model": "linear_elastic", "E": E, "nu": 0.0, "density": 1.0},
                "initial": {"velocity": [v, 0.0]}}
    return {"analysis": {"kind": "dynamic", "dt": 0.025, "t_end": 2.5, "output_interval": 2.5},
            "bodies": [bar("a", hard, -10.05, 1.0), bar("b", 100.0, 0.0, 0.0)],
            "contact": [{"name": "ends", "body_1": "a", "surface_1": "right", "body_2": "b",
                         "surface_2": "left", "method": "augmented_lagrangian",
                         "law": "persistency", "penalty_normal": 1000.0}]}


@pytest.fixture(scope="module")
def unequal():
    return ntc.run(ntc.scenario_from_dict(bars(400.0)))


def test_the_widest_opening_under_traction_is_reported_where_it_is(unequal):
    contact, summary = unequal.contact, unequal.summary
    pressed = contact[contact["normal_traction"] > 0.0]
    assert summary["max_separation_under_traction"] == pytest.approx(
        -pressed["end_gap"].min(), rel=1e-12)
    assert summary["max_separation_under_traction"] > 1e-3  # measured 1.1e-3
    at = summary["max_separation_under_traction_at"]
    assert at["interface"] == "ends" and at["element_size"] == pytest.approx(1.0)
    assert at["file_node"] == -1  # a generated mesh
    row = pressed.loc[pressed["end_gap"].idxmin()]
    assert at["node"] == row["node_1"] and at["time"] == pytest.approx(row["time"])


def test_bars_of_equal_impedance_hold_no_opening():
    """Equal bars separate at once at the end of contact (2L/c): no pair opens under
    traction, so the key stays at its start value."""
    summary = ntc.run(ntc.scenario_from_dict(bars(100.0))).summary
    assert summary["max_separation_under_traction"] == 0.0
    assert summary["max_separation_under_traction_at"] is None


def test_gap_law_pairs_are_not_counted():
    """The gap law holds its mid-step gap at zero while its step-end gap swings (a tester's
    gap-law slide: -4e-16 and -0.0069): no opening is held, so the key stays 0."""
    data = bars(400.0)
    data["contact"][0] |= {"method": "lagrange", "law": "gap"}
    del data["contact"][0]["penalty_normal"]
    results = ntc.run(ntc.scenario_from_dict(data))
    pressed = results.contact[results.contact["normal_traction"] > 0.0]
    assert pressed["end_gap"].min() < -1e-3  # the step ends do swing open
    assert results.summary["max_separation_under_traction"] == 0.0
