"""Static contact of bodies placed touching: the gap is zero to round-off, and its sign must
not decide the run. An independent tester's distorted, non-matching blocks (tests/data/
distorted_*.msh, interface at y = 1), frictional, pressure and shear on top, the lower block
clamped. Rotated as a whole by 0.001 or 180 degrees they failed as singular (no pair entered:
the rotation left the gaps 1e-16 open and the gap law took only g >= 0), at 10 or 37 degrees
the augmented Lagrangian's Newton failed, and with the lower block ALE a run rotated by 37
degrees completed with stresses 6.7e-2 off (3.7 %). Lifted by 1e-12 the frictionless block
failed the same way. Now every rotation gives the unrotated answer to 1e-13 of the stress."""

from __future__ import annotations

import numpy as np
import pytest
from helpers import EXAMPLES

import ntncontact as ntc

DATA = EXAMPLES.parent / "tests" / "data"


def rotation(degrees: float) -> np.ndarray:
    t = np.radians(degrees)
    return np.array([[np.cos(t), -np.sin(t)], [np.sin(t), np.cos(t)]])


def scenario(degrees: float, method: str, motion: str, lift: float = 0.0) -> dict:
    turn = {"rotate_deg": degrees, "center": [0.0, 0.0], "translate": [0.0, lift]}
    ramp = {"times": [0.0, 1.0], "values": [0.0, 1.0]}
    shear = [float(a) for a in rotation(degrees) @ [0.2, 0.0]]
    material = {"model": "linear_elastic", "nu": 0.3, "density": 1.0}
    return {"analysis": {"kind": "static", "dt": 0.25, "t_end": 1.0},
            "bodies": [
                {"name": "upper",
                 "mesh": {"type": "gmsh", "file": str(DATA / "distorted_upper.msh"),
                          "transform": turn},
                 "material": material | {"E": 100.0},
                 "loads": [{"type": "pressure", "set": "top", "value": 1.0, "function": ramp},
                           {"type": "traction", "set": "top", "vector": shear,
                            "function": ramp}]},
                {"name": "lower", "mesh_motion": motion,
                 "mesh": {"type": "gmsh", "file": str(DATA / "distorted_lower.msh"),
                          "transform": turn | {"translate": [0.0, 0.0]}},
                 "material": material | {"E": 300.0},
                 "supports": [{"set": "bottom", "x": 0.0, "y": 0.0}]}],
            "contact": [{"name": "interface", "body_1": "upper", "surface_1": "bottom",
                         "body_2": "lower", "surface_2": "top", "method": method,
                         "friction": 0.5, "penalty_normal": 1e4, "penalty_tangential": 1e4}]}


def stresses_unrotated(degrees: float, method: str, motion: str) -> np.ndarray:
    """The last frame's cell stresses, turned back by the rotation: R^T sigma R."""
    results = ntc.run(ntc.scenario_from_dict(scenario(degrees, method, motion)))
    assert results.summary["status"] == "completed", results.summary["error"]
    s = results.fields(results.times[-1]).cell_data["stress"][0]
    sigma = np.stack([np.stack([s[:, 0], s[:, 3]], -1), np.stack([s[:, 3], s[:, 1]], -1)], -2)
    R = rotation(degrees)
    return np.einsum("ji,njk,kl->nil", R, sigma, R)


@pytest.mark.parametrize(("method", "motion"), [("penalty", "lagrangian"),
                                                ("augmented_lagrangian", "lagrangian"),
                                                ("augmented_lagrangian", "ale")])
def test_a_touching_static_problem_rotated_gives_the_rotated_answer(method, motion):
    reference = stresses_unrotated(0.0, method, motion)
    scale = np.abs(reference).max()  # measured 1.73-1.83
    for degrees in (0.001, 37.0, 180.0):
        turned = stresses_unrotated(degrees, method, motion)
        assert np.abs(turned - reference).max() < 1e-12 * scale, degrees


def held_frictionless(lift: float):
    data = scenario(0.0, "penalty", "lagrangian", lift)
    data["contact"][0]["friction"] = 0.0
    data["bodies"][0]["loads"] = data["bodies"][0]["loads"][:1]
    data["bodies"][0]["supports"] = [{"set": "left", "x": 0.0}]
    results = ntc.run(ntc.scenario_from_dict(data))
    assert results.summary["status"] == "completed", results.summary["error"]
    return results.contact[results.contact["step"] == results.contact["step"].max()]


def test_a_block_placed_a_round_off_away_is_held_by_contact():
    """Frictionless, its pairs its only support in y: lifted by 1e-12 (the penalty gap law's
    pairs enter at a gap of -1e-12 and take the pressed branch's stiffness) or pushed in by
    1e-12, it carries the pressure (1 on the top's width 2, which widens by 1e-6 here)."""
    above, below = held_frictionless(1e-12), held_frictionless(-1e-12)
    assert above["normal_force"].sum() == pytest.approx(2.0, rel=1e-5)
    assert np.allclose(above["normal_force"], below["normal_force"], rtol=1e-9, atol=0.0)
