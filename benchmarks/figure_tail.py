"""The demo's figure tail: from the end of the time loop to the process exit, A/B interleaved.

    python benchmarks/figure_tail.py [--repeat N] [--base DIR]

Runs the ``make demo`` command (``ntncontact run examples/ring_impact.toml --gif --times ...
--compare``) ``N`` times with this checkout's figure code and ``N`` times with the figure code
(plotting.py, figure_jobs.py) of ``DIR`` (another checkout's ``src/ntncontact``, e.g. a git
worktree of an earlier commit), alternately; everything else is this checkout's. Prints the
tail (end of ``Simulation.run`` to the exit of the process, as ``console_main`` ends it), the
whole wall time and the time loop (``Simulation.run``, which the workers beside it must not
slow down) of each run, then the minima and medians.
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

# The child: the figure modules of FIGURE_SRC (if set) replace this checkout's before the CLI
# imports them, Simulation.run notes when it returns, then main runs as console_main does.
CHILD = r"""
import importlib.util, json, os, sys, time
src = os.environ.get("FIGURE_SRC")
if src:
    import ntncontact
    for name in ("plotting", "figure_jobs"):
        spec = importlib.util.spec_from_file_location(f"ntncontact.{name}", f"{src}/{name}.py")
        module = importlib.util.module_from_spec(spec)
        sys.modules[spec.name] = module
        spec.loader.exec_module(module)
from ntncontact import cli, simulation
run, marks = simulation.Simulation.run, {}
def timed_run(self, *args, **kwargs):
    marks["loop_start"] = time.time()
    try:
        return run(self, *args, **kwargs)
    finally:
        marks["loop_end"] = time.time()
simulation.Simulation.run = timed_run
code = cli.main(sys.argv[1:])
marks["main_returned"] = time.time()
with open(os.environ["TAIL_MARKS"], "w") as handle:
    json.dump(marks, handle)
sys.stdout.flush()
os._exit(code)
"""


def run_once(figure_src: str | None, out: Path) -> tuple[float, float, float]:
    """(tail, wall, time loop) seconds of one demo run."""
    env = dict(os.environ, MPLBACKEND="Agg", NUMBA_CACHE_DIR=str(ROOT / ".numba_cache"))
    env.pop("FIGURE_SRC", None)
    if figure_src:
        env["FIGURE_SRC"] = figure_src
    with tempfile.NamedTemporaryFile(suffix=".json") as marks_file:
        env["TAIL_MARKS"] = marks_file.name
        start = time.time()
        subprocess.run([sys.executable, "-c", CHILD, *DEMO, "--out", str(out)], cwd=ROOT,
                       env=env, check=True, stdout=subprocess.DEVNULL)
        end = time.time()
        marks = json.loads(Path(marks_file.name).read_text())
    return end - marks["loop_end"], end - start, marks["loop_end"] - marks["loop_start"]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=5)
    parser.add_argument("--base", help="src/ntncontact of the checkout to compare with")
    args = parser.parse_args()
    variants = {"this": None} | ({"base": args.base} if args.base else {})
    results: dict[str, list[tuple[float, float, float]]] = {name: [] for name in variants}
    with tempfile.TemporaryDirectory() as scratch:
        for _ in range(args.repeat):
            for name, src in variants.items():
                tail, wall, loop = run_once(src, Path(scratch) / name)
                results[name].append((tail, wall, loop))
                print(f"{name:5s} tail {tail:.3f} s  wall {wall:.3f} s  loop {loop:.3f} s",
                      flush=True)
    for name, rows in results.items():
        tails, walls, loops = zip(*rows, strict=True)
        print(f"{name:5s} min tail {min(tails):.3f} s  min wall {min(walls):.3f} s  "
              f"min loop {min(loops):.3f} s  (medians {_median(tails):.3f} / "
              f"{_median(walls):.3f} / {_median(loops):.3f} s)")


def _median(values: tuple[float, ...]) -> float:
    return sorted(values)[len(values) // 2]


if __name__ == "__main__":
    main()
