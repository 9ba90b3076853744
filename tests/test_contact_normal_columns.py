"""contact.csv gives each pair's normal (``normal_x``, ``normal_y``), so that the contact
resultant can be formed from the files, as docs/scenarios.md says: an independent tester's
impulse from contact.csv with the flat normal missed the ball's momentum change by 1.3 %
(session 41)."""

from __future__ import annotations

import numpy as np
import pytest

import ntncontact as ntc

OBLIQUE = {
    "analysis": {"kind": "dynamic", "dt": 0.004, "t_end": 0.2, "output_interval": 0.2,
                 "mass": "lumped"},
    "bodies": [
        {"name": "ball", "mesh": {"type": "rectangle", "width": 0.4, "height": 0.4, "nx": 4,
                                  "ny": 4, "origin": [-0.2, 0.01]},
         "material": {"model": "neo_hookean", "E": 1000.0, "nu": 0.3, "density": 1.0},
         "initial": {"velocity": [1.0, -1.0]}},
        {"name": "base", "mesh": {"type": "rectangle", "width": 2.0, "height": 0.3, "nx": 20,
                                  "ny": 2, "origin": [-1.0, -0.3]},
         "material": {"model": "neo_hookean", "E": 5000.0, "nu": 0.3, "density": 2.0}}],
    "contact": [{"name": "ib", "body_1": "ball", "surface_1": "bottom", "body_2": "base",
                 "surface_2": "top", "penalty_normal": 2000.0, "penalty_tangential": 2000.0,
                 "friction": 0.2}]}


def test_the_pairs_forces_along_their_normals_give_the_balls_momentum_change(tmp_path):
    result = ntc.run(ntc.scenario_from_dict(OBLIQUE), tmp_path / "out")
    c = result.contact
    n = c[["normal_x", "normal_y"]].to_numpy()
    assert np.allclose(np.linalg.norm(n, axis=1), 1.0)
    e = np.column_stack([-n[:, 1], n[:, 0]])  # n turned by +90 degrees
    # the force on body 1 is -(F_N n + F_T e), at t_{n+1/2}: over each step dt
    on_ball = -(c["normal_force"].to_numpy()[:, None] * n
                + c["tangential_force"].to_numpy()[:, None] * e)
    impulse = 0.004 * on_ball.sum(axis=0)

    first, last = result.fields(0.0), result.fields(0.2)
    ball = np.arange(len(first.points)) < 25  # the ball's 5 x 5 nodes come first
    mass = lumped_masses(first.points[:, :2], first.cells_dict["quad"], ball_cells=16)
    change = sum(sign * (mass[ball, None] * frame.point_data["velocity"][ball, :2]).sum(axis=0)
                 for sign, frame in ((1.0, last), (-1.0, first)))
    assert change[1] > 0.1  # the ball was stopped and thrown back up
    assert impulse == pytest.approx(change, rel=1e-6, abs=1e-9)


def lumped_masses(points: np.ndarray, quads: np.ndarray, ball_cells: int) -> np.ndarray:
    """Row-sum masses of the undeformed quads: a quarter of each cell's mass at each of its
    nodes (density 1 for the ball's cells, which come first, and 2 for the base's)."""
    x, y = points[quads][:, :, 0], points[quads][:, :, 1]
    area = 0.5 * np.abs(np.sum(x * np.roll(y, -1, axis=1) - y * np.roll(x, -1, axis=1), axis=1))
    density = np.where(np.arange(len(quads)) < ball_cells, 1.0, 2.0)
    mass = np.zeros(len(points))
    np.add.at(mass, quads, (area * density)[:, None] / 4.0)
    return mass
