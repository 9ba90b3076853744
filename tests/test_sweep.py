"""Sweeps on Dask: a LocalCluster with 2 workers, a failing case, a rerun that skips."""

from __future__ import annotations

import json
import signal
import socket
import subprocess
import sys
import time
import warnings
from pathlib import Path

import pandas as pd
import pytest

from ntncontact.io.scenario import ScenarioError
from ntncontact.studies.sweep import SCHEDULER_HTTP, case_name, load_sweep, sweep

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
    # how far it got, from its folder (NaN before): it failed in its first step
    assert bad["steps"] == 0 and bad["wall_time_s"] > 0 and bad["energy_initial"] > 0
    # grid order, last key fastest; kinetic energy grows with the spin
    assert ok["analysis.mass"].tolist() == ["consistent", "lumped"] * 2
    assert (ok["final_kinetic"].iloc[2:].to_numpy() > ok["final_kinetic"].iloc[:2].to_numpy()).all()
    assert (ok["momentum_change"] < 1e-10).all()  # a free body keeps its angular momentum
    # the [[cases]] case sets neither grid key: its cells hold the base's values (NaN before)
    assert bad["analysis.mass"] == "consistent"
    assert bad["bodies.0.initial.angular_velocity"] == 2.0
    assert list(table.columns[:3]) == ["case", "bodies.0.initial.angular_velocity",
                                       "analysis.mass"]
    assert (out / "sweep_final_kinetic_vs_bodies_0_initial_angular_velocity.png").is_file()
    written = pd.read_csv(out / "sweep.csv")
    assert written["case"].tolist() == table["case"].tolist()
    for case in ok["case"]:
        assert (out / "cases" / case / "history.csv").is_file()

    again = sweep(sweep_file, out, workers=2, progress=False)
    assert again.iloc[:4]["skipped"].all()  # finished: not run again
    assert not bool(again.iloc[4]["skipped"]) and again.iloc[4]["status"] == "failed"
    pd.testing.assert_series_equal(again["final_kinetic"].iloc[:4], table["final_kinetic"].iloc[:4])

    # the base scenario edited: its completed cases are no longer this sweep's (a tester's
    # rerun after E 100 -> 400 reused the old results as the new ones)
    block = sweep_file.parent / "block.toml"
    block.write_text(block.read_text().replace("E = 100.0", "E = 400.0"))
    edited = sweep(sweep_file, out, workers=2, progress=False)
    assert not edited.iloc[:4]["skipped"].any()
    assert (edited["status"].iloc[:4] == "completed").all()
    assert (edited["final_kinetic"].iloc[:4] != table["final_kinetic"].iloc[:4]).all()


@pytest.mark.slow
def test_a_sweep_beside_a_busy_dashboard_port_warns_nothing(tmp_path):
    """Port 8787 taken (by another sweep or a notebook's Dask dashboard): the sweep's own
    cluster serves its HTTP routes elsewhere, without Distributed's "already in use"."""
    (tmp_path / "block.toml").write_text(BLOCK)
    spec = tmp_path / "sweep.toml"
    spec.write_text('scenario = "block.toml"\n[grid]\n"analysis.mass" = ["lumped"]\n')
    with socket.socket() as busy:
        try:
            busy.bind(("127.0.0.1", 8787))
            busy.listen()
        except OSError:
            pass  # already taken by something else: the case under test all the same
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            table = sweep(spec, tmp_path / "out", workers=1, progress=False)
    assert table["status"].tolist() == ["completed"]
    assert not [w for w in caught if "already in use" in str(w.message)]


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


def test_a_case_costs_its_steps_times_its_elements_and_nothing_once_completed(
        sweep_file, tmp_path):
    from ntncontact.api import load_scenario
    from ntncontact.studies.sweep import case_cost

    block = sweep_file.parent / "block.toml"
    base = case_cost(load_scenario(block), tmp_path / "a")
    assert base == 4 * 2 * round(0.06 / 0.02)  # 4 x 2 elements, 3 steps
    finer = load_scenario(block, {"bodies.0.mesh.nx": 12, "analysis.dt": 0.005})
    assert case_cost(finer, tmp_path / "b") == pytest.approx(12 * 2 * 12)
    # a mesh that cannot be built stops the sweep before any case runs (it used to cost
    # nothing here and fail on its worker after the other cases had run)
    broken = load_scenario(block, {"bodies.0.mesh": {"type": "gmsh", "file": "missing.msh"}})
    with pytest.raises(ScenarioError, match="mesh file not found"):
        case_cost(broken, tmp_path / "c")
    done = tmp_path / "done"
    done.mkdir()
    (done / "summary.json").write_text(
        f'{{"status": "completed", "overrides": {list(finer.overrides)!r}}}'.replace("'", '"'))
    assert case_cost(finer, done) == 0.0  # a rerun only reads it back
    assert case_cost(load_scenario(block, {"bodies.0.mesh.nx": 12, "analysis.dt": 0.01}),
                     done) > 0  # other overrides: run again
    # a folder completed before its mesh broke is checked all the same (a tester's rerun
    # after a gmsh file was damaged reported the old results as completed)
    (done / "summary.json").write_text(json.dumps({"status": "completed",
                                                   "overrides": list(broken.overrides)}))
    with pytest.raises(ScenarioError, match="mesh file not found"):
        case_cost(broken, done)


def test_the_cases_start_longest_first_and_come_back_in_the_files_order(monkeypatch, tmp_path):
    """One worker thread: the cases run strictly in the order the sweep hands them out."""
    from dask.distributed import Client, LocalCluster

    from ntncontact.studies import sweep as sweep_module

    def fake_case(scenario_path, case, folder, reductions):
        import time

        return {"case": folder, "started": time.perf_counter_ns()}  # one process: one clock

    monkeypatch.setattr(sweep_module, "run_case", fake_case)
    spec = sweep_module.SweepSpec(scenario="x.toml", cases=[{"a": k} for k in range(5)])
    costs = [3.0, 10.0, 0.0, 10.0, 7.0]
    work = [({"a": k}, f"case{k}", cost) for k, cost in enumerate(costs)]
    with LocalCluster(n_workers=1, threads_per_worker=1, processes=False,
                      dashboard_address=None, scheduler_kwargs=SCHEDULER_HTTP) as cluster, \
            Client(cluster) as client:
        rows = [None] * len(work)
        sweep_module._run_cases(client, True, spec, "x.toml", work, False, rows)
    started = [r["case"] for r in sorted(rows, key=lambda r: r["started"])]
    assert started == ["case1", "case3", "case4", "case0", "case2"]  # ties in file order
    assert [r["case"] for r in rows] == [f"case{k}" for k in range(5)]


@pytest.mark.slow
def test_the_sweeps_own_cluster_runs_with_the_sweeps_dask_settings():
    """The settings reach the worker processes, the nannies and the scheduler, as the
    intervals of their periodic callbacks (ms), and leave this process's Dask config alone."""
    import dask

    from ntncontact.studies.sweep import LOCAL_DASK_CONFIG, _dask_client

    def intervals(server) -> dict[str, float]:
        return {name: pc.callback_time for name, pc in server.periodic_callbacks.items()}

    before = {key: dask.config.get(key) for key in LOCAL_DASK_CONFIG}
    with _dask_client(None, 1) as (client, cluster):
        (worker,) = client.run(lambda dask_worker: intervals(dask_worker)).values()
        (nanny,) = (intervals(n) for n in cluster.workers.values())
        scheduler = intervals(cluster.scheduler)
    assert "profile" not in worker and "profile-cycle" not in worker  # no profiler
    for server in (worker, scheduler):
        assert server["tick"] == 1000 and server["monitor"] == 5000
    assert worker["memory_monitor"] == nanny["memory_monitor"] == 1000
    assert {key: dask.config.get(key) for key in LOCAL_DASK_CONFIG} == before  # not leaked


@pytest.mark.parametrize("workers", [0, -1])
def test_a_sweep_of_no_workers_is_refused_before_anything_starts(sweep_file, tmp_path, workers):
    """A LocalCluster of no workers waited for ever, silently (a tester's `--workers 0`)."""
    with pytest.raises(ValueError, match="workers must be >= 1"):
        sweep(sweep_file, tmp_path / "out", workers=workers, progress=False)
    assert not (tmp_path / "out").exists()


def test_a_case_whose_mesh_cannot_be_built_stops_the_sweep_before_any_case_runs(tmp_path):
    """docs/api.md: every case is checked before any runs. A tester's case with a missing mesh
    file failed on its worker after the valid case had run, and a bad key in [[cases]] was
    reported as the base scenario's, naming neither the case nor the sweep file."""
    (tmp_path / "block.toml").write_text(BLOCK)
    spec = tmp_path / "sweep.toml"
    spec.write_text('scenario = "block.toml"\n[[cases]]\n"analysis.dt" = 0.02\n[[cases]]\n'
                    '"bodies.0.mesh" = { type = "gmsh", file = "missing.msh" }\n')
    with pytest.raises(ScenarioError, match=r"sweep\.toml: case 1 .*mesh file not found"):
        sweep(spec, tmp_path / "out", workers=1, progress=False)
    assert not (tmp_path / "out" / "cases").exists()
    spec.write_text('scenario = "block.toml"\n[[cases]]\n"analysis.dtt" = 0.02\n')
    with pytest.raises(ScenarioError, match=r"sweep\.toml: case 0 \(analysis\.dtt=0\.02\)"):
        sweep(spec, tmp_path / "out", workers=1, progress=False)


@pytest.mark.slow
@pytest.mark.parametrize("signum", [signal.SIGTERM, signal.SIGINT])
def test_a_signalled_sweep_stops_and_keeps_the_cases_done(sweep_file, tmp_path, signum):
    """A tester's sweep started with SIGINT ignored (a script's background job) ran on
    through a SIGINT, and SIGTERM ended it without a word or a sweep.csv. Now either stops the
    sweep with one line, keeps the cases done in sweep.csv, and a rerun runs the rest."""
    out = tmp_path / "out"
    child = subprocess.Popen(
        [sys.executable, "-m", "ntncontact.cli", "sweep", str(sweep_file), "--out", str(out),
         "--workers", "1", "--quiet"], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
        text=True, preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_IGN))
    cases = out / "cases"
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline and not any(
            (c / "summary.json").is_file() and '"completed"' in (c / "summary.json").read_text()
            for c in (cases.iterdir() if cases.is_dir() else [])):
        time.sleep(0.1)
    child.send_signal(signum)
    _, err = child.communicate(timeout=120)
    assert child.returncode == 130, err
    assert "interrupted" in err and "Traceback" not in err
    done = pd.read_csv(out / "sweep.csv")
    ran = done[done["status"] != "interrupted"]  # the case running then is listed as such
    assert 1 <= len(ran) < 5 and set(done["status"]) <= {"completed", "failed", "interrupted"}
    again = sweep(sweep_file, out, workers=1, progress=False)
    assert len(again) == 5 and again["skipped"].sum() >= (ran["status"] == "completed").sum()


def test_an_interrupted_sweep_keeps_a_case_completed_on_disk_whose_result_was_in_flight(
        sweep_file, tmp_path):
    """CI caught a SIGINT after a case's folder completed but before its result reached the
    client: sweep.csv was written empty. The interrupted sweep's rows now take such a case from
    its folder, the same row its worker returns; a case not run stays out."""
    import time

    from ntncontact.studies.sweep import _rows_on_disk, run_case

    reductions = {"final_kinetic": "kinetic_energy:last"}
    cases = [{"analysis.mass": "lumped"}, {"analysis.mass": "consistent"}]
    work = [(case, str(tmp_path / f"case{k}"), 1.0) for k, case in enumerate(cases)]
    started = time.time()
    returned = run_case(str(sweep_file.parent / "block.toml"), cases[0], work[0][1], reductions)
    assert returned["status"] == "completed" and not returned["skipped"]
    assert _rows_on_disk(work, [None, None], reductions, started) == [returned]
    assert _rows_on_disk(work, [{"case": "x"}, None], reductions, started) == [{"case": "x"}]
    # a folder completed before this sweep started may be another base scenario's (a
    # tester's interrupted rerun after an edit listed such rows as this run's)
    assert _rows_on_disk(work, [None, None], reductions, time.time() + 1.0) == []
    # a case running at the interrupt is listed as such (a tester's sweep.csv had none)
    (running,) = _rows_on_disk(work, [None, None], reductions, time.time() + 1.0, {1})
    assert running["case"] == "case1" and running["status"] == "interrupted"
    assert running["analysis.mass"] == "consistent" and "steps" not in running
    assert _rows_on_disk(work, [None, None], reductions, started, {0, 1})[0] == returned


def test_a_figure_of_a_column_the_table_will_not_have_is_refused_before_any_case_runs(
        tmp_path):
    """A tester's figure of an unknown column failed only after every case had run."""
    bad = tmp_path / "bad.toml"
    bad.write_text('scenario = "x.toml"\n[grid]\n"analysis.dt" = [0.1]\n[[figures]]\n'
                   'x = "analysis.dt"\ny = "nope"\n')
    with pytest.raises(ScenarioError, match="figures.0.y = 'nope': not a column of sweep.csv"):
        load_sweep(bad)
    bad.write_text('scenario = "x.toml"\n[grid]\n"analysis.dt" = [0.1]\n[reductions]\n'
                   'ke = "kinetic_energy:last"\n[[figures]]\nx = "analysis.dt"\ny = "ke"\n'
                   'by = "max_penetration"\n')
    assert load_sweep(bad)[0].figures[0].y == "ke"


def test_a_completed_case_whose_edited_base_no_longer_builds_is_failed_without_old_results(
        sweep_file, tmp_path):
    """A tester's rerun after an edit that made the base unbuildable (bodies overlapping)
    reported every case `completed` with the old geometry's results and the build error: the
    error's row took the folder's old summary, status and all."""
    from ntncontact.studies.sweep import run_case

    block = sweep_file.parent / "block.toml"
    reductions = {"final_kinetic": "kinetic_energy:last"}
    folder = str(tmp_path / "case")
    first = run_case(str(block), {"analysis.mass": "lumped"}, folder, reductions)
    assert first["status"] == "completed" and first["steps"] == 3
    block.write_text(BLOCK.replace("max_cutbacks = 0", "max_cutbacks = 0\n"
                                   "energy_conserving = true"))  # refused when built
    again = run_case(str(block), {"analysis.mass": "lumped"}, folder, reductions)
    assert again["status"] == "failed" and not again["skipped"]
    assert "energy_conserving" in again["error"]
    for key in ("steps", "final_kinetic", "wall_time_s", "energy_final"):
        assert key not in again, key  # the old scenario's numbers are not this case's


def test_repeated_cases_are_refused_and_key_order_does_not_make_another_case(tmp_path):
    """A tester's repeated [[cases]] table shared one folder and was recorded `running` (the
    first case's lock); the same overrides in another key order ran twice in two folders."""
    bad = tmp_path / "bad.toml"
    bad.write_text('scenario = "x.toml"\n[[cases]]\n"a.b" = 0.3\n[[cases]]\n"c" = 1\n'
                   '[[cases]]\n"a.b" = 0.3\n')
    with pytest.raises(ScenarioError, match=r"cases 0 and 2 are the same case \(a\.b=0\.3\)"):
        load_sweep(bad)
    bad.write_text('scenario = "x.toml"\n[[cases]]\n"a" = 1\n"b" = "x"\n'
                   '[[cases]]\n"b" = "x"\n"a" = 1\n')
    with pytest.raises(ScenarioError, match=r"cases 0 and 1 are the same case"):
        load_sweep(bad)
    # 10000 and 10000.0 are one value (tester R: two folders, two equal rows)
    bad.write_text('scenario = "x.toml"\n[[cases]]\n"a" = 10000\n[[cases]]\n"a" = 10000.0\n')
    with pytest.raises(ScenarioError, match=r"cases 0 and 1 are the same case"):
        load_sweep(bad)
    # a grid's cases keep their keys' order, so their folders keep their names
    ok = tmp_path / "ok.toml"
    ok.write_text('scenario = "x.toml"\n[set]\n"z" = 2\n[grid]\n"b" = [1]\n"a" = [3]\n'
                  '[[cases]]\n"a" = 4\n"b" = 5\n')
    spec = load_sweep(ok)[0]
    assert [list(c) for c in spec.case_overrides()] == [["z", "b", "a"], ["z", "b", "a"]]
    assert case_name(["z=2", "b=1", "a=3"]) == "case-" + __import__("hashlib").sha1(
        b"z=2\nb=1\na=3").hexdigest()[:10]


def test_a_key_in_both_set_and_grid_is_refused_and_a_case_overrides_set(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text('scenario = "x.toml"\n[set]\n"a" = 0.9\n[grid]\n"a" = [0.0, 0.4]\n')
    with pytest.raises(ScenarioError, match="'a' is in both \\[set\\] and \\[grid\\]"):
        load_sweep(bad)
    bad.write_text('scenario = "x.toml"\n[set]\n"a" = 0.9\n"b" = 1\n[[cases]]\n"a" = 0.1\n'
                   '[[cases]]\n"b" = 2\n')
    assert load_sweep(bad)[0].case_overrides() == [{"a": 0.1, "b": 1}, {"a": 0.9, "b": 2}]


def test_a_reduction_of_a_column_history_csv_never_has_is_refused_naming_close_ones(
        tmp_path):
    """A tester's misspelt reduction column gave an empty sweep.csv column, silently."""
    bad = tmp_path / "bad.toml"
    bad.write_text('scenario = "x.toml"\n[grid]\na = [1]\n[reductions]\n'
                   'd = "frictional_dissipaton:last"\n')
    with pytest.raises(ScenarioError, match="reductions.d = 'frictional_dissipaton:last': "
                       "history.csv has no column 'frictional_dissipaton' "
                       r"\(did you mean frictional_dissipation\?\)"):
        load_sweep(bad)
    bad.write_text('scenario = "x.toml"\n[grid]\na = [1]\n[reductions]\n'
                   'r = "reaction_base_bottom_y:max_abs"\nw = "external_work:last"\n'
                   'p = "penetration_off_surfaces:max"\n')
    assert len(load_sweep(bad)[0].reductions) == 3  # the model's own columns pass


def test_figures_of_vectors_and_blanks_are_drawn_and_one_that_cannot_be_is_a_warning(
        tmp_path):
    """A tester's figure by velocity vectors, and one of a text x with a blank, raised after
    every case had run: the command said "internal error" and the API lost the table."""
    from ntncontact.studies.sweep import FigureSpec, _draw_figures

    table = pd.DataFrame({"v": [[1.0, -1.0], [2.0, -2.0], [1.0, -1.0], None],
                          "mass": ["consistent", "lumped", None, "lumped"],
                          "mu": [0.1, 0.1, 0.3, 0.3], "d": [1.0, 2.0, 3.0, 4.0]})
    figures = [FigureSpec(x="mu", y="d", by="v"), FigureSpec(x="mass", y="d", by="v"),
               FigureSpec(x="mu", y="d", by="mass"), FigureSpec(x="mu", y="nope")]
    with pytest.warns(RuntimeWarning, match="figure nope against mu not drawn: .*no column "
                      "nope") as caught:
        _draw_figures(table, figures, tmp_path)
    assert len(caught) == 1
    for name in ("sweep_d_vs_mu.png", "sweep_d_vs_mass.png"):
        assert (tmp_path / name).stat().st_size > 0


def test_a_figure_of_vectors_on_its_x_axis_is_refused_before_any_case_runs(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text('scenario = "x.toml"\n[grid]\n"v" = [[1, -1], [2, -2]]\n"mu" = [0.1]\n'
                   '[[figures]]\nx = "v"\ny = "steps"\n')
    with pytest.raises(ScenarioError, match=r"figures\.0\.x = 'v': its values are not numbers "
                       r"or text \(\[1, -1\]\).*can be `by`"):
        load_sweep(bad)
    bad.write_text(bad.read_text().replace('x = "v"', 'x = "mu"\nby = "v"'))
    assert load_sweep(bad)[0].figures[0].by == "v"


def test_a_case_that_does_not_set_a_sweep_key_gets_the_value_it_ran_with(sweep_file):
    """A tester's case without `analysis.mass` had NaN there in sweep.csv (it ran with the
    consistent mass), and the figure by mass dropped it silently."""
    from ntncontact.api import load_scenario
    from ntncontact.studies.sweep import _filled, _values

    keys = ["contact.0.friction", "analysis.mass", "bodies.0.initial.velocity",
            "bodies.0.initial.angular_velocity"]
    scenario = load_scenario(sweep_file.parent / "block.toml", {"analysis.dt": 0.01})
    values = _values(scenario, keys)
    assert values == {"contact.0.friction": None, "analysis.mass": "consistent",
                      "bodies.0.initial.velocity": [1.0, 0.0],
                      "bodies.0.initial.angular_velocity": 2.0}
    row = {"case": "c1", "analysis.mass": "lumped", "status": "completed"}
    filled = _filled(row, {"c1": values})
    assert list(filled) == ["case", *keys, "status"]
    assert filled["analysis.mass"] == "lumped" and filled["bodies.0.initial.velocity"] == [1.0, 0.0]


@pytest.mark.parametrize(("at_end", "duration"), [(False, 2.05), (True, None)])
def test_a_run_that_ended_in_contact_has_no_contact_duration(at_end, duration):
    """A tester's rod impact cut at t = 1.0 read a duration of 0.95 beside the full run's 2.05:
    its contact_end_time was the run's end (summary.json contact_at_end)."""
    from types import SimpleNamespace

    import pandas as pd

    from ntncontact.studies.sweep import _results_row

    summary = {"status": "completed", "contact_start_time": 0.05, "contact_end_time": 2.1,
               "contact_at_end": at_end}
    row = _results_row(SimpleNamespace(summary=summary, history=pd.DataFrame()), {})
    assert row["contact_at_end"] is at_end
    assert "contact_duration" in row  # a column even where no case's contact ended
    assert row["contact_duration"] == (None if duration is None else pytest.approx(duration))


@pytest.mark.parametrize(("sets", "expected"), [
    ({}, {"law": "persistency", "detection": "penetration", "moment_free": True}),
    ({"contact.0.method": "lagrange", "contact.0.law": "gap", "contact.0.penalty_normal": 0.0},
     {"law": "gap", "detection": "predicted", "moment_free": True}),
    ({"contact.0.detection": "predicted", "contact.0.moment_free": False},
     {"law": "persistency", "detection": "predicted", "moment_free": False})])
def test_keys_the_build_resolves_get_the_value_the_case_ran_with(sets, expected):
    """Tester R (session 41): contact.0.detection, law and moment_free stayed empty in
    sweep.csv for cases that did not set them (their config holds None until the build), and
    a figure by detection drew one "none" line through a predicted and a penetration case."""
    from ntncontact.api import load_scenario
    from ntncontact.engine.builder import build_model
    from ntncontact.studies.sweep import _values

    scenario = load_scenario(Path(__file__).parents[1] / "examples" / "rod_impact.toml", sets)
    keys = [f"contact.0.{k}" for k in expected]
    assert _values(scenario, keys) == {f"contact.0.{k}": v for k, v in expected.items()}
    model = build_model(scenario.config, scenario.base_dir)  # what the run takes
    ci = model.interfaces[0]
    assert (ci.persistency, ci.predicted_detection, ci.law.moment_free) == (
        expected["law"] == "persistency", expected["detection"] == "predicted",
        expected["moment_free"])


def test_cases_with_table_values_are_compared_too(tmp_path):
    """A case may set a table (a mesh): the repeat check must compare it, not fail on it (the
    first version raised "unhashable type: 'dict'")."""
    bad = tmp_path / "bad.toml"
    mesh = '{ type = "rectangle", width = 1.0, height = 1.0, nx = 2, ny = 2 }'
    bad.write_text(f'scenario = "x.toml"\n[[cases]]\n"bodies.0.mesh" = {mesh}\n'
                   f'[[cases]]\n"bodies.0.mesh" = {mesh.replace("1.0", "1")}\n')
    with pytest.raises(ScenarioError, match=r"cases 0 and 1 are the same case"):
        load_sweep(bad)


def test_an_interrupted_sweeps_teardown_logs_nothing_to_the_terminal(monkeypatch, caplog):
    """The full suite under load once printed Tornado's "Exception in callback ...
    'forgotten'" traceback after a SIGINT: the client, closing, forgot the cases in flight.
    A client whose close logs that error (a stand-in for the race) must log nothing when the
    sweep was interrupted, and logging must be as before afterwards; a close after a sweep
    that ended normally still logs."""
    import logging

    import dask.distributed

    from ntncontact.studies import sweep as sweep_module

    class ForgettingClient:
        def __init__(self, address):
            self.address = address

        def __enter__(self):
            return self

        def __exit__(self, *exc):
            logging.getLogger("tornado.application").error("Exception in callback: forgotten")
            logging.getLogger("distributed.client").error("forgotten keys")

    monkeypatch.setattr(dask.distributed, "Client", ForgettingClient)
    before = logging.root.manager.disable
    with caplog.at_level(logging.INFO), pytest.raises(KeyboardInterrupt):
        with sweep_module._dask_client("tcp://nowhere:1", None):
            raise KeyboardInterrupt
    assert not caplog.records and logging.root.manager.disable == before
    with caplog.at_level(logging.INFO), sweep_module._dask_client("tcp://nowhere:1", None):
        pass
    assert {r.name for r in caplog.records} == {"tornado.application", "distributed.client"}
