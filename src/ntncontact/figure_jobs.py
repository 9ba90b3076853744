"""The figures of a results folder drawn on worker processes, after a run or while it goes on.

matplotlib draws on one core and the figures are independent, so two forked workers share them,
the slowest first (``ntncontact plot``). ``ntncontact run --plot`` starts the workers with the
run: they import matplotlib while the first steps are computed, draw the snapshots as soon as the
frames they show are written, and the other figures when the run ends. Where the platform cannot
fork, the figures are drawn one after the other in the calling process.
"""

from __future__ import annotations

import contextlib
import multiprocessing as mp
import os
from collections.abc import Callable, Sequence
from concurrent.futures import Future, ProcessPoolExecutor
from pathlib import Path
from typing import Any

from .plotting import (
    FIGURE_MAKERS,
    PVD_FILE,
    animate,
    check_made,
    plot_deformed,
    plot_figure,
    warm_up,
)

WORKERS = 2  # this code's CI and demo machines have two cores


def _import_matplotlib(turn: Any = None) -> None:
    """Worker initializer: the ~1 s matplotlib import and the first figure's one-off work
    (:func:`~ntncontact.plotting.warm_up`), paid before the first figure is asked; holding
    ``turn`` (a lock shared by the workers) if given, so that one worker at a time does it."""
    with turn if turn is not None else contextlib.nullcontext():
        from matplotlib.backends import backend_agg  # noqa: F401
        from PIL import Image  # noqa: F401

        warm_up()


class FigureJobs:
    """The figures ``ntncontact plot DIR [--gif] [--times T ...]`` writes, as jobs: with
    ``times``, the deformed meshes at those times (snapshots.png) instead of six evenly spaced
    ones (deformed_von_mises.png).

    ``start()`` forks the workers; ``on_step``/``on_finish`` make it a simulation observer (put
    it after the results writer) that submits each figure once its data are on disk; ``paths()``
    waits for them. Use as a context manager so that the workers are always shut down.
    """

    def __init__(self, directory: str | os.PathLike, gif: bool = False,
                 times: Sequence[float] | None = None) -> None:
        self.directory = Path(directory)
        self.gif, self.times = gif, list(times) if times else None
        self._pool: ProcessPoolExecutor | None = None
        self._requested: dict[str, Future | Any] = {}  # snapshots and animation: must exist
        self._figures: list[Future | Any] = []  # the others: drawn when there are data
        self._finished = False

    def __enter__(self) -> FigureJobs:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def start(self, beside_a_run: bool = False) -> FigureJobs:
        """Fork the workers now (cheap before a run has built its arrays). ``beside_a_run``:
        the workers prepare one after the other, leaving the second core to the run, which
        starts at the same time (on two cores, three busy processes slowed its start-up);
        they still have the whole run to get ready."""
        if self._pool is None and "fork" in mp.get_all_start_methods():
            context = mp.get_context("fork")
            turn = context.Lock() if beside_a_run else None
            self._pool = ProcessPoolExecutor(WORKERS, context, initializer=_import_matplotlib,
                                             initargs=(turn,))
            for _ in range(WORKERS):  # the pool forks its workers at the first submission
                self._pool.submit(int)
        return self

    def submit_all(self) -> None:
        """Every figure not yet submitted, the slowest first."""
        self._submit_animation()
        self._submit_snapshots()
        if not self._figures:
            # the snapshots at the asked times take the place of six evenly spaced ones
            makers = [m for m in FIGURE_MAKERS if not (self.times and m is plot_deformed)]
            self._figures = [self._submit(plot_figure, make, self.directory) for make in makers]

    def on_step(self, model: object, record: Any) -> None:
        """Snapshots go out once a frame at or after their last time is written: the frames
        nearest to the times cannot change after it."""
        if self.times and "snapshots" not in self._requested \
                and record.state.time >= max(self.times) and self._frame_written(max(self.times)):
            self._submit_snapshots()

    def on_finish(self, status: str, error: str | None) -> None:
        """Draw what is left when the run completed; a failed run draws nothing more (its
        folder stays readable by ``ntncontact plot``)."""
        self._finished = status == "completed"
        if self._finished:
            self.submit_all()

    def paths(self) -> list[Path]:
        """The figures written (waiting for the workers): the snapshots and animation asked
        for, then the others the folder had data for. Errors of a figure are raised here."""
        requested = [_result(f) for f in self._requested.values()]
        made = check_made([p for p in map(_result, self._figures) if p is not None],
                          self.directory)
        return made + requested

    def close(self) -> None:
        if self._pool is not None:
            self._pool.shutdown(wait=True, cancel_futures=not self._finished)
            self._pool = None

    def _submit_snapshots(self) -> None:
        if self.times and "snapshots" not in self._requested:
            self._requested["snapshots"] = self._submit(
                plot_deformed, self.directory, self.times, path=self.directory / "snapshots.png")

    def _submit_animation(self) -> None:
        if self.gif and "animation" not in self._requested:
            self._requested["animation"] = self._submit(
                animate, self.directory, self.directory / "animation.gif")

    def _submit(self, fn: Callable[..., Any], *args: Any, **kwargs: Any) -> Future | Any:
        if self._pool is None:
            return fn(*args, **kwargs)
        return self._pool.submit(fn, *args, **kwargs)

    def _frame_written(self, time: float) -> bool:
        from .io.vtk import read_pvd

        pvd = self.directory / PVD_FILE
        return pvd.is_file() and any(t >= time for t, _ in read_pvd(pvd))


def _result(outcome: Future | Any) -> Any:
    return outcome.result() if isinstance(outcome, Future) else outcome
