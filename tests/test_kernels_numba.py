"""The Numba assembly kernel against the NumPy oracle (tests/element_oracle.py), and its error
reporting."""

import numba
import numpy as np
import pytest
from element_oracle import oracle_internal

from ntncontact.fem import kernels_numba
from ntncontact.fem.assembly import Assembler, MaterialGroup
from ntncontact.fem.kernels_numba import NumbaAssembly, block_partition
from ntncontact.fem.q4 import InvertedElementError

# Both kernels evaluate the same formulas in a different order: differences are a few ulps of
# the largest terms summed, far below 1e-12 of the largest entry for meshes of <= 1000 elements.
RTOL = 1e-12


def distorted_grid(nx, ny, rng, jitter=0.25):
    """Structured grid over [0, 2] x [0, 1] with every node moved: no two elements alike."""
    xs, ys = np.meshgrid(np.linspace(0, 2.0, nx + 1), np.linspace(0, 1.0, ny + 1))
    nodes = np.column_stack([xs.ravel(), ys.ravel()])
    nodes += jitter * rng.uniform(-1, 1, nodes.shape) / max(nx, ny)
    i, j = np.meshgrid(np.arange(nx), np.arange(ny))
    n0 = (j * (nx + 1) + i).ravel()
    return nodes, np.column_stack([n0, n0 + 1, n0 + nx + 2, n0 + nx + 1])


def deformed(nodes, rng, h, amount=0.15):
    """A finite homogeneous stretch/shear, a rotation and a random nodal perturbation of 5% of
    the element size h (large enough to vary F between elements, small enough not to fold)."""
    G = np.array([[0.3, 0.2], [-0.1, -0.2]]) * amount / 0.15
    th = 0.7
    R = np.array([[np.cos(th), -np.sin(th)], [np.sin(th), np.cos(th)]])
    return (nodes + nodes @ G.T) @ R.T + 0.05 * h * rng.standard_normal(nodes.shape)


def make_assembler(nodes, cells, groups, rng):
    ne = len(cells)
    lam = rng.uniform(0.5, 3.0, ne)  # per-element parameters catch indexing mistakes
    mu = rng.uniform(0.5, 2.0, ne)
    return Assembler(cells, len(nodes), groups, lam, mu, np.ones(ne))


def both_kernels(asm, X, x, need_tangent=True):
    """(the oracle's, the package's) force, tangent and energy at positions x."""
    d = x - X
    return (oracle_internal(asm, X, d, need_tangent),
            asm.internal(X, d=d, need_tangent=need_tangent))


def assert_same(reference, result):
    (f0, K0, W0), (f1, K1, W1) = reference, result
    assert np.abs(f1 - f0).max() <= RTOL * np.abs(f0).max()
    assert abs(W1 - W0) <= RTOL * abs(W0)
    if K0 is not None:
        # identical pattern, so the data arrays compare entry by entry
        assert np.array_equal(K0.indices, K1.indices) and np.array_equal(K0.indptr, K1.indptr)
        assert np.abs(K1.data - K0.data).max() <= RTOL * np.abs(K0.data).max()


@pytest.mark.parametrize("seed", [0, 1, 2])
@pytest.mark.parametrize("kind", ["neo_hookean", "linear_elastic"])
def test_numba_matches_numpy_on_random_distorted_meshes(kind, seed):
    rng = np.random.default_rng(seed)
    nodes, cells = distorted_grid(12, 7, rng)
    asm = make_assembler(nodes, cells, [MaterialGroup(kind, np.arange(len(cells)))], rng)
    x = deformed(nodes, rng, 1 / 7)
    reference, result = both_kernels(asm, nodes, x)
    assert_same(reference, result)
    assert_same(*both_kernels(asm, nodes, x, need_tangent=False))


@pytest.mark.parametrize("threads", [1, 2])
def test_mixed_groups_and_threaded_blocks_match_numpy(monkeypatch, threads):
    rng = np.random.default_rng(5)
    nodes, cells = distorted_grid(30, 20, rng)
    ne = len(cells)
    neo = rng.permutation(ne)[: ne // 2]  # scattered, unsorted element subsets
    lin = np.setdiff1d(np.arange(ne), neo)
    groups = [MaterialGroup("neo_hookean", neo), MaterialGroup("linear_elastic", lin)]
    asm = make_assembler(nodes, cells, groups, rng)
    monkeypatch.setattr(kernels_numba, "MIN_ELEMENTS_PER_THREAD", 10)  # thread small groups
    asm._numba_groups = [NumbaAssembly(g.kind, cells, g.elements, threads) for g in groups]
    assert asm._numba_groups[0].threads == min(threads, numba.get_num_threads())
    assert_same(*both_kernels(asm, nodes, deformed(nodes, rng, 1 / 20)))


def test_block_partition_blocks_share_no_node():
    rng = np.random.default_rng(3)
    _, cells = distorted_grid(40, 30, rng)
    elements = np.arange(len(cells))
    elems, starts, deferred = block_partition(cells, elements, 3)
    assert np.array_equal(np.sort(np.concatenate([elems, deferred])), elements)
    node_sets = [set(cells[elems[starts[t]:starts[t + 1]]].ravel()) for t in range(3)]
    for t in range(3):
        assert node_sets[t]  # every block has work
        for u in range(t):
            assert not node_sets[t] & node_sets[u]
    assert deferred.size < 0.1 * len(cells)  # row-ordered mesh: only seam rows are deferred


@pytest.mark.parametrize("threads", [1, 2])
def test_inverted_element_is_named_by_global_index(monkeypatch, threads):
    monkeypatch.setattr(kernels_numba, "MIN_ELEMENTS_PER_THREAD", 10)
    rng = np.random.default_rng(4)
    nodes, cells = distorted_grid(20, 10, rng, jitter=0.0)
    bad = 157  # in the second half: the second thread's block
    kernel = NumbaAssembly("neo_hookean", cells, np.arange(len(cells)), threads)
    assert kernel.threads == min(threads, numba.get_num_threads())
    lam, mu = np.ones(len(cells)), np.ones(len(cells))
    force = np.zeros(2 * len(nodes))
    x = nodes.copy()
    x[cells[bad, 2]] = x[cells[bad, 0]] - [0.01, 0.01]  # fold element `bad` over its corner
    entry_map = np.zeros(64 * len(cells), dtype=np.int64)
    with pytest.raises(InvertedElementError, match=r"element 1[45]\d .*current") as info:
        kernel.add(nodes, x - nodes, lam, mu, entry_map, force, None)
    # the moved node is shared by up to four elements: the first of them is named
    first = min(e for e in range(len(cells)) if cells[bad, 2] in cells[e])
    assert info.value.element == first and info.value.value < 0.0


def test_reference_inversion_is_reported_for_both_models():
    rng = np.random.default_rng(6)
    nodes, cells = distorted_grid(4, 3, rng, jitter=0.0)
    cells = cells.copy()
    cells[5] = cells[5, ::-1]  # clockwise element: negative reference Jacobian
    for kind in ("neo_hookean", "linear_elastic"):
        asm = make_assembler(nodes, cells, [MaterialGroup(kind, np.arange(len(cells)))], rng)
        with pytest.raises(InvertedElementError, match="element 5 .*reference"):
            asm.internal(nodes, d=np.zeros_like(nodes))


def test_the_global_element_of_a_group_is_named():
    rng = np.random.default_rng(7)
    nodes, cells = distorted_grid(4, 2, rng, jitter=0.0)
    groups = [MaterialGroup("linear_elastic", np.arange(4)), MaterialGroup("neo_hookean",
                                                                          np.arange(4, 8))]
    asm = make_assembler(nodes, cells, groups, rng)
    x = nodes.copy()
    x[cells[6, 2]] = x[cells[6, 0]] - [0.05, 0.05]  # node 2 of element 6 is in elements 6, 7
    with pytest.raises(InvertedElementError, match="element 6 .*current"):
        asm.internal(nodes, d=x - nodes)


def numba_internal(asm, X, x, need_tangent=True):
    """The Numba path's force, CSR data and energy at positions x."""
    f, K, W = asm.internal(X, d=x - X, need_tangent=need_tangent)
    return f, None if K is None else K.data, W


def assert_identical(a, b):
    for u, v in zip(a, b, strict=True):
        assert (u is None and v is None) or np.array_equal(u, v)


@pytest.mark.parametrize("threads", [1, 2])
def test_reference_cache_follows_x_moved_in_place(monkeypatch, threads):
    """The cached dN/dX are recomputed for the elements whose nodes moved, even when X is the
    same array modified in place, and the results are those of a fresh kernel bit for bit."""
    monkeypatch.setattr(kernels_numba, "MIN_ELEMENTS_PER_THREAD", 10)
    rng = np.random.default_rng(8)
    nodes, cells = distorted_grid(30, 20, rng)
    ne = len(cells)
    neo = rng.permutation(ne)[: ne // 2]
    groups = [MaterialGroup("neo_hookean", neo),
              MaterialGroup("linear_elastic", np.setdiff1d(np.arange(ne), neo))]
    asm = make_assembler(nodes, cells, groups, rng)

    def fresh(X, x, need_tangent=True):
        asm.__dict__.pop("_numba_groups", None)
        asm._numba_groups = [NumbaAssembly(g.kind, cells, g.elements, threads) for g in groups]
        return numba_internal(asm, X, x, need_tangent)

    X = nodes.copy()
    x = deformed(nodes, rng, 1 / 20)
    first = fresh(X, x)
    assert_identical(numba_internal(asm, X, x), first)  # from the cache
    assert_identical(numba_internal(asm, X.copy(), x), first)  # equal values, other array
    moved = rng.random(len(X)) < 0.1
    X[moved] += 0.01 / 20 * rng.standard_normal((moved.sum(), 2))  # in place, as ALE does
    for need_tangent in (False, True):
        result = numba_internal(asm, X, x, need_tangent)
        expected = fresh(X, x, need_tangent)
        assert_identical(result, expected)
        assert not np.array_equal(result[0], first[0])  # a stale cache would give `first`
        numba_internal(asm, X, x, need_tangent)
    assert_identical(numba_internal(asm, nodes, x), first)  # moved back


def test_cached_kernel_still_matches_numpy():
    rng = np.random.default_rng(9)
    nodes, cells = distorted_grid(12, 7, rng)
    asm = make_assembler(nodes, cells, [MaterialGroup("neo_hookean", np.arange(len(cells)))],
                         rng)
    for step in range(3):  # the reference moves between calls (ALE): cache refreshed each time
        X = nodes + 0.01 / 7 * step * rng.standard_normal(nodes.shape)
        x = deformed(X, rng, 1 / 7)
        for _ in range(2):  # second call from the cache
            assert_same(*both_kernels(asm, X, x))


def test_reference_inversion_after_cached_calls_and_recovery():
    """An element whose X is moved in place until it inverts is reported (its cached data are
    not used), and once X is restored the results are those of the first call again."""
    rng = np.random.default_rng(10)
    nodes, cells = distorted_grid(6, 4, rng, jitter=0.0)
    asm = make_assembler(nodes, cells, [MaterialGroup("neo_hookean", np.arange(len(cells)))],
                         rng)
    X = nodes.copy()
    x = deformed(nodes, rng, 1 / 4)
    first = numba_internal(asm, X, x)
    n0, n2 = cells[9, 0], cells[9, 2]
    X[n2] = nodes[n0] - 0.3 * (nodes[n2] - nodes[n0])  # element 9 folded over its corner 0
    for _ in range(2):  # the failed element must not be taken from the cache the second time
        with pytest.raises(InvertedElementError, match=r"element \d+ .*reference"):
            asm.internal(X, d=np.zeros_like(X))
    X[n2] = nodes[n2]
    assert_identical(numba_internal(asm, X, x), first)


def test_current_inversion_reported_before_a_later_reference_one():
    """Gauss points are checked in order: det F failing at an earlier point than a
    non-convex reference element's det J names the current configuration, as before caching."""
    nodes = np.array([[0.0, 0.0], [1.0, 0.0], [0.2, 0.2], [0.0, 1.0]])  # re-entrant corner 2
    asm = Assembler(np.array([[0, 1, 2, 3]]), 4, [MaterialGroup("neo_hookean", np.arange(1))],
                    np.ones(1), np.ones(1), np.ones(1))
    with pytest.raises(InvertedElementError, match="element 0 .*reference"):
        asm.internal(nodes, d=np.zeros_like(nodes))
    x = nodes[[0, 3, 2, 1]]  # mirrored: det F < 0 wherever det J > 0
    with pytest.raises(InvertedElementError, match="element 0 .*current"):
        asm.internal(nodes, d=x - nodes)


@pytest.mark.parametrize("kind", ["linear_elastic", "neo_hookean"])
def test_force_round_off_is_relative_to_the_stress_not_to_the_positions(kind):
    """A stiff body (block sliding's E = 1e10 foundation) far from the origin, strained 1e-8:
    the kernel forms F = I + Grad d from the displacements, so moving the body by c changes
    its force only through the rounding of dN/dX (~eps c / h relative). From positions x of
    size c, F - I would carry eps c / h absolutely: 2e-5 of this force, measured 5e-5 of 3600
    in block sliding's reactions before the change."""
    rng = np.random.default_rng(11)
    nodes, cells = distorted_grid(12, 7, rng)
    ne = len(cells)
    asm = Assembler(cells, len(nodes), [MaterialGroup(kind, np.arange(ne))],
                    np.full(ne, 0.3e10), np.full(ne, 0.4e10), np.ones(ne))
    d = 1e-8 * (deformed(nodes, rng, 1 / 7) - nodes)
    f0, K0, W0 = asm.internal(nodes, d=d)
    c, h = 1000.0, 1.0 / 7.0
    f1, K1, W1 = asm.internal(nodes + c, d=d)
    tolerance = 100.0 * np.finfo(float).eps * c / h
    assert np.abs(f1 - f0).max() <= tolerance * np.abs(f0).max()
    assert np.abs(K1.data - K0.data).max() <= tolerance * np.abs(K0.data).max()
    assert abs(W1 - W0) <= tolerance * W0
