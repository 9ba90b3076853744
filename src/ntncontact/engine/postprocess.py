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

from ..fem.q4 import Kinematics, kinematics
from ..materials.models import cauchy_stress, von_mises
from .model import Model

#: status codes of the contact-node field ``contact_status``
OPEN, STICK, SLIP = 0, 1, 2
TENSOR_FIELDS = ("stress", "strain")
SCALAR_FIELDS = ("von_mises", "pressure")


def _symmetric6(xx: NDArray, yy: NDArray, zz: NDArray, xy: NDArray) -> NDArray:
    """ParaView's symmetric tensor layout (xx, yy, zz, xy, yz, xz) of in-plane components."""
    zero = np.zeros_like(xx)
    return np.stack([xx, yy, zz, xy, zero, zero], axis=-1)


def _gauss_fields(body, kin: Kinematics) -> tuple[dict[str, NDArray], NDArray]:
    """Per Gauss point (ne, ngp, ...) of ``kin``: stress, strain, von Mises, pressure; and the
    current area weights J w (ne, ngp)."""
    F, mat = kin.F, body.material
    sigma, s33 = cauchy_stress(mat.kind, F, mat.effective_lambda, mat.mu, mat.plane_stress)
    C = np.swapaxes(F, -1, -2) @ F
    E = 0.5 * (C - np.eye(2))  # Green-Lagrange
    if mat.plane_stress:  # sigma_33 = 0 of linear elasticity (lambda*/(2 mu) = nu/(1-nu))
        e33 = -mat.effective_lambda / (2.0 * mat.mu) * (E[..., 0, 0] + E[..., 1, 1])
    else:
        e33 = np.zeros(E.shape[:-2])  # plane strain
    J = F[..., 0, 0] * F[..., 1, 1] - F[..., 0, 1] * F[..., 1, 0]
    values = {
        "stress": _symmetric6(sigma[..., 0, 0], sigma[..., 1, 1], s33, sigma[..., 0, 1]),
        "strain": _symmetric6(E[..., 0, 0], E[..., 1, 1], e33, E[..., 0, 1]),
        "von_mises": von_mises(sigma, s33),
        "pressure": -(sigma[..., 0, 0] + sigma[..., 1, 1] + s33) / 3.0,
    }
    return values, kin.weight * J


def stress_fields(model: Model, X: NDArray, x: NDArray) -> tuple[dict, dict]:
    """(cell data, point data) of stress, strain, von Mises and pressure: cell averages over
    the Gauss points and their area-weighted nodal averages (``<name>_nodal``)."""
    cell, nodal, _ = frame_fields(model, X, x)
    return cell, nodal


def frame_fields(model: Model, X: NDArray, x: NDArray, F_bodies: Sequence[int] = ()
                 ) -> tuple[dict, dict, NDArray | None]:
    """:func:`stress_fields`' (cell data, point data) and, for the bodies of index
    ``F_bodies``, the nodal deformation gradient (n, 2, 2; zero at the other bodies' nodes,
    None without such bodies) that :func:`mesh_velocity` takes. One kinematics per body
    serves both: computed twice, they were ~1.3 s of a 50 s Hertz run refined 8x."""
    n_cells, n_nodes = len(model.cells), len(X)
    cell = {name: np.zeros((n_cells, 6)) for name in TENSOR_FIELDS}
    cell |= {name: np.zeros(n_cells) for name in SCALAR_FIELDS}
    area = np.zeros(n_cells)
    F_parts = []
    for index, body in enumerate(model.bodies):  # bodies may differ in material model
        cells = model.cells[body.cells]
        kin = kinematics(X[cells], x[cells])
        values, weight = _gauss_fields(body, kin)
        area[body.cells] = weight.sum(axis=1)
        for name, value in values.items():
            w = weight.reshape(weight.shape + (1,) * (value.ndim - 2))
            cell[name][body.cells] = (value * w).sum(axis=1) / area[body.cells].reshape(
                (-1,) + (1,) * (value.ndim - 2))
        if index in F_bodies:
            F_parts.append((cells, _cell_deformation_gradient(kin)))
    return cell, _nodal_averages(model.cells, area, cell, n_nodes), _nodal_F(F_parts, n_nodes)


def _cell_deformation_gradient(kin: Kinematics) -> tuple[NDArray, NDArray]:
    """(reference areas, reference-area averages of F over each cell's Gauss points)."""
    weight = kin.weight
    area = weight.sum(axis=1)
    return area, (kin.F * weight[..., None, None]).sum(axis=1) / area[:, None, None]


def _nodal_F(parts: list, n_nodes: int) -> NDArray | None:
    """Reference-area-weighted nodal averages of the cell F of ``parts`` ((cells, (areas,
    cell F)) per body; bodies share no node), zero at the nodes of no part."""
    if not parts:
        return None
    out = np.zeros((n_nodes, 2, 2))
    for cells, (area, F_cell) in parts:
        nodes = np.unique(cells)
        out[nodes] = _nodal_averages(cells, area, {"F": F_cell}, n_nodes)["F_nodal"][nodes]
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


def contact_node_fields(rows: dict | None, n_nodes: int) -> dict[str, NDArray]:
    """Point data from a step's contact.csv rows, on the surface-1 node of each active pair
    (zero elsewhere; ``contact_partner`` -1): tractions, gap, gap rate, status, partner."""
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
    return out


def mesh_velocity(v: NDArray, X: NDArray, X_before: NDArray, dt: float,
                  F_nodal: NDArray | None) -> NDArray:
    """Spatial velocity of the mesh nodes, w = v + F dX/dt: the node sits on the particle X(t),
    so d/dt phi(X(t), t) = v + F Xdot. Lagrangian nodes (X fixed) move with the material."""
    if dt <= 0.0 or F_nodal is None:
        return v.copy()
    X_rate = (X - X_before) / dt
    return v + np.einsum("nij,nj->ni", F_nodal, X_rate)
