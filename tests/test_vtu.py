"""The VTU frames (written and read by meshio) and their PVD collection."""

import json
import xml.etree.ElementTree as ET
from pathlib import Path

import meshio
import numpy as np
import pytest

from ntncontact.io import vtk
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


def disk_full_at_frame(index: int, monkeypatch) -> None:
    """meshio's VTU writer fails on frame ``index`` (0-based) as a full disk would, after
    leaving a partial file (which must never get a frame's name)."""
    write = meshio.write
    calls = []

    def failing_write(path, mesh, **kwargs):
        calls.append(1)
        if len(calls) == index + 1:
            Path(path).write_text("<VTKFile")
            raise OSError("No space left on device")
        return write(path, mesh, **kwargs)

    monkeypatch.setattr(vtk.meshio, "write", failing_write)


def ring_like_frame(n_points: int = 7000):
    """A frame large enough for several 32 kB compression blocks per array."""
    rng = np.random.default_rng(3)
    points = rng.random((n_points, 2))
    cells = rng.integers(0, n_points, size=(n_points // 2, 4))
    point_data = {"displacement": rng.normal(size=(n_points, 2)),
                  "velocity": rng.normal(size=(n_points, 2))}
    cell_data = {"von_mises": rng.random(len(cells)), "body_id": np.ones(len(cells))}
    return points, cells, point_data, cell_data


def test_frames_are_meshio_files_with_the_contract_fields(tmp_path):
    """meshio writes the frames (binary, zlib-compressed), and meshio's own reader gets back
    every array, 2D vectors padded with a zero z for ParaView."""
    points, cells, point_data, cell_data = ring_like_frame()
    path = VtuSeriesWriter(tmp_path).write(0, 0.0, points, cells, point_data, cell_data)
    root = ET.parse(path).getroot()
    assert root.get("compressor") == "vtkZLibDataCompressor"
    assert {a.get("format") for a in root.iter("DataArray")} == {"binary"}
    mesh = meshio.vtu.read(path)
    np.testing.assert_array_equal(mesh.points, vtk.pad_to_3d(points))
    np.testing.assert_array_equal(mesh.cells_dict["quad"], cells)
    for name, values in point_data.items():
        np.testing.assert_array_equal(mesh.point_data[name], vtk.pad_to_3d(values))
    for name, values in cell_data.items():
        np.testing.assert_array_equal(mesh.cell_data[name][0], values)


def test_read_vtu_gives_back_what_was_written(tmp_path):
    points, cells, point_data, cell_data = ring_like_frame()
    cell_data["body_id"] = np.arange(len(cells))  # an integer array too
    path = VtuSeriesWriter(tmp_path).write(3, 0.5, points, cells, point_data, cell_data)
    frame = read_vtu(path, time=0.5)
    assert frame.time == 0.5 and frame.path == path
    np.testing.assert_array_equal(frame.points, points)
    np.testing.assert_array_equal(frame.cells, cells)
    for name, values in point_data.items():
        np.testing.assert_array_equal(frame.point_data[name], values)
    np.testing.assert_array_equal(frame.cell_data["von_mises"], cell_data["von_mises"])
    assert frame.cell_data["body_id"].dtype == np.int64
    np.testing.assert_array_equal(frame.cell_data["body_id"], cell_data["body_id"])
    frame.point_data["velocity"][0, 0] = 1.0  # writable


def test_read_vtu_reads_other_layouts_and_refuses_other_cells(tmp_path):
    points, cells = unit_square_mesh()
    path = tmp_path / "ascii.vtu"
    mesh = meshio.Mesh(vtk.pad_to_3d(points), [("quad", cells)],
                       point_data={"displacement": vtk.pad_to_3d(np.ones((6, 2)))})
    meshio.write(path, mesh, file_format="vtu", binary=False)  # (meshio prints a warning)
    frame = read_vtu(path)
    np.testing.assert_array_equal(frame.cells, cells)
    np.testing.assert_array_equal(frame.deformed_points, points + 1.0)
    triangles = tmp_path / "triangles.vtu"
    meshio.write(triangles, meshio.Mesh(vtk.pad_to_3d(points), [("triangle", cells[:, :3])]),
                 file_format="vtu")
    with pytest.raises(ValueError, match="quadrilaterals"):
        read_vtu(triangles)


def test_values_vtu_cannot_hold_are_refused_at_write(tmp_path):
    points, cells = unit_square_mesh()
    point_data, cell_data = fields(len(points), len(cells), 1.0)
    cell_data["body_id"] = np.array(["a", "b"])
    with pytest.raises(ValueError, match="body_id"):
        VtuSeriesWriter(tmp_path).write(0, 0.0, points, cells, point_data, cell_data)
    assert not (tmp_path / "fields.pvd").exists() and not list(tmp_path.rglob("*.vtu"))


def test_each_frame_is_on_disk_and_listed_when_write_returns(tmp_path):
    points, cells = unit_square_mesh()
    writer = VtuSeriesWriter(tmp_path)
    displacement = np.zeros((len(points), 2))
    for step in range(5):
        point_data, cell_data = fields(len(points), len(cells), 1.0)
        displacement[:] = step  # the caller reuses its arrays
        point_data["displacement"] = displacement
        writer.write(step, 0.1 * step, points, cells, point_data, cell_data)
        series = read_pvd(tmp_path / "fields.pvd")
        assert [t for t, _ in series] == [0.1 * k for k in range(step + 1)]
        assert np.all(read_vtu(series[-1][1]).point_data["displacement"] == step)
    assert not list(tmp_path.rglob("*.tmp"))


@pytest.mark.parametrize("frames", [6, 3], ids=["a later frame", "the last frame"])
def test_a_frame_that_cannot_be_written_fails_the_run_and_keeps_the_others(tmp_path,
                                                                             monkeypatch, frames):
    """Writing frame 2 fails (a full disk). The run folder writes a frame beside the next
    step, so the error reaches the time loop at the next frame's write, or, when it was the
    last frame, at closing the folder: either way the summary says failed (not completed),
    the frames before it stay listed and readable, and no temporary file is left."""
    disk_full_at_frame(2, monkeypatch)
    points, cells = unit_square_mesh()
    with pytest.raises(OSError, match="No space"), ResultsDirectory(tmp_path) as out:
        for step in range(frames):
            out.write_history(history_row(step))
            out.fields.write(step, float(step), points, cells, *fields(6, 2, 1.0))
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["status"] == "failed" and "No space" in summary["error"]
    series = read_pvd(tmp_path / "fields.pvd")
    assert [t for t, _ in series] == [0.0, 1.0]
    assert all(read_vtu(path).points.shape == (6, 2) for _, path in series)
    assert not list(tmp_path.rglob("*.tmp"))  # the partial file never got a frame's name


def test_an_interrupted_run_keeps_every_frame_it_wrote(tmp_path):
    """Ctrl-C in the middle of a run: the frames written before it are all on disk and
    listed, the summary says interrupted, and no temporary file is left."""
    from helpers import model_from_example

    from ntncontact.engine.simulation import Simulation
    from ntncontact.io.results import ResultWriter

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


def test_frames_written_in_the_background_are_the_synchronous_ones_byte_for_byte(tmp_path):
    """The run folder's writer compresses a frame beside the next step: its files are the
    same bytes as those written in the caller's thread, although the caller changes its
    arrays in place right after each write (a von Mises array of one column, which
    ``frame_mesh`` does not pad, included), and each frame is listed once the next write
    (or ``entries``) returns."""
    points, cells, point_data, cell_data = ring_like_frame()
    writers = {mode: VtuSeriesWriter(tmp_path / mode, background=mode == "background")
               for mode in ("synchronous", "background")}
    for step in range(4):
        for writer in writers.values():
            point_data["displacement"][:] = step
            cell_data["von_mises"][:] = 10.0 * step
            writer.write(step, 0.5 * step, points, cells, point_data, cell_data)
            point_data["displacement"][:] = -1.0  # the caller's next step, meanwhile
            cell_data["von_mises"][:] = -1.0
            assert len(writer.entries) == step + 1  # waits for the frame in flight
    for writer in writers.values():
        writer.close()
    for step in range(4):
        name = f"fields/fields_{step:05d}.vtu"
        background = (tmp_path / "background" / name).read_bytes()
        assert background == (tmp_path / "synchronous" / name).read_bytes()
        frame = read_vtu(tmp_path / "background" / name)
        assert np.all(frame.point_data["displacement"] == step)
        assert np.all(frame.cell_data["von_mises"] == 10.0 * step)
    assert (tmp_path / "background" / "fields.pvd").read_bytes() == \
        (tmp_path / "synchronous" / "fields.pvd").read_bytes()



@pytest.mark.parametrize("start, end, steps", [(0.0, 0.8, 320), (0.0, 2e-6, 400),
                                               (5.0, 5.0 + 1e-3, 10), (0.0, 3e4, 300)])
def test_a_frame_is_found_at_its_own_time_and_nowhere_between(start, end, steps):
    """One tolerance for every lookup of a frame by its time, relative to the series' time
    scale: each frame is found at its time given with round-off (t (1 + 1e-14), written as a
    sum of steps), and a time a hundredth of a step away from every frame finds none, on runs
    of microseconds, of hours, and of a short window late in a run."""
    times = np.linspace(start, end, steps + 1)
    step = (end - start) / steps
    for k in (0, 1, steps // 2, steps):
        assert vtk.frame_index(times, times[k] * (1 + 1e-14)) == k
        assert vtk.frame_index(times, start + step * k) == k
        assert vtk.frame_index(times, times[k] + 0.01 * step) is None
    assert vtk.frame_index(times, end + step) is None
    assert vtk.frame_index([0.0], 0.0) == 0  # one frame at t = 0: only exactly there
    assert vtk.frame_index([0.0], 1e-12) is None
