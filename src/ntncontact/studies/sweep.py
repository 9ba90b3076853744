"""Parameter sweeps: one scenario over a grid or a list of overrides, each case a full run on a
Dask worker, collected into ``sweep.csv`` and figures.

A sweep file (TOML; docs/api.md)::

    scenario = "../blocks_fast_sliding.toml"      # relative to the sweep file
    [set]                                          # overrides of every case (optional)
    "analysis.t_end" = 0.5
    [grid]                                         # every combination (or [[cases]] tables)
    "contact.0.friction" = [0.0, 0.1, 0.2]
    "analysis.mass" = ["consistent", "lumped"]
    [reductions]                                   # extra sweep.csv columns from history.csv
    dissipation = "frictional_dissipation:last"
    [[figures]]
    x = "contact.0.friction"
    y = "dissipation"
    by = "analysis.mass"

Each case runs in ``OUT/cases/case-<hash of its overrides>/``: a rerun skips a case whose folder
says ``completed`` for the same overrides and scenario (``scenario_hash``), and a failing case
is recorded with its error without stopping the others.
"""

from __future__ import annotations

import contextlib
import difflib
import hashlib
import itertools
import json
import logging
import sys
import time
import traceback
import warnings
from collections.abc import Callable, Collection, Iterator, Mapping, Sequence
from pathlib import Path
from typing import Annotated, Any, Literal

import numpy as np
import pandas as pd
from pydantic import BaseModel, ConfigDict, Field, ValidationError, model_validator

from ..api import load_scenario, read_results, run
from ..engine.builder import build_mesh, build_model
from ..engine.config import ScenarioError
from ..io.checkpoint import run_identity
from ..io.results import CONTACT_HISTORY, OFF_SURFACE_HISTORY
from ..io.scenario import Scenario, override_strings, read_toml, toml_value
from ..io.writers import HISTORY_COLUMNS
from ..report.run_warnings import result_warnings
from ..threads import single_threaded

SWEEP_FILE = "sweep.csv"
REDUCTIONS: dict[str, Callable[[np.ndarray], float]] = {
    "last": lambda a: float(a[-1]),
    "first": lambda a: float(a[0]),
    "max": lambda a: float(np.max(a)),
    "min": lambda a: float(np.min(a)),
    "max_abs": lambda a: float(np.max(np.abs(a))),
    "max_change": lambda a: float(np.max(np.abs(a - a[0]))),
}
#: summary.json values copied into every sweep.csv row (where the run has them)
HEADLINE = ("status", "steps", "wall_time_s", "cpu_time_s", "energy_initial", "energy_final",
            "energy_max_relative_variation", "contact_start_time", "contact_end_time",
            "contact_at_end", "max_penetration", "max_active_pairs", "max_penetration_off_surfaces",
            "max_penetration_surface_2", "max_self_penetration", "cut_back_steps",
            # a case's solver cost, the accepted sub-steps' and the discarded attempts'
            "newton_iterations", "failed_newton_iterations")
#: the exception types of a case that failed for a reason its message states (a bad scenario,
#: a diverged solve, a full disk), as ``ntncontact run`` takes them; any other is a bug
EXPECTED_ERRORS = (ValueError, RuntimeError, OSError, ArithmeticError, MemoryError)
#: where a case's internal error keeps its traceback, in the case's folder
TRACEBACK_FILE = "traceback.txt"

#: Dask settings of the LocalCluster a sweep starts (docs/api.md, "Where it runs"). Its
#: periodic work otherwise costs ~7 % of a core-second per worker-second of a running case
#: (benchmarks/README.md, "Sweep overhead"): the workers' statistical profiler (every 10 ms;
#: it feeds only the dashboard, which this cluster has not), the system monitor (500 ms),
#: the event loops' health tick (20 ms) and the nannies' memory monitor (100 ms).
LOCAL_DASK_CONFIG: dict[str, Any] = {
    "distributed.worker.profile.enabled": False,
    "distributed.admin.system-monitor.interval": "5s",
    "distributed.admin.tick.interval": "1s",
    "distributed.worker.memory.monitor-interval": "1s",
}


#: The scheduler serves its health and metrics routes over HTTP even without a dashboard, on
#: port 8787 unless told otherwise: with that port taken (another sweep, a notebook's Dask
#: dashboard) Distributed warned "Port 8787 is already in use" to the user's terminal. A free
#: port on the loopback interface, which nothing of a sweep needs to know.
SCHEDULER_HTTP: dict[str, Any] = {"dashboard_address": "127.0.0.1:0"}


class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)


class FigureSpec(_Strict):
    x: str
    y: str
    by: str | None = None


class SweepSpec(_Strict):
    """A sweep file: the scenario, the cases (``grid`` or ``cases``), reductions, figures."""

    scenario: str
    set: dict[str, Any] = Field(default_factory=dict)  # overrides applied to every case
    grid: dict[str, Annotated[list[Any], Field(min_length=1)]] = Field(default_factory=dict)
    cases: list[dict[str, Any]] = Field(default_factory=list)
    reductions: dict[str, str] = Field(default_factory=dict)
    figures: list[FigureSpec] = Field(default_factory=list)
    on_error: Literal["record"] = "record"

    @model_validator(mode="after")
    def _some_cases(self) -> SweepSpec:
        if not self.grid and not self.cases:
            raise ValueError("give [grid] or [[cases]]")
        for name, spec in self.reductions.items():
            column, _, op = spec.partition(":")
            if not column or op not in REDUCTIONS:
                raise ValueError(f"reductions.{name} = '{spec}': expected 'COLUMN:OP' with OP "
                                 f"one of {', '.join(REDUCTIONS)}")
            _check_history_column(f"reductions.{name} = '{spec}'", column)
        both = [key for key in self.grid if key in self.set]
        if both:  # else [set]'s value would be dropped without a word
            raise ValueError(f"'{both[0]}' is in both [set] and [grid]: the grid's values "
                             "would replace [set]'s in every case; give it in one of them")
        self._check_figures()
        self._check_repeats()
        return self

    def _check_repeats(self) -> None:
        """Two equal cases (as mappings: in any key order) would run in one folder, the second
        stopped by the first's lock: refused, naming both."""
        seen: dict[tuple, int] = {}
        for k, case in enumerate(self.case_overrides()):
            # 10000 and 10000.0 are one value
            same = tuple((key, _as_number(value)) for key, value in case.items())
            if same in seen:
                items = override_strings(case)
                raise ValueError(f"cases {seen[same]} and {k} are the same case "
                                 f"({', '.join(items) or 'no overrides'}): give each once")
            seen[same] = k

    def key_order(self) -> list[str]:
        """Every override key in the order it first appears: [set], [grid], then [[cases]].
        A case's overrides are put in this order, which names its folder, so that two cases
        equal as mappings are one case (the same keys in another order made two folders)."""
        keys = dict.fromkeys(self.set) | dict.fromkeys(self.grid)
        for case in self.cases:
            keys |= dict.fromkeys(case)
        return list(keys)

    def _check_figures(self) -> None:
        """Each figure's columns are sweep.csv's: refused here, not after every case ran."""
        known = (set(self.set) | set(self.grid) | {k for c in self.cases for k in c}
                 | set(self.reductions) | set(HEADLINE) | {"contact_duration"})
        for k, figure in enumerate(self.figures):
            listed = [v for v in self._values_of(figure.x) if isinstance(v, list | dict)]
            if listed:  # vectors as x would fail the figure after the run
                raise ValueError(f"figures.{k}.x = '{figure.x}': its values are not numbers "
                                 f"or text ({toml_value(listed[0])}): give a scalar key as x "
                                 "(a vector key can be `by`)")
            for key in ("x", "y", "by"):
                column = getattr(figure, key)
                if column is not None and column not in known:
                    raise ValueError(f"figures.{k}.{key} = '{column}': not a column of "
                                     f"sweep.csv (an override key, a reduction, or one of "
                                     f"{', '.join(HEADLINE)}, contact_duration)")

    def _values_of(self, key: str) -> list[Any]:
        """The values the file gives override ``key`` (none for another column)."""
        values = list(self.grid.get(key, []))
        return values + [c[key] for c in [self.set, *self.cases] if key in c]

    def case_overrides(self) -> list[dict[str, Any]]:
        """The cases in order: the grid's combinations (last key fastest), then ``cases``;
        each after the overrides of ``set`` (a case's own value of a key wins), its keys in
        :meth:`key_order`."""
        keys = list(self.grid)
        combos = [dict(zip(keys, values, strict=True))
                  for values in itertools.product(*self.grid.values())] if keys else []
        order = self.key_order()
        merged = [self.set | case for case in combos + [dict(c) for c in self.cases]]
        return [{key: case[key] for key in order if key in case} for case in merged]


#: history.csv's columns that depend on the model's supports and ties (engine.reactions,
#: io.results.tie_history): known only once the model is built
MODEL_HISTORY_PREFIXES = ("reaction_", "tie_")


def _check_history_column(where: str, column: str) -> None:
    """Refuse a reduction of a column history.csv never has, naming the close ones (else a misspelt
    column is an empty sweep.csv column). The columns come from the writers' lists, not from a run:
    they are checked before any case runs."""
    known = (*HISTORY_COLUMNS, "external_work", *CONTACT_HISTORY, *OFF_SURFACE_HISTORY)
    if column in known or column.startswith(MODEL_HISTORY_PREFIXES):
        return
    close = difflib.get_close_matches(column, known, n=3)
    hint = f" (did you mean {', '.join(close)}?)" if close else (
        f" (one of {', '.join(dict.fromkeys(known))}, or reaction_*/tie_* of the model)")
    raise ValueError(f"{where}: history.csv has no column '{column}'{hint}")


def load_sweep(path: str | Path) -> tuple[SweepSpec, Path]:
    """Read a sweep file: the spec and the scenario path (resolved against the file)."""
    path = Path(path)
    data = read_toml(path)
    try:
        spec = SweepSpec.model_validate(data)
    except ValidationError as err:
        problems = "; ".join(f"{'.'.join(map(str, e['loc'])) or '(top level)'}: {e['msg']}"
                             for e in err.errors())
        raise ScenarioError(f"{path}: invalid sweep file: {problems}") from None
    return spec, (path.parent / spec.scenario)


def _check_scenario_file(spec: str | Path, sweep_spec: SweepSpec, scenario: Path) -> None:
    """Refuse a sweep whose scenario file is missing, naming the sweep file and the folder
    the path is relative to ("nosuch.toml: scenario file not found" named neither)."""
    if not scenario.is_file():
        raise ScenarioError(f"{spec}: scenario = \"{sweep_spec.scenario}\": "
                            f"{'a folder' if scenario.is_dir() else 'no such file'} (looked "
                            f"for {scenario.resolve()}; the path is relative to the sweep "
                            f"file's folder {Path(spec).parent.resolve()})")


def case_name(overrides: Sequence[str]) -> str:
    """A folder name that depends only on the case's overrides (stable across reruns)."""
    digest = hashlib.sha1("\n".join(overrides).encode()).hexdigest()[:10]
    return f"case-{digest}"


def run_case(scenario_path: str, overrides: Mapping[str, Any], folder: str,
             reductions: Mapping[str, str]) -> dict[str, Any]:
    """One case, on a worker: run it unless its folder already completed the same overrides,
    and return its sweep.csv row. Never raises: a failure becomes the row's ``error``."""
    items = override_strings(overrides)
    row: dict[str, Any] = {"case": Path(folder).name, **overrides}
    started = time.time()  # what the folder holds from before is not this case's
    with contextlib.suppress(OSError):  # an earlier run's traceback is not this one's
        (Path(folder) / TRACEBACK_FILE).unlink(missing_ok=True)
    try:
        scenario = load_scenario(scenario_path, list(items))
        done = _completed(Path(folder), scenario)
        if done:
            results = read_results(folder)
        else:
            with single_threaded(), warnings.catch_warnings():  # one case per worker and core
                warnings.simplefilter("ignore")  # in the row (the summary's), not the log
                results = run(scenario, Path(folder), overwrite=True)  # read back from it
        row |= {"skipped": done} | _results_row(results, reductions)
    except Exception as err:  # recorded, the other cases go on
        row |= _written_so_far(folder, reductions, started)
        error = f"{type(err).__name__}: {err}".strip()
        if not isinstance(err, EXPECTED_ERRORS):
            error += f" (an internal error; its traceback is in {_save_traceback(folder)})"
        row |= {"status": "failed", "skipped": False, "error": error}
    return row


def _save_traceback(folder: str) -> str:
    """Write the current exception's traceback to the case's folder and return its path: in
    sweep.csv the one-line error says all a user needs."""
    path = Path(folder) / TRACEBACK_FILE
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(traceback.format_exc(), encoding="utf-8")
    except OSError as err:  # the error is recorded all the same
        return f"nowhere ({path} could not be written: {err.strerror})"
    return str(path)


def _written_so_far(folder: str, reductions: Mapping[str, str],
                    started: float) -> dict[str, Any]:
    """A failed case's headline figures and reductions from what its folder holds (how far it
    got); nothing where the folder holds no results, or only results from before
    ``started`` (a time.time()): a case whose edited base no longer built was recorded with
    the old scenario's results, and their ``completed``, as its own."""
    summary = Path(folder) / "summary.json"
    try:
        if summary.stat().st_mtime < started:
            return {}
        return _results_row(read_results(folder), reductions)
    except (OSError, ValueError):
        return {}


def _results_row(results: Any, reductions: Mapping[str, str]) -> dict[str, Any]:
    """A case's sweep.csv values from its read-back results (without case and overrides)."""
    summary = results.summary
    row: dict[str, Any] = {"error": summary.get("error")}
    row |= {k: summary.get(k) for k in HEADLINE if k in summary}
    # the lines ntncontact run prints, from the summary (also of a skipped case)
    lines = list(summary.get("build_warnings") or []) + result_warnings(summary)
    row["warnings"] = " | ".join(lines) or None
    # no duration where the run ended in contact (its end time is the run's); the column
    # stays when no case's contact ended
    row["contact_duration"] = None
    if row.get("contact_end_time") is not None and row.get("contact_start_time") is not None \
            and not row.get("contact_at_end"):
        row["contact_duration"] = row["contact_end_time"] - row["contact_start_time"]
    return row | _reduce(results.history, reductions)


def _rows_on_disk(work: list[tuple[dict, str, float]], rows: list[dict | None],
                  reductions: Mapping[str, str], started: float,
                  in_flight: Collection[int] = ()) -> list[dict]:
    """The rows of an interrupted sweep: those returned, and those of cases whose folder
    completed during this sweep (its summary written after ``started``, a time.time()) but
    whose result had not reached the client yet. A folder completed before it may hold
    another base scenario's results. A case still running (``in_flight``, indices of
    ``work``) is listed ``interrupted``: its worker is stopped when the sweep's cluster
    closes, or, on a running scheduler, may still complete its folder, which a rerun then
    reads back."""
    kept = []
    for i, ((case, folder, _), row) in enumerate(zip(work, rows, strict=True)):
        summary = Path(folder) / "summary.json"
        if (row is None and summary.is_file() and summary.stat().st_mtime >= started
                and _completed_summary(Path(folder), override_strings(case))):
            row = {"case": Path(folder).name, **case, "skipped": False}
            row |= _results_row(read_results(folder), reductions)
        elif row is None and i in in_flight:
            row = {"case": Path(folder).name, **case, "status": "interrupted",
                   "skipped": False, "error": "the sweep was interrupted while the case ran"}
        if row is not None:
            kept.append(row)
    return kept


def _completed(folder: Path, scenario: Scenario) -> bool:
    """Whether ``folder`` holds a completed run of this case: the same overrides, and the
    same validated scenario and meshes (``scenario_hash``, as a checkpoint is matched): a
    rerun after an edit of the base scenario runs the case again."""
    data = _completed_summary(folder, scenario.overrides)
    if data is None:
        return False
    with warnings.catch_warnings():  # the build's warnings are the case's row's, not the log's
        warnings.simplefilter("ignore")
        model = build_model(scenario.config, scenario.base_dir)
    identity = run_identity(scenario.config, scenario.overrides, model)
    return data.get("scenario_hash") == identity["scenario_hash"]


def _completed_summary(folder: Path, items: Sequence[str]) -> dict | None:
    """The summary of a completed run of these overrides in ``folder``, else None."""
    summary = folder / "summary.json"
    if not summary.is_file():
        return None
    data = json.loads(summary.read_text(encoding="utf-8"))
    if data.get("status") != "completed" or list(data.get("overrides", [])) != list(items):
        return None
    return data


def _reduce(history: pd.DataFrame, reductions: Mapping[str, str]) -> dict[str, float | None]:
    out: dict[str, float | None] = {}
    for name, spec in reductions.items():
        column, _, op = spec.partition(":")
        values = history[column].to_numpy(float) if column in history else np.empty(0)
        out[name] = REDUCTIONS[op](values) if values.size else None
    return out


def sweep(spec: str | Path, out: str | Path, *, scheduler: str | None = None,
          workers: int | None = None, progress: bool = True) -> pd.DataFrame:
    """Run every case of the sweep file ``spec`` on Dask into ``out`` and return the table
    written to ``out/sweep.csv``. ``scheduler``: the address of a running Dask scheduler;
    default a LocalCluster with ``workers`` single-threaded worker processes (one per core)."""
    if workers is not None and workers < 1:  # a LocalCluster of none waits for ever
        raise ValueError(f"workers must be >= 1, got {workers}")
    sweep_spec, scenario_path = load_sweep(spec)
    _check_scenario_file(spec, sweep_spec, scenario_path)
    load_scenario(scenario_path)  # a broken scenario fails here, once, not in every case
    cases = sweep_spec.case_overrides()
    out = Path(out)
    folders = [str(out / "cases" / case_name(override_strings(c))) for c in cases]
    meshes: dict[str, int] = {}
    keys = sweep_spec.key_order()
    checked = [_checked_case(spec, k, case, scenario_path, Path(folder), meshes, keys)
               for k, (case, folder) in enumerate(zip(cases, folders, strict=True))]
    ran_with = {Path(folder).name: values
                for folder, (_, values) in zip(folders, checked, strict=True)}
    (out / "cases").mkdir(parents=True, exist_ok=True)
    work = [(case, folder, cost)
            for case, folder, (cost, _) in zip(cases, folders, checked, strict=True)]
    rows: list[dict | None] = [None] * len(work)
    in_flight: set[int] = set()  # the cases submitted whose rows are not in yet
    started = time.time()  # folders completed from now on are this sweep's
    with _dask_client(scheduler, workers) as (client, cluster):
        try:
            _run_cases(client, cluster is not None, sweep_spec, str(scenario_path), work,
                       progress, rows, in_flight)
        except KeyboardInterrupt:  # the cases done so far are kept in sweep.csv
            done = [_filled(row, ran_with) for row in _rows_on_disk(
                work, rows, sweep_spec.reductions, started, in_flight)]
            pd.DataFrame(done, columns=None if done else ["case"]).to_csv(out / SWEEP_FILE,
                                                                          index=False)
            raise
        rows = [_filled(r, ran_with) for r in rows if r is not None]
        if cluster is not None:
            client.run(_quiet_worker_logs)  # every case's result is in
            cluster.scale(0)  # its workers shut down while the results are written
        table = pd.DataFrame(rows)
        table.to_csv(out / SWEEP_FILE, index=False)
        _draw_figures(table, sweep_spec.figures, out)
    return table


def _checked_case(spec: str | Path, k: int, case: Mapping[str, Any], scenario_path: Path,
                  folder: Path, meshes: dict[str, int],
                  keys: Sequence[str]) -> tuple[float, dict[str, Any]]:
    """:func:`case_cost` of case ``k``, whose scenario and meshes are checked here, before any
    case runs, and the value of each sweep key ``keys`` it runs with; an error names the sweep
    file and the case."""
    try:
        scenario = load_scenario(scenario_path, case)
        return case_cost(scenario, folder, meshes), _values(scenario, keys)
    except (ScenarioError, ValueError, OSError) as err:
        raise ScenarioError(f"{spec}: case {k} ({', '.join(override_strings(case))}): "
                            f"{err}") from None


def _as_number(value: Any) -> Any:
    """A value as a case compares it (hashable): numbers (not bools) as floats, lists and
    tables (a mesh given as a table) item by item."""
    if isinstance(value, Mapping):
        return tuple(sorted((k, _as_number(v)) for k, v in value.items()))
    if isinstance(value, (list, tuple)):
        return tuple(_as_number(v) for v in value)
    if isinstance(value, (int, float)) and not isinstance(value, bool):
        return float(value)
    return value


def _values(scenario: Scenario, keys: Sequence[str]) -> dict[str, Any]:
    """Each dotted key's value in the case's validated scenario (the base's, or the default):
    a case that does not set a sweep key has its value in sweep.csv and its figures too."""
    data = scenario.config.model_dump(mode="json")
    kind = scenario.config.analysis.kind
    for contact, config in zip(data.get("contact", []), scenario.config.contact, strict=True):
        # the keys whose default the build resolves (None in the config)
        contact |= {k: v for k, v in config.resolved(kind).items() if contact.get(k) is None}
    values = {}
    for key in keys:
        value: Any = data
        for part in key.split("."):
            if isinstance(value, list) and part.isdigit() and int(part) < len(value):
                value = value[int(part)]
            elif isinstance(value, dict) and part in value:
                value = value[part]
            else:
                value = None
                break
        values[key] = value
    return values


def _filled(row: dict[str, Any], ran_with: Mapping[str, Mapping[str, Any]]) -> dict[str, Any]:
    """A case's row with every sweep key's column, in the file's key order after ``case``:
    the case's own value, else the one it ran with (:func:`_values`)."""
    values = dict(ran_with.get(row["case"], {}))
    values |= {key: row[key] for key in values if key in row}
    return {"case": row["case"]} | values | row


def case_cost(scenario: Scenario, folder: Path, meshes: dict[str, int] | None = None) -> float:
    """A case's expected run time up to a constant, to start the longest cases first: its
    steps times its elements; 0 for a case its folder says completed (a rerun may only read
    it). ``meshes`` caches element counts by mesh settings (a grid repeats the same meshes);
    a mesh that cannot be built raises, also for a completed case."""
    meshes = {} if meshes is None else meshes
    cells = 0
    for body in scenario.config.bodies:
        key = body.mesh.model_dump_json()
        if key not in meshes:
            meshes[key] = len(build_mesh(body.mesh, body.name, scenario.base_dir).cells)
        cells += meshes[key]
    if _completed_summary(folder, scenario.overrides) is not None:  # an order, not a check
        return 0.0
    analysis = scenario.config.analysis
    return cells * analysis.t_end / analysis.dt


@contextlib.contextmanager
def _dask_client(scheduler: str | None, workers: int | None) -> Iterator[tuple[Any, Any]]:
    """A Dask client, and the LocalCluster it uses (with :data:`LOCAL_DASK_CONFIG`) unless
    ``scheduler`` gives the address of a running one (then the cluster is None)."""
    import dask
    from dask.distributed import Client, LocalCluster

    cluster = None
    if scheduler is None:
        with dask.config.set(LOCAL_DASK_CONFIG):  # read by the scheduler, nannies, workers
            cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                                   dashboard_address=None, scheduler_kwargs=SCHEDULER_HTTP)
    with contextlib.ExitStack() as teardown:
        try:
            with Client(cluster if cluster is not None else scheduler) as client:
                try:
                    yield client, cluster
                except KeyboardInterrupt:
                    teardown.enter_context(_logs_below_critical_dropped())
                    raise
                if cluster is not None:
                    _wait_until_workers_left(client)
        finally:
            if cluster is not None:
                cluster.close()


@contextlib.contextmanager
def _logs_below_critical_dropped() -> Iterator[None]:
    """Every logger drops its records below CRITICAL (``logging.disable``), restored on exit.
    For an interrupted sweep's closing client and cluster: the client forgets the cases still
    in flight, and a callback waiting on one logged "Exception in callback ... CancelledError
    ... 'forgotten'" with a traceback to the user's terminal through Tornado (the full suite
    under load, test_sweep's SIGINT case, once). The sweep.csv of the cases done is written by
    then, and nothing the teardown logs changes it. Dask sets its loggers' levels one by one
    ("distributed.client" its own), so silencing their parent would not reach them."""
    previous = logging.root.manager.disable
    logging.disable(logging.ERROR)
    try:
        yield
    finally:
        logging.disable(previous)


def _quiet_worker_logs() -> None:
    """Run on each worker of the sweep's own cluster once every case's result is in: its
    Dask logs below CRITICAL are dropped. A worker whose heartbeat is in flight while the
    scheduler drops it at the scale-down logs "Failed to communicate with scheduler during
    heartbeat" with a traceback to the user's terminal (a race inside Distributed, even with
    the wait below); nothing a worker can report then changes the sweep's results."""
    logging.getLogger("distributed").setLevel(logging.CRITICAL)


#: how long the scheduler waits for the scaled-down workers to leave before it closes
WORKERS_LEAVE_TIMEOUT_S = 60.0


def _wait_until_workers_left(client: Any) -> None:
    """Wait until the scheduler has no worker left (the sweep scaled its cluster to 0 while
    it wrote the results). Closed before that, the scheduler met a retiring worker's last
    heartbeat with a closed connection, and the worker logged an error with a traceback to
    the user's terminal."""
    deadline = time.monotonic() + WORKERS_LEAVE_TIMEOUT_S
    while client.scheduler_info().get("workers") and time.monotonic() < deadline:
        time.sleep(0.05)


def _run_cases(client: Any, own_cluster: bool, spec: SweepSpec, scenario_path: str,
               work: list[tuple[dict, str, float]], progress: bool,
               rows: list[dict | None], in_flight: set[int] | None = None) -> None:
    """The cases' rows into ``rows``, in the order of ``work`` (case, folder, cost), run
    longest first; the caller's list keeps the rows of the cases done if it is interrupted,
    and ``in_flight`` the indices of those submitted and not back yet.

    On the sweep's own LocalCluster one case per worker thread is in flight and the next
    longest goes to the first worker that is free (list scheduling: Dask assigns a few long
    tasks at submission, before their lengths are known, and a short case queued behind a
    long one then leaves the other worker idle at the end). On a running scheduler every
    case is submitted at once, longest first by priority, so that a cluster that is still
    scaling up sees all of them."""
    from dask.distributed import as_completed
    from tqdm import tqdm

    slots = max(sum(client.nthreads().values()), 1) if own_cluster else len(work)
    waiting = iter(enumerate(sorted(range(len(work)), key=lambda i: -work[i][2])))
    index: dict[str, int] = {}
    in_flight = set() if in_flight is None else in_flight

    def submit(rank: int, i: int) -> Any:
        case, folder, _ = work[i]
        future = client.submit(run_case, scenario_path, case, folder, spec.reductions,
                               pure=False, priority=len(work) - rank)
        index[future.key] = i
        in_flight.add(i)
        return future

    running = as_completed([submit(*item) for item in itertools.islice(waiting, slots)])
    with tqdm(total=len(work), unit="case", disable=not progress or None,
              file=sys.stderr) as bar:
        for future in running:
            rows[index[future.key]] = future.result()
            in_flight.discard(index[future.key])
            # released now, so that scaling the workers down after the last case does not
            # find a result still wanted ("... lose already computed task(s)" warnings)
            future.release()
            bar.update(1)
            for item in itertools.islice(waiting, 1):  # the next longest, if any
                running.add(submit(*item))


def _draw_figures(table: pd.DataFrame, figures: Sequence[FigureSpec], out: Path) -> None:
    """Each figure's PNG; one that cannot be drawn is a one-line warning, never an error: the
    cases ran, and their table must reach the caller."""
    for fig_spec in figures:
        try:
            _draw_figure(table, fig_spec, out)
        except Exception as err:  # noqa: BLE001 - the figure is lost, not the sweep
            warnings.warn(f"figure {fig_spec.y} against {fig_spec.x} not drawn: "
                          f"{type(err).__name__}: {err}", RuntimeWarning, stacklevel=2)


def _draw_figure(table: pd.DataFrame, fig_spec: FigureSpec, out: Path) -> None:
    """One figure: ``y`` against ``x``, a line per value of ``by`` (vectors by their text),
    made without pyplot (no figure of the caller's pyplot state touched). matplotlib is loaded
    here: a sweep without figures does not load it (~0.5 s) after its last case."""
    from matplotlib.figure import Figure

    missing = [c for c in (fig_spec.x, fig_spec.y, fig_spec.by) if c and c not in table]
    if missing:
        raise ScenarioError(f"no column {', '.join(missing)} in {SWEEP_FILE}")
    data = table[table[fig_spec.x].notna()]  # a case that failed to load has no value
    if data[fig_spec.x].dtype == object:  # text on a categorical axis
        data = data.assign(**{fig_spec.x: data[fig_spec.x].astype(str)})
    fig = Figure(figsize=(5, 3.5), layout="constrained")
    ax = fig.subplots()
    if fig_spec.by:
        labels = data[fig_spec.by].map(_label)
        groups = data.groupby(labels, sort=False)
    else:
        groups = [(None, data)]
    for label, group in groups:
        ok = group.sort_values(fig_spec.x)
        ax.plot(ok[fig_spec.x], ok[fig_spec.y], "o-",
                label=f"{fig_spec.by} = {label}" if fig_spec.by else None)
    ax.set_xlabel(fig_spec.x)
    ax.set_ylabel(fig_spec.y)
    if fig_spec.by:
        ax.legend()
    fig.savefig(out / f"sweep_{_slug(fig_spec.y)}_vs_{_slug(fig_spec.x)}.png", dpi=120)


def _label(value: Any) -> str:
    """A ``by`` value as a legend's text: a vector as TOML writes it, no value as "none"."""
    if isinstance(value, list | tuple | dict):
        return toml_value(value)
    if value is None or (isinstance(value, float) and np.isnan(value)):
        return "none"
    return str(value)


def _slug(name: str) -> str:
    return "".join(ch if ch.isalnum() else "_" for ch in name).strip("_")


__all__ = ["LOCAL_DASK_CONFIG", "SCHEDULER_HTTP", "SweepSpec", "case_cost", "load_sweep",
           "run_case", "sweep"]
