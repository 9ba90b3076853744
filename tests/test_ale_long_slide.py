"""A pair whose ALE node could not follow its partner is released (``contact.beyond_reach``).

An independent tester's block sliding 5 of its lengths over a flat ALE base (session 42):
the base nodes behind the block are clamped by ``ale.max_stretch``, and pairs were never
paired again, so the block's trailing corner stayed "pressed" on base node 5, 4.5 (45
spacings) behind it, with a normal force of 0.3 at t = 1. A node-to-node pair must not
transmit force between nodes that far apart: detection now releases a kept pair farther
apart than a new pair may be (``contact.pairing.REACH_STRETCH``) and pairs its node afresh
(the tester's case: max_ale_mismatch 4.50 -> 0.265, the farthest pressed pair 4.50 ->
0.242; the block's trailing nodes now sink up to 0.074 into the dragged base, unheld, where
the far pairs had held them: the ALE base cannot carry so long a slide, and the run's
penetration and mismatch warnings say so). Here a coarse, short version of it."""

from __future__ import annotations

import json

import numpy as np

from ntncontact.cli import main
from ntncontact.contact import ContactSurface, Interface, beyond_reach, ordered_partners
from ntncontact.contact.pairing import REACH_STRETCH
from ntncontact.report.run_warnings import result_warnings

LONG_SLIDE = """
[analysis]
kind = "dynamic"
dt = 0.004
t_end = 0.24
output_interval = 0.24

[[bodies]]
name = "block"
mesh = { type = "rectangle", width = 1.0, height = 0.4, nx = 5, ny = 2, origin = [0.4, 0.0] }
material = { model = "neo_hookean", E = 1000.0, nu = 0.3, density = 1.0 }
initial = { velocity = [5.0, 0.0] }
loads = [ { type = "gravity", vector = [0.0, -10.0] } ]

[[bodies]]
name = "base"
mesh_motion = "ale"
mesh = { type = "rectangle", width = 4.0, height = 0.4, nx = 20, ny = 2, origin = [0.0, -0.4] }
material = { model = "neo_hookean", E = 5000.0, nu = 0.3, density = 2.0 }
supports = [ { set = "bottom", x = 0.0, y = 0.0 } ]

[[contact]]
body_1 = "block"
surface_1 = "bottom"
body_2 = "base"
surface_2 = "top"
penalty_normal = 2000.0
penalty_tangential = 2000.0
"""


def test_a_pressed_pair_does_not_stay_spacings_behind_a_long_slide(tmp_path):
    """The block slides 1.2 (6 spacings of 0.2) away from a trailing base node it is paired
    with, which max_stretch = 2 holds at 0.8 from the base's fixed end: kept, that pair was
    pressed 0.80 apart (4 spacings). Released once beyond the reach (REACH_STRETCH = 2
    spacings), no pressed pair ends farther off than that plus one step's slide (0.02):
    0.419 now."""
    path = tmp_path / "long.toml"
    path.write_text(LONG_SLIDE)
    assert main(["run", str(path), "--out", str(tmp_path / "out"), "--quiet"]) == 0
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    spacing = summary["max_ale_mismatch_at"]["element_size"]
    assert summary["status"] == "completed"
    assert summary["max_ale_mismatch"] < (REACH_STRETCH + 0.2) * spacing
    assert summary["energy_balance_max_relative_error"] < 1e-9


def test_a_stretched_end_segment_does_not_let_a_far_fixed_end_pair():
    """Tester X's finding 4: a base end segment stretched to 0.68 (4x its 0.17, max_stretch =
    4) made its fixed chain end 'within reach' of a block corner 0.64 away, and the pair
    carried force until the end (a mismatch of 0.64 that no motion can close). Its reach
    now counts the segment at no more than REACH_STRETCH times its original length."""
    block = np.column_stack([[0.84, 0.74, 0.64], np.ones(3)])  # walked right to left
    base = np.column_stack([[0.0, 0.68, 0.85, 1.02], np.ones(4)])  # chain end at x = 0
    x = np.vstack([block, base])
    interface = Interface(ContactSurface(np.arange(3)), ContactSurface(np.arange(3, 7)))
    kept = [[1, 4], [0, 5]]  # the base nodes under the block follow their partners
    original = np.array([0.0, 0.17, 0.34, 0.51])
    # with the stretched segment's reach (0.68) the old code paired it with node 3 (x = 0)
    assert ordered_partners(x, interface, [2], kept=kept, reference_arc=original)[0] == -1
    pair = np.array([[2, 3]])
    assert beyond_reach(x, interface, pair, original)[0]
    assert not beyond_reach(x, interface, np.array([[1, 4]]), original)[0]


def test_the_mismatch_advice_says_a_long_slide_needs_a_lagrangian_body():
    """Tester X: the first advice (max_stretch, respace) failed for a block sliding 5 of its
    lengths; the advice now bounds it by the partner's length and names the Lagrangian body
    for a longer slide. At a fixed end it no longer blames only the start or a slide past
    the end, which a partner sliding away from the end also gives."""
    at = {"time": 1.0, "element_size": 0.1, "interface": "c", "body": "base", "body_node": 5,
          "partner_body": "block", "partner_body_node": 0}
    summary = {"max_ale_mismatch": 0.265, "max_ale_mismatch_at": at}
    [line] = [w for w in result_warnings(summary, static=False) if "ALE contact node" in w]
    advice = line.split("no longer node to node. ", 1)[1]
    assert advice.startswith("A larger ale.max_stretch")
    assert "up to about the partner's own length" in advice
    assert "slides on farther" in advice and 'mesh_motion = "lagrangian"' in advice
    summary["max_ale_mismatch_at"] = {**at, "fixed_end": True}
    [line] = [w for w in result_warnings(summary, static=False) if "ALE contact node" in w]
    assert "sliding away from it" in line and "twice the end segment's original length" in line
