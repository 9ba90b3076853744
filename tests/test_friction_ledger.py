"""Frictional runs (issue 16 item 5): the energy never increases, the frictional dissipation
grows at every step, and the ledger E + D_friction - W_ext - R closes to 1e-6 E0 at every step
(R = ale_remap_energy, the strain energy the ALE remaps changed: with conserve_energy =
"kinetic" it is part of E's change, with the default "total" the remap hands it to the
velocities and R does not enter E)."""

import numpy as np
import pytest
from helpers import Recorder, model_from_dict, model_from_example

from ntncontact.engine.simulation import Simulation

# per step, the energy balance of the integrator closes to the Newton tolerance (rtol 1e-10 of
# the forces in play) and the remap's to round-off: an "increase" below this is round-off
ROUND_OFF = 1e-9


def ledger(recorder, total: bool):
    """(E - R, D, W_ext) per record; D, W_ext and R are cumulative (R left out of E with
    ``total``: the remap already conserved E)."""
    E = np.array([r.balance.total_energy for r in recorder.records])
    D = np.array([r.extra.get("frictional_dissipation", 0.0) for r in recorder.records])
    W = np.array([r.extra.get("external_work", 0.0) for r in recorder.records])
    R = np.array([r.extra.get("ale_remap_energy", 0.0) for r in recorder.records])
    return (E if total else E - R), D, W


def check_ledger(recorder, min_dissipation, total: bool = True):
    E, D, W = ledger(recorder, total)
    E0 = E[0]
    assert recorder.status == ("completed", None)
    assert D[-1] > min_dissipation * E0  # friction really acts
    assert np.all(np.diff(D) >= 0.0)  # dissipation >= 0 at every step
    assert np.all(np.diff(E) <= ROUND_OFF * E0)  # no external loads: E never increases
    assert np.abs(E + D - W - E0).max() < 1e-6 * E0
    return np.abs(E + D - W - E0).max() / E0


@pytest.mark.parametrize("mass", ["consistent", "lumped"])
def test_fast_sliding_blocks_with_friction_close_the_energy_ledger(mass):
    """Report 6.5 with mu = 0.2: 23 % of E0 is dissipated; the ledger closes to 1e-11 (measured;
    before the remap conserved energy it was off by the remap's ~1e-3)."""
    rec = Recorder()
    model = model_from_example("blocks_fast_sliding.toml",
                               ["contact.0.friction=0.2", f'analysis.mass="{mass}"'])
    Simulation(model, [rec]).run()
    check_ledger(rec, 0.1)


def skidding_block(mesh_motion):
    """Own case: a Neo-Hookean 0.6 x 0.3 block (6 x 3) lands at v = (2, -1) on a slab
    (2.4 x 0.2, 12 x 2, held at its bottom) whose top nodes do not match the block's
    (spacing 0.2 against 0.1), and skids along it with mu = 0.3."""
    soft = {"model": "neo_hookean", "E": 60.0, "nu": 0.3, "density": 1.0}
    slab = {"name": "slab", "material": {"model": "neo_hookean", "E": 300.0, "nu": 0.25,
                                         "density": 3.0},
            "mesh": {"type": "rectangle", "width": 2.4, "height": 0.2, "nx": 12, "ny": 2,
                     "origin": [-0.6, -0.2]},
            "supports": [{"set": "bottom", "x": 0.0, "y": 0.0}], "mesh_motion": mesh_motion}
    if mesh_motion == "ale":
        slab["ale"] = {"smoothing_layers": 1}
    return model_from_dict({
        "analysis": {"kind": "dynamic", "dt": 0.005, "t_end": 0.3},
        "bodies": [{"name": "block", "material": soft, "initial": {"velocity": [2.0, -1.0]},
                    "mesh": {"type": "rectangle", "width": 0.6, "height": 0.3, "nx": 6,
                             "ny": 3, "origin": [-0.5, 0.03]}}, slab],
        "contact": [{"body_1": "block", "surface_1": "bottom", "body_2": "slab",
                     "surface_2": "top", "method": "augmented_lagrangian",
                     "law": "persistency", "penalty_normal": 1000.0,
                     "penalty_tangential": 1000.0, "friction": 0.3}],
    })


def test_a_block_skidding_on_an_ale_slab_closes_the_energy_ledger():
    rec = Recorder()
    Simulation(skidding_block("ale"), [rec]).run()
    check_ledger(rec, 0.01)


def test_fast_sliding_with_friction_keeps_angular_momentum_with_an_exact_remap():
    """Free bodies, one of them ALE, mu = 0.2: with moment-free pair forces (the dynamic
    default, not set here) and the remap's exact momentum correction (with the run's consistent
    mass) L stays to round-off (measured 9e-12 of |L0| = 0.141; 1.2-1.6 % with the report's
    forces and the earlier lumped-mass correction, issue 16)."""
    rec = Recorder()
    model = model_from_example("blocks_fast_sliding.toml",
                               ["contact.0.friction=0.2"])
    Simulation(model, [rec]).run()
    L = np.array([r.balance.angular_momentum for r in rec.records])
    P = np.array([r.balance.linear_momentum for r in rec.records])
    size = np.ptp(model.X0, axis=0).max()
    assert rec.status == ("completed", None)
    assert np.abs(L - L[0]).max() < 1e-10 * (abs(L[0]) + size * np.linalg.norm(P[0]))
    check_ledger(rec, 0.1)
