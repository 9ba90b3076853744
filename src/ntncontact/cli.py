"""The ``ntncontact`` command: run scenarios, plot results."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from . import __version__


def _run(args: argparse.Namespace) -> int:
    from tqdm import tqdm

    from .builder import build_model
    from .io.results import ResultWriter
    from .io.scenario import load_scenario
    from .simulation import Simulation

    scenario = Path(args.scenario)
    config = load_scenario(scenario, args.set)
    model = build_model(config, scenario.parent)
    if args.times:  # refused before the run, not after it
        from .plotting import check_times

        check_times(args.times, 0.0, model.analysis.t_end, f"the run of {scenario}")
    out = Path(args.out)
    writer = ResultWriter(out, model, scenario=str(scenario), title=config.title,
                          overrides=list(args.set or []))
    sim = Simulation(model, [writer])
    t_end = model.analysis.t_end
    with tqdm(total=t_end, unit="t", disable=args.quiet or None, desc=scenario.stem,
              bar_format="{l_bar}{bar}| t={n:.4g}/{total:.4g} [{elapsed}<{remaining}]") as bar:

        def progress(t: float) -> None:
            bar.update(t - bar.n)

        sim.run(progress)
    print(f"results written to {out} (history.csv, summary.json, fields.pvd)")
    if args.compare:
        _print_comparison(out)
    if args.plot or args.gif or args.times:
        print("figures:", *_draw_figures(out, args), sep="\n  ")
    return 0


def _draw_figures(directory: Path, args: argparse.Namespace) -> list[Path]:
    from .plotting import plot_all

    return plot_all(directory, times=args.times, gif=args.gif)


def _plot(args: argparse.Namespace) -> int:
    for path in _draw_figures(Path(args.directory), args):
        print(path)
    return 0


def _mesh_quality(args: argparse.Namespace) -> int:
    """Table 4.1 statistics of every body of a scenario (reference meshes) or of a VTU file."""
    from .mesh.quality import quality_statistics

    path = Path(args.path)
    if path.suffix == ".vtu":
        from .io.vtk import read_vtu

        frame = read_vtu(path)
        tables = {path.name: quality_statistics(frame.deformed_points, frame.cells)}
    else:
        from .builder import build_model
        from .io.scenario import load_scenario

        model = build_model(load_scenario(path, args.set), path.parent)
        tables = {b.name: quality_statistics(b.mesh) for b in model.bodies}
    for name, stats in tables.items():
        print(f"{name}:")
        for key, value in stats.items():
            print(f"  {key:22s} {value:.6g}")
    return 0


def _compare(args: argparse.Namespace) -> int:
    return _print_comparison(Path(args.directory))


def _print_comparison(directory: Path) -> int:
    """The run's headline numbers beside the report's; also DIR/comparison.csv."""
    from .reference import compare, format_comparison, write_comparison_csv

    label, rows = compare(directory)
    print(format_comparison(label, rows))
    write_comparison_csv(directory / "comparison.csv", rows)
    return 0


def _validate(args: argparse.Namespace) -> int:
    """Run every example of the report and write DIR/report.html and report.md."""
    from tqdm import tqdm

    from .validation import CASES, validate

    out = Path(args.out)
    started: list[str] = []
    with tqdm(total=len(CASES), unit="case", disable=None) as bar:

        def progress(name: str) -> None:  # called as each case starts: count the finished one
            bar.update(1 if started else 0)
            started.append(name)
            bar.set_description(name)

        results = validate(out, quick=args.quick, progress=progress)
        bar.update(bar.total - bar.n)
    failed = [r.case.name for r in results if not r.passed()]
    print(f"report: {out / 'report.html'} ({len(results) - len(failed)} passed, "
          f"{len(failed)} failed{': ' + ', '.join(failed) if failed else ''})")
    return 0


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="ntncontact", description=__doc__)
    parser.add_argument("--version", action="version", version=f"ntncontact {__version__}")
    sub = parser.add_subparsers(dest="command", required=True)
    run = sub.add_parser("run", help="run a scenario file")
    run.add_argument("scenario", help="scenario TOML file")
    run.add_argument("--out", required=True, help="results folder")
    run.add_argument("--set", action="append", metavar="KEY=VALUE",
                     help="override a scenario key, e.g. analysis.mass=\"lumped\" (repeatable)")
    run.add_argument("--quiet", action="store_true", help="no progress bar")
    run.add_argument("--plot", action="store_true",
                     help="then write the figures of `ntncontact plot`")
    _figure_options(run, "(implies --plot)")
    run.add_argument("--compare", action="store_true",
                     help="then print the comparison with the report (as `ntncontact compare`)")
    run.set_defaults(func=_run)
    plot = sub.add_parser("plot", help="write PNG figures of a results folder")
    plot.add_argument("directory")
    _figure_options(plot)
    plot.set_defaults(func=_plot)
    val = sub.add_parser("validate", help="run the report's examples and write a report")
    val.add_argument("--out", required=True)
    val.add_argument("--quick", action="store_true", help="shortened runs (for CI)")
    val.set_defaults(func=_validate)
    comp = sub.add_parser("compare", help="compare a results folder with the report's numbers")
    comp.add_argument("directory")
    comp.set_defaults(func=_compare)
    quality = sub.add_parser("mesh-quality",
                             help="edge and angle statistics (report Table 4.1) of a scenario's "
                                  "meshes or of a VTU snapshot")
    quality.add_argument("path", help="scenario TOML or results VTU file")
    quality.add_argument("--set", action="append", metavar="KEY=VALUE")
    quality.set_defaults(func=_mesh_quality)
    return parser


def _figure_options(parser: argparse.ArgumentParser, note: str = "") -> None:
    parser.add_argument("--times", type=float, nargs="+", metavar="T",
                        help="draw the deformed meshes at these times (snapshots.png; "
                             "interpolated linearly between the output frames around a time "
                             "no frame was written at) instead of six evenly spaced ones "
                             f"(deformed_von_mises.png) {note}".strip())
    parser.add_argument("--gif", action="store_true",
                        help=f"also write animation.gif {note}".strip())


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        return int(args.func(args))
    except KeyboardInterrupt:
        print("interrupted: files written so far are valid", file=sys.stderr)
        return 130
    except (ValueError, RuntimeError, OSError) as err:
        print(f"error: {err}", file=sys.stderr)
        return 1


def console_main() -> None:
    """The ``ntncontact`` command: :func:`main`'s return value is the exit code."""
    sys.exit(main())


if __name__ == "__main__":  # pragma: no cover
    console_main()
