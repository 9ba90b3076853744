"""The remap's velocity correction (``ale.conservation.conserving_correction``): the package's
mass-block solve (SuperLU below ``MASS_CG_DOFS``, conjugate gradients from there) against a
sparse LU at every size (SuperLU, the package's solver for all sizes before session 53).

Usage::

    .venv/bin/python benchmarks/mass_correction.py      # whole bodies of 100^2-400^2 cells
    .venv/bin/python benchmarks/mass_correction.py --cells 250 --repeats 5
    .venv/bin/python benchmarks/mass_correction.py --example ring_impact.toml --t-end 0.4

A whole-body correction (S all dofs but a held bottom row and one more x: the dof block of
both components, as a supported body gives) of a uniform n x n body, each method in a fresh
process (its own peak resident memory): seconds of the correction, the process's peak memory,
and the momenta's and kinetic energy's errors. ``--example``: CPU seconds of a whole run with
either (the corrections there act on the cells around the moved nodes, 40-600 dofs: the
package factors them too, so the two should agree within the machine's noise).
"""

from __future__ import annotations

import argparse
import json
import resource
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import scipy.sparse as sp
from scipy.sparse.linalg import splu

from ntncontact.ale import conservation

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"


def superlu_solver(mass: sp.csr_matrix, dofs: np.ndarray):
    """The reference: SuperLU of the dof block with a symmetric ordering and no pivoting."""
    A = conservation._dof_block(mass, dofs)
    lu = splu(A, permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0,
              options={"SymmetricMode": True})
    return A, lu.solve


def whole_body(cells: int, method: str) -> dict:
    from ntncontact.engine.remap_conservation import body_mass
    from ntncontact.mesh.generators import rectangle

    if method == "superlu":
        conservation._mass_solver = superlu_solver
    mesh = rectangle(1.0, 1.0, cells, cells)
    rng = np.random.default_rng(1)
    mass = body_mass(mesh.nodes, mesh.cells, np.ones(len(mesh.cells)), False)
    v = rng.standard_normal(mesh.nodes.shape)
    momenta, kinetic = conservation.dof_momenta(mass, mesh.nodes, v)
    dofs = np.arange(2 * (cells + 1) + 1, v.size)
    start = time.perf_counter()
    out = conservation.conserving_correction(mass, mesh.nodes, v, dofs, 1.01 * momenta,
                                             0.97 * kinetic)
    seconds = time.perf_counter() - start
    after, k = conservation.dof_momenta(mass, mesh.nodes, out.v)
    peak_mb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    error = np.abs(after - 1.01 * momenta).max() / np.abs(momenta).max()
    return {"method": method, "cells": cells * cells, "dofs": int(dofs.size),
            "seconds": seconds, "peak_mb": peak_mb, "momenta_error": float(error),
            "energy_error": abs(k / (0.97 * kinetic) - 1)}


def example_run(example: str, t_end: float, method: str) -> dict:
    from ntncontact.engine.builder import build_model
    from ntncontact.engine.simulation import Simulation
    from ntncontact.io.scenario import load_config

    if method == "superlu":
        conservation._mass_solver = superlu_solver
    path = EXAMPLES / example
    model = build_model(load_config(path, [f"analysis.t_end={t_end}"]), path.parent)
    start = time.process_time()
    Simulation(model).run()
    return {"method": method, "example": example, "cpu_seconds": time.process_time() - start}


def in_child(arguments: list[str]) -> dict:
    output = subprocess.run([sys.executable, __file__, "--child", *arguments], check=True,
                            capture_output=True, text=True).stdout
    return json.loads(output.strip().splitlines()[-1])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cells", type=int, nargs="+", default=[100, 250, 400])
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--example")
    parser.add_argument("--t-end", type=float, default=0.4)
    parser.add_argument("--child", nargs="+", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.child:
        kind, method, *rest = args.child
        result = (whole_body(int(rest[0]), method) if kind == "body"
                  else example_run(rest[0], float(rest[1]), method))
        print(json.dumps(result))
        return
    methods = ("superlu", "package")
    if args.example:
        for _ in range(args.repeats):
            for method in methods:
                r = in_child(["example", method, args.example, str(args.t_end)])
                print(f"{args.example} to t = {args.t_end}: {method} "
                      f"{r['cpu_seconds']:.2f} s CPU")
        return
    print("| cells | dofs | method | s (median) | peak MB | momenta error | energy error |")
    print("| ---: | ---: | --- | ---: | ---: | ---: | ---: |")
    for cells in args.cells:
        for method in methods:
            runs = [in_child(["body", method, str(cells)]) for _ in range(args.repeats)]
            r = runs[0]
            print(f"| {r['cells']} | {r['dofs']} | {method} | "
                  f"{np.median([x['seconds'] for x in runs]):.3f} | "
                  f"{max(x['peak_mb'] for x in runs):.0f} | {r['momenta_error']:.1e} | "
                  f"{r['energy_error']:.1e} |")


if __name__ == "__main__":
    main()
