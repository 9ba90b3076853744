"""Penetrations that no key reported (an independent tester's findings 2, 4 and 8, session
40):

- a surface-2 node inside surface 1's body (a 45-degree square's corner, surface 2, cut 0.71
  of the spacing into a flat block between its nodes; ``max_penetration`` said 0.0):
  summary.json ``max_penetration_surface_2`` and a warning (``engine.diagnostics.
  SurfaceTwoCheck``);
- a body through itself (a thin ring folded by a fast impact into a figure-eight, completed
  in silence): ``max_self_penetration`` and a warning that the results are not physical from
  the first crossing on (``SelfCrossingCheck``, ``mesh.overlap.deepest_self_overlap``);
- cut-back steps, counted in summary.json only: one line on stderr.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
from helpers import model_from_example, run_example

from ntncontact.cli import main
from ntncontact.engine import diagnostics
from ntncontact.engine.diagnostics import SelfCrossingCheck, SelfPenetration
from ntncontact.mesh import overlap
from ntncontact.mesh.boundary import boundary_edges
from ntncontact.mesh.generators import annulus, half_disk
from ntncontact.mesh.overlap import deepest_self_overlap, edge_size
from ntncontact.report.run_warnings import PENETRATION_WARNING, result_warnings

#: the tester's t4_swap.toml: the corner of a 45-degree square (surface 2) on a flat block
SWAP = """
title = "corner of a 45-deg square hits a free block face at 14% of c"
[analysis]
kind = "dynamic"
dt = 0.002
t_end = 0.04
output_interval = 0.02
[[bodies]]
name = "sq"
material = { model = "neo_hookean", E = 1000.0, nu = 0.3, density = 1.0 }
initial = { velocity = [0.0, -5.0] }
[bodies.mesh]
type = "rectangle"
width = 0.5
height = 0.5
nx = 8
ny = 8
origin = [-0.25, 0.0]
transform = { rotate_deg = 45.0, center = [0.0, 0.25], translate = [0.03125, 0.1045] }
[[bodies]]
name = "block"
mesh = { type = "rectangle", width = 2.0, height = 0.5, nx = 32, ny = 8, origin = [-1.0, -0.5] }
material = { model = "neo_hookean", E = 1000.0, nu = 0.3, density = 1.0 }
[[contact]]
name = "c"
body_1 = "block"
surface_1 = "top"
body_2 = "sq"
surface_2 = "left+bottom"
penalty_normal = 2000.0
detection = "predicted"
"""

#: the tester's t7_ring.toml at vy = -5.5: a thin ring (t/R = 0.1) folds through itself
RING = """
[analysis]
kind = "dynamic"
dt = 0.003
t_end = 0.24
output_interval = 0.24
[[bodies]]
name = "ring"
material = { model = "neo_hookean", E = 1000.0, nu = 0.3, density = 1.0 }
initial = { velocity = [0.0, -5.5] }
[bodies.mesh]
type = "annulus"
r_inner = 0.9
r_outer = 1.0
n_radial = 2
n_circ = 96
center = [0.0, 1.005]
[[bodies]]
name = "block"
mesh = { type = "rectangle", width = 3.0, height = 0.3, nx = 46, ny = 4, origin = [-1.5, -0.3] }
material = { model = "neo_hookean", E = 1.0e5, nu = 0.3, density = 1.0 }
supports = [ { set = "bottom", x = 0.0, y = 0.0 } ]
[[contact]]
name = "c"
body_1 = "ring"
surface_1 = "outer"
body_2 = "block"
surface_2 = "top"
penalty_normal = 2000.0
detection = "predicted"
"""


def _run(tmp_path, text: str, capsys) -> tuple[dict, str]:
    path = tmp_path / "case.toml"
    path.write_text(text)
    out = tmp_path / "out"
    assert main(["run", str(path), "--out", str(out), "--quiet"]) == 0
    return json.loads((out / "summary.json").read_text()), capsys.readouterr().err


def test_a_surface_2_corner_inside_the_flat_surface_1_is_measured_and_warned(tmp_path, capsys):
    """The square's corner (node 0) goes ~0.045 below the block's top between two block
    nodes (the tester measured 0.0428-0.0445 on the frames); no pair reports it."""
    summary, err = _run(tmp_path, SWAP, capsys)
    at = summary["max_penetration_surface_2_at"]
    assert summary["max_penetration"] == 0.0  # what the pairs saw
    assert (at["interface"], at["node"]) == ("c", 0)
    assert summary["max_penetration_surface_2"] == at["depth"]
    assert 0.6 * at["element_size"] < at["depth"] < 0.8 * at["element_size"]
    assert "node 0 of interface 'c', on surface_2, went" in err
    assert "max_penetration_surface_2" in err


def test_the_ring_impact_s_surface_2_nodes_stay_under_the_warning(tmp_path, capsys):
    """The example's surface-2 nodes go 0.0048 into the ring, deeper than its pairs (0.0027)
    but under 10 % of the spacing: no warning, and the results are untouched."""
    summary, err = run_example("ring_impact.toml", tmp_path / "ring", capsys)
    at = summary["max_penetration_surface_2_at"]
    assert 0.0 < at["depth"] < PENETRATION_WARNING * at["element_size"]
    assert summary["max_self_penetration"] == 0.0
    assert "surface_2" not in err and "itself" not in err


def test_a_ring_through_itself_is_found_with_its_first_time(tmp_path, capsys):
    """The tester's ring crossed itself from t ~ 0.225 (14 nodes in its own cells by 0.225,
    t75.png a figure-eight): the warning says so and from when."""
    summary, err = _run(tmp_path, RING, capsys)
    at = summary["max_self_penetration_at"]
    assert at["body"] == "ring"
    assert at["first_time"] == pytest.approx(0.225, abs=0.01)
    assert summary["max_self_penetration"] > 0.1 * at["element_size"]
    assert "body 'ring' passed through itself" in err
    assert f"not physical from t = {at['first_time']:.6g} on" in err


def test_a_node_in_a_remote_cell_of_its_own_body_is_a_self_crossing():
    """An unfolded ring has none (its nodes lie on their own cells' edges only); an outer
    node moved into the cell across the ring's hole is found, with its depth there."""
    mesh = annulus(0.9, 1.0, 2, 16)
    edges = boundary_edges(mesh.cells)
    nodes = np.unique(edges)
    size = edge_size(mesh.nodes, edges)
    assert deepest_self_overlap(nodes, mesh.nodes, mesh.cells, edges, size) is None
    moved = mesh.nodes.copy()
    top = 2 * 16 + 8  # the outer circle's top node (start at -90 degrees)
    moved[top] = [0.0, -0.93]  # inside the bottom cells, 0.03 below the inner circle
    found = deepest_self_overlap(nodes, moved, mesh.cells, edges, size)
    assert found is not None and nodes[found.point] == top
    assert found.depth == pytest.approx(0.03)  # to the inner circle's node below it


@pytest.mark.parametrize("cut, steps, too_large", [(18, 30, True), (3, 30, False)])
def test_cut_back_steps_are_said(cut, steps, too_large):
    """The tester's block at 82 % of c halved 18 of 30 steps; the delamination example 3 of
    30 at its onset, on purpose: dt is called too large for the first only."""
    (line,) = result_warnings({"cut_back_steps": cut, "steps": steps}, static=False)
    assert line.startswith(f"{cut} of {steps} steps needed halving (summary.json "
                           "cut_back_steps)")
    assert ("dt is too large" in line) is too_large
    assert result_warnings({"cut_back_steps": 0, "steps": steps}, static=False) == []


def test_a_paired_surface_2_node_as_deep_as_its_pair_is_not_warned_twice():
    """The spinning block's oblique impact (tests/test_run_warnings.py): the base's node 155
    is 0.0316 inside the block, its pair 0.0309; the penetration warning says it already."""
    at = {"time": 0.045, "interface": "if", "node": 155, "depth": 0.0316, "file_node": -1,
          "element_size": 0.125}
    summary = {"max_penetration": 0.0309, "max_penetration_surface_2_at": at}
    assert result_warnings(summary, static=False) == []
    summary["max_penetration"] = 0.0
    (line,) = result_warnings(summary, static=False)
    assert line.startswith("node 155 of interface 'if', on surface_2, went 0.0316")


def _all_pairs_clearance(boundary, nodes, cells):
    """``self_clearance`` by definition: every boundary node against every cell it is not a
    corner of, capped at two cell radii."""
    corners = nodes[cells]
    radius = np.linalg.norm(corners - corners.mean(axis=1)[:, None], axis=-1).max()
    point, cell = np.divmod(np.arange(len(boundary) * len(cells)), len(cells))
    foreign = ~np.any(cells[cell] == boundary[point, None], axis=1)
    quad, at = corners[cell[foreign]], nodes[boundary[point[foreign]], None, :]
    ab, rel = np.roll(quad, -1, axis=1) - quad, at - quad
    t = np.clip(np.sum(rel * ab, axis=-1) / np.sum(ab * ab, axis=-1), 0.0, 1.0)
    return min(2.0 * radius, float(np.linalg.norm(rel - t[..., None] * ab, axis=-1).min()))


def test_self_clearance_measures_the_near_cells_only(monkeypatch):
    """A graded body (Hertz's half cylinder, its contact zone's cells 7 times smaller than
    the far ones) has the same clearance as every pair gives, bit for bit, deformed or not,
    measuring ~4.5 pairs a boundary node a call: searching every cell within three times
    the largest radius measured 73 a node here, and 200 000 a step on Hertz refined 8x
    (0.12 s of its 2.1 s step)."""
    mesh = half_disk(400.0, 80, 8, bottom_size=6.0, fine_half_width=60.0)
    edges = boundary_edges(mesh.cells)
    boundary = np.unique(edges)
    measured = []

    class Counted(overlap.cKDTree):
        def sparse_distance_matrix(self, *args, **kwargs):
            found = super().sparse_distance_matrix(*args, **kwargs)
            measured.append(len(found))
            return found

    monkeypatch.setattr(overlap, "cKDTree", Counted)
    rng = np.random.default_rng(3)
    for scale in (0.0, 0.05, 0.3):
        nodes = mesh.nodes + rng.normal(scale=scale, size=mesh.nodes.shape)
        assert overlap.self_clearance(boundary, nodes, mesh.cells) == \
            _all_pairs_clearance(boundary, nodes, mesh.cells)
    assert sum(measured) < 3 * 20 * len(boundary)


def test_a_body_deforming_fast_is_searched_without_remeasuring_its_clearance(monkeypatch):
    """Hertz's cylinder squashed by 3 % a step moves farther from a rigid motion each step
    than its reference's half clearance: it is searched every step (clean) but its clearance
    is not measured again until it rests (measuring it every step cost 48 ms a step on Hertz
    refined 8x, more than the search); at rest, the first clean search takes a new reference
    and the next steps are skipped."""
    model = model_from_example("hertz.toml")
    check = SelfCrossingCheck(model)
    measured, searched = [], []
    monkeypatch.setattr(diagnostics, "self_clearance",
                        lambda *a: measured.append(1) or overlap.self_clearance(*a))
    monkeypatch.setattr(diagnostics, "deepest_self_overlap",
                        lambda *a: searched.append(1) or overlap.deepest_self_overlap(*a))
    body = model.bodies[0]
    nodes = np.arange(body.node_offset, body.node_offset + len(body.mesh.nodes))
    x = model.X0.copy()
    for _ in range(5):
        x[nodes, 1] *= 0.97
        assert check.deepest(x) == SelfPenetration()
    assert (len(searched), len(measured)) == (5, 0)
    for _ in range(10):  # at rest
        assert check.deepest(x) == SelfPenetration()
    assert len(measured) == 1 and len(searched) < 5 + 10


def test_the_checks_cell_geometry_is_numpy_s_to_the_bit():
    """The per-step checks' centroids and largest radius (``mesh.overlap._inside_pairs``,
    run on every cell of a body every step: 47 -> 24 ms a step on Hertz refined 8x) are the
    values ``mean`` and ``norm`` give, and the pairs found are every pair's test's."""
    mesh = half_disk(400.0, 80, 8, bottom_size=6.0, fine_half_width=60.0)
    rng = np.random.default_rng(5)
    nodes = mesh.nodes + rng.normal(scale=0.5, size=mesh.nodes.shape)
    corners = nodes[mesh.cells]
    centroid = overlap._centroids(corners)
    assert np.array_equal(centroid, corners.mean(axis=1))
    assert overlap._largest_radius(corners, centroid) == \
        float(np.linalg.norm(corners - centroid[:, None], axis=-1).max())
    points = nodes[np.unique(boundary_edges(mesh.cells))]
    slack = 0.05
    point, cell = overlap._inside_pairs(points, nodes, mesh.cells, slack)
    every = np.stack(np.divmod(np.arange(len(points) * len(mesh.cells)), len(mesh.cells)))
    quad = corners[every[1]]
    edges = np.roll(quad, -1, axis=1) - quad
    rel = points[every[0], None, :] - quad
    cross = edges[..., 0] * rel[..., 1] - edges[..., 1] * rel[..., 0]
    inside = (cross >= -slack * np.linalg.norm(edges, axis=-1)).all(axis=-1)
    assert sorted(zip(point.tolist(), cell.tolist(), strict=True)) == \
        sorted(map(tuple, every[:, inside].T.tolist()))
    assert len(point) > len(points)  # each node is in its own cells
