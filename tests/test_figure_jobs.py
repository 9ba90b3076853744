"""Figures drawn while a run goes on (``ntncontact run --plot``) and by ``ntncontact plot``."""

import json

from helpers import EXAMPLES, model_from_example

import ntncontact.figure_jobs as figure_jobs
from ntncontact.cli import main
from ntncontact.io.results import ResultWriter
from ntncontact.io.vtk import read_pvd
from ntncontact.plotting import ANIMATION_SHAPE, animate, panels_shape
from ntncontact.simulation import Simulation

TIMES = ["0.1", "0.3"]


def test_run_with_plot_writes_the_figures_of_plot(tmp_path, capsys):
    live, after = tmp_path / "live", tmp_path / "after"
    args = [str(EXAMPLES / "rod_impact.toml"), "--quiet", "--set", "analysis.t_end=0.5"]
    assert main(["run", *args, "--out", str(live), "--gif", "--times", *TIMES]) == 0
    printed = capsys.readouterr().out
    assert main(["run", *args, "--out", str(after)]) == 0
    assert main(["plot", str(after), "--gif", "--times", *TIMES]) == 0
    names = {p.name for p in live.glob("*.png")} | {p.name for p in live.glob("*.gif")}
    assert names == {p.name for p in after.glob("*.png")} | {p.name for p in after.glob("*.gif")}
    assert {"snapshots.png", "animation.gif", "energies.png", "pair_history.png"} <= names
    assert "deformed_von_mises.png" not in names  # the snapshots at the times take its place
    assert all(str(live / name) in printed for name in names)
    assert main(["plot", str(after)]) == 0  # no times: six evenly spaced meshes
    assert (after / "deformed_von_mises.png").is_file()


def test_snapshots_are_drawn_once_their_frames_exist_and_before_the_run_ends(tmp_path,
                                                                             monkeypatch):
    """Serial mode (no workers started): the snapshot job runs inside the observer call, so
    it sees the results folder exactly as it was when it was submitted."""
    seen = []

    def spy(directory, times, path):
        seen.append([t for t, _ in read_pvd(directory / "fields.pvd")])
        path.write_bytes(b"png")
        return path

    monkeypatch.setattr(figure_jobs, "plot_deformed", spy)
    model = model_from_example("rod_impact.toml", ["analysis.t_end=0.5"])
    out = tmp_path / "r"
    jobs = figure_jobs.FigureJobs(out, times=[0.1, 0.23])
    monkeypatch.setattr(jobs, "_submit_animation", lambda: None)
    monkeypatch.setattr(figure_jobs, "FIGURE_MAKERS", ())
    monkeypatch.setattr(figure_jobs, "check_made", lambda made, directory: made)
    Simulation(model, [ResultWriter(out, model), jobs]).run()
    assert len(seen) == 1
    written, final = seen[0], [t for t, _ in read_pvd(out / "fields.pvd")]
    # a frame after the last time was listed, and the run went on (the frames are written on
    # a background thread: the PVD may list one more by the step that sees the first)
    assert written[-1] >= 0.23 and sum(t >= 0.23 for t in written) <= 2
    assert len(written) < len(final)
    assert jobs.paths() == [out / "snapshots.png"]


def test_failed_run_with_plot_stops_its_workers_and_keeps_the_folder(tmp_path, capsys):
    out = tmp_path / "o"
    # one Newton iteration fails at step 10 only narrowly (|R| 1.4e-8 against 4.0e-9) with the
    # report's pair forces; the moment-free ones converge there in one iteration
    code = main(["run", str(EXAMPLES / "rod_impact.toml"), "--out", str(out), "--quiet", "--gif",
                 "--set", "analysis.t_end=0.5", "--set", "analysis.max_cutbacks=0",
                 "--set", "analysis.newton.max_iterations=1",
                 "--set", "contact.0.moment_free=false"])
    assert code == 1 and "error" in capsys.readouterr().err
    assert json.loads((out / "summary.json").read_text())["status"] == "failed"
    assert not list(out.glob("*.png")) and not list(out.glob("*.gif"))  # nothing drawn
    assert main(["plot", str(out)]) == 0  # but the folder is still plottable
    assert (out / "energies.png").is_file()


def _record_warm_up(log):
    import os
    import time

    def warm_up(*args):
        start = time.monotonic()
        time.sleep(0.3)
        with open(log, "a") as handle:
            handle.write(f"{os.getpid()} {start} {time.monotonic()}\n")
    return warm_up


def _warm_up_intervals(tmp_path, monkeypatch, beside_a_run):
    log = tmp_path / f"warm_{beside_a_run}.log"
    monkeypatch.setattr(figure_jobs, "warm_up", _record_warm_up(log))
    with figure_jobs.FigureJobs(tmp_path).start(beside_a_run=beside_a_run):
        pass  # closing waits for the workers, hence for their initializers
    rows = [line.split() for line in log.read_text().splitlines()]
    return sorted((float(a), float(b)) for _, a, b in rows)


def test_workers_beside_a_run_prepare_one_at_a_time(tmp_path, monkeypatch):
    """Beside a run the two workers take turns (one core stays with the run); for
    ``ntncontact plot`` they prepare together."""
    first, second = _warm_up_intervals(tmp_path, monkeypatch, beside_a_run=True)
    assert second[0] >= first[1]
    first, second = _warm_up_intervals(tmp_path, monkeypatch, beside_a_run=False)
    assert second[0] < first[1]


def test_beside_a_run_the_workers_also_make_their_figures_in_turn(tmp_path, monkeypatch):
    """The empty figures made ahead (the animation's, and the other worker's) wait for the
    warm-ups and for each other: one worker busy beside the run at a time."""
    import time

    from matplotlib.backends import backend_agg  # noqa: F401 - the workers' imports: instant
    from PIL import Image  # noqa: F401

    log = tmp_path / "turns.log"
    monkeypatch.setattr(figure_jobs, "warm_up", _record_warm_up(log))
    monkeypatch.setattr(figure_jobs, "prepare_figures", _record_warm_up(log))
    with figure_jobs.FigureJobs(tmp_path, gif=True).start(beside_a_run=True):
        deadline = time.monotonic() + 60.0
        while len(_lines(log)) < 4 and time.monotonic() < deadline:
            time.sleep(0.02)
    intervals = sorted(tuple(map(float, what.split())) for _, what in _lines(log))
    assert len(intervals) == 4
    assert all(b[0] >= a[1] for a, b in zip(intervals, intervals[1:], strict=False))


def _log_calls(monkeypatch, module, name, log, describe):
    """Replace module.name by a wrapper appending ``pid describe(args)`` lines to ``log`` (a
    file: the workers, forked later, inherit the wrapper)."""
    import os

    original = getattr(module, name)

    def logged(*args, **kwargs):
        with open(log, "a") as handle:
            handle.write(f"{os.getpid()} {describe(*args)}\n")
        return original(*args, **kwargs)

    monkeypatch.setattr(module, name, logged)


def _lines(log):
    text = log.read_text() if log.exists() else ""
    return [tuple(line.split(" ", 1)) for line in text.splitlines()]


class _HoldRun:
    """Observer after the figure jobs: once ``frames`` frames are written, it holds the run
    (up to a minute) until ``ready(log lines)``; ``held`` tells if it came."""

    def __init__(self, folder, log, frames, ready):
        self.folder, self.log, self.frames, self.ready, self.held = folder, log, frames, ready, None

    def on_step(self, model, record):
        import time

        pvd = self.folder / "fields.pvd"
        if self.held is not None or not pvd.is_file() or len(read_pvd(pvd)) < self.frames:
            return
        deadline = time.monotonic() + 60.0
        while not self.ready(_lines(self.log)) and time.monotonic() < deadline:
            time.sleep(0.02)
        self.held = self.ready(_lines(self.log))

    def on_finish(self, status, error):
        pass


class _AwaitSnapshots:
    """Observer after the figure jobs: once the snapshots are submitted, it holds the run
    until they are drawn. The animation's worker is busy until the run ends, so the other
    worker must draw them (without this, a loaded machine could leave them queued until the
    animation's worker is free again, which draws them on a figure of its own)."""

    def __init__(self, jobs):
        self.jobs, self.drawn = jobs, False

    def on_step(self, model, record):
        snapshots = self.jobs._requested.get("snapshots")
        if snapshots is not None and not self.drawn:
            snapshots.result(timeout=60.0)
            self.drawn = True

    def on_finish(self, status, error):
        pass


def _animation_pid(lines):
    """The worker that made the animation's figure."""
    return next((pid for pid, what in lines if what == f"build {ANIMATION_SHAPE}"), None)


def test_animation_reads_the_frames_during_the_run_and_others_use_prepared_figures(
        tmp_path, monkeypatch):
    """Beside a run, the animation's worker reads each frame as it is written, never twice,
    and its GIF is the one ``animate`` draws afterwards; the other worker makes the
    snapshots' figure ahead and draws them on it. (The run is held at its third frame until
    the animation's worker has read the second and the other one has made its figure, and
    again once the snapshots are submitted, until they are drawn.)"""
    from ntncontact import plotting

    log = tmp_path / "calls.log"
    _log_calls(monkeypatch, plotting, "read_vtu", log, lambda path, **_: f"read {path.name}")
    _log_calls(monkeypatch, plotting, "_build_figure", log, lambda *shape: f"build {shape}")
    monkeypatch.setattr(figure_jobs, "FIGURE_MAKERS", ())
    monkeypatch.setattr(figure_jobs, "check_made", lambda made, directory: made)
    model = model_from_example("rod_impact.toml", ["analysis.t_end=0.5"])
    out = tmp_path / "r"
    panels = f"build {panels_shape(1)}"

    def ready(lines):
        gif = _animation_pid(lines)
        return (gif, "read fields_00001.vtu") in lines and \
            any(pid != gif and what == panels for pid, what in lines)

    hold = _HoldRun(out, log, 3, ready)
    with figure_jobs.FigureJobs(out, gif=True, times=[0.2]) as jobs:
        snapshots = _AwaitSnapshots(jobs)
        Simulation(model, [ResultWriter(out, model), jobs.start(beside_a_run=True), hold,
                           snapshots]).run()
        assert jobs.paths() == [out / "animation.gif", out / "snapshots.png"]
    assert hold.held and snapshots.drawn
    lines = _lines(log)
    gif = _animation_pid(lines)
    builds = [line for line in lines if line[1].startswith("build")]
    assert builds.count((gif, f"build {ANIMATION_SHAPE}")) == 1  # made ahead, then used
    assert len([line for line in builds if line[1] == panels]) == 1  # the same
    reads = [what for pid, what in lines if pid == gif and what.startswith("read")]
    assert len(reads) == len(set(reads)) == len(read_pvd(out / "fields.pvd"))
    again = animate(out, tmp_path / "again.gif")
    assert again.read_bytes() == (out / "animation.gif").read_bytes()


def test_closing_before_the_run_ends_stops_the_waiting_animation(tmp_path, monkeypatch):
    """An interrupted run (no on_finish): the animation's worker, waiting for the run, gives
    up, and closing returns."""
    import threading
    import time

    from ntncontact import plotting

    log = tmp_path / "calls.log"
    _log_calls(monkeypatch, plotting, "_build_figure", log, lambda *shape: f"build {shape}")
    jobs = figure_jobs.FigureJobs(tmp_path, gif=True).start(beside_a_run=True)
    deadline = time.monotonic() + 60.0
    while _animation_pid(_lines(log)) is None and time.monotonic() < deadline:
        time.sleep(0.02)  # until the animation is running, in its loop
    closing = threading.Thread(target=jobs.close)
    closing.start()
    closing.join(60.0)
    assert not closing.is_alive()
    assert jobs._requested["animation"].result() is None
    assert not (tmp_path / "animation.gif").exists()
