"""Surface curve, projection, relocation and respacing of ALE surface nodes."""

import numpy as np
import pytest

from ntncontact.ale.surface import (
    SurfaceCurve,
    point_at,
    project_to_surface,
    relocate_surface_nodes,
    respace_surface,
)

ROUND = 1e-12  # positions of order 1 computed through a few flops


def arc_chain(n: int, radius: float = 1.0, span: float = np.pi / 2) -> np.ndarray:
    # slightly non-uniform angles so the chord-length parametrization matters
    t = np.linspace(0.0, 1.0, n)
    theta = span * (t + 0.08 * np.sin(np.pi * t) * t)
    return radius * np.column_stack([np.cos(theta), np.sin(theta)])


def max_radial_error(n: int) -> float:
    curve = SurfaceCurve.from_chain(arc_chain(n))
    s = np.linspace(0.0, curve.length, 20 * n)
    return float(np.max(np.abs(np.linalg.norm(curve.point_at(s), axis=1) - 1.0)))


def test_curve_interpolates_nodes_and_arc_length_is_consistent():
    chain = arc_chain(9)
    curve = SurfaceCurve.from_chain(chain)
    np.testing.assert_allclose(curve.point_at(curve.node_s), chain, atol=ROUND)
    # quarter circle: the curve length converges to pi/2 (O(h^3) geometry => tiny error)
    assert curve.length == pytest.approx(np.pi / 2, rel=1e-4)
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
    s = project_to_surface(chain, points)
    foot = point_at(chain, s)
    foot_angle = np.arctan2(foot[:, 1], foot[:, 0])
    # the foot of the normal on a circle is on the radius, up to the O(h^3) curve error
    np.testing.assert_allclose(foot_angle, angles, atol=1e-4)
    # a node projects onto itself
    curve = SurfaceCurve.from_chain(chain)
    assert curve.project(chain[5])[0] == pytest.approx(curve.node_s[5], abs=1e-10)


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
    h = curve.length / 20
    targets[[8, 9]] = curve.node_s[[8, 9]] + 3.5 * h
    new = respace_surface(chain, anchors, targets)
    s_new = curve.project(new)
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
    new, s_active = relocate_surface_nodes(chain, [4], [[7.3, 0.2]], spacing=np.ones(10))
    assert s_active[0] == pytest.approx(7.3, abs=1e-12)
    np.testing.assert_allclose(new[:, 1], 0.0, atol=ROUND)
    np.testing.assert_allclose(new[:5, 0], np.linspace(0, 7.3, 5), atol=1e-12)
    np.testing.assert_allclose(new[4:, 0], np.linspace(7.3, 10, 7), atol=1e-12)


def test_relocated_nodes_stay_on_a_circle_to_third_order():
    def radial_error(n):
        chain = arc_chain(n)
        # the middle node chases a target 2.3 segments ahead, slightly off the circle
        theta = np.arctan2(chain[n // 2 + 2, 1], chain[n // 2 + 2, 0]) + 0.3 * (np.pi / 2) / n
        new, _ = relocate_surface_nodes(chain, [n // 2], [[1.01 * np.cos(theta),
                                                           1.01 * np.sin(theta)]])
        return np.max(np.abs(np.linalg.norm(new, axis=1) - 1.0))

    errors = np.array([radial_error(n) for n in (9, 17, 33)])
    # nodes between old nodes inherit the curve error: at least third order in h
    assert np.all(np.log2(errors[:-1] / errors[1:]) > 2.7), errors
