"""The one set-up of a run into a results folder (or into memory), for ``ntncontact.run``,
``ntncontact run`` and ``ntncontact validate``."""

from __future__ import annotations

import contextlib
from collections.abc import Callable
from contextlib import AbstractContextManager
from pathlib import Path

from ..engine.builder import build_model
from ..engine.diagnostics import warnings_noted
from ..engine.model import Model
from ..engine.simulation import Simulation
from . import checkpoint
from .results import ResultWriter
from .run_folder import RunLock
from .scenario import Scenario


def check_run_mode(*, overwrite: bool, restart: bool) -> None:
    """Refuse a run asked both to continue and to replace the results folder's run (the one
    check and message of ``ntncontact.run`` and ``ntncontact run``)."""
    if restart and overwrite:
        raise ValueError("restart continues the run in the results folder, overwrite replaces "
                         "it: give one of them")


def start_run(scenario: Scenario, out: Path | None, *, overwrite: bool, restart: bool,
              writing: Callable[[ResultWriter], AbstractContextManager[object]] = (
                  lambda writer: contextlib.nullcontext()),
              lock: RunLock | None = None,
              building: Callable[[], AbstractContextManager[object]] = contextlib.nullcontext,
              built: Callable[[Model], None] | None = None) -> tuple[Simulation, ResultWriter]:
    """The run of ``scenario`` into the results folder ``out`` (None: in memory), set up for
    :meth:`Simulation.run`: the model, built inside ``building()`` and then given to ``built``
    (before any file is written); its results writer (``restart``: cut back to the folder's
    last checkpoint; ``lock``: the folder's lock if the caller took it); the simulation with
    the writer and the checkpoints attached, set up inside ``writing(writer)``, which answers
    for the writer when that fails."""
    check_run_mode(overwrite=overwrite, restart=restart)
    with warnings_noted() as build_warnings, building():  # kept in the summary
        model = build_model(scenario.config, scenario.base_dir)
    if built is not None:
        built(model)
    identity = checkpoint.run_identity(scenario.config, scenario.overrides, model)
    resume = checkpoint.load_latest(out, identity) if restart else None
    writer = ResultWriter(out, model, overwrite=overwrite,
                          resume=resume and resume["writer"], scenario=scenario.source,
                          title=scenario.config.title, overrides=list(scenario.overrides),
                          scenario_hash=identity["scenario_hash"],
                          build_warnings=build_warnings, lock=lock)
    with writing(writer):
        simulation = Simulation(model, [writer])
        if out is not None:
            checkpoint.attach(simulation, writer, out,
                              scenario.config.analysis.checkpoint_interval, identity, resume)
    return simulation, writer
