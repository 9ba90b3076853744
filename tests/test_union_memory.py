"""The Newton matrix made in the tangent's own data array (issue 18, memory): the assembler
leaves room after the tangent's entries, the triplet union spreads them into its pattern
there and the free block is gathered there, so that no second array of the pattern's size
is made (Hertz refined 8x held K's and the union's data together, its run's peak)."""

import tracemalloc

import numpy as np
import scipy.sparse as sp
from helpers import neo_hookean_assembler

from ntncontact.fem import sparse
from ntncontact.fem.sparse import TripletUnion
from ntncontact.mesh.generators import rectangle


def _tangent(union: TripletUnion, spare: bool = True) -> sp.csr_matrix:
    mesh = rectangle(2.0, 1.0, 40, 20)
    asm, X, d = neo_hookean_assembler(mesh, seed=7)
    room = union.spare(asm.pattern.nnz) if spare else 0
    return asm.internal(X, d=d, spare=room)[1]


def _triplets(n: int):
    rng = np.random.default_rng(8)
    rows = rng.integers(0, n, 300)
    return rows, (rows + rng.integers(50, 400, 300)) % n, rng.normal(size=300)


def test_the_union_is_made_in_the_tangents_array_with_the_same_values(monkeypatch):
    monkeypatch.setattr(sparse, "MOVE_CHUNK", 1000)  # chunks well below this pattern's size
    union = TripletUnion()
    K = _tangent(union)
    rows, cols, vals = _triplets(K.shape[0])
    want = K.copy() + sp.csr_matrix((vals, (rows, cols)), shape=K.shape)
    union.add(K.copy(), rows, cols, vals)  # the union pattern, built from a plain copy
    union.add(_tangent(union), rows, cols, vals)  # its gaps found once a pattern
    K = _tangent(union)
    tracemalloc.start()
    try:
        got = union.add(K, rows, cols, vals)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert got.nnz > K.nnz and np.shares_memory(got.data, K.data)
    assert peak < 0.2 * got.data.nbytes  # a new array of the union's size was all of it
    np.testing.assert_array_equal(got.toarray(), want.toarray())
    free = np.flatnonzero(np.arange(K.shape[0]) % 7 != 0)
    block = union.free_block(got, free)
    taken = union.free_block(got, free, spend=True)  # spends got
    assert np.shares_memory(taken.data, K.data)
    np.testing.assert_array_equal(taken.toarray(), block.toarray())
    np.testing.assert_array_equal(taken.toarray(), want[free][:, free].toarray())


def test_a_tangent_without_room_is_copied_into_a_new_union_array():
    union = TripletUnion()
    K = _tangent(union, spare=False)
    rows, cols, vals = _triplets(K.shape[0])
    want = K + sp.csr_matrix((vals, (rows, cols)), shape=K.shape)
    got = union.add(K, rows, cols, vals)
    assert not np.shares_memory(got.data, K.data)
    np.testing.assert_array_equal(got.toarray(), want.toarray())



def test_a_growth_makes_no_copy_of_ks_places_in_a_wider_type():
    """A growth shifts K's places with a search among them for the insertion places, in their
    own integer type: NumPy converts the searched array to the wider type of the two, and
    int64 insertion places made an int64 copy of K's int32 places (Hertz refined 8x's growth,
    17 MB)."""
    union = TripletUnion()
    K = _tangent(union)
    rows, cols, vals = _triplets(K.shape[0])
    union.add(K, rows, cols, vals)
    places = union._k_map.nbytes
    new = np.array([0 * K.shape[1] + 700, 5 * K.shape[1] + 900], dtype=np.int64)
    assert not union._locate(new)[1].any()  # two entries the union lacks
    tracemalloc.start()
    try:
        union._grow(new)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    # the new union indices and the places' shift, each of the places' size (the copy: + 2)
    assert peak < 2.5 * places
