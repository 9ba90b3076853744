"""The VTU files written and read without meshio, and their background writer."""

import json

import meshio
import numpy as np
import pytest

from ntncontact.io import vtk, vtu
from ntncontact.io.vtk import VtuSeriesWriter, read_pvd, read_vtu
from ntncontact.io.writers import HISTORY_COLUMNS, ResultsDirectory


def unit_square_mesh() -> tuple[np.ndarray, np.ndarray]:
    points = np.array([[0.0, 0.0], [1.0, 0.0], [2.0, 0.0], [0.0, 1.0], [1.0, 1.0], [2.0, 1.0]])
    return points, np.array([[0, 1, 4, 3], [1, 2, 5, 4]])


def fields(n_points: int, n_cells: int, scale: float) -> tuple[dict, dict]:
    point_data = {"displacement": np.full((n_points, 2), scale),
                  "velocity": np.arange(2 * n_points, dtype=float).reshape(-1, 2)}
    cell_data = {"von_mises": np.linspace(0.0, scale, n_cells), "body_id": np.zeros(n_cells)}
    return point_data, cell_data


def history_row(step: int) -> dict:
    return {name: float(step) for name in HISTORY_COLUMNS} | {"step": step}


def ring_like_frame(n_points: int = 7000):
    """A frame large enough for several 32 kB compression blocks per array."""
    rng = np.random.default_rng(3)
    points = rng.random((n_points, 2))
    cells = rng.integers(0, n_points, size=(n_points // 2, 4))
    point_data = {"displacement": rng.normal(size=(n_points, 2)),
                  "velocity": rng.normal(size=(n_points, 2))}
    cell_data = {"von_mises": rng.random(len(cells)), "body_id": np.ones(len(cells))}
    return points, cells, point_data, cell_data


def _data_arrays(path):
    """(piece sizes, and name, type, components of every DataArray) of a VTU file: what a
    reader needs to know of its layout."""
    import xml.etree.ElementTree as ET

    root = ET.parse(path).getroot()
    pieces = [(p.get("NumberOfPoints"), p.get("NumberOfCells")) for p in root.iter("Piece")]
    arrays = [(a.get("Name"), a.get("type"), a.get("NumberOfComponents", "1"))
              for a in root.iter("DataArray")]
    return pieces, arrays


def test_files_read_back_as_what_meshio_writes(tmp_path):
    """meshio reads our file and its own (which wrote the earlier snapshots) into the same
    arrays, bit for bit, with the same DataArrays. (Not compared as bytes: meshio's layout and
    comment are its own and may change between its versions.)"""
    points, cells, point_data, cell_data = ring_like_frame()
    ours = VtuSeriesWriter(tmp_path).write(0, 0.0, points, cells, point_data, cell_data)
    pad = vtk.pad_to_3d
    theirs = tmp_path / "meshio.vtu"
    meshio.write(theirs, meshio.Mesh(pad(points), [("quad", cells)],
                                     point_data={k: pad(v) for k, v in point_data.items()},
                                     cell_data={k: [v] for k, v in cell_data.items()}),
                 file_format="vtu")
    assert _data_arrays(ours) == _data_arrays(theirs)
    a, b = meshio.read(ours), meshio.read(theirs)
    np.testing.assert_array_equal(a.points, b.points)
    np.testing.assert_array_equal(a.points[:, :2], points)
    assert [c.type for c in a.cells] == [c.type for c in b.cells] == ["quad"]
    np.testing.assert_array_equal(a.cells[0].data, cells)
    for name in point_data:
        np.testing.assert_array_equal(a.point_data[name], b.point_data[name])
    for name in cell_data:
        np.testing.assert_array_equal(a.cell_data[name][0], b.cell_data[name][0])
    assert b"<!--This file was created by ntncontact-->" in ours.read_bytes()
    longest = max(len(line) for line in ours.read_bytes().split(b"\n"))
    assert longest > 2 * vtu.BLOCK_SIZE  # several compression blocks


def test_read_vtu_decodes_its_own_files_without_meshio(tmp_path, monkeypatch):
    points, cells, point_data, cell_data = ring_like_frame()
    cell_data["body_id"] = np.arange(len(cells))  # an integer array too
    path = VtuSeriesWriter(tmp_path).write(3, 0.5, points, cells, point_data, cell_data)

    def no_meshio(path):
        raise AssertionError("this package's layout must not need meshio")

    monkeypatch.setattr(vtk, "_read_with_meshio", no_meshio)
    frame = read_vtu(path, time=0.5)
    np.testing.assert_array_equal(frame.points, points)
    np.testing.assert_array_equal(frame.cells, cells)
    for name, values in point_data.items():
        np.testing.assert_array_equal(frame.point_data[name], values)
    np.testing.assert_array_equal(frame.cell_data["von_mises"], cell_data["von_mises"])
    assert frame.cell_data["body_id"].dtype == np.int64
    np.testing.assert_array_equal(frame.cell_data["body_id"], cell_data["body_id"])
    frame.point_data["velocity"][0, 0] = 1.0  # writable, as meshio's arrays were


def test_read_vtu_leaves_other_layouts_to_meshio(tmp_path):
    points, cells = unit_square_mesh()
    path = tmp_path / "ascii.vtu"
    mesh = meshio.Mesh(vtk.pad_to_3d(points), [("quad", cells)],
                       point_data={"displacement": vtk.pad_to_3d(np.ones((6, 2)))})
    meshio.write(path, mesh, file_format="vtu", binary=False)  # (meshio prints a warning)
    with pytest.raises(vtu.UnsupportedVtu):
        vtu.read_vtu_arrays(path.read_bytes())
    frame = read_vtu(path)
    np.testing.assert_array_equal(frame.cells, cells)
    np.testing.assert_array_equal(frame.deformed_points, points + 1.0)


def test_values_vtu_cannot_hold_are_refused_at_write(tmp_path):
    points, cells = unit_square_mesh()
    point_data, cell_data = fields(len(points), len(cells), 1.0)
    cell_data["body_id"] = np.array(["a", "b"])
    with pytest.raises(ValueError, match="body_id"):
        VtuSeriesWriter(tmp_path, background=True).write(0, 0.0, points, cells, point_data,
                                                         cell_data)


def test_background_frames_are_complete_and_listed_after_close(tmp_path):
    """One frame at most is in flight: when write returns, every earlier frame is listed."""
    points, cells = unit_square_mesh()
    writer = VtuSeriesWriter(tmp_path, background=True)
    displacement = np.zeros((len(points), 2))
    for step in range(5):
        point_data, cell_data = fields(len(points), len(cells), 1.0)
        displacement[:] = step  # the caller reuses its arrays: the frame keeps a copy
        point_data["displacement"] = displacement
        writer.write(step, 0.1 * step, points, cells, point_data, cell_data)
        pvd = tmp_path / "fields.pvd"
        listed = len(read_pvd(pvd)) if pvd.is_file() else 0
        assert listed in (step, step + 1)  # the frames before this one, maybe this one
    writer.close()
    series = read_pvd(tmp_path / "fields.pvd")
    assert [t for t, _ in series] == [0.1 * k for k in range(5)]
    for step, (_, path) in enumerate(series):
        assert np.all(read_vtu(path).point_data["displacement"] == step)
    assert not list(tmp_path.rglob("*.tmp"))
    writer.close()  # closing twice is harmless


def test_a_frame_that_cannot_be_written_fails_the_run_and_keeps_the_others(tmp_path,
                                                                             monkeypatch):
    """The background write of frame 2 fails: the error reaches the time loop, the summary
    says failed, and the frames before it stay listed and readable."""
    encode = vtu.encode_vtu
    calls = []

    def failing_encode(layout):
        calls.append(1)
        if len(calls) == 3:
            raise OSError("No space left on device")
        return encode(layout)

    monkeypatch.setattr(vtk, "encode_vtu", failing_encode)
    points, cells = unit_square_mesh()
    with pytest.raises(OSError, match="No space"), ResultsDirectory(tmp_path) as out:
        for step in range(6):
            out.write_history(history_row(step))
            out.fields.write(step, float(step), points, cells, *fields(6, 2, 1.0))
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["status"] == "failed" and "No space" in summary["error"]
    series = read_pvd(tmp_path / "fields.pvd")
    assert [t for t, _ in series] == [0.0, 1.0]
    assert all(read_vtu(path).points.shape == (6, 2) for _, path in series)


def test_results_directory_waits_for_its_frames(tmp_path):
    points, cells = unit_square_mesh()
    with ResultsDirectory(tmp_path) as out:
        assert out.fields.background
        for step in range(3):
            out.fields.write(step, float(step), points, cells, *fields(6, 2, 1.0))
    assert len(read_pvd(tmp_path / "fields.pvd")) == 3
    assert json.loads((tmp_path / "summary.json").read_text())["status"] == "completed"


def test_an_interrupted_run_keeps_every_frame_it_handed_over(tmp_path):
    """Ctrl-C in the middle of a run: the frames given to the background writer before it are
    all on disk and listed, the summary says interrupted, and no temporary file is left."""
    from helpers import model_from_example

    from ntncontact.io.results import ResultWriter
    from ntncontact.simulation import Simulation

    class Interrupt:
        def on_step(self, model, record) -> None:
            if record.state.step == 7:
                raise KeyboardInterrupt

        def on_finish(self, status: str, error: str | None) -> None:
            pass

    model = model_from_example("spinning_block.toml", ["analysis.output_interval=0.02"])
    writer = ResultWriter(tmp_path, model)
    with pytest.raises(KeyboardInterrupt):
        Simulation(model, [writer, Interrupt()]).run()
    series = read_pvd(tmp_path / "fields.pvd")
    assert [round(t / 0.02) for t, _ in series] == list(range(8))  # steps 0..7
    assert all(read_vtu(path).cells.shape == (72, 4) for _, path in series)
    assert json.loads((tmp_path / "summary.json").read_text())["status"] == "interrupted"
    assert not list(tmp_path.rglob("*.tmp"))
