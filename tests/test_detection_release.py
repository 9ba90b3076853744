"""Detection decides which pairs it releases once a step: ``interfaces.detect_all`` needs the
release for its candidates (a released node may enter again at once, ``_staying``) and hands
it to ``contact.detect``, which computed it again before."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
from helpers import model_from_dict
from test_active_set_punch import _punch

from ntncontact.contact import ContactSurface, Interface, PairState, detect, detection
from ntncontact.engine import interfaces, simulation
from ntncontact.engine.simulation import Simulation


def test_detect_takes_the_release_it_is_given():
    """Four pairs that ended open under the gap law: released by detect's own test, kept
    where the caller's release keeps them."""
    x = np.array([[0.0, 0.1], [1.0, 0.1], [1.0, 0.0], [0.0, 0.0]])
    interface = Interface(ContactSurface([0, 1]), ContactSurface([2, 3]))
    open_pairs = PairState.from_pairs(np.array([[0, 3], [1, 2]]))
    open_pairs = replace(open_pairs, t_N=np.zeros(2), gap=np.full(2, -0.1))
    none = np.zeros((0, 2), np.int64)
    assert len(detect(open_pairs, none, x, None, interface, persistency=False).state) == 0
    kept = (np.zeros(2, bool), np.zeros(2, np.int64))
    found = detect(open_pairs, none, x, None, interface, persistency=False, release=kept)
    np.testing.assert_array_equal(found.state.pairs, open_pairs.pairs)


def test_a_step_start_tests_the_release_once(monkeypatch):
    calls = {"release_mask": 0, "detect_all": 0}

    def counted(name, function):
        def wrapper(*args, **kwargs):
            calls[name] += 1
            return function(*args, **kwargs)
        return wrapper

    monkeypatch.setattr(interfaces, "release_mask", counted("release_mask",
                                                            interfaces.release_mask))
    monkeypatch.setattr(detection, "release_mask", counted("release_mask",
                                                           detection.release_mask))
    monkeypatch.setattr(simulation, "detect_all", counted("detect_all", simulation.detect_all))
    Simulation(model_from_dict(_punch())).run()
    assert calls["detect_all"] > 0
    assert calls["release_mask"] == calls["detect_all"], calls  # one interface
