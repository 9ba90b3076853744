"""Tests of boundary edges, surface chains, edge and tributary lengths."""

from __future__ import annotations

import numpy as np
import pytest

from ntncontact.mesh.boundary import (
    SurfaceChain,
    boundary_edges,
    chain_edge_lengths,
    chain_from_edges,
    hanging_nodes,
    nodal_tributary_lengths,
    nodes_inside_cells,
    surface_chain,
)
from ntncontact.mesh.generators import annulus, disk, half_disk, rectangle
from ntncontact.mesh.quadmesh import MeshError, QuadMesh

EPS = np.finfo(float).eps


def test_boundary_edges_of_rectangle_form_ccw_loop():
    m = rectangle(2.0, 1.0, 4, 3)
    edges = boundary_edges(m)
    assert edges.shape == (2 * (4 + 3), 2)
    chain = chain_from_edges(edges)
    assert chain.closed and len(chain.nodes) == 14
    xy = m.nodes[chain.nodes]
    shoelace = 0.5 * np.sum(xy[:, 0] * np.roll(xy[:, 1], -1) - np.roll(xy[:, 0], -1) * xy[:, 1])
    # counter-clockwise loop around the body encloses its area (exact binary fractions)
    assert shoelace == pytest.approx(2.0, rel=10 * EPS)
    # the union of the four named sides equals the boundary, with the same orientation
    named = np.vstack([m.edge_sets[s] for s in ("bottom", "right", "top", "left")])
    assert {tuple(e) for e in named.tolist()} == {tuple(e) for e in edges.tolist()}


def test_boundary_edges_of_annulus_has_two_loops():
    m = annulus(0.5, 1.0, 2, 16)
    edges = boundary_edges(m)
    assert len(edges) == 32
    with pytest.raises(MeshError, match="more than one piece"):
        chain_from_edges(edges, "ring boundary")


def test_boundary_edges_detects_clockwise_cell():
    m = rectangle(2.0, 1.0, 2, 1)
    cells = m.cells.copy()
    cells[1] = cells[1, ::-1]
    with pytest.raises(MeshError, match="same direction"):
        boundary_edges(QuadMesh(m.nodes, cells))


def test_boundary_edges_detects_nonmanifold_edge():
    nodes = np.array([[0, 0], [1, 0], [1, 1], [0, 1], [2, 0], [2, 1], [1, 2], [0, 2]], float)
    # three cells sharing edge (1, 2) (the third overlaps the second)
    cells = np.array([[0, 1, 2, 3], [1, 4, 5, 2], [1, 4, 6, 2]])
    with pytest.raises(MeshError, match="more than two cells"):
        boundary_edges(QuadMesh(nodes, cells))


def test_surface_chain_open_and_order():
    m = rectangle(3.0, 1.0, 3, 1)
    chain = surface_chain(m, "top")
    assert isinstance(chain, SurfaceChain)
    assert not chain.closed and chain.nodes.tolist() == [7, 6, 5, 4]
    # shuffled edges give the same chain
    shuffled = m.edge_sets["top"][[2, 0, 1]]
    assert chain_from_edges(shuffled).nodes.tolist() == [7, 6, 5, 4]


def test_surface_chain_closed_loop_does_not_repeat_first_node():
    m = annulus(0.5, 1.0, 1, 12)
    chain = surface_chain(m, "outer")
    assert chain.closed and len(chain.nodes) == 12 == len(np.unique(chain.nodes))


@pytest.mark.parametrize(
    "edges, message",
    [
        ([[0, 1], [1, 2], [1, 3]], "starts or ends two edges"),  # branch
        ([[0, 1], [2, 1]], "starts or ends two edges"),  # opposite orientation
        ([[0, 1], [5, 6]], "separate pieces"),
        ([[0, 1], [1, 2], [2, 0], [5, 6]], "more than one piece"),
        (np.zeros((0, 2), int), "no edges"),
    ],
)
def test_chain_errors(edges, message):
    with pytest.raises(MeshError, match=message):
        chain_from_edges(np.asarray(edges), "test")


def test_surface_chain_unknown_set():
    with pytest.raises(MeshError, match="no surface"):
        surface_chain(rectangle(1.0, 1.0, 1, 1), "nope")


def test_a_joined_surface_is_one_chain_through_the_shared_corner():
    m = rectangle(3.0, 2.0, 3, 2)
    chain = surface_chain(m, "bottom+right")
    # bottom 0 -> 3, then up the right face 3 -> 7 -> 11; the corner 3 once
    assert not chain.closed and chain.nodes.tolist() == [0, 1, 2, 3, 7, 11]
    assert surface_chain(m, "right+bottom").nodes.tolist() == chain.nodes.tolist()
    assert m.node_set("bottom+right").tolist() == [0, 1, 2, 3, 7, 11]
    assert surface_chain(m, "left+bottom+right").nodes.tolist() == [8, 4, 0, 1, 2, 3, 7, 11]


@pytest.mark.parametrize("name, message", [
    ("bottom+top", "separate pieces"),  # not one surface
    ("bottom+rigth", "no surface .edge set. named 'rigth'.*join several with"),
])
def test_a_joined_surface_that_is_no_chain_is_refused(name, message):
    with pytest.raises(MeshError, match=message):
        surface_chain(rectangle(3.0, 2.0, 3, 2), name)


def test_edge_and_tributary_lengths():
    xy = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 2.0]])
    assert chain_edge_lengths(xy, closed=False).tolist() == [1.0, 2.0]
    assert np.allclose(chain_edge_lengths(xy, closed=True), [1.0, 2.0, np.sqrt(5.0)],
                       rtol=10 * EPS, atol=0.0)
    assert nodal_tributary_lengths(xy, closed=False).tolist() == [0.5, 1.5, 1.0]
    trib = nodal_tributary_lengths(xy, closed=True)
    # node i gets half of each edge it touches (5.5-5.6); together they share out the perimeter
    r5 = np.sqrt(5.0)
    assert np.allclose(trib, [(r5 + 1) / 2, 1.5, (2 + r5) / 2], rtol=10 * EPS, atol=0.0)
    assert trib.sum() == pytest.approx(3.0 + r5, rel=10 * EPS)


def test_edge_lengths_reject_a_single_node():
    with pytest.raises(MeshError, match="shape"):
        chain_edge_lengths(np.zeros((1, 2)), False)


def test_rectangle_surfaces_have_the_body_on_the_left():
    m = rectangle(2.0, 1.0, 4, 2)
    for side, outward in (("bottom", [0, -1]), ("right", [1, 0]), ("top", [0, 1]),
                          ("left", [-1, 0])):
        chain = surface_chain(m, side)
        edge = np.diff(m.nodes[chain.nodes], axis=0)
        normals = np.column_stack((edge[:, 1], -edge[:, 0])) / np.linalg.norm(edge, axis=1)[:, None]
        assert np.abs(normals - outward).max() < 10 * EPS


def _three_beside_one(offset: float) -> QuadMesh:
    """Three cells stacked (x 0..1) beside one cell (x 1..2), joined at the corners only; the
    two inner nodes of the left column are moved right by ``offset``."""
    ys = np.array([0.0, 1 / 3, 2 / 3, 1.0])
    xs = np.array([0.0, 0.0, 0.0, 0.0, 1.0, 1.0 + offset, 1.0 + offset, 1.0, 2.0, 2.0])
    nodes = np.column_stack((xs, np.concatenate((ys, ys, [0.0, 1.0]))))
    cells = [[0, 4, 5, 1], [1, 5, 6, 2], [2, 6, 7, 3], [4, 8, 9, 7]]
    return QuadMesh(nodes, np.array(cells))


def test_hanging_nodes_are_found_on_their_edge():
    """Both nodes of a 3-to-1 T-junction hang on the big cell's edge (7, 4), also a round-off
    away from it; moved off the edge by more than HANGING_RTOL of its length (a slot 1e-8 or
    5e-4 wide: a tester's valid U-shaped body with a 5e-4 slot was refused) they do not."""
    found = hanging_nodes(_three_beside_one(0.0))
    assert sorted(found[:, 0].tolist()) == [5, 6]
    assert np.all(found[:, 1:] == [7, 4])
    assert hanging_nodes(_three_beside_one(-1e-13)).shape[0] == 2  # round-off off the line
    for slot in (-1e-8, -5e-4, -2e-3):
        assert hanging_nodes(_three_beside_one(slot)).shape == (0, 3)


@pytest.mark.parametrize("mesh", [rectangle(3.0, 1.0, 30, 4, grading_x=1.3),
                                  annulus(1.0, 1.2, 2, 64), disk(1.0, 48, 4, 0.05),
                                  half_disk(1.0, 24, 5, 0.02)], ids=lambda m: m.name)
def test_generated_meshes_have_no_hanging_nodes(mesh):
    assert hanging_nodes(mesh).shape == (0, 3)
    assert nodes_inside_cells(mesh).shape == (0, 2)


def test_a_surface_that_is_a_point_group_says_so():
    """A contact surface named after a physical point group was "no surface (edge set) named
    'bottom' (known: ...)"; now it says 'bottom' holds nodes only and a surface needs a line
    group."""
    mesh = rectangle(1.0, 1.0, 2, 2).with_sets(node_sets={"corner": np.array([0])})
    with pytest.raises(MeshError, match=r"'corner' is a node set only \(a physical point or "
                                        r"surface group.*needs a physical line group"):
        mesh.edge_set("corner")
    with pytest.raises(MeshError, match="no surface .* named 'nowhere'"):
        mesh.edge_set("nowhere")


@pytest.mark.parametrize("size", [0, 1, 7, 5000])
def test_unique_pairs_gives_numpys_row_unique(size):
    """``unique_pairs`` (one int64 key a pair) against NumPy's row-wise unique: the same rows
    in the same order, first indices, inverse and counts, on pairs with many repeats, zeros,
    node numbers up to 10^6 and negative ones; and the boundary edges built on it are those
    of a mesh's cell edges used once."""
    from ntncontact.mesh.quadmesh import cell_edges, unique_pairs

    rng = np.random.default_rng(size)
    pairs = np.column_stack([rng.integers(0, 40, size), rng.integers(0, 40, size)])
    pairs[: size // 2] *= 25_000  # large node numbers too
    pairs[size // 3: size // 2] -= 20  # and negative ones (bad input), kept apart
    flags = dict(return_index=True, return_inverse=True, return_counts=True)
    mine, reference = unique_pairs(pairs, **flags), np.unique(pairs, axis=0, **flags)
    for a, b in zip(mine, reference, strict=True):
        np.testing.assert_array_equal(a.reshape(-1), b.reshape(-1))
    np.testing.assert_array_equal(unique_pairs(pairs), np.unique(pairs, axis=0).reshape(-1, 2))
    only = unique_pairs(pairs, return_index=False, return_counts=True)  # a flag given False
    np.testing.assert_array_equal(only[1], reference[3])
    np.testing.assert_array_equal(unique_pairs(pairs, return_index=False),  # all of them
                                  np.unique(pairs, axis=0).reshape(-1, 2))
    mesh = annulus(0.5, 1.0, 3, 17)
    edges = cell_edges(mesh.cells)
    keys = np.sort(edges, axis=1)
    used_once = [tuple(e) for e, k in zip(edges, keys, strict=True)
                 if (keys == k).all(axis=1).sum() == 1]
    assert sorted(map(tuple, boundary_edges(mesh))) == sorted(used_once)
