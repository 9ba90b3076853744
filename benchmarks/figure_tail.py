"""The demo's figure tail: from the end of the time loop to the process exit, A/B interleaved.

    python benchmarks/figure_tail.py [--repeat N] [--base DIR]

Runs the ``make demo`` command (``ntncontact run examples/ring_impact.toml --gif --times ...
--compare``) ``N`` times with this checkout's figure code and command line and ``N`` times with
those of ``DIR`` (the report/plotting.py, figure_jobs.py if any, and cli.py of another checkout's
``src/ntncontact``, e.g. ``git show`` of an earlier commit's files into a folder),
alternately; everything else is this checkout's. Each run ends through its ``console_main``.
Prints the tail (end of ``Simulation.run`` to the exit of the process), the whole wall time,
the time loop (``Simulation.run``) and the CPU time of the process and its children of each
run, then the minima and medians.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
DEMO = ["run", "examples/ring_impact.toml", "--gif", "--quiet", "--compare",
        "--times", "0.075", "0.145", "0.285", "0.425", "0.565", "0.805"]

# The child: the modules of FIGURE_SRC (if set) replace this checkout's before the CLI
# imports them, Simulation.run writes when it started and ended, then the command runs.
CHILD = r"""
import importlib.util, json, os, sys, time
src = os.environ.get("FIGURE_SRC")
if src:
    import ntncontact
    for name in ("plotting", "figure_jobs", "cli"):
        if os.path.isfile(f"{src}/{name}.py"):
            spec = importlib.util.spec_from_file_location(f"ntncontact.{name}",
                                                          f"{src}/{name}.py")
            module = importlib.util.module_from_spec(spec)
            sys.modules[spec.name] = module
            spec.loader.exec_module(module)
from ntncontact import cli, simulation
run = simulation.Simulation.run
def timed_run(self, *args, **kwargs):
    start = time.time()
    try:
        return run(self, *args, **kwargs)
    finally:
        with open(os.environ["TAIL_MARKS"], "w") as handle:
            json.dump({"loop_start": start, "loop_end": time.time()}, handle)
simulation.Simulation.run = timed_run
sys.argv = ["ntncontact", *sys.argv[1:]]
cli.console_main()
"""


def run_once(figure_src: str | None, out: Path) -> tuple[float, float, float, float]:
    """(tail, wall, time loop, CPU) seconds of one demo run."""
    import resource

    env = dict(os.environ, MPLBACKEND="Agg")  # the package's kernel cache, as `make demo`
    env.pop("FIGURE_SRC", None)
    if figure_src:
        env["FIGURE_SRC"] = figure_src
    with tempfile.NamedTemporaryFile(suffix=".json") as marks_file:
        env["TAIL_MARKS"] = marks_file.name
        cpu = resource.getrusage(resource.RUSAGE_CHILDREN)
        start = time.time()
        subprocess.run([sys.executable, "-c", CHILD, *DEMO, "--out", str(out)], cwd=ROOT,
                       env=env, check=True, stdout=subprocess.DEVNULL)
        end = time.time()
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
        marks = json.loads(Path(marks_file.name).read_text())
    used = after.ru_utime + after.ru_stime - cpu.ru_utime - cpu.ru_stime
    return end - marks["loop_end"], end - start, marks["loop_end"] - marks["loop_start"], used


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=5)
    parser.add_argument("--base", help="src/ntncontact of the checkout to compare with")
    args = parser.parse_args()
    variants = {"this": None} | ({"base": args.base} if args.base else {})
    results: dict[str, list[tuple[float, ...]]] = {name: [] for name in variants}
    with tempfile.TemporaryDirectory() as scratch:
        for index in range(args.repeat):
            for name, src in variants.items():
                row = run_once(src, Path(scratch) / f"{name}_{index}")
                results[name].append(row)
                print(f"{name:5s} tail {row[0]:.3f} s  wall {row[1]:.3f} s  loop {row[2]:.3f} s"
                      f"  cpu {row[3]:.3f} s  load {os.getloadavg()[0]:.1f}", flush=True)
    for name, rows in results.items():
        tails, walls, loops, cpus = zip(*rows, strict=True)
        print(f"{name:5s} min tail {min(tails):.3f} s  min wall {min(walls):.3f} s  "
              f"min loop {min(loops):.3f} s  min cpu {min(cpus):.3f} s  (medians "
              f"{_median(tails):.3f} / {_median(walls):.3f} / {_median(loops):.3f} / "
              f"{_median(cpus):.3f} s)")


def _median(values: tuple[float, ...]) -> float:
    return sorted(values)[len(values) // 2]


if __name__ == "__main__":
    main()
