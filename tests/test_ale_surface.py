"""Surface curve, normal feet, relocation and respacing of ALE surface nodes."""

import numpy as np
import pytest

from ntncontact.ale.surface import (
    GAUSS_U,
    GAUSS_W,
    SurfaceCurve,
    local_slides,
    respace_surface,
)

ROUND = 1e-12  # positions of order 1 computed through a few flops


def arc_chain(n: int, radius: float = 1.0, span: float = np.pi / 2) -> np.ndarray:
    # slightly non-uniform angles so the chord-length parametrization matters
    t = np.linspace(0.0, 1.0, n)
    theta = span * (t + 0.08 * np.sin(np.pi * t) * t)
    return radius * np.column_stack([np.cos(theta), np.sin(theta)])


def relocate(chain, active, targets_xy, spacing=None):
    """Active chain nodes moved to the normal feet of their targets, the others respaced
    between them (``respace_surface``); (new chain positions, the active nodes' arc lengths)."""
    curve = SurfaceCurve.from_chain(chain)
    s_active = curve.normal_foot(np.asarray(targets_xy, dtype=float))[0]
    mask = np.zeros(len(chain), bool)
    mask[active] = True
    targets = np.zeros(len(chain))
    targets[active] = s_active
    return respace_surface(chain, mask, targets, spacing=spacing), s_active


def closest_point(curve, p, segments):
    """Arc length of the point of ``segments`` closest to p (Newton on d|x(u) - p|^2/du = 0
    from the best of 9 samples, per segment)."""
    best = (np.inf, 0.0)
    for k in segments:
        x0, d, q = curve.points[k], curve.points[k + 1] - curve.points[k], curve.bulge[k]
        x = lambda u, x0=x0, d=d, q=q: x0 + u * d + u * (u - 1.0) * q  # noqa: E731
        u = min(np.linspace(0.0, 1.0, 9), key=lambda v: np.linalg.norm(x(v) - p))
        for _ in range(30):
            r, dx = x(u) - p, d + (2.0 * u - 1.0) * q
            u = float(np.clip(u - (r @ dx) / (dx @ dx + 2.0 * r @ q), 0.0, 1.0))
        dist = np.linalg.norm(x(u) - p)
        if dist < best[0]:
            gauss = u * GAUSS_U
            arc = u * np.linalg.norm(d + (2.0 * gauss[:, None] - 1.0) * q, axis=1) @ GAUSS_W
            best = (dist, curve.node_s[k] + arc)
    return best[1]


def max_radial_error(n: int) -> float:
    curve = SurfaceCurve.from_chain(arc_chain(n))
    s = np.linspace(0.0, curve.node_s[-1], 20 * n)
    return float(np.max(np.abs(np.linalg.norm(curve.point_at(s), axis=1) - 1.0)))


def test_curve_interpolates_nodes_and_arc_length_is_consistent():
    chain = arc_chain(9)
    curve = SurfaceCurve.from_chain(chain)
    np.testing.assert_allclose(curve.point_at(curve.node_s), chain, atol=ROUND)
    # quarter circle: the curve length converges to pi/2 (O(h^3) geometry => tiny error)
    assert curve.node_s[-1] == pytest.approx(np.pi / 2, rel=1e-4)
    # unit speed: a small arc step moves the point by the same distance to first order
    s, ds = 0.7, 1e-6
    p0, p1 = curve.point_at([s, s + ds])
    assert np.linalg.norm(p1 - p0) == pytest.approx(ds, rel=1e-6)


def test_circle_error_is_third_order():
    errors = np.array([max_radial_error(n) for n in (9, 17, 33)])
    rates = np.log2(errors[:-1] / errors[1:])
    # at least O(h^3) (the averaged parabolas measure ~4 here); a chord interpolant gives 2
    assert np.all(rates > 2.7), rates
    assert errors[-1] < 1e-5


def test_projection_of_radial_points_lands_on_the_radius():
    chain = arc_chain(17)
    angles = np.array([0.1, 0.55, 1.2])
    points = 1.3 * np.column_stack([np.cos(angles), np.sin(angles)])
    s = SurfaceCurve.from_chain(chain).normal_foot(points)[0]
    foot = SurfaceCurve.from_chain(chain).point_at(s)
    foot_angle = np.arctan2(foot[:, 1], foot[:, 0])
    # the foot of the normal on a circle is on the radius, up to the O(h^3) curve error
    np.testing.assert_allclose(foot_angle, angles, atol=1e-4)
    # a node projects onto itself
    curve = SurfaceCurve.from_chain(chain)
    assert curve.normal_foot(chain[5])[0][0] == pytest.approx(curve.node_s[5], abs=1e-10)


def test_corner_is_a_segment_break():
    # L-shaped chain: along x, then up at the corner node 3
    chain = np.array([[0, 0], [1, 0], [2, 0], [3, 0], [3, 1], [3, 2], [3, 3]], dtype=float)
    corner = np.zeros(7, bool)
    corner[3] = True
    with_corner = SurfaceCurve.from_chain(chain, corner)
    p = with_corner.point_at([2.5, 3.5])
    np.testing.assert_allclose(p, [[2.5, 0.0], [3.0, 0.5]], atol=ROUND)
    without = SurfaceCurve.from_chain(chain)
    q = without.point_at([2.5])
    assert abs(q[0, 1]) > 1e-2  # bends around the unflagged corner


def test_respace_preserves_order_anchors_and_stays_on_curve():
    chain = arc_chain(21)
    curve = SurfaceCurve.from_chain(chain)
    anchors = np.zeros(21, bool)
    anchors[[8, 9]] = True
    targets = np.zeros(21)
    # active nodes jump 3.5 element lengths along the surface, over several old nodes (Fig 4.2)
    h = curve.node_s[-1] / 20
    targets[[8, 9]] = curve.node_s[[8, 9]] + 3.5 * h
    new = respace_surface(chain, anchors, targets)
    s_new = curve.normal_foot(new)[0]
    assert np.all(np.diff(s_new) > 0)
    np.testing.assert_allclose(s_new[[8, 9]], targets[[8, 9]], atol=1e-9)
    np.testing.assert_allclose(new[[0, -1]], chain[[0, -1]], atol=ROUND)
    # on the old curve: the projection returns the point itself
    np.testing.assert_allclose(curve.point_at(s_new), new, atol=1e-9)
    # proportional spacing: free nodes between anchors are evenly stretched or compressed
    np.testing.assert_allclose(np.diff(s_new[:9]), np.diff(s_new[:9]).mean(), rtol=0.1)


def test_respace_rejects_anchor_passing_a_corner():
    chain = np.column_stack([np.arange(6.0), np.zeros(6)])
    corner = np.zeros(6, bool)
    corner[3] = True
    anchors = np.zeros(6, bool)
    anchors[1] = True
    targets = np.zeros(6)
    targets[1] = 3.5
    with pytest.raises(ValueError, match="out of order at chain node 3"):
        respace_surface(chain, anchors, targets, corner)


def test_relocate_moves_active_node_to_projected_target_with_equal_spacing():
    chain = np.column_stack([np.linspace(0, 10, 11), np.zeros(11)])
    new, s_active = relocate(chain, [4], [[7.3, 0.2]], spacing=np.ones(10))
    assert s_active[0] == pytest.approx(7.3, abs=1e-12)
    np.testing.assert_allclose(new[:, 1], 0.0, atol=ROUND)
    np.testing.assert_allclose(new[:5, 0], np.linspace(0, 7.3, 5), atol=1e-12)
    np.testing.assert_allclose(new[4:, 0], np.linspace(7.3, 10, 7), atol=1e-12)


def test_relocated_nodes_stay_on_a_circle_to_third_order():
    def radial_error(n):
        chain = arc_chain(n)
        # the middle node chases a target 2.3 segments ahead, slightly off the circle
        theta = np.arctan2(chain[n // 2 + 2, 1], chain[n // 2 + 2, 0]) + 0.3 * (np.pi / 2) / n
        new, _ = relocate(chain, [n // 2], [[1.01 * np.cos(theta), 1.01 * np.sin(theta)]])
        return np.max(np.abs(np.linalg.norm(new, axis=1) - 1.0))

    errors = np.array([radial_error(n) for n in (9, 17, 33)])
    # nodes between old nodes inherit the curve error: at least third order in h
    assert np.all(np.log2(errors[:-1] / errors[1:]) > 2.7), errors


def segments_in_band(s, ref, anchors, tol):
    """Every segment within [1 - t, 1/(1 - t)] of its reference length scaled by its run."""
    seg, ok = np.diff(s), True
    for a, b in zip(anchors[:-1], anchors[1:], strict=True):
        target = ref[a:b] * seg[a:b].sum() / ref[a:b].sum()
        ratio = seg[a:b] / target
        ok &= bool(np.all(ratio >= 1 - tol - 1e-12) and np.all(ratio <= 1 / (1 - tol) + 1e-12))
    return ok


def test_local_slides_move_only_the_buffer_next_to_a_sliding_anchor():
    s, ref = np.arange(11.0), np.ones(10)
    # no slide: nothing moves, exactly
    out, resets = local_slides(s, ref, [0, 3, 10], [0.0, 0.0, 0.0])
    assert not out.any() and resets == 0
    # a slide the neighbouring segment can absorb within the band (t = 0.5: lengths >= 0.5)
    out, _ = local_slides(s, ref, [0, 3, 10], [0.0, 0.3, 0.0])
    np.testing.assert_array_equal(np.flatnonzero(out), [3])
    # 1.3 into the right run needs three segments (slack 0.5 each), shared equally; the left
    # run grows (slack 1 each up to twice the length): two segments
    out, resets = local_slides(s, ref, [0, 3, 10], [0.0, 1.3, 0.0])
    np.testing.assert_allclose(out, [0, 0, 0.65, 1.3, 1.3 - 1.3 / 3, 1.3 / 3, 0, 0, 0, 0, 0],
                               atol=1e-15)
    assert resets == 0
    # two anchors sliding the same way with room between them: two buffers, middle untouched
    out, _ = local_slides(s, ref, [0, 3, 6, 10], [0.0, 0.2, 0.2, 0.0])
    np.testing.assert_array_equal(np.flatnonzero(out), [3, 6])
    # adjacent anchors sliding together (buffers overlap): the run between moves rigidly
    out, _ = local_slides(s, ref, [0, 3, 5, 10], [0.0, 0.6, 0.6, 0.0])
    assert out[4] == 0.6


def test_local_slides_carry_saturated_segments_and_keep_the_band_under_repeated_slides():
    """A node sliding the same way step after step compresses a neighbourhood that widens only
    as its segments reach the band, never leaves the band, and moves far fewer nodes than
    respacing the run every time."""
    n = 41
    ref = 1.0 + 0.5 * np.sin(np.arange(n - 1.0))  # graded reference spacing
    s = np.concatenate([[0.0], np.cumsum(ref)])
    anchors, node = np.array([0, 10, n - 1]), 10
    moved_per_step = []
    for _ in range(40):
        out, resets = local_slides(s, ref, anchors, [0.0, 0.1, 0.0], tolerance=0.5)
        assert resets == 0
        moved_per_step.append(np.count_nonzero(out))
        s = s + out
        assert segments_in_band(s, ref, anchors, 0.5)
        assert np.all(np.diff(s) > 0)
    assert s[node] == pytest.approx(np.sum(ref[:10]) + 4.0, abs=1e-12)
    assert moved_per_step[0] <= 2 < moved_per_step[-1] < n - 2  # the buffer widened gradually
    # a segment at the band's edge is carried rigidly: segment 3-4 of 6/13 is half its target
    # (run 3-10 of length 6/13 + 6 over 7 reference segments: target 12/13)
    s = np.concatenate([np.arange(4.0), 3.0 + 6.0 / 13.0 + np.arange(7.0)])
    out, _ = local_slides(s, np.ones(10), [0, 3, 10], [0.0, 0.2, 0.0], tolerance=0.5)
    assert out[4] == pytest.approx(0.2, abs=1e-12) and not out[5:].any()


def test_local_slides_reset_a_run_that_cannot_absorb_the_slide():
    s, ref = np.arange(6.0), np.ones(5)
    # 3.5 into a run of length 5 cannot keep its 5 segments above 0.5 each: reference respacing
    out, resets = local_slides(np.arange(11.0), np.ones(10), [0, 4, 10], [0.0, 3.5, 0.0])
    assert resets == 1
    new = np.arange(11.0) + out
    np.testing.assert_allclose(np.diff(new[4:]), (10 - 7.5) / 6, atol=1e-12)  # even spacing
    with pytest.raises(ValueError, match="tolerance"):
        local_slides(s, ref, [0, 5], [0.0, 0.0], tolerance=1.0)
    with pytest.raises(ValueError, match="increasing"):
        local_slides(s, ref, [5, 0], [0.0, 0.0])


def test_node_tangents_average_the_one_sided_tangents_except_at_breaks():
    chain = arc_chain(9)
    corner = np.zeros(9, bool)
    corner[4] = True
    for curve in (SurfaceCurve.from_chain(chain), SurfaceCurve.from_chain(chain, corner)):
        nodes = np.arange(9)
        t = curve.node_tangents(nodes)
        d = np.diff(curve.points, axis=0)  # dx/du at u = 0 of each segment, u = 1 of the last
        one_sided = np.vstack([d - curve.bulge, d[-1:] + curve.bulge[-1:]])
        one_sided /= np.linalg.norm(one_sided, axis=1, keepdims=True)
        # the parabolas' tangent kinks at smooth nodes are O(h^2) (h ~ 0.2 here: up to 2e-3)
        np.testing.assert_allclose(t, one_sided, atol=5e-3)
        np.testing.assert_allclose(t[curve.breaks], one_sided[curve.breaks], atol=1e-12)
        # on the circle the tangent is perpendicular to the radius, to the curve's accuracy
        assert np.abs(np.einsum("ij,ij->i", t, chain)).max() < 1e-2
    # a mirror-symmetric chain has an exactly mirror-symmetric tangent at its middle node
    x = np.linspace(-1.0, 1.0, 9)
    sym = SurfaceCurve.from_chain(np.column_stack([x, 0.05 * x**2 + 0.02 * x**4]))
    assert abs(sym.node_tangents([4])[0, 1]) < 1e-15


def test_normal_foot_is_well_defined_at_the_nodes_of_a_curved_chain():
    """The averaged parabolas leave tiny tangent kinks at the nodes of a curved chain, so the
    closest point to a point straight below a node is one of two points a hair either side of
    it (the choice flips with round-off); the normal foot is the node itself."""
    x = np.linspace(-1.0, 1.0, 9)
    chain = np.column_stack([x, 0.05 * x**2 + 0.02 * x**4])  # symmetric, curved, non-uniform h''
    curve = SurfaceCurve.from_chain(chain)
    below = chain[4] - [0.0, 0.01]
    s_close = closest_point(curve, below, (3, 4))
    s_foot, foot = curve.normal_foot(below)
    assert abs(s_close - curve.node_s[4]) > 1e-9  # the closest point is off the node
    assert s_foot[0] == pytest.approx(curve.node_s[4], abs=1e-15)
    np.testing.assert_allclose(foot[0], chain[4], atol=1e-15)
    # mirrored points get mirrored feet, and the foot moves smoothly through the node
    offsets = np.array([-1e-6, -1e-9, 1e-9, 1e-6])
    s = curve.normal_foot(below + offsets[:, None] * [1.0, 0.0])[0] - curve.node_s[4]
    np.testing.assert_allclose(s[::-1], -s, atol=1e-15)
    assert np.all(np.diff(s) > 0) and np.all(np.abs(s) < 2.0 * np.abs(offsets))


def test_normal_foot_is_the_orthogonal_projection_on_a_straight_chain_and_stops_at_breaks():
    chain = np.column_stack([np.linspace(0.0, 4.0, 5), np.zeros(5)])
    curve = SurfaceCurve.from_chain(chain)
    pts = np.array([[0.3, 0.7], [2.0, -0.4], [3.99, 0.1]])
    s, foot = curve.normal_foot(pts)
    np.testing.assert_allclose(s, pts[:, 0], atol=1e-14)
    np.testing.assert_allclose(foot, np.column_stack([pts[:, 0], np.zeros(3)]), atol=1e-14)
    s, foot = curve.normal_foot([[-0.5, 0.2], [4.5, -0.1]])  # beyond the chain ends
    np.testing.assert_allclose(s, [0.0, 4.0], atol=1e-14)
    # on an arc the normal foot of a radial point is on that radius (to the curve's accuracy)
    arc = arc_chain(17)
    angles = np.array([0.1, 0.55, 1.2])
    s, foot = SurfaceCurve.from_chain(arc).normal_foot(
        1.2 * np.column_stack([np.cos(angles), np.sin(angles)]))
    np.testing.assert_allclose(np.arctan2(foot[:, 1], foot[:, 0]), angles, atol=1e-4)


def test_normal_foot_of_points_on_the_nodal_normals_is_the_node():
    """Points on the continuous field's normal at a node project onto that node (the root
    sits at a segment end, u = 0 or 1 up to round-off, of two candidate segments)."""
    chain = arc_chain(13)
    curve = SurfaceCurve.from_chain(chain)
    t = curve.node_tangents(np.arange(13))
    normal = np.column_stack([t[:, 1], -t[:, 0]])
    for gap in (-0.01, 0.003):
        s, foot = curve.normal_foot(chain + gap * normal)
        np.testing.assert_allclose(s, curve.node_s, atol=1e-14)
        np.testing.assert_allclose(foot, chain, atol=1e-14)
