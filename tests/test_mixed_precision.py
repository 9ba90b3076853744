"""Whole runs with PARDISO factoring in single precision (refined in double to
``linear.MIXED_RTOL``) against the same runs factored in double: the same steps, the same
Newton iterations within a few, and states within the Newton tolerance's reach.

Forced on meshes of the report's examples (890-2,130 unknowns), which "auto" solves in double:
from 10,000 unknowns it is the default (issue 18)."""

import numpy as np
import pytest
from helpers import EXAMPLES, Recorder, model_from_example

from ntncontact.engine.simulation import Simulation
from ntncontact.solvers.linear import LinearSolver, pardiso_available

pytestmark = pytest.mark.skipif(not pardiso_available(), reason="pypardiso not installed")

#: Both runs end every step at |R| <= 1e-10 of the force scale (NewtonSettings.rtol), so
#: they differ by the inverse tangent times a residual of that order: measured 1.2e-12 (d)
#: and 8.1e-11 (v) of the run's largest values on the ring, 5.5e-13 and 6.9e-12 on Hertz.
#: The bound leaves two orders for other meshes and libraries; a solve at 1e-6 without the
#: Newton test behind it would miss it by orders.
STATE_RTOL = 1e-8


def run(example: str, overrides: list[str], precision: str):
    recorder, solver = Recorder(), LinearSolver("pardiso", precision=precision)
    Simulation(model_from_example(example, overrides), [recorder],
               linear_solve=solver.solve).run()
    return recorder.records, solver.stats


@pytest.mark.parametrize("example, overrides", [
    ("ring_impact.toml", ["analysis.t_end=0.15"]),  # dynamic, ALE, the impact's 16 steps
    ("hertz.toml", []),  # quasi-static, augmented Lagrangian, active-set passes
])
def test_a_run_factored_in_single_precision_matches_the_run_in_double(example, overrides):
    double, double_stats = run(example, overrides, "double")
    single, single_stats = run(example, overrides, "single")
    assert len(single) == len(double)
    assert double_stats.refinements == 0 and single_stats.double_fallbacks == 0
    iterations = [sum(r.newton_iterations for r in records) for records in (double, single)]
    assert abs(iterations[1] - iterations[0]) <= 0.02 * iterations[0]  # ring: 165 / 166
    for field in ("d", "v"):
        scale = max(np.abs(getattr(r.state, field)).max() for r in double)
        worst = max(np.abs(getattr(a.state, field) - getattr(b.state, field)).max()
                    for a, b in zip(double, single, strict=True))
        assert worst <= STATE_RTOL * scale, field


def test_the_scenario_chooses_how_pardiso_factors():
    """``analysis.newton.factor_precision`` reaches the run's default solver; a wrong value is
    refused with the key's name."""
    from ntncontact.io.scenario import ScenarioError, load_scenario

    for precision in ("auto", "single", "double"):
        model = model_from_example("ring_impact.toml",
                                   [f'analysis.newton.factor_precision="{precision}"'])
        assert model.analysis.factor_precision == precision
        assert Simulation(model).solve.__self__.precision == precision
    with pytest.raises(ScenarioError, match="factor_precision"):
        load_scenario(EXAMPLES / "ring_impact.toml", ['analysis.newton.factor_precision="half"'])
