"""The energy-conserving Lagrange-multiplier variant (report 5.5)."""

import numpy as np
import pytest
from helpers import Recorder, model_from_example

from ntncontact.contact import PairState
from ntncontact.dynamics.energy import EnergyConstraint
from ntncontact.interfaces import contact_terms, lagrange_terms
from ntncontact.problem import StepProblem, StepState
from ntncontact.simulation import Simulation


def rods_in_contact():
    model = model_from_example("rod_impact.toml", [
        'contact.0.method="lagrange"', 'contact.0.law="gap"', "analysis.energy_conserving=true"])
    sim = Simulation(model)
    rng = np.random.default_rng(3)
    ci = model.interfaces[0]
    pairs = np.column_stack([ci.interface.surface1.nodes, ci.interface.surface2.nodes])
    contact = (PairState.from_pairs(pairs).with_multipliers(np.full(2, 4.0)),)
    d = 1e-3 * rng.standard_normal(model.X0.shape)
    v = np.zeros_like(d)
    v[model.body("rod_left").nodes, 0] = 1.0
    state = StepState(3, 0.1, model.X0, d, v, np.zeros_like(d), contact)
    return model, sim, state


def test_bordered_energy_system_jacobian_matches_central_differences():
    model, sim, state = rods_in_contact()
    dt = 0.05
    mass = sim._dof_mass(state)
    energy = EnergyConstraint(model.assembler, mass, state.X, state.d.ravel(), state.v.ravel(),
                              dt, sim.balance(state).total_energy, lambda_start=0.1)
    problem = StepProblem(model, state, dt, mass, contact_terms(model.interfaces, state.contact,
                                                                dt),
                          lagrange_terms(model.interfaces, state.contact, dt) + [energy])
    y = problem.initial_guess() + 1e-3 * np.random.default_rng(4).standard_normal(
        problem.initial_guess().size)
    J = problem.jacobian(y).toarray()
    h = 1e-6
    for k in np.random.default_rng(5).choice(y.size, 12, replace=False).tolist() + [y.size - 1]:
        e = np.zeros(y.size)
        e[k] = h
        fd = (problem.residual(y + e)[0] - problem.residual(y - e)[0]) / (2 * h)
        # central differences: O(h^2) truncation and O(eps/h) round-off relative to O(|J|)
        np.testing.assert_allclose(fd, J[:, k], rtol=1e-5, atol=1e-6 * np.abs(J).max())


@pytest.mark.slow
def test_energy_conserving_rod_impact_keeps_energy_to_the_solver_tolerance():
    model = model_from_example("rod_impact.toml", [
        'contact.0.method="lagrange"', 'contact.0.law="gap"', "analysis.energy_conserving=true"])
    rec = Recorder()
    Simulation(model, [rec]).run()
    energy = np.array([r.balance.total_energy for r in rec.records])
    assert np.abs(energy - energy[0]).max() < 1e-8 * energy[0]
    px = np.array([r.balance.linear_momentum[0] for r in rec.records])
    assert np.abs(px - px[0]).max() < 1e-9


def test_end_energy_is_the_energy_of_the_mid_point_update():
    """E_{n+1}(d_{n+1/2}) equals the balance of the state the mid-point update produces."""
    from ntncontact.dynamics.midpoint import end_of_step

    model, sim, state = rods_in_contact()
    dt = 0.05
    energy = EnergyConstraint(model.assembler, sim._dof_mass(state), state.X, state.d.ravel(),
                              state.v.ravel(), dt, 0.0)
    d_half = state.d + 0.5 * dt * state.v + 1e-3
    d1, v1, a1 = end_of_step(d_half, state.d, state.v, dt)
    expected = sim.balance(StepState(4, 0.15, state.X, d1, v1, a1)).total_energy
    assert energy.end_energy(d_half.ravel())[0] == pytest.approx(expected, rel=1e-13)
