"""Per-pair contact kinematics and their exact derivatives (report 2.1.1, 5.1.2).

Every quantity of a pair (node1 ``i`` on surface 1, node2 ``j`` on surface 2) depends on the
positions of at most six nodes, its SLOTS:

    slot 0: i,   slot 1: j,
    slots 2, 3: the nodes (a, b) defining the normal, n = rot(-90)(x_b - x_a)/|x_b - x_a|
                (a, b) = (prev(i), next(i)) on surface 1, or (next(j), prev(j)) on surface 2
                when i is a corner, i.e. n = -n2(j) (report 6.6),
    slots 4, 5: the chain neighbours of i entering L_c = (L_{i-1,i} + L_{i,i+1})/2 (5.5).

Gradients are stored per slot: a scalar's gradient is (P, 6, 2), a vector's Jacobian
(P, 6, 2, 2) with [p, k, r, c] = d(value_r)/d(x_{slot k, c}). Repeated slots (e.g. a = i at a
chain end) simply add up when assembled.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from .surfaces import Interface

__all__ = ["PairKinematics", "N_SLOTS", "pair_gaps", "pair_kinematics", "project"]

N_SLOTS = 6
_ROT_M90 = np.array([[0.0, 1.0], [-1.0, 0.0]])  # n = R u rotates the chord by -90 degrees


@dataclass(frozen=True)
class PairKinematics:
    """Geometry of P node pairs and derivatives with respect to the slot positions.

    ``normal_measure`` is the gap g (gap law) or gap rate gdot (rate law) that enters
    t_N; ``slip_measure`` the tangential relative displacement increment since the step start
    (gap law) or the tangential relative velocity gdot_T (rate law), both along e.
    """

    slots: NDArray[np.int64]  # (P, 6) global nodes
    normal: NDArray[np.float64]  # n, (P, 2)
    tangent: NDArray[np.float64]  # e = m x n = (-n_y, n_x), (P, 2)
    d_normal: NDArray[np.float64]  # (P, 6, 2, 2)
    d_tangent: NDArray[np.float64]  # (P, 6, 2, 2)
    length: NDArray[np.float64]  # L_c, (P,)
    d_length: NDArray[np.float64]  # (P, 6, 2)
    gap: NDArray[np.float64]  # g = (x_i - x_j) . n  (2.4), (P,)
    d_gap: NDArray[np.float64]
    gap_rate: NDArray[np.float64] | None  # gdot = (v_i - v_j) . n  (2.9)
    d_gap_rate: NDArray[np.float64] | None
    slip_measure: NDArray[np.float64]
    d_slip_measure: NDArray[np.float64]
    rate_law: bool
    #: objective kinematics only (``objective=True``): the tangential offset s = (x_i - x_j).e,
    #: the normal chord's length l and their slot gradients
    offset: NDArray[np.float64] | None = None
    d_offset: NDArray[np.float64] | None = None
    chord: NDArray[np.float64] | None = None
    d_chord: NDArray[np.float64] | None = None

    @property
    def normal_measure(self) -> NDArray[np.float64]:
        return self.gap_rate if self.rate_law else self.gap  # type: ignore[return-value]

    @property
    def d_normal_measure(self) -> NDArray[np.float64]:
        return self.d_gap_rate if self.rate_law else self.d_gap  # type: ignore[return-value]


def _slots(interface: Interface, pairs: NDArray[np.int64]) -> NDArray[np.int64]:
    """Global node of every slot (module docstring), corners swapped to the partner normal."""
    s1, s2 = interface.surface1, interface.surface2
    i, j = pairs[:, 0], pairs[:, 1]
    k1 = s1.index_of(i)
    k2 = s2.index_of(j)
    corner = s1.corner[k1]
    a = np.where(corner, s2.next[k2], s1.prev[k1])
    b = np.where(corner, s2.prev[k2], s1.next[k1])
    return np.column_stack((i, j, a, b, s1.prev[k1], s1.next[k1]))


def _unit_chord(x: NDArray, slots: NDArray) -> tuple[NDArray, NDArray]:
    """e = (x_b - x_a)/l and l of every pair's normal chord (slots 2, 3)."""
    chord = x[slots[:, 3]] - x[slots[:, 2]]
    length = np.linalg.norm(chord, axis=1)
    if np.any(length == 0.0):
        raise ValueError("a contact normal is undefined (coincident chain neighbours)")
    return chord / length[:, None], length


def _normal_frame(x: NDArray, slots: NDArray) -> tuple[NDArray, NDArray, NDArray, NDArray]:
    """n, e and their slot Jacobians from n = R (x_b - x_a)/l, e = (x_b - x_a)/l."""
    e, length = _unit_chord(x, slots)
    n = e @ _ROT_M90.T
    # d e / d x_b = (I - e e^T)/l; x_a enters with the opposite sign
    de_b = (np.eye(2) - np.einsum("pr,pc->prc", e, e)) / length[:, None, None]
    d_tangent = np.zeros((len(slots), N_SLOTS, 2, 2))
    d_tangent[:, 2], d_tangent[:, 3] = -de_b, de_b
    d_normal = np.einsum("rs,pksc->pkrc", _ROT_M90, d_tangent)
    return n, e, d_normal, d_tangent


def _tributary_length(x: NDArray, slots: NDArray) -> tuple[NDArray, NDArray]:
    """L_c (5.5) and its slot gradient; a missing neighbour (open end) contributes nothing."""
    xi = x[slots[:, 0]]
    back = xi - x[slots[:, 4]]
    ahead = x[slots[:, 5]] - xi
    l_back = np.linalg.norm(back, axis=1)
    l_ahead = np.linalg.norm(ahead, axis=1)
    u_back = np.divide(back, l_back[:, None], out=np.zeros_like(back), where=l_back[:, None] > 0)
    u_ahead = np.divide(ahead, l_ahead[:, None], out=np.zeros_like(ahead),
                        where=l_ahead[:, None] > 0)
    grad = np.zeros((len(slots), N_SLOTS, 2))
    grad[:, 0] = 0.5 * (u_back - u_ahead)
    grad[:, 4] = -0.5 * u_back
    grad[:, 5] = 0.5 * u_ahead
    return 0.5 * (l_back + l_ahead), grad


def project(
    w: NDArray, scale: float, axis: NDArray, d_axis: NDArray
) -> tuple[NDArray, NDArray]:
    """s = w . axis with w = w(x_i) - w(x_j), dw/dx_i = scale I: value and slot gradient."""
    value = np.einsum("pr,pr->p", w, axis)
    grad = np.einsum("pkrc,pr->pkc", d_axis, w)
    grad[:, 0] += scale * axis
    grad[:, 1] -= scale * axis
    return value, grad


def _chord_rate(value: NDArray, d_value: NDArray, chord: NDArray, d_chord: NDArray,
                n: NDArray, dn: NDArray, v: NDArray, slots: NDArray,
                rate_factor: float) -> tuple[NDArray, NDArray]:
    """(value/l) n.(v_a - v_b) and its slot gradient (dv/dx = rate_factor I): the part of an
    objective rate that comes from the rotation of the normal chord (slots a = 2, b = 3)."""
    dv = v[slots[:, 2]] - v[slots[:, 3]]
    nd = np.einsum("pr,pr->p", n, dv)
    q = value / chord
    d_q = (d_value - q[:, None, None] * d_chord) / chord[:, None, None]
    grad = nd[:, None, None] * d_q + q[:, None, None] * np.einsum("pkrc,pr->pkc", dn, dv)
    grad[:, 2] += (rate_factor * q)[:, None] * n
    grad[:, 3] -= (rate_factor * q)[:, None] * n
    return q * nd, grad


def pair_kinematics(
    x: NDArray[np.float64],
    interface: Interface,
    pairs: NDArray[np.int64],
    v: NDArray[np.float64] | None = None,
    rate_factor: float | None = None,
    x_start: NDArray[np.float64] | None = None,
    objective: bool = False,
) -> PairKinematics:
    """Kinematics of ``pairs`` (P, 2) at positions ``x`` (n_nodes, 2).

    Rate law (``rate_factor`` given, dv/dx = rate_factor I): gap rate (2.9) and tangential
    relative velocity (2.10). Gap law (``rate_factor`` None): gap (2.4) and the tangential
    relative displacement since ``x_start`` (zero if ``x_start`` is None). The gap rate is
    still reported under the gap law when ``v`` is given (used by detection).

    ``objective``: the rates are the time derivatives of the invariant measures g = w.n and
    s = w.e (w = x_i - x_j), gdot = dg/dx . v = (v_i - v_j).n + (s/l) n.(v_a - v_b) and
    (rate law) gdot_T = ds/dx . v = (v_i - v_j).e - (g/l) n.(v_a - v_b), l the normal chord;
    they vanish under any rigid motion (docs/theory.md, "Moment-free pair forces").
    """
    pairs = np.asarray(pairs, dtype=np.int64).reshape(-1, 2)
    slots = _slots(interface, pairs)
    n, e, dn, de = _normal_frame(x, slots)
    length, d_length = _tributary_length(x, slots)
    i, j = pairs[:, 0], pairs[:, 1]
    gap, d_gap = project(x[i] - x[j], 1.0, n, dn)
    rate_law = rate_factor is not None
    gap_rate = d_gap_rate = None
    if v is not None:
        gap_rate, d_gap_rate = project(v[i] - v[j], rate_factor or 0.0, n, dn)
    if rate_law:
        if v is None:
            raise ValueError("the rate law needs velocities v")
        slip, d_slip = project(v[i] - v[j], float(rate_factor), e, de)
    else:
        rel = x[i] - x[j]
        if x_start is not None:
            rel = rel - (x_start[i] - x_start[j])
        else:
            rel = np.zeros_like(rel)
        slip, d_slip = project(rel, 1.0 if x_start is not None else 0.0, e, de)
    if not objective:
        return PairKinematics(slots, n, e, dn, de, length, d_length, gap, d_gap, gap_rate,
                              d_gap_rate, slip, d_slip, rate_law)
    offset, d_offset = project(x[i] - x[j], 1.0, e, de)
    chord = np.linalg.norm(x[slots[:, 3]] - x[slots[:, 2]], axis=1)
    d_chord = np.zeros((len(slots), N_SLOTS, 2))
    d_chord[:, 3], d_chord[:, 2] = e, -e
    if v is not None:
        factor = rate_factor or 0.0
        extra, d_extra = _chord_rate(offset, d_offset, chord, d_chord, n, dn, v, slots, factor)
        gap_rate, d_gap_rate = gap_rate + extra, d_gap_rate + d_extra
        if rate_law:
            extra, d_extra = _chord_rate(gap, d_gap, chord, d_chord, n, dn, v, slots, factor)
            slip, d_slip = slip - extra, d_slip - d_extra
    return PairKinematics(slots, n, e, dn, de, length, d_length, gap, d_gap, gap_rate,
                          d_gap_rate, slip, d_slip, rate_law, offset, d_offset, chord, d_chord)


def pair_gaps(
    x: NDArray[np.float64],
    interface: Interface,
    pairs: NDArray[np.int64],
    v: NDArray[np.float64] | None = None,
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64] | None]:
    """Normal n, gap g (2.4) and, with ``v``, gap rate gdot (2.9) of ``pairs``: the values
    :func:`pair_kinematics` gives (the same operations, so the same bits) without the
    derivatives, which pairing and detection do not need (they were ~0.5 ms of ~1.5 ms per
    detection of the ring impact)."""
    pairs = np.asarray(pairs, dtype=np.int64).reshape(-1, 2)
    e, _ = _unit_chord(x, _slots(interface, pairs))
    n = e @ _ROT_M90.T
    i, j = pairs[:, 0], pairs[:, 1]
    gap = np.einsum("pr,pr->p", x[i] - x[j], n)
    rate = None if v is None else np.einsum("pr,pr->p", v[i] - v[j], n)
    return n, gap, rate
