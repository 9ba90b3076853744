"""Field remapping: point location, Q4 and quadratic interpolation, momentum correction."""

import numpy as np
import pytest

from ntncontact.ale.remap import (
    Remapper,
    conservative_velocity_correction,
    inverse_bilinear,
    momenta,
)
from ntncontact.mesh.quadmesh import MeshError

XI = np.array([[-1.0, -1.0], [1.0, -1.0], [1.0, 1.0], [-1.0, 1.0]])


def q4_shape(xi):
    """Bilinear shape functions N_a(xi, eta) = (1 + xi_a xi)(1 + eta_a eta)/4, (p, 4)."""
    return 0.25 * (1.0 + xi[..., None, 0] * XI[:, 0]) * (1.0 + xi[..., None, 1] * XI[:, 1])


def perturbed_grid(nx: int, ny: int, amp: float = 0.2, seed: int = 0):
    """Unit-spacing grid with interior nodes jittered: cells are general (non-affine) quads."""
    xs, ys = np.meshgrid(np.arange(nx + 1.0), np.arange(ny + 1.0))
    nodes = np.column_stack([xs.ravel(), ys.ravel()])
    interior = (nodes[:, 0] > 0) & (nodes[:, 0] < nx) & (nodes[:, 1] > 0) & (nodes[:, 1] < ny)
    rng = np.random.default_rng(seed)
    nodes[interior] += rng.uniform(-amp, amp, (interior.sum(), 2))
    i, j = np.meshgrid(np.arange(nx), np.arange(ny))
    n0 = (j * (nx + 1) + i).ravel()
    return nodes, np.column_stack([n0, n0 + 1, n0 + nx + 2, n0 + nx + 1])


def random_points(nodes, cells, count, seed=1):
    """Points inside random cells, with their exact cells."""
    rng = np.random.default_rng(seed)
    cell = rng.integers(0, len(cells), count)
    xi = rng.uniform(-0.95, 0.95, (count, 2))
    pts = np.einsum("pa,pai->pi", q4_shape(xi), nodes[cells[cell]])
    return pts, cell, xi


def test_shape_functions_partition_of_unity_and_kronecker():
    corners = np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]], dtype=float)
    np.testing.assert_allclose(q4_shape(corners), np.eye(4), atol=1e-15)
    xi = np.random.default_rng(0).uniform(-1, 1, (10, 2))
    np.testing.assert_allclose(q4_shape(xi).sum(axis=1), 1.0, atol=1e-15)


def test_inverse_bilinear_recovers_reference_coordinates():
    nodes, cells = perturbed_grid(4, 3)
    pts, cell, xi = random_points(nodes, cells, 200)
    found, res = inverse_bilinear(nodes[cells[cell]], pts)
    # Newton converges quadratically: round-off of O(1) coordinates
    np.testing.assert_allclose(found, xi, atol=1e-12)
    assert res.max() < 1e-12


def test_locate_finds_containing_cells():
    nodes, cells = perturbed_grid(8, 5)
    pts, cell, xi = random_points(nodes, cells, 500)
    loc = Remapper(nodes, cells).locate(pts)
    np.testing.assert_array_equal(loc.cell, cell)
    np.testing.assert_allclose(loc.xi, xi, atol=1e-12)
    assert not loc.clamped.any()


@pytest.mark.parametrize("shear", [4.0, 12.0, 30.0])
def test_locate_finds_points_in_strongly_sheared_cells(shear):
    """A point inside a strongly sheared cell is farther from that cell's centroid than from
    dozens of other centroids (the refined fast-sliding blocks of issue 17 failed so, with
    "lies outside the old mesh"): every point inside the mesh is located, in its cell, and a
    point just outside the sheared boundary is clamped onto it."""
    nodes, cells = perturbed_grid(40, 12, amp=0.0)
    nodes[:, 0] += shear * nodes[:, 1]  # row j shifted by shear * j cell widths
    remapper = Remapper(nodes, cells)
    pts, cell, xi = random_points(nodes, cells, 200, seed=3)
    # corners of cells of the middle rows: near a corner, far from the centroid
    corner_xi = np.array([[-0.97, 0.97], [0.97, -0.97]])[np.arange(40) % 2]
    corner_cells = np.arange(40) + 40 * (np.arange(40) % 10 + 1)
    corner_pts = np.einsum("pa,pai->pi", q4_shape(corner_xi), nodes[cells[corner_cells]])
    pts, cell = np.vstack([pts, corner_pts]), np.concatenate([cell, corner_cells])
    xi = np.vstack([xi, corner_xi])
    centroid = nodes[cells].mean(axis=1)
    rank = np.array([np.sum(np.linalg.norm(centroid - p, axis=1) < np.linalg.norm(
        centroid[c] - p)) for p, c in zip(pts, cell, strict=True)])
    if shear >= 12.0:  # the case: beyond the 4 x 8 nearest centroids searched before
        assert rank.max() >= 32
    loc = remapper.locate(pts)
    np.testing.assert_array_equal(loc.cell, cell)
    np.testing.assert_allclose(loc.xi, xi, atol=1e-9)
    assert not loc.clamped.any()
    # just above the top edge of a sheared top-row cell: clamped onto that edge
    top = 40 * 11 + 20
    edge_mid = 0.5 * (nodes[cells[top, 2]] + nodes[cells[top, 3]])
    loc = remapper.locate(edge_mid + [0.0, 0.02])
    assert loc.clamped[0] and loc.cell[0] == top
    np.testing.assert_allclose(loc.xi[0], [0.0, 1.0], atol=1e-9)
    with pytest.raises(MeshError, match="outside the old mesh"):
        remapper.locate(edge_mid + [0.0, 0.5])


@pytest.mark.parametrize("method", ["linear", "quadratic"])
def test_linear_fields_are_reproduced_exactly(method):
    nodes, cells = perturbed_grid(6, 4)
    coeff = np.array([[0.3, -1.0], [2.0, 0.5], [-0.7, 1.5]])  # f = c0 + c1 x + c2 y, 2 components
    field = lambda x: coeff[0] + x[:, :1] * coeff[1] + x[:, 1:] * coeff[2]  # noqa: E731
    pts, _, _ = random_points(nodes, cells, 300)
    out = Remapper(nodes, cells).remap(field(nodes), pts, method=method)
    # isoparametric Q4 (and any quadratic fit) contain x and y: exact up to round-off
    np.testing.assert_allclose(out, field(pts), atol=1e-12)


def quadratic_field(x):
    return 1.0 + 0.5 * x[:, 0] - 0.3 * x[:, 1] + 0.2 * x[:, 0] ** 2 - 0.4 * x[:, 0] * x[:, 1] + (
        0.1 * x[:, 1] ** 2
    )


def test_quadratic_option_reproduces_quadratic_fields_and_linear_does_not():
    nodes, cells = perturbed_grid(6, 5)
    pts, _, _ = random_points(nodes, cells, 300)
    remapper = Remapper(nodes, cells)
    quad = remapper.remap(quadratic_field(nodes), pts, method="quadratic")
    # least squares of an exact quadratic: round-off amplified by the 6x6 fit conditioning
    np.testing.assert_allclose(quad, quadratic_field(pts), atol=1e-10)
    lin = remapper.remap(quadratic_field(nodes), pts, method="linear")
    assert np.abs(lin - quadratic_field(pts)).max() > 1e-3


def test_unmoved_nodes_keep_their_values_and_single_cell_falls_back_to_linear():
    nodes, cells = perturbed_grid(4, 4)
    field = np.sin(3.0 * nodes[:, 0]) * np.cos(2.0 * nodes[:, 1])
    out = Remapper(nodes, cells).remap(field, nodes, method="quadratic")
    np.testing.assert_array_equal(out, field)
    one = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])
    val = Remapper(one, [[0, 1, 2, 3]]).remap([0.0, 1.0, 2.0, 1.0], [[0.5, 0.5]], "quadratic")
    assert val[0] == pytest.approx(1.0, abs=1e-14)  # bilinear value; 4 nodes cannot fit 6 terms


def test_points_slightly_outside_clamp_and_far_points_raise():
    nodes, cells = perturbed_grid(4, 2)
    field = nodes[:, 0] * 2.0 + 1.0
    remapper = Remapper(nodes, cells)
    loc = remapper.locate([[2.3, -0.04], [4.03, 1.5]])
    assert loc.clamped.all()
    out = remapper.remap(field, [[2.3, -0.04], [4.03, 1.5]])
    # clamped to the nearest boundary points (2.3, 0) and (4, 1.5)
    np.testing.assert_allclose(out, [5.6, 9.0], atol=1e-12)
    with pytest.raises(MeshError, match="outside the old mesh"):
        remapper.locate([[2.0, -0.5]])


def test_conservative_correction_restores_momenta_with_a_rigid_field():
    rng = np.random.default_rng(5)
    m = rng.uniform(0.5, 2.0, 30)
    x = rng.uniform(-1, 3, (30, 2))
    v = rng.normal(size=(30, 2))
    target_p, target_l = np.array([1.5, -0.4]), 2.7
    w = conservative_velocity_correction(m, x, v, target_p, target_l)
    p, ang = momenta(m, x, w)
    # sums of 30 O(1) products: round-off
    np.testing.assert_allclose(p, target_p, atol=1e-12)
    assert ang == pytest.approx(target_l, abs=1e-12)
    # the correction is a rigid velocity field: a + omega e_z x r fits it exactly
    dv = w - v
    basis = np.zeros((60, 3))
    basis[0::2, 0], basis[1::2, 1] = 1.0, 1.0
    basis[0::2, 2], basis[1::2, 2] = -x[:, 1], x[:, 0]
    coef, *_ = np.linalg.lstsq(basis, dv.ravel(), rcond=None)
    np.testing.assert_allclose(basis @ coef, dv.ravel(), atol=1e-12)
    # already conserving: no change
    p0, l0 = momenta(m, x, v)
    np.testing.assert_allclose(conservative_velocity_correction(m, x, v, p0, l0), v, atol=1e-13)


def smooth_field(x):
    return np.column_stack([np.sin(3.0 * x[:, 0] + 1.0) * np.cos(2.0 * x[:, 1]),
                            np.exp(0.5 * x[:, 0] - x[:, 1])])


def unit_grid(n: int, amp: float = 0.15):
    nodes, cells = perturbed_grid(n, n, amp=amp, seed=2)
    return nodes / n, cells


@pytest.mark.parametrize("where", ["interior", "boundary"])
def test_quadratic_is_third_order_also_on_the_boundary(where):
    """The gradient-enhanced interpolant converges as h^3 (linear: h^2), on boundary points
    too, where the earlier patch fit was worst; measured rates 3.0-3.4 and 1.9-2.0."""
    rng = np.random.default_rng(4)
    pts = rng.uniform(0.0, 1.0, (300, 2))
    if where == "boundary":
        pts[:, 1] = 0.0
    errors = {"linear": [], "quadratic": []}
    for n in (8, 16, 32):
        nodes, cells = unit_grid(n)
        remapper = Remapper(nodes, cells)
        for method, err in errors.items():
            err.append(np.abs(remapper.remap(smooth_field(nodes), pts, method)
                              - smooth_field(pts)).max())
    rates = {k: np.log2(np.array(v[:-1]) / np.array(v[1:])) for k, v in errors.items()}
    assert np.all(rates["quadratic"] > 2.7), rates
    assert np.all(rates["linear"] > 1.7) and np.all(rates["linear"] < 2.4), rates
    assert errors["quadratic"][-1] < 0.1 * errors["linear"][-1]


def test_quadratic_is_continuous_at_the_nodes():
    """A node moved by delta takes a value within O(delta) of its own: no jump as delta -> 0
    (a least-squares patch fit evaluated at the point jumps by O(h^2 f''))."""
    nodes, cells = unit_grid(8)
    remapper = Remapper(nodes, cells)
    f = smooth_field(nodes)
    corner_side = np.flatnonzero((nodes[:, 1] == 0.0) & (nodes[:, 0] > 0) & (nodes[:, 0] < 1))
    for node in (corner_side[2], 40):  # a bottom boundary node and an interior node
        jumps = np.array([np.abs(remapper.remap(f, nodes[node] + [delta, 0.0], "quadratic")
                                 - f[node]).max() for delta in (1e-3, 1e-5, 1e-7)])
        # linear in delta (slope |df/dx| ~ 1.4-1.6 here): a jump would stall the decrease
        np.testing.assert_allclose(jumps[1:] / jumps[:-1], 0.01, rtol=0.05)
        assert jumps[-1] < 1e-6


def test_hints_give_the_same_location_and_clamp_just_outside_a_boundary_edge():
    nodes, cells = perturbed_grid(6, 4)
    remapper = Remapper(nodes, cells)
    pts, cell, xi = random_points(nodes, cells, 50)
    right = remapper.locate(pts, hint=cell)
    wrong = remapper.locate(pts, hint=(cell + 7) % len(cells))  # wrong hints are searched past
    for loc in (right, wrong):
        np.testing.assert_array_equal(loc.cell, cell)
        np.testing.assert_allclose(loc.xi, xi, atol=1e-12)
    # a point just below the bottom edge of cell 2 (x in [2, 3]): clamped onto that edge
    out = [[2.4, -0.01]]
    hinted, searched = remapper.locate(out, hint=[2]), remapper.locate(out)
    assert hinted.clamped[0] and searched.clamped[0] and hinted.cell[0] == searched.cell[0] == 2
    np.testing.assert_allclose(hinted.xi, searched.xi, atol=1e-12)
    field = 2.0 * nodes[:, 0] + 1.0
    assert remapper.remap(field, out, hint=[2])[0] == pytest.approx(5.8, abs=1e-12)


def reference_gradient_operators(remapper, nodes):
    """``Remapper._gradient_operators`` as it was: the linear fit for every node, overridden by
    the quadratic one where the patch determines it."""
    patch, lengths = remapper._topology.patches
    patch, lengths = patch[nodes], lengths[nodes]
    centre = remapper.nodes[nodes]
    valid = patch >= 0
    d = (remapper.nodes[np.where(valid, patch, 0)] - centre[:, None, :]) * valid[..., None]
    scale = np.sqrt(np.sum(d**2, axis=(1, 2)) / np.maximum(lengths, 1))
    scale = np.where(scale > 0, scale, 1.0)
    ds = d / scale[:, None, None]
    dx, dy = ds[..., 0], ds[..., 1]
    quad = np.stack([dx, dy, 0.5 * dx * dx, dx * dy, 0.5 * dy * dy], axis=-1)
    ops = np.zeros((len(patch), 2, patch.shape[1]))
    for basis, terms in ((ds, 2), (quad, 5)):
        u, sv, vt = np.linalg.svd(basis, full_matrices=False)
        ok = (lengths >= terms) & (sv[:, -1] > 1e-8 * sv[:, 0])
        inv = np.where(sv > 1e-8 * sv[:, :1], 1.0 / np.where(sv > 0, sv, 1.0), 0.0)
        pinv = np.einsum("nji,nj,nqj->niq", vt, inv, u)
        ops[ok] = pinv[ok, :2, :] / scale[ok, None, None]
    return patch, ops


@pytest.mark.parametrize("shape", [(6, 1), (1, 5), (5, 4), (2, 2), (1, 1)])
def test_gradient_operators_equal_the_linear_then_quadratic_fits_bit_for_bit(shape):
    """The quadratic fit first and the linear one only for the nodes left (strips one cell
    thick have nodes whose patch cannot carry a quadratic) gives the same operators."""
    nodes, cells = perturbed_grid(*shape, seed=3)
    remapper = Remapper(nodes, cells)
    rng = np.random.default_rng(7)
    for which in (np.arange(len(nodes)), rng.choice(len(nodes), min(5, len(nodes)), False)):
        patch, ops = remapper._gradient_operators(which)
        want_patch, want_ops = reference_gradient_operators(remapper, which)
        np.testing.assert_array_equal(patch, want_patch)
        np.testing.assert_array_equal(ops, want_ops)
