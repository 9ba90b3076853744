"""Numba kernel of :func:`ntncontact.contact.evaluate.evaluate_contact`: one compiled loop over
the pairs computes the kinematics, the tractions, the force and the consistent tangent.

Same formulas, evaluated in the same order, as the NumPy reference (``kinematics.py``,
``laws.py``, ``friction.py``, ``evaluate.py``; slot convention in ``kinematics.py``): with a
handful of pairs the reference spends its time in ~100 small NumPy calls, this kernel in one.
The COO triplets come out in the reference's order, [pair, node (i/j), slot, r, c].
"""

from __future__ import annotations

import numpy as np
from numba import njit

#: Integer codes of the normal laws compiled into the kernel (ContactLaw.method).
METHOD_CODES: dict[str, int] = {"penalty": 0, "augmented_lagrangian": 1, "lagrange": 2}
#: Kernel return codes; the caller re-runs the reference, which raises the matching error.
OK, NOT_ON_SURFACE, ZERO_CHORD = 0, 1, 2
#: Entries of a pair's force Jacobian: 2 nodes x 6 slots x 2 x 2 (twice that with the
#: moment-free couple on the two chord nodes).
ENTRIES_PER_PAIR = 48
#: Rows of the per-pair scalar output.
GAP, GAP_RATE, SLIP_MEASURE, T_N, T_T, TRIAL_T, LENGTH = range(7)
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
    """Global node of every slot (kinematics._slots); False if i or j is not on its surface."""
    k1, k2 = _chain_index(table1, i), _chain_index(table2, j)
    if k1 < 0 or k2 < 0:
        return False
    slots[0], slots[1] = i, j
    if table1[4, k1]:  # corner: the partner's normal negated (report 6.6)
        slots[2], slots[3] = table2[3, k2], table2[2, k2]
    else:
        slots[2], slots[3] = table1[2, k1], table1[3, k1]
    slots[4], slots[5] = table1[2, k1], table1[3, k1]
    return True


@njit(cache=True, inline="always")
def _normal_frame(x, slots, dn, de):
    """(chord length l, e0, e1) with e = (x_b - x_a)/l; fills the slot-2/3 Jacobians of e and
    n = rot(-90) e = (e1, -e0), d e/d x_b = (I - e e^T)/l (kinematics._normal_frame)."""
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
    """s = w . axis and its slot gradient (kinematics.project); returns s."""
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
def _normal_traction(method, lambda_n, eps_N, measure, frictional):
    """(t_N, dt_N/d measure) of laws.normal_traction; "lagrange": the multiplier itself."""
    if method == 2:
        return lambda_n, 0.0
    trial = (0.0 if method == 0 else lambda_n) + eps_N * measure
    if method == 1 and not frictional and lambda_n > 0.0:  # laws.held_pairs
        return trial, eps_N
    return (trial, eps_N) if trial >= 0.0 else (0.0, 0.0)


@njit(cache=True, inline="always")
def _return_mapping(t_prev, dlam, slip, t_n, mu, eps_T):
    """(t_T, trial, status, d t_T/d slip, d t_T/d t_N) of friction.return_mapping, friction on."""
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
    """F = L_c (t_N n + t_T e), returned, and dF/dx_slot into jac (evaluate._force_jacobian)."""
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
    """+F on node i, -F on node j, and 48 COO entries from position q in the reference's
    order; returns the next position."""
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
    (kinematics._chord_rate): the normal chord's rotation in an objective rate."""
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
    dC/dx_slot into jac (evaluate._moment_free_couple): the chord part of
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


@njit(cache=True)
def evaluate_pairs(x, v, x_start, table1, table2, pairs, lambda_N, dlambda_T, t_prev, params,
                   flags):
    """Force, COO tangent and per-pair results of the active pairs.

    params: (eps_N, eps_T, mu, rate_factor, dissipation time factor).
    flags: (method code, rate law, v given, x_start given, frictional, moment free).
    Returns (error code, force (ndof,), rows, cols, vals (48 P, or 96 P moment free),
    scalars (7, P) indexed by
    GAP...LENGTH, normal (P, 2), tangent (P, 2), status (P,), dissipation).
    """
    eps_N, eps_T, mu, rate_factor, step = params[0], params[1], params[2], params[3], params[4]
    method, rate_law, has_v, has_start, frictional = (flags[0], flags[1], flags[2], flags[3],
                                                      flags[4])
    moment_free = flags[5]
    npairs = pairs.shape[0]
    force = np.zeros(2 * x.shape[0])
    entries = ENTRIES_PER_PAIR * (2 if moment_free else 1) * npairs
    rows = np.empty(entries, np.int64)
    cols = np.empty(entries, np.int64)
    vals = np.empty(entries)
    scalars = np.empty((7, npairs))
    normal, tangent = np.empty((npairs, 2)), np.empty((npairs, 2))
    status = np.empty(npairs, np.int8)
    slots = np.empty(6, np.int64)
    dn, de = np.zeros((6, 2, 2)), np.zeros((6, 2, 2))  # only slots 2, 3 ever non-zero
    d_length = np.zeros((6, 2))
    d_gap, d_rate, d_slip = np.empty((6, 2)), np.empty((6, 2)), np.empty((6, 2))
    d_tn, d_tt, jac = np.empty((6, 2)), np.empty((6, 2)), np.empty((6, 2, 2))
    d_offset = np.empty((6, 2))
    dissipation = 0.0
    q = 0
    for p in range(npairs):
        i, j = pairs[p, 0], pairs[p, 1]
        if not _fill_slots(table1, table2, i, j, slots):
            return NOT_ON_SURFACE, force, rows, cols, vals, scalars, normal, tangent, status, 0.0
        chord, e0, e1 = _normal_frame(x, slots, dn, de)
        if chord == 0.0:
            return ZERO_CHORD, force, rows, cols, vals, scalars, normal, tangent, status, 0.0
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
        if moment_free:  # objective rates (kinematics.pair_kinematics)
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
        t_n, dt_dm = _normal_traction(method, lambda_N[p], eps_N, measure, frictional)
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
        q = _scatter(q, i, j, slots, f0, f1, jac, force, rows, cols, vals)
        if moment_free:
            c0, c1 = _moment_free_couple(t_n, t_t, gap, offset, e0, e1, chord, length, d_tn,
                                         d_tt, d_gap, dn, d_length, d_offset, jac)
            q = _scatter(q, slots[3], slots[2], slots, c0, c1, jac, force, rows, cols, vals)
        scalars[GAP, p], scalars[GAP_RATE, p], scalars[SLIP_MEASURE, p] = gap, gap_rate, slip
        scalars[T_N, p], scalars[T_T, p], scalars[TRIAL_T, p] = t_n, t_t, trial
        scalars[LENGTH, p] = length
        normal[p, 0], normal[p, 1], tangent[p, 0], tangent[p, 1] = n0, n1, e0, e1
        status[p] = stat
        if stat == _SLIP:
            dissipation += t_t * (slip * step) * length
    return OK, force, rows, cols, vals, scalars, normal, tangent, status, dissipation
