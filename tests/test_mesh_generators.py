"""Tests of the structured mesh generators: rectangle, annulus, disk, half disk (Hertz)."""

from __future__ import annotations

import numpy as np
import pytest

from ntncontact.mesh.boundary import boundary_edges, surface_chain
from ntncontact.mesh.generators import (
    annulus,
    disk,
    geometric_breaks,
    half_disk,
    hertz_cylinder_mesh,
    rectangle,
)
from ntncontact.mesh.quadmesh import MeshError, QuadMesh
from ntncontact.mesh.quality import corner_jacobians

EPS = np.finfo(float).eps


def cell_areas(mesh: QuadMesh) -> np.ndarray:
    """Signed shoelace area of every cell (positive for counter-clockwise)."""
    x = mesh.nodes[mesh.cells]
    xs, ys = x[..., 0], x[..., 1]
    return 0.5 * np.sum(xs * np.roll(ys, -1, axis=1) - np.roll(xs, -1, axis=1) * ys, axis=1)


def interior_angles_deg(mesh: QuadMesh) -> np.ndarray:
    x = mesh.nodes[mesh.cells]
    to_next, to_prev = np.roll(x, -1, axis=1) - x, np.roll(x, 1, axis=1) - x
    cos = np.sum(to_next * to_prev, axis=-1) / (
        np.linalg.norm(to_next, axis=-1) * np.linalg.norm(to_prev, axis=-1))
    return np.degrees(np.arccos(np.clip(cos, -1.0, 1.0)))


def assert_edge_sets_on_boundary(mesh: QuadMesh) -> None:
    """Every edge-set edge is a boundary edge with the same (body-on-left) orientation."""
    oriented = {tuple(e) for e in boundary_edges(mesh).tolist()}
    for name, edges in mesh.edge_sets.items():
        missing = [tuple(e) for e in edges.tolist() if tuple(e) not in oriented]
        assert not missing, f"{name}: edges not on the boundary with body-on-left: {missing[:3]}"


def assert_normals_point_away(mesh: QuadMesh) -> None:
    """Outward normal of each edge-set edge points away from the adjacent cell's centroid."""
    centroid_of_edge = {}
    cell_of_edge = np.repeat(np.arange(mesh.n_cells), 4)
    all_edges = np.stack((mesh.cells, np.roll(mesh.cells, -1, axis=1)), axis=-1).reshape(-1, 2)
    centroids = mesh.nodes[mesh.cells].mean(axis=1)
    for k, e in enumerate(all_edges.tolist()):
        centroid_of_edge[tuple(e)] = centroids[cell_of_edge[k]]
    for edges in mesh.edge_sets.values():
        xa, xb = mesh.nodes[edges[:, 0]], mesh.nodes[edges[:, 1]]
        t = xb - xa
        normal = np.column_stack((t[:, 1], -t[:, 0]))
        inward = np.array([centroid_of_edge[tuple(e)] for e in edges.tolist()]) - 0.5 * (xa + xb)
        assert np.all(np.sum(normal * inward, axis=1) < 0.0)


# ---------------------------------------------------------------------------------- rectangle
def test_geometric_breaks_grading_and_ends():
    b = geometric_breaks(3.0, 5, grading=4.0)
    sizes = np.diff(b)
    assert b[0] == 0.0 and b[-1] == 3.0
    # ratio of consecutive sizes is constant; round-off of a few ulps per cumulative sum
    assert np.allclose(sizes[1:] / sizes[:-1], 4.0 ** 0.25, rtol=1e-12, atol=0.0)
    assert sizes[-1] / sizes[0] == pytest.approx(4.0, rel=1e-12)


def test_rectangle_numbering_area_and_sets():
    m = rectangle(3.0, 2.0, 3, 2, origin=(1.0, -1.0))
    assert m.n_nodes == 12 and m.n_cells == 6
    # node j*(nx+1)+i at column i, row j
    assert np.allclose(m.nodes[5], [2.0, 0.0]) and np.allclose(m.nodes[11], [4.0, 1.0])
    assert np.all(np.abs(cell_areas(m) - 1.0) < 10 * EPS)
    assert cell_areas(m).sum() == pytest.approx(6.0, rel=10 * EPS)
    assert m.node_sets["corner_bottom_left"].tolist() == [0]
    assert m.node_sets["corner_bottom_right"].tolist() == [3]
    assert m.node_sets["corner_top_right"].tolist() == [11]
    assert m.node_sets["corner_top_left"].tolist() == [8]
    assert m.node_sets["top"].tolist() == [11, 10, 9, 8]
    assert m.node_sets["left"].tolist() == [8, 4, 0]
    assert len(m.node_sets["all"]) == 12
    assert_edge_sets_on_boundary(m)
    assert_normals_point_away(m)
    # the four sides walk the whole boundary counter-clockwise
    loop = np.concatenate([surface_chain(m, s).nodes[:-1] for s in ("bottom", "right", "top",
                                                                     "left")])
    assert sorted(loop.tolist()) == sorted(np.unique(boundary_edges(m)).tolist())


def test_rectangle_grading_and_breaks():
    m = rectangle(10.0, 4.0, 8, 5, grading_x=3.0, grading_y=0.5)
    xs = m.nodes[: 9, 0]
    ys = m.nodes[:: 9, 1]
    assert np.diff(xs)[-1] / np.diff(xs)[0] == pytest.approx(3.0, rel=1e-12)
    assert np.diff(ys)[-1] / np.diff(ys)[0] == pytest.approx(0.5, rel=1e-12)
    assert np.all(cell_areas(m) > 0)
    # graded mesh still tiles the rectangle exactly (round-off only)
    assert cell_areas(m).sum() == pytest.approx(40.0, rel=100 * EPS)
    m2 = rectangle(2.0, 1.0, 3, 1, x_breaks=[0.0, 0.2, 1.5, 2.0])
    assert np.allclose(m2.nodes[:4, 0], [0.0, 0.2, 1.5, 2.0])


@pytest.mark.parametrize(
    "kwargs",
    [
        dict(x_breaks=[0.0, 1.0, 2.0]),  # wrong count for nx=3
        dict(x_breaks=[0.0, 1.0, 0.5, 2.0]),  # not increasing
        dict(x_breaks=[0.0, 1.0, 1.5, 2.5]),  # does not end at the width
    ],
)
def test_rectangle_bad_breaks(kwargs):
    with pytest.raises(MeshError, match="x_breaks"):
        rectangle(2.0, 1.0, 3, 1, **kwargs)


def test_rectangle_bad_sizes():
    with pytest.raises(MeshError, match="at least one element"):
        rectangle(1.0, 1.0, 0, 2)
    with pytest.raises(MeshError, match="positive"):
        rectangle(-1.0, 1.0, 2, 2)


# ---------------------------------------------------------------------------------- annulus
def test_annulus_ring_impact_mesh():
    m = annulus(0.7, 1.0, 4, 48, center=(0.0, 2.0))
    assert m.n_cells == 192  # report section 6.4: 192 ring elements
    assert np.all(cell_areas(m) > 0)
    bottom = m.nodes[m.node_sets["bottom"][0]]
    assert np.allclose(bottom, [0.0, 1.0], atol=10 * EPS)
    assert bottom[1] == pytest.approx(m.nodes[:, 1].min(), abs=10 * EPS)
    # the polygon inscribed in both circles has this area exactly (up to round-off)
    exact = 0.5 * (1.0 - 0.49) * 48 * np.sin(2 * np.pi / 48)
    assert cell_areas(m).sum() == pytest.approx(exact, rel=100 * EPS)
    assert_edge_sets_on_boundary(m)
    assert_normals_point_away(m)
    outer, inner = surface_chain(m, "outer"), surface_chain(m, "inner")
    assert outer.closed and inner.closed and len(outer.nodes) == len(inner.nodes) == 48
    # inner loop runs clockwise around the centre: negative shoelace area
    xy = m.nodes[inner.nodes] - [0.0, 2.0]
    shoelace = 0.5 * np.sum(xy[:, 0] * np.roll(xy[:, 1], -1) - np.roll(xy[:, 0], -1) * xy[:, 1])
    assert shoelace < 0


def test_annulus_area_converges_at_second_order():
    n = np.array([12, 24, 48, 96])
    errors = np.array([abs(cell_areas(annulus(0.7, 1.0, 2, k)).sum() - np.pi * 0.51) for k in n])
    rate = -np.polyfit(np.log(n), np.log(errors), 1)[0]
    # chord-segment area error is (2 pi)^3 (r_o^2 - r_i^2) / (12 n^2): exactly rate 2 asymptotically
    assert rate == pytest.approx(2.0, abs=0.05)


def test_annulus_errors():
    with pytest.raises(MeshError, match="r_inner < r_outer"):
        annulus(1.0, 0.7, 2, 12)
    with pytest.raises(MeshError, match="n_circ"):
        annulus(0.7, 1.0, 2, 2)


# ---------------------------------------------------------------------------------- half disk
def inscribed_half_polygon_area(mesh: QuadMesh, radius: float, center) -> float:
    """Exact area of the polygon bounded by the arc nodes and the flat diameter."""
    xy = mesh.nodes[surface_chain(mesh, "arc").nodes] - np.asarray(center)
    theta = np.unwrap(np.arctan2(xy[:, 1], xy[:, 0]))
    return 0.5 * radius**2 * np.sum(np.sin(np.abs(np.diff(theta))))


@pytest.mark.parametrize("bottom_size", [None, 0.05])
def test_half_disk_geometry_and_sets(bottom_size):
    center = (0.3, 1.0)
    m = half_disk(1.0, 40, 6, bottom_size=bottom_size, center=center, fine_half_width=0.2)
    assert np.all(cell_areas(m) > 0)
    # cells tile the inscribed polygon: sums agree to round-off
    exact = inscribed_half_polygon_area(m, 1.0, center)
    assert cell_areas(m).sum() == pytest.approx(exact, rel=1e3 * EPS)
    radii = np.linalg.norm(m.nodes - center, axis=1)
    assert radii.max() <= 1.0 + 10 * EPS
    arc_nodes = surface_chain(m, "arc").nodes
    assert np.all(np.abs(radii[arc_nodes] - 1.0) < 10 * EPS)
    flat = surface_chain(m, "flat")
    assert not flat.closed and np.allclose(m.nodes[flat.nodes, 1], 1.0, atol=10 * EPS)
    assert np.all(np.diff(m.nodes[flat.nodes, 0]) < 0)  # right to left
    assert flat.nodes[0] == arc_nodes[-1] and flat.nodes[-1] == arc_nodes[0]
    bottom = m.nodes[m.node_sets["bottom"][0]]
    assert np.allclose(bottom, [0.3, 0.0], atol=10 * EPS)
    assert np.allclose(m.nodes[m.node_sets["flat_center"][0]], [0.3, 1.0], atol=10 * EPS)
    assert_edge_sets_on_boundary(m)
    assert_normals_point_away(m)
    # arc + flat is the whole boundary
    assert len(boundary_edges(m)) == len(m.edge_sets["arc"]) + len(m.edge_sets["flat"])


def test_half_disk_bottom_size_is_honoured():
    m = half_disk(400.0, 52, 12, bottom_size=6.0, fine_half_width=60.0)
    arc = m.nodes[surface_chain(m, "arc").nodes]
    arc_len = 400.0 * np.abs(np.diff(np.unwrap(np.arctan2(arc[:, 1], arc[:, 0]))))
    mid = len(arc_len) // 2
    # uniform fine zone of round(60/6) = 10 cells each side of the bottom, exactly 6 long
    assert np.all(np.abs(arc_len[mid - 10: mid + 10] - 6.0) < 1e-10 * 6.0)
    assert arc_len[mid + 10] > 6.0 and np.all(np.diff(arc_len[mid + 9:]) > 0)
    assert arc_len.sum() == pytest.approx(np.pi * 400.0, rel=1e-12)
    # the contact layer below the bottom node is bottom_size thick too
    below = np.sort(m.nodes[np.abs(m.nodes[:, 0]) < 1e-9, 1])
    assert below[1] - below[0] == pytest.approx(6.0, rel=1e-10)


def test_half_disk_area_converges_at_second_order():
    n = np.array([16, 32, 64, 128])
    errors = np.array([abs(cell_areas(half_disk(1.0, k, 4)).sum() - 0.5 * np.pi) for k in n])
    rate = -np.polyfit(np.log(n), np.log(errors), 1)[0]
    # circular-segment error pi^3 / (12 n^2) per unit radius: rate 2 asymptotically
    assert rate == pytest.approx(2.0, abs=0.05)


@pytest.mark.parametrize("level, bottom_size", [(1, 6.0), (2, 4.0), (3, 3.0)])
def test_hertz_meshes_quality_and_refinement(level, bottom_size):
    m = hertz_cylinder_mesh(level)
    areas = cell_areas(m)
    assert np.all(areas > 0)  # no inverted elements
    angles = interior_angles_deg(m)
    assert angles.min() > 30.0 and angles.max() < 150.0
    assert 500 < m.n_cells < 3000  # report Table 6.2: 711, 950, 2229 elements
    # elements touching the contact zone (|x| < 50 at the bottom) have the target size
    arc = m.edge_sets["arc"]
    xa, xb = m.nodes[arc[:, 0]], m.nodes[arc[:, 1]]
    contact = (np.abs(xa[:, 0]) < 50) & (np.abs(xb[:, 0]) < 50)
    chord = np.linalg.norm(xb - xa, axis=1)
    # chord = 2R sin(h / 2R) differs from the arc size h by h^3 / (24 R^2) < 1e-5 relative
    assert np.all(np.abs(chord[contact] / bottom_size - 1.0) < 1e-4)
    assert chord.max() > 5 * bottom_size  # coarse away from the contact zone


def test_hertz_levels_refine_monotonically():
    counts = [hertz_cylinder_mesh(level).n_cells for level in (1, 2, 3)]
    assert counts[0] < counts[1] < counts[2]
    with pytest.raises(MeshError, match="level"):
        hertz_cylinder_mesh(4)


def test_half_disk_errors():
    with pytest.raises(MeshError, match="even n_arc"):
        half_disk(1.0, 15, 3)
    with pytest.raises(MeshError, match="fine zone"):
        half_disk(1.0, 16, 3, bottom_size=0.01, fine_half_width=0.5)
    with pytest.raises(MeshError, match="core_fraction"):
        half_disk(1.0, 16, 3, core_fraction=0.9)


# ---------------------------------------------------------------------------------- disk
@pytest.mark.parametrize("n_circ, n_radial, surface_size", [(8, 1, None), (32, 4, None),
                                                             (64, 6, 0.02), (128, 12, 0.01)])
def test_disk_tiles_the_inscribed_polygon_with_good_quads(n_circ, n_radial, surface_size):
    center = (0.3, -2.0)
    m = disk(0.5, n_circ, n_radial, surface_size, center=center)
    areas = cell_areas(m)
    assert np.all(areas > 0)
    # the boundary is the inscribed n-gon, tiled exactly: its area to round-off
    exact = 0.5 * n_circ * 0.25 * np.sin(2 * np.pi / n_circ)
    assert areas.sum() == pytest.approx(exact, rel=100 * EPS)
    assert m.n_cells == (n_circ // 4) ** 2 + n_circ * n_radial
    # every corner Jacobian positive (not only the shoelace area)
    assert corner_jacobians(m.nodes, m.cells).min() > 0
    # the O-grid's worst corners are at the core's corners, 270/2 = 135 degrees wide, so the
    # opposite ones go down towards 45; nothing is worse than that
    angles = interior_angles_deg(m)
    assert angles.min() > 45.0 and angles.max() < 135.0 + 1e-9
    assert_edge_sets_on_boundary(m)
    assert_normals_point_away(m)
    assert len(boundary_edges(m)) == n_circ == len(m.edge_sets["outer"])


def test_disk_sets_lowest_node_and_center():
    center = np.array([1.0, 2.0])
    m = disk(0.5, 48, 3, center=center)
    outer = surface_chain(m, "outer")
    assert outer.closed and list(outer.nodes) == list(m.node_sets["outer"])
    radii = np.linalg.norm(m.nodes[outer.nodes] - center, axis=1)
    assert np.all(np.abs(radii - 0.5) < 10 * EPS)
    assert np.linalg.norm(m.nodes - center, axis=1).max() <= 0.5 + 10 * EPS
    xy = m.nodes[outer.nodes] - center  # counter-clockwise: positive shoelace area
    assert np.sum(xy[:, 0] * np.roll(xy[:, 1], -1) - np.roll(xy[:, 0], -1) * xy[:, 1]) > 0
    bottom, top = m.node_sets["bottom"][0], m.node_sets["top"][0]
    assert bottom == outer.nodes[0] and m.nodes[bottom, 1] == m.nodes[:, 1].min()
    assert np.array_equal(m.nodes[bottom], center + [0.0, -0.5])
    assert np.array_equal(m.nodes[top], center + [0.0, 0.5])
    assert np.array_equal(m.nodes[m.node_sets["center"][0]], center)
    assert m.node_sets["all"].size == m.n_nodes


def test_disk_area_converges_at_second_order():
    n = np.array([16, 32, 64, 128])
    errors = np.array([abs(cell_areas(disk(1.0, k, 3)).sum() - np.pi) for k in n])
    rate = -np.polyfit(np.log(n), np.log(errors), 1)[0]
    # n circular segments of area (2 pi / n)^3 / 12 each: rate 2 asymptotically
    assert rate == pytest.approx(2.0, abs=0.05)


def test_disk_grading_sets_the_surface_layer():
    m = disk(1.0, 64, 8, surface_size=0.02)
    below = np.sort(m.nodes[np.abs(m.nodes[:, 0]) < 1e-12, 1])
    layers = np.diff(below[:9])  # from the lowest node up through the ring layers
    assert layers[0] == pytest.approx(0.02, rel=1e-10)
    assert np.all(np.diff(layers[:8]) > 0)  # thicker inward
    uniform = disk(1.0, 64, 8)
    below = np.sort(uniform.nodes[np.abs(uniform.nodes[:, 0]) < 1e-12, 1])
    assert np.allclose(np.diff(below[:9]), 0.5 / 8, rtol=1e-12)  # (1 - core 0.5) / 8 layers


def test_disk_errors():
    with pytest.raises(MeshError, match="multiple of 8"):
        disk(1.0, 12, 2)
    with pytest.raises(MeshError, match="radius > 0"):
        disk(-1.0, 16, 2)
    with pytest.raises(MeshError, match="core_fraction"):
        disk(1.0, 16, 2, core_fraction=0.8)
    # the key is named (the message used to speak of a "first cell size" only)
    with pytest.raises(MeshError, match="surface_size = 0.6 does not fit.*too large"):
        disk(1.0, 16, 2, surface_size=0.6)
    with pytest.raises(MeshError, match="surface_size = 0.3 does not fit.*cannot cover"):
        disk(1.0, 16, 1, surface_size=0.3)
