"""Measure a validation case: read its results folder into comparison rows and figures.

One function per kind of case (:data:`MEASURES`): it reads contact.csv, history.csv,
summary.json and the VTU snapshots of the case's run, hands the arrays to the checks of
:mod:`ntncontact.report.validation_checks`, and draws the case's figures
(:mod:`ntncontact.report.validation_figures`). The mesh-motion example has no run: it is
computed here.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import numpy as np

from ..ale.example_mesh_motion import mesh_motion_example
from ..contact import pair_gaps
from ..engine.model import Model
from ..io.vtk import frame_index, read_pvd, read_vtu
from ..io.writers import read_csv_table
from ..mesh.boundary import nodal_tributary_lengths, surface_chain
from ..mesh.quality import corner_jacobians
from .plotting import plot_all, plot_contact_tractions, plot_deformed, plot_energies, plot_momenta
from .reference import SMOOTHERS, compare
from .validation_cases import Case
from .validation_checks import (
    CaseResult,
    DelaminationPosition,
    HertzSnapshot,
    block_sliding_rows,
    delamination_rows,
    hertz_friction_rows,
    hertz_rows,
    mesh_motion_rows,
)
from .validation_figures import (
    plot_block_sliding,
    plot_delamination,
    plot_hertz,
    plot_mesh_motion,
    plot_report_overlay,
    plot_table_4_1,
)


class _Results:
    """contact.csv rows and VTU positions of a results folder at chosen times."""

    def __init__(self, directory: Path) -> None:
        self.contact = read_csv_table(directory / "contact.csv")
        self.series = read_pvd(directory / "fields.pvd")

    def times(self) -> np.ndarray:
        return np.unique(self.contact["time"])

    def has(self, t: float) -> bool:
        return bool(np.isclose(self.contact["time"], t, rtol=0.0, atol=1e-9).any())

    def rows(self, t: float, interface: str | None = None) -> dict[str, np.ndarray]:
        keep = np.isclose(self.contact["time"], t, rtol=0.0, atol=1e-9)
        if interface is not None:
            keep &= self.contact["interface"] == interface
        if not keep.any():
            raise LookupError(f"no contact rows at t = {t:g}")
        order = np.argsort(self.contact["node_1"][keep], kind="stable")
        return {k: v[keep][order] for k, v in self.contact.items()}

    def positions(self, t: float) -> np.ndarray:
        i = frame_index([s for s, _ in self.series], t)
        if i is None:
            raise LookupError(f"no VTU snapshot at t = {t:g}")
        return read_vtu(self.series[i][1], time=self.series[i][0]).deformed_points


def _measure_impact(case: Case, model: Model, directory: Path, quick: bool,
                    result: CaseResult) -> None:
    result.label, result.rows = compare(directory, case.tolerance)
    t = read_csv_table(directory / "history.csv")["time"]
    if quick:
        result.notes.append(f"Shortened run (to t = {t[-1]:g}): values derived from the "
                            "report's time tables are taken over the same span; quantities "
                            "that need the end of contact are left out if it had not ended.")
    result.images = (plot_all(directory) if not quick else
                     [f(directory) for f in (plot_energies, plot_momenta, plot_deformed,
                                             plot_contact_tractions)])
    overlay = plot_report_overlay(directory, case)
    if overlay is not None:
        result.images.insert(0, overlay)


def _measure_block_sliding(case: Case, model: Model, directory: Path, quick: bool,
                           result: CaseResult) -> None:
    res = _Results(directory)
    t_end = float(res.times()[-1])
    main = res.rows(t_end, "block_foundation")
    x = res.positions(t_end)
    nodes = np.rint(model.X0[main["node_1"], 0] - 5.0).astype(int) + 1  # report numbering
    t_n, t_t = main["normal_traction"], -main["tangential_traction"]  # table's sign
    slip = main["status"] == "slip"
    offset = float(np.abs(x[main["node_1"], 0] - x[main["node_2"], 0]).max())  # tangential
    result.label = "block sliding on a stiff ALE foundation (mu = 0.5), final state"
    result.rows = block_sliding_rows(nodes, t_n, t_t, slip, main["normal_force"],
                                     -main["tangential_force"], offset,
                                     float(main["gap"].max()))
    result.data = {"nodes": nodes, "t_n": t_n, "t_t": t_t, "slip": slip}
    result.images = [plot_block_sliding(directory, nodes, t_n, t_t, slip),
                     *_quasi_static_plots(directory, quick)]


HERTZ_SNAPSHOTS = {5.0: 4.0 / 15.0, 11.0: 9.0 / 15.0, 18.0: 1.0}  # examples/hertz.toml holds


def hertz_snapshots(model: Model, directory: Path) -> list[HertzSnapshot]:
    """The report's load levels (26.7, 60, 100 %) that the run of ``model`` reached."""
    res = _Results(directory)
    cylinder = model.body("cylinder")
    chain = surface_chain(cylinder.mesh, "arc").nodes + cylinder.node_offset
    lengths = np.zeros(model.n_nodes)
    lengths[chain] = nodal_tributary_lengths(model.X0[chain], closed=False)
    top = model.body("foundation").global_nodes("top")
    out = []
    for t, fraction in HERTZ_SNAPSHOTS.items():
        if not res.has(t):
            continue
        rows, x = res.rows(t), res.positions(t)
        X = model.X0[rows["node_1"], 0]
        order = np.argsort(X)
        rows = {k: v[order] for k, v in rows.items()}
        n1 = rows["node_1"]
        # the vertical force on the cylinder, -(f_N n + f_T e) . e_y with the pairs' own
        # normals (the foundation's, as the arc faces an ALE surface; e = (-n_y, n_x))
        n, _, _ = pair_gaps(x, model.interfaces[0].interface,
                            np.column_stack([n1, rows["node_2"]]))
        vertical = -(rows["normal_force"] * n[:, 1] + rows["tangential_force"] * n[:, 0])
        arc = chain[~np.isin(chain, n1)]
        force = np.zeros(model.n_nodes)
        force[n1] = rows["normal_force"]
        arc_order = np.argsort(model.X0[chain, 0])
        surface = x[top][np.argsort(x[top, 0])]
        depth = np.interp(x[arc, 0], surface[:, 0], surface[:, 1]) - x[arc, 1]
        out.append(HertzSnapshot(
            fraction, X[order], rows["normal_force"] / lengths[n1], rows["normal_traction"],
            rows["tangential_traction"], rows["status"] == "slip", vertical,
            rows["tangential_force"], float(np.abs(x[n1, 0] - x[rows["node_2"], 0]).max()),
            float(depth.max()) if depth.size else 0.0, model.X0[chain, 0][arc_order],
            force[chain][arc_order]))
    if not out:
        raise LookupError("the run reached none of the report's load levels")
    return out


def _measure_hertz(case: Case, model: Model, directory: Path, quick: bool,
                   result: CaseResult) -> None:
    snaps = hertz_snapshots(model, directory)
    mu, h = case.friction, case.mesh_size
    result.label = (f"Hertz, contact element size {h:g}, "
                    + (f"mu = {mu:g}" if mu else "frictionless"))
    for snap in snaps:
        result.rows += hertz_friction_rows(snap, h, mu) if mu else hertz_rows(snap, h)
    result.data = {"snapshots": snaps}
    result.images = [plot_hertz(directory, snaps, mu), *_quasi_static_plots(directory, quick)]


DELAMINATION_POSITIONS = tuple(  # the report's x = L, 6/7 L, ..., 0 at t = 1, 3, ..., 15
    (1.0 + 2.0 * k, 46.0 - 4.0 * k, "L" if k == 0 else "0" if k == 7 else f"{7 - k}/7 L")
    for k in range(8))


def delamination_positions(model: Model, directory: Path) -> list[DelaminationPosition]:
    res = _Results(directory)
    out = []
    for t, x_load, label in DELAMINATION_POSITIONS:
        if not res.has(t):
            continue
        rows, x = res.rows(t), res.positions(t)
        X1, X2 = model.X0[rows["node_1"], 0], model.X0[rows["node_2"], 0]
        order = np.argsort(X1)
        rows = {k: v[order] for k, v in rows.items()}
        out.append(DelaminationPosition(
            label, x_load, X1[order], X2[order], rows["normal_traction"],
            rows["tangential_traction"], rows["status"] == "stick",
            float(np.abs(x[rows["node_1"], 0] - x[rows["node_2"], 0])[
                rows["normal_traction"] > 0.0].max()),
            float(rows["gap"].max())))
    if not out:
        raise LookupError("the run reached none of the report's load positions")
    return out


def _measure_delamination(case: Case, model: Model, directory: Path, quick: bool,
                          result: CaseResult) -> None:
    positions = delamination_positions(model, directory)
    result.label = "delamination under a moving point load (mu = 0.1)"
    result.rows = delamination_rows(positions)
    result.images = [plot_delamination(directory, positions),
                     *_quasi_static_plots(directory, quick)]


def _quasi_static_plots(directory: Path, quick: bool) -> list[Path]:
    return [plot_deformed(directory)] + ([] if quick else [plot_contact_tractions(directory)])


def run_mesh_motion(case: Case, directory: Path, quick: bool, result: CaseResult) -> None:
    directory.mkdir(parents=True, exist_ok=True)
    out = mesh_motion_example()
    inverted = {s: int(np.count_nonzero((corner_jacobians(out["meshes"][s]) <= 0.0).any(axis=1)))
                for s in SMOOTHERS}
    result.label = "mesh motion of a layer (rebuilt: the report's mesh is not given)"
    result.rows = mesh_motion_rows(out["statistics"], inverted)
    result.images = [plot_table_4_1(directory, out["statistics"]),
                     plot_mesh_motion(directory, out["meshes"])]


#: the measure of each kind of case: (case, its model, its results folder, quick, the result
#: to fill in)
MEASURES: dict[str, Callable[[Case, Model, Path, bool, CaseResult], None]] = {
    "impact": _measure_impact,
    "block_sliding": _measure_block_sliding,
    "hertz": _measure_hertz,
    "delamination": _measure_delamination,
}
