"""Mesh quality measures on hand-made meshes."""

import numpy as np
import pytest

from ntncontact.mesh.quadmesh import MeshError, QuadMesh
from ntncontact.mesh.quality import (
    cell_min_sines,
    check_elements,
    check_move,
    corner_angles_deg,
    corner_jacobians,
    edge_lengths,
    quality_statistics,
    unique_edges,
)

# Exact-arithmetic geometry evaluated in floating point: a few ulps of the unit scale.
TOL = 1e-12

UNIT_SQUARE = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])


def grid(nx: int, ny: int, hx: float = 1.0, hy: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    xs, ys = np.meshgrid(np.arange(nx + 1) * hx, np.arange(ny + 1) * hy)
    nodes = np.column_stack([xs.ravel(), ys.ravel()])
    i, j = np.meshgrid(np.arange(nx), np.arange(ny))
    n0 = (j * (nx + 1) + i).ravel()
    cells = np.column_stack([n0, n0 + 1, n0 + nx + 2, n0 + nx + 1])
    return nodes, cells


def test_unit_square_measures():
    cells = np.array([[0, 1, 2, 3]])
    np.testing.assert_allclose(edge_lengths(UNIT_SQUARE, cells), 1.0, atol=TOL)
    np.testing.assert_allclose(corner_angles_deg(UNIT_SQUARE, cells), 90.0, atol=TOL)
    np.testing.assert_allclose(corner_jacobians(UNIT_SQUARE, cells), 1.0, atol=TOL)
    stats = quality_statistics(QuadMesh(UNIT_SQUARE, cells))
    assert stats["min_edge"] == pytest.approx(1.0, abs=TOL)
    assert stats["variance_edge"] == pytest.approx(0.0, abs=TOL)
    assert stats["average_angle_deg"] == pytest.approx(90.0, abs=TOL)
    assert stats["variance_angle"] == pytest.approx(0.0, abs=TOL)


def test_shared_edges_counted_once_and_population_variance():
    nodes, cells = grid(2, 1, hx=2.0, hy=1.0)
    edges = unique_edges(cells)
    assert len(edges) == 7  # 2 cells: 8 half-edges, 1 shared
    stats = quality_statistics(nodes, cells)
    lengths = np.array([2, 2, 2, 2, 1, 1, 1], dtype=float)
    assert stats["average_edge"] == pytest.approx(lengths.mean(), abs=TOL)
    # population variance (divide by 7, not 6) as defined under report Table 4.1
    assert stats["variance_edge"] == pytest.approx(np.sum((lengths - 11 / 7) ** 2) / 7, abs=TOL)
    assert stats["max_edge"] == pytest.approx(2.0, abs=TOL)


def test_parallelogram_angles_and_variance():
    # 60/120 degree rhombus of unit side
    c, s = np.cos(np.pi / 3), np.sin(np.pi / 3)
    nodes = np.array([[0, 0], [1, 0], [1 + c, s], [c, s]])
    angles = corner_angles_deg(nodes, [[0, 1, 2, 3]])
    np.testing.assert_allclose(angles, [[60, 120, 60, 120]], atol=1e-9)
    stats = quality_statistics(nodes, [[0, 1, 2, 3]])
    assert stats["variance_angle"] == pytest.approx(900.0, abs=1e-8)  # all deviate by 30
    assert stats["min_angle_deg"] == pytest.approx(60.0, abs=1e-9)


def test_reflex_corner_reads_above_180_and_sums_to_360():
    # an arrow-head (non-convex but counter-clockwise) quad: reflex corner at node 2
    nodes = np.array([[0.0, 0.0], [2.0, 0.0], [1.0, 0.3], [0.0, 2.0]])
    angles = corner_angles_deg(nodes, [[0, 1, 2, 3]])
    assert angles[0, 2] > 180.0
    assert angles.sum() == pytest.approx(360.0, abs=1e-9)
    assert corner_jacobians(nodes, [[0, 1, 2, 3]])[0, 2] < 0


def test_check_elements_passes_valid_mesh():
    nodes, cells = grid(3, 2)
    check_elements(nodes, cells, "block")  # must not raise


def test_check_elements_names_inverted_element_node_and_body():
    nodes, cells = grid(3, 2)
    nodes = nodes.copy()
    # push node 5 (interior, row 1 col 1) far right: inverts cells that have it on their left
    nodes[5] = [2.6, 1.0]
    with pytest.raises(MeshError) as err:
        check_elements(nodes, cells, "ring")
    msg = str(err.value)
    jac = corner_jacobians(nodes, cells)
    first = int(np.flatnonzero((jac <= 0).any(axis=1))[0])
    assert f"body 'ring': element {first} is inverted" in msg
    assert "at node " in msg
    node = int(msg.rsplit("at node ", 1)[1].rstrip(")"))
    assert node in cells[first]


def test_check_elements_degenerate_and_quadmesh_name():
    nodes = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 0.0], [0.0, 1.0]])  # collapsed edge
    mesh = QuadMesh(nodes, [[0, 1, 2, 3]], name="foundation")
    with pytest.raises(MeshError, match="body 'foundation': element 0 is degenerate"):
        check_elements(mesh)


def test_check_move_names_the_cell_a_move_inverts():
    old, cells = grid(3, 2)
    new = old.copy()
    new[5] = [2.6, 1.0]  # as above, from a valid mesh
    with pytest.raises(MeshError, match="body 'ring': element 1 is inverted"):
        check_move(new, old, cells, "ring")
    with pytest.raises(MeshError, match="element 4 is inverted"):
        check_move(new, old, cells, "ring", which=[3, 4, 5])  # numbers stay the mesh's


def test_check_move_lets_a_reflex_cell_improve_and_refuses_to_make_it_worse():
    """Cell 1 of a row of three has a reflex corner at node 2 before the move (the material's
    deformation did it; sine -0.2). Moving node 2 so that it is less reflex (-0.16) is not the
    move's doing and passes, although check_elements refuses the result; moving it the other
    way (-0.40) is refused."""
    old, cells = grid(3, 1)
    old = old.copy()
    old[2] = [1.5, 0.6]
    assert cell_min_sines(old, cells)[1] == pytest.approx(-0.2, abs=1e-3)
    better, worse = old.copy(), old.copy()
    better[2], worse[2] = [1.5, 0.58], [1.5, 0.7]
    assert cell_min_sines(old, cells)[1] < cell_min_sines(better, cells)[1] < 0.0
    check_move(better, old, cells, "block")  # must not raise
    with pytest.raises(MeshError, match="element 1 is inverted"):
        check_elements(better, cells, "block")
    with pytest.raises(MeshError, match="body 'block': element 1 is inverted"):
        check_move(worse, old, cells, "block")


def test_smoothing_beside_a_reflex_cell_it_does_not_touch():
    """Smoother.run given the mesh before the move (an ALE body's t_n mesh) refuses only cells
    made worse than there (``check_move``): with cell 0 reflex and only node 8 free (not a
    node of cell 0), the sweep puts node 8 back at its neighbours' mean and returns; without
    a reference the reflex cell is refused, as for a mesh to be smoothed on its own."""
    from ntncontact.ale.smoothing import Smoother

    nodes, cells = grid(4, 2)
    nodes = nodes.copy()
    nodes[1] = [0.4, 0.6]  # cell 0 reflex at node 1
    nodes[8] = [3.3, 1.2]
    assert cell_min_sines(nodes, cells)[0] < 0.0 and 8 not in cells[0]
    fixed = np.ones(len(nodes), bool)
    fixed[8] = False
    smoother = Smoother(cells, len(nodes), fixed, method="laplacian")
    result = smoother.run(nodes, max_sweeps=50, reference=nodes)
    np.testing.assert_allclose(result.nodes[8], [3.0, 1.0], atol=1e-5)
    np.testing.assert_array_equal(result.nodes[fixed], nodes[fixed])
    with pytest.raises(MeshError, match="element 0 is inverted"):
        smoother.run(nodes, max_sweeps=50)
