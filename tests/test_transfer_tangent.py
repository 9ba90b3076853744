"""The unpaired share's tangent against central differences (contact/transfer.py).

The share's weights S(x) move with the nodes (arc-length parameters of the finer surface, the
span and the tributary lengths), and the kernel sees S x, S v and S x_start: the tangent must
carry S^T K (dS/dx) x, the rate law's K_v (dS/dx) v, the gap law's slip increment through
(dS/dx) x_start and (dS/dx)^T f. Without them (the old S^T K S) the error was 1e-4 to 3e-2 of
max|K| on these cases. Tolerance 1e-9: with h = 1e-6 on coordinates of order 1, central
differences carry a truncation error ~h^2 |f'''| ~ 1e-12 and a round-off ~eps |f| / h ~ 1e-10
relative (measured here: 2e-11 to 5.7e-10), five orders below the terms' size.
"""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

from ntncontact.contact import ContactLaw, ContactSurface, Interface, PairState, evaluate_contact
from ntncontact.contact.lagrange import lagrange_blocks

H = 1e-6
TOL = 1e-9


def shared_interface(curved: bool) -> tuple[np.ndarray, Interface, np.ndarray]:
    """Surface 1 (11 nodes, walked right to left, body 1 below) under surface 2 (5 nodes):
    every node of the coarse one paired with a node of the fine one, 1 or 2 unpaired fine
    nodes between pairs. Flat: the fine nodes unevenly spaced (a sheared surface); curved:
    both on a tilted arc. Surface 1 is pressed 1e-2 into surface 2, and all nodes jittered."""
    s1, s2 = np.linspace(2.0, 0.0, 11), np.linspace(0.0, 2.0, 5)
    s1[1:-1] += 0.05 * np.sin(3.0 * s1[1:-1])  # uneven spacing: the share's weights vary
    paired = np.array([10, 8, 5, 3, 0])  # fine nodes under s2's nodes 0..4
    s1[paired] = s2
    if curved:
        def place(s, lift):
            angle = 0.3 + 0.4 * s  # an arc of radius 2.5, turned
            return np.column_stack([2.5 * np.sin(angle), lift - 2.5 * np.cos(angle)])
    else:
        def place(s, lift):
            return np.column_stack([s, np.full(s.size, lift)])
    x = np.vstack([place(s1, 1e-2), place(s2, 0.0)])
    x += 1e-3 * np.random.default_rng(7).standard_normal(x.shape)
    interface = Interface(ContactSurface(np.arange(11)), ContactSurface(11 + np.arange(5)))
    return x, interface, np.column_stack([paired, 11 + np.arange(5)])


def fd_check(x0, v0, rate_factor, interface, state, law, x_start=None) -> float:
    """max |K - FD| / max |FD| of d force / d x, v following x with rate_factor."""
    def force(x):
        v = None if v0 is None else v0 + rate_factor * (x - x0)
        return evaluate_contact(x, v, rate_factor, interface, state, law,
                                x_start=x_start).force

    res = evaluate_contact(x0, v0, rate_factor, interface, state, law, x_start=x_start)
    assert res.transfer is not None and res.transfer.derivative is not None  # shares present
    k = res.tangent_matrix().toarray()
    fd = np.zeros_like(k)
    for dof in range(x0.size):
        e = np.zeros(x0.size)
        e[dof] = H
        fd[:, dof] = (force(x0 + e.reshape(-1, 2)) - force(x0 - e.reshape(-1, 2))) / (2 * H)
    return float(np.abs(k - fd).max() / np.abs(fd).max())


@pytest.mark.parametrize("curved", [False, True])
@pytest.mark.parametrize("method", ["penalty", "augmented_lagrangian", "lagrange"])
def test_gap_law_tangent_with_shares(curved, method):
    """Static: the tangent includes the weights' derivative (frictionless and with friction,
    whose slip increment is measured from S x_start)."""
    x, interface, pairs = shared_interface(curved)
    state = PairState.from_pairs(pairs).with_multipliers(np.full(len(pairs), 3.0))
    frictionless = ContactLaw(method, eps_N=50.0, unpaired_share=True)
    assert fd_check(x, None, None, interface, state, frictionless) < TOL
    frictional = ContactLaw(method, eps_N=50.0, eps_T=40.0, mu=0.3, unpaired_share=True)
    x_start = x + 2e-3 * np.random.default_rng(8).standard_normal(x.shape)
    assert fd_check(x, None, None, interface, state, frictional, x_start=x_start) < TOL


@pytest.mark.parametrize("moment_free", [False, True])
@pytest.mark.parametrize("curved", [False, True])
def test_rate_law_tangent_with_shares(curved, moment_free):
    """Dynamic (persistency law, friction): v_c = S v moves with the weights too (the kernel's
    K_v, returned with the force, includes the moment-free chord rotation's v terms)."""
    x, interface, pairs = shared_interface(curved)
    state = PairState.from_pairs(pairs).with_multipliers(np.full(len(pairs), 3.0))
    law = ContactLaw("augmented_lagrangian", eps_N=50.0, eps_T=40.0, mu=0.3,
                     unpaired_share=True, moment_free=moment_free)
    v = np.random.default_rng(9).standard_normal(x.shape)
    v[11:] *= 0.1
    v[:11, 1] -= 1.0  # surface 1 approaching surface 2
    assert fd_check(x, v, 40.0, interface, state, law) < TOL


@pytest.mark.parametrize("rate_factor", [None, 40.0])
def test_lagrange_constraint_gradient_with_shares(rate_factor):
    """G = dh/dx of the Lagrange blocks includes the weights' derivative."""
    x0, interface, pairs = shared_interface(curved=True)
    state = PairState.from_pairs(pairs).with_multipliers(np.full(len(pairs), 3.0))
    law = ContactLaw("lagrange", unpaired_share=True)
    v0 = None if rate_factor is None else np.random.default_rng(9).standard_normal(x0.shape)

    def blocks(x):
        v = None if v0 is None else v0 + rate_factor * (x - x0)
        return lagrange_blocks(x, v, rate_factor, interface, state, law)

    g = sp.csr_matrix((lambda b: (b.g_vals, (b.g_rows, b.g_cols)))(blocks(x0)),
                      shape=(len(pairs), x0.size)).toarray()
    fd = np.zeros_like(g)
    for dof in range(x0.size):
        e = np.zeros(x0.size)
        e[dof] = H
        fd[:, dof] = (blocks(x0 + e.reshape(-1, 2)).values
                      - blocks(x0 - e.reshape(-1, 2)).values) / (2 * H)
    assert np.abs(g - fd).max() / np.abs(fd).max() < TOL


def _complex_step_value(x: np.ndarray, block) -> np.ndarray:
    """The oracle of ShareBlock.value: the weights of each segment from its local nodes (taken
    from the block's dofs) by the complex step, step 1e-30 (no difference of nearly equal
    numbers: exact to round-off). Lengths as sqrt(d.d), analytic, 0 where d = 0."""
    def length(d):
        out = np.sqrt(np.sum(d * d, axis=-1))
        return np.where(out.real == 0.0, 0.0, out)

    nodes = block.dofs[:, ::2] // 2  # (G, n): the chain (m), then each pair's prev, node, next
    n_seg, n_dof = block.dofs.shape
    m, step = nodes.shape[1] - 6, 1e-30
    xl = np.broadcast_to(x[nodes].astype(complex)[:, None], (n_seg, n_dof, n_dof // 2, 2)).copy()
    xl.reshape(n_seg, n_dof, n_dof)[:, np.arange(n_dof), np.arange(n_dof)] += 1j * step
    arc = np.cumsum(length(np.diff(xl[..., :m, :], axis=-2)), axis=-1)
    arc = np.concatenate((np.zeros_like(arc[..., :1]), arc), axis=-1)
    xi = arc / arc[..., -1:]
    share = np.zeros(xi.shape[:-1] + (2, m), dtype=complex)
    for lo in range(m - 1):
        a, b = xi[..., lo], xi[..., lo + 1]
        mid, h = 0.5 * (a + b), b - a
        for side, psi in enumerate((lambda t: 2.0 - 3.0 * t, lambda t: 3.0 * t - 1.0)):
            share[..., side, lo] += h / 6.0 * (psi(a) + 2.0 * psi(mid))
            share[..., side, lo + 1] += h / 6.0 * (2.0 * psi(mid) + psi(b))
    around = m + np.arange(6).reshape(2, 3)
    span = length(xl[..., m + 1, :] - xl[..., m + 4, :])
    tributary = 0.5 * (length(xl[..., around[:, 1], :] - xl[..., around[:, 0], :])
                       + length(xl[..., around[:, 2], :] - xl[..., around[:, 1], :]))
    scale = span[..., None] / tributary
    d_scale, d_share = scale.imag / step, share.imag / step
    return np.concatenate((scale.real[..., None] * d_share + d_scale[..., None] * share.real,
                           -0.5 * d_scale[..., None]), axis=-1)


@pytest.mark.parametrize("curved", [False, True])
def test_closed_form_weight_derivative_matches_complex_step(curved):
    """The weights' derivative in closed form (transfer._group_derivative) equals the complex
    step's to round-off, and both are dW/dx: central differences of the weights agree to
    their truncation error. A wrong sign or a missing term (the span's or a tributary
    length's derivative) breaks the first by O(1) of the values."""
    from ntncontact.contact.transfer import unpaired_share

    x, interface, pairs = shared_interface(curved)
    transfer = unpaired_share(x, interface, pairs)
    assert transfer is not None and len(transfer.derivative) == 2  # chains of 3 and 4 nodes
    dense = np.zeros((transfer.distributed.size, x.shape[0], x.size))
    for block in transfer.derivative:
        oracle = _complex_step_value(x, block)
        assert np.abs(block.value - oracle).max() <= 1e-13 * np.abs(oracle).max()
        r = np.broadcast_to(block.rows[:, None, :, None], block.value.shape)
        q = np.broadcast_to(block.nodes[:, None], block.value.shape)
        k = np.broadcast_to(block.dofs[:, :, None, None], block.value.shape)
        np.add.at(dense, (r.ravel(), q.ravel(), k.ravel()), block.value.ravel())
    for dof in range(x.size):
        e = np.zeros(x.size)
        e[dof] = H
        plus = unpaired_share(x + e.reshape(-1, 2), interface, pairs).weights.toarray()
        minus = unpaired_share(x - e.reshape(-1, 2), interface, pairs).weights.toarray()
        assert np.abs(dense[:, :, dof] - (plus - minus) / (2 * H)).max() < 1e-8


def test_deferred_tangent_is_the_eager_one():
    """The step problem's contact terms defer the share's tangent to the evaluations that build
    one (ContactResult.triplets): the same entries, bit for bit, the force computed at once."""
    x, interface, pairs = shared_interface(curved=True)
    state = PairState.from_pairs(pairs).with_multipliers(np.full(len(pairs), 3.0))
    law = ContactLaw("augmented_lagrangian", eps_N=50.0, eps_T=40.0, mu=0.3,
                     unpaired_share=True)
    v = np.random.default_rng(9).standard_normal(x.shape)
    eager = evaluate_contact(x, v, 40.0, interface, state, law, x_start=x)
    deferred = evaluate_contact(x, v, 40.0, interface, state, law, x_start=x,
                                deferred_tangent=True)
    assert deferred.rows is None and deferred.deferred is not None
    assert np.array_equal(deferred.force, eager.force)
    for a, b in zip(deferred.triplets(), eager.triplets(), strict=True):
        assert np.array_equal(a, b)
    assert deferred.triplets() is deferred.triplets()  # computed once


def test_weights_term_comes_summed_with_its_zero_entries():
    """A D_a (Transfer._through, the kernel's tangent through the moving weights) comes as
    unique entries: each entry of A times each of its D row, summed only afterwards, was 26k
    entries for 2k places at a refined slide (k = 4) and 8 ms a tangent in the sort. The
    places are those of the structural product, products that sum to exactly zero included
    (a pattern that moved with the values would be a new analysis of the Newton matrix)."""
    x, interface, pairs = shared_interface(curved=True)
    state = PairState.from_pairs(pairs).with_multipliers(np.full(len(pairs), 3.0))
    transfer = evaluate_contact(x, None, None, interface, state,
                                ContactLaw("penalty", eps_N=50.0, unpaired_share=True)).transfer
    n_dof, dist = x.size, transfer.distributed
    rng = np.random.default_rng(3)
    rows, cols = rng.integers(0, n_dof, 400), rng.integers(0, n_dof, 400)  # duplicates too
    vals = rng.standard_normal(400)
    vals[rows == rows[np.isin(cols // 2, dist)][0]] = 0.0  # one row of exact zeros
    got_rows, got_cols, got_vals = transfer._through(rows, cols, [(vals, x)])
    keys = got_rows * n_dof + got_cols
    assert np.all(np.diff(keys) > 0)  # unique, sorted
    # the reference, dense: A (dofs x D's rows) and D_a = (dS/dx) x
    hit = np.isin(cols // 2, dist)
    a_rows = 2 * np.searchsorted(dist, cols[hit] // 2) + cols[hit] % 2
    A, A_s = np.zeros((n_dof, 2 * dist.size)), np.zeros((n_dof, 2 * dist.size))
    np.add.at(A, (rows[hit], a_rows), vals[hit])
    np.add.at(A_s, (rows[hit], a_rows), 1.0)
    D, D_s = np.zeros((2 * dist.size, n_dof)), np.zeros((2 * dist.size, n_dof))
    for block in transfer.derivative:
        d_x = np.einsum("gdpq,gpqi->gpid", block.value, x[block.nodes])
        d_rows = np.broadcast_to((2 * block.rows[..., None] + np.arange(2))[..., None],
                                 d_x.shape)
        d_cols = np.broadcast_to(block.dofs[:, None, None], d_x.shape)
        np.add.at(D, (d_rows.ravel(), d_cols.ravel()), d_x.ravel())
        np.add.at(D_s, (d_rows.ravel(), d_cols.ravel()), 1.0)
    places = np.flatnonzero(A_s @ D_s > 0)
    assert np.array_equal(keys, places)
    assert np.any(got_vals == 0.0)  # the zero row's places are kept
    ref = (A @ D).ravel()[places]
    assert np.abs(got_vals - ref).max() <= 1e-13 * np.abs(ref).max()
