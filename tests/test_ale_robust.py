"""ALE bodies whose own material motion made slivers (ale.motion.SLIVER_SINE): a move around
them smooths the interior in position, where every acceptance test of a move (each against
t_n) would leave them. Under friction the contact-side rows of a sliding ALE body shear while
its surface nodes are held under their partners (the fast-sliding blocks refined 8x with both
blocks ALE: the upper block's second-row cell folded at t = 0.126)."""

import numpy as np
from helpers import reflex_cell_block

from ntncontact.ale.motion import SLIVER_SINE, AleBody, move_ale_body
from ntncontact.mesh.generators import rectangle
from ntncontact.mesh.quality import cell_min_sines

DT = 0.01


def sheared_block(peak: float):
    """A 16 x 4 block of flat cells (0.25 x 0.1) whose row below the top is shifted along x
    by ``peak`` at the middle, tapering to zero at the ends: the top row sheared as by a held
    surface over sliding material; (mesh, X, d, v, a)."""
    mesh = rectangle(4.0, 0.4, 16, 4)
    X = mesh.nodes.copy()
    d = np.zeros_like(X)
    row = np.isclose(X[:, 1], 0.3)
    d[row, 0] = peak * np.maximum(0.0, 1.0 - np.abs(X[row, 0] - 2.0) / 2.0)
    n = len(X)
    return mesh, X, d, np.tile([1.0, 0.0], (n, 1)), np.zeros((n, 2))


def slide_middle(mesh, X, d, v, a, slide: float):
    """Move the top's middle node ``slide`` along the top."""
    body = AleBody.from_mesh(mesh, "top")
    x = X + d
    node = int(np.flatnonzero(np.isclose(x[:, 0], 2.0) & np.isclose(x[:, 1], 0.4))[0])
    x_pred = x[[node]] + DT * v[[node]]
    return body, move_ale_body(body, X, d, v, a, [node], x_pred + [slide, 0.0], x_pred, DT)


def test_a_move_beside_slivers_smooths_them():
    """Top-row cells at sine 0.083 at t_n (shear 12): the slide alone would be acceptable (it
    makes no changed cell worse than at t_n), so before the interior stayed and the slivers
    with it; now the region is smoothed and no cell is left a sliver."""
    mesh, X, d, v, a = sheared_block(1.2)
    before = cell_min_sines(X + d, mesh.cells)
    assert before.min() < SLIVER_SINE
    body, out = slide_middle(mesh, X, d, v, a, 0.01)
    assert out.interior == "position"
    assert cell_min_sines(out.x_mesh, mesh.cells).min() > SLIVER_SINE


def test_a_move_beside_sheared_cells_above_the_threshold_keeps_its_interior():
    """Shear 6 (sine 0.16): the same slide moves the surface alone, as before."""
    mesh, X, d, v, a = sheared_block(0.6)
    assert cell_min_sines(X + d, mesh.cells).min() > SLIVER_SINE
    body, out = slide_middle(mesh, X, d, v, a, 0.01)
    assert out.interior == "surface"


def test_a_reflex_cell_the_material_made_is_smoothed_valid():
    """test_ale_motion's reflex cell (a top node pushed 0.15 down and left, sine -0.38 at t_n):
    the surface's move alone left it reflex (-0.13 / -0.32); with the region smoothed it is
    valid again (measured 0.246 / 0.008)."""
    mesh, X, d, node, x = reflex_cell_block()
    zero = np.zeros_like(X)
    for slide in (0.03, -0.03):
        out = move_ale_body(AleBody.from_mesh(mesh, "top"), X, d, zero, zero, [node],
                            x[[node]] + [[slide, 0.0]], x[[node]], DT)
        assert out.interior == "position"
        assert cell_min_sines(out.x_mesh, mesh.cells).min() > 0.0
