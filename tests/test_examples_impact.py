"""Impact examples of the report (6.4-6.6) against its tables (slow: full runs)."""

import numpy as np
import pytest
from helpers import Recorder, model_from_example

from ntncontact.engine.simulation import Simulation

pytestmark = pytest.mark.slow


def run(name, overrides=()):
    rec = Recorder()
    sim = Simulation(model_from_example(name, list(overrides)), [rec])
    sim.run()
    energy = np.array([r.balance.total_energy for r in rec.records])
    momentum = np.array([r.balance.linear_momentum for r in rec.records])
    angular = np.array([r.balance.angular_momentum for r in rec.records])
    pressed = [r.state.time for r in rec.records
               if r.extra and np.any(r.extra["contact_rows"]["normal_traction"] > 0)]
    return rec, energy, momentum, angular, pressed


def test_fast_sliding_frictionless_conserves_energy_and_momentum():
    rec, energy, momentum, _, pressed = run("blocks_fast_sliding.toml")
    # Table 6.8 (mu = 0, consistent): 1.56 -> at most 1.5622 (0.14 %); the issue asks for 1 %.
    assert np.abs(energy - energy[0]).max() / energy[0] < 0.01
    assert energy[0] == pytest.approx(1.56, rel=1e-12)  # 1/2 0.24 (3^2 + 2^2)
    # the mid-point rule and equal and opposite contact forces: momentum to round-off (the
    # report's 1-4 % drifts come from its remap; ours conserves momentum in the remap too)
    assert np.abs(momentum - momentum[0]).max() < 1e-9
    # contact starts at 0.048 as in the report (initial gap 0.096 at vy = -2)
    assert pressed[0] - 0.003 == pytest.approx(0.048, abs=0.0031)


@pytest.mark.parametrize("mu, dissipated", [(0.1, 0.14), (0.2, 0.225)])
def test_fast_sliding_friction_dissipates_what_the_report_finds(mu, dissipated):
    rec, energy, momentum, _, _ = run("blocks_fast_sliding.toml",
                                      [f"contact.0.friction={mu}"])
    lost = (energy[0] - energy[-1]) / energy[0]
    # Table 6.8: 14 % and 22.5 %; the issue allows 3 points
    assert lost == pytest.approx(dissipated, abs=0.03)
    # the ledger: what friction dissipated is what the bodies lost (the rest is the scheme's
    # own error, which the frictionless run bounds at ~0.2 %)
    ledger = rec.records[-1].extra["frictional_dissipation"]
    assert ledger == pytest.approx(energy[0] - energy[-1], rel=0.02)
    # the work of the contact forces is (minus) what friction dissipated: the normal forces
    # do no work under the persistency condition (report 3.3.1)
    contact_work = rec.records[-1].extra["contact_work"]
    assert contact_work == pytest.approx(-ledger, rel=0.02)
    assert np.abs(momentum - momentum[0]).max() < 1e-9


def test_tilted_blocks_conserve_energy_and_momenta():
    rec, energy, momentum, angular, pressed = run("tilted_blocks.toml")
    assert energy[0] == pytest.approx(0.120, rel=1e-12)  # 1/2 0.24 1^2
    # Table 6.10: ripple 0.75 % (consistent mass); the issue asks for 1 %
    assert np.abs(energy - energy[0]).max() / energy[0] < 0.01
    # linear momentum of the free system: report within 2.75 %; the mid-point rule with
    # momentum-conserving remap keeps it to round-off
    np.testing.assert_allclose(momentum[0], [0.0, -0.24], atol=1e-12)
    assert np.abs(momentum - momentum[0]).max() < 1e-9
    # angular momentum: starts at 0; the report reaches 0.0022 (Table 6.10), the report's pair
    # forces 2.4e-4 (they act at the two nodes of a pair, apart by the penetration); the
    # moment-free ones (the default) and the remap's correction keep it to round-off:
    # 1e-10 of R |P0| (R = 1.8, |P0| = 0.24; measured 1.7e-13)
    assert abs(angular[0]) < 1e-15 and np.abs(angular).max() < 1e-10 * 1.8 * 0.24
    assert pressed and pressed[0] == pytest.approx(0.06 + 0.003, abs=0.0031)


def test_ring_impact_against_the_report():
    rec, energy, momentum, angular, pressed = run("ring_impact.toml")
    # initial energy: our polygonal ring (48 sides) has 0.24 % less area than the circle the
    # report's 1.6014 assumes: 1/2 rho A v^2 with A = 24 sin(7.5 deg) (1 - 0.49)
    area = 0.5 * 48 * np.sin(2 * np.pi / 48) * (1.0 - 0.49)
    assert energy[0] == pytest.approx(0.5 * 2.0 * area, rel=1e-12)
    # report: contact 0.065-0.815; ours starts one step later (detection after penetration)
    # and ends within 0.08 (release needs two steps without pressure)
    assert pressed[0] - 0.005 == pytest.approx(0.065, abs=0.0051)
    assert pressed[-1] == pytest.approx(0.815, abs=0.08)
    # report: energy variation < 0.8 %, momentum variation < 1.5 %, La up to 0.0365
    assert np.abs(energy - energy[0]).max() / energy[0] < 0.008
    assert np.abs(momentum - momentum[0]).max() < 1e-9
    assert np.abs(angular).max() < 1e-9
    rows = [r.extra["contact_rows"] for r in rec.records if r.extra]
    assert max(len(r["node_1"]) for r in rows) == 7  # report: at most 7 active pairs
    # The ring touches at t = 0.065 exactly, a step boundary: the sign of the round-off of that
    # zero gap decides whether the touching node is caught then (first pressure at 0.070) or
    # one step late, after penetrating v dt = 0.005 (docs/examples.md, "Detection lag"). A
    # gap moved by -1e-12 or +1e-12 gives either path in every version of the kernel.
    penetration = max(r["gap"].max() for r in rows if len(r["gap"]))
    if pressed[0] == pytest.approx(0.070, abs=1e-9):
        assert 0.0 < penetration < 0.005
    else:
        assert penetration == pytest.approx(0.005, rel=1e-6)


def test_fast_sliding_with_lumped_mass_stays_within_table_6_8():
    _, energy, momentum, _, _ = run("blocks_fast_sliding.toml", ['analysis.mass="lumped"'])
    # Table 6.8, mu = 0 lumped: the report's energy varies by up to 1.2 % (min 1.5413)
    assert np.abs(energy - energy[0]).max() / energy[0] < 0.012
    assert np.abs(momentum - momentum[0]).max() < 1e-9


def test_tilted_blocks_with_large_friction_nearly_stick():
    rec, energy, momentum, angular, _ = run("tilted_blocks.toml", ["contact.0.friction=10"])
    # Table 6.10, mu = 10: the energy stays within 1.7 % (0.118-0.121); the pairs stick
    assert np.abs(energy - energy[0]).max() / energy[0] < 0.017
    assert np.abs(momentum - momentum[0]).max() < 1e-9
    assert np.abs(angular).max() < 5.2e-4  # the report's largest |Ma| for mu = 10
    statuses = np.concatenate([r.extra["contact_rows"]["status"] for r in rec.records
                               if r.extra and len(r.extra["contact_rows"]["status"])])
    assert np.mean(statuses == "stick") > 0.5


def test_tilted_blocks_friction_dissipation_is_steep_around_mu_0_2():
    """Table 6.10 loses 9.2 % with mu = 0.2, we lose 5.8 %: not a bookkeeping error (friction
    dissipated what the bodies lost), but the loss falls steeply from mu = 0.15 to 0.3 (8.6,
    5.8, 2.3 %) as the sliding gives way to sticking; our mu = 0.15 run follows the report's
    mu = 0.2 energy history within the table's rounding (docs/validation.md, 6.6)."""
    from ntncontact.report.reference import table

    ref = table("tilted_blocks_table_6_10")
    losses = {}
    for mu in (0.15, 0.2):
        rec, energy, momentum, _, _ = run("tilted_blocks.toml", [f"contact.0.friction={mu}"])
        losses[mu] = (energy[0] - energy[-1]) / energy[0]
        ledger = rec.records[-1].extra["frictional_dissipation"]
        assert ledger == pytest.approx(energy[0] - energy[-1], rel=0.02)
        assert rec.records[-1].extra["contact_work"] == pytest.approx(-ledger, rel=0.02)
        assert np.abs(momentum - momentum[0]).max() < 1e-9
        times = np.array([r.state.time for r in rec.records])
        gap = np.abs(np.interp(ref["time"], times, energy) - ref["mu0.2_total_energy"]).max()
        # the report's mu = 0.2 history: within 0.0025 (2 % of E0) of our mu = 0.15 run, 0.0045
        # away from our mu = 0.2 run
        assert (gap < 0.0025) if mu == 0.15 else (gap > 0.004)
    assert losses[0.2] == pytest.approx(0.058, abs=0.005)
    assert losses[0.15] > losses[0.2] + 0.02
