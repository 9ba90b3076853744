"""Numba Q4 kernel: internal force, strain energy and tangent scattered straight into CSR data.

The package's one implementation of the element force and of the constitutive laws in it
(report (5.10); Neo-Hookean and linear elastic in :func:`_material`, the energy-momentum
integrator's algorithmic stress in :func:`_element_em`); tests/element_oracle.py is an
independent NumPy version that the tests compare it with. Each element's 8x8 tangent is added
to the global CSR ``data`` through the precomputed ``entry_map`` of
:class:`ntncontact.fem.assembly.CsrPattern` and its force to the global vector,
so no (ne, 8, 8) temporary exists. Elements are processed one at a time in a compiled loop.

With ``parallel=True`` the elements are split into one contiguous block per thread; an element
sharing a node with another block is deferred to a serial pass, so no two threads ever add to
the same force or CSR entry (no atomics needed, result independent of the thread count up to
the summation order).
"""

from __future__ import annotations

import numba
import numpy as np
from numba import prange
from numpy.typing import NDArray

from ..jit import njit
from ..materials.models import MaterialKind
from ..threads import run_threads
from .q4 import DN_GP, GAUSS_WEIGHTS, InvertedElementError, NonFiniteElementError

#: Integer codes of the constitutive models compiled into the kernel.
MODEL_CODES: dict[str, int] = {"linear_elastic": 0, "neo_hookean": 1}
#: Below this many elements per thread the serial loop is used (thread start-up dominates).
MIN_ELEMENTS_PER_THREAD = 2000
#: Codes of where an inverted element was found (``status[1]``).
_WHERE = {1: "reference configuration", 2: "current configuration"}

# dN_a/dxi and dN_a/deta per Gauss point as nested tuples: compile-time constants
_DXI = tuple(tuple(float(v) for v in DN_GP[g, :, 0]) for g in range(4))
_DETA = tuple(tuple(float(v) for v in DN_GP[g, :, 1]) for g in range(4))
_GW = tuple(float(w) for w in GAUSS_WEIGHTS)


@njit(cache=True, inline="always")
def _jacobian_minus_one(H00, H01, H10, H11):
    """J - 1 = det(I + H) - 1 = tr H + det H, without the round-off of 1 + ... (J near 1)."""
    return H00 + H11 + (H00 * H11 - H01 * H10)


@njit(cache=True, inline="always", error_model="numpy")
def _material(model, H00, H01, H10, H11, lam, mu):
    """Stress and tangent data at one point of displacement gradient H = Grad d (F = I + H):
    (W, P00, P01, P10, P11, Fi00, Fi01, Fi10, Fi11, c1).

    Both models have A_iJkL = mu d_ik d_JL + c1 Fi_Li Fi_Jk + lam Fi_Ji Fi_Lk, with Fi = F^-1 and
    c1 = mu - lam ln J for Neo-Hookean, and Fi = I, c1 = mu for linear elasticity, so the
    element tangent takes the cheap spatial form used in :func:`_add_tangent`.
    The stress is formed from H, never from F - I: its round-off is then relative to the
    stress itself (a stress of E |H| computed as E (F - I) carries eps E; from positions x of
    size L, eps E L / h: the residual floor of a stiff body far from the origin).
    """
    if model == 1:
        detH = H00 * H11 - H01 * H10
        j = H00 + H11 + detH  # J - 1
        lnJ = np.log1p(j)
        r = 1.0 / (1.0 + j)
        F00, F11 = 1.0 + H00, 1.0 + H11
        Fi00, Fi01, Fi10, Fi11 = F11 * r, -H01 * r, -H10 * r, F00 * r
        # P = mu (F - F^-T) + lam ln J F^-T with F - F^-T = H + (H^T + det H I)/J and
        # F^-T = cof F / J: every term is O(H), none is 1 + O(H)
        a, b = mu * r, lam * lnJ * r
        P00 = mu * H00 + a * (H00 + detH) + b * F11
        P11 = mu * H11 + a * (H11 + detH) + b * F00
        P01 = mu * H01 + (a - b) * H10
        P10 = mu * H10 + (a - b) * H01
        # W = mu/2 (|F|^2 - 2) - mu ln J + lam/2 ln J^2, |F|^2 - 2 = 2 tr H + |H|^2
        W = mu * (0.5 * (H00 * H00 + H01 * H01 + H10 * H10 + H11 * H11) - detH + (j - lnJ))
        W += 0.5 * lam * lnJ * lnJ
        return W, P00, P01, P10, P11, Fi00, Fi01, Fi10, Fi11, mu - lam * lnJ
    # linear elastic: eps = sym(H), P = lam tr(eps) I + 2 mu eps
    e00, e11, e01 = H00, H11, 0.5 * (H01 + H10)
    tr = e00 + e11
    P00, P11, P01 = lam * tr + 2.0 * mu * e00, lam * tr + 2.0 * mu * e11, 2.0 * mu * e01
    W = 0.5 * (P00 * e00 + P11 * e11 + 2.0 * P01 * e01)
    return W, P00, P01, P01, P11, 1.0, 0.0, 0.0, 1.0, mu


@njit(cache=True, inline="always")
def gauss_jacobian(dn, g, X, cell):
    """J_ij = dX_i / dxi_j at Gauss point g of the Q4 with nodes ``cell`` (4,), from the
    natural gradients ``dn`` (g, a, j) and the node positions X (n, 2); for the ALE kernels
    that gather X by node (the element kernel keeps its cached, per-element form)."""
    J00 = J01 = J10 = J11 = 0.0
    for a in range(4):
        n = cell[a]
        J00 += dn[g, a, 0] * X[n, 0]
        J01 += dn[g, a, 1] * X[n, 0]
        J10 += dn[g, a, 0] * X[n, 1]
        J11 += dn[g, a, 1] * X[n, 1]
    return J00, J01, J10, J11


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
def _reference_point(Xx, Xy, g):
    """(det J, Gx, Gy) at Gauss point g of an element's reference coordinates: the reference
    Jacobian J_ij = dX_i/dxi_j and dN_a/dX = dN_a/dxi J^-1 (not finite where det J = 0)."""
    dxi, deta = _DXI[g], _DETA[g]
    J00, J01, J10, J11 = _dot4(Xx, dxi), _dot4(Xx, deta), _dot4(Xy, dxi), _dot4(Xy, deta)
    det = J00 * J11 - J01 * J10
    r = 1.0 / det
    return det, _comb4(dxi, deta, J11 * r, -J10 * r), _comb4(dxi, deta, -J01 * r, J00 * r)


@njit(cache=True, error_model="numpy", inline="always")
def _reference(p, Xx, Xy, geo, Xc):
    """Recompute geo[p] (Gx, Gy and det J * weight per Gauss point) from the element's reference
    coordinates; return the number of Gauss points with det J > 0 (4: element valid).

    These are the expressions the kernel always used, so the cached values are the same bits.
    Xc[p] records the coordinates only when all four points are valid; otherwise it is poisoned
    (NaN never compares equal) so that the element is recomputed, and found inverted, next time.
    """
    for g in range(4):
        det, Gx, Gy = _reference_point(Xx, Xy, g)
        if not det > 0.0:
            Xc[p, 0] = np.nan
            return g
        for a in range(4):
            geo[p, g, a] = Gx[a]
            geo[p, g, 4 + a] = Gy[a]
        geo[p, g, 8] = det * _GW[g]
    for a in range(4):
        Xc[p, a] = Xx[a]
        Xc[p, 4 + a] = Xy[a]
    return 4


@njit(cache=True, inline="always")
def _same_reference(Xx, Xy, xc):
    """Whether element p's reference coordinates are those geo[p] was computed from.

    Equal floats may differ only in the sign of a zero, which cannot change the gradients of an
    element with det J > 0 (a Jacobian entry is a signed zero only if det J = 0).
    """
    return (Xx[0] == xc[0] and Xx[1] == xc[1] and Xx[2] == xc[2] and Xx[3] == xc[3]
            and Xy[0] == xc[4] and Xy[1] == xc[5] and Xy[2] == xc[6] and Xy[3] == xc[7])


@njit(cache=True, inline="always")
def _gradients(gp, g):
    """Gx, Gy and the weight of Gauss point g from an element's cached row gp = geo[p]."""
    return ((gp[g, 0], gp[g, 1], gp[g, 2], gp[g, 3]),
            (gp[g, 4], gp[g, 5], gp[g, 6], gp[g, 7]), gp[g, 8])


@njit(cache=True, error_model="numpy")
def _where_inverted(model, p, valid, ux, uy, geo):
    """Where code of an element whose reference det J fails at Gauss point ``valid``: the
    current configuration (2) if a Neo-Hookean det F fails at an earlier point, as the points
    are checked in order, else the reference one (1)."""
    for g in range(valid):
        Gx, Gy, _ = _gradients(geo[p], g)
        j = _jacobian_minus_one(_dot4(ux, Gx), _dot4(ux, Gy), _dot4(uy, Gx), _dot4(uy, Gy))
        if model == 1 and not 1.0 + j > 0.0:
            return 2
    return 1


@njit(cache=True, error_model="numpy", inline="always")
def _element_displacements(model, p, X, d, ecells, geo, Xc, status):
    """Nodal displacements (ux, uy) of the p-th element of a group; refreshes its cached
    reference data when X moved (ALE) and sets status[1] (1: reference, 2: current
    configuration) if it is inverted."""
    n0, n1, n2, n3 = ecells[p, 0], ecells[p, 1], ecells[p, 2], ecells[p, 3]
    ux = (d[n0, 0], d[n1, 0], d[n2, 0], d[n3, 0])
    uy = (d[n0, 1], d[n1, 1], d[n2, 1], d[n3, 1])
    Xx = (X[n0, 0], X[n1, 0], X[n2, 0], X[n3, 0])
    Xy = (X[n0, 1], X[n1, 1], X[n2, 1], X[n3, 1])
    if not _same_reference(Xx, Xy, Xc[p]):  # X moved (ALE) or first call
        valid = _reference(p, Xx, Xy, geo, Xc)
        if valid < 4:
            status[1] = _where_inverted(model, p, valid, ux, uy, geo)
    return ux, uy


@njit(cache=True, error_model="numpy", inline="always")
def _element(model, p, e, X, d, ecells, lam, mu, geo, Xc, need_tangent, Ke, status):
    """Force (fx, fy) 4-tuples, upper block triangle of Ke (8,8) and energy of element e, the
    p-th of its group (the row of its cached reference data), at nodal displacements d.

    Sets status[1] (1: reference, 2: current configuration) and stops at an inverted point.
    """
    fx = fy = (0.0, 0.0, 0.0, 0.0)
    energy = 0.0
    ux, uy = _element_displacements(model, p, X, d, ecells, geo, Xc, status)
    if status[1] != 0:
        return fx, fy, energy
    if need_tangent:
        Ke[:, :] = 0.0
    gp = geo[p]
    for g in range(4):
        Gx, Gy, w = _gradients(gp, g)
        H00, H01, H10, H11 = _dot4(ux, Gx), _dot4(ux, Gy), _dot4(uy, Gx), _dot4(uy, Gy)
        if model == 1 and not 1.0 + _jacobian_minus_one(H00, H01, H10, H11) > 0.0:
            status[1] = 2
            return fx, fy, energy
        W, P00, P01, P10, P11, Fi00, Fi01, Fi10, Fi11, c1 = _material(
            model, H00, H01, H10, H11, lam[e], mu[e])
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


#: |z| below which :func:`_log_quotient` sums series: the closed form of phi'(z) loses about
#: eps/|z| of relative accuracy, the series truncated after z^9 is exact to ~1e-20 there.
_SERIES_Z = 1e-2


@njit(cache=True, inline="always", error_model="numpy")
def _log_quotient(z):
    """phi(z) = log1p(z)/z = (ln I1 - ln I0)/(I1 - I0) * I0 with z = (I1 - I0)/I0, and
    phi'(z); phi(0) = 1, accurate for every z > -1."""
    if abs(z) < _SERIES_Z:
        phi, dphi = 0.0, 0.0  # phi = sum_k (-z)^k/(k+1), by Horner from k = 9 down
        for k in range(9, -1, -1):
            sign = 1.0 if k % 2 == 0 else -1.0
            phi = phi * z + sign / (k + 1.0)
            if k >= 1:
                dphi = dphi * z + sign * k / (k + 1.0)
        return phi, dphi
    L = np.log1p(z)
    return L / z, (z / (1.0 + z) - L) / (z * z)


@njit(cache=True, error_model="numpy", inline="always")
def _element_em(p, e, X, d0, d, ecells, lam, mu, geo, Xc, need_tangent, Ke, status):
    """Neo-Hookean element of the energy-momentum scheme (docs/theory.md), displacements
    d0 = d_n and d = d_{n+1/2} (x = X + d): force f_ai = int (F_m S_alg)_iJ G_aJ with
    F_m = I + Grad d and Gonzalez's discrete gradient S_alg = mu I + 2 q cof(C_m),
    q = (U(I_{n+1}) - U(I_n))/(I_{n+1} - I_n) for U(I) = -mu/2 ln I + lam/8 (ln I)^2 and
    I = det C; its full (unsymmetric) tangent with respect to d in Ke; the strain energy at d.
    status[1] = 2 if det F <= 0 at t_n, t_{n+1/2} or t_{n+1}."""
    fx = fy = (0.0, 0.0, 0.0, 0.0)
    energy = 0.0
    ux, uy = _element_displacements(1, p, X, d, ecells, geo, Xc, status)
    if status[1] != 0:
        return fx, fy, energy
    n0, n1, n2, n3 = ecells[p, 0], ecells[p, 1], ecells[p, 2], ecells[p, 3]
    ox = (d0[n0, 0], d0[n1, 0], d0[n2, 0], d0[n3, 0])
    oy = (d0[n0, 1], d0[n1, 1], d0[n2, 1], d0[n3, 1])
    if need_tangent:
        Ke[:, :] = 0.0
    gp = geo[p]
    lam_e, mu_e = lam[e], mu[e]
    for g in range(4):
        Gx, Gy, w = _gradients(gp, g)
        # F = I + Grad d at t_{n+1/2} (m), t_n (a) and t_{n+1} (b: 2 d_{n+1/2} - d_n)
        h00, h01, h10, h11 = _dot4(ux, Gx), _dot4(ux, Gy), _dot4(uy, Gx), _dot4(uy, Gy)
        k00, k01, k10, k11 = _dot4(ox, Gx), _dot4(ox, Gy), _dot4(oy, Gx), _dot4(oy, Gy)
        m00, m01, m10, m11 = 1.0 + h00, h01, h10, 1.0 + h11
        a00, a01, a10, a11 = 1.0 + k00, k01, k10, 1.0 + k11
        b00, b01 = 1.0 + (2.0 * h00 - k00), 2.0 * h01 - k01
        b10, b11 = 2.0 * h10 - k10, 1.0 + (2.0 * h11 - k11)
        jm = _jacobian_minus_one(h00, h01, h10, h11)  # J - 1, free of the round-off of 1 + ..
        j0 = _jacobian_minus_one(k00, k01, k10, k11)
        j1 = _jacobian_minus_one(b00 - 1.0, b01, b10, b11 - 1.0)
        Jm, J0, J1 = 1.0 + jm, 1.0 + j0, 1.0 + j1
        if not (Jm > 0.0 and J0 > 0.0 and J1 > 0.0):
            status[1] = 2
            return fx, fy, energy
        # C_m = (C_n + C_{n+1})/2 and the discrete derivative q of the volumetric energy
        cm00 = 0.5 * (a00 * a00 + a10 * a10 + b00 * b00 + b10 * b10)
        cm01 = 0.5 * (a00 * a01 + a10 * a11 + b00 * b01 + b10 * b11)
        cm11 = 0.5 * (a01 * a01 + a11 * a11 + b01 * b01 + b11 * b11)
        I0, I1 = J0 * J0, J1 * J1
        phi, dphi = _log_quotient((j1 - j0) * (J1 + J0) / I0)
        slope = 0.25 * lam_e * (np.log1p(j0) + np.log1p(j1)) - 0.5 * mu_e  # dU/d(ln I), avg.
        q = slope * phi / I0
        S00, S01, S11 = mu_e + 2.0 * q * cm11, -2.0 * q * cm01, mu_e + 2.0 * q * cm00
        lnJ = np.log1p(jm)
        # as in _material: mu/2 (|F|^2 - 2) - mu ln J = mu (|H|^2/2 - det H + j - ln J)
        W = mu_e * (0.5 * (h00 * h00 + h01 * h01 + h10 * h10 + h11 * h11)
                    - (h00 * h11 - h01 * h10) + (jm - lnJ))
        energy += w * (W + 0.5 * lam_e * lnJ * lnJ)
        # P = F_m S_alg
        P00, P01 = m00 * S00 + m01 * S01, m00 * S01 + m01 * S11
        P10, P11 = m10 * S00 + m11 * S01, m10 * S01 + m11 * S11
        fx = _comb4(fx, _comb4(Gx, Gy, P00, P01), 1.0, w)
        fy = _comb4(fy, _comb4(Gx, Gy, P10, P11), 1.0, w)
        if need_tangent:
            # dq = dq/dI1 dI1 with dI1 = 4 I1 H_bk, H = dN/dx_{n+1} (x_{n+1} = 2 x - x_n)
            r = 1.0 / J1
            Hx = _comb4(Gx, Gy, b11 * r, -b10 * r)
            Hy = _comb4(Gx, Gy, -b01 * r, b00 * r)
            dq = 4.0 * slope * dphi * I1 / (I0 * I0) + 0.5 * lam_e * phi / I0
            _add_em_tangent(Gx, Gy, Hx, Hy, (b00, b01, b10, b11), (m00, m01, m10, m11),
                            (S00, S01, S11), (cm00, cm01, cm11), q, dq, w, Ke)
    return fx, fy, energy


@njit(cache=True, inline="always")
def _add_em_tangent(Gx, Gy, Hx, Hy, F1, Fm, S, Cm, q, dq, w, Ke):
    """Ke[2a+i, 2b+k] += w (d_ik G_a.S G_b + (F_m dS G_a)_i), dS the change of S_alg for a
    unit x at node b, direction k: dS = 2 dq H_bk cof(C_m) + q cof(dC_{n+1}),
    dC_{n+1} = 2 (F1^T e_k (x) G_b + G_b (x) F1^T e_k)."""
    m00, m01, m10, m11 = Fm
    for b in range(4):
        gb0, gb1 = Gx[b], Gy[b]
        sg0, sg1 = S[0] * gb0 + S[1] * gb1, S[1] * gb0 + S[2] * gb1
        for k in range(2):
            f0, f1 = (F1[0], F1[1]) if k == 0 else (F1[2], F1[3])
            dq2 = 2.0 * dq * (Hx[b] if k == 0 else Hy[b])
            dC00, dC01, dC11 = 4.0 * f0 * gb0, 2.0 * (f0 * gb1 + f1 * gb0), 4.0 * f1 * gb1
            dS00, dS01 = dq2 * Cm[2] + q * dC11, -dq2 * Cm[1] - q * dC01
            dS11 = dq2 * Cm[0] + q * dC00
            T00, T01 = m00 * dS00 + m01 * dS01, m00 * dS01 + m01 * dS11
            T10, T11 = m10 * dS00 + m11 * dS01, m10 * dS01 + m11 * dS11
            col = 2 * b + k
            for a in range(4):
                gab = Gx[a] * sg0 + Gy[a] * sg1
                Ke[2 * a, col] += w * (T00 * Gx[a] + T01 * Gy[a] + (gab if k == 0 else 0.0))
                Ke[2 * a + 1, col] += w * (T10 * Gx[a] + T11 * Gy[a] + (gab if k == 1 else 0.0))


@njit(cache=True)
def _scatter(p, e, ecells, fx, fy, Ke, need_tangent, full, entry_map, force, data):
    """Add element e's force and tangent (lower blocks mirrored unless ``full``) to the global
    arrays."""
    for a in range(4):
        n = ecells[p, a]
        force[2 * n] += fx[a]
        force[2 * n + 1] += fy[a]
    if not need_tangent:
        return
    base = e * 64
    for r in range(8):
        for c in range(8):
            v = Ke[r, c] if full or (r >> 1) <= (c >> 1) else Ke[c, r]
            data[entry_map[base + 8 * r + c]] += v


@njit(cache=True, inline="always")
def _run(model, order, lo, hi, X, d0, d, ecells, lam, mu, geo, Xc, need_tangent, entry_map,
         force, data, status):
    """Process order[lo:hi]; return the energy. Stops at the first inverted element.

    With d0 (d_n) not empty, a Neo-Hookean group takes the energy-momentum element at the
    mid-point d = d_{n+1/2}; its tangent is unsymmetric, so it is scattered in full."""
    full = d0.shape[0] > 0
    Ke = np.empty((8, 8))
    energy = 0.0
    for p in range(lo, hi):
        e = order[p]
        if full:
            fx, fy, w = _element_em(p, e, X, d0, d, ecells, lam, mu, geo, Xc, need_tangent, Ke,
                                    status)
        else:
            fx, fy, w = _element(model, p, e, X, d, ecells, lam, mu, geo, Xc, need_tangent,
                                 Ke, status)
        if status[1] != 0:
            status[0] = p
            return energy
        energy += w
        _scatter(p, e, ecells, fx, fy, Ke, need_tangent, full, entry_map, force, data)
    return energy


@njit(cache=True)
def _run_both(model, order, lo, hi, X, d0, d, ecells, lam, mu, geo, Xc, need_tangent,
              entry_map, force, data, status):
    """:func:`_run` compiled once per case, so that the force-only loop has no tangent code in
    it (and behind a call: Numba's parallel pass fails on the inlined loop)."""
    if need_tangent:
        return _run(model, order, lo, hi, X, d0, d, ecells, lam, mu, geo, Xc, True,
                    entry_map, force, data, status)
    return _run(model, order, lo, hi, X, d0, d, ecells, lam, mu, geo, Xc, False, entry_map,
                force, data, status)


@njit(cache=True)
def assemble_serial(model, order, X, d0, d, ecells, lam, mu, geo, Xc, need_tangent, entry_map,
                    force, data, status):
    """Serial assembly of the elements ``order`` at nodal displacements ``d`` (n, 2) from the
    reference positions ``X``: adds into ``force`` and ``data``.

    ``d0``: d_n for the energy-momentum scheme (Neo-Hookean groups), or an empty (0, 2) array.
    ``ecells`` = cells[order]; ``geo`` and ``Xc`` are the reference data cache (see
    :class:`NumbaAssembly`). ``status`` (int64[2]) is reset, then receives (position in order,
    where code) of the first inverted element. Returns (energy, whether an element inverted).
    """
    status[0] = status[1] = 0
    energy = _run_both(model, order, 0, order.size, X, d0, d, ecells, lam, mu, geo, Xc,
                       need_tangent, entry_map, force, data, status)
    return energy, status[1] != 0


@njit(cache=True, parallel=True)
def assemble_blocks(model, order, starts, X, d0, d, ecells, lam, mu, geo, Xc, need_tangent,
                    entry_map, force, data, status):
    """Threaded assembly: block t is order[starts[t]:starts[t+1]], then order[starts[-1]:]
    (the deferred elements) serially.

    Blocks must not share nodes (see :func:`block_partition`). ``status`` is (nblocks + 1, 2).
    """
    nb = starts.size - 1
    status[:, :] = 0
    energies = np.zeros(nb + 1)
    for t in prange(nb):
        energies[t] = _run_both(model, order, starts[t], starts[t + 1], X, d0, d, ecells, lam,
                                mu, geo, Xc, need_tangent, entry_map, force, data, status[t])
    energies[nb] = _run_both(model, order, starts[nb], order.size, X, d0, d, ecells, lam, mu,
                             geo, Xc, need_tangent, entry_map, force, data, status[nb])
    return energies.sum(), status[:, 1].any()


#: Columns of :func:`cell_fields`' rows: Cauchy stress and Green-Lagrange strain (xx, yy, zz,
#: xy), von Mises, pressure (current-area averages over the Gauss points), the current and the
#: reference area, and F (00, 01, 10, 11) averaged over the reference area.
CELL_FIELD_COLUMNS = ("stress_xx", "stress_yy", "stress_zz", "stress_xy", "strain_xx",
                      "strain_yy", "strain_zz", "strain_xy", "von_mises", "pressure", "area",
                      "reference_area", "F00", "F01", "F10", "F11")


@njit(cache=True, error_model="numpy")
def cell_fields(model, X, d, ecells, lam, mu, plane_stress, out):
    """Fill ``out`` (ne, 16), one row per element of ``ecells``, with the fields of
    :data:`CELL_FIELD_COLUMNS` at displacements d; return -1, or the first element whose
    reference Jacobian is not positive (its row and the later ones are not filled).

    The stress comes from :func:`_material`, the law of the internal force: sigma = P F^T / J
    (Neo-Hookean, sigma_33 = lam ln J / J) or sigma = P (linear elasticity, sigma_33 =
    lam tr eps in plane strain, 0 in plane stress, ``lam`` the effective one), and the strain
    E = (H + H^T + H^T H) / 2 from H = Grad d, as the kernel forms its stress (no 1 + O(H)
    round-off). Hertz refined 8x (61,086 elements): ~14 ms a frame for both bodies, where
    the NumPy Gauss-point arrays it replaced took ~140 ms."""
    acc = np.empty(15)  # one buffer: an array per element would be a heap allocation each
    for p in range(ecells.shape[0]):
        n0, n1, n2, n3 = ecells[p, 0], ecells[p, 1], ecells[p, 2], ecells[p, 3]
        Xx = (X[n0, 0], X[n1, 0], X[n2, 0], X[n3, 0])
        Xy = (X[n0, 1], X[n1, 1], X[n2, 1], X[n3, 1])
        ux = (d[n0, 0], d[n1, 0], d[n2, 0], d[n3, 0])
        uy = (d[n0, 1], d[n1, 1], d[n2, 1], d[n3, 1])
        acc[:] = 0.0
        reference_area = 0.0
        for g in range(4):
            det, Gx, Gy = _reference_point(Xx, Xy, g)
            if not det > 0.0:
                return p
            H00, H01 = _dot4(ux, Gx), _dot4(ux, Gy)
            H10, H11 = _dot4(uy, Gx), _dot4(uy, Gy)
            _gauss_point_fields(model, H00, H01, H10, H11, lam[p], mu[p], plane_stress,
                                det * _GW[g], acc)
            reference_area += det * _GW[g]
        out[p, :10] = acc[:10] / acc[10]
        out[p, 10] = acc[10]
        out[p, 11] = reference_area
        out[p, 12:] = acc[11:] / reference_area
    return -1


@njit(cache=True, error_model="numpy", inline="always")
def _gauss_point_fields(model, H00, H01, H10, H11, lam, mu, plane_stress, w, acc):
    """Add one Gauss point's fields, times its current weight J w, to acc[:10], J w to
    acc[10] and F w to acc[11:] (see :func:`cell_fields`)."""
    _, P00, P01, P10, P11, _, _, _, _, _ = _material(model, H00, H01, H10, H11, lam, mu)
    j = _jacobian_minus_one(H00, H01, H10, H11)
    J = 1.0 + j
    F00, F11 = 1.0 + H00, 1.0 + H11
    if model == 1:
        s00 = (P00 * F00 + P01 * H01) / J
        s11 = (P10 * H10 + P11 * F11) / J
        s01 = (P00 * H10 + P01 * F11) / J
        s33 = lam * np.log1p(j) / J
    else:
        s00, s11, s01 = P00, P11, P01
        s33 = 0.0 if plane_stress else lam * (H00 + H11)
    E00 = H00 + 0.5 * (H00 * H00 + H10 * H10)
    E11 = H11 + 0.5 * (H01 * H01 + H11 * H11)
    E01 = 0.5 * (H01 + H10 + H00 * H01 + H10 * H11)
    E33 = -lam / (2.0 * mu) * (E00 + E11) if plane_stress else 0.0
    mises = np.sqrt(0.5 * ((s00 - s11) ** 2 + (s11 - s33) ** 2 + (s33 - s00) ** 2)
                    + 3.0 * s01 * s01)
    wJ = w * J
    values = (s00, s11, s33, s01, E00, E11, E33, E01, mises, -(s00 + s11 + s33) / 3.0)
    for k in range(10):
        acc[k] += values[k] * wJ
    acc[10] += wJ
    acc[11] += F00 * w
    acc[12] += H01 * w
    acc[13] += H10 * w
    acc[14] += F11 * w


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
    ``force`` and CSR ``data`` arrays. ``threads`` defaults to the run's threads
    (:func:`ntncontact.threads.run_threads`); it is reduced so that each thread has at least
    :data:`MIN_ELEMENTS_PER_THREAD` elements and to Numba's thread count (``NUMBA_NUM_THREADS``);
    1 means the serial loop. The sum at each node then depends on the thread count (elements
    on a block seam are added last), not on the run: same threads, same bits. Two threads
    assemble the ring refined 8x in 0.129 against 0.198 s a step (2 cores; the assembly and
    the sparse solver never run at once, see :mod:`ntncontact.threads`).

    The reference-configuration data (dN/dX and det J * weight at the Gauss points, 36 floats
    per element) are cached between calls with the reference coordinates they came from: X
    changes only when an ALE mesh moves, so an element is recomputed only when one of its
    nodes' X differs from the kept copy (compared at every call, in the kernel). Not thread
    safe: one instance must not be used by two calls at once.
    """

    def __init__(self, kind: MaterialKind, cells: NDArray, elements: NDArray,
                 threads: int | None = None) -> None:
        self.model = MODEL_CODES[kind]
        self.cells = np.ascontiguousarray(cells, dtype=np.int64)
        self.elements = np.ascontiguousarray(elements, dtype=np.int64)
        threads = run_threads() if threads is None else int(threads)
        threads = min(threads, self.elements.size // MIN_ELEMENTS_PER_THREAD)
        if threads > 1:  # only now start Numba's thread pool
            threads = min(threads, numba.get_num_threads())
        self.threads = max(threads, 1)
        if self.threads > 1:
            elems, self.starts, deferred = block_partition(self.cells, self.elements,
                                                           self.threads)
            order = np.concatenate([elems, deferred])
        else:
            order = self.elements
        # processing order and its cells, unsigned: Numba then skips the negative-index test
        self.order = order.astype(np.uint64)
        self.ecells = np.ascontiguousarray(self.cells[order], dtype=np.uint64)
        self.geo = np.empty((order.size, 4, 9))  # per Gauss point: Gx (4), Gy (4), weight
        self.Xc = np.full((order.size, 8), np.nan)  # X of each element's geo row; NaN: none
        self.status = np.zeros((self.starts.size if self.threads > 1 else 1, 2), dtype=np.int64)

    def add(self, X: NDArray, d: NDArray, lam: NDArray, mu: NDArray, entry_map: NDArray,
            force: NDArray, data: NDArray | None, d_start: NDArray | None = None) -> float:
        """Add internal force (and tangent if ``data`` is given) at the nodal displacements
        ``d`` (n, 2) from the reference positions ``X``; return the strain energy.

        The kernel forms F = I + Grad d, never Grad x: positions of size L would put a
        round-off of eps E L / h into every stress (see :func:`_material`).
        ``d_start`` (d_n, with d = d_{n+1/2}): a Neo-Hookean group adds the energy-momentum
        scheme's force and its unsymmetric tangent instead (linear elasticity is unchanged: the
        mid-point rule already conserves its quadratic energy).
        Raises :class:`InvertedElementError` naming the global index of the first inverted
        element (reference Jacobian, or det F for Neo-Hookean, not positive at a Gauss point).
        """
        need_tangent = data is not None
        data_ = data if need_tangent else _NO_DATA
        em = d_start is not None and self.model == MODEL_CODES["neo_hookean"]
        d0 = np.ascontiguousarray(d_start, dtype=float) if em else _NO_DISPLACEMENTS
        if self.threads > 1:
            energy, failed = assemble_blocks(
                self.model, self.order, self.starts, X, d0, d, self.ecells, lam, mu, self.geo,
                self.Xc, need_tangent, entry_map, force, data_, self.status)
        else:
            energy, failed = assemble_serial(
                self.model, self.order, X, d0, d, self.ecells, lam, mu, self.geo, self.Xc,
                need_tangent, entry_map, force, data_, self.status[0])
        if failed:
            self._raise(X, d, d0 if em else None)
        return energy

    def _raise(self, X: NDArray, d: NDArray, d_start: NDArray | None) -> None:
        """Raise for the first inverted element (the lowest global index over the blocks)."""
        rows = np.flatnonzero(self.status[:, 1])
        bad = [int(self.order[self.status[t, 0]]) for t in rows]
        t = rows[int(np.argmin(bad))]
        configurations = [d] if d_start is None else [d_start, d, 2.0 * d - d_start]
        _raise_inverted(min(bad), int(self.status[t, 1]), X, configurations, self.cells)


#: The ``data`` argument of force-only calls (never written).
_NO_DATA = np.empty(0)
#: The ``d0`` argument of the plain kernel (no energy-momentum scheme).
_NO_DISPLACEMENTS = np.empty((0, 2))


def raise_inverted(e: int, X: NDArray, cells: NDArray) -> None:
    """Raise :class:`InvertedElementError` for element e of ``cells``, inverted in the
    reference configuration X (as :func:`cell_fields` reports it)."""
    _raise_inverted(e, 1, X, [], cells)


#: |Grad d| past which the kernel's det F = 1 + tr H + det H overflows (H00 H11 > 1.8e308) and
#: its failed test says nothing about inversion.
_OVERFLOWING_GRADIENT = 1e154


def _raise_inverted(e: int, where: int, X: NDArray, configurations: list[NDArray],
                    cells: NDArray) -> None:
    """Raise :class:`InvertedElementError` for element e with its smallest determinant (over
    the current configurations, given by their displacements, when where == 2)."""
    X_e = X[cells[e]]
    with np.errstate(all="ignore"):  # a non-finite element is told below, not warned about
        J = np.einsum("gaj,ai->gij", DN_GP, X_e)
        det = J[:, 0, 0] * J[:, 1, 1] - J[:, 0, 1] * J[:, 1, 0]
        d_e = np.stack([X_e - X_e] + [d[cells[e]] for d in configurations])
        size = float(np.abs(np.nan_to_num(d_e, nan=np.inf)).max())
        overflow = False
        if where == 2:
            grad = np.einsum("gaj,gjI->gaI", DN_GP, np.linalg.inv(J))
            F = np.eye(2) + np.einsum("cai,gaJ->cgiJ", d_e[1:], grad)
            det = F[..., 0, 0] * F[..., 1, 1] - F[..., 0, 1] * F[..., 1, 0]
            overflow = size * float(np.abs(grad).max()) > _OVERFLOWING_GRADIENT
    if overflow or not (np.isfinite(X_e).all() and np.isfinite(det).all()):
        raise NonFiniteElementError(e, size, _WHERE[where])
    raise InvertedElementError(e, float(det.min()), _WHERE[where])
