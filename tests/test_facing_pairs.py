"""Which candidate pairs may enter contact (independent testers, session 40).

1. A node paired with a partner along its own tangent has a normal gap of zero at any
   distance. A disk falling straight onto a plate had its equator node, 0.10 above the plate
   node below it, enter as "touching" by the sign of a round-off rate: the pair pushed the
   disk sideways (mean v_x -0.265 of a 10 fall, where mirror symmetry gives 0), and a 1e-7
   shift of the disk removed it. A pair now enters only if its normal faces its partner's
   (``contact.kinematics.facing``).
2. A face touching its partner at t = 0 while it slides along it enters whole at the first
   step. Rotated by 30 degrees, the normal rates were +-1e-16 instead of 0 and 3 of 9 pairs
   waited a step and kept 2.6e-6 of penetration (``contact.kinematics.rate_roundoff``).
"""

from __future__ import annotations

import numpy as np
import pytest

from ntncontact.api import load_scenario, run

DROP = """
[analysis]
kind = "dynamic"
dt = 0.004
t_end = 0.008
output_interval = 0.004
[[bodies]]
name = "pellet"
mesh = {{ type = "disk", radius = 0.1, n_circ = 16, n_radial = 2, center = [{x0}, 0.13] }}
material = {{ model = "neo_hookean", E = 100000.0, nu = 0.3, density = 1.0 }}
initial = {{ velocity = [0.0, -10.0] }}
[[bodies]]
name = "plate"
mesh = {{type = "rectangle", width = 2.0, height = 0.05, nx = 40, ny = 1, origin = [-1.0, -0.05] }}
material = {{ model = "neo_hookean", E = 100000.0, nu = 0.3, density = 1.0 }}
supports = [ {{ set = "left", x = 0.0, y = 0.0 }}, {{ set = "right", x = 0.0, y = 0.0 }} ]
[[contact]]
name = "c"
body_1 = "pellet"
surface_1 = "outer"
body_2 = "plate"
surface_2 = "top"
penalty_factor = 50.0
detection = "predicted"
"""


def pellet_velocity(result, time: float) -> np.ndarray:
    """Mean velocity of the pellet's nodes (the disk's nodes are mirror-symmetric)."""
    frame = result.fields(time)
    body = np.zeros(len(frame.points), int)
    body[frame.cells[0].data[frame.cell_data["body_id"][0] == 1].ravel()] = 1
    return frame.point_data["velocity"][body == 0, :2].mean(axis=0)


def test_a_node_beside_its_partner_does_not_push(tmp_path):
    """The symmetric drop stays symmetric, and the shifted one agrees with it."""
    outcomes = []
    for x0 in (0.0, 1e-7):
        path = tmp_path / f"drop{x0}.toml"
        path.write_text(DROP.format(x0=x0))
        result = run(load_scenario(path), tmp_path / f"out{x0}")
        assert result.summary["status"] == "completed"
        first = result.contact[result.contact["step"] == 1]
        # only the lowest node of the disk (the one facing the plate) is paired
        assert len(first) == 1
        outcomes.append(pellet_velocity(result, 0.004))
    symmetric, shifted = outcomes
    assert abs(symmetric[0]) < 1e-9  # -0.265 before
    assert symmetric == pytest.approx(shifted, abs=1e-6)


SLIDE = """
[analysis]
kind = "dynamic"
dt = 0.005
t_end = 0.01
[[bodies]]
name = "block"
mesh = {{type = "rectangle",width = 0.4, height = 0.2, nx = 8, ny = 2, origin = [-1.0, 0.0], {rot}}}
material = {{ model = "neo_hookean", E = 1000.0, nu = 0.3, density = 1.0 }}
initial = {{ velocity = [{vx}, {vy}] }}
loads = [ {{ type = "gravity", vector = [{gx}, {gy}] }} ]
[[bodies]]
name = "base"
mesh = {{type = "rectangle", width=3.0, height=0.3, nx = 60, ny = 2, origin=[-1.5, -0.3], {rot}}}
material = {{ model = "neo_hookean", E = 10000.0, nu = 0.3, density = 5.0 }}
supports = [ {{ set = "bottom", x = 0.0, y = 0.0 }} ]
[[contact]]
name = "c"
body_1 = "block"
surface_1 = "bottom"
body_2 = "base"
surface_2 = "top"
penalty_normal = 2000.0
"""


@pytest.mark.parametrize("angle", [0.0, 30.0, 37.0])
def test_a_face_sliding_along_its_partner_enters_whole_in_any_frame(tmp_path, angle):
    """All 9 bottom nodes of the block, touching the base and sliding along it at 2, enter at
    the first step whatever the frame (before: 6 of 9 at 30 degrees)."""
    c, s = np.cos(np.radians(angle)), np.sin(np.radians(angle))
    path = tmp_path / "slide.toml"
    rot = f"transform = {{ rotate_deg = {angle}, center = [0.0, 0.0] }}"
    path.write_text(SLIDE.format(rot=rot, vx=2.0 * c, vy=2.0 * s, gx=10.0 * s,
                                 gy=-10.0 * c))
    result = run(load_scenario(path), tmp_path / "out")
    assert result.summary["status"] == "completed"
    assert list(result.history["active_pairs"][1:]) == [9, 9]
