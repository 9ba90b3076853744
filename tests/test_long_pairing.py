"""Pairing on long interfaces (10^3-10^4 contact nodes): the ordered partners' admissible pairs,
their order-preserving DP and the closest segments give the answers of the all-pairs searches
they replaced, written here as oracles, and ``ordered_partners`` costs about linearly in the
surface (it was n^2: 2.2 s at 4,000 surface nodes, 0.11 s at 1,000)."""

import time

import numpy as np
import pytest

from ntncontact.contact import pairing
from ntncontact.contact.pairing import MIN_MATCHED_SPACING, closest_pairs, ordered_partners
from ntncontact.contact.surfaces import ContactSurface, Interface


def _cpu_time(f, *args, repeats=3, **kwargs) -> float:
    """The least CPU time of a few calls (the machine may be shared: wall time is noise)."""
    f(*args, **kwargs)
    best = np.inf
    for _ in range(repeats):
        start = time.process_time()
        f(*args, **kwargs)
        best = min(best, time.process_time() - start)
    return best


def _layer(n: int, seed: int = 0, wavy: bool = True) -> tuple[np.ndarray, Interface]:
    """A layer's bottom of n nodes (spacing 1, a little uneven, pressed up to 2e-3 into the
    surface) over a longer base top of 1.3 n nodes (finer, wavy): surface 1 runs right to left."""
    rng = np.random.default_rng(seed)
    m = int(1.3 * n)
    base_x = np.linspace(0.0, n + 10.0, m) + 0.1 * rng.random(m) * (n + 10.0) / m
    base_x.sort()
    base_y = 0.05 * np.sin(0.3 * base_x) if wavy else np.zeros(m)
    top_x = 5.0 + np.arange(n)[::-1] + 0.2 * rng.random(n)
    top_y = (0.05 * np.sin(0.3 * top_x) if wavy else 0.0) - 2e-3 * rng.random(n)
    x = np.vstack([np.column_stack([top_x, top_y]), np.column_stack([base_x, base_y])])
    return x, Interface(ContactSurface(np.arange(n)), ContactSurface(n + np.arange(m)))


# --- oracles: the former all-pairs forms --------------------------------------------------------


def _admissible_oracle(x, interface, node1, taken, kept, s2, depth=None):
    """Every candidate against every surface-2 node (the former C x S form)."""
    s1 = interface.surface1
    reach1 = np.zeros(len(x))
    reach1[s1.nodes] = pairing._longest_adjacent_segment(x, s1)
    reach2 = pairing._longest_adjacent_segment(x, interface.surface2)
    dist = np.linalg.norm(x[node1][:, None, :] - x[s2][None, :, :], axis=2)
    if depth is not None:
        dist = np.maximum(dist - np.asarray(depth, dtype=float)[:, None], 0.0)
    reach = np.maximum(reach1[node1][:, None], reach2[None, :])
    busy = np.isin(s2, np.concatenate([np.asarray(taken, np.int64).reshape(-1), kept[:, 1]]))
    cand, j = np.nonzero((dist <= reach) & ~busy[None, :])
    closeness = 1.0 - dist[cand, j] / reach[cand, j]
    return cand, j, 1.0 + closeness / (node1.size + 1.0)


def _interval_oracle(pairs, along, arc, j, cand, weight, left, right):
    """The DP with every earlier pair tested for every pair (the former form)."""

    def spaced(a_along, a_arc, b_along, b_arc):
        with np.errstate(invalid="ignore"):
            return ~(b_along - a_along < MIN_MATCHED_SPACING * (b_arc - a_arc))

    pairs = pairs[np.lexsort((j[pairs], along[pairs]))]
    p_along, p_arc, p_j, p_cand = along[pairs], arc[pairs], j[pairs], cand[pairs]
    best = np.where(spaced(left[0], left[1], p_along, p_arc), weight[pairs], -np.inf)
    back = np.full(pairs.size, -1, dtype=np.int64)
    for q in range(pairs.size):
        prev = np.flatnonzero((p_cand[:q] != p_cand[q]) & (p_j[:q] < p_j[q])
                              & (p_along[:q] < p_along[q])
                              & spaced(p_along[:q], p_arc[:q], p_along[q], p_arc[q]))
        if prev.size:
            k = prev[np.argmax(best[prev])]
            if best[k] + weight[pairs[q]] > best[q]:
                best[q], back[q] = best[k] + weight[pairs[q]], k
    best[~spaced(p_along, p_arc, right[0], right[1])] = -np.inf
    if not np.any(best > 0.0):
        return []
    q, out = int(np.argmax(best)), []
    while q >= 0:
        out.append(int(pairs[q]))
        q = int(back[q])
    return out


def _best_matching_oracle(along, arc2, spacing_arc, cand, j, weight, kept_along, kept_j):
    """Every pair tested against every kept pair's interval (the former form)."""
    order = np.argsort(kept_j)
    bounds_j = np.concatenate([[-1], kept_j[order], [arc2.size]])
    bounds_along = np.concatenate([[-np.inf], kept_along[order], [np.inf]])
    bounds_arc = np.concatenate([[-np.inf], spacing_arc[kept_j[order]], [np.inf]])
    picks = []
    for k in range(bounds_j.size - 1):
        inside = np.flatnonzero((j > bounds_j[k]) & (j < bounds_j[k + 1])
                                & (along[cand] > bounds_along[k])
                                & (along[cand] < bounds_along[k + 1]))
        if inside.size:
            picks += _interval_oracle(inside, along[cand], spacing_arc[j], j, cand, weight,
                                      (bounds_along[k], bounds_arc[k]),
                                      (bounds_along[k + 1], bounds_arc[k + 1]))
    return np.asarray(picks, dtype=np.int64)


def _closest_segment_oracle(q, a, b):
    """Every query against every segment; the nearest, then the lowest segment."""
    ab = b - a
    rel = q[:, None, :] - a[None, :, :]
    xi = np.clip(np.einsum("csi,si->cs", rel, ab) / np.einsum("si,si->s", ab, ab), 0.0, 1.0)
    dist = np.linalg.norm(q[:, None, :] - (a[None] + xi[..., None] * ab[None]), axis=2)
    seg = np.argmin(dist, axis=1)
    rows = np.arange(len(q))
    return seg, xi[rows, seg], dist[rows, seg]


# --- the same answers -------------------------------------------------------------------------


def _kept(x, interface, every):
    """Every ``every``-th candidate's distinct nearest partner, kept."""
    return closest_pairs(x, interface, unique=True).pairs[::every]


@pytest.mark.parametrize("n, every", [(30, 3), (2500, 1000000), (2500, 2)])
def test_the_admissible_pairs_are_those_of_the_all_pairs_search(n, every):
    x, interface = _layer(n, seed=n + every)
    kept = _kept(x, interface, every) if every < n else np.zeros((0, 2), np.int64)
    node1 = np.setdiff1d(interface.surface1.nodes, kept[:, 0])
    s2 = interface.surface2.nodes
    depth = np.maximum(closest_pairs(x, interface, node1).projection_gap, 0.0)
    taken = s2[::17]
    for d in (None, depth):
        got = pairing._admissible_pairs(x, interface, node1, taken, kept, s2, d)
        want = _admissible_oracle(x, interface, node1, taken, kept, s2, d)
        assert want[0].size > node1.size  # a few per candidate
        for g, w in zip(got, want, strict=True):
            assert g.dtype == w.dtype and np.array_equal(g, w)


def _matching_arguments(x, interface, kept, shift=0.0):
    """The arguments ``ordered_partners`` gives ``_best_matching``; the spacing arc measured
    on surface 2 stretched by ``shift`` (an ALE surface moved since the original mesh)."""
    s2 = interface.surface2.nodes
    arc2 = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(x[s2], axis=0), axis=1))])
    node1 = np.setdiff1d(interface.surface1.nodes, kept[:, 0])
    proj = closest_pairs(x, interface, candidates=np.concatenate([node1, kept[:, 0]]))
    edges2 = interface.surface2.edges()
    along = arc2[proj.segment] + proj.xi * np.linalg.norm(
        x[edges2[proj.segment, 1]] - x[edges2[proj.segment, 0]], axis=1)
    chain_index = np.full(len(x), -1, dtype=np.int64)
    chain_index[s2] = np.arange(s2.size)
    depth = np.maximum(proj.projection_gap[: node1.size], 0.0)
    cand, j, weight = pairing._admissible_pairs(x, interface, node1, (), kept, s2, depth)
    spacing_arc = arc2 * (1.0 + shift * np.sin(arc2 / 7.0) ** 2)
    return (along[: node1.size], arc2, spacing_arc, cand, j, weight, along[node1.size:],
            chain_index[kept[:, 1]])


@pytest.mark.parametrize("n, every, shift", [(40, 1000000, 0.0), (40, 3, 0.3),
                                             (2000, 1000000, 0.0), (2000, 1000000, 0.4),
                                             (2000, 3, 0.0)])
def test_the_order_preserving_matching_is_that_of_the_all_pairs_dp(n, every, shift):
    """Without kept pairs (one interval, the DP over all the pairs) and with every third
    candidate kept; on the spacing arc of the original mesh and on one 30-40 % stretched in
    places, where the spacing rule leaves pairs out."""
    x, interface = _layer(n, seed=n + every)
    kept = _kept(x, interface, every) if every < n else np.zeros((0, 2), np.int64)
    args = _matching_arguments(x, interface, kept, shift)
    got = pairing._best_matching(*args)
    want = _best_matching_oracle(*args)
    assert want.size > 0.1 * args[0].size  # a real matching (the stretch leaves out many)
    assert got.dtype == want.dtype and np.array_equal(got, want)


def test_the_dp_with_ties_and_crossings_is_that_of_the_all_pairs_dp():
    """Random pairs on a few positions and nodes (equal positions, equal weights, crossing
    orders, spacing violations): the running maximum keeps the oracle's lowest index."""
    rng = np.random.default_rng(5)
    for _ in range(200):
        p = int(rng.integers(1, 40))
        cand = rng.integers(0, 12, p)
        along = np.round(rng.random(12) * 6.0, 1)
        j = rng.integers(0, 15, p)
        arc = np.round(np.sort(rng.random(15)) * 8.0, 1)
        weight = 1.0 + np.round(rng.random(p), 1) / 13.0
        left = (-np.inf, -np.inf) if rng.random() < 0.5 else (0.5, 0.3)
        right = (np.inf, np.inf) if rng.random() < 0.5 else (5.5, 7.0)
        args = (np.arange(p), along[cand], arc[j], j, cand, weight, left, right)
        assert pairing._interval_matching(*args) == _interval_oracle(*args)


@pytest.mark.parametrize("n", [30, 3000])
def test_the_closest_segments_are_those_of_the_all_pairs_search(n):
    x, interface = _layer(n, seed=n)
    edges = interface.surface2.edges()
    a, b = x[edges[:, 0]], x[edges[:, 1]]
    q = np.vstack([x[interface.surface1.nodes], x[interface.surface2.nodes[::5]]])  # ties
    d, _ = pairing._nearest_nodes(q, x[interface.surface2.nodes])
    half = 0.5 * np.max(np.linalg.norm(b - a, axis=1))
    got = pairing._closest_on_segments(q, a, b, d + half * (1.0 + 1e-12) + 1e-300)
    for g, w in zip(got, _closest_segment_oracle(q, a, b), strict=True):
        assert np.array_equal(g, w)


# --- the cost ---------------------------------------------------------------------------------


def test_ordered_partners_cost_about_linearly_in_the_surface():
    """8x the surface (1,000 -> 8,000 nodes) cost 47x before (the admissible pairs among all
    C x S, the DP testing every earlier pair); now about 8x."""
    small, large = _layer(1000, wavy=False), _layer(8000, wavy=False)
    partners = ordered_partners(*large, large[1].surface1.nodes)
    assert np.count_nonzero(partners >= 0) > 7900  # a real matching: almost all paired
    ratio = (_cpu_time(ordered_partners, *large, large[1].surface1.nodes)
             / _cpu_time(ordered_partners, *small, small[1].surface1.nodes))
    assert ratio < 24.0, f"8x the surface nodes cost {ratio:.1f}x"
