"""The remap's strain-energy repair (ale.strain_repair, engine.remap_conservation): the
configurational force is dW/dX at fixed x, a node of a point-loaded block slid by the ALE
changes W to first order, and the repair restores W to round-off with a change of X within
the remap's own ambiguity, leaving positions, the reference outline and (after the velocity
correction) momenta and kinetic energy exact."""

import numpy as np
import pytest
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from helpers import Recorder, energy_after_each_episode, model_from_example

from ntncontact.ale.conservation import conserving_correction, dof_momenta
from ntncontact.ale.motion import AleBody, lumped_masses, move_ale_body
from ntncontact.ale.strain_repair import StrainRepair, restore_strain_energy
from ntncontact.engine.remap_conservation import body_mass
from ntncontact.engine.simulation import Simulation
from ntncontact.fem.assembly import Assembler, MaterialGroup
from ntncontact.fem.kernels_numba import MODEL_CODES
from ntncontact.mesh.generators import rectangle
from ntncontact.mesh.quality import cell_min_sines

LAM, MU = 60.0, 40.0
MODELS = ["linear_elastic", "neo_hookean"]


def material(mesh, model):
    m = len(mesh.cells)
    return StrainRepair(mesh.cells.astype(np.int64), np.full(m, MODEL_CODES[model]),
                        np.full(m, LAM), np.full(m, MU))


@pytest.mark.parametrize("model", MODELS)
def test_the_configurational_force_is_the_strain_energys_derivative_at_fixed_positions(model):
    rng = np.random.default_rng(5)
    mesh = rectangle(1.5, 1.0, 3, 2)
    X = mesh.nodes + 0.04 * rng.standard_normal(mesh.nodes.shape)
    x = X + 0.08 * rng.standard_normal(X.shape)
    repair = material(mesh, model)
    cells = np.arange(len(mesh.cells))
    _, g, ok = repair.energy_and_force(X, x - X, cells)
    assert ok
    h, fd = 1e-6, np.zeros_like(X)
    for a in range(len(X)):
        for i in range(2):
            up, down = X.copy(), X.copy()
            up[a, i] += h
            down[a, i] -= h
            fd[a, i] = (repair.energy(up, x - up, cells)
                        - repair.energy(down, x - down, cells)) / (2 * h)
    # central differences: error h^2 W''' ~ 1e-12 and round-off eps W / h ~ 1e-10
    assert np.abs(fd - g).max() < 1e-8 * np.abs(g).max()


def pressed_block(model, load=(0.6, -4.0)):
    """A 2 x 1 block (16 x 8), held at its bottom, in equilibrium under a point force at the
    top node nearest x = 1.05 (Newton on the compiled kernel's force and tangent)."""
    mesh = rectangle(2.0, 1.0, 16, 8)
    X = mesh.nodes
    n = len(X)
    m = len(mesh.cells)
    asm = Assembler(mesh.cells, n, [MaterialGroup(model, np.arange(m))], np.full(m, LAM),
                    np.full(m, MU), np.ones(m))
    top = mesh.node_sets["top"]
    node = int(top[np.argmin(np.abs(X[top, 0] - 1.05))])
    f = np.zeros(2 * n)
    f[2 * node: 2 * node + 2] = load
    free = np.flatnonzero(np.repeat(X[:, 1] > 1e-12, 2))
    d = np.zeros(2 * n)
    for _ in range(30):
        force, K, _ = asm.internal(X, d=d.reshape(-1, 2))
        r = (f - force)[free]
        if np.linalg.norm(r) < 1e-12 * np.linalg.norm(load):
            break
        d[free] += spla.spsolve(sp.csc_matrix(K[free][:, free]), r)
    return mesh, d.reshape(-1, 2), node


def slide(mesh, d, node, distance):
    """The ALE move of the loaded node along the top by ``distance`` (only the surface moves)."""
    body = AleBody.from_mesh(mesh, "top")
    X = mesh.nodes
    x = X + d
    zero = np.zeros_like(X)
    target = x[node] + distance * np.array([1.0, 0.0])
    return body, move_ale_body(body, X, d, zero, zero, [node], target[None], x[node][None], 0.01)


@pytest.mark.parametrize("model", MODELS)
def test_a_slid_loaded_node_changes_w_to_first_order_and_the_repair_restores_it(model):
    mesh, d, node = pressed_block(model)
    repair = material(mesh, model)
    cells = np.arange(len(mesh.cells))
    X0 = mesh.nodes
    W0 = repair.energy(X0, d, cells)
    h = 0.125
    changes = {}
    for s in (0.02 * h, 0.01 * h):
        body, up = slide(mesh, d, node, s)
        changes[s] = repair.energy(up.X, up.x_mesh - up.X, cells) - W0
    # first order in the slide: halving it halves the change (a smooth field: quarters it)
    ratio = changes[0.02 * h] / changes[0.01 * h]
    assert ratio == pytest.approx(2.0, rel=0.1)
    assert abs(changes[0.02 * h]) > 1e-4 * W0
    # the repair on the interior nodes of the cells around the move
    free = body.within_layers(up.moved, 1) & ~body.boundary
    result = restore_strain_energy(repair, up.X, up.x_mesh, free, lumped_masses(X0, mesh.cells),
                                   cells, W0, 1e-13 * W0)
    assert result.restored
    W = repair.energy(result.X, up.x_mesh - result.X, cells)
    assert abs(W - W0) <= 1e-13 * W0  # from 1e-4 W0: nine orders
    delta = np.linalg.norm(result.X - up.X, axis=1)
    assert np.array_equal(delta > 0, free & (delta > 0)) and (delta[free] > 0).any()
    # a relabel of the order of the slide (measured 2.5-2.8 x the slide and 2.6 x the
    # one-sided interpolants' spread at the moved node: the interior nodes' configurational
    # forces are second order in the load, docs/theory.md): the reference cells stay sound
    assert delta.max() < 5 * 0.01 * h
    assert cell_min_sines(result.X, mesh.cells).min() > 0.95
    # the reference outline the remap left, hence the total reference area, is kept
    assert lumped_masses(result.X, mesh.cells).sum() == pytest.approx(
        lumped_masses(up.X, mesh.cells).sum(), rel=1e-14)


def test_after_the_repair_the_velocity_correction_keeps_momenta_and_kinetic_energy():
    """The repair changes X, hence the mass matrix; the velocity correction that follows (as in
    engine.remap_conservation) sees the repaired masses: momenta about the origin and K exact."""
    mesh, d, node = pressed_block("neo_hookean")
    repair = material(mesh, "neo_hookean")
    cells = np.arange(len(mesh.cells))
    X0 = mesh.nodes
    body, up = slide(mesh, d, node, 0.01)
    free = body.within_layers(up.moved, 1) & ~body.boundary
    result = restore_strain_energy(repair, up.X, up.x_mesh, free, lumped_masses(X0, mesh.cells),
                                   cells, repair.energy(X0, d, cells), 1e-14)
    rng = np.random.default_rng(2)
    v = rng.standard_normal(X0.shape)
    rho = np.full(len(cells), 3.0)
    for lumped in (False, True):
        momenta, kinetic = dof_momenta(body_mass(X0, mesh.cells, rho, lumped), X0 + d, v)
        mass = body_mass(result.X, mesh.cells, rho, lumped)
        out = conserving_correction(mass, up.x_mesh, v, np.arange(v.size), momenta, kinetic)
        m2, k2 = dof_momenta(mass, up.x_mesh, out.v)
        assert out.energy_restored
        assert np.abs(m2 - momenta).max() < 1e-13 * np.abs(momenta).max()
        assert k2 == pytest.approx(kinetic, rel=1e-14)


def test_w_out_of_reach_leaves_x_and_says_so():
    mesh, d, node = pressed_block("linear_elastic")
    repair = material(mesh, "linear_elastic")
    cells = np.arange(len(mesh.cells))
    body, up = slide(mesh, d, node, 0.01)
    free = body.within_layers(up.moved, 1) & ~body.boundary
    # relabelling a few nodes cannot take away half the strain energy
    W0 = repair.energy(mesh.nodes, d, cells)
    result = restore_strain_energy(repair, up.X, up.x_mesh, free,
                                   lumped_masses(mesh.nodes, mesh.cells), cells, 0.5 * W0,
                                   1e-13 * W0)
    assert not result.restored
    assert np.array_equal(result.X, up.X)


def ring_remap_changes(*overrides):
    """Per remapping step of the ring impact's first 0.2 s: (dK, dW, dP, dL) of the move."""
    from test_remap_conservation import remap_changes

    return remap_changes(*overrides)


@pytest.mark.parametrize("mass", ["consistent", "lumped"])
def test_the_ring_impacts_remap_keeps_k_w_and_momenta_each(mass):
    """The repair with conserve_energy = "kinetic": every remap of the ring impact's
    first 0.2 s keeps K and W each (W to the repair's 1e-12 of the obstacle's W, K and the
    momenta to round-off), and E to the Newton tolerance (measured 1.5e-10; 1.3e-4 with the
    plain remap)."""
    changes, energy = ring_remap_changes(f'analysis.mass="{mass}"',
                                         'bodies.1.ale.conserve_energy="kinetic"')
    assert len(changes) > 20
    E0 = energy[0]
    for dK, dW, dP, dL in changes:
        assert abs(dK) < 1e-13 * E0 and abs(dW) < 1e-12 * E0
        assert np.abs(dP).max() < 1e-13 and abs(dL) < 1e-13  # |P0| = 3.2, |L| ~ 3
    assert np.abs(energy / E0 - 1).max() < 1e-8


def test_the_ring_impact_remaps_change_less_than_1e_6_of_e0_per_impact():
    """Issue 16 item 3's aim on examples/ring_impact.toml: over the whole impact the remaps
    change the strain energy by < 1e-6 E0 (measured 1.7e-12; 4.3e-4 net and 2.3e-3 summed
    over the steps with the plain remap); the energy varies by < 1e-8 (measured 2.5e-10;
    5.9e-4), contact ends at 0.875 as with the plain remap and the momentum is kept to
    round-off. The whole example: 19 s on a loaded machine, so not marked slow."""
    rec = Recorder()
    Simulation(model_from_example("ring_impact.toml"), [rec]).run()
    assert rec.status == ("completed", None)
    E0 = rec.records[0].balance.total_energy
    remap = np.array([r.extra.get("ale_remap_energy", 0.0) for r in rec.records[1:]])
    assert np.abs(np.diff(remap, prepend=0.0)).sum() < 1e-6 * E0
    error, ends = energy_after_each_episode(rec)
    assert np.abs(error).max() < 1e-8
    pressed = [r.state.time for r in rec.records
               if r.extra and np.any(r.extra["contact_rows"]["normal_traction"] > 0)]
    assert pressed[-1] == pytest.approx(0.875, abs=1e-9)
    momentum = np.array([r.balance.linear_momentum for r in rec.records])
    assert np.abs(momentum - momentum[0]).max() < 1e-9


def test_the_quadratic_step_finds_the_root_of_an_exact_quadratic():
    """The line search's shortened step: through psi0, its slope and one trial, the fitted
    quadratic is the function itself when that is quadratic, so the step is its root (its
    smaller one), else its minimum; a concave fit gives 0 (the caller halves instead)."""
    from ntncontact.ale.strain_repair import _quadratic_step

    psi0, slope, c = 1.0, -3.0, 2.0  # roots 0.5 and 1.0
    psi = lambda t: psi0 + slope * t + c * t * t  # noqa: E731
    assert _quadratic_step(psi0, slope, 1.5, psi(1.5)) == pytest.approx(0.5, rel=1e-14)
    c = 4.0  # no root: the minimum at 3 / 8
    assert _quadratic_step(psi0, slope, 1.5, psi(1.5)) == pytest.approx(0.375, rel=1e-14)
    assert _quadratic_step(psi0, slope, 1.0, psi0 + slope) == 0.0  # linear: no curvature


@pytest.mark.slow
def test_the_repair_does_not_crawl_on_a_refined_mesh():
    """Fast-sliding blocks refined 4x (t <= 0.093): the interior's configurational forces are
    small beside W's curvature along them, so Newton's full step overshoots. Halving it alone
    (before session 28) the residual fell ~0.8 an iteration, 69 of 127 repairs ran all 30
    iterations, and the remaps handed 6.52e-5 E0 from W to K; with the fitted step and
    conjugate directions, measured 1.95e-5 E0. Bound: half the old figure. The energy itself
    is kept either way (E_end / E0 - 1 = 6e-13: what a repair does not restore, the velocity
    correction hands over)."""
    from helpers import EXAMPLES, refined

    from ntncontact import api

    results = api.run(api.load_scenario(EXAMPLES / "blocks_fast_sliding.toml",
                                        refined(4, 0.093)), None)
    history = results.history
    e0 = history["total_energy"].iloc[0]
    assert history["ale_remap_energy"].iloc[-1] < 0.5 * 6.52e-5 * e0
    assert abs(history["total_energy"].iloc[-1] / e0 - 1.0) < 1e-10


OBLIQUE = """
title = "a spinning disk hits a free spinning ALE block obliquely (an independent tester's)"
[analysis]
kind = "dynamic"
dt = 0.004
t_end = 0.3
output_interval = 0.3
[[bodies]]
name = "disk"
mesh = { type = "disk", radius = 0.5, n_circ = 32, n_radial = 3, center = [0.0, 0.56] }
material = { model = "neo_hookean", E = 1000.0, nu = 0.3, density = 1.0 }
initial = { velocity = [0.5, -1.0], angular_velocity = 2.0 }
[[bodies]]
name = "block"
mesh_motion = "ale"
mesh = { type = "rectangle", width = 3.0, height = 0.4, nx = 30, ny = 4, origin = [-1.5, -0.4] }
material = { model = "neo_hookean", E = 2000.0, nu = 0.3, density = 1.0 }
initial = { velocity = [-0.3, 0.2], angular_velocity = -0.3 }
[[contact]]
body_1 = "disk"
surface_1 = "outer"
body_2 = "block"
surface_2 = "top"
penalty_normal = 2000.0
"""


@pytest.mark.parametrize("shift", [100.0, 1000.0])
def test_a_translated_ale_impact_runs_as_at_the_origin(tmp_path, shift):
    """A tester's oblique impact moved by (shift, shift): the repair's W reached its target
    (1e-12) in 126 of 166 repairs at +100, and the run ended 0.7 % apart in kinetic energy;
    at +1000 its augmentations failed at t = 0.09. The repair now works from a whole-number
    point near its nodes. Bound: positions at |x| ~ 1000 carry 1.1e-13 of round-off, 1e-12 of
    an element of 0.1, so the energies may differ by ~1e-11 of their scale, not more."""
    import ntncontact as ntc

    path = tmp_path / "oblique.toml"
    path.write_text(OBLIQUE)
    moved = {f"bodies.{b}.mesh.transform": {"translate": [shift, shift]} for b in (0, 1)}
    here, there = (ntc.run(ntc.load_scenario(path, sets), None).history
                   for sets in ({}, moved))
    assert len(here) == len(there) == 76 and here["active_pairs"].max() > 0
    assert here["newton_iterations"].tolist() == there["newton_iterations"].tolist()
    scale = here["total_energy"].abs().max()
    for column in ("kinetic_energy", "strain_energy", "total_energy"):
        assert np.abs(here[column] - there[column]).max() < 1e-9 * scale, column


def test_the_repair_of_a_translated_block_is_the_repair_at_the_origin():
    """The repaired reference positions do not depend on where the body sits: at (1000, -700)
    the iteration on x - X lost W's last digits to the positions' round-off and could not
    reach 1e-13 of W (the origin's test above asks for it)."""
    mesh, d, node = pressed_block("neo_hookean")
    repair = material(mesh, "neo_hookean")
    cells = np.arange(len(mesh.cells))
    W0 = repair.energy(mesh.nodes, d, cells)
    body, up = slide(mesh, d, node, 0.02 * 0.125)
    free = body.within_layers(up.moved, 1) & ~body.boundary
    weights = lumped_masses(mesh.nodes, mesh.cells)
    at_origin = restore_strain_energy(repair, up.X, up.x_mesh, free, weights, cells, W0,
                                      1e-13 * W0)
    shift = np.array([1000.0, -700.0])
    moved = restore_strain_energy(repair, up.X + shift, up.x_mesh + shift, free, weights, cells,
                                  W0, 1e-13 * W0)
    assert at_origin.restored and moved.restored
    assert moved.iterations == at_origin.iterations
    # the shifted positions are rounded to 1.1e-13 there, and the repair's answer moves by a
    # few times that (measured 4.8e-13, against a relabel of ~1e-3)
    assert np.abs(moved.X - shift - at_origin.X).max() < 2e-12
