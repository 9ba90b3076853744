"""The advice of a step whose augmentations ran out names the failed test and offers only
what can help with it (tester Y, session 42: a static block with friction failed the slip
test, and the message always said 'Uzawa's multiplier update can converge slowly on fine
meshes: try augmentation.update = "newton"', which fails there as well)."""

from types import SimpleNamespace

import pytest
from helpers import model_from_dict

from ntncontact.engine.interfaces import AugmentationFailure, augmentation_advice
from ntncontact.engine.simulation import Simulation, SimulationError

NEWTON_HINT = 'augmentation.update = "newton"'


def static_tilt(max_cutbacks: int = 2, **contact) -> dict:
    """Tester Y's static_tilt.toml (80 elements): a Neo-Hookean block pressed and slid on a
    20-degree tilted Neo-Hookean base, friction 0.3, gap law; one load step of 0.1. With
    penalty_tangential = 500 its augmentations shrink the slip change by ~0.78 each."""
    rotate = {"rotate_deg": 20.0, "center": [0.0, 0.0]}
    return {
        "analysis": {"kind": "static", "dt": 0.1, "t_end": 0.1, "max_cutbacks": max_cutbacks},
        "bodies": [
            {"name": "base",
             "mesh": {"type": "rectangle", "width": 3.0, "height": 0.5, "nx": 15, "ny": 3,
                      "origin": [-1.5, -0.5], "transform": rotate},
             "material": {"model": "neo_hookean", "E": 1000.0, "nu": 0.3, "density": 1.0},
             "supports": [{"set": "bottom", "x": 0.0, "y": 0.0}]},
            {"name": "block",
             "mesh": {"type": "rectangle", "width": 0.8, "height": 0.4, "nx": 7, "ny": 4,
                      "origin": [-0.4, 0.0], "transform": rotate},
             "material": {"model": "neo_hookean", "E": 200.0, "nu": 0.3, "density": 1.0},
             "supports": [{"set": "top", "x": 0.25, "y": -0.12,
                           "function": {"times": [0.0, 0.4, 1.0],
                                        "values": [0.0, 0.3, 1.0]}}]},
        ],
        "contact": [{"name": "c", "body_1": "block", "surface_1": "bottom", "body_2": "base",
                     "surface_2": "top", "method": "augmented_lagrangian", "law": "gap",
                     "penalty_normal": 5000.0, "penalty_tangential": 500.0,
                     "friction": 0.3} | contact],
    }


def test_a_failed_slip_test_is_named_and_not_told_to_try_newton_updates():
    with pytest.raises(SimulationError) as err:
        Simulation(model_from_dict(static_tilt())).run()
    message = str(err.value)
    # halved twice: the gap change (~2.6e-8 at dt, in proportion to the sub-step) passes
    assert "failed: the slip test;" in message
    assert "change of the slip" in message and "(slip_tolerance 1e-08)" in message
    assert NEWTON_HINT not in message and "fine meshes" not in message
    assert "a larger penalty_tangential (now 500)" in message
    assert "a looser augmentation.slip_tolerance (now 1e-08)" in message
    assert 'method = "lagrange" or "penalty"' in message


@pytest.mark.parametrize("advice", [
    {"penalty_tangential": 5000.0},
    {"augmentation": {"slip_tolerance": 1e-6}},
    {"method": "lagrange"},
    {"method": "penalty"},
    {"augmentation": {"update": "newton"}},  # not advised: it fails as Uzawa does
])
def test_what_the_advice_offers_passes_the_step(advice):
    """Each option the message offers completes the step; Newton updates do not."""
    simulation = Simulation(model_from_dict(static_tilt(max_cutbacks=4, **advice)))
    if advice.get("augmentation", {}).get("update") == "newton":
        with pytest.raises(SimulationError, match="failed: the slip test"):
            simulation.run()
        return
    assert simulation.run().time == pytest.approx(0.1)


def _failure(tests: tuple[str, ...], sticking: bool, friction: float = 0.3,
             update: str = "uzawa") -> AugmentationFailure:
    law = SimpleNamespace(method="augmented_lagrangian", frictional=friction > 0.0,
                          eps_T=500.0 if friction else 0.0)
    interface = SimpleNamespace(name="c", law=law, multiplier_update=update,
                                tolerances=SimpleNamespace(tangential=1e-8))
    return AugmentationFailure(interface, "", True, tests, sticking)


def test_newton_updates_are_offered_for_the_gap_test_without_sticking_pairs():
    assert NEWTON_HINT in augmentation_advice([_failure(("gap",), False, friction=0.0)])
    assert NEWTON_HINT in augmentation_advice([_failure(("normal rate",), False)])
    # already on: nothing more to offer for the gap; with sticking pairs it cannot help
    assert augmentation_advice([_failure(("gap",), False, update="newton")]) == ""
    sticking = augmentation_advice([_failure(("gap",), True)])
    assert NEWTON_HINT not in sticking and "larger penalty_tangential" in sticking
    assert "slip_tolerance" not in sticking  # the slip test passed


def test_no_advice_where_halving_cannot_help():
    failure = _failure(("gap",), False)._replace(halving_helps=False)
    assert augmentation_advice([failure]) == ""
