"""Figures written after a run (``ntncontact run --plot``) and by ``ntncontact plot``."""

import json

from helpers import EXAMPLES

from ntncontact.cli import main

TIMES = ["0.1", "0.3"]


def _figures(folder):
    return {p.name for p in folder.glob("*.png")} | {p.name for p in folder.glob("*.gif")}


def test_run_with_plot_writes_the_figures_of_plot(tmp_path, capsys):
    live, after = tmp_path / "live", tmp_path / "after"
    args = [str(EXAMPLES / "rod_impact.toml"), "--quiet", "--set", "analysis.t_end=0.5"]
    assert main(["run", *args, "--out", str(live), "--gif", "--times", *TIMES]) == 0
    printed = capsys.readouterr().out
    assert main(["run", *args, "--out", str(after)]) == 0
    assert main(["plot", str(after), "--gif", "--times", *TIMES]) == 0
    names = _figures(live)
    assert names == _figures(after)
    assert {"snapshots.png", "animation.gif", "energies.png", "pair_history.png"} <= names
    assert "deformed_von_mises.png" not in names  # the snapshots at the times take its place
    assert all(str(live / name) in printed for name in names)
    assert main(["plot", str(after)]) == 0  # no times: six evenly spaced meshes
    assert (after / "deformed_von_mises.png").is_file()


def test_failed_run_with_plot_draws_nothing_and_keeps_the_folder(tmp_path, capsys):
    out = tmp_path / "o"
    # free flight converges in one Newton iteration (a rigid motion); the impact at t = 0.07 does
    # not, and no halving is allowed: the run fails after 14 steps
    code = main(["run", str(EXAMPLES / "ring_impact.toml"), "--out", str(out), "--quiet", "--gif",
                 "--set", "analysis.t_end=0.12", "--set", "analysis.max_cutbacks=0",
                 "--set", "analysis.newton.max_iterations=1"])
    assert code == 1 and "error" in capsys.readouterr().err
    assert json.loads((out / "summary.json").read_text())["status"] == "failed"
    assert not _figures(out)  # nothing drawn
    assert main(["plot", str(out)]) == 0  # but the folder is still plottable
    assert (out / "energies.png").is_file()


def _processes() -> list[tuple[int, int, int]]:
    """(pid, parent pid, session id) of every process (Linux /proc)."""
    from pathlib import Path

    rows = []
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
        except OSError:  # ended meanwhile
            continue
        rows.append((int(stat.parent.name), int(fields[1]), int(fields[3])))
    return rows


def test_a_killed_run_with_plot_leaves_no_process_behind(tmp_path):
    """``run --plot --gif`` starts no other process; SIGKILL mid-run leaves none alive in its
    session, and the caller's pipes reach their end at once (nothing else holds them)."""
    import os
    import signal
    import subprocess
    import sys
    import time
    from pathlib import Path

    import pytest

    from ntncontact.io.vtk import read_pvd

    if not Path("/proc/self/stat").is_file():
        pytest.skip("needs Linux /proc")
    out = tmp_path / "ring"
    run = subprocess.Popen(
        [sys.executable, "-m", "ntncontact.cli", "run", str(EXAMPLES / "ring_impact.toml"),
         "--out", str(out), "--plot", "--gif", "--quiet"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, start_new_session=True)
    deadline = time.monotonic() + 300.0
    while time.monotonic() < deadline and run.poll() is None:
        pvd = out / "fields.pvd"
        if pvd.is_file() and len(read_pvd(pvd)) >= 3:
            break
        time.sleep(0.1)
    assert run.poll() is None, "the run ended before it could be killed"
    assert [pid for pid, parent, _ in _processes() if parent == run.pid] == []
    os.kill(run.pid, signal.SIGKILL)
    run.communicate(timeout=10.0)  # end of output: no process left holding the pipes
    assert run.returncode == -signal.SIGKILL
    assert [pid for pid, _, session in _processes() if session == run.pid] == []


def test_times_outside_the_run_are_refused_in_one_line(tmp_path, capsys):
    """`plot --times 100 -1` names both and draws nothing; `run --times` past t_end is refused
    before the run starts."""
    out = tmp_path / "rods"
    args = [str(EXAMPLES / "rod_impact.toml"), "--quiet", "--set", "analysis.t_end=0.5"]
    assert main(["run", *args, "--out", str(out)]) == 0
    capsys.readouterr()
    assert main(["plot", str(out), "--times", "100", "-1"]) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "Traceback" not in err
    assert "times 100, -1 are outside" in err and "fields.pvd (t = 0 to 0.5)" in err
    assert not _figures(out)
    late = tmp_path / "late"
    assert main(["run", *args, "--out", str(late), "--times", "0.2", "0.7"]) == 1
    err = capsys.readouterr().err
    assert "time 0.7 is outside the run of" in err and "(t = 0 to 0.5)" in err
    assert not late.exists()  # refused before anything ran or was written
