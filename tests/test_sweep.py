"""Sweeps on Dask: a LocalCluster with 2 workers, a failing case, a rerun that skips."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pandas as pd
import pytest

from ntncontact.io.scenario import ScenarioError
from ntncontact.studies.sweep import case_name, load_sweep, sweep

BLOCK = """
title = "small free block"
[analysis]
kind = "dynamic"
dt = 0.02
t_end = 0.06
max_cutbacks = 0
[[bodies]]
name = "block"
mesh = { type = "rectangle", width = 1.0, height = 0.5, nx = 4, ny = 2 }
material = { model = "neo_hookean", E = 100.0, nu = 0.3, density = 1.0 }
initial = { velocity = [1.0, 0.0], angular_velocity = 2.0 }
"""

SWEEP = """
scenario = "block.toml"
[grid]
"bodies.0.initial.angular_velocity" = [1.0, 3.0]
"analysis.mass" = ["consistent", "lumped"]
[[cases]]
# one Newton iteration cannot converge a Neo-Hookean step, and no cut-back is allowed
"analysis.newton.max_iterations" = 1
[reductions]
final_kinetic = "kinetic_energy:last"
momentum_change = "angular_momentum:max_change"
[[figures]]
x = "bodies.0.initial.angular_velocity"
y = "final_kinetic"
by = "analysis.mass"
"""


@pytest.fixture
def sweep_file(tmp_path: Path) -> Path:
    (tmp_path / "block.toml").write_text(BLOCK)
    path = tmp_path / "sweep.toml"
    path.write_text(SWEEP)
    return path


@pytest.mark.slow
def test_a_sweep_runs_every_case_records_the_failure_and_skips_finished_ones_on_rerun(
        sweep_file, tmp_path):
    out = tmp_path / "out"
    table = sweep(sweep_file, out, workers=2, progress=False)
    assert len(table) == 5
    ok, bad = table.iloc[:4], table.iloc[4]
    assert (ok["status"] == "completed").all() and not ok["skipped"].any()
    assert bad["status"] == "failed" and "converge" in bad["error"].lower()
    # grid order, last key fastest; kinetic energy grows with the spin
    assert ok["analysis.mass"].tolist() == ["consistent", "lumped"] * 2
    assert (ok["final_kinetic"].iloc[2:].to_numpy() > ok["final_kinetic"].iloc[:2].to_numpy()).all()
    assert (ok["momentum_change"] < 1e-10).all()  # a free body keeps its angular momentum
    assert (out / "sweep_final_kinetic_vs_bodies_0_initial_angular_velocity.png").is_file()
    written = pd.read_csv(out / "sweep.csv")
    assert written["case"].tolist() == table["case"].tolist()
    for case in ok["case"]:
        assert (out / "cases" / case / "history.csv").is_file()

    again = sweep(sweep_file, out, workers=2, progress=False)
    assert again.iloc[:4]["skipped"].all()  # finished: not run again
    assert not bool(again.iloc[4]["skipped"]) and again.iloc[4]["status"] == "failed"
    pd.testing.assert_series_equal(again["final_kinetic"].iloc[:4], table["final_kinetic"].iloc[:4])


def test_case_folders_depend_only_on_the_overrides():
    assert case_name(["a=1", "b=2"]) == case_name(["a=1", "b=2"])
    assert case_name(["a=1", "b=2"]) != case_name(["a=1", "b=3"])


def test_a_sweep_file_without_cases_or_with_a_wrong_reduction_is_refused(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text('scenario = "x.toml"\n')
    with pytest.raises(ScenarioError, match="give \\[grid\\] or \\[\\[cases\\]\\]"):
        load_sweep(bad)
    bad.write_text('scenario = "x.toml"\n[grid]\na = [1]\n[reductions]\ne = "total_energy:mean"\n')
    with pytest.raises(ScenarioError, match="reductions.e = 'total_energy:mean'"):
        load_sweep(bad)


def test_an_override_naming_no_key_stops_the_sweep_before_any_case_runs(sweep_file, tmp_path):
    sweep_file.write_text(SWEEP.replace('"analysis.mass"', '"analysis.masss"'))
    with pytest.raises(ScenarioError, match="analysis.masss"):
        sweep(sweep_file, tmp_path / "out", workers=1, progress=False)
    assert not (tmp_path / "out").exists()


@pytest.mark.slow
def test_the_sweep_command_exits_1_when_a_case_failed(sweep_file, tmp_path):
    done = subprocess.run([sys.executable, "-m", "ntncontact.cli", "sweep", str(sweep_file),
                           "--out", str(tmp_path / "o"), "--workers", "2", "--quiet"],
                          capture_output=True, text=True, timeout=600)
    assert done.returncode == 1, done.stderr
    assert "5 cases (0 already done, 1 not completed)" in done.stdout
    assert "Traceback" not in done.stderr
