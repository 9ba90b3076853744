"""Checkpoint and restart (issue 19 §2): a run killed by SIGKILL at a random step and continued
with ``--restart`` writes what the uninterrupted run writes, number for number."""

from __future__ import annotations

import json
import os
import random
import signal
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from helpers import history_steps, wait_until

import ntncontact as ntc
from ntncontact.cli import main
from ntncontact.engine import interfaces
from ntncontact.io.checkpoint import (
    CHECKPOINT_DIR,
    KEEP,
    CheckpointError,
    checkpoint_files,
    read_checkpoint,
)
from ntncontact.io.vtk import XdmfSeries, read_pvd, read_vtu
from ntncontact.io.writers import read_csv_table
from ntncontact.solvers.linear import pardiso_available

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"
TIMEOUT = 600.0  # a loaded machine (2 cores, many jobs) runs the children slowly
#: shown in every failure message; RESTART_TEST_SEED=<seed> replays a failure's kill steps
SEED = int(os.environ.get("RESTART_TEST_SEED") or random.SystemRandom().randrange(2**32))

# (scenario, overrides, checkpoint_interval, first and last step of the first kill). Every kill
# step is past the first checkpoint, in the case's contact phase, and leaves room for a second
# kill (of the restarted run) before the last step:
# - the static frictional block (report 6.1), 8 load steps;
# - the fast-sliding blocks with friction 0.2 (ALE lower block), contact from t = 0.048;
# - the ring impact (ALE obstacle, Newton multiplier updates), contact from t = 0.065;
# - the same refined 4x (12 002 unknowns): PARDISO, single-precision factors and the union's
#   reserved entries. Its reference runs in this process, which asked for PARDISO at
#   collection, its children load MKL after Numba's kernels: 5 of 5 tries differed before
#   MKL's threading layer was pinned (solvers.linear._pin_mkl_threading_layer).
RING_4X = ["bodies.0.mesh.n_radial=16", "bodies.0.mesh.n_circ=192", "bodies.1.mesh.nx=160",
           "bodies.1.mesh.ny=16"]
CASES = {
    "block_sliding": ("block_sliding.toml", [], 0.5, 3, 5),
    "blocks_fast_sliding": ("blocks_fast_sliding.toml",
                            ["contact.0.friction=0.2", "analysis.t_end=0.09"], 0.012, 18, 25),
    "ring_impact": ("ring_impact.toml", ["analysis.t_end=0.12"], 0.02, 14, 19),
    "ring_impact_4x": ("ring_impact.toml", ["analysis.t_end=0.12", *RING_4X], 0.02, 14, 19),
}


def run_cli(scenario: Path, out: Path, overrides: list[str], *extra: str) -> int:
    sets = [item for o in overrides for item in ("--set", o)]
    return main(["run", str(scenario), "--out", str(out), "--quiet", *sets, *extra])


def start_child(scenario: Path, out: Path, overrides: list[str], *extra: str
                ) -> subprocess.Popen:
    """``ntncontact run`` in a child process with this test's environment (kernel cache)."""
    sets = [item for o in overrides for item in ("--set", o)]
    command = [sys.executable, "-m", "ntncontact.cli", "run", str(scenario), "--out", str(out),
               "--quiet", *sets, *extra]
    return subprocess.Popen(command, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                            text=True)


def kill_at_step(child: subprocess.Popen, out: Path, step: int) -> None:
    """SIGKILL the child as soon as history.csv holds the row of ``step``."""
    wait_until(lambda: bool(history_steps(out)) and history_steps(out)[-1] >= step, child,
               f"step {step} (seed {SEED})", TIMEOUT, poll=0.002)
    child.send_signal(signal.SIGKILL)
    child.communicate(timeout=TIMEOUT)
    assert child.returncode == -signal.SIGKILL


def assert_same_table(path_a: Path, path_b: Path, context: str) -> None:
    """Equal columns, numbers compared exactly (floats parsed from repr, NaN equal to NaN)."""
    a, b = read_csv_table(path_a), read_csv_table(path_b)
    assert list(a) == list(b), context
    for name in a:
        assert a[name].shape == b[name].shape, f"{context}: {path_a.name} {name} rows"
        same = (np.array_equal(a[name], b[name], equal_nan=True) if a[name].dtype.kind == "f"
                else np.array_equal(a[name], b[name]))
        assert same, f"{context}: {path_a.name} column {name} differs"


def assert_same_frames(out_a: Path, out_b: Path, context: str) -> None:
    """The same frames at the same times, with exactly the same points, cells and data."""
    frames_a, frames_b = read_pvd(out_a / "fields.pvd"), read_pvd(out_b / "fields.pvd")
    assert [t for t, _ in frames_a] == [t for t, _ in frames_b], context
    assert [p.name for _, p in frames_a] == [p.name for _, p in frames_b], context
    assert sorted(p.name for p in (out_b / "fields").glob("*.vtu")) == \
        sorted(p.name for _, p in frames_b), f"{context}: frames not in the PVD"
    for (_, path_a), (_, path_b) in zip(frames_a, frames_b, strict=True):
        fa, fb = read_vtu(path_a), read_vtu(path_b)
        assert np.array_equal(fa.points, fb.points), f"{context}: {path_a.name} points"
        assert np.array_equal(fa.cells, fb.cells), f"{context}: {path_a.name} cells"
        for kind in ("point_data", "cell_data"):
            da, db = getattr(fa, kind), getattr(fb, kind)
            assert sorted(da) == sorted(db), f"{context}: {path_a.name} {kind}"
            for name in da:  # NaN where a field is undefined (gap rates of a static run)
                assert np.array_equal(da[name], db[name], equal_nan=da[name].dtype.kind == "f"), \
                    f"{context}: {path_a.name} {name}"


def summary(out: Path) -> dict:
    data = json.loads((out / "summary.json").read_text())
    data.pop("wall_time_s")
    data.pop("cpu_time_s")
    data.pop("scenario_hash")  # the killed runs' scenarios add analysis.checkpoint_interval
    return data


@pytest.fixture(scope="module")
def reference(tmp_path_factory):
    """Uninterrupted runs (without checkpoints: writing them must not change a number)."""
    done: dict[str, Path] = {}

    def get(name: str) -> Path:
        if name not in done:
            scenario, overrides, *_ = CASES[name]
            out = tmp_path_factory.mktemp("reference") / name
            assert run_cli(EXAMPLES / scenario, out, overrides) == 0
            done[name] = out
        return done[name]

    return get


@pytest.mark.slow
@pytest.mark.parametrize("name", list(CASES))
def test_a_killed_run_continued_from_its_checkpoint_matches_the_uninterrupted_one(
        name, reference, tmp_path):
    scenario, overrides, interval, first, last = CASES[name]
    overrides = [*overrides, f"analysis.checkpoint_interval={interval}"]
    rng = random.Random(f"{SEED}-{name}")
    kill_step = rng.randint(first, last)
    out = tmp_path / name
    kill_at_step(start_child(EXAMPLES / scenario, out, overrides), out, kill_step)
    # the restarted run is killed too, at a step past the rows the first one left
    steps = len(history_steps(reference(name))) - 1
    again = min(history_steps(out)[-1] + rng.randint(1, 2), steps - 1)
    context = f"{name} killed at steps {kill_step} and {again} (seed {SEED})"
    kill_at_step(start_child(EXAMPLES / scenario, out, overrides, "--restart"), out, again)
    assert summary(out)["status"] == "running", context  # killed: no chance to say more
    checkpoints = checkpoint_files(out)
    assert 1 <= len(checkpoints) <= KEEP, context
    resumed_from = read_checkpoint(checkpoints[0])[0]["step"]
    assert history_steps(out)[-1] >= resumed_from, context
    # the frames up to the checkpoint are kept as they are, later ones are written again
    kept = {p: p.stat().st_mtime_ns for p in (out / "fields").glob("*.vtu")
            if int(p.stem.rsplit("_", 1)[-1]) <= resumed_from}
    assert run_cli(EXAMPLES / scenario, out, overrides, "--restart") == 0, context
    assert kept and all(p.stat().st_mtime_ns == t for p, t in kept.items()), context
    assert not list(out.rglob("*.tmp")), f"{context}: temporary files left"
    ref = reference(name)
    assert history_steps(out) == list(range(len(history_steps(ref)))), context
    assert_same_table(ref / "history.csv", out / "history.csv", context)
    assert_same_table(ref / "contact.csv", out / "contact.csv", context)
    assert len(read_csv_table(out / "contact.csv")["step"]) > 0, f"{context}: no contact"
    assert_same_frames(ref, out, context)
    assert summary(out) == summary(ref) | {"overrides": overrides}, context


def assert_same_xdmf_frames(out_a: Path, out_b: Path, context: str) -> None:
    """The same XDMF frames at the same times, with exactly the same points, cells and data,
    and no array in the HDF5 file that the index does not name."""
    import h5py

    series_a, series_b = XdmfSeries(out_a / "fields.xdmf"), XdmfSeries(out_b / "fields.xdmf")
    assert series_a.times == series_b.times, context
    for k in range(len(series_a)):
        fa, fb = series_a.mesh(k), series_b.mesh(k)
        assert np.array_equal(fa.points, fb.points), f"{context}: frame {k} points"
        assert np.array_equal(fa.cells[0].data, fb.cells[0].data), f"{context}: frame {k}"
        assert sorted(fa.point_data) == sorted(fb.point_data), context
        for name in fa.point_data:
            assert np.array_equal(fa.point_data[name], fb.point_data[name], equal_nan=True), \
                f"{context}: frame {k} {name}"
        for name in fa.cell_data:
            assert np.array_equal(fa.cell_data[name][0], fb.cell_data[name][0],
                                  equal_nan=True), f"{context}: frame {k} {name}"
    with h5py.File(out_a / "fields.h5") as a, h5py.File(out_b / "fields.h5") as b:
        assert sorted(a) == sorted(b), f"{context}: arrays the index does not name"


@pytest.mark.slow
def test_a_killed_xdmf_run_continued_from_its_checkpoint_matches_the_uninterrupted_one(
        tmp_path):
    """An XDMF + HDF5 series (long runs' format) restarts as VTU frames do: the checkpoint
    writes the index, the restart keeps the checkpoint's frames and drops the later ones a
    kill left in the HDF5 file. It used to be refused when the scenario was read."""
    pytest.importorskip("h5py")
    spin = EXAMPLES / "ring_impact.toml"
    overrides = ["analysis.t_end=0.12", 'analysis.field_format="xdmf"',
                 "analysis.output_interval=0.01"]
    ref = tmp_path / "reference"
    assert run_cli(spin, ref, overrides) == 0
    overrides.append("analysis.checkpoint_interval=0.02")
    rng = random.Random(f"{SEED}-xdmf")
    out = tmp_path / "ring"
    kill_at_step(start_child(spin, out, overrides), out, rng.randint(14, 19))
    again = min(history_steps(out)[-1] + rng.randint(1, 2), 22)
    context = f"xdmf killed at {history_steps(out)[-1]} and {again} (seed {SEED})"
    kill_at_step(start_child(spin, out, overrides, "--restart"), out, again)
    assert run_cli(spin, out, overrides, "--restart") == 0, context
    assert not list(out.glob(".*")), f"{context}: temporary files left"
    assert_same_table(ref / "history.csv", out / "history.csv", context)
    assert_same_table(ref / "contact.csv", out / "contact.csv", context)
    assert_same_xdmf_frames(ref, out, context)


def test_a_restart_from_an_unreadable_hdf5_file_says_so_and_changes_nothing(tmp_path, capsys):
    """A fields.h5 cut short (a disk failure) cannot give the checkpoint's frames: the restart
    stops with one line naming it, and leaves the file and summary.json as they were (the
    summary used to be rewritten as a fresh run's before the frames were read)."""
    pytest.importorskip("h5py")
    spin = EXAMPLES / "spinning_block.toml"
    overrides = ["analysis.t_end=0.08", "analysis.checkpoint_interval=0.02",
                 'analysis.field_format="xdmf"']
    out = tmp_path / "spin"
    assert run_cli(spin, out, overrides) == 0
    checkpoint_files(out)[0].unlink()  # the restart would cut the CSV files back a step
    h5 = out / "fields.h5"
    h5.write_bytes(h5.read_bytes()[: h5.stat().st_size // 3])
    files = [h5, out / "fields.xdmf", out / "summary.json", out / "history.csv",
             out / "contact.csv"]
    before = {path: path.read_bytes() for path in files if path.exists()}
    capsys.readouterr()
    assert run_cli(spin, out, overrides, "--restart") == 1
    err = capsys.readouterr().err
    assert str(h5) in err and "cannot restart" in err and "Traceback" not in err, err
    # a tester's refused restart had cut history.csv back already
    assert {path: path.read_bytes() for path in before} == before
    assert not list(out.glob(".*"))
    h5.unlink()  # missing: said so in one line (it was "[Errno 2] ... -> .fields.h5.restart")
    assert run_cli(spin, out, overrides, "--restart") == 1
    assert f"{h5} is missing" in capsys.readouterr().err


def test_a_restart_killed_while_it_copies_the_series_leaves_it_readable(tmp_path,
                                                                        monkeypatch):
    """The restart writes the kept frames beside the old file and then replaces the index
    and the file: a tester's restart killed while it copied in place left every frame
    unreadable until the next restart. Here the copy fails half way (as a kill would stop
    it): every frame of the folder still reads, and the next restart completes the run."""
    pytest.importorskip("h5py")
    from ntncontact.io import vtk

    spin = EXAMPLES / "spinning_block.toml"
    overrides = ["analysis.t_end=0.08", "analysis.checkpoint_interval=0.02",
                 'analysis.field_format="xdmf"']
    full = tmp_path / "full"
    assert run_cli(spin, full, overrides) == 0
    out = tmp_path / "spin"
    assert run_cli(spin, out, overrides) == 0
    checkpoint_files(out)[0].unlink()
    real = vtk.XdmfSeriesWriter._copy_frames

    def killed(self, old, new, frames):
        real(self, old, new, frames)
        raise KeyboardInterrupt  # after the copy, before the files are replaced

    monkeypatch.setattr(vtk.XdmfSeriesWriter, "_copy_frames", killed)
    assert run_cli(spin, out, overrides, "--restart") == 130
    results = ntc.read_results(out)
    assert [results.fields(t).points.shape for t in results.times]  # every frame reads
    monkeypatch.undo()
    assert run_cli(spin, out, overrides, "--restart") == 0
    assert_same_xdmf_frames(full, out, "restart after a killed restart")


def test_a_restart_is_refused_for_another_scenario_overrides_or_version(tmp_path, capsys,
                                                                        monkeypatch):
    spin = EXAMPLES / "spinning_block.toml"
    base = ["analysis.t_end=0.06", "analysis.checkpoint_interval=0.02"]
    out = tmp_path / "spin"
    assert run_cli(spin, out, base) == 0
    assert len(checkpoint_files(out)) == KEEP
    capsys.readouterr()
    refusals = {
        "other overrides": (spin, [*base, "analysis.mass=\"lumped\""]),
        "another scenario": (EXAMPLES / "ring_impact.toml", base),
    }
    for why, (scenario, overrides) in refusals.items():
        assert run_cli(scenario, out, overrides, "--restart") == 1
        err = capsys.readouterr().err
        assert why in err and "belongs to another run" in err, err
        assert len(err.strip().splitlines()) == 1 and "Traceback" not in err
    monkeypatch.setattr("ntncontact.io.checkpoint.__version__", "0.0.0-other")
    assert run_cli(spin, out, base, "--restart") == 1
    assert "ntncontact 0.1" in capsys.readouterr().err
    monkeypatch.undo()
    # the refused restarts changed nothing: the run's own restart still works
    assert run_cli(spin, out, base, "--restart") == 0


def test_restart_needs_a_readable_checkpoint_and_skips_a_corrupt_newest(tmp_path, capsys):
    spin = EXAMPLES / "spinning_block.toml"
    base = ["analysis.t_end=0.08", "analysis.checkpoint_interval=0.02"]
    out = tmp_path / "spin"
    assert run_cli(spin, out, ["analysis.t_end=0.08"]) == 0  # no checkpoint_interval: none
    assert not checkpoint_files(out)
    assert run_cli(spin, out, ["analysis.t_end=0.08"], "--restart") == 1
    assert "no checkpoint to restart from" in capsys.readouterr().err
    assert run_cli(spin, out, base, "--overwrite") == 0
    reference = read_csv_table(out / "history.csv")
    newest, older = checkpoint_files(out)
    newest.write_bytes(newest.read_bytes()[:100])  # a kill while it was written
    with pytest.raises(CheckpointError):
        read_checkpoint(newest)
    assert run_cli(spin, out, base, "--restart") == 0
    restarted = read_csv_table(out / "history.csv")
    for column in reference:
        assert np.array_equal(reference[column], restarted[column], equal_nan=True), column
    assert run_cli(spin, out, base, "--restart", "--overwrite") == 1
    assert "give one of them" in capsys.readouterr().err


def test_restart_with_overwrite_is_refused_alike_by_the_api_and_the_command(tmp_path, capsys):
    """One check and one message (io.run_setup.check_run_mode) for ntncontact.run and
    ``ntncontact run``, before the results folder is made or locked."""
    spin, out = EXAMPLES / "spinning_block.toml", tmp_path / "spin"
    with pytest.raises(ValueError, match="give one of them") as refused:
        ntc.run(spin, out, restart=True, overwrite=True)
    assert main(["run", str(spin), "--out", str(out), "--quiet", "--restart", "--overwrite"]) == 1
    assert capsys.readouterr().err == f"error: {refused.value}\n"
    assert not out.exists()


def test_the_api_restarts_like_the_command(tmp_path):
    scenario = ntc.load_scenario(EXAMPLES / "spinning_block.toml",
                                 {"analysis.t_end": 0.08, "analysis.checkpoint_interval": 0.02})
    full = ntc.run(scenario, tmp_path / "full")
    out = tmp_path / "cut"
    ntc.run(scenario, out)
    checkpoint_files(out)[0].unlink()  # as if killed between the last two checkpoints
    resumed = ntc.run(scenario, out, restart=True)
    assert resumed.history.equals(full.history)
    assert os.path.isdir(out / CHECKPOINT_DIR)


@pytest.mark.parametrize("t_end", [0.06, 0.072, 0.084, 0.096])
def test_a_restart_reserves_the_union_entries_where_the_run_it_continues_did(
        tmp_path, monkeypatch, t_end):
    """The union pattern's reserved entries (engine.interfaces.RESERVED_FROM_DOFS, forced on
    for this small case) are added at the same calls in a restored run: restored with the
    reservation at its first build, the run factored a larger pattern than the one it
    continued and its kinetic energy differed in the last bits."""
    monkeypatch.setattr(interfaces, "RESERVED_FROM_DOFS", 0)
    scenario = ntc.load_scenario(EXAMPLES / "blocks_fast_sliding.toml",
                                 {"contact.0.friction": 0.2, "analysis.t_end": t_end,
                                  "analysis.checkpoint_interval": 0.012})
    full = ntc.run(scenario, tmp_path / "full")
    out = tmp_path / "cut"
    ntc.run(scenario, out)
    checkpoint_files(out)[0].unlink()  # resumed at t_end - 0.012, in contact from 0.048
    resumed = ntc.run(scenario, out, restart=True)
    assert len(full.contact) and resumed.history.equals(full.history)
    assert resumed.contact.equals(full.contact)


@pytest.mark.parametrize("n", [60, 400, 2500])  # static LU, static LU, SuperLU
def test_a_restored_linear_solver_factors_like_the_one_it_was_saved_from(n):
    """The next matrix of the saved pattern is factored on the kept path (static LU or
    SuperLU on the kept ordering, no new analysis): the same solution, bit for bit."""
    import scipy.sparse as sp

    from ntncontact.solvers.linear import LinearSolver

    rng = np.random.default_rng(n)
    pattern = sp.random(n, n, density=8.0 / n, random_state=rng) + sp.eye(n)
    pattern = (pattern + pattern.T).tocsr()

    def matrix() -> sp.csr_matrix:  # the pattern, new values, diagonally dominant, unsymmetric
        values = pattern.copy()
        values.data = rng.uniform(-1.0, 1.0, values.nnz)
        return (values + sp.diags(np.abs(values).sum(axis=1).A1 + 1.0)).tocsr()

    first, second, b = matrix(), matrix(), rng.standard_normal(n)
    running = LinearSolver(backend="auto")
    running.solve(first, b)
    saved = running.analysis_state()
    expected = running.solve(second, b)
    restored = LinearSolver(backend="auto")
    info, arrays = saved
    restored.restore_analysis(json.loads(json.dumps(info)), arrays)  # as the header keeps it
    assert np.array_equal(restored.solve(second, b), expected)
    assert restored.stats.analyses == 0


@pytest.mark.skipif(not pardiso_available(), reason="pypardiso not installed")
@pytest.mark.parametrize("precision", ["single", "double"])
def test_a_restored_pardiso_solver_analyses_with_the_values_of_the_saved_analysis(monkeypatch,
                                                                                 precision):
    """PARDISO's analysis (scaling, weighted matching) depends on the values it is made with:
    a restored solver analyses with the saved values, not with its first matrix's, and so
    factors that matrix to the same bits as the solver it was saved from. The saved mode's
    precision is restored with it, whatever the restored solver's own setting."""
    import scipy.sparse as sp

    from ntncontact.solvers.linear import PARDISO_MIN_UNKNOWNS, LinearSolver

    monkeypatch.setenv("MKL_NUM_THREADS", "1")
    rng = np.random.default_rng(7)
    side = int(np.ceil(np.sqrt(PARDISO_MIN_UNKNOWNS)))
    pattern = (sp.kronsum(sp.diags([1.0, 1.0, 1.0], [-1, 0, 1], (side, side)),
                          sp.diags([1.0, 1.0, 1.0], [-1, 0, 1], (side, side)))).tocsr()

    def matrix() -> sp.csr_matrix:  # unsymmetric, rows scaled over e^-3..e^3
        values = pattern.copy()
        values.data = rng.uniform(-1.0, 1.0, values.nnz)
        rows = np.exp(rng.uniform(-3.0, 3.0, pattern.shape[0]))
        return (sp.diags(rows) @ (values + sp.diags(np.abs(values).sum(axis=1).A1 + 0.5))).tocsr()

    first, second, b = matrix(), matrix(), rng.standard_normal(pattern.shape[0])
    running = LinearSolver(backend="pardiso", precision=precision)
    running.solve(first, b)
    info, arrays = running.analysis_state()
    expected = running.solve(second, b)
    other = "double" if precision == "single" else "single"
    restored = LinearSolver(backend="pardiso", precision=other)
    restored.restore_analysis(json.loads(json.dumps(info)), arrays)
    assert np.array_equal(restored.solve(second, b), expected)
    assert [impl.single for impl in restored._impls.values()] == [precision == "single"]
    fresh = LinearSolver(backend="pardiso", precision=precision)  # its own analysis: other bits
    assert not np.array_equal(fresh.solve(second, b), expected)


def test_checkpoints_do_not_rewrite_the_xdmf_index(tmp_path, monkeypatch):
    """A checkpoint flushes the HDF5 file only; the restart lists the frames the index lacks.
    Rewriting the index at every checkpoint cost O(frames) each: a tester's run with a
    checkpoint and a frame every step took 146 s for 1200 frames against 14 s without."""
    pytest.importorskip("h5py")
    from ntncontact.io import vtk

    writes = []
    real = vtk.XdmfSeriesWriter._write_index
    monkeypatch.setattr(vtk.XdmfSeriesWriter, "_write_index",
                        lambda self: writes.append(1) or real(self))
    monkeypatch.setattr(vtk.XdmfSeriesWriter, "INDEX_INTERVAL", 1e9)  # first frame and end
    overrides = ["analysis.t_end=0.4", "analysis.checkpoint_interval=0.02",
                 'analysis.field_format="xdmf"']
    assert run_cli(EXAMPLES / "spinning_block.toml", tmp_path / "spin", overrides) == 0
    assert len(writes) == 2  # 20 checkpoints: 22 before
