"""contact_start_time / contact_end_time count only tractions above round-off (tester Q finding
10, tester U finding 1c): a load cycle back to exactly zero left 9 pairs with t_N <= 3.3e-11,
and contact_end_time said 4.0 (the zero-load step) instead of 3.75."""

import math

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


def sliding_touch() -> dict:
    """A block placed touching a held base, both rotated by 37 degrees, sliding along it at
    0.3 with no load: its pairs enter touching and carry round-off only (5.6e-13 from the
    step starting at t = 0.02 before the fix, which made that the contact start)."""
    material = {"model": "neo_hookean", "E": 1.0e3, "nu": 0.3, "density": 1.0}
    turn = {"rotate_deg": 37.0, "center": [0.0, 0.0]}
    c, s = math.cos(math.radians(37.0)), math.sin(math.radians(37.0))

    def block(name, width, nx, origin, velocity, supports=()):
        return {"name": name, "material": material, "supports": list(supports),
                "mesh": {"type": "rectangle", "width": width, "height": 0.5, "nx": nx,
                         "ny": 2, "origin": origin, "transform": turn},
                "initial": {"velocity": velocity}}
    return {"analysis": {"kind": "dynamic", "dt": 0.01, "t_end": 0.05},
            "bodies": [block("top", 1.0, 4, [0.5, 0.5], [0.3 * c, 0.3 * s]),
                       block("base", 2.0, 8, [0.0, 0.0], [0.0, 0.0],
                             [{"set": "bottom", "x": 0.0, "y": 0.0}])],
            "contact": [{"name": "c", "body_1": "top", "surface_1": "bottom",
                         "body_2": "base", "surface_2": "top", "penalty_normal": 1.0e4}]}


def test_a_round_off_traction_alone_starts_no_contact():
    results = ntc.run(ntc.scenario_from_dict(sliding_touch()))
    # the pairs are there, with round-off tractions only
    assert len(results.contact) and (results.contact["normal_traction"].abs() < 1e-9).all()
    assert results.summary["contact_start_time"] is None
    assert results.summary["contact_end_time"] is None
