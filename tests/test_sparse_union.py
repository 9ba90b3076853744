"""fem.sparse.TripletUnion: K + COO triplets in a pattern that exact zeros do not change."""

import numpy as np
import scipy.sparse as sp

from ntncontact.fem.sparse import TripletUnion


def _random_case(rng, n=12, m=20):
    K = sp.random(n, n, density=0.3, random_state=rng, format="csr") + sp.eye(n, format="csr")
    rows, cols = rng.integers(0, n, m), rng.integers(0, n, m)
    return K.tocsr(), rows, cols, rng.normal(size=m)


def test_sum_equals_scipy_sum():
    rng = np.random.default_rng(0)
    union = TripletUnion()
    for _ in range(5):  # new patterns each time: rebuilt, still exact
        K, rows, cols, vals = _random_case(rng)
        got = union.add(K, rows, cols, vals)
        want = K + sp.csr_matrix((vals, (rows, cols)), shape=K.shape)
        assert np.allclose(got.toarray(), want.toarray(), rtol=0, atol=1e-14)
        assert got.has_sorted_indices


def test_pattern_kept_when_values_cancel():
    """Triplets that cancel K entries (or are zero) keep their places: same indptr/indices."""
    rng = np.random.default_rng(1)
    K, rows, cols, vals = _random_case(rng)
    union = TripletUnion()
    first = union.add(K, rows, cols, vals)
    zero = union.add(K, rows, cols, np.zeros_like(vals))
    cancel_rows, cancel_cols = K.nonzero()
    cancelling = union.add(K, np.concatenate([rows, cancel_rows]),
                           np.concatenate([cols, cancel_cols]),
                           np.concatenate([vals, -K.data]))
    assert np.array_equal(zero.indptr, first.indptr)
    assert np.array_equal(zero.indices, first.indices)
    assert np.allclose(zero.toarray(), K.toarray())
    # the cancelled entries are stored explicit zeros, not dropped
    assert cancelling.nnz >= K.nnz
    assert np.allclose(cancelling.toarray(),
                       sp.csr_matrix((vals, (rows, cols)), shape=K.shape).toarray())


def test_rebuilt_when_triplet_places_change():
    rng = np.random.default_rng(2)
    K, rows, cols, vals = _random_case(rng)
    union = TripletUnion()
    union.add(K, rows, cols, vals)
    moved = (rows + 1) % K.shape[0]
    got = union.add(K, moved, cols, vals)
    want = K + sp.csr_matrix((vals, (moved, cols)), shape=K.shape)
    assert np.allclose(got.toarray(), want.toarray(), rtol=0, atol=1e-14)
