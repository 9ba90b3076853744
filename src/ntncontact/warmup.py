"""Compile the Numba kernels into their on-disk cache before the first run.

With a cold cache the first simulation spends about a minute compiling (element, contact and ALE
kernels, in that order, on one core). ``python -m ntncontact.warmup`` (run by ``make`` after
installing) compiles them on two processes side by side, each through the real code paths so
that exactly the type signatures a run uses are cached:

- a small ring impact with a Lagrangian obstacle: element and contact kernels, and the
  output's fields;
- the same impact with an ALE obstacle: the ALE kernels (the larger half); the element and
  contact kernels have no other form (one implementation each), so they are compiled by
  whichever process reaches them first and loaded from the cache by the other; then, in the
  same process, the impact with both bodies ALE (the ring a closed surface chain) and the
  obstacle's interior diffused, which reaches the remaining ALE paths (~0.5 s, its kernels
  compiled by then);
- where the run may assemble on several threads, two steps of a free block of
  2 x MIN_ELEMENTS_PER_THREAD elements: the threaded assembly, which every mesh of that many
  elements a material group takes (18-23 s inside a first 10^4-element run otherwise).

Numba compiles a kernel once per argument type, and a read-only array, a writable one and a
broadcast view are three types: the callers pass each kernel one form (``jit.read_only``), so
that the types these runs cache are the ones every run uses (the examples, validation and
the common configurations then compile nothing; ``tests/test_warmup_coverage.py`` checks
it). A branch these runs do not reach would still be compiled on first use, and the compile
note says so.

It also writes the package's Python bytecode (``__pycache__``), which the interpreter does not
write where ``PYTHONDONTWRITEBYTECODE`` is set (~0.15-0.2 s of every start otherwise).
"""

from __future__ import annotations

import compileall
import multiprocessing as mp
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

from . import jit
from .engine.builder import build_model
from .engine.postprocess import frame_fields
from .engine.simulation import Simulation
from .fem.kernels_numba import MIN_ELEMENTS_PER_THREAD
from .io.scenario import parse_scenario
from .package import kernel_cache_dir
from .threads import run_threads

#: Steps to run: contact starts at step 3 (initial gap 0.01, speed 1, dt 0.005); the ring is
#: off-centre by a third of an obstacle element so that its nodes land between the obstacle's
#: and the ALE mesh slides (and remaps) from the first contact step.
STEPS = 12
#: Steps of :func:`_closed_chain_scenario`: 6 were too few to reach the cell search
CLOSED_CHAIN_STEPS = 12


def _scenario(ale: bool) -> dict:
    obstacle = {
        "name": "obstacle",
        "mesh": {"type": "rectangle", "width": 2.0, "height": 0.25, "nx": 16, "ny": 2,
                 "origin": [-1.0, -0.25]},
        "material": {"model": "neo_hookean", "E": 400.0, "nu": 0.3, "density": 20.0},
    }
    if ale:
        obstacle |= {"mesh_motion": "ale", "ale": {"smoothing_layers": 1, "remap": "quadratic"}}
    return {
        "analysis": {"kind": "dynamic", "dt": 0.005, "t_end": STEPS * 0.005},
        "bodies": [
            {"name": "ring",
             "mesh": {"type": "annulus", "r_inner": 0.7, "r_outer": 1.0, "n_radial": 2,
                      "n_circ": 24, "center": [0.04, 1.01]},
             "material": {"model": "neo_hookean", "E": 800.0, "nu": 0.3, "density": 2.0},
             "initial": {"velocity": [0.0, -1.0]}},
            obstacle,
        ],
        "contact": [{"body_1": "ring", "surface_1": "outer", "body_2": "obstacle",
                     "surface_2": "top", "method": "augmented_lagrangian",
                     "law": "persistency", "penalty_normal": 1000.0,
                     "augmentation": {"gap_tolerance": 1e-6}}],
    }


def _closed_chain_scenario() -> dict:
    """The ALE impact with the ring ALE too (a closed surface chain, opened at each update)
    and the obstacle's interior moved by diffusion (``ale.interior = "displacement"``): paths
    the first ALE run does not take, which call kernels from Python that it calls only from
    other kernels or not at all (``slide_chain`` on an opened closed chain, the remap's cell
    search). Its kernels are compiled by then, with the same argument types (the callers keep
    each to one form), so it costs its run time only; it makes these calls part of what the
    warm-up runs, against which ``tests/test_warmup_coverage.py`` compares other runs."""
    data = _scenario(ale=True)
    data["analysis"]["t_end"] = CLOSED_CHAIN_STEPS * 0.005
    data["bodies"][0] |= {"mesh_motion": "ale", "ale": {"smoothing_layers": 1}}
    data["bodies"][1]["ale"] |= {"interior": "displacement"}
    return data


def _block_scenario() -> dict:
    """Two steps of a free spinning block just large enough for the threaded assembly."""
    n = int(np.ceil(np.sqrt(2 * MIN_ELEMENTS_PER_THREAD))) + 1
    return {
        "analysis": {"kind": "dynamic", "dt": 0.005, "t_end": 0.01},
        "bodies": [{"name": "block",
                    "mesh": {"type": "rectangle", "width": 1.0, "height": 1.0, "nx": n,
                             "ny": n},
                    "material": {"model": "neo_hookean", "E": 100.0, "nu": 0.3,
                                 "density": 1.0},
                    "initial": {"velocity": [0.1, 0.0], "angular_velocity": 1.0}}],
    }


def compile_threaded_assembly() -> float:
    """Seconds taken by two steps of :func:`_block_scenario` where runs use several threads
    (0 where they do not: the serial loop is the small runs')."""
    if run_threads() < 2:
        return 0.0
    start = time.perf_counter()
    Simulation(build_model(parse_scenario(_block_scenario(), Path("<warmup>")))).run()
    return time.perf_counter() - start


def exercise(ale: bool) -> Simulation:
    """Run the small impact for one kernel group (module doc) and return the finished run;
    the Lagrangian group also computes the output's fields of the last state (a frame's
    kernel, which the run itself does not call without a result writer)."""
    simulation = Simulation(build_model(parse_scenario(_scenario(ale), Path("<warmup>"))))
    simulation.run()
    if ale:
        Simulation(build_model(parse_scenario(_closed_chain_scenario(), Path("<warmup>")))).run()
    else:
        state = simulation.state
        frame_fields(simulation.model, state.X, state.d, [1])
    return simulation


def compile_group(ale: bool) -> float:
    """Seconds taken by :func:`exercise` (mostly compilation when the cache is cold)."""
    start = time.perf_counter()
    exercise(ale)
    return time.perf_counter() - start


def compile_bytecode(directory: Path = Path(__file__).parent) -> bool:
    """Write the bytecode of every module under ``directory`` that lacks an up-to-date one
    (whatever ``sys.dont_write_bytecode`` says: this is an installation step); True if all
    compiled."""
    return bool(compileall.compile_dir(directory, quiet=1))


def main() -> int:
    start = time.perf_counter()
    compile_bytecode()
    print(f"Compiling the Numba kernels into {kernel_cache_dir()} (cached for later runs)...",
          flush=True)
    jit.NOTE.said = True  # said here, not again by each process
    if "fork" in mp.get_all_start_methods():
        with ProcessPoolExecutor(max_workers=2, mp_context=mp.get_context("fork")) as pool:
            groups = [pool.submit(compile_group, ale) for ale in (True, False)]
            groups.append(pool.submit(compile_threaded_assembly))
            [group.result() for group in groups]
    else:
        for ale in (True, False):
            compile_group(ale)
        compile_threaded_assembly()
    print(f"Kernels compiled in {time.perf_counter() - start:.1f} s.")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
