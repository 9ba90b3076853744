"""Figures made from a results folder alone (history.csv, contact.csv, fields.pvd + VTUs or
fields.xdmf + fields.h5).

They are drawn after a run, in the calling process. matplotlib is imported inside the
functions and the figures are made without pyplot, so importing this module costs nothing and
never changes the user's backend; matplotlib's constrained layout places the axes. Every
function tolerates a partially written run: truncated CSV lines are dropped and only the VTU
files the PVD lists (and that parse) are used, or the frames of the XDMF index.
"""

from __future__ import annotations

import os
import warnings
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from ntncontact.engine.diagnostics import energy_balance
from ntncontact.io.vtk import (
    FrameSource,
    VtuFrame,
    find_field_series,
    frame_time_tolerance,
    read_frame,
    read_series,
)
from ntncontact.io.writers import CONTACT_FILE, HISTORY_FILE, read_csv_table

if TYPE_CHECKING:
    from matplotlib.figure import Figure

PVD_FILE = "fields.pvd"
XDMF_FILE = "fields.xdmf"  # analysis.field_format = "xdmf"
EVENLY_SPACED_PANELS = 6  # meshes in deformed_<field>.png when no times are asked for
DPI = 110
FIELD_CMAP = "viridis"  # colour map of the mesh fields (and of the times of several interfaces)
MARKERS = "os^Dv<>P"  # markers of the interfaces in contact_tractions.png

#: (rows, columns, size in inches) of the figures
HISTORY_SHAPE = (2, 1, (7.0, 6.0))  # energies, momenta, tractions
PAIR_SHAPE = (3, 1, (7.0, 8.0))
ANIMATION_SHAPE = (1, 1, (6.0, 4.5))


class ResultsNotFoundError(FileNotFoundError):
    """A results folder (or one of its files) is missing or holds no data yet."""


def _new_figure(nrows: int = 1, ncols: int = 1, size: tuple[float, float] = (7.0, 4.5),
                layout: str = "constrained", grid: bool = False) -> tuple[Figure, NDArray]:
    """A figure and its grid of axes (report/validation.py's figures too). ``layout="compressed"``
    for a grid of equal-aspect axes: no white bands between them; ``grid``: faint grid lines
    on every axes."""
    from matplotlib.figure import Figure

    fig = Figure(figsize=size, dpi=DPI, layout=layout)
    axes = fig.subplots(nrows, ncols, squeeze=False)
    for ax in axes.flat if grid else ():
        ax.grid(True, alpha=0.3)
    return fig, axes


def _panels(count: int, per_row: int, panel: tuple[float, float], margin: float,
            **options: Any) -> tuple[Figure, NDArray]:
    """A figure of ``count`` panels, up to ``per_row`` in a row, each ``panel`` inches and
    ``margin`` inches of width besides (``options``: :func:`_new_figure`'s); the axes beyond
    ``count`` hidden."""
    ncols = min(per_row, count)
    nrows = -(-count // ncols)
    fig, axes = _new_figure(nrows, ncols, (panel[0] * ncols + margin, panel[1] * nrows),
                            **options)
    for ax in axes.flat[count:]:
        ax.set_visible(False)
    return fig, axes


def _save(fig: Figure, path: str | os.PathLike) -> Path:
    fig.savefig(path)
    return Path(path)


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
    folder = Path(directory)
    history = _load_table(folder, HISTORY_FILE)
    time, total = history["time"], history["total_energy"]
    fig, axes = _new_figure(*HISTORY_SHAPE, grid=True)
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
    return _save(fig, Path(path) if path else folder / "energies.png")


def plot_momenta(directory: str | os.PathLike, path: str | os.PathLike | None = None) -> Path:
    """Linear momentum components and angular momentum against time."""
    folder = Path(directory)
    history = _load_table(folder, HISTORY_FILE)
    fig, axes = _new_figure(*HISTORY_SHAPE, grid=True)
    top, bottom = axes[0, 0], axes[1, 0]
    top.plot(history["time"], history["linear_momentum_x"], label="linear momentum x")
    top.plot(history["time"], history["linear_momentum_y"], label="linear momentum y")
    top.set_ylabel("linear momentum")
    top.legend(loc="best", fontsize="small")
    bottom.plot(history["time"], history["angular_momentum"], color="C2")
    bottom.set_ylabel("angular momentum")
    bottom.set_xlabel("time")
    return _save(fig, Path(path) if path else folder / "momenta.png")


def _series(directory: Path) -> tuple[Path, list[tuple[float, FrameSource]]]:
    """The folder's field series (fields.pvd, or fields.xdmf) and its frames."""
    source = find_field_series(directory)
    if source is None:
        raise ResultsNotFoundError(f"no {PVD_FILE} or {XDMF_FILE} in results folder {directory}")
    try:
        series = read_series(source)
    except ValueError as error:
        raise ResultsNotFoundError(str(error)) from None
    if not series:
        raise ResultsNotFoundError(f"{source} lists no existing frames")
    return source, series


def _evenly_spaced(count: int, wanted: int) -> list[int]:
    return sorted({int(i) for i in np.round(np.linspace(0, count - 1, min(count, wanted)))})


def _read_or_warn(source: FrameSource, time: float) -> VtuFrame | None:
    try:
        return read_frame(source, time=time)
    except Exception as error:  # a corrupt file (any parser error) must not stop the plot
        warnings.warn(f"skipping unreadable {source}: {error}", stacklevel=3)
        return None


def load_frames(directory: str | os.PathLike, max_frames: int = EVENLY_SPACED_PANELS
                ) -> list[VtuFrame]:
    """Up to ``max_frames`` evenly spaced frames of the folder; unreadable files skipped."""
    _, series = _series(Path(directory))
    frames = [frame for index in _evenly_spaced(len(series), max_frames)
              if (frame := _read_or_warn(series[index][1], series[index][0])) is not None]
    if not frames:
        raise ResultsNotFoundError(f"no readable frames in results folder {directory}")
    return frames


def check_times(times: Sequence[float], first: float, last: float, where: str,
                tolerance: float = 0.0) -> None:
    """A one-line ValueError naming the times not within ``first``..``last`` (give or take
    ``tolerance``; NaN is outside) and ``where`` they were looked for."""
    outside = [f"{t:g}" for t in times if not first - tolerance <= t <= last + tolerance]
    if outside:
        what = "time " + outside[0] + " is" if len(outside) == 1 else \
            "times " + ", ".join(outside) + " are"
        raise ValueError(f"{what} outside {where} (t = {first:g} to {last:g})")


def frames_at(directory: str | os.PathLike, times: Sequence[float]
              ) -> list[tuple[VtuFrame, bool]]:
    """The state at each of ``times``, with True where it is interpolated: the frame written
    at that time (within 1e-9 of the run's span), or else the linear interpolation between the
    readable frames before and after it. Times outside the frames raise a ValueError."""
    folder = Path(directory)
    source, series = _series(folder)
    written = np.array([t for t, _ in series])
    tolerance = frame_time_tolerance(written)
    check_times(times, written[0], written[-1], f"the frames of {source}", tolerance)
    read: dict[int, VtuFrame | None] = {}

    def frame(index: int) -> VtuFrame | None:
        if index not in read:
            read[index] = _read_or_warn(series[index][1], series[index][0])
        return read[index]

    states = []
    for time in times:
        first_after = int(np.searchsorted(written, time - tolerance))
        later = next((i for i in range(first_after, len(series)) if frame(i) is not None), None)
        if later is not None and abs(written[later] - time) <= tolerance:
            states.append((frame(later), False))
            continue
        earlier = next((i for i in range(first_after - 1, -1, -1) if frame(i) is not None),
                       None)
        if earlier is None or later is None:
            raise ResultsNotFoundError(f"no readable frames around t = {time:g} in {folder}")
        states.append((interpolate(frame(earlier), frame(later), time), True))
    return states


def interpolate(before: VtuFrame, after: VtuFrame, time: float) -> VtuFrame:
    """The linear interpolation in time between two frames of one mesh: of the points and of
    every floating-point field; other fields (body_id) are taken from the nearer frame."""
    if not np.array_equal(before.cells, after.cells):
        raise ValueError(f"cannot interpolate between {before.path} and {after.path}: "
                         "their cells differ")
    weight = (time - before.time) / (after.time - before.time)

    def mix(a: NDArray, b: NDArray) -> NDArray:
        if a.dtype.kind == "f" and a.shape == b.shape:
            return (1.0 - weight) * a + weight * b
        return a if weight < 0.5 else b

    return VtuFrame(
        time=time,
        path=before.path if weight < 0.5 else after.path,
        points=mix(before.points, after.points),
        cells=before.cells,
        point_data={k: mix(v, after.point_data[k]) for k, v in before.point_data.items()
                    if k in after.point_data},
        cell_data={k: mix(v, after.cell_data[k]) for k, v in before.cell_data.items()
                   if k in after.cell_data},
    )


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


def _time_title(frame: VtuFrame, interpolated: bool = False) -> str:
    return f"t = {frame.time:g}" + (" (interpolated)" if interpolated else "")


def _draw_mesh(ax: Any, frame: VtuFrame, field: str, norm: Any, limits: tuple) -> Any:
    from matplotlib.collections import PolyCollection

    collection = PolyCollection(
        frame.deformed_points[frame.cells],
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
    return collection


def plot_deformed(
    directory: str | os.PathLike,
    times: Sequence[float] | None = None,
    field: str = "von_mises",
    path: str | os.PathLike | None = None,
) -> Path:
    """Deformed meshes of all bodies coloured by ``field``, with one colour bar: at each of
    ``times`` (see :func:`frames_at`), or at six evenly spaced output frames."""
    folder = Path(directory)
    if times is None:
        states = [(frame, False) for frame in load_frames(folder)]
    else:
        states = frames_at(folder, times)
    frames = [frame for frame, _ in states]
    fig, axes = _panels(len(frames), 3, (3.6, 3.2), 1.0, layout="compressed")
    norm, xlim, ylim = _common_view(frames, field)
    for ax, (frame, interpolated) in zip(axes.flat, states, strict=False):
        collection = _draw_mesh(ax, frame, field, norm, (xlim, ylim))
        ax.set_title(_time_title(frame, interpolated), fontsize="small")
    fig.colorbar(collection, ax=axes, label=field.replace("_", " "))
    return _save(fig, Path(path) if path else folder / f"deformed_{field}.png")


def _pick_steps(available: NDArray, steps: Sequence[int] | None) -> list[int]:
    if steps is None:
        return [int(available[i]) for i in _evenly_spaced(len(available), EVENLY_SPACED_PANELS)]
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
    fig = tractions_figure(_load_table(folder, CONTACT_FILE), steps)
    return _save(fig, Path(path) if path else folder / "contact_tractions.png")


def tractions_figure(contact: dict[str, NDArray], steps: Sequence[int] | None = None) -> Figure:
    """The figure of :func:`plot_contact_tractions` from contact.csv's columns. One interface: a
    colour and a legend entry per time. Several: a legend entry per time and interface would
    overflow the axes, so the time is a colour on a colour bar and the interface a marker in a
    legend of its own."""
    chosen = _pick_steps(np.unique(contact["step"]), steps)
    interfaces = list(dict.fromkeys(contact["interface"].tolist()))
    fig, axes = _new_figure(*HISTORY_SHAPE, grid=True)
    top, bottom = axes[0, 0], axes[1, 0]
    colours = _time_colours(fig, axes, contact, chosen) if len(interfaces) > 1 else None
    for k, step in enumerate(chosen):
        for i, interface in enumerate(interfaces):
            rows = (contact["step"] == step) & (contact["interface"] == interface)
            if not np.any(rows):
                continue
            order = np.argsort(contact["x"][rows])
            x = contact["x"][rows][order]
            style = {"ms": 3, "marker": "o", "label": f"t = {contact['time'][rows][0]:.4g}"}
            if colours is not None:
                style = {"ms": 4, "color": colours[k], "marker": MARKERS[i % len(MARKERS)]}
            line = top.plot(x, contact["normal_traction"][rows][order], "-", **style)[0]
            bottom.plot(x, contact["tangential_traction"][rows][order], "-", ms=style["ms"],
                        color=line.get_color(), marker=line.get_marker())
    top.set_ylabel("normal traction")
    bottom.set_ylabel("tangential traction")
    bottom.set_xlabel("x")
    if colours is None:
        top.legend(loc="best", fontsize="small")
    else:
        _interface_legend(top, interfaces)
    return fig


def _time_colours(fig: Figure, axes: NDArray, contact: dict[str, NDArray],
                  chosen: list[int]) -> list[Any]:
    """A colour per chosen step, with a colour bar beside the axes whose ticks are the steps'
    times: as many entries as times, whatever the number of interfaces."""
    from matplotlib import colormaps
    from matplotlib.cm import ScalarMappable
    from matplotlib.colors import BoundaryNorm, ListedColormap

    # viridis without its pale yellow end, which is faint on white
    colours = list(colormaps[FIELD_CMAP](np.linspace(0.0, 0.85, len(chosen))))
    norm = BoundaryNorm(np.arange(len(chosen) + 1) - 0.5, len(chosen))
    bar = fig.colorbar(ScalarMappable(norm=norm, cmap=ListedColormap(colours)),
                       ax=axes.ravel().tolist(), ticks=range(len(chosen)))
    times = [contact["time"][contact["step"] == step][0] for step in chosen]
    bar.ax.set_yticklabels([f"{t:.4g}" for t in times])
    bar.set_label("t")
    return colours


def _interface_legend(ax: Any, interfaces: list[str]) -> None:
    """One legend entry per interface, its marker in grey (the colour is the time)."""
    from matplotlib.lines import Line2D

    handles = [Line2D([], [], color="0.4", marker=MARKERS[i % len(MARKERS)], ms=4, label=name)
               for i, name in enumerate(interfaces)]
    ax.legend(handles=handles, loc="best", fontsize="small", title="interface",
              title_fontsize="small")


def broken_at_gaps(steps: NDArray, *columns: NDArray) -> list[NDArray]:
    """The columns with a NaN between rows whose steps are not consecutive, so that a line
    plot leaves out the steps the pair was not in contact (it drew across them)."""
    gaps = np.flatnonzero(np.diff(steps) > 1) + 1
    return [np.insert(np.asarray(c, dtype=float), gaps, np.nan) for c in columns]


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
    fig, axes = _new_figure(*PAIR_SHAPE, grid=True)
    tn = contact["normal_traction"][rows]
    peak = np.abs(tn).max() or 1.0
    axes[0, 0].plot(*broken_at_gaps(contact["step"][rows], contact["time"][rows], tn / peak),
                    "o-", ms=3)
    axes[0, 0].set_ylabel(f"normal traction / {peak:.4g}")
    axes[0, 0].set_title(f"pair ({node_1}, {node_2})")
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
    return _save(fig, Path(path) if path else folder / "pair_history.png")


#: The figures :func:`plot_all` draws when the folder has data for them.
FIGURE_MAKERS: tuple[Callable[[Path], Path], ...] = (
    plot_deformed, plot_pair_history, plot_contact_tractions, plot_energies, plot_momenta)


def plot_all(directory: str | os.PathLike, times: Sequence[float] | None = None,
             gif: bool = False) -> list[Path]:
    """Every figure the folder has data for; the list of files written. ``times``: the
    deformed meshes at those times (snapshots.png) instead of six evenly spaced ones
    (deformed_von_mises.png); ``gif``: also animation.gif. These two must be drawn: an error
    if they cannot (drawn first, so that a bad time is reported at once)."""
    folder = Path(directory)
    asked = [plot_deformed(folder, times, path=folder / "snapshots.png")] if times else []
    made = []
    for make in FIGURE_MAKERS:
        if times and make is plot_deformed:
            continue
        try:
            made.append(make(folder))
        except ResultsNotFoundError:
            pass
    if not made:
        raise ResultsNotFoundError(
            f"no results to plot in {directory} (looked for {HISTORY_FILE}, {CONTACT_FILE}, "
            f"{PVD_FILE}, {XDMF_FILE})"
        )
    return made + asked + ([animate(folder, folder / "animation.gif")] if gif else [])


def animate(
    directory: str | os.PathLike,
    path_gif: str | os.PathLike,
    max_frames: int = 60,
    field: str = "von_mises",
) -> Path:
    """A GIF of the deformed meshes over (up to ``max_frames`` evenly spaced) output steps,
    drawn by matplotlib and saved by Pillow."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from PIL import Image

    frames = load_frames(directory, max_frames)
    norm, xlim, ylim = _common_view(frames, field)
    fig, axes = _new_figure(*ANIMATION_SHAPE)
    canvas = FigureCanvasAgg(fig)
    ax = axes[0, 0]
    collection = _draw_mesh(ax, frames[0], field, norm, (xlim, ylim))
    fig.colorbar(collection, ax=ax, label=field.replace("_", " "))
    ax.set_title(_time_title(frames[0]), fontsize="small")
    # The axes, ticks and colour bar are the same in every frame: lay them out once (a
    # constrained layout at every frame took half of the animation's time).
    fig.draw_without_rendering()
    fig.set_layout_engine("none")
    images = []
    for frame in frames:
        collection.set_verts(frame.deformed_points[frame.cells])
        collection.set_array(cell_values(frame, field))
        ax.set_title(_time_title(frame), fontsize="small")
        canvas.draw()
        size = canvas.get_width_height()
        rgb = Image.frombuffer("RGBA", size, canvas.buffer_rgba()).convert("RGB")
        # Pillow's fast octree palette: a tenth of the time of its default (median cut)
        images.append(rgb.quantize(method=Image.Quantize.FASTOCTREE))
    images[0].save(path_gif, save_all=True, append_images=images[1:],
                   duration=100, loop=0)  # milliseconds a frame: 10 frames a second
    return Path(path_gif)
