"""Stopping and watching a long run: a signal during the model's build stops at once, the folder
is locked (and reported "starting") from before the build, an interrupted or failed run keeps a
frame of its last completed step, and a batch job's log gets progress lines."""

from __future__ import annotations

import contextlib
import io
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from helpers import EXAMPLES, history_steps, wait_until

from ntncontact import cli
from ntncontact.cli import main
from ntncontact.io import run_setup
from ntncontact.io.run_folder import LOCK_FILE, RunLock, read_lock, run_status
from ntncontact.io.vtk import read_pvd

SPIN = EXAMPLES / "spinning_block.toml"  # dt 0.02
SHORT = ["--set", "analysis.t_end=0.1"]  # 5 steps
SPARSE = ["--set", "analysis.output_interval=100.0"]  # frames at step 0 and the end only
TIMEOUT = 180.0


def summary(out: Path) -> dict:
    return json.loads((out / "summary.json").read_text())


def frame_steps(out: Path) -> list[int]:
    return [int(path.stem.rsplit("_", 1)[1]) for _, path in read_pvd(out / "fields.pvd")]


def test_a_first_signal_during_the_build_stops_it_at_once(tmp_path, capsys, monkeypatch):
    """A tester's first Ctrl-C 8 s into a 31 s build was silent until the build ended. The
    build here takes 20 s after the signal: the run must end well before."""
    build = run_setup.build_model

    def slow_build(*args, **kwargs):
        os.kill(os.getpid(), signal.SIGINT)
        for _ in range(400):  # 20 s, in short sleeps as a build's Python steps
            time.sleep(0.05)
        return build(*args, **kwargs)

    monkeypatch.setattr(run_setup, "build_model", slow_build)
    out = tmp_path / "spin"
    started = time.monotonic()
    assert main(["run", str(SPIN), "--out", str(out), "--quiet"]) == 130
    assert time.monotonic() - started < 5.0
    assert capsys.readouterr().err == \
        "interrupted by SIGINT before the run began: nothing was written\n"
    assert not out.exists()  # made for the lock, removed with it: nothing was written


def test_the_folder_is_locked_and_starting_during_the_build(tmp_path, capsys, monkeypatch):
    """A tester's `status` during a long build said "holds no run" (exit 1), and a second run
    into the folder was not refused then. Here over an earlier run's results (--overwrite):
    `status` must not report the old run either."""
    out = tmp_path / "spin"
    assert main(["run", str(SPIN), "--out", str(out), "--quiet", *SHORT]) == 0
    capsys.readouterr()
    build = run_setup.build_model
    seen = {}

    def checked_build(*args, **kwargs):
        if not seen:
            seen["lock"] = read_lock(out)
            seen["status"] = main(["status", str(out)]), capsys.readouterr()
            seen["second"] = main(["run", str(SPIN), "--out", str(out), "--quiet",
                                   "--overwrite", *SHORT]), capsys.readouterr()
        return build(*args, **kwargs)

    monkeypatch.setattr(run_setup, "build_model", checked_build)
    assert main(["run", str(SPIN), "--out", str(out), "--quiet", "--overwrite", *SHORT]) == 0
    assert seen["lock"]["pid"] == os.getpid() and seen["lock"]["phase"] == "building"
    code, printed = seen["status"]
    assert code == 0 and printed.out.startswith("status: starting (building the model)\n")
    assert f"pid:    {os.getpid()} on" in printed.out
    code, printed = seen["second"]
    assert code == 1 and "in use by another run" in printed.err
    assert f"PID {os.getpid()}" in printed.err
    assert summary(out)["status"] == "completed" and not (out / LOCK_FILE).exists()
    assert "phase" not in json.loads((out / "summary.json").read_text())


def test_a_lock_left_by_a_run_killed_during_its_build_reads_stale(tmp_path, capsys):
    out = tmp_path / "spin"
    out.mkdir()
    gone = subprocess.Popen(["true"])
    gone.wait()
    (out / LOCK_FILE).write_text(json.dumps(
        {"pid": gone.pid, "host": os.uname().nodename, "started": "x", "phase": "building"}))
    assert run_status(out).state == "stale"
    assert main(["status", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "status: stale (killed before its first step)" in printed and "(gone)" in printed
    (out / LOCK_FILE).unlink()
    assert main(["status", str(out)]) == 1  # no lock, no summary: no run
    assert "no summary.json" in capsys.readouterr().err
    # a folder that is not there is named as such (a tester's typo read "holds no run")
    assert main(["status", str(out / "typo")]) == 1
    err = capsys.readouterr().err
    assert "typo does not exist" in err and "holds no run" not in err


def test_the_lock_phase_is_rewritten_whole(tmp_path):
    lock = RunLock.acquire(tmp_path, phase="building")
    assert read_lock(tmp_path)["phase"] == "building"
    lock.set_phase(None)
    assert "phase" not in read_lock(tmp_path) and read_lock(tmp_path)["pid"] == os.getpid()
    lock.release()
    assert not (tmp_path / LOCK_FILE).exists()


def test_an_interrupted_run_writes_a_frame_of_its_last_step(tmp_path):
    """A tester's run interrupted at step 16 (frames every 10 steps) kept step 10's fields
    only. Here frames only at step 0 would be due: the stop must add the last step's."""
    out = tmp_path / "spin"
    command = [sys.executable, "-m", "ntncontact.cli", "run", str(SPIN), "--out", str(out),
               "--quiet", "--set", "analysis.t_end=400.0", *SPARSE]
    child = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    wait_until(lambda: len(history_steps(out)) > 12, child, "12 steps", TIMEOUT)
    child.send_signal(signal.SIGINT)
    _, err = child.communicate(timeout=TIMEOUT)
    assert child.returncode == 130, err
    data = summary(out)
    # step 12 was written (13 rows with step 0's); a signal between two steps stops there
    assert data["status"] == "interrupted" and data["steps"] >= 12
    assert frame_steps(out) == [0, data["steps"]]
    times = [t for t, _ in read_pvd(out / "fields.pvd")]
    assert times[-1] == pytest.approx(data["time"], abs=1e-12)
    assert not (out / LOCK_FILE).exists()


def stop_at_call(monkeypatch, calls: int, action, repeat: bool = False) -> None:
    """``action`` on the ``calls``-th step (Simulation.advance; ``repeat``: and on later
    ones, the step's cut-back halvings among them)."""
    from ntncontact.engine.simulation import Simulation

    advance = Simulation.advance
    count = []

    def counted(self, *args, **kwargs):
        count.append(1)
        if len(count) == calls or (repeat and len(count) > calls):
            action()
        return advance(self, *args, **kwargs)

    monkeypatch.setattr(Simulation, "advance", counted)


def test_a_failed_run_writes_a_frame_of_its_last_completed_step(tmp_path, capsys, monkeypatch):
    def fail():
        raise RuntimeError("no convergence (a stand-in)")

    stop_at_call(monkeypatch, 4, fail, repeat=True)
    out = tmp_path / "spin"
    assert main(["run", str(SPIN), "--out", str(out), "--quiet", *SPARSE]) == 1
    data = summary(out)
    assert data["status"] == "failed" and "stand-in" in data["error"]
    assert frame_steps(out) == [0, data["steps"]] and data["steps"] >= 1


def test_a_second_signal_gives_the_last_frame_up_and_still_closes(tmp_path, capsys,
                                                                  monkeypatch):
    """The last frame must not hold a second Ctrl-C off: it is given up, the files closed."""
    from ntncontact.io.results import ResultWriter

    stop_at_call(monkeypatch, 4, lambda: os.kill(os.getpid(), signal.SIGINT))
    write = ResultWriter._write_fields

    def second_signal_in_the_last_frame(self, model, record, before=None):
        if record.state.step > 0:
            os.kill(os.getpid(), signal.SIGINT)
        return write(self, model, record, before)

    monkeypatch.setattr(ResultWriter, "_write_fields", second_signal_in_the_last_frame)
    out = tmp_path / "spin"
    assert main(["run", str(SPIN), "--out", str(out), "--quiet", *SPARSE]) == 130
    data = summary(out)
    assert data["status"] == "interrupted" and data["steps"] >= 3
    assert frame_steps(out) == [0] and not (out / LOCK_FILE).exists()
    assert "Traceback" not in capsys.readouterr().err


def test_progress_lines_come_every_interval():
    clock = iter([0.0, 10.0, 31.0, 40.0, 62.0, 3700.0])
    steps = iter([3, 7, 9, 12])
    lines = cli.ProgressLines("spin", 0.4, lambda: next(steps), started=-5.0, interval=30.0,
                          clock=lambda: next(clock))
    stream = io.StringIO()
    with contextlib.redirect_stderr(stream):
        for t in (0.1, 0.14, 0.2, 0.3, 0.4):
            lines(t)
    printed = stream.getvalue().splitlines()
    assert printed == ["spin: step 3, t = 0.14 / 0.4 (35 %), elapsed 0:00:36",
                       "spin: step 7, t = 0.3 / 0.4 (75 %), elapsed 0:01:07",
                       "spin: step 9, t = 0.4 / 0.4 (100 %), elapsed 1:01:45"]


def test_a_run_whose_stderr_is_not_a_terminal_prints_progress_lines(tmp_path, capsys,
                                                                    monkeypatch):
    """A tester's batch job (stderr to a file) saw nothing in 60 s: tqdm is off there."""
    monkeypatch.setattr(cli, "PROGRESS_INTERVAL", 0.0, raising=False)  # a line every step
    assert main(["run", str(SPIN), "--out", str(tmp_path / "spin"), *SHORT]) == 0
    lines = [line for line in capsys.readouterr().err.splitlines()
             if line.startswith("spinning_block: step")]
    assert len(lines) == 5 and lines[-1].startswith("spinning_block: step 5, t = 0.1 / 0.1 "
                                                    "(100 %), elapsed 0:00:")
    monkeypatch.setattr(cli, "PROGRESS_INTERVAL", 0.0, raising=False)
    assert main(["run", str(SPIN), "--out", str(tmp_path / "quiet"), "--quiet", *SHORT]) == 0
    assert "step" not in capsys.readouterr().err


def test_an_interrupted_run_prints_the_warnings_of_its_steps(tmp_path, capsys, monkeypatch):
    """A tester's run stopped with Ctrl-C printed none of the warnings its summary called for
    (a failed run printed them). The summary's warnings stand in for a real one here: which
    lines a summary calls for is ``report.run_warnings``' own test."""
    seen = []

    def one_warning(summary, static):
        seen.append(summary["steps"])
        return ["a stand-in warning"]

    monkeypatch.setattr(cli, "result_warnings", one_warning)
    stop_at_call(monkeypatch, 4, lambda: os.kill(os.getpid(), signal.SIGINT))
    out = tmp_path / "spin"
    assert main(["run", str(SPIN), "--out", str(out), "--quiet", *SPARSE]) == 130
    err = capsys.readouterr().err
    assert "warning: a stand-in warning" in err
    assert seen == [summary(out)["steps"]] and seen[0] >= 3
