"""fem.assembly.CsrPattern's entry map in int32 (issue 18, memory): the same matrices."""

import numpy as np
import pytest
import scipy.sparse as sp
from helpers import neo_hookean_assembler

from ntncontact.fem.assembly import CsrPattern, element_dofs
from ntncontact.mesh.generators import rectangle


def test_the_entry_map_is_int32_and_assembles_what_coo_sums_give():
    mesh = rectangle(2.0, 1.0, 6, 4)
    edofs = element_dofs(np.asarray(mesh.cells))
    ndof = 2 * len(mesh.nodes)
    pattern = CsrPattern.from_element_dofs(edofs, ndof)
    assert pattern.entry_map.dtype == np.int32  # int64 took 512 bytes an element
    blocks = np.random.default_rng(3).normal(size=(len(edofs), 8, 8))
    rows, cols = np.repeat(edofs, 8, axis=1).ravel(), np.tile(edofs, (1, 8)).ravel()
    want = sp.coo_matrix((blocks.ravel(), (rows, cols)), shape=(ndof, ndof)).toarray()
    np.testing.assert_allclose(pattern.matrix(blocks).toarray(), want, rtol=1e-14, atol=1e-14)


def test_the_kernel_scatters_the_same_bits_through_an_int32_or_int64_map():
    mesh = rectangle(2.0, 1.0, 6, 4)
    asm, X, d = neo_hookean_assembler(mesh, seed=4)
    kernel = asm._numba_groups[0]
    out = []
    for dtype in (np.int64, np.int32):
        force, data = np.zeros(asm.ndof), np.zeros(asm.pattern.nnz)
        kernel.add(X, d, asm.lam, asm.mu, asm.pattern.entry_map.astype(dtype), force, data)
        out.append((force, data))
    np.testing.assert_array_equal(out[0][0], out[1][0])
    np.testing.assert_array_equal(out[0][1], out[1][1])


@pytest.mark.parametrize("mesh", ["rectangle", "annulus", "two bodies, graded"])
def test_the_dof_pattern_from_the_node_pattern_is_the_sorted_one(mesh):
    """``CsrPattern.of_dofs`` (the node pattern spread to 2 x 2 blocks) gives the arrays and
    types of ``from_element_dofs`` on the element dofs (a sort of 64 keys an element): the
    same indptr, column indices and place of every element entry, on a structured mesh, a
    closed ring (its seam's cells number their nodes out of order) and two stacked bodies
    whose node numbers interleave nothing."""
    from ntncontact.mesh.generators import annulus

    if mesh == "rectangle":
        cells, n = rectangle(2.0, 1.0, 7, 3).cells, 32
    elif mesh == "annulus":
        ring = annulus(0.5, 1.0, 3, 20)
        cells, n = ring.cells, len(ring.nodes)
    else:
        a = rectangle(1.0, 1.0, 5, 4, grading_x=6.0)
        b = rectangle(1.0, 1.0, 3, 3)
        cells = np.vstack([a.cells, b.cells + len(a.nodes)])
        n = len(a.nodes) + len(b.nodes)
    reference = CsrPattern.from_element_dofs(element_dofs(cells), 2 * n)
    spread = CsrPattern.from_element_dofs(cells, n).of_dofs(cells)
    assert spread.shape == reference.shape == (2 * n, 2 * n)
    for name in ("indptr", "indices", "entry_map"):
        mine, theirs = getattr(spread, name), getattr(reference, name)
        assert mine.dtype == theirs.dtype, name
        np.testing.assert_array_equal(mine, theirs, err_msg=name)
