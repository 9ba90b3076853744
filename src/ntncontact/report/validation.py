"""``ntncontact validate``: run every example of the report and write a side-by-side report.

The cases are a table (``data/validation_cases.toml``, read by
:mod:`ntncontact.report.validation_cases`); ``quick`` adds the overrides that make each case cheap.
Every case runs in its own results folder (two at a time on a machine with two cores) and is
then measured (:mod:`ntncontact.report.validation_measure`, whose checks are in
:mod:`ntncontact.report.validation_checks`); a failing case is reported with its error and the
others still run. :func:`link_results` adds the comparisons between cases, and the reports are
written by :mod:`ntncontact.report.validation_report`.
"""

from __future__ import annotations

import contextlib
import multiprocessing
import os
import time
import traceback
from collections.abc import Callable
from concurrent.futures import ProcessPoolExecutor, as_completed
from pathlib import Path

from .reference import hertz_plane_strain
from .validation_cases import CASES, EXAMPLES, Case
from .validation_checks import (
    HERTZ_BETA,
    CaseResult,
    hertz_convergence_rows,
    hertz_versus_rows,
)
from .validation_figures import plot_hertz_versus
from .validation_measure import MEASURES, overrides, quiet_build, run_mesh_motion
from .validation_report import RunInfo, write_html, write_markdown


def _run_scenario(case: Case, directory: Path, quick: bool) -> None:
    """Run the case's scenario into ``directory`` (results as ``ntncontact run`` writes them);
    raises if the run does not complete."""
    from ..engine.builder import build_model
    from ..engine.simulation import Simulation
    from ..io.results import ResultWriter
    from ..io.scenario import load_scenario

    scenario = EXAMPLES / case.example
    items = overrides(case, quick)
    config = load_scenario(scenario, items)
    with quiet_build():
        model = build_model(config, scenario.parent)
    writer = ResultWriter(directory, model, scenario=str(scenario), title=config.title,
                          overrides=items, overwrite=True)  # validate reruns every case
    Simulation(model, [writer]).run()  # raises if the run fails


def run_case(case: Case, out: Path, quick: bool) -> CaseResult:
    """Run and measure one case; never raises (an error is recorded in the result)."""
    directory = out / case.name
    start = time.perf_counter()
    result = CaseResult(case, directory, 0.0)
    try:
        if case.kind == "mesh_motion":
            run_mesh_motion(case, directory, quick, result)
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
    h1 = max(c.mesh_size for c in CASES if c.kind == "hertz")  # mesh 1, the coarsest
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
