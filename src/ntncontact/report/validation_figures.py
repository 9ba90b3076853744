"""The figures of ``ntncontact validate``: our results over the report's tables."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..io.writers import read_csv_table
from .plotting import _new_figure, _panels, _save
from .reference import (
    TABLE_4_1_STAGES,
    hertz_plane_strain,
    table,
    table_4_1,
    table_6_1_first_slip_node,
)
from .validation_cases import Case
from .validation_checks import DELAMINATION_SLIT, DelaminationPosition, HertzSnapshot, load_level


#: (reference table, column) of the total energy the report tabulates for each example/case.
def _energy_column(case: Case) -> tuple[str, str, str] | None:
    friction = case.friction
    mass = "lumped" if any("lumped" in o for o in case.overrides) else "consistent"
    if case.example == "blocks_fast_sliding.toml":
        return "blocks_fast_sliding_table_6_8", "time", f"mu{friction:g}_{mass}"
    if case.example == "tilted_blocks.toml":
        return "tilted_blocks_table_6_10", "time", f"mu{friction:g}_total_energy"
    if case.example == "ring_impact.toml":
        return "ring_impact_table_6_4", "time", "total_energy"
    return None


def plot_report_overlay(directory: Path, case: Case) -> Path | None:
    """Our total energy history over the report's tabulated one."""
    spec = _energy_column(case)
    if spec is None:
        return None
    name, tcol, ecol = spec
    ref = table(name)
    ours = read_csv_table(directory / "history.csv")
    fig, axes = _new_figure(1, 1, grid=True)
    ax = axes[0, 0]
    ax.plot(ours["time"], ours["total_energy"], "-", label="ntncontact")
    ax.plot(ref[tcol], ref[ecol], "o", ms=4, label=f"report ({name.split('_table_')[1]})")
    ax.set(xlabel="time", ylabel="total energy")
    ax.legend()
    return _save(fig, directory / "energy_vs_report.png")


def plot_block_sliding(directory: Path, nodes: np.ndarray, t_n: np.ndarray, t_t: np.ndarray,
                       slip: np.ndarray) -> Path:
    """Contact stresses vs node number over Table 6.1 (report Fig. 6.4)."""
    t = table("block_sliding_table_6_1")
    fig, axes = _new_figure(1, 1, size=(7.0, 4.8), grid=True)
    ax = axes[0, 0]
    for ours, key, name in ((t_n, "normal", "normal"), (t_t, "tangent", "tangential")):
        line = ax.plot(nodes, ours, "-", lw=1.5, label=f"{name}, ntncontact")[0]
        ax.plot(t["node"], t[f"{key}_report"], "o", ms=5, mfc="none", color=line.get_color(),
                label=f"{name}, report (Table 6.1)")
        ax.plot(t["node"], t[f"{key}_simo_laursen"], "x", ms=5, color=line.get_color(),
                label=f"{name}, Simo & Laursen")
    ax.plot(nodes[slip], t_t[slip], "s", ms=7, mfc="none", color="k", label="sliding (ours)")
    ax.axvline(table_6_1_first_slip_node("report") - 0.5, color="0.5", ls="--",
               label="report's slip boundary")
    ax.set(xlabel="node number", ylabel="contact stress")
    ax.legend(fontsize="x-small", ncol=2)
    return _save(fig, directory / "table_6_1_stresses.png")


def plot_hertz(directory: Path, snaps: list[HertzSnapshot], mu: float) -> Path:
    """Pressure (nodal force / reference length) over the Hertz ellipses; t_T with friction."""
    fig, axes = _new_figure(2 if mu else 1, 1, size=(7.0, 6.5 if mu else 4.5), grid=True)
    ax = axes[0, 0]
    for snap in snaps:
        a, p0 = hertz_plane_strain(snap.load)
        xs = np.linspace(-a, a, 201)
        line = ax.plot(snap.X, snap.p_ref, "o", ms=4,
                       label=f"ntncontact, {load_level(snap.fraction)}")
        ax.plot(xs, p0 * np.sqrt(1.0 - (xs / a) ** 2), "--", color=line[0].get_color(),
                label=f"Hertz, {load_level(snap.fraction)}")
        if mu:
            axes[1, 0].plot(snap.X, snap.t_t, "o-", ms=3, color=line[0].get_color(),
                            label=load_level(snap.fraction))
    ax.set(ylabel="contact pressure (reference length)", xlabel="X")
    ax.legend(fontsize="x-small")
    if mu:
        axes[1, 0].set(ylabel="tangential traction t_T", xlabel="X")
        axes[1, 0].legend(fontsize="x-small")
    return _save(fig, directory / "hertz_pressure.png")


def plot_hertz_versus(directory: Path, snaps: list[HertzSnapshot],
                      frictionless: list[HertzSnapshot], mu: float) -> Path:
    fig, axes = _new_figure(1, 1, grid=True)
    ax = axes[0, 0]
    theirs = {s.fraction: s for s in frictionless}
    for snap in snaps:
        if snap.fraction not in theirs:
            continue
        line = ax.plot(snap.X, snap.p_ref, "o-", ms=4, label=f"mu = {mu:g}, "
                       f"{load_level(snap.fraction)}")
        other = theirs[snap.fraction]
        ax.plot(other.X, other.p_ref, "x--", ms=4, color=line[0].get_color(),
                label=f"frictionless, {load_level(snap.fraction)}")
    ax.set(xlabel="X", ylabel="contact pressure (reference length)")
    ax.legend(fontsize="x-small")
    return _save(fig, directory / "hertz_vs_frictionless.png")


def plot_delamination(directory: Path, positions: list[DelaminationPosition]) -> Path:
    """Contact tractions along the slit at each load position (report Fig. 6.17)."""
    fig, axes = _panels(len(positions), 4, (3.2, 2.8), 0.5, grid=True)
    for ax, p in zip(axes.flat, positions, strict=False):
        ax.plot(p.X1, p.t_n, "o-", ms=3, label="normal")
        ax.plot(p.X1, p.t_t, "s-", ms=3, label="tangential")
        ax.axvline(p.x_load, color="0.4", ls="--", lw=1)
        ax.set_title(f"P at {p.label} (x = {p.x_load:g})", fontsize="small")
        ax.set_xlim(DELAMINATION_SLIT[0] - 3, DELAMINATION_SLIT[1] + 3)
    axes[0, 0].legend(fontsize="x-small")
    return _save(fig, directory / "delamination_tractions.png")


TABLE_4_1_PLOTTED = (("min_angle_deg", "minimum angle (deg)"),
                     ("max_angle_deg", "maximum angle (deg)"),
                     ("variance_angle", "variance of angle"),
                     ("variance_edge", "variance of edge length"))


def plot_table_4_1(directory: Path, stats: dict[str, dict[str, float]]) -> Path:
    """Table 4.1's statistics as bars, ours beside the report's."""
    ref = table_4_1()
    fig, axes = _new_figure(2, 2, size=(9.0, 6.0))
    x = np.arange(len(TABLE_4_1_STAGES))
    labels = ["original", "before", "Laplacian", "SABS", "WABS"]
    for ax, (measure, title) in zip(axes.flat, TABLE_4_1_PLOTTED, strict=True):
        ax.bar(x - 0.2, [stats[s][measure] for s in TABLE_4_1_STAGES], 0.4, label="ntncontact")
        ax.bar(x + 0.2, [ref[measure][s] for s in TABLE_4_1_STAGES], 0.4,
               label="report (Table 4.1)")
        ax.set_xticks(x, labels, fontsize="small")
        ax.set_title(title, fontsize="small")
        ax.grid(True, axis="y", alpha=0.3)
    axes[0, 0].legend(fontsize="x-small")
    return _save(fig, directory / "table_4_1.png")


def plot_mesh_motion(directory: Path, meshes: dict) -> Path:
    """The layer at each stage (report Fig. 4.10)."""
    from matplotlib.collections import PolyCollection

    fig, axes = _new_figure(3, 2, size=(10.0, 5.5))
    for ax, (stage, mesh) in zip(axes.flat, meshes.items(), strict=False):
        ax.add_collection(PolyCollection(mesh.nodes[mesh.cells], facecolors="none",
                                         edgecolors="k", linewidths=0.4))
        low, high = mesh.nodes.min(axis=0), mesh.nodes.max(axis=0)
        pad = 0.02 * float(np.max(high - low))
        ax.set_xlim(low[0] - pad, high[0] + pad)
        ax.set_ylim(low[1] - pad, high[1] + pad)
        ax.set_aspect("equal")
        ax.set_title(stage.replace("_", " "), fontsize="small")
        ax.set_xticks([])
        ax.set_yticks([])
    return _save(fig, directory / "mesh_motion.png")
