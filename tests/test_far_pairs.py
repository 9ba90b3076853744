"""Pairs whose bodies have parted are released (an independent tester, session 40).

A spinning disk struck a free block off-centre and rolled away from it: one pair was never
released. The persistency law held its frozen gap, each step's re-pairing with the nearest
block node made it jump (0.004 -> 0.084 -> 0.175), and the pair pushed the bodies apart
from 0.66 away: ``max_penetration`` 0.175 warned as "went inside" a block it was 0.63 outside
of, ``contact_end_time`` = t_end. A spinning ring rolling off its obstacle was dented by pairs
2.2 apart. Kept pairs are now released where their normal no longer faces the partner's,
and, between Lagrangian bodies, where paired again with a partner that leaves them more open
than the last one (``engine.interfaces``, session 41). A release of every pair open by more
than half the partner's chord was tried and taken back (the rods below)."""

from __future__ import annotations

import numpy as np
import pytest
from helpers import EXAMPLES

from ntncontact.api import load_scenario, run

SPIN = """
[analysis]
kind = "dynamic"
dt = 0.01
t_end = 0.4
output_interval = 0.01
[[bodies]]
name = "disk"
mesh = { type = "disk", radius = 0.3, n_circ = 16, n_radial = 2, center = [-0.62, 0.15] }
material = { model = "neo_hookean", E = 100.0, nu = 0.3, density = 1.0 }
initial = { velocity = [2.0, 0.5], angular_velocity = 4.0 }
[[bodies]]
name = "block"
mesh = { type = "rectangle", width = 0.6, height = 0.8, nx = 6, ny = 8, origin = [0.0, -0.4] }
material = { model = "neo_hookean", E = 200.0, nu = 0.25, density = 1.5 }
initial = { velocity = [-0.5, 0.1], angular_velocity = -1.0 }
[[contact]]
name = "dc"
body_1 = "disk"
surface_1 = "outer"
body_2 = "block"
surface_2 = "left"
penalty_normal = 1000.0
"""
SPACING = 0.1  # the block's left face


def test_a_disk_rolling_away_is_let_go(tmp_path):
    path = tmp_path / "spin.toml"
    path.write_text(SPIN)
    result = run(load_scenario(path), tmp_path / "out")
    assert result.summary["status"] == "completed"
    pressed = result.contact[result.contact["normal_force"] > 0.0]
    worst = 0.0
    for time, rows in pressed.groupby("time"):
        frame = result.fields(time)
        x = frame.points[:, :2] + frame.point_data["displacement"][:, :2]
        apart = np.linalg.norm(x[rows["node_1"].to_numpy()] - x[rows["node_2"].to_numpy()],
                               axis=1)
        worst = max(worst, apart.max())
    assert worst < 2.0 * SPACING  # 0.66 before
    # the bodies part at about t = 0.31 (the frames): contact ended before t_end
    assert result.summary["contact_end_time"] <= 0.32
    assert result.summary["max_penetration"] < 0.5 * SPACING  # 0.175 before


RODS = """
[analysis]
kind = "dynamic"
dt = 0.05
t_end = 2.5
[[bodies]]
name = "left"
mesh = { type = "rectangle", width = 10.0, height = 1.0, nx = 10, ny = 30, origin = [-10.04, 0.0] }
material = { model = "linear_elastic", E = 100.0, nu = 0.0, density = 1.0 }
initial = { velocity = [1.0, 0.0] }
[[bodies]]
name = "right"
mesh = { type = "rectangle", width = 10.0, height = 1.0, nx = 10, ny = 30, origin = [0.0, 0.0] }
material = { model = "linear_elastic", E = 100.0, nu = 0.0, density = 1.0 }
[[contact]]
name = "ends"
body_1 = "left"
surface_1 = "right"
body_2 = "right"
surface_2 = "left"
method = "{method}"
penalty_normal = 1000.0
detection = "predicted"
"""


@pytest.mark.parametrize("method", ["penalty", "augmented_lagrangian"])
def test_pairs_held_across_their_entry_opening_stay(tmp_path, method):
    """Rods meeting at 1 with dt = 0.05 and predicted detection: the pairs enter up to v dt =
    0.05 early and the persistency law holds that opening, 1.5 of the face spacing (1/30). A
    release of pairs open by more than half the partner's chord (tried this session) dropped
    them every other step: the penalty rods went 0.5 through each other and contact ended at
    1.35 instead of 2L/c = 2; the augmented Lagrangian's went 0.031 inside."""
    path = tmp_path / "rods.toml"
    path.write_text(RODS.replace("{method}", method))
    result = run(load_scenario(path), tmp_path / "out")
    summary = result.summary
    assert summary["status"] == "completed"
    # 2L/c = 2 after an entry a step early (the predicted detection): within a step of it
    assert 1.9 <= summary["contact_end_time"] - summary["contact_start_time"] <= 2.1
    assert summary["max_penetration"] < 0.01
    assert (summary.get("max_penetration_surface_2") or 0.0) < 0.01


def test_a_spinning_ring_rising_off_its_obstacle_is_let_go(tmp_path):
    """The report's ring impact (examples/ring_impact.toml) with the ring spinning at 3 rad/s
    and a Lagrangian obstacle (a tester, session 40). The ring's node 192 was paired again with
    each obstacle node in turn while it rose 0.46 above the obstacle, every new partner
    0.016-0.058 more open than the last, and the persistency law kept it pressed: at t = 0.33
    it pushed with a force of 2.3 across an open gap of 0.24, 2.4 of the obstacle's spacing.
    A pair paired again more open than before by a tenth of the faced segment is released."""
    scenario = load_scenario(EXAMPLES / "ring_impact.toml", {
        "bodies.0.initial.velocity": [0.8, -1.0], "bodies.0.initial.angular_velocity": 3.0,
        "bodies.1.mesh_motion": "lagrangian", "analysis.t_end": 0.4})
    summary = run(scenario, tmp_path / "out").summary
    assert summary["status"] == "completed"
    # at most half the obstacle's spacing (0.1) open under traction: 0.36 before; what is
    # left (0.022 at t = 0.4) is steps without traction that opened pairs still kept
    assert summary["max_separation_under_traction"] < 0.5 * 0.1


SLIDING_DISK = """
[analysis]
kind = "dynamic"
dt = 0.01
t_end = 1.0
output_interval = 1.0
[[bodies]]
name = "disk"
mesh = { type = "disk", radius = 1.0, n_circ = 64, n_radial = 6, center = [0.0, 1.0] }
material = { model = "neo_hookean", E = 100.0, nu = 0.3, density = 1.0 }
initial = { velocity = [1.0, 0.0] }
loads = [ { type = "gravity", vector = [0.0, -20.0] } ]
[[bodies]]
name = "base"
mesh = { type = "rectangle", width = 6.0, height = 0.5, nx = 60, ny = 3, origin = [-2.0, -0.5] }
material = { model = "neo_hookean", E = 1.0e4, nu = 0.3, density = 1.0 }
supports = [ { set = "bottom", x = 0.0, y = 0.0 } ]
[[contact]]
name = "c"
body_1 = "disk"
surface_1 = "outer"
body_2 = "base"
surface_2 = "top"
penalty_normal = 1.0e4
"""


def test_a_soft_disk_sliding_on_a_lagrangian_flat_is_not_pressed_across_an_opening(tmp_path):
    """A case of our own beside the report's ring: a soft disk sliding frictionless along a
    flat base under its weight, both Lagrangian. Its contact nodes slide along the base and
    are paired again with base node after base node; where they rise off it, each new partner
    more open, they stayed pressed across an opening of up to 0.159 (1.6 of the base's spacing
    0.1; measured on the session-40 code) until pairs paired again more open were released:
    0.004 now."""
    path = tmp_path / "slide.toml"
    path.write_text(SLIDING_DISK)
    summary = run(load_scenario(path), tmp_path / "out").summary
    assert summary["status"] == "completed"
    assert summary["max_separation_under_traction"] < 0.1 * 0.1  # 0.159 before
