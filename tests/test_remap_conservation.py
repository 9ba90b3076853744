"""The remap's velocity correction (ale.conservation, engine.remap_conservation): momenta and
kinetic (or total) energy exact, with the least mass-norm change."""

import numpy as np
import pytest
import scipy.sparse as sp
from helpers import Recorder, model_from_dict, model_from_example

from ntncontact.ale.conservation import conserving_correction, dof_momenta, rigid_modes
from ntncontact.engine.remap_conservation import body_mass, hand_over_energy
from ntncontact.engine.simulation import Simulation


def distorted_grid(nx, ny, rng):
    xs, ys = np.meshgrid(np.linspace(0, 2.0, nx + 1), np.linspace(0, 1.0, ny + 1))
    X = np.column_stack([xs.ravel(), ys.ravel()]) + 0.03 * rng.standard_normal(
        ((nx + 1) * (ny + 1), 2))
    i, j = np.meshgrid(np.arange(nx), np.arange(ny))
    n0 = (j * (nx + 1) + i).ravel()
    return X, np.column_stack([n0, n0 + 1, n0 + nx + 2, n0 + nx + 1])


@pytest.fixture(params=[False, True], ids=["consistent", "lumped"])
def case(request):
    rng = np.random.default_rng(3)
    X, cells = distorted_grid(5, 3, rng)
    mass = body_mass(X, cells, rng.uniform(0.5, 2.0, len(cells)), request.param)
    x = X + 0.1 * rng.standard_normal(X.shape) + 3.0  # off the origin: L is not trivial
    v = rng.standard_normal(X.shape)
    return mass, x, v, rng


def test_momenta_and_kinetic_energy_take_their_targets_and_only_the_chosen_dofs_change(case):
    mass, x, v, rng = case
    momenta, kinetic = dof_momenta(mass, x, v)
    remapped = v + 0.02 * rng.standard_normal(v.shape)
    dofs = np.arange(8, 30)
    out = conserving_correction(mass, x, remapped, dofs, momenta, 1.003 * kinetic)
    m2, k2 = dof_momenta(mass, x, out.v)
    assert out.energy_restored
    scale = np.abs(mass @ np.abs(v)).sum() * (1 + np.abs(x).max())
    assert np.abs(m2 - momenta).max() < 1e-14 * scale
    assert abs(k2 / (1.003 * kinetic) - 1) < 1e-14
    others = np.setdiff1d(np.arange(v.size), dofs)
    assert np.array_equal(out.v.ravel()[others], remapped.ravel()[others])


def test_the_correction_is_the_least_mass_norm_change(case):
    """KKT: A delta lies in the span of the constraints' gradients on S (the rigid modes'
    B = (M G)_S and the energy's M v'), so no admissible change is smaller; and a random
    admissible change found by projecting onto the constraints is not smaller."""
    mass, x, v, rng = case
    momenta, kinetic = dof_momenta(mass, x, v)
    remapped = v + 0.02 * rng.standard_normal(v.shape)
    dofs = np.arange(6, 34)
    out = conserving_correction(mass, x, remapped, dofs, momenta, 0.998 * kinetic)
    M = sp.kron(mass, sp.eye(2), format="csr")
    A = M[dofs][:, dofs]
    delta = (out.v - remapped).ravel()[dofs]
    basis = np.column_stack([M[dofs] @ rigid_modes(x), (M @ out.v.ravel())[dofs]])
    coef = np.linalg.lstsq(basis, A @ delta, rcond=None)[0]
    assert np.linalg.norm(basis @ coef - A @ delta) < 1e-10 * np.linalg.norm(A @ delta)
    best = delta @ (A @ delta)
    for _ in range(20):  # other admissible changes: the same correction of a perturbed start
        trial = remapped.copy()
        trial.ravel()[dofs] += 0.01 * rng.standard_normal(dofs.size)
        other = conserving_correction(mass, x, trial, dofs, momenta, 0.998 * kinetic)
        change = (other.v - remapped).ravel()[dofs]
        assert change @ (A @ change) >= best * (1 - 1e-12)


def test_an_energy_out_of_reach_keeps_the_momenta_and_says_so(case):
    mass, x, v, rng = case
    momenta, kinetic = dof_momenta(mass, x, v)
    # two nodes cannot give up half the body's kinetic energy
    out = conserving_correction(mass, x, v, np.arange(4), momenta, 0.5 * kinetic)
    m2, k2 = dof_momenta(mass, x, out.v)
    assert not out.energy_restored
    assert np.abs(m2 - momenta).max() < 1e-12 * np.abs(momenta).max()
    # it gives what it can: the least K the momenta allow on those dofs, so that what is
    # missing changes continuously with the target (whatever lower target: the same v)
    assert 0.5 * kinetic < k2 < kinetic
    lower = conserving_correction(mass, x, v, np.arange(4), momenta, 0.25 * kinetic)
    np.testing.assert_allclose(lower.v, out.v, rtol=0, atol=1e-12 * np.abs(v).max())


def test_a_body_at_rest_needs_no_correction_and_no_widening(case):
    """v = 0 already carries the targets P* = 0, K* = 0: restored on the small set S as it
    is. (It said "not restored", since no change of a vanishing motion can change K, and the
    caller widened S to the whole body: the fast-sliding blocks refined 8x spent minutes per
    augmentation factoring their resting lower block, issue 17.)"""
    mass, x, _, _ = case
    rest = np.zeros_like(x)
    out = conserving_correction(mass, x, rest, np.arange(8, 20), np.zeros(3), 0.0)
    assert out.energy_restored
    assert np.array_equal(out.v, rest)
    # a target the resting body cannot reach is still reported
    assert not conserving_correction(mass, x, rest, np.arange(8, 20), np.zeros(3),
                                     1e-3).energy_restored


@pytest.mark.parametrize("lumped", [False, True], ids=["consistent", "lumped"])
def test_the_whole_body_correction_of_a_large_body_is_exact(lumped):
    """The whole-body correction (S all dofs) on the lower block of the fast-sliding blocks
    refined 8x (288 x 40 cells, 23,698 dofs, sheared): the momenta and the energy to
    round-off, from a sparse factor of M_SS (the dense one took minutes and 4.5 GB)."""
    rng = np.random.default_rng(5)
    X, cells = distorted_grid(288, 40, np.random.default_rng(0))
    X = np.column_stack([np.linspace(0, 1.8, 289)[np.arange(len(X)) % 289],
                         np.linspace(-0.2, 0.0, 41)[np.arange(len(X)) // 289]])
    X[:, 0] += 0.3 * X[:, 1]  # sheared: the mass is no multiple of a regular grid's
    mass = body_mass(X, cells, np.full(len(cells), 500.0), lumped)
    v = rng.standard_normal(X.shape)
    momenta, kinetic = dof_momenta(mass, X, v)
    out = conserving_correction(mass, X, v + 0.01 * rng.standard_normal(v.shape),
                                np.arange(v.size), momenta, kinetic)
    m2, k2 = dof_momenta(mass, X, out.v)
    assert out.energy_restored
    scale = np.abs(mass @ np.abs(v)).sum() * (1 + np.abs(X).max())
    assert np.abs(m2 - momenta).max() < 1e-12 * scale
    assert abs(k2 / kinetic - 1) < 1e-12


def remap_changes(*overrides):
    """Per remapping step of the ring impact's first 0.2 s: the change of the kinetic and strain
    energy and of the momenta that the move and remap of the obstacle made."""
    changes = []
    original = Simulation._solve_step

    def spy(self, state, contact, dt, *more, **options):
        solved = original(self, state, contact, dt, *more, **options)
        if solved.state is not state:
            before, after = self.balance(state), self.balance(solved.state)
            changes.append((after.kinetic_energy - before.kinetic_energy,
                            after.strain_energy - before.strain_energy,
                            np.subtract(after.linear_momentum, before.linear_momentum),
                            after.angular_momentum - before.angular_momentum))
        return solved

    model = model_from_example("ring_impact.toml", ["analysis.t_end=0.2", *overrides])
    recorder = Recorder()
    Simulation._solve_step = spy
    try:
        Simulation(model, [recorder]).run()
    finally:
        Simulation._solve_step = original
    energy = np.array([r.balance.total_energy for r in recorder.records])
    return changes, energy


@pytest.mark.parametrize("mass", ["consistent", "lumped"])
def test_the_ring_impacts_remap_conserves_total_energy_and_momenta(mass):
    """``conserve_energy = "total"`` without the strain-energy repair: each remap keeps
    E = K + W and both momenta (with the run's own mass matrix) to round-off, so the ALE
    run's energy error is the Newton tolerance's (measured 2e-10 over the 27 contact steps;
    1.3e-4 with the plain remap)."""
    changes, energy = remap_changes(f'analysis.mass="{mass}"',
                                    'bodies.1.ale.conserve_energy="total"',
                                    "bodies.1.ale.restore_strain_energy=false")
    assert len(changes) > 20
    E0 = energy[0]
    for dK, dW, dP, dL in changes:
        assert abs(dK + dW) < 1e-12 * E0
        assert np.abs(dP).max() < 1e-13 and abs(dL) < 1e-13  # |P0| = 3.2, |L| ~ 3
    # the remap does change W (what it hands to the velocities), by up to ~1e-3 E0 a step
    assert max(abs(c[1]) for c in changes) > 1e-5 * E0
    assert np.abs(energy / E0 - 1).max() < 1e-8


def test_kinetic_mode_keeps_the_kinetic_energy_of_each_remap():
    changes, _ = remap_changes('bodies.1.ale.conserve_energy="kinetic"')
    assert all(abs(dK) < 1e-13 for dK, *_ in changes)


@pytest.mark.parametrize("interior", ["minimal", "displacement"])
def test_the_corrections_support_does_not_depend_on_which_active_nodes_slid(interior):
    """The correction acts around every active contact node whether its slide was made or
    dropped (below ale.slide_tolerance): a sticking pair's node wants a slide of ~0, and a
    support that followed the moved nodes made the corrected velocities jump from one
    augmentation to the next (tilted blocks, mu = 10: the augmentations cycled;
    tests/test_angular_momentum.py runs that case)."""
    from ntncontact.engine.remap_conservation import _correction_nodes

    model = model_from_example("tilted_blocks.toml", [f'bodies.1.ale.interior="{interior}"'])
    setup = model.ale_bodies[0]
    motion = setup.motion
    active = motion.surface[[20, 21, 22]]
    around = np.flatnonzero(np.isin(motion.cells, active).any(axis=1))
    one = np.flatnonzero(np.isin(motion.cells, active[2]).any(axis=1))
    supports = [_correction_nodes(setup, touched, active) for touched in (around, one)]
    assert np.array_equal(supports[0], supports[1])
    assert supports[0][motion.cells[around].ravel()].all()
    # without the active nodes the support is that of the moved nodes' cells: it changes
    plain = [_correction_nodes(setup, touched, None) for touched in (around, one)]
    assert plain[0].sum() > plain[1].sum()
    if interior != "minimal":  # the interior nodes a small slide moves, and their cells
        assert supports[0].sum() > np.unique(motion.cells[around]).size


def test_the_energy_an_ale_body_cannot_give_back_comes_from_its_partner_first():
    """``hand_over_energy`` takes what an ALE body's remap left over from a Lagrangian body,
    the ALE body's contact partners before any other (a faster body elsewhere does not pay
    for this contact's remap), its momenta kept and its kinetic energy changed by exactly
    the rest; with no partner named, from the body with the most kinetic energy."""
    def body(name, origin, speed, **extra):
        return {"name": name, "mesh": {"type": "rectangle", "width": 1.0, "height": 0.5,
                                       "nx": 4, "ny": 2, "origin": list(origin)},
                "material": {"model": "neo_hookean", "E": 1000.0, "nu": 0.3, "density": 1.0},
                "initial": {"velocity": [speed, 0.0]}} | extra

    model = model_from_dict({
        "analysis": {"kind": "dynamic", "dt": 0.01, "t_end": 0.01},
        "bodies": [body("ale", (0.0, 0.0), 0.0, mesh_motion="ale"),
                   body("partner", (0.0, 0.6), 1.0), body("far", (3.0, 0.0), 2.0)],
        "contact": [{"name": "c", "body_1": "partner", "surface_1": "bottom",
                     "body_2": "ale", "surface_2": "top", "penalty_normal": 100.0}]})
    X = model.X0.copy()
    rng = np.random.default_rng(5)
    v = np.repeat([[0.0, 0.0], [1.0, 0.0], [2.0, 0.0]], 15, axis=0)
    v += 0.1 * rng.standard_normal(v.shape)
    lumped = model.analysis.mass == "lumped"

    def momenta_and_k(index, vel):
        b = model.bodies[index]
        rows = slice(b.node_offset, b.node_offset + b.mesh.n_nodes)
        mass = body_mass(X[rows], b.mesh.cells, model.assembler.rho[b.cells], lumped)
        return dof_momenta(mass, X[rows], vel[rows])

    for partners, payer, idle in ((frozenset({1}), 1, 2), (frozenset(), 2, 1)):
        out, rest = hand_over_energy(model, 0.0, X, X, v, 1e-3, partners)
        (p0, k0), (p1, k1) = momenta_and_k(payer, v), momenta_and_k(payer, out)
        assert rest == 0.0 and k1 == pytest.approx(k0 - 1e-3, rel=0, abs=1e-12)
        np.testing.assert_allclose(p1, p0, rtol=0, atol=1e-12)
        b = model.bodies[idle]
        rows = slice(b.node_offset, b.node_offset + b.mesh.n_nodes)
        np.testing.assert_array_equal(out[rows], v[rows])


@pytest.mark.parametrize("dofs", [np.arange(8, 30), np.r_[9:30, 33, 40:44]],
                         ids=["both dofs of each node", "a node with one dof"])
def test_the_mass_block_solver_inverts_the_dof_block(case, dofs):
    """``_mass_solver``: with both dofs of each node it factors the scalar node block once for
    x and y; otherwise the dof block itself. Either way A is M_SS on the dofs (M acting
    alike on x and y) and solve applies A^-1, to a vector and to columns."""
    from ntncontact.ale.conservation import _dof_block, _mass_solver

    mass, _, _, rng = case
    mass = sp.csr_matrix(mass)
    A, solve = _mass_solver(mass, dofs)
    reference = _dof_block(mass, dofs).toarray()
    np.testing.assert_array_equal(A.toarray(), reference)
    mixed = dofs[:, None] % 2 != dofs[None, :] % 2
    assert not reference[mixed].any() and reference[~mixed].any()  # x and y do not couple
    for rhs in (rng.standard_normal(dofs.size), rng.standard_normal((dofs.size, 3))):
        x = solve(rhs)
        assert x.shape == rhs.shape
        np.testing.assert_allclose(reference @ x, rhs, rtol=0, atol=1e-12 * np.abs(rhs).max()
                                   * np.linalg.cond(reference))
