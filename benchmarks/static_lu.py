"""Static-pattern LU (``solvers/static_lu.py``) against SuperLU on the ring impact's tangent.

Usage::

    .venv/bin/python benchmarks/static_lu.py            # factor/solve times, ~20 s
    .venv/bin/python benchmarks/static_lu.py --loop 3   # + whole ring runs, ~2 minutes

1. The tangent of ``examples/ring_impact.toml`` after ``--steps`` steps (contact active) is
   captured from the run's own ``LinearSolver``; its factorization (analysis reused, as in
   every Newton iteration after a pattern's first) and solve are timed through
   ``LinearSolver`` with ``backend="superlu"``, ``"pardiso"`` (if installed) and
   ``"static"``: best of 7 batches.
2. ``--loop N``: the whole ring impact (200 steps, results written as ``ntncontact run``
   does) with ``backend="superlu"`` and ``"auto"`` (the static LU at this size), N runs each
   in fresh processes, interleaved (the machine is shared: the minimum is the least
   disturbed run). The runs' ``summary.json`` and ``history.csv`` are compared.
"""

from __future__ import annotations

import argparse
import csv
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
os.environ.setdefault("MPLBACKEND", "Agg")

import numpy as np  # noqa: E402
import scipy.sparse as sp  # noqa: E402

from ntncontact.engine.builder import build_model  # noqa: E402
from ntncontact.engine.simulation import Simulation  # noqa: E402
from ntncontact.io.scenario import load_config  # noqa: E402
from ntncontact.solvers.linear import LinearSolver, pardiso_available  # noqa: E402

EXAMPLE = ROOT / "examples" / "ring_impact.toml"


class CapturingSolver(LinearSolver):
    """A LinearSolver that keeps the last matrix it factored."""

    last: sp.csr_matrix | None = None

    def factorize(self, A):
        self.last = sp.csr_matrix(A, copy=True)
        return super().factorize(A)


def ring_matrix(steps: int) -> sp.csr_matrix:
    """The last tangent factored in the first ``steps`` steps of the ring impact."""
    model = build_model(load_config(EXAMPLE), EXAMPLE.parent)
    solver = CapturingSolver("superlu")
    sim = Simulation(model, linear_solve=solver.solve)
    for _ in range(steps):
        sim.state, _, _ = sim.step_with_cutback(model.analysis.dt)
    return solver.last


def per_call(fn, calls: int, batches: int = 7) -> float:
    """Smallest mean seconds per call over ``batches`` batches of ``calls`` calls."""
    fn()
    best = np.inf
    for _ in range(batches):
        start = time.perf_counter()
        for _ in range(calls):
            fn()
        best = min(best, (time.perf_counter() - start) / calls)
    return best


def time_backend(A: sp.csr_matrix, backend: str, b: np.ndarray) -> dict:
    solver = LinearSolver(backend)
    solver.factorize(A)  # the pattern's analysis (ordering, symbolic LU)
    factor = solver.factorize(A)
    x = factor(b)
    residual = np.linalg.norm(A @ x - b) / (abs(A).max() * np.linalg.norm(x))
    result = {"factor": per_call(lambda: solver.factorize(A), 100)}
    factor = solver.factorize(A)  # a PARDISO factor is replaced by each later factorization
    result |= {"solve": per_call(lambda: factor(b), 1000), "residual": residual, "x": x}
    assert solver.stats.fallbacks == 0 and solver.stats.analyses == 1
    return result


def matrix_report(steps: int) -> None:
    A = ring_matrix(steps)
    b = np.random.default_rng(0).standard_normal(A.shape[0])
    print(f"ring impact tangent after {steps} steps: {A.shape[0]} unknowns, {A.nnz} entries")
    superlu, static = time_backend(A, "superlu", b), time_backend(A, "static", b)
    pardiso = time_backend(A, "pardiso", b) if pardiso_available() else None
    difference = np.abs(static["x"] - superlu["x"]).max() / np.abs(superlu["x"]).max()
    print("| | SuperLU | PARDISO | static LU | SuperLU / static | PARDISO / static |\n"
          "| --- | ---: | ---: | ---: | ---: | ---: |")
    for key in ("factor", "solve"):
        p_ms = f"{1e3 * pardiso[key]:.3f}" if pardiso else "-"
        p_ratio = f"{pardiso[key] / static[key]:.2f}x" if pardiso else "-"
        print(f"| {key} (ms) | {1e3 * superlu[key]:.3f} | {p_ms} | {1e3 * static[key]:.3f} "
              f"| {superlu[key] / static[key]:.2f}x | {p_ratio} |")
    print(f"relative residuals: SuperLU {superlu['residual']:.1e}, static "
          f"{static['residual']:.1e}; solutions differ by {difference:.1e} (relative)")


def child_run(backend: str, out: str) -> None:
    """One whole ring run in this process; prints the time loop's wall time and the stats."""
    from ntncontact.io.results import ResultWriter

    model = build_model(load_config(EXAMPLE), EXAMPLE.parent)
    solver = LinearSolver(backend)
    sim = Simulation(model, [ResultWriter(out, model)], linear_solve=solver.solve)
    start, cpu = time.perf_counter(), time.process_time()
    sim.run()
    print(json.dumps({"wall": time.perf_counter() - start, "cpu": time.process_time() - cpu,
                      "stats": vars(solver.stats)}))


def loop_report(repeats: int) -> None:
    runs: dict[str, list] = {"superlu": [], "auto": []}
    with tempfile.TemporaryDirectory() as tmp:
        for k in range(repeats):
            for backend in runs:  # interleaved: both backends see the same machine load
                out = Path(tmp) / f"{backend}{k}"
                proc = subprocess.run([sys.executable, __file__, "--child", backend, str(out)],
                                      capture_output=True, text=True, check=True)
                runs[backend].append(json.loads(proc.stdout.strip().splitlines()[-1]))
                last = runs[backend][-1]
                print(f"  {backend:8s} run {k + 1}: {last['wall']:.2f} s wall, "
                      f"{last['cpu']:.2f} s CPU")
        print("| backend | time loop wall, min (all runs) s | CPU, min s | analyses "
              "| factorizations | fallbacks | solves |\n"
              "| --- | ---: | ---: | ---: | ---: | ---: | ---: |")
        for backend, results in runs.items():
            walls = sorted(r["wall"] for r in results)
            s = results[0]["stats"]
            print(f"| {backend} | {walls[0]:.2f} ({', '.join(f'{w:.2f}' for w in walls)}) "
                  f"| {min(r['cpu'] for r in results):.2f} | {s['analyses']} "
                  f"| {s['factorizations']} | {s['fallbacks']} | {s['solves']} |")
        compare_results(Path(tmp) / "superlu0", Path(tmp) / "auto0")


def compare_results(a: Path, b: Path) -> None:
    """Largest differences between two runs' summary.json numbers and history.csv columns."""
    sa, sb = (json.loads((d / "summary.json").read_text()) for d in (a, b))
    for key in ("energy_max_relative_variation", "max_penetration", "max_active_pairs",
                "newton_iterations"):
        if key in sa:
            print(f"{key}: superlu {sa[key]!r}, static {sb.get(key)!r}")
    ha, hb = (list(csv.DictReader((d / "history.csv").open())) for d in (a, b))
    differences = []
    for key in ha[0]:
        try:
            ca = np.array([float(row[key]) for row in ha])
            cb = np.array([float(row[key]) for row in hb])
        except ValueError:
            continue
        scale = np.abs(ca).max()
        if scale > 0:
            differences.append((np.abs(ca - cb).max() / scale, key, scale))
    significant = sorted(d for d in differences if d[2] > 1e-10)[-3:]
    tiny = sorted(d for d in differences if d[2] <= 1e-10)

    def listed(rows: list) -> str:
        return ", ".join(f"{key} {d:.1e} (largest {scale:.1e}, differs by {d * scale:.1e})"
                         for d, key, scale in reversed(rows))
    print(f"history.csv, {len(ha)} rows: largest differences of a column relative to its "
          f"largest value: {listed(significant)}; columns at round-off level throughout "
          f"(largest value <= 1e-10): {listed(tiny)}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=30, help="ring steps before the capture")
    parser.add_argument("--loop", type=int, default=0, help="whole ring runs per backend")
    parser.add_argument("--child", nargs=2, metavar=("BACKEND", "OUT"), help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.child:
        child_run(*args.child)
        return
    matrix_report(args.steps)
    if args.loop:
        loop_report(args.loop)


if __name__ == "__main__":
    main()
