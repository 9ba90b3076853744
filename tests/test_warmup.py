"""ntncontact.warmup: its two small runs reach the kernels they are meant to compile."""

import numpy as np

from ntncontact.contact import evaluate
from ntncontact.warmup import exercise


def test_lagrangian_group_makes_contact():
    sim = exercise(ale=False)
    assert sum(len(c) for c in sim.state.contact) > 0  # the contact kernel ran
    assert not sim.model.ale_bodies


def test_ale_group_moves_the_mesh_and_restores_the_kernels():
    before = evaluate.KERNEL
    sim = exercise(ale=True)
    assert evaluate.KERNEL == before  # the NumPy switch is undone
    setup = sim.model.ale_bodies[0]
    rows = slice(setup.node_offset, setup.node_offset + setup.n_nodes)
    # the ALE obstacle's nodes carry other particles than at the start: the mesh slid and the
    # fields were remapped (the kernels the warm-up is for)
    assert np.abs(sim.state.X[rows] - sim.model.X0[rows]).max() > 1e-4
