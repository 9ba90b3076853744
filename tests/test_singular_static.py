"""A static body whose supports leave a rigid motion free fails with a clear line, even when
the load has no resultant along that motion (a right-hand side in the stiffness's range:
the solution does not grow, and only the pivots tell). Before, such a run completed with
the body shifted by whatever the round-off gave (an independent tester's case, session 36:
u_x from -0.0144 to +0.0012 on a block that should have been symmetric)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from ntncontact import api
from ntncontact.cli import main
from ntncontact.engine.simulation import SimulationError

BLOCK = """
title = "static block, supported in y only"
[analysis]
kind = "static"
dt = 1.0
t_end = 1.0
[[bodies]]
name = "b"
mesh = {{ type = "rectangle", width = 2.0, height = 1.0, nx = 4, ny = 2 }}
material = {{ model = "linear_elastic", E = 100.0, nu = 0.3, density = 1.0 }}
supports = [ {supports} ]
loads = [ {{ type = "pressure", set = "top", value = 2.0 }} ]
"""


def run(tmp_path, capsys, supports: str) -> tuple[int, dict, str]:
    path = tmp_path / "block.toml"
    path.write_text(BLOCK.format(supports=supports))
    code = main(["run", str(path), "--out", str(tmp_path / "out"), "--quiet"])
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    return code, summary, capsys.readouterr().err


def test_a_free_sliding_block_under_a_balanced_load_fails_clearly(tmp_path, capsys):
    code, summary, err = run(tmp_path, capsys, '{ set = "bottom", y = 0.0 }')
    assert code == 1
    assert summary["status"] == "failed"
    assert "numerically singular" in err and "rigid motion free" in err
    assert "Traceback" not in err
    # where: the body and the direction it is free in (a tester's case named no body)
    assert "the free motion moves the dofs of body 'b' (x)" in err


def test_the_same_block_held_in_x_is_solved(tmp_path, capsys):
    """The left face held in x as well: the run completes."""
    code, summary, err = run(tmp_path, capsys, '{ set = "bottom", y = 0.0 }, '
                             '{ set = "left", x = 0.0 }')
    assert code == 0 and summary["status"] == "completed"
    assert "warning" not in err


CYLINDER = """
title = "a half cylinder held in x at its lowest node only, pressed on a held foundation"
[analysis]
kind = "static"
dt = 0.2
t_end = 1.0
max_cutbacks = {cutbacks}
[[bodies]]
name = "cyl"
material = {{ model = "linear_elastic", E = 1000.0, nu = 0.3, density = 1.0 }}
supports = [ {{ set = "bottom", x = 0.0 }} ]
[[bodies.loads]]
type = "pressure"
set = "flat"
value = 5.0
function = {{ times = [0.0, 1.0], values = [0.0, 1.0] }}
[bodies.mesh]
type = "half_disk"
radius = 1.0
n_arc = 40
n_radial = 10
bottom_size = 0.02
center = [0.0, 1.0]
[[bodies]]
name = "fnd"
mesh_motion = "ale"
material = {{ model = "linear_elastic", E = 1.0e7, nu = 0.3, density = 1.0 }}
supports = [ {{ set = "bottom", x = 0.0, y = 0.0 }} ]
[bodies.mesh]
type = "rectangle"
width = 0.6
height = 0.3
nx = 30
ny = 4
origin = [-0.3, -0.3]
grading_y = 0.25
[[contact]]
body_1 = "cyl"
surface_1 = "arc"
body_2 = "fnd"
surface_2 = "top"
law = "gap"
detection = "predicted"
penalty_factor = 100.0
"""


@pytest.mark.parametrize("cutbacks", [0, 1])
def test_the_free_body_is_named_not_the_held_one(tmp_path, capsys, cutbacks):
    """A tester's cylinder, free to turn about its one held node, was reported by the
    foundation held on its whole bottom ("the tiny pivots are on the dofs of body 'fnd'"): the
    pivot's column is where the elimination met the free motion, not the motion. The motion
    itself (the null vector of the factor) is on the cylinder; after a cut-back the factor is
    of the reordered matrix, whose columns were mapped as the original's."""
    path = tmp_path / "cylinder.toml"
    path.write_text(CYLINDER.format(cutbacks=cutbacks))
    assert main(["run", str(path), "--out", str(tmp_path / "out"), "--quiet"]) == 1
    err = capsys.readouterr().err
    assert "numerically singular" in err and "Traceback" not in err
    assert "the free motion moves the dofs of body 'cyl'" in err and "'fnd'" not in err, err



def test_a_body_that_contact_lets_go_at_zero_load_is_not_moved(tmp_path):
    """Tester Q's cycle of the report's Hertz problem, loaded in 17 steps, held, unloaded in
    17 to zero and held: the cylinder, held in x only, loses its last pairs at zero load and
    nothing holds it in y. The step fails with the singular-matrix error naming it; before,
    Newton moved it by R's round-off over its free pivot (0.987, a sixth of an element) and
    the run completed, with no stress and no word."""
    root = Path(__file__).resolve().parents[1]
    function = {"times": [0.0, 17.0, 18.0, 35.0, 36.0], "values": [0.0, 1.0, 1.0, 0.0, 0.0]}
    scenario = api.load_scenario(root / "examples" / "hertz.toml",
                             {"analysis.t_end": 36.0, "bodies.0.loads.0.function": function})
    with pytest.raises(SimulationError) as failed:
        api.run(scenario)
    message = str(failed.value)
    assert message.startswith("step 36 ")
    assert "numerically singular" in message
    assert "the free motion moves the dofs of body 'cylinder' (y)" in message


APART = """
title = "static block placed 0.001 above its base, held in x only"
[analysis]
kind = "static"
dt = 1.0
t_end = 1.0
max_cutbacks = 2
[[bodies]]
name = "block"
mesh = { type = "rectangle", width = 1.0, height = 0.5, nx = 4, ny = 2, origin = [0.0, 0.001] }
material = { model = "neo_hookean", E = 1000.0, nu = 0.3, density = 1.0 }
supports = [{ set = "left", x = 0.0 }]
loads = [{ type = "pressure", set = "top", value = 10.0 }]
[[bodies]]
name = "base"
mesh = { type = "rectangle", width = 2.0, height = 0.3, nx = 6, ny = 1, origin = [-0.5, -0.3] }
material = { model = "neo_hookean", E = 1.0e5, nu = 0.3, density = 1.0 }
supports = [{ set = "bottom", x = 0.0, y = 0.0 }]
[[contact]]
body_1 = "block"
surface_1 = "bottom"
body_2 = "base"
surface_2 = "top"
penalty_normal = 1.0e5
"""


def test_a_static_body_placed_apart_from_its_partner_is_told_to_start_touching(tmp_path,
                                                                               capsys):
    """A tester's block placed 0.001 above its base, pressed from above and held in x only:
    nothing holds it in y until contact closes, so the step is singular; the message listed
    every cause but that one (session 40)."""
    path = tmp_path / "apart.toml"
    path.write_text(APART)
    assert main(["run", str(path), "--out", str(tmp_path / "out"), "--quiet"]) == 1
    err = capsys.readouterr().err
    assert "numerically singular" in err and "placed apart from its partner" in err
    assert "body 'block' (y)" in err and "Traceback" not in err
