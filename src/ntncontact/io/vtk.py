"""VTU snapshots and their PVD time collection, written so an interrupted run stays readable.

Layout: ``DIR/<name>.pvd`` lists ``DIR/<name>/<name>_<step:05d>.vtu``. meshio writes and reads
the VTU files (binary, zlib-compressed; ~1.3-2.1 ms a ring-impact frame). What meshio lacks is
here: the PVD collection, and writing each file to a temporary name that is renamed into place
(:func:`~ntncontact.io.run_folder.replace_atomically`). The PVD is rewritten only after the VTU
it newly lists is complete, so every file a PVD names exists and parses.
"""

from __future__ import annotations

import copy
import errno
import os
import resource
import shutil
import time as _time
import xml.etree.ElementTree as ET
from collections.abc import Mapping, Sequence
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path
from xml.sax.saxutils import quoteattr

import meshio
import numpy as np
from numpy.typing import ArrayLike, NDArray

from .run_folder import RunFolderError, make_subfolder, replace_atomically

MEGABYTE = 1 << 20

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
        if array.dtype.kind not in "iuf":
            raise ValueError(f"{kind} data '{name}' has type {array.dtype}, which VTU cannot hold")
    return arrays


def frame_mesh(points: ArrayLike, cells: ArrayLike, point_data: Mapping[str, ArrayLike],
               cell_data: Mapping[str, ArrayLike], copy: bool = False) -> meshio.Mesh:
    """One output frame as a meshio Mesh: 2D points and vectors padded to 3D (ParaView's
    form), Q4 cells, the required point and cell data checked; ``copy``: every array its
    own copy (the caller may change its arrays while the frame is written)."""
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

    def own(values: NDArray) -> NDArray:
        padded = pad_to_3d(values)  # a new array already for 2-vectors
        return padded.copy() if copy and padded is values else padded

    return meshio.Mesh(own(xy), [("quad", quads.copy() if copy else quads)],
                       point_data={name: own(v) for name, v in pdata.items()},
                       cell_data={name: [own(v)] for name, v in cdata.items()})


class VtuSeriesWriter:
    """Write one VTU per output step and keep a PVD collection listing the finished ones.

    Call :meth:`write` once per output step with the mesh points (material positions X at the
    nodes, which move for ALE bodies), Q4 cells, point data (at least ``displacement`` = x - X and
    ``velocity``) and cell data (at least ``von_mises`` and ``body_id``). The frame is on disk
    and listed when :meth:`write` returns.

    ``background=True`` (the run folder's writer, ``ResultsDirectory``): :meth:`write` checks
    and copies the frame, then compresses and writes it on a thread of its own while the
    caller goes on with the next step; a frame is on disk and listed once the next
    :meth:`write`, :meth:`flush`, :attr:`entries` or :meth:`close` returns, and an error of
    its writing (a full disk) is raised there. At most one frame is in flight. Why: meshio's
    zlib compression, which releases the GIL, is most of a frame's time at scale: Hertz
    refined 8x (61 086 elements) 5.47 -> 4.25 s a step, for the frame's copy held meanwhile
    (0.9 KB an element; ``benchmarks/README.md``).
    """

    def __init__(self, directory: str | os.PathLike, name: str = "fields",
                 background: bool = False) -> None:
        self.directory = Path(directory)
        self.name = name
        self.pvd_path = self.directory / f"{name}.pvd"
        self.vtu_directory = self.directory / name
        self.directory.mkdir(parents=True, exist_ok=True)
        make_subfolder(self.vtu_directory)
        self._entries: list[tuple[float, str]] = []
        self._pool = ThreadPoolExecutor(1, thread_name_prefix="vtu") if background else None
        self._pending: Future | None = None

    def resume(self, step: int, entries: Sequence[Sequence]) -> None:
        """A restart after output step ``step``: list ``entries`` (time, relative path, as
        :attr:`entries` gave them at the checkpoint) and remove the frames of later steps, and
        those the entries do not list: an interrupted run's frame of its last step, off the
        schedule, when that step is the checkpoint's."""
        self._entries = [(float(time), str(relative)) for time, relative in entries]
        listed = {Path(relative).name for _, relative in self._entries}
        for frame in self.vtu_directory.glob(f"{self.name}_*.vtu"):
            number = frame.stem.rsplit("_", 1)[-1]
            if number.isdigit() and (int(number) > step or frame.name not in listed):
                frame.unlink()
        for leftover in self.vtu_directory.glob(f".{self.name}_*.tmp"):  # a kill mid-write
            leftover.unlink()
        replace_atomically(self.pvd_path, self._write_pvd)

    @property
    def entries(self) -> list[tuple[float, str]]:
        """(time, path relative to the PVD) of every snapshot written so far (on disk)."""
        self.flush()
        return list(self._entries)

    def flush(self) -> None:
        """Wait for the frame in flight (background mode); raise the error of its writing."""
        pending, self._pending = self._pending, None
        if pending is not None:
            pending.result()

    def close(self) -> None:
        """Write the frame in flight, then stop the writing thread (background mode)."""
        try:
            self.flush()
        finally:
            if self._pool is not None:
                self._pool.shutdown()
                self._pool = None

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
        (in background mode: once the frame before it is written, see the class)."""
        # the frame in flight is written first, then this one copied: one frame's copy held at
        # a time, not two
        self.flush()
        mesh = frame_mesh(points, cells, point_data, cell_data, copy=self._pool is not None)
        vtu_path = self.vtu_directory / f"{self.name}_{int(step):05d}.vtu"
        if self._pool is None:
            self._write_frame(int(step), float(time), vtu_path, mesh)
        else:
            self._pending = self._pool.submit(self._write_frame, int(step), float(time),
                                              vtu_path, mesh)
        return vtu_path

    def _write_frame(self, step: int, time: float, vtu_path: Path, mesh: meshio.Mesh) -> None:
        try:
            replace_atomically(vtu_path, lambda tmp: meshio.write(tmp, mesh, file_format="vtu"))
        except OSError as err:  # named by its step: in background mode it surfaces a step later
            last = (f"the last frame written is t = {self._entries[-1][0]:.6g} "
                    f"({self._entries[-1][1]})" if self._entries else "no frame was written")
            raise OSError(err.errno, f"{err.strerror or err} (the frame of step {step}, "
                          f"t = {time:.6g}; {last})", str(err.filename or vtu_path)) from err
        self._entries.append((time, f"{self.name}/{vtu_path.name}"))
        replace_atomically(self.pvd_path, self._write_pvd)

    def _write_pvd(self, path: Path) -> None:
        datasets = "".join(
            f'    <DataSet timestep="{time!r}" group="" part="0" file={quoteattr(relative)} />\n'
            for time, relative in self._entries)
        path.write_text("<?xml version='1.0' encoding='utf-8'?>\n"
                        '<VTKFile type="Collection" version="0.1" byte_order="LittleEndian">\n'
                        f"  <Collection>\n{datasets}  </Collection>\n</VTKFile>\n",
                        encoding="utf-8")


def frame_time_tolerance(times: ArrayLike) -> float:
    """How close to a frame's time a requested time must be to mean that frame: 1e-9 of the
    series' time scale (its span or its last time, whichever is larger). The one tolerance of
    every lookup of a frame by its time (the API's, the figures' and the validation's)."""
    times = np.asarray(times, dtype=float)
    return 1e-9 * max(times[-1] - times[0], abs(times[-1]))


def frame_index(times: ArrayLike, t: float) -> int | None:
    """The index of the frame written at time ``t`` (within :func:`frame_time_tolerance`),
    or None if there is none."""
    times = np.asarray(times, dtype=float)
    k = int(np.argmin(np.abs(times - t)))
    return k if abs(times[k] - t) <= frame_time_tolerance(times) else None


def read_pvd(pvd_path: str | os.PathLike) -> list[tuple[float, Path]]:
    """(time, absolute VTU path) of each dataset a PVD lists whose file exists, in time order."""
    pvd = Path(pvd_path)
    root = ET.parse(pvd).getroot()
    series = [(float(dataset.attrib.get("timestep", "nan")), path)
              for dataset in root.iter("DataSet")
              if (path := pvd.parent / dataset.attrib["file"]).is_file()]
    return sorted(series, key=lambda item: item[0])


def read_vtu(path: str | os.PathLike, time: float = float("nan")) -> VtuFrame:
    """Read a VTU of Q4 cells (as :class:`VtuSeriesWriter` writes) back into 2D arrays.

    Raises ``ValueError`` naming the file when it is not a readable VTU (corrupt, cut short)
    or holds no quadrilaterals.
    """
    return _frame_of(_read_vtu_mesh(path), time, Path(path))


def _read_vtu_mesh(path: str | os.PathLike) -> meshio.Mesh:
    """meshio's VTU reader, its errors as one ValueError that names the file (meshio.read()
    calls sys.exit on a corrupt file; the format reader raises ReadError, ParseError,
    zlib.error, ... with no file name, some with an empty message)."""
    try:
        return meshio.vtu.read(os.fspath(path))
    except OSError:
        raise
    except Exception as error:  # noqa: BLE001 (whatever a corrupt file makes the parser raise)
        raise ValueError(f"{path} is not a readable VTU file, corrupt or cut short "
                         f"({type(error).__name__}{': ' + str(error) if str(error) else ''})"
                         ) from None


def _frame_of(mesh: meshio.Mesh, time: float, path: Path) -> VtuFrame:
    """A meshio Mesh of Q4 cells as 2D arrays (the padding of :func:`pad_to_3d` undone)."""
    blocks = [block for block in mesh.cells if block.type == "quad"]
    if len(blocks) != len(mesh.cells) or not blocks:
        raise ValueError(f"{path} holds cells other than 4-node quadrilaterals")
    quads = np.vstack([block.data for block in blocks]).astype(np.int64)
    n_points, n_cells = len(mesh.points), len(quads)
    return VtuFrame(
        time=time,
        path=path,
        points=np.asarray(mesh.points[:, :2], dtype=float),
        cells=quads,
        point_data={name: _drop_z(v, n_points) for name, v in mesh.point_data.items()},
        cell_data={name: _drop_z(np.concatenate([np.asarray(b) for b in blocks_], axis=0),
                                 n_cells) for name, blocks_ in mesh.cell_data.items()},
    )


#: positions in VTK's symmetric 6-vector (XX, YY, ZZ, XY, YZ, XZ) of the 9 components of the
#: full tensor, row-major (XX, XY, XZ, YX, YY, YZ, ZX, ZY, ZZ)
SYMMETRIC6_TO_FULL9 = np.array([0, 3, 5, 3, 1, 4, 5, 4, 2])
#: positions in the row-major 9 of VTK's 6 (the inverse of SYMMETRIC6_TO_FULL9)
FULL9_TO_SYMMETRIC6 = np.array([0, 4, 8, 1, 5, 2])


def full_tensor(value: NDArray) -> NDArray:
    """An (n, 6) array (VTK's symmetric tensors) as (n, 9) row-major full tensors, which
    meshio labels XDMF ``Tensor``; other arrays unchanged. Why: meshio labels an (n, 6) array
    ``Tensor6``, whose XDMF order is XX, XY, XZ, YY, YZ, ZZ, not VTK's; ParaView's "XDMF
    Reader" (vtkXdmfReader) reorders Tensor6 by XDMF's rule and showed sigma_yy as sigma_xy,
    while its Xdmf3 readers pass the 6 values through in VTK's order, so no order of 6 is
    right for both. A full tensor reads the same in every reader."""
    return value[:, SYMMETRIC6_TO_FULL9] if value.ndim == 2 and value.shape[1] == 6 else value


def symmetric_tensor(value: NDArray) -> NDArray:
    """Undo :func:`full_tensor`: a symmetric (n, 9) array of an XDMF frame back in VTK's
    6-component layout, as the VTU frame holds it; other arrays unchanged (a non-symmetric
    (n, 9) one is not a tensor this package wrote as 6)."""
    array = np.asarray(value)
    if array.ndim == 2 and array.shape[1] == 9 and np.array_equal(
            array, array.reshape(-1, 3, 3).transpose(0, 2, 1).reshape(-1, 9)):
        return array[:, FULL9_TO_SYMMETRIC6]
    return array


def _drop_z(values: NDArray, count: int) -> NDArray:
    # Undo pad_to_3d: 3-vectors whose z is identically zero were 2D fields.
    array = np.asarray(values)
    if array.ndim == 2 and array.shape == (count, 3) and not np.any(array[:, 2]):
        return array[:, :2]
    return array


class XdmfSeriesWriter:
    """The frames of a run as one XDMF + HDF5 time series (``DIR/<name>.xdmf`` and
    ``DIR/<name>.h5``), written with meshio's TimeSeriesWriter: for runs with thousands of
    frames or 10^5 elements, where a VTU per frame is slow and large (benchmarks/README.md).

    Same :meth:`write` as :class:`VtuSeriesWriter`. The mesh is stored once, at the points of
    the first frame; since ALE bodies' points (material positions) move, every frame adds
    ``node_displacement``, the node's current position minus that stored point ("Warp By
    Vector" with it shows the deformed mesh). The XDMF index (XML, ~2 kB a frame) is rewritten
    atomically, with the HDF5 file flushed, at most every ``INDEX_INTERVAL`` seconds and at
    :meth:`close` (which every end of a run calls): rewriting it after every frame would cost
    O(frames^2) over a run of thousands; a killed run (SIGKILL) loses at most the frames of
    the last interval from the index, never the readability of the files.
    """

    INDEX_INTERVAL = 2.0

    def __init__(self, directory: str | os.PathLike, name: str = "fields") -> None:
        try:
            import h5py  # noqa: F401  (missing: refused before any file exists)
        except ImportError:
            raise RuntimeError("analysis.field_format = \"xdmf\" needs h5py: pip install "
                               "'ntncontact[xdmf]' (or h5py)") from None
        self.directory = Path(directory)
        self.directory.mkdir(parents=True, exist_ok=True)
        self.path = self.directory / f"{name}.xdmf"
        self._series = meshio.xdmf.TimeSeriesWriter(self.path)
        # meshio opens its HDF5 file in the working folder; ours goes beside the XDMF, opened
        # at the first frame or by resume (which reads the file a new one would truncate)
        self._series.h5_filename = os.fspath(self.directory / f"{name}.h5")
        self._series.h5_file = None
        self._first: tuple[NDArray, NDArray] | None = None
        self._entries: list[tuple[float, str]] = []
        self._indexed = -np.inf  # monotonic time of the last index written

    @property
    def entries(self) -> list[tuple[float, str]]:
        """(time, XDMF file name) of every frame written so far."""
        return list(self._entries)

    def write(self, step: int, time: float, points: ArrayLike, cells: ArrayLike,
              point_data: Mapping[str, ArrayLike], cell_data: Mapping[str, ArrayLike]) -> Path:
        """Append output step ``step`` at ``time``; returns the XDMF path."""
        mesh = frame_mesh(points, cells, point_data, cell_data)
        mesh.point_data = {name: full_tensor(v) for name, v in mesh.point_data.items()}
        mesh.cell_data = {name: [full_tensor(v) for v in blocks]
                          for name, blocks in mesh.cell_data.items()}
        self._check_room(mesh)
        if self._first is None:
            import h5py

            self._series.h5_file = h5py.File(self._series.h5_filename, "w")
            self._first = (mesh.points, mesh.cells[0].data)
            self._series.write_points_cells(mesh.points, [("quad", mesh.cells[0].data)])
        elif not np.array_equal(self._first[1], mesh.cells[0].data):
            raise ValueError("an XDMF series keeps one mesh: the cells changed")
        offset = mesh.points + mesh.point_data["displacement"] - self._first[0]
        self._series.write_data(float(time),
                                point_data=mesh.point_data | {"node_displacement": offset},
                                cell_data=dict(mesh.cell_data))
        self._entries.append((float(time), self.path.name))
        if _time.monotonic() - self._indexed >= self.INDEX_INTERVAL:
            self._write_index()
        return self.path

    def _check_room(self, mesh: meshio.Mesh) -> None:
        """Refuse a frame that may not fit on the disk or under the file-size limit, before
        HDF5 starts it: HDF5 does not recover from a write that fails (a full disk ended the
        run in a segmentation fault). The room asked is twice the frame's arrays and 64 kB
        besides (HDF5's metadata)."""
        frame = sum(np.asarray(a).nbytes for a in mesh.point_data.values())
        frame += sum(np.asarray(a).nbytes for blocks in mesh.cell_data.values() for a in blocks)
        if self._first is None:
            frame += mesh.points.nbytes + mesh.cells[0].data.nbytes
        needed = 2 * frame + 64 * 1024
        h5 = Path(self._series.h5_filename)
        limit = resource.getrlimit(resource.RLIMIT_FSIZE)[0]
        size = h5.stat().st_size if h5.exists() else 0
        if shutil.disk_usage(self.directory).free < needed or (
                limit != resource.RLIM_INFINITY and size + needed > limit):
            raise OSError(errno.ENOSPC, "no room for the next XDMF frame (HDF5 cannot recover "
                          f"from a write that fails; {needed / MEGABYTE:.1f} MB needed)",
                          str(h5))

    def _write_index(self) -> None:
        self._series.h5_file.flush()
        replace_atomically(self.path, ET.ElementTree(self._series.xdmf_file).write)
        self._indexed = _time.monotonic()

    def flush(self) -> None:
        """The HDF5 file flushed, so that the frames' arrays so far are on disk (a checkpoint
        calls it). The index is not rewritten here: a restart lists the frames it lacks
        (:meth:`_copy_frames`). Rewriting it at every checkpoint cost O(frames) each: a run
        checkpointing every step took 146 s for 1200 frames against 14 s."""
        if self._series.h5_file:
            self._series.h5_file.flush()

    def resume(self, step: int, entries: Sequence[Sequence]) -> None:
        """A restart: keep the series' first ``len(entries)`` frames (the checkpoint's; its
        :meth:`flush` put them in the index) and drop those written after it. The kept frames'
        arrays are copied into a new HDF5 file (a kill leaves the old one with frames the
        index does not list, and HDF5 cannot shrink a file), so a restart costs one read and
        write of the frames kept. The new file is written beside the old one, then the new
        index and the new file replace the old ones in that order: a kill at any point leaves
        a readable series (the old index over the old file; the new index over the old file,
        which holds its frames; or the new pair), and a later restart starts again from it.
        ``step`` is unused (the frames are counted, not numbered)."""
        import h5py

        kept = [(float(time), str(name)) for time, name in entries]
        if not kept:
            return
        h5 = Path(self._series.h5_filename)
        new = self.directory / f".{h5.name}.new"
        new.unlink(missing_ok=True)  # a restart killed while it copied
        if not h5.is_file():
            raise RunFolderError(f"{h5} is missing: cannot restart its XDMF series")
        try:
            self._copy_frames(h5, new, [time for time, _ in kept])
        except BaseException:
            if self._series.h5_file:
                self._series.h5_file.close()
            self._series.h5_file = None
            new.unlink(missing_ok=True)
            raise
        self._entries = kept
        self._series.h5_file.close()
        replace_atomically(self.path, ET.ElementTree(self._series.xdmf_file).write)
        os.replace(new, h5)
        self._series.h5_file = h5py.File(h5, "a")
        self._indexed = _time.monotonic()

    def _copy_frames(self, old: Path, new: Path, times: list[float]) -> None:
        """The index's mesh and its frames at ``times`` (the checkpoint's), with the arrays
        they name copied from ``old`` into the HDF5 file ``new``; meshio's writer then
        appends after them. Frames the index does not list yet (it is rewritten every
        INDEX_INTERVAL seconds) are listed after its last one (:func:`_frames_after`)."""
        frames = len(times)
        import h5py

        try:
            root = ET.parse(self.path).getroot()
        except (OSError, ET.ParseError) as err:
            raise RunFolderError(f"{self.path} cannot be read ({err}): cannot restart its "
                                 "XDMF series") from None
        # meshio's layout: the Domain holds the temporal collection (a grid a frame) and the
        # mesh grid that every frame includes
        domain = root.find("Domain")
        collection = None if domain is None else domain.find("Grid[@GridType='Collection']")
        mesh = None if domain is None else domain.find("Grid[@Name='mesh']")
        timed = [] if collection is None else collection.findall("Grid")
        if mesh is None or not timed:
            raise RunFolderError(f"{self.path} lists no frame: it is not the checkpointed "
                                 "run's series")
        h5_name = Path(self._series.h5_filename).name
        for grid in _frames_after(timed[-1], times[len(timed):], h5_name):
            collection.append(grid)
        for later in timed[frames:]:
            collection.remove(later)
        items = [item for item in root.iter("DataItem")
                 if item.text and item.text.strip().startswith(h5_name + ":/")]
        names = [item.text.strip().split(":/", 1)[1] for item in items]  # type: ignore[union-attr]
        self._series.h5_file = h5py.File(new, "w")
        try:
            with h5py.File(old, "r") as source:
                for item, name in zip(items, names, strict=True):
                    shape = tuple(int(n) for n in item.get("Dimensions", "").split())
                    if source[name].shape != shape:  # not the array this index entry names
                        raise KeyError(f"{name} has shape {source[name].shape}, not {shape}")
                    source.copy(source[name], self._series.h5_file, name)
        except (OSError, KeyError) as err:
            raise RunFolderError(f"{old} cannot be read ({err}): cannot restart its XDMF "
                                 "series") from None
        points, cells = (self._series.h5_file[_h5_dataset(mesh.find(f"{tag}/DataItem"))][()]
                         for tag in ("Geometry", "Topology"))
        self._first = (points, cells)
        self._series.xdmf_file, self._series.domain, self._series.collection = (
            root, domain, collection)
        self._series.has_mesh = True
        self._series.data_counter = 1 + max(int(n.removeprefix("data")) for n in names)

    def close(self) -> None:
        """Write the complete XDMF index and close the HDF5 file (once); no index without a
        frame (meshio cannot read a series of none)."""
        if self._series.h5_file:
            if self._entries:
                self._write_index()
            self._series.h5_file.close()


def _frames_after(last: ET.Element, times: Sequence[float], h5_name: str) -> list[ET.Element]:
    """The index grids of frames written after ``last`` at ``times``: meshio's writer gives
    every frame the same attributes in the same order, each array the next dataset number,
    so frame j after ``last`` names ``last``'s datasets shifted by j times their count."""
    items = list(last.iter("DataItem"))
    grids = []
    for j, time in enumerate(times, 1):
        grid = copy.deepcopy(last)
        grid.find("Time").set("Value", str(time))  # type: ignore[union-attr]
        for item in grid.iter("DataItem"):
            number = int(item.text.strip().split(":/data", 1)[1])  # type: ignore[union-attr]
            item.text = f"{h5_name}:/data{number + j * len(items)}"
        grids.append(grid)
    return grids


def _h5_dataset(item: ET.Element | None) -> str:
    """The HDF5 dataset a meshio DataItem names (``fields.h5:/data3`` -> ``data3``)."""
    if item is None or not item.text:
        raise RunFolderError("an XDMF index without its mesh: cannot restart its series")
    return item.text.strip().split(":/", 1)[1]


class XdmfSeries:
    """An XDMF time series written by :class:`XdmfSeriesWriter`, read back frame by frame with
    meshio's TimeSeriesReader as the frames of a VTU run: :meth:`mesh` gives the meshio Mesh
    that the VTU of the same frame holds (its points are the frame's material positions, the
    point data ``material_position``, and the writer's ``node_displacement`` is dropped).

    The XML index is parsed once; the HDF5 file is opened for each read and closed again, so
    that an instance holds no open file. Raises ``meshio.ReadError`` (or an XML
    ``ParseError``) if the index is not an XDMF time series.
    """

    def __init__(self, path: str | os.PathLike) -> None:
        self.path = Path(path)
        self._reader = meshio.xdmf.TimeSeriesReader(self.path)
        # the index is meshio's: one temporal grid per frame, its Time element first
        self.times = [float(grid.find("Time").attrib["Value"])  # type: ignore[union-attr]
                      for grid in self._reader.collection]
        self._points_cells: tuple[NDArray, list] | None = None

    def __len__(self) -> int:
        return len(self.times)

    def mesh(self, k: int) -> meshio.Mesh:
        """Frame k as the meshio Mesh of the VTU frame it replaces."""
        reader = self._reader
        try:
            if self._points_cells is None:
                self._points_cells = reader.read_points_cells()
            _, point_data, cell_data = reader.read_data(k)
        finally:  # meshio keeps the HDF5 files it opened until its context exits
            for h5 in reader.hdf5_files.values():
                h5.close()
            reader.hdf5_files.clear()
        stored, cells = self._points_cells
        offset = point_data.pop("node_displacement", None)
        points = point_data.get("material_position")
        if points is None:  # a series without the field: the node's position less d
            points = stored + offset - point_data["displacement"]
        return meshio.Mesh(np.array(points), cells,
                           point_data={name: symmetric_tensor(v) for name, v in point_data.items()},
                           cell_data={name: [symmetric_tensor(v) for v in blocks]
                                      for name, blocks in cell_data.items()})

    def frame(self, k: int) -> VtuFrame:
        """Frame k as :func:`read_vtu` reads the VTU frame it replaces."""
        return _frame_of(self.mesh(k), self.times[k], self.path)


@dataclass(frozen=True)
class XdmfStep:
    """Frame ``index`` of an XDMF series: the entry of a field series that a VTU path is in a
    VTU run (see :func:`read_series`)."""

    series: XdmfSeries
    index: int

    def __str__(self) -> str:
        return f"{self.series.path} (frame {self.index})"


#: A field series entry: a VTU file, or a frame of an XDMF series.
FrameSource = Path | XdmfStep


def find_field_series(directory: str | os.PathLike, name: str = "fields") -> Path | None:
    """The field series of a results folder: ``<name>.pvd`` (VTU frames) or else
    ``<name>.xdmf`` (``analysis.field_format = "xdmf"``); None if it has neither."""
    for suffix in (".pvd", ".xdmf"):
        path = Path(directory) / f"{name}{suffix}"
        if path.is_file():
            return path
    return None


def read_series(path: str | os.PathLike) -> list[tuple[float, FrameSource]]:
    """(time, frame source) of every frame of a PVD (the VTU files that exist) or of an XDMF
    series, in time order; read a frame with :func:`read_frame` or :func:`read_frame_mesh`."""
    if Path(path).suffix != ".xdmf":
        return list(read_pvd(path))
    series = _open_xdmf(path)  # its frames in the order written, which is time order
    return [(time, XdmfStep(series, k)) for k, time in enumerate(series.times)]


def _open_xdmf(path: str | os.PathLike) -> XdmfSeries:
    """:class:`XdmfSeries`, meshio's and the XML parser's errors as one ValueError naming the
    file."""
    try:
        return XdmfSeries(path)
    except (meshio.ReadError, ET.ParseError, KeyError, AttributeError) as error:
        raise ValueError(f"{path} is not a readable XDMF time series ({error!r})") from None


def read_frame(source: FrameSource, time: float = float("nan")) -> VtuFrame:
    """One frame of a field series (see :func:`read_series`) as 2D arrays."""
    if isinstance(source, XdmfStep):
        return source.series.frame(source.index)
    return read_vtu(source, time)


def read_frame_mesh(source: FrameSource) -> meshio.Mesh:
    """One frame of a field series as the meshio Mesh of its VTU (see :class:`XdmfSeries`)."""
    if isinstance(source, XdmfStep):
        return source.series.mesh(source.index)
    return _read_vtu_mesh(source)


def read_xdmf(path: str | os.PathLike) -> list[VtuFrame]:
    """Every frame of an XDMF series written by :class:`XdmfSeriesWriter`, in time order, as
    :func:`read_vtu` reads the VTU frames of the same run. ``path``: the ``.xdmf`` file or,
    as ``read_results`` takes it, the results folder (its ``fields.xdmf``). Raises
    FileNotFoundError without the file, ValueError naming it when it is not an XDMF series."""
    xdmf = Path(path)
    if xdmf.is_dir():
        xdmf = xdmf / "fields.xdmf"
        if not xdmf.is_file():
            vtu = " (its frames are VTU files: fields.pvd)" if (
                xdmf.parent / "fields.pvd").is_file() else ""
            raise FileNotFoundError(f"no fields.xdmf in results folder {path}{vtu}")
    elif not xdmf.is_file():
        raise FileNotFoundError(f"no XDMF series {path}")
    series = _open_xdmf(xdmf)
    return [series.frame(k) for k in range(len(series))]
