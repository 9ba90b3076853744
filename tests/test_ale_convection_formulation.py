"""The two ALE formulations in the time loop: "remap" (v remapped, plain Lagrangian step) and
"convective_term" (only X, d remapped; the step adds C(c) v with c = -(mesh move)/dt)."""

from dataclasses import replace

import numpy as np
import pytest
from helpers import Recorder, model_from_dict, model_from_example

import ntncontact.engine.simulation as simulation_module
from ntncontact.contact import PairState
from ntncontact.dynamics.midpoint import end_of_step
from ntncontact.engine.convection import convective_terms
from ntncontact.engine.mesh_motion import move_meshes
from ntncontact.engine.problem import StepProblem
from ntncontact.engine.simulation import Simulation, default_linear_solve
from ntncontact.solvers.newton import NewtonSettings, newton

MODES = ["remap", "convective_term"]


def translating_blocks(mode: str, dt: float = 0.01, t_end: float = 0.05):
    """A 0.5 x 0.2 block on a 2 x 0.2 ALE block, matching spacing 0.1, touching at y = 0; both
    translate with vy = 0.2, the upper one 2 faster in x: frictionless sliding, no forces."""
    material = {"model": "neo_hookean", "E": 100.0, "nu": 0.3, "density": 1.0}
    return model_from_dict({
        "analysis": {"kind": "dynamic", "dt": dt, "t_end": t_end},
        "bodies": [
            {"name": "upper", "material": material, "initial": {"velocity": [2.5, 0.2]},
             "mesh": {"type": "rectangle", "width": 0.5, "height": 0.2, "nx": 5, "ny": 2,
                      "origin": [-0.3, 0.0]}},
            {"name": "lower", "mesh_motion": "ale", "ale": {"convection": mode},
             "material": material | {"density": 3.0}, "initial": {"velocity": [0.5, 0.2]},
             "mesh": {"type": "rectangle", "width": 2.0, "height": 0.2, "nx": 20, "ny": 2,
                      "origin": [-1.0, -0.2]}},
        ],
        "contact": [{"body_1": "upper", "surface_1": "bottom", "body_2": "lower",
                     "surface_2": "top", "penalty_normal": 1e3}],
    })


def coincident_pairs(model):
    """(upper bottom node, lower top node at the same place) for every upper bottom node."""
    up = model.body("upper").global_nodes("bottom")
    low = model.body("lower").global_nodes("top")
    dist = np.linalg.norm(model.X0[up][:, None] - model.X0[low][None], axis=2)
    assert dist.min(axis=1).max() < 1e-12
    return np.column_stack([up, low[dist.argmin(axis=1)]])


@pytest.mark.parametrize("mode", MODES)
def test_uniform_translation_does_not_see_the_mesh_motion(mode):
    """METHOD_NOTES test 1 in the time loop: the lower block's contact nodes follow their
    sliding partners (its mesh moves by 0.02 per step), yet velocities stay uniform, energy
    and momentum constant to round-off in both formulations (grad v = 0: C v = 0)."""
    model = translating_blocks(mode)
    rec = Recorder()
    sim = Simulation(model, [rec])
    sim.state = replace(sim.state, contact=(PairState.from_pairs(coincident_pairs(model)),))
    sim.run()
    low = model.body("lower").nodes
    moved = np.abs(sim.state.X[low] - model.X0[low]).max()
    assert moved > 0.05  # the ALE mesh did slide under the block (2 x 0.05 relative)
    v0 = rec.records[0].state.v
    energy = np.array([r.balance.total_energy for r in rec.records])
    momentum = np.array([r.balance.linear_momentum for r in rec.records])
    # coordinates O(1), velocities O(1): a few hundred round-offs over 5 steps
    np.testing.assert_allclose(sim.state.v, v0, rtol=0, atol=1e-11)
    assert np.abs(energy - energy[0]).max() < 1e-12 * energy[0]
    assert np.abs(momentum - momentum[0]).max() < 1e-12 * np.abs(momentum[0]).max()
    np.testing.assert_allclose(sim.state.X[low, 1], model.X0[low, 1], atol=1e-12)


def test_convective_mode_keeps_v_and_adds_a_term_only_there():
    """The move remaps X and d in both modes alike; only "remap" changes v, only
    "convective_term" adds a step term, whose c is minus the mesh velocity."""
    out = {}
    for mode in MODES:
        model = translating_blocks(mode)
        state = Simulation(model).state
        rng = np.random.default_rng(0)
        state = replace(state, v=state.v + rng.normal(scale=0.1, size=state.v.shape))
        contact = (PairState.from_pairs(coincident_pairs(model)),)
        x_pred = state.x + 0.01 * state.v
        x_pred[model.body("upper").nodes, 0] += 0.03  # the partners slide ahead
        motion = move_meshes(model, state, contact, x_pred, 0.01, None)
        out[mode] = (state, motion, convective_terms(model, motion, 0.01))
    (s, remap, none), (_, conv, terms) = out["remap"], out["convective_term"]
    assert none == [] and len(terms) == 1
    moved = conv.updates[0].moved
    assert moved.sum() >= 5
    np.testing.assert_array_equal(conv.state.X, remap.state.X)
    np.testing.assert_array_equal(conv.state.d, remap.state.d)
    np.testing.assert_array_equal(conv.state.v, s.v)  # untouched
    assert np.abs(remap.state.v - s.v).max() > 1e-3  # the remap changed the random field
    # the term is C(c) v with c = -mesh velocity on the lower body: zero for v = 0
    x = conv.state.x
    f, (rows, cols, vals) = terms[0](x, np.zeros_like(x), 200.0, x)
    assert not f.any() and vals.size and np.abs(vals).max() > 0


def one_step(mode: str, dt: float, with_term: bool = True, slide: float = 0.03):
    """One step of the lower block with a linear velocity field v = v0 + L (x - x_c) whose mesh
    is slid by ``slide`` at t_n (no contact force: the pairs only drive the mesh motion);
    returns the lower block's v_{n+1} and x_{n+1}."""
    model = translating_blocks(mode)
    state = Simulation(model).state
    low = model.body("lower").nodes
    v = state.v.copy()
    v[low] += (state.x[low] - state.x[low].mean(axis=0)) @ np.array([[0.3, -0.5],
                                                                      [0.4, 0.1]]).T
    state = replace(state, v=v)
    pairs = coincident_pairs(model)
    x_pred = state.x + dt * v
    x_pred[pairs[:, 0]] = state.x[pairs[:, 0]] + dt * v[pairs[:, 1]] + [slide, 0.0]
    motion = move_meshes(model, state, (PairState.from_pairs(pairs),), x_pred, dt, None)
    s = motion.state
    extra = convective_terms(model, motion, dt) if with_term else []
    problem = StepProblem(model, s, dt, model.assembler.mass(s.X, False), extra)
    result = newton(problem.residual, problem.jacobian, default_linear_solve(),
                    problem.initial_guess(), NewtonSettings(rtol=1e-12), 2.0)
    d1, v1, _ = end_of_step(problem.full(result.y).reshape(-1, 2), s.d, s.v, dt)
    assert motion.updates[0].moved.sum() >= 5  # the mesh did move
    return v1[low], (s.X + d1)[low]


def test_the_two_formulations_agree_to_first_order_in_dt():
    """With a linear v the remap adds (dx . grad) v exactly and C(c) v with c = -dx/dt is the
    same to first order; what is left comes from grad v_{n+1/2} at x_{n+1/2} in the term vs
    grad v_n at x_n in the remap: O(dt). Halving dt (same slide) must halve the difference,
    and the term must account for most of the convection (dropping it: an O(1) error)."""
    diff = []
    for dt in (0.01, 0.005):
        v_remap, _ = one_step("remap", dt)
        v_term, _ = one_step("convective_term", dt)
        diff.append(np.abs(v_term - v_remap).max())
    v_none, _ = one_step("convective_term", 0.005, with_term=False)
    dropped = np.abs(v_none - v_remap).max()
    # measured: 3.9e-3, 1.8e-3 against 9.8e-3 without the term (slide 0.03 x |L| ~ 0.6)
    assert 0.4 < diff[1] / diff[0] < 0.6
    assert diff[1] < 0.25 * dropped


def coarse_fast_sliding(mode: str, dt: float) -> list[str]:
    """Report 6.5 on a 4 x 8 / 18 x 3 mesh up to t = 0.1 (impact at 0.048, then sliding)."""
    return ["bodies.0.mesh.nx=4", "bodies.0.mesh.ny=8", "bodies.1.mesh.nx=18",
            "bodies.1.mesh.ny=3", f"analysis.dt={dt}", "analysis.t_end=0.1",
            f"analysis.output_interval={dt}", f"bodies.1.ale.convection={mode}"]


@pytest.fixture(scope="module")
def fast_sliding():
    """Both formulations, and the convective one with its term dropped (convection lost)."""
    out = {}
    for key, mode in (("remap", "remap"), ("term", "convective_term"),
                      ("dropped", "convective_term")):
        rec = Recorder()
        # the report's mid-point rule: with the energy-momentum integrator some coarse contact
        # steps are halved (a Newton trial inverts a thin element at t_{n+1}), and the halved
        # steps move the ALE mesh differently in the two formulations (docs/theory.md)
        # the remap keeps the kinetic energy, not the total: the default "total" also hands the
        # strain energy the remap changed to the velocities, which neither the convective term
        # nor the convection itself does (it moves the upper block's v_y at t = 0.1 by 8e-4,
        # as much as dropping the convection; "kinetic": 1e-4 from the convective term).
        # The report's pair forces: with moment-free ones the contact tractions' step-to-step
        # (odd-even) oscillation of the mid-point rule changes phase at t = 0.078 in one
        # formulation, so the end velocities differ by +-0.019 from step to step; averaged over
        # the last two steps they differ by 6.6e-4 (2.7e-4 here), and at dt = 0.003 the end
        # velocities differ by 7.7e-4 with either force (docs/theory.md)
        model = model_from_example("blocks_fast_sliding.toml",
                                   [*coarse_fast_sliding(mode, 0.006),
                                    'analysis.integrator="midpoint"',
                                    'bodies.1.ale.conserve_energy="kinetic"',
                                    "contact.0.moment_free=false"])
        sim = Simulation(model, [rec])
        if key == "dropped":
            with pytest.MonkeyPatch.context() as mp:
                mp.setattr(simulation_module, "convective_terms", lambda *args: [])
                sim.run()
        else:
            sim.run()
        energy = np.array([r.balance.total_energy for r in rec.records])
        momentum = np.array([r.balance.linear_momentum for r in rec.records])
        mass = np.asarray(model.assembler.nodal_mass(sim.state.X, False).sum(axis=1)).ravel()
        up = model.body("upper").nodes
        v_upper = mass[up] @ sim.state.v[up] / mass[up].sum()
        out[key] = (energy, momentum, v_upper)
    return out


def relative_energy_error(energy):
    return np.abs(energy - energy[0]).max() / energy[0]


def test_fast_sliding_energy_in_both_formulations(fast_sliding):
    """Energy: the mid-point step and the persistency contact conserve it; the ALE part (remap
    diffusion, masses of new particles) does not exactly. Measured (dt 0.006, coarse): remap
    0.167 %, convective term 0.173 %. The project's bound for this example is 1 %
    (test_examples_impact); the term must do no worse than 1.5 x the remap's error."""
    remap = relative_energy_error(fast_sliding["remap"][0])
    term = relative_energy_error(fast_sliding["term"][0])
    assert remap < 0.01 and term < 0.01
    assert term < 1.5 * remap


def test_fast_sliding_momentum_in_both_formulations(fast_sliding):
    """Momentum: the remap's rigid correction keeps it to round-off. The convective term does
    not: the new particles' masses at the moved nodes (with v kept) and C(c) v cancel only to
    first order in the slide and up to O(h) (F^-1 c interpolated vs. remapped X). Measured:
    |dp| = (1.2e-3, 5.6e-3), 0.64 % of |p0| = 0.865 (the report's drifts are 1.5-4 %)."""
    p_remap, p_term = fast_sliding["remap"][1], fast_sliding["term"][1]
    assert np.abs(p_remap - p_remap[0]).max() < 1e-9  # round-off of |p| ~ 1 over 17 steps
    drift = np.abs(p_term - p_term[0]).max()
    assert drift < 0.02 * np.linalg.norm(p_term[0])


def test_fast_sliding_formulations_agree(fast_sliding):
    """The upper block's mean velocity at t = 0.1: the two formulations differ by much less
    than dropping the convection does (measured 3.6e-4 vs 1.3e-3 of |v| ~ 3)."""
    v_remap, v_term, v_dropped = (fast_sliding[k][2] for k in ("remap", "term", "dropped"))
    assert np.abs(v_term - v_remap).max() < 0.5 * np.abs(v_dropped - v_remap).max()
    assert np.abs(v_term - v_remap).max() < 1e-3 * np.linalg.norm(v_remap)
