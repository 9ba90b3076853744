"""A CSR matrix plus COO triplets in a pattern that stays fixed while the triplets' places do.

Adding contact tangents to the stiffness with SciPy's ``K + extra`` drops the entries that
happen to sum to exactly zero, so the sparsity pattern changed from one Newton iteration to
the next and the sparse solver redid its ordering and symbolic analysis almost every time
(468 analyses for 623 factorizations in the ring impact). :class:`TripletUnion` keeps the
union pattern of K and the triplet positions, explicit zeros included, and reuses it for as
long as K's pattern holds and the triplets fall on places it already has.

The union only grows while K's pattern holds: when the active set changes, pairs that leave
keep their (zero) entries and pairs that come back find theirs, so the solver sees a new
pattern, and redoes its analysis, only when a pair touches dofs that no earlier pair coupled.
When it grows, it also takes in the entries its caller reserves (``TripletUnion.add``'s
``reserve``: the contact terms give those of the pairs a growing zone takes next), so that a
zone growing by a pair or two a step is not a new analysis at every step.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import scipy.sparse as sp
from numpy.typing import NDArray


class TripletUnion:
    """``add(K, rows, cols, vals)`` = K + COO(vals at rows, cols), in a stable CSR pattern."""

    def __init__(self) -> None:
        self._k_key: tuple | None = None  # K's (indptr, indices) the union was built for
        self._t_key: tuple | None = None  # the triplets' (rows, cols) that _t_map places
        # a checkpoint's union entries (row * n_cols + col, sorted), taken in by the first build
        self._restored = np.zeros(0, dtype=np.int64)
        self._k_map = self._t_map = self._indptr = self._indices = None
        self._gaps: NDArray | None = None  # the union's places that are not K's
        self._shape = (0, 0)
        self.free_block = FreeBlock()  # the Newton matrix's free-dof block, same lifetime

    def add(self, K: sp.csr_matrix, rows: NDArray, cols: NDArray, vals: NDArray,
            reserve: Reserve | None = None) -> sp.csr_matrix:
        """``reserve``: called only when the pattern must grow, (rows, cols) of entries that
        the triplets are expected to take soon, added to the union with the triplets' own
        (a growing contact zone's next pairs: one analysis instead of one per growth)."""
        if not self._same_k(K):  # a new K pattern starts afresh (a first K takes up a restore)
            self._build(K)
        if self._t_key is None or not all(map(np.array_equal, (rows, cols), self._t_key)):
            # placed in the union of K and the keys so far, and so grown and reserved at the
            # same calls in a restored run as in the run it continues (bit for bit)
            self._place(K, rows, cols, reserve)
        data = self._union_data(K)
        # only the few triplets' places (a bincount to the full size took another nnz array)
        np.add.at(data, self._t_map, vals)
        return sp.csr_matrix((data, self._indices, self._indptr), shape=K.shape)

    def spare(self, nnz: int) -> int:
        """How many entries to leave free after a tangent of ``nnz`` entries
        (``Assembler.internal``'s ``spare``) for :meth:`add` to spread it into the union in
        its own array: the union's entries beyond it, and room for a growth."""
        size = nnz if self._indices is None else max(self._indices.size, nnz)
        return size - nnz + max(MIN_GROWTH_ROOM, int(GROWTH_ROOM * size))

    def _union_data(self, K: sp.csr_matrix) -> NDArray:
        """K's values in the union pattern, zeros elsewhere: in K's own array when it is the
        head of one long enough (:meth:`spare`), else in a new one. Hertz refined 8x held K's
        and the union's data (2 x 17.7 MB) together here, its run's peak (issue 18)."""
        size = self._indices.size
        data = _head(K.data, size)
        if data is None:
            data = np.zeros(size)
            data[self._k_map] = K.data
            return data
        _spread(data, K.nnz, self._k_map)
        data[self._gap_places()] = 0.0
        return data

    def _gap_places(self) -> NDArray:
        if self._gaps is None:
            is_k = np.zeros(self._indices.size, dtype=bool)
            is_k[self._k_map] = True
            self._gaps = np.flatnonzero(~is_k)
        return self._gaps

    def holds(self, K: sp.csr_matrix) -> bool:
        """Whether a union pattern beyond K's own was built (or restored) for K's pattern."""
        if self._k_key is None:
            return self._restored.size > K.nnz
        return self._indices.size > K.nnz and self._same_k(K)

    @property
    def keys(self) -> NDArray:
        """The union's entries (row * n_cols + col, sorted), for a restart checkpoint. Made
        from the CSR arrays when asked: kept, they were an int64 array of the union's size
        alive at every factorization (17 MB at Hertz refined 8x; issue 18, memory)."""
        if self._k_key is None:
            return self._restored
        n_rows, n_cols = self._shape
        keys = np.repeat(np.arange(n_rows, dtype=np.int64) * n_cols, np.diff(self._indptr))
        keys += self._indices
        return keys

    def restore(self, keys: NDArray) -> None:
        """Start from a checkpoint's union (its K pattern is the model's, rebuilt the same):
        without it a restarted run would factor a smaller pattern than the run it continues,
        which PARDISO and the static LU order differently (other round-off)."""
        self.__init__()
        self._restored = np.asarray(keys, dtype=np.int64)

    def _same_k(self, K: sp.csr_matrix) -> bool:
        if self._k_key is None:
            return False
        indptr, indices = self._k_key
        return _same_array(K.indptr, indptr) and _same_array(K.indices, indices)

    def _place(self, K: sp.csr_matrix, rows: NDArray, cols: NDArray,
               reserve: Reserve | None) -> None:
        """New triplet places: found in the union (pattern kept), else the union grown (by
        the reserved entries too)."""
        keys_t = _keys(rows, cols, K.shape[1])
        at, found = self._locate(keys_t)
        if not found.all():
            reserved = np.zeros(0, np.int64) if reserve is None else _keys(*reserve(), K.shape[1])
            new = np.unique(np.concatenate([keys_t[~found], reserved]))
            self._grow(new[~self._locate(new)[1]])
            at, _ = self._locate(keys_t)
        self._t_map = at
        self._t_key = (np.array(rows, copy=True), np.array(cols, copy=True))

    def _locate(self, keys: NDArray) -> tuple[NDArray, NDArray[np.bool_]]:
        """Where the entries ``keys`` (row * n_cols + col) are in the union's CSR arrays, or
        would be inserted (before the entries of larger keys), and whether they are there.
        Searched among the keys of the rows they touch only, so that no array of the union's
        size is made or kept for it."""
        n_cols = self._shape[1]
        touched = np.unique(keys // n_cols)
        starts = self._indptr[touched]
        lengths = self._indptr[touched + 1] - starts
        offsets = starts - (np.cumsum(lengths) - lengths)  # global minus local position
        places = np.repeat(offsets, lengths) + np.arange(lengths.sum())
        local_keys = np.repeat(touched * n_cols, lengths) + self._indices[places]
        local = np.searchsorted(local_keys, keys)
        found = local < local_keys.size
        found[found] = local_keys[local[found]] == keys[found]
        return local + offsets[np.searchsorted(touched, keys // n_cols)], found

    def _grow(self, new: NDArray) -> None:
        """Insert keys ``new`` (sorted, none in the union) into the union for the same K: the
        same pattern as a rebuild from K, the triplets and the old union, and each K entry's
        place shifted by the entries inserted before it. A rebuild sorted all the keys again:
        at Hertz refined 8x (2.1 M entries) it held ~100 MB of temporaries, the largest
        transient of a step (issue 18); the insertion holds ~2 arrays of entries."""
        n_rows, n_cols = self._shape
        before, _ = self._locate(new)  # np.insert puts new[i] before index before[i]
        self._indices = np.insert(self._indices, before, (new % n_cols).astype(
            self._indices.dtype))
        added = np.bincount(new // n_cols, minlength=n_rows)
        self._indptr = self._indptr + np.concatenate([[0], np.cumsum(added)])
        # K's places rise (K's keys are sorted, see _build) by the number of insertions at or
        # before them: one small-integer array of K's size, where a search of every place
        # made two int64 ones, the RSS peak of Hertz refined 8x's step (issue 18, memory)
        # before in the places' own type: NumPy's search would otherwise convert all of
        # _k_map to int64 first (a temporary of twice its size: Hertz 8x's growth, 17 MB)
        firsts = np.searchsorted(self._k_map, before.astype(self._k_map.dtype))
        runs = np.diff(np.concatenate([[0], firsts, [self._k_map.size]]))
        self._k_map += np.repeat(np.arange(before.size + 1, dtype=self._k_map.dtype), runs)
        self._gaps = None

    def _build(self, K: sp.csr_matrix) -> None:
        """Union pattern (sorted, unique) of K and a restored union (before the first K only),
        and each K entry's place in it; the triplets are placed next (:meth:`_place`)."""
        if not K.has_sorted_indices:  # K's places in the union must rise with its entries
            raise ValueError("TripletUnion needs K with sorted column indices in each row")
        n_rows, n_cols = K.shape
        keys_k = np.repeat(np.arange(n_rows, dtype=np.int64) * n_cols, np.diff(K.indptr))
        keys_k += K.indices  # row * n_cols + col, built in place, sorted
        restored = self._restored if self._k_key is None else np.zeros(0, dtype=np.int64)
        union = _sorted_unique(np.concatenate([keys_k, restored]))
        self._restored = np.zeros(0, dtype=np.int64)
        self._shape = K.shape
        self._indptr = row_starts(union, K.shape)
        self._indices = (union % n_cols).astype(K.indices.dtype)
        position = np.int32 if union.size < 2**31 else np.int64  # kept: half the bytes
        self._k_map = np.searchsorted(union, keys_k).astype(position)
        self._k_key = (K.indptr, K.indices)  # by reference, see FreeBlock._build
        self._t_key = None
        self._gaps = None


#: :meth:`TripletUnion.spare`'s room for a growth: this fraction of the union's entries, at
#: least MIN_GROWTH_ROOM (a growing contact zone adds a few hundred to a few thousand)
GROWTH_ROOM = 0.01
MIN_GROWTH_ROOM = 4096
#: entries moved at a time by the in-place moves (a temporary of this size at most)
MOVE_CHUNK = 1 << 16


def _head(values: NDArray, size: int) -> NDArray | None:
    """The first ``size`` entries of the array that ``values`` begins (a view of its head,
    as ``Assembler.internal`` makes with ``spare``), or None if there is no such array."""
    base = values.base
    if (not isinstance(base, np.ndarray) or base.ndim != 1 or base.dtype != values.dtype
            or base.size < size or not base.flags.c_contiguous
            or not values.flags.c_contiguous
            or base.__array_interface__["data"][0] != values.__array_interface__["data"][0]):
        return None
    return base[:size]


def _spread(data: NDArray, n: int, places: NDArray) -> None:
    """``data[places] = data[:n]`` in place, ``places`` rising and ``places[i] >= i``: moved
    from the end, a chunk at a time, so that no value is overwritten before it moves."""
    for stop in range(n, 0, -MOVE_CHUNK):
        start = max(stop - MOVE_CHUNK, 0)
        data[places[start:stop]] = data[start:stop]


def _gather(data: NDArray, places: NDArray) -> NDArray:
    """``data[places]`` into the head of ``data`` itself, ``places`` rising and ``places[i] >=
    i``: moved from the start, a chunk at a time; the values beyond the head are spent."""
    for start in range(0, places.size, MOVE_CHUNK):
        stop = min(start + MOVE_CHUNK, places.size)
        data[start:stop] = data[places[start:stop]]
    return data[:places.size]


#: () -> (rows, cols) of entries to reserve in the union pattern (``TripletUnion.add``)
Reserve = Callable[[], tuple[NDArray, NDArray]]


def row_starts(keys: NDArray, shape: tuple[int, int]) -> NDArray:
    """CSR indptr (int64) of sorted keys row * n_cols + col: where each row's keys start."""
    return np.searchsorted(keys, np.arange(shape[0] + 1, dtype=np.int64) * shape[1])


def _sorted_unique(keys: NDArray) -> NDArray:
    """``np.unique(keys)`` by a stable sort in place (``keys`` is a temporary): the
    concatenated keys are a few sorted runs, which the stable sort merges. NumPy 2.3+'s
    ``np.unique`` takes a hash table instead, which on these structured int64 keys took
    1.2-3 s per union of the ring's 46 530-dof pattern against 0.05 s (issue 18: 15 s of a
    18-step k = 8 run)."""
    keys.sort(kind="stable")
    first = np.empty(keys.size, dtype=bool)
    first[:1] = True
    np.not_equal(keys[1:], keys[:-1], out=first[1:])
    return keys[first]


def _keys(rows: NDArray, cols: NDArray, n_cols: int) -> NDArray:
    return np.asarray(rows, np.int64) * n_cols + np.asarray(cols, np.int64)


class FreeBlock:
    """``K[free][:, free]`` by a map of the kept entries, computed once per pattern of K and
    set of free dofs. SciPy's two fancy-index passes made two copies of K's pattern and data
    per Newton matrix (~3 arrays of nnz entries live at the factorization, issue 18); the map
    makes one data array and shares the block's pattern between calls."""

    def __init__(self) -> None:
        self._key: tuple | None = None  # K's (indptr, indices) and the free dofs of the map
        self._map = self._indptr = self._indices = None
        self._shape = (0, 0)

    def __call__(self, K: sp.csr_matrix, free: NDArray, spend: bool = False) -> sp.csr_matrix:
        """The block; ``spend``: made in K's own data array, which it spends (K is not to be
        used again): no second array of K's size (issue 18, memory)."""
        if not self._same(K, free):
            self._build(K, free)
        data = _gather(K.data, self._map) if spend else K.data[self._map]
        return sp.csr_matrix((data, self._indices, self._indptr), shape=self._shape)

    def _same(self, K: sp.csr_matrix, free: NDArray) -> bool:
        if self._key is None:
            return False
        indptr, indices, kept = self._key
        return (_same_array(K.indptr, indptr) and _same_array(K.indices, indices)
                and _same_array(free, kept))

    def _build(self, K: sp.csr_matrix, free: NDArray) -> None:
        """The map, indptr and indices of the block, with no temporary beyond a boolean per
        entry and a chunk (the map built by index arrays of K's size, one of them int64,
        was Hertz refined 8x's peak once the union's growth was made in place; issue 18)."""
        n = K.shape[0]
        is_free = np.zeros(n, dtype=bool)
        is_free[free] = True
        keep = np.repeat(is_free, np.diff(K.indptr))  # the entry's row is free ...
        keep &= is_free[K.indices]  # ... and its column
        position = np.int32 if K.nnz < 2**31 else np.int64
        self._map = np.empty(np.count_nonzero(keep), dtype=position)
        taken = 0
        for start in range(0, keep.size, MOVE_CHUNK):
            found = np.flatnonzero(keep[start:start + MOVE_CHUNK]) + start
            self._map[taken:taken + found.size] = found
            taken += found.size
        del keep
        counts = np.diff(np.searchsorted(self._map, K.indptr))[free]  # kept entries a row
        self._indptr = np.concatenate([[0], np.cumsum(counts)]).astype(K.indptr.dtype)
        column = np.full(n, -1, dtype=K.indices.dtype)  # free dof -> its column in the block
        column[free] = np.arange(free.size)
        self._indices = np.empty(self._map.size, dtype=K.indices.dtype)
        for start in range(0, self._map.size, MOVE_CHUNK):
            stop = start + MOVE_CHUNK
            self._indices[start:stop] = column[K.indices[self._map[start:stop]]]
        self._shape = (free.size, free.size)
        # K's pattern arrays by reference (no copy of nnz entries): the assembler's and the
        # union's patterns are replaced, never changed in place
        self._key = (K.indptr, K.indices, np.array(free, copy=True))


def _same_array(a: NDArray, b: NDArray) -> bool:
    """Equal arrays; views of the same memory (SciPy wraps index arrays in views) at once."""
    if a.shape != b.shape or a.dtype != b.dtype:
        return a.shape == b.shape and np.array_equal(a, b)
    same_memory = (a.__array_interface__["data"][0] == b.__array_interface__["data"][0]
                   and a.strides == b.strides)
    return same_memory or np.array_equal(a, b)
