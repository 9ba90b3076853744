"""fem.assembly.CsrPattern's entry map in int32 (issue 18, memory): the same matrices."""

import numpy as np
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
