"""An ALE contact surface whose segments the mesh motion squeezed or stretched far from their
ORIGINAL length is named (summary.json ``ale_surface_spacing_at``, ``ntncontact run``'s
warning). The local respacing keeps its band [1 - t, 1 / (1 - t)] = [0.5, 2] only around
each run's current mean stretch within one move (``ale.motion``, item 3), not against the
original lengths: an independent tester (session 43, tester Z) dragged a block its own length
over an ALE base of spacing 0.1 and got segments of 0.0198 (0.20x) ahead of it and 0.31 (3.1x)
behind, cells of 17 deg, and the run said nothing. The examples leave the band a little where
their bodies deform (the disk drop's block 0.46x / 2.43x), so the warning waits for the band's
square, [0.25, 4]."""

from __future__ import annotations

import json
from types import SimpleNamespace

import numpy as np
import pytest

from ntncontact.cli import main
from ntncontact.engine.diagnostics import AleSpacingCheck
from ntncontact.report.run_warnings import result_warnings

#: tester Z's slot_cycle.toml up to t = 1: the block pressed onto the ALE base (spacing 0.1,
#: 40 segments) and dragged +1 by its top edge, static
DRAG = """
[analysis]
kind = "static"
dt = 0.05
t_end = 1.0
output_interval = 1.0
[[bodies]]
name = "block"
mesh = { type = "rectangle", width = 1.0, height = 0.5, nx = 10, ny = 5, origin = [-0.5, 0.0] }
material = { model = "neo_hookean", E = 100.0, nu = 0.3, density = 1.0 }
supports = [ { set = "top", x = 1.0, function = { times = [0.0, 1.0], values = [0.0, 1.0] } } ]
loads = [ { type = "pressure", set = "top", value = 1.0 } ]
[[bodies]]
name = "base"
mesh_motion = "ale"
mesh = { type = "rectangle", width = 4.0, height = 0.5, nx = 40, ny = 5, origin = [-2.0, -0.5] }
material = { model = "neo_hookean", E = 1000.0, nu = 0.3, density = 1.0 }
supports = [ { set = "bottom", x = 0.0, y = 0.0 } ]
[[contact]]
name = "slide"
body_1 = "block"
surface_1 = "bottom"
body_2 = "base"
surface_2 = "top"
method = "augmented_lagrangian"
penalty_factor = 50.0
friction = 0.3
"""


def test_a_block_dragged_its_length_over_an_ale_base_is_named(tmp_path, capsys):
    path = tmp_path / "drag.toml"
    path.write_text(DRAG)
    assert main(["run", str(path), "--out", str(tmp_path / "out"), "--quiet"]) == 0
    err = capsys.readouterr().err
    at = json.loads((tmp_path / "out" / "summary.json").read_text())["ale_surface_spacing_at"]
    short, long = at["shortest"], at["longest"]
    # ahead of the block: 15 segments in 0.505 (0.34x on average), the nearest squeezed to
    # 0.2x although a respacing could have kept them all at 0.34x (not done: see ale.motion)
    assert short["body"] == "base" and short["ratio"] < 0.25 and short["midpoint"][0] > 1.4
    assert short["length"] == pytest.approx(short["ratio"] * short["reference_length"])
    # behind it: the 15 segments from -2 stretched over 2.49 (1.66x), the nearest to 3.1x
    assert long["ratio"] > 2.5 and long["midpoint"][0] < 0.6
    assert short["band"] == [0.5, 2.0] and 0.0 < short["first_time"] <= short["time"] <= 1.0
    line = next(line for line in err.splitlines() if "ale_surface_spacing_at" in line)
    assert f"squeezed to {short['ratio']:.2f} of its original length" in line
    assert f"stretched to {long['ratio']:.2f}" in line and "of 'base' at (" in line


def _strip(n: int = 5) -> SimpleNamespace:
    """A model-like stand-in: one ALE body whose contact surface is an open chain of ``n``
    nodes 0.1 apart (local numbers 0..n-1, global from offset 3)."""
    motion = SimpleNamespace(surface=np.arange(n), closed=False, spacing_tolerance=0.5,
                             reference_spacing=np.full(n - 1, 0.1))
    setup = SimpleNamespace(body_index=0, node_offset=3, motion=motion, more_motions=())
    return SimpleNamespace(bodies=[SimpleNamespace(name="base")], ale_bodies=[setup])


def test_only_segments_outside_the_band_of_their_original_length_are_recorded():
    check = AleSpacingCheck(_strip())
    x = np.zeros((8, 2))
    x[3:, 0] = [0.0, 0.1, 0.2, 0.3, 0.4]
    assert check.extremes(x) == (None, None)
    x[3:, 0] = [0.0, 0.051, 0.25, 0.31, 0.4]  # 0.51x, 1.99x, 0.6x, 0.9x: inside
    assert check.extremes(x) == (None, None)
    x[3:, 0] = [0.0, 0.16, 0.2, 0.41, 0.42]  # 1.6, 0.4, 2.1, 0.1
    short, long = check.extremes(x)
    assert (short.nodes, long.nodes) == ((3, 4), (2, 3)) and short.body == "base"
    assert short.ratio == pytest.approx(0.1) and long.ratio == pytest.approx(2.1)
    assert short.midpoint == pytest.approx((0.415, 0.0)) and long.length == pytest.approx(0.21)


def _summary(short: float, long: float) -> dict:
    side = {"time": 1.0, "body": "base", "nodes": [20, 19], "midpoint": [1.6, 0.0],
            "reference_length": 0.1, "band": [0.5, 2.0], "first_time": 0.1}
    return {"ale_surface_spacing_at": {
        "shortest": side | {"ratio": short, "length": 0.1 * short},
        "longest": side | {"ratio": long, "length": 0.1 * long}}}


def test_the_warning_waits_for_the_square_of_the_band():
    def lines(summary: dict) -> list[str]:
        return [w for w in result_warnings(summary) if "ale_surface_spacing_at" in w]

    assert not lines(_summary(0.46, 2.43))  # the disk drop example's block
    assert not lines({"ale_surface_spacing_at": None})
    assert not lines({"ale_surface_spacing_at": {"shortest": None, "longest": None}})
    [line] = lines(_summary(0.19, 3.18))  # tester Z's drag: the squeeze alone crosses 0.25
    assert ("squeezed to 0.19 of its original length (0.019 of 0.1, nodes 20-19 of 'base' "
            "at (1.6, 0), t = 1) and one stretched to 3.18") in line
    assert 'mesh_motion = "lagrangian"' in line
    assert lines(_summary(0.6, 4.2))  # a stretch alone
