"""contact_start_time / contact_end_time count only tractions above round-off (tester Q finding
10, tester U finding 1c): a load cycle back to exactly zero left 9 pairs with t_N <= 3.3e-11,
and contact_end_time said 4.0 (the zero-load step) instead of 3.75."""

import ntncontact as ntc


def load_cycle() -> dict:
    """Tester Q's lu_base: a linear block (2 x 1) pressed onto a 10x stiffer base by a pressure
    ramped 0 -> 10 -> 0 over t = 0..4 in 16 static steps, frictionless."""
    def block(name, width, nx, origin, E, supports, loads=()):
        return {"name": name, "mesh": {"type": "rectangle", "width": width, "height": 1.0,
                                       "nx": nx, "ny": 4, "origin": origin},
                "material": {"model": "linear_elastic", "E": E, "nu": 0.3, "density": 1.0},
                "supports": supports, "loads": list(loads)}
    press = {"type": "pressure", "set": "top", "value": 10.0,
             "function": {"times": [0.0, 2.0, 4.0], "values": [0.0, 1.0, 0.0]}}
    return {"analysis": {"kind": "static", "dt": 0.25, "t_end": 4.0},
            "bodies": [block("block", 2.0, 8, [1.0, 1.0], 100.0,
                             [{"set": "corner_top_left", "x": 0.0}], [press]),
                       block("base", 4.0, 16, [0.0, 0.0], 1000.0,
                             [{"set": "bottom", "x": 0.0, "y": 0.0}])],
            "contact": [{"name": "c", "body_1": "block", "surface_1": "bottom",
                         "body_2": "base", "surface_2": "top", "method": "augmented_lagrangian",
                         "law": "gap", "penalty_normal": 1.0e5}]}


def test_round_off_tractions_at_zero_load_end_no_contact():
    results = ntc.run(ntc.scenario_from_dict(load_cycle()))
    contact = results.contact
    last = contact[contact["time"] == 4.0]
    # the pairs are still listed at zero load, with round-off tractions only
    assert len(last) == 9 and last["normal_traction"].abs().max() < 1e-9
    assert results.summary["contact_start_time"] == 0.0
    assert results.summary["contact_end_time"] == 3.75


def plate_crossed_in_one_step() -> dict:
    """Tester U's t16: a disk (R 0.1) at vy = -20 crosses a 0.05-thick plate within one step
    (dt 0.015, penetration detection). Its equator node and a plate node lie on one tangent
    line, so their pair's gap is round-off (-8e-17) and its traction 1.9e-11, 0.17-0.77
    apart: no contact took place."""
    material = {"model": "neo_hookean", "E": 1.0e5, "nu": 0.3, "density": 1.0}
    return {"analysis": {"kind": "dynamic", "dt": 0.015, "t_end": 0.045},
            "bodies": [{"name": "pellet", "material": material,
                        "mesh": {"type": "disk", "radius": 0.1, "n_circ": 16, "n_radial": 2,
                                 "center": [0.0, 0.13]},
                        "initial": {"velocity": [0.0, -20.0]}},
                       {"name": "plate", "material": material,
                        "mesh": {"type": "rectangle", "width": 2.0, "height": 0.05, "nx": 40,
                                 "ny": 1, "origin": [-1.0, -0.05]},
                        "supports": [{"set": "left", "x": 0.0, "y": 0.0},
                                     {"set": "right", "x": 0.0, "y": 0.0}]}],
            "contact": [{"name": "c", "body_1": "pellet", "surface_1": "outer",
                         "body_2": "plate", "surface_2": "top", "penalty_factor": 50.0,
                         "detection": "penetration"}]}


def test_a_round_off_traction_alone_starts_no_contact():
    results = ntc.run(ntc.scenario_from_dict(plate_crossed_in_one_step()))
    # the pair (if detection still admits it) carries round-off only
    assert (results.contact["normal_traction"].abs() < 1e-9).all()
    assert results.summary["contact_start_time"] is None
    assert results.summary["contact_end_time"] is None
