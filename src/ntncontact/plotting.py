"""Figures made from a results folder alone (history.csv, contact.csv, fields.pvd + VTUs).

matplotlib is imported inside the functions and drives an Agg canvas directly (no pyplot), so
importing this module costs nothing and never changes the user's global backend. Every function
tolerates a partially written run: truncated CSV lines are dropped and only the VTU files the PVD
lists (and that parse) are used.
"""

from __future__ import annotations

import contextlib
import io
import os
import warnings
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from ntncontact.io.vtk import VtuFrame, read_pvd, read_vtu
from ntncontact.io.writers import CONTACT_FILE, HISTORY_FILE, read_csv_table

if TYPE_CHECKING:
    from matplotlib.figure import Figure

PVD_FILE = "fields.pvd"
MAX_PANELS = 6
DPI = 110
FIELD_CMAP = "viridis"  # colour map of the mesh fields (and of the GIF palette)


class ResultsNotFoundError(FileNotFoundError):
    """A results folder (or one of its files) is missing or holds no data yet."""


#: A figure's layout: rows and columns of axes, size (inches), and a colour bar axes or not.
FigureShape = tuple[int, int, tuple[float, float], bool]
HISTORY_SHAPE: FigureShape = (2, 1, (7.0, 6.0), False)  # energies, momenta, tractions
PAIR_SHAPE: FigureShape = (3, 1, (7.0, 8.0), False)
ANIMATION_SHAPE: FigureShape = (1, 1, (6.0, 4.5), True)
_TICKS_AHEAD = 11  # major ticks per axis made ahead: the axes here draw 6 to 11
_PREPARED: dict[FigureShape, list[tuple[Figure, NDArray, Any]]] = {}


def panels_shape(count: int) -> FigureShape:
    """The shape of :func:`plot_deformed` for ``count`` meshes: up to 3 per row."""
    ncols = min(3, count)
    nrows = -(-count // ncols)
    return nrows, ncols, (3.6 * ncols + 1.0, 3.2 * nrows), True


def _new_figure(nrows: int = 1, ncols: int = 1,
                size: tuple[float, float] = (7.0, 4.5)) -> tuple[Figure, NDArray]:
    """A figure and its grid of axes (validation.py's figures too)."""
    fig, axes, _ = _figure_of((nrows, ncols, size, False))
    return fig, axes


def _figure_of(shape: FigureShape) -> tuple[Figure, NDArray, Any]:
    """A figure of this shape, its grid of axes and its colour bar axes (None without): one
    that :func:`prepare_figures` made if there is one."""
    prepared = _PREPARED.get(shape)
    return prepared.pop() if prepared else _build_figure(*shape)


def _build_figure(nrows: int, ncols: int, size: tuple[float, float],
                  colorbar: bool) -> tuple[Figure, NDArray, Any]:
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    # No layout engine: constrained layout measured every tick label of every axes twice per
    # save (~60 % of a figure's time); _fit_layout places the axes from a cheap measure instead.
    fig = Figure(figsize=size, dpi=DPI)
    FigureCanvasAgg(fig)
    axes = fig.subplots(nrows, ncols, squeeze=False)
    cax = fig.add_axes((0.9, 0.1, 0.02, 0.8)) if colorbar else None  # placed by _fit_layout
    return fig, axes, cax


def prepare_figures(shapes: Sequence[FigureShape]) -> None:
    """Make empty figures of these shapes now, for the next figures of those shapes this
    process draws. A figure's axes and the tick objects they will draw (each tick two
    markers, a grid line and two labels) were ~20 % of a figure's time, which a figure worker
    pays this way while the run is still going. The figures drawn are the same."""
    for shape in shapes:
        fig, axes, cax = _build_figure(*shape)
        for ax in [*axes.flat, *([cax] if cax is not None else [])]:
            ax.xaxis.get_major_ticks(_TICKS_AHEAD)
            ax.yaxis.get_major_ticks(_TICKS_AHEAD)
        fig.canvas.get_renderer()
        _PREPARED.setdefault(shape, []).append((fig, axes, cax))


_PAD = 4.0 / 72.0  # inches between decorations and the figure edge or the next axes
_CBAR_ASPECT = 20.0  # colour bar length / width, as matplotlib's default


def _tick_labels(axis: Any) -> tuple[list[str], str, float]:
    """The major tick labels ``axis`` will draw in its current view, its offset text, and the
    gap from the last tick to the view's upper end (fraction of the view)."""
    low, high = sorted(axis.get_view_interval())
    span = max(high - low, 1e-300)
    locs = [v for v in axis.get_majorticklocs() if low - 1e-9 * span <= v <= high + 1e-9 * span]
    formatter = axis.get_major_formatter()
    gap = (high - max(locs)) / span if locs else 1.0
    return formatter.format_ticks(locs), formatter.get_offset(), gap


class _TextSizes:
    """Text sizes (inches) from the figure's renderer; each string is measured once, as the
    panels of a grid (and the second layout pass) repeat the same tick labels."""

    def __init__(self, fig: Figure) -> None:
        self.renderer = fig.canvas.get_renderer()
        self._known: dict[tuple[str, Any], tuple[float, float]] = {}

    def _size(self, text: str, size: Any) -> tuple[float, float]:
        key = (text, size)
        if key not in self._known:
            from matplotlib.font_manager import FontProperties

            w, h, _ = self.renderer.get_text_width_height_descent(
                text, FontProperties(size=size), ismath="$" in text)
            self._known[key] = (w / DPI, h / DPI)
        return self._known[key]

    def width(self, texts: Sequence[str], size: Any) -> float:
        return max((self._size(t, size)[0] for t in texts if t), default=0.0)

    def line_height(self, size: Any) -> float:
        return self._size("lp", size)[1]

    def artist(self, text: Any) -> tuple[float, float]:
        """Width and height of a Text artist, zero if it is empty or hidden."""
        if not text.get_visible() or not text.get_text():
            return 0.0, 0.0
        box = text.get_window_extent(self.renderer)
        return box.width / DPI, box.height / DPI


def _outer_sizes(ax: Any, sizes: _TextSizes) -> tuple[float, float, float, float]:
    """Inches the tick labels, axis labels, offset texts and title of ``ax`` reach beyond its
    box: (left, bottom, right, top)."""
    from matplotlib import rcParams

    ax.apply_aspect()  # an equal-aspect box is shrunk: its tick spacing follows that size
    box = ax.get_position().transformed(ax.figure.dpi_scale_trans)
    xlabels, xoffset, xgap = _tick_labels(ax.xaxis)
    ylabels, yoffset, ygap = _tick_labels(ax.yaxis)
    xw = sizes.width(xlabels[-1:], rcParams["xtick.labelsize"])
    xh = sizes.line_height(rcParams["xtick.labelsize"])
    yw = sizes.width(ylabels, rcParams["ytick.labelsize"])
    yh = sizes.line_height(rcParams["ytick.labelsize"])
    xtick = (rcParams["xtick.major.size"] + rcParams["xtick.major.pad"]) / 72.0
    ytick = (rcParams["ytick.major.size"] + rcParams["ytick.major.pad"]) / 72.0
    labelpad = rcParams["axes.labelpad"] / 72.0
    ylabel_w = sizes.artist(ax.yaxis.label)[0]
    xlabel_h = sizes.artist(ax.xaxis.label)[1]
    title_h = sizes.artist(ax.title)[1]
    left = ytick + yw + (labelpad + ylabel_w if ylabel_w else 0.0)
    offset = xh + 3.0 / 72.0 if xoffset else 0.0  # under the tick labels, 3 pt apart
    bottom = xtick + xh + (labelpad + xlabel_h if xlabel_h else 0.0) + offset
    # the last tick labels are centred on their ticks: only what is beyond the box counts
    top = max(yh / 2 - ygap * box.height, yh + _PAD if yoffset else 0.0, 0.0)
    if title_h:
        top += rcParams["axes.titlepad"] / 72.0 + title_h
        # titles are placed with y=1 (see _title): lift one above a y offset text ourselves
        ax.title.set_y(1.0 + (yh + _PAD) / box.height if yoffset else 1.0)
    return left, bottom, max(xw / 2 - xgap * box.width, 0.0), top


def _fit_layout(fig: Figure, axes: NDArray, cax: Any = None) -> None:
    """Place the grid ``axes`` (and a colour bar ``cax`` right of them, as tall as the grid)
    so that their decorations just fit, like constrained layout but measured once per axes."""
    from matplotlib import rcParams

    sizes = _TextSizes(fig)
    nrows, ncols = axes.shape
    width, height = fig.get_size_inches()
    for _ in range(2):  # the ticks depend on the axes' size, which depends on the margins
        outer = np.zeros((nrows, ncols, 4))
        for (row, col), ax in np.ndenumerate(axes):
            if ax.get_visible():
                outer[row, col] = _outer_sizes(ax, sizes)
        left, bottom, right, top = (outer[..., k] for k in range(4))
        margin_left = left.max() + _PAD
        column_gap = right.max() + left.max() + 2 * _PAD
        margin_top = top[0].max() + _PAD
        margin_bottom = bottom.max(axis=1)[-1] + _PAD
        row_gap = max((bottom[r].max() + top[r + 1].max() for r in range(nrows - 1)),
                      default=0.0) + 2 * _PAD
        margin_right = right.max() + _PAD
        if cax is not None:
            bar_height = height - margin_top - margin_bottom
            bar_width = bar_height / _CBAR_ASPECT
            labels = _tick_labels(cax.yaxis)[0]
            tick_w = sizes.width(labels, rcParams["ytick.labelsize"])
            label_w = sizes.artist(cax.yaxis.label)[0]
            decorations = ((rcParams["ytick.major.size"] + rcParams["ytick.major.pad"]) / 72.0
                           + tick_w + rcParams["axes.labelpad"] / 72.0 + label_w)
            bar_left = width - _PAD - decorations - bar_width
            margin_right = width - bar_left + right.max() + 4 * _PAD
            cax.set_position((bar_left / width, margin_bottom / height, bar_width / width,
                              bar_height / height))
        cell_w = (width - margin_left - margin_right - (ncols - 1) * column_gap) / ncols
        cell_h = (height - margin_top - margin_bottom - (nrows - 1) * row_gap) / nrows
        fig.subplots_adjust(left=margin_left / width, right=1.0 - margin_right / width,
                            bottom=margin_bottom / height, top=1.0 - margin_top / height,
                            wspace=column_gap / cell_w, hspace=row_gap / cell_h)


def _title(ax: Any, text: str, **kwargs: Any) -> None:
    # y=1 turns off matplotlib's title placement, which measured all tick labels of the axes
    # at every draw (~15 % of a mesh figure); _outer_sizes makes room for the title instead.
    ax.set_title(text, y=1.0, **kwargs)


def _save(fig: Figure, path: Path, axes: NDArray | None = None, cax: Any = None) -> Path:
    if axes is not None:
        _fit_layout(fig, axes, cax)
    png = Path(path).suffix.lower() == ".png"
    # zlib level 3 instead of 6: ~35 % faster to write, files ~10 % larger
    fig.savefig(path, **({"pil_kwargs": {"compress_level": 3}} if png else {}))
    return path


def warm_up() -> None:
    """Draw and encode a small figure of the kinds made here, into memory: a process's first
    figure pays ~0.15-0.2 s of one-off work (fonts, colour maps, text layout, PNG encoder),
    which figure workers do this way while the run they will plot is still going."""
    from matplotlib.collections import PolyCollection

    fig, axes, cax = _build_figure(1, 1, (3.0, 2.0), True)
    ax = axes[0, 0]
    ax.plot([0.0, 1.0], [0.0, 1.0], "o-", ms=3, label="a")
    ax.legend(loc="best", fontsize="small")
    square = np.array([[[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]]])
    collection = PolyCollection(square, array=np.array([1.0]), cmap=FIELD_CMAP,
                                edgecolors=(0.0, 0.0, 0.0, 0.35), linewidths=0.3)
    ax.add_collection(collection)
    _title(ax, "t = 0", fontsize="small")
    fig.colorbar(collection, cax=cax, label="field")
    _fit_layout(fig, axes, cax)
    fig.savefig(io.BytesIO(), format="png", pil_kwargs={"compress_level": 3})


def _load_table(directory: Path, name: str) -> dict[str, NDArray]:
    path = directory / name
    if not path.is_file():
        raise ResultsNotFoundError(f"no {name} in results folder {directory}")
    try:
        table = read_csv_table(path)
    except ValueError as error:
        raise ResultsNotFoundError(f"{path} is empty: {error}") from error
    if not table or len(next(iter(table.values()))) == 0:
        raise ResultsNotFoundError(f"{path} has no data rows yet")
    return table


def plot_energies(directory: str | os.PathLike, path: str | os.PathLike | None = None) -> Path:
    """Kinetic, strain and total energy and the work of the loads and contact against time;
    below, the energy balance error (E - E0 - W_ext - W_contact) / S, S the largest energy of
    the ledger (``diagnostics.energy_balance``): it stays small with loads, where E - E0 does
    not."""
    from ntncontact.diagnostics import energy_balance

    folder = Path(directory)
    history = _load_table(folder, HISTORY_FILE)
    time, total = history["time"], history["total_energy"]
    fig, axes, _ = _figure_of(HISTORY_SHAPE)
    top, bottom = axes[0, 0], axes[1, 0]
    for column in ("kinetic_energy", "strain_energy", "total_energy"):
        top.plot(time, history[column], label=column.replace("_", " "))
    works = {}
    for column in ("external_work", "contact_work", "frictional_dissipation"):
        if column in history and history[column].dtype.kind in "iuf":
            works[column] = history[column]
            top.plot(time, history[column], "--", label=column.replace("_", " "))
    top.set_ylabel("energy")
    top.legend(loc="best", fontsize="small")
    error, scale = energy_balance(total, works.get("external_work", 0.0),
                                  works.get("contact_work", 0.0))
    bottom.plot(time, error / scale if scale > 0 else error, color="k")
    bottom.set_ylabel("(E - E0 - W_ext - W_c) / max|E, W|" if scale > 0
                      else "E - E0 - W_ext - W_c")
    bottom.set_xlabel("time")
    for ax in (top, bottom):
        ax.grid(True, alpha=0.3)
    return _save(fig, Path(path) if path else folder / "energies.png", axes)


def plot_momenta(directory: str | os.PathLike, path: str | os.PathLike | None = None) -> Path:
    """Linear momentum components and angular momentum against time."""
    folder = Path(directory)
    history = _load_table(folder, HISTORY_FILE)
    fig, axes, _ = _figure_of(HISTORY_SHAPE)
    top, bottom = axes[0, 0], axes[1, 0]
    top.plot(history["time"], history["linear_momentum_x"], label="linear momentum x")
    top.plot(history["time"], history["linear_momentum_y"], label="linear momentum y")
    top.set_ylabel("linear momentum")
    top.legend(loc="best", fontsize="small")
    bottom.plot(history["time"], history["angular_momentum"], color="C2")
    bottom.set_ylabel("angular momentum")
    bottom.set_xlabel("time")
    for ax in (top, bottom):
        ax.grid(True, alpha=0.3)
    return _save(fig, Path(path) if path else folder / "momenta.png", axes)


def _series(directory: Path) -> list[tuple[float, Path]]:
    pvd = directory / PVD_FILE
    if not pvd.is_file():
        raise ResultsNotFoundError(f"no {PVD_FILE} in results folder {directory}")
    series = read_pvd(pvd)
    if not series:
        raise ResultsNotFoundError(f"{pvd} lists no existing VTU files")
    return series


def _evenly_spaced(count: int, wanted: int) -> list[int]:
    return sorted({int(i) for i in np.round(np.linspace(0, count - 1, min(count, wanted)))})


def _nearest(available: NDArray, targets: Sequence[float]) -> list[int]:
    picks = [int(np.argmin(np.abs(available - t))) for t in targets]
    return list(dict.fromkeys(picks))  # unique, in the requested order


def load_frames(
    directory: str | os.PathLike, times: Sequence[float] | None = None, max_frames: int = 6
) -> list[VtuFrame]:
    """Snapshots nearest to ``times``, or up to ``max_frames`` evenly spaced; bad files skipped."""
    series = _series(Path(directory))
    available = np.array([t for t, _ in series])
    if times is None:
        indices = _evenly_spaced(len(series), max_frames)
    else:
        indices = _nearest(available, times)[:max_frames]
    frames = []
    for i in indices:
        time, vtu = series[i]
        try:
            frames.append(_read_frame(vtu, time))
        except Exception as error:  # a corrupt file (any parser error) must not stop the plot
            warnings.warn(f"skipping unreadable {vtu}: {error}", stacklevel=2)
    if not frames:
        raise ResultsNotFoundError(f"no readable VTU files in results folder {directory}")
    return frames


# VTU path -> ((mtime, size) when read, frame): what prefetch_frames read in this process
_READ_AHEAD: dict[Path, tuple[tuple[int, int] | None, VtuFrame]] = {}
READ_AHEAD_BYTES = 256 * 2**20  # frames kept at most per process (the ring's 41: ~2 MB)
_MESHES: dict[Path, tuple[VtuFrame, list]] = {}  # VTU path -> (frame, its cells' paths)


def prefetch_frames(directory: str | os.PathLike, meshes: bool = False) -> int:
    """Read the frames the folder's PVD lists that this process has not read yet, and keep
    them for :func:`load_frames`: a figure worker reads the frames while the run writes
    them (~1 ms each) instead of all of them after it (the GIF and the pair history read
    every frame). Up to :data:`READ_AHEAD_BYTES` (the others are read when drawn).
    ``meshes``: also make the paths of the frames' deformed cells (for the animation).
    Returns how many it read."""
    pvd = Path(directory) / PVD_FILE
    if not pvd.is_file():
        return 0
    count, kept = 0, sum(_frame_bytes(frame) for _, frame in _READ_AHEAD.values())
    for time, vtu in read_pvd(pvd):
        if kept > READ_AHEAD_BYTES:
            break
        if _read_ahead(vtu, time) is None:
            stamp = _stamp(vtu)  # before reading: a file replaced meanwhile is read again
            with contextlib.suppress(Exception):  # unreadable: load_frames will warn
                frame = read_vtu(vtu, time=time)
                _READ_AHEAD[vtu] = (stamp, frame)
                kept += _frame_bytes(frame)
                count += 1
    if meshes:
        for vtu, (_, frame) in _READ_AHEAD.items():
            if _MESHES.get(vtu, (None,))[0] is not frame:
                _MESHES[vtu] = (frame, _mesh_paths(frame))
    return count


def _frame_bytes(frame: VtuFrame) -> int:
    arrays = [frame.points, frame.cells, *frame.point_data.values(), *frame.cell_data.values()]
    return sum(np.asarray(a).nbytes for a in arrays)


def _stamp(path: Path) -> tuple[int, int] | None:
    try:
        status = path.stat()
    except OSError:
        return None
    return status.st_mtime_ns, status.st_size


def _read_ahead(vtu: Path, time: float) -> VtuFrame | None:
    """The frame prefetch_frames read, if the file has not changed since (frames are
    written once, by a rename, but a run can be started again in the same folder)."""
    stamp, frame = _READ_AHEAD.get(vtu, (None, None))
    if frame is None or stamp is None or stamp != _stamp(vtu) or frame.time != time:
        return None
    return frame


def _read_frame(vtu: Path, time: float) -> VtuFrame:
    frame = _read_ahead(vtu, time)
    return frame if frame is not None else read_vtu(vtu, time=time)


def cell_values(frame: VtuFrame, field: str) -> NDArray[np.float64]:
    """One value per cell: a cell field, or a point field averaged over each cell's nodes.

    Vector fields are reduced to their magnitude.
    """
    if field in frame.cell_data:
        values = np.asarray(frame.cell_data[field], dtype=float)
    elif field in frame.point_data:
        values = np.asarray(frame.point_data[field], dtype=float)[frame.cells].mean(axis=1)
    else:
        known = sorted(set(frame.cell_data) | set(frame.point_data))
        raise KeyError(f"no field '{field}' in {frame.path} (available: {known})")
    return np.linalg.norm(values, axis=1) if values.ndim == 2 else values


def _common_view(frames: Sequence[VtuFrame], field: str):
    """Shared colour normalisation and axis limits so panels/animation frames compare."""
    from matplotlib.colors import Normalize

    values = np.concatenate([cell_values(f, field) for f in frames])
    finite = values[np.isfinite(values)]
    low, high = (finite.min(), finite.max()) if finite.size else (0.0, 1.0)
    norm = Normalize(vmin=low, vmax=high if high > low else low + 1.0)
    points = np.vstack([f.deformed_points for f in frames])
    lower, upper = points.min(axis=0), points.max(axis=0)
    pad = 0.05 * max(float(np.max(upper - lower)), 1e-12)
    return norm, (lower[0] - pad, upper[0] + pad), (lower[1] - pad, upper[1] + pad)


def _mesh_paths(frame: VtuFrame) -> list:
    """The deformed cells of ``frame`` as closed matplotlib paths; those of the frames
    ``prefetch_frames(..., meshes=True)`` read are made then (~1 ms a frame)."""
    from matplotlib.collections import PolyCollection

    kept = _MESHES.get(frame.path)
    if kept is not None and kept[0] is frame:
        return kept[1]
    # a PolyCollection makes the paths of many polygons fastest (one template path)
    return PolyCollection(frame.deformed_points[frame.cells]).get_paths()


def _draw_mesh(ax: Any, frame: VtuFrame, field: str, norm: Any, limits: tuple) -> Any:
    from matplotlib.collections import PathCollection

    # the paths of a PolyCollection, but one whose paths can be swapped for others as they
    # are (a PolyCollection's set_paths takes vertices): the animation's frames
    collection = PathCollection(
        _mesh_paths(frame),
        array=cell_values(frame, field),
        cmap=FIELD_CMAP,
        norm=norm,
        edgecolors=(0.0, 0.0, 0.0, 0.35),
        linewidths=0.3,
    )
    ax.add_collection(collection)
    ax.set_xlim(*limits[0])
    ax.set_ylim(*limits[1])
    ax.set_aspect("equal")
    _title(ax, f"t = {frame.time:.4g}", fontsize="small")
    return collection


def plot_deformed(
    directory: str | os.PathLike,
    times: Sequence[float] | None = None,
    field: str = "von_mises",
    path: str | os.PathLike | None = None,
) -> Path:
    """Deformed meshes of all bodies at up to six times, coloured by ``field``, one colour bar."""
    folder = Path(directory)
    frames = load_frames(folder, times, MAX_PANELS)
    fig, axes, cax = _figure_of(panels_shape(len(frames)))
    norm, xlim, ylim = _common_view(frames, field)
    for ax, frame in zip(axes.flat, frames, strict=False):
        collection = _draw_mesh(ax, frame, field, norm, (xlim, ylim))
    for ax in list(axes.flat)[len(frames):]:
        ax.set_visible(False)
    fig.colorbar(collection, cax=cax, label=field.replace("_", " "))
    return _save(fig, Path(path) if path else folder / f"deformed_{field}.png", axes, cax)


def _pick_steps(available: NDArray, steps: Sequence[int] | None) -> list[int]:
    if steps is None:
        return [int(available[i]) for i in _evenly_spaced(len(available), MAX_PANELS)]
    chosen = [int(s) for s in steps if int(s) in set(available.tolist())]
    if not chosen:
        raise ResultsNotFoundError(f"none of steps {list(steps)} has contact rows")
    return chosen


def plot_contact_tractions(
    directory: str | os.PathLike,
    steps: Sequence[int] | None = None,
    path: str | os.PathLike | None = None,
) -> Path:
    """Normal and tangential traction along each interface against x at chosen output steps."""
    folder = Path(directory)
    contact = _load_table(folder, CONTACT_FILE)
    chosen = _pick_steps(np.unique(contact["step"]), steps)
    interfaces = list(dict.fromkeys(contact["interface"].tolist()))
    fig, axes, _ = _figure_of(HISTORY_SHAPE)
    top, bottom = axes[0, 0], axes[1, 0]
    for step in chosen:
        for interface in interfaces:
            rows = (contact["step"] == step) & (contact["interface"] == interface)
            if not np.any(rows):
                continue
            order = np.argsort(contact["x"][rows])
            label = f"t = {contact['time'][rows][0]:.4g}"
            label += f" ({interface})" if len(interfaces) > 1 else ""
            x = contact["x"][rows][order]
            line = top.plot(x, contact["normal_traction"][rows][order], "o-", ms=3, label=label)
            bottom.plot(x, contact["tangential_traction"][rows][order], "o-", ms=3,
                        color=line[0].get_color())
    top.set_ylabel("normal traction")
    bottom.set_ylabel("tangential traction")
    bottom.set_xlabel("x")
    top.legend(loc="best", fontsize="small")
    for ax in (top, bottom):
        ax.grid(True, alpha=0.3)
    return _save(fig, Path(path) if path else folder / "contact_tractions.png", axes)


def plot_pair_history(
    directory: str | os.PathLike, path: str | os.PathLike | None = None
) -> Path:
    """History of the longest-lived contact pair (report Figs 3.3-3.5): its normal traction
    normalized by its peak, and the displacement and velocity (x and y) of both of its nodes
    from the VTU series (as many samples as were written)."""
    folder = Path(directory)
    contact = _load_table(folder, CONTACT_FILE)
    nodes, counts = np.unique(contact["node_1"], return_counts=True)
    node_1 = int(nodes[np.argmax(counts)])
    rows = contact["node_1"] == node_1
    node_2 = int(np.bincount(contact["node_2"][rows]).argmax())
    fig, axes, _ = _figure_of(PAIR_SHAPE)
    tn = contact["normal_traction"][rows]
    peak = np.abs(tn).max() or 1.0
    axes[0, 0].plot(contact["time"][rows], tn / peak, "o-", ms=3)
    axes[0, 0].set_ylabel(f"normal traction / {peak:.4g}")
    _title(axes[0, 0], f"pair ({node_1}, {node_2})")
    try:
        frames = load_frames(folder, max_frames=10**6)
    except ResultsNotFoundError:
        frames = []
    times = np.array([f.time for f in frames])
    for ax, field in ((axes[1, 0], "displacement"), (axes[2, 0], "velocity")):
        for node, style in ((node_1, "-"), (node_2, "--")):
            values = np.array([f.point_data[field][node] for f in frames]).reshape(-1, 2)
            for comp, name in ((0, "x"), (1, "y")):
                ax.plot(times, values[:, comp], style, label=f"node {node} {name}")
        ax.set_ylabel(field)
        ax.legend(loc="best", fontsize="small")
    axes[2, 0].set_xlabel("time")
    for ax in axes[:, 0]:
        ax.grid(True, alpha=0.3)
    return _save(fig, Path(path) if path else folder / "pair_history.png", axes)


#: The figures of :func:`plot_all`, slowest first (so that two workers share them evenly).
FIGURE_MAKERS = (plot_deformed, plot_pair_history, plot_contact_tractions, plot_energies,
                 plot_momenta)


def plot_figure(make: Callable[[Path], Path], directory: str | os.PathLike) -> Path | None:
    """The figure ``make`` (one of :data:`FIGURE_MAKERS`) draws for the folder, or None if
    the folder has no data for it."""
    try:
        return make(Path(directory))
    except ResultsNotFoundError:
        return None


def plot_all(directory: str | os.PathLike) -> list[Path]:
    """Every figure the folder has data for; the list of PNGs written."""
    made = [p for p in (plot_figure(make, directory) for make in FIGURE_MAKERS) if p is not None]
    return check_made(made, directory)


def check_made(made: list[Path], directory: str | os.PathLike) -> list[Path]:
    """``made``, or an error naming the files looked for when it is empty."""
    if not made:
        raise ResultsNotFoundError(
            f"no results to plot in {directory} (looked for {HISTORY_FILE}, {CONTACT_FILE}, "
            f"{PVD_FILE})"
        )
    return made


def animate(
    directory: str | os.PathLike,
    path_gif: str | os.PathLike,
    max_frames: int = 60,
    field: str = "von_mises",
    fps: int = 10,
) -> Path:
    """A GIF of the deformed meshes over (up to ``max_frames`` evenly spaced) output steps."""
    from matplotlib.cm import ScalarMappable

    frames = load_frames(directory, None, max_frames)
    norm, xlim, ylim = _common_view(frames, field)
    fig, axes, cax = _figure_of(ANIMATION_SHAPE)
    ax = axes[0, 0]
    # The colour bar gets its own mappable: the mesh collection is replaced every frame.
    fig.colorbar(ScalarMappable(norm, FIELD_CMAP), cax=cax, label=field.replace("_", " "))
    collection = _draw_mesh(ax, frames[0], field, norm, (xlim, ylim))
    # Axes, ticks and colour bar never change: draw them once (blitting) and only draw the
    # mesh and the title on top per frame; redrawing the whole figure per frame was ~10x slower.
    collection.set_visible(False)
    ax.set_title(" ", fontsize="small")
    _fit_layout(fig, axes, cax)
    fig.canvas.draw()
    background = fig.canvas.copy_from_bbox(fig.bbox)
    collection.set_visible(True)
    palette = _gif_palette(FIELD_CMAP)
    still = _quantized(fig.canvas, (0, 0, *fig.canvas.get_width_height()), palette)
    images = []
    for frame in frames:
        fig.canvas.restore_region(background)
        collection.set_paths(_mesh_paths(frame))
        collection.set_array(cell_values(frame, field))
        ax.title.set_text(f"t = {frame.time:.4g}")
        ax.draw_artist(collection)
        ax.draw_artist(ax.title)
        # only the axes and the title change: the rest of the frame is the still one's
        box = _changed_box(fig, ax)
        image = still.copy()
        image.paste(_quantized(fig.canvas, box, palette), box[:2])
        images.append(image)
    output = Path(path_gif)
    # optimize=False: PIL's default made every unchanged pixel of a frame transparent (a
    # difference, a mask and a paste per frame: half of the ~0.1 s the saving took) for no
    # gain here, the mesh moving all over the changed rectangle; the frames still hold only
    # that rectangle, they look the same and the file is a few % smaller.
    images[0].save(output, save_all=True, append_images=images[1:], duration=int(1000 / fps),
                   loop=0, optimize=False)
    return output


def _changed_box(fig: Figure, ax: Any) -> tuple[int, int, int, int]:
    """The canvas pixels (left, top, right, bottom) the mesh (clipped to the axes) and the
    title of an animation frame can reach, with a 2-pixel margin for antialiasing."""
    from matplotlib.transforms import Bbox

    width, height = fig.canvas.get_width_height()
    box = Bbox.union([ax.bbox, ax.title.get_window_extent(fig.canvas.get_renderer())])
    return (max(int(box.x0) - 2, 0), max(int(height - box.y1) - 2, 0),
            min(int(box.x1) + 3, width), min(int(height - box.y0) + 3, height))


def _quantized(canvas: Any, box: tuple[int, int, int, int], palette: Any):
    """The ``box`` of the canvas in the GIF's palette (each pixel to its nearest colour)."""
    from PIL import Image

    # PIL drops the alpha channel itself (a strided numpy copy cost ~3 ms per frame)
    rgba = Image.frombuffer("RGBA", canvas.get_width_height(), canvas.buffer_rgba(), "raw",
                            "RGBA", 0, 1)
    return rgba.crop(box).convert("RGB").quantize(palette=palette, dither=Image.Dither.NONE)


def _gif_palette(cmap: str):
    """A fixed 256-colour palette: 224 steps of the colour map and 32 greys (background,
    edges, text). Mapping each frame to it is ~10x faster than an adaptive palette per frame
    (median cut), and the colours of the field stay the same from frame to frame."""
    from matplotlib import colormaps
    from PIL import Image

    colours = np.round(colormaps[cmap](np.linspace(0.0, 1.0, 224))[:, :3] * 255)
    greys = np.repeat(np.linspace(0.0, 255.0, 32)[:, None], 3, axis=1).round()
    image = Image.new("P", (1, 1))
    image.putpalette(np.vstack([colours, greys]).astype(np.uint8).ravel().tolist())
    return image
