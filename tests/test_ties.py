"""Tie constraints between bodies ([[tie]], ntncontact.engine.ties)."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest
from helpers import EXAMPLES, Recorder, model_from_dict
from scipy.spatial import cKDTree

from ntncontact.engine.problem import StepProblem
from ntncontact.engine.simulation import Simulation, default_linear_solve, initial_state
from ntncontact.engine.ties import tie_forces, tie_terms, tie_violation
from ntncontact.io.scenario import ScenarioError, load_config
from ntncontact.solvers.newton import NewtonSettings, newton

WIDTH, H_LOW, H_UP, P = 2.0, 0.5, 0.75, 30.0


def material(E: float, nu: float = 0.3, model: str = "linear_elastic") -> dict:
    return {"model": model, "E": E, "nu": nu, "density": 1.0}


def rect(width: float, height: float, nx: int, ny: int, origin=(0.0, 0.0)) -> dict:
    return {"type": "rectangle", "width": width, "height": height, "nx": nx, "ny": ny,
            "origin": list(origin)}


def static(t_end: float = 1.0) -> dict:
    return {"kind": "static", "dt": t_end, "t_end": t_end}


def two_layers(E_low: float, E_up: float, pressure: float, sides_fixed: bool,
               tie: dict | None = None, shift: float = 0.0) -> dict:
    """Lower layer on a roller base, upper layer tied on top, pressure on the upper top."""
    sides = [{"set": "left", "x": 0.0}] + ([{"set": "right", "x": 0.0}] if sides_fixed else [])
    lower = {"name": "lower", "mesh": rect(WIDTH, H_LOW, 4, 2), "material": material(E_low),
             "supports": [{"set": "bottom", "y": 0.0}] + sides}
    upper = {"name": "upper", "mesh": rect(WIDTH, H_UP, 4, 3, (shift, H_LOW)),
             "material": material(E_up), "supports": list(sides),
             "loads": [{"type": "pressure", "set": "top", "value": pressure}]}
    tie = tie or {"name": "glue", "body_1": "upper", "surface_1": "bottom", "body_2": "lower",
                  "surface_2": "top"}
    return {"analysis": static(), "bodies": [lower, upper], "tie": [tie]}


def one_block(E: float, pressure: float, sides_fixed: bool) -> dict:
    sides = [{"set": "left", "x": 0.0}] + ([{"set": "right", "x": 0.0}] if sides_fixed else [])
    block = {"name": "block", "mesh": rect(WIDTH, H_LOW + H_UP, 4, 5), "material": material(E),
             "supports": [{"set": "bottom", "y": 0.0}] + sides,
             "loads": [{"type": "pressure", "set": "top", "value": pressure}]}
    return {"analysis": static(), "bodies": [block]}


def solve(data: dict):
    model = model_from_dict(data)
    sim = Simulation(model)
    sim.run()
    return model, sim.state


def displacement_at(model, state, points: np.ndarray) -> np.ndarray:
    """Displacement of a node at each reference point (either one of two tied nodes)."""
    dist, idx = cKDTree(model.X0).query(points)
    assert dist.max() < 1e-12
    return state.d[idx]


@pytest.mark.parametrize("pressure", [P, -P])  # compression and tension
def test_two_tied_blocks_reproduce_the_single_block(pressure):
    model1, s1 = solve(one_block(1.0e3, pressure, sides_fixed=False))
    model2, s2 = solve(two_layers(1.0e3, 1.0e3, pressure, sides_fixed=False))
    d1 = s1.d
    d2 = displacement_at(model2, s2, model1.X0)
    scale = np.abs(d1).max()
    assert scale > 1e-3  # a real deformation (lateral expansion too: nu = 0.3)
    np.testing.assert_allclose(d2, d1, rtol=0, atol=1e-10 * scale)
    # the tied nodes coincide, and the tie components prescribed on both sides were dropped
    (tie,) = model2.ties
    assert tie_violation(model2.ties, s2.x) <= 1e-12 * scale
    assert tie.nodes_1.size == 5 and tie.size == 2 * 5 - 1


def test_tie_with_two_moduli_gives_the_layered_series_solution():
    """Sides on rollers: each layer in uniaxial strain, sigma_yy = -p, so the top moves by
    -p (h_low / M_low + h_up / M_up), M = E (1 - nu) / ((1 + nu)(1 - 2 nu)) (exact for Q4)."""
    E_low, E_up, nu = 5.0e4, 2.0e4, 0.3
    model, state = solve(two_layers(E_low, E_up, P, sides_fixed=True))

    def M(E: float) -> float:
        return E * (1 - nu) / ((1 + nu) * (1 - 2 * nu))

    top = model.body("upper").global_nodes("top")
    interface = model.body("lower").global_nodes("top")
    expected_top = -P * (H_LOW / M(E_low) + H_UP / M(E_up))
    np.testing.assert_allclose(state.d[top, 1], expected_top, rtol=1e-9)
    np.testing.assert_allclose(state.d[interface, 1], -P * H_LOW / M(E_low), rtol=1e-9)
    # no lateral motion: round-off of the bordered solve (eps times its condition, ~1e5)
    np.testing.assert_allclose(state.d[:, 0], 0.0, atol=1e-10 * abs(expected_top))


def test_tie_reaction_carries_the_load_of_the_upper_layer():
    """The multipliers of a bordered solve: the tie pushes the upper layer up by p W."""
    model = model_from_dict(two_layers(5.0e4, 2.0e4, P, sides_fixed=True))
    state = initial_state(model)
    problem = StepProblem(model, state, 1.0, None, (), tie_terms(model.ties))
    result = newton(problem.residual, problem.jacobian, default_linear_solve(),
                    problem.initial_guess(), NewtonSettings(rtol=1e-12), WIDTH)
    forces = tie_forces(problem.constraints, problem.multipliers(result.y))["glue"]
    assert forces[:, 1].sum() == pytest.approx(P * WIDTH, rel=1e-10)
    # uniform pressure, consistent nodal loads: W/4 per inner node, W/8 at the two ends
    # (the end nodes' x components are left to the supports)
    np.testing.assert_allclose(np.sort(forces[:, 1]), P * WIDTH / 8 * np.array([1, 1, 2, 2, 2]),
                               rtol=1e-9)
    np.testing.assert_allclose(forces[:, 0], 0.0, atol=1e-9 * P * WIDTH)


def test_a_node_without_coincident_partner_is_named():
    data = two_layers(1.0e3, 1.0e3, P, sides_fixed=False, shift=0.1)
    with pytest.raises(ScenarioError, match=r"tie.0 \('glue'\).*body 'upper' has no "
                       r"coincident node on body 'lower'.*\(0\.1, 0\.5\)"):
        model_from_dict(data)


def test_unknown_body_surface_or_key_of_a_tie_is_an_error():
    tie = {"name": "glue", "body_1": "upper", "surface_1": "bottom", "body_2": "nowhere",
           "surface_2": "top"}
    with pytest.raises(ScenarioError, match=r"tie.0 \('glue'\).body_2: no body named 'nowhere'"):
        model_from_dict(two_layers(1.0, 1.0, P, False, tie))
    tie = tie | {"body_2": "lower", "surface_2": "roof"}
    with pytest.raises(ScenarioError, match=r"tie.0 \('glue'\).*no node or edge set named "
                       r"'roof'"):
        model_from_dict(two_layers(1.0, 1.0, P, False, tie))
    with pytest.raises(ScenarioError, match=r"tie.0.stiffness: unknown key"):
        model_from_dict(two_layers(1.0, 1.0, P, False, tie | {"surface_2": "top",
                                                              "stiffness": 1.0}))


def floating_blocks(v_left: tuple[float, float], v_right: tuple[float, float],
                    spin: float) -> dict:
    """Two free blocks side by side, tied along their common side, with different initial
    velocities: the tie must absorb the mismatch with equal and opposite forces. Neo-Hookean:
    small-strain elasticity is not objective, its internal forces alone change the angular
    momentum of a spinning body."""
    bodies = [
        {"name": "left", "mesh": rect(1.0, 1.0, 3, 3),
         "material": material(50.0, model="neo_hookean"),
         "initial": {"velocity": list(v_left), "angular_velocity": spin}},
        {"name": "right", "mesh": rect(1.0, 1.0, 3, 3, (1.0, 0.0)),
         "material": material(50.0, model="neo_hookean"),
         "initial": {"velocity": list(v_right)}},
    ]
    tie = {"name": "seam", "body_1": "left", "surface_1": "right", "body_2": "right",
           "surface_2": "left"}
    analysis = {"kind": "dynamic", "dt": 0.02, "t_end": 0.4}
    return {"analysis": analysis, "bodies": bodies, "tie": [tie]}


@pytest.mark.parametrize("ny_right", [3, 6])
def test_dynamic_run_of_two_tied_blocks_conserves_momentum(ny_right):
    """ny_right = 6: the right block's 7 side nodes against the left's 4, three held on its
    edges, whose forces sum to zero where the points coincide: the momenta are kept as by
    the coincident pairs."""
    data = floating_blocks((0.5, 0.2), (-0.3, 0.0), spin=0.4)
    data["bodies"][1]["mesh"] = rect(1.0, 1.0, 3, ny_right, (1.0, 0.0))
    model = model_from_dict(data)
    assert model.ties[0].edge_dofs.size == 2 * (ny_right - 3)
    rec = Recorder()
    Simulation(model, [rec]).run()
    assert rec.status == ("completed", None)
    b = [r.balance for r in rec.records]
    p = np.array([x.linear_momentum for x in b])
    L = np.array([x.angular_momentum for x in b])
    np.testing.assert_allclose(p - p[0], 0.0, atol=1e-12 * np.abs(p[0]).max())
    np.testing.assert_allclose(L - L[0], 0.0, atol=1e-10 * abs(L[0]))
    # the blocks really pushed on each other: the right block's momentum changed
    right = model.body("right").nodes
    v_right = rec.records[-1].state.v[right].mean(axis=0)
    assert abs(v_right[0] - (-0.3)) > 0.1
    assert max(tie_violation(model.ties, r.state.x) for r in rec.records) < 1e-12


def test_tied_rod_with_exact_contact_multipliers_matches_the_whole_rod():
    """Report 3.2's rods with exact gap multipliers (Lagrange terms in the bordered system):
    the right rod cut in two tied halves gives the same run as the whole rod, so the contact
    interface gets its own multipliers back, not the tie's."""
    base = load_config(EXAMPLES / "rod_impact.toml", [
        'contact.0.method="lagrange"', 'contact.0.law="gap"', "analysis.t_end=0.5",
        "analysis.energy_conserving=true"]).model_dump(by_alias=True, exclude_none=True)
    whole = _run_records(base)
    halves = dict(base)
    right = base["bodies"][1]
    halves["bodies"] = [base["bodies"][0]] + [
        right | {"name": f"rod_right_{k}", "mesh": right["mesh"] | {
            "width": 5.0, "nx": 20, "origin": [5.0 * k, 0.0]}} for k in (0, 1)]
    halves["contact"] = [base["contact"][0] | {"body_2": "rod_right_0"}]
    halves["tie"] = [{"name": "cut", "body_1": "rod_right_0", "surface_1": "right",
                      "body_2": "rod_right_1", "surface_2": "left"}]
    split = _run_records(halves)
    e_whole = np.array([r.balance.total_energy for r in whole])
    e_split = np.array([r.balance.total_energy for r in split])
    np.testing.assert_allclose(e_split, e_whole, rtol=1e-8)
    lam_whole = [r.extra["contact_rows"]["normal_traction"] for r in whole if r.extra]
    lam_split = [r.extra["contact_rows"]["normal_traction"] for r in split if r.extra]
    assert max(a.max() for a in lam_whole if a.size) > 0.1  # the rods really pushed
    for a, b in zip(lam_whole, lam_split, strict=True):
        np.testing.assert_allclose(b, a, rtol=1e-7, atol=1e-9)


def test_energy_variant_hands_the_contact_multipliers_back_in_order_with_ties():
    """simulation._lagrange_multipliers after the energy re-solve (report 5.5): the tie terms
    stay separate constraint terms ('others') and sort after the Lagrange interfaces, which
    interfaces.with_solved_multipliers consumes from the front."""
    model = model_from_dict(two_layers(1.0, 1.0, P, sides_fixed=False))
    (tie,) = tie_terms(model.ties)
    lag = [SimpleNamespace(order=0), SimpleNamespace(order=1)]
    combined = SimpleNamespace(terms=lag)
    lam_tie, lam_combined = np.full(tie.size, 7.0), np.array([1.0, 2.0, 0.5])  # ..., theta
    problem = SimpleNamespace(constraints=[tie, combined],
                              multipliers=lambda y: [lam_tie, lam_combined])
    split = ([tie], [np.array([1.0]), np.array([2.0])])
    out = Simulation._lagrange_multipliers(problem, SimpleNamespace(y=None), split)
    assert [float(v[0]) for v in out] == [1.0, 2.0, 7.0]


def _run_records(data: dict) -> list:
    rec = Recorder()
    Simulation(model_from_dict(data, EXAMPLES), [rec]).run()
    assert rec.status == ("completed", None)
    return rec.records


def test_run_folder_records_the_tie_reaction_and_violation(tmp_path):
    """history.csv carries each tie's resultant on body 1 (p W upwards on the upper layer here)
    and the tied nodes' largest distance; summary.json the worst distance of the run."""
    import json

    from ntncontact.io.results import ResultWriter
    from ntncontact.io.writers import read_csv_table

    model = model_from_dict(two_layers(5.0e4, 2.0e4, P, sides_fixed=True))
    Simulation(model, [ResultWriter(tmp_path, model)]).run()
    history = read_csv_table(tmp_path / "history.csv")
    assert history["tie_glue_force_y"][-1] == pytest.approx(P * WIDTH, rel=1e-9)
    assert abs(history["tie_glue_force_x"][-1]) <= 1e-9 * P * WIDTH
    assert history["tie_violation"].max() < 1e-12
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["max_tie_violation"] == pytest.approx(history["tie_violation"].max())


def non_matching_patch(ny_b: int, load: list[float]) -> dict:
    """Block A (2 x 1, ny = 2) tied along its right side to block B (2 x 1, ny = ny_b): B's
    left side has nodes between A's (an independent tester's patch test, ny_b = 4)."""
    a = {"name": "A", "mesh": rect(2.0, 1.0, 2, 2), "material": material(1000.0),
         "supports": [{"set": "left", "x": 0.0}, {"set": "corner_bottom_left", "y": 0.0}]}
    b = {"name": "B", "mesh": rect(2.0, 1.0, 3, ny_b, (2.0, 0.0)), "material": material(1000.0),
         "loads": [{"type": "traction", "set": "right", "vector": load}]}
    tie = {"name": "glue", "body_1": "A", "surface_1": "right", "body_2": "B",
           "surface_2": "left"}
    return {"analysis": static(), "bodies": [a, b], "tie": [tie]}


@pytest.mark.parametrize("ny_b", [4, 6])
def test_a_tie_of_non_matching_meshes_passes_the_patch_test(ny_b):
    """The surface-2 nodes between surface 1's are held on its edges: a uniform tension passes
    the bond unchanged (exact linear field). Left free, they gave shear stresses of 0.23 and
    sigma_yy of -0.022 against sigma_xx = 1 (ny_b = 4)."""
    model, state = solve(non_matching_patch(ny_b, [1.0, 0.0]))
    tie = model.ties[0]
    assert tie.edge_dofs.size == 2 * (ny_b + 1 - 3)  # B's nodes not on A's
    X, d = model.X0, state.d
    # the displacement field is the linear one of sigma_xx = 1: u_x = x (1 - nu^2) / E
    nu, E = 0.3, 1000.0
    np.testing.assert_allclose(d[:, 0], X[:, 0] * (1 - nu**2) / E, atol=1e-12)
    np.testing.assert_allclose(d[:, 1], -X[:, 1] * nu * (1 + nu) / E, atol=1e-12)
    assert tie_violation(model.ties, state.x) < 1e-14


def tied_halves_on_a_foundation(method: str, exclude: list[str] | None = None) -> dict:
    """Two tied 2 x 2 blocks, each with its own interface on one foundation (a tester's)."""
    press = {"type": "pressure", "set": "top", "value": 50.0}
    halves = [{"name": name, "mesh": rect(2.0, 2.0, 4, 4, (x, 0.0)),
               "material": material(1000.0), "loads": [press]}
              for name, x in (("A", 0.0), ("B", 2.0))]
    halves[0]["supports"] = [{"set": "left", "x": 0.0}]
    foundation = {"name": "F", "mesh": rect(8.0, 1.0, 16, 2, (-2.0, -1.0)),
                  "material": material(1e6), "supports": [{"set": "bottom", "x": 0.0,
                                                             "y": 0.0}]}
    contact = [{"body_1": name, "surface_1": "bottom", "body_2": "F", "surface_2": "top",
                "method": method, "law": "gap", "penalty_normal": 1e5} for name in "AB"]
    if exclude:
        contact[1]["exclude"] = exclude
    tie = {"name": "glue", "body_1": "A", "surface_1": "right", "body_2": "B",
           "surface_2": "left"}
    return {"analysis": static(), "bodies": [*halves, foundation], "tie": [tie],
            "contact": contact}


def test_tied_nodes_held_twice_by_exact_multipliers_are_refused_by_name():
    """Both tied corner nodes against the same foundation node: two identical gap
    constraints, a singular multiplier system ("SuperLU: Factor is exactly singular" in a
    tester's run). Refused at build time, naming the nodes and the cure, which works."""
    with pytest.raises(ScenarioError, match=r"nodes \[4\] of body 'A' and \[0\] of body 'B', "
                                            r"tied together by tie 'glue'.*contact\.1\.exclude"):
        model_from_dict(tied_halves_on_a_foundation("lagrange"))
    model, state = solve(tied_halves_on_a_foundation("lagrange", ["corner_bottom_left"]))
    reference, ref_state = solve(tied_halves_on_a_foundation("augmented_lagrangian"))
    np.testing.assert_allclose(state.d, ref_state.d, atol=1e-6 * np.abs(ref_state.d).max())
