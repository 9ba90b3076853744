"""summary.json ``max_linear_elastic_rotation``: small-strain linear elasticity is not
rotation-invariant, and an independent tester's spinning block made linear elastic stretched
from 1 x 0.5 to 4 x 6.5 without stress while its energy and momenta were "conserved"; nothing
said so. The largest element rotation of a linear elastic body is now reported."""

from __future__ import annotations

import numpy as np
import pytest
from helpers import EXAMPLES

import ntncontact as ntc
from ntncontact.engine.builder import build_model
from ntncontact.engine.diagnostics import linear_elastic_measures


def spinning(model: str, t_end: float = 0.5):
    return ntc.run(ntc.load_scenario(EXAMPLES / "spinning_block.toml",
                                     [f'bodies.0.material.model="{model}"',
                                      f"analysis.t_end={t_end}"]))


@pytest.mark.parametrize("angle", [0.3, -2.0])
def test_a_rigid_rotation_is_measured_exactly(angle):
    scenario = ntc.load_scenario(EXAMPLES / "spinning_block.toml",
                                 ['bodies.0.material.model="linear_elastic"'])
    model = build_model(scenario.config, scenario.base_dir)
    c, s = np.cos(angle), np.sin(angle)
    X = model.X0 + [3.0, -1.0]  # anywhere
    d = X @ np.array([[c, s], [-s, c]]) - X + [0.5, 0.2]
    turned, body = linear_elastic_measures(model, X, d)["rotation"]
    assert turned == pytest.approx(abs(angle), abs=1e-12) and body == "block"


@pytest.mark.parametrize("angle, stretches", [(0.4, (1.3, 0.8)), (-2.5, (0.6, 1.05)),
                                              (3.0, (2.0, 2.0))])
def test_a_homogeneous_deformation_of_a_distorted_mesh_is_measured_exactly(angle, stretches):
    """x = M X with M = R(angle) U: every bilinear cell, however distorted, has F = M at its
    centre, so the figures are M's own (scipy's polar decomposition and singular values):
    the closed-form 2 x 2 algebra of the measures checked on cells of many shapes."""
    from scipy.linalg import polar
    scenario = ntc.load_scenario(EXAMPLES / "spinning_block.toml",
                                 ['bodies.0.material.model="linear_elastic"'])
    model = build_model(scenario.config, scenario.base_dir)
    spacing = np.min(np.ptp(model.X0, axis=0)) / 10
    X = model.X0 + np.random.default_rng(7).uniform(-0.2, 0.2, model.X0.shape) * spacing
    c, s = np.cos(0.7), np.sin(0.7)
    axes = np.array([[c, -s], [s, c]])  # U's principal axes, not the frame's
    U = axes @ np.diag(stretches) @ axes.T
    M = np.array([[np.cos(angle), -np.sin(angle)], [np.sin(angle), np.cos(angle)]]) @ U
    found = linear_elastic_measures(model, X, X @ M.T - X)
    R = polar(M)[0]
    singular = np.linalg.svd(M, compute_uv=False)
    assert found["rotation"][0] == pytest.approx(abs(np.arctan2(R[1, 0], R[0, 0])), abs=1e-12)
    assert found["stretch"][0] == pytest.approx(singular.max(), rel=1e-12)
    assert found["strain"][0] == pytest.approx(np.max(np.abs(singular**2 - 1.0)) / 2, rel=1e-12)


def test_a_spinning_linear_elastic_block_reports_its_turn():
    """omega = 3: the linear body's nodes fly off on straight lines, x = X + t (omega x X),
    so F = I + t W and the measured turn is atan(omega t), 0.98 rad at t = 0.5."""
    summary = spinning("linear_elastic").summary
    assert summary["max_linear_elastic_rotation"] == pytest.approx(np.arctan(1.5), rel=1e-3)
    assert summary["max_linear_elastic_rotation_at"]["body"] == "block"


def test_a_neo_hookean_body_has_no_such_key():
    assert "max_linear_elastic_rotation" not in spinning("neo_hookean", 0.1).summary


def test_the_summary_keeps_the_total_frictional_dissipation():
    results = ntc.run(ntc.load_scenario(EXAMPLES / "block_sliding.toml"))
    last = results.history["frictional_dissipation"].iloc[-1]
    assert last > 0.0 and results.summary["frictional_dissipation"] == last
