"""A body that crosses a thin partner within one step (engine.diagnostics.StepCrossingCheck,
summary.json ``max_contact_step``). From an independent tester: a disk at vy = -20 with
dt = 0.015 (100 times the dt rule) ended its first step wholly below a 0.05-thick plate;
contact detects at the steps' ends, so the run completed with ``max_penetration`` 0.0, an
energy variation of 3e-16 and no warning. (Pairs that enter later now report a depth, which
names the detection lag, not the crossing.)"""

from __future__ import annotations

import warnings

import pytest
from helpers import model_from_dict

import ntncontact as ntc
from ntncontact.engine.diagnostics import StepCrossingCheck


def pellet_on_plate(dt: float, t_end: float, detection: str = "penetration") -> dict:
    """The tester's t16_tunnel.toml: a disk (R 0.1) at vy = -20 over a plate 0.05 thick,
    surface spacing 0.05, held at both ends."""
    material = {"model": "neo_hookean", "E": 1e5, "nu": 0.3, "density": 1.0}
    return {
        "analysis": {"kind": "dynamic", "dt": dt, "t_end": t_end, "output_interval": t_end},
        "bodies": [
            {"name": "pellet", "mesh": {"type": "disk", "radius": 0.1, "n_circ": 16,
                                        "n_radial": 2, "center": [0.0, 0.13]},
             "material": material, "initial": {"velocity": [0.0, -20.0]}},
            {"name": "plate", "mesh": {"type": "rectangle", "width": 2.0, "height": 0.05,
                                       "nx": 40, "ny": 1, "origin": [-1.0, -0.05]},
             "material": material,
             "supports": [{"set": "left", "x": 0.0, "y": 0.0},
                          {"set": "right", "x": 0.0, "y": 0.0}]}],
        "contact": [{"name": "c", "body_1": "pellet", "surface_1": "outer", "body_2": "plate",
                     "surface_2": "top", "penalty_factor": 50.0, "detection": detection}]}


def run(data: dict) -> tuple[dict, list[str]]:
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        results = ntc.run(ntc.scenario_from_dict(data))
    return results.summary, [str(w.message) for w in caught
                             if issubclass(w.category, ntc.PhysicsWarning)]


def test_a_disk_through_a_thin_plate_within_one_step_is_warned_about():
    summary, lines = run(pellet_on_plate(0.015, 0.045))
    assert summary["status"] == "completed"
    # the bottom node's first step: 0.3 against the plate's spacing 0.05
    assert summary["max_contact_step"] == pytest.approx(6.0, rel=0.05)
    at = summary["max_contact_step_at"]
    assert at["interface"] == "c" and at["element_size"] == pytest.approx(0.05)
    assert at["time"] == pytest.approx(0.015)
    (line,) = [w for w in lines if "max_contact_step" in w]
    assert "tunnelling" in line and "analysis.dt" in line
    assert 'contact.0.detection = "predicted"' in line


def test_the_same_impact_at_a_small_dt_is_not_warned_about():
    """dt 5e-4: 0.01 a step, a fifth of the spacing; the disk bounces off the plate."""
    summary, lines = run(pellet_on_plate(5e-4, 0.006))
    assert summary["max_contact_step"] < 0.25
    assert summary["contact_start_time"] is not None  # it did touch
    assert not [w for w in lines if "max_contact_step" in w]


def test_only_the_move_along_the_partners_normal_counts():
    """A slide along the plate (an ALE partner's nodes slide so, the disk drop's block 1.2
    spacings a step) crosses nothing; the same move across it does."""
    model = model_from_dict(pellet_on_plate(0.015, 0.045))
    check = StepCrossingCheck(model)
    x0 = model.X0.copy()
    pellet = model.body("pellet").nodes
    across, along = x0.copy(), x0.copy()
    across[pellet] += [0.0, -0.3]
    along[pellet] += [0.3, 0.0]
    found = check.largest(x0, across)
    assert found.ratio == pytest.approx(6.0) and found.interface == "c"
    assert found.displacement == pytest.approx(0.3)
    assert check.largest(x0, along).ratio == 0.0
