"""``ntncontact validate``: run the report's examples and write a side-by-side report.

Each case is an example scenario with overrides (friction, mass type); ``quick`` adds
overrides that make it cheap (shorter time, for CI). Every case runs in its own results
folder; a failing case is reported with its error and the others still run.
"""

from __future__ import annotations

import html
import time
import traceback
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

from .reference import Comparison, compare

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"


@dataclass(frozen=True)
class Case:
    name: str
    example: str
    overrides: tuple[str, ...] = ()
    quick: tuple[str, ...] = ()  # extra overrides for --quick
    tolerance: float = 0.05  # relative difference allowed on the compared quantities


CASES: tuple[Case, ...] = (
    Case("rod_impact", "rod_impact.toml", tolerance=0.03),
    Case("ring_impact", "ring_impact.toml", quick=("analysis.t_end=0.2",), tolerance=0.15),
    *(
        Case(f"fast_sliding_mu{mu:g}_{mass}", "blocks_fast_sliding.toml",
             (f"contact.0.friction={mu}", f'analysis.mass="{mass}"'),
             quick=("analysis.t_end=0.09",), tolerance=0.15)
        for mu in (0.0, 0.1, 0.2) for mass in ("consistent", "lumped")
    ),
    *(
        Case(f"tilted_blocks_mu{mu:g}", "tilted_blocks.toml", (f"contact.0.friction={mu}",),
             quick=("analysis.t_end=0.1",), tolerance=0.15)
        for mu in (0.0, 0.2, 10.0)
    ),
)

#: Quantities compared with a pass/fail (others are shown for information).
CHECKED = ("contact_start_time", "energy_initial", "energy_dissipated_fraction",
           "contact_duration")


@dataclass
class CaseResult:
    case: Case
    directory: Path
    seconds: float
    error: str | None = None
    label: str = ""
    rows: list[Comparison] = field(default_factory=list)
    images: list[Path] = field(default_factory=list)

    def passed(self) -> bool:
        if self.error is not None:
            return False
        checked = [r for r in self.rows if r.quantity in CHECKED]
        return all(abs(r.relative) <= self.case.tolerance or abs(r.difference) < 1e-3
                   for r in checked)


def run_case(case: Case, out: Path, quick: bool) -> CaseResult:
    """Run one case with the CLI's own code path; never raises."""
    from .cli import main

    directory = out / case.name
    overrides = list(case.overrides) + (list(case.quick) if quick else [])
    args = ["run", str(EXAMPLES / case.example), "--out", str(directory), "--quiet"]
    for item in overrides:
        args += ["--set", item]
    start = time.perf_counter()
    result = CaseResult(case, directory, 0.0)
    try:
        if main(args) != 0:
            raise RuntimeError((directory / "summary.json").read_text()
                               if (directory / "summary.json").is_file() else "run failed")
        result.label, result.rows = compare(directory)
        from .plotting import plot_all

        result.images = plot_all(directory)
        overlay = plot_report_overlay(directory, case)
        if overlay is not None:
            result.images.insert(0, overlay)
    except Exception as err:  # a failed case is reported, the others go on
        result.error = f"{type(err).__name__}: {err}\n{traceback.format_exc(limit=3)}"
    result.seconds = time.perf_counter() - start
    return result


#: (reference table, column) of the total energy the report tabulates for each example/case.
def _energy_column(case: Case) -> tuple[str, str, str] | None:
    friction = next((float(o.split("=")[1]) for o in case.overrides if "friction" in o), 0.0)
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
    from .reference import table

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


def validate(out: str | Path, quick: bool = False, cases: tuple[Case, ...] = CASES,
             progress: Callable[[str], None] | None = None) -> list[CaseResult]:
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    results = []
    for case in cases:
        if progress:
            progress(case.name)
        results.append(run_case(case, out, quick))
    write_markdown(out / "report.md", results, quick)
    write_html(out / "report.html", results, quick)
    return results


def _rows_md(result: CaseResult) -> list[str]:
    lines = ["| quantity | ours | report | relative difference |", "| --- | --- | --- | --- |"]
    for r in result.rows:
        lines.append(f"| {r.quantity} | {r.ours:.5g} | {r.report:.5g} | {r.relative:.2%} |")
    return lines


def write_markdown(path: Path, results: list[CaseResult], quick: bool) -> None:
    total = sum(r.seconds for r in results)
    lines = ["# ntncontact validation against Xu & Hjelmstad's report", "",
             f"Mode: {'quick (shortened runs)' if quick else 'full'}; total time {total:.0f} s.",
             ""]
    for r in results:
        status = "PASS" if r.passed() else "FAIL"
        lines += [f"## {r.case.name}: {status}", "",
                  f"Scenario `{r.case.example}` {' '.join(r.case.overrides)}; {r.seconds:.1f} s; "
                  f"tolerance {r.case.tolerance:.0%} on {', '.join(CHECKED)}.", ""]
        if r.error:
            lines += ["```", r.error.strip(), "```", ""]
            continue
        lines += _rows_md(r) + [""]
        lines += [f"![{p.stem}]({p.relative_to(path.parent).as_posix()})" for p in r.images]
        lines.append("")
    path.write_text("\n".join(lines))


def write_html(path: Path, results: list[CaseResult], quick: bool) -> None:
    esc = html.escape
    parts = ["<!doctype html><html><head><meta charset='utf-8'>",
             "<title>ntncontact validation</title><style>body{font-family:sans-serif;"
             "max-width:1100px;margin:auto}table{border-collapse:collapse}td,th{border:1px solid"
             " #aaa;padding:2px 8px}.PASS{color:green}.FAIL{color:#b00}img{max-width:520px}"
             "</style></head><body>",
             "<h1>ntncontact validation against Xu &amp; Hjelmstad's report</h1>",
             f"<p>Mode: {'quick' if quick else 'full'}; total time "
             f"{sum(r.seconds for r in results):.0f} s.</p>"]
    for r in results:
        status = "PASS" if r.passed() else "FAIL"
        parts.append(f"<section id='{esc(r.case.name)}'><h2>{esc(r.case.name)}: "
                     f"<span class='{status}'>{status}</span></h2>")
        parts.append(f"<p>{esc(r.case.example)} {esc(' '.join(r.case.overrides))}; "
                     f"{r.seconds:.1f} s</p>")
        if r.error:
            parts.append(f"<pre>{esc(r.error)}</pre></section>")
            continue
        parts.append("<table><tr><th>quantity</th><th>ours</th><th>report</th>"
                     "<th>relative difference</th></tr>")
        for c in r.rows:
            parts.append(f"<tr><td>{esc(c.quantity)}</td><td>{c.ours:.5g}</td>"
                         f"<td>{c.report:.5g}</td><td>{c.relative:.2%}</td></tr>")
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
