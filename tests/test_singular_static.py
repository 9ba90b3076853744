"""A static body whose supports leave a rigid motion free fails with a clear line, even when
the load has no resultant along that motion (a right-hand side in the stiffness's range:
the solution does not grow, and only the pivots tell). Before, such a run completed with
the body shifted by whatever the round-off gave (an independent tester's case, session 36:
u_x from -0.0144 to +0.0012 on a block that should have been symmetric)."""

from __future__ import annotations

import json

from ntncontact.cli import main

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
    assert "the tiny pivots are on the dofs of body 'b' (x)" in err


def test_the_same_block_held_in_x_is_solved(tmp_path, capsys):
    """The left face held in x as well: the run completes."""
    code, summary, err = run(tmp_path, capsys, '{ set = "bottom", y = 0.0 }, '
                             '{ set = "left", x = 0.0 }')
    assert code == 0 and summary["status"] == "completed"
    assert "warning" not in err
