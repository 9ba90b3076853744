"""``analysis.contact_output``: contact.csv keeps every step's pairs ("steps", the default),
only the steps of the field frames ("frames") or none ("none"), so that a long run's file can
be thinned (tester T: ~168 bytes a pair a step, 3.4 GB for 2,000 pairs over 10^4 steps). The
summary's contact figures are taken from every step's pairs whichever is chosen."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from helpers import EXAMPLES

import ntncontact as ntc
from ntncontact.cli import main
from ntncontact.io.checkpoint import checkpoint_files, read_checkpoint
from ntncontact.io.scenario import ScenarioError, load_config
from ntncontact.io.vtk import read_pvd
from ntncontact.io.writers import read_csv_table

ROD = EXAMPLES / "rod_impact.toml"  # dt 0.05, contact from step 2 (t = 0.05..0.1) to t = 2
#: 12 steps, frames every 4 steps: contact starts at step 2, between frames
SHORT = {"analysis.t_end": 0.6, "analysis.output_interval": 0.2}


def run_rod(out: Path | None, contact_output: str | None, restart: bool = False,
            **extra: object) -> ntc.Results:
    """The short rod impact into ``out``; ``extra``: more overrides."""
    overrides = dict(SHORT, **extra)
    if contact_output is not None:
        overrides["analysis.contact_output"] = contact_output
    return ntc.run(ntc.load_scenario(ROD, overrides), out, restart=restart)


def frame_steps(out: Path) -> list[int]:
    return [int(path.stem.rsplit("_", 1)[1]) for _, path in read_pvd(out / "fields.pvd")]


def summary(out: Path) -> dict:
    """summary.json without what differs between runs of other overrides (and wall times)."""
    data = json.loads((out / "summary.json").read_text())
    for key in ("wall_time_s", "cpu_time_s", "scenario_hash", "overrides"):
        data.pop(key, None)
    return data


def rows_at(table: dict, steps: list[int]) -> dict:
    keep = np.isin(table["step"], steps)
    return {name: values[keep] for name, values in table.items()}


def assert_same_rows(a: dict, b: dict) -> None:
    assert list(a) == list(b)
    for name in a:
        assert np.array_equal(a[name], b[name]), name


def test_the_key_defaults_to_every_step_and_refuses_other_values(tmp_path):
    assert load_config(ROD).analysis.contact_output == "steps"
    frames = load_config(ROD, ['analysis.contact_output="frames"'])
    assert frames.analysis.contact_output == "frames"
    with pytest.raises(ScenarioError) as info:
        load_config(ROD, ['analysis.contact_output="sometimes"'])
    message = str(info.value)
    assert "analysis.contact_output" in message and str(ROD) in message
    assert "\n" not in message


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    """The short rod impact with each value (and the default), in folders."""
    base = tmp_path_factory.mktemp("contact_output")
    done = {}
    for value in (None, "steps", "frames", "none"):
        out = base / str(value)
        run_rod(out, value)
        done[value] = out
    return done


def test_frames_keeps_the_rows_of_the_frames_steps_only(runs):
    every = read_csv_table(runs["steps"] / "contact.csv")
    framed = read_csv_table(runs["frames"] / "contact.csv")
    frames = frame_steps(runs["frames"])
    assert frames == [0, 4, 8, 12]
    # contact from step 2: steps 2-12 have rows, 4, 8 and 12 of them are framed
    assert sorted(set(every["step"].tolist())) == list(range(2, 13))
    assert sorted(set(framed["step"].tolist())) == [4, 8, 12]
    assert_same_rows(framed, rows_at(every, frames))


def test_none_writes_the_header_only(runs):
    none = read_csv_table(runs["none"] / "contact.csv")
    every = read_csv_table(runs["steps"] / "contact.csv")
    assert list(none) == list(every)
    assert all(len(values) == 0 for values in none.values())


def test_the_default_is_every_step_byte_for_byte(runs):
    for name in ("contact.csv", "history.csv"):
        assert (runs[None] / name).read_bytes() == (runs["steps"] / name).read_bytes(), name


def test_the_summary_and_history_are_those_of_every_step(runs):
    """The contact summary comes from every step's pairs: contact starts at t = 0.05 (step
    2's start), which the framed rows (steps 4, 8, 12) alone would put at 0.15."""
    reference = summary(runs["steps"])
    assert reference["contact_start_time"] == pytest.approx(0.05)
    for value in ("frames", "none"):
        assert summary(runs[value]) == reference, value
        assert (runs[value] / "history.csv").read_bytes() == \
            (runs["steps"] / "history.csv").read_bytes(), value


def test_a_restart_keeps_the_frames_rows(tmp_path, runs):
    """Restarted from a checkpoint between frames, the run writes the uninterrupted run's
    contact.csv: the frame schedule (the checkpoint's output cursor) picks the same steps."""
    out = tmp_path / "cut"
    run_rod(out, "frames", **{"analysis.checkpoint_interval": 0.15})
    checkpoints = checkpoint_files(out)
    checkpoints[0].unlink()  # as if killed between the last two checkpoints
    resumed_from = read_checkpoint(checkpoint_files(out)[0])[0]["step"]
    assert resumed_from not in frame_steps(runs["frames"])
    run_rod(out, "frames", restart=True, **{"analysis.checkpoint_interval": 0.15})
    assert (out / "contact.csv").read_bytes() == \
        (runs["frames"] / "contact.csv").read_bytes()
    assert frame_steps(out) == frame_steps(runs["frames"])


def fail_from_the_seventh_step(monkeypatch) -> None:
    from ntncontact.engine.simulation import Simulation

    advance = Simulation.advance
    calls = []

    def failing(self, *args, **kwargs):
        calls.append(1)
        if len(calls) >= 7:
            raise RuntimeError("no convergence (a stand-in)")
        return advance(self, *args, **kwargs)

    monkeypatch.setattr(Simulation, "advance", failing)


def test_a_failed_runs_last_frame_adds_no_rows_and_a_restart_drops_it(tmp_path, capsys,
                                                                       monkeypatch, runs):
    """A run that stops between frames writes a frame of its last completed step (6), off
    the output schedule: it adds no contact.csv rows under "frames", and a restart from that
    step's checkpoint drops it, so the restarted run's files are the uninterrupted run's (a
    tester's restart kept the extra step's rows and its VTU file)."""
    out = tmp_path / "rod"
    every_step = {**SHORT, "analysis.contact_output": '"frames"',
                  "analysis.checkpoint_interval": 0.05}
    sets = [item for key, value in every_step.items() for item in ("--set", f"{key}={value}")]
    with monkeypatch.context() as patch:
        fail_from_the_seventh_step(patch)
        assert main(["run", str(ROD), "--out", str(out), "--quiet", *sets]) == 1
    data = json.loads((out / "summary.json").read_text())
    assert data["status"] == "failed" and data["steps"] == 6
    assert frame_steps(out) == [0, 4, 6]
    assert sorted(set(read_csv_table(out / "contact.csv")["step"].tolist())) == [4]
    assert main(["run", str(ROD), "--out", str(out), "--quiet", "--restart", *sets]) == 0
    assert (out / "contact.csv").read_bytes() == (runs["frames"] / "contact.csv").read_bytes()
    assert frame_steps(out) == frame_steps(runs["frames"])
    frames = sorted(path.name for path in (out / "fields").glob("*.vtu"))
    assert frames == sorted(path.name for path in (runs["frames"] / "fields").glob("*.vtu"))


def test_a_run_kept_in_memory_keeps_the_same_rows(runs):
    """``ntncontact.run(out=None)`` thins its contact table as the folder's contact.csv."""
    kept = run_rod(None, "frames")
    assert sorted(set(kept.contact["step"].tolist())) == [4, 8, 12]
    assert len(run_rod(None, "none").contact) == 0
    assert kept.summary["contact_start_time"] == pytest.approx(0.05)
