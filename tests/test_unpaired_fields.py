"""The frames' contact fields at surface-1 nodes in no pair that carry a share of the pairs'
forces (``unpaired_share`` beside an ALE body, contact/transfer.py).

Tester V: a block with 8 elements across pressed uniformly onto an ALE base with 5 read
``contact_pressure`` 9.96 / 0 / 9.96 ... and ``contact_status`` 0 ("open") at the three unpaired
nodes of its bottom, and the field integrated along the surface to 12.5 of a load of 20.
"""

from __future__ import annotations

import numpy as np
import pytest

from ntncontact import api
from ntncontact.engine.postprocess import SHARED, SLIP, STICK, contact_node_fields

P = 10.0


def _pressed(traction_x: float = 0.0, nx_base: int = 5) -> dict:
    """The tester's press_mis_ale_same.toml; ``traction_x`` adds a shear on the block's top,
    whose moment makes the contact pressure vary along the face (friction carries it)."""
    loads = [{"type": "pressure", "set": "top", "value": P,
              "function": {"times": [0.0, 1.0], "values": [0.0, 1.0]}}]
    if traction_x:
        loads.append({"type": "traction", "set": "top", "vector": [traction_x, 0.0],
                      "function": {"times": [0.0, 1.0], "values": [0.0, 1.0]}})
    material = {"model": "linear_elastic", "E": 1000.0, "nu": 0.3, "density": 1.0}
    contact = {"name": "c", "body_1": "block", "surface_1": "bottom", "body_2": "base",
               "surface_2": "top", "method": "augmented_lagrangian", "penalty_normal": 1.0e6}
    supports = [{"set": "left", "x": 0.0}]
    if traction_x:  # friction alone holds the block sideways
        contact |= {"friction": 0.5, "penalty_tangential": 1.0e6}
        supports = []
    return {
        "title": "block pressed on an ALE base with fewer surface nodes",
        "analysis": {"kind": "static", "dt": 1.0, "t_end": 2.0},
        "bodies": [
            {"name": "block", "material": material, "loads": loads,
             "mesh": {"type": "rectangle", "width": 2.0, "height": 1.0, "nx": 8, "ny": 4,
                      "origin": [0.0, 1.0]},
             "supports": supports},
            {"name": "base", "mesh_motion": "ale", "material": material,
             "mesh": {"type": "rectangle", "width": 2.0, "height": 1.0, "nx": nx_base,
                      "ny": 3},
             "supports": [{"set": "bottom", "y": 0.0}, {"set": "left", "x": 0.0}]},
        ],
        "contact": [contact],
    }


def _last_frame(data: dict, tmp_path):
    """(contact-field point data of the block's bottom nodes 0..8, their current x, the last
    step's contact.csv rows)."""
    results = api.run(api.scenario_from_dict(data), out=tmp_path / "out")
    t = results.times[-1]
    frame = results.fields(t)
    bottom = np.arange(9)  # the 8 x 4 rectangle numbers its bottom row first
    x = frame.points[bottom, :2] + frame.point_data["displacement"][bottom, :2]
    rows = results.contact[np.isclose(results.contact["time"], t, rtol=0.0, atol=1e-12)]
    return {k: v[bottom] for k, v in frame.point_data.items()}, x, rows


def _integral(values: np.ndarray, x: np.ndarray) -> float:
    """The trapezoid rule along the current surface (the docs' ParaView recipe)."""
    return float(np.trapezoid(values, x[:, 0]))


def test_unpaired_nodes_carry_the_uniform_pressure_and_it_integrates_to_the_load(tmp_path):
    p, x, rows = _last_frame(_pressed(), tmp_path)
    paired = rows["node_1"].to_numpy()
    unpaired = np.setdiff1d(np.arange(9), paired)
    assert len(paired) == 6 and len(unpaired) == 3
    assert np.all(p["contact_status"][unpaired] == SHARED)
    assert np.all(np.isin(p["contact_status"][paired], (STICK, SLIP)))
    # uniform: every node reads the pairs' traction (per current length)
    np.testing.assert_allclose(p["contact_pressure"], rows["normal_traction"].iloc[0],
                               rtol=1e-9)
    # the pair-force sum is the load; the field now integrates to it (was 12.5 of 20)
    total = rows["normal_force"].sum()
    np.testing.assert_allclose(total, 2.0 * P, rtol=1e-9)
    np.testing.assert_allclose(_integral(p["contact_pressure"], x), total, rtol=1e-9)
    # the pairs' own values are contact.csv's, and gap and partner stay pair values
    np.testing.assert_array_equal(p["contact_pressure"][paired], rows["normal_traction"])
    assert np.all(p["contact_partner"][unpaired] == -1)
    assert not np.any(p["contact_gap"][unpaired])


def test_a_varying_pressure_and_friction_integrate_to_the_pair_forces(tmp_path):
    """A shear on the top tilts the pressure along the face (moment) and loads the friction:
    both fields integrate to the pair-force sums within the trapezoid rule's error."""
    p, x, rows = _last_frame(_pressed(traction_x=1.0), tmp_path)
    unpaired = np.setdiff1d(np.arange(9), rows["node_1"].to_numpy())
    assert np.all(p["contact_status"][unpaired] == SHARED)
    pressure = p["contact_pressure"]
    assert np.ptp(pressure) > 0.05 * P  # not uniform: the check below is not the one above
    normal, tangential = rows["normal_force"].sum(), rows["tangential_force"].sum()
    assert abs(tangential) > 0.01 * normal
    # the trapezoid rule's error on this smooth field: measured 6e-6 (normal) and 6e-6
    # (tangential) of the sums; 0 at the unpaired nodes (the old frames) misses ~1/3 of them
    np.testing.assert_allclose(_integral(pressure, x), normal, rtol=1e-3)
    np.testing.assert_allclose(_integral(p["contact_tangential_traction"], x), tangential,
                               rtol=1e-3)


@pytest.mark.parametrize("nx_base", [8])
def test_equal_counts_have_no_shared_nodes(tmp_path, nx_base):
    """Node to node (no transfer): the frame is the pairs' rows, as before."""
    p, x, rows = _last_frame(_pressed(nx_base=nx_base), tmp_path)
    assert len(rows) == 9
    assert not np.any(p["contact_status"] == SHARED)
    np.testing.assert_array_equal(p["contact_pressure"][rows["node_1"].to_numpy()],
                                  rows["normal_traction"])


def test_a_node_paired_on_another_interface_keeps_its_pair_values():
    """Two interfaces on one surface: a node shared on one and paired on the other shows its
    pair (contact.csv's row), not the share."""
    rows = {"node_1": np.array([1]), "node_2": np.array([9]), "normal_traction": np.array([5.0]),
            "tangential_traction": np.array([0.5]), "gap": np.array([1e-3]),
            "gap_rate": np.array([np.nan]), "status": np.array(["stick"])}
    shares = {"node": np.array([1, 2]), "normal_traction": np.array([7.0, 8.0]),
              "tangential_traction": np.array([0.7, 0.8])}
    out = contact_node_fields(rows, 4, shares)
    np.testing.assert_array_equal(out["contact_pressure"], [0.0, 5.0, 8.0, 0.0])
    np.testing.assert_array_equal(out["contact_tangential_traction"], [0.0, 0.5, 0.8, 0.0])
    np.testing.assert_array_equal(out["contact_status"], [0, STICK, SHARED, 0])
    np.testing.assert_array_equal(out["contact_partner"], [-1, 9, -1, -1])
