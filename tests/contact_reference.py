"""NumPy oracle of the compiled contact kernel (ntncontact.contact.evaluate): the same
formulas written with whole-array operations, kept only to test the kernel against
(tests/test_contact_kernel.py) and for the analytic tests of the kinematics and the friction law.

Slot convention (as in the kernel): every quantity of a pair (node1 i on surface 1, node2 j on
surface 2) depends on at most six nodes,

    slot 0: i,   slot 1: j,
    slots 2, 3: the nodes (a, b) defining the normal, n = rot(-90)(x_b - x_a)/|x_b - x_a|
                (a, b) = (prev(i), next(i)) on surface 1, or (next(j), prev(j)) on surface 2
                when i is a corner, i.e. n = -n2(j) (report 6.6),
    slots 4, 5: the chain neighbours of i entering L_c = (L_{i-1,i} + L_{i,i+1})/2 (5.5).

A scalar's gradient is (P, 6, 2), a vector's Jacobian (P, 6, 2, 2) with [p, k, r, c] =
d(value_r)/d(x_{slot k, c}); repeated slots add up when assembled.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ntncontact.contact import ContactLaw, ContactResult, Interface, PairState
from ntncontact.contact.friction import SLIP, STICK
from ntncontact.contact.kinematics import _ROT_M90, N_SLOTS, _slots, _unit_chord


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



def normal_traction(
    law: ContactLaw, lambda_N: NDArray[np.float64], measure: NDArray[np.float64]
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """t_N and dt_N/d(measure) per pair.

    measure is g (gap law, 2.33) or gdot (persistency law, 2.34): t_N = <lambda_N + eps_N measure>
    (lambda_N = 0 for penalty). "lagrange": t_N = lambda_N, the multiplier itself, WITHOUT the
    Macaulay bracket, so Newton sees a smooth system; its sign is checked after the solve.

    A pair held by its multiplier (:func:`held_pairs`) takes lambda_N + eps_N measure without
    the bracket as well: within one augmentation's Newton solve its traction may turn tensile,
    and the augmentation test (``augmentation.check_augmentation``) only accepts a solution
    where it has not, so converged tractions are those of the bracketed law.
    """
    if law.method == "lagrange":
        return np.asarray(lambda_N, dtype=float).copy(), np.zeros_like(measure)
    base = 0.0 if law.method == "penalty" else lambda_N
    trial = base + law.eps_N * measure
    # An active pair exactly at the kink (touching, g = 0) takes the pressed branch's
    # derivative: otherwise a body held only by contact has a singular tangent at first touch.
    pressed = (trial >= 0.0) | held_pairs(law, lambda_N)
    return np.where(pressed, trial, 0.0), np.where(pressed, law.eps_N, 0.0)


def held_pairs(law: ContactLaw, lambda_N: NDArray[np.float64]) -> NDArray[np.bool_]:
    """Pairs kept on the pressed branch of the normal law during a Newton solve: frictionless
    augmented-Lagrangian pairs with a positive multiplier (a fixed active set per
    augmentation, a semi-smooth Newton step on the bracket).

    Why: such a pair that starts a solve separating (lambda_N + eps_N gdot < 0 at the initial
    guess) contributes neither force nor stiffness there, so the Newton step drives it deep into
    penetration and its traction jumps to ~10x its value; the line search then backtracks and
    the Jacobian is factored again. On the ring impact (report 6.4) this happened in about a
    third of the fresh Newton steps. Frictional pairs are left bracketed: a tensile t_N would
    flip the sign of the Coulomb limit mu t_N."""
    lambda_N = np.asarray(lambda_N, dtype=float)
    if not law.frictionless_augmented:
        return np.zeros(lambda_N.shape, dtype=bool)
    return lambda_N > 0.0


@dataclass(frozen=True)
class ReturnMapping:
    """Result of the return mapping for P pairs.

    t_T = traction; d_t_T = d_slip * d(slip measure) + d_normal * d(t_N) gives its derivative
    (d_slip = eps_T for stick, 0 otherwise; d_normal = mu sign(trial) where the cone is active).
    """

    traction: NDArray[np.float64]
    trial: NDArray[np.float64]
    status: NDArray[np.int8]
    reversed: NDArray[np.bool_]
    d_slip: NDArray[np.float64]
    d_normal: NDArray[np.float64]


def return_mapping(
    t_prev: NDArray[np.float64],
    dlambda: NDArray[np.float64],
    slip_measure: NDArray[np.float64],
    t_N: NDArray[np.float64],
    mu: float,
    eps_T: float,
) -> ReturnMapping:
    """Coulomb return mapping (2.39)-(2.43) with the reversal rule of 3.3.2 (module doc).

    With ``mu == 0`` or ``eps_T == 0`` the interface is frictionless: t_T = 0, status SLIP.
    """
    p = np.shape(t_N)
    if mu == 0.0 or eps_T == 0.0:
        zero = np.zeros(p)
        return ReturnMapping(zero, zero, np.full(p, SLIP), np.zeros(p, bool), zero, zero)
    trial = t_prev + dlambda + eps_T * slip_measure
    limit = mu * t_N
    # an unloaded pair (t_N = 0) carries no friction: treat it as sliding, not as stuck at 0;
    # except at trial = 0 (first touch, no slip yet), where the stick branch's stiffness keeps
    # a body held only by friction from being singular in its first Newton iteration
    beyond = (np.abs(trial) > limit) | ((limit <= 0.0) & (trial != 0.0))
    # trial beyond the cone yet pointing against the motion: the sliding direction reversed
    reversed_ = beyond & (slip_measure * trial < 0.0)
    slip = beyond & ~reversed_
    sign = np.sign(trial)
    traction = np.where(beyond, limit * sign, trial)
    d_slip = np.where(beyond, 0.0, eps_T)
    d_normal = np.where(beyond, mu * sign, 0.0)
    status = np.where(slip, SLIP, STICK).astype(np.int8)
    return ReturnMapping(traction, trial, status, reversed_, d_slip, d_normal)


def frictional_dissipation(
    traction: NDArray[np.float64],
    slip_measure: NDArray[np.float64],
    length: NDArray[np.float64],
    status: NDArray[np.int8],
    dt: float | None = None,
) -> float:
    """Work dissipated by friction over the step, sum over SLIP pairs of t_T delta g_T L_c
    (3.17)-(3.18). Under the rate law ``slip_measure`` is gdot_T and delta g_T = gdot_T dt.

    STICK pairs are not counted: the report treats them as not sliding (gdot_T = 0, 3.3.2);
    the regularized elastic part eps_T of their motion is stored, not dissipated.
    """
    increment = slip_measure * (1.0 if dt is None else dt)
    return float(np.sum(np.where(status == SLIP, traction * increment * length, 0.0)))


@dataclass(frozen=True)
class PairResponse:
    """Kinematics, normal traction and return mapping of the active pairs (shared by
    :func:`evaluate_contact` and the Lagrange blocks)."""

    kin: PairKinematics
    t_N: NDArray[np.float64]
    d_t_N: NDArray[np.float64]  # (P, 6, 2)
    friction: ReturnMapping
    d_t_T: NDArray[np.float64]  # (P, 6, 2)


def pair_response(
    x_eval: NDArray[np.float64],
    v_eval: NDArray[np.float64] | None,
    rate_factor: float | None,
    interface: Interface,
    state: PairState,
    law: ContactLaw,
    x_start: NDArray[np.float64] | None = None,
) -> PairResponse:
    """Tractions t_N (2.33/2.34) and t_T (2.39-2.43) with their slot gradients."""
    kin = pair_kinematics(x_eval, interface, state.pairs, v_eval, rate_factor, x_start,
                          objective=law.moment_free)
    t_N, dt_dmeasure = normal_traction(law, state.lambda_N, kin.normal_measure)
    d_t_N = dt_dmeasure[:, None, None] * kin.d_normal_measure
    dlam = state.dlambda_T if law.method != "penalty" else np.zeros(len(state))
    rm = return_mapping(state.t_T, dlam, kin.slip_measure, t_N, law.mu, law.eps_T)
    d_t_T = rm.d_slip[:, None, None] * kin.d_slip_measure + rm.d_normal[:, None, None] * d_t_N
    return PairResponse(kin, t_N, d_t_N, rm, d_t_T)


def _force_jacobian(resp: PairResponse) -> tuple[NDArray, NDArray]:
    """F = L_c (t_N n + t_T e) per pair and dF/dx_slot, (P, 2) and (P, 6, 2, 2)."""
    k, t_N, t_T = resp.kin, resp.t_N, resp.friction.traction
    direction = t_N[:, None] * k.normal + t_T[:, None] * k.tangent
    outer = np.einsum  # d(L_c a)/dx = a dL_c^T + L_c da/dx
    d_dir = (outer("pr,pkc->pkrc", k.normal, resp.d_t_N) + t_N[:, None, None, None] * k.d_normal
             + outer("pr,pkc->pkrc", k.tangent, resp.d_t_T)
             + t_T[:, None, None, None] * k.d_tangent)
    jac = outer("pr,pkc->pkrc", direction, k.d_length) + k.length[:, None, None, None] * d_dir
    return k.length[:, None] * direction, jac


def _moment_free_couple(resp: PairResponse) -> tuple[NDArray, NDArray]:
    """The chord part of L_c (t_N dg/dx + t_T ds/dx): C = L_c (t_T g - t_N s)/l n, applied +C on
    the chord's node b (slot 3) and -C on a (slot 2), and dC/dx_slot; (P, 2), (P, 6, 2, 2).

    g = w.n, s = w.e with w = x_i - x_j and n, e from the chord x_b - x_a of length l:
    dg/dx_b = w.dn/dx_b = -(s/l) n and ds/dx_b = (g/l) n, so the pair's moment
    w x F = L_c (g t_T - s t_N) is cancelled by the couple l e x C."""
    k, t_N, t_T = resp.kin, resp.t_N, resp.friction.traction
    moment = t_T * k.gap - t_N * k.offset
    d_moment = (k.gap[:, None, None] * resp.d_t_T + t_T[:, None, None] * k.d_gap
                - k.offset[:, None, None] * resp.d_t_N - t_N[:, None, None] * k.d_offset)
    coef = k.length * moment / k.chord
    d_coef = (moment[:, None, None] * k.d_length + k.length[:, None, None] * d_moment
              - coef[:, None, None] * k.d_chord) / k.chord[:, None, None]
    jac = (np.einsum("pr,pkc->pkrc", k.normal, d_coef)
           + coef[:, None, None, None] * k.d_normal)
    return coef[:, None] * k.normal, jac


def assemble_pair_vectors(pairs: NDArray, vectors: NDArray, ndof: int) -> NDArray:
    """Global vector with +vectors on node1 dofs and -vectors on node2 dofs."""
    idx = np.concatenate([2 * pairs[:, 0], 2 * pairs[:, 0] + 1, 2 * pairs[:, 1],
                          2 * pairs[:, 1] + 1])
    w = np.concatenate([vectors[:, 0], vectors[:, 1], -vectors[:, 0], -vectors[:, 1]])
    return np.bincount(idx, weights=w, minlength=ndof).astype(float)


def assemble_pair_jacobian(
    pairs: NDArray, slots: NDArray, jac: NDArray
) -> tuple[NDArray, NDArray, NDArray]:
    """COO of d(+F on node1, -F on node2)/dx from dF/dx_slot (P, 6, 2, 2)."""
    p = len(pairs)
    shape = (p, 2, N_SLOTS, 2, 2)  # pair, node (i/j), slot, force comp r, position comp c
    comp = np.arange(2)
    rows = 2 * pairs[:, :, None, None, None] + comp[None, None, None, :, None]
    cols = 2 * slots[:, None, :, None, None] + comp[None, None, None, None, :]
    sign = np.array([1.0, -1.0])[None, :, None, None, None]
    vals = sign * jac[:, None]
    return (np.broadcast_to(rows, shape).ravel(), np.broadcast_to(cols, shape).ravel(),
            np.broadcast_to(vals, shape).ravel())


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
) -> ContactResult:
    """The oracle of ``ntncontact.contact.evaluate_contact`` (same arguments and result).

    x_eval: (n_nodes, 2) positions of ALL bodies where geometry is evaluated (the mid-point
        configuration in dynamics); v_eval: velocities with dv/dx_eval = rate_factor I.
    rate_factor: 2/dt for the mid-point rule -> persistency law t_N = <lambda + eps_N gdot>
        (2.34) and rate friction; None -> gap law t_N = <lambda + eps_N g> (2.33) and the
        tangential increment since ``x_start`` (required for friction under the gap law).
    dt: only scales the reported dissipation under the rate law (default 2/rate_factor).
    Multipliers (lambda_N, dlambda_T) and the friction history come from ``state`` and are
    held fixed: this is what Newton calls at every iteration.
    """
    ndof = 2 * x_eval.shape[0]
    if law.frictional and rate_factor is None and x_start is None:
        raise ValueError("friction under the gap law needs x_start (tangential increment)")
    resp = pair_response(x_eval, v_eval, rate_factor, interface, state, law, x_start)
    force_pp, jac = _force_jacobian(resp)
    k, rm = resp.kin, resp.friction
    force = assemble_pair_vectors(state.pairs, force_pp, ndof)
    rows, cols, vals = assemble_pair_jacobian(state.pairs, k.slots, jac)
    if law.moment_free:
        chord_nodes = k.slots[:, [3, 2]]
        couple, d_couple = _moment_free_couple(resp)
        force += assemble_pair_vectors(chord_nodes, couple, ndof)
        couple_coo = assemble_pair_jacobian(chord_nodes, k.slots, d_couple)
        # the compiled kernel's order: each pair's 48 pair entries, then its 48 couple entries
        rows, cols, vals = (np.concatenate((a.reshape(len(state), -1), b.reshape(len(state), -1)),
                                           axis=1).ravel()
                            for a, b in zip((rows, cols, vals), couple_coo, strict=True))
    step = None if rate_factor is None else (dt if dt is not None else 2.0 / rate_factor)
    gap_rate = k.gap_rate if k.gap_rate is not None else np.full(len(state), np.nan)
    return ContactResult(
        force=force, rows=rows, cols=cols,
        vals=vals, pairs=state.pairs, gap=k.gap, gap_rate=gap_rate,
        slip_measure=k.slip_measure, t_N=resp.t_N, t_T=rm.traction, trial_T=rm.trial,
        status=rm.status, length=k.length, normal=k.normal, tangent=k.tangent,
        dissipation=frictional_dissipation(rm.traction, k.slip_measure, k.length, rm.status,
                                           step),
        rate_law=k.rate_law,
    )


