"""``ntncontact validate``: run every example of the report and write a side-by-side report.

The cases are a table (``data/validation_cases.toml``, read by
:mod:`ntncontact.report.validation_cases`); ``quick`` adds the overrides that make each case cheap.
Every case runs in its own results folder (two at a time on a machine with two cores) and is
then measured (:mod:`ntncontact.report.validation_measure`, whose checks are in
:mod:`ntncontact.report.validation_checks`); a failing case is reported with its error and the
others still run. :func:`link_results` adds the comparisons between cases, and the reports are
written by :mod:`ntncontact.report.validation_report`.

A stop request (``validate``'s ``stop``: the command's SIGINT/SIGTERM handling) stops the
running cases after their current step, in the workers too, and starts no new one; the report
then lists the finished cases and the rest as "not run: interrupted"; no worker is left
running on, orphaned.
"""

from __future__ import annotations

import contextlib
import ctypes
import multiprocessing
import os
import signal
import threading
import time
import traceback
import warnings
from collections.abc import Callable
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from pathlib import Path

from ..engine.diagnostics import PhysicsWarning
from ..engine.model import Model
from ..io.run_setup import start_run
from ..io.scenario import Scenario
from .reference import hertz_plane_strain
from .validation_cases import CASES, EXAMPLES, Case
from .validation_checks import (
    HERTZ_BETA,
    CaseResult,
    hertz_convergence_rows,
    hertz_versus_rows,
)
from .validation_figures import plot_hertz_versus
from .validation_measure import MEASURES, run_mesh_motion
from .validation_report import RunInfo, write_html, write_markdown

#: a stop request: the reason to stop (e.g. "interrupted by SIGINT"), or None to go on
StopReason = Callable[[], "str | None"]
SIGNALS = (signal.SIGINT, signal.SIGTERM)
#: seconds between two looks at the stop request while the cases run in the workers
POLL = 0.2
#: seconds a worker whose parent died waits for its case to stop before it exits
ORPHAN_GRACE = 30.0


def _run_scenario(case: Case, directory: Path, quick: bool, stop: StopReason | None) -> Model:
    """Run the case's scenario into ``directory`` (results as ``ntncontact run`` writes them)
    and return its model; raises if the run does not complete."""
    scenario = Scenario.from_file(EXAMPLES / case.example,
                                  case.overrides + (case.quick if quick else ()))
    # the build's warnings are kept in the summary, not printed: the shipped examples' are
    # known (hertz.toml's slip_tolerance serves its friction cases, unread in the others)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", PhysicsWarning)
        simulation, _ = start_run(scenario, directory, overwrite=True,  # rerun every case
                                  restart=False)
    # raises if the run fails, RunInterrupted after the step in progress when asked to stop
    simulation.run(stop_reason=stop)
    return simulation.model


def not_run(case: Case, out: Path, reason: str, seconds: float = 0.0) -> CaseResult:
    """The result of a case an interruption kept from running, or stopped before its end."""
    return CaseResult(case, out / case.name, seconds, error=f"not run: {reason}",
                      interrupted=True)


def run_case(case: Case, out: Path, quick: bool, stop: StopReason | None = None) -> CaseResult:
    """Run and measure one case; never raises (an error is recorded in the result). ``stop``
    (default: the worker's, see :func:`_worker_stop`) is asked before and during the run."""
    stop = stop or _worker_stop
    directory = out / case.name
    start = time.perf_counter()
    if stop() is not None:  # queued before the stop request: do not start it
        return not_run(case, out, stop() or "interrupted")
    result = CaseResult(case, directory, 0.0)
    try:
        if case.kind == "mesh_motion":
            run_mesh_motion(case, directory, quick, result)
        else:
            model = _run_scenario(case, directory, quick, stop)
            MEASURES[case.kind](case, model, directory, quick, result)
    except KeyboardInterrupt as err:  # stopped after a step (RunInterrupted): not a result
        reason = stop() or str(err) or "interrupted"
        return not_run(case, out, f"{reason} (stopped before its end; its files so far are "
                                  "valid)", time.perf_counter() - start)
    except Exception as err:  # a failed case is reported, the others go on
        if stop() is not None:  # asked to stop, then an error (a signal inside a kernel)
            return not_run(case, out, f"{stop()} (stopped before its end)",
                           time.perf_counter() - start)
        result.error = f"{type(err).__name__}: {err}\n{traceback.format_exc(limit=4)}"
    result.seconds = time.perf_counter() - start
    return result


def link_results(results: list[CaseResult]) -> None:
    """Comparisons between cases: the finer Hertz meshes against mesh 1 ("all three meshes
    yield identical normal pressures"), each frictional Hertz case against the frictionless
    one on the same mesh (tolerance mu beta, see :data:`HERTZ_BETA`)."""
    hertz = {(r.case.mesh_size, r.case.friction): r for r in results
             if r.case.kind == "hertz"}
    if not hertz:  # a run of other cases (CASES then may hold no Hertz case either)
        return
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


# ---- the worker processes' side of a stop request ----------------------------------------
#: the parent's stop request, shared with the workers: STOP_AFTER_STEP once asked, STOP_NOW on
#: a second signal
_shared_stop: ctypes.c_int | None = None
STOP_AFTER_STEP, STOP_NOW = 1, 2
#: a signal this worker received itself (a Ctrl-C reaches every process of the terminal's job)
_own_signum = 0
#: set once the worker must leave: its next signal ends it by SystemExit (a plain exit)
_leaving = False


def _worker_stop() -> str | None:
    """A worker's stop reason: a signal it received itself, or the parent's request; in the
    calling process (no worker) None."""
    if _own_signum:
        return f"interrupted by {signal.Signals(_own_signum).name}"
    return "interrupted" if _shared_stop is not None and _shared_stop.value else None


def _worker_signal(signum: int, frame: object) -> None:
    """Record the signal: the case stops after its step (raising here could land inside a
    compiled kernel, as the command's own handler explains), unless the worker is leaving:
    then it exits through the interpreter (the handler runs between bytecodes, never inside a
    kernel)."""
    global _own_signum
    _own_signum = _own_signum or signum
    if _leaving:
        raise SystemExit(128 + signum)


def _init_worker(shared: ctypes.c_int) -> None:
    """A worker's start: the stop request, its own signal handlers, then the signals (blocked
    by the parent while it started the workers, so none arrives before the handlers), and a
    watch on the parent."""
    global _shared_stop
    _shared_stop = shared
    for signum in SIGNALS:
        signal.signal(signum, _worker_signal)
    signal.pthread_sigmask(signal.SIG_UNBLOCK, SIGNALS)
    threading.Thread(target=_watch_parent, args=(os.getppid(), shared), daemon=True).start()


def _watch_parent(parent: int, shared: ctypes.c_int) -> None:
    """Make the worker leave when the parent is gone (killed by SIGKILL: no one joins this worker
    any more, and it would idle for ever; its case stops after its step, given ORPHAN_GRACE to
    close its files) or asks for a stop at once (a second signal). The worker's main thread waits
    in the pool's queue or runs a case, so it is told by a SIGTERM to itself, repeated until it has
    gone (a case that catches the first one returns to the queue, where the next one ends it)."""
    global _leaving, _own_signum
    while os.getppid() == parent and shared.value != STOP_NOW:
        time.sleep(1.0)
    if shared.value != STOP_NOW:
        _own_signum = _own_signum or signal.SIGTERM
        time.sleep(ORPHAN_GRACE)  # the case's step and its files' closing, within reason
    _leaving = True
    while True:
        os.kill(os.getpid(), signal.SIGTERM)
        time.sleep(1.0)


def default_jobs(n_cases: int) -> int:
    """Worker processes: one per core, at most two (the cases are single-threaded solves)."""
    return max(1, min(n_cases, os.cpu_count() or 1, 2))


def validate(out: str | Path, quick: bool = False, cases: tuple[Case, ...] = CASES,
             progress: Callable[[str], None] | None = None,
             jobs: int | None = None, stop: StopReason | None = None) -> list[CaseResult]:
    """Run ``cases`` (``jobs`` at a time; default :func:`default_jobs`), compare, and write
    ``out``/report.md and report.html. ``progress(name)`` is called as each case finishes.
    ``stop``: asked as the cases run; a reason stops the running cases after their step and
    starts no other, and the report lists them as not run (see the module's docstring)."""
    out = Path(out).resolve()
    out.mkdir(parents=True, exist_ok=True)
    jobs = default_jobs(len(cases)) if jobs is None else max(1, jobs)
    stop = stop or (lambda: None)
    load_before = os.getloadavg()[0]
    start = time.perf_counter()
    results: list[CaseResult | None] = [None] * len(cases)
    if jobs == 1:
        for i, case in enumerate(cases):
            results[i] = run_case(case, out, quick, stop)
            if progress:
                progress(case.name)
    else:
        _run_in_workers(cases, out, quick, jobs, results, progress, stop)
    done = [r if r is not None else not_run(case, out, stop() or "interrupted")
            for case, r in zip(cases, results, strict=True)]
    link_results(done)
    info = RunInfo(quick, time.perf_counter() - start, jobs, os.cpu_count() or 1, load_before,
                   os.getloadavg()[0])
    write_markdown(out / "report.md", done, info)
    write_html(out / "report.html", done, info)
    return done


def _run_in_workers(cases: tuple[Case, ...], out: Path, quick: bool, jobs: int,
                    results: list[CaseResult | None], progress: Callable[[str], None] | None,
                    stop: StopReason) -> None:
    """Run the cases in ``jobs`` worker processes, the longest first, into ``results``. A stop
    request is passed on to the workers (their cases stop after their step); the cases not
    started are cancelled. Every worker has exited on return, also when it raises (a second
    signal: they are terminated)."""
    order = sorted(range(len(cases)), key=lambda i: -cases[i].cost)
    context = multiprocessing.get_context("spawn")  # no state inherited from the caller
    shared = context.Value("i", 0, lock=False)  # the stop request: read before every step
    # the workers start with the signals blocked (the mask is inherited): a Ctrl-C while one
    # starts up is taken by its handler, not shown as its KeyboardInterrupt traceback
    signal.pthread_sigmask(signal.SIG_BLOCK, SIGNALS)
    try:
        pool = ProcessPoolExecutor(jobs, mp_context=context, initializer=_init_worker,
                                   initargs=(shared,))
        futures = {pool.submit(run_case, cases[i], out, quick): i for i in order}
    finally:
        signal.pthread_sigmask(signal.SIG_UNBLOCK, SIGNALS)
    try:
        _collect(futures, cases, out, results, progress, stop, shared)
    except BaseException:  # a second signal: the workers leave at once (_watch_parent)
        shared.value = STOP_NOW
        pool.shutdown(wait=True, cancel_futures=True)
        raise
    pool.shutdown(wait=True, cancel_futures=True)


def _collect(futures: dict[Future, int], cases: tuple[Case, ...], out: Path,
             results: list[CaseResult | None], progress: Callable[[str], None] | None,
             stop: StopReason, shared: ctypes.c_int) -> None:
    """Wait for the cases' results, looking at the stop request every :data:`POLL` s; on one,
    tell the workers and cancel the cases not handed to a worker yet (left None: not run)."""
    pending = set(futures)
    while pending:
        finished, pending = wait(pending, timeout=POLL, return_when=FIRST_COMPLETED)
        if stop() is not None and not shared.value:
            shared.value = STOP_AFTER_STEP
            pending = {f for f in pending if not f.cancel()}  # those a worker has: they stop
        for future in finished:
            i = futures[future]
            results[i] = _result_of(future, cases[i], out)
            if progress:
                progress(cases[i].name)


def _result_of(future: Future, case: Case, out: Path) -> CaseResult:
    """A finished future's result: the case's, or its worker's death as the case's error."""
    try:
        return future.result()
    except Exception as err:  # the worker died: the case failed, the rest go on
        return CaseResult(case, out / case.name, 0.0, error=f"{type(err).__name__}: {err}")
