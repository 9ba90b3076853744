"""A restart's run identity (``io.checkpoint.run_identity``): the ``--set`` overrides of
different keys may come in any order, while a real change (another value, another scenario
file, an added or removed override, another last value of a key set twice) is still refused."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
from helpers import EXAMPLES

from ntncontact.cli import main
from ntncontact.io.checkpoint import checkpoint_files, read_checkpoint
from ntncontact.io.writers import read_csv_table

SPIN = EXAMPLES / "spinning_block.toml"
T_END, INTERVAL = "analysis.t_end=0.06", "analysis.checkpoint_interval=0.02"


def run_cli(scenario: Path, out: Path, overrides: list[str], *extra: str) -> int:
    sets = [item for o in overrides for item in ("--set", o)]
    return main(["run", str(scenario), "--out", str(out), "--quiet", *sets, *extra])


def history(out: Path) -> dict[str, np.ndarray]:
    return read_csv_table(out / "history.csv")


def assert_same_history(a: dict, b: dict) -> None:
    assert list(a) == list(b)
    for column in a:
        assert np.array_equal(a[column], b[column], equal_nan=True), column


def cut_back(out: Path) -> None:
    """As if the run was killed between its last two checkpoints: the restart has steps to
    compute again."""
    newest = checkpoint_files(out)[0]
    newest.unlink()
    assert checkpoint_files(out), "no older checkpoint left to restart from"


def refused(capsys, scenario: Path, out: Path, overrides: list[str]) -> str:
    """The one-line error of a refused restart."""
    assert run_cli(scenario, out, overrides, "--restart") == 1
    err = capsys.readouterr().err
    assert "belongs to another run" in err and "Traceback" not in err, err
    assert len(err.strip().splitlines()) == 1, err
    return err


def test_a_restart_takes_the_overrides_in_another_order(tmp_path, capsys):
    out = tmp_path / "spin"
    assert run_cli(SPIN, out, [INTERVAL, T_END]) == 0
    full = history(out)
    cut_back(out)
    assert run_cli(SPIN, out, [T_END, INTERVAL], "--restart") == 0, capsys.readouterr().err
    assert_same_history(history(out), full)
    # spaces and the spelling of a value do not matter either (compared as TOML values)
    assert run_cli(SPIN, out, ["analysis.checkpoint_interval = 0.020", T_END], "--restart") == 0


def test_a_restart_with_a_real_change_is_still_refused(tmp_path, capsys):
    out = tmp_path / "spin"
    assert run_cli(SPIN, out, [INTERVAL, T_END]) == 0
    capsys.readouterr()
    assert "other overrides" in refused(capsys, SPIN, out, [INTERVAL, "analysis.t_end=0.08"])
    assert "other overrides" in refused(capsys, SPIN, out, [INTERVAL])  # one removed
    # one added that leaves the validated scenario as it was (the file says "consistent")
    err = refused(capsys, SPIN, out, [T_END, 'analysis.mass="consistent"', INTERVAL])
    assert "other overrides" in err and 'analysis.mass="consistent"' in err
    err = refused(capsys, EXAMPLES / "ring_impact.toml", out, [T_END, INTERVAL])
    assert "another scenario" in err
    # the refusals changed nothing: the run's own restart, in either order, still works
    assert run_cli(SPIN, out, [T_END, INTERVAL], "--restart") == 0


def test_a_key_set_twice_keeps_its_last_value(tmp_path, capsys):
    out = tmp_path / "spin"
    assert run_cli(SPIN, out, ["analysis.t_end=0.04", INTERVAL, T_END]) == 0  # t_end 0.06
    full = history(out)
    assert full["time"][-1] == np.float64(0.06)
    cut_back(out)
    assert run_cli(SPIN, out, [INTERVAL, "analysis.t_end=0.04", T_END], "--restart") == 0
    assert_same_history(history(out), full)
    assert run_cli(SPIN, out, [T_END, INTERVAL], "--restart") == 0  # the same final values
    capsys.readouterr()
    err = refused(capsys, SPIN, out, [T_END, INTERVAL, "analysis.t_end=0.04"])  # last: 0.04
    assert "other overrides" in err and "analysis.t_end=0.04 here" in err


def test_a_checkpoint_of_the_previous_version_still_restarts(tmp_path, capsys):
    """Checkpoints written before held the overrides as given (in order, a key set twice
    twice): they are compared by key too, so the run's own restart goes on, another is
    refused with the usual line."""
    out = tmp_path / "spin"
    given = ["analysis.t_end=0.04", INTERVAL, T_END]
    assert run_cli(SPIN, out, given) == 0
    full = history(out)
    cut_back(out)
    path = checkpoint_files(out)[0]
    header, arrays = read_checkpoint(path)
    header["identity"]["overrides"] = ["analysis.t_end=0.04", "analysis.checkpoint_interval=0.02",
                                       "analysis.t_end=0.06"]  # as the previous version wrote
    with open(path, "wb") as handle:
        np.savez(handle, header=np.array(json.dumps(header)), **arrays)
    assert read_checkpoint(path)[0]["identity"]["overrides"][0] == "analysis.t_end=0.04"
    capsys.readouterr()
    assert "other overrides" in refused(capsys, SPIN, out, [INTERVAL, "analysis.t_end=0.04"])
    assert run_cli(SPIN, out, [INTERVAL, T_END], "--restart") == 0, capsys.readouterr().err
    assert_same_history(history(out), full)
