"""The reports of ``ntncontact validate``: report.md and report.html, a summary table and each
case's rows and figures."""

from __future__ import annotations

import html
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .reference import Comparison, format_value, verdict
from .validation_cases import Case
from .validation_checks import CaseResult


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
        not_run = sum(r.interrupted for r in results)
        interrupted = f" {not_run} not run: interrupted." if not_run else ""
        return (f"Mode: {'quick (shortened runs)' if self.quick else 'full'}. "
                f"{passed} of {len(results)} cases passed.{interrupted} "
                f"Wall time {self.wall_seconds:.0f} s "
                f"with {self.jobs} worker process{'es' if self.jobs > 1 else ''} on "
                f"{self.cpus} cores (sum of the case times "
                f"{sum(r.seconds for r in results):.0f} s; 1-minute load average "
                f"{self.load_before:.1f} before, {self.load_after:.1f} after).")


def _status(result: CaseResult) -> str:
    return "NOT RUN" if result.interrupted else "PASS" if result.passed() else "FAIL"


def _summary_counts(result: CaseResult) -> str:
    checked = result.checked()
    if result.interrupted:
        return "not run"
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


def write_markdown(path: Path, results: list[CaseResult], info: RunInfo) -> None:
    quick = info.quick
    lines = ["# ntncontact validation against Xu & Hjelmstad's report", "",
             info.text(results), ""]
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


def write_html(path: Path, results: list[CaseResult], info: RunInfo) -> None:
    esc, quick = html.escape, info.quick
    parts = ["<!doctype html><html><head><meta charset='utf-8'>",
             "<title>ntncontact validation</title><style>body{font-family:sans-serif;"
             "max-width:1200px;margin:auto}table{border-collapse:collapse;margin:6px 0}"
             "td,th{border:1px solid #aaa;padding:2px 8px;font-size:90%}"
             ".PASS,.pass{color:green}.FAIL{color:#b00;font-weight:bold}.info{color:#777}"
             "img{max-width:560px;margin:4px}</style></head><body>",
             "<h1>ntncontact validation against Xu &amp; Hjelmstad's report</h1>",
             f"<p>{esc(info.text(results))}</p>",
             "<table><tr><th>case</th><th>report</th><th>status</th>"
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
