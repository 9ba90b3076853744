"""The ALE convective kernel (ale.convective): tangents by central differences, exactness for
uniform and linear fields, the integral identity of the row sums, and that the tests bite."""

import numpy as np
import pytest
import scipy.sparse as sp

from ntncontact.ale import convective
from ntncontact.ale.convective import convective_force

# 3 distorted elements in a row (8 nodes): no two edges parallel, so F^-1 and F^-T differ
X_NODES = np.array([[0.0, 0.0], [1.1, 0.1], [2.0, -0.1], [3.2, 0.05],
                    [-0.1, 0.9], [0.9, 1.2], [2.1, 0.8], [3.0, 1.1]])
CELLS = np.array([[0, 1, 5, 4], [1, 2, 6, 5], [2, 3, 7, 6]])
RHO = np.array([1.0, 2.5, 0.7])
A = np.array([[1.2, 0.35], [-0.2, 0.9]])  # affine map x = A X + t (non-symmetric)


def random_state(seed=0):
    rng = np.random.default_rng(seed)
    x = X_NODES @ A.T + [0.3, -0.2] + 0.05 * rng.normal(size=X_NODES.shape)
    v = rng.normal(size=X_NODES.shape)
    c = rng.normal(size=X_NODES.shape)
    return x, v, c


def dense(triplets, n):
    rows, cols, vals = triplets
    return sp.csr_matrix((vals, (rows, cols)), shape=(n, n)).toarray()


def central_differences(fun, z, h):
    """Columns d fun / d z_j by central differences of step h."""
    z = z.ravel()
    cols = []
    for j in range(z.size):
        e = np.zeros(z.size)
        e[j] = h
        cols.append((fun((z + e).reshape(-1, 2)) - fun((z - e).reshape(-1, 2))) / (2 * h))
    return np.column_stack(cols)


@pytest.mark.parametrize("wrt", ["x", "v"])
def test_tangents_match_central_differences(wrt):
    """f is linear in v, so central differences are exact there up to round-off
    eps |f| / h ~ 1e-10 (h = 1e-6, O(1) data); in x the truncation error h^2 |f'''| ~ 1e-12
    adds. 1e-6 relative is thus far above both yet far below any wrong term (O(1))."""
    x, v, c = random_state()
    args = {"x": x, "v": v, "c": c}

    def force(z):
        kw = dict(args, **{wrt: z})
        return convective_force(X_NODES, kw["x"], kw["v"], kw["c"], CELLS, RHO).force

    result = convective_force(X_NODES, x, v, c, CELLS, RHO)
    K = dense(getattr(result, f"d_{wrt}"), x.size)
    K_fd = central_differences(force, args[wrt], 1e-6)
    assert np.abs(K).max() > 0.1  # a non-trivial tangent
    assert np.abs(K - K_fd).max() < 1e-6 * np.abs(K).max()


def test_velocity_derivative_times_velocity_is_the_force():
    """f = C v is linear in v, and d f / d v = kron(C, I2) acts on each component alike."""
    x, v, c = random_state(1)
    result = convective_force(X_NODES, x, v, c, CELLS, RHO)
    K_v = dense(result.d_v, x.size)
    f = result.force
    np.testing.assert_allclose(K_v @ v.ravel(), f, rtol=0, atol=1e-14 * np.abs(f).max())
    C = K_v[::2, ::2]
    np.testing.assert_allclose(K_v, np.kron(C, np.eye(2)), atol=1e-15)


def test_uniform_velocity_is_not_convected():
    """c . grad v = 0 for uniform v: the rows of C sum to zero (partition of unity)."""
    x, _, c = random_state(2)
    v = np.tile([1.7, -0.4], (len(x), 1))
    result = convective_force(X_NODES, x, v, c, CELLS, RHO)
    f, C = result.force, dense(result.d_v, x.size)[::2, ::2]
    scale = np.abs(C).max() * 1.7
    assert np.abs(f).max() < 20 * np.finfo(float).eps * scale
    assert np.abs(C @ np.ones(len(x))).max() < 20 * np.finfo(float).eps * np.abs(C).max()


def rectangle_strip():
    """Two rectangles 1.5 x 0.8 and 0.5 x 0.8 side by side (6 nodes)."""
    X = np.array([[0.0, 0.0], [1.5, 0.0], [2.0, 0.0], [0.0, 0.8], [1.5, 0.8], [2.0, 0.8]])
    return X, np.array([[0, 1, 4, 3], [1, 2, 5, 4]]), np.array([2.0, 3.0])


def test_uniform_c_and_linear_v_give_the_closed_form():
    """v = L x + b, uniform c: c . grad v = L c, so f_a = (L c) int rho0 N_a dV0 = (L c) rho0
    A_e / 4 summed over the rectangles around node a (x an affine image of X)."""
    X, cells, rho = rectangle_strip()
    x = X @ A.T + [0.1, 0.2]
    L = np.array([[0.5, -1.3], [2.0, 0.7]])
    v = x @ L.T + [1.0, -2.0]
    c = np.tile([0.8, -0.6], (len(X), 1))
    f = convective_force(X, x, v, c, cells, rho).force.reshape(-1, 2)
    quarter = rho * np.array([1.5 * 0.8, 0.5 * 0.8]) / 4  # rho0 A_e / 4 per element
    share = np.zeros(len(X))
    np.add.at(share, cells, np.repeat(quarter[:, None], 4, axis=1))
    expected = share[:, None] * (L @ c[0])
    np.testing.assert_allclose(f, expected, rtol=1e-13, atol=1e-14)


def boundary_integral(X, x, v, c0, cells, rho):
    """int rho0 c . grad_x v dV0 = rho0 / det A * sum over element edges of (c . n) L (v1 + v2)/2
    (divergence theorem for uniform c; x = A X + t so rho0 dV0 = rho0 / det A dV; v is linear
    along every straight edge, so the edge rule is exact)."""
    total = np.zeros(2)
    for cell, r in zip(cells, rho, strict=True):
        a, b = cell, np.roll(cell, -1)
        edge = x[b] - x[a]
        outward = np.column_stack([edge[:, 1], -edge[:, 0]])  # counter-clockwise cells: n L
        flux = outward @ c0
        total += r / np.linalg.det(A) * (flux[:, None] * 0.5 * (v[a] + v[b])).sum(axis=0)
    return total


def test_sum_of_nodal_forces_is_the_integral_of_c_grad_v():
    """sum_a f_a = int rho c . grad v (the column sums of C weigh v by int rho c . grad N_b).
    With x an affine image of X the integrand of the kernel is a polynomial of degree <= 3 in
    each natural coordinate (rational terms cancel), so 2 x 2 Gauss is exact."""
    rng = np.random.default_rng(3)
    x = X_NODES @ A.T + [0.3, -0.2]
    v = rng.normal(size=x.shape)
    c0 = np.array([0.7, -1.1])
    c = np.tile(c0, (len(x), 1))
    f = convective_force(X_NODES, x, v, c, CELLS, RHO).force.reshape(-1, 2)
    expected = boundary_integral(X_NODES, x, v, c0, CELLS, RHO)
    np.testing.assert_allclose(f.sum(axis=0), expected, rtol=1e-12)
    K_v = dense(convective_force(X_NODES, x, v, c, CELLS, RHO).d_v, x.size)
    np.testing.assert_allclose(np.ones(len(x)) @ (K_v[::2, ::2] @ v), expected, rtol=1e-12)


def test_a_transposed_inverse_is_caught(monkeypatch):
    """The closed-form and integral tests bite: with grad_x N = grad_X N F^-T (a plausible
    slip) the forces are wrong by O(1) for the non-symmetric A used above."""
    good = convective._spatial

    def transposed(X_e, x_e):
        gx, w = good(X_e, x_e)
        from ntncontact.fem.q4 import deformation_gradient, reference_gradients

        grad, _ = reference_gradients(X_e)
        Finv = np.linalg.inv(deformation_gradient(grad, x_e))
        return np.einsum("egbJ,egkJ->egbk", grad, Finv), w

    monkeypatch.setattr(convective, "_spatial", transposed)
    with pytest.raises(AssertionError):
        test_uniform_c_and_linear_v_give_the_closed_form()
    with pytest.raises(AssertionError):
        test_sum_of_nodal_forces_is_the_integral_of_c_grad_v()
