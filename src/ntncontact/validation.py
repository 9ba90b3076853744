"""``ntncontact validate``: run every example of the report and write a side-by-side report.

Each case is an example of the report: a scenario with overrides (friction, mass type, mesh),
or, for the mesh-motion example of section 4.2, the mesh operation itself. ``quick`` adds
overrides that make each case cheap (shorter time, the first load level); the comparisons are
then made over the same time span or load levels. Every case runs in its own results folder
(two at a time on a machine with two cores); a failing case is reported with its error and the
others still run.

Each case yields comparison rows (:class:`~ntncontact.reference.Comparison`: ours, the report's
value, the difference and a check against a stated tolerance) and figures, with the report's
tabulated values overlaid where it has a table. A case passes when it ran and every checked
row passes. ``docs/validation.md`` explains each tolerance.
"""

from __future__ import annotations

import contextlib
import html
import io
import json
import multiprocessing
import os
import time
import traceback
from collections.abc import Callable
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .reference import (
    HERTZ_LOAD,
    HERTZ_POISSON,
    SMOOTHERS,
    TABLE_4_1_STAGES,
    Comparison,
    compare,
    fit_hertz_ellipse,
    fit_hertz_nodal_forces,
    format_value,
    hertz_plane_strain,
    smoother_ranking,
    start_of_last_run,
    table,
    table_4_1,
    table_6_1_first_slip_node,
    verdict,
)

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"
KINDS = ("impact", "mesh_motion", "block_sliding", "hertz", "delamination")


@dataclass(frozen=True)
class Case:
    name: str
    example: str  # scenario file in examples/ ("" for the mesh-motion example)
    overrides: tuple[str, ...] = ()
    quick: tuple[str, ...] = ()  # extra overrides for --quick
    tolerance: float = 0.05  # impact cases: relative difference allowed on CHECKED quantities
    kind: str = "impact"
    section: str = ""  # of the report
    mesh_size: float = 0.0  # contact element size (Hertz meshes)
    cost: float = 1.0  # rough relative run time: the longest cases start first

    def __post_init__(self) -> None:
        if self.kind not in KINDS:
            raise ValueError(f"case {self.name}: unknown kind {self.kind!r}, expected {KINDS}")

    @property
    def friction(self) -> float:
        return next((float(o.split("=")[1]) for o in self.overrides if "friction" in o), 0.0)


HERTZ_LEVELS = {  # mesh level: (contact element size, overrides) of examples/hertz.toml
    1: (6.0, ()),
    2: (4.0, ("bodies.0.mesh.file=meshes/hertz_cylinder_2.msh", "bodies.1.mesh.nx=75")),
    3: (3.0, ("bodies.0.mesh.file=meshes/hertz_cylinder_3.msh", "bodies.1.mesh.nx=100")),
}
HERTZ_FRICTION = 0.3

CASES: tuple[Case, ...] = (
    Case("rod_impact", "rod_impact.toml", quick=("analysis.t_end=2.5",), tolerance=0.03,
         section="3.2", cost=2.0),
    Case("mesh_motion", "", kind="mesh_motion", section="4.2", cost=0.2),
    Case("block_sliding", "block_sliding.toml", kind="block_sliding", section="6.1", cost=3.0),
    *(
        Case(f"hertz_mesh{level}" + (f"_mu{mu:g}" if mu else ""), "hertz.toml",
             overrides + ((f"contact.0.friction={mu}",) if mu else ()),
             quick=("analysis.t_end=5.0",), kind="hertz", section="6.2", mesh_size=h,
             cost=(3.5, 6.0, 9.5)[level - 1] * (1.2 if mu else 1.0))
        for mu in (0.0, HERTZ_FRICTION) for level, (h, overrides) in HERTZ_LEVELS.items()
    ),
    Case("delamination", "delamination.toml", quick=("analysis.t_end=5.0",),
         kind="delamination", section="6.3", cost=5.5),
    Case("ring_impact", "ring_impact.toml", quick=("analysis.t_end=0.2",), tolerance=0.15,
         section="6.4", cost=27.0),
    *(
        Case(f"fast_sliding_mu{mu:g}_{mass}", "blocks_fast_sliding.toml",
             (f"contact.0.friction={mu}", f'analysis.mass="{mass}"'),
             quick=("analysis.t_end=0.075",), tolerance=0.15, section="6.5", cost=9.0)
        for mu in (0.0, 0.1, 0.2) for mass in ("consistent", "lumped")
    ),
    *(
        Case(f"tilted_blocks_mu{mu:g}", "tilted_blocks.toml", (f"contact.0.friction={mu}",),
             quick=("analysis.t_end=0.1",), tolerance=0.15, section="6.6", cost=7.5)
        for mu in (0.0, 0.2, 10.0)
    ),
)

#: Impact quantities compared with the case's relative tolerance.
CHECKED = ("contact_start_time", "energy_initial", "energy_dissipated_fraction",
           "contact_duration")
#: Impact quantities the report states as bounds of its own drift: ours must not exceed them.
BOUNDS = ("linear_momentum_max_relative_variation", "angular_momentum_max", "max_penetration")


@dataclass
class CaseResult:
    case: Case
    directory: Path
    seconds: float
    error: str | None = None
    label: str = ""
    rows: list[Comparison] = field(default_factory=list)
    images: list[Path] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)
    data: dict = field(default_factory=dict)  # measurements other cases compare with

    def checked(self) -> list[Comparison]:
        return [r for r in self.rows if r.checked]

    def passed(self) -> bool:
        """Ran, has checked rows, and every one of them passes."""
        checked = self.checked()
        return self.error is None and bool(checked) and all(r.passed() for r in checked)

    def failed_rows(self) -> list[Comparison]:
        return [r for r in self.checked() if not r.passed()]


# ----------------------------------------------------------------------------------------------
# Comparison rows (pure functions of measured arrays: tested on synthetic inputs)
# ----------------------------------------------------------------------------------------------
def impact_rows(rows: list[Comparison], tolerance: float, friction: float, dt: float,
                onset: float = 0.0) -> list[Comparison]:
    """The checks of an impact case's headline rows (from :func:`reference.compare`).

    - contact start, initial energy, contact duration, dissipated energy (with friction):
      relative ``tolerance``; the contact start also within one time step ``dt``;
    - ``onset``: for a run stopped during contact (``--quick``), dt / (t_end - t_start): the
      dissipation grows about linearly from the contact start, which either computation knows
      to one time step only, so its share of the dissipation so far is added to the tolerance;
    - with mu = 0 the dissipated fraction is a difference of nearly equal energies: shown only;
      the energy's largest variation is then the report's drift and must not exceed it;
    - momentum drift, largest angular momentum, largest penetration: bounds of the report's
      drift, ours at most the report's (+ ``tolerance``).
    """
    out = []
    for r in rows:
        q = r.quantity
        if q == "contact_start_time":
            r = r.with_check(tolerance, atol=dt * (1.0 + 1e-9),
                             note=f"within {tolerance:.0%} or one time step")
        elif q == "energy_dissipated_fraction" and friction == 0.0:
            r = r.with_check(None, note="frictionless: both near zero; see the energy drift")
        elif q == "energy_dissipated_fraction" and onset:
            r = r.with_check(tolerance + onset, note=f"within {tolerance:.0%} + {onset:.0%} "
                             "(one time step of the sliding so far)")
        elif q in CHECKED:
            r = r.with_check(tolerance, note=f"within {tolerance:.0%}")
        elif q in BOUNDS or (q == "energy_max_relative_variation" and friction == 0.0):
            r = r.with_check(tolerance, mode="at_most", atol=1e-12,
                             note="the report's drift is a bound (+ round-off)")
        out.append(r)
    return out


def mesh_motion_rows(stats: dict[str, dict[str, float]],
                     inverted: dict[str, int]) -> list[Comparison]:
    """Table 4.1 side by side: the smoothers' ranking and repair (checked) and every value
    (shown: the report's mesh is not given, ours is an analogous layer).

    ``stats``: {stage: {measure: value}} for the stages of Table 4.1; ``inverted``: number of
    elements with a non-positive corner Jacobian after each smoother.
    """
    ref = table_4_1()
    rows = []
    names = {"laplacian": "L", "simple_angle_based": "S", "weighted_angle_based": "W"}
    for measure, larger in (("min_angle_deg", True), ("max_angle_deg", False),
                            ("variance_angle", False)):
        ours = {s: stats[s][measure] for s in SMOOTHERS}
        rank = " > ".join(names[s] for s in smoother_ranking(ours, larger))
        rank_ref = " > ".join(names[s] for s in smoother_ranking(ref[measure], larger))
        rows.append(Comparison(f"ranking by {measure} (best first)", rank, rank_ref, 0.0,
                               "equal", note="L Laplacian, S simple, W weighted angle-based"))
    for measure, larger in (("min_angle_deg", True), ("max_angle_deg", False),
                            ("variance_angle", False)):
        sign = 1.0 if larger else -1.0
        for s in SMOOTHERS:
            rows.append(Comparison(
                f"{measure} change by {s} (improvement > 0)",
                sign * (stats[s][measure] - stats["before_smoothing"][measure]),
                sign * (ref[measure][s] - ref[measure]["before_smoothing"]), 0.0, "same_sign",
                note="every smoother repairs the moved mesh"))
    rows.append(Comparison("inverted elements after smoothing", sum(inverted.values()), 0, 0.0,
                           "equal"))
    for measure in ref:
        if measure == "average_angle_deg":
            continue  # 90 degrees for any quadrilateral mesh
        for stage in TABLE_4_1_STAGES:
            rows.append(Comparison(f"{measure}, {stage}", stats[stage][measure],
                                   ref[measure][stage]))
    return rows


def table_6_1_scatter() -> tuple[float, float]:
    """Largest difference between Table 6.1's two columns: normal, tangential stresses."""
    t = table("block_sliding_table_6_1")
    return (float(np.abs(t["normal_report"] - t["normal_simo_laursen"]).max()),
            float(np.abs(t["tangent_report"] - t["tangent_simo_laursen"]).max()))


def block_sliding_rows(nodes: np.ndarray, t_n: np.ndarray, t_t: np.ndarray, slip: np.ndarray,
                       normal_force: np.ndarray, tangential_force: np.ndarray,
                       pair_offset: float, max_gap: float, mu: float = 0.5
                       ) -> list[Comparison]:
    """Table 6.1 side by side (nodes 2-20 in order). ``t_t``, ``tangential_force``: in the
    table's sign convention (the friction force on the block along +x). Tolerances: the largest
    difference between the table's two columns (the report's own scatter)."""
    t = table("block_sliding_table_6_1")
    if not np.array_equal(nodes, t["node"]):
        raise ValueError(f"expected the pairs of nodes 2-20 in order, got nodes {list(nodes)}")
    scatter_n, scatter_t = table_6_1_scatter()
    columns = (("report", "report (NTN)"), ("simo_laursen", "Simo & Laursen"))
    sums = {f"{k}_{c}": float(t[f"{k}_{c}"].sum()) for k in ("normal", "tangent")
            for c, _ in columns}
    arm = nodes - 11.0  # about the block's centre, node 11
    moments = {c: float((arm * t[f"normal_{c}"]).sum()) for c, _ in columns}
    note = "tolerance: the difference between the table's columns"
    rows = []
    for what, ours, key in (("sum of normal forces", normal_force.sum(), "normal"),
                            ("sum of tangential forces", tangential_force.sum(), "tangent")):
        scatter = abs(sums[f"{key}_report"] - sums[f"{key}_simo_laursen"])
        rows += [Comparison(f"{what}, nodes 2-20 vs {name}", float(ours), sums[f"{key}_{c}"],
                            scatter, "absolute", note=note) for c, name in columns]
    rows += [Comparison(f"moment of the normal forces about node 11 vs {name}",
                        float((arm * normal_force).sum()), moments[c],
                        abs(moments["report"] - moments["simo_laursen"]), "absolute", note=note)
             for c, name in columns]
    ours_slip = start_of_last_run(nodes, slip)
    rows.append(Comparison("first sliding node (sticking to its left)",
                           float("nan") if ours_slip is None else float(ours_slip),
                           float(table_6_1_first_slip_node("report")), 1.0, "absolute",
                           note="report's text and both columns: node 16; one node of "
                                "resolution"))
    cone = float(np.max(np.abs(t_t) / (mu * t_n)))
    rows.append(Comparison("max |t_T| / (mu t_N)", cone, 1.0, 1e-9, "at_most",
                           note="Coulomb cone (2.20)"))
    rows.append(Comparison("max tangential pair offset (node to node)", pair_offset, 0.0, 1e-6,
                           "absolute", note="report: pairs stay matched exactly (ALE)"))
    rows.append(Comparison("max gap (penetration > 0)", max_gap, 0.0, 0.0, "at_most", atol=1e-6,
                           note="no penetration beyond the augmentation tolerance"))
    for i, node in enumerate(nodes):
        for key, name in columns:
            rows.append(Comparison(f"t_N node {node} vs {name}", float(t_n[i]),
                                   float(t[f"normal_{key}"][i]), scatter_n, "absolute"))
        for key, name in columns:
            rows.append(Comparison(f"t_T node {node} vs {name}", float(t_t[i]),
                                   float(t[f"tangent_{key}"][i]), scatter_t, "absolute"))
    return rows


@dataclass
class HertzSnapshot:
    """The contact of one load level, pairs sorted by the cylinder nodes' reference X."""

    fraction: float  # of the full load
    X: np.ndarray  # reference x of the cylinder nodes in contact
    p_ref: np.ndarray  # normal force / reference tributary length
    t_n: np.ndarray  # contact.csv tractions (per current length)
    t_t: np.ndarray
    slip: np.ndarray
    vertical_force: np.ndarray  # on the cylinder, per pair
    tangential_force: np.ndarray
    pair_offset: float  # max |x1 - x2| (tangential: along x) over the pairs
    penetration: float  # deepest arc node outside the active set below the foundation's top
    arc_X: np.ndarray  # reference x of every arc node, sorted
    arc_force: np.ndarray  # ... and its normal contact force (0 off the active set)

    @property
    def load(self) -> float:
        return HERTZ_LOAD * self.fraction

    @property
    def pressed(self) -> np.ndarray:
        return self.t_n > 0.0

    def fit(self) -> tuple[float, float]:
        a, p0 = hertz_plane_strain(self.load)
        return fit_hertz_ellipse(self.X[self.pressed], self.p_ref[self.pressed], a, p0)

    def fit_forces(self) -> tuple[float, float]:
        """(a, p0) whose work-equivalent nodal forces match ours (all arc nodes): the
        read-out that converges with the mesh (docs/examples.md, 6.2)."""
        a, p0 = hertz_plane_strain(self.load)
        return fit_hertz_nodal_forces(self.arc_X, self.arc_force, a, p0)

    def edge(self) -> float:
        return float(np.abs(self.X[self.pressed]).max())


def _pct(fraction: float) -> str:
    return f"{100.0 * fraction:.1f} %"


def hertz_rows(snap: HertzSnapshot, h: float) -> list[Comparison]:
    """Frictionless: half-width and peak pressure vs the plane-strain Hertz formulas. Pressures
    are nodal forces over reference tributary lengths (linear elasticity: the reference
    configuration). Half-width within one contact element h (the pressed zone ends at a node);
    peaks within (h/a)^2 (a nodal value is the tributary average of the pressure, p0 (1 - h^2 /
    (12 a^2)) at the centre, plus the model's finite size). The work-equivalent fit
    (:func:`~ntncontact.reference.fit_hertz_nodal_forces`) reads an exact Hertz profile back
    exactly, so only its rows converge with the mesh (also within (h/a)^2)."""
    a, p0 = hertz_plane_strain(snap.load)
    a_fit, p0_fit = snap.fit()
    a_work, p0_work = snap.fit_forces()
    tol_p = (h / a) ** 2
    lvl = _pct(snap.fraction)
    return [
        Comparison(f"half-width a, work-equivalent fit, {lvl}", a_work, a, tol_p,
                   note="Hertz; (h/a)^2"),
        Comparison(f"peak pressure p0, work-equivalent fit, {lvl}", p0_work, p0, tol_p,
                   note="Hertz; (h/a)^2"),
        Comparison(f"half-width a, outermost pressed node, {lvl}", snap.edge(), a, h, "absolute",
                   note="Hertz; one element"),
        Comparison(f"half-width a, ellipse fit, {lvl}", a_fit, a, h, "absolute",
                   note="Hertz; one element"),
        Comparison(f"peak pressure p0, largest nodal value, {lvl}", float(snap.p_ref.max()), p0,
                   tol_p, note="Hertz; (h/a)^2"),
        Comparison(f"peak pressure p0, ellipse fit, {lvl}", p0_fit, p0, tol_p,
                   note="Hertz; (h/a)^2"),
        *_hertz_common_rows(snap, h),
    ]


def _hertz_common_rows(snap: HertzSnapshot, h: float) -> list[Comparison]:
    lvl = _pct(snap.fraction)
    return [
        Comparison(f"vertical contact force, {lvl}", float(snap.vertical_force.sum()), snap.load,
                   1e-6, note="equilibrium with the applied load"),
        Comparison(f"max pair offset / h, {lvl}", snap.pair_offset / h, 0.0, 1e-6, "absolute",
                   note="node to node (ALE foundation)"),
        Comparison(f"deepest arc node outside the active set / h, {lvl}", snap.penetration / h,
                   0.0, 0.0, "at_most", atol=1e-6, note="no missed penetration"),
    ]


#: (1 - 2 nu) / (2 (1 - nu)): how much a tangential traction changes the normal displacement
#: of an elastic half-plane (Dundurs' beta against a rigid flat). With |t_T| <= mu t_N, friction
#: changes the pressure by O(mu beta): the tolerance of the frictional case against the
#: frictionless one.
HERTZ_BETA = (1.0 - 2.0 * HERTZ_POISSON) / (2.0 * (1.0 - HERTZ_POISSON))


#: Tractions of examples/hertz.toml settle to eps_T times the augmentation tolerance,
#: 1e6 * 1e-7, on each side of a pair: a pair within this of the Coulomb cone slides (the
#: return mapping may label it either way).
HERTZ_TRACTION_TOLERANCE = 2.0 * 1.0e6 * 1.0e-7


def hertz_friction_rows(snap: HertzSnapshot, h: float, mu: float,
                        traction_tol: float = HERTZ_TRACTION_TOLERANCE) -> list[Comparison]:
    """With friction (the report compares with ABAQUS only, figures lost): at full load, stick
    at the centre and slip at both edges (report Figs 6.10-6.12; a pair slides when on the
    Coulomb cone within ``traction_tol``); at every level the cone, equilibrium and node-to-node
    pairs. The comparison with the frictionless run is made by :func:`link_results`."""
    lvl = _pct(snap.fraction)
    on = snap.pressed
    cone = float(np.max(np.abs(snap.t_t[on]) / (mu * snap.t_n[on])))
    rows = []
    if snap.fraction == 1.0:  # the report's figures are at full load
        sliding = on & (mu * snap.t_n - np.abs(snap.t_t) <= traction_tol)
        state = np.where(sliding, "slip", "stick")
        centre = int(np.argmin(np.abs(snap.X)))
        sticking = np.abs(snap.X[on & ~sliding])
        rows += [
            Comparison(f"centre pair state, {lvl}", str(state[centre]), "stick", 0.0, "equal",
                       note="Figs 6.10-6.12: stick at the centre"),
            Comparison(f"outermost pressed pairs' state, {lvl}", " / ".join(state[on][[0, -1]]),
                       "slip / slip", 0.0, "equal", note="... slip (on the cone) at the edges"),
            Comparison(f"stick zone half-width |X|, {lvl}",
                       float(sticking.max()) if sticking.size else 0.0, float("nan"),
                       note="figures lost: no number"),
        ]
    return rows + [
        Comparison(f"max |t_T| / (mu t_N), {lvl}", cone, 1.0, 1e-9, "at_most",
                   note="Coulomb cone"),
        Comparison(f"net tangential force / P, {lvl}",
                   float(abs(snap.tangential_force.sum())) / snap.load, 0.0,
                   note="antisymmetric friction would give 0; the active set's history may "
                        "differ on the two sides"),
        *_hertz_common_rows(snap, h),
    ]


def hertz_versus_rows(snap: HertzSnapshot, other: HertzSnapshot, what: str, rel: float,
                      a_tol: float, note: str) -> list[Comparison]:
    """Peak pressure and fitted half-width of ``snap`` against another run's (``other``) at the
    same load level: relative ``rel`` on the peak, ``a_tol`` relative on the half-width."""
    lvl = _pct(snap.fraction)
    a_fit, _ = snap.fit()
    a_other, _ = other.fit()
    return [
        Comparison(f"peak pressure vs {what}, {lvl}", float(snap.p_ref.max()),
                   float(other.p_ref.max()), rel, note=note),
        Comparison(f"half-width (fit) vs {what}, {lvl}", a_fit, a_other, a_tol, note=note),
    ]


#: The load level whose work-equivalent fit must converge at second order: the model's own
#: offset from Hertz (finite a/R and finite body, about 0.25 % at full load) grows with the
#: load, at 26.7 % it is under 0.05 % and the discretization error dominates on all three
#: meshes (docs/examples.md, 6.2).
HERTZ_CONVERGENCE_FRACTION = 4.0 / 15.0


def hertz_convergence_rows(snap: HertzSnapshot, coarse: HertzSnapshot, h: float,
                           h_coarse: float) -> list[Comparison]:
    """Error of the work-equivalent fit (a and p0 against Hertz) on this mesh over mesh 1's:
    second-order convergence means (h / h1)^2; checked (25 % margin) at the lowest load level,
    shown at the others, where the model's offset from Hertz (growing with the load) takes over."""
    a, p0 = hertz_plane_strain(snap.load)
    lvl = _pct(snap.fraction)
    checked = bool(np.isclose(snap.fraction, HERTZ_CONVERGENCE_FRACTION))
    rows = []
    for i, (name, exact) in enumerate((("a", a), ("p0", p0))):
        ours, theirs = snap.fit_forces()[i] - exact, coarse.fit_forces()[i] - exact
        ratio = abs(ours / theirs) if theirs else float("nan")
        rows.append(Comparison(
            f"work-equivalent fit: |error of {name}| / mesh 1's, {lvl}",
            ratio, (h / h_coarse) ** 2, 0.25 if checked else None, "at_most",
            note="second order, (h/h1)^2" if checked else
            "information: the model's offset from Hertz grows with the load"))
    return rows


@dataclass
class DelaminationPosition:
    """The slit's contact with the load at ``x_load`` (pairs sorted by x)."""

    label: str  # the report's name of the position, e.g. "5/7 L"
    x_load: float
    X1: np.ndarray  # reference x of the upper-face node of each pair
    X2: np.ndarray  # ... and of its lower-face partner
    t_n: np.ndarray
    t_t: np.ndarray
    stick: np.ndarray
    pair_offset: float  # max |x1 - x2| (current) of the pressed pairs
    max_gap: float

    @property
    def pressed(self) -> np.ndarray:
        return self.t_n > 0.0


DELAMINATION_H, DELAMINATION_MU = 2.0, 0.1
DELAMINATION_SLIT = (18.0, 46.0)  # first and last candidate pair (examples/delamination.toml)


def delamination_rows(positions: list[DelaminationPosition], h: float = DELAMINATION_H,
                      mu: float = DELAMINATION_MU) -> list[Comparison]:
    """The report's statements on Figs 6.16-6.17 (their numbers are lost) as checks."""
    first, last = DELAMINATION_SLIT
    rows = []
    interior_peaks, centroids = [], []
    for p in positions:
        on = p.pressed
        name = f"P at {p.label} (x = {p.x_load:g})"
        x_peak = float(p.X1[np.argmax(p.t_n)])
        inside = first < p.x_load < last
        rows.append(Comparison(f"pressure peak x, {name}", x_peak, p.x_load,
                               0.0 if inside else h, "absolute",
                               note="the peak moves with the load" + (
                                   "" if inside else "; end pair: next candidate inside")))
        if inside:
            interior_peaks.append(float(p.t_n.max()))
        centroids.append(float((p.X1 * p.t_n).sum() / p.t_n.sum()))
        rows.append(Comparison(f"pairs not node to node, {name}",
                               int(np.count_nonzero(p.X1 != p.X2)), 0, 0.0, "equal"))
        rows.append(Comparison(f"max pair offset / h, {name}", p.pair_offset / h, 0.0, 1e-6,
                               "absolute", note="ALE lower layer: pressed pairs node to node"))
        rows.append(Comparison(f"max |t_T| / (mu t_N), {name}",
                               float(np.max(np.abs(p.t_t[on]) / (mu * p.t_n[on]))), 1.0, 1e-9,
                               "at_most", note="Coulomb cone"))
        rows.append(Comparison(f"max gap, {name}", p.max_gap, 0.0, 0.0, "at_most", atol=1e-6,
                               note="no penetration"))
        rows.append(Comparison(f"sticking pairs, {name}", int(np.count_nonzero(p.stick & on)), 0,
                               2.0, "absolute", note="'all contact pairs are sliding'; the "
                               "zero crossing of t_T under the load may stick"))
        if p.label == "L":
            rows.append(Comparison(f"leftmost closed pair x, {name}", float(p.X1[on].min()),
                                   0.5 * (first + last), 0.0, "at_least",
                                   note="Fig. 6.16a: the left part of the gap stays open"))
        if p.label in ("5/7 L", "4/7 L", "3/7 L"):
            t_t = p.t_t[on]
            signs = np.sign(t_t[np.abs(t_t) > 1e-9 * p.t_n.max()])
            rows.append(Comparison(f"sign changes of t_T, {name}",
                                   int(np.count_nonzero(np.diff(signs))), 1, 0.0, "equal",
                                   note="S shape (Fig. 6.17c-e)"))
        if p.label in ("4/7 L", "3/7 L"):
            more = int(np.count_nonzero(p.t_t[on] > 0) - np.count_nonzero(p.t_t[on] < 0))
            rows.append(Comparison(f"pairs with t_T > 0 minus t_T < 0, {name}", more, 1, 0.0,
                                   "at_least", note="Fig. 6.17d-e: more positive"))
    by_label = {p.label: p for p in positions}
    if "2/7 L" in by_label and "6/7 L" in by_label:
        rows.append(Comparison("rightmost closed pair x at 2/7 L",
                               float(by_label["2/7 L"].X1[by_label["2/7 L"].pressed].max()),
                               float(by_label["6/7 L"].X1[by_label["6/7 L"].pressed].max()) - h,
                               0.0, "at_most", note="Fig. 6.16f: a gap reopens on the right "
                               "(report column: 6/7 L's rightmost closed pair - h)"))
    if len(centroids) >= 2:
        rows.append(Comparison("load positions where the pressure centroid does not move left",
                               int(np.count_nonzero(np.diff(centroids) >= 0.0)), 0, 0.0,
                               "equal", note="the contact zone travels with the load"))
    if len(interior_peaks) >= 2:
        rows.append(Comparison("largest / smallest interior pressure peak",
                               max(interior_peaks) / min(interior_peaks), 1.0, 0.10,
                               note="'the maximum quantity remains unchanged': within 10 %"))
    return rows


# ----------------------------------------------------------------------------------------------
# Running the cases
# ----------------------------------------------------------------------------------------------
def _overrides(case: Case, quick: bool) -> list[str]:
    return list(case.overrides) + (list(case.quick) if quick else [])


def _run_scenario(case: Case, directory: Path, quick: bool) -> None:
    """The case's scenario through the CLI's own code path."""
    from .cli import main

    args = ["run", str(EXAMPLES / case.example), "--out", str(directory), "--quiet",
            "--overwrite"]  # validate reruns every case
    for item in _overrides(case, quick):
        args += ["--set", item]
    with contextlib.redirect_stdout(io.StringIO()):
        code = main(args)
    if code != 0:
        summary = directory / "summary.json"
        raise RuntimeError(summary.read_text() if summary.is_file() else "run failed")


def _model(case: Case, quick: bool):
    """The case's model (reference coordinates, bodies, surfaces), not run."""
    from .builder import build_model
    from .io.scenario import load_scenario

    return build_model(load_scenario(EXAMPLES / case.example, _overrides(case, quick)),
                       EXAMPLES)


class _Results:
    """contact.csv rows and VTU positions of a results folder at chosen times."""

    def __init__(self, directory: Path) -> None:
        from .io.vtk import read_pvd
        from .io.writers import read_csv_table

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
        from .io.vtk import read_vtu

        times = np.array([s for s, _ in self.series])
        i = int(np.argmin(np.abs(times - t)))
        if abs(times[i] - t) > 1e-9:
            raise LookupError(f"no VTU snapshot at t = {t:g}")
        return read_vtu(self.series[i][1], time=times[i]).deformed_points


def _measure_impact(case: Case, directory: Path, quick: bool, result: CaseResult) -> None:
    from .io.writers import read_csv_table

    result.label, rows = compare(directory)
    t = read_csv_table(directory / "history.csv")["time"]
    dt = float(t[1] - t[0]) if len(t) > 1 else 0.0
    summary = json.loads((directory / "summary.json").read_text())
    start, end = summary.get("contact_start_time"), summary.get("contact_end_time")
    onset = 0.0
    if start is not None and end is not None and abs(end - t[-1]) <= 1e-9 and t[-1] > start:
        onset = dt / (float(t[-1]) - start)  # stopped during contact
    result.rows = impact_rows(rows, case.tolerance, case.friction, dt, onset)
    if quick:
        result.notes.append(f"Shortened run (to t = {t[-1]:g}): values derived from the "
                            "report's time tables are taken over the same span; quantities "
                            "that need the end of contact are left out if it had not ended.")
    result.images = _impact_plots(directory, quick)
    overlay = plot_report_overlay(directory, case)
    if overlay is not None:
        result.images.insert(0, overlay)


def _impact_plots(directory: Path, quick: bool) -> list[Path]:
    from .plotting import (
        plot_all,
        plot_contact_tractions,
        plot_deformed,
        plot_energies,
        plot_momenta,
    )

    if not quick:
        return plot_all(directory)
    return [f(directory) for f in (plot_energies, plot_momenta, plot_deformed,
                                   plot_contact_tractions)]


def _measure_block_sliding(case: Case, directory: Path, quick: bool,
                           result: CaseResult) -> None:
    model = _model(case, quick)
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


def hertz_snapshots(case: Case, directory: Path, quick: bool) -> list[HertzSnapshot]:
    """The report's load levels (26.7, 60, 100 %) that the run reached."""
    from .mesh.boundary import nodal_tributary_lengths, surface_chain

    model = _model(case, quick)
    res = _Results(directory)
    cylinder = model.body("cylinder")
    chain = surface_chain(cylinder.mesh, "arc").nodes + cylinder.node_offset
    lengths = np.zeros(model.n_nodes)
    lengths[chain] = nodal_tributary_lengths(model.X0[chain], closed=False)
    where = np.full(model.n_nodes, -1)
    where[chain] = np.arange(len(chain))
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
        # the vertical force on the cylinder, -(f_N n + f_T e) . e_y with the body-1 normal
        # n = rot(-90)(x_next - x_prev) / |.| of the deformed arc (e = (-n_y, n_x))
        k = where[n1]
        chord = x[chain[k + 1]] - x[chain[k - 1]]
        n = np.column_stack([chord[:, 1], -chord[:, 0]]) / np.linalg.norm(chord, axis=1)[:, None]
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


def _measure_hertz(case: Case, directory: Path, quick: bool, result: CaseResult) -> None:
    snaps = hertz_snapshots(case, directory, quick)
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


def delamination_positions(case: Case, directory: Path, quick: bool
                           ) -> list[DelaminationPosition]:
    model = _model(case, quick)
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


def _measure_delamination(case: Case, directory: Path, quick: bool,
                          result: CaseResult) -> None:
    positions = delamination_positions(case, directory, quick)
    result.label = "delamination under a moving point load (mu = 0.1)"
    result.rows = delamination_rows(positions)
    result.images = [plot_delamination(directory, positions),
                     *_quasi_static_plots(directory, quick)]


def _quasi_static_plots(directory: Path, quick: bool) -> list[Path]:
    from .plotting import plot_contact_tractions, plot_deformed

    return [plot_deformed(directory)] + ([] if quick else [plot_contact_tractions(directory)])


def _run_mesh_motion(case: Case, directory: Path, quick: bool, result: CaseResult) -> None:
    from .ale.example_mesh_motion import mesh_motion_example
    from .mesh.quality import corner_jacobians

    directory.mkdir(parents=True, exist_ok=True)
    out = mesh_motion_example()
    inverted = {s: int(np.count_nonzero((corner_jacobians(out["meshes"][s]) <= 0.0).any(axis=1)))
                for s in SMOOTHERS}
    result.label = "mesh motion of a layer (rebuilt: the report's mesh is not given)"
    result.rows = mesh_motion_rows(out["statistics"], inverted)
    result.images = [plot_table_4_1(directory, out["statistics"]),
                     plot_mesh_motion(directory, out["meshes"])]


MEASURES: dict[str, Callable[[Case, Path, bool, CaseResult], None]] = {
    "impact": _measure_impact,
    "block_sliding": _measure_block_sliding,
    "hertz": _measure_hertz,
    "delamination": _measure_delamination,
}


def run_case(case: Case, out: Path, quick: bool) -> CaseResult:
    """Run and measure one case; never raises (an error is recorded in the result)."""
    directory = out / case.name
    start = time.perf_counter()
    result = CaseResult(case, directory, 0.0)
    try:
        if case.kind == "mesh_motion":
            _run_mesh_motion(case, directory, quick, result)
        else:
            _run_scenario(case, directory, quick)
            MEASURES[case.kind](case, directory, quick, result)
    except Exception as err:  # a failed case is reported, the others go on
        result.error = f"{type(err).__name__}: {err}\n{traceback.format_exc(limit=4)}"
    result.seconds = time.perf_counter() - start
    return result


def link_results(results: list[CaseResult]) -> None:
    """Comparisons between cases: the finer Hertz meshes against mesh 1 ("all three meshes
    yield identical normal pressures"), each frictional Hertz case against the frictionless
    one on the same mesh (tolerance mu beta, see :data:`HERTZ_BETA`)."""
    hertz = {(r.case.mesh_size, r.case.friction): r for r in results
             if r.case.kind == "hertz"}
    h1 = HERTZ_LEVELS[1][0]
    for (h, mu), r in hertz.items():
        if r.error is not None:
            continue
        ref_key = (h1, 0.0) if mu == 0.0 else (h, 0.0)
        if ref_key == (h, mu):
            continue
        ref = hertz.get(ref_key)
        what = "mesh 1" if mu == 0.0 else "frictionless"
        if ref is None or ref.error is not None:
            r.notes.append(f"No comparison with {what}: that case "
                           f"{'is not in this run' if ref is None else 'failed'}.")
            continue
        theirs = {s.fraction: s for s in ref.data["snapshots"]}
        for snap in r.data["snapshots"]:
            other = theirs.get(snap.fraction)
            if other is None:
                continue
            a, _ = hertz_plane_strain(snap.load)
            if mu == 0.0:
                r.rows += hertz_versus_rows(
                    snap, other, what, h1**2 / (12.0 * a**2), h1 / a,
                    "report: identical pressures on all meshes; mesh 1's averaging error "
                    "h^2/(12 a^2), one mesh-1 element on a")
                r.rows += hertz_convergence_rows(snap, other, h, h1)
            else:
                r.rows += hertz_versus_rows(
                    snap, other, what, mu * HERTZ_BETA, mu * HERTZ_BETA,
                    f"friction changes the pressure by O(mu beta) = {mu * HERTZ_BETA:.3f}")
        if mu:
            with contextlib.suppress(Exception):  # a figure must not fail the comparison
                r.images.insert(1, plot_hertz_versus(r.directory, r.data["snapshots"],
                                                     ref.data["snapshots"], mu))


def default_jobs(n_cases: int) -> int:
    """Worker processes: one per core, at most two (the cases are single-threaded solves)."""
    return max(1, min(n_cases, os.cpu_count() or 1, 2))


@dataclass
class RunInfo:
    quick: bool
    wall_seconds: float
    jobs: int
    cpus: int
    load_before: float
    load_after: float

    def text(self, results: list[CaseResult]) -> str:
        passed = sum(r.passed() for r in results)
        return (f"Mode: {'quick (shortened runs)' if self.quick else 'full'}. "
                f"{passed} of {len(results)} cases passed. Wall time {self.wall_seconds:.0f} s "
                f"with {self.jobs} worker process{'es' if self.jobs > 1 else ''} on "
                f"{self.cpus} cores (sum of the case times "
                f"{sum(r.seconds for r in results):.0f} s; 1-minute load average "
                f"{self.load_before:.1f} before, {self.load_after:.1f} after).")


def validate(out: str | Path, quick: bool = False, cases: tuple[Case, ...] = CASES,
             progress: Callable[[str], None] | None = None,
             jobs: int | None = None) -> list[CaseResult]:
    """Run ``cases`` (``jobs`` at a time; default :func:`default_jobs`), compare, and write
    ``out``/report.md and report.html. ``progress(name)`` is called as each case finishes."""
    out = Path(out).resolve()
    out.mkdir(parents=True, exist_ok=True)
    jobs = default_jobs(len(cases)) if jobs is None else max(1, jobs)
    load_before = os.getloadavg()[0]
    start = time.perf_counter()
    results: list[CaseResult | None] = [None] * len(cases)
    if jobs == 1:
        for i, case in enumerate(cases):
            results[i] = run_case(case, out, quick)
            if progress:
                progress(case.name)
    else:
        order = sorted(range(len(cases)), key=lambda i: -cases[i].cost)
        context = multiprocessing.get_context("spawn")  # no state inherited from the caller
        with ProcessPoolExecutor(jobs, mp_context=context) as pool:
            futures = {pool.submit(run_case, cases[i], out, quick): i for i in order}
            for future in as_completed(futures):
                i = futures[future]
                try:
                    results[i] = future.result()
                except Exception as err:  # the worker died: the case failed, the rest go on
                    results[i] = CaseResult(cases[i], out / cases[i].name, 0.0,
                                            error=f"{type(err).__name__}: {err}")
                if progress:
                    progress(cases[i].name)
    done = [r for r in results if r is not None]
    link_results(done)
    info = RunInfo(quick, time.perf_counter() - start, jobs, os.cpu_count() or 1, load_before,
                   os.getloadavg()[0])
    write_markdown(out / "report.md", done, quick, info)
    write_html(out / "report.html", done, quick, info)
    return done


# ----------------------------------------------------------------------------------------------
# Figures
# ----------------------------------------------------------------------------------------------
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
    from .io.writers import read_csv_table
    from .plotting import _new_figure, _save

    spec = _energy_column(case)
    if spec is None:
        return None
    name, tcol, ecol = spec
    ref = table(name)
    ours = read_csv_table(directory / "history.csv")
    fig, axes = _new_figure(1, 1)
    ax = axes[0, 0]
    ax.plot(ours["time"], ours["total_energy"], "-", label="ntncontact")
    ax.plot(ref[tcol], ref[ecol], "o", ms=4, label=f"report ({name.split('_table_')[1]})")
    ax.set_xlabel("time")
    ax.set_ylabel("total energy")
    ax.grid(True, alpha=0.3)
    ax.legend()
    return _save(fig, directory / "energy_vs_report.png")


def plot_block_sliding(directory: Path, nodes: np.ndarray, t_n: np.ndarray, t_t: np.ndarray,
                       slip: np.ndarray) -> Path:
    """Contact stresses vs node number over Table 6.1 (report Fig. 6.4)."""
    from .plotting import _new_figure, _save

    t = table("block_sliding_table_6_1")
    fig, axes = _new_figure(1, 1, size=(7.0, 4.8))
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
    ax.set_xlabel("node number")
    ax.set_ylabel("contact stress")
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize="x-small", ncol=2)
    return _save(fig, directory / "table_6_1_stresses.png")


def plot_hertz(directory: Path, snaps: list[HertzSnapshot], mu: float) -> Path:
    """Pressure (nodal force / reference length) over the Hertz ellipses; t_T with friction."""
    from .plotting import _new_figure, _save

    fig, axes = _new_figure(2 if mu else 1, 1, size=(7.0, 6.5 if mu else 4.5))
    ax = axes[0, 0]
    for snap in snaps:
        a, p0 = hertz_plane_strain(snap.load)
        xs = np.linspace(-a, a, 201)
        line = ax.plot(snap.X, snap.p_ref, "o", ms=4, label=f"ntncontact, {_pct(snap.fraction)}")
        ax.plot(xs, p0 * np.sqrt(1.0 - (xs / a) ** 2), "--", color=line[0].get_color(),
                label=f"Hertz, {_pct(snap.fraction)}")
        if mu:
            axes[1, 0].plot(snap.X, snap.t_t, "o-", ms=3, color=line[0].get_color(),
                            label=_pct(snap.fraction))
    ax.set_ylabel("contact pressure (reference length)")
    ax.set_xlabel("X")
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize="x-small")
    if mu:
        axes[1, 0].set_ylabel("tangential traction t_T")
        axes[1, 0].set_xlabel("X")
        axes[1, 0].grid(True, alpha=0.3)
        axes[1, 0].legend(fontsize="x-small")
    return _save(fig, directory / "hertz_pressure.png")


def plot_hertz_versus(directory: Path, snaps: list[HertzSnapshot],
                      frictionless: list[HertzSnapshot], mu: float) -> Path:
    from .plotting import _new_figure, _save

    fig, axes = _new_figure(1, 1)
    ax = axes[0, 0]
    theirs = {s.fraction: s for s in frictionless}
    for snap in snaps:
        if snap.fraction not in theirs:
            continue
        line = ax.plot(snap.X, snap.p_ref, "o-", ms=4, label=f"mu = {mu:g}, "
                       f"{_pct(snap.fraction)}")
        other = theirs[snap.fraction]
        ax.plot(other.X, other.p_ref, "x--", ms=4, color=line[0].get_color(),
                label=f"frictionless, {_pct(snap.fraction)}")
    ax.set_xlabel("X")
    ax.set_ylabel("contact pressure (reference length)")
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize="x-small")
    return _save(fig, directory / "hertz_vs_frictionless.png")


def plot_delamination(directory: Path, positions: list[DelaminationPosition]) -> Path:
    """Contact tractions along the slit at each load position (report Fig. 6.17)."""
    from .plotting import _new_figure, _save

    ncols = min(4, len(positions))
    nrows = -(-len(positions) // ncols)
    fig, axes = _new_figure(nrows, ncols, size=(3.2 * ncols + 0.5, 2.8 * nrows))
    for ax, p in zip(axes.flat, positions, strict=False):
        ax.plot(p.X1, p.t_n, "o-", ms=3, label="normal")
        ax.plot(p.X1, p.t_t, "s-", ms=3, label="tangential")
        ax.axvline(p.x_load, color="0.4", ls="--", lw=1)
        ax.set_title(f"P at {p.label} (x = {p.x_load:g})", fontsize="small")
        ax.set_xlim(DELAMINATION_SLIT[0] - 3, DELAMINATION_SLIT[1] + 3)
        ax.grid(True, alpha=0.3)
    for ax in list(axes.flat)[len(positions):]:
        ax.set_visible(False)
    axes[0, 0].legend(fontsize="x-small")
    return _save(fig, directory / "delamination_tractions.png")


TABLE_4_1_PLOTTED = (("min_angle_deg", "minimum angle (deg)"),
                     ("max_angle_deg", "maximum angle (deg)"),
                     ("variance_angle", "variance of angle"),
                     ("variance_edge", "variance of edge length"))


def plot_table_4_1(directory: Path, stats: dict[str, dict[str, float]]) -> Path:
    """Table 4.1's statistics as bars, ours beside the report's."""
    from .plotting import _new_figure, _save

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

    from .plotting import _new_figure, _save

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


# ----------------------------------------------------------------------------------------------
# Reports
# ----------------------------------------------------------------------------------------------
def _status(result: CaseResult) -> str:
    return "PASS" if result.passed() else "FAIL"


def _summary_counts(result: CaseResult) -> str:
    checked = result.checked()
    if result.error is not None:
        return "error"
    return f"{sum(bool(r.passed()) for r in checked)}/{len(checked)}"


def _scenario_text(case: Case) -> str:
    if not case.example:
        return "ntncontact.ale.example_mesh_motion"
    return f"{case.example} {' '.join(case.overrides)}".strip()


def results_table_md(results: list[CaseResult]) -> list[str]:
    """The summary table (also pasted into docs/validation.md)."""
    lines = ["| case | report | status | checks passed | time (s) | failed checks |",
             "| --- | --- | --- | --- | --- | --- |"]
    for r in results:
        failed = ", ".join(f.quantity for f in r.failed_rows()[:4])
        if len(r.failed_rows()) > 4:
            failed += f", ... ({len(r.failed_rows())} in all)"
        if r.error is not None:
            failed = r.error.splitlines()[0][:80]
        lines.append(f"| {r.case.name} | {r.case.section} | {_status(r)} | {_summary_counts(r)}"
                     f" | {r.seconds:.1f} | {failed} |")
    return lines


ROW_HEADER = ("quantity", "ours", "report", "difference", "rel. difference", "tolerance",
              "result", "note")


def _row_cells(r: Comparison) -> list[str]:
    rel = "" if not np.isfinite(r.relative) else f"{r.relative:.2%}"
    diff = "" if not np.isfinite(r.difference) else f"{r.difference:.4g}"
    return [r.quantity, format_value(r.ours), format_value(r.report), diff, rel,
            r.tolerance_text(), verdict(r), r.note]


def write_markdown(path: Path, results: list[CaseResult], quick: bool,
                   info: RunInfo | None = None) -> None:
    lines = ["# ntncontact validation against Xu & Hjelmstad's report", ""]
    lines += [info.text(results) if info else
              f"Mode: {'quick (shortened runs)' if quick else 'full'}.", ""]
    lines += results_table_md(results) + [""]
    for r in results:
        lines += [f"## {r.case.name}: {_status(r)}", "",
                  f"Report section {r.case.section}; `{_scenario_text(r.case)}`"
                  f"{' + ' + ' '.join(r.case.quick) if quick and r.case.quick else ''}; "
                  f"{r.seconds:.1f} s. {r.label}", ""]
        lines += [f"- {n}" for n in r.notes] + ([""] if r.notes else [])
        if r.error:
            lines += ["```", r.error.strip(), "```", ""]
            continue
        lines += ["| " + " | ".join(ROW_HEADER) + " |", "|" + " --- |" * len(ROW_HEADER)]
        lines += ["| " + " | ".join(cell.replace("|", "\\|") for cell in _row_cells(c)) + " |"
                  for c in r.rows]
        lines.append("")
        lines += [f"![{p.stem}]({p.relative_to(path.parent).as_posix()})" for p in r.images]
        lines.append("")
    path.write_text("\n".join(lines))


def write_html(path: Path, results: list[CaseResult], quick: bool,
               info: RunInfo | None = None) -> None:
    esc = html.escape
    parts = ["<!doctype html><html><head><meta charset='utf-8'>",
             "<title>ntncontact validation</title><style>body{font-family:sans-serif;"
             "max-width:1200px;margin:auto}table{border-collapse:collapse;margin:6px 0}"
             "td,th{border:1px solid #aaa;padding:2px 8px;font-size:90%}"
             ".PASS,.pass{color:green}.FAIL{color:#b00;font-weight:bold}.info{color:#777}"
             "img{max-width:560px;margin:4px}</style></head><body>",
             "<h1>ntncontact validation against Xu &amp; Hjelmstad's report</h1>",
             f"<p>{esc(info.text(results)) if info else ('Mode: quick' if quick else 'full')}"
             "</p>", "<table><tr><th>case</th><th>report</th><th>status</th>"
             "<th>checks passed</th><th>time (s)</th></tr>"]
    for r in results:
        status = _status(r)
        parts.append(f"<tr><td><a href='#{esc(r.case.name)}'>{esc(r.case.name)}</a></td>"
                     f"<td>{esc(r.case.section)}</td><td class='{status}'>{status}</td>"
                     f"<td>{_summary_counts(r)}</td><td>{r.seconds:.1f}</td></tr>")
    parts.append("</table>")
    for r in results:
        status = _status(r)
        parts.append(f"<section id='{esc(r.case.name)}'><h2>{esc(r.case.name)}: "
                     f"<span class='{status}'>{status}</span></h2>")
        parts.append(f"<p>Report section {esc(r.case.section)}; "
                     f"<code>{esc(_scenario_text(r.case))}</code>"
                     f"{esc(' + ' + ' '.join(r.case.quick)) if quick and r.case.quick else ''}"
                     f"; {r.seconds:.1f} s. {esc(r.label)}</p>")
        if r.notes:
            parts.append("<ul>" + "".join(f"<li>{esc(n)}</li>" for n in r.notes) + "</ul>")
        if r.error:
            parts.append(f"<pre>{esc(r.error)}</pre></section>")
            continue
        parts.append("<table><tr>" + "".join(f"<th>{h}</th>" for h in ROW_HEADER) + "</tr>")
        for c in r.rows:
            cells = _row_cells(c)
            parts.append("<tr>" + "".join(
                f"<td class='{esc(cell)}'>{esc(cell)}</td>" if i == 6 else f"<td>{esc(cell)}</td>"
                for i, cell in enumerate(cells)) + "</tr>")
        parts.append("</table>")
        for p in r.images:
            parts.append(f"<img src='{esc(p.relative_to(path.parent).as_posix())}' "
                         f"alt='{esc(p.stem)}'>")
        parts.append("</section>")
    # marks each image once the browser has decoded it (checked by a headless-browser test)
    parts.append("<script>window.addEventListener('load',()=>{let n=0;"
                 "document.querySelectorAll('img').forEach(i=>{if(i.naturalWidth>0){"
                 "i.dataset.loaded='yes';n++}});document.body.dataset.imagesLoaded=n;});"
                 "</script>")
    parts.append("</body></html>")
    path.write_text("\n".join(parts))
