"""A run folder is safe: old results, concurrent runs, planted symlinks, and every way a run can
end (SIGINT, SIGTERM, SIGKILL, at start-up and mid-run) leave a status that tells the truth.

The signal tests start a real ``ntncontact run`` in a child process and send real signals."""

from __future__ import annotations

import json
import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest
from helpers import EXAMPLES, history_steps, wait_until

from ntncontact.cli import main
from ntncontact.io.run_folder import (
    LOCK_FILE,
    RunFolderError,
    RunLock,
    read_lock,
    replace_atomically,
    run_status,
)
from ntncontact.io.vtk import VtuSeriesWriter, read_pvd, read_vtu
from ntncontact.io.writers import HistoryWriter, SummaryWriter, read_csv_table

SPIN = EXAMPLES / "spinning_block.toml"
SHORT = ["--set", "analysis.t_end=0.1"]  # 5 steps, 2 frames
LONG = ["--set", "analysis.t_end=400.0"]  # 20,000 steps: always stopped by the test
TIMEOUT = 180.0  # generous: the machine is shared, and the child loads the compiled kernels


def run_spin(out: Path, *extra: str) -> int:
    return main(["run", str(SPIN), "--out", str(out), "--quiet", *SHORT, *extra])


def summary(out: Path) -> dict:
    return json.loads((out / "summary.json").read_text())


# ------------------------------------------------------------------------------------------------
# Old results and --overwrite
# ------------------------------------------------------------------------------------------------
def test_a_folder_with_results_is_refused_unless_overwrite(tmp_path, capsys):
    out = tmp_path / "spin"
    assert run_spin(out) == 0
    before = (out / "history.csv").read_text()
    capsys.readouterr()
    assert run_spin(out, "--set", "analysis.dt=0.01") == 1
    err = capsys.readouterr().err
    assert str(out) in err and "--overwrite" in err and "history.csv" in err
    assert "Traceback" not in err
    assert (out / "history.csv").read_text() == before  # nothing touched
    assert summary(out)["status"] == "completed" and not (out / LOCK_FILE).exists()
    assert run_spin(out, "--set", "analysis.dt=0.01", "--overwrite") == 0
    assert len(read_csv_table(out / "history.csv")["step"]) == 11  # the new run's, alone


def test_overwrite_removes_only_what_a_run_writes(tmp_path):
    out = tmp_path / "spin"
    assert main(["run", str(SPIN), "--out", str(out), "--quiet",
                 "--set", "analysis.t_end=0.4"]) == 0
    assert len(read_pvd(out / "fields.pvd")) == 5
    (out / "comparison.csv").write_text("old\n")
    (out / "energies.png").write_bytes(b"old figure")
    (out / "animation.gif").write_bytes(b"old animation")
    (out / ".history.csv.k2j3.tmp").write_text("left by a killed run")
    (out / "notes.txt").write_text("the user's own")
    (out / "fields" / "mine.txt").write_text("the user's own, among the frames")
    (out / "scenario.toml").write_text("kept")
    assert run_spin(out, "--overwrite") == 0
    assert sorted(p.name for p in out.iterdir()) == [
        "contact.csv", "fields", "fields.pvd", "history.csv", "notes.txt", "scenario.toml",
        "summary.json"]
    frames = sorted(p.name for p in (out / "fields").iterdir())
    assert frames == ["fields_00000.vtu", "fields_00005.vtu", "mine.txt"]
    assert [path.name for _, path in read_pvd(out / "fields.pvd")] == frames[:2]
    assert (out / "notes.txt").read_text() == "the user's own"


def test_the_status_command_reports_a_finished_run(tmp_path, capsys):
    out = tmp_path / "spin"
    assert main(["status", str(out)]) == 1
    assert "spin does not exist" in capsys.readouterr().err  # not yet run: no folder
    assert run_spin(out) == 0
    capsys.readouterr()
    assert main(["status", str(out)]) == 0
    lines = dict(line.split(":", 1) for line in capsys.readouterr().out.splitlines())
    assert lines["status"].strip() == "completed"
    assert int(lines["step"]) == 5 and float(lines["time"]) == pytest.approx(0.1, abs=1e-12)
    from ntncontact.cli import _short

    assert _short(13 * 0.004) == "0.052" and _short(None) == "None"  # a tester's disk drop
    assert 13 * 0.004 != 0.052  # printed as 0.052000000000000005 before


# ------------------------------------------------------------------------------------------------
# Symbolic links planted in the folder
# ------------------------------------------------------------------------------------------------
def test_a_planted_symlink_is_never_written_through(tmp_path, capsys):
    """`history.csv -> elsewhere` used to overwrite elsewhere. Now the run is refused (the
    name is taken); with --overwrite the link itself is replaced and its target untouched."""
    out, elsewhere, folder = tmp_path / "spin", tmp_path / "precious.txt", tmp_path / "precious"
    out.mkdir()
    folder.mkdir()
    elsewhere.write_text("do not touch")
    (out / "history.csv").symlink_to(elsewhere)
    (out / "summary.json").symlink_to(elsewhere)
    (out / "fields").symlink_to(folder, target_is_directory=True)
    assert run_spin(out) == 1
    assert str(out) in capsys.readouterr().err
    assert run_spin(out, "--overwrite") == 0
    assert elsewhere.read_text() == "do not touch" and not list(folder.iterdir())
    for name in ("history.csv", "summary.json", "fields"):
        assert not (out / name).is_symlink()
    assert summary(out)["status"] == "completed" and len(read_pvd(out / "fields.pvd")) == 2


def test_writers_refuse_or_replace_a_symlink_planted_after_the_check(tmp_path):
    """A link that appears between the folder check and the file's creation: the CSV writers
    refuse it (O_EXCL | O_NOFOLLOW), atomic rewrites replace it, the frames' folder refuses
    it; the target is never written."""
    target = tmp_path / "target.txt"
    target.write_text("do not touch")
    out = tmp_path / "out"
    out.mkdir()
    (out / "history.csv").symlink_to(target)
    with pytest.raises(RunFolderError, match="history.csv"):
        HistoryWriter(out)
    (out / "summary.json").symlink_to(target)
    SummaryWriter(out, scenario="x")
    assert json.loads((out / "summary.json").read_text())["scenario"] == "x"
    assert not (out / "summary.json").is_symlink()
    (out / "fields.pvd").symlink_to(target)
    replace_atomically(out / "fields.pvd", lambda tmp: tmp.write_text("new"))
    assert (out / "fields.pvd").read_text() == "new" and not (out / "fields.pvd").is_symlink()
    (out / "frames").symlink_to(tmp_path, target_is_directory=True)
    with pytest.raises(RunFolderError, match="symbolic link"):
        VtuSeriesWriter(out, name="frames")
    assert target.read_text() == "do not touch"
    (out / LOCK_FILE).symlink_to(target)
    with pytest.raises(RunFolderError, match="symbolic link"):
        RunLock.acquire(out)
    assert target.read_text() == "do not touch"


# ------------------------------------------------------------------------------------------------
# One run at a time
# ------------------------------------------------------------------------------------------------
def test_a_held_lock_refuses_a_second_run_and_names_the_first(tmp_path, capsys):
    out = tmp_path / "spin"
    out.mkdir()
    lock = RunLock.acquire(out)
    assert read_lock(out) == read_lock(out) | {"pid": os.getpid(),
                                                 "host": socket.gethostname()}
    assert run_spin(out, "--overwrite") == 1
    err = capsys.readouterr().err
    assert f"PID {os.getpid()}" in err and "in use" in err and str(out) in err
    assert not (out / "summary.json").exists()
    lock.release()
    assert not (out / LOCK_FILE).exists()
    assert run_spin(out) == 0 and not (out / LOCK_FILE).exists()


def start_run(out: Path, scenario: Path = SPIN, *extra: str) -> subprocess.Popen:
    """``ntncontact run`` in a child process, with this test's environment (kernel cache)."""
    command = [sys.executable, "-m", "ntncontact.cli", "run", str(scenario), "--out", str(out),
               "--quiet", *extra]
    return subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


def finish(child: subprocess.Popen) -> tuple[int, str]:
    _, err = child.communicate(timeout=TIMEOUT)
    return child.returncode, err


def assert_stopped_cleanly(out: Path, rc: int, err: str, code: int, name: str) -> dict:
    """The run ended through its own exit: the code of the signal, status interrupted naming
    it, summary and history agreeing, the folder released, every file listed readable."""
    assert rc == code, err
    assert "Traceback" not in err and "SystemError" not in err, err
    data = summary(out)
    assert data["status"] == "interrupted" and name in data["error"], data
    steps = history_steps(out)
    assert data["steps"] == (steps[-1] if steps else 0)
    assert steps == list(range(len(steps)))  # whole rows, in order, none spliced
    assert not (out / LOCK_FILE).exists()
    assert not list(out.rglob("*.tmp"))
    for _, path in read_pvd(out / "fields.pvd") if (out / "fields.pvd").exists() else []:
        read_vtu(path)
    return data


@pytest.mark.parametrize(("signum", "code"), [(signal.SIGINT, 130), (signal.SIGTERM, 143)])
def test_a_signal_mid_run_ends_it_as_interrupted_with_files_closed(tmp_path, signum, code):
    out = tmp_path / "spin"
    child = start_run(out, SPIN, *LONG)
    wait_until(lambda: len(history_steps(out)) > 30, child, "30 steps", TIMEOUT)
    child.send_signal(signum)
    rc, err = finish(child)
    data = assert_stopped_cleanly(out, rc, err, code, signal.Signals(signum).name)
    assert data["steps"] >= 30 and data["time"] == pytest.approx(0.02 * data["steps"])


def test_a_sigint_during_start_up_leaves_status_interrupted(tmp_path):
    """SIGINT after summary.json exists, before the first step: the child is paused as soon
    as summary.json appears, so that the signal is sure to land before any step."""
    for attempt in range(3):
        out = tmp_path / f"spin{attempt}"
        child = start_run(out, SPIN, *LONG)
        wait_until((out / "summary.json").exists, child, "summary.json", TIMEOUT)
        child.send_signal(signal.SIGSTOP)
        before_first_step = history_steps(out) in ([], [0])
        child.send_signal(signal.SIGINT)
        child.send_signal(signal.SIGCONT)
        rc, err = finish(child)
        if before_first_step:
            break
    else:
        pytest.fail("could not catch the run before its first step in three tries")
    data = assert_stopped_cleanly(out, rc, err, 130, "SIGINT")
    assert data["steps"] == 0


def test_two_runs_into_one_folder_cannot_happen(tmp_path, capsys):
    out = tmp_path / "spin"
    first = start_run(out, SPIN, *LONG)
    wait_until(lambda: len(history_steps(out)) > 5, first, "5 steps", TIMEOUT)
    assert run_spin(out, "--overwrite") == 1
    err = capsys.readouterr().err
    assert f"PID {first.pid}" in err and str(out) in err
    first.send_signal(signal.SIGTERM)
    rc, err = finish(first)
    assert_stopped_cleanly(out, rc, err, 143, "SIGTERM")  # its rows were never mixed


def test_after_sigkill_the_run_reads_as_stale_and_the_summary_lags_one_step_at_most(tmp_path,
                                                                                   capsys):
    out = tmp_path / "spin"
    child = start_run(out, SPIN, *LONG)
    wait_until(lambda: len(history_steps(out)) > 40, child, "40 steps", TIMEOUT)
    assert run_status(out).state == "running"
    child.send_signal(signal.SIGKILL)
    child.communicate(timeout=TIMEOUT)
    data, steps = summary(out), history_steps(out)
    assert data["status"] == "running"  # the run could not say anything more...
    assert 0 <= steps[-1] - data["steps"] <= 1  # ...but had said everything up to a step
    assert read_lock(out)["pid"] == child.pid  # ...and its lock names a PID that is gone
    capsys.readouterr()
    assert main(["status", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "status: stale" in printed and f"{child.pid} (gone)" in printed
    assert run_spin(out, "--overwrite") == 0  # a killed run does not block the folder
    assert summary(out)["status"] == "completed" and not (out / LOCK_FILE).exists()


@pytest.mark.slow
@pytest.mark.parametrize("delay", [0.2, 0.8])
def test_signals_landing_in_compiled_kernels_give_interrupted(tmp_path, delay):
    """The ring impact spends most of its steps in compiled contact, element and ALE kernels.
    A SIGINT there used to leak a SystemError from the kernel's dispatcher (1 in 36); the
    handler now only records it. Then a second SIGINT at once, which stops the run where it
    is: still interrupted, with no traceback."""
    out = tmp_path / "ring"
    child = start_run(out, EXAMPLES / "ring_impact.toml")
    wait_until(lambda: len(history_steps(out)) > 1, child, "the first step", TIMEOUT)
    time.sleep(delay)
    child.send_signal(signal.SIGINT)
    rc, err = finish(child)
    assert_stopped_cleanly(out, rc, err, 130, "SIGINT")
    again = tmp_path / "again"
    child = start_run(again, EXAMPLES / "ring_impact.toml")
    wait_until(lambda: len(history_steps(again)) > 1, child, "the first step", TIMEOUT)
    time.sleep(delay)
    child.send_signal(signal.SIGINT)
    child.send_signal(signal.SIGINT)
    rc, err = finish(child)
    assert rc == 130 and "Traceback" not in err, err
    assert summary(again)["status"] == "interrupted" and not (again / LOCK_FILE).exists()


def test_a_signal_while_the_figures_are_drawn_stops_them_at_once(tmp_path):
    """The run is complete when its figures are drawn: a SIGINT then stops the drawing at once
    (it used to say "stopping after this step" and go on drawing until a second signal), the
    exit code is the signal's, the status stays "completed", and stderr says what is missing."""
    out = tmp_path / "spin"
    command = [sys.executable, "-m", "ntncontact.cli", "run", str(SPIN), "--out", str(out),
               "--quiet", "--set", "analysis.t_end=2.0", "--gif"]  # 100 frames to draw
    child = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                             env=os.environ | {"PYTHONUNBUFFERED": "1"})
    line = child.stdout.readline()
    while line and not line.startswith("results written to"):
        line = child.stdout.readline()
    assert line, "the run did not complete"
    started = time.monotonic()
    child.send_signal(signal.SIGINT)
    rc, err = finish(child)
    assert time.monotonic() - started < 30.0  # not after the whole animation
    assert rc == 130, err
    assert "Traceback" not in err
    assert "after the run had completed" in err and "stopping after this step" not in err
    assert summary(out)["status"] == "completed"
    assert not (out / "animation.gif").exists()
    assert not (out / LOCK_FILE).exists()


@pytest.mark.parametrize("limit, failing", [(40_000, "contact.csv"), (30_000, "fields_0")])
def test_a_file_that_cannot_grow_fails_the_run_with_whole_rows_and_names_the_file(
        tmp_path, limit, failing):
    """A file-size limit (as a full disk) stops the run: a tester's contact.csv ended inside a
    number, which pandas read as that row's value, the summary stayed "running" (status
    "stale") when no new file could be made, and the error named no file. Now the rows stay
    whole, the summary says failed, and the error names what could not be written."""
    import resource

    def limited() -> None:
        resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit))

    out = tmp_path / "ring"
    interval = "10.0" if failing == "contact.csv" else "0.025"  # frames or contact rows first
    done = subprocess.run([sys.executable, "-m", "ntncontact.cli", "run",
                           str(EXAMPLES / "ring_impact.toml"), "--out", str(out), "--quiet",
                           "--set", f"analysis.output_interval={interval}"],
                          preexec_fn=limited, capture_output=True, text=True, timeout=300)
    assert done.returncode == 1 and "Traceback" not in done.stderr
    assert "File too large" in done.stderr and failing in done.stderr
    summary = json.loads((out / "summary.json").read_text())
    assert summary["status"] == "failed" and failing in summary["error"]
    for name in ("history.csv", "contact.csv"):
        text = (out / name).read_text()
        assert text.endswith("\n")
        widths = {line.count(",") for line in text.splitlines()}
        assert len(widths) == 1, (name, widths)  # every row whole
    if failing == "contact.csv":  # its rows up to the last whole step
        contact = read_csv_table(out / "contact.csv")
        assert contact["step"].size > 0 and contact["step"].max() <= summary["steps"] + 1


def test_an_xdmf_series_that_would_not_fit_stops_the_run_before_hdf5_fails(tmp_path):
    """HDF5 does not recover from a write that fails: a tester's full disk crashed an XDMF run
    with a segmentation fault, 42 tracebacks on stderr and the index at the first frame. The
    writer now refuses a frame without room for it (a file-size limit here, the same check as
    the disk's free space), and the frames before it stay readable."""
    import resource

    import ntncontact as ntc

    def limited() -> None:
        resource.setrlimit(resource.RLIMIT_FSIZE, (600_000, 600_000))

    out = tmp_path / "ring"
    done = subprocess.run([sys.executable, "-m", "ntncontact.cli", "run",
                           str(EXAMPLES / "ring_impact.toml"), "--out", str(out), "--quiet",
                           "--set", 'analysis.field_format="xdmf"'],
                          preexec_fn=limited, capture_output=True, text=True, timeout=300)
    assert done.returncode == 1, done.stderr
    assert "no room for the next XDMF frame" in done.stderr and "fields.h5" in done.stderr
    assert "Traceback" not in done.stderr
    results = ntc.read_results(out)
    assert results.summary["status"] == "failed" and len(results.times) >= 1
    assert results.fields(results.times[-1]).points.shape[0] > 0


def test_a_second_signal_while_the_last_files_are_written_waits_for_them(tmp_path, monkeypatch):
    """A tester's double Ctrl-C left summary.json "running" (status stale) 1 time in 8: the
    second signal's KeyboardInterrupt cut the final summary's write, which the signal mask
    did not hold off when another thread (the VTU writer's) took the signal. The command's
    handler now lets the last files be written; the run ends right after them."""
    from ntncontact.cli import StopOnSignal
    from ntncontact.io.writers import ResultsDirectory, SummaryWriter

    stop = StopOnSignal()
    stop.signum = signal.SIGINT  # the first Ctrl-C asked the run to stop
    finish = SummaryWriter.finish

    def second_signal_lands(self, *args, **kwargs):
        stop._handle(signal.SIGINT, None)
        return finish(self, *args, **kwargs)

    monkeypatch.setattr(SummaryWriter, "finish", second_signal_lands)
    out = tmp_path / "out"
    ResultsDirectory(out).close("interrupted", stop.reason())
    assert summary(out)["status"] == "interrupted" and not (out / LOCK_FILE).exists()
    with pytest.raises(KeyboardInterrupt):  # at any other time it stops at once
        stop._handle(signal.SIGINT, None)


def test_a_signal_before_the_run_began_says_nothing_was_written(tmp_path, capsys,
                                                               monkeypatch):
    """A tester's Ctrl-C a second into `ntncontact run` was told "files written so far are
    valid" where no folder had been made."""
    from ntncontact import cli

    def stopped_while_starting(args, stop):
        stop.signum = signal.SIGINT
        raise KeyboardInterrupt

    monkeypatch.setattr(cli, "_run_until_stopped", stopped_while_starting)
    out = tmp_path / "never"
    assert main(["run", str(SPIN), "--out", str(out), "--quiet"]) == 130
    assert "interrupted by SIGINT before the run began: nothing was written" in \
        capsys.readouterr().err
    assert not out.exists()


def test_a_sigint_during_the_build_over_an_old_run_says_one_true_line(tmp_path, capsys,
                                                                      monkeypatch):
    """A tester's Ctrl-C a second into `ntncontact run --overwrite` over a folder holding an
    earlier completed run printed "stopping after this step" (no step existed) and then "files
    written so far are valid", and status said "completed": the old run, untouched."""
    from ntncontact.io import run_setup

    out = tmp_path / "spin"
    assert run_spin(out, "--set", "analysis.t_end=0.1") == 0
    before = (out / "summary.json").read_bytes()
    capsys.readouterr()
    build = run_setup.build_model

    def signalled(*args, **kwargs):
        os.kill(os.getpid(), signal.SIGINT)  # lands in the command's handler, mid-build
        return build(*args, **kwargs)

    monkeypatch.setattr(run_setup, "build_model", signalled)
    assert main(["run", str(SPIN), "--out", str(out), "--quiet", "--overwrite"]) == 130
    err = capsys.readouterr().err
    assert err == "interrupted by SIGINT before the run began: nothing was written\n"
    assert (out / "summary.json").read_bytes() == before


def test_a_bug_ends_in_one_line_with_its_traceback_in_a_file(tmp_path, capsys, monkeypatch):
    """An exception the command does not expect (here an AttributeError from a step, as a
    session's own slip produced) printed a traceback; now one line names it and the file that
    keeps the traceback, and the run's folder says "failed" with its rows readable."""
    from ntncontact.engine.simulation import Simulation

    advance = Simulation.advance
    calls = []

    def failing(self, *args, **kwargs):
        calls.append(1)
        if len(calls) > 3:
            raise AttributeError("'NoneType' object has no attribute 't_N'")
        return advance(self, *args, **kwargs)

    monkeypatch.setattr(Simulation, "advance", failing)
    out = tmp_path / "spin"
    assert main(["run", str(SPIN), "--out", str(out), "--quiet"]) == 1
    err = capsys.readouterr().err
    assert "Traceback" not in err and err.count("\n") == 1, err
    assert err.startswith("internal error: AttributeError: 'NoneType' object has no attribute")
    saved = Path(err.split("its traceback is in ")[1].split(":")[0])
    assert "Traceback" in saved.read_text() and "failing" in saved.read_text()
    saved.unlink()
    data = summary(out)
    assert data["status"] == "failed" and "no attribute 't_N'" in data["error"]
    assert history_steps(out) == list(range(data["steps"] + 1))
