"""ALE bodies in the time loop: node-to-node contact kept on non-matching meshes."""

import numpy as np
from helpers import Recorder, model_from_dict

from ntncontact.engine.simulation import Simulation


def two_blocks(nx_top=5, nx_base=5, motion="ale", pressure=2.0, kind="static", extra=None):
    return model_from_dict({
        "analysis": {"kind": kind, "dt": 0.5, "t_end": 1.0},
        "bodies": [
            {"name": "top",
             "mesh": {"type": "rectangle", "width": 2.0, "height": 1.0, "nx": nx_top, "ny": 3,
                      "origin": [0.0, 1.0]},
             "material": {"model": "linear_elastic", "E": 100.0, "nu": 0.0, "density": 1.0},
             "supports": [{"set": "left", "x": 0.0}],
             "loads": [{"type": "pressure", "set": "top", "value": pressure,
                        "function": {"times": [0.0, 1.0], "values": [0.0, 1.0]}}]},
            {"name": "base", "mesh_motion": motion,
             "mesh": {"type": "rectangle", "width": 2.0, "height": 1.0, "nx": nx_base, "ny": 4,
                      "grading_x": 3.0},
             "material": {"model": "linear_elastic", "E": 100.0, "nu": 0.0, "density": 1.0},
             "supports": [{"set": "bottom", "y": 0.0}, {"set": "left", "x": 0.0}]},
        ],
        "contact": [{"body_1": "top", "surface_1": "bottom", "body_2": "base",
                     "surface_2": "top", "penalty_normal": 1e4,
                     "augmentation": {"gap_tolerance": 1e-12}} | (extra or {})],
    })


def test_node_to_node_patch_test_on_non_matching_meshes_gives_uniform_pressure():
    """The base's surface nodes are graded (non-matching); the ALE base moves them under the
    top block's nodes: exact node-to-node, so the uniform pressure is transmitted exactly
    (a node-to-segment scheme fails this)."""
    rec = Recorder()
    sim = Simulation(two_blocks(), [rec])
    sim.run()
    rows = rec.records[-1].extra["contact_rows"]
    assert len(rows["node_1"]) == 6
    np.testing.assert_allclose(rows["normal_traction"], 2.0, rtol=1e-7)
    x = sim.state.x
    pairs = np.column_stack([rows["node_1"], rows["node_2"]])
    # every pair is exactly node to node (the ALE node sits under its partner)
    assert np.abs(x[pairs[:, 0], 0] - x[pairs[:, 1], 0]).max() < 1e-9
    # the base mesh stays valid and its material positions stay inside the base
    base = sim.model.body("base").nodes
    assert sim.state.X[base, 1].max() <= 1.0 + 1e-12 and sim.state.X[base, 1].min() >= -1e-12


def test_without_ale_the_same_non_matching_meshes_do_not_transmit_uniform_pressure():
    rec = Recorder()
    Simulation(two_blocks(motion="lagrangian"), [rec]).run()
    rows = rec.records[-1].extra["contact_rows"]
    # node-to-node pairing of non-matching nodes: forces act between offset points, so the
    # nodal pressure is not the applied one everywhere (this is what the ALE motion fixes)
    assert np.abs(rows["normal_traction"] - 2.0).max() > 1e-3


def test_ordered_partners_are_distinct_and_keep_the_surface_order():
    from ntncontact.contact import ContactSurface, Interface, ordered_partners

    top = np.column_stack([np.linspace(0, 2, 6)[::-1], np.ones(6)])  # walked right to left
    base = np.column_stack([2.0 * np.linspace(0, 1, 6) ** 2, np.ones(6)])  # clustered at 0
    x = np.vstack([top, base])
    interface = Interface(ContactSurface(np.arange(6)), ContactSurface(np.arange(6, 12)))
    partners = ordered_partners(x, interface, np.arange(6))
    # nearest-node pairing would give node 6 (x = 0.08) to both x = 0 and x = 0.4; pulling
    # the cluster out to pair all six would move base nodes farther than a segment (0.48 >
    # 0.4): the node at x = 1.6 stays unpaired, every other one gets its nearest base node
    np.testing.assert_array_equal(partners, [11, -1, 10, 9, 8, 6])
    paired = partners >= 0
    assert np.all(np.diff(x[partners[paired][::-1], 0]) > 0)  # order along the surfaces kept
    # a taken node is not used: x = 0.4 then takes the next base node within reach (0.08)
    np.testing.assert_array_equal(ordered_partners(x, interface, np.arange(6), taken=[8]),
                                  [11, -1, 10, 9, 7, 6])
