"""Support sets that meet: reaction columns that would share a name, and one dof given two
prescribed motions (tester V, findings 2 and 3)."""

from __future__ import annotations

import numpy as np
import pytest
from helpers import model_from_dict

from ntncontact.engine.reactions import reaction_columns, support_sets
from ntncontact.fem.loads import dirichlet_values
from ntncontact.io.scenario import ScenarioError


def _body(name: str, supports: list[dict], origin: tuple[float, float] = (0.0, 0.0)) -> dict:
    return {"name": name,
            "mesh": {"type": "rectangle", "width": 1.0, "height": 2.0, "nx": 2, "ny": 4,
                     "origin": list(origin)},
            "material": {"model": "linear_elastic", "E": 1000.0, "nu": 0.3, "density": 1.0},
            "supports": supports}


def _scenario(*bodies: dict) -> dict:
    return {"analysis": {"kind": "static", "dt": 1.0, "t_end": 1.0}, "bodies": list(bodies)}


def test_two_support_sets_whose_reaction_columns_share_a_name_are_refused():
    """Body 'b' set 'corner_top_left' and body 'b_corner_top' set 'left' both label their
    columns reaction_b_corner_top_left_*: history.csv had one column holding the sum of the
    two reactions (the tester's -12 for supports carrying -5 and -7)."""
    bottom = {"set": "bottom", "y": 0.0}
    data = _scenario(_body("b", [{"set": "corner_top_left", "x": 0.0}, bottom]),
                     _body("b_corner_top", [{"set": "left", "x": 0.0}, bottom], origin=(5.0, 0.0)))
    with pytest.raises(ScenarioError, match=r"bodies.0 \('b'\) set 'corner_top_left' and "
                       r"bodies.1 \('b_corner_top'\) set 'left'.*reaction_b_corner_top_left_x"
                       r".*rename"):
        model_from_dict(data)


def test_one_set_named_twice_in_a_body_keeps_its_one_set_of_columns():
    data = _scenario(_body("b", [{"set": "left", "x": 0.0}, {"set": "left", "y": 0.0}]))
    model = model_from_dict(data)
    assert reaction_columns(model) == ("reaction_b_left_x", "reaction_b_left_y",
                                       "reaction_b_left_moment")


def _column(supports: list[dict]) -> dict:
    return _scenario(_body("col", supports))


def test_two_supports_prescribing_different_values_to_a_dof_are_refused():
    """'bottom' y = 0 and 'corner_bottom_left' y = 0.05: the corner took whichever came last
    in the file (y = 0.05 or 0.0, the tester's conflict1/conflict2)."""
    bottom, corner = {"set": "bottom", "y": 0.0}, {"set": "corner_bottom_left", "y": 0.05}
    for supports, first, second in (([bottom, corner], "0 \\(set 'bottom'\\)",
                                      "1 \\(set 'corner_bottom_left'\\)"),
                                     ([corner, bottom], "0 \\(set 'corner_bottom_left'\\)",
                                      "1 \\(set 'bottom'\\)")):
        with pytest.raises(ScenarioError, match=rf"bodies.0 \('col'\): supports.{first} and "
                           rf"supports.{second} prescribe different y displacements to node 0 "
                           r"of body 'col' at \(0, 0\)"):
            model_from_dict(_column(supports))


def test_the_same_value_under_different_time_functions_is_refused():
    ramp = {"times": [0.0, 1.0], "values": [0.0, 1.0]}
    supports = [{"set": "left", "x": 0.1}, {"set": "corner_top_left", "x": 0.1, "function": ramp}]
    with pytest.raises(ScenarioError, match=r"x displacements to node 12 of body 'col' at "
                       r"\(0, 2\): 0.1 and 0.1 x s\(t\)"):
        model_from_dict(_column(supports))


def test_the_same_motion_from_two_sets_is_accepted_and_reacts_in_the_last_set():
    """y = 0 twice at a corner (held by 'bottom' and 'corner_bottom_left') is the common case;
    so is the same motion given once as 0.2 x ramp and once as 0.1 x (twice the ramp): the
    motions are compared as functions of time, not as objects."""
    ramp = {"times": [0.0, 1.0], "values": [0.0, 1.0]}
    double = {"times": [0.0, 1.0], "values": [0.0, 2.0]}
    model = model_from_dict(_column([
        {"set": "bottom", "y": 0.0}, {"set": "corner_bottom_left", "x": 0.0, "y": 0.0},
        {"set": "right", "x": 0.2, "function": ramp},
        {"set": "corner_top_right", "x": 0.1, "function": double}]))
    dofs, values = dirichlet_values(model.prescribed, 0.5, model.ndof)
    assert values[dofs == 28][0] == pytest.approx(0.1)  # node 14, the top right corner, x
    sets = support_sets(model)
    assert 1 in sets["col_corner_bottom_left"] and 1 not in sets["col_bottom"]
    assert 28 in sets["col_corner_top_right"] and 28 not in sets["col_right"]
    assert np.array_equal(np.sort(np.concatenate(list(sets.values()))), dofs)
