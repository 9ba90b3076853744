"""The watchdog: a full Newton step that raises |R| is kept when the next iterate is better."""

import numpy as np
import pytest
import scipy.sparse as sp
from helpers import Recorder, model_from_dict

from ntncontact.engine.simulation import Simulation
from ntncontact.solvers.linear import LinearSolver
from ntncontact.solvers.newton import NewtonSettings, newton


def _cantilever(nx: int, ny: int, nu: float) -> dict:
    """Tester A's Neo-Hookean cantilever (session 41): 10 x 1, a tip shear giving a 2 % of L
    deflection, one static load step."""
    return {
        "analysis": {"kind": "static", "dt": 1.0, "t_end": 1.0},
        "bodies": [{
            "name": "beam",
            "mesh": {"type": "rectangle", "width": 10.0, "height": 1.0, "nx": nx, "ny": ny},
            "material": {"model": "neo_hookean", "E": 1000.0, "nu": nu, "density": 1.0},
            "supports": [{"set": "left", "x": 0.0, "y": 0.0}],
            "loads": [{"type": "traction", "set": "right", "vector": [0.0, -0.1]}],
        }],
    }


@pytest.mark.parametrize("nu", [0.33, 0.49])
def test_bending_step_that_raises_the_residual_is_kept(nu):
    """|R| 4.7e-2 -> 5.8 -> 7.3e-3 -> 6e-8 with full steps; backtracking on |R| cut the first
    to 1/8, crept, and failed after 25 iterations and 4 halvings."""
    recorder = Recorder()
    Simulation(model_from_dict(_cantilever(20, 2, nu)), [recorder]).run()
    assert recorder.status[0] == "completed"
    assert [r.newton_iterations for r in recorder.records[1:]] == [pytest.approx(5, abs=1)]


def test_a_trial_step_that_does_not_help_is_backtracked():
    """R(y) = atan(y) from y = 3: the full step overshoots to -9.5 (|R| 1.25 -> 1.47) and so
    does the half step (-3.2), so the full step is tried; the next step, backtracked, ends at
    |R| 1.45, not below 1.25 (full steps diverge from |y| > 1.39), so the watchdog goes back
    to y = 3 and backtracks there (1/4, y = -0.12), and Newton converges."""
    def residual(y):
        return np.arctan(y), 1.0

    def jacobian(y):
        return sp.csr_matrix(np.diag(1.0 / (1.0 + y**2)))

    result = newton(residual, jacobian, LinearSolver("superlu").solve, np.array([3.0]),
                    NewtonSettings(rtol=1e-12, watchdog=True))
    assert abs(result.y[0]) < 1e-10
    norms = result.residual_norms
    assert norms[1] > norms[0] > norms[2]  # the trial, then the backtracked step from y = 3
    assert all(b < a for a, b in zip(norms[2:], norms[3:], strict=False))
