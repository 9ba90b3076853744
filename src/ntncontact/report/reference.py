"""The report's published numbers and a side-by-side comparison with a results folder.

The tables (report 4.1, 6.1, 6.4, 6.7, 6.8, 6.10) ship as CSV files in ``ntncontact/data``
(transcribed from the report; see ``data/README.md`` for the report's own inconsistencies).
Headline values that the report gives only in its text are listed in :data:`TEXT_VALUES` with
the section they come from.
"""

from __future__ import annotations

import csv
from dataclasses import dataclass, replace
from importlib import resources
from pathlib import Path

import numpy as np

from ..io.run_folder import read_summary, run_status
from ..io.writers import read_csv_table
from .validation_cases import CASES, TABLE, impact_tolerance

#: Values the report states in its text (section in the comment).
TEXT_VALUES: dict[str, dict[str, float]] = {
    "rod_impact": {"contact_duration": 2.05},  # 3.2 (theory 2 L / c = 2)
    "ring_impact": {  # 6.4
        "contact_start_time": 0.065, "contact_end_time": 0.815, "energy_initial": 1.6014,
        "energy_max_relative_variation": 0.008, "linear_momentum_max_relative_variation": 0.015,
        "angular_momentum_max": 0.0365, "max_penetration": 0.005, "max_active_pairs": 7,
    },
    "blocks_fast_sliding": {  # 6.5
        "contact_start_time": 0.048, "contact_end_time": 0.126, "energy_initial": 1.56,
    },
    "tilted_blocks": {"energy_initial": 0.120},  # 6.6
}


def table(name: str) -> dict[str, np.ndarray]:
    """A reference table by file stem, e.g. ``blocks_fast_sliding_table_6_8``."""
    with resources.as_file(resources.files("ntncontact") / "data" / f"{name}.csv") as path:
        return read_csv_table(path)


# ----------------------------------------------------------------------------------------------
# The quasi-static examples (report 4.2, 6.1, 6.2): reference values and their measures
# ----------------------------------------------------------------------------------------------
#: Report 6.2: load per unit thickness (q = 300 over the diameter 800), radius, the cylinder's
#: Young's modulus and Poisson's ratio.
HERTZ_LOAD, HERTZ_RADIUS, HERTZ_YOUNG, HERTZ_POISSON = 240000.0, 400.0, 5.0e4, 0.3


def hertz_plane_strain(load: float, radius: float = HERTZ_RADIUS, young: float = HERTZ_YOUNG,
                       poisson: float = HERTZ_POISSON) -> tuple[float, float]:
    """Half-width a and peak pressure p0 of a cylinder pressed onto a rigid flat, plane strain:
    a = sqrt(4 P R (1 - nu^2) / (pi E)), p0 = 2 P / (pi a)."""
    a = float(np.sqrt(4.0 * load * radius * (1.0 - poisson**2) / (np.pi * young)))
    return a, 2.0 * load / (np.pi * a)


def fit_hertz_ellipse(X: np.ndarray, p: np.ndarray, a0: float, p0: float) -> tuple[float, float]:
    """Least-squares (a, p0) of the Hertz profile p0 sqrt(1 - X^2/a^2) through (X, p)."""
    from scipy.optimize import least_squares

    X, p = np.asarray(X, float), np.asarray(p, float)
    a, peak = least_squares(
        lambda z: z[1] * np.sqrt(np.clip(1.0 - (X / z[0]) ** 2, 0.0, None)) - p, [a0, p0]).x
    return float(a), float(peak)


def hertz_nodal_forces(X: np.ndarray, a: float, p0: float) -> np.ndarray:
    """Work-equivalent nodal forces, int p N_i dx, of the Hertz profile p0 sqrt(1 - x^2/a^2)
    on the piecewise linear hat functions N_i of the sorted node positions ``X`` (exact
    integrals). A node-to-node contact solution balances these, not point values of p: the
    outermost pressed node's force comes from the part of its hat inside the contact only."""
    X = np.asarray(X, float)
    u = np.clip(X, -a, a)
    root = np.sqrt(np.clip(a * a - u * u, 0.0, None))
    i0 = 0.5 * (u * root + a * a * np.arcsin(u / a))  # int sqrt(a^2 - x^2) dx
    i1 = -root**3 / 3.0  # int x sqrt(a^2 - x^2) dx
    length = np.diff(X)
    d0, d1 = np.diff(i0), np.diff(i1)
    scale = p0 / a
    F = np.zeros_like(X)
    F[:-1] += scale * (X[1:] * d0 - d1) / length  # N = (x_b - x) / L on each segment
    F[1:] += scale * (d1 - X[:-1] * d0) / length  # N = (x - x_a) / L
    return F


def fit_hertz_nodal_forces(X: np.ndarray, F: np.ndarray, a0: float, p0: float
                           ) -> tuple[float, float]:
    """Least-squares (a, p0) of the Hertz profile whose work-equivalent nodal forces
    (:func:`hertz_nodal_forces`) match the nodal normal forces ``F`` at the sorted reference
    positions ``X`` (all surface nodes, pressed or not). Unlike :func:`fit_hertz_ellipse`,
    which reads force / tributary length as a point value, it is exact for an exact Hertz
    profile on any mesh, so its error is the solution's, not the read-out's."""
    from scipy.optimize import least_squares

    X, F = np.asarray(X, float), np.asarray(F, float)
    order = np.argsort(X)
    X, F = X[order], F[order]
    a, peak = least_squares(lambda z: hertz_nodal_forces(X, z[0], z[1]) - F, [a0, p0],
                            x_scale=[a0, p0]).x
    return float(a), float(peak)


#: Table 4.1's smoothers (its last three stages).
SMOOTHERS = ("laplacian", "simple_angle_based", "weighted_angle_based")
#: Table 4.1's stages in the order of its columns.
TABLE_4_1_STAGES = ("original", "before_smoothing", *SMOOTHERS)


def table_4_1() -> dict[str, dict[str, float]]:
    """Table 4.1 as {measure: {stage: value}}."""
    t = table("mesh_smoothing_table_4_1")
    return {str(m): {stage: float(t[stage][i]) for stage in TABLE_4_1_STAGES}
            for i, m in enumerate(t["measure"])}


def smoother_ranking(values: dict[str, float], larger_is_better: bool) -> list[str]:
    """The smoothers from best to worst by one measure."""
    return sorted(SMOOTHERS, key=lambda s: -values[s] if larger_is_better else values[s])


def start_of_last_run(nodes: np.ndarray, mask: np.ndarray) -> int | None:
    """The first node of the final run of ``mask`` (e.g. the start of a slip zone at the end of
    an interface); None if the last node is not in it."""
    mask = np.asarray(mask, bool)
    if not mask[-1]:
        return None
    outside = np.flatnonzero(~mask)
    return int(nodes[0] if outside.size == 0 else nodes[outside[-1] + 1])


def first_slip_node(nodes: np.ndarray, t_n: np.ndarray, t_t: np.ndarray, mu: float,
                    rtol: float | np.ndarray = 0.0) -> int | None:
    """The first node (in the given order) on the Coulomb cone, |t_T| >= (1 - rtol) mu t_N,
    after which every node is on it (the start of the slip zone); None if the last one sticks.
    """
    on_cone = np.abs(t_t) >= (1.0 - np.asarray(rtol)) * mu * np.asarray(t_n)
    return start_of_last_run(nodes, on_cone)


def table_6_1_first_slip_node(source: str, mu: float = 0.5) -> int | None:
    """Where Table 6.1's column (``report`` or ``simo_laursen``) reaches the Coulomb cone: its
    stresses are rounded to integers, so a node is on the cone within the rounding,
    0.5 / |t_T| + 0.5 / t_N (both columns: node 16, as the report's text says)."""
    t = table("block_sliding_table_6_1")
    t_n, t_t = t[f"normal_{source}"].astype(float), t[f"tangent_{source}"].astype(float)
    rtol = 0.5 / np.maximum(np.abs(t_t), 0.5) + 0.5 / t_n
    return first_slip_node(t["node"], t_n, t_t, mu, rtol)


#: How a row is checked: see :meth:`Comparison.passed`.
MODES = ("relative", "absolute", "at_most", "at_least", "same_sign", "equal")


@dataclass(frozen=True)
class Comparison:
    """One quantity, ours beside the report's, and how it is checked.

    ``tolerance`` None: shown for information only. Otherwise, by ``mode``:

    - ``relative``: |ours - report| <= tolerance |report| (or <= ``atol``);
    - ``absolute``: |ours - report| <= tolerance;
    - ``at_most`` / ``at_least``: ours <= report + tolerance |report| + atol (a bound the report
      states, e.g. its energy drift) / ours >= report - tolerance |report| - atol;
    - ``same_sign``: ours and report are both positive or both negative (a trend: a gain,
      a shift in a given direction);
    - ``equal``: ours == report (text values, counts, rankings).

    ``note`` says where the report's value comes from or why the tolerance.
    """

    quantity: str
    ours: float | str
    report: float | str
    tolerance: float | None = None
    mode: str = "relative"
    atol: float = 0.0
    note: str = ""

    def __post_init__(self) -> None:
        if self.mode not in MODES:
            raise ValueError(f"unknown comparison mode {self.mode!r}; expected one of {MODES}")

    @property
    def numeric(self) -> bool:
        return not isinstance(self.ours, str) and not isinstance(self.report, str)

    @property
    def difference(self) -> float:
        return float(self.ours) - float(self.report) if self.numeric else float("nan")

    @property
    def relative(self) -> float:
        if not self.numeric or not self.report:
            return float("nan")
        return self.difference / abs(float(self.report))

    @property
    def checked(self) -> bool:
        return self.tolerance is not None

    def difference_text(self) -> str:
        """The relative difference in percent; the absolute one where the report's value is 0
        (a relative one would read -100 % or infinite); empty for text values."""
        if not self.numeric:
            return ""
        if not float(self.report):
            return f"{self.difference:+.3g} abs."
        return f"{self.relative:+.2%}"

    def passed(self) -> bool | None:
        """True/False against the tolerance; None for an information row."""
        if self.tolerance is None:
            return None
        if self.mode == "equal":
            return self.ours == self.report
        if not self.numeric or not np.isfinite(float(self.ours)):
            return False
        ours, report, tol = float(self.ours), float(self.report), self.tolerance
        if self.mode == "same_sign":
            return ours * report > 0.0
        if self.mode == "relative":
            return abs(ours - report) <= max(tol * abs(report), self.atol)
        if self.mode == "absolute":
            return abs(ours - report) <= tol
        slack = tol * abs(report) + self.atol
        return ours <= report + slack if self.mode == "at_most" else ours >= report - slack

    def tolerance_text(self) -> str:
        if self.tolerance is None:
            return "info"
        tol = self.tolerance
        extra = f" or ±{self.atol:.3g}" if self.atol else ""
        return {
            "relative": f"±{tol:.3g} rel.{extra}",
            "absolute": f"±{tol:.3g}",
            "at_most": f"≤ report{f' +{tol:.3g} rel.' if tol else ''}"
                       f"{f' +{self.atol:.3g}' if self.atol else ''}",
            "at_least": f"≥ report{f' -{tol:.3g} rel.' if tol else ''}"
                        f"{f' -{self.atol:.3g}' if self.atol else ''}",
            "same_sign": "same sign",
            "equal": "equal",
        }[self.mode]

    def with_check(self, tolerance: float | None, mode: str = "relative", atol: float = 0.0,
                   note: str = "") -> Comparison:
        return replace(self, tolerance=tolerance, mode=mode, atol=atol,
                       note=note or self.note)


#: Impact quantities compared with the case's relative tolerance.
CHECKED = ("contact_start_time", "energy_initial", "energy_dissipated_fraction",
           "contact_duration")
#: Impact quantities the report states as bounds of its own drift: ours must not exceed them.
BOUNDS = ("linear_momentum_max_relative_variation", "angular_momentum_max", "max_penetration")


#: Why the other impact quantities are shown without a check.
SHOWN_ONLY = {
    "contact_end_time": "shown, not checked: the report states no contact duration for "
                        "this example, and the end is set by the last pairs' release "
                        "(docs/examples.md)",
    "energy_max_relative_variation": "shown: with friction the energy falls by the dissipation "
                                     "(checked)",
    "max_active_pairs": "shown: the report states the count, not a bound",
}


def impact_rows(rows: list[Comparison], tolerance: float, friction: float, dt: float,
                onset: float = 0.0) -> list[Comparison]:
    """The checks of an impact example's headline rows (as :func:`compare` makes them).

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
        else:
            r = r.with_check(None, note=SHOWN_ONLY.get(q, "shown only"))
        out.append(r)
    return out


def _case(summary: dict) -> tuple[str, float, str]:
    """(example name, friction coefficient, mass type) of a run, from its summary: the
    values the run used (``contact_friction``, ``mass``), so also those its scenario file
    sets. A summary written before those keys were recorded gives them by its ``--set``
    overrides only."""
    example = Path(summary.get("scenario", "")).stem
    if "mass" in summary:
        friction = max(summary.get("contact_friction", {}).values(), default=0.0)
        return example, float(friction), str(summary["mass"])
    friction, mass = 0.0, "consistent"
    for item in summary.get("overrides", []):
        key, _, value = item.partition("=")
        if key.strip().endswith("friction"):
            friction = float(value)
        if key.strip() == "analysis.mass":
            mass = value.strip().strip('"')
    return example, friction, mass


def _until(time: np.ndarray, values: np.ndarray, until: float | None) -> np.ndarray:
    """The tabulated values up to ``until`` (the last one interpolated at ``until``)."""
    if until is None or until >= time[-1]:
        return values
    keep = time < until
    return np.concatenate([values[keep], [np.interp(until, time, values)]])


def report_values(example: str, friction: float = 0.0, mass: str = "consistent",
                  until: float | None = None) -> dict:
    """The report's numbers for one case of one example (text values and table-derived).

    ``until``: the end time of a shortened run; the quantities derived from the report's time
    tables (6.8, 6.10) are then taken over the same time span.
    """
    values = dict(TEXT_VALUES.get(example, {}))
    column = f"mu{friction:g}_{mass}"
    if example == "blocks_fast_sliding":
        t68 = table("blocks_fast_sliding_table_6_8")
        if column in t68:
            e = _until(t68["time"], t68[column], until)
            values["energy_max_relative_variation"] = float(np.abs(e - e[0]).max() / e[0])
            values["energy_dissipated_fraction"] = float((e[0] - e[-1]) / e[0])
    if example == "tilted_blocks":
        t610 = table("tilted_blocks_table_6_10")
        key = f"mu{friction:g}"
        if f"{key}_total_energy" in t610:
            e = _until(t610["time"], t610[f"{key}_total_energy"], until)
            my = _until(t610["time"], t610[f"{key}_My"], until)
            ma = _until(t610["time"], t610[f"{key}_Ma"], until)
            values["energy_max_relative_variation"] = float(np.abs(e - e[0]).max() / e[0])
            values["linear_momentum_max_relative_variation"] = float(
                np.abs(my - my[0]).max() / abs(my[0]))
            values["angular_momentum_max"] = float(np.abs(ma).max())
    return values


def our_values(directory: Path) -> dict[str, float]:
    """The same quantities measured from a results folder.

    A run that ends while its bodies are still in contact (a shortened run) has no contact end
    time, duration or final count of active pairs. A run whose energy starts at 0 (a static run,
    or bodies at rest and unloaded) has no relative energy variation or dissipated fraction
    (they divide by it): it has the absolute ``energy_max_change``, max |E - E0|, instead;
    likewise ``linear_momentum_max_change`` where the linear momentum starts at 0.
    """
    summary = read_summary(directory)  # a file that is not JSON is named
    h = read_csv_table(directory / "history.csv")
    e = h["total_energy"]
    e0 = float(e[0])
    p = np.column_stack([h["linear_momentum_x"], h["linear_momentum_y"]])
    p0 = float(np.linalg.norm(p[0]))
    p_change = float(np.linalg.norm(p - p[0], axis=1).max())
    out = {"energy_initial": e0}
    if e0 != 0.0:
        out["energy_max_relative_variation"] = float(np.abs(e - e0).max() / abs(e0))
        out["energy_dissipated_fraction"] = float((e0 - e[-1]) / e0)
    else:  # a static run, or bodies that start at rest: relative to E0 = 0 is undefined
        out["energy_max_change"] = float(np.abs(e - e0).max())
    if p0 > 0.0:
        out["linear_momentum_max_relative_variation"] = p_change / p0
    else:  # at rest at first: the change itself, not a "relative" one divided by 1
        out["linear_momentum_max_change"] = p_change
    out["angular_momentum_max"] = float(np.abs(h["angular_momentum"]).max())
    for key in ("contact_start_time", "contact_end_time", "max_penetration", "max_active_pairs"):
        if summary.get(key) is not None:
            out[key] = float(summary[key])
    t_last = float(h["time"][-1])
    if "contact_end_time" in out and abs(out["contact_end_time"] - t_last) <= 1e-9 * max(
            1.0, abs(t_last)):
        for key in ("contact_end_time", "max_active_pairs"):
            out.pop(key, None)
    if "contact_start_time" in out and "contact_end_time" in out:
        out["contact_duration"] = out["contact_end_time"] - out["contact_start_time"]
    return out


class ResultsFolderError(ValueError):
    """A folder that is not the results folder of a run (missing, or without its files)."""


#: The files of a run's results folder that :func:`compare` reads.
RESULTS_FILES = ("summary.json", "history.csv")


def require_results_folder(directory: str | Path) -> Path:
    """``directory`` as a Path if it holds a run's results; else a one-line error saying what
    was expected."""
    directory = Path(directory)
    expected = (f"expected the results folder of `ntncontact run --out {directory}`, with "
                f"{' and '.join(RESULTS_FILES)}")
    if not directory.is_dir():
        what = "is a file" if directory.exists() else "does not exist"
        raise ResultsFolderError(f"{directory} {what}: {expected}")
    missing = [name for name in RESULTS_FILES if not (directory / name).is_file()]
    if missing:
        raise ResultsFolderError(f"{directory} has no {' or '.join(missing)}: {expected}")
    return directory


def _contact_onset(summary: dict, time: np.ndarray, dt: float) -> float:
    """dt / (t_end - t_start) for a run stopped during contact (see :func:`impact_rows`),
    else 0."""
    start, end = summary.get("contact_start_time"), summary.get("contact_end_time")
    t_last = float(time[-1])
    if start is not None and end is not None and abs(end - t_last) <= 1e-9 and t_last > start:
        return dt / (t_last - start)
    return 0.0


def compare(directory: str | Path, tolerance: float | None = None
            ) -> tuple[str, list[Comparison]]:
    """Side-by-side rows for every quantity both the report and the run have, checked as
    ``ntncontact validate`` checks the example (:func:`impact_rows`) with ``tolerance``, by
    default the example's tolerance in ``data/validation_cases.toml``.

    The label names the case; a line under it for each note (:func:`_notes`): a run whose
    energy starts at 0 (static), and why there are no rows."""
    directory = require_results_folder(directory)
    summary = read_summary(directory)  # a file that is not JSON is named
    example, friction, mass = _case(summary)
    history = read_csv_table(directory / "history.csv")
    time = history["time"]
    report = report_values(example, friction, mass, float(time[-1]))
    ours = our_values(directory)
    rows = [Comparison(k, ours[k], v) for k, v in report.items() if k in ours]
    tolerance = impact_tolerance(example) if tolerance is None else tolerance
    if tolerance is None:
        rows = [r.with_check(None, note=f"shown: {example} has no tolerance in {TABLE}")
                for r in rows]
    else:
        dt = float(time[1] - time[0]) if len(time) > 1 else 0.0
        rows = impact_rows(rows, tolerance, friction, dt, _contact_onset(summary, time, dt))
    static = "kinetic_energy" in history and not np.any(history["kinetic_energy"])
    label = f"{example} (mu = {friction:g}, {'static run' if static else f'{mass} mass'})"
    # "stale" where summary.json still says running; a summary without a status (written by
    # hand, or by a version before it had one) is taken as completed
    state = run_status(directory).state if "status" in summary else "completed"
    notes = _notes(example, summary | {"status": state}, ours, static, bool(rows))
    return "\n".join([label, *notes]), rows


def _notes(example: str, summary: dict, ours: dict[str, float], static: bool,
           has_rows: bool) -> list[str]:
    """What :func:`compare` says under its label: what a run whose energy starts at 0 has
    instead of a relative energy variation, and why a run has no rows."""
    notes = []
    status = summary.get("status", "completed")
    if status != "completed":
        error = summary.get("error")
        notes.append(f"note: the run is {status} (at t = {summary.get('time', 0.0):.6g}"
                     + (f": {error}" if error else "") + "); the values are those of the "
                     "steps it wrote")
    if "energy_max_change" in ours:
        why = "a static run has no kinetic energy" if static else "the bodies start at rest"
        balance = summary.get("energy_balance_max_relative_error")
        notes.append(
            f"note: the energy starts at 0 ({why}), so it has no relative variation or "
            f"dissipated fraction; its largest change is {ours['energy_max_change']:.5g}"
            + ("" if balance is None else
               f", the energy balance closes to {balance:.3g} of the largest energy "
               "(summary.json energy_balance_max_relative_error)"))
    if summary.get("overrides"):  # a shortened run's "pass" is not the example's
        notes.append("note: the run was made with --set " + ", ".join(summary["overrides"])
                     + "; the report's values are those of the example as shipped")
    if not has_rows:
        notes.append(_why_no_rows(example, summary))
    return notes


def _why_no_rows(example: str, summary: dict) -> str:
    """Why :func:`compare` has no row: the run's contact had not ended where the report gives
    contact times only, or the example is not one of the report's impacts."""
    end = summary.get("contact_end_time")
    if example in TEXT_VALUES and end is not None and abs(end - summary.get("time", -1.0)) \
            <= 1e-9 * max(1.0, abs(end)):
        return (f"note: the bodies were still in contact at the run's end (t = {end:.6g}), so "
                "it has no contact end time or duration to compare with the report's")
    checked = sorted({c.section for c in CASES
                      if c.kind != "impact" and Path(c.example).stem == example})
    where = (f"`ntncontact validate` checks {example} (report {', '.join(checked)}) by its "
             "own measures; " if checked else "")
    return (f"note: {where}`compare` has the report's values of "
            f"{', '.join(sorted(TEXT_VALUES))} only")


def format_value(value: float | str) -> str:
    """A table cell: text as is, numbers to 5 significant digits."""
    if isinstance(value, str):
        return value
    return "n/a" if np.isnan(value) else f"{value:.5g}"


def verdict(row: Comparison) -> str:
    return {None: "info", True: "pass", False: "FAIL"}[row.passed()]


COMPARISON_HEADER = ("quantity", "ours", "report", "difference", "result", "tolerance",
                     "reason")


def format_comparison(label: str, rows: list[Comparison]) -> str:
    """The rows as a text table: each with its verdict, tolerance and reason."""
    widths = (42, 12, 12, 14, 6, 24)
    cells = [COMPARISON_HEADER] + [
        (r.quantity, format_value(r.ours), format_value(r.report), r.difference_text(),
         verdict(r), r.tolerance_text(), r.note) for r in rows]
    lines = [label] + [" ".join(f"{cell:{'<' if i in (0, 4, 5) else '>'}{widths[i]}s}"
                                for i, cell in enumerate(row[:-1])) + f"  {row[-1]}".rstrip()
                       for row in cells]
    if not rows:
        lines.append("(no value of the report to compare with)")
    return "\n".join(lines)


def write_comparison_csv(path: Path, rows: list[Comparison]) -> None:
    """The rows with their verdicts: relative_difference is empty where the report's value is
    0 (the difference column says how far off)."""
    with path.open("w", newline="") as fh:
        writer = csv.writer(fh)
        writer.writerow(["quantity", "ours", "report", "difference", "relative_difference",
                         "tolerance", "result", "note"])
        for r in rows:
            relative = "" if r.numeric and not float(r.report) else repr(r.relative)
            writer.writerow([r.quantity, *(v if isinstance(v, str) else repr(v)
                                           for v in (r.ours, r.report)), repr(r.difference),
                             relative, r.tolerance_text(), verdict(r), r.note])
