"""The ``ntncontact`` command: run scenarios, plot results."""

from __future__ import annotations

import argparse
import contextlib
import os
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
    out = Path(args.out)
    writer = ResultWriter(out, model, scenario=str(scenario), title=config.title,
                          overrides=list(args.set or []))
    plotting = args.plot or args.gif or bool(args.times)
    with _figure_jobs(out, args) if plotting else contextlib.nullcontext() as figures:
        sim = Simulation(model, [writer] + ([figures.start(beside_a_run=True)] if figures else []))
        t_end = model.analysis.t_end
        with tqdm(total=t_end, unit="t", disable=args.quiet or None, desc=scenario.stem,
                  bar_format="{l_bar}{bar}| t={n:.4g}/{total:.4g} [{elapsed}<{remaining}]") \
                as bar:

            def progress(t: float) -> None:
                bar.update(t - bar.n)

            sim.run(progress)
        print(f"results written to {out} (history.csv, summary.json, fields.pvd)")
        if args.compare:  # while the figure workers draw
            _print_comparison(out)
        if figures:
            print("figures:", *figures.paths(), sep="\n  ")
    return 0


def _figure_jobs(directory: Path, args: argparse.Namespace):
    from .figure_jobs import FigureJobs

    return FigureJobs(directory, gif=args.gif, times=args.times)


def _plot(args: argparse.Namespace) -> int:
    with _figure_jobs(Path(args.directory), args) as figures:
        figures.start().submit_all()
        for path in figures.paths():
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


def _sweep(args: argparse.Namespace) -> int:
    """Run a sweep file's cases on Dask; write OUT/sweep.csv and the figures it asks for."""
    from .studies.sweep import SWEEP_FILE, sweep

    table = sweep(args.sweep, args.out, scheduler=args.scheduler, workers=args.workers,
                  progress=not args.quiet)
    failed = table[table["status"] != "completed"] if "status" in table else table.iloc[:0]
    skipped = int(table["skipped"].fillna(False).astype(bool).sum()) if "skipped" in table else 0
    print(f"{len(table)} cases ({skipped} already done, {len(failed)} not completed): "
          f"{Path(args.out) / SWEEP_FILE}")
    for _, row in failed.iterrows():
        print(f"  {row['case']}: {row.get('status')}: {row.get('error')}", file=sys.stderr)
    return 1 if len(failed) else 0


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
                     help="also write the figures of `ntncontact plot`, drawn on two worker "
                          "processes while the run goes on")
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
    sw = sub.add_parser("sweep", help="run one scenario over a grid or list of overrides on Dask")
    sw.add_argument("sweep", help="sweep TOML file (docs/api.md)")
    sw.add_argument("--out", required=True, help="sweep folder (cases/, sweep.csv, figures)")
    sw.add_argument("--scheduler", metavar="ADDRESS",
                    help="a running Dask scheduler (default: a local cluster, one worker a core)")
    sw.add_argument("--workers", type=int, help="local workers (default: one per core)")
    sw.add_argument("--quiet", action="store_true", help="no progress bar")
    sw.set_defaults(func=_sweep)
    quality = sub.add_parser("mesh-quality",
                             help="edge and angle statistics (report Table 4.1) of a scenario's "
                                  "meshes or of a VTU snapshot")
    quality.add_argument("path", help="scenario TOML or results VTU file")
    quality.add_argument("--set", action="append", metavar="KEY=VALUE")
    quality.set_defaults(func=_mesh_quality)
    return parser


def _figure_options(parser: argparse.ArgumentParser, note: str = "") -> None:
    parser.add_argument("--times", type=float, nargs="+", metavar="T",
                        help="draw the deformed meshes nearest to these times (snapshots.png) "
                             "instead of six evenly spaced ones (deformed_von_mises.png) "
                             f"{note}".strip())
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


#: numpy's optional submodules that ``import scipy.sparse`` loads (its array-API layer copies
#: numpy's namespace, attribute by attribute) but that nothing in a run uses: ~0.08 s at
#: start-up. (numpy.ma and numpy.polynomial are used: by np.unique and by Numba's import.)
UNUSED_NUMPY_MODULES = ("numpy.f2py", "numpy.testing", "numpy.ctypeslib")


def defer_imports(names: tuple[str, ...]) -> list[str]:
    """Make the modules ``names`` (not yet imported) load at the first use of one of their
    attributes instead of at their import (the standard library's ``LazyLoader``); return the
    names deferred. Their parent packages are imported now."""
    import importlib.util

    deferred = []
    for name in names:
        if name in sys.modules:
            continue
        spec = importlib.util.find_spec(name)
        if spec is None or spec.loader is None:
            continue
        spec.loader = importlib.util.LazyLoader(spec.loader)
        module = importlib.util.module_from_spec(spec)
        sys.modules[name] = module
        spec.loader.exec_module(module)
        parent, _, child = name.rpartition(".")
        setattr(sys.modules[parent], child, module)  # numpy's own lazy __getattr__ would recurse
        deferred.append(name)
    return deferred


def console_main() -> None:
    """The ``ntncontact`` command: :func:`main`, then the process ends without the
    interpreter's teardown, which spent ~0.4 s after every run releasing the compiled kernels
    (LLVM). When main returns, every results file is closed and the figure workers have
    exited, so only the standard streams are left to flush. An exception main does not handle
    still ends the process normally, with its traceback."""
    defer_imports(UNUSED_NUMPY_MODULES)
    code = main()
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(code)


if __name__ == "__main__":  # pragma: no cover
    console_main()
