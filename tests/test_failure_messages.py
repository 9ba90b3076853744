"""A step that runs out of halvings says where its last attempt stopped, and an element the
solve found inverted is named once, with its body (tester Q finding 10: "step 1 (t = 0 -> 1)
failed after 6 halvings" without the sub-step; "element 4 is inverted in the current
configuration (det J = -1.795e-03): element 4 of body 'block'")."""

import re

import pytest
from helpers import model_from_example

import ntncontact as ntc
from ntncontact.engine.diagnostics import element_label
from ntncontact.engine.simulation import SimulationError


def compressed(dt: float) -> dict:
    """Tester Q's nh_comp: a Neo-Hookean unit block (4 x 4) on a stiff base, its top pushed
    down 1.1 (110 %: impossible) over t = 0..1, Lagrange multipliers, frictionless."""
    push = {"set": "top", "y": -1.1, "function": {"times": [0.0, 1.0], "values": [0.0, 1.0]}}
    return {"analysis": {"kind": "static", "dt": dt, "t_end": 1.0, "max_cutbacks": 6,
                         "newton": {"max_iterations": 40}},
            "bodies": [{"name": "block", "mesh": {"type": "rectangle", "width": 1.0,
                                                  "height": 1.0, "nx": 4, "ny": 4,
                                                  "origin": [1.0, 1.0]},
                        "material": {"model": "neo_hookean", "E": 100.0, "nu": 0.3,
                                     "density": 1.0},
                        "supports": [push, {"set": "corner_top_left", "x": 0.0}]},
                       {"name": "base", "mesh": {"type": "rectangle", "width": 4.0,
                                                 "height": 1.0, "nx": 16, "ny": 4},
                        "material": {"model": "linear_elastic", "E": 1.0e7, "nu": 0.3,
                                     "density": 1.0},
                        "supports": [{"set": "bottom", "x": 0.0, "y": 0.0}]}],
            "contact": [{"name": "c", "body_1": "block", "surface_1": "bottom",
                         "body_2": "base", "surface_2": "top", "method": "lagrange",
                         "law": "gap"}]}


def failure(dt: float) -> str:
    with pytest.raises(SimulationError) as info:
        ntc.run(ntc.scenario_from_dict(compressed(dt)))
    return str(info.value)


def test_a_failed_step_names_its_last_sub_step():
    message = failure(1.0)
    assert message.startswith("step 1 (t = 0 -> 1) failed after 6 halvings of the step: ")
    found = re.search(r"sub-steps converged to t = ([0-9.]+), the last attempt was "
                      r"t = ([0-9.]+) -> ([0-9.]+)$", message)
    assert found, message
    reached, start, end = (float(g) for g in found.groups())
    assert reached == start and 0.5 < start < 1.0  # measured: 0.890625 -> 0.90625
    assert end - start == pytest.approx(2.0 ** -6)  # the sixth halving's sub-step


def test_an_inverted_element_is_named_once_with_its_body():
    message = failure(0.1)
    assert "element 4 of body 'block' (global element 4; centred at (1.125, 1.375) in the " \
           "reference mesh) is inverted in the current configuration" in message
    assert "element 4 is inverted" not in message and "): element 4 of body" not in message
    assert message.count("of body 'block'") == 1, message


def test_a_file_element_is_named_by_its_file_number_and_place():
    """Run errors named internal numbers only (session 42's noticed item): an element of a
    gmsh mesh is named by its body, its number there, the file's element number and its
    reference centre, and the undefined normal's nodes by their file numbers too."""
    model = model_from_example("block_sliding.toml")
    block = model.body("block")
    local = block.mesh.n_cells - 1
    label = element_label(model, block.cell_offset + local)
    file_number = int(block.mesh.file_element_ids[local])
    centre = block.mesh.nodes[block.mesh.cells[local]].mean(axis=0)
    assert label == (f"element {local} of body 'block' (global element "
                     f"{block.cell_offset + local}, file element {file_number}; centred at "
                     f"({centre[0]:.6g}, {centre[1]:.6g}) in the reference mesh)")
    assert file_number != local  # gmsh numbers its quads after the lines and points
    generated = model.body("foundation")
    assert "file element" not in element_label(model, generated.cell_offset)
