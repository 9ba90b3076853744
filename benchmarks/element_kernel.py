"""Element kernel (``fem/kernels_numba.py``): internal force and tangent, elements per second.

Usage::

    .venv/bin/python benchmarks/element_kernel.py                         # this tree, ~20 s
    .venv/bin/python benchmarks/element_kernel.py --baseline /tmp/old/src --rounds 3

Times ``NumbaAssembly.add`` (the compiled loop and its call) and ``Assembler.internal`` (plus
the force vector, CSR data and matrix) for force-only and tangent calls with a fixed reference
X, as within a Newton solve, and a force-only call right after X moved (ALE: the reference data
are recomputed), on the ring impact's mesh (352 Neo-Hookean elements), on it refined 8x per
direction (22,528) and on the 10,000-element distorted grid of ``run.py``. Each figure is the
minimum over batches of thread CPU time (time spent waiting for a core is not counted). With
``--baseline SRC`` (the ``src`` directory of another checkout, e.g. a ``git worktree`` of the
previous commit) each round runs both codes in fresh processes, interleaved, and the table gives
both and their ratio.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
EXAMPLE = ROOT / "examples" / "ring_impact.toml"


def best_us(fn: Callable[[], object], calls: int, batches: int = 7) -> float:
    """Smallest thread CPU time per call over ``batches`` batches of ``calls`` calls, in us."""
    fn()
    best = float("inf")
    for _ in range(batches):
        t = time.thread_time()
        for _ in range(calls):
            fn()
        best = min(best, (time.thread_time() - t) / calls)
    return best * 1e6


def measure_mesh(asm, X, x, calls: int) -> dict[str, float]:
    """us per call of the kernel alone and through Assembler.internal, fixed and moved X."""
    import inspect

    import numpy as np

    kernel = asm._numba_groups[0]
    force, data = np.zeros(asm.ndof), np.zeros(asm.pattern.nnz)
    em = asm.pattern.entry_map
    # the kernel's second argument: displacements since F = I + Grad d, positions before
    takes_d = "d" in inspect.signature(asm.internal).parameters
    u = x - X if takes_d else x

    def internal(need_tangent):
        if takes_d:
            return lambda: asm.internal(X, d=u, need_tangent=need_tangent)
        return lambda: asm.internal(X, x, need_tangent)

    def add(tangent_data):
        return lambda: kernel.add(X, u, asm.lam, asm.mu, em, force, tangent_data)

    moved = [X + 1e-9 * (k % 2) for k in range(2)]  # alternate: every call sees X moved
    it = iter(range(10**9))
    return {
        "force": best_us(add(None), calls),
        "tangent": best_us(add(data), calls),
        "internal_force": best_us(internal(False), calls),
        "internal_tangent": best_us(internal(True), calls),
        "force_X_moved": best_us(lambda: kernel.add(moved[next(it) % 2], u, asm.lam, asm.mu,
                                                    em, force, None), calls),
    }


def worker() -> None:
    """Measure the code on sys.path; print one JSON line."""
    sys.path.insert(0, str(ROOT / "benchmarks"))
    from run import GRIDS, deformed, distorted_grid, neo_hookean_assembler

    from ntncontact.engine.builder import build_model
    from ntncontact.io.scenario import load_config

    rng = __import__("numpy").random.default_rng(0)
    out = {}
    for name, refine, calls in (("ring", 1, 300), ("ring8", 8, 5)):
        overrides = [f"bodies.0.mesh.n_radial={4 * refine}", f"bodies.0.mesh.n_circ={48 * refine}",
                     f"bodies.1.mesh.nx={40 * refine}", f"bodies.1.mesh.ny={4 * refine}"]
        model = build_model(load_config(EXAMPLE, overrides), EXAMPLE.parent)
        X = model.X0.copy()
        x = X + 1e-3 / refine * rng.random(X.shape)
        out[name] = measure_mesh(model.assembler, X, x, calls)
        out[f"{name}_ne"] = len(model.assembler.cells)
    nodes, cells = distorted_grid(*GRIDS[10_000])
    out["grid"] = measure_mesh(neo_hookean_assembler(nodes, cells), nodes, deformed(nodes), 10)
    out["grid_ne"] = len(cells)
    print(json.dumps(out))


def run_worker(src: Path, cache: Path) -> dict:
    env = dict(os.environ, PYTHONPATH=str(src), NUMBA_CACHE_DIR=str(cache))
    res = subprocess.run([sys.executable, __file__, "--worker"], env=env, check=True,
                         capture_output=True, text=True)
    return json.loads(res.stdout.strip().splitlines()[-1])


def table(runs: dict[str, list[dict]]) -> str:
    names = list(runs)
    head = "| mesh | call | " + " | ".join(f"{n} us/call | {n} M elements/s" for n in names)
    lines = [head + (" | ratio |" if len(names) == 2 else " |"),
             "|" + " --- |" * 2 + " ---: |" * (2 * len(names) + (len(names) == 2))]
    for mesh in ("ring", "ring8", "grid"):
        ne = runs[names[0]][0][f"{mesh}_ne"]
        for call in runs[names[0]][0][mesh]:
            best = [min(r[mesh][call] for r in runs[n]) for n in names]
            cells = " | ".join(f"{t:.1f} | {ne / t:.2f}" for t in best)
            ratio = f" | {best[0] / best[1]:.2f}x" if len(names) == 2 else ""
            lines.append(f"| {mesh} ({ne}) | {call} | {cells}{ratio} |")
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--baseline", type=Path, help="src directory of the code to compare")
    parser.add_argument("--rounds", type=int, default=3, help="fresh processes per code")
    parser.add_argument("--worker", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.worker:
        return worker()
    codes = {"this": (ROOT / "src", ROOT / ".numba_cache")}
    if args.baseline:
        codes = {"baseline": (args.baseline, args.baseline.parent / ".numba_cache_bench"),
                 **codes}
    runs: dict[str, list[dict]] = {name: [] for name in codes}
    for _ in range(args.rounds):  # interleaved: the machine's speed drifts
        for name, (src, cache) in codes.items():
            runs[name].append(run_worker(src, cache))
    print(f"minimum over {args.rounds} processes x 7 batches, thread CPU time\n")
    print(table(runs))


if __name__ == "__main__":
    main()
