"""Round trips of the result writers: history/contact CSV, summary JSON and the VTU/PVD series."""

from __future__ import annotations

import csv
import json
import xml.etree.ElementTree as ET

import meshio
import numpy as np
import pytest

from ntncontact.io.vtk import VtuSeriesWriter, read_pvd, read_vtu
from ntncontact.io.writers import (
    CONTACT_COLUMNS,
    HISTORY_COLUMNS,
    ContactWriter,
    HistoryWriter,
    ResultsDirectory,
    SummaryWriter,
    read_csv_table,
    to_jsonable,
)

EXTRA = ("active_pairs", "frictional_dissipation", "contact_work")


def history_row(step: int, energy: float = 1.0) -> dict:
    row = {name: 0.1 * step + 1.0 / 3.0 for name in HISTORY_COLUMNS}
    row.update(step=step, newton_iterations=np.int64(4), total_energy=energy)
    row.update(active_pairs=step, frictional_dissipation=np.float64(2.0 / 7.0), contact_work=0.0)
    return row


def contact_pairs(n: int) -> dict:
    rng = np.random.default_rng(0)
    return {
        "interface": "ball_wall",
        "node_1": np.arange(n),
        "node_2": np.arange(n) + 100,
        "x": rng.random(n),
        "y": rng.random(n),
        "gap": -rng.random(n) * 1e-9,
        "gap_rate": rng.standard_normal(n),
        "normal_traction": rng.standard_normal(n),
        "tangential_traction": rng.standard_normal(n),
        "normal_force": rng.standard_normal(n),
        "tangential_force": rng.standard_normal(n),
        "status": np.array(["stick", "slip"] * (n // 2) + ["stick"] * (n % 2)),
        "end_gap": -rng.random(n) * 1e-9,
        "normal_x": np.zeros(n),
        "normal_y": -np.ones(n),
    }


def test_history_round_trip_exact(tmp_path):
    with HistoryWriter(tmp_path, EXTRA) as writer:
        rows = [history_row(k, energy=1.0 + k * np.pi * 1e-13) for k in range(3)]
        for row in rows:
            writer.write(row)
    with open(tmp_path / "history.csv", newline="") as handle:
        records = list(csv.DictReader(handle))
    assert list(records[0]) == list(HISTORY_COLUMNS) + list(EXTRA)
    assert len(records) == 3
    for row, record in zip(rows, records, strict=True):
        assert float(record["total_energy"]) == row["total_energy"]  # repr is lossless
        assert int(record["newton_iterations"]) == 4
        assert float(record["frictional_dissipation"]) == 2.0 / 7.0


def test_history_is_flushed_after_each_row(tmp_path):
    writer = HistoryWriter(tmp_path)
    writer.write({name: 1.5 for name in HISTORY_COLUMNS})
    # Read while the writer is still open, as after a crash.
    table = read_csv_table(tmp_path / "history.csv")
    assert table["time"].tolist() == [1.5]
    writer.close()


@pytest.mark.parametrize("change", ["missing", "unknown"])
def test_history_rejects_wrong_keys(tmp_path, change):
    writer = HistoryWriter(tmp_path, EXTRA)
    row = history_row(0)
    if change == "missing":
        del row["contact_work"]
    else:
        row["surprise"] = 1.0
    with pytest.raises(KeyError, match="contact_work" if change == "missing" else "surprise"):
        writer.write(row)
    writer.close()


def test_history_rejects_duplicate_extra_column(tmp_path):
    with pytest.raises(ValueError, match="time"):
        HistoryWriter(tmp_path, ("time",))


def test_contact_round_trip(tmp_path):
    pairs = contact_pairs(5)
    with ContactWriter(tmp_path, ("lambda_n",)) as writer:
        assert writer.write_step(3, 0.25, pairs | {"lambda_n": np.ones(5)}) == 5
        assert writer.write_step(4, 0.5, contact_pairs(0) | {"lambda_n": np.ones(0)}) == 0
        assert writer.write_step(5, 0.75, pairs | {"lambda_n": 2.0}) == 5
    with open(tmp_path / "contact.csv", newline="") as handle:
        records = list(csv.DictReader(handle))
    assert list(records[0]) == list(CONTACT_COLUMNS) + ["lambda_n"]
    assert len(records) == 10
    assert {r["step"] for r in records} == {"3", "5"}
    first = records[:5]
    assert [float(r["gap"]) for r in first] == pairs["gap"].tolist()
    assert [int(r["node_2"]) for r in first] == pairs["node_2"].tolist()
    assert [r["status"] for r in first] == pairs["status"].tolist()
    assert {r["interface"] for r in records} == {"ball_wall"}
    assert [float(r["lambda_n"]) for r in records[5:]] == [2.0] * 5


def test_contact_rejects_mismatched_lengths(tmp_path):
    pairs = contact_pairs(4)
    pairs["gap"] = np.zeros(3)
    with ContactWriter(tmp_path) as writer, pytest.raises(ValueError, match="gap"):
        writer.write_step(0, 0.0, pairs)


def test_contact_rejects_unknown_column(tmp_path):
    with ContactWriter(tmp_path) as writer, pytest.raises(KeyError, match="pressure"):
        writer.write_step(0, 0.0, contact_pairs(2) | {"pressure": np.zeros(2)})


def test_read_csv_table_drops_truncated_last_line(tmp_path):
    with HistoryWriter(tmp_path) as writer:
        for k in range(3):
            writer.write({name: float(k) for name in HISTORY_COLUMNS} | {"step": k})
    path = tmp_path / "history.csv"
    path.write_text(path.read_text() + "3,0.12")  # a row cut off mid-write
    table = read_csv_table(path)
    assert table["step"].dtype.kind == "i"
    assert table["step"].tolist() == [0, 1, 2]


def test_summary_atomic_and_numpy_converted(tmp_path):
    summary = SummaryWriter(tmp_path, scenario="ball", mesh_sizes=np.array([4, 8]))
    first = json.loads((tmp_path / "summary.json").read_text())
    assert first["status"] == "running" and first["error"] is None
    for step, energy in enumerate([2.0, 2.02, 1.99, 2.01]):
        summary.record_energy(step, np.float64(energy))
    summary.update(max_gap=np.float32(0.5), flags=np.array([True, False]), bad=np.nan)
    summary.finish("completed")
    data = json.loads((tmp_path / "summary.json").read_text())
    assert data["steps"] == 3
    assert data["energy_initial"] == 2.0 and data["energy_final"] == 2.01
    assert data["energy_max_relative_variation"] == pytest.approx(0.01, rel=1e-12)
    assert data["mesh_sizes"] == [4, 8] and data["flags"] == [True, False]
    assert data["max_gap"] == 0.5 and data["bad"] is None
    assert data["status"] == "completed" and data["wall_time_s"] >= 0.0
    assert not list(tmp_path.glob("*.tmp"))


def test_summary_failed_update_keeps_previous_file(tmp_path):
    summary = SummaryWriter(tmp_path, scenario="ball")
    with pytest.raises(TypeError):
        summary.update(mesh=object())
    data = json.loads((tmp_path / "summary.json").read_text())
    assert data["scenario"] == "ball" and "mesh" not in data
    summary.finish("completed")  # the rejected value was not kept
    assert json.loads((tmp_path / "summary.json").read_text())["status"] == "completed"


def test_summary_rejects_unknown_status(tmp_path):
    summary = SummaryWriter(tmp_path)
    with pytest.raises(ValueError, match="status"):
        summary.finish("done")


def test_to_jsonable_rejects_unknown_objects():
    with pytest.raises(TypeError, match="object"):
        to_jsonable({"x": object()})


def fields(n_points: int, n_cells: int, scale: float) -> tuple[dict, dict]:
    point_data = {
        "displacement": np.full((n_points, 2), scale),
        "velocity": np.arange(2 * n_points, dtype=float).reshape(-1, 2),
    }
    cell_data = {"von_mises": np.linspace(0.0, scale, n_cells), "body_id": np.zeros(n_cells, int)}
    return point_data, cell_data


def unit_square_mesh() -> tuple[np.ndarray, np.ndarray]:
    points = np.array([[0.0, 0.0], [1.0, 0.0], [2.0, 0.0], [0.0, 1.0], [1.0, 1.0], [2.0, 1.0]])
    cells = np.array([[0, 1, 4, 3], [1, 2, 5, 4]])
    return points, cells


def test_vtu_round_trip_and_pvd_valid_after_two_steps(tmp_path):
    points, cells = unit_square_mesh()
    writer = VtuSeriesWriter(tmp_path)
    for step, time in ((0, 0.0), (10, 0.5)):
        point_data, cell_data = fields(len(points), len(cells), scale=0.1 * (step + 1))
        writer.write(step, time, points + 0.01 * step, cells, point_data, cell_data)
        # After every step the PVD lists only complete files that meshio can parse.
        root = ET.parse(tmp_path / "fields.pvd").getroot()
        listed = [d.attrib["file"] for d in root.iter("DataSet")]
        assert len(listed) == (1 if step == 0 else 2)
        for relative in listed:
            mesh = meshio.read(tmp_path / relative)
            assert mesh.points.shape == (6, 3) and not np.any(mesh.points[:, 2])
    assert (tmp_path / "fields" / "fields_00000.vtu").is_file()
    series = read_pvd(tmp_path / "fields.pvd")
    assert [t for t, _ in series] == [0.0, 0.5]
    mesh = meshio.read(series[1][1])
    assert mesh.point_data["velocity"].shape == (6, 3)
    frame = read_vtu(series[1][1], time=0.5)
    np.testing.assert_array_equal(frame.points, points + 0.1)
    np.testing.assert_array_equal(frame.cells, cells)
    np.testing.assert_array_equal(frame.point_data["displacement"], np.full((6, 2), 1.1))
    np.testing.assert_array_equal(frame.cell_data["von_mises"], [0.0, 1.1])
    np.testing.assert_array_equal(frame.deformed_points, points + 0.1 + 1.1)
    assert not list(tmp_path.rglob("*.tmp"))


def test_pvd_quotes_series_names_and_keeps_exact_times(tmp_path):
    """The PVD text is formatted directly (not by ElementTree): a series name with XML
    special characters must still give a valid file, and times must survive to the bit."""
    points, cells = unit_square_mesh()
    name = 'run "a" & <b>'
    writer = VtuSeriesWriter(tmp_path, name=name)
    times = (0.0, 0.1 + 0.2, 1e-17)
    for step, time in enumerate(times):
        point_data, cell_data = fields(len(points), len(cells), scale=1.0)
        writer.write(step, time, points, cells, point_data, cell_data)
    series = read_pvd(tmp_path / f"{name}.pvd")
    assert [t for t, _ in series] == sorted(times)
    assert all(path.is_file() and path.parent.name == name for _, path in series)


def test_vtu_requires_contract_fields(tmp_path):
    points, cells = unit_square_mesh()
    point_data, cell_data = fields(len(points), len(cells), 1.0)
    del cell_data["body_id"]
    with pytest.raises(ValueError, match="body_id"):
        VtuSeriesWriter(tmp_path).write(0, 0.0, points, cells, point_data, cell_data)


def test_vtu_rejects_wrong_point_count(tmp_path):
    points, cells = unit_square_mesh()
    point_data, cell_data = fields(len(points) - 1, len(cells), 1.0)
    with pytest.raises(ValueError, match="displacement"):
        VtuSeriesWriter(tmp_path).write(0, 0.0, points, cells, point_data, cell_data)


def test_results_directory_marks_failure(tmp_path):
    with pytest.raises(RuntimeError), ResultsDirectory(tmp_path, EXTRA, run="x") as out:
        out.write_history(history_row(0, energy=1.0))
        out.write_history(history_row(1, energy=1.5))
        raise RuntimeError("Newton diverged")
    data = json.loads((tmp_path / "summary.json").read_text())
    assert data["status"] == "failed" and "Newton diverged" in data["error"]
    assert data["steps"] == 1 and data["energy_max_relative_variation"] == 0.5
    assert data["run"] == "x"
    assert len(read_csv_table(tmp_path / "history.csv")["step"]) == 2


def test_results_directory_marks_interrupt(tmp_path):
    with pytest.raises(KeyboardInterrupt), ResultsDirectory(tmp_path):
        raise KeyboardInterrupt
    data = json.loads((tmp_path / "summary.json").read_text())
    assert data["status"] == "interrupted"


def test_read_vtu_raises_on_corrupt_file(tmp_path):
    """meshio.read() would sys.exit here; callers need an exception they can catch, and one
    that names the file (meshio's ReadError has an empty message)."""
    bad = tmp_path / "half.vtu"
    bad.write_text("<VTKFile")
    with pytest.raises(ValueError, match=f"{bad} is not a readable VTU file"):
        read_vtu(bad)


def test_summary_is_rewritten_at_every_update_with_step_and_time(tmp_path):
    """No throttling: what a reader finds on disk is always the latest update (the summary
    never lags history.csv by more than the step being written)."""
    with ResultsDirectory(tmp_path, EXTRA, scenario="ball") as out:
        for step in range(4):
            row = history_row(step) | {"time": 0.25 * step}
            out.write_history(row, max_gap=0.5 * step)
            on_disk = json.loads((tmp_path / "summary.json").read_text())
            assert on_disk["status"] == "running" and on_disk["steps"] == step
            assert on_disk["time"] == 0.25 * step and on_disk["max_gap"] == 0.5 * step
            assert on_disk["scenario"] == "ball"
    assert json.loads((tmp_path / "summary.json").read_text())["status"] == "completed"
    assert not list(tmp_path.glob("*.tmp")) and not list(tmp_path.glob(".*.tmp"))


def test_result_files_get_the_permissions_open_would_give(tmp_path):
    """The temporary files behind the atomic rewrites are created 0600 by mkstemp: the results
    must still be readable as any file the user creates (umask applied)."""
    import os

    umask = os.umask(0o022)
    os.umask(umask)
    points, cells = unit_square_mesh()
    with ResultsDirectory(tmp_path, EXTRA) as out:
        out.write_history(history_row(0))
        out.fields.write(0, 0.0, points, cells, *fields(len(points), len(cells), 1.0))
        running = os.stat(tmp_path / "summary.json").st_mode & 0o777
    expected = 0o666 & ~umask
    assert running == expected
    for path in ("summary.json", "history.csv", "fields.pvd", "fields/fields_00000.vtu"):
        assert os.stat(tmp_path / path).st_mode & 0o777 == expected, path
