"""The ntncontact command: run scenarios, plot results."""

from __future__ import annotations

import argparse
import contextlib
import os
import signal
import sys
import tempfile
import threading
import time
import traceback
import warnings
from collections.abc import Callable, Iterator
from pathlib import Path

from tqdm import tqdm

from .api import load_scenario
from .engine.builder import build_model
from .engine.config import ScenarioError
from .engine.model import Model
from .engine.simulation import RunInterrupted
from .io.results import ResultWriter
from .io.run_folder import RunLock, read_summary, run_status
from .io.run_setup import check_run_mode, start_run
from .io.vtk import read_vtu
from .io.writers import closing
from .mesh.gmsh_io import read_msh
from .mesh.quality import quality_statistics
from .package import __version__
from .report import validation_cases
from .report.plotting import check_times, plot_all
from .report.reference import compare, format_comparison, write_comparison_csv
from .report.run_warnings import result_warnings
from .report.validation import validate
from .studies.sweep import SWEEP_FILE, sweep

#: seconds of wall time between two progress lines when stderr is not a terminal (a batch
#: job's log, where tqdm's bar is off)
PROGRESS_INTERVAL = 30.0


class StopOnSignal:
    """SIGINT and SIGTERM ask a run to stop; the time loop stops at its next step
    (``Simulation.run``'s ``stop_reason``), and the run ends as interrupted with every file
    closed. Raising KeyboardInterrupt from the handler instead could land inside a compiled
    kernel and surface as a SystemError. A second signal stops at once (KeyboardInterrupt).
    While the model is built (``building``) nothing is written and no step is to finish,
    so the first signal stops at once. The handlers are installed in the main thread only, and the
    previous ones restored."""

    SIGNALS = (signal.SIGINT, signal.SIGTERM)

    def __init__(self, at_once: bool = False) -> None:
        self.signum: int | None = None
        #: the run is complete (only figures and comparisons are left), or nothing in progress
        #: can land in a compiled kernel (a sweep's driver): stop at the first signal
        self.at_once = at_once
        #: the model is being built: nothing written, nothing to finish: stop at the first signal
        self.building = False
        #: the run's results writer exists (its folder was prepared): before, nothing was written
        self.writing = False
        self._previous: dict[int, object] = {}

    def __enter__(self) -> StopOnSignal:
        if threading.current_thread() is threading.main_thread():
            for signum in self.SIGNALS:
                self._previous[signum] = signal.signal(signum, self._handle)
        return self

    def __exit__(self, *exc_info: object) -> None:
        for signum, handler in self._previous.items():
            signal.signal(signum, handler)

    def _handle(self, signum: int, frame: object) -> None:
        if self.signum is not None:
            if closing():  # the run's last files are being written; it ends right after
                return
            raise KeyboardInterrupt(self.reason())
        self.signum = signum
        # drawing figures: no step to finish; building: nothing to keep (an error from a
        # compiled kernel it lands in is taken for the interruption, see _run)
        if self.at_once or self.building:
            raise KeyboardInterrupt(self.reason())
        if not self.writing:  # no step to finish: the run stops before it begins, one line
            return
        # os.write: print() from a signal handler can meet the stream mid-write
        os.write(2, f"\n{signal.Signals(signum).name}: stopping after this step "
                    "(again to stop at once)\n".encode())

    @contextlib.contextmanager
    def building_model(self) -> Iterator[None]:
        """The model is being built: a first signal stops at once (:attr:`building`)."""
        self.building = True
        try:
            yield
        finally:
            self.building = False

    def reason(self) -> str | None:
        """Why the run should stop, or None."""
        return None if self.signum is None else \
            f"interrupted by {signal.Signals(self.signum).name}"

    @property
    def exit_code(self) -> int:
        """The shell's code for the signal: 130 for SIGINT, 143 for SIGTERM."""
        return 128 + (self.signum or signal.SIGINT)


def _run(args: argparse.Namespace) -> int:
    with StopOnSignal() as stop:
        try:
            return _run_until_stopped(args, stop)
        except BaseException:
            if stop.signum is None:
                raise
        if stop.at_once:
            print(f"{stop.reason()} after the run had completed (its results are whole; "
                  "summary.json status \"completed\"): the figures and comparisons not yet "
                  "written are missing", file=sys.stderr)
        elif not stop.writing:  # stopped while it started up, the folder untouched
            print(f"{stop.reason()} before the run began: nothing was written",
                  file=sys.stderr)
        else:
            print(f"{stop.reason()}: files written so far are valid", file=sys.stderr)
        return stop.exit_code


def _run_until_stopped(args: argparse.Namespace, stop: StopOnSignal) -> int:
    started = time.monotonic()
    scenario = load_scenario(args.scenario, args.set)
    out = _out_folder(args.out)
    check_run_mode(overwrite=args.overwrite, restart=args.restart)  # before the folder is locked
    created = not out.exists()
    lock = _lock_before_build(out)
    try:
        sim, writer = start_run(scenario, out, overwrite=args.overwrite, restart=args.restart,
                                lock=lock, building=stop.building_model,
                                built=lambda model: _check_built(model, args, stop),
                                writing=lambda writer: _writing(writer, stop))
    except BaseException:
        if not stop.writing:  # the writer would have released the lock
            _release_unused(lock, out, created)
        raise
    name, t_end = Path(args.scenario).stem, sim.model.analysis.t_end
    with _writing(writer, stop):
        if args.quiet or not sys.stderr.isatty():
            lines = None if args.quiet else ProgressLines(name, t_end,
                                                          lambda: sim.state.step, started)
            sim.run(lines, stop.reason)
        else:
            with tqdm(total=t_end, unit="t", desc=name,
                      bar_format="{l_bar}{bar}| t={n:.4g}/{total:.4g} "
                                 "[{elapsed}<{remaining}]") as bar:

                def progress(t: float) -> None:
                    bar.update(t - bar.n)

                sim.run(progress, stop.reason)
    stop.at_once = True  # the run is complete: a signal from here on stops at once
    analysis = sim.model.analysis
    fields = "fields.xdmf" if analysis.field_format == "xdmf" else "fields.pvd"
    print(f"results written to {out} (history.csv, summary.json, {fields})")
    _warn_results(writer.results.summary.data, analysis.kind == "static")
    if stop.signum is not None:  # asked to stop during the last step: no figures
        raise RunInterrupted(stop.reason())
    if args.compare:
        _print_comparison(out)
    if args.plot or args.gif or args.times:
        print("figures:", *plot_all(out, times=args.times, gif=args.gif), sep="\n  ")
    return 0


def _check_built(model: Model, args: argparse.Namespace, stop: StopOnSignal) -> None:
    """Before any file is written: stop if asked to during the build, and refuse ``--times``
    outside the run (before the run, not after it)."""
    if stop.signum is not None:
        raise RunInterrupted(stop.reason())
    if args.times:
        check_times(args.times, 0.0, model.analysis.t_end, f"the run of {Path(args.scenario)}")


def _out_folder(out: str) -> Path:
    """``--out`` as a folder; an existing file is refused by name."""
    path = Path(out)
    if path.exists() and not path.is_dir():
        raise ValueError(f"--out {out}: is a file; --out names the results folder (a new or "
                         "an existing folder)")
    return path


def _lock_before_build(out: Path) -> RunLock:
    """The results folder, created if need be and locked before the model's build (as long as
    35 s for long interfaces), which ``ntncontact status`` reports as "starting" and during
    which a second run into the folder is refused."""
    out.mkdir(parents=True, exist_ok=True)
    return RunLock.acquire(out, phase="building")


def _release_unused(lock: RunLock, out: Path, created: bool) -> None:
    """Release the folder a run stopped or failed before it wrote anything into (with the
    stop signals held off: a second Ctrl-C must not leave the lock file behind), and remove
    the folder if this run made it and it is still empty."""
    held = signal.pthread_sigmask(signal.SIG_BLOCK, StopOnSignal.SIGNALS)
    try:
        lock.release()
        if created:
            with contextlib.suppress(OSError):
                out.rmdir()
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, held)


class ProgressLines:
    """Progress as plain lines on stderr, one every ``interval`` seconds of wall time, where
    stderr is not a terminal (a batch job's log): the step, t / t_end, the fraction done and
    the time since the command started."""

    def __init__(self, name: str, t_end: float, step: Callable[[], int], started: float,
                 interval: float | None = None,
                 clock: Callable[[], float] = time.monotonic) -> None:
        self.name, self.t_end, self.step, self.started = name, t_end, step, started
        self.interval = PROGRESS_INTERVAL if interval is None else interval
        self.clock = clock
        self._printed = clock()

    def __call__(self, t: float) -> None:
        now = self.clock()
        if now - self._printed < self.interval:
            return
        self._printed = now
        elapsed = int(now - self.started)
        print(f"{self.name}: step {self.step()}, t = {t:.6g} / {self.t_end:.6g} "
              f"({100.0 * t / self.t_end:.0f} %), elapsed {elapsed // 3600}:"
              f"{elapsed // 60 % 60:02d}:{elapsed % 60:02d}", file=sys.stderr, flush=True)


@contextlib.contextmanager
def _writing(writer: ResultWriter, stop: StopOnSignal) -> Iterator[None]:
    """The run's files are being written: a first signal now stops after the step in
    progress. An exception before the time loop took over (a signal during the set-up) is
    written in the summary too (after the time loop, ``writer.on_finish`` does nothing). A
    failed or interrupted run's warnings are printed before its error: they may name its
    cause."""
    stop.writing = True
    try:
        yield
    except BaseException as err:
        interrupted = stop.signum is not None or isinstance(err, KeyboardInterrupt)
        writer.on_finish("interrupted" if interrupted else "failed",
                         stop.reason() or str(err) or "interrupted by the user")
        if interrupted or isinstance(err, Exception):
            _warn_results(writer.results.summary.data,
                          writer.model.analysis.kind == "static")
        raise


def _warn_results(summary: dict, static: bool) -> None:
    """The warnings a run's summary calls for (``report.run_warnings``), one line each on
    stderr."""
    for line in result_warnings(summary, static):
        print(f"warning: {line}", file=sys.stderr)


def _short(value: float | None) -> str:
    """A time as a reader wants it: 0.052, not 0.052000000000000005 (None as it is)."""
    return str(value) if value is None else f"{value:.10g}"


def _status(args: argparse.Namespace) -> int:
    """The run in a results folder: its status (stale: killed), step, time."""
    status = run_status(Path(args.directory))
    gone = " (gone)" if status.state == "stale" else ""
    if status.state == "starting" or status.steps is None:  # nothing written yet
        doing = "building the model" if status.phase == "building" else "preparing the folder"
        note = f" ({doing})" if status.state == "starting" else " (killed before its first step)"
        print(f"status: {status.state}{note}")
        lock = status.lock or {}
        print(f"pid:    {lock.get('pid')}{gone} on {lock.get('host')}, "
              f"started {lock.get('started')}")
        return 0
    print(f"status: {status.state}")
    print(f"step:   {status.steps}")
    print(f"time:   {_short(status.time)}")
    if status.lock is not None and status.state in ("running", "stale"):
        print(f"pid:    {status.lock.get('pid')}{gone} on {status.lock.get('host')}")
    if status.error:
        print(f"error:  {status.error}")
    return 0


def _plot(args: argparse.Namespace) -> int:
    for path in plot_all(Path(args.directory), times=args.times, gif=args.gif):
        print(path)
    return 0


QUALITY_INPUTS = ("a scenario (.toml), a Gmsh mesh (.msh), a results VTU file (.vtu) or a "
                  "results folder (its final meshes, summary.json mesh_quality)")


def _mesh_quality(args: argparse.Namespace) -> int:
    """Table 4.1 statistics of every body of a scenario (reference meshes), of a Gmsh mesh or
    of a VTU file."""
    path = Path(args.path)
    if path.is_dir():
        return _print_quality(_folder_quality(path))
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no such file (expected {QUALITY_INPUTS})")
    if args.set and path.suffix != ".toml":
        raise ValueError(f"{path}: --set changes scenario keys; this is not a scenario (.toml)")
    if path.suffix == ".vtu":
        frame = read_vtu(path)
        # a results frame: its current configuration; a plain quad mesh: its points
        points = (frame.deformed_points if "displacement" in frame.point_data
                  else frame.points)
        tables = {path.name: quality_statistics(points, frame.cells)}
    elif path.suffix == ".msh":
        tables = {path.name: quality_statistics(read_msh(path, name=path.stem))}
    elif path.suffix == ".toml":
        model = build_model(load_scenario(path, args.set).config, path.parent)
        tables = {b.name: quality_statistics(b.mesh) for b in model.bodies}
    else:
        raise ValueError(f"{path}: expected {QUALITY_INPUTS}, by its file name extension")
    return _print_quality(tables)


def _folder_quality(folder: Path) -> dict:
    """The final meshes' statistics a run folder's summary.json holds, body by body."""
    summary = folder / "summary.json"
    if not summary.is_file():
        raise FileNotFoundError(f"{folder}: a folder without summary.json (expected "
                                f"{QUALITY_INPUTS})")
    tables = read_summary(folder).get("mesh_quality")
    if not tables:
        raise ValueError(f"{summary}: no mesh_quality (the run wrote none: it did not end; "
                         "give one of its frames, fields/*.vtu)")
    return tables


def _print_quality(tables: dict) -> int:
    for name, stats in tables.items():
        print(f"{name}:")
        for key, value in stats.items():
            print(f"  {key:22s} {value:.6g}")
    return 0


def _print_comparison(directory: Path) -> int:
    """The run's headline numbers beside the report's, each with its verdict, tolerance and
    reason (as `validate` checks them); also DIR/comparison.csv. A folder that is not a run's
    results is an error naming what was expected."""
    label, rows = compare(directory)
    print(format_comparison(label, rows))
    write_comparison_csv(directory / "comparison.csv", rows)
    return 0


def _validate(args: argparse.Namespace) -> int:
    """Run every example of the report and write DIR/report.html and report.md. SIGINT and
    SIGTERM stop the cases after their step and start no other; the report of the finished
    ones is written, and the command ends as interrupted (130/143, as ``run``)."""
    cases = validation_cases.CASES  # looked up here: a test runs the command on a few cases
    out = Path(args.out)
    started: list[str] = []
    with StopOnSignal() as stop, tqdm(total=len(cases), unit="case", disable=None) as bar:
        stop.writing = True  # the first signal: "stopping after this step", the cases' steps

        def progress(name: str) -> None:  # called as each case starts: count the finished one
            bar.update(1 if started else 0)
            started.append(name)
            bar.set_description(name)

        try:
            results = validate(out, quick=args.quick, cases=cases, progress=progress,
                               stop=stop.reason)
        except KeyboardInterrupt:
            if stop.signum is None:
                raise
            # a second signal: the workers were terminated, no report
            print(f"{stop.reason()}: stopped at once, no report written (the cases' files "
                  "written so far are valid)", file=sys.stderr)
            return stop.exit_code
        bar.update(bar.total - bar.n)
    failed = [r.case.name for r in results if not r.passed() and not r.interrupted]
    not_run = sum(r.interrupted for r in results)
    report = (f"report: {out / 'report.html'} ({len(results) - len(failed) - not_run} passed, "
              f"{len(failed)} failed{': ' + ', '.join(failed) if failed else ''}")
    if stop.signum is not None:
        print(f"{report}, {not_run} not run: interrupted)")
        print(f"{stop.reason()}: files written so far are valid", file=sys.stderr)
        return stop.exit_code
    print(f"{report})")
    return 1 if failed else 0  # a failed or crashed case fails the command (CI, scripts)


def _sweep(args: argparse.Namespace) -> int:
    """Run a sweep file's cases on Dask; write OUT/sweep.csv and the figures it asks for."""
    _out_folder(args.out)
    # the sweep's driver waits on its cases (no compiled kernel to land in): the first signal
    # stops it, also where SIGINT was ignored (a script's background job); the cases done are
    # kept in sweep.csv and a rerun runs the rest
    with StopOnSignal(at_once=True):
        table = sweep(args.sweep, args.out, scheduler=args.scheduler, workers=args.workers,
                      progress=not args.quiet)
    failed = table[table["status"] != "completed"] if "status" in table else table.iloc[:0]
    skipped = int(table["skipped"].fillna(False).astype(bool).sum()) if "skipped" in table else 0
    print(f"{len(table)} cases ({skipped} already done, {len(failed)} not completed): "
          f"{Path(args.out) / SWEEP_FILE}")
    for _, row in failed.iterrows():
        print(f"  {row['case']}: {row.get('status')}: {row.get('error')}", file=sys.stderr)
    return 1 if len(failed) else 0


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="ntncontact", description=__doc__)
    parser.add_argument("--version", action="version", version=f"ntncontact {__version__}")
    sub = parser.add_subparsers(dest="command", required=True)
    run = sub.add_parser("run", help="run a scenario file")
    run.add_argument("scenario", help="scenario TOML file")
    run.add_argument("--out", required=True, help="results folder")
    run.add_argument("--set", action="append", metavar="KEY=VALUE",
                     help="override a scenario key, e.g. analysis.mass=\"lumped\" (repeatable)")
    run.add_argument("--quiet", action="store_true",
                     help="no progress bar (nor, when stderr is not a terminal, the progress "
                          "line printed every 30 s instead)")
    run.add_argument("--overwrite", action="store_true",
                     help="replace the results already in the folder (only the files a run "
                          "writes: CSV, JSON, fields.pvd/fields.xdmf with their frames, the "
                          "checkpoints, comparison.csv, PNG and GIF figures)")
    run.add_argument("--restart", action="store_true",
                     help="continue the killed run in --out from its last checkpoint "
                          "(analysis.checkpoint_interval); its files are cut back to it")
    run.add_argument("--plot", action="store_true",
                     help="then write the figures of `ntncontact plot`")
    _figure_options(run, "(implies --plot)")
    run.add_argument("--compare", action="store_true",
                     help="then print the comparison with the report (as `ntncontact compare`)")
    run.set_defaults(func=_run)
    plot = sub.add_parser("plot", help="write PNG figures of a results folder")
    plot.add_argument("directory")
    _figure_options(plot)
    plot.set_defaults(func=_plot)
    val = sub.add_parser("validate", help="run the report's examples and write a report")
    val.add_argument("--out", required=True,
                     help="folder for the runs and report.html / report.md (exit code 1 when a "
                          "case fails)")
    val.add_argument("--quick", action="store_true", help="shortened runs (for CI)")
    val.set_defaults(func=_validate)
    comp = sub.add_parser("compare", help="compare a results folder with the report's numbers")
    comp.add_argument("directory")
    comp.set_defaults(func=lambda args: _print_comparison(Path(args.directory)))
    status = sub.add_parser("status", help="the status of the run in a results folder: "
                                           "running, completed, interrupted, failed, or stale "
                                           "(killed)")
    status.add_argument("directory")
    status.set_defaults(func=_status)
    sw = sub.add_parser("sweep", help="run one scenario over a grid or list of overrides on Dask")
    sw.add_argument("sweep", help="sweep TOML file (docs/api.md)")
    sw.add_argument("--out", required=True, help="sweep folder (cases/, sweep.csv, figures)")
    sw.add_argument("--scheduler", metavar="ADDRESS",
                    help="a running Dask scheduler (default: a local cluster, one worker a core)")
    sw.add_argument("--workers", type=int, help="local workers (default: one per core)")
    sw.add_argument("--quiet", action="store_true", help="no progress bar")
    sw.set_defaults(func=_sweep)
    quality = sub.add_parser("mesh-quality",
                             help="edge and angle statistics (report Table 4.1) of a scenario's "
                                  "meshes or of a VTU snapshot")
    quality.add_argument("path", help="scenario TOML, Gmsh .msh, results VTU file or "
                         "results folder")
    quality.add_argument("--set", action="append", metavar="KEY=VALUE",
                         help="override a scenario key (a scenario TOML only; repeatable)")
    quality.set_defaults(func=_mesh_quality)
    return parser


def _figure_options(parser: argparse.ArgumentParser, note: str = "") -> None:
    parser.add_argument("--times", type=float, nargs="+", metavar="T",
                        help="draw the deformed meshes at these times (snapshots.png; "
                             "interpolated linearly between the output frames around a time "
                             "no frame was written at) instead of six evenly spaced ones "
                             f"(deformed_von_mises.png) {note}".strip())
    parser.add_argument("--gif", action="store_true",
                        help=f"also write animation.gif {note}".strip())


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        with warnings.catch_warnings():
            warnings.showwarning = _show_warning
            return int(args.func(args))
    except KeyboardInterrupt:
        print("interrupted: files written so far are valid", file=sys.stderr)
        return 130
    except BrokenPipeError:  # `ntncontact ... | head`: the reader has what it wanted
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())  # none at exit either
        return 128 + signal.SIGPIPE
    except (ValueError, RuntimeError, OSError, ArithmeticError, MemoryError) as err:
        print(f"error: {_one_line(_with_source(err, args))}", file=sys.stderr)
        return 1
    except Exception as err:  # noqa: BLE001 - a bug: one line here, the traceback in a file
        print(f"internal error: {type(err).__name__}: {_one_line(str(err))} (a bug in "
              f"ntncontact; its traceback is in {_save_traceback()}: please report it with "
              "the scenario; the results written so far are readable)", file=sys.stderr)
        return 1


def _save_traceback() -> str:
    """Write the current exception's traceback to a new file in the temporary folder."""
    fd, path = tempfile.mkstemp(prefix="ntncontact-traceback-", suffix=".txt")
    with os.fdopen(fd, "w") as stream:
        traceback.print_exc(file=stream)
    return path


def _with_source(err: BaseException, args: argparse.Namespace) -> str:
    """The message, led by the scenario file when it is about the scenario and does not name
    it yet (the model builder knows the keys, not the file)."""
    text = str(err) or type(err).__name__  # a bare MemoryError has no message
    if isinstance(err, MemoryError):
        text = f"out of memory ({text})"
    source = getattr(args, "scenario", None) or getattr(args, "path", None)
    if isinstance(err, ScenarioError) and source and not text.startswith(str(source)):
        text = f"{source}: {text}"
    return text


def _show_warning(message: Warning | str, *_: object, **__: object) -> None:
    """A warning as the command's other warnings are: one line, without the source line
    Python's default format shows (``warning: skipping unreadable ...``)."""
    print(f"warning: {_one_line(str(message))}", file=sys.stderr)


def _one_line(text: str) -> str:
    """Error messages are one line (several problems are separated by '; ')."""
    return "; ".join(line.strip() for line in text.splitlines() if line.strip())


def console_main() -> None:
    """The ``ntncontact`` command: :func:`main`'s return value is the exit code."""
    sys.exit(main())


if __name__ == "__main__":  # pragma: no cover
    console_main()
