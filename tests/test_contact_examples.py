"""Contact in the time loop: rod impact (report 3.2), stacked blocks under uniform pressure."""

import numpy as np
import pytest
from helpers import Recorder, model_from_dict, model_from_example

from ntncontact.engine.simulation import Simulation, SimulationError


def body_mean_velocity(model, state, body):
    M = model.assembler.nodal_mass(model.X0, lumped=True).diagonal()
    nodes = model.body(body).nodes
    return (M[nodes, None] * state.v[nodes]).sum(axis=0) / M[nodes].sum()


def test_rod_impact_lasts_two_wave_transits_and_exchanges_velocities():
    model = model_from_example("rod_impact.toml")
    rec = Recorder()
    sim = Simulation(model, [rec])
    sim.run()
    pressed = [r for r in rec.records
               if r.extra and np.any(r.extra["contact_rows"]["normal_traction"] > 0)]
    start, end = pressed[0].state.time - pressed[0].dt, pressed[-1].state.time
    # Theory 2 L / c = 2 (the report computes 2.05); the issue asks for 3 %.
    assert end - start == pytest.approx(2.0, rel=0.03)
    # Velocities exchanged: mean velocities after release ~ (0, 1) (elastic waves remain, so
    # the means oscillate by the wave content; 2 % of the impact velocity).
    v_left = body_mean_velocity(model, sim.state, "rod_left")
    v_right = body_mean_velocity(model, sim.state, "rod_right")
    assert abs(v_left[0]) < 0.02 and v_right[0] == pytest.approx(1.0, abs=0.02)
    # Frictionless persistency contact conserves energy (3.3.1) and the mid-point rule momentum.
    energy = np.array([r.balance.total_energy for r in rec.records])
    assert np.abs(energy - energy[0]).max() < 1e-8 * energy[0]
    px = np.array([r.balance.linear_momentum[0] for r in rec.records])
    assert np.abs(px - 10.0).max() < 1e-9
    # Mean contact pressure = rho c v / 2 = 5 over the contact period (the nodal value
    # oscillates with the mesh's dispersion).
    tn = np.concatenate([r.extra["contact_rows"]["normal_traction"] for r in pressed])
    assert tn.mean() == pytest.approx(5.0, rel=0.05)


def stacked_blocks(method="augmented_lagrangian", nx_top=6):
    return model_from_dict({**_stacked_dict(nx_top), "contact": [
        {"body_1": "top", "surface_1": "bottom", "body_2": "base", "surface_2": "top",
         "method": method, "penalty_normal": 1e4, "augmentation": {"gap_tolerance": 1e-12}}]})


def _stacked_dict(nx_top=6):
    return {
        "analysis": {"kind": "static", "dt": 0.5, "t_end": 1.0},
        "bodies": [
            {"name": "top",
             "mesh": {"type": "rectangle", "width": 2.0, "height": 1.0, "nx": nx_top, "ny": 3,
                      "origin": [0.0, 1.0]},
             "material": {"model": "linear_elastic", "E": 100.0, "nu": 0.0, "density": 1.0},
             "supports": [{"set": "left", "x": 0.0}],
             "loads": [{"type": "pressure", "set": "top", "value": 2.0,
                        "function": {"times": [0.0, 1.0], "values": [0.0, 1.0]}}]},
            {"name": "base",
             "mesh": {"type": "rectangle", "width": 2.0, "height": 1.0, "nx": 6, "ny": 3},
             "material": {"model": "linear_elastic", "E": 100.0, "nu": 0.0, "density": 1.0},
             "supports": [{"set": "bottom", "y": 0.0}, {"set": "left", "x": 0.0}]},
        ],
    }


def test_stacked_blocks_with_matched_meshes_carry_uniform_pressure():
    rec = Recorder()
    Simulation(stacked_blocks(), [rec]).run()
    rows = rec.records[-1].extra["contact_rows"]
    assert len(rows["node_1"]) == 7
    # nu = 0 and matched meshes: the contact pressure is the applied 2.0 everywhere, to the
    # augmentation tolerance (gap change 1e-12 times eps_N 1e4 = 1e-8).
    np.testing.assert_allclose(rows["normal_traction"], 2.0, rtol=1e-7)
    # ... while the nodal forces follow the tributary lengths (half at the two ends)
    ends = np.isclose(rows["x"], 0.0, atol=1e-9) | np.isclose(rows["x"], 2.0, atol=1e-9)
    lengths = np.where(ends, 1 / 6, 1 / 3)
    np.testing.assert_allclose(rows["normal_force"], 2.0 * lengths, rtol=1e-7)
    # the augmented Lagrangian drives the gap to zero; penalty leaves t_N / eps_N
    assert np.abs(rows["gap"]).max() < 1e-10


def test_penalty_leaves_a_penetration_of_traction_over_penalty():
    rec = Recorder()
    Simulation(stacked_blocks("penalty"), [rec]).run()
    rows = rec.records[-1].extra["contact_rows"]
    np.testing.assert_allclose(rows["gap"], 2.0 / 1e4, rtol=1e-6)
    np.testing.assert_allclose(rows["normal_traction"], 2.0, rtol=1e-7)


def pulled_block(pull=0.6, mu=0.5):
    return model_from_dict({
        "analysis": {"kind": "static", "dt": 0.25, "t_end": 1.0},
        "bodies": [
            {"name": "block",
             "mesh": {"type": "rectangle", "width": 4.0, "height": 1.0, "nx": 8, "ny": 2,
                      "origin": [0.0, 1.0]},
             "material": {"model": "linear_elastic", "E": 100.0, "nu": 0.3, "density": 1.0},
             "loads": [
                 {"type": "pressure", "set": "top", "value": 1.0},
                 {"type": "traction", "set": "right", "vector": [pull, 0.0],
                  "function": {"times": [0.0, 1.0], "values": [0.0, 1.0]}}]},
            {"name": "foundation",
             "mesh": {"type": "rectangle", "width": 4.0, "height": 1.0, "nx": 8, "ny": 2},
             "material": {"model": "linear_elastic", "E": 1e6, "nu": 0.0, "density": 1.0},
             "supports": [{"set": "bottom", "x": 0.0, "y": 0.0}]},
        ],
        "contact": [{"body_1": "block", "surface_1": "bottom", "body_2": "foundation",
                     "surface_2": "top", "penalty_normal": 1e4, "penalty_tangential": 1e4,
                     "friction": mu, "augmentation": {"gap_tolerance": 1e-10,
                                                      "slip_tolerance": 1e-10}}],
    })


def test_pulled_block_has_stick_and_slip_zones_within_the_coulomb_cone():
    rec = Recorder()
    Simulation(pulled_block(), [rec]).run()
    rows = rec.records[-1].extra["contact_rows"]
    tn, tt = rows["normal_traction"], rows["tangential_traction"]
    # Coulomb cone (2.20) holds at every pair, to round-off of the return mapping
    assert np.all(np.abs(tt) <= 0.5 * tn * (1 + 1e-12) + 1e-14)
    # equilibrium: the contact forces carry the applied resultants (pressure 4, pull 0.6); the
    # deformed surface's normals turn by ~1e-5 rad, which mixes the two sums at that level
    assert rows["normal_force"].sum() == pytest.approx(4.0, rel=1e-4)
    assert abs(rows["tangential_force"].sum()) == pytest.approx(0.6, rel=1e-4)
    status = set(rows["status"])
    assert status == {"stick", "slip"}, status
    dissipation = np.array([r.extra["frictional_dissipation"] for r in rec.records[1:]])
    assert np.all(dissipation >= 0.0) and np.all(np.diff(dissipation) >= -1e-15)


def test_lagrange_multipliers_enforce_zero_gap_and_uniform_pressure():
    rec = Recorder()
    Simulation(stacked_blocks("lagrange"), [rec]).run()
    rows = rec.records[-1].extra["contact_rows"]
    assert np.abs(rows["gap"]).max() < 1e-12  # exact constraint, Newton tolerance only
    np.testing.assert_allclose(rows["normal_traction"], 2.0, rtol=1e-9)


def _off_centre_load(augmentation, **analysis):
    """Stacked blocks under an off-centre point load (a non-uniform pressure that penalty
    alone gets wrong), one static step unless ``analysis`` says otherwise."""
    base = _stacked_dict()
    base["bodies"][0]["loads"] = [{"type": "point", "set": "corner_top_right",
                                   "vector": [0.0, -2.0]}]
    return model_from_dict({**base, "analysis": {"kind": "static", "dt": 1.0, "t_end": 1.0,
                                                 **analysis},
                            "contact": [{"name": "glued", "body_1": "top",
                                         "surface_1": "bottom", "body_2": "base",
                                         "surface_2": "top", "penalty_normal": 1e3,
                                         "augmentation": augmentation}]})


def test_augmentations_shrink_the_penetration_towards_the_lagrange_solution():
    """Report Fig. 6.5: each augmentation improves the solution; penalty alone is t_N/eps_N."""
    gaps = []
    for k in (1, 2, 3, 4):
        model = _off_centre_load({"max_iterations": k, "on_limit": "accept",
                                  "gap_tolerance": 1e-14})
        rec = Recorder()
        Simulation(model, [rec]).run()
        rows = rec.records[-1].extra["contact_rows"]
        assert rec.records[-1].extra["augmentations_converged"] == 0  # accepted, and so noted
        gaps.append(np.abs(rows["gap"][rows["normal_traction"] > 0]).max())
    gaps = np.array(gaps)
    assert np.all(np.diff(gaps) < 0) and gaps[-1] < 1e-2 * gaps[0], gaps


def test_a_step_whose_augmentations_run_out_is_cut_back_then_fails():
    """By default the limit of augmentations is a failed step (not a silently accepted one):
    it is halved, and once the halvings run out the error names the interface and the test
    that failed."""
    model = _off_centre_load({"max_iterations": 3, "gap_tolerance": 1e-14}, max_cutbacks=2)
    with pytest.raises(SimulationError) as err:
        Simulation(model).run()
    message = str(err.value)
    assert "failed after 2 halvings" in message
    assert "did not converge in 3" in message
    assert "interface 'glued': change of the gap" in message  # (it said "normal rate")
    assert 'try augmentation.update = "newton"' in message  # Uzawa updates (the default)


@pytest.mark.parametrize(("augmentation", "why"), [
    ({"max_iterations": 1}, "one augmentation only, and the test compares two"),
    # below one ulp of the coordinates: the tester's 1e-20 was halved 4 times and told to
    # try Newton updates
    ({"max_iterations": 3, "gap_tolerance": 1e-20}, "is below the round-off of the gaps"),
])
def test_augmentations_no_shorter_step_can_converge_fail_at_once(augmentation, why):
    """One augmentation (the test compares two) or a gap_tolerance below round-off: no halving
    and no update rule can pass the test, so the step fails unhalved and says so (tester B
    F6)."""
    model = _off_centre_load(augmentation, max_cutbacks=2)
    with pytest.raises(SimulationError) as err:
        Simulation(model).run()
    message = str(err.value)
    assert "halvings" not in message and "the step was not halved" in message, message
    assert why in message and "augmentation.update" not in message, message


def test_an_interface_with_newton_updates_is_not_told_to_take_them():
    model = _off_centre_load({"max_iterations": 1, "update": "newton"}, max_cutbacks=0)
    with pytest.raises(SimulationError) as err:
        Simulation(model).run()
    message = str(err.value)
    assert "did not converge in 1" in message and "augmentation.update" not in message


def test_accepted_unconverged_steps_are_counted_in_the_results(tmp_path):
    """augmentation.on_limit = "accept" keeps the last augmentation (report Fig. 6.5 studies a
    fixed number of them); history.csv and summary.json say which steps did."""
    import json

    from ntncontact.io.results import ResultWriter
    from ntncontact.io.writers import read_csv_table
    from ntncontact.report.run_warnings import result_warnings

    accepting = _off_centre_load({"max_iterations": 2, "gap_tolerance": 1e-14,
                                  "on_limit": "accept"}, dt=0.5)
    Simulation(accepting, [ResultWriter(tmp_path, accepting)]).run()
    history = read_csv_table(tmp_path / "history.csv")
    np.testing.assert_array_equal(history["augmentations_converged"], [1, 0, 0])  # t = 0 first
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["unconverged_steps"] == 2
    # and the run says so (tester B F5: 4 of 4 steps kept so, and only the summary told)
    said = [line for line in result_warnings(summary, static=True) if "unconverged" in line]
    assert len(said) == 1 and said[0].startswith("2 of 2 steps kept an unconverged"), said
    assert f"largest penetration {summary['max_penetration']:.3g}" in said[0]
    converging = _off_centre_load({"gap_tolerance": 1e-8}, dt=0.5)
    Simulation(converging, [ResultWriter(tmp_path / "ok", converging)]).run()
    history = read_csv_table(tmp_path / "ok" / "history.csv")
    np.testing.assert_array_equal(history["augmentations_converged"], [1, 1, 1])
    summary = json.loads((tmp_path / "ok" / "summary.json").read_text())
    assert summary["unconverged_steps"] == 0
    assert not [line for line in result_warnings(summary, static=True) if "unconverged" in line]


def test_three_bodies_and_two_interfaces_carry_the_same_pressure():
    data = _stacked_dict()
    top, block = data["bodies"]
    middle = {**block, "name": "middle", "supports": [{"set": "left", "x": 0.0}]}
    base = {**block, "name": "base", "mesh": {**block["mesh"], "origin": [0.0, -1.0]}}
    data["bodies"] = [top, middle, base]
    data["contact"] = [
        {"name": "upper", "body_1": "top", "surface_1": "bottom", "body_2": "middle",
         "surface_2": "top", "penalty_normal": 1e4, "augmentation": {"gap_tolerance": 1e-12}},
        {"name": "lower", "body_1": "middle", "surface_1": "bottom", "body_2": "base",
         "surface_2": "top", "method": "lagrange"},
    ]
    rec = Recorder()
    Simulation(model_from_dict(data), [rec]).run()
    rows = rec.records[-1].extra["contact_rows"]
    for name in ("upper", "lower"):
        mine = rows["interface"] == name
        assert mine.sum() == 7
        np.testing.assert_allclose(rows["normal_traction"][mine], 2.0, rtol=1e-7)


@pytest.mark.parametrize("method", ["lagrange", "augmented_lagrangian"])
def test_friction_that_cycles_in_newton_says_what_may_converge(method):
    """Hertz (report 6.2) with mu = 0.3, no cut-backs and penalty_tangential 1e6: stick and
    slip cycle in Newton at step 10 by either method; 1e5 converges. A tester's
    Cattaneo-Mindlin case failed so without a hint of the cause; the error now names the
    interface, its tangential penalty and what may converge."""
    overrides = [f'contact.0.method="{method}"', "contact.0.friction=0.3",
                 "analysis.max_cutbacks=0", "analysis.t_end=10.0"]
    with pytest.raises(SimulationError) as err:
        Simulation(model_from_example("hertz.toml", overrides)).run()
    message = str(err.value)
    assert "no convergence" in message
    assert "interface 'cylinder_foundation' has friction" in message and "(1e+06)" in message
    assert ('method = "augmented_lagrangian" (its cap' in message) == (method == "lagrange")
    Simulation(model_from_example("hertz.toml", [*overrides,
                                                 "contact.0.penalty_tangential=1e5"])).run()
