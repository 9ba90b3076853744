"""Contact force and consistent tangent for a GIVEN active set and fixed multipliers.

Virtual work (2.57) with the tributary length L_c as the discrete measure (5.5)-(5.6):

    G^c = sum_pairs L_c (t_N n + t_T e) . (w_i - w_j),

so the residual R = f_int - f_ext + f_contact receives +F on node i (surface 1) and -F on node j
(surface 2), F = L_c (t_N n + t_T e) (5.11)-(5.12); the traction on body 1 is -t_N n - t_T e
(2.13). With ``ContactLaw.moment_free`` the pair force is L_c (t_N dg/dx + t_T ds/dx), which adds
a couple on the normal's chord nodes, and the rates are dg/dx . v, ds/dx . v (docs/theory.md,
"Moment-free pair forces"). The tangent is the exact derivative dF/dx_eval: unlike (5.23)-(5.24)
it keeps the derivatives of n, e and L_c with respect to the chain neighbours (so Newton
converges quadratically) and the dependence of the slip traction on t_N. It is unsymmetric in
general.

One compiled loop over the pairs (:func:`evaluate_pairs`) computes the kinematics, the
tractions, the force and the tangent; slot convention in ``kinematics.py``. A NumPy form of the
same formulas is the tests' oracle (tests/contact_reference.py).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from functools import cache, partial

import numpy as np
import scipy.sparse as sp
from numpy.typing import NDArray

from ..jit import njit
from .kinematics import raise_undefined_normal
from .laws import ContactLaw
from .state import PairState
from .surfaces import Interface
from .transfer import Transfer, unpaired_share

__all__ = ["ContactResult", "evaluate_contact"]

#: A gap within this fraction of its nodes' largest coordinate is zero to round-off (a touch):
#: detection decides it one way (``engine.interfaces.touch_tolerance``), and under the gap law
#: the kernel gives such a pair the pressed branch's stiffness (``_normal_traction``). A few
#: thousand ulps: at 1e-10 a tester's rods placed 1e5 from the origin and 1e-6 apart were a
#: touch, held apart under 2e7 Pa for the whole impact
TOUCH_ROUNDOFF = 1e-12

#: Integer codes of the normal laws compiled into the kernel (ContactLaw.method).
METHOD_CODES: dict[str, int] = {"penalty": 0, "augmented_lagrangian": 1, "lagrange": 2}
#: Kernel return codes; the caller raises the matching error.
OK, NOT_ON_SURFACE, ZERO_CHORD = 0, 1, 2
#: Entries of a pair's force Jacobian: 2 nodes x 6 slots x 2 x 2 (twice that with the
#: moment-free couple on the two chord nodes).
ENTRIES_PER_PAIR = 48
#: Rows of the per-pair scalar output (OFFSET: s = (x_i - x_j).e, 0 unless moment-free; CHORD:
#: the normal's chord length l; FRICTION_SLOPE: d t_T / d t_N; RATE_OFFSET: g_n/dt added to the
#: rate of a gap-restoring pair).
(GAP, GAP_RATE, SLIP_MEASURE, T_N, T_T, TRIAL_T, LENGTH, OFFSET, CHORD, FRICTION_SLOPE,
 RATE_OFFSET) = range(11)
N_SCALARS = 11
_STICK, _SLIP = 0, 1


@njit(cache=True, inline="always")
def _chain_index(table, node):
    """Position of a global node in a surface chain (``ContactSurface.kernel_table``), or -1."""
    keys = table[0]
    pos = np.searchsorted(keys, node)
    if pos >= keys.size:
        pos = keys.size - 1
    if keys[pos] != node:
        return -1
    return table[1, pos]


@njit(cache=True, inline="always")
def _fill_slots(table1, table2, i, j, slots):
    """Global node of every slot (kinematics._slots: corners and nodes facing an ALE surface
    take the partner's normal); False if i or j is not on its surface."""
    k1, k2 = _chain_index(table1, i), _chain_index(table2, j)
    if k1 < 0 or k2 < 0:
        return False
    slots[0], slots[1] = i, j
    if table1[4, k1]:  # a corner (report 6.6) or a node facing an ALE surface: the partner's
        # normal negated
        slots[2], slots[3] = table2[3, k2], table2[2, k2]
    else:
        slots[2], slots[3] = table1[2, k1], table1[3, k1]
    slots[4], slots[5] = table1[2, k1], table1[3, k1]
    return True


@njit(cache=True, inline="always")
def _normal_frame(x, slots, dn, de):
    """(chord length l, e0, e1) with e = (x_b - x_a)/l; fills the slot-2/3 Jacobians of e and
    n = rot(-90) e = (e1, -e0), d e/d x_b = (I - e e^T)/l."""
    c0, c1 = x[slots[3], 0] - x[slots[2], 0], x[slots[3], 1] - x[slots[2], 1]
    chord = np.sqrt(c0 * c0 + c1 * c1)
    if chord == 0.0:
        return chord, 0.0, 0.0
    e0, e1 = c0 / chord, c1 / chord
    for r in range(2):
        er = e0 if r == 0 else e1
        for c in range(2):
            deb = ((1.0 if r == c else 0.0) - er * (e0 if c == 0 else e1)) / chord
            de[2, r, c], de[3, r, c] = -deb, deb
    for k in range(2, 4):
        for c in range(2):
            dn[k, 0, c], dn[k, 1, c] = de[k, 1, c], -de[k, 0, c]
    return chord, e0, e1


@njit(cache=True, inline="always")
def _tributary_length(x, slots, d_length):
    """L_c (5.5), filling its slot gradient; a missing neighbour (open end) adds nothing."""
    i, prev, nxt = slots[0], slots[4], slots[5]
    b0, b1 = x[i, 0] - x[prev, 0], x[i, 1] - x[prev, 1]
    a0, a1 = x[nxt, 0] - x[i, 0], x[nxt, 1] - x[i, 1]
    l_back, l_ahead = np.sqrt(b0 * b0 + b1 * b1), np.sqrt(a0 * a0 + a1 * a1)
    ub0, ub1 = (b0 / l_back, b1 / l_back) if l_back > 0.0 else (0.0, 0.0)
    ua0, ua1 = (a0 / l_ahead, a1 / l_ahead) if l_ahead > 0.0 else (0.0, 0.0)
    d_length[0, 0], d_length[0, 1] = 0.5 * (ub0 - ua0), 0.5 * (ub1 - ua1)
    d_length[4, 0], d_length[4, 1] = -0.5 * ub0, -0.5 * ub1
    d_length[5, 0], d_length[5, 1] = 0.5 * ua0, 0.5 * ua1
    return 0.5 * (l_back + l_ahead)


@njit(cache=True, inline="always")
def _project(w0, w1, scale, a0, a1, d_axis, grad):
    """s = w . axis and its slot gradient ; returns s."""
    for k in range(6):
        for c in range(2):
            grad[k, c] = d_axis[k, 0, c] * w0 + d_axis[k, 1, c] * w1
    grad[0, 0] += scale * a0
    grad[0, 1] += scale * a1
    grad[1, 0] -= scale * a0
    grad[1, 1] -= scale * a1
    return w0 * a0 + w1 * a1


@njit(cache=True, inline="always")
def _sign(a):
    if a > 0.0:
        return 1.0
    if a < 0.0:
        return -1.0
    return a  # 0 and NaN as np.sign


@njit(cache=True, inline="always")
def _normal_traction(method, lambda_n, eps_N, measure, frictional, touch):
    """(t_N, dt_N/d measure): t_N = <lambda_N + eps_N measure> (2.33/2.34, lambda_N = 0 for
    penalty); "lagrange": the multiplier itself, without the bracket, so Newton sees a smooth
    system (its sign is checked after the solve). A pair at the kink (trial = 0, or ``touch``:
    a gap within round-off of zero) takes the pressed branch's derivative, else a body held
    only by contact has a singular tangent at first touch (a tester's static block placed on
    another: lifted by 1e-12, or the problem rotated by 0.001 degree, it failed as singular).
    Held pairs: a frictionless augmented-Lagrangian pair with lambda_N > 0 stays on the
    pressed branch within one augmentation's solve, unbracketed (docs/theory.md, 5.4): one that
    starts a solve separating would otherwise give Newton neither force nor stiffness and be
    driven deep into penetration; the augmentation test accepts only non-tensile tractions."""
    if method == 2:
        return lambda_n, 0.0
    trial = (0.0 if method == 0 else lambda_n) + eps_N * measure
    if method == 1 and not frictional and lambda_n > 0.0:  # held pair
        return trial, eps_N
    if trial >= 0.0:
        return trial, eps_N
    return (0.0, eps_N) if touch else (0.0, 0.0)


@njit(cache=True, inline="always")
def _return_mapping(t_prev, dlam, slip, t_n, mu, eps_T):
    """(t_T, trial, status, d t_T/d slip, d t_T/d t_N): the return mapping (2.39)-(2.43) with the
    reversal rule of 3.3.2 (friction.py). An unloaded pair (t_N = 0) carries no friction and
    slides, except at trial = 0 (first touch), where the stick branch's stiffness keeps a body
    held only by friction from being singular in its first Newton iteration."""
    trial = t_prev + dlam + eps_T * slip
    limit = mu * t_n
    beyond = (abs(trial) > limit) or (limit <= 0.0 and trial != 0.0)
    if not beyond:
        return trial, trial, _STICK, eps_T, 0.0
    sign = _sign(trial)
    # beyond the cone against the motion: the sliding direction reversed, it sticks (3.3.2)
    status = _STICK if slip * trial < 0.0 else _SLIP
    return limit * sign, trial, status, 0.0, mu * sign


@njit(cache=True, inline="always")
def _force_jacobian(t_n, t_t, e0, e1, length, d_tn, d_tt, dn, de, d_length, jac):
    """F = L_c (t_N n + t_T e), returned, and dF/dx_slot into jac ."""
    n0, n1 = e1, -e0
    dir0, dir1 = t_n * n0 + t_t * e0, t_n * n1 + t_t * e1
    for k in range(6):
        for r in range(2):
            nr, er, dirr = (n0, e0, dir0) if r == 0 else (n1, e1, dir1)
            for c in range(2):
                d_dir = (nr * d_tn[k, c] + t_n * dn[k, r, c] + er * d_tt[k, c]
                         + t_t * de[k, r, c])
                jac[k, r, c] = dirr * d_length[k, c] + length * d_dir
    return length * dir0, length * dir1


@njit(cache=True, inline="always")
def _scatter(q, i, j, slots, f0, f1, jac, force, rows, cols, vals):
    """+F on node i, -F on node j, and 48 COO entries from position q in the order
    [node (i/j), slot, r, c]; returns the next position."""
    force[2 * i] += f0
    force[2 * i + 1] += f1
    force[2 * j] -= f0
    force[2 * j + 1] -= f1
    for node in range(2):
        row, sgn = (2 * i, 1.0) if node == 0 else (2 * j, -1.0)
        for k in range(6):
            for r in range(2):
                for c in range(2):
                    rows[q], cols[q], vals[q] = row + r, 2 * slots[k] + c, sgn * jac[k, r, c]
                    q += 1
    return q


@njit(cache=True, inline="always")
def _chord_derivative(k, c, e0, e1):
    """d l / d x_slot of the normal chord l = |x_b - x_a| (slots a = 2, b = 3)."""
    if k == 3:
        return e0 if c == 0 else e1
    if k == 2:
        return -e0 if c == 0 else -e1
    return 0.0


@njit(cache=True, inline="always")
def _add_chord_rate(sign, value, d_value, chord, e0, e1, dv0, dv1, dn, rate_factor, grad):
    """Adds sign (value/l) n.(v_a - v_b) to a rate, returned, and its slot gradient to grad
    : the normal chord's rotation in an objective rate."""
    n0, n1 = e1, -e0
    nd = n0 * dv0 + n1 * dv1
    q = value / chord
    for k in range(6):
        for c in range(2):
            d_q = (d_value[k, c] - q * _chord_derivative(k, c, e0, e1)) / chord
            g = nd * d_q + q * (dn[k, 0, c] * dv0 + dn[k, 1, c] * dv1)
            if k == 2:
                g += rate_factor * q * (n0 if c == 0 else n1)
            elif k == 3:
                g -= rate_factor * q * (n0 if c == 0 else n1)
            grad[k, c] += sign * g
    return sign * q * nd


@njit(cache=True, inline="always")
def _moment_free_couple(t_n, t_t, gap, offset, e0, e1, chord, length, d_tn, d_tt, d_gap,
                        dn, d_length, d_offset, jac):
    """Couple C = L_c (t_T g - t_N s)/l n on the chord nodes (+C on b, -C on a), returned, and
    dC/dx_slot into jac: the chord part of
    L_c (t_N dg/dx + t_T ds/dx), with s = (x_i - x_j).e the tangential offset and l the chord."""
    n0, n1 = e1, -e0
    moment = t_t * gap - t_n * offset
    coef = length * moment / chord
    for k in range(6):
        for c in range(2):
            d_moment = (gap * d_tt[k, c] + t_t * d_gap[k, c] - offset * d_tn[k, c]
                        - t_n * d_offset[k, c])
            d_chord = _chord_derivative(k, c, e0, e1)
            d_coef = (moment * d_length[k, c] + length * d_moment - coef * d_chord) / chord
            jac[k, 0, c] = n0 * d_coef + coef * dn[k, 0, c]
            jac[k, 1, c] = n1 * d_coef + coef * dn[k, 1, c]
    return coef * n0, coef * n1


@njit(cache=True, inline="always")
def _restoring_rate(x_start, slots, i, j, rate_factor):
    """g_n/dt, g_n = (x_i - x_j).n at the step start (a constant of the step): with it the
    persistency law asks gdot = -g_n/dt, i.e. g_{n+1} = g_n + dt gdot = 0, so that a pair
    detected after it penetrated (or, detected at the predicted positions, before it touched)
    ends its first step touching instead of keeping the detection's gap for the whole impact."""
    c0 = x_start[slots[3], 0] - x_start[slots[2], 0]
    c1 = x_start[slots[3], 1] - x_start[slots[2], 1]
    chord = np.sqrt(c0 * c0 + c1 * c1)
    if chord == 0.0:
        return 0.0
    w0, w1 = x_start[i, 0] - x_start[j, 0], x_start[i, 1] - x_start[j, 1]
    return (w0 * c1 - w1 * c0) / chord * (0.5 * rate_factor)


@njit(cache=True, inline="always")
def _input_gradients(rate_law, moment_free, gap, offset, chord, n0, n1, e0, e1, d_meas, d_slip):
    """Slot gradients of the normal measure and of the slip with respect to the kernel's
    moving input alone (v under the rate law, w = x_i - x_j in the gap law's increment
    w - w_start): the parts that the rate factor (or 1) scales in the full gradients."""
    for k in range(6):
        for c in range(2):
            d_meas[k, c], d_slip[k, c] = 0.0, 0.0
    d_slip[0, 0], d_slip[0, 1], d_slip[1, 0], d_slip[1, 1] = e0, e1, -e0, -e1
    if not rate_law:
        return
    d_meas[0, 0], d_meas[0, 1], d_meas[1, 0], d_meas[1, 1] = n0, n1, -n0, -n1
    if moment_free:  # the chord's rotation n.(v_a - v_b) (_add_chord_rate), a = 2, b = 3
        q_rate, q_slip = offset / chord, -gap / chord
        d_meas[2, 0], d_meas[2, 1] = q_rate * n0, q_rate * n1
        d_meas[3, 0], d_meas[3, 1] = -q_rate * n0, -q_rate * n1
        d_slip[2, 0], d_slip[2, 1] = q_slip * n0, q_slip * n1
        d_slip[3, 0], d_slip[3, 1] = -q_slip * n0, -q_slip * n1


@njit(cache=True, inline="always")
def _input_jacobian(q, t_n_coef, t_t_coef, dn_coef, gap, offset, e0, e1, length, chord,
                    moment_free, d_meas, d_slip, vals_in):
    """The pair's force Jacobian with respect to the moving input (:func:`_input_gradients`),
    written to vals_in from position q in :func:`_scatter`'s order (and the couple's)."""
    n0, n1 = e1, -e0
    for part in range(2 if moment_free else 1):  # the pair force, then the couple
        for node in range(2):  # +F on i, -F on j; +C on chord node b (slot 3), -C on a
            sgn = 1.0 if node == 0 else -1.0
            for k in range(6):
                for r in range(2):
                    nr, er = (n0, e0) if r == 0 else (n1, e1)
                    for c in range(2):
                        d_tn = t_n_coef * d_meas[k, c]
                        d_tt = t_t_coef * d_slip[k, c] + dn_coef * d_tn
                        if part == 0:
                            vals_in[q] = sgn * length * (nr * d_tn + er * d_tt)
                        else:
                            vals_in[q] = sgn * nr * length * (gap * d_tt - offset * d_tn) / chord
                        q += 1


@njit(cache=True)
def evaluate_pairs(x, v, x_start, table1, table2, pairs, lambda_N, dlambda_T, t_prev, restoring,
                   params, flags):
    """Force, COO tangent and per-pair results of the active pairs.

    restoring: per pair, non-zero where the persistency law gets the gap-restoring rate
    g_n/dt (:func:`_restoring_rate`), g_n the gap at ``x_start``.

    params: (eps_N, eps_T, mu, rate_factor, dissipation time factor).
    flags: (method code, rate law, v given, x_start given, frictional, moment free, partial
    tangents wanted).
    Returns (error code, force (ndof,), rows, cols, vals (48 P, or 96 P moment free),
    scalars (N_SCALARS, P) indexed by GAP...FRICTION_SLOPE, normal (P, 2), tangent (P, 2),
    status (P,), dissipation, the slots' global nodes (P, 6), the slot gradients of the
    normal measure (g or gdot) and of L_c, (P, 2, 6, 2), which the Lagrange blocks use, and,
    with the last flag, the partial tangents that the unpaired share's chain rule needs
    (Transfer.weight_terms): vals_in, K's part through the moving input alone (K_v with
    K = K_x + rate_factor K_v under the rate law; the part through w in the gap law's slip
    increment w - w_start), on rows and cols, and the normal measure's slot gradient through
    it (P, 6, 2); empty without the flag).
    """
    eps_N, eps_T, mu, rate_factor, step = params[0], params[1], params[2], params[3], params[4]
    method, rate_law, has_v, has_start, frictional = (flags[0], flags[1], flags[2], flags[3],
                                                      flags[4])
    moment_free, partials = flags[5], flags[6]
    npairs = pairs.shape[0]
    force = np.zeros(2 * x.shape[0])
    entries = ENTRIES_PER_PAIR * (2 if moment_free else 1) * npairs
    rows = np.empty(entries, np.int64)
    cols = np.empty(entries, np.int64)
    vals = np.empty(entries)
    scalars = np.empty((N_SCALARS, npairs))
    all_slots = np.empty((npairs, 6), np.int64)
    grads = np.empty((npairs, 2, 6, 2))
    normal, tangent = np.empty((npairs, 2)), np.empty((npairs, 2))
    status = np.empty(npairs, np.int8)
    slots = np.empty(6, np.int64)
    dn, de = np.zeros((6, 2, 2)), np.zeros((6, 2, 2))  # only slots 2, 3 ever non-zero
    d_length = np.zeros((6, 2))
    d_gap, d_rate, d_slip = np.empty((6, 2)), np.empty((6, 2)), np.empty((6, 2))
    d_tn, d_tt, jac = np.empty((6, 2)), np.empty((6, 2)), np.empty((6, 2, 2))
    d_offset = np.empty((6, 2))
    vals_in = np.zeros(entries if partials else 0)
    grads_in = np.zeros((npairs if partials else 0, 6, 2))
    d_slip_in = np.empty((6, 2))
    dissipation = 0.0
    q = 0
    for p in range(npairs):
        i, j = pairs[p, 0], pairs[p, 1]
        if not _fill_slots(table1, table2, i, j, slots):
            return (NOT_ON_SURFACE, force, rows, cols, vals, scalars, normal, tangent, status, 0.0,
                    all_slots, grads, vals_in, grads_in)
        chord, e0, e1 = _normal_frame(x, slots, dn, de)
        if chord == 0.0:
            return (ZERO_CHORD, force, rows, cols, vals, scalars, normal, tangent, status, 0.0,
                    all_slots, grads, vals_in, grads_in)
        n0, n1 = e1, -e0
        length = _tributary_length(x, slots, d_length)
        # gap (2.4), gap rate (2.9), tangential measure (2.10 or the increment since x_start)
        w0, w1 = x[i, 0] - x[j, 0], x[i, 1] - x[j, 1]
        gap = _project(w0, w1, 1.0, n0, n1, dn, d_gap)
        gap_rate, vw0, vw1 = np.nan, 0.0, 0.0
        if has_v:
            vw0, vw1 = v[i, 0] - v[j, 0], v[i, 1] - v[j, 1]
            gap_rate = _project(vw0, vw1, rate_factor, n0, n1, dn, d_rate)
        if rate_law:
            slip = _project(vw0, vw1, rate_factor, e0, e1, de, d_slip)
        elif has_start:
            s0, s1 = w0 - (x_start[i, 0] - x_start[j, 0]), w1 - (x_start[i, 1] - x_start[j, 1])
            slip = _project(s0, s1, 1.0, e0, e1, de, d_slip)
        else:
            slip = _project(0.0, 0.0, 0.0, e0, e1, de, d_slip)
        offset = 0.0
        if moment_free:  # objective rates (docs/theory.md)
            offset = _project(w0, w1, 1.0, e0, e1, de, d_offset)
            if has_v:
                dv0 = v[slots[2], 0] - v[slots[3], 0]
                dv1 = v[slots[2], 1] - v[slots[3], 1]
                gap_rate += _add_chord_rate(1.0, offset, d_offset, chord, e0, e1, dv0, dv1, dn,
                                            rate_factor, d_rate)
                if rate_law:
                    slip += _add_chord_rate(-1.0, gap, d_gap, chord, e0, e1, dv0, dv1, dn,
                                            rate_factor, d_slip)
        measure, d_measure = (gap_rate, d_rate) if rate_law else (gap, d_gap)
        rate_offset = 0.0
        if rate_law and has_start and restoring[p] != 0.0:
            rate_offset = _restoring_rate(x_start, slots, i, j, rate_factor)
            measure += rate_offset
        touch = not rate_law and abs(gap) <= TOUCH_ROUNDOFF * max(
            abs(x[i, 0]), abs(x[i, 1]), abs(x[j, 0]), abs(x[j, 1]))
        t_n, dt_dm = _normal_traction(method, lambda_N[p], eps_N, measure, frictional, touch)
        t_t, trial, stat, ds_coef, dn_coef = 0.0, 0.0, _SLIP, 0.0, 0.0
        if frictional:
            dlam = dlambda_T[p] if method != 0 else 0.0
            t_t, trial, stat, ds_coef, dn_coef = _return_mapping(t_prev[p], dlam, slip, t_n, mu,
                                                                 eps_T)
        for k in range(6):
            for c in range(2):
                d_tn[k, c] = dt_dm * d_measure[k, c]
                d_tt[k, c] = ds_coef * d_slip[k, c] + dn_coef * d_tn[k, c]
        f0, f1 = _force_jacobian(t_n, t_t, e0, e1, length, d_tn, d_tt, dn, de, d_length, jac)
        if partials:
            _input_gradients(rate_law, moment_free, gap, offset, chord, n0, n1, e0, e1,
                             grads_in[p], d_slip_in)
            _input_jacobian(q, dt_dm, ds_coef, dn_coef, gap, offset, e0, e1, length, chord,
                            moment_free, grads_in[p], d_slip_in, vals_in)
        q = _scatter(q, i, j, slots, f0, f1, jac, force, rows, cols, vals)
        if moment_free:
            c0, c1 = _moment_free_couple(t_n, t_t, gap, offset, e0, e1, chord, length, d_tn,
                                         d_tt, d_gap, dn, d_length, d_offset, jac)
            q = _scatter(q, slots[3], slots[2], slots, c0, c1, jac, force, rows, cols, vals)
        scalars[GAP, p], scalars[GAP_RATE, p], scalars[SLIP_MEASURE, p] = gap, gap_rate, slip
        scalars[T_N, p], scalars[T_T, p], scalars[TRIAL_T, p] = t_n, t_t, trial
        scalars[LENGTH, p], scalars[OFFSET, p], scalars[CHORD, p] = length, offset, chord
        scalars[FRICTION_SLOPE, p], scalars[RATE_OFFSET, p] = dn_coef, rate_offset
        all_slots[p] = slots
        grads[p, 0], grads[p, 1] = d_measure, d_length
        normal[p, 0], normal[p, 1], tangent[p, 0], tangent[p, 1] = n0, n1, e0, e1
        status[p] = stat
        if stat == _SLIP:
            dissipation += t_t * (slip * step) * length
    return (OK, force, rows, cols, vals, scalars, normal, tangent, status, dissipation, all_slots,
            grads, vals_in, grads_in)


@dataclass(frozen=True)
class ContactResult:
    """Contact contribution to the residual and its tangent, plus per-pair diagnostics.

    force: (ndof,) vector to ADD to R = f_int - f_ext + f_contact.
    rows, cols, vals: COO triplets of d force / d x_eval in global dofs (duplicates add up);
    None for a result evaluated with ``deferred_tangent`` whose transfer maps them back on
    first use (:meth:`triplets`).
    Per pair (aligned with ``pairs``): gap g (2.4), gap_rate gdot (2.9; NaN without
    velocities), slip_measure (gdot_T, or delta g_T under the gap law), t_N, t_T (tractions),
    trial_T, normal_force = t_N L_c, tangential_force = t_T L_c, status (friction.STICK/SLIP),
    length L_c, normal n, tangent e. dissipation: frictional work of the step (3.18).
    """

    force: NDArray[np.float64]
    rows: NDArray[np.int64]
    cols: NDArray[np.int64]
    vals: NDArray[np.float64]
    pairs: NDArray[np.int64]
    gap: NDArray[np.float64]
    gap_rate: NDArray[np.float64]
    slip_measure: NDArray[np.float64]
    t_N: NDArray[np.float64]
    t_T: NDArray[np.float64]
    trial_T: NDArray[np.float64]
    status: NDArray[np.int8]
    length: NDArray[np.float64]
    normal: NDArray[np.float64]
    tangent: NDArray[np.float64]
    dissipation: float
    rate_law: bool
    #: for the Lagrange blocks (lagrange.py): per pair the slots' global nodes (P, 6), the slot
    #: gradients of the normal measure and of L_c (P, 2, 6, 2), the tangential offset s, the
    #: normal chord l and d t_T/d t_N; None from the tests' oracle
    slots: NDArray[np.int64] | None = None
    gradients: NDArray[np.float64] | None = None
    offset: NDArray[np.float64] | None = None
    chord: NDArray[np.float64] | None = None
    friction_slope: NDArray[np.float64] | None = None
    #: g_n/dt of the gap-restoring pairs (0 for the others); the rate law constrains
    #: gdot + rate_offset. None from the tests' oracle
    rate_offset: NDArray[np.float64] | None = None
    #: the unpaired nodes' share (transfer.py): slots and gradients are those of the kernel's
    #: positions S x; force and tangent are already mapped back. None: pairs node to node
    transfer: Transfer | None = None
    #: with a transfer: (x, v, rate_factor, the normal measure's slot gradient through v
    #: alone (P, 6, 2) under the rate law, else None), what the Lagrange blocks' G needs for
    #: the weights' own derivative (Transfer.columns)
    share_inputs: tuple | None = None
    #: with ``deferred_tangent`` and a transfer: () -> (rows, cols, vals), computed once
    deferred: Callable[[], tuple[NDArray, NDArray, NDArray]] | None = None

    def triplets(self) -> tuple[NDArray, NDArray, NDArray]:
        """(rows, cols, vals), the deferred ones computed on the first call."""
        return (self.rows, self.cols, self.vals) if self.deferred is None else self.deferred()

    @property
    def normal_force(self) -> NDArray[np.float64]:
        return self.t_N * self.length

    @property
    def tangential_force(self) -> NDArray[np.float64]:
        return self.t_T * self.length

    @property
    def normal_measure(self) -> NDArray[np.float64]:
        """The quantity the normal law constrains: gdot (+ g_n/dt for a gap-restoring pair,
        rate law) or g (gap law)."""
        if not self.rate_law:
            return self.gap
        return self.gap_rate if self.rate_offset is None else self.gap_rate + self.rate_offset

    def tangent_matrix(self) -> sp.csr_matrix:
        """The COO triplets as a square CSR matrix (duplicates summed)."""
        n = self.force.size
        rows, cols, vals = self.triplets()
        return sp.csr_matrix((vals, (rows, cols)), shape=(n, n))


_NO_ARRAY = np.zeros((0, 2))


def evaluate_contact(
    x_eval: NDArray[np.float64],
    v_eval: NDArray[np.float64] | None,
    rate_factor: float | None,
    interface: Interface,
    state: PairState,
    law: ContactLaw,
    *,
    x_start: NDArray[np.float64] | None = None,
    dt: float | None = None,
    deferred_tangent: bool = False,
) -> ContactResult:
    """Contact force, consistent tangent and per-pair results for the active set ``state``.

    x_eval: (n_nodes, 2) positions of ALL bodies where geometry is evaluated (the mid-point
        configuration in dynamics); v_eval: velocities with dv/dx_eval = rate_factor I.
    rate_factor: 2/dt for the mid-point rule -> persistency law t_N = <lambda + eps_N gdot>
        (2.34) and rate friction; None -> gap law t_N = <lambda + eps_N g> (2.33) and the
        tangential increment since ``x_start`` (required for friction under the gap law).
    dt: only scales the reported dissipation under the rate law (default 2/rate_factor).
    Multipliers (lambda_N, dlambda_T) and the friction history come from ``state`` and are
    held fixed: this is what Newton calls at every iteration.
    deferred_tangent: an unpaired share's tangent (S^T K S and the weights' terms, 5x the
    kernel's time) is mapped back only when :meth:`ContactResult.triplets` asks for it: in
    the ring example 261 of 2297 evaluations (the others are residuals: line search,
    modified Newton, augmentation checks).
    """
    if law.frictional and rate_factor is None and x_start is None:
        raise ValueError("friction under the gap law needs x_start (tangential increment)")
    if rate_factor is not None and v_eval is None:
        raise ValueError("the rate law needs velocities v")
    rate_law = rate_factor is not None
    step = 1.0 if rate_factor is None else (dt if dt is not None else 2.0 / rate_factor)
    params = np.array([law.eps_N, law.eps_T, law.mu, rate_factor or 0.0, step])
    pairs = state.pairs
    transfer = unpaired_share(x_eval, interface, pairs) if law.unpaired_share else None
    # the weights' chain rule needs K's part through the moving input: v under the rate law,
    # the slip increment's w - w_start under a frictional gap law
    moving_input = transfer is not None and transfer.segments is not None and (
        rate_law or (x_start is not None and law.frictional))
    flags = np.array([METHOD_CODES[law.method], rate_law, v_eval is not None,
                      x_start is not None, law.frictional, law.moment_free, moving_input],
                     dtype=np.int64)
    table1 = interface.surface1.kernel_table
    # the nodes' own positions: the weights' derivative, and an undefined normal names them
    x_nodes, v_nodes, start_nodes = x_eval, v_eval, x_start
    if transfer is not None:  # the kernel sees each shared pair's weighted point
        x_eval, v_eval, x_start = (transfer.positions(a) for a in (x_eval, v_eval, x_start))
        table1 = transfer.surface1.kernel_table
    # the pairs' first step (no committed gap rate yet) under law.gap_restoring
    restoring = (np.isnan(state.gap_rate) if law.gap_restoring
                 else np.zeros(len(state), bool)).astype(np.float64)

    def c_float(a: NDArray | None) -> NDArray:  # one compiled signature: C-contiguous float64
        return _NO_ARRAY if a is None else np.ascontiguousarray(a, dtype=np.float64)

    (code, force, rows, cols, vals, scalars, normal, tangent, status, dissipation, slots,
     gradients, vals_in, gradients_in) = evaluate_pairs(
            c_float(x_eval), c_float(v_eval), c_float(x_start), table1,
            interface.surface2.kernel_table, np.ascontiguousarray(pairs, dtype=np.int64),
            c_float(state.lambda_N), c_float(state.dlambda_T), c_float(state.t_T), restoring,
            params, flags)
    if code == NOT_ON_SURFACE:
        interface.surface1.index_of(pairs[:, 0])  # raises, naming the nodes
        interface.surface2.index_of(pairs[:, 1])
    if code == ZERO_CHORD:
        raise_undefined_normal(np.asarray(x_nodes), interface, pairs)
    if transfer is not None:
        moving = [(vals, x_nodes)]  # K's factors of dS/dx applied to x (and v, x_start)
        if moving_input and rate_law:
            # v_c = S v moves with the weights too: K = K_x + rate_factor K_v, so
            # K_x (dS x) + K_v (dS v) = K (dS x) + K_v (dS (v - rate_factor x))
            moving = [(vals - rate_factor * vals_in, x_nodes), (vals_in, v_nodes)]
        elif moving_input:
            # the slip increment w - w_start, w_start = S x_start: K_start = -K_w
            moving = [(vals, x_nodes), (-vals_in, start_nodes)]
        mapped = cache(partial(transfer.tangent, rows, cols, vals, moving, force))
        force = transfer.force(force)
        rows, cols, vals = (None, None, None) if deferred_tangent else mapped()
    return ContactResult(
        force=force, rows=rows, cols=cols, vals=vals, pairs=pairs, gap=scalars[GAP],
        gap_rate=scalars[GAP_RATE], slip_measure=scalars[SLIP_MEASURE],
        t_N=scalars[T_N], t_T=scalars[T_T], trial_T=scalars[TRIAL_T], status=status,
        length=scalars[LENGTH], normal=normal, tangent=tangent,
        dissipation=float(dissipation), rate_law=rate_law, slots=slots, gradients=gradients,
        offset=scalars[OFFSET], chord=scalars[CHORD], friction_slope=scalars[FRICTION_SLOPE],
        rate_offset=scalars[RATE_OFFSET], transfer=transfer,
        share_inputs=None if transfer is None else (
            x_nodes, v_nodes, rate_factor, gradients_in if moving_input and rate_law else None),
        deferred=mapped if transfer is not None and deferred_tangent else None,
    )
