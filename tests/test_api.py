"""The public Python API (docs/api.md): scenarios from files and dicts, run, read_results."""

from __future__ import annotations

import math
import sys
from pathlib import Path

import meshio
import numpy as np
import pandas as pd
import pytest

import ntncontact as ntc
from ntncontact.io.scenario import ScenarioError, read_toml, toml_value
from ntncontact.io.writers import CONTACT_COLUMNS, HISTORY_COLUMNS

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"
SPIN = EXAMPLES / "spinning_block.toml"
SHORT = {"analysis.t_end": 0.1, "analysis.output_interval": 0.04}


def test_dict_overrides_equal_the_set_strings_of_the_cli():
    by_dict = ntc.load_scenario(SPIN, {"analysis.mass": "lumped", "analysis.dt": 0.01,
                                       "bodies.0.initial.velocity": [2.0, -1]})
    by_strings = ntc.load_scenario(SPIN, ['analysis.mass="lumped"', "analysis.dt=0.01",
                                          "bodies.0.initial.velocity=[2.0, -1]"])
    assert by_dict.config == by_strings.config
    assert by_dict.config.analysis.mass == "lumped"
    assert by_dict.config.bodies[0].initial.velocity == (2.0, -1.0)


def test_a_scenario_from_a_plain_dict_is_the_same_as_from_its_file():
    data = read_toml(SPIN)
    assert ntc.scenario_from_dict(data, EXAMPLES).config == ntc.load_scenario(SPIN).config
    more = ntc.scenario_from_dict(data, EXAMPLES).with_overrides({"analysis.t_end": 0.5})
    assert more.config.analysis.t_end == 0.5 and more.overrides == ("analysis.t_end=0.5",)


def test_a_wrong_key_in_the_overrides_names_it():
    with pytest.raises(ScenarioError, match="analysis.no_such_key"):
        ntc.load_scenario(SPIN, {"analysis.no_such_key": 1})


@pytest.mark.parametrize("value", [True, 3, -2.5, 1e-300, "lumped", 'a "quoted" \\ word',
                                   "caf\u00e9 \x7f\n", [1.0, 2], {"a": 1, "b": [True, "x"]},
                                   math.inf, np.float32(0.5), np.int64(7)])
def test_python_values_become_toml_values_that_read_back_equal(value):
    assert tomllib.loads(f"v = {toml_value(value)}")["v"] == value


def test_a_value_toml_cannot_hold_is_refused():
    with pytest.raises(TypeError, match="cannot give"):
        toml_value(object())


def test_run_of_a_dict_names_the_function_that_takes_one():
    """A dict is not a scenario yet (its mesh files need a base folder): the error names
    scenario_from_dict, where it said "expected str, bytes or os.PathLike object"."""
    with pytest.raises(TypeError, match="scenario_from_dict"):
        ntc.run({"analysis": {"kind": "dynamic"}})


@pytest.fixture(scope="module")
def spin_results(tmp_path_factory):
    out = tmp_path_factory.mktemp("spin")
    return ntc.run(ntc.load_scenario(SPIN, SHORT), out=out), out


def test_run_returns_the_tables_summary_and_frames_of_the_folder(spin_results):
    results, out = spin_results
    assert isinstance(results.history, pd.DataFrame)
    assert list(results.history.columns[: len(HISTORY_COLUMNS)]) == list(HISTORY_COLUMNS)
    assert results.history["step"].tolist() == list(range(6))
    assert results.summary["status"] == "completed"
    assert results.times == pytest.approx([0.0, 0.04, 0.08, 0.1])
    # a free body: the mid-point rule keeps linear momentum to round-off
    p = results.history[["linear_momentum_x", "linear_momentum_y"]].to_numpy()
    assert np.max(np.abs(p - p[0])) <= 1e-12 * np.max(np.abs(p[0]))
    again = ntc.read_results(out)
    pd.testing.assert_frame_equal(again.history, results.history)
    assert again.summary == results.summary


def test_fields_gives_a_meshio_mesh_at_a_frame_time_and_refuses_other_times(spin_results):
    results, _ = spin_results
    mesh = results.fields(0.08)
    assert isinstance(mesh, meshio.Mesh)
    d = mesh.point_data["displacement"][:, :2]
    v = mesh.point_data["velocity"][:, :2]
    assert d.shape == (91, 2) and np.abs(d).max() > 0.05  # the block has moved
    assert v[:, 0].mean() == pytest.approx(1.0, rel=1e-9)  # mean velocity = initial (uniform mesh)
    with pytest.raises(ValueError, match="no field frame at t = 0.05; frames at 0, 0.04"):
        results.fields(0.05)


def test_read_results_drops_a_cut_off_last_line(tmp_path, spin_results):
    _, out = spin_results
    for name in ("history.csv", "contact.csv", "summary.json"):
        (tmp_path / name).write_bytes((out / name).read_bytes())
    text = (tmp_path / "history.csv").read_text()
    (tmp_path / "history.csv").write_text(text + "6,0.12,1.2")  # a killed run's half row
    results = ntc.read_results(tmp_path)
    assert len(results.history) == 6 and results.times == []
    assert list(results.contact.columns) == list(CONTACT_COLUMNS)


def test_read_results_of_a_folder_without_results_says_so(tmp_path):
    with pytest.raises(FileNotFoundError, match="not a results folder"):
        ntc.read_results(tmp_path)


def test_a_run_without_a_folder_keeps_the_same_results_in_memory_and_writes_nothing(
        spin_results, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    on_disk, _ = spin_results
    kept = ntc.run(ntc.load_scenario(SPIN, SHORT))  # out=None
    assert list(tmp_path.iterdir()) == []  # nothing written, not even here
    assert kept.directory is None
    pd.testing.assert_frame_equal(kept.history, on_disk.history, check_dtype=False)
    assert list(kept.contact.columns) == list(CONTACT_COLUMNS) and kept.contact.empty
    ignore = {"wall_time_s", "cpu_time_s"}
    assert {k: v for k, v in kept.summary.items() if k not in ignore} == \
        {k: v for k, v in on_disk.summary.items() if k not in ignore}
    assert kept.times == on_disk.times
    for t in kept.times:
        a, b = kept.fields(t), on_disk.fields(t)
        np.testing.assert_array_equal(a.points, b.points)
        assert sorted(a.point_data) == sorted(b.point_data)
        for name in a.point_data:
            np.testing.assert_array_equal(a.point_data[name], b.point_data[name])


def test_a_run_in_memory_keeps_contact_rows_like_contact_csv(tmp_path):
    rod = EXAMPLES / "rod_impact.toml"
    overrides = {"analysis.t_end": 0.15}
    on_disk = ntc.run(ntc.load_scenario(rod, overrides), out=tmp_path / "rod")
    kept = ntc.run(ntc.load_scenario(rod, overrides))
    assert len(kept.contact) == len(on_disk.contact) > 0
    pd.testing.assert_frame_equal(kept.contact, on_disk.contact, check_dtype=False)


def test_checkpoints_need_a_folder(tmp_path):
    with pytest.raises(ScenarioError, match="need a results folder"):
        ntc.run(ntc.load_scenario(SPIN, SHORT | {"analysis.checkpoint_interval": 0.05}))


def test_frames_fall_on_the_first_steps_past_each_multiple_of_the_output_interval():
    """An interval that is not a multiple of dt: frames at the first steps at or past 0.03,
    0.06, 0.09 (and the last step), as Abaqus and FEBio schedule them; counted from each
    frame's time the schedule drifted onto the dt grid (a tester's interval 0.3 at dt 0.25
    gave frames at 0, 0.5, 1.0)."""
    scenario = ntc.load_scenario(EXAMPLES / "spinning_block.toml",
                                 {"analysis.dt": 0.02, "analysis.t_end": 0.12,
                                  "analysis.output_interval": 0.03})
    times = ntc.run(scenario, out=None).times
    np.testing.assert_allclose(times, [0.0, 0.04, 0.06, 0.10, 0.12], atol=1e-12)


def test_a_scenario_dict_takes_numpy_numbers():
    """Studies build values with np.arange and np.linspace: an np.int64 mesh count was refused
    while an np.float64 modulus passed (a tester's case)."""
    scenario = ntc.load_scenario(EXAMPLES / "spinning_block.toml")
    raw = scenario.data | {}
    raw["bodies"] = [dict(b) for b in raw["bodies"]]
    raw["bodies"][0]["mesh"] = dict(raw["bodies"][0]["mesh"]) | {"nx": np.int64(3)}
    raw["bodies"][0]["material"] = dict(raw["bodies"][0]["material"]) | {"E": np.float64(50.0)}
    raw["bodies"][0]["initial"] = dict(raw["bodies"][0].get("initial", {})) | {
        "velocity": np.array([0.5, 0.0])}
    built = ntc.scenario_from_dict(raw, base_dir=EXAMPLES)
    assert built.config.bodies[0].mesh.nx == 3
    assert built.config.bodies[0].material.E == 50.0


def test_a_summary_that_is_not_json_is_named(tmp_path, capsys):
    """A tester's truncated summary.json: `compare` said "Invalid control character at: line 1
    column 17", naming no file."""
    from ntncontact.cli import main
    from ntncontact.io.run_folder import RunFolderError

    (tmp_path / "summary.json").write_text('{"status": "compl\x01', encoding="utf-8")
    (tmp_path / "history.csv").write_text("step,time,total_energy\n0,0.0,1.0\n")
    with pytest.raises(RunFolderError, match=r"summary\.json is not valid JSON"):
        ntc.read_results(tmp_path)
    assert main(["compare", str(tmp_path)]) == 1
    assert f"{tmp_path / 'summary.json'} is not valid JSON" in capsys.readouterr().err


def test_a_progress_that_is_not_a_function_is_refused_before_the_run(tmp_path):
    """A tester's progress=5 failed the run after its first step, naming no argument."""
    with pytest.raises(TypeError, match="progress must be a function"):
        ntc.run(ntc.load_scenario(SPIN, SHORT), tmp_path / "out", progress=5)
    assert not (tmp_path / "out").exists()


def test_an_out_that_is_a_file_is_refused_naming_it(tmp_path):
    """A tester's out="oblique.toml" gave a bare FileExistsError."""
    path = tmp_path / "oblique.toml"
    path.write_text("")
    with pytest.raises(ValueError, match="is a file: give the results folder"):
        ntc.run(ntc.load_scenario(SPIN, SHORT), path)
    assert path.read_text() == ""


def test_a_run_failing_after_its_folder_was_prepared_says_failed_and_frees_it(tmp_path,
                                                                              monkeypatch):
    """A set-up error once the writer exists (here attaching the checkpoints) left the folder's
    summary "running" and its lock held by the live process, which refused the next run into
    the folder as "in use by another run"; the command already wrote "failed" there."""
    from ntncontact.io import checkpoint
    from ntncontact.io.run_folder import LOCK_FILE

    def full_disk(*args, **kwargs):
        raise OSError("No space left on device")

    monkeypatch.setattr(checkpoint, "attach", full_disk)
    out = tmp_path / "spin"
    scenario = ntc.load_scenario(SPIN, SHORT)
    with pytest.raises(OSError, match="^No space left on device$"):
        ntc.run(scenario, out)
    summary = ntc.read_results(out).summary
    assert summary["status"] == "failed" and summary["error"] == "No space left on device"
    assert not (out / LOCK_FILE).exists()
    monkeypatch.undo()
    assert ntc.run(scenario, out, overwrite=True).summary["status"] == "completed"
