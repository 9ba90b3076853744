"""Scenarios the builder refuses or warns about because they cannot run as written: redundant
tie and Lagrange constraints (a singular matrix), a penalty interface that cannot carry the
load it is named for (tester C, session 41)."""

from __future__ import annotations

import copy
import warnings

import pytest
from helpers import model_from_dict, model_from_example

from ntncontact.engine.diagnostics import PhysicsWarning
from ntncontact.io.scenario import ScenarioError


def _block(name: str, width: float, height: float, nx: int, ny: int, origin: list[float],
           **extra) -> dict:
    return {"name": name, "mesh": {"type": "rectangle", "width": width, "height": height,
                                   "nx": nx, "ny": ny, "origin": origin},
            "material": {"model": "neo_hookean", "E": 1000.0, "nu": 0.3, "density": 1.0},
            **extra}


def _tie(name: str, body_1: str, surface_1: str, body_2: str, surface_2: str) -> dict:
    return {"name": name, "body_1": body_1, "surface_1": surface_1, "body_2": body_2,
            "surface_2": surface_2}


def _t_junction(close_loop: bool) -> dict:
    """A and C side by side on B, tied to it; ``close_loop``: A and C tied to each other too,
    so the corner node where the three meet is held twice (tester C's tie_tjunction.toml)."""
    ties = [_tie("AB", "A", "bottom", "B", "top"), _tie("CB", "C", "bottom", "B", "top")]
    if close_loop:
        ties.append(_tie("AC", "A", "right", "C", "left"))
    load = [{"type": "traction", "set": "top", "vector": [10.0, -50.0]}]
    return {"analysis": {"kind": "static", "dt": 0.5, "t_end": 1.0},
            "bodies": [_block("B", 2.0, 0.5, 8, 2, [-1.0, 0.0],
                              supports=[{"set": "bottom", "x": 0.0, "y": 0.0}]),
                       _block("A", 1.0, 0.5, 4, 2, [-1.0, 0.5], loads=load),
                       _block("C", 1.0, 0.5, 4, 2, [0.0, 0.5], loads=load)],
            "tie": ties}


def test_three_ties_around_one_corner_are_refused_naming_the_node_and_the_ties():
    model_from_dict(_t_junction(close_loop=False))  # runs today: exact tie forces
    with pytest.raises(ScenarioError) as err:
        model_from_dict(_t_junction(close_loop=True))
    line = str(err.value)
    assert "\n" not in line
    assert line.startswith("tie 'AC' holds node 4 of body 'A' at (0, 0.5) to node 0 of body "
                           "'C' at (0, 0.5), which tie(s) 'AB', 'CB' already hold together")
    assert "drop one of the ties" in line


def test_a_node_tied_to_two_supported_nodes_is_refused_through_the_supports():
    data = _t_junction(close_loop=False)
    data["bodies"][1]["supports"] = [{"set": "right", "x": 0.0, "y": 0.0}]
    data["bodies"][2]["supports"] = [{"set": "left", "x": 0.0, "y": 0.0}]
    # A's and C's touching faces both held: the corner of B is tied to two held nodes
    with pytest.raises(ScenarioError, match="which the supports and tie"):
        model_from_dict(data)


def test_a_tied_node_in_a_lagrange_interface_is_refused_with_the_exclude_advice():
    lagrange = ["analysis.t_end=1.0", 'contact.0.method="lagrange"']
    with pytest.raises(ScenarioError) as err:
        model_from_example("delamination.toml", [*lagrange, "contact.0.exclude=[]"])
    line = str(err.value)
    assert line.startswith("contact.0 ('delamination', method = \"lagrange\"): node 8 of "
                           "body 'upper' at (16, 10) is a contact candidate and tie(s) 'bond' "
                           "hold it to node 173 of body 'lower' at (16, 10)")
    assert 'exclude = ["tips"]' in line and "\n" not in line
    # as shipped (exclude = ["tips"]), and the augmented Lagrangian without exclude, run
    model_from_example("delamination.toml", lagrange)
    model_from_example("delamination.toml", ["contact.0.exclude=[]"])


def _stack4(loaded: tuple[str, ...]) -> dict:
    """Tester C's stack4_pen.toml: base, b1, b2, b3 stacked, penalty interfaces i1 = b1/base,
    i2 = b2/b1, i3 = b3/b2, gravity on the ``loaded`` bodies."""
    gravity = [{"type": "gravity", "vector": [0.0, -10.0]}]
    bodies = [_block("base", 2.0, 0.5, 4, 1, [-1.0, -0.5],
                     supports=[{"set": "bottom", "x": 0.0, "y": 0.0}])]
    bodies += [_block(f"b{k}", 1.0, 0.5, 2, 1, [-0.5, 0.5 * (k - 1)]) for k in (1, 2, 3)]
    for body in bodies:
        body["loads"] = copy.deepcopy(gravity) if body["name"] in loaded else []
    contact = [{"name": f"i{k}", "body_1": f"b{k}", "surface_1": "bottom",
                "body_2": "base" if k == 1 else f"b{k - 1}", "surface_2": "top",
                "method": "penalty", "penalty_normal": 100.0} for k in (1, 2, 3)]
    return {"analysis": {"kind": "dynamic", "dt": 0.01, "t_end": 1.0},
            "bodies": bodies, "contact": contact}


def _penalty_lines(data: dict) -> list[str]:
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        model_from_dict(data)
    return [str(w.message) for w in caught
            if w.category is PhysicsWarning and "cannot carry" in str(w.message)]


def test_the_penalty_rate_law_warning_names_a_loaded_body_of_each_interface():
    lines = _penalty_lines(_stack4(("base", "b1", "b2", "b3")))
    named = [line.split("sustained gravity on ")[1].split(":")[0] for line in lines]
    assert named == ["'b1'", "'b2'", "'b3'"]
    # gravity on the top block only: it presses every interface below it
    lines = _penalty_lines(_stack4(("base", "b3")))
    assert all("gravity on 'b3'" in line for line in lines) and len(lines) == 3


def _row(surface_b: str = "right", origin_c: tuple[float, float] = (0.1, 0.05)) -> dict:
    """Tester C's cradle3.toml: blocks A, B, C in a row, interfaces A/B and B/C."""
    bodies = [_block("A", 0.5, 0.5, 5, 5, [-1.1, 0.1], initial={"velocity": [3.0, 0.0]}),
              _block("B", 0.5, 0.6, 6, 6, [-0.5, 0.0]),
              _block("C", 0.5, 0.5, 5, 5, list(origin_c))]
    contact = [{"name": "AB", "body_1": "A", "surface_1": "right", "body_2": "B",
                "surface_2": "left", "penalty_normal": 3000.0},
               {"name": "BC", "body_1": "B", "surface_1": surface_b, "body_2": "C",
                "surface_2": "left", "penalty_normal": 3000.0}]
    return {"analysis": {"kind": "dynamic", "dt": 0.002, "t_end": 0.02},
            "bodies": bodies, "contact": contact}


def test_a_surface_on_the_far_side_of_its_body_is_refused_naming_the_key():
    model_from_dict(_row())
    with pytest.raises(ScenarioError) as err:
        model_from_dict(_row(surface_b="left"))
    line = str(err.value)
    assert line.startswith("contact.1 ('BC'): surface_1 'left' of 'B' and surface_2 'left' of "
                           "'C' face away from each other at t = 0")
    assert "change contact.1.surface_1 or surface_2" in line and "\n" not in line
    # the same row far apart, C 10 units on: still facing each other, still built
    model_from_dict(_row(origin_c=(10.0, 0.05)))


def test_surfaces_that_face_each_other_are_built_whatever_their_shape():
    """Concave partners (a disk in a ring, near and far from its wall) and the examples with
    curved surfaces: their nearest normals are opposed."""
    ring = {"name": "ring", "mesh": {"type": "annulus", "r_inner": 1.0, "r_outer": 1.3,
                                     "n_radial": 2, "n_circ": 48},
            "material": {"model": "neo_hookean", "E": 1000.0, "nu": 0.3, "density": 1.0}}
    for center in ([0.0, 0.0], [0.0, -0.69]):
        disk = {"name": "disk", "mesh": {"type": "disk", "radius": 0.3, "n_circ": 32,
                                         "n_radial": 3, "center": center},
                "material": ring["material"]}
        data = {"analysis": {"kind": "dynamic", "dt": 0.01, "t_end": 0.1},
                "bodies": [disk, ring],
                "contact": [{"body_1": "disk", "surface_1": "outer", "body_2": "ring",
                             "surface_2": "inner", "penalty_normal": 100.0}]}
        model_from_dict(data)
        data["contact"][0]["surface_2"] = "outer"  # the ring's far side: refused
        with pytest.raises(ScenarioError, match="face away from each other"):
            model_from_dict(data)
    for name in ("ring_impact.toml", "hertz.toml", "disk_drop.toml", "rod_impact.toml"):
        model_from_example(name)


def test_bodies_overlapping_at_t0_with_no_interface_are_refused_naming_node_and_depth():
    with pytest.raises(ScenarioError) as err:
        model_from_dict(_row(origin_c=(-0.9, 0.4)))  # C 0.2 deep inside A, no A/C interface
    assert str(err.value) == (
        "bodies 'A' and 'C' overlap at t = 0 and no [[contact]] joins them: node 34 of 'A' at "
        "(-0.7, 0.6) is 0.2 deep inside 'C', and nothing would push it out; place the bodies "
        "apart (bodies.*.mesh origin, center or transform)")
    # touching bodies are no overlap: tied parts (the T-junction)
    model_from_dict(_t_junction(close_loop=False))


def tied_squares(x_b: float, function_b: dict | None = None) -> dict:
    """Two static squares tied along a shared edge, each top corner on it held in x: a's at
    0, b's at ``x_b`` (times ``function_b``, if given)."""
    def square(name, origin, supports):
        return {"name": name, "mesh": {"type": "rectangle", "width": 0.5, "height": 0.5,
                                       "nx": 2, "ny": 2, "origin": origin},
                "material": {"model": "linear_elastic", "E": 1000.0, "nu": 0.3,
                             "density": 1.0},
                "supports": supports,
                "loads": [{"type": "pressure", "set": "top", "value": 10.0}]}
    corner_b = {"set": "corner_top_left", "x": x_b} | (
        {} if function_b is None else {"function": function_b})
    return {"analysis": {"kind": "static", "dt": 1.0, "t_end": 1.0},
            "bodies": [square("a", [-0.5, 0.0], [{"set": "bottom", "x": 0.0, "y": 0.0},
                                                {"set": "corner_top_right", "x": 0.0}]),
                       square("b", [0.0, 0.0], [{"set": "bottom", "y": 0.0}, corner_b])],
            "tie": [{"name": "ab", "body_1": "a", "surface_1": "right", "body_2": "b",
                     "surface_2": "left"}]}


def test_tied_nodes_prescribed_different_motions_are_refused():
    """A tester's tied corners held at x = 0 and x = 0.01 ran to "completed" 0.01 apart; the
    tie leaves a component prescribed on both nodes to the supports (session 41)."""
    with pytest.raises(ScenarioError, match=r"tie 'ab': node \d+ of body 'a' .* different x "
                                            r"motions \('a_corner_top_right', "
                                            r"'b_corner_top_left'\)"):
        model_from_dict(tied_squares(0.01))
    model_from_dict(tied_squares(0.0))  # the same motion: the supports' own business
    # equal at the function's points only if equal everywhere: 0 * s(t) is 0 at all times
    model_from_dict(tied_squares(0.0, {"times": [0.0, 1.0], "values": [0.0, 1.0]}))
    with pytest.raises(ScenarioError, match="different x motions"):
        model_from_dict(tied_squares(0.01, {"times": [0.0, 1.0], "values": [0.0, 1.0]}))
