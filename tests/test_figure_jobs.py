"""Figures drawn while a run goes on (``ntncontact run --plot``) and by ``ntncontact plot``."""

import json

from helpers import EXAMPLES, model_from_example

import ntncontact.figure_jobs as figure_jobs
from ntncontact.cli import main
from ntncontact.io.results import ResultWriter
from ntncontact.io.vtk import read_pvd
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
    assert written[-1] >= 0.23 and written[-2] < 0.23  # the first frame after the last time
    assert len(written) < len(final)
    assert jobs.paths() == [out / "snapshots.png"]


def test_failed_run_with_plot_stops_its_workers_and_keeps_the_folder(tmp_path, capsys):
    out = tmp_path / "o"
    code = main(["run", str(EXAMPLES / "rod_impact.toml"), "--out", str(out), "--quiet", "--plot",
                 "--set", "analysis.t_end=0.5", "--set", "analysis.max_cutbacks=0",
                 "--set", "analysis.newton.max_iterations=1"])
    assert code == 1 and "error" in capsys.readouterr().err
    assert json.loads((out / "summary.json").read_text())["status"] == "failed"
    assert not list(out.glob("*.png"))  # nothing drawn for a failed run
    assert main(["plot", str(out)]) == 0  # but the folder is still plottable
    assert (out / "energies.png").is_file()


def _record_warm_up(log):
    import os
    import time

    def warm_up():
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
