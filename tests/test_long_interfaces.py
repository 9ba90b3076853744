"""Long contact surfaces (10^3-10^4 nodes, pavement layers and sliding joints): the ALE surface
move (``ale.surface.slide_chain``) and the build's overlap check
(``mesh.overlap.distance_to_segments``) give the answers of the all-pairs searches they
replaced, written here as oracles, and their cost grows about linearly with the surface (both
were n^2: 721 ms a call on a 4,020-node chain, 34 s of the build at 8,000 touching nodes)."""

import time

import numpy as np
import pytest

from ntncontact.ale import surface
from ntncontact.ale.surface import SurfaceCurve, slide_chain
from ntncontact.mesh.boundary import boundary_edges
from ntncontact.mesh.generators import rectangle
from ntncontact.mesh.overlap import deepest_overlap, distance_to_segments


def _cpu_time(f, *args, repeats=3) -> float:
    """The least CPU time of a few calls (the machine may be shared: wall time is noise)."""
    f(*args)  # compiled, caches warm
    best = np.inf
    for _ in range(repeats):
        start = time.process_time()
        f(*args)
        best = min(best, time.process_time() - start)
    return best


# --- the ALE surface move ---------------------------------------------------------------------


def _nearest_oracle(curve: SurfaceCurve, pts: np.ndarray, keep: int) -> np.ndarray:
    """Every segment's closest of 9 samples, a stable sort (the kernel's former all-pairs loop,
    with its operations in the same order)."""
    p, q = curve.points, curve.bulge
    u = np.arange(9) / 8.0
    w = u * (u - 1.0)
    d = p[1:] - p[:-1]
    x0 = p[:-1, 0, None] + u * d[:, 0, None] + w * q[:, 0, None]  # (segments, 9)
    x1 = p[:-1, 1, None] + u * d[:, 1, None] + w * q[:, 1, None]
    r0 = x0[None] - pts[:, 0, None, None]
    r1 = x1[None] - pts[:, 1, None, None]
    near = np.sqrt(r0 * r0 + r1 * r1).min(axis=2)
    return np.argsort(near, axis=1, kind="stable")[:, :keep]


def _folded_chain(n: int, corner_every: int) -> tuple[np.ndarray, np.ndarray]:
    """A wavy chain that runs out and back (a U: segments far apart along the chain lie
    side by side), with a corner every ``corner_every`` nodes."""
    half = n // 2
    s = np.linspace(0.0, 1.0, half)
    out = np.c_[10.0 * s, 0.05 * np.sin(40.0 * s)]
    back = np.c_[10.0 * s[::-1], 0.7 + 0.05 * np.cos(33.0 * s[::-1])]
    xy = np.vstack([out, [[10.4, 0.35]], back])
    corners = np.zeros(len(xy), bool)
    corners[::corner_every] = True
    return xy, corners


@pytest.mark.parametrize("corner_every", [7, 10**6])
def test_the_nearest_segments_are_those_of_the_all_pairs_search(corner_every):
    """Points near and far, on the nodes (where two segments tie: the lower index first), between
    the two legs of the U and beyond the ends: the same 3 segments in the same order."""
    xy, corners = _folded_chain(400, corner_every)
    curve = SurfaceCurve.from_chain(xy, corners)
    rng = np.random.default_rng(7)
    pts = np.vstack([xy, xy[::3] + rng.normal(scale=0.02, size=(len(xy[::3]), 2)),
                     np.c_[rng.uniform(-2.0, 13.0, 300), rng.uniform(-1.0, 2.0, 300)],
                     [[5.0, 0.35], [-50.0, 0.0], [1e6, -1e6]]])
    got = surface._nearest_segments(curve.points, curve.bulge, pts, 3)
    np.testing.assert_array_equal(got, _nearest_oracle(curve, pts, 3))


def test_a_point_that_is_not_finite_is_left_to_the_plain_order():
    xy, corners = _folded_chain(40, 5)
    curve = SurfaceCurve.from_chain(xy, corners)
    pts = np.array([[np.nan, 0.0], [np.inf, 1.0], [1.0, 0.0]])
    got = surface._nearest_segments(curve.points, curve.bulge, pts, 3)
    np.testing.assert_array_equal(got, _nearest_oracle(curve, pts, 3))


def test_the_gap_to_the_nearest_break_is_the_least_of_all():
    rng = np.random.default_rng(3)
    at = np.sort(np.r_[rng.uniform(0.0, 10.0, 50), [2.0, 2.0, 0.0, 10.0]])
    for s in np.r_[rng.uniform(-1.0, 11.0, 200), at, [2.0]]:
        assert surface._gap_to_sorted(at, s) == np.abs(s - at).min()
    assert np.isnan(surface._gap_to_sorted(at, np.nan))


def _stretch_clamp_oracle(node_s, brk, pos, spacing, stretch, snap, targets, clamped):
    """The clamp's former loop over every active node per run between breaks."""
    cum = np.r_[0.0, np.cumsum(spacing)]
    for r in range(brk.size - 1):
        b0, b1 = brk[r], brk[r + 1]
        scale = stretch * (node_s[b1] - node_s[b0]) / (cum[b1] - cum[b0])
        inside = [i for i in range(pos.size) if b0 < pos[i] < b1]
        if not inside:
            continue
        first = min(inside, key=lambda i: pos[i])
        last = max(inside, key=lambda i: pos[i])
        hi = max(node_s[b0] + scale * (cum[pos[first]] - cum[b0]), node_s[pos[first]])
        if targets[first] > hi:
            clamped[first] = clamped[first] or targets[first] - hi > snap
            targets[first] = hi
        lo = min(node_s[b1] - scale * (cum[b1] - cum[pos[last]]), node_s[pos[last]])
        if targets[last] < lo:
            clamped[last] = clamped[last] or lo - targets[last] > snap
            targets[last] = lo


def test_the_stretch_clamp_bounds_the_same_nodes_as_the_run_by_run_search():
    rng = np.random.default_rng(11)
    node_s = np.cumsum(np.r_[0.0, rng.uniform(0.5, 1.5, 199)])
    spacing = np.full(199, 1.0)
    brk = np.r_[0, np.sort(rng.choice(np.arange(1, 199), 15, replace=False)), 199]
    pos = rng.permutation(np.arange(200))[:120]  # some on breaks, in no order
    targets = node_s[pos] + rng.normal(scale=30.0, size=pos.size)
    expected_t, expected_c = targets.copy(), np.zeros(pos.size, bool)
    _stretch_clamp_oracle(node_s, brk, pos, spacing, 1.3, 1e-9, expected_t, expected_c)
    got_t, got_c = targets.copy(), np.zeros(pos.size, bool)
    surface._stretch_clamp(node_s, brk, pos, spacing, 1.3, 1e-9, got_t, got_c)
    assert not np.array_equal(expected_t, targets)  # the clamp acted
    np.testing.assert_array_equal(got_t, expected_t)
    np.testing.assert_array_equal(got_c, expected_c)


def _slide_arguments(n: int) -> tuple:
    """``slide_chain``'s arguments for a wavy n-node chain with a corner every 50 nodes, every
    other node following a wanted point 0.3 segments ahead (as ``ale.motion`` passes them)."""
    x = np.linspace(0.0, n, n)
    xy = np.c_[x, 0.1 * np.sin(0.05 * x)]
    corners = np.zeros(n, bool)
    corners[::50] = True
    curve = SurfaceCurve.from_chain(xy, corners)
    t_start, t_end = curve.tangents
    pos = np.flatnonzero(~curve.breaks)
    wanted = xy[pos] + [0.3, 0.0]
    return (xy.copy(), np.arange(n), curve.points, curve.bulge, curve.node_s, t_start, t_end,
            curve.breaks, np.diff(curve.node_s), wanted, pos, 1e-8, 0.25, 1e-10, 0.5, 2.0,
            True, 1e-10, 2.0)


def test_the_surface_move_costs_about_linearly_in_the_chain_nodes():
    """8x the nodes cost 64x before (the nearest segments searched among all, and every break
    scanned per active node); now about 8x (n log n)."""
    small, large = _slide_arguments(1000), _slide_arguments(8000)
    out = slide_chain(*large)
    assert out[6] == -1 and np.abs(out[1]).max() > 0.1  # a real move: the nodes slid
    ratio = _cpu_time(slide_chain, *large) / _cpu_time(slide_chain, *small)
    assert ratio < 24.0, f"8x the chain nodes cost {ratio:.1f}x"


# --- the build's overlap check ----------------------------------------------------------------


def _distance_oracle(points: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Every point against every segment (the check's former form, in chunks)."""
    ab = b - a
    out = np.empty(len(points))
    for start in range(0, len(points), 256):
        rel = points[start:start + 256, None, :] - a[None]
        t = np.clip(np.sum(rel * ab, axis=-1) / np.maximum(np.sum(ab * ab, axis=-1), 1e-300),
                    0.0, 1.0)
        gap = rel - t[..., None] * ab[None]
        out[start:start + 256] = np.sqrt(np.min(np.sum(gap * gap, axis=-1), axis=1))
    return out


def test_the_distances_to_segments_are_those_of_the_all_pairs_search():
    """3,000 points on and around a 3,000-segment wavy outline with short and long (and one
    degenerate) segments: the same distances to the bit."""
    rng = np.random.default_rng(5)
    x = np.sort(np.r_[rng.uniform(0.0, 3000.0, 1499), 0.0, 3000.0])
    top = np.c_[x, 0.01 * np.sin(x)]
    outline = np.vstack([top, top[::-1] + [0.0, -4.0]])
    a, b = outline[:-1], outline[1:]
    a = np.vstack([a, [[7.0, -2.0]]])
    b = np.vstack([b, [[7.0, -2.0]]])  # a point as a segment
    pts = np.vstack([top[:1000], np.c_[rng.uniform(-5.0, 3005.0, 2000),
                                       rng.uniform(-10.0, 6.0, 2000)],
                     [[1e5, 1e5], [7.0, -2.0]]])
    np.testing.assert_array_equal(distance_to_segments(pts, a, b), _distance_oracle(pts, a, b))
    bad = distance_to_segments(np.array([[np.nan, 0.0], [1.0, 1.0]]), a, b)
    assert np.isnan(bad[0]) and bad[1] == _distance_oracle(np.array([[1.0, 1.0]]), a, b)[0]


@pytest.mark.parametrize("sink", [0.0, 0.05])
def test_a_long_layer_on_its_base_gets_the_verdict_of_the_all_pairs_search(sink):
    """A 3,000-element layer on a 3,000-element base (every surface node inside within the
    tolerance): touching builds; one node pushed 0.05 in is found, as deep as the oracle says."""
    n = 3000
    base = rectangle(float(n), 2.0, n, 2)
    layer_nodes = rectangle(float(n), 2.0, n, 2).nodes + [0.0, 2.0]
    bottom = np.flatnonzero(np.isclose(layer_nodes[:, 1], 2.0))
    bottom = bottom[np.argsort(layer_nodes[bottom, 0])]  # the layer on the left: left to right
    chain = layer_nodes[bottom].copy()
    chain[1234, 1] -= sink
    found = deepest_overlap(chain, base.nodes, base.cells, chain=True)
    if sink == 0.0:
        assert found is None
        return
    edges = boundary_edges(base.cells)  # the oracle's depths: to every boundary edge
    depth = _distance_oracle(chain, base.nodes[edges[:, 0]], base.nodes[edges[:, 1]])
    assert found is not None and found.point == int(np.argmax(depth)) == 1234
    assert found.depth == depth[1234] == pytest.approx(sink)


def test_the_distances_cost_about_linearly_in_the_surface():
    """8x the points and segments cost 64x before (every pair); now about 8x."""
    def case(n):
        x = np.linspace(0.0, n, n + 1)
        edge = np.c_[x, 1e-3 * np.sin(x)]
        return edge[:-1] + [0.25, 1e-9], edge[:-1], edge[1:]
    ratio = _cpu_time(distance_to_segments, *case(8000)) / _cpu_time(
        distance_to_segments, *case(1000))
    assert ratio < 24.0, f"8x the surface cost {ratio:.1f}x"
