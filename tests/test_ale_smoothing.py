"""Interior smoothing: fixed points, untangling, refusal of inverting moves, error reporting."""

import numpy as np
import pytest

from ntncontact.ale.smoothing import (
    Smoother,
    boundary_node_mask,
    harmonic_extension,
    node_adjacency,
)
from ntncontact.mesh.quadmesh import MeshError
from ntncontact.mesh.quality import cell_min_sines, corner_angles_deg, corner_jacobians

METHODS = ["laplacian", "angle", "weighted_angle"]


def grid(nx: int, ny: int, hx: float = 1.0, hy: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    xs, ys = np.meshgrid(np.arange(nx + 1) * hx, np.arange(ny + 1) * hy)
    nodes = np.column_stack([xs.ravel(), ys.ravel()])
    i, j = np.meshgrid(np.arange(nx), np.arange(ny))
    n0 = (j * (nx + 1) + i).ravel()
    return nodes, np.column_stack([n0, n0 + 1, n0 + nx + 2, n0 + nx + 1])


def test_boundary_mask():
    nodes, cells = grid(4, 3)
    mask = boundary_node_mask(cells, len(nodes))
    assert mask.sum() == 2 * (5 + 4) - 4
    assert not mask[6] and mask[0]


@pytest.mark.parametrize("method", METHODS)
def test_uniform_rectangular_grid_is_a_fixed_point(method):
    nodes, cells = grid(5, 4, hx=0.5, hy=0.3)
    result = Smoother(cells, len(nodes), method=method).run(nodes, max_sweeps=3)
    # a fixed point up to round-off of angle/rotation evaluations on an O(1) mesh
    np.testing.assert_allclose(result.nodes, nodes, atol=1e-12)
    assert result.sweeps == 1


@pytest.mark.parametrize("method", METHODS)
def test_untangles_perturbed_grid(method):
    nodes, cells = grid(6, 6)
    rng = np.random.default_rng(3)
    free = ~boundary_node_mask(cells, len(nodes))
    perturbed = nodes + free[:, None] * rng.uniform(-0.35, 0.35, nodes.shape)
    perturbed[24] = [4.7, 3.2]  # node (3, 3) dragged past its neighbours: tangled
    assert (corner_jacobians(perturbed, cells) < 0).any()
    smoother = Smoother(cells, len(nodes), method=method)
    out = smoother.run(perturbed, max_sweeps=200, rel_tol=1e-10).nodes
    assert (corner_jacobians(out, cells) > 0).all()
    np.testing.assert_array_equal(out[~free], nodes[~free])
    # the boundary of a square grid pins the unique smooth answer, the uniform grid; Jacobi
    # angle sweeps converge linearly (~1e-6 after 200 sweeps), far below the 0.35 perturbation
    np.testing.assert_allclose(out, nodes, atol=1e-4)
    assert corner_angles_deg(out, cells).min() > 89.9


def test_weighted_angle_differs_from_simple_angle():
    nodes, cells = grid(4, 4)
    moved = nodes.copy()
    moved[12] += [0.45, 0.3]
    simple = Smoother(cells, len(nodes), method="angle").candidates(moved)
    weighted = Smoother(cells, len(nodes), method="weighted_angle").candidates(moved)
    assert np.abs(simple - weighted).max() > 1e-3


def chevron_patch() -> tuple[np.ndarray, np.ndarray]:
    """Fig 4.7 analogue: four thin cells around P (node 8) in a V-shaped band.

    The centroid of P's edge neighbours (S, E, N, W) lies above N, outside the band.
    """
    nodes = np.array([
        [0.0, 0.0], [1.0, 2.0], [1.0, 2.2], [1.0, 2.4],  # S, SE, E, NE
        [0.0, 0.4], [-1.0, 2.4], [-1.0, 2.2], [-1.0, 2.0],  # N, NW, W, SW
        [0.0, 0.2],  # P
    ])
    cells = np.array([[0, 1, 2, 8], [8, 2, 3, 4], [7, 0, 8, 6], [6, 8, 4, 5]])
    return nodes, cells


def test_inverting_move_is_refused_or_shortened():
    nodes, cells = chevron_patch()
    assert (corner_jacobians(nodes, cells) > 0).all(), "test set-up: valid start"
    fixed = np.ones(9, bool)
    fixed[8] = False
    refusing = Smoother(cells, 9, fixed, method="laplacian", max_halvings=0)
    proposed = refusing.candidates(nodes)
    np.testing.assert_allclose(proposed[8], [0.0, 1.2], atol=1e-12)
    assert (corner_jacobians(proposed, cells) <= 0).any(), "test set-up: the move must invert"
    result = refusing.run(nodes, max_sweeps=5)
    np.testing.assert_array_equal(result.nodes, nodes)
    # every move refused => nothing moved => converged after one sweep
    assert result.refused_moves == 1 and result.sweeps == 1
    # with step halving: 1/2 and 1/4 of the step still pass N (y = 0.4), 1/8 does not
    halving = Smoother(cells, 9, fixed, method="laplacian", max_halvings=3)
    one = halving.run(nodes, max_sweeps=1)
    np.testing.assert_allclose(one.nodes[8], [0.0, 0.2 + 1.0 / 8], atol=1e-12)
    assert one.shortened_moves == 1 and one.refused_moves == 0
    assert (corner_jacobians(one.nodes, cells) > 0).all()


def test_inverted_final_mesh_raises_with_body_name():
    nodes, cells = grid(2, 2)
    nodes[0] = [1.5, 1.5]  # a fixed boundary node inverts its cell: smoothing cannot fix it
    smoother = Smoother(cells, len(nodes), method="angle", body_name="foundation")
    with pytest.raises(MeshError, match="body 'foundation': element 0 is inverted"):
        smoother.run(nodes, max_sweeps=5)


def test_unknown_method_rejected():
    nodes, cells = grid(1, 1)
    with pytest.raises(ValueError, match="unknown smoothing method"):
        Smoother(cells, len(nodes), method="spring")


@pytest.mark.parametrize("dense_limit", [400, 0])  # dense and sparse solves
def test_harmonic_extension_reproduces_linear_moves_and_leaves_the_rest_in_place(dense_limit):
    """On a uniform grid the graph Laplacian of a linear field vanishes: the extension of a
    linear boundary move is that linear move; nodes outside the free set keep their moves."""
    nodes, cells = grid(8, 6, hx=0.5, hy=0.3)
    n = len(nodes)
    adjacency = node_adjacency(cells, n)
    free = ~boundary_node_mask(cells, n)
    linear = nodes @ np.array([[0.01, -0.02], [0.03, 0.005]]).T + [0.002, -0.001]
    moves = np.where(free[:, None], 0.0, linear)
    out = harmonic_extension(adjacency, moves, free, dense_limit=dense_limit)
    np.testing.assert_allclose(out, linear, atol=1e-15)  # O(0.01) moves: round-off
    # zero given moves: exactly zero, whatever the free set
    assert not harmonic_extension(adjacency, np.zeros((n, 2)), free, dense_limit).any()
    # one top node moved, only the two rows below it free: everything else stays exactly put
    top = 6 * 9 + 4  # the node at (2, 1.8), middle of the top side
    moves = np.zeros((n, 2))
    moves[top] = [0.1, 0.0]
    near = free & (nodes[:, 1] > 1.0) & (np.abs(nodes[:, 0] - 2.0) < 1.1)  # 2 rows of 5
    out = harmonic_extension(adjacency, moves, near, dense_limit=dense_limit)
    np.testing.assert_array_equal(out[~near & (np.arange(n) != top)], 0.0)
    assert np.all(out[near, 0] > 0.0) and np.all(out[near, 0] < 0.1)  # maximum principle
    assert near.sum() == 10 and out[top - 9, 0] == out[near, 0].max()  # the one right below


def test_cell_min_sines():
    nodes, cells = grid(2, 1)
    np.testing.assert_allclose(cell_min_sines(nodes, cells), 1.0, atol=1e-15)
    sheared = nodes + np.column_stack([nodes[:, 1], np.zeros(len(nodes))])  # 45 degree shear
    np.testing.assert_allclose(cell_min_sines(sheared, cells), np.sin(np.pi / 4), atol=1e-15)
    flipped = nodes.copy()
    flipped[0] = [1.5, 0.5]  # node 0 pulled across its cell
    assert cell_min_sines(flipped, cells)[0] < 0.0 < cell_min_sines(flipped, cells)[1]


@pytest.mark.parametrize("method", METHODS)
def test_sweeps_around_a_few_free_nodes_match_the_whole_mesh_sweeps_to_the_bit(method):
    """With the free nodes in a corner of a larger mesh (an ALE body's smoothing layers),
    ``run`` sweeps only the cells around them: the same positions to the bit, and the same
    counts, as the sweeps over the whole mesh; the rest of the mesh stays where it was."""
    nodes, cells = grid(20, 16, hx=0.5, hy=0.3)
    rng = np.random.default_rng(7)
    fixed = boundary_node_mask(cells, len(nodes))
    free = np.isin(np.arange(len(nodes)), cells[np.isin(cells, [22, 23, 44]).any(axis=1)])
    free &= ~fixed  # the nodes of the cells around nodes 22, 23 and 44
    moved = nodes + free[:, None] * rng.uniform(-0.12, 0.12, nodes.shape)
    smoother = Smoother(cells, len(nodes), ~free, method=method)
    assert free[cells].any(axis=1).sum() < 0.5 * len(cells)  # the local path
    local = smoother.run(moved, max_sweeps=200, rel_tol=1e-4)
    scale = float(np.mean(np.linalg.norm(moved[smoother._src] - moved[smoother._dst], axis=1)))
    whole = smoother._sweeps(moved.copy(), 200, 1e-4, scale)
    np.testing.assert_array_equal(local.nodes, whole.nodes)
    assert (local.sweeps, local.shortened_moves, local.refused_moves) == (
        whole.sweeps, whole.shortened_moves, whole.refused_moves)
    # laplacian and angle converge (21 and 47 sweeps); weighted_angle cycles to the limit
    assert (1 < local.sweeps < 200) if method != "weighted_angle" else (local.sweeps == 200)
    assert not np.array_equal(local.nodes[free], moved[free])
    np.testing.assert_array_equal(local.nodes[~free], moved[~free])
