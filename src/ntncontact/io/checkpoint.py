"""Restart checkpoints of a run (the format is in docs/outputs.md).

Every ``analysis.checkpoint_interval`` of simulated time, after the step's rows are written,
:class:`Checkpointer` saves the whole state of the run to ``DIR/checkpoints/checkpoint_<step:08d>
.npz`` (``numpy.savez``: the arrays, and a JSON header under ``header``), written to a temporary
file, synced and renamed into place; the last two are kept. ``ntncontact run ... --restart``
(:func:`load_latest`) takes the newest readable one whose run identity (the validated scenario's
hash, the overrides, the package version) matches, cuts the folder's files back to its step and
continues: the restarted run writes what the uninterrupted run would have written, bit for bit.
"""

from __future__ import annotations

import hashlib
import json
import zipfile
from collections.abc import Iterable, Sequence
from dataclasses import fields
from pathlib import Path
from typing import Any

import numpy as np

from ..contact import PairState
from ..engine.config import ScenarioConfig
from ..engine.model import Model
from ..engine.problem import StepState
from ..engine.simulation import Simulation, StepRecord
from ..package import __version__
from .results import ResultWriter
from .run_folder import make_subfolder, replace_atomically
from .scenario import tomllib

FORMAT = "ntncontact-checkpoint/1"
CHECKPOINT_DIR = "checkpoints"
KEEP = 2  # checkpoints kept: the newest may be cut short by a kill while being written
PAIR_FIELDS = tuple(f.name for f in fields(PairState))


class CheckpointError(RuntimeError):
    """No usable checkpoint: none, none readable, or one of another run (one-line message)."""


def run_identity(config: ScenarioConfig, overrides: Sequence[str], model: Model) -> dict:
    """What a checkpoint must match to be continued: the hash of the validated scenario (and
    of the meshes it built, which may come from files), the overrides (:func:`_by_key`: the
    order of overrides of different keys does not matter) and the version."""
    digest = hashlib.sha256(config.model_dump_json().encode())
    digest.update(np.ascontiguousarray(model.X0, dtype=float).tobytes())
    digest.update(np.ascontiguousarray(model.cells, dtype=np.int64).tobytes())
    return {"scenario_hash": digest.hexdigest(),
            "overrides": _by_key(_normalized(item) for item in overrides),
            "version": __version__}


def _by_key(normalized: Iterable[str]) -> list[str]:
    """Normalized overrides (:func:`_normalized`) as the run applies them: one per key, with
    the key's last value (a later ``--set`` of a key replaces an earlier one), sorted by key.
    Overrides of different keys then compare equal in any order; the same key set twice
    keeps the order that matters, which value comes last. (Overlapping keys, a table and a
    key inside it, are told apart by the scenario hash: the validated scenario differs.)
    Checkpoints written before this kept the overrides as given: compared through it too."""
    final: dict[str, str] = {}
    for item in normalized:
        key, _, value = str(item).partition("=")
        final[key] = value
    return [f"{key}={final[key]}" for key in sorted(final)]


def _normalized(item: str) -> str:
    """``key = 0.10`` and ``key=0.1`` are the same override (values compared as TOML)."""
    key, _, raw = str(item).partition("=")
    try:
        value: Any = tomllib.loads(f"v = {raw}")["v"]
    except tomllib.TOMLDecodeError:
        value = raw.strip()
    return f"{key.strip()}={json.dumps(value, sort_keys=True, default=str)}"


def checkpoint_folder(directory: str | Path) -> Path:
    return Path(directory) / CHECKPOINT_DIR


def checkpoint_files(directory: str | Path) -> list[Path]:
    """The checkpoints in a results folder, newest (highest step) first."""
    found = checkpoint_folder(directory).glob("checkpoint_*.npz")
    return sorted((p for p in found if p.stem.rsplit("_", 1)[-1].isdigit()),
                  key=lambda p: int(p.stem.rsplit("_", 1)[-1]), reverse=True)


def remove_checkpoints(directory: str | Path) -> None:
    """A fresh run into the folder: an earlier run's checkpoints (and temporary files of a
    kill mid-write) go, so that --restart never continues them with this run's files."""
    folder = checkpoint_folder(directory)
    if not folder.is_dir() or folder.is_symlink():
        return
    for path in [*folder.glob("checkpoint_*.npz"), *folder.glob(".checkpoint_*.tmp")]:
        path.unlink(missing_ok=True)


class Checkpointer:
    """The observer (after the result writer) that writes checkpoints every ``interval`` of
    simulated time (None: never)."""

    def __init__(self, directory: str | Path, interval: float | None, identity: dict,
                 simulation: Simulation, writer: ResultWriter,
                 resume: dict | None = None) -> None:
        self.folder = checkpoint_folder(directory)
        self.interval = interval
        self.identity = identity
        self.simulation = simulation
        self.writer = writer
        self._next = float(resume["next_checkpoint"]) if resume is not None else interval
        if interval is not None:
            make_subfolder(self.folder)

    def on_step(self, model: Model, record: StepRecord) -> None:
        if self.interval is None or record.state.step == 0:
            return
        if record.state.time >= self._next - 1e-9 * model.analysis.dt:
            self._next = record.state.time + self.interval
            self.write()

    def on_finish(self, status: str, error: str | None) -> None:
        pass

    def write(self) -> Path:
        """Save the run's state after its last step; keep the newest :data:`KEEP`."""
        saved = self.simulation.checkpoint_state()
        state: StepState = saved["state"]
        header = {"format": FORMAT, "identity": self.identity, "step": state.step,
                  "time": state.time, "last_substep": saved["last_substep"],
                  "ledger": saved["ledger"], "energy_multiplier": saved["energy_multiplier"],
                  "first_rate": saved["first_rate"], "interfaces": len(state.contact),
                  "next_checkpoint": self._next,
                  "writer": self.writer.checkpoint_state()}
        arrays = {"X": state.X, "x": state.x, "d": state.d, "v": state.v, "a": state.a,
                  "union_keys": saved["union_keys"], "contact_force": saved["contact_force"]}
        solver_info, solver_arrays = saved["linear_solver"]
        header["linear_solver"] = solver_info
        arrays |= {f"solver_{name}": value for name, value in solver_arrays.items()}
        for index, pairs in enumerate(state.contact):
            arrays |= {f"contact_{index}_{name}": getattr(pairs, name) for name in PAIR_FIELDS}
        path = self.folder / f"checkpoint_{state.step:08d}.npz"
        replace_atomically(path, lambda tmp: _save(tmp, header, arrays), sync=True)
        for old in checkpoint_files(self.folder.parent)[KEEP:]:
            old.unlink(missing_ok=True)
        return path


def _save(path: Path, header: dict, arrays: dict[str, np.ndarray]) -> None:
    with open(path, "wb") as handle:  # a file object: savez would append ".npz" to a name
        np.savez(handle, header=np.array(json.dumps(header)), **arrays)


def read_checkpoint(path: str | Path) -> tuple[dict, dict[str, np.ndarray]]:
    """A checkpoint's header and arrays (no pickles); raises ``CheckpointError`` when the
    file cannot be read."""
    try:
        with np.load(path, allow_pickle=False) as data:
            arrays = {name: data[name] for name in data.files}
        header = json.loads(str(arrays.pop("header")))
    except (OSError, ValueError, KeyError, EOFError, zipfile.BadZipFile) as err:
        raise CheckpointError(f"{path}: not a readable checkpoint ({err})") from None
    if not isinstance(header, dict) or header.get("format") != FORMAT:
        raise CheckpointError(f"{path}: not a checkpoint of format {FORMAT}")
    return header, arrays


def load_latest(directory: str | Path, identity: dict) -> dict:
    """The newest readable checkpoint of a results folder, checked against ``identity``, as
    the values a restart resumes from: "simulation" (``Simulation.restore_state``), "writer"
    (``ResultWriter``'s ``resume``) and "checkpointer" (:class:`Checkpointer`'s)."""
    files = checkpoint_files(directory)
    if not files:
        raise CheckpointError(f"{directory}: no checkpoint to restart from (none in "
                              f"{CHECKPOINT_DIR}/: a run saves one every "
                              "analysis.checkpoint_interval of simulated time, so it was not "
                              "set, or the run stopped before its first)")
    unreadable = []
    for path in files:
        try:
            header, arrays = read_checkpoint(path)
        except CheckpointError as err:
            unreadable.append(str(err))
            continue
        check_identity(header["identity"], identity, path)
        return _resume_values(header, arrays)
    raise CheckpointError(f"{directory}: no readable checkpoint: " + "; ".join(unreadable))


def check_identity(saved: dict, current: dict, path: Path) -> None:
    """Refuse a checkpoint of another scenario, override set or package version."""
    if saved.get("version") != current["version"]:
        why = (f"ntncontact {saved.get('version')}, this is {current['version']}")
    elif _saved_overrides(saved) != _by_key(current["overrides"]):
        why = (f"other overrides ({_listed(_saved_overrides(saved))} there, "
               f"{_listed(_by_key(current['overrides']))} here)")
    elif saved.get("scenario_hash") != current["scenario_hash"]:
        why = "another scenario (its validated configuration or meshes differ)"
    else:
        return
    raise CheckpointError(f"{path} belongs to another run: written by {why}; restart with the "
                          "run's own scenario and --set options, or start afresh with "
                          "--overwrite")


def _saved_overrides(saved: dict) -> list[str] | None:
    """A checkpoint's overrides by key (older checkpoints hold them in the order given);
    None if the header holds no list of them (then no run's overrides match)."""
    overrides = saved.get("overrides")
    return _by_key(overrides) if isinstance(overrides, list) else None


def _listed(overrides: list | None) -> str:
    return "none" if not overrides else ", ".join(overrides)


def _resume_values(header: dict, arrays: dict[str, np.ndarray]) -> dict:
    contact = tuple(
        PairState(*(arrays[f"contact_{index}_{name}"] for name in PAIR_FIELDS))
        for index in range(int(header["interfaces"])))
    state = StepState(int(header["step"]), float(header["time"]), arrays["X"], arrays["d"],
                      arrays["v"], arrays["a"], contact)
    return {"simulation": {"state": state, "ledger": header["ledger"],
                           "energy_multiplier": header["energy_multiplier"],
                           "last_substep": header["last_substep"],
                           # Simulation._first_early_ratio's (checkpoints before it: none)
                           "first_rate": header.get("first_rate", 0.0),
                           # the stiffness pattern's union (checkpoints before it: none)
                           "union_keys": arrays.get("union_keys", np.zeros(0, np.int64)),
                           # static runs' trapezoidal contact work (checkpoints before: none)
                           "contact_force": arrays.get("contact_force"),
                           "linear_solver": (header["linear_solver"], {
                               name.removeprefix("solver_"): value
                               for name, value in arrays.items()
                               if name.startswith("solver_")})},
            "writer": header["writer"] | {"state": state},
            "checkpointer": {"next_checkpoint": header["next_checkpoint"]}}


def attach(simulation: Simulation, writer: ResultWriter, directory: str | Path,
           interval: float | None, identity: dict, resume: dict | None) -> Checkpointer:
    """Restore ``simulation`` from ``resume`` (or, for a fresh run, remove the folder's old
    checkpoints) and add the observer that writes checkpoints, after ``writer``."""
    if resume is not None:
        simulation.restore_state(resume["simulation"])
        for leftover in checkpoint_folder(directory).glob(".checkpoint_*.tmp"):  # a kill
            leftover.unlink(missing_ok=True)  # while one was written
    else:
        remove_checkpoints(directory)
    checkpointer = Checkpointer(directory, interval, identity, simulation, writer,
                                None if resume is None else resume["checkpointer"])
    simulation.observers.append(checkpointer)
    return checkpointer
