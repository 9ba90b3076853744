"""The compiled ALE kernels (in ``ale.surface``, ``ale.remap``, ``ale.motion``,
``mesh.quality``, ``mesh_motion``) against the NumPy code they replaced, kept here as oracles,
bit for bit where NumPy's results are fixed by IEEE arithmetic: the kernels repeat its
operations in its order, so the ALE update's results did not change when they were introduced.
Where the NumPy code sums through ``np.sum`` or ``np.einsum``, the order of those sums is NumPy's
implementation detail (blocking, unrolling, memory layout), which other NumPy versions may
change: there the comparison allows the round-off of a reordered sum (:data:`REORDERED`)."""

from __future__ import annotations

import numpy as np
import pytest
from test_ale_remap import XI, q4_shape

from ntncontact.ale import remap, surface
from ntncontact.ale.motion import _element_masses, _masses_after
from ntncontact.ale.remap import Remapper, inverse_bilinear
from ntncontact.ale.surface import SurfaceCurve, local_slides
from ntncontact.engine import mesh_motion
from ntncontact.fem.q4 import DN_GP, N_GP
from ntncontact.mesh import quality
from ntncontact.mesh.generators import rectangle


def nearest_on_boundary(cell_xy, points):
    """Closest point of each cell's boundary to each point: (distance, xi, local edge)."""
    a, b = cell_xy, np.roll(cell_xy, -1, axis=-2)  # the 4 straight edges a -> b
    d = b - a
    t = np.einsum("...ei,...ei->...e", points[..., None, :] - a, d)
    t = np.clip(t / np.maximum(np.einsum("...ei,...ei->...e", d, d), 1e-300), 0.0, 1.0)
    dist = np.linalg.norm(a + t[..., None] * d - points[..., None, :], axis=-1)
    edge = np.argmin(dist, axis=-1)
    te = np.take_along_axis(t, edge[..., None], axis=-1)[..., 0]
    start, end = XI[edge], XI[(edge + 1) % 4]  # the bilinear map is linear along an edge
    return np.min(dist, axis=-1), start + te[..., None] * (end - start), edge

SNAP = 1e-10
#: Round-off of a sum of up to a few hundred terms taken in another order, relative to the
#: largest result: at most ~log2(n) eps (2e-15 for n = 300) of the sum of magnitudes, which
#: here is of the order of the results; 1e-13 leaves a margin of 50 and stays far below any
#: change an algorithmic difference (another branch, another term) would make.
REORDERED = 1e-13


def assert_equal_up_to_reordering(got, want):
    want = np.asarray(want, float)
    scale = max(float(np.abs(want).max(initial=0.0)), 1.0)
    np.testing.assert_allclose(got, want, rtol=0.0, atol=REORDERED * scale)


def reference_local_slides(s, ref, idx, slide, tolerance):
    """``ale.surface.local_slides`` as it was in NumPy (a Python loop over the runs)."""
    lo, hi = 1.0 - tolerance, 1.0 / (1.0 - tolerance)

    def slack_of(cur, target, change):
        room = cur - lo * target if change < 0.0 else hi * target - cur
        return np.maximum(room, 0.0)

    def buffer(cur, target, slide_):
        change = -slide_
        slack = slack_of(cur, target, change)
        total = np.cumsum(slack)
        enough = np.flatnonzero(total >= abs(change))
        if enough.size == 0:
            return None
        m = int(enough[0]) + 1
        return change * slack[:m] / total[m - 1]

    out = np.zeros(s.size)
    out[idx] = slide
    seg = np.diff(s)
    resets = 0
    for k in np.flatnonzero((np.diff(idx) >= 2) & ((slide[:-1] != 0.0) | (slide[1:] != 0.0))):
        a, b, sa, sb = idx[k], idx[k + 1], slide[k], slide[k + 1]
        cur, rseg = seg[a:b], ref[a:b]
        target = rseg * (cur.sum() / rseg.sum())
        head = buffer(cur, target, sa) if sa != 0.0 else np.zeros(0)
        tail = buffer(cur[::-1], target[::-1], -sb) if sb != 0.0 else np.zeros(0)
        if head is not None and tail is not None and head.size + tail.size <= b - a:
            out[a + 1:a + head.size] = sa + np.cumsum(head)[:-1]
            out[b - tail.size + 1:b] = (sb - np.cumsum(tail)[:-1])[::-1]
            continue
        change = sb - sa
        slack = slack_of(cur, target, change)
        if change == 0.0:
            out[a + 1:b] = sa
        elif slack.sum() >= abs(change):
            out[a + 1:b] = sa + change * np.cumsum(slack)[:-1] / slack.sum()
        else:
            resets += 1
            cum = np.concatenate([[0.0], np.cumsum(rseg)])
            local = s[a:b + 1] - s[a]
            out[a + 1:b] = sa + cum[1:-1] / cum[-1] * (local[-1] + change) - local[1:-1]
    return out, resets


def reference_stretch_clamp(node_s, brk, pos, spacing, stretch, targets):
    """``ale.surface._stretch_clamp`` in NumPy terms: per run between breaks, the stretch from
    each break to the nearest active node is bounded by ``stretch`` x its reference length x
    the run's mean stretch."""
    cum = np.concatenate([[0.0], np.cumsum(spacing)])
    targets = targets.copy()
    for b0, b1 in zip(brk[:-1], brk[1:], strict=True):
        scale = stretch * (node_s[b1] - node_s[b0]) / (cum[b1] - cum[b0])
        inside = np.flatnonzero((pos > b0) & (pos < b1))
        if inside.size == 0:
            continue
        first, last = inside[np.argmin(pos[inside])], inside[np.argmax(pos[inside])]
        bound = node_s[b0] + scale * (cum[pos[first]] - cum[b0])
        targets[first] = min(targets[first], max(bound, node_s[pos[first]]))
        bound = node_s[b1] - scale * (cum[b1] - cum[pos[last]])
        targets[last] = max(targets[last], min(bound, node_s[pos[last]]))
    return targets


def reference_anchor_targets(node_s, breaks, pos, wanted, slide_tolerance, ratio, spacing,
                             stretch=np.inf):
    """``ale.motion``'s NumPy clamping of the wanted arc lengths (``_clamp_slides``), the
    mismatch, the anchors and the first pair of anchors out of order (-1: none); the clamp
    keeps ``ratio`` times the stretch's smallest reference segment (``spacing``), and no
    stretch between anchors beyond ``stretch`` times its scaled reference length."""
    seg = np.diff(node_s)
    near = np.minimum(seg[np.maximum(pos - 1, 0)], seg[np.minimum(pos, seg.size - 1)])
    still = np.abs(wanted - node_s[pos]) <= slide_tolerance * near
    kept = np.where(still, node_s[pos], wanted)
    brk = np.flatnonzero(breaks)
    run_min = np.minimum.reduceat(spacing, brk[:-1])
    j = np.searchsorted(brk, pos)
    on_break = brk[np.minimum(j, brk.size - 1)] == pos
    run = np.clip(j - 1, 0, brk.size - 2)
    b0, b1 = brk[run], brk[run + 1]
    h = ratio * run_min[run]
    lo = np.minimum(node_s[b0] + (pos - b0) * h, node_s[pos])
    hi = np.maximum(node_s[b1] - (b1 - pos) * h, node_s[pos])
    targets = np.where(on_break, node_s[pos], np.clip(kept, lo, hi))
    clamped = np.abs(targets - kept) > SNAP * run_min[run]
    if stretch < np.inf:
        bounded = reference_stretch_clamp(node_s, brk, pos, spacing, stretch, targets)
        clamped |= np.abs(bounded - targets) > SNAP * run_min.min()
        targets = bounded
    mismatch = float(np.max(np.abs(wanted - targets), initial=0.0))
    anchor = breaks.copy()
    anchor[pos] = True
    idx = np.flatnonzero(anchor)
    s = node_s.copy()
    s[pos] = targets
    bad = np.flatnonzero(np.diff(s[idx]) <= 0.0)
    slide = np.zeros(node_s.size)
    slide[pos] = targets - node_s[pos]
    return targets, clamped, mismatch, idx, slide[idx], int(bad[0]) if bad.size else -1


def random_chain(rng, n):
    ref = rng.uniform(0.5, 2.0, n - 1)
    s = np.concatenate([[0.0], np.cumsum(ref * rng.uniform(0.6, 1.6, n - 1))])
    return s, ref


@pytest.mark.parametrize("seed", range(6))
def test_local_slides_equal_the_numpy_loop_up_to_the_order_of_sums(seed):
    rng = np.random.default_rng(seed)
    for n in (3, 8, 12, 41, 300):  # runs above 8 and 128 segments: NumPy's pairwise sums
        s, ref = random_chain(rng, n)
        for _ in range(20):
            inner = np.sort(rng.choice(np.arange(1, n - 1), rng.integers(0, min(4, n - 2) + 1),
                                       replace=False))
            idx = np.concatenate([[0], inner, [n - 1]])
            scale = rng.choice([0.05, 0.5, 3.0, 30.0])
            slide = np.where(rng.uniform(size=idx.size) < 0.3, 0.0,
                             scale * rng.standard_normal(idx.size))
            slide[[0, -1]] = 0.0
            if rng.uniform() < 0.2 and idx.size > 3:
                slide[2] = slide[1]  # equal slides (rigid shift of a run)
            tolerance = rng.choice([0.2, 0.5, 0.9])
            got, resets = local_slides(s, ref, idx, slide, tolerance)
            want, want_resets = reference_local_slides(s, ref, idx, slide, tolerance)
            assert_equal_up_to_reordering(got, want)  # np.cumsum / np.sum in the oracle
            assert resets == want_resets


@pytest.mark.parametrize("seed", range(6))
def test_anchor_targets_equal_the_numpy_clamping_bit_for_bit(seed):
    rng = np.random.default_rng(100 + seed)
    for n in (4, 12, 41):
        s, ref = random_chain(rng, n)
        for _ in range(30):
            breaks = rng.uniform(size=n) < 0.15
            breaks[[0, -1]] = True
            pos = rng.choice(n, rng.integers(1, min(5, n) + 1), replace=False)
            wanted = s[pos] + rng.choice([1e-12, 0.1, 1.0, 5.0]) * rng.standard_normal(pos.size)
            ratio = rng.choice([0.1, 0.25, 0.6])
            stretch = rng.choice([np.inf, 1.2, 2.0, 4.0])
            got = surface._anchor_targets(s, breaks, pos, wanted, 1e-8, ratio, SNAP, ref,
                                          stretch)
            want = reference_anchor_targets(s, breaks, pos, wanted, 1e-8, ratio, ref, stretch)
            for g, w in zip(got, want, strict=True):
                np.testing.assert_array_equal(g, w)


@pytest.mark.parametrize("n", [0, 1, 7, 8, 9, 100, 128, 129, 300, 1000, 4099])
def test_pairwise_sum_is_accurate_like_numpys(n):
    """Within the pairwise summation's error bound, (log2(n) + 1) eps sum |a|, of the exact sum
    (math.fsum), as NumPy's sum is (whose exact order is NumPy's own business)."""
    import math

    rng = np.random.default_rng(n)
    a = rng.standard_normal(n) * 10.0 ** rng.uniform(-6, 6, n)
    for lo, size in ((0, n), (2, n - 5)):
        if size <= 0:
            continue
        part = a[lo:lo + size]
        bound = (np.log2(max(size, 1)) + 1.0) * np.finfo(float).eps * np.abs(part).sum()
        exact = math.fsum(part)
        assert abs(surface._pairwise_sum(a, lo, size) - exact) <= bound
        assert abs(part.sum() - exact) <= bound


def reference_try_hints(remapper, pts, hint, outside_tol):
    """The hinted location of ``Remapper.locate`` as it was in NumPy: (cell or -1, xi, clamped)."""
    n = len(pts)
    cell, xi, clamped = np.full(n, -1), np.zeros((n, 2)), np.zeros(n, bool)
    idx = np.flatnonzero(hint >= 0)
    h = hint[idx]
    cell_xy, size = remapper._cell_xy, remapper.cell_size
    found, res = inverse_bilinear(cell_xy[h], pts[idx])
    inside = (np.max(np.abs(found), axis=-1) <= 1.0 + 1e-9) & (res <= 1e-9 * size[h])
    cell[idx[inside]], xi[idx[inside]] = h[inside], found[inside]
    rest, h = idx[~inside], h[~inside]
    if rest.size:
        dist, bxi, edge = nearest_on_boundary(cell_xy[h], pts[rest])
        a, b = cell_xy[h, edge], cell_xy[h, (edge + 1) % 4]
        rel = pts[rest] - a
        outward = (b - a)[:, 0] * rel[:, 1] - (b - a)[:, 1] * rel[:, 0] < 0.0
        out = remapper._outer_edge[h, edge] & outward & (dist <= outside_tol * size[h])
        cell[rest[out]], xi[rest[out]], clamped[rest[out]] = h[out], bxi[out], True
    return cell, xi, clamped


def reference_interpolation(remapper, f2, loc, pts, g):
    """``Remapper.remap``'s NumPy einsums (before the ``same node`` snapping)."""
    nodes = remapper.cells[loc.cell]
    shape = q4_shape(loc.xi)
    out = np.einsum("pa,pak->pk", shape, f2[nodes])
    if g is not None:
        rel = pts[:, None, :] - remapper.nodes[nodes]
        out += 0.5 * np.einsum("pa,paki,pai->pk", shape, g, rel)
        off = pts - np.einsum("pa,pai->pi", shape, remapper.nodes[nodes])
        out += 0.5 * np.einsum("pa,paki,pi->pk", shape, g, off)
    return out


def distorted_block(rng, nx=8, ny=5):
    mesh = rectangle(2.0, 1.0, nx, ny)
    nodes = mesh.nodes + 0.2 * rng.uniform(-1, 1, mesh.nodes.shape) / max(nx, ny)
    return nodes, mesh.cells


@pytest.mark.parametrize("seed", range(4))
def test_hinted_location_and_interpolation_equal_the_numpy_code(seed):
    rng = np.random.default_rng(200 + seed)
    nodes, cells = distorted_block(rng)
    remapper = Remapper(nodes, cells)
    fields = rng.standard_normal((len(nodes), 6))
    node_cell = np.full(len(nodes), -1)
    node_cell[cells.ravel()] = np.repeat(np.arange(len(cells)), 4)
    for p in (1, 3, 7, 20):
        base = rng.choice(len(nodes), p, replace=False)
        # moved nodes: inside their hint cell, in a neighbour, or pushed off the boundary
        pts = nodes[base] + rng.choice([1e-3, 0.05, 0.2]) * rng.standard_normal((p, 2))
        hint = np.where(rng.uniform(size=p) < 0.2, -1, node_cell[base])
        got = remap._locate_in_hints(remapper._cell_xy, remapper.cell_size,
                                     remapper._outer_edge, pts, hint, 0.1, 1e-9, 12)
        for g, w in zip(got, reference_try_hints(remapper, pts, hint, 0.1), strict=True):
            np.testing.assert_array_equal(g, w)
        loc = remapper.locate(pts, 10.0, hint)
        # C-contiguous, as the ALE update's (``LazyGradients``): NumPy's einsum sums in an
        # order that depends on the operands' memory layout
        grads = remapper.nodal_gradients(fields, np.arange(len(nodes)))
        grads = np.ascontiguousarray(grads[remapper.cells[loc.cell]])
        for g in (None, grads):
            got = remap._interpolate(remapper.nodes, remapper.cells, fields, loc.cell, loc.xi,
                                      pts, np.zeros((p, 4, 6, 2)) if g is None else g,
                                      g is not None)
            # the oracle sums through np.einsum, in an order of NumPy's choosing
            assert_equal_up_to_reordering(got, reference_interpolation(remapper, fields, loc,
                                                                       pts, g))


@pytest.mark.parametrize("seed", range(4))
def test_snapping_to_the_located_cells_corners_equals_the_node_tree_query(seed):
    """``interpolate_at_nodes`` (unmoved nodes keep their values: the corners of the located
    cell are searched) against the k-d tree query over all nodes it replaced."""
    from scipy.spatial import cKDTree

    rng = np.random.default_rng(300 + seed)
    nodes, cells = distorted_block(rng)
    remapper = Remapper(nodes, cells)
    fields = rng.standard_normal((len(nodes), 6))
    grads = remapper.nodal_gradients(fields, np.arange(len(nodes)))
    # points on nodes (interior and boundary), a round-off away from them, and elsewhere
    base = rng.choice(len(nodes), 12, replace=False)
    pts = nodes[base] + np.repeat([0.0, 1e-15, 1e-6, 0.05], 3)[:, None] * rng.standard_normal(
        (12, 2))
    loc = remapper.locate(pts, 10.0)
    g = np.ascontiguousarray(grads[remapper.cells[loc.cell]])
    for quadratic in (False, True):
        want = remap._interpolate(remapper.nodes, remapper.cells, fields, loc.cell, loc.xi, pts,
                                   g, quadratic)
        dist, node = cKDTree(nodes).query(pts)
        same = dist <= 1e-12 * remapper.cell_size[loc.cell]
        want[same] = fields[node[same]]
        got = remap._interpolate_at_nodes(remapper.nodes, remapper.cells, fields, loc.cell,
                                           loc.xi, pts, g, quadratic, remapper.cell_size, 1e-12)
        assert same[:6].all() and not same[6:].any()
        np.testing.assert_array_equal(got, want)


@pytest.mark.parametrize("seed", range(4))
def test_masses_after_equals_the_numpy_update_bit_for_bit(seed):
    rng = np.random.default_rng(400 + seed)
    X, cells = distorted_block(rng)
    density = rng.uniform(1.0, 3.0, len(cells))
    old = _element_masses(X, cells, np.arange(len(cells)), density, DN_GP, N_GP)
    masses = np.bincount(cells.ravel(), old.ravel(), len(X))
    idx = np.sort(rng.choice(len(cells), 7, replace=False))
    X_new = X + 0.01 * rng.standard_normal(X.shape)
    change = _element_masses(X_new, cells, idx, density[idx], DN_GP, N_GP)
    change -= old[idx]
    want = masses + np.bincount(cells[idx].ravel(), change.ravel(), len(X))
    got = _masses_after(X_new, cells, idx, density, DN_GP, N_GP, old, masses)
    np.testing.assert_array_equal(got, want)


def reference_min_sines(nodes, cells):
    """``mesh.quality.cell_min_sines`` as it was in NumPy."""
    x = nodes[cells]
    a, b = np.roll(x, -1, axis=1) - x, np.roll(x, 1, axis=1) - x
    cross = a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]
    scale = np.sqrt(np.einsum("...i,...i->...", a, a) * np.einsum("...i,...i->...", b, b))
    sines = np.divide(cross, scale, out=np.full_like(cross, -1.0), where=scale > 0)
    return sines.min(axis=1)


def test_changed_cells_and_their_acceptance_equal_the_numpy_expressions():
    rng = np.random.default_rng(5)
    x, cells = distorted_block(rng)
    reference = reference_min_sines(x, cells)
    np.testing.assert_array_equal(quality.cell_min_sines(x, cells), reference)
    tn = reference_min_sines(x + 0.01 * rng.standard_normal(x.shape), cells)
    for scale in (0.0, 1e-3, 0.05, 0.3):
        x_new = x.copy()
        x_new[[3, 17]] += scale * rng.standard_normal((2, 2))
        q = reference_min_sines(x_new, cells)
        moved = np.any(x_new != x, axis=1)
        touched = np.flatnonzero(moved[cells].any(axis=1))
        for min_q in (0.5, 0.9, 1.0):
            got = quality.changed_cells(x_new, x, cells, min_q, reference, tn, 0.3)
            np.testing.assert_array_equal(got[0], moved)
            np.testing.assert_array_equal(got[1], touched)
            floor = np.minimum(min_q * reference, tn)[touched]
            assert got[2] == bool(np.all(q[touched] >= floor))
            assert got[3] == bool(np.any(q[touched] <= 0.3))


def reference_body_pairs(pairs_list, lo, hi):
    """``mesh_motion._ale_nodes_and_partners`` as it was in NumPy."""
    own, partner = [], []
    for pairs in pairs_list:
        for side in (1, 0):
            nodes = pairs[:, side]
            mine = (nodes >= lo) & (nodes < hi)
            own.append(nodes[mine])
            partner.append(pairs[mine, 1 - side])
    own, partner = np.concatenate(own), np.concatenate(partner)
    _, first = np.unique(own, return_index=True)
    return own[np.sort(first)], partner[np.sort(first)]


@pytest.mark.parametrize("seed", range(6))
def test_body_pairs_and_first_occurrences_equal_the_numpy_selection(seed):
    rng = np.random.default_rng(500 + seed)
    lo, hi = 20, 40
    pairs_list = [rng.integers(0, 60, (rng.integers(0, 25), 2)) for _ in range(1 + seed % 3)]
    found = [mesh_motion._body_pairs(p, lo, hi) for p in pairs_list]
    own = np.concatenate([f[0] for f in found])
    partner = np.concatenate([f[1] for f in found])
    first = mesh_motion._first_occurrences(own)
    want_own, want_partner = reference_body_pairs(pairs_list, lo, hi)
    np.testing.assert_array_equal(own[first], want_own)
    np.testing.assert_array_equal(partner[first], want_partner)


def test_min_sines_below_is_the_numpy_test():
    rng = np.random.default_rng(9)
    x, cells = distorted_block(rng)
    which = np.arange(len(cells))
    sines = reference_min_sines(x, cells)
    for tol in (sines.min() - 1e-12, sines.min(), np.median(sines), 2.0):
        assert quality.min_sines_below(x, cells, which, tol) == bool(np.any(sines <= tol))
    assert not quality.min_sines_below(x, cells, which[:0], 1.0)


def reference_bulges(points, breaks):
    """``SurfaceCurve``'s bulges as they were in NumPy."""
    chord = np.diff(points, axis=0)
    h = np.linalg.norm(chord, axis=1)
    slope = chord / np.where(h > 0, h, 1.0)[:, None]
    d2 = np.zeros_like(points)
    d2[1:-1] = (slope[1:] - slope[:-1]) / np.maximum(h[1:] + h[:-1], np.finfo(float).tiny)[:, None]
    smooth = ~breaks
    left, right = smooth[:-1], smooth[1:]
    total = d2[:-1] * left[:, None] + d2[1:] * right[:, None]
    count = np.maximum(left.astype(int) + right, 1)
    return (h**2 / count)[:, None] * total


def reference_lengths(curve):
    """Segment lengths by the 8-point Gauss rule on |dx/du|, as in NumPy."""
    d = np.diff(curve.points, axis=0)
    uu = surface.GAUSS_U[None, :, None]
    dx = d[:, None, :] + (2.0 * uu - 1.0) * curve.bulge[:, None, :]
    return np.linalg.norm(dx, axis=-1) @ surface.GAUSS_W


def reference_tangents(curve):
    """``SurfaceCurve.tangents`` as it was in NumPy."""
    d = np.diff(curve.points, axis=0)
    start, end = d - curve.bulge, d + curve.bulge
    start /= np.linalg.norm(start, axis=1, keepdims=True)
    end /= np.linalg.norm(end, axis=1, keepdims=True)
    inner = ~curve.breaks[1:-1]
    mean = end[:-1] + start[1:]
    mean /= np.linalg.norm(mean, axis=1, keepdims=True)
    end[:-1][inner], start[1:][inner] = mean[inner], mean[inner]
    return start, end


@pytest.mark.parametrize("seed", range(6))
def test_curve_construction_kernels_equal_the_numpy_code_bit_for_bit(seed):
    """Bulges, segment lengths and end tangents of ``SurfaceCurve``."""
    rng = np.random.default_rng(600 + seed)
    n = int(rng.integers(2, 40))
    t = np.sort(rng.uniform(0.0, 3.0, n))
    xy = np.column_stack([t, 0.3 * np.sin(2.0 * t) + 0.01 * rng.standard_normal(n)])
    if seed == 0:
        xy[3] = xy[2]  # a zero-length segment
    corners = rng.uniform(size=n) < 0.2
    curve = SurfaceCurve.from_chain(xy, corners)
    np.testing.assert_array_equal(curve.bulge, reference_bulges(curve.points, curve.breaks))
    lengths = reference_lengths(curve)
    np.testing.assert_array_equal(curve.node_s, np.concatenate([[0.0], np.cumsum(lengths)]))
    if seed != 0:  # (a zero-length segment has no tangent)
        for got, want in zip(curve.tangents, reference_tangents(curve), strict=True):
            np.testing.assert_array_equal(got, want)
