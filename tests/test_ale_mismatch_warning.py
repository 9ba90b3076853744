"""An ALE node that ends far from its partner's place is named (summary.json
``max_ale_mismatch``, ``ntncontact run``'s warning): the pair is then no longer node to node,
which nothing said before (an independent tester, session 36: a block sliding off the end of
an ALE base, whose end nodes stay fixed, left its pairs 1.85 from their ALE nodes, and a
slide over a locally respaced base 0.265, 2.1 spacings, both runs "completed" in silence;
pairs beyond the surface's end are now released, and a pair reaches 0.66 of a spacing at
the fixed end before its release).
Where the motion follows its pairs, the mismatch is round-off, measured at the step's end since
session 39 (across the pressed pairs' normals): the examples' largest are 5.6e-9 (ring impact),
1.0e-9 (disk drop), 3.6e-10 (fast-sliding blocks), 3.3e-10 (tilted blocks)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from helpers import LEDGE, run_example

import ntncontact as ntc
from ntncontact.cli import main
from ntncontact.report.run_warnings import MISMATCH_WARNING, result_warnings


def test_a_slide_past_the_ale_surfaces_end_is_named(tmp_path, capsys):
    path = tmp_path / "ledge.toml"
    path.write_text(LEDGE.format(motion="ale", t_end=0.5))
    assert main(["run", str(path), "--out", str(tmp_path / "out"), "--quiet"]) == 0
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    at = summary["max_ale_mismatch_at"]
    assert at["element_size"] == pytest.approx(0.125)
    assert summary["max_ale_mismatch"] > MISMATCH_WARNING * at["element_size"]
    err = capsys.readouterr().err
    assert "warning: an ALE contact node (node " in err and "max_ale_mismatch" in err
    # where: the ALE node (body-local) and its partner, in their interface
    assert at["body"] == "base" and at["partner_body"] == "block" and at["interface"]
    assert (f"node {at['body_node']} of body 'base', paired with node "
            f"{at['partner_body_node']} of 'block' in interface '{at['interface']}'") in err
    # and the case no ALE setting helps, a partner surface running through the contact
    assert "spinning or rolling body" in err and 'mesh_motion = "lagrangian"' in err


def test_the_examples_ale_runs_keep_no_mismatch_worth_a_warning(tmp_path, capsys):
    summary, err = run_example("disk_drop.toml", tmp_path / "disk", capsys, "analysis.t_end=0.4")
    assert summary["max_ale_mismatch"] < 1e-6 * summary["max_ale_mismatch_at"]["element_size"]
    assert "max_ale_mismatch" not in err


DECEL = """
[analysis]
kind = "dynamic"
dt = 0.005
t_end = 1.0
output_interval = 0.25

[[bodies]]
name = "block"
mesh = { type = "rectangle", width = 0.5, height = 0.25, nx = 4, ny = 2, origin = [-1.5, 0.0] }
material = { model = "neo_hookean", E = 1000.0, nu = 0.3, density = 1.0 }
initial = { velocity = [2.0, 0.0] }
[[bodies.loads]]
type = "gravity"
vector = [0.0, -10.0]
function = { times = [0.0, 0.1], values = [0.0, 1.0] }

[[bodies]]
name = "base"
mesh_motion = "ale"
ale = { smoothing_layers = 1, max_stretch = %s }
mesh = { type = "rectangle", width = 4.0, height = 0.25, nx = 32, ny = 2, origin = [-2.0, -0.25] }
material = { model = "neo_hookean", E = 10000.0, nu = 0.3, density = 5.0 }
supports = [ { set = "bottom", x = 0.0, y = 0.0 } ]

[[contact]]
body_1 = "block"
surface_1 = "bottom"
body_2 = "base"
surface_2 = "top"
method = "augmented_lagrangian"
penalty_normal = 2000.0
penalty_tangential = 2000.0
friction = 0.3
"""


@pytest.mark.parametrize("max_stretch", [2.0, 4.0])
def test_a_slide_away_from_the_surfaces_start_is_followed_within_max_stretch(
        tmp_path, capsys, max_stretch):
    """A block decelerating by friction slides 0.77 away from an ALE base's start (0.5 away
    at first): the surface behind its trailing pair stretches, and with the default
    ``ale.max_stretch`` = 2 the pair's ALE node is held back (0.19, 1.5 spacings, and the
    warning names the key); with 4 it follows (round-off)."""
    path = tmp_path / "decel.toml"
    path.write_text(DECEL % max_stretch)
    out = tmp_path / str(max_stretch)
    assert main(["run", str(path), "--out", str(out), "--quiet"]) == 0
    summary = json.loads((out / "summary.json").read_text())
    spacing = summary["max_ale_mismatch_at"]["element_size"]
    err = capsys.readouterr().err
    if max_stretch == 2.0:
        assert summary["max_ale_mismatch"] > spacing
        assert "ale.max_stretch" in err
    else:
        assert summary["max_ale_mismatch"] < 1e-6 * spacing
        assert "max_ale_mismatch" not in err


@pytest.mark.parametrize("method", ["penalty", "augmented_lagrangian"])
def test_the_mismatch_is_measured_at_the_step_end_with_every_method(method):
    """An independent tester's patch test (tests/data/distorted_*.msh): the upper block (E =
    100) widens by nu (1 + nu) p / E = 0.0039 under p = 1, the lower ALE one (E = 300) by
    0.0013, so the upper corner node ends 2 x 0.0026 = 0.0052 beyond the lower surface's
    fixed end, which the mesh motion cannot follow. With the penalty method (one mesh move a
    step, before the solve) summary.json read 0."""
    data = Path(__file__).parent / "data"
    body = {"material": {"model": "linear_elastic", "nu": 0.3, "density": 1.0}}
    scenario = {
        "analysis": {"kind": "static", "dt": 1.0, "t_end": 1.0},
        "bodies": [
            body | {"name": "upper", "mesh": {"type": "gmsh",
                                              "file": str(data / "distorted_upper.msh")},
                    "material": body["material"] | {"E": 100.0},
                    "loads": [{"type": "pressure", "set": "top", "value": 1.0}],
                    "supports": [{"set": "corner_bottom_left", "x": 0.0}]},
            body | {"name": "lower", "mesh_motion": "ale",
                    "mesh": {"type": "gmsh", "file": str(data / "distorted_lower.msh")},
                    "material": body["material"] | {"E": 300.0},
                    "supports": [{"set": "bottom", "y": 0.0},
                                 {"set": "corner_bottom_left", "x": 0.0}]}],
        "contact": [{"name": "interface", "body_1": "upper", "surface_1": "bottom",
                     "body_2": "lower", "surface_2": "top", "method": method,
                     "penalty_normal": 1e5}]}
    summary = ntc.run(ntc.scenario_from_dict(scenario)).summary
    assert summary["max_ale_mismatch"] == pytest.approx(0.0052, rel=2e-3)
    # at the lower surface's fixed end, which no ALE setting moves: the advice says so
    at = summary["max_ale_mismatch_at"]
    assert at["body"] == "lower" and at["interface"] == "interface" and at["fixed_end"]
    [line] = [w for w in result_warnings(summary | {"max_ale_mismatch_at": at | {
        "element_size": 0.01}}, static=True) if "ALE contact node" in w]
    assert "fixed end of its ALE surface" in line and "ale.max_stretch" not in line


ROW = """
[analysis]
kind = "dynamic"
dt = 0.002
t_end = 0.12

[[bodies]]
name = "A"
mesh = { type = "rectangle", width = 0.5, height = 0.5, nx = 5, ny = 5, origin = [-1.1, 0.1] }
material = { model = "neo_hookean", E = 1000.0, nu = 0.3, density = 1.0 }
initial = { velocity = [3.0, 0.3], angular_velocity = 1.0 }

[[bodies]]
name = "B"
mesh_motion = "ale"
mesh = { type = "rectangle", width = 0.5, height = 0.6, nx = 6, ny = 6, origin = [-0.5, 0.0] }
material = { model = "neo_hookean", E = 2000.0, nu = 0.25, density = 1.5 }

[[bodies]]
name = "C"
mesh = { type = "rectangle", width = 0.5, height = 0.5, nx = 5, ny = 5, origin = [0.1, 0.05] }
material = { model = "neo_hookean", E = 1500.0, nu = 0.3, density = 1.0 }
initial = { velocity = [-0.5, 0.0] }

[[contact]]
name = "AB"
body_1 = "A"
surface_1 = "right"
body_2 = "B"
surface_2 = "left"
penalty_normal = 3000.0
penalty_tangential = 3000.0
friction = 0.3
detection = "predicted"

[[contact]]
name = "BC"
body_1 = "B"
surface_1 = "right"
body_2 = "C"
surface_2 = "left"
penalty_normal = 3000.0
detection = "predicted"
"""  # noqa: E501 (a TOML inline table is one line)


def test_the_mismatch_is_over_the_pressed_pairs_and_says_where(tmp_path, capsys):
    """Tester C (session 41): A hits B hits C, B ALE. At t = 0.112-0.114 the one pair left
    carries no force (waiting for its release) and the mesh motion's own miss there, 0.0657,
    was the summary's figure; over the pressed pairs (as the docs say) it is 0.0634, at B's
    bottom-right corner facing C's corner node 0.05 off B's grid. The summary now names the
    interface, the ALE node and its partner, and the warning the fixed end."""
    path = tmp_path / "row.toml"
    path.write_text(ROW)
    assert main(["run", str(path), "--out", str(tmp_path / "out"), "--quiet"]) == 0
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert summary["max_ale_mismatch"] == pytest.approx(0.0634, abs=2e-4)
    at = summary["max_ale_mismatch_at"]
    assert (at["interface"], at["body"], at["body_node"], at["partner_body"],
            at["partner_body_node"], at["fixed_end"]) == ("BC", "B", 6, "C", 0, True)
    err = capsys.readouterr().err
    assert "node 6 of body 'B', paired with node 0 of 'C' in interface 'BC'" in err
    assert "fixed end of its ALE surface" in err and "ale.max_stretch" not in err
