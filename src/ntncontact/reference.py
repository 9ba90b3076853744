"""The report's published numbers and a side-by-side comparison with a results folder.

The tables (report 4.1, 6.1, 6.4, 6.7, 6.8, 6.10) ship as CSV files in ``ntncontact/data``
(transcribed from the report; see ``data/README.md`` for the report's own inconsistencies).
Headline values that the report gives only in its text are listed in :data:`TEXT_VALUES` with
the section they come from.
"""

from __future__ import annotations

import csv
import json
from dataclasses import dataclass
from importlib import resources
from pathlib import Path

import numpy as np

from .io.writers import read_csv_table

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


@dataclass(frozen=True)
class Comparison:
    quantity: str
    ours: float
    report: float

    @property
    def difference(self) -> float:
        return self.ours - self.report

    @property
    def relative(self) -> float:
        return self.difference / abs(self.report) if self.report else float("nan")


def _case(summary: dict) -> tuple[str, float, str]:
    """(example name, friction coefficient, mass type) of a run, from its summary."""
    example = Path(summary.get("scenario", "")).stem
    friction, mass = 0.0, "consistent"
    for item in summary.get("overrides", []):
        key, _, value = item.partition("=")
        if key.strip().endswith("friction"):
            friction = float(value)
        if key.strip() == "analysis.mass":
            mass = value.strip().strip('"')
    return example, friction, mass


def report_values(example: str, friction: float = 0.0, mass: str = "consistent") -> dict:
    """The report's numbers for one case of one example (text values and table-derived)."""
    values = dict(TEXT_VALUES.get(example, {}))
    column = f"mu{friction:g}_{mass}"
    if example == "blocks_fast_sliding":
        t68 = table("blocks_fast_sliding_table_6_8")
        if column in t68:
            e = t68[column]
            values["energy_max_relative_variation"] = float(np.abs(e - e[0]).max() / e[0])
            values["energy_dissipated_fraction"] = float((e[0] - e[-1]) / e[0])
    if example == "tilted_blocks":
        t610 = table("tilted_blocks_table_6_10")
        key = f"mu{friction:g}"
        if f"{key}_total_energy" in t610:
            e, my = t610[f"{key}_total_energy"], t610[f"{key}_My"]
            values["energy_max_relative_variation"] = float(np.abs(e - e[0]).max() / e[0])
            values["linear_momentum_max_relative_variation"] = float(
                np.abs(my - my[0]).max() / abs(my[0]))
            values["angular_momentum_max"] = float(np.abs(t610[f"{key}_Ma"]).max())
    return values


def our_values(directory: Path) -> dict[str, float]:
    """The same quantities measured from a results folder."""
    summary = json.loads((directory / "summary.json").read_text())
    h = read_csv_table(directory / "history.csv")
    e = h["total_energy"]
    p = np.column_stack([h["linear_momentum_x"], h["linear_momentum_y"]])
    p0 = np.linalg.norm(p[0]) or 1.0
    out = {
        "energy_initial": float(e[0]),
        "energy_max_relative_variation": float(np.abs(e - e[0]).max() / abs(e[0])),
        "energy_dissipated_fraction": float((e[0] - e[-1]) / e[0]),
        "linear_momentum_max_relative_variation": float(
            np.linalg.norm(p - p[0], axis=1).max() / p0),
        "angular_momentum_max": float(np.abs(h["angular_momentum"]).max()),
    }
    for key in ("contact_start_time", "contact_end_time", "max_penetration", "max_active_pairs"):
        if summary.get(key) is not None:
            out[key] = float(summary[key])
    if "contact_start_time" in out and "contact_end_time" in out:
        out["contact_duration"] = out["contact_end_time"] - out["contact_start_time"]
    return out


def compare(directory: str | Path) -> tuple[str, list[Comparison]]:
    """Side-by-side rows for every quantity both the report and the run have."""
    directory = Path(directory)
    summary = json.loads((directory / "summary.json").read_text())
    example, friction, mass = _case(summary)
    report = report_values(example, friction, mass)
    ours = our_values(directory)
    rows = [Comparison(k, ours[k], v) for k, v in report.items() if k in ours]
    label = f"{example} (mu = {friction:g}, {mass} mass)"
    return label, rows


def format_comparison(label: str, rows: list[Comparison]) -> str:
    lines = [label, f"{'quantity':42s} {'ours':>12s} {'report':>12s} {'rel. diff':>10s}"]
    for r in rows:
        lines.append(f"{r.quantity:42s} {r.ours:12.5g} {r.report:12.5g} {r.relative:10.2%}")
    if not rows:
        lines.append("(no reference values for this example)")
    return "\n".join(lines)


def write_comparison_csv(path: Path, rows: list[Comparison]) -> None:
    with path.open("w", newline="") as fh:
        writer = csv.writer(fh)
        writer.writerow(["quantity", "ours", "report", "difference", "relative_difference"])
        for r in rows:
            writer.writerow([r.quantity, repr(r.ours), repr(r.report), repr(r.difference),
                             repr(r.relative)])
