"""Tied bodies that start with different velocities at their tied nodes (engine/initial.py
``warn_tied_velocities``). From an independent tester: two tied parts, each given
``initial.angular_velocity = 1.5``, each spun about its own centre of mass, and their tied
nodes kept velocities 0.45 apart for the whole run (the tie holds positions only), in
silence."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from helpers import model_from_dict

import ntncontact as ntc
from ntncontact.engine.simulation import initial_state


def two_parts(spin_low: float, spin_up: float, v_low=(0.0, 0.0), v_up=(0.0, 0.0),
              ny_up: int = 2) -> dict:
    """A 0.6 x 0.6 block made of two tied halves (the upper one finer with ``ny_up`` > 2)."""
    def part(name: str, origin: list[float], nx: int, ny: int, spin: float, v) -> dict:
        return {"name": name, "mesh": {"type": "rectangle", "width": 0.6, "height": 0.3,
                                       "nx": nx, "ny": ny, "origin": origin},
                "material": {"model": "neo_hookean", "E": 100.0, "nu": 0.3, "density": 1.0},
                "initial": {"velocity": list(v), "angular_velocity": spin}}
    return {"analysis": {"kind": "dynamic", "dt": 0.01, "t_end": 0.02},
            "bodies": [part("low", [0.0, -0.3], 4, 2, spin_low, v_low),
                       part("up", [0.0, 0.0], 4 * ny_up // 2, ny_up, spin_up, v_up)],
            "tie": [{"name": "glue", "body_1": "low", "surface_1": "top", "body_2": "up",
                     "surface_2": "bottom"}]}


def build_warnings(data: dict) -> list[str]:
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        model_from_dict(data)
    return [str(w.message) for w in caught if issubclass(w.category, ntc.PhysicsWarning)]


@pytest.mark.parametrize("ny_up", [2, 4])
def test_tied_parts_each_spun_about_their_own_centre_are_warned_about(ny_up):
    """Same spin, own centres (0.3, -0.15) and (0.3, 0.15): the tied nodes start
    omega x 0.3 = 0.45 apart (ny_up = 4: nodes held on edges too)."""
    lines = [w for w in build_warnings(two_parts(1.5, 1.5, ny_up=ny_up)) if "tie 'glue'" in w]
    assert len(lines) == 1
    assert "bodies 'low' and 'up'" in lines[0]
    assert "up to 0.45 apart" in lines[0]
    assert "velocity = v + omega x (c_part - c)" in lines[0]


def test_the_advised_velocities_of_one_rigid_motion_start_the_tied_nodes_together():
    """Spin 1.5 about the assembly's centre (0.3, 0): the lower part's centre is 0.15 below
    it, so its velocity is (0 - 1.5 (-0.15), 0) = (0.225, 0), the upper's (-0.225, 0). No
    warning, and the tied nodes do start with one velocity."""
    data = two_parts(1.5, 1.5, v_low=(0.225, 0.0), v_up=(-0.225, 0.0))
    assert not [w for w in build_warnings(data) if "tie 'glue'" in w]
    model = model_from_dict(data)
    v = initial_state(model).v
    tie = model.ties[0]
    assert np.abs(v[tie.nodes_1] - v[tie.nodes_2]).max() < 1e-12


def test_tied_parts_moving_together_are_not_warned_about():
    assert not [w for w in build_warnings(two_parts(0.0, 0.0, (1.0, -2.0), (1.0, -2.0)))
                if "tie 'glue'" in w]
