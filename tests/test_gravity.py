"""Gravity loads (``type = "gravity"``, an acceleration): the body force rho g per volume."""

from __future__ import annotations

import numpy as np
import pytest
from helpers import Recorder, model_from_dict

from ntncontact.ale.motion import lumped_masses
from ntncontact.engine.simulation import Simulation
from ntncontact.fem.loads import LoadCase, MeshBodyForce, TimeFunction
from ntncontact.io.scenario import ScenarioError
from ntncontact.mesh.generators import disk

G = (0.7, -9.81)


def falling_disk(integrator: str, mass: str, v0=(0.3, 0.1), dt=0.01, steps=30) -> dict:
    return {
        "analysis": {"kind": "dynamic", "dt": dt, "t_end": dt * steps, "mass": mass,
                     "integrator": integrator},
        "bodies": [{
            "name": "disk",
            "mesh": {"type": "disk", "radius": 0.5, "n_circ": 16, "n_radial": 2,
                     "center": [0.0, 3.0]},
            "material": {"model": "neo_hookean", "E": 100.0, "nu": 0.3, "density": 2.5},
            "initial": {"velocity": list(v0)},
            "loads": [{"type": "gravity", "vector": list(G)}],
        }],
    }


@pytest.mark.parametrize("integrator", ["midpoint", "energy_momentum"])
@pytest.mark.parametrize("mass", ["consistent", "lumped"])
def test_a_free_falling_body_accelerates_at_g(integrator, mass):
    """No internal force in a rigid translation, and int rho N_a g dV is the mass matrix's row
    sum times g (partition of unity): every node's acceleration is g, which the mid-point rule
    integrates exactly (constant acceleration: v = v0 + g t, x = X + v0 t + g t^2 / 2)."""
    rec = Recorder()
    model = model_from_dict(falling_disk(integrator, mass))
    Simulation(model, [rec]).run()
    assert rec.status == ("completed", None) and len(rec.records) >= 30
    g, v0 = np.array(G), np.array([0.3, 0.1])
    for record in rec.records:
        t, state = record.state.time, record.state
        # Newton stops at 1e-10 of the force scale (rho g V): the velocity to that of g t
        assert np.abs(state.v - (v0 + g * t)).max() <= 1e-10 * np.linalg.norm(g) * max(t, 1.0)
        expected = model.X0 + v0 * t + 0.5 * g * t**2
        assert np.abs(state.x - expected).max() <= 1e-10 * np.linalg.norm(g) * max(t, 1.0)


def column(g, function=None) -> dict:
    load = {"type": "gravity", "vector": list(g)}
    if function is not None:
        load["function"] = function
    return {
        "analysis": {"kind": "static", "dt": 0.5, "t_end": 1.0},
        "bodies": [{
            "name": "column",
            "mesh": {"type": "rectangle", "width": 1.0, "height": 3.0, "nx": 3, "ny": 9,
                     "grading_y": 2.0},
            "material": {"model": "linear_elastic", "E": 1000.0, "nu": 0.3, "density": 2.0},
            "supports": [{"set": "bottom", "x": 0.0, "y": 0.0}],
            "loads": [load],
        }],
    }


@pytest.mark.parametrize("g", [(0.0, -10.0), (3.0, -10.0)])
def test_a_static_column_rests_on_its_weight(g):
    """The support's reaction is the column's weight, rho g times its area, whatever the
    direction of g (and ramped with a time function)."""
    rec = Recorder()
    ramp = {"times": [0.0, 1.0], "values": [0.0, 1.0]}
    Simulation(model_from_dict(column(g, ramp)), [rec]).run()
    assert rec.status == ("completed", None)
    weight = 2.0 * 3.0 * np.array(g)  # rho * area * g
    for record in rec.records[1:]:
        scale = record.state.time  # the ramp
        reaction = np.array([record.extra["reaction_column_bottom_x"],
                             record.extra["reaction_column_bottom_y"]])
        # the reaction balances the load: Newton's 1e-10 of the force scale
        np.testing.assert_allclose(reaction, -scale * weight, rtol=0,
                                   atol=1e-9 * np.abs(weight).max())
    assert abs(weight[1]) > 0 and rec.records[-1].extra["reaction_column_bottom_y"] > 0


def test_gravity_on_a_moved_mesh_is_the_lumped_mass_times_g():
    """On an ALE body the nodal gravity follows the moved reference mesh: the masses it
    carries (row sums of the rebuilt mass matrix) times g, for any node positions."""
    mesh = disk(1.0, 16, 2)
    rng = np.random.default_rng(3)
    moved = mesh.nodes + 0.02 * rng.standard_normal(mesh.nodes.shape)
    rho, g = 1.7, np.array(G)
    load = MeshBodyForce(mesh.cells, rho * g, TimeFunction())
    ndof = 2 * mesh.n_nodes
    expected = lumped_masses(moved, mesh.cells, rho)[:, None] * g
    np.testing.assert_allclose(load.vector(moved, ndof).reshape(-1, 2), expected, rtol=1e-13,
                               atol=1e-15)
    case = LoadCase((), (), (load,), mesh.nodes)
    total = case(0.0, ndof).reshape(-1, 2).sum(axis=0)  # unmoved: on X0, the weight rho A g
    area = 0.5 * 16 * np.sin(2 * np.pi / 16)
    np.testing.assert_allclose(total, rho * area * g, rtol=1e-13)
    assert not np.allclose(case(0.0, ndof, moved), case(0.0, ndof))


@pytest.mark.parametrize("load, expected", [
    ({"type": "gravity", "vector": [0.0, -1.0], "set": "all"}, "acts on the whole body"),
    ({"type": "gravity"}, "a gravity load needs 'vector'"),
    ({"type": "gravity", "value": 9.81}, "a gravity load needs 'vector'"),
])
def test_bad_gravity_entries_are_clear_errors(load, expected):
    data = column((0.0, -1.0))
    data["bodies"][0]["loads"] = [load]
    with pytest.raises(ScenarioError, match=expected):
        model_from_dict(data)
