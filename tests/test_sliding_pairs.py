"""Pairs between sliding bodies keep facing each other (an independent tester, session 36).

Between two Lagrangian bodies nothing moves a pair's partner with its node: a pair kept where
it entered held a sliding block by base nodes up to 2 away, and a block that had slid 1.5
past the end of its base stayed up, resting on the base's nodes (the run "completed", its
ledger closed). Now a kept pair takes its node's nearest surface-2 node at every step start,
and a pair whose node lies beyond an end of the partner surface is released (on an ALE base
too, whose end stays fixed). Own case: a block sliding off a ledge under gravity.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
from helpers import LEDGE

from ntncontact.cli import main
from ntncontact.io.vtk import read_pvd, read_vtu
from ntncontact.io.writers import read_csv_table

BLOCK_MASS = 0.5 * 0.25 * 1.0
SPACING = 0.125  # the base's surface segments


def run(tmp_path, motion: str, t_end: float) -> tuple[dict, dict]:
    path = tmp_path / f"{motion}.toml"
    path.write_text(LEDGE.format(motion=motion, t_end=t_end))
    out = tmp_path / motion
    assert main(["run", str(path), "--out", str(out), "--quiet"]) == 0
    return (json.loads((out / "summary.json").read_text()),
            read_csv_table(out / "history.csv"))


@pytest.mark.parametrize("motion", ["lagrangian", "ale"])
def test_a_block_sliding_off_a_ledge_falls(tmp_path, motion):
    """The block's centre passes the base's end (x = 0) at t = 0.125 and its last node
    leaves it at t = 0.25; by t = 0.6 nothing holds it: no pair, and its vertical momentum
    grows by its weight's impulse over the last 0.2 s (before: 2 pairs, momentum ~0)."""
    summary, history = run(tmp_path, motion, 0.6)
    assert summary["status"] == "completed"
    time, pairs, p_y = history["time"], history["active_pairs"], history["linear_momentum_y"]
    late = time >= 0.4 - 1e-9
    assert np.all(pairs[late] == 0)
    step = np.flatnonzero(late)[0]
    gained = p_y[-1] - p_y[step]  # the base is held: the block's momentum alone changes
    assert gained == pytest.approx(-10.0 * BLOCK_MASS * (time[-1] - time[step]), rel=0.02)


def test_lagrangian_pairs_follow_the_nearest_node_while_they_slide(tmp_path):
    """While the block slides over the base (0.5 in 0.25 s, four base segments), every
    pressed pair's nodes are at most a segment apart along the surface (a pair keeps its
    partner while the node faces one of the partner's segments), or a segment and a half at
    the base's end (a node up to half the end segment beyond it is kept), plus the step's own
    slide (2 dt v = 0.02: a pair is taken at the step start, the frames show its end; before,
    0.18 apart on a disk dropped on a Lagrangian block, and 2 here)."""
    run(tmp_path, "lagrangian", 0.25)
    contact = read_csv_table(tmp_path / "lagrangian" / "contact.csv")
    worst = 0.0
    for t, path in read_pvd(tmp_path / "lagrangian" / "fields.pvd"):
        rows = np.isclose(contact["time"], t) & (contact["normal_traction"] > 0.0)
        if rows.any():
            x = read_vtu(path, t).deformed_points
            offset = x[contact["node_1"][rows].astype(int)] - x[contact["node_2"][rows].astype(int)]
            worst = max(worst, np.abs(offset[:, 0]).max())
    assert 0.0 < worst <= 1.5 * SPACING + 2 * 0.005 * 2.0


RESTING = """
[analysis]
kind = "dynamic"
dt = 0.005
t_end = 0.1

[[bodies]]
name = "block"
mesh = { type = "rectangle", width = 1.0, height = 0.5, nx = 8, ny = 4, origin = [-0.5, 0.0] }
material = { model = "neo_hookean", E = 1000.0, nu = 0.3, density = 1.0 }
loads = [ { type = "gravity", vector = [0.0, -10.0] } ]

[[bodies]]
name = "base"
mesh = { type = "rectangle", width = 2.0, height = 0.5, nx = 16, ny = 4, origin = [-1.0, -0.5] }
material = { model = "neo_hookean", E = 10000.0, nu = 0.3, density = 5.0 }
supports = [ { set = "bottom", x = 0.0, y = 0.0 } ]

[[contact]]
body_1 = "block"
surface_1 = "bottom"
body_2 = "base"
surface_2 = "top"
method = "augmented_lagrangian"
penalty_normal = 2000.0
"""


def test_a_block_placed_at_rest_on_a_base_is_held_from_the_first_step(tmp_path):
    """Touching at t = 0 with no velocity, under gravity: its pairs enter at the first step
    (at rest, gdot = 0) and hold it with no penetration beyond round-off. Before, they
    entered one step late and the persistency law kept that step's fall, g dt^2 / 2 =
    1.25e-4, for the whole run (an independent tester's case)."""
    path = tmp_path / "resting.toml"
    path.write_text(RESTING)
    assert main(["run", str(path), "--out", str(tmp_path / "out"), "--quiet"]) == 0
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert summary["contact_start_time"] == 0.0
    assert summary["max_penetration"] < 1e-9
