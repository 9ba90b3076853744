"""Scaling of a contact run with the mesh: the ring impact, the fast-sliding blocks and Hertz,
every body refined k times in each direction (dt unchanged).

Usage::

    .venv/bin/python benchmarks/scaling.py                 # k = 1, 2, 4 (~10-20 min, loaded)
    .venv/bin/python benchmarks/scaling.py --k 1 2 4 8     # + k = 8 (make bench; ~15 min quiet)
    .venv/bin/python benchmarks/scaling.py --cases ring --k 1 2
    .venv/bin/python benchmarks/scaling.py --threads ring 4 2   # thread settings, A/B/C
    .venv/bin/python benchmarks/scaling.py --cases hertz_factor --k 8 \
        --set 'analysis.newton.factor_precision="double"'       # any scenario key, A/B

Each (case, k) runs in a fresh process (its own peak memory) as ``ntncontact run`` does:
results written by ``ResultWriter`` into a temporary folder. The dynamic cases run a window
that starts before the impact and covers ~15 contact steps (``CASES``); Hertz runs its 18
load steps. Reported per run: elements, unknowns, wall and CPU seconds per step, Newton
iterations and augmentations per step (over all steps and over the steps with contact), the
linear solver's analyses / factorizations / solves, the time per part of a step (exclusive:
a part's time excludes the parts it calls), the peak resident memory above the memory after
the model was built, PARDISO's own peak memory (MKL's count; part of the resident memory),
and, over k, the fitted exponent p of time ~ elements^p.

Parts: ``solve`` (LinearSolver.factorize, Factorization calls), ``assembly`` (element
internal forces and tangents, and the rest of StepProblem.residual/jacobian: mass, union
pattern, free-dof block, bordered matrix), ``contact`` (detection, contact and Lagrange
evaluations, augmentation, multiplier sensitivities), ``ALE`` (mesh motion, remap, the
moving mass), ``output`` (ResultWriter), ``other`` (the rest: Newton's own work, Python).

Kernels: the package's kernel cache (the one ``make`` fills), and each case first runs once at
k = 1 unreported (:func:`warm_up`), so that no reported run compiles a kernel. Before session
27 the script kept a cache of its own in the source tree, which ``make`` never filled: the
first run of each kernel set compiled in its timed loop (ring k = 1 on a cold cache 0.229
against ~0.02 s a step, and ring k = 8 run first 2.74 against 0.80 s a step), which also bent
the fitted exponents.

The machine is shared: report ratios and counts; wall times carry the load (printed).
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from collections import defaultdict
from collections.abc import Sequence
from functools import wraps
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
os.environ.setdefault("MPLBACKEND", "Agg")

import numpy as np  # noqa: E402

EXAMPLES = ROOT / "examples"

#: example file, window end time (None: the whole run), overrides for refinement k
CASES = {
    "ring": ("ring_impact.toml", 0.15, lambda k: [
        f"bodies.0.mesh.n_radial={4 * k}", f"bodies.0.mesh.n_circ={48 * k}",
        f"bodies.1.mesh.nx={40 * k}", f"bodies.1.mesh.ny={4 * k}"]),
    "fast_sliding": ("blocks_fast_sliding.toml", 0.093, lambda k: [
        f"bodies.0.mesh.nx={8 * k}", f"bodies.0.mesh.ny={21 * k}",
        f"bodies.1.mesh.nx={36 * k}", f"bodies.1.mesh.ny={5 * k}"]),
    "hertz": ("hertz.toml", None, lambda k: [
        f"bodies.1.mesh.nx={50 * k}", f"bodies.1.mesh.ny={3 * k}"]),
    # the same with the penalty from the mesh (contact.penalty_factor; 89 gives hertz.toml's
    # 1e6 at k = 1): eps_N grows as 1/h, as docs/scenarios.md advises for the gap law
    "hertz_factor": ("hertz.toml", None, lambda k: [
        f"bodies.1.mesh.nx={50 * k}", f"bodies.1.mesh.ny={3 * k}",
        "contact.0.penalty_normal=0", "contact.0.penalty_tangential=0",
        "contact.0.penalty_factor=89"]),
}
PARTS = ("solve", "assembly", "contact", "ALE", "output", "other")


class PartTimer:
    """Exclusive wall time per part: a wrapped call's time minus that of wrapped calls
    inside it (so that e.g. contact evaluated inside a residual counts as contact)."""

    def __init__(self) -> None:
        self.seconds: dict[str, float] = defaultdict(float)
        self._inner = [0.0]  # per open call: time spent in wrapped calls inside it

    def wrap(self, part: str, fn):
        @wraps(fn)
        def timed(*args, **kwargs):
            start = time.perf_counter()
            self._inner.append(0.0)
            try:
                return fn(*args, **kwargs)
            finally:
                elapsed = time.perf_counter() - start
                inner = self._inner.pop()
                self.seconds[part] += elapsed - inner
                self._inner[-1] += elapsed
        return timed

    def patch(self, owner, name: str, part: str) -> None:
        setattr(owner, name, self.wrap(part, getattr(owner, name)))


def instrument(timer: PartTimer) -> None:
    """Wrap the functions of each part where the step engine looks them up."""
    from ntncontact.dynamics.mass import MovingMass
    from ntncontact.engine import interfaces, problem, simulation
    from ntncontact.fem.assembly import Assembler
    from ntncontact.io.results import ResultWriter
    from ntncontact.solvers.linear import Factorization, LinearSolver

    timer.patch(LinearSolver, "factorize", "solve")
    timer.patch(Factorization, "__call__", "solve")
    timer.patch(Assembler, "internal", "assembly")
    timer.patch(problem.StepProblem, "residual", "assembly")
    timer.patch(problem.StepProblem, "jacobian", "assembly")
    for name in ("detect_all", "evaluate_all", "augment_all", "newton_update",
                 "lagrange_blocks", "commit_all"):
        timer.patch(simulation, name, "contact")
    timer.patch(interfaces, "evaluate_contact", "contact")
    timer.patch(interfaces.LagrangeTerm, "__call__", "contact")
    timer.patch(simulation, "move_meshes", "ALE")
    timer.patch(MovingMass, "matrix", "ALE")
    timer.patch(ResultWriter, "on_step", "output")


def hertz_mesh(k: int, directory: Path) -> Path:
    """The Hertz cylinder of mesh 1 with k times the elements along the arc and the radius
    (contact-zone size 6 / k), written as examples/meshes/make_meshes.py writes it."""
    sys.path.insert(0, str(EXAMPLES / "meshes"))
    import make_meshes

    from ntncontact.mesh.generators import _HERTZ_LEVELS, half_disk

    bottom_size, n_arc, n_radial = _HERTZ_LEVELS[1]
    mesh = half_disk(make_meshes.HERTZ_RADIUS, n_arc * k, n_radial * k,
                     bottom_size=bottom_size / k, center=(0.0, make_meshes.HERTZ_RADIUS),
                     name="cylinder", fine_half_width=60.0)
    nodes = mesh.nodes.copy()
    nodes[np.abs(nodes) < 1e-9 * make_meshes.HERTZ_RADIUS] = 0.0  # lowest point on y = 0
    mesh = mesh.with_nodes(nodes)
    path = directory / f"hertz_cylinder_k{k}.msh"
    make_meshes.write_msh(path, mesh, {n: mesh.edge_sets[n] for n in ("arc", "flat")},
                          {n: mesh.node_sets[n] for n in ("bottom", "flat_center")})
    return path


def resident_kb() -> int:
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE") // 1024


def child(case: str, k: int, out: Path, sets: Sequence[str] = ()) -> dict:
    """One run in this process; returns its figures."""
    from ntncontact.engine.builder import build_model
    from ntncontact.engine.simulation import Simulation
    from ntncontact.io.results import ResultWriter
    from ntncontact.io.scenario import load_config
    from ntncontact.solvers.linear import LinearSolver

    if os.environ.get("SCALING_THREADED_BLAS"):  # the A/B variant of --threads
        from contextlib import nullcontext

        from ntncontact.engine import simulation

        simulation.serial_blas = nullcontext
    filename, t_end, refine = CASES[case]
    overrides = refine(k) + list(sets)
    if case.startswith("hertz"):
        overrides.append(f"bodies.0.mesh.file={hertz_mesh(k, out.parent)}")
    if t_end is not None:
        overrides.append(f"analysis.t_end={t_end}")
    path = EXAMPLES / filename
    model = build_model(load_config(path, overrides), path.parent)
    timer = PartTimer()
    instrument(timer)
    solver = LinearSolver(precision=model.analysis.factor_precision)
    records = []

    class Counter:
        def on_step(self, model, record) -> None:
            records.append((record.newton_iterations, record.extra.get("augmentations", 0),
                            record.extra.get("active_pairs", 0)))

        def on_finish(self, status, error) -> None:
            records.append((status, error))

    sim = Simulation(model, [ResultWriter(out, model), Counter()], linear_solve=solver.solve)
    start_kb = resident_kb()
    wall, cpu = time.perf_counter(), time.process_time()
    error = None
    try:
        sim.run()
    except Exception as err:  # a failed run is reported, with the steps it completed
        error = f"{type(err).__name__}: {err}"[:200]
    wall, cpu = time.perf_counter() - wall, time.process_time() - cpu
    steps = [r for r in records[1:] if len(r) == 3]
    contact = [r for r in steps if r[2] > 0]
    n_steps = max(len(steps), 1)
    total = sum(timer.seconds.values())
    seconds = dict(timer.seconds) | {"other": max(wall - total, 0.0)}
    return {
        "case": case, "k": k, "elements": int(sum(b.cells.shape[0] for b in model.bodies)),
        "dofs": int(model.ndof), "steps": len(steps), "contact_steps": len(contact),
        "error": error, "s_per_step": wall / n_steps, "cpu_per_step": cpu / n_steps,
        "its_per_step": sum(r[0] for r in steps) / n_steps,
        "its_per_contact_step": sum(r[0] for r in contact) / max(len(contact), 1),
        "augs_per_contact_step": sum(r[1] for r in contact) / max(len(contact), 1),
        "parts_per_step": {p: seconds.get(p, 0.0) / n_steps for p in PARTS},
        "stats": vars(solver.stats), "backend": solver.backend,
        "peak_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
        "above_start_kb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss - start_kb,
        "pardiso_mb": pardiso_mb(solver),
    }


def pardiso_mb(solver) -> float:
    """PARDISO's own peak memory (MKL: max(iparm 15, iparm 16 + iparm 17), in KB), which
    tracemalloc does not see; 0 when the run did not use PARDISO."""
    peak = 0
    for impl in getattr(solver, "_impls", {}).values():
        p = getattr(impl, "pardiso", None)
        if p is not None:
            peak = max(peak, p.get_iparm(15), p.get_iparm(16) + p.get_iparm(17))
    return peak / 1024


def run_child(case: str, k: int, tmp: Path, env: dict | None = None, tag: str = "",
              sets: Sequence[str] = ()) -> dict:
    out = tmp / f"{case}_k{k}{tag}"
    command = [sys.executable, __file__, "--child", case, str(k), str(out)]
    proc = subprocess.run(command + [arg for item in sets for arg in ("--set", item)],
                          capture_output=True, text=True, env=os.environ | (env or {}))
    if proc.returncode != 0:
        return {"case": case, "k": k, "error": proc.stderr.strip().splitlines()[-1:]}
    return json.loads(proc.stdout.strip().splitlines()[-1])


def warm_up(cases: list[str], tmp: Path) -> None:
    """Run each case once at k = 1, unreported: a kernel the warm-up of ``make`` did not reach
    (a case's own branches) is compiled and cached here, not in a timed run."""
    for case in cases:
        run_child(case, 1, tmp, tag="_warm_up")


def exponent(rows: list[dict], value) -> float:
    """p of value ~ elements^p, least squares in log-log over the rows."""
    x = np.log([r["elements"] for r in rows])
    y = np.log([max(value(r), 1e-12) for r in rows])
    return float(np.polyfit(x, y, 1)[0]) if len(rows) > 1 else float("nan")


def report(rows: list[dict]) -> str:
    load = os.getloadavg()
    lines = [f"Machine: {os.cpu_count()} cores, load average {load[0]:.1f} / {load[1]:.1f} / "
             f"{load[2]:.1f} at the end (1 / 5 / 15 min).", "",
             "| case | k | elements | dofs | steps (contact) | s/step | CPU s/step | "
             "its/step | its/contact step | augs/contact step | analyses / factorizations "
             "/ solves | peak MB | KB/element above start | PARDISO MB | "
             + " | ".join(f"{p} s/step" for p in PARTS) + " |",
             "|" + " --- |" * 2 + " ---: |" * (12 + len(PARTS))]
    for r in rows:
        if "elements" not in r:
            lines.append(f"| {r['case']} | {r['k']} | failed: {r['error']} |")
            continue
        s = r["stats"]
        failed = f" (stopped: {r['error']})" if r["error"] else ""
        lines.append(
            f"| {r['case']} | {r['k']} | {r['elements']} | {r['dofs']} | {r['steps']} "
            f"({r['contact_steps']}){failed} | {r['s_per_step']:.3f} | {r['cpu_per_step']:.3f} "
            f"| {r['its_per_step']:.1f} | {r['its_per_contact_step']:.1f} "
            f"| {r['augs_per_contact_step']:.1f} | {s['analyses']} / {s['factorizations']} / "
            f"{s['solves']} | {r['peak_mb']:.0f} | {r['above_start_kb'] / r['elements']:.1f} | "
            f"{r.get('pardiso_mb', 0.0):.0f} | "
            + " | ".join(f"{r['parts_per_step'][p]:.4f}" for p in PARTS) + " |")
    lines += ["", "Fitted exponents p (time per step ~ elements^p over the k run):", "",
              "| case | s/step | CPU s/step | " + " | ".join(PARTS) + " | its/contact step |",
              "|" + " --- |" + " ---: |" * (3 + len(PARTS))]
    for case in dict.fromkeys(r["case"] for r in rows):
        ok = [r for r in rows if r["case"] == case and "elements" in r and not r["error"]]
        if len(ok) < 2:
            continue
        parts = [exponent(ok, lambda r, p=p: r["parts_per_step"][p]) for p in PARTS]
        lines.append(f"| {case} | {exponent(ok, lambda r: r['s_per_step']):.2f} "
                     f"| {exponent(ok, lambda r: r['cpu_per_step']):.2f} | "
                     + " | ".join(f"{p:.2f}" for p in parts)
                     + f" | {exponent(ok, lambda r: r['its_per_contact_step']):.2f} |")
    return "\n".join(lines)


#: --threads: the thread settings compared (environment of the child run)
THREAD_VARIANTS = {
    "chosen (BLAS serial in a run, assembly on run_threads(), PARDISO on pardiso_threads())": {},
    "BLAS threaded (before session 30)": {"SCALING_THREADED_BLAS": "1"},
    "PARDISO on 2 threads": {"MKL_NUM_THREADS": "2"},
    "Numba assembly on 1 thread": {"NUMBA_NUM_THREADS": "1"},
    "all on 1 thread (OMP_NUM_THREADS=1)": {"OMP_NUM_THREADS": "1"},
}


def thread_report(case: str, k: int, repeats: int, tmp: Path) -> str:
    """The thread variants run interleaved (A/B/C/A/B/C...), each ``repeats`` times."""
    runs: dict[str, list] = {name: [] for name in THREAD_VARIANTS}
    warm_up([case], tmp)
    for repeat in range(repeats):
        for index, (name, env) in enumerate(THREAD_VARIANTS.items()):
            runs[name].append(run_child(case, k, tmp, env, f"_t{index}_{repeat}"))
            print(f"{name}: {runs[name][-1].get('s_per_step', float('nan')):.3f} s/step",
                  flush=True)
    lines = [f"Thread settings, {case} k = {k}, {repeats} interleaved runs each (load average "
             f"{os.getloadavg()[0]:.1f} at the end):", "",
             "| setting | s/step (min, all) | CPU s/step (min) | solve s/step (min) "
             "| assembly s/step (min) | other s/step (min) | its/step |",
             "| --- | ---: | ---: | ---: | ---: | ---: | ---: |"]
    for name, rows in runs.items():
        ok = [r for r in rows if "s_per_step" in r]
        if not ok:
            continue
        walls = sorted(r["s_per_step"] for r in ok)
        lines.append(
            f"| {name} | {walls[0]:.3f} ({', '.join(f'{w:.3f}' for w in walls)}) "
            f"| {min(r['cpu_per_step'] for r in ok):.3f} "
            f"| {min(r['parts_per_step']['solve'] for r in ok):.3f} "
            f"| {min(r['parts_per_step']['assembly'] for r in ok):.3f} "
            f"| {min(r['parts_per_step']['other'] for r in ok):.3f} "
            f"| {ok[0]['its_per_step']:.1f} |")
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cases", nargs="+", choices=list(CASES), default=list(CASES))
    parser.add_argument("--k", nargs="+", type=int, default=[1, 2, 4])
    parser.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "scaling_results.md")
    parser.add_argument("--threads", nargs=3, metavar=("CASE", "K", "REPEATS"),
                        help="only compare the thread settings on one case (interleaved runs)")
    parser.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                        help="a scenario override for every run, e.g. "
                             "analysis.newton.factor_precision='\"double\"' (A/B runs)")
    parser.add_argument("--child", nargs=3, help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.child:
        case, k, out = args.child
        print(json.dumps(child(case, int(k), Path(out), args.set)))
        return
    if args.threads:
        case, k, repeats = args.threads
        with tempfile.TemporaryDirectory() as tmp:
            print(thread_report(case, int(k), int(repeats), Path(tmp)))
        return
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        warm_up(args.cases, Path(tmp))
        for case in args.cases:
            for k in args.k:
                rows.append(run_child(case, k, Path(tmp), sets=args.set))
                r = rows[-1]
                print(f"{case} k={k}: " + (f"{r['s_per_step']:.3f} s/step, "
                      f"{r['its_per_contact_step']:.1f} its/contact step"
                      if "elements" in r else f"failed {r['error']}"), flush=True)
    text = report(rows)
    print(text)
    args.out.write_text("# Scaling benchmark (benchmarks/scaling.py)\n\n" + text + "\n")


if __name__ == "__main__":
    main()
