"""Why the Neo-Hookean block bouncing between walls (tests/test_energy_momentum.py) left over a
wall with moment-free pair forces (issue 16, item 1; docs/theory.md, "Moment-free pair forces").

The block's first touch fell on a step boundary, where round-off entered one pair of a face a
step before the others: the first impact was off-centre. An off-centre impact on this soft
block and these soft walls pushes the block sideways (along the wall) and spins it, and each
later impact of the shifted block is more off-centre: after 13 episodes it had risen 0.5 and
flew over the wall's top corner (the pair with gap +6e-4 and objective rate -2.14 at step 589
joined the block's corner to that wall corner, beyond the wall's face).

The report's pair forces act at body 1's nodes: while the block is shifted by less than a node
spacing, they load its face as if it were centred, and the block takes no sideways velocity at
all. Moment-free forces act on the line of the partner node, as the contact does; they see the
shift. Measured sideways velocity after one impact with the block raised by 0.05 (half a node
spacing of the coarse mesh), moment-free / report's forces: 4 x 2 elements 0.051 / 0.000,
8 x 4 (dt/2) 0.080 / 0.000, 16 x 8 (dt/4) 0.073 / 0.105. The report's forces see the shift
only once the mesh resolves it; the moment-free ones are near the fine result on every mesh.
"""

from __future__ import annotations

import numpy as np
import pytest
from helpers import Recorder
from test_energy_momentum import bouncing_block

from ntncontact.engine.simulation import Simulation


def block_velocity(model, record):
    """Mass-weighted mean velocity of the block."""
    block = model.body("block").nodes
    mass = np.asarray(model.assembler.nodal_mass(record.state.X, False).sum(axis=1)).ravel()
    return mass[block] @ record.state.v[block] / mass[block].sum()


def one_impact(moment_free: bool, lift: float):
    """The block's first impact on the right wall (t = 0.103 to ~0.35), then free flight."""
    model = bouncing_block("energy_momentum", 0.4, lift=lift, moment_free=moment_free)
    rec = Recorder()
    Simulation(model, [rec]).run()
    assert rec.status == ("completed", None)
    assert any(len(c.pairs) for r in rec.records for c in r.state.contact)
    return block_velocity(model, rec.records[-1])


def test_an_off_centre_impact_pushes_the_block_along_the_wall():
    """Raised by 0.05, the block leaves the wall with a sideways velocity of order 0.07-0.1
    (the fine-mesh results above); the moment-free forces give it on the coarse mesh, the
    report's forces give none (the whole face loaded as if centred)."""
    free = one_impact(True, 0.05)
    report = one_impact(False, 0.05)
    assert free[0] < -0.2 and report[0] < -0.2  # rebounded
    assert 0.03 < free[1] < 0.15
    assert abs(report[1]) < 1e-10


@pytest.mark.parametrize("moment_free", [True, False])
def test_a_centred_block_stays_centred(moment_free):
    """With the touch inside a step, the symmetric set-up stays symmetric under either force
    over five impacts: the sideways momentum stays at round-off (measured over the 24 episodes
    of 10 s: 6.6e-8 with moment-free forces, 9e-10 with the report's), so the growth that made
    the block leave needs an off-centre start."""
    model = bouncing_block("energy_momentum", 2.1, moment_free=moment_free)
    rec = Recorder()
    Simulation(model, [rec]).run()
    assert rec.status == ("completed", None)
    active = [sum(len(c.pairs) for c in r.state.contact) for r in rec.records]
    ended = sum(1 for a, b in zip(active[:-1], active[1:], strict=True) if a and not b)
    assert ended >= 4  # contact episodes
    sideways = max(abs(r.balance.linear_momentum[1]) for r in rec.records)
    assert sideways < 1e-8  # |P0| = 0.5; an off-centre impact of 0.05 gives ~0.03
