"""Prescribed motion in dynamic runs: a supported dof ends each step at its motion's own
velocity (the rate of the time function's segment that ends there), not at the mid-point
rule's 2 v_{n+1/2} - v_n. From an independent tester (session 41): a rod's end pushed at 0.1
until t = 0.2, then held, kept v = +-0.1 and a = +-40 on the held nodes for ever, and its
reaction flipped sign every step (mean -0.008, standard deviation 0.72)."""

from __future__ import annotations

import numpy as np
import pytest

import ntncontact as ntc
from ntncontact.dynamics.midpoint import end_of_step
from ntncontact.fem.loads import Prescribed, TimeFunction, dirichlet_rates

DT, STOP, SPEED = 0.005, 0.1, 0.1


def push_stop(mass: str) -> ntc.Results:
    """A rod 5 x 0.5 (20 elements) whose left end is pushed at 0.1 until t = 0.1, then held."""
    push = {"times": [0.0, STOP, 1.0], "values": [0.0, SPEED * STOP, SPEED * STOP]}
    data = {"analysis": {"kind": "dynamic", "dt": DT, "t_end": 0.2, "output_interval": DT,
                         "mass": mass},
            "bodies": [{"name": "rod",
                        "mesh": {"type": "rectangle", "width": 5.0, "height": 0.5, "nx": 20,
                                 "ny": 1},
                        "material": {"model": "linear_elastic", "E": 1000.0, "nu": 0.3,
                                     "density": 2.0},
                        "supports": [{"set": "left", "x": 1.0, "function": push}]}]}
    return ntc.run(ntc.scenario_from_dict(data))


def test_the_rate_before_a_time_is_that_of_the_segment_ending_there():
    f = TimeFunction((0.0, 1.0, 3.0), (0.0, 2.0, 1.0))
    assert [f.rate_before(t) for t in (-1.0, 0.0, 0.5, 1.0, 2.0, 3.0, 4.0)] == [
        0.0, 0.0, 2.0, 2.0, -0.5, -0.5, 0.0]
    # two supports on one dof: the later one wins, as for the values
    first = Prescribed(np.array([0, 3]), np.array([1.0, 1.0]), f)
    second = Prescribed(np.array([3]), np.array([2.0]), TimeFunction((0.0, 1.0), (0.0, 1.0)))
    dofs, rates = dirichlet_rates((first, second), 1.0, 4)
    assert dofs.tolist() == [0, 3] and rates.tolist() == [2.0, 2.0]


def test_end_of_step_gives_prescribed_dofs_their_rate():
    """Dof 0 free, dof 1 prescribed, stopped in this step after moving at 0.1."""
    d_n, v_n, dt = np.zeros(2), np.array([0.1, 0.1]), 0.01
    d_half = np.array([0.0005, 0.0002])
    _, v1, a1 = end_of_step(d_half, d_n, v_n, dt, (np.array([1]), np.array([0.0])))
    assert v1 == pytest.approx([0.1, 0.0])  # the rule's 2 v_1/2 - v_n gave -0.02 at dof 1
    assert a1 == pytest.approx([0.0, -10.0])  # (0 - 0.1) / dt, not 2 (0.04 - 0.1) / dt


@pytest.mark.parametrize("mass", ["consistent", "lumped"])
def test_a_stopped_support_rests_and_its_reaction_does_not_alternate(mass):
    results = push_stop(mass)
    points = results.fields(0.0).points
    held = np.isclose(points[:, 0], 0.0)
    after = [t for t in results.times if t > STOP + 0.5 * DT]
    for t in after:
        v = results.fields(t).point_data["velocity"][held, 0]  # x held; y free
        assert np.abs(v).max() < 1e-12, (t, v)  # was +-0.1, alternating
    a = [results.fields(t).point_data["acceleration"][held, 0] for t in after]
    assert a[0] == pytest.approx(-SPEED / DT)  # the stop, spread over its step
    assert np.abs(a[1:]).max() < 1e-12  # was +-40 for ever
    h = results.history
    reaction = h["reaction_rod_left_x"].to_numpy()[h["time"].to_numpy() > STOP + DT]
    flips = np.mean(np.sign(reaction[1:]) != np.sign(reaction[:-1]))
    assert flips < 0.5  # was 1: every step


@pytest.mark.parametrize("mass", ["consistent", "lumped"])
def test_the_ledger_closes_with_the_supports_work(mass):
    """E - E0 - W_ext - W_support, W_support the sum of reaction . displacement increment,
    is round-off at every step but the stop's, where it is the energy of the held nodes'
    velocity jump: m dv^2 / 2 with a lumped mass (docs/theory.md, "Prescribed motion")."""
    h = push_stop(mass).history
    t = h["time"].to_numpy()
    u = np.interp(t, [0.0, STOP, 1.0], [0.0, SPEED * STOP, SPEED * STOP])
    work = np.concatenate([[0.0], np.cumsum(h["reaction_rod_left_x"].to_numpy()[1:]
                                            * np.diff(u))])
    energy = h["total_energy"].to_numpy()
    error = energy - energy[0] - h["external_work"].to_numpy() - work
    jumps = np.diff(error)
    kink = int(np.argmin(np.abs(t[1:] - (STOP + DT))))
    scale = np.abs(energy).max()
    assert np.abs(np.delete(jumps, kink)).max() < 1e-9 * scale
    if mass == "lumped":
        held_mass = 2.0 * 0.5 * 0.25 / 2.0  # two nodes, each a quarter of rho h dx
        assert jumps[kink] == pytest.approx(-0.5 * held_mass * SPEED**2, rel=1e-6)
    assert abs(jumps[kink]) < 0.05 * scale  # O(h): the held nodes carry the mass


def test_a_step_end_within_round_off_of_a_kink_takes_the_segment_that_ends_there():
    """Step 12 of dt = 0.025 ends at 0.30000000000000004: a kink at 0.3 gave the constant
    extension's rate 0 there, and a time point one ulp later the incoming one (a tester's
    reaction 1.3 % apart, session 41)."""
    f = TimeFunction((0.0, 0.11, 0.3), (0.0, 1.0, -1.0))
    incoming = -2.0 / 0.19
    for t in (12 * 0.025, 0.3, np.nextafter(0.3, 0.0), np.nextafter(0.3, 1.0)):
        assert f.rate_before(t) == pytest.approx(incoming)
    g = TimeFunction((0.0, 0.11, 0.30000000000000004), (0.0, 1.0, -1.0))
    assert g.rate_before(12 * 0.025) == pytest.approx(-2.0 / (0.30000000000000004 - 0.11))
    assert f.rate_before(0.31) == 0.0 and f.rate_before(0.2) == pytest.approx(incoming)
