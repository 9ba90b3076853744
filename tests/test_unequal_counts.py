"""Contact patch test with unequal node counts (issue 16): two stacked 2 x 1 blocks under a
uniform pressure, static, gap law, frictionless, the surfaces 7 and 10 elements across.

Node-to-node pairs carry point forces: where one surface has more nodes than the other, the
unpaired nodes between two pairs take their share of the pair forces by dual mortar weights
(contact/transfer.py). The exact solution is a uniform state: both blocks (same material)
expand sideways alike, the pressure acts on the reference width W0 = 2, so the contact traction
on the current width W is q W0 / W everywhere."""

from dataclasses import replace

import numpy as np
import pytest
import scipy.sparse as sp
from helpers import Recorder, model_from_dict

from ntncontact.contact import ContactLaw, ContactSurface, Interface, PairState, evaluate_contact
from ntncontact.contact.transfer import unpaired_share
from ntncontact.engine.simulation import Simulation

Q = 10.0


def stacked_blocks(n_lower=10, n_upper=7, ale="lower", lower_is_body_1=False, nu=0.3,
                   method="augmented_lagrangian", angle=0.0, share=None):
    """The patch test; ``angle`` = 90 turns the whole set-up about the origin (meshes, and
    supports with it: x and y exchanged, so the rollers stay rollers)."""
    upper = {"name": "upper",
             "mesh": {"type": "rectangle", "width": 2.0, "height": 1.0, "nx": n_upper, "ny": 5,
                      "origin": [0.0, 1.0]},
             "material": {"model": "linear_elastic", "E": 100.0, "nu": nu, "density": 1.0},
             "supports": [{"set": "left", "x": 0.0}],
             "loads": [{"type": "pressure", "set": "top", "value": Q,
                        "function": {"times": [0.0, 1.0], "values": [0.0, 1.0]}}]}
    lower = {"name": "lower",
             "mesh": {"type": "rectangle", "width": 2.0, "height": 1.0, "nx": n_lower,
                      "ny": 5},
             "material": {"model": "linear_elastic", "E": 100.0, "nu": nu, "density": 1.0},
             "supports": [{"set": "bottom", "y": 0.0}, {"set": "left", "x": 0.0}]}
    for body in (upper, lower):
        if ale == body["name"]:
            body["mesh_motion"] = "ale"
        if angle:
            assert angle == 90.0
            body["mesh"]["transform"] = {"rotate_deg": angle}
            body["supports"] = [{"set": sup["set"], ("y" if "x" in sup else "x"): 0.0}
                                for sup in body["supports"]]
    sides = [("upper", "bottom"), ("lower", "top")]
    if lower_is_body_1:
        sides.reverse()
    contact = {"body_1": sides[0][0], "surface_1": sides[0][1], "body_2": sides[1][0],
               "surface_2": sides[1][1], "method": method, "law": "gap",
               "augmentation": {"gap_tolerance": 1e-12}}
    if method != "lagrange":
        contact["penalty_normal"] = 1e4
    if share is not None:
        contact["unpaired_share"] = share
    return model_from_dict({"analysis": {"kind": "static", "dt": 0.5, "t_end": 1.0},
                            "bodies": [upper, lower], "contact": [contact]})


def contact_tractions(model, angle=0.0):
    """(t_N of every pair, the exact uniform traction q W0 / W) at the end of the run."""
    recorder = Recorder()
    sim = Simulation(model, [recorder])
    sim.run()
    assert recorder.status == ("completed", None)
    rows = recorder.records[-1].extra["contact_rows"]
    top = sim.model.body("lower").nodes
    turn = np.deg2rad(angle)
    back = np.array([[np.cos(turn), np.sin(turn)], [-np.sin(turn), np.cos(turn)]])
    on_top = np.abs((sim.state.X[top] @ back.T)[:, 1] - 1.0) < 1e-9
    width = np.linalg.norm(np.ptp(sim.state.x[top][on_top], axis=0))
    return np.asarray(rows["normal_traction"]), Q * 2.0 / width


# The solve is converged to gap_tolerance 1e-12 on gaps of order q/eps_N = 1e-3: a relative
# traction error of 1e-8 is far above that and far below any lumping error (percent)
EXACT = 1e-8
PENALTY = ContactLaw("penalty", eps_N=50.0)


@pytest.mark.parametrize(("ale", "lower_is_body_1"), [
    ("lower", False),  # the finer surface ALE, body 2 (the first set-up)
    ("upper", True),   # swapped: body 1 the 11-node Lagrangian surface, body 2 the ALE 8-node
    ("upper", False),  # the coarser surface ALE, body 1
    ("lower", True),   # the finer surface ALE, body 1
])
def test_unequal_counts_transmit_the_uniform_pressure_exactly(ale, lower_is_body_1):
    t_n, exact = contact_tractions(stacked_blocks(ale=ale, lower_is_body_1=lower_is_body_1))
    assert len(t_n) == 8  # one pair per node of the coarser surface
    np.testing.assert_allclose(t_n, exact, rtol=EXACT)


def test_other_ratio_and_exact_multipliers():
    """10 against 4 elements (up to three unpaired nodes between two pairs), Lagrange
    multipliers instead of the augmented Lagrangian."""
    t_n, exact = contact_tractions(stacked_blocks(n_upper=4, method="lagrange"))
    assert len(t_n) == 5
    np.testing.assert_allclose(t_n, exact, rtol=EXACT)


def test_turned_frame():
    """The first set-up turned by 90 degrees: the normals along x."""
    t_n, exact = contact_tractions(stacked_blocks(angle=90.0), angle=90.0)
    assert len(t_n) == 8
    np.testing.assert_allclose(t_n, exact, rtol=EXACT)


def test_without_the_share_the_pressure_is_lumped_unevenly():
    """The report's point forces on the same meshes: the test above can fail."""
    t_n, exact = contact_tractions(stacked_blocks(share=False))
    assert np.abs(t_n / exact - 1.0).max() > 1e-2


def test_lagrangian_bodies_keep_the_report_forces_by_default():
    """Offset Lagrangian pairs are not node to node: sharing their forces would place them at
    the wrong points, so the default leaves them alone; their error is the method's limit
    (docs/theory.md, "Unequal node counts")."""
    default, exact = contact_tractions(stacked_blocks(ale="none"))
    report, _ = contact_tractions(stacked_blocks(ale="none", share=False))
    np.testing.assert_array_equal(default, report)
    assert np.abs(default / exact - 1.0).max() > 1e-2


def flat_pair_interface(n1, n2, width=2.0):
    """Two straight open surfaces on y = 0, surface 1 walked right to left (body 1 below,
    outward normal up). Every node of the coarser one is paired with the nearest node of the
    finer one, which is moved onto it, as the ALE motion does."""
    x1 = np.column_stack([np.linspace(width, 0.0, n1 + 1), np.zeros(n1 + 1)])
    x2 = np.column_stack([np.linspace(0.0, width, n2 + 1), np.zeros(n2 + 1)])
    coarse, fine = (x1, x2) if n1 <= n2 else (x2, x1)
    near = np.abs(coarse[:, 0][:, None] - fine[:, 0][None, :]).argmin(axis=1)
    fine[near] = coarse
    x = np.vstack([x1, x2])
    interface = Interface(ContactSurface(np.arange(n1 + 1)),
                          ContactSurface(n1 + 1 + np.arange(n2 + 1)))
    coarse_nodes = np.arange(coarse.shape[0])
    pairs = (np.column_stack([coarse_nodes, n1 + 1 + near]) if n1 <= n2
             else np.column_stack([near, n1 + 1 + coarse_nodes]))
    return x, interface, pairs


def consistent_loads(x, surface):
    """Uniform unit traction on a chain of linear segments: half of each adjacent segment."""
    seg = np.linalg.norm(np.diff(x[surface.nodes], axis=0), axis=1)
    return np.concatenate(([0.0], seg / 2)) + np.concatenate((seg / 2, [0.0]))


def _full_map(transfer):
    """S as a dense (ndof, ndof) map of the displacement dofs: the identity but on the
    distributed nodes' rows, which are the weights."""
    n = transfer.weights.shape[1]
    nodes = np.eye(n)
    nodes[transfer.distributed] = transfer.weights.toarray()
    return np.kron(nodes, np.eye(2))


@pytest.mark.parametrize(("n1", "n2"), [(7, 10), (4, 10), (10, 7), (3, 11)])
def test_weights_give_each_node_its_consistent_load_and_keep_points(n1, n2):
    """Uniform traction: pair forces t L_c (on the pairs' chain) spread by the weights give
    every node of the finer surface its consistent load, the forces of linear elements; on a
    straight surface each pair's weighted point is its own node."""
    x, interface, pairs = flat_pair_interface(n1, n2)
    transfer = unpaired_share(x, interface, pairs)
    s = _full_map(transfer)[::2, ::2]
    np.testing.assert_allclose(s.sum(axis=1), 1.0, atol=1e-14)
    np.testing.assert_allclose(s @ x, x, atol=1e-14)
    chain = transfer.surface1
    k = chain.index_of(pairs[:, 0])
    length = 0.5 * (np.linalg.norm(x[pairs[:, 0]] - x[chain.prev[k]], axis=1)
                    + np.linalg.norm(x[chain.next[k]] - x[pairs[:, 0]], axis=1))
    force = np.zeros(x.shape[0])
    force[pairs[:, 0]] += length
    force[pairs[:, 1]] += length
    nodal = s.T @ force  # each side's loads, pair forces shared where they are distributed
    for surface in (interface.surface1, interface.surface2):
        np.testing.assert_allclose(nodal[surface.nodes], consistent_loads(x, surface),
                                   atol=1e-13)


def test_equal_counts_stay_node_to_node():
    """Matching node counts, even offset along the surface: no share, the kernel's pairs."""
    x, interface, pairs = flat_pair_interface(6, 6)
    x[7:, 0] += 0.05
    assert unpaired_share(x, interface, pairs) is None


@pytest.mark.parametrize(("n1", "n2"), [(4, 10), (10, 4)])
def test_weighted_tangent_is_the_derivative_of_the_weighted_force(n1, n2):
    """The weighted tangent is the derivative of S(x)^T f(S(x) x): S^T K S plus the terms of
    the weights' own motion (contact/transfer.py; tests/test_transfer_tangent.py checks them
    on sheared, curved, frictional and rate-law cases)."""
    x, interface, pairs = flat_pair_interface(n1, n2)
    x[interface.surface1.nodes, 1] += 1e-3  # pressed: body 1 below, pushed into body 2
    x = x + 1e-3 * np.random.default_rng(3).standard_normal(x.shape)
    state = PairState.from_pairs(pairs)

    def force(y):
        return evaluate_contact(y, None, None, interface, state,
                                replace(PENALTY, unpaired_share=True)).force

    res = evaluate_contact(x, None, None, interface, state,
                           replace(PENALTY, unpaired_share=True))
    assert res.transfer is not None
    k = sp.csr_matrix((res.vals, (res.rows, res.cols)), shape=(x.size, x.size)).toarray()
    step = 1e-7
    fd = np.zeros_like(k)
    for col in range(x.size):
        e = np.zeros(x.size)
        e[col] = step
        fd[:, col] = (force(x + e.reshape(x.shape)) - force(x - e.reshape(x.shape))) / (2 * step)
    np.testing.assert_allclose(k, fd, atol=1e-6 * np.abs(k).max())


@pytest.mark.parametrize(("n1", "n2"), [(4, 10), (10, 4), (7, 10)])
def test_transfer_on_its_rows_equals_the_full_map(n1, n2):
    """positions, force, tangent and columns act on the distributed rows only; they equal
    S x, S^T f, S^T K S and G S with S the full (ndof, ndof) map, to round-off."""
    x, interface, pairs = flat_pair_interface(n1, n2)
    transfer = unpaired_share(x, interface, pairs)
    assert transfer is not None and transfer.distributed.size > 0
    S = _full_map(transfer)
    rng = np.random.default_rng(7)
    y = x + 0.01 * rng.standard_normal(x.shape)
    np.testing.assert_allclose(transfer.positions(y), (S @ y.ravel()).reshape(y.shape),
                               rtol=0, atol=1e-15)
    f = rng.standard_normal(x.size)
    np.testing.assert_allclose(transfer.force(f), S.T @ f, rtol=0, atol=1e-14)
    n = x.size
    rows, cols = rng.integers(0, n, 60), rng.integers(0, n, 60)
    rows[:20] = 2 * transfer.distributed[rng.integers(0, transfer.distributed.size, 20)]
    vals = rng.standard_normal(60)
    K = sp.coo_matrix((vals, (rows, cols)), shape=(n, n)).toarray()
    r, c, v = transfer.tangent(rows, cols, vals)
    assert np.unique(r * n + c).size == r.size  # summed entries
    np.testing.assert_allclose(sp.coo_matrix((v, (r, c)), shape=(n, n)).toarray(),
                               S.T @ K @ S, rtol=0, atol=1e-13)
    g_rows = rng.integers(0, 3, 30)
    r, c, v = transfer.columns(g_rows, cols[:30], vals[:30], 3)
    G = sp.coo_matrix((vals[:30], (g_rows, cols[:30])), shape=(3, n)).toarray()
    np.testing.assert_allclose(sp.coo_matrix((v, (r, c)), shape=(3, n)).toarray(), G @ S,
                               rtol=0, atol=1e-13)


@pytest.mark.parametrize("order", [(0, 1), (1, 0)])
def test_two_pairs_across_a_closed_surfaces_start_share_nothing(order):
    """A disk (closed surface 1, 24 nodes) touching a flat surface with two pairs at its chain
    positions 0 and 23, neighbours across the chain's start, whose partners are neighbours:
    nothing lies between them. Before, the long arc's 22 nodes were taken as unpaired between
    the pairs and the surface left without them failed ("a contact surface needs >= 2 nodes"):
    a spinning disk on an ALE block stopped at its first contact step (a tester's case)."""
    angle = -np.pi / 2 + 2 * np.pi * np.arange(24) / 24  # the lowest node first
    disk = np.column_stack([np.cos(angle), 1.0 + np.sin(angle)])
    flat = np.column_stack([np.linspace(-1.0, 1.0, 9), np.zeros(9)])
    x = np.vstack([disk, flat])
    interface = Interface(ContactSurface(np.arange(24), closed=True),
                          ContactSurface(24 + np.arange(9)))
    pairs = np.array([[0, 24 + 4], [23, 24 + 3]])[list(order)]
    assert unpaired_share(x, interface, pairs) is None
