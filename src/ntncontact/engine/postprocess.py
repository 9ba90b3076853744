"""Derived fields for output: stress and strain tensors, von Mises, pressure (per cell and
averaged to the nodes), contact-node fields and the ALE mesh velocity. Names and units:
docs/outputs.md, "Fields of a frame".

Tensors are written as ParaView's 6-component symmetric tensors (xx, yy, zz, xy, yz, xz), yz and
xz zero in 2D. Cell values are averages over the element's Gauss points weighted by their
current area (J w), i.e. int sigma da / int da; nodal values average the cells around a node
weighted by their current area. Both are exact for a uniform field.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray

from ..fem.kernels_numba import CELL_FIELD_COLUMNS, MODEL_CODES, cell_fields, raise_inverted
from .model import Model

#: status codes of the contact-node field ``contact_status``; SHARED: a surface-1 node in no
#: pair that carries a share of its neighbouring pairs' forces (``unpaired_share``)
OPEN, STICK, SLIP, SHARED = 0, 1, 2, 3


def _symmetric6(xx: NDArray, yy: NDArray, zz: NDArray, xy: NDArray) -> NDArray:
    """ParaView's symmetric tensor layout (xx, yy, zz, xy, yz, xz) of in-plane components."""
    zero = np.zeros_like(xx)
    return np.stack([xx, yy, zz, xy, zero, zero], axis=-1)


def stress_fields(model: Model, X: NDArray, x: NDArray) -> tuple[dict, dict]:
    """(cell data, point data) of stress, strain, von Mises and pressure: cell averages over
    the Gauss points and their area-weighted nodal averages (``<name>_nodal``)."""
    cell, nodal, _ = frame_fields(model, X, x - X)
    return cell, nodal


def frame_fields(model: Model, X: NDArray, d: NDArray, F_bodies: Sequence[int] = ()
                 ) -> tuple[dict, dict, NDArray | None]:
    """:func:`stress_fields`' (cell data, point data) at displacements d and, for the bodies
    of index ``F_bodies``, the nodal deformation gradient (n, 2, 2; zero at the other bodies'
    nodes, None without such bodies) that :func:`mesh_velocity` takes. The Gauss-point work
    is the compiled :func:`~ntncontact.fem.kernels_numba.cell_fields`, with the internal
    force's constitutive law, in d as the internal force takes it: from positions x, a stiff
    body far from the origin got eps |x| / h of round-off into its strain (Hertz's foundation,
    E = 2e8 at |x| ~ 400: up to 2.5e-10 of its largest stress)."""
    rows = _cell_rows(model, X, d)
    cell = {"stress": _symmetric6(*rows[:, 0:4].T), "strain": _symmetric6(*rows[:, 4:8].T),
            "von_mises": rows[:, 8], "pressure": rows[:, 9]}
    F_parts = [(model.cells[model.bodies[i].cells], rows[model.bodies[i].cells])
               for i in F_bodies]
    return (cell, _nodal_averages(model.cells, rows[:, 10], cell, len(X)),
            _nodal_F(F_parts, len(X)))


def _cell_rows(model: Model, X: NDArray, d: NDArray) -> NDArray:
    """:data:`~ntncontact.fem.kernels_numba.CELL_FIELD_COLUMNS` of every cell, body by body
    (bodies may differ in material model); raises InvertedElementError naming the first
    element (its index in its body) with a reference Jacobian that is not positive."""
    rows = np.empty((len(model.cells), len(CELL_FIELD_COLUMNS)))
    for body in model.bodies:
        cells, mat = model.cells[body.cells], body.material
        n = len(cells)
        out = np.empty((n, len(CELL_FIELD_COLUMNS)))
        bad = cell_fields(MODEL_CODES[mat.kind], X, d, cells, np.full(n, mat.effective_lambda),
                          np.full(n, mat.mu), mat.plane_stress, out)
        if bad >= 0:
            raise_inverted(int(bad), X, cells)
        rows[body.cells] = out
    return rows


def _nodal_F(parts: list, n_nodes: int) -> NDArray | None:
    """Reference-area-weighted nodal averages of the cell F of ``parts`` ((cells, cell rows)
    per body; bodies share no node), zero at the nodes of no part."""
    if not parts:
        return None
    out = np.zeros((n_nodes, 2, 2))
    for cells, rows in parts:
        nodes = np.unique(cells)
        F_cell = {"F": rows[:, 12:16].reshape(-1, 2, 2)}
        out[nodes] = _nodal_averages(cells, rows[:, 11], F_cell, n_nodes)["F_nodal"][nodes]
    return out


def _nodal_averages(cells: NDArray, area: NDArray, cell: dict, n_nodes: int) -> dict:
    """sum_e A_e v_e / sum_e A_e over the cells e around each node."""
    nodes = cells.ravel()
    share = np.repeat(area, cells.shape[1])
    total = np.bincount(nodes, weights=share, minlength=n_nodes)
    total[total == 0.0] = 1.0  # nodes without cells (none in a valid mesh)
    out = {}
    for name, value in cell.items():
        columns = value.reshape(len(value), -1)
        nodal = np.stack([np.bincount(nodes, weights=share * np.repeat(c, cells.shape[1]),
                                      minlength=n_nodes) for c in columns.T], axis=-1)
        out[f"{name}_nodal"] = (nodal / total[:, None]).reshape((n_nodes,) + value.shape[1:])
    return out


def contact_node_fields(rows: dict | None, n_nodes: int, shares: dict | None = None
                        ) -> dict[str, NDArray]:
    """Point data from a step's contact.csv rows, on the surface-1 node of each active pair
    (zero elsewhere; ``contact_partner`` -1): tractions, gap, gap rate, status, partner.
    ``shares`` (``engine.interfaces.unpaired_shares``): the unpaired surface-1 nodes that
    carry part of the pairs' forces get their tractions and status SHARED (gap, gap rate and
    partner are the pairs' and stay 0, 0, -1 there), so that the field integrates to the
    contact force along the surface."""
    out = {name: np.zeros(n_nodes) for name in ("contact_pressure", "contact_tangential_traction",
                                                "contact_gap", "contact_gap_rate")}
    out["contact_status"] = np.full(n_nodes, OPEN, dtype=np.int64)
    out["contact_partner"] = np.full(n_nodes, -1, dtype=np.int64)
    if rows is None or not len(rows["node_1"]):
        return out
    nodes = np.asarray(rows["node_1"], dtype=np.int64)
    for name, column in (("contact_pressure", "normal_traction"),
                         ("contact_tangential_traction", "tangential_traction"),
                         ("contact_gap", "gap"), ("contact_gap_rate", "gap_rate")):
        out[name][nodes] = rows[column]
    out["contact_status"][nodes] = np.where(np.asarray(rows["status"]) == "slip", SLIP, STICK)
    out["contact_partner"][nodes] = rows["node_2"]
    if shares is not None and len(shares["node"]):
        # a node paired on another interface of the same surface keeps its pair's values
        keep = ~np.isin(shares["node"], nodes)
        shared = np.asarray(shares["node"], dtype=np.int64)[keep]
        out["contact_pressure"][shared] = np.asarray(shares["normal_traction"])[keep]
        out["contact_tangential_traction"][shared] = np.asarray(
            shares["tangential_traction"])[keep]
        out["contact_status"][shared] = SHARED
    return out


def mesh_velocity(v: NDArray, X: NDArray, X_before: NDArray, dt: float,
                  F_nodal: NDArray | None) -> NDArray:
    """Spatial velocity of the mesh nodes, w = v + F dX/dt: the node sits on the particle X(t),
    so d/dt phi(X(t), t) = v + F Xdot. Lagrangian nodes (X fixed) move with the material."""
    if dt <= 0.0 or F_nodal is None:
        return v.copy()
    X_rate = (X - X_before) / dt
    return v + np.einsum("nij,nj->ni", F_nodal, X_rate)
