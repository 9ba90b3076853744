"""How Lagrange multipliers release pairs (tester B, findings 3 and 7): at once, in the step
that finds them in tension, so ``release_steps`` does nothing for them and is warned about;
and a multiplier at round-off (t_N ~ 1e-30 at zero load) makes no contact time."""

from __future__ import annotations

import json
import warnings

import pytest
from helpers import model_from_dict
from test_active_set_cycle import _unloaded_block

from ntncontact.engine.diagnostics import PhysicsWarning


@pytest.mark.parametrize(("method", "warned"), [("lagrange", 'method = "lagrange"'),
                                                ("augmented_lagrangian", "under the gap law")])
def test_release_steps_with_lagrange_is_warned_about(method, warned):
    """Lagrange releases a pair in tension at once; under the gap law (the static runs' law)
    a pair is released when its gap opens: release_steps is read by neither (the gap-law case
    was silent until tester R, session 41)."""
    contact = {"name": "c", "body_1": "top", "surface_1": "bottom", "body_2": "base",
               "surface_2": "top", "method": method, "law": "gap", "release_steps": 1}
    if method != "lagrange":
        contact["penalty_normal"] = 1e3
    data = {"analysis": {"kind": "static", "dt": 1.0, "t_end": 1.0},
            "bodies": [_body("top", 1.0), _body("base", 0.0, supported=True)],
            "contact": [contact]}
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        model_from_dict(data)
    said = [str(w.message) for w in caught if issubclass(w.category, PhysicsWarning)
            and "release_steps" in str(w.message)]
    assert len(said) == 1, said
    assert said[0].startswith("contact.0 ('c'): release_steps has no effect") and warned in \
        said[0], said


def _body(name: str, y0: float, supported: bool = False) -> dict:
    body = {"name": name, "mesh": {"type": "rectangle", "width": 1.0, "height": 1.0, "nx": 2,
                                   "ny": 2, "origin": [0.0, y0]},
            "material": {"model": "linear_elastic", "E": 100.0, "nu": 0.3, "density": 1.0}}
    body["supports"] = ([{"set": "bottom", "x": 0.0, "y": 0.0}] if supported
                        else [{"set": "corner_top_left", "x": 0.0}])
    if not supported:
        body["loads"] = [{"type": "pressure", "set": "top", "value": 1.0}]
    return body


def test_round_off_multipliers_make_no_contact_time(tmp_path):
    """Tester B's block unloaded to zero at t = 2: its Lagrange pairs keep t_N ~ 1e-30 in the
    last step (t = 1.75 -> 2), which made contact_end_time 2.0; the augmented Lagrangian and
    penalty say 1.75."""
    from ntncontact.engine.simulation import Simulation, SimulationError
    from ntncontact.io.results import ResultWriter

    model = _unloaded_block(t_end=2.0)
    try:
        Simulation(model, [ResultWriter(tmp_path, model)]).run()
    except SimulationError as err:
        # whether the zero-load end of the last step still converges with the pairs closed
        # is round-off (test_active_set_cycle.py): where it does not, the run fails there,
        # and the summary written so far must say the same
        assert str(err).startswith("step 8 (t = 1.75 -> 2) failed"), err
        assert "as at zero load" in str(err)
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["contact_start_time"] == 0.0
    assert summary["contact_end_time"] == pytest.approx(1.75)


@pytest.mark.parametrize(("sets", "said"), [
    ({"release_steps": 3}, "release_steps has no effect under the gap law"),
    ({"gap_restoring": True}, "gap_restoring has no effect in a static run"),
    ({"gap_restoring": True, "active_set_pass": True},
     "gap_restoring and active_set_pass have no effect in a static run"),
    ({"gap_restoring": False}, None)])
def test_keys_a_static_gap_law_run_leaves_unread_are_warned_of(sets, said):
    """Tester R (session 41): release_steps under the gap law, and gap_restoring or
    active_set_pass in a static run, changed nothing (contact.csv byte for byte), silently."""
    from ntncontact.engine.builder import _unread_in_this_run
    from ntncontact.engine.config import ContactConfig

    contact = ContactConfig(body_1="a", surface_1="bottom", body_2="b", surface_2="top",
                            penalty_normal=1e4, **sets)
    notes = _unread_in_this_run(contact, static=True)
    assert notes == ([] if said is None else [notes[0]]) and (said is None or said in notes[0])
