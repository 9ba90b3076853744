"""contact.neighbour_pairs: the pairs a growing contact zone takes in next, whose entries the
union pattern reserves (fem.sparse, engine.interfaces.ContactNewtonTerm.reserve)."""

import numpy as np
import pytest
from helpers import model_from_example

from ntncontact.contact import ContactSurface, Interface, neighbour_pairs
from ntncontact.engine import interfaces
from ntncontact.engine.simulation import Simulation
from ntncontact.solvers.linear import LinearSolver


def _flat_interface(n1: int = 9, n2: int = 11, closed: bool = False):
    """Surface 1: nodes 0..n1-1 on y = 0.01 (x = 0..n1-1), walked right to left as a body
    above would be; surface 2: nodes n1.. on y = 0 (x = -1..n2-2), walked left to right."""
    x1 = np.column_stack([np.arange(n1, dtype=float), np.full(n1, 0.01)])
    x2 = np.column_stack([np.arange(n2, dtype=float) - 1.0, np.zeros(n2)])
    x = np.vstack([x1, x2])
    s1 = ContactSurface(np.arange(n1)[::-1], closed=closed)
    s2 = ContactSurface(n1 + np.arange(n2))
    return x, Interface(s1, s2)


def test_the_nodes_within_reach_pair_with_the_nearest_node_and_its_neighbours():
    x, interface = _flat_interface()
    nearest, before, after = neighbour_pairs(x, interface, active=[4], reach=2)
    assert nearest[:, 0].tolist() == [2, 3, 5, 6]  # within 2 chain steps, 4 itself left out
    assert (nearest[:, 1] == nearest[:, 0] + 10).all()  # the node below: x2 = x1
    assert (before[:, 1] == nearest[:, 1] - 1).all() and (after[:, 1] == nearest[:, 1] + 1).all()


def test_an_open_chain_stops_at_its_ends_and_a_closed_one_wraps():
    x, interface = _flat_interface()
    nearest, *_ = neighbour_pairs(x, interface, active=[0, 1], reach=3)
    assert nearest[:, 0].tolist() == [2, 3, 4]  # no node beyond the chain's end
    x, interface = _flat_interface(closed=True)
    nearest, *_ = neighbour_pairs(x, interface, active=[0], reach=2)
    assert sorted(nearest[:, 0].tolist()) == [1, 2, 7, 8]  # around the closing segment


def test_no_active_pairs_reserve_nothing():
    x, interface = _flat_interface()
    assert neighbour_pairs(x, interface, active=np.zeros(0, np.int64), reach=4) == ()


def test_a_shared_segments_entries_are_widened_along_both_chains():
    """An unpaired share couples the nodes of a shared segment and its pairs' surface-1
    neighbours, a few chain steps apart (the ring refined 2x: ring nodes 768-770, ALE nodes
    1549-1555), which no grown set with every node paired holds: the reserved entries of
    such an interface are widened by SHARE_RESERVED_STEPS along both chains."""
    x, interface = _flat_interface()
    rows, cols = interfaces.along_chains(np.array([2 * 4]), np.array([2 * 14 + 1]), interface,
                                         len(x), 2)
    entries = set(zip((rows // 2).tolist(), (cols // 2).tolist(), strict=True))
    # node 4 (surface 1) and node 14 (surface 2): each moved 0..2 steps along its chain
    assert entries == {(a, b) for a in range(2, 7) for b in range(12, 17)}
    assert len(rows) == 4 * len(entries)  # both dofs of each node
    x, interface = _flat_interface(closed=True)
    rows, _ = interfaces.along_chains(np.array([0]), np.array([0]), interface, len(x), 1)
    assert set((rows // 2).tolist()) == {8, 0, 1}  # around the closing segment


RING_2X = ["bodies.0.mesh.n_radial=8", "bodies.0.mesh.n_circ=96", "bodies.1.mesh.nx=80",
           "bodies.1.mesh.ny=8", "analysis.t_end=0.15"]  # a mesh of our own, to the rebound


@pytest.mark.parametrize(("example", "overrides", "analyses", "before"),
                         [("hertz", [], 1, 7), ("tilted_blocks", [], 2, 6),
                          ("ring_impact", RING_2X, 2, 6)])
def test_a_growing_contact_zone_finds_its_entries_reserved(monkeypatch, example, overrides,
                                                           analyses, before):
    """With the next pairs' entries reserved at each growth of the union pattern, the Hertz
    load steps (the zone grows from 7 to 17 pairs) are one analysis of the matrix, and the
    tilted blocks and the ring refined 2x one per symmetry mode (free flight, contact);
    ``before`` is the count
    without the reservation, which these small examples keep by default (below
    RESERVED_FROM_DOFS, where an analysis is cheap)."""
    model = model_from_example(f"{example}.toml", overrides)
    assert model.ndof < interfaces.RESERVED_FROM_DOFS
    for threshold, expected in ((interfaces.RESERVED_FROM_DOFS, before), (0, analyses)):
        monkeypatch.setattr(interfaces, "RESERVED_FROM_DOFS", threshold)
        solver = LinearSolver()
        Simulation(model, [], linear_solve=solver.solve).run()
        assert solver.stats.analyses == expected, threshold
