"""examples/disk_drop.toml (the tutorial's dynamic step) at reduced length: a disk dropped with
friction onto an ALE block under gravity, checked against rigid-body rolling theory."""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest
from helpers import EXAMPLES, Recorder, model_from_example, offsets_across_normal

from ntncontact.ale.surface import SurfaceCurve
from ntncontact.cli import main
from ntncontact.engine.simulation import Simulation

SPACING = 0.1  # the block's surface spacing (4.0 / 40); the disk's is 0.098
V0, MU, G = 2.0, 0.3, 10.0
#: the run stops at 0.3: a rigid disk rolls from v0 / (3 mu g) = 0.22 on
REDUCED = ["analysis.t_end=0.3"]


def run(overrides=()):
    rec = Recorder()
    sim = Simulation(model_from_example("disk_drop.toml", REDUCED + list(overrides)), [rec])
    sim.run()
    assert rec.status == ("completed", None)
    return sim, rec


def energy_error(rec) -> np.ndarray:
    """E_n - E_0 - (work of gravity and of the contact forces, friction's included)."""
    return np.array([r.balance.total_energy - rec.records[0].balance.total_energy
                     - r.extra.get("external_work", 0.0) - r.extra.get("contact_work", 0.0)
                     for r in rec.records[1:]])


def surface_offsets(chain, x, rows) -> np.ndarray:
    """Distance along the block's surface between each pair's nodes: along the tangent of the
    block's surface curve (node chain ``chain`` at positions ``x``) at the pair's block node."""
    where = {int(n): k for k, n in enumerate(chain)}
    tangents = SurfaceCurve.from_chain(x[chain]).node_tangents(
        [where[int(n)] for n in rows["node_2"]])
    return np.abs(np.einsum("ij,ij->i", x[rows["node_1"]] - x[rows["node_2"]], tangents))


@pytest.fixture(scope="module")
def ale_run():
    return run()


def test_the_disk_slips_then_rolls_and_friction_takes_a_third(ale_run):
    """Coulomb friction brakes the slide and spins the disk up until it rolls. For a rigid
    uniform disk the friction work is then a third of the initial kinetic energy, whatever the
    normal force did meanwhile (angular momentum about the contact point is kept): the elastic
    disk's vibrations and the 32-gon's moment of inertia (0.3 % below a disk's) move it by
    the 2.8 % measured (-1.9 % with the report's pair normal, ``ale_normal = false``); 3 % is
    the bound."""
    sim, rec = ale_run
    statuses = [set(r.extra["contact_rows"]["status"]) for r in rec.records[1:]
                if r.extra["contact_rows"]["node_1"].size]
    assert "slip" in statuses[0] and any("stick" in s for s in statuses[-10:])
    kinetic0 = rec.records[0].balance.kinetic_energy
    assert kinetic0 == pytest.approx(0.5 * np.pi * 0.25 * 0.9936 * V0**2, rel=1e-3)
    dissipated = rec.records[-1].extra["frictional_dissipation"]
    assert dissipated == pytest.approx(kinetic0 / 3.0, rel=0.03)


def test_no_penetration_beyond_a_hundredth_of_the_spacing(ale_run):
    """With predicted detection a pair is caught in the step it touches and the persistency
    law holds its gap rate: penetration (gap > 0) stays below 1 % of the surface spacing
    (measured 0.3 %). The law keeps gdot = 0, not g: a block node that the ALE slides through
    the disk's dimple carries its gap along, so a pressed pair may open by a few per cent of
    the spacing (measured 7.5 %; docs/scenarios.md, "Choosing penalty_normal, dt and the ALE
    body"); bound 10 %."""
    sim, rec = ale_run
    rows = [r.extra["contact_rows"] for r in rec.records[1:]]
    gaps = np.concatenate([r["gap"] for r in rows])
    pressed = np.concatenate([r["gap"][r["normal_traction"] > 0] for r in rows])
    assert gaps.size > 50 and gaps.max() < 0.01 * SPACING
    assert pressed.min() > -0.1 * SPACING


def test_pairs_stay_node_to_node_while_the_disk_rolls_over_the_ale_block(ale_run):
    """The ALE's own measure (the distance along the surface between a pair's predicted end
    positions, history's ``ale_mismatch``) is below 1e-6 of the spacing, and so is the offset
    of every pair's nodes across its line of action (the contact normal of a closed pair, the
    block's normal of an open one; issue 17 item 1). Along the block's surface tangent the
    offset is larger (2.3e-4 of the spacing): a pressed pair's gap opens by up to 7.5 % of the
    spacing here (previous test), along a normal that turns from the block's."""
    sim, rec = ale_run
    mismatch = np.array([r.extra.get("ale_mismatch", 0.0) for r in rec.records[1:]])
    assert mismatch.max() <= 1e-6 * SPACING
    chain = sim.model.interfaces[0].interface.surface2.nodes
    closed = [r for r in rec.records[1:] if r.extra["contact_rows"]["node_1"].size]
    offsets = [offsets_across_normal(sim.model, r) for r in closed]
    assert len(offsets) > 30 and np.concatenate(offsets).max() <= 1e-6 * SPACING
    along = [surface_offsets(chain, r.state.x, r.extra["contact_rows"]) for r in closed]
    assert np.concatenate(along).max() <= 5e-4 * SPACING
    # the block's surface nodes did slide (the disk travelled ~0.5 over it)
    top = sim.model.body("block").global_nodes("top")
    assert np.abs(sim.state.X[top] - sim.model.X0[top]).max() > SPACING


def test_energy_balance(ale_run):
    """The ledger closes: with a Lagrangian block to the Newton tolerance; the ALE block's remap
    interpolates the moving contact dimple and only loses energy (numerical dissipation,
    measured 0.85 % of the initial energy; bound 1.5 %)."""
    _, rec = ale_run
    error = energy_error(rec)
    e0 = rec.records[0].balance.total_energy
    assert error.max() <= 1e-8 * e0 and error.min() >= -0.015 * e0
    _, lagrangian = run(["bodies.1.mesh_motion=\"lagrangian\""])
    assert np.abs(energy_error(lagrangian)).max() <= 1e-8 * e0


def test_the_whole_drop_closes_the_ledger_where_the_block_cannot_take_a_remaps_energy():
    """At step 79 (t = 0.316, after the reduced runs above) a third pair's node joins the
    dimple under the rolling disk: that remap adds 1.17e-3 to the block's strain energy, and
    the supported block holds only 1.12e-3 of kinetic energy, so no change of its velocities
    gives it back (the ledger gained it: 7.3e-4 of E0). The rolling disk's velocities give it, its
    momenta kept (``engine.remap_conservation.hand_over_energy``): over the whole example the
    ledger closes to 1e-8 of E0 (measured 5.3e-12; 7.3e-4 before)."""
    _, rec = run(["analysis.t_end=0.4"])
    remap = np.array([r.extra.get("ale_remap_energy", 0.0) for r in rec.records])
    assert np.diff(remap).max() > 1e-3  # the move described above
    e0 = rec.records[0].balance.total_energy
    assert np.abs(energy_error(rec)).max() <= 1e-8 * e0


@pytest.mark.slow
def test_refined_four_times_the_drop_completes_with_the_same_physics():
    """Both bodies refined 4x (the disk 128 x 12, the block 160 x 16: spacing 0.025), dt
    unchanged. Before the ALE kept each step's interior stage (``ale.motion._move_interior``),
    step 68 (t = 0.268) failed: the interior nodes under the disk moved 2.8e-5 at every other
    augmentation, and report 5.4's test cycled at 3e-6 against 1e-8. Now it completes, and the
    coarse run's kinematic claims hold: no penetration beyond 1 % of the spacing, the pairs
    node to node (1e-6 of the spacing), and the ledger closes to 1e-8 of E0 (two remaps, at
    steps 27 and 29, change W by more than the resting block's velocities can give back: the
    disk gives it, as in the previous test; on that trajectory step 63 cycled until a move
    kept the step's earlier smoothing seeds, ``ale.motion._move_interior``). Not asserted,
    open (docs/examples.md, "The disk drop refined"): friction takes 3.8 % more than a third
    of the kinetic energy here (2.8 % on the coarse mesh)."""
    spacing = SPACING / 4
    sim, rec = run(["bodies.0.mesh.n_circ=128", "bodies.0.mesh.n_radial=12",
                    "bodies.1.mesh.nx=160", "bodies.1.mesh.ny=16"])
    assert rec.records[-1].state.time == pytest.approx(0.3)
    assert np.abs(energy_error(rec)).max() <= 1e-8 * rec.records[0].balance.total_energy
    rows = [r.extra["contact_rows"] for r in rec.records[1:]]
    assert np.concatenate([r["gap"] for r in rows]).max() < 0.01 * spacing
    closed = [r for r in rec.records[1:] if r.extra["contact_rows"]["node_1"].size]
    assert np.concatenate([offsets_across_normal(sim.model, r) for r in closed]).max() \
        <= 1e-6 * spacing


def test_energy_no_body_can_give_back_is_named_in_the_outputs(tmp_path, capsys):
    """With the disk ALE too, no Lagrangian body can take what the first contact step's remap
    changed (``hand_over_energy`` returns it): the ledger gains it (measured 3.06e-3, 2e-3 of
    E0). history.csv's ``ale_unreturned_energy`` holds it, so that E - E0 - W - it closes to
    the integrator's error again (measured 5.6e-12), summary.json keeps its last value and
    the CLI names the cause."""
    path = tmp_path / "both_ale.toml"
    path.write_text((EXAMPLES / "disk_drop.toml").read_text()
                    .replace('name = "disk"', 'name = "disk"\nmesh_motion = "ale"')
                    .replace("t_end = 0.4", "t_end = 0.024"))
    out = tmp_path / "out"
    assert main(["run", str(path), "--out", str(out), "--quiet"]) == 0
    history = pd.read_csv(out / "history.csv")
    summary = json.loads((out / "summary.json").read_text())
    e0 = history["total_energy"].iloc[0]
    ledger = (history["total_energy"] - e0 - history["external_work"]
              - history["contact_work"])
    unreturned = history["ale_unreturned_energy"]
    assert np.abs(ledger).max() > 1e-3 * e0  # what the column explains
    assert np.abs(ledger - unreturned).max() <= 1e-8 * e0
    assert summary["ale_unreturned_energy"] == unreturned.iloc[-1]
    assert "no body's velocities could give back" in capsys.readouterr().err
