"""Modified Newton's bound on kept-factor steps (``NewtonSettings.max_reused_steps``) and the
scenario key that sets it: 0 is full Newton, with its quadratic rate."""

import math

import numpy as np
import pytest
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from helpers import Recorder, model_from_dict

from ntncontact.engine import simulation
from ntncontact.engine.simulation import Simulation
from ntncontact.io.scenario import ScenarioError
from ntncontact.solvers.newton import FactorCache, NewtonSettings, newton

N = 6
K = sp.csr_matrix(np.diag(np.arange(1.0, N + 1.0)) + 0.1 * np.eye(N, k=1))
B = np.ones(N)


def _runs(max_reused_steps: int, solves: int) -> list[int]:
    """Kept-factor steps between factorizations over ``solves`` Newton solves sharing a cache.
    R = K y - b, and each factor is of 1.05 K, so that every step, fresh or kept, shrinks |R|
    by ~0.05: a kept step always passes the 0.1 contraction test, and only the bound stops
    the reuse."""
    cache = FactorCache(lambda m: spla.factorized(sp.csc_matrix(1.05 * m)))
    at_refresh = []
    refresh = cache.refresh

    def counting(matrix):
        at_refresh.append(cache.reused_steps)
        return refresh(matrix)

    cache.refresh = counting
    settings = NewtonSettings(rtol=1e-12, max_reused_steps=max_reused_steps)
    for k in range(solves):  # nearby problems, as the augmentations of a step
        newton(lambda y, k=k: (K @ y - (1.0 + 0.01 * k) * B, float(np.abs(B).sum())),
               lambda y: K, spla.spsolve, np.zeros(N), settings, factors=cache)
    marks = at_refresh + [cache.reused_steps]
    return [b - a for a, b in zip(marks, marks[1:], strict=False)]


def test_the_bound_holds_within_a_solve():
    """One solve of ~10 iterations: a fresh factorization after every 4 kept-factor steps."""
    runs = _runs(4, 1)
    assert max(runs) == 4 and len(runs) >= 2, runs


def test_the_count_restarts_at_each_solve():
    """The documented behaviour (docs/theory.md, (5.17)-(5.19)): the factor left by a solve
    serves the next solve's first steps and the count starts again there, so a run of kept
    steps can exceed the bound over the solves of a step (kept: counting with the cache was
    slower, benchmarks/README.md, session 42)."""
    one = _runs(4, 1)
    assert max(_runs(4, 3)) > 4 and max(one) == 4


def test_zero_factors_at_every_iteration():
    assert _runs(0, 2) == [0] * len(_runs(0, 2))


def _block(newton_keys: dict) -> dict:
    """A Neo-Hookean block, clamped at the bottom, sheared and squeezed through its top in
    one static step: a nonlinear problem without contact, a few Newton iterations."""
    return {
        "analysis": {"kind": "static", "dt": 1.0, "t_end": 1.0, "newton": newton_keys},
        "bodies": [{
            "name": "block",
            "mesh": {"type": "rectangle", "width": 1.0, "height": 1.0, "nx": 4, "ny": 4},
            "material": {"model": "neo_hookean", "E": 1000.0, "nu": 0.3, "density": 1.0},
            "supports": [{"set": "bottom", "x": 0.0, "y": 0.0},
                         {"set": "top", "x": 0.15, "y": -0.1}],
        }],
    }


def _solves(monkeypatch, newton_keys: dict) -> list:
    """(residual norms / scale, factorizations) of every Newton solve of the block's run."""
    solves = []

    def recording(residual, jacobian, solve, y0, settings, length_scale=1.0, factors=None,
                  early_ratio=0.0, active_set=None):
        before = factors.factorizations if factors is not None else 0
        result = newton(residual, jacobian, solve, y0, settings, length_scale, factors,
                        early_ratio, active_set)
        after = factors.factorizations if factors is not None else 0
        solves.append((result.residual_norms, result.iterations, after - before))
        return result

    monkeypatch.setattr(simulation, "newton", recording)
    recorder = Recorder()
    sim = Simulation(model_from_dict(_block(newton_keys)), [recorder])
    sim.run()
    assert recorder.status[0] == "completed"
    return sim, solves


def test_zero_is_full_newton_with_a_quadratic_rate(monkeypatch):
    """max_reused_steps = 0: a fresh factorization at every iteration, and the residual falls
    quadratically (the default's kept-factor steps converge linearly)."""
    sim, solves = _solves(monkeypatch, {"max_reused_steps": 0})
    assert sim.settings.max_reused_steps == 0
    assert [f for _, _, f in solves] == [its for _, its, _ in solves], solves
    # each solve starts where the one before it ended (the early-stopped one, then the rest);
    # the norms at round-off (below 1e-12 of the first) say nothing of the rate
    norms = [solves[0][0][0]] + [n for solve, _, _ in solves for n in solve[1:]]
    r = [n for n in norms if n > 1e-12 * norms[0]][-3:]
    order = math.log(r[2] / r[1]) / math.log(r[1] / r[0])
    assert order > 1.7, norms  # measured 1.91 (|R| 11.7, 0.19, 7.0e-5, 1.6e-11)


def test_default_keeps_four_reused_steps(monkeypatch):
    """Without the key, the setting is the former 4, and kept factors serve some steps, which
    converge linearly."""
    sim, solves = _solves(monkeypatch, {})
    assert sim.settings.max_reused_steps == 4
    assert sum(its for _, its, _ in solves) > sum(f for _, _, f in solves)


def test_a_negative_bound_is_refused():
    with pytest.raises(ScenarioError, match=r"max_reused_steps = -1: .*greater than or equal to 0"):
        model_from_dict(_block({"max_reused_steps": -1}))
