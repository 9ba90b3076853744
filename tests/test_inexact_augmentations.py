"""Inexact augmentations (``analysis.newton.inexact_augmentations``): the Newton solves of the
augmentations before the last stop early; every step still ends with a solve to rtol, so a
run gives the exact-solve results to within the augmentation tolerance, with fewer iterations."""

import numpy as np
import pytest
from helpers import Recorder, recorded_ring_impact

from ntncontact.engine.simulation import Simulation


def ring_impact(ratio: float, moment_free: bool | None = None) -> Recorder:
    forces = [] if moment_free is None else [f"contact.0.moment_free={str(moment_free).lower()}"]
    return recorded_ring_impact(f"analysis.newton.inexact_augmentations={ratio}", *forces)


#: Newton iterations of the inexact run over the exact one: the report's forces 231 / 365
#: (0.63); the moment-free forces (the default since session 10) 354 / 417 (0.85): their
#: early-stopped solves take more augmentations (146 against 119 with exact solves)
@pytest.mark.parametrize(("moment_free", "saving"), [(False, 0.8), (True, 0.9)])
def test_ring_impact_with_inexact_augmentations_matches_exact_solves(moment_free, saving):
    exact, rough = ring_impact(0.0, moment_free), ring_impact(1e-4, moment_free)
    energy = [np.array([r.balance.total_energy for r in rec.records]) for rec in (exact, rough)]
    # contact from t = 0.065: the comparison covers 27 contact steps
    assert max(r.extra["active_pairs"] for r in rough.records[1:]) >= 3
    # the augmentation test bounds gap-rate changes by 1e-6 (of the impact speed 1): the
    # energies then agree to ~1e-9 relative (measured: 5.5e-10 absolute, E0 = 1.6)
    assert np.abs(energy[1] - energy[0]).max() <= 1e-8 * energy[0][0]
    for a, b in zip(exact.records[1:], rough.records[1:], strict=True):
        assert np.abs(a.state.d - b.state.d).max() <= 1e-8
        np.testing.assert_array_equal(a.extra["contact_rows"]["node_1"],
                                      b.extra["contact_rows"]["node_1"])
    its = [sum(r.newton_iterations for r in rec.records) for rec in (exact, rough)]
    assert its[1] < saving * its[0]


def test_every_step_ends_with_a_solve_to_the_tolerances(monkeypatch):
    """Whichever augmentation meets the test, its solve is finished to rtol before the step
    is accepted (an early stop is only allowed for augmentations that are followed by more)."""
    import ntncontact.engine.simulation as simulation

    log: list = []
    newton, advance = simulation.newton, Simulation.advance

    def logged_newton(*args, **kwargs):
        result = newton(*args, **kwargs)
        log.append(result.early)
        return result

    def marked_advance(self, *args, **kwargs):
        log.append("step")
        return advance(self, *args, **kwargs)

    monkeypatch.setattr(simulation, "newton", logged_newton)
    monkeypatch.setattr(Simulation, "advance", marked_advance)
    ring_impact(1e-4)
    steps = " ".join("S" if e == "step" else ("e" if e else "x") for e in log).split("S")[1:]
    assert len(steps) == 40
    assert all(s.split()[-1] == "x" for s in steps)
    assert sum(s.count("e") for s in steps) > 50  # early stops did happen
