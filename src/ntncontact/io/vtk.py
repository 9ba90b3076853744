"""VTU snapshots and their PVD time collection, written so an interrupted run stays readable.

Layout: ``DIR/<name>.pvd`` lists ``DIR/<name>/<name>_<step:05d>.vtu``. Each VTU is written to a
temporary file and renamed into place; the PVD is rewritten (also atomically) only after the VTU
it newly lists is complete, so every file a PVD names exists and parses. The file format itself
is in :mod:`ntncontact.io.vtu`.
"""

from __future__ import annotations

import os
import xml.etree.ElementTree as ET
from collections.abc import Mapping, Sequence
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .vtu import VtuArrays, VtuLayout, encode_vtu, read_vtu_arrays, vtu_layout

REQUIRED_POINT_DATA = ("displacement", "velocity")
REQUIRED_CELL_DATA = ("von_mises", "body_id")


@dataclass(frozen=True)
class VtuFrame:
    """One snapshot read back from a VTU: 2D points, Q4 cells and their data."""

    time: float
    path: Path
    points: NDArray[np.float64]
    cells: NDArray[np.int64]
    point_data: dict[str, NDArray] = field(default_factory=dict)
    cell_data: dict[str, NDArray] = field(default_factory=dict)

    @property
    def deformed_points(self) -> NDArray[np.float64]:
        """Current positions x = X + displacement (the points are material positions X)."""
        return self.points + self.point_data["displacement"]


def pad_to_3d(values: ArrayLike) -> NDArray:
    """Pad (n, 2) vectors with a zero z component, as ParaView expects 3-vectors."""
    array = np.asarray(values)
    if array.ndim == 2 and array.shape[1] == 2:
        return np.hstack([array, np.zeros((array.shape[0], 1), dtype=array.dtype)])
    return array


def stack_bodies(
    points: Sequence[ArrayLike], cells: Sequence[ArrayLike]
) -> tuple[NDArray[np.float64], NDArray[np.int64], NDArray[np.int64]]:
    """Concatenate several bodies into one mesh: (points, cells with offsets, body_id per cell)."""
    if len(points) != len(cells):
        raise ValueError(f"got {len(points)} point arrays but {len(cells)} cell arrays")
    offsets = np.cumsum([0] + [len(np.asarray(p)) for p in points])
    stacked_cells = [
        np.asarray(c, dtype=np.int64).reshape(-1, 4) + offset
        for c, offset in zip(cells, offsets[:-1], strict=True)
    ]
    body_id = np.concatenate(
        [np.full(len(c), i, dtype=np.int64) for i, c in enumerate(stacked_cells)]
    )
    all_points = np.vstack([np.asarray(p, dtype=float).reshape(-1, 2) for p in points])
    return all_points, np.vstack(stacked_cells).reshape(-1, 4), body_id


def _xml_escape(text: str) -> str:
    """``text`` for a double-quoted XML attribute (xml.sax.saxutils would import urllib and
    ssl at start-up, ~0.05 s)."""
    return (text.replace("&", "&amp;").replace("<", "&lt;").replace(">", "&gt;")
            .replace('"', "&quot;"))


def _atomic_replace(tmp: Path, final: Path) -> None:
    # The rename is atomic: a run that fails, is killed or interrupted leaves either the old or
    # the complete new file, never a partial one. There is no fsync: like the CSV rows (only
    # flushed), the frames are protected against the run's own end, not against the machine
    # losing power; two fsyncs per frame were ~8 ms of its ~15 ms (0.3 s of the ring impact).
    os.replace(tmp, final)


def _check_data(kind: str, data: Mapping[str, ArrayLike], count: int, required: Sequence[str]):
    missing = [name for name in required if name not in data]
    if missing:
        raise ValueError(f"{kind} data is missing required fields {missing}")
    arrays = {name: np.asarray(values) for name, values in data.items()}
    for name, array in arrays.items():
        if array.ndim == 0 or array.shape[0] != count:
            raise ValueError(
                f"{kind} data '{name}' has shape {array.shape}, expected ({count}, ...)"
            )
    return arrays


class VtuSeriesWriter:
    """Write one VTU per output step and keep a PVD collection listing the finished ones.

    Call :meth:`write` once per output step with the mesh points (material positions X at the
    nodes, which move for ALE bodies), Q4 cells, point data (at least ``displacement`` = x - X and
    ``velocity``) and cell data (at least ``von_mises`` and ``body_id``).

    With ``background=True`` :meth:`write` checks and copies the arrays, and a worker thread
    compresses and writes the files (zlib releases the GIL, so this runs beside the caller's
    next steps). One frame at most is in flight: :meth:`write` first waits for the previous
    one, so when it returns every earlier frame is listed (what is on disk lags by one frame
    at most, for those who watch the PVD), and :meth:`close` waits for the last. A failed write
    is raised by the next :meth:`write` or by :meth:`close`; the frames before it stay listed.
    """

    def __init__(self, directory: str | os.PathLike, name: str = "fields",
                 background: bool = False) -> None:
        self.directory = Path(directory)
        self.name = name
        self.pvd_path = self.directory / f"{name}.pvd"
        self.vtu_directory = self.directory / name
        self.vtu_directory.mkdir(parents=True, exist_ok=True)
        self._entries: list[tuple[float, str]] = []
        self.background = background
        self._pool: ThreadPoolExecutor | None = None  # started at the first write
        self._in_flight: Future | None = None

    @property
    def entries(self) -> list[tuple[float, str]]:
        """(time, path relative to the PVD) of every snapshot written so far."""
        return list(self._entries)

    def write(
        self,
        step: int,
        time: float,
        points: ArrayLike,
        cells: ArrayLike,
        point_data: Mapping[str, ArrayLike],
        cell_data: Mapping[str, ArrayLike],
    ) -> Path:
        """Write output step ``step`` as a VTU, list it in the PVD and return the VTU path
        (in the background: where it will be once :meth:`close` returns)."""
        layout = self._layout(points, cells, point_data, cell_data)
        vtu_path = self.vtu_directory / f"{self.name}_{int(step):05d}.vtu"
        if not self.background:
            self._store(vtu_path, float(time), layout)
            return vtu_path
        self._wait()
        if self._pool is None:
            self._pool = ThreadPoolExecutor(1, thread_name_prefix="vtu-writer")
        self._in_flight = self._pool.submit(self._store, vtu_path, float(time), layout)
        return vtu_path

    def close(self) -> None:
        """Wait for the frame being written in the background (if any); raise its error."""
        try:
            self._wait()
        finally:
            if self._pool is not None:
                self._pool.shutdown(wait=True)
                self._pool = None

    def _wait(self) -> None:
        """Wait for the frame in flight (if any); raise its error."""
        future, self._in_flight = self._in_flight, None
        if future is not None and future.exception() is not None:
            raise future.exception()

    def _store(self, vtu_path: Path, time: float, layout: VtuLayout) -> None:
        tmp = vtu_path.with_name(vtu_path.name + ".tmp")
        tmp.write_bytes(encode_vtu(layout))
        _atomic_replace(tmp, vtu_path)
        self._entries.append((time, f"{self.name}/{vtu_path.name}"))
        self._write_pvd()

    @staticmethod
    def _layout(points, cells, point_data, cell_data) -> VtuLayout:
        xy = np.asarray(points, dtype=float)
        quads = np.asarray(cells, dtype=np.int64)
        if xy.ndim != 2 or xy.shape[1] != 2:
            raise ValueError(f"points must have shape (n, 2), got {xy.shape}")
        if quads.ndim != 2 or quads.shape[1] != 4:
            raise ValueError(f"cells must have shape (m, 4), got {quads.shape}")
        if quads.size and (quads.min() < 0 or quads.max() >= len(xy)):
            raise ValueError("cells refer to points that do not exist")
        pdata = _check_data("point", point_data, len(xy), REQUIRED_POINT_DATA)
        cdata = _check_data("cell", cell_data, len(quads), REQUIRED_CELL_DATA)
        return vtu_layout(pad_to_3d(xy), quads,
                          {name: pad_to_3d(v) for name, v in pdata.items()},
                          {name: pad_to_3d(v) for name, v in cdata.items()})

    def _write_pvd(self) -> None:
        # The text ElementTree wrote (same declaration and indentation), formatted directly:
        # building and indenting the tree anew for every frame cost ~4 ms by the 40th.
        datasets = "".join(
            f'    <DataSet timestep="{time!r}" group="" part="0" '
            f'file="{_xml_escape(relative)}" />\n' for time, relative in self._entries)
        text = ("<?xml version='1.0' encoding='utf-8'?>\n"
                '<VTKFile type="Collection" version="0.1" byte_order="LittleEndian">\n'
                f"  <Collection>\n{datasets}  </Collection>\n</VTKFile>")
        tmp = self.pvd_path.with_name(self.pvd_path.name + ".tmp")
        tmp.write_text(text, encoding="utf-8")
        _atomic_replace(tmp, self.pvd_path)


def read_pvd(pvd_path: str | os.PathLike) -> list[tuple[float, Path]]:
    """(time, absolute VTU path) of each dataset a PVD lists whose file exists, in time order."""
    pvd = Path(pvd_path)
    root = ET.parse(pvd).getroot()
    series = []
    for dataset in root.iter("DataSet"):
        path = pvd.parent / dataset.attrib["file"]
        if path.is_file():
            series.append((float(dataset.attrib.get("timestep", "nan")), path))
    return sorted(series, key=lambda item: item[0])


def read_vtu(path: str | os.PathLike, time: float = float("nan")) -> VtuFrame:
    """Read a VTU written by :class:`VtuSeriesWriter` back into 2D arrays.

    Other VTU layouts are read by meshio. Raises ``meshio.ReadError`` (or
    ``xml.etree.ElementTree.ParseError``) on a corrupt file.
    """
    try:
        arrays = read_vtu_arrays(Path(path).read_bytes())
    except OSError:
        raise
    except Exception:  # noqa: BLE001 - not this package's layout: meshio's reader decides
        arrays = _read_with_meshio(path)
    n_points, n_cells = len(arrays.points), len(arrays.quads)
    return VtuFrame(
        time=time,
        path=Path(path),
        points=np.asarray(arrays.points[:, :2], dtype=float),
        cells=arrays.quads,
        point_data={name: _drop_z(v, n_points) for name, v in arrays.point_data.items()},
        cell_data={name: _drop_z(v, n_cells) for name, v in arrays.cell_data.items()},
    )


def _read_with_meshio(path: str | os.PathLike) -> VtuArrays:
    import meshio  # ~0.06 s to import: only for files this package did not write

    # meshio.read() calls sys.exit on a corrupt file; the format reader raises ReadError instead.
    mesh = meshio.vtu.read(os.fspath(path))
    quads = np.vstack([block.data for block in mesh.cells if block.type == "quad"])
    cell_data = {name: np.concatenate([np.asarray(b) for b in blocks], axis=0)
                 for name, blocks in mesh.cell_data.items()}
    return VtuArrays(mesh.points, quads.astype(np.int64), dict(mesh.point_data), cell_data)


def _drop_z(values: NDArray, count: int) -> NDArray:
    # Undo pad_to_3d: 3-vectors whose z is identically zero were 2D fields.
    array = np.asarray(values)
    if array.ndim == 2 and array.shape == (count, 3) and not np.any(array[:, 2]):
        return array[:, :2]
    return array
