"""fem.sparse.TripletUnion: K + COO triplets in a pattern that exact zeros do not change."""

import numpy as np
import scipy.sparse as sp

from ntncontact.fem.sparse import FreeBlock, TripletUnion


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


def test_pattern_kept_when_the_active_set_shrinks_and_returns():
    """Triplets that leave keep their (zero) places and come back to them: the pattern, and so
    the solver's analysis, stays; a triplet on a new place grows the union, keeping the old."""
    from ntncontact.solvers.linear import LinearSolver

    rng = np.random.default_rng(3)
    n = 12
    K = (sp.random(n, n, density=0.2, random_state=rng) + 4.0 * n * sp.eye(n)).tocsr()
    rows, cols, vals = rng.integers(0, n, 20), rng.integers(0, n, 20), rng.normal(size=20)
    union, solver = TripletUnion(), LinearSolver("superlu")
    first = union.add(K, rows, cols, vals)
    subsets = [np.arange(5), np.arange(10, 20), np.arange(20)[::-1], np.zeros(0, int)]
    for keep in subsets:
        got = union.add(K, rows[keep], cols[keep], vals[keep])
        want = K + sp.csr_matrix((vals[keep], (rows[keep], cols[keep])), shape=K.shape)
        assert np.allclose(got.toarray(), want.toarray(), rtol=0, atol=1e-14)
        assert np.array_equal(got.indptr, first.indptr)
        assert np.array_equal(got.indices, first.indices)
        solver.solve(got, np.ones(n))
    assert solver.stats.analyses == 1
    new_place = np.flatnonzero(first.toarray() == 0)[0]  # an entry outside the union
    r, c = divmod(int(new_place), n)
    grown = union.add(K, np.append(rows[:3], r), np.append(cols[:3], c), np.ones(4))
    assert grown.nnz == first.nnz + 1
    assert np.allclose(grown.toarray(), (K + sp.csr_matrix(
        (np.ones(4), (np.append(rows[:3], r), np.append(cols[:3], c))), shape=K.shape)).toarray())
    again = union.add(K, rows, cols, vals)  # the first triplets: found in the grown union
    assert np.array_equal(again.indices, grown.indices)
    other_k = (K + sp.eye(n, k=1)).tocsr()  # a new K pattern starts afresh
    fresh = union.add(other_k, rows, cols, vals)
    assert np.allclose(fresh.toarray(), (other_k + sp.csr_matrix(
        (vals, (rows, cols)), shape=K.shape)).toarray())


def test_free_block_equals_scipy_fancy_indexing():
    """The map of kept entries gives K[free][:, free] exactly, reuses its pattern while K's
    pattern and the free dofs hold, and is rebuilt when either changes."""
    rng = np.random.default_rng(3)
    block = FreeBlock()
    K, *_ = _random_case(rng, n=15)
    free = np.sort(rng.choice(15, 11, replace=False))
    first = None
    for step in range(6):
        if step == 2:
            free = np.sort(rng.choice(15, 9, replace=False))  # other supports
        if step == 4:
            K, *_ = _random_case(rng, n=15)  # another pattern
        K = sp.csr_matrix((rng.normal(size=K.nnz), K.indices, K.indptr), shape=K.shape)
        got = block(K, free)
        want = K[free][:, free]
        assert got.shape == want.shape
        np.testing.assert_array_equal(got.toarray(), want.toarray())
        assert got.has_sorted_indices
        if step == 0:
            first = got
        if step == 1:  # same pattern and dofs: the block's pattern arrays are shared
            assert np.shares_memory(got.indices, first.indices)
            assert np.shares_memory(got.indptr, first.indptr)


def test_union_places_repeated_triplets_once_each():
    """Triplets at the same place add up (np.add.at, not a buffered fancy assignment)."""
    K = sp.eye(3, format="csr")
    rows, cols = np.array([0, 0, 2, 0]), np.array([1, 1, 2, 1])
    got = TripletUnion().add(K, rows, cols, np.array([1.0, 2.0, 5.0, 4.0])).toarray()
    np.testing.assert_array_equal(got, [[1.0, 7.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 6.0]])


def test_union_keys_are_those_of_np_unique():
    """The union's keys (a stable sort of a few sorted runs, not NumPy's hash-based unique):
    sorted, without repeats, the same set as np.unique, for runs that overlap and repeat."""
    from ntncontact.fem.sparse import _sorted_unique

    rng = np.random.default_rng(5)
    runs = [np.sort(rng.integers(0, 10**12, size)) for size in (1000, 37, 0, 500)]
    runs.append(runs[0][::3].copy())  # an earlier union's keys again
    keys = np.concatenate(runs)
    assert np.array_equal(_sorted_unique(keys), np.unique(keys))
    assert _sorted_unique(np.zeros(0, np.int64)).size == 0


def test_no_triplets_keep_the_union_pattern_and_a_restored_union_is_the_same():
    """A step without contact after one with it (``problem._add_triplets`` with no triplets)
    gives K in the union's pattern, so the solver keeps its analysis; and a union restored
    from a checkpoint's keys gives the same pattern as the union it was saved from."""
    from ntncontact.engine.problem import _add_triplets

    rng = np.random.default_rng(7)
    K, rows, cols, vals = _random_case(rng)
    union = TripletUnion()
    assert _add_triplets(K, [], union) is K  # nothing coupled yet: K itself
    contact = _add_triplets(K, [(rows, cols, vals)], union)
    assert contact.nnz > K.nnz and union.holds(K)
    free = _add_triplets(K, [(rows[:0], cols[:0], vals[:0])], union)
    assert np.array_equal(free.indices, contact.indices)
    assert np.array_equal(free.indptr, contact.indptr)
    np.testing.assert_array_equal(free.toarray(), K.toarray())
    restored = TripletUnion()
    restored.restore(union.keys.copy())
    assert restored.holds(K)
    for triplets in ([], [(rows[:4], cols[:4], vals[:4])]):
        again = _add_triplets(K, triplets, restored)
        want = _add_triplets(K, triplets, union)
        assert np.array_equal(again.indices, want.indices)
        np.testing.assert_array_equal(again.toarray(), want.toarray())
    other_k = (K + sp.eye(K.shape[0], k=1)).tocsr()
    assert not union.holds(other_k)


def test_a_grown_union_is_the_pattern_a_rebuild_gives():
    """New triplet places are inserted into the union (``TripletUnion._grow``): the same
    indptr, indices and values as a union built at once from K and all the triplets."""
    rng = np.random.default_rng(6)
    K, rows, cols, vals = _random_case(rng, n=40, m=30)
    union = TripletUnion()
    union.add(K, rows, cols, vals)
    more_rows, more_cols = rng.integers(0, 40, 25), rng.integers(0, 40, 25)
    more_vals = rng.normal(size=25)
    grown = union.add(K, more_rows, more_cols, more_vals)
    built = TripletUnion().add(K, np.concatenate([rows, more_rows]),
                               np.concatenate([cols, more_cols]),
                               np.concatenate([np.zeros_like(vals), more_vals]))
    assert np.array_equal(grown.indptr, built.indptr)
    assert np.array_equal(grown.indices, built.indices)
    assert np.array_equal(grown.data, built.data)
    assert union.keys.size == built.nnz


def test_reserved_entries_join_the_union_when_it_grows_and_only_then():
    """``reserve`` is asked for only when the pattern must grow (a first build or triplets on
    new places); its entries are explicit zeros of the union, and triplets that later fall
    on them keep the pattern."""
    rng = np.random.default_rng(4)
    n = 12
    K = (sp.random(n, n, density=0.2, random_state=rng) + 4.0 * n * sp.eye(n)).tocsr()
    outside = np.argwhere(K.toarray() == 0.0)
    reserved_rows, reserved_cols = outside[:6, 0], outside[:6, 1]
    calls = []

    def reserve():
        calls.append(1)
        return reserved_rows, reserved_cols

    rows, cols = outside[6:9, 0], outside[6:9, 1]
    union = TripletUnion()
    first = union.add(K, rows, cols, np.ones(3), reserve)
    assert len(calls) == 1 and first.nnz == K.nnz + 9
    assert np.allclose(first.toarray(), (K + sp.csr_matrix(
        (np.ones(3), (rows, cols)), shape=K.shape)).toarray())
    # the active set moves onto reserved places: found, no growth, no call
    moved = union.add(K, reserved_rows[:4], reserved_cols[:4], np.full(4, 2.0), reserve)
    assert len(calls) == 1
    assert np.array_equal(moved.indices, first.indices)
    assert np.allclose(moved.toarray(), (K + sp.csr_matrix(
        (np.full(4, 2.0), (reserved_rows[:4], reserved_cols[:4])), shape=K.shape)).toarray())
    # a place neither taken nor reserved grows the union, with the reservation asked again
    new_r, new_c = outside[9]
    grown = union.add(K, np.append(rows, new_r), np.append(cols, new_c), np.ones(4), reserve)
    assert len(calls) == 2 and grown.nnz == first.nnz + 1


def test_repeated_growth_matches_a_union_built_at_once():
    """Growth after growth (rows of several entries each, repeated and reserved places)
    keeps the pattern, the values and the triplets' places of a union built at once."""
    rng = np.random.default_rng(11)
    n = 60
    K = (sp.random(n, n, density=0.1, random_state=rng) + sp.eye(n)).tocsr()
    union = TripletUnion()
    seen_rows, seen_cols = np.zeros(0, np.int64), np.zeros(0, np.int64)
    for _ in range(6):
        rows, cols = rng.integers(0, n, 40), rng.integers(0, n, 40)
        extra_rows, extra_cols = rng.integers(0, n, 5), rng.integers(0, n, 5)
        vals = rng.normal(size=40)
        got = union.add(K, rows, cols, vals, lambda r=extra_rows, c=extra_cols: (r, c))
        seen_rows = np.concatenate([seen_rows, rows, extra_rows])
        seen_cols = np.concatenate([seen_cols, cols, extra_cols])
        places = np.zeros(K.shape)
        places[seen_rows, seen_cols] = 1.0
        pattern = (K + sp.csr_matrix(places)).tocsr()
        pattern.sort_indices()
        assert np.array_equal(got.indptr, pattern.indptr)
        assert np.array_equal(got.indices, pattern.indices)
        want = K.toarray()
        np.add.at(want, (rows, cols), vals)
        np.testing.assert_array_equal(got.toarray(), want)
        keys = np.repeat(np.arange(n), np.diff(pattern.indptr)) * n + pattern.indices
        assert np.array_equal(union.keys, keys)


def test_the_union_keeps_no_array_of_keys():
    """Between calls the union holds its indices (int32) and K's places in it (int32), not
    an int64 key per entry as well (issue 18: 17 MB alive at Hertz refined 8x's
    factorizations); its keys for a checkpoint are made when asked."""
    rng = np.random.default_rng(12)
    n = 400
    K = (sp.random(n, n, density=0.02, random_state=rng) + sp.eye(n)).tocsr()
    rows, cols = rng.integers(0, n, 50), rng.integers(0, n, 50)
    union = TripletUnion()
    matrix = union.add(K, rows, cols, rng.normal(size=50))
    held = sum(v.nbytes for v in vars(union).values() if isinstance(v, np.ndarray))
    held += sum(a.nbytes for a in union._t_key)
    assert held <= 4 * matrix.nnz + 4 * K.nnz + 8 * (n + 1) + 3 * 8 * rows.size
    assert union.keys.size == matrix.nnz


def test_growing_the_union_holds_no_large_temporaries():
    """A union that grows shifts K's places by one small-integer array of K's size (and
    makes the new data): below 16 bytes a K entry at its traced peak, where a search of
    every place made two int64 arrays (24 bytes and more; issue 18, Hertz refined 8x's RSS
    peak)."""
    import tracemalloc

    n = 20000
    K = sp.diags([np.full(n - abs(k), 1.0 + k) for k in range(-5, 6)], range(-5, 6),
                 format="csr")
    rng = np.random.default_rng(13)
    union = TripletUnion()
    union.add(K, rng.integers(0, n, 20), rng.integers(0, n, 20), rng.normal(size=20))
    rows, cols = rng.integers(0, n, 30), rng.integers(0, n, 30)
    tracemalloc.start()
    try:
        start = tracemalloc.get_traced_memory()[0]
        grown = union.add(K, rows, cols, rng.normal(size=30))
        peak = tracemalloc.get_traced_memory()[1] - start
    finally:
        tracemalloc.stop()
    assert grown.nnz > K.nnz + 30
    assert peak < 16 * K.nnz
