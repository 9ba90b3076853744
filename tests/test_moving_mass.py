"""MovingMass: the mass after ALE moves equals a full rebuild, bit for bit, both mass types."""

import numpy as np
import pytest
from helpers import EXAMPLES

from ntncontact.dynamics.mass import MovingMass
from ntncontact.engine.builder import build_model
from ntncontact.io.scenario import load_config


@pytest.mark.parametrize("mass", ["consistent", "lumped"])
def test_incremental_mass_equals_a_full_rebuild(mass):
    model = build_model(load_config(EXAMPLES / "ring_impact.toml",
                                      [f'analysis.mass="{mass}"']))
    obstacle = model.bodies[1]
    moving = MovingMass(model.assembler, model.X0, mass == "lumped", obstacle.cells)
    lumped = mass == "lumped"
    assert (moving.matrix(model.X0) != model.assembler.mass(model.X0, lumped)).nnz == 0
    rng = np.random.default_rng(3)
    X = model.X0.copy()
    for _ in range(3):  # a few moves of a handful of obstacle nodes each
        nodes = rng.choice(obstacle.nodes, size=6, replace=False)
        X[nodes] += 0.01 * rng.uniform(-1, 1, (6, 2))
        M = moving.matrix(X)
        every = np.arange(len(model.assembler.cells))  # all elements' mass data, K's pattern
        full = model.assembler.pattern_matrix(model.assembler.dof_mass_data(
            model.assembler.element_masses(X, every), lumped, every))
        assert np.array_equal(M.data, full.data) and np.array_equal(M.indices, full.indices)
        assert M.sum() == pytest.approx(model.assembler.mass(X, lumped).sum(), rel=1e-14)
    assert moving.matrix(X) is M  # unchanged positions: the same matrix, nothing rebuilt
