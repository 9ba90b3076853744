"""The figures of a results folder drawn on worker processes, after a run or while it goes on.

matplotlib draws on one core and the figures are independent, so two forked workers share them,
the slowest first (``ntncontact plot``). ``ntncontact run --plot`` starts the workers with the
run and has them do beforehand all they can: they import matplotlib while the first steps are
computed; with ``--gif``, the animation holds one worker for the whole run, which reads each
frame as it is written and draws the GIF when the run ends; the other worker makes the empty
figures it will draw, reads the frames too, draws the snapshots as soon as the frames they show
are written, and the other figures when the run ends (the first worker free takes the next).
Where the platform cannot fork, the figures are drawn one after the other in the calling
process.
"""

from __future__ import annotations

import contextlib
import multiprocessing as mp
import os
from collections.abc import Callable, Sequence
from concurrent.futures import BrokenExecutor, Future, ProcessPoolExecutor
from pathlib import Path
from typing import Any

from .plotting import (
    ANIMATION_SHAPE,
    FIGURE_MAKERS,
    HISTORY_SHAPE,
    PAIR_SHAPE,
    PVD_FILE,
    FigureShape,
    animate,
    check_made,
    panels_shape,
    plot_deformed,
    plot_figure,
    plot_pair_history,
    prefetch_frames,
    prepare_figures,
    warm_up,
)

WORKERS = 2  # this code's CI and demo machines have two cores
POLL_SECONDS = 0.05  # how often the animation looks for new frames during the run

# In a worker: (run ended, run completed), the events FigureJobs sets when the run ends, and
# the lock the workers beside a run take turns with.
_RUN_END: tuple[Any, Any] | None = None
_TURN: Any = None


def _import_matplotlib(turn: Any = None, run_end: tuple[Any, Any] | None = None) -> None:
    """Worker initializer: the ~1 s matplotlib import and the first figure's one-off work
    (:func:`~ntncontact.plotting.warm_up`), paid before the first figure is asked; holding
    ``turn`` (a lock shared by the workers) if given, so that one worker at a time does it
    (and later makes its empty figures). ``run_end``: the events of the run's end. Only fork
    can hand these over."""
    global _RUN_END, _TURN
    _RUN_END, _TURN = run_end, turn
    with _in_turn():
        from matplotlib.backends import backend_agg  # noqa: F401
        from PIL import Image  # noqa: F401

        warm_up()


def _in_turn() -> Any:
    """The workers' turn (beside a run: one at a time does its heavy preparation)."""
    return _TURN if _TURN is not None else contextlib.nullcontext()


def _prepare_in_turn(shapes: Sequence[FigureShape]) -> None:
    with _in_turn():
        prepare_figures(shapes)


def _animate_during_run(directory: Path, path: Path) -> Path | None:
    """The animation, submitted as the run starts: it holds one worker, which makes the
    empty figure, reads each frame as it is written and makes its mesh's paths, then draws
    the GIF once the run has completed (~0.08 s less after it). None if the run failed or
    was stopped: its frames' common colour scale and axis limits are only known at the end."""
    assert _RUN_END is not None, "only in a worker started by FigureJobs.start"
    ended, completed = _RUN_END
    _prepare_in_turn([ANIMATION_SHAPE])
    seen = None
    while not ended.wait(POLL_SECONDS):
        stamp = _mtime(directory / PVD_FILE)
        if stamp != seen:  # the PVD is rewritten after each new frame
            seen = stamp
            prefetch_frames(directory, meshes=True)
    if not completed.is_set():
        return None
    prefetch_frames(directory, meshes=True)  # the last frames (kept for the next figures too)
    return animate(directory, path)


def _mtime(path: Path) -> int | None:
    try:
        return path.stat().st_mtime_ns
    except OSError:
        return None


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
        self._run_end: tuple[Any, Any] | None = None  # (ended, completed), beside a run
        self._prefetch: Future | None = None
        self._pvd_seen: int | None = None

    def __enter__(self) -> FigureJobs:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def start(self, beside_a_run: bool = False) -> FigureJobs:
        """Fork the workers now (cheap before a run has built its arrays). ``beside_a_run``:
        the workers prepare one after the other, leaving the second core to the run, which
        starts at the same time (on two cores, three busy processes slowed its start-up);
        they still have the whole run to get ready, and use it (see the module's doc)."""
        if self._pool is None and "fork" in mp.get_all_start_methods():
            context = mp.get_context("fork")
            turn = context.Lock() if beside_a_run else None
            if beside_a_run:
                self._run_end = (context.Event(), context.Event())
            self._pool = ProcessPoolExecutor(WORKERS, context, initializer=_import_matplotlib,
                                             initargs=(turn, self._run_end))
            for _ in range(WORKERS):  # the pool forks its workers at the first submission
                self._pool.submit(int)
            if beside_a_run:
                # in this order: the animation takes the first worker ready for good, so
                # that the other worker prepares (and later draws) the other figures
                self._submit_animation()
                self._pool.submit(_prepare_in_turn, self._shapes_drawn_beside())
        return self

    def _shapes_drawn_beside(self) -> list[FigureShape]:
        """The shapes of the figures the worker that does not draw the animation draws."""
        shapes = {plot_pair_history: PAIR_SHAPE, plot_deformed: panels_shape(6)}
        makers = [m for m in FIGURE_MAKERS if not (self.times and m is plot_deformed)]
        snapshots = [panels_shape(min(len(self.times), 6))] if self.times else []
        return snapshots + [shapes.get(m, HISTORY_SHAPE) for m in makers]

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
        nearest to the times cannot change after it. Each new frame is read by a worker."""
        self._prefetch_new_frames()
        if self.times and "snapshots" not in self._requested \
                and record.state.time >= max(self.times) and self._frame_written(max(self.times)):
            self._submit_snapshots()

    def on_finish(self, status: str, error: str | None) -> None:
        """Draw what is left when the run completed; a failed run draws nothing more (its
        folder stays readable by ``ntncontact plot``)."""
        self._finished = status == "completed"
        self._end_run()
        if self._finished:
            self.submit_all()

    def paths(self) -> list[Path]:
        """The figures written (waiting for the workers): the snapshots and animation asked
        for, then the others the folder had data for. Errors of a figure are raised here."""
        requested = [p for p in map(_result, self._requested.values()) if p is not None]
        made = check_made([p for p in map(_result, self._figures) if p is not None],
                          self.directory)
        return made + requested

    def close(self) -> None:
        if self._pool is not None:
            self._end_run()  # an animation still waiting for the run gives up
            self._pool.shutdown(wait=True, cancel_futures=not self._finished)
            self._pool = None

    def _end_run(self) -> None:
        if self._run_end is not None and not self._run_end[0].is_set():
            ended, completed = self._run_end
            if self._finished:
                completed.set()
            ended.set()

    def _prefetch_new_frames(self) -> None:
        """Have a worker read the frames written since it last looked (one job at a time):
        the one beside the animation, which holds the other."""
        if self._pool is None or self._run_end is None or \
                (self._prefetch is not None and not self._prefetch.done()):
            return
        stamp = _mtime(self.directory / PVD_FILE)
        if stamp is not None and stamp != self._pvd_seen:
            self._pvd_seen = stamp
            with contextlib.suppress(BrokenExecutor):  # the figures will report it, not the run
                self._prefetch = self._pool.submit(prefetch_frames, self.directory)

    def _submit_snapshots(self) -> None:
        if self.times and "snapshots" not in self._requested:
            self._requested["snapshots"] = self._submit(
                plot_deformed, self.directory, self.times, path=self.directory / "snapshots.png")

    def _submit_animation(self) -> None:
        if self.gif and "animation" not in self._requested:
            during_run = self._pool is not None and self._run_end is not None
            self._requested["animation"] = self._submit(
                _animate_during_run if during_run else animate, self.directory,
                self.directory / "animation.gif")

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
