"""A quasi-static Lagrange step whose active set cycles (tester B, finding 2): a block pressed
onto a base and unloaded to zero is held by contact only; its Lagrange pairs go into tension,
are released, penetrate again by round-off and are taken in again. The step ran without end
(11 min, no message, the first SIGTERM not seen); the augmented Lagrangian failed at once as
singular. Now the step fails after ACTIVE_SET_REPEATS cycling passes, and a stop request is
seen between the passes of a step.
"""

from __future__ import annotations

import signal

import pytest
from helpers import model_from_dict

from ntncontact.engine.simulation import RunInterrupted, Simulation, SimulationError


def _unloaded_block(t_end: float = 2.25, max_cutbacks: int = 0):
    """Tester B's block_unload.toml (pressure 0 -> 1 -> 0 over t = 0, 1, 2), Lagrange."""
    ramp = {"times": [0.0, 1.0, 2.0], "values": [0.0, 1.0, 0.0]}
    return model_from_dict({
        "analysis": {"kind": "static", "dt": 0.25, "t_end": t_end, "max_cutbacks": max_cutbacks},
        "bodies": [
            {"name": "block", "mesh": {"type": "rectangle", "width": 2.0, "height": 1.0,
                                       "nx": 8, "ny": 4, "origin": [1.0, 1.0]},
             "material": {"model": "linear_elastic", "E": 100.0, "nu": 0.3, "density": 1.0},
             "loads": [{"type": "pressure", "set": "top", "value": 1.0, "function": ramp}],
             "supports": [{"set": "corner_top_left", "x": 0.0}]},
            {"name": "base", "mesh": {"type": "rectangle", "width": 4.0, "height": 1.0,
                                      "nx": 16, "ny": 4, "origin": [0.0, 0.0]},
             "material": {"model": "linear_elastic", "E": 1000.0, "nu": 0.3, "density": 1.0},
             "supports": [{"set": "bottom", "x": 0.0, "y": 0.0}]}],
        "contact": [{"name": "c", "body_1": "block", "surface_1": "bottom", "body_2": "base",
                     "surface_2": "top", "method": "lagrange", "law": "gap"}]})


@pytest.fixture
def alarm():
    """The old code never ended the step: fail after 120 s rather than hang the suite."""
    def expired(signum, frame):
        raise TimeoutError("the step did not end in 120 s")
    old = signal.signal(signal.SIGALRM, expired)
    signal.alarm(120)
    yield
    signal.alarm(0)
    signal.signal(signal.SIGALRM, old)


def test_a_cycling_lagrange_active_set_fails_the_step_with_its_cause(alarm):
    with pytest.raises(SimulationError) as err:
        Simulation(_unloaded_block()).run()
    message = str(err.value)
    # the load is 0 from t = 2 on, the end of step 8: whether that step's zero-load end still
    # converges with the pairs closed at zero force is round-off (it did on one machine, not
    # on another); either way the failing step is one that ends at zero load
    assert message.startswith(("step 8 (t = 1.75 -> 2) failed", "step 9 (t = 2 -> 2.25) failed")), \
        message
    assert "active set did not settle" in message and "ACTIVE_SET_REPEATS" in message
    assert "as at zero load" in message and "Lagrange interface(s) ['c']" in message


def test_a_stop_request_is_seen_inside_a_step(alarm):
    """The stop flag is asked before each active-set pass too, not only between steps: a
    one-step run asked to stop at its second question ends in that step (it used to finish)."""
    asked = []

    def stop_reason():
        asked.append(1)
        return "SIGTERM" if len(asked) >= 2 else None

    with pytest.raises(RunInterrupted, match="SIGTERM"):
        Simulation(_unloaded_block(t_end=0.25)).run(stop_reason=stop_reason)
