"""Q4 element kernels and global assembly: finite differences, patch tests, mass."""

import numpy as np
import pytest
from element_oracle import stress_and_tangent

from ntncontact.fem.assembly import Assembler, MaterialGroup
from ntncontact.fem.q4 import InvertedElementError

RNG = np.random.default_rng(1)


def distorted_grid(nx=3, ny=2, jitter=0.15):
    """A structured grid with interior nodes moved: non-parallelogram elements."""
    xs, ys = np.meshgrid(np.linspace(0, 1.5, nx + 1), np.linspace(0, 1.0, ny + 1))
    nodes = np.column_stack([xs.ravel(), ys.ravel()])
    interior = (nodes[:, 0] > 0) & (nodes[:, 0] < 1.5) & (nodes[:, 1] > 0) & (nodes[:, 1] < 1.0)
    nodes[interior] += jitter * RNG.uniform(-1, 1, (interior.sum(), 2)) / max(nx, ny)
    i, j = np.meshgrid(np.arange(nx), np.arange(ny))
    n0 = (j * (nx + 1) + i).ravel()
    cells = np.column_stack([n0, n0 + 1, n0 + nx + 2, n0 + nx + 1])
    return nodes, cells


def make_assembler(nodes, cells, kind):
    ne = len(cells)
    return Assembler(cells, len(nodes), [MaterialGroup(kind, np.arange(ne))],
                     np.full(ne, 2.0), np.full(ne, 1.0), np.full(ne, 3.0))


@pytest.mark.parametrize("kind", ["neo_hookean", "linear_elastic"])
def test_element_tangent_matches_central_differences(kind):
    """One element through the assembler (the compiled kernel): force = dW/dd, K = df/dd."""
    nodes, cells = distorted_grid(1, 1)
    asm = make_assembler(nodes, cells, kind)
    u = 0.1 * RNG.standard_normal(nodes.shape)
    f, K, W = asm.internal(nodes, d=u)
    K = K.toarray()
    h = 1e-6
    for d in range(8):
        du = np.zeros(8)
        du[d] = h
        fp, _, Wp = asm.internal(nodes, d=u + du.reshape(4, 2), need_tangent=False)
        fm, _, Wm = asm.internal(nodes, d=u - du.reshape(4, 2), need_tangent=False)
        # central differences: truncation O(h^2) and cancellation O(eps/h) ~ 1e-10 at O(1) forces
        np.testing.assert_allclose((fp - fm) / (2 * h), K[:, d], rtol=1e-6, atol=1e-8)
        assert (Wp - Wm) / (2 * h) == pytest.approx(f[d], rel=1e-6, abs=1e-8)


@pytest.mark.parametrize("kind", ["neo_hookean", "linear_elastic"])
def test_patch_test_homogeneous_deformation_gives_zero_interior_force(kind):
    nodes, cells = distorted_grid(4, 3, jitter=0.3)
    asm = make_assembler(nodes, cells, kind)
    G = np.array([[0.02, 0.01], [-0.015, 0.03]]) if kind == "linear_elastic" else np.array(
        [[0.3, 0.2], [-0.1, 0.25]])
    f, K, W = asm.internal(nodes, d=nodes @ G.T)
    boundary = (np.isclose(nodes[:, 0], 0) | np.isclose(nodes[:, 0], 1.5)
                | np.isclose(nodes[:, 1], 0) | np.isclose(nodes[:, 1], 1.0))
    f = f.reshape(-1, 2)
    # a homogeneous F is reproduced exactly by Q4: interior nodes carry no force (round-off)
    assert np.abs(f[~boundary]).max() < 1e-12 * np.abs(f).max()
    # total energy equals W(F) times the area, and boundary forces equal the traction resultants
    P, _, Wd = stress_and_tangent(kind, np.eye(2) + G, 2.0, 1.0)
    assert W == pytest.approx(Wd * 1.5, rel=1e-12)
    right = np.isclose(nodes[:, 0], 1.5)
    np.testing.assert_allclose(f[right].sum(axis=0), P[:, 0] * 1.0, rtol=1e-12)
    assert K.shape == (2 * len(nodes),) * 2


def test_rigid_rotation_is_stress_free_for_neo_hookean():
    nodes, cells = distorted_grid(3, 2)
    asm = make_assembler(nodes, cells, "neo_hookean")
    th = 1.1
    R = np.array([[np.cos(th), -np.sin(th)], [np.sin(th), np.cos(th)]])
    f, _, W = asm.internal(nodes, d=nodes @ R.T + [3.0, -2.0] - nodes, need_tangent=False)
    assert np.abs(f).max() < 1e-13 and abs(W) < 1e-14


def test_global_tangent_matches_central_differences():
    nodes, cells = distorted_grid(3, 2)
    asm = make_assembler(nodes, cells, "neo_hookean")
    u = 0.05 * RNG.standard_normal(nodes.shape)
    _, K, _ = asm.internal(nodes, d=u)
    v = RNG.standard_normal(nodes.shape)
    h = 1e-6
    fp, _, _ = asm.internal(nodes, d=u + h * v, need_tangent=False)
    fm, _, _ = asm.internal(nodes, d=u - h * v, need_tangent=False)
    np.testing.assert_allclose((fp - fm) / (2 * h), K @ v.ravel(), rtol=1e-6, atol=1e-7)
    assert abs(K - K.T).max() < 1e-12 * abs(K).max()  # hyperelastic tangent is symmetric


def test_mass_matrices_carry_the_total_mass_and_lumping_keeps_it():
    nodes, cells = distorted_grid(3, 2)
    asm = make_assembler(nodes, cells, "linear_elastic")
    area = 1.5
    for lumped in (False, True):
        M = asm.mass(nodes, lumped)
        ones_x = np.tile([1.0, 0.0], len(nodes))
        assert ones_x @ M @ ones_x == pytest.approx(3.0 * area, rel=1e-13)
    Mc, Ml = asm.nodal_mass(nodes, False), asm.nodal_mass(nodes, True)
    np.testing.assert_allclose(np.asarray(Mc.sum(axis=1)).ravel(), Ml.diagonal(), rtol=1e-13)


def test_balance_takes_the_nodal_or_the_dof_mass():
    """The dof mass is the nodal one times the 2 x 2 identity: the same energies and momenta
    (the time loop passes the dof mass of an ALE body's current mesh)."""
    from ntncontact.engine.diagnostics import balance

    nodes, cells = distorted_grid(3, 2)
    asm = make_assembler(nodes, cells, "linear_elastic")
    rng = np.random.default_rng(3)
    x, v = nodes + 0.01 * rng.standard_normal(nodes.shape), rng.standard_normal(nodes.shape)
    for lumped in (False, True):
        by_node = balance(asm.nodal_mass(nodes, lumped), x, v, 2.0)
        by_dof = balance(asm.mass(nodes, lumped), x, v, 2.0)
        np.testing.assert_allclose(by_dof.linear_momentum, by_node.linear_momentum, rtol=1e-13)
        for name in ("kinetic_energy", "angular_momentum"):
            assert getattr(by_dof, name) == pytest.approx(getattr(by_node, name), rel=1e-13)
        assert by_dof.kinetic_energy > 0.0


def test_inverted_element_is_named():
    nodes, cells = distorted_grid(2, 1)
    asm = make_assembler(nodes, cells, "neo_hookean")
    x = nodes.copy()
    x[cells[1, 2]] = x[cells[1, 0]] - [0.1, 0.1]  # fold element 1
    with pytest.raises(InvertedElementError, match="element 1 .*current"):
        asm.internal(nodes, d=x - nodes)
