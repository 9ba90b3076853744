"""Contact force and consistent tangent for a GIVEN active set and fixed multipliers.

Virtual work (2.57) with the tributary length L_c as the discrete measure (5.5)-(5.6):

    G^c = sum_pairs L_c (t_N n + t_T e) . (w_i - w_j),

so the residual R = f_int - f_ext + f_contact receives +F on node i (surface 1) and -F on node j
(surface 2), F = L_c (t_N n + t_T e) (5.11)-(5.12); the traction on body 1 is -t_N n - t_T e
(2.13). The tangent is the exact derivative dF/dx_eval: unlike (5.23)-(5.24) it keeps the
derivatives of n, e and L_c with respect to the chain neighbours (so Newton converges
quadratically) and the dependence of the slip traction on t_N. It is unsymmetric in general.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from numpy.typing import NDArray

from .friction import ReturnMapping, frictional_dissipation, return_mapping
from .kinematics import N_SLOTS, PairKinematics, pair_kinematics
from .laws import ContactLaw, normal_traction
from .state import PairState
from .surfaces import Interface

try:
    from . import kernels_numba
except ImportError:  # pragma: no cover - Numba missing: the NumPy reference still works
    kernels_numba = None  # type: ignore[assignment]

#: Implementation of :func:`evaluate_contact`: "numba" (one compiled loop over the pairs,
#: equal to the reference to round-off, the default when Numba imports) or "numpy" (the
#: vectorized reference built from :func:`pair_response`). Read at every call.
KERNEL: str = "numba" if kernels_numba is not None else "numpy"

__all__ = [
    "ContactResult",
    "ContactTerm",
    "PairResponse",
    "contact_term",
    "evaluate_contact",
    "pair_response",
]


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
    dlam = state.dlambda_T if law.uses_multipliers else np.zeros(len(state))
    rm = return_mapping(state.t_T, dlam, kin.slip_measure, t_N, law.mu, law.eps_T)
    d_t_T = rm.d_slip[:, None, None] * kin.d_slip_measure + rm.d_normal[:, None, None] * d_t_N
    return PairResponse(kin, t_N, d_t_N, rm, d_t_T)


@dataclass(frozen=True)
class ContactResult:
    """Contact contribution to the residual and its tangent, plus per-pair diagnostics.

    force: (ndof,) vector to ADD to R = f_int - f_ext + f_contact.
    rows, cols, vals: COO triplets of d force / d x_eval in global dofs (duplicates add up).
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

    @property
    def normal_force(self) -> NDArray[np.float64]:
        return self.t_N * self.length

    @property
    def tangential_force(self) -> NDArray[np.float64]:
        return self.t_T * self.length

    @property
    def normal_measure(self) -> NDArray[np.float64]:
        """The quantity the normal law constrains: gdot (rate law) or g (gap law)."""
        return self.gap_rate if self.rate_law else self.gap

    def tangent_matrix(self) -> sp.csr_matrix:
        """The COO triplets as a square CSR matrix (duplicates summed)."""
        n = self.force.size
        return sp.csr_matrix((self.vals, (self.rows, self.cols)), shape=(n, n))


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
    """Contact force, consistent tangent and per-pair results for the active set ``state``.

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
    if KERNEL == "numba":
        res = _evaluate_compiled(x_eval, v_eval, rate_factor, interface, state, law, x_start,
                                 dt)
        if res is not None:
            return res  # else: an error the reference reports with its own message
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


_NO_ARRAY = np.zeros((0, 2))


def _evaluate_compiled(
    x_eval: NDArray, v_eval: NDArray | None, rate_factor: float | None, interface: Interface,
    state: PairState, law: ContactLaw, x_start: NDArray | None, dt: float | None,
) -> ContactResult | None:
    """:func:`evaluate_contact` by :func:`kernels_numba.evaluate_pairs`; None on bad input."""
    rate_law = rate_factor is not None
    if rate_law and v_eval is None:
        return None
    step = 1.0 if rate_factor is None else (dt if dt is not None else 2.0 / rate_factor)
    params = np.array([law.eps_N, law.eps_T, law.mu, rate_factor or 0.0, step])
    flags = np.array([kernels_numba.METHOD_CODES[law.method], rate_law, v_eval is not None,
                      x_start is not None, law.frictional, law.moment_free], dtype=np.int64)
    pairs = state.pairs

    def c_float(a: NDArray | None) -> NDArray:  # one compiled signature: C-contiguous float64
        return _NO_ARRAY if a is None else np.ascontiguousarray(a, dtype=np.float64)

    code, force, rows, cols, vals, scalars, normal, tangent, status, dissipation = \
        kernels_numba.evaluate_pairs(
            c_float(x_eval), c_float(v_eval), c_float(x_start), interface.surface1.kernel_table,
            interface.surface2.kernel_table, np.ascontiguousarray(pairs, dtype=np.int64),
            c_float(state.lambda_N), c_float(state.dlambda_T), c_float(state.t_T), params,
            flags)
    if code != kernels_numba.OK:
        return None
    k = kernels_numba
    return ContactResult(
        force=force, rows=rows, cols=cols, vals=vals, pairs=pairs, gap=scalars[k.GAP],
        gap_rate=scalars[k.GAP_RATE], slip_measure=scalars[k.SLIP_MEASURE],
        t_N=scalars[k.T_N], t_T=scalars[k.T_T], trial_T=scalars[k.TRIAL_T], status=status,
        length=scalars[k.LENGTH], normal=normal, tangent=tangent,
        dissipation=float(dissipation), rate_law=rate_law,
    )


ContactTerm = Callable[
    [NDArray, NDArray | None, float | None, NDArray | None],
    tuple[NDArray, tuple[NDArray, NDArray, NDArray]],
]


def contact_term(
    interface: Interface, state: PairState, law: ContactLaw, dt: float | None = None
) -> ContactTerm:
    """Adapter to the ``extra`` term signature of :class:`ntncontact.problem.StepProblem`:
    (x_eval, v_eval, rate_factor, x_start) -> (force, (rows, cols, vals)), multipliers fixed."""

    def term(
        x_eval: NDArray, v_eval: NDArray | None, rate_factor: float | None,
        x_start: NDArray | None,
    ) -> tuple[NDArray, tuple[NDArray, NDArray, NDArray]]:
        res = evaluate_contact(x_eval, v_eval, rate_factor, interface, state, law,
                               x_start=x_start, dt=dt)
        return res.force, (res.rows, res.cols, res.vals)

    return term
