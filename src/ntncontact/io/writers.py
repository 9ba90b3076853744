"""Result writers for a run folder: history CSV, contact CSV, summary JSON (and the VTU series).

Every writer leaves valid files behind at any moment: CSV rows are flushed as they are written
(a reader drops an unterminated last line, see :func:`read_table`) and the summary JSON is
replaced atomically. Files are created without following symbolic links (see
:mod:`ntncontact.io.run_folder`). :class:`ResultsDirectory` bundles the four writers for a time
loop and holds the folder's lock meanwhile.
"""

from __future__ import annotations

import csv
import io
import json
import math
import os
import signal
import time as _time
from collections.abc import Mapping, Sequence
from pathlib import Path
from types import TracebackType
from typing import Any

import numpy as np
import pandas as pd
from numpy.typing import ArrayLike, NDArray

from ntncontact.io.run_folder import (
    RunFolderError,
    RunLock,
    create_new_text,
    new_temporary,
    prepare,
    remove_leftovers,
    replace_atomically,
)
from ntncontact.io.vtk import VtuSeriesWriter, XdmfSeriesWriter, frame_mesh

HISTORY_FILE = "history.csv"
CONTACT_FILE = "contact.csv"
SUMMARY_FILE = "summary.json"

HISTORY_COLUMNS = (
    "step",
    "time",
    "kinetic_energy",
    "strain_energy",
    "total_energy",
    "linear_momentum_x",
    "linear_momentum_y",
    "angular_momentum",
    "newton_iterations",
)
CONTACT_COLUMNS = (
    "step",
    "time",
    "interface",
    "node_1",
    "node_2",
    "x",
    "y",
    "gap",
    "gap_rate",
    "normal_traction",
    "tangential_traction",
    "normal_force",
    "tangential_force",
    "status",
    "end_gap",
    "normal_x",
    "normal_y",
)
SUMMARY_STATUSES = ("running", "completed", "failed", "interrupted")
_STOP_SIGNALS = {signal.SIGINT, signal.SIGTERM}


def format_value(value: Any) -> str:
    """One CSV cell: integers and bools as integers, floats by ``repr`` (round-trips exactly)."""
    if isinstance(value, (bool, np.bool_, int, np.integer)):
        return str(int(value))
    if isinstance(value, (float, np.floating)):
        return repr(float(value))
    if isinstance(value, str):
        return value
    raise TypeError(f"cannot write {value!r} of type {type(value).__name__} to a CSV cell")


def _format_column(values: NDArray) -> list[str]:
    # Vectorised per dtype: tolist() yields Python scalars whose repr round-trips.
    if values.dtype.kind in "biu":
        return [str(int(v)) for v in values.tolist()]
    if values.dtype.kind == "f":
        return [repr(v) for v in values.tolist()]
    return [format_value(v) if not isinstance(v, str) else v for v in values.tolist()]


def _check_columns(extra_columns: Sequence[str], required: Sequence[str]) -> tuple[str, ...]:
    columns = tuple(required) + tuple(extra_columns)
    duplicates = sorted({c for c in columns if columns.count(c) > 1})
    if duplicates:
        raise ValueError(f"duplicate column names {duplicates}")
    return columns


def _check_keys(given: Sequence[str], expected: Sequence[str], what: str) -> None:
    missing = [c for c in expected if c not in given]
    unknown = [c for c in given if c not in expected]
    if missing or unknown:
        raise KeyError(f"{what}: missing columns {missing}, unknown columns {unknown}")


class _CsvWriter:
    """The new CSV file ``FILE`` in ``directory`` opened for writing with its header (the
    ``REQUIRED`` columns then ``extra_columns``) written and flushed (refused if the name is
    taken, by a file or a symbolic link). With ``resume_step`` (a restart), the existing file
    instead, cut back to its rows of steps up to ``resume_step`` (the first column is the
    step) and opened for appending."""

    FILE: str
    REQUIRED: tuple[str, ...]

    def __init__(self, directory: str | os.PathLike, extra_columns: Sequence[str] = (),
                 resume_step: int | None = None) -> None:
        self.path = Path(directory) / self.FILE
        self.columns = _check_columns(extra_columns, self.REQUIRED)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        if resume_step is not None:
            self._file = _truncated_to_step(self.path, self.columns, resume_step)
            return
        self._file = create_new_text(self.path)
        self._write_rows([list(self.columns)])

    def _write_rows(self, rows: Sequence[Sequence[str]]) -> None:
        """Append ``rows`` whole or not at all (the file object's own buffer is never used:
        a write it failed to flush would be retried, cut, at the next write or at close)."""
        if self._file.closed:
            raise ValueError(f"{self.path} is already closed")
        text = io.StringIO()
        csv.writer(text, lineterminator="\n").writerows(rows)
        _append_whole(self._file.fileno(), text.getvalue().encode("utf-8"), self.path)

    def close(self) -> None:
        self._file.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()


def _append_whole(fd: int, data: bytes, path: Path) -> None:
    """Append ``data`` to the file of ``fd``, all or nothing: a write that fails part-way (a
    full disk, a file-size limit) is cut back to the size before it, so that CSV rows stay
    whole (a row cut inside a number reads as a row with another value), and the error names
    the file."""
    start = os.lseek(fd, 0, os.SEEK_END)
    view = memoryview(data)
    try:
        while view:
            view = view[os.write(fd, view):]
    except OSError as err:
        os.ftruncate(fd, start)
        raise OSError(err.errno, err.strerror, str(path)) from None


def _truncated_to_step(path: Path, columns: tuple[str, ...], step: int) -> io.TextIOWrapper:
    """``path`` rewritten with its header and the complete rows of steps <= ``step`` (a new
    file renamed over it: a kill leaves the old or the new one), open for appending. The rows
    are in step order, so the cut is at the first later step."""
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise RunFolderError(f"{path} is missing: cannot restart the run in its folder") from None
    lines = text.split("\n")[:-1]  # complete lines only (a killed run may cut the last)
    if not lines or next(csv.reader(lines[:1])) != list(columns):
        raise RunFolderError(f"{path}: its columns are not this run's: cannot restart into it")
    kept = lines[:1]
    for line in lines[1:]:
        if int(line.split(",", 1)[0]) > step:
            break
        kept.append(line)
    fd, tmp = new_temporary(path)
    handle = os.fdopen(fd, "w", newline="", encoding="utf-8")
    try:
        handle.write("\n".join(kept) + "\n")
        handle.flush()
        os.replace(tmp, path)
    except BaseException:
        handle.close()
        tmp.unlink(missing_ok=True)
        raise
    return handle


class HistoryWriter(_CsvWriter):
    """``history.csv``: one row per output step, the required columns then ``extra_columns``."""

    FILE, REQUIRED = HISTORY_FILE, HISTORY_COLUMNS

    def last_step(self) -> int | None:
        """The step of the last complete row (None: header only)."""
        rows = read_csv_table(self.path)["step"]
        return int(rows[-1]) if len(rows) else None

    def write(self, row: Mapping[str, Any]) -> None:
        """Append one row; ``row`` must hold exactly the writer's columns."""
        _check_keys(list(row), self.columns, str(self.path))
        self._write_rows([[format_value(row[c]) for c in self.columns]])


class ContactWriter(_CsvWriter):
    """``contact.csv``: one row per active node pair per output step."""

    FILE, REQUIRED = CONTACT_FILE, CONTACT_COLUMNS

    def write_step(self, step: int, time: float, pairs: Mapping[str, ArrayLike]) -> int:
        """Append the rows of one output step and return how many were written.

        ``pairs`` maps every column except ``step`` and ``time`` to an array with one entry per
        active pair; scalars (e.g. a single ``interface`` name) are repeated for every pair.
        """
        count, columns = _pair_columns(pairs, self.columns[2:], str(self.path))
        cells = [[format_value(step)] * count, [format_value(time)] * count]
        cells += [_format_column(column) for column in columns.values()]
        self._write_rows(list(zip(*cells, strict=True)))
        return count


def _pair_columns(pairs: Mapping[str, ArrayLike], columns: Sequence[str],
                  where: str) -> tuple[int, dict[str, NDArray]]:
    """The pair count and each of ``columns`` as a 1D array of it (scalars repeated)."""
    _check_keys(list(pairs), columns, where)
    arrays = {name: np.asarray(values) for name, values in pairs.items()}
    lengths = {name: a.shape[0] for name, a in arrays.items() if a.ndim > 0}
    if not lengths:
        raise ValueError("contact rows need at least one per-pair array (e.g. node_1)")
    count = max(lengths.values())
    wrong = {name: n for name, n in lengths.items() if n != count}
    if wrong or any(a.ndim > 1 for a in arrays.values()):
        raise ValueError(f"contact columns must be 1D of length {count}; got lengths {wrong}")
    return count, {name: np.broadcast_to(arrays[name], (count,)) for name in columns}


def to_jsonable(value: Any) -> Any:
    """Convert numpy scalars/arrays, paths and tuples to JSON types; non-finite floats to None.

    Non-finite floats become ``null`` so the file is strict JSON that any parser accepts.
    """
    if isinstance(value, Mapping):
        return {str(k): to_jsonable(v) for k, v in value.items()}
    if isinstance(value, np.ndarray):
        return to_jsonable(value.tolist())
    if isinstance(value, (list, tuple)):
        return [to_jsonable(v) for v in value]
    if isinstance(value, np.generic):
        return to_jsonable(value.item())
    if isinstance(value, float) and not math.isfinite(value):
        return None
    if isinstance(value, os.PathLike):
        return os.fspath(value)
    if value is None or isinstance(value, (bool, int, float, str)):
        return value
    raise TypeError(f"cannot write {value!r} of type {type(value).__name__} to JSON")


class SummaryWriter:
    """``summary.json``: run status, step count, simulated time, wall time and energy
    conservation.

    ``wall_time_s`` is measured from construction unless given, and ``cpu_time_s`` (the
    process's CPU time over the same span, all threads) with it. The energy statistics come from
    :meth:`record_energy`: ``energy_max_relative_variation`` is max |E - E0| / |E0| (null when
    E0 is zero). :meth:`update` checks every value at once and rewrites the file every time,
    so that it never lags history.csv by more than the step being written.

    While the status is "running" the file is rewritten in place: one ``pwrite`` at offset 0 of
    the file this writer created, padded with spaces (valid JSON) so that it never shrinks.
    Renaming a new file over it instead cost 1-8 ms a step here (ext4 flushes the new file's
    data when a rename replaces a file), ~10 % of the ring impact's time loop; the write costs
    microseconds. A write of a few hundred bytes is whole or absent after a kill; a reader
    that catches one mid-write (a window of microseconds) reads again
    (:func:`ntncontact.io.run_folder.read_summary`). Any other status, and :meth:`finish`,
    replace the file atomically, synced to disk.
    """

    def __init__(self, directory: str | os.PathLike | None, **extra: Any) -> None:
        """``directory`` None: the summary is kept in memory only (``ntncontact.run(out=None)``)."""
        self.path = None if directory is None else Path(directory) / SUMMARY_FILE
        if self.path is not None:
            self.path.parent.mkdir(parents=True, exist_ok=True)
        self._start = _time.perf_counter()
        self._cpu_start = _time.process_time()
        self._max_variation = 0.0
        self._file: io.RawIOBase | None = None  # summary.json, while rewritten in place
        self._size = 0  # its length
        self._data: dict[str, Any] = {
            "steps": 0,
            "time": 0.0,
            "wall_time_s": 0.0,
            "cpu_time_s": 0.0,
            "energy_initial": None,
            "energy_final": None,
            "energy_max_relative_variation": None,
            "status": "running",
            "error": None,
        }
        self.update(**extra)

    @property
    def data(self) -> dict[str, Any]:
        """A copy of the current summary contents."""
        return dict(self._data)

    def checkpoint_state(self) -> dict[str, Any]:
        """The running values a restart needs (JSON types; see :meth:`restore`)."""
        return {"data": to_jsonable(self._data), "max_variation": self._max_variation,
                "wall_time_s": _time.perf_counter() - self._start,
                "cpu_time_s": _time.process_time() - self._cpu_start}

    def restore(self, saved: Mapping[str, Any]) -> None:
        """Continue from :meth:`checkpoint_state`'s values (the wall time goes on from
        the checkpoint's) and rewrite the file."""
        self._max_variation = float(saved["max_variation"])
        self._start = _time.perf_counter() - float(saved["wall_time_s"])
        self._cpu_start = _time.process_time() - float(saved.get("cpu_time_s", 0.0))
        self.update(**(dict(saved["data"]) | {"status": "running", "error": None}))

    def record_energy(self, step: int, total_energy: float, time: float | None = None) -> None:
        """Track the total energy of an output step at ``time`` (does not write; call
        :meth:`update`)."""
        energy = float(total_energy)
        if self._data["energy_initial"] is None:
            self._data["energy_initial"] = energy
        initial = self._data["energy_initial"]
        self._data["energy_final"] = energy
        if int(step) >= int(self._data["steps"]) and time is not None:
            self._data["time"] = float(time)
        self._data["steps"] = max(int(step), int(self._data["steps"]))
        if initial != 0.0:
            self._max_variation = max(self._max_variation, abs(energy - initial) / abs(initial))
            self._data["energy_max_relative_variation"] = self._max_variation

    def update(self, **fields: Any) -> None:
        """Merge ``fields`` into the summary and rewrite the file."""
        status = fields.get("status", self._data["status"])
        if status not in SUMMARY_STATUSES:
            raise ValueError(f"summary status must be one of {SUMMARY_STATUSES}, got {status!r}")
        if "wall_time_s" not in fields:
            fields["wall_time_s"] = _time.perf_counter() - self._start
            fields["cpu_time_s"] = _time.process_time() - self._cpu_start
        merged = self._data | fields
        # formatted first: a value JSON cannot hold leaves the file and the state unchanged
        text = json.dumps(to_jsonable(merged), indent=2, allow_nan=False) + "\n"
        if self.path is not None and status == "running":
            self._write_in_place(text.encode())
        elif self.path is not None:
            self._write_final(text)
        self._data = merged

    def _write_final(self, text: str) -> None:
        """The final summary as a new file renamed over the old one, or, where no new file
        can be made (a full disk, a folder that takes no new file), written in place as while
        running: else the file would say "running", which ``ntncontact status`` calls a killed
        run."""
        try:
            replace_atomically(self.path, lambda tmp: tmp.write_text(text, encoding="utf-8"),
                               sync=True)
        except OSError:
            if self._file is None:
                raise
            self._write_in_place(text.encode())
        finally:
            self.close()

    def finish(self, status: str = "completed", error: str | None = None, **fields: Any) -> None:
        """Record the final status (and error message) of the run."""
        self.update(status=status, error=error, **fields)

    def close(self) -> None:
        """Stop rewriting the file in place (:meth:`finish` does this)."""
        if self._file is not None:
            self._file.close()
            self._file = None

    def _write_in_place(self, data: bytes) -> None:
        if self._file is None:  # a new file, renamed over the name (a planted link: replaced)
            fd, tmp = new_temporary(self.path)
            self._file = os.fdopen(fd, "r+b", buffering=0)
            self._file.write(data)
            os.replace(tmp, self.path)
        else:
            os.pwrite(self._file.fileno(), data.ljust(self._size), 0)
        self._size = max(self._size, len(data))


#: how many ResultsDirectory.close calls are writing a run's last files now
_CLOSING = [0]


def closing() -> bool:
    """Whether a run folder is writing its last files (summary.json's status) now: a stop
    signal's handler must not raise into that."""
    return _CLOSING[0] > 0


class _Results:
    """What :class:`ResultsDirectory` and :class:`MemoryResults` share."""

    history: HistoryWriter | _MemoryTable
    summary: SummaryWriter

    def write_history(self, row: Mapping[str, Any], **summary_fields: Any) -> None:
        """Append a history row, then rewrite the summary with its step count, time and
        energy statistics, and ``summary_fields``."""
        self.history.write(row)
        self.summary.record_energy(row["step"], row["total_energy"], row.get("time"))
        self.summary.update(**summary_fields)


class ResultsDirectory(_Results):
    """All writers of one run folder; use as a context manager around the time loop, or call
    :meth:`close` with the run's status.

    The folder is locked while the writers are open, and refused if it holds results already
    unless ``overwrite`` (see :func:`ntncontact.io.run_folder.prepare`). On leaving the ``with``
    block the summary status becomes ``completed``, ``interrupted`` (KeyboardInterrupt) or
    ``failed`` (any other exception, message in ``error``).
    """

    def __init__(
        self,
        directory: str | os.PathLike,
        history_columns: Sequence[str] = (),
        overwrite: bool = False,
        resume: Mapping[str, Any] | None = None,
        field_format: str = "vtu",
        lock: RunLock | None = None,
        **summary_extra: Any,
    ) -> None:
        """``lock``: the folder's lock, taken by the caller already (``ntncontact run`` takes
        it before the model's build), now this writer's to release."""
        self.directory = Path(directory)
        # a restart keeps the folder's results (cut back to the checkpoint, below)
        if resume is not None and lock is not None:
            lock.set_phase(None)
        self._lock: RunLock | None = (prepare(self.directory, overwrite, lock)
                                      if resume is None
                                      else lock or RunLock.acquire(self.directory))
        step = None if resume is None else int(resume["step"])
        try:
            # the fields first: without h5py the xdmf writer stops before any file exists;
            # VTU frames are compressed and written beside the next step (VtuSeriesWriter)
            self.fields = (XdmfSeriesWriter(self.directory) if field_format == "xdmf"
                           else VtuSeriesWriter(self.directory, background=True))
            if resume is not None:
                remove_leftovers(self.directory)  # of a kill mid-write
                # may fail (an unreadable fields.h5): before any other file is cut back or
                # rewritten
                self.fields.resume(step, resume["pvd_entries"])
            self.history = HistoryWriter(self.directory, history_columns, step)
            if step is not None and self.history.last_step() != step:
                raise RunFolderError(f"{self.history.path} does not reach the checkpoint's "
                                     f"step {step}: it is not the checkpointed run's")
            self.contact = ContactWriter(self.directory, resume_step=step)
            self.summary = SummaryWriter(self.directory, **summary_extra)
            if resume is not None:
                self.summary.restore(resume["summary"])
        except BaseException:
            for writer in (getattr(self, "history", None), getattr(self, "contact", None)):
                if writer is not None:
                    writer.close()
            self._lock.release()
            raise

    def checkpoint_state(self, step: int) -> dict[str, Any]:
        """What :class:`ResultsDirectory` needs as ``resume`` to continue after ``step``:
        the step, the PVD entries (the output cursor of the frames) and the summary."""
        self.fields.flush()  # the frames so far on disk (XDMF: fields.h5 flushed)
        return {"step": int(step), "pvd_entries": [list(e) for e in self.fields.entries],
                "summary": self.summary.checkpoint_state()}

    @property
    def closed(self) -> bool:
        return self._lock is None

    def close(self, status: str = "completed", error: str | None = None,
              **summary_fields: Any) -> None:
        """Close the CSV files, write the final summary and release the folder (only the
        first call acts)."""
        if self._lock is None:
            return
        # A signal (a second Ctrl-C) waits until this is done: it must not leave the summary
        # saying "running" with the files closed. The mask holds it off this thread; one
        # that another thread (the VTU writer's) takes still runs its Python handler here,
        # and the command's handler asks closing()
        held = signal.pthread_sigmask(signal.SIG_BLOCK, _STOP_SIGNALS)
        _CLOSING[0] += 1
        try:
            self.history.close()
            self.contact.close()
            try:
                self.fields.close()  # a VTU frame still in flight is written first
            except Exception as err:  # its writing failed (a full disk): the run too
                status, error = "failed", error or f"{type(err).__name__}: {err}"
                raise
        finally:
            try:
                self.summary.finish(status, error, **summary_fields)
            finally:
                self._lock.release()
                self._lock = None
                _CLOSING[0] -= 1
                signal.pthread_sigmask(signal.SIG_SETMASK, held)

    def __enter__(self) -> ResultsDirectory:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        traceback: TracebackType | None,
    ) -> None:
        if exc_type is None:
            self.close("completed")
        elif issubclass(exc_type, KeyboardInterrupt):
            self.close("interrupted", str(exc) or "interrupted by the user")
        else:
            self.close("failed", f"{exc_type.__name__}: {exc}")


class MemoryResults(_Results):
    """A run's results kept in memory (``ntncontact.run(out=None)``): what
    :class:`ResultsDirectory` writes, received through the same methods, nothing on disk. The
    history rows, the contact rows of each step, the summary and the field frames (meshio
    meshes, the VTU files' content) are read back as tables by ``ntncontact.api``."""

    def __init__(self, history_columns: Sequence[str] = (), **summary_extra: Any) -> None:
        self.history = _MemoryTable(_check_columns(history_columns, HISTORY_COLUMNS))
        self.contact = _MemoryTable(CONTACT_COLUMNS)
        self.fields = _MemoryFrames()
        self.summary = SummaryWriter(None, **summary_extra)
        self.closed = False

    def close(self, status: str = "completed", error: str | None = None,
              **summary_fields: Any) -> None:
        if not self.closed:
            self.closed = True
            self.summary.finish(status, error, **summary_fields)

    def checkpoint_state(self, step: int) -> dict[str, Any]:
        raise RunFolderError("checkpoints need a results folder (out=...)")


class _MemoryTable:
    """Rows of history.csv or contact.csv kept as values: ``write`` takes a history row,
    ``write_step`` a step's contact pairs (as :class:`ContactWriter.write_step`)."""

    def __init__(self, columns: tuple[str, ...]) -> None:
        self.columns = columns
        self.rows: list[dict[str, Any]] = []

    def write(self, row: Mapping[str, Any]) -> None:
        _check_keys(list(row), self.columns, "history")
        self.rows.append({c: row[c] for c in self.columns})

    def write_step(self, step: int, time: float, pairs: Mapping[str, ArrayLike]) -> int:
        count, columns = _pair_columns(pairs, self.columns[2:], "contact")
        self.rows += [{"step": step, "time": time} | {n: c[i].item() for n, c in columns.items()}
                      for i in range(count)]
        return count


class _MemoryFrames:
    """Field frames kept as meshio meshes, as the VTU series would write them."""

    def __init__(self) -> None:
        self.frames: list[tuple[float, Any]] = []

    def write(self, step: int, time: float, points: ArrayLike, cells: ArrayLike,
              point_data: Mapping[str, ArrayLike], cell_data: Mapping[str, ArrayLike]) -> None:
        self.frames.append((float(time), frame_mesh(points, cells, point_data, cell_data)))


def read_table(path: str | os.PathLike) -> pd.DataFrame:
    """A results CSV as a DataFrame of its complete lines (a run killed mid-write may cut the
    last; rows with too many cells are dropped); empty when no line is complete. Only "nan"
    is a missing value: an interface named "NA" or "null" stays a name."""
    text = Path(path).read_text(encoding="utf-8")
    complete = text[: text.rfind("\n") + 1]
    if not complete.strip():
        return pd.DataFrame()
    return pd.read_csv(io.StringIO(complete), on_bad_lines="skip", keep_default_na=False,
                       na_values=["nan"])


def read_csv_table(path: str | os.PathLike) -> dict[str, NDArray]:
    """A results CSV's columns as arrays (int, float, or object for text), as
    :func:`read_table` reads it; a ValueError without a header line."""
    table = read_table(path)
    if table.columns.empty:
        raise ValueError(f"{path} has no header line")
    return {name: column.to_numpy() for name, column in table.items()}
