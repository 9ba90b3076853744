"""A run folder is safe: old results, concurrent runs, planted symlinks."""

from __future__ import annotations

import json
import os
import socket
from pathlib import Path

import pytest
from helpers import EXAMPLES

from ntncontact.cli import main
from ntncontact.io.run_folder import (
    LOCK_FILE,
    RunFolderError,
    RunLock,
    read_lock,
    replace_atomically,
)
from ntncontact.io.vtk import VtuSeriesWriter, read_pvd
from ntncontact.io.writers import HistoryWriter, SummaryWriter, read_csv_table

SPIN = EXAMPLES / "spinning_block.toml"
SHORT = ["--set", "analysis.t_end=0.1"]  # 5 steps, 2 frames


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
