"""Newton-Raphson: full and modified (kept factor) iterations reach the same root."""

import warnings

import numpy as np
import pytest
import scipy.sparse as sp

from ntncontact.solvers.linear import LinearSolver
from ntncontact.solvers.newton import FactorCache, NewtonSettings, _floor_note, newton, norm2

N = 40


def cubic_system(shift: float):
    """R(y) = A y + y^3 - b (A: 1D Laplacian + shift I), a nonlinear SPD-tangent system."""
    main = np.full(N, 2.0 + shift)
    A = sp.diags([main, -np.ones(N - 1), -np.ones(N - 1)], [0, -1, 1], format="csr")
    b = np.linspace(0.5, 1.5, N)

    def residual(y):
        return A @ y + y**3 - b, float(np.linalg.norm(b))

    def jacobian(y):
        return sp.csr_matrix(A + sp.diags(3.0 * y**2))

    return residual, jacobian


def solve_full(shift):
    residual, jacobian = cubic_system(shift)
    solver = LinearSolver("superlu")
    return newton(residual, jacobian, solver.solve, np.zeros(N), NewtonSettings(rtol=1e-12))


def test_kept_factor_reaches_the_same_root_with_fewer_factorizations():
    """Two nearby problems (as two augmentations of a step) share one factor cache."""
    solver = LinearSolver("superlu")
    cache = FactorCache(solver.factorize)
    settings = NewtonSettings(rtol=1e-12)
    for shift in (0.5, 0.51):
        residual, jacobian = cubic_system(shift)
        start = solve_full(0.5).y  # the previous augmentation's answer as warm start
        result = newton(residual, jacobian, solver.solve, start, settings, factors=cache)
        reference = solve_full(shift).y
        assert np.abs(result.y - reference).max() <= 1e-10 * np.abs(reference).max()
        assert np.linalg.norm(residual(result.y)[0]) <= 1e-12 * residual(result.y)[1]
    assert cache.reused_steps >= 2
    assert cache.factorizations < 3  # the full method factors at every iteration


def test_a_stale_factor_that_does_not_contract_is_replaced():
    """A factor of a very different matrix: its step fails the contraction test, so Newton
    factors the true Jacobian instead of crawling (or diverging) with the stale one."""
    solver = LinearSolver("superlu")
    cache = FactorCache(solver.factorize)
    wrong = sp.identity(N, format="csr") * 1e-3  # steps 1000x too long
    cache.refresh(wrong)
    residual, jacobian = cubic_system(0.5)
    result = newton(residual, jacobian, solver.solve, np.zeros(N), NewtonSettings(rtol=1e-12),
                    factors=cache)
    assert result.iterations <= 8
    assert np.abs(result.y - solve_full(0.5).y).max() <= 1e-10
    assert cache.factorizations >= 2  # the stale one, then at least one fresh


@pytest.mark.parametrize("contraction", [0.1, 0.5])
def test_contraction_setting_controls_reuse(contraction):
    solver = LinearSolver("superlu")
    cache = FactorCache(solver.factorize)
    residual, jacobian = cubic_system(0.5)
    newton(residual, jacobian, solver.solve, np.zeros(N),
           NewtonSettings(rtol=1e-12, reuse_contraction=contraction), factors=cache)
    assert cache.factorizations >= 1


def test_early_ratio_stops_at_that_fraction_of_the_first_residual():
    residual, jacobian = cubic_system(0.5)
    solver = LinearSolver("superlu")
    start = np.zeros(N)
    first = np.linalg.norm(residual(start)[0])
    rough = newton(residual, jacobian, solver.solve, start, NewtonSettings(rtol=1e-12),
                   early_ratio=1e-3)
    full = solve_full(0.5)
    assert rough.early and not full.early
    assert rough.residual_norms[-1] <= 1e-3 * first < rough.residual_norms[-2]
    assert rough.iterations < full.iterations
    # continuing from the rough answer reaches the same root
    polished = newton(residual, jacobian, solver.solve, rough.y, NewtonSettings(rtol=1e-12))
    assert np.abs(polished.y - full.y).max() <= 1e-10 * np.abs(full.y).max()


def test_norm2_of_entries_whose_squares_overflow_is_finite_and_silent():
    """A residual of ~1e200 (a body with density 1e300) squared overflows: the norm is still
    the Euclidean norm, and no NumPy RuntimeWarning is printed (it reached the user before)."""
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert norm2(np.array([3e200, -4e200, 0.0])) == pytest.approx(5e200, rel=1e-15)
        assert norm2(np.array([3.0, 4.0])) == 5.0
        assert norm2(np.array([1e300, np.inf])) == np.inf


def test_a_tolerance_below_the_round_off_floor_is_named_as_such():
    """A tester's rtol = 1e-12 on a free spinning Neo-Hookean block failed as "no convergence"
    with |R| 6.6e-11 against 2.8e-11: the residual's round-off floor. The message says so; a
    real failure to converge (|R| far above round-off) does not get the note."""
    import ntncontact as ntc

    block = {"analysis": {"kind": "dynamic", "dt": 0.02, "t_end": 0.4, "output_interval": 0.4,
                          "newton": {"rtol": 1e-13}},
             "bodies": [{"name": "block", "mesh": {"type": "rectangle", "width": 1.0,
                                                   "height": 0.5, "nx": 8, "ny": 4},
                         "material": {"model": "neo_hookean", "E": 100.0, "nu": 0.3,
                                      "density": 1.0},
                         "initial": {"velocity": [1.0, 0.5], "angular_velocity": 4.0}}]}
    with pytest.raises(RuntimeError, match="stalled at its round-off floor"):
        ntc.run(ntc.scenario_from_dict(block))
    assert _floor_note([1.0, 0.5, 0.4, 0.45, 0.41, 0.43], 1.0) == ""  # stalled, not round-off
    assert _floor_note([1e-12, 2e-12, 1.5e-12, 1e-12, 3e-12], 1.0).startswith(": the residual")
