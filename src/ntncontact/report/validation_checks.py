"""The checks of ``ntncontact validate``: comparison rows from measured arrays.

Each function turns the measurements of one case (impact histories, Table 4.1 statistics,
Table 6.1 stresses, Hertz load levels, delamination load positions) into
:class:`~ntncontact.report.reference.Comparison` rows: ours, the report's value and the
tolerance it is checked against, with the reason in its note. They are pure functions of
arrays, tested on synthetic inputs (``tests/test_validation.py``); ``docs/validation.md``
explains each tolerance.
A :class:`CaseResult` holds one case's rows: it passes when the case ran and every checked row
passes.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .reference import (
    HERTZ_LOAD,
    HERTZ_POISSON,
    SMOOTHERS,
    TABLE_4_1_STAGES,
    Comparison,
    fit_hertz_ellipse,
    fit_hertz_nodal_forces,
    hertz_plane_strain,
    smoother_ranking,
    start_of_last_run,
    table,
    table_4_1,
    table_6_1_first_slip_node,
)
from .validation_cases import Case


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
    #: not run, or stopped before its end, by an interruption (``error`` says which)
    interrupted: bool = False

    def checked(self) -> list[Comparison]:
        return [r for r in self.rows if r.checked]

    def passed(self) -> bool:
        """Ran, has checked rows, and every one of them passes."""
        checked = self.checked()
        return self.error is None and bool(checked) and all(r.passed() for r in checked)

    def failed_rows(self) -> list[Comparison]:
        return [r for r in self.checked() if not r.passed()]


#: Table 4.1's measures the smoothers are ranked by, True where larger is better
SMOOTHING_MEASURES = {"min_angle_deg": True, "max_angle_deg": False, "variance_angle": False}


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
    for measure, larger in SMOOTHING_MEASURES.items():
        ours = {s: stats[s][measure] for s in SMOOTHERS}
        rank = " > ".join(names[s] for s in smoother_ranking(ours, larger))
        rank_ref = " > ".join(names[s] for s in smoother_ranking(ref[measure], larger))
        rows.append(Comparison(f"ranking by {measure} (best first)", rank, rank_ref, 0.0,
                               "equal", note="L Laplacian, S simple, W weighted angle-based"))
    for measure, larger in SMOOTHING_MEASURES.items():
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
        for label, key, ours in (("t_N", "normal", t_n), ("t_T", "tangent", t_t)):
            scatter = float(np.abs(t[f"{key}_report"] - t[f"{key}_simo_laursen"]).max())
            rows += [Comparison(f"{label} node {node} vs {name}", float(ours[i]),
                                float(t[f"{key}_{c}"][i]), scatter, "absolute")
                     for c, name in columns]
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


def load_level(fraction: float) -> str:
    return f"{100.0 * fraction:.1f} %"


def hertz_rows(snap: HertzSnapshot, h: float) -> list[Comparison]:
    """Frictionless: half-width and peak pressure vs the plane-strain Hertz formulas. Pressures
    are nodal forces over reference tributary lengths (linear elasticity: the reference
    configuration). Half-width within one contact element h (the pressed zone ends at a node);
    peaks within (h/a)^2 (a nodal value is the tributary average of the pressure, p0 (1 - h^2 /
    (12 a^2)) at the centre, plus the model's finite size). The work-equivalent fit
    (:func:`~ntncontact.report.reference.fit_hertz_nodal_forces`) reads an exact Hertz profile back
    exactly, so only its rows converge with the mesh (also within (h/a)^2)."""
    a, p0 = hertz_plane_strain(snap.load)
    a_fit, p0_fit = snap.fit()
    a_work, p0_work = snap.fit_forces()
    tol_p = (h / a) ** 2
    lvl = load_level(snap.fraction)
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
    lvl = load_level(snap.fraction)
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


def hertz_friction_rows(snap: HertzSnapshot, h: float, mu: float) -> list[Comparison]:
    """With friction (the report compares with ABAQUS only, figures lost): at full load, stick
    at the centre and slip at both edges (report Figs 6.10-6.12; a pair slides when on the
    Coulomb cone within HERTZ_TRACTION_TOLERANCE); at every level the cone, equilibrium and
    node-to-node pairs. The comparison with the frictionless run is made by
    :func:`link_results`."""
    lvl = load_level(snap.fraction)
    on = snap.pressed
    cone = float(np.max(np.abs(snap.t_t[on]) / (mu * snap.t_n[on])))
    rows = []
    if snap.fraction == 1.0:  # the report's figures are at full load
        sliding = on & (mu * snap.t_n - np.abs(snap.t_t) <= HERTZ_TRACTION_TOLERANCE)
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
    lvl = load_level(snap.fraction)
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
    lvl = load_level(snap.fraction)
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
