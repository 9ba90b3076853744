"""The convective term of ALE bodies with ``convection = "convective_term"`` as a step term.

In that formulation the mesh move at t_n remaps only X and d (``ale.motion`` item 6), and the
mid-point step adds C(c) v_{n+1/2} (report (5.7), (5.15)) over the body's elements, with
c = -(x~_n - x_n)/dt: during the step the node moves by x~_n - x_n + dt v, so v_hat = v + (x~_n -
x_n)/dt and c = v - v_hat. c is held constant in the Newton iteration (the report's remark after
(5.13)); it changes between augmentations with the mesh motion.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from ..ale.convective import convective_force
from .mesh_motion import MeshMotion
from .model import AleSetup, Model
from .problem import ExtraTerm

__all__ = ["convective_terms"]


def convective_terms(model: Model, motion: MeshMotion | None, dt: float) -> list[ExtraTerm]:
    """One step term per ALE body in convective-term mode whose mesh moved (else none)."""
    if motion is None:
        return []
    terms = []
    for setup, update in zip(model.ale_bodies, motion.updates, strict=True):
        if update is None or setup.motion.convection != "convective_term":
            continue
        c = np.zeros((model.n_nodes, 2))
        c[setup.node_offset:setup.node_offset + setup.n_nodes] = update.convective
        if np.any(c):
            terms.append(_body_term(model, setup, motion.state.X, c))
    return terms


def _body_term(model: Model, setup: AleSetup, X: NDArray, c: NDArray) -> ExtraTerm:
    """f = C(c) v_eval over the body's cells and d f / d x_eval = df/dx + rate df/dv."""
    cells = model.bodies[setup.body_index].cells
    cell_nodes = model.cells[cells]
    rho = model.assembler.rho[cells]

    def term(x_eval: NDArray, v_eval: NDArray | None, rate: float | None,
             x_start: NDArray) -> tuple[NDArray, tuple[NDArray, NDArray, NDArray]]:
        if v_eval is None:  # quasi-static: no inertia, no convection
            empty = np.zeros(0)
            return np.zeros(x_eval.size), (empty.astype(np.int64), empty.astype(np.int64), empty)
        r = convective_force(X, x_eval, v_eval, c, cell_nodes, rho)
        (rx, cx, kx), (rv, cv, kv) = r.d_x, r.d_v
        return r.force, (np.concatenate([rx, rv]), np.concatenate([cx, cv]),
                         np.concatenate([kx, rate * kv]))

    return term
