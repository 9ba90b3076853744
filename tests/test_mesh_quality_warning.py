"""An ALE body whose mesh motion flattened a cell to a sliver is named (summary.json
``ale_mesh_degraded_at``, ``ntncontact run``'s warning). An independent tester (session 42,
tester X) slid a block over an ALE base smoothed by the angle-based rule: its top row ended
0.01 thick and 0.9 long, corners of 1.08 / 179.8 deg (179.9998 at t = 0.476), and the run
said "completed" and nothing else; the Laplacian rule kept the same base at 22.5 deg.
The check costs 6.3 us a step on the ring impact (160 ALE cells, 0.02 % of its 25.6 ms
step)."""

from __future__ import annotations

import json
from types import SimpleNamespace

import numpy as np
import pytest

from ntncontact.cli import main
from ntncontact.engine.diagnostics import ALE_ANGLE_LIMIT, AleQualityCheck
from ntncontact.report.run_warnings import result_warnings

#: tester X's slide.toml, shortened to t = 0.35 (its base's first sliver below 10 deg at
#: t = 0.316 with the angle rule), with max_stretch = 4 so that the ALE follows the block
SLIDE = """
[analysis]
kind = "dynamic"
dt = 0.004
t_end = 0.35
output_interval = 0.35
[[bodies]]
name = "block"
mesh = { type = "rectangle", width = 1.0, height = 0.5, nx = 10, ny = 5, origin = [0.5, 0.0] }
material = { model = "neo_hookean", E = 1000.0, nu = 0.3, density = 1.0 }
initial = { velocity = [1.0, -0.3] }
loads = [ { type = "gravity", vector = [0.0, -10.0] } ]
[[bodies]]
name = "base"
mesh_motion = "ale"
ale = { max_stretch = 4.0, smoothing = "%s" }
mesh = { type = "rectangle", width = 3.06, height = 0.5, nx = 18, ny = 3, origin = [0.0, -0.5] }
material = { model = "neo_hookean", E = 5000.0, nu = 0.3, density = 2.0 }
supports = [{ set = "bottom", x = 0.0, y = 0.0 }]
[[contact]]
name = "c"
body_1 = "block"
surface_1 = "bottom"
body_2 = "base"
surface_2 = "top"
penalty_normal = 2000.0
penalty_tangential = 2000.0
friction = 0.0
"""


def _slide(tmp_path, smoothing: str, capsys) -> tuple[dict, str]:
    path = tmp_path / f"slide_{smoothing}.toml"
    path.write_text(SLIDE % smoothing)
    out = tmp_path / smoothing
    assert main(["run", str(path), "--out", str(out), "--quiet"]) == 0
    return json.loads((out / "summary.json").read_text()), capsys.readouterr().err


def test_the_angle_rules_sliver_is_named(tmp_path, capsys):
    summary, err = _slide(tmp_path, "angle", capsys)
    at = summary["ale_mesh_degraded_at"]
    assert at["body"] == "base" and at["initial_angle"] == pytest.approx(90.0)
    # the top row, pulled up to the surface: a corner far beyond 180 - 10
    assert at["angle"] > 180.0 - ALE_ANGLE_LIMIT and at["centroid"][1] > -0.167
    assert 0.3 < at["first_time"] <= at["time"] <= 0.35
    assert f"warning: cell {at['cell']} of the ALE body 'base' (centroid (" in err
    assert "ale_mesh_degraded_at" in err and 'ale.smoothing = "laplacian"' in err


def test_the_laplacian_rule_keeps_the_same_base_unwarned(tmp_path, capsys):
    summary, err = _slide(tmp_path, "laplacian", capsys)
    assert summary["ale_mesh_degraded_at"] is None
    assert "ale_mesh_degraded_at" not in err
    assert summary["mesh_quality"]["base"]["min_angle_deg"] > 2 * ALE_ANGLE_LIMIT


def _two_cells(skew_deg: float) -> SimpleNamespace:
    """A model-like stand-in: one ALE body of two cells side by side, the left one a
    parallelogram with corners of ``skew_deg`` and 180 - ``skew_deg`` as the user gave it."""
    shift = 1.0 / np.tan(np.radians(skew_deg))
    X0 = np.array([[0.0, 0.0], [1.0, 0.0], [2.0, 0.0],
                   [shift, 1.0], [1.0 + shift, 1.0], [2.0 + shift, 1.0]])
    body = SimpleNamespace(name="base", cells=np.arange(2))
    return SimpleNamespace(X0=X0, cells=np.array([[0, 1, 4, 3], [1, 2, 5, 4]]),
                           bodies=[body], ale_bodies=[SimpleNamespace(
                               body_index=0, motion=SimpleNamespace(smoothing="laplacian",
                                                                    smoothing_layers=3))])


def test_a_users_own_skewed_mesh_is_not_flagged_for_what_it_was_given():
    model = _two_cells(5.0)  # both cells 5 deg, below the limit, from the start
    check = AleQualityCheck(model)
    assert check.worst(model.X0) is None
    x = model.X0.copy()
    x[3:, 0] += 0.05  # the material's own small shear: 5.0 -> 4.8 deg, not the motion's
    assert check.worst(x) is None
    x[0, 0] -= 10.0  # the left cell's bottom-left node dragged along the bottom: 2.7 deg
    found = check.worst(x)
    assert found is not None and (found.body, found.cell) == ("base", 0)
    assert min(found.initial_angle, 180.0 - found.initial_angle) == pytest.approx(5.0)
    assert min(found.angle, 180.0 - found.angle) == pytest.approx(
        np.degrees(np.arctan(1.0 / (10.05 + 1.0 / np.tan(np.radians(5.0))))))
    assert found.centroid == pytest.approx(tuple(x[[0, 1, 4, 3]].mean(axis=0)))


def test_the_warning_reads_from_the_summary_alone():
    at = {"time": 0.476, "body": "base", "cell": 37, "centroid": [0.5256, -0.00567],
          "angle": 179.9998, "initial_angle": 90.0, "min_sine": 4.3e-6, "first_time": 0.316,
          "smoothing": "angle", "smoothing_layers": 3}
    lines = [line for line in result_warnings({"ale_mesh_degraded_at": at})
             if "ale_mesh_degraded_at" in line]
    assert len(lines) == 1
    assert ("cell 37 of the ALE body 'base' (centroid (0.5256, -0.00567)) was flattened to a "
            "corner of 180.00 deg (its sine 4.3e-06, t = 0.476, first below 10 deg at t = "
            "0.316; 90 deg at t = 0") in lines[0]
    assert 'ale.smoothing = "laplacian" (the default; "angle" can make' in lines[0]
    assert "more ale.smoothing_layers (now 3)" in lines[0]
    assert 'mesh_motion = "lagrangian"' in lines[0]
    # a Laplacian body is not told to use the rule it has (tester X's long slide: 176.1 deg)
    lines = result_warnings({"ale_mesh_degraded_at": at | {"smoothing": "laplacian"}})
    assert 'ale.smoothing = "laplacian"' not in lines[0] and "smoothing_layers" in lines[0]
    assert not [line for line in result_warnings({"ale_mesh_degraded_at": None})
                if "ale_mesh" in line]


def _zhou_shimada(x: np.ndarray, cells: np.ndarray, p: int) -> np.ndarray:
    """Report (4.10)-(4.14) node by node, written apart from ``ale.smoothing``: every node i
    of the polygon around P rotates P about itself onto the bisector of the polygon's angle
    (i-1, i, i+1), and P goes to the mean of the proposals."""
    succ = {}
    for cell in cells[(cells == p).any(axis=1)]:
        k = int(np.flatnonzero(cell == p)[0])
        succ[cell[(k + 1) % 4]], succ[cell[(k + 2) % 4]] = cell[(k + 2) % 4], cell[(k + 3) % 4]
    order = [next(iter(succ))]
    while succ[order[-1]] != order[0]:
        order.append(succ[order[-1]])
    proposals = []
    for j, i in enumerate(order):
        a, b, v = x[order[j - 1]] - x[i], x[order[(j + 1) % len(order)]] - x[i], x[p] - x[i]
        ccw = [np.mod(np.arctan2(w[1], w[0]) - np.arctan2(a[1], a[0]), 2 * np.pi)
               for w in (b, v)]  # from a to b and to P, counter-clockwise
        half = 0.5 * ccw[0] if ccw[1] < ccw[0] else -0.5 * (2 * np.pi - ccw[0])  # P's side
        turn = np.arctan2(a[1], a[0]) + half
        proposals.append(x[i] + np.linalg.norm(v) * np.array([np.cos(turn), np.sin(turn)]))
    return np.mean(proposals, axis=0)


def test_the_angle_rules_sliver_is_the_rule_not_its_code():
    """The angle rule's sweep is (4.10)-(4.14) to round-off on a mesh dragged as the tester's
    slide drags its base (a long surface segment beside squeezed ones): its sliver there
    (docs/scenarios.md, ale.smoothing) is the rule's fixed point, not a coding error."""
    from ntncontact.ale.smoothing import Smoother
    from ntncontact.mesh.generators import rectangle

    mesh = rectangle(3.0, 0.5, 6, 3)
    x = mesh.nodes.copy()
    rng = np.random.default_rng(7)
    top = np.flatnonzero(np.isclose(x[:, 1], 0.5))
    x[top[1:-1], 0] = [0.9, 1.05, 1.2, 1.35, 2.5]  # the long segment 0..0.9, then squeezed
    inner = np.flatnonzero((x[:, 1] > 0.0) & (x[:, 1] < 0.5) & (x[:, 0] > 0.0) & (x[:, 0] < 3.0))
    x[inner] += rng.uniform(-0.03, 0.03, (inner.size, 2))
    smoother = Smoother(mesh.cells, len(x), method="angle")
    swept = smoother.candidates(x)
    for p in inner:
        assert swept[p] == pytest.approx(_zhou_shimada(x, mesh.cells, p), abs=1e-12)
