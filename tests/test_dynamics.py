"""Mid-point rule verification: conservation laws of free bodies, linear free vibration."""

import numpy as np
import pytest
from helpers import Recorder, model_from_dict, model_from_example

from ntncontact.engine.simulation import Simulation


def history(recorder):
    b = [r.balance for r in recorder.records]
    energy = np.array([x.total_energy for x in b])
    lin = np.array([x.linear_momentum for x in b])
    ang = np.array([x.angular_momentum for x in b])
    return energy, lin, ang


def test_spinning_neo_hookean_block_conserves_momenta_to_round_off():
    """The report's mid-point rule (the energy-momentum integrator: test_energy_momentum)."""
    model = model_from_example("spinning_block.toml", ['analysis.integrator="midpoint"'])
    rec = Recorder()
    Simulation(model, [rec]).run()
    energy, lin, ang = history(rec)
    assert rec.status == ("completed", None)
    assert len(rec.records) == 101
    # The mid-point rule conserves linear and angular momentum exactly (quadratic invariants);
    # what is left is the Newton tolerance (1e-10 relative) and round-off over 100 steps.
    assert np.abs(lin - lin[0]).max() < 1e-12 * np.abs(lin[0]).max()
    assert np.abs(ang - ang[0]).max() < 1e-11 * abs(ang[0])
    # Energy: the mid-point rule is not exactly energy-conserving for Neo-Hookean; measured
    # 6.4e-4 relative drift over 2 s with dt = 0.02 (about 1/5 of the block's lowest period).
    assert np.abs(energy - energy[0]).max() / energy[0] < 1e-3
    # Initial values: m = rho A = 0.5, v = (1, 0.5), L = m v; spin omega = 3 about the centre.
    np.testing.assert_allclose(lin[0], [0.5, 0.25], rtol=1e-13)
    inertia = 0.5 * (1.0**2 + 0.5**2) / 12.0
    assert ang[0] == pytest.approx(3.0 * inertia, rel=1e-12)


def vibrating_bar(mass="consistent"):
    return model_from_dict({
        "analysis": {"kind": "dynamic", "dt": 0.01, "t_end": 0.5, "mass": mass},
        "bodies": [{
            "name": "bar",
            "mesh": {"type": "rectangle", "width": 2.0, "height": 0.5, "nx": 8, "ny": 2},
            "material": {"model": "linear_elastic", "E": 100.0, "nu": 0.25, "density": 1.0},
            "initial": {"angular_velocity": 0.5},
            "supports": [{"set": "left", "x": 0.0, "y": 0.0}],
        }],
    })


@pytest.mark.parametrize("mass", ["consistent", "lumped"])
def test_linear_free_vibration_conserves_energy_exactly(mass):
    rec = Recorder()
    Simulation(vibrating_bar(mass), [rec]).run()
    energy, _, _ = history(rec)
    # For a linear system the mid-point rule conserves the quadratic energy exactly: only the
    # Newton tolerance (rtol 1e-10) and round-off remain.
    assert np.abs(energy - energy[0]).max() / energy[0] < 1e-9
    # ... and energy really moves between kinetic and strain forms (the test is not trivial)
    strain = np.array([r.balance.strain_energy for r in rec.records])
    assert strain.max() > 0.3 * energy[0]


def test_mid_point_free_vibration_period_matches_modal_analysis():
    """A fixed-free bar oscillating axially: period from the generalized eigenproblem."""
    import scipy.linalg as sla

    model = vibrating_bar()
    sim = Simulation(model)
    free = np.setdiff1d(np.arange(model.ndof), np.concatenate([p.dofs for p in model.prescribed]))
    _, K, _ = model.assembler.internal(model.X0, d=np.zeros_like(model.X0))
    M = model.assembler.mass(model.X0, lumped=False)
    w2, modes = sla.eigh(K[free][:, free].toarray(), M[free][:, free].toarray())
    omega = np.sqrt(w2[0])
    # Start in the first mode: v = 0, d = small amplitude * mode; compare the period.
    from ntncontact.engine.problem import StepState

    d = np.zeros(model.ndof)
    d[free] = 1e-3 * modes[:, 0] / np.abs(modes[:, 0]).max()
    state = StepState(0, 0.0, model.X0, d.reshape(-1, 2), np.zeros_like(model.X0),
                      np.zeros_like(model.X0))
    dt = 2 * np.pi / omega / 200
    tip = []
    for _ in range(400):
        state, _ = sim.advance(state, dt)
        tip.append(state.d.ravel()[free][np.argmax(np.abs(modes[:, 0]))])
    tip = np.array(tip)
    crossings = np.flatnonzero(np.diff(np.sign(tip)) > 0)
    period = np.diff(crossings).mean() * dt
    # The mid-point rule's period elongation: T_h / T = 1 + (omega dt)^2 / 12 + ... ~ 8e-5 here.
    assert period == pytest.approx(2 * np.pi / omega, rel=2e-3)


def test_energy_ledger_closes_for_a_block_under_gravity():
    """history's external_work: for the mid-point rule under a constant force, the kinetic
    energy gained equals f . (x_{n+1} - x_n) exactly (a free block stays unstrained)."""
    model = model_from_dict({
        "analysis": {"kind": "dynamic", "dt": 0.05, "t_end": 0.5},
        "bodies": [{
            "name": "block",
            "mesh": {"type": "rectangle", "width": 1.0, "height": 1.0, "nx": 3, "ny": 3},
            "material": {"model": "neo_hookean", "E": 10.0, "nu": 0.3, "density": 2.0},
            "initial": {"velocity": [1.0, 0.0]},
            "loads": [{"type": "body_force", "vector": [0.0, -19.62]}],
        }],
    })
    rec = Recorder()
    Simulation(model, [rec]).run()
    energy = np.array([r.balance.total_energy for r in rec.records])
    work = np.array([r.extra.get("external_work", 0.0) for r in rec.records])
    np.testing.assert_allclose(energy - energy[0], work, atol=1e-10 * energy.max())
    # falling 1/2 g t^2 = 2.4525 with mass 2: work = m g h = 2 * 9.81 * 1.22625
    assert work[-1] == pytest.approx(2.0 * 9.81 * 0.5 * 9.81 * 0.25, rel=1e-10)
