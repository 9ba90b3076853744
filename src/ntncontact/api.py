"""The public Python entry points: load a scenario, run it, read its results, sweep it.

Documented with runnable examples in docs/api.md (the test suite runs them)::

    import ntncontact as ntc

    scenario = ntc.load_scenario("examples/spinning_block.toml", {"analysis.t_end": 0.1})
    results = ntc.run(scenario, out="results/spin")
    results.history[["time", "total_energy"]]
"""

from __future__ import annotations

import contextlib
import copy
import json
import warnings
from collections.abc import Callable, Iterator, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import meshio
import numpy as np
import pandas as pd

from .engine.config import ScenarioError
from .io import writers
from .io.results import ResultWriter
from .io.run_folder import read_summary
from .io.run_setup import start_run
from .io.scenario import Overrides, Scenario
from .io.vtk import find_field_series, frame_index, read_frame_mesh, read_series
from .io.writers import CONTACT_FILE, HISTORY_FILE, SUMMARY_FILE, MemoryResults, to_jsonable
from .report.run_warnings import PhysicsWarning, result_warnings


def load_scenario(path: str | Path, overrides: Overrides = None) -> Scenario:
    """Read and validate a TOML scenario; ``overrides`` maps dotted keys to values
    (``{"contact.0.friction": 0.2}``) or lists ``"key=value"`` strings as ``--set`` takes."""
    return Scenario.from_file(path, overrides)


def scenario_from_dict(data: Mapping[str, Any], base_dir: str | Path = ".",
                       overrides: Overrides = None) -> Scenario:
    """A scenario from a plain mapping with the keys of a scenario file (docs/scenarios.md);
    mesh files are looked up relative to ``base_dir``. NumPy scalars and arrays are taken as
    the Python numbers and lists they hold (NumPy's integers are not Python ints, which
    strict validation requires)."""
    return Scenario.from_data(_plain(data), Path(base_dir), "<dict>", overrides)


def _plain(value: Any) -> Any:
    """``value`` with NumPy scalars and arrays replaced by Python numbers and lists."""
    if isinstance(value, np.generic | np.ndarray):
        return value.tolist()
    if isinstance(value, Mapping):
        return {key: _plain(item) for key, item in value.items()}
    if isinstance(value, list | tuple):
        return [_plain(item) for item in value]
    return copy.deepcopy(value)


@dataclass(frozen=True)
class Results:
    """A run's results: ``history`` and ``contact`` tables (pandas), the ``summary`` (dict),
    and the field frames (``times``; :meth:`fields` gives one as a meshio Mesh)."""

    history: pd.DataFrame
    contact: pd.DataFrame
    summary: dict[str, Any]
    directory: Path | None = None
    frames: tuple[tuple[float, Any], ...] = ()

    @property
    def times(self) -> list[float]:
        """Times of the field frames, in order."""
        return [t for t, _ in self.frames]

    def fields(self, t: float) -> meshio.Mesh:
        """The field frame at time ``t`` (within 1e-9 of the run's time scale): material
        points X, Q4 cells, point data (displacement, velocity, ...) and cell data."""
        if not self.frames:
            raise ValueError("these results hold no field frames")
        times = self.times
        k = frame_index(times, t)
        if k is None:
            shown = ", ".join(f"{time:g}" for time in times[:8])
            more = f", ... ({len(times)} in all)" if len(times) > 8 else ""
            raise ValueError(f"no field frame at t = {t:g}; frames at {shown}{more}")
        frame = self.frames[k][1]
        return frame if isinstance(frame, meshio.Mesh) else read_frame_mesh(frame)


def read_results(directory: str | Path) -> Results:
    """The results of a run folder (also of an interrupted or failed run: the rows written
    so far; an unterminated last CSV line is dropped)."""
    directory = Path(directory)
    summary_path = directory / SUMMARY_FILE
    if not summary_path.is_file():
        raise FileNotFoundError(f"{directory}: not a results folder (no {SUMMARY_FILE})")
    summary = read_summary(directory)  # a file that is not JSON is named
    series = find_field_series(directory)  # fields.pvd, or fields.xdmf (field_format)
    frames = tuple(read_series(series)) if series is not None else ()
    history, contact = (writers.read_table(path) if path.is_file() else pd.DataFrame()
                        for path in (directory / HISTORY_FILE, directory / CONTACT_FILE))
    return Results(history, contact, summary, directory, frames)


def run(scenario: Scenario | str | Path, out: str | Path | None = None, *,
        progress: Callable[[float], None] | None = None, overwrite: bool = False,
        restart: bool = False) -> Results:
    """Run a scenario (a :class:`Scenario` or a TOML path) into the results folder ``out``
    and return its :class:`Results`; with ``out=None`` nothing is written and the results
    are kept in memory (the same tables, summary and frames). A folder that already holds
    results is refused unless ``overwrite`` (then a run's old files are removed first), or
    ``restart``: continue the killed run in ``out`` from its last checkpoint
    (``analysis.checkpoint_interval``; the scenario and overrides must be the run's). A
    failed step raises (``SimulationError``) after the folder's summary says ``failed``. The
    warnings ``ntncontact run`` prints (penetration, energy) are issued as
    :class:`PhysicsWarning`, one per line, also before a failed run's error."""
    if isinstance(scenario, Mapping):
        raise TypeError("run takes a Scenario or the path of a scenario file; make a Scenario "
                        "of a dict with ntc.scenario_from_dict(data)")
    if not isinstance(scenario, Scenario):
        scenario = load_scenario(scenario)
    _check_run_arguments(out, progress)
    static = scenario.config.analysis.kind == "static"
    failed = None
    try:
        results = _run_with_writer(scenario, None if out is None else Path(out), progress,
                                   overwrite, restart)
    except _RunFailed as err:
        failed = err
    if failed is not None:  # its warnings before its error, as the command prints them
        _issue_warnings(failed.summary, static)
        raise failed.error  # as the run raised it (outside the except: no chained context)
    _issue_warnings(results.summary, static)
    return results


def _check_run_arguments(out: str | Path | None, progress: object) -> None:
    """Refuse, before the build, a ``progress`` that is not callable (it would fail the run
    after its first step) and an ``out`` naming a file."""
    if progress is not None and not callable(progress):
        raise TypeError(f"progress must be a function of the time t (or None), not "
                        f"{type(progress).__name__} {progress!r}")
    if out is not None and Path(out).exists() and not Path(out).is_dir():
        raise ValueError(f"out = {str(out)!r} is a file: give the results folder's path (a "
                         "folder, new or holding a run)")


class _RunFailed(Exception):
    """A run that failed after its writer started: the summary so far, for its warnings."""

    def __init__(self, summary: dict, error: Exception) -> None:
        super().__init__(str(error))
        self.summary, self.error = summary, error


def _run_with_writer(scenario: Scenario, out: Path | None,
                     progress: Callable[[float], None] | None, overwrite: bool,
                     restart: bool) -> Results:
    """:func:`run` into the results folder ``out``, or with ``out`` None in memory."""
    if out is None and (restart or scenario.config.analysis.checkpoint_interval is not None):
        raise ScenarioError(f"{scenario.source}: checkpoints and restarts need a results "
                            "folder: give out=...")
    simulation, writer = start_run(scenario, out, overwrite=overwrite, restart=restart,
                                   writing=_failed_with_summary)
    with _failed_with_summary(writer):
        simulation.run(progress)  # a failed step raises, with or without a folder
    return read_results(out) if out is not None else _results_of(writer.results)


@contextlib.contextmanager
def _failed_with_summary(writer: ResultWriter) -> Iterator[None]:
    """A failed run's error, carried with its summary so far (:class:`_RunFailed`): the
    warnings come before the error, as the command prints them. A run that failed before its
    time loop (which finishes the writer itself) is finished here: its folder says so."""
    try:
        yield
    except Exception as err:
        writer.on_finish("failed", str(err))
        raise _RunFailed(dict(writer.results.summary.data), err) from None


def _issue_warnings(summary: Mapping[str, Any], static: bool) -> None:
    """The warnings ``ntncontact run`` prints after a run, as :class:`PhysicsWarning` at the
    caller of :func:`run`."""
    for line in result_warnings(dict(summary), static):
        warnings.warn(line, PhysicsWarning, stacklevel=3)


def _results_of(kept: MemoryResults) -> Results:
    """Results from a memory writer, with the types the files would give (JSON summary)."""
    summary = json.loads(json.dumps(to_jsonable(kept.summary.data), allow_nan=False))
    history = pd.DataFrame(kept.history.rows, columns=list(kept.history.columns))
    contact = pd.DataFrame(kept.contact.rows, columns=list(kept.contact.columns))
    return Results(history, contact, summary, None, tuple(kept.fields.frames))
