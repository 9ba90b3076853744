"""Whole runs with PARDISO factoring in single precision (refined in double to
``linear.MIXED_RTOL``) against the same runs factored in double: the same steps, the same
Newton iterations within a few, and states within the Newton tolerance's reach.

Forced on the report's examples and on meshes of our own (890-3,068 unknowns), which "auto"
solves in double: from 10,000 unknowns it is the default (issue 18)."""

import numpy as np
import pytest
from helpers import EXAMPLES, Recorder, model_from_example

from ntncontact.engine.simulation import Simulation
from ntncontact.solvers.linear import LinearSolver, pardiso_available

pytestmark = pytest.mark.skipif(not pardiso_available(), reason="pypardiso not installed")

#: Both runs end every step at |R| <= 1e-10 of the force scale (NewtonSettings.rtol), so
#: they differ by the inverse tangent times a residual of that order: measured 1.2e-12 (d)
#: and 8.1e-11 (v) of the run's largest values on the ring, 5.5e-13 and 6.9e-12 on Hertz,
#: 1.1e-15 and 1.7e-13 on the refined frictional blocks, 2.4e-15 and 7.3e-13 with Lagrange
#: multipliers.
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
    # meshes of our own: refined 2x with friction (unsymmetric tangents), and Lagrange
    # multipliers (a zero diagonal block, which single precision pivots too)
    ("blocks_fast_sliding.toml", ["contact.0.friction=0.2", "analysis.t_end=0.08",
                                  "bodies.0.mesh.nx=16", "bodies.0.mesh.ny=42",
                                  "bodies.1.mesh.nx=72", "bodies.1.mesh.ny=10"]),
    ("tilted_blocks.toml", ['contact.0.method="lagrange"', "analysis.t_end=0.09"]),
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
    from ntncontact.io.scenario import ScenarioError, load_config

    for precision in ("auto", "single", "double"):
        model = model_from_example("ring_impact.toml",
                                   [f'analysis.newton.factor_precision="{precision}"'])
        assert model.analysis.factor_precision == precision
        assert Simulation(model).solve.__self__.precision == precision
    with pytest.raises(ScenarioError, match="factor_precision"):
        load_config(EXAMPLES / "ring_impact.toml", ['analysis.newton.factor_precision="half"'])
