"""Exact normal multipliers: the blocks of a bordered (saddle-point) Newton system (report 2.2.1).

Unknowns: x_eval (through the solver's d) and one multiplier t_N per active pair (traction
units, t_N = lambda_N, as for the other methods). With ``law.method == "lagrange"``,
:func:`~ntncontact.contact.evaluate.evaluate_contact` called with ``state.lambda_N = t_N``
returns the contact force f_c(x, t_N) and the block K_c = df_c/dx at fixed multipliers. This
module adds the constraint and coupling blocks, for the Newton step

    [ K + K_c   B ] [dx  ]     [ R = f_int - f_ext + f_c ]
    [ G         0 ] [dt_N] = - [ h                       ]

    h_p = L_c g_p (gap law) or L_c gdot_p (persistency law): the tributary-weighted constraint,
        work-conjugate to t_N, so that G ~ B^T (exactly at g = 0 for a fixed normal);
    G = dh/dx_eval  (rows: pair index, columns: global dofs; the rate law's G carries the
        factor rate_factor of dv/dx = rate_factor I: scale the row block if you prefer),
    B = d f_c / d t_N  (rows: global dofs, columns: pair index; includes mu sign(trial) L_c e
        on slipping pairs, whose traction is mu t_N).

Activity is checked after Newton converges: a pair with t_N < 0 (tension, 2.14) is released with
:func:`release_tensile_pairs` and the step is solved again; new penetrations enter through
:func:`~ntncontact.contact.detection.detect` at the next step. The energy-conserving variant of
report 5.5 borders the same system with one more row/column (lambda_E); it reuses h, G and B.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from .evaluate import ContactResult, evaluate_contact
from .kinematics import N_SLOTS
from .laws import ContactLaw
from .state import PairState
from .surfaces import Interface

__all__ = ["LagrangeBlocks", "blocks_of", "lagrange_blocks", "release_tensile_pairs"]


@dataclass(frozen=True)
class LagrangeBlocks:
    """Constraint values h (P,), G = dh/dx and B = df_c/dt_N as COO triplets."""

    values: NDArray[np.float64]
    g_rows: NDArray[np.int64]
    g_cols: NDArray[np.int64]
    g_vals: NDArray[np.float64]
    b_rows: NDArray[np.int64]
    b_cols: NDArray[np.int64]
    b_vals: NDArray[np.float64]


def lagrange_blocks(
    x_eval: NDArray[np.float64],
    v_eval: NDArray[np.float64] | None,
    rate_factor: float | None,
    interface: Interface,
    state: PairState,
    law: ContactLaw,
    x_start: NDArray[np.float64] | None = None,
) -> LagrangeBlocks:
    """h, G and B (module docstring) at ``x_eval`` with multipliers ``state.lambda_N``."""
    if x_start is None and rate_factor is None:
        x_start = x_eval  # the gap law's h needs no tangential increment: take it as zero
    result = evaluate_contact(x_eval, v_eval, rate_factor, interface, state, law,
                              x_start=x_start)
    return blocks_of(result, law)


def blocks_of(result: ContactResult, law: ContactLaw) -> LagrangeBlocks:
    """h, G and B from the per-pair data of an :func:`evaluate_contact` result."""
    p = len(result.pairs)
    slots, d_measure, d_length = result.slots, result.gradients[:, 0], result.gradients[:, 1]
    measure = result.normal_measure
    values = result.length * measure
    d_h = measure[:, None, None] * d_length + result.length[:, None, None] * d_measure
    comp = np.arange(2)
    g_rows = np.broadcast_to(np.arange(p)[:, None, None], (p, N_SLOTS, 2)).ravel()
    g_cols = (2 * slots[:, :, None] + comp).ravel()
    # dF/dt_N = L_c (n + d t_T/d t_N e): +on node i, -on node j
    slope = result.friction_slope
    column = result.length[:, None] * (result.normal + slope[:, None] * result.tangent)
    nodes = result.pairs
    if law.moment_free:  # and the couple L_c (t_T g - t_N s)/l n: +on b, -on a (evaluate.py)
        d_coef = result.length * (slope * result.gap - result.offset) / result.chord
        nodes = np.hstack((nodes, slots[:, [3, 2]]))
        column = np.hstack((column, d_coef[:, None] * result.normal))
    n_nodes = nodes.shape[1]
    b_rows = (2 * nodes[:, :, None] + comp).ravel()
    b_cols = np.repeat(np.arange(p), 2 * n_nodes)
    sign = np.array([1.0, -1.0] * (n_nodes // 2))[None, :, None]
    b_vals = (sign * column.reshape(p, n_nodes // 2, 2).repeat(2, axis=1)).ravel()
    g_vals = d_h.ravel()
    if result.transfer is not None:  # back from the kernel's positions S x: G S and S^T B
        moving = _share_moving(result, g_vals)
        g_rows, g_cols, g_vals = result.transfer.columns(g_rows, g_cols, g_vals, p, moving)
        b_cols, b_rows, b_vals = result.transfer.columns(b_cols, b_rows, b_vals, p)
    return LagrangeBlocks(values, g_rows, g_cols, g_vals, b_rows, b_cols, b_vals)


def _share_moving(result: ContactResult, g_vals: NDArray[np.float64]
                  ) -> list[tuple[NDArray, NDArray]]:
    """G's parts that multiply dS/dx applied to x and to v (Transfer.weight_terms): under the
    rate law G = G_x + rate_factor G_v, G_v = L_c d gdot/dv from the kernel's gradient
    through v alone."""
    x, v, rate_factor, gradients_v = result.share_inputs
    if gradients_v is None:
        return [(g_vals, x)]
    g_v = (result.length[:, None, None] * gradients_v).ravel()
    return [(g_vals - rate_factor * g_v, x), (g_v, v)]


def release_tensile_pairs(state: PairState, multipliers: NDArray[np.float64]
                          ) -> tuple[PairState, NDArray[np.bool_]]:
    """Drop pairs whose converged multiplier is tensile, t_N < 0 (violates 2.14).

    Returns the reduced state (multipliers stored as lambda_N) and the released mask; if any
    pair was released the step must be solved again with the reduced active set.
    """
    multipliers = np.asarray(multipliers, dtype=float)
    tensile = multipliers < 0.0
    return state.with_multipliers(multipliers).take(~tensile), tensile
