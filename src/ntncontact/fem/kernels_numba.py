"""Numba Q4 kernel: internal force, strain energy and tangent scattered straight into CSR data.

Same mathematics as :func:`ntncontact.fem.element.element_force_tangent` (the NumPy reference),
but each element's 8x8 tangent is added to the global CSR ``data`` through the precomputed
``entry_map`` of :class:`ntncontact.fem.assembly.CsrPattern` and its force to the global vector,
so no (ne, 8, 8) temporary exists. Elements are processed one at a time in a compiled loop.

With ``parallel=True`` the elements are split into one contiguous block per thread; an element
sharing a node with another block is deferred to a serial pass, so no two threads ever add to
the same force or CSR entry (no atomics needed, result independent of the thread count up to
the summation order).
"""

from __future__ import annotations

import numba
import numpy as np
from numba import njit, prange
from numpy.typing import NDArray

from ..materials.models import MaterialKind
from .q4 import DN_GP, GAUSS_WEIGHTS, InvertedElementError

#: Integer codes of the constitutive models compiled into the kernel.
MODEL_CODES: dict[str, int] = {"linear_elastic": 0, "neo_hookean": 1}
#: Threads used by :class:`NumbaAssembly` when not given. Serial by default: two threads made
#: assembly alone ~1.5x faster on 2 cores, but a Newton iteration is dominated by the
#: factorization, whose MKL threads then compete with Numba's (see benchmarks/README.md).
THREADS = 1
#: Below this many elements per thread the serial loop is used (thread start-up dominates).
MIN_ELEMENTS_PER_THREAD = 2000
#: Codes of where an inverted element was found (``status[1]``).
_WHERE = {1: "reference configuration", 2: "current configuration"}

_DN = np.ascontiguousarray(DN_GP)  # (4 gp, 4 nodes, 2) natural gradients
# dN_a/dxi and dN_a/deta per Gauss point as nested tuples: compile-time constants
_DXI = tuple(tuple(float(v) for v in DN_GP[g, :, 0]) for g in range(4))
_DETA = tuple(tuple(float(v) for v in DN_GP[g, :, 1]) for g in range(4))
_GW = tuple(float(w) for w in GAUSS_WEIGHTS)


@njit(cache=True, inline="always", error_model="numpy")
def _material(model, F00, F01, F10, F11, lam, mu):
    """Stress and tangent data at one point: (W, P00, P01, P10, P11, Fi00, Fi01, Fi10, Fi11, c1).

    Both models have A_iJkL = mu d_ik d_JL + c1 Fi_Li Fi_Jk + lam Fi_Ji Fi_Lk, with Fi = F^-1 and
    c1 = mu - lam ln J for Neo-Hookean, and Fi = I, c1 = mu for linear elasticity, so the
    element tangent takes the cheap spatial form used in :func:`_add_tangent`.
    """
    if model == 1:
        J = F00 * F11 - F01 * F10
        lnJ = np.log(J)
        r = 1.0 / J
        Fi00, Fi01, Fi10, Fi11 = F11 * r, -F01 * r, -F10 * r, F00 * r
        # P = mu F + (lam ln J - mu) F^-T
        c = lam * lnJ - mu
        W = 0.5 * mu * (F00 * F00 + F01 * F01 + F10 * F10 + F11 * F11 - 2.0) - mu * lnJ
        W += 0.5 * lam * lnJ * lnJ
        return (W, mu * F00 + c * Fi00, mu * F01 + c * Fi10, mu * F10 + c * Fi01,
                mu * F11 + c * Fi11, Fi00, Fi01, Fi10, Fi11, mu - lam * lnJ)
    # linear elastic: eps = sym(F - I), P = lam tr(eps) I + 2 mu eps
    e00, e11, e01 = F00 - 1.0, F11 - 1.0, 0.5 * (F01 + F10)
    tr = e00 + e11
    P00, P11, P01 = lam * tr + 2.0 * mu * e00, lam * tr + 2.0 * mu * e11, 2.0 * mu * e01
    W = 0.5 * (P00 * e00 + P11 * e11 + 2.0 * P01 * e01)
    return W, P00, P01, P01, P11, 1.0, 0.0, 0.0, 1.0, mu


@njit(cache=True, inline="always")
def _dot4(a, b):
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2] + a[3] * b[3]


@njit(cache=True, inline="always")
def _scale4(a, c):
    return (a[0] * c, a[1] * c, a[2] * c, a[3] * c)


@njit(cache=True, inline="always")
def _comb4(a, b, ca, cb):
    """ca a + cb b for 4-tuples (tuples stay in registers; small arrays would go to memory)."""
    return (a[0] * ca + b[0] * cb, a[1] * ca + b[1] * cb, a[2] * ca + b[2] * cb,
            a[3] * ca + b[3] * cb)


@njit(cache=True, error_model="numpy", inline="always")
def _element(model, e, X, x, cells, lam, mu, need_tangent, Ke, status):
    """Force (fx, fy) 4-tuples, upper block triangle of Ke (8,8) and energy of element e.

    Sets status[1] (1: reference, 2: current configuration) and stops at an inverted point.
    """
    n0, n1, n2, n3 = cells[e, 0], cells[e, 1], cells[e, 2], cells[e, 3]
    Xx = (X[n0, 0], X[n1, 0], X[n2, 0], X[n3, 0])
    Xy = (X[n0, 1], X[n1, 1], X[n2, 1], X[n3, 1])
    xx = (x[n0, 0], x[n1, 0], x[n2, 0], x[n3, 0])
    xy = (x[n0, 1], x[n1, 1], x[n2, 1], x[n3, 1])
    fx = fy = (0.0, 0.0, 0.0, 0.0)
    if need_tangent:
        Ke[:, :] = 0.0
    energy = 0.0
    for g in range(4):
        dxi, deta = _DXI[g], _DETA[g]
        # reference Jacobian J_ij = dX_i/dxi_j and dN_a/dX = dN_a/dxi J^-1
        J00, J01, J10, J11 = _dot4(Xx, dxi), _dot4(Xx, deta), _dot4(Xy, dxi), _dot4(Xy, deta)
        det = J00 * J11 - J01 * J10
        if not det > 0.0:
            status[1] = 1
            return fx, fy, energy
        r = 1.0 / det
        Gx = _comb4(dxi, deta, J11 * r, -J10 * r)
        Gy = _comb4(dxi, deta, -J01 * r, J00 * r)
        F00, F01, F10, F11 = _dot4(xx, Gx), _dot4(xx, Gy), _dot4(xy, Gx), _dot4(xy, Gy)
        if model == 1 and not F00 * F11 - F01 * F10 > 0.0:
            status[1] = 2
            return fx, fy, energy
        W, P00, P01, P10, P11, Fi00, Fi01, Fi10, Fi11, c1 = _material(
            model, F00, F01, F10, F11, lam[e], mu[e])
        w = det * _GW[g]
        energy += w * W
        fx = _comb4(fx, _comb4(Gx, Gy, P00, P01), 1.0, w)  # f_ai += w P_iJ G_aJ
        fy = _comb4(fy, _comb4(Gx, Gy, P10, P11), 1.0, w)
        if need_tangent:
            Hx = _comb4(Gx, Gy, Fi00, Fi10)  # spatial gradient dN_a/dx = G_aJ Fi_Jk
            Hy = _comb4(Gx, Gy, Fi01, Fi11)
            _add_tangent(Gx, Gy, Hx, Hy, c1 * w, lam[e] * w, mu[e] * w, Ke)
    return fx, fy, energy


@njit(cache=True, inline="always")
def _add_tangent(Gx, Gy, Hx, Hy, c1, lam, mu, Ke):
    """Ke[2a+i, 2b+k] += mu d_ik G_a.G_b + c1 H_bi H_ak + lam H_ai H_bk for blocks b >= a.

    This is G_aJ A_iJkL G_bL (weights folded into c1, lam, mu); the tangent is symmetric.
    """
    cx, cy, lx, ly = _scale4(Hx, c1), _scale4(Hy, c1), _scale4(Hx, lam), _scale4(Hy, lam)
    mx, my = _scale4(Gx, mu), _scale4(Gy, mu)
    for b in range(4):
        for a in range(b + 1):
            gab = mx[a] * Gx[b] + my[a] * Gy[b]
            Ke[2 * a, 2 * b] += gab + cx[b] * Hx[a] + lx[a] * Hx[b]
            Ke[2 * a, 2 * b + 1] += cx[b] * Hy[a] + lx[a] * Hy[b]
            Ke[2 * a + 1, 2 * b] += cy[b] * Hx[a] + ly[a] * Hx[b]
            Ke[2 * a + 1, 2 * b + 1] += gab + cy[b] * Hy[a] + ly[a] * Hy[b]


@njit(cache=True)
def _scatter(e, cells, fx, fy, Ke, need_tangent, entry_map, force, data):
    """Add element e's force and tangent (lower blocks mirrored) to the global arrays."""
    for a in range(4):
        n = cells[e, a]
        force[2 * n] += fx[a]
        force[2 * n + 1] += fy[a]
    if not need_tangent:
        return
    base = e * 64
    for r in range(8):
        for c in range(8):
            v = Ke[r, c] if (r >> 1) <= (c >> 1) else Ke[c, r]
            data[entry_map[base + 8 * r + c]] += v


@njit(cache=True)
def _run(model, elems, lo, hi, X, x, cells, lam, mu, need_tangent, entry_map, force, data, status):
    """Process elems[lo:hi] in order; return the energy. Stops at the first inverted element."""
    Ke = np.empty((8, 8))
    energy = 0.0
    for p in range(lo, hi):
        e = elems[p]
        fx, fy, w = _element(model, e, X, x, cells, lam, mu, need_tangent, Ke, status)
        if status[1] != 0:
            status[0] = p
            return energy
        energy += w
        _scatter(e, cells, fx, fy, Ke, need_tangent, entry_map, force, data)
    return energy


@njit(cache=True)
def assemble_serial(model, elems, X, x, cells, lam, mu, need_tangent, entry_map, force, data,
                    status):
    """Serial assembly over ``elems``: adds into ``force`` and ``data``; returns the energy.

    ``status`` (int64[2]) receives (position in elems, where code) of the first inverted element.
    """
    return _run(model, elems, 0, elems.size, X, x, cells, lam, mu, need_tangent, entry_map,
                force, data, status)


@njit(cache=True, parallel=True)
def assemble_blocks(model, elems, starts, deferred, X, x, cells, lam, mu, need_tangent, entry_map,
                    force, data, status):
    """Threaded assembly: block t is elems[starts[t]:starts[t+1]], then ``deferred`` serially.

    Blocks must not share nodes (see :func:`block_partition`). ``status`` is (nblocks + 1, 2).
    """
    nb = starts.size - 1
    energies = np.zeros(nb + 1)
    for t in prange(nb):
        energies[t] = _run(model, elems, starts[t], starts[t + 1], X, x, cells, lam, mu,
                           need_tangent, entry_map, force, data, status[t])
    energies[nb] = _run(model, deferred, 0, deferred.size, X, x, cells, lam, mu, need_tangent,
                        entry_map, force, data, status[nb])
    return energies.sum()


def block_partition(cells: NDArray, elements: NDArray, nblocks: int) -> tuple[NDArray, NDArray,
                                                                                 NDArray]:
    """Split ``elements`` into contiguous blocks that share no node, plus deferred elements.

    Returns (block elements concatenated, block start offsets (nblocks + 1,), deferred elements).
    An element is kept in its block only if none of its nodes is used by an earlier block, so
    every node (and CSR row) written by a block belongs to that block alone; for a mesh numbered
    row by row only one row of elements per seam is deferred.
    """
    elements = np.asarray(elements, dtype=np.int64)
    block = np.arange(elements.size) * nblocks // max(elements.size, 1)
    nodes = cells[elements]
    first = np.full(int(cells.max()) + 1 if cells.size else 0, nblocks, dtype=np.int64)
    np.minimum.at(first, nodes.ravel(), np.repeat(block, nodes.shape[1]))
    own = (first[nodes] == block[:, None]).all(axis=1)
    starts = np.zeros(nblocks + 1, dtype=np.int64)
    starts[1:] = np.cumsum(np.bincount(block[own], minlength=nblocks))
    return elements[own], starts, elements[~own]


class NumbaAssembly:
    """Force/tangent assembly of one material group with the compiled kernel.

    Holds the group's element list (and its thread partition), and adds into caller-owned
    ``force`` and CSR ``data`` arrays. ``threads`` defaults to :data:`THREADS`; it is reduced
    so that each thread has at least :data:`MIN_ELEMENTS_PER_THREAD` elements and to Numba's
    thread count; 1 means the serial loop.
    """

    def __init__(self, kind: MaterialKind, cells: NDArray, elements: NDArray,
                 threads: int | None = None) -> None:
        self.model = MODEL_CODES[kind]
        self.cells = np.ascontiguousarray(cells, dtype=np.int64)
        self.elements = np.ascontiguousarray(elements, dtype=np.int64)
        threads = THREADS if threads is None else int(threads)
        if threads > 1:  # only now start Numba's thread pool
            threads = min(threads, numba.get_num_threads(),
                          self.elements.size // MIN_ELEMENTS_PER_THREAD)
        self.threads = max(threads, 1)
        if self.threads > 1:
            self.blocks = block_partition(self.cells, self.elements, self.threads)

    def add(self, X: NDArray, x: NDArray, lam: NDArray, mu: NDArray, entry_map: NDArray,
            force: NDArray, data: NDArray | None) -> float:
        """Add internal force (and tangent if ``data`` is given); return the strain energy.

        Raises :class:`InvertedElementError` naming the global index of the first inverted
        element (reference Jacobian, or det F for Neo-Hookean, not positive at a Gauss point).
        """
        need_tangent = data is not None
        data_ = data if need_tangent else np.empty(0)
        args = (X, x, self.cells, lam, mu, need_tangent, entry_map, force, data_)
        if self.threads > 1:
            elems, starts, deferred = self.blocks
            status = np.zeros((starts.size, 2), dtype=np.int64)
            energy = assemble_blocks(self.model, elems, starts, deferred, *args, status)
            # rows 0..nb-1 hold positions in elems, the last row a position in deferred
            orders = [elems] * (starts.size - 1) + [deferred]
        else:
            status = np.zeros((1, 2), dtype=np.int64)
            energy = assemble_serial(self.model, self.elements, *args, status[0])
            orders = [self.elements]
        bad = [int(orders[t][status[t, 0]]) for t in np.flatnonzero(status[:, 1])]
        if bad:
            t = np.flatnonzero(status[:, 1])[int(np.argmin(bad))]
            _raise_inverted(min(bad), int(status[t, 1]), X, x, self.cells)
        return float(energy)


def _raise_inverted(e: int, where: int, X: NDArray, x: NDArray, cells: NDArray) -> None:
    """Raise :class:`InvertedElementError` for element e with its smallest determinant."""
    X_e, x_e = X[cells[e]], x[cells[e]]
    J = np.einsum("gaj,ai->gij", _DN, X_e)
    det = J[:, 0, 0] * J[:, 1, 1] - J[:, 0, 1] * J[:, 1, 0]
    if where == 2:
        grad = np.einsum("gaj,gjI->gaI", _DN, np.linalg.inv(J))
        F = np.einsum("ai,gaJ->giJ", x_e, grad)
        det = F[:, 0, 0] * F[:, 1, 1] - F[:, 0, 1] * F[:, 1, 0]
    raise InvertedElementError(e, float(det.min()), _WHERE[where])
