"""Plots from a small synthetic results folder written with the real writers."""

from __future__ import annotations

from pathlib import Path

import matplotlib.image as mpimg
import numpy as np
import pytest
from matplotlib.backends.backend_agg import FigureCanvasAgg

from ntncontact.io.writers import HISTORY_COLUMNS, ResultsDirectory
from ntncontact.report import plotting
from ntncontact.report.plotting import (
    DPI,
    ResultsNotFoundError,
    animate,
    plot_all,
    plot_contact_tractions,
    plot_deformed,
    plot_energies,
    plot_momenta,
)

N_STEPS = 5


def grid(nx: int, ny: int, origin: tuple[float, float], size: float):
    """A structured (nx x ny)-cell Q4 grid with counter-clockwise cells."""
    xs = origin[0] + size * np.arange(nx + 1)
    ys = origin[1] + size * np.arange(ny + 1)
    points = np.array([(x, y) for y in ys for x in xs])
    cells = [
        [j * (nx + 1) + i, j * (nx + 1) + i + 1, (j + 1) * (nx + 1) + i + 1, (j + 1) * (nx + 1) + i]
        for j in range(ny)
        for i in range(nx)
    ]
    return points, np.array(cells)


def write_run(folder: Path) -> None:
    block, block_cells = grid(4, 2, (0.0, 1.0), 0.25)
    wall, wall_cells = grid(6, 1, (-0.25, 0.0), 0.25)
    points = np.vstack([block, wall])
    cells = np.vstack([block_cells, wall_cells + len(block)])
    body_id = np.repeat([0, 1], [len(block_cells), len(wall_cells)])
    is_block = np.arange(len(points)) < len(block)
    with ResultsDirectory(folder, ("active_pairs",), scenario="synthetic") as out:
        for step in range(N_STEPS):
            time = 0.1 * step
            drop = np.where(is_block, -0.2 * step, 0.0)
            displacement = np.column_stack([0.02 * step * points[:, 1] * is_block, drop])
            row = {name: float(step) for name in HISTORY_COLUMNS}
            row.update(step=step, time=time, kinetic_energy=1.0 - 0.1 * step,
                       strain_energy=0.1 * step, total_energy=1.0 + 1e-3 * np.sin(step),
                       newton_iterations=3, active_pairs=3 if step >= 2 else 0)
            out.write_history(row)
            von_mises = np.linspace(0.0, step + 1.0, len(cells))
            out.fields.write(step, time, points, cells,
                             {"displacement": displacement, "velocity": displacement / 0.1},
                             {"von_mises": von_mises, "body_id": body_id})
            if step >= 2:
                x = np.array([0.0, 0.5, 1.0])
                out.contact.write_step(step, time, {
                    "interface": "block_wall", "node_1": [0, 2, 4], "node_2": [21, 23, 25],
                    "x": x, "y": np.zeros(3), "gap": np.zeros(3), "gap_rate": -np.ones(3),
                    "normal_traction": -step * (1.0 - (x - 0.5) ** 2),
                    "tangential_traction": 0.1 * step * (x - 0.5),
                    "normal_force": -np.ones(3), "tangential_force": np.zeros(3),
                    "status": ["stick", "slip", "stick"], "end_gap": np.zeros(3),
                    "normal_x": np.zeros(3), "normal_y": -np.ones(3),
                })


@pytest.fixture(scope="module")
def results(tmp_path_factory) -> Path:
    folder = tmp_path_factory.mktemp("run")
    write_run(folder)
    return folder


def assert_real_image(path: Path, width_in: float | None = None) -> None:
    assert path.is_file() and path.stat().st_size > 0
    image = mpimg.imread(path)
    assert image.ndim == 3 and min(image.shape[:2]) > 100
    if width_in is not None:
        assert image.shape[1] == round(width_in * DPI)
    assert float(np.var(image[..., :3])) > 0.0  # not a blank canvas


def test_energy_and_momentum_plots(results, tmp_path):
    assert_real_image(plot_energies(results, tmp_path / "e.png"), width_in=7.0)
    assert_real_image(plot_momenta(results, tmp_path / "m.png"), width_in=7.0)


def test_deformed_plot_at_chosen_times(results, tmp_path):
    path = plot_deformed(results, times=[0.0, 0.2, 0.4], path=tmp_path / "d.png")
    assert_real_image(path, width_in=3.6 * 3 + 1.0)


def test_deformed_plot_by_point_field(results, tmp_path):
    assert_real_image(plot_deformed(results, field="velocity", path=tmp_path / "v.png"))
    with pytest.raises(KeyError, match="pressure"):
        plot_deformed(results, field="pressure", path=tmp_path / "p.png")


def test_contact_traction_plot(results, tmp_path):
    assert_real_image(plot_contact_tractions(results, steps=[2, 4], path=tmp_path / "c.png"))
    with pytest.raises(ResultsNotFoundError, match="steps"):
        plot_contact_tractions(results, steps=[0], path=tmp_path / "none.png")


def test_plot_all_writes_every_figure_into_the_folder(tmp_path):
    write_run(tmp_path)
    paths = plot_all(tmp_path)
    assert sorted(p.name for p in paths) == [
        "contact_tractions.png", "deformed_von_mises.png", "energies.png", "momenta.png",
        "pair_history.png",
    ]
    for path in paths:
        assert path.parent == tmp_path
        assert_real_image(path)


def test_animation_gif(results, tmp_path):
    from PIL import Image

    path = animate(results, tmp_path / "run.gif", max_frames=3)
    with Image.open(path) as gif:
        assert gif.n_frames == 3
        assert gif.size == (round(6.0 * DPI), round(4.5 * DPI))
        assert np.var(np.asarray(gif.convert("RGB"))) > 0.0


def test_partial_run_is_still_plotted(tmp_path):
    write_run(tmp_path)
    history = tmp_path / "history.csv"
    history.write_text(history.read_text() + "5,0.5,0.4")  # killed mid-row
    (tmp_path / "fields" / "fields_00004.vtu").unlink()  # fewer VTUs than listed
    contact = tmp_path / "contact.csv"
    contact.write_text(contact.read_text() + "5,0.5,block_wall,0,2")
    with pytest.warns(UserWarning, match="fields_00003"):
        (tmp_path / "fields" / "fields_00003.vtu").write_text("<VTKFile")  # half-written file
        paths = plot_all(tmp_path)
    assert len(paths) == 5  # every figure, pair history included
    for path in paths:
        assert_real_image(path)


def test_history_only_folder_makes_history_plots(tmp_path):
    with ResultsDirectory(tmp_path) as out:
        row = {name: 1.0 for name in HISTORY_COLUMNS} | {"step": 0, "newton_iterations": 2}
        out.write_history(row)
        out.write_history(row | {"step": 1, "time": 2.0})
    assert sorted(p.name for p in plot_all(tmp_path)) == ["energies.png", "momenta.png"]


def test_empty_folder_error_names_it(tmp_path):
    empty = tmp_path / "nothing_here"
    empty.mkdir()
    with pytest.raises(ResultsNotFoundError, match="nothing_here"):
        plot_all(empty)
    with pytest.raises(ResultsNotFoundError, match="history.csv"):
        plot_energies(empty)
    with pytest.raises(ResultsNotFoundError, match="fields.pvd"):
        animate(empty, tmp_path / "x.gif")


def test_figures_follow_the_matplotlibrc_and_the_file_name(results, tmp_path):
    """savefig writes the figures: a matplotlibrc's resolution applies, and a .pdf name gets a
    PDF."""
    import matplotlib

    with matplotlib.rc_context({"savefig.dpi": DPI / 2}):
        half = plot_energies(results, tmp_path / "half.png")
    assert mpimg.imread(half).shape[1] == round(7.0 * DPI / 2)
    pdf = plot_energies(results, tmp_path / "e.pdf")
    assert pdf.read_bytes()[:5] == b"%PDF-"


def _expected_state(step: float, folder: Path):
    """What write_run's fields are at a (fractional) step: all of them are linear in it."""
    from ntncontact.io.vtk import read_vtu

    first = read_vtu(folder / "fields" / "fields_00000.vtu")
    is_block = first.cell_data["body_id"] == 0
    points = first.points
    on_block = np.zeros(len(points), dtype=bool)
    on_block[first.cells[is_block].ravel()] = True
    displacement = np.column_stack([0.02 * step * points[:, 1] * on_block,
                                    -0.2 * step * on_block])
    return displacement, np.linspace(0.0, step + 1.0, len(first.cells))


def test_frames_between_outputs_are_interpolated_linearly(results):
    from ntncontact.report.plotting import frames_at

    (frame, interpolated), = frames_at(results, [0.25])
    assert interpolated and frame.time == 0.25
    displacement, von_mises = _expected_state(2.5, results)
    assert np.allclose(frame.point_data["displacement"], displacement, rtol=0.0, atol=1e-12)
    assert np.allclose(frame.cell_data["von_mises"], von_mises, rtol=0.0, atol=1e-12)
    assert frame.cell_data["body_id"].dtype.kind in "iu"


def test_a_time_with_a_frame_draws_that_frame(results):
    from ntncontact.io.vtk import read_vtu
    from ntncontact.report.plotting import frames_at

    (frame, interpolated), = frames_at(results, [0.3])
    written = read_vtu(results / "fields" / "fields_00003.vtu")
    assert not interpolated and frame.time == pytest.approx(0.3, abs=1e-15)
    assert np.array_equal(frame.point_data["displacement"], written.point_data["displacement"])


def test_interpolation_steps_over_an_unreadable_frame(tmp_path):
    from ntncontact.report.plotting import frames_at

    write_run(tmp_path)
    (tmp_path / "fields" / "fields_00003.vtu").write_text("<VTKFile")  # half-written
    with pytest.warns(UserWarning, match="fields_00003"):
        (frame, interpolated), = frames_at(tmp_path, [0.25])  # between 0.2 and 0.4 now
    displacement, von_mises = _expected_state(2.5, tmp_path)
    assert interpolated
    assert np.allclose(frame.point_data["displacement"], displacement, rtol=0.0, atol=1e-12)
    assert np.allclose(frame.cell_data["von_mises"], von_mises, rtol=0.0, atol=1e-12)


def test_times_a_rounding_error_off_the_ends_draw_the_end_frames(results):
    from ntncontact.report.plotting import frames_at

    states = frames_at(results, [-1e-12, 0.4 + 1e-12])
    assert [(frame.time, interpolated) for frame, interpolated in states] == \
        [(0.0, False), (pytest.approx(0.4, abs=1e-15), False)]


@pytest.mark.parametrize("times", [[0.5], [-0.1], [0.1, float("nan")], [100.0, -1.0]])
def test_times_outside_the_frames_are_refused(results, tmp_path, times):
    with pytest.raises(ValueError, match=r"outside the frames of .*fields\.pvd \(t = 0 to 0\.4\)"):
        plot_deformed(results, times=times, path=tmp_path / "x.png")
    assert not (tmp_path / "x.png").exists()


def test_every_time_asked_for_is_drawn_under_its_own_title(results, tmp_path, monkeypatch):
    """Seven times (more than the six evenly spaced panels), in the order given, each panel
    titled with the time it shows."""
    from ntncontact.report import plotting

    drawn = []
    save = plotting._save
    monkeypatch.setattr(plotting, "_save", lambda fig, path: drawn.append(fig) or save(fig, path))
    times = [0.0, 0.05, 0.1, 0.15, 0.4, 0.333, 0.2]
    assert_real_image(plot_deformed(results, times=times, path=tmp_path / "seven.png"),
                      width_in=3.6 * 3 + 1.0)
    titles = [ax.get_title() for ax in drawn[0].axes if ax.get_visible() and ax.get_title()]
    assert titles == ["t = 0", "t = 0.05 (interpolated)", "t = 0.1", "t = 0.15 (interpolated)",
                      "t = 0.4", "t = 0.333 (interpolated)", "t = 0.2"]


def test_the_pair_history_leaves_out_the_steps_without_contact():
    """A pair in contact at steps 3-4 and again at 7: its line breaks between 4 and 7 (it
    was drawn straight across the steps the pair was apart)."""
    from ntncontact.report.plotting import broken_at_gaps

    time, value = broken_at_gaps(np.array([3, 4, 7]), np.array([0.3, 0.4, 0.7]),
                                 np.array([1.0, 2.0, 3.0]))
    assert np.array_equal(time, [0.3, 0.4, np.nan, 0.7], equal_nan=True)
    assert np.array_equal(value, [1.0, 2.0, np.nan, 3.0], equal_nan=True)


def write_three_interfaces(folder: Path) -> None:
    """contact.csv of a 4-block stack: 3 interfaces over the same x, 8 output steps."""
    x = np.linspace(-0.75, 0.75, 7)
    with ResultsDirectory(folder, ("active_pairs",), scenario="synthetic") as out:
        for step in range(1, 9):
            for k, name in enumerate(("i1", "i2", "i3")):
                n = len(x)
                out.contact.write_step(step, 0.15 * step, {
                    "interface": name, "node_1": np.arange(n), "node_2": np.arange(n) + 50,
                    "x": x, "y": np.full(n, 0.5 * k), "gap": np.zeros(n),
                    "gap_rate": np.zeros(n), "normal_traction": (3 - k) * step * (1.0 - x**2),
                    "tangential_traction": np.zeros(n), "normal_force": -np.ones(n),
                    "tangential_force": np.zeros(n), "status": ["stick"] * n,
                    "end_gap": np.zeros(n), "normal_x": np.zeros(n),
                    "normal_y": -np.ones(n),
                })


def test_contact_traction_legend_of_three_interfaces_stays_clear_of_the_ticks(tmp_path,
                                                                             monkeypatch):
    """A tester's 4-block stack: a legend entry per time and interface (18) overflowed the
    top panel and hid its x tick labels; the times are now a colour bar."""
    write_three_interfaces(tmp_path)
    figures = []
    save = plotting._save
    monkeypatch.setattr(plotting, "_save", lambda fig, path: figures.append(fig) or save(fig, path))
    assert_real_image(plot_contact_tractions(tmp_path))
    fig = figures[0]
    canvas = FigureCanvasAgg(fig)
    canvas.draw()
    renderer = canvas.get_renderer()
    top = fig.axes[0]
    legend = top.get_legend()
    assert len(legend.get_texts()) == 3  # one per interface
    box = legend.get_window_extent(renderer)
    assert top.get_window_extent(renderer).contains(box.x0, box.y0)
    ticks = [label.get_window_extent(renderer) for ax in fig.axes[:2]
             for label in ax.get_xticklabels() + ax.get_yticklabels() if label.get_text()]
    assert ticks and not any(box.overlaps(tick) for tick in ticks)
