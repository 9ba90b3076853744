"""Cost of the ALE mesh motion: the same impact run with the partner body ALE and Lagrangian.

Usage: .venv/bin/python benchmarks/ale_step.py [--example ring_impact.toml] [--t-end 0.4]

Reports steps/s of both runs, the time spent in the mesh update (surface relocation,
respacing, smoothing, remap) and its share of the ALE run, the per-step overhead ratio, and the
time of one ALE body move (``move_ale_body``): median and mean over all calls of the run, wall
and thread CPU time (the CPU time is not inflated by other processes on a shared machine).
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from ntncontact.engine import mesh_motion, simulation
from ntncontact.engine.builder import build_model
from ntncontact.io.scenario import load_config

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"


def timed_run(
    example: str, t_end: float, motion: str, moves: list | None = None
) -> tuple[float, int, float]:
    """(wall time, steps, time inside the ALE mesh update, time rebuilding the mass) of one
    run; appends (wall, CPU) seconds of every ``move_ale_body`` call to ``moves``."""
    path = EXAMPLES / example
    config = load_config(path, [f"analysis.t_end={t_end}",
                                  f'bodies.1.mesh_motion="{motion}"'])
    model = build_model(config, path.parent)
    spent = [0.0]
    original = simulation.move_meshes

    def timed_move(*args, **kwargs):
        start = time.perf_counter()
        try:
            return original(*args, **kwargs)
        finally:
            spent[0] += time.perf_counter() - start

    original_body = mesh_motion.move_ale_body

    def timed_body(*args, **kwargs):
        start, cpu = time.perf_counter(), time.thread_time()
        try:
            return original_body(*args, **kwargs)
        finally:
            if moves is not None:
                moves.append((time.perf_counter() - start, time.thread_time() - cpu))

    original_mass = simulation.Simulation._dof_mass
    mass_time = [0.0]

    def timed_mass(self, state):
        start = time.perf_counter()
        try:
            return original_mass(self, state)
        finally:
            mass_time[0] += time.perf_counter() - start

    simulation.move_meshes = timed_move
    mesh_motion.move_ale_body = timed_body
    simulation.Simulation._dof_mass = timed_mass
    try:
        sim = simulation.Simulation(model)
        start = time.perf_counter()
        sim.run()
        wall = time.perf_counter() - start
    finally:
        simulation.move_meshes = original
        mesh_motion.move_ale_body = original_body
        simulation.Simulation._dof_mass = original_mass
    return wall, sim.state.step, spent[0], mass_time[0]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--example", default="ring_impact.toml")
    parser.add_argument("--t-end", type=float, default=0.4)
    args = parser.parse_args()
    timed_run(args.example, 0.02, "lagrangian")  # warm up Numba and imports
    timed_run(args.example, 0.1, "ale")  # and the ALE kernels (first contact ~ t = 0.065)
    lag, steps, _, _ = timed_run(args.example, args.t_end, "lagrangian")
    moves: list[tuple[float, float]] = []
    ale, steps_ale, motion, mass = timed_run(args.example, args.t_end, "ale", moves)
    print(f"{args.example} to t = {args.t_end} ({steps} steps)")
    print("| run | wall s | steps/s | mesh update s | share |")
    print("| --- | ---: | ---: | ---: | ---: |")
    print(f"| Lagrangian partner | {lag:.2f} | {steps / lag:.1f} | - | - |")
    print(f"| ALE partner | {ale:.2f} | {steps_ale / ale:.1f} | {motion:.2f} | "
          f"{motion / ale:.0%} |")
    print(f"ALE run / Lagrangian run: {ale / lag:.2f}; mesh update alone adds "
          f"{motion / lag:.0%} to the Lagrangian run's time; with the mass rebuilt after each "
          f"move ({mass:.2f} s) the ALE work adds {(motion + mass) / lag:.0%}")
    if moves:
        wall_ms, cpu_ms = 1e3 * np.array(moves).T
        print(f"move_ale_body: {len(moves)} calls, median {np.median(wall_ms):.2f} ms wall "
              f"({np.median(cpu_ms):.2f} ms CPU), mean {wall_ms.mean():.2f} ms wall "
              f"({cpu_ms.mean():.2f} ms CPU), total {wall_ms.sum() / 1e3:.2f} s")


if __name__ == "__main__":
    main()
