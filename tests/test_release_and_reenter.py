"""A pair that detection releases is a free candidate in that same detection.

Under the gap law a pair that ended a step open (t_N = 0, g < 0) is released at the next step's
detection. With ``detection = "predicted"`` the penetration test is at x + dt v, where that node
may be inside again (a quasi-static load step pressing on: Hertz refined 4x, 13 of 18 steps).
Detection used to test only the nodes not paired before the release, so such a node waited for
the step's first solve to end before it was taken in: one more active-set pass
(``Simulation.advance``). The released pair comes back fresh: no multiplier or friction history.
"""

from dataclasses import replace

import numpy as np
import pytest
from test_touch_on_step_boundary import DT, blocks, touching

from ntncontact.contact import PairState, pair_gaps
from ntncontact.engine.interfaces import detect_all


def _face_ended_open(mesh_motion: str, opening: float, law: str = "gap"):
    """(model, state, face nodes, pairs): the upper block's face ``opening`` above the lower
    block, its pairs as a step leaves them when it ended that open: no traction, gap
    -opening, and a multiplier and a friction history that a fresh pair would not have."""
    model = blocks(mesh_motion, detection="predicted", law=law)
    touch, bottom = touching(model, np.zeros(9))
    found, = detect_all(model.interfaces, (PairState.empty(),), touch.x,
                        np.zeros_like(touch.v), DT)
    assert np.array_equal(np.sort(found.pairs[:, 0]), np.sort(bottom))
    n = len(found)
    ended = replace(found, lambda_N=np.full(n, 5.0), t_T=np.full(n, 0.5),
                    gap=np.full(n, -opening), t_N=np.zeros(n), gap_rate=np.full(n, -1.0),
                    release_count=np.full(n, model.interfaces[0].release_steps - 1))
    d = touch.d.copy()
    d[model.bodies[0].nodes, 1] += opening
    return model, replace(touch, d=d), bottom, ended


@pytest.mark.parametrize("mesh_motion", ["lagrangian", "ale"])
def test_a_released_pair_penetrating_at_the_predicted_end_enters_again(mesh_motion):
    """Both pairings (nearest nodes between Lagrangian bodies, ordered partners beside an ALE
    body): the face ended its last step 1e-3 open, and moves down by 2e-3 in the step."""
    model, state, bottom, ended = _face_ended_open(mesh_motion, 1e-3)
    v = np.zeros_like(state.v)
    v[model.bodies[0].nodes, 1] = -2e-3 / DT  # inside by 1e-3 at x + dt v
    found, = detect_all(model.interfaces, (ended,), state.x, v, DT)
    assert np.array_equal(np.sort(found.pairs[:, 0]), np.sort(bottom))
    # fresh pairs: the released history does not come back with them
    assert not found.lambda_N.any() and not found.t_T.any()
    _, gap, _ = pair_gaps(state.x + DT * v, model.interfaces[0].interface, found.pairs)
    np.testing.assert_allclose(gap, 1e-3, rtol=1e-6)


def test_a_released_pair_that_stays_open_is_released():
    """The same face ended 1e-3 open and does not move: released, not taken in again."""
    model, state, _, ended = _face_ended_open("lagrangian", 1e-3)
    found, = detect_all(model.interfaces, (ended,), state.x, np.zeros_like(state.v), DT)
    assert len(found) == 0


def test_a_pair_released_by_the_persistency_law_waits_a_step():
    """The persistency law releases a pair that separated at the solve's (mid-point) rate for
    release_steps steps; the step-end velocity that detection tests can point the other way
    (the mid-point rule's odd-even mode). Such a pair is not taken in afresh by the same
    detection: a block sliding off an ALE ledge (test_sliding_pairs) had one released and
    taken in again at once, and its base was left ringing."""
    model, state, _, ended = _face_ended_open("lagrangian", 1e-3, law="persistency")
    v = np.zeros_like(state.v)
    v[model.bodies[0].nodes, 1] = -2e-3 / DT  # approaching, inside by 1e-3 at x + dt v
    found, = detect_all(model.interfaces, (ended,), state.x, v, DT)
    assert len(found) == 0
