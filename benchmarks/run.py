"""Assembly and Newton-iteration benchmarks: ntncontact's NumPy and Numba kernels vs scikit-fem.

Usage: ``.venv/bin/python benchmarks/run.py [--quick]``. Writes a Markdown table to stdout and to
``benchmarks/results.md``. Every figure is the best of several repetitions (wall clock): on a
shared machine the best run is the one least disturbed by other processes.

1. Neo-Hookean internal force + tangent assembly on a distorted structured Q4 grid, in elements
   per second: the NumPy reference kernel, the Numba kernel (1 thread and the default thread
   count), and scikit-fem assembling the same tangent and force (ElementQuad1 vector basis, 2x2
   Gauss, hand-written Neo-Hookean forms) on the same mesh. Before timing, the scikit-fem tangent
   and force are checked against ours on a small mesh (must agree to round-off).
2. One Newton iteration of a clamped block under a top traction: assemble (Numba), eliminate the
   clamped dofs, factor and solve, per linear-solver backend. The first iteration of a pattern
   includes the solver's symbolic analysis; later ones reuse it.
"""

from __future__ import annotations

import argparse
import os
import platform
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

import numba  # noqa: E402
import numpy as np  # noqa: E402
import scipy  # noqa: E402
import scipy.sparse as sp  # noqa: E402

from ntncontact.fem.assembly import Assembler, MaterialGroup  # noqa: E402
from ntncontact.fem.kernels_numba import NumbaAssembly  # noqa: E402
from ntncontact.solvers.linear import LinearSolver, pardiso_available  # noqa: E402

#: Lame constants of the benchmark material (E = 1, nu = 0.3).
LAM, MU = 0.3 / (1.3 * 0.4), 1.0 / 2.6
#: Grid sizes (nx, ny) with nx * ny = 1e3 ... 1e6 elements over a 1.6 x 1 block.
GRIDS = {1_000: (40, 25), 10_000: (125, 80), 100_000: (400, 250), 1_000_000: (1250, 800)}


def distorted_grid(nx: int, ny: int, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Nodes (row by row) and counter-clockwise Q4 cells of [0, 1.6] x [0, 1]; interior nodes
    moved by up to 20% of the element size so that no two elements are alike."""
    rng = np.random.default_rng(seed)
    xs, ys = np.meshgrid(np.linspace(0, 1.6, nx + 1), np.linspace(0, 1.0, ny + 1))
    nodes = np.column_stack([xs.ravel(), ys.ravel()])
    inner = (xs.ravel() > 0) & (xs.ravel() < 1.6) & (ys.ravel() > 0) & (ys.ravel() < 1.0)
    nodes[inner] += 0.2 / ny * rng.uniform(-1, 1, (inner.sum(), 2))
    i, j = np.meshgrid(np.arange(nx), np.arange(ny))
    n0 = (j * (nx + 1) + i).ravel()
    return nodes, np.column_stack([n0, n0 + 1, n0 + nx + 2, n0 + nx + 1])


def deformed(nodes: np.ndarray, seed: int = 1) -> np.ndarray:
    """A finite stretch and shear with a small smooth perturbation (det F > 0 everywhere)."""
    X, Y = nodes[:, 0], nodes[:, 1]
    x = nodes + nodes @ np.array([[0.15, 0.1], [-0.05, -0.1]]).T
    x[:, 1] += 0.02 * np.sin(3 * X) * np.cos(2 * Y)
    return x


def best_time(fn: Callable[[], object], repeats: int, warmup: bool = True) -> float:
    """Smallest wall time of ``repeats`` calls (after one warm-up call: compilation, caches)."""
    return best_times(fn, repeats, warmup)[0]


def best_times(fn: Callable[[], object], repeats: int, warmup: bool = True
               ) -> tuple[float, float]:
    """Smallest wall time and smallest process CPU time (all threads) of ``repeats`` calls.

    CPU time does not count the time this process waited for a core, so on a loaded machine it
    tells what a serial kernel costs; for threaded code it is the work summed over threads.
    """
    if warmup:
        fn()
    wall = cpu = np.inf
    for _ in range(repeats):
        t, c = time.perf_counter(), time.process_time()
        fn()
        wall = min(wall, time.perf_counter() - t)
        cpu = min(cpu, time.process_time() - c)
    return wall, cpu


def repeats_for(ne: int) -> int:
    return 7 if ne <= 10_000 else 3 if ne <= 100_000 else 1


# ---------------------------------------------------------------- scikit-fem peer


def skfem_forms():
    """Neo-Hookean tangent and internal-force forms for scikit-fem (same model as ours):
    dv : A : du = mu dv:du + (mu - lam ln J) tr(dv Fi du Fi) + lam tr(Fi dv) tr(Fi du)."""
    from skfem import BilinearForm, LinearForm
    from skfem.helpers import ddot, det, grad, inv

    def kinematics(w):
        g = w["d"].grad
        F = g + np.eye(2)[:, :, None, None]
        return F, inv(F), np.log(det(F))

    def mm(A, B):
        return np.einsum("ij...,jk...->ik...", A, B)

    def tr(A):
        return A[0, 0] + A[1, 1]

    @BilinearForm
    def tangent(du, v, w):
        F, Fi, lnJ = kinematics(w)
        gu, gv = grad(du), grad(v)
        return (MU * ddot(gv, gu) + (MU - LAM * lnJ) * tr(mm(mm(gv, Fi), mm(gu, Fi)))
                + LAM * tr(mm(Fi, gv)) * tr(mm(Fi, gu)))

    @LinearForm
    def force(v, w):
        F, Fi, lnJ = kinematics(w)
        FiT = np.swapaxes(Fi, 0, 1)
        return ddot(MU * (F - FiT) + LAM * lnJ * FiT, grad(v))

    return tangent, force


@dataclass
class SkfemPeer:
    """scikit-fem basis on our mesh (same node order and interleaved x/y dofs as ours)."""

    basis: object
    tangent: object
    force: object

    @classmethod
    def build(cls, nodes: np.ndarray, cells: np.ndarray) -> SkfemPeer:
        from skfem import Basis, ElementQuad1, ElementVector, MeshQuad

        mesh = MeshQuad(np.ascontiguousarray(nodes.T), np.ascontiguousarray(cells.T))
        basis = Basis(mesh, ElementVector(ElementQuad1()), intorder=3)  # 2x2 Gauss points
        assert basis.X.shape[1] == 4, "scikit-fem must use the 2x2 Gauss rule"
        return cls(basis, *skfem_forms())

    def assemble(self, d: np.ndarray, need_force: bool = True):
        field = self.basis.interpolate(d)
        K = self.tangent.assemble(self.basis, d=field)
        f = self.force.assemble(self.basis, d=field) if need_force else None
        return f, K


def check_skfem_matches(rtol: float = 1e-12) -> float:
    """scikit-fem's tangent and force equal ours on a small distorted mesh; returns the
    largest relative difference (both sum the same 2x2 Gauss point terms: round-off only)."""
    nodes, cells = distorted_grid(12, 8)
    x = deformed(nodes)
    asm = neo_hookean_assembler(nodes, cells)
    f, K, _ = asm.internal(nodes, d=x - nodes)
    f_sk, K_sk = SkfemPeer.build(nodes, cells).assemble((x - nodes).ravel())
    dK = abs(K - K_sk).max() / abs(K).max()
    df = np.abs(f - f_sk).max() / np.abs(f).max()
    if not max(dK, df) < rtol:
        raise AssertionError(f"scikit-fem disagrees with ntncontact: dK={dK:.2e}, df={df:.2e}")
    return max(dK, df)


# ---------------------------------------------------------------- our kernels


def neo_hookean_assembler(nodes: np.ndarray, cells: np.ndarray) -> Assembler:
    ne = len(cells)
    return Assembler(cells, len(nodes), [MaterialGroup("neo_hookean", np.arange(ne))],
                     np.full(ne, LAM), np.full(ne, MU), np.ones(ne))


def numpy_assembly(asm: Assembler, X: np.ndarray, x: np.ndarray):
    """The vectorized NumPy version of the element kernel (the tests' oracle since issue 15)."""
    sys.path.insert(0, str(ROOT / "tests"))
    from element_oracle import oracle_internal

    return oracle_internal(asm, X, x - X)


def numba_assembly(asm: Assembler, kernel: NumbaAssembly, X: np.ndarray, x: np.ndarray):
    """The Assembler's Numba path with a given thread setting."""
    asm._numba_groups = [kernel]
    return asm.internal(X, d=x - X)


@dataclass
class AssemblyRow:
    ne: int
    numpy: float  # elements per second
    numba_1: float  # serial: the default
    numba_1_cpu: float  # serial, from CPU time (insensitive to waiting for a core)
    numba_n: float  # numba.get_num_threads() threads
    skfem: float
    skfem_tangent: float
    skfem_basis_s: float


def assembly_row(ne: int, with_numpy: bool, with_skfem: bool) -> AssemblyRow:
    nodes, cells = distorted_grid(*GRIDS[ne])
    x = deformed(nodes)
    asm = neo_hookean_assembler(nodes, cells)
    reps = repeats_for(ne)
    elements = np.arange(ne)
    serial = NumbaAssembly("neo_hookean", cells, elements, threads=1)
    threaded = NumbaAssembly("neo_hookean", cells, elements, threads=numba.get_num_threads())
    t1, c1 = best_times(lambda: numba_assembly(asm, serial, nodes, x), reps)
    tn = best_time(lambda: numba_assembly(asm, threaded, nodes, x), reps)
    slow_reps, warm = max(reps // 2, 1), ne <= 10_000  # nothing to compile in NumPy/scikit-fem
    tnp = best_time(lambda: numpy_assembly(asm, nodes, x), slow_reps, warm) if with_numpy \
        else np.nan
    tsk = tsk_k = tbasis = np.nan
    if with_skfem:
        t = time.perf_counter()
        peer = SkfemPeer.build(nodes, cells)
        tbasis = time.perf_counter() - t
        d = (x - nodes).ravel()
        tsk = best_time(lambda: peer.assemble(d), slow_reps, warm)
        tsk_k = best_time(lambda: peer.assemble(d, need_force=False), slow_reps, warm)
    rate = lambda t: ne / t  # noqa: E731
    return AssemblyRow(ne, rate(tnp), rate(t1), rate(c1), rate(tn), rate(tsk), rate(tsk_k),
                       tbasis)


# ---------------------------------------------------------------- Newton iteration


@dataclass
class NewtonRow:
    ne: int
    ndof: int
    backend: str
    mode: str  # matrix type the solver chose
    assemble_s: float
    eliminate_s: float
    first_solve_s: float  # includes the symbolic analysis of the pattern
    solve_s: float  # numerical factorization + solve, analysis reused
    solve_cpu_s: float  # the same in CPU time summed over threads
    residual: float

    @property
    def iteration_s(self) -> float:
        return self.assemble_s + self.eliminate_s + self.solve_s


def clamped_block(ne: int):
    """Block clamped at the bottom, with a shear + compressive traction on the top edge."""
    nodes, cells = distorted_grid(*GRIDS[ne])
    nx, ny = GRIDS[ne]
    asm = neo_hookean_assembler(nodes, cells)
    free = np.flatnonzero(np.repeat(nodes[:, 1] > 0.0, 2))
    top = np.flatnonzero(np.isclose(nodes[:, 1], 1.0))
    f_ext = np.zeros_like(nodes)
    f_ext[top] = np.array([0.02, -0.03]) * 1.6 / nx  # nodal share of the traction
    f_ext[top[[0, -1]]] *= 0.5
    return nodes, asm, free, f_ext.ravel()


def newton_rows(ne: int, backends: list[str]) -> list[NewtonRow]:
    nodes, asm, free, f_ext = clamped_block(ne)
    x = nodes.copy()
    # one Newton update from the reference state, so that the timed iteration is nonlinear
    f_int, K, _ = asm.internal(nodes, d=x - nodes)
    dy = LinearSolver("superlu" if "pardiso" not in backends else "pardiso").solve(
        sp.csr_matrix(K[free][:, free]), (f_ext - f_int)[free])
    x.ravel()[free] += dy
    reps = 5  # factorizations are the noisiest figure on a shared machine
    d = x - nodes
    t_asm = best_time(lambda: asm.internal(nodes, d=d), reps)
    f_int, K, _ = asm.internal(nodes, d=d)
    t_elim = best_time(lambda: K[free][:, free], reps)
    A = sp.csr_matrix(K[free][:, free])
    b = (f_ext - f_int)[free]
    rows = []
    for backend in backends:
        solver = LinearSolver(backend)
        t = time.perf_counter()
        y = solver.solve(A, b)
        t_first = time.perf_counter() - t
        t_solve, c_solve = best_times(lambda solver=solver: solver.solve(A, b), reps)
        assert solver.stats.analyses == 1, "the analysis must be reused"
        mode = next(iter(solver._impls))
        mode = {True: "symmetric", False: "unsymmetric", None: "LU"}[mode]
        res = float(np.linalg.norm(A @ y - b) / np.linalg.norm(b))
        rows.append(NewtonRow(ne, A.shape[0], backend, mode, t_asm, t_elim, t_first, t_solve,
                              c_solve, res))
    return rows


# ---------------------------------------------------------------- report


def machine() -> str:
    cpu = platform.processor() or platform.machine()
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    return (f"{cpu}, {os.cpu_count()} cores, Numba threads {numba.get_num_threads()}, "
            f"load average at start {load:.1f}; Python {platform.python_version()}, "
            f"NumPy {np.__version__}, SciPy {scipy.__version__}, Numba {numba.__version__}, "
            f"scikit-fem {_version('skfem')}, pypardiso {_version('pypardiso')}")


def _version(module: str) -> str:
    try:
        from importlib.metadata import version

        return version({"skfem": "scikit-fem"}.get(module, module))
    except Exception:  # noqa: BLE001 - not installed
        return "absent"


def fmt_rate(r: float) -> str:
    return "-" if not np.isfinite(r) else f"{r / 1e6:.3f}" if r < 1e6 else f"{r / 1e6:.2f}"


def assembly_table(rows: list[AssemblyRow]) -> str:
    n = numba.get_num_threads()
    lines = [
        f"| elements | NumPy | Numba serial (default) | Numba serial, CPU time "
        f"| Numba {n} threads | scikit-fem K+f | scikit-fem K | Numba serial / scikit-fem K+f "
        "| Numba serial / NumPy |",
        "| ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: |",
    ]
    for r in rows:
        ratio_sk = r.numba_1 / r.skfem if np.isfinite(r.skfem) else np.nan
        ratio_np = r.numba_1 / r.numpy if np.isfinite(r.numpy) else np.nan
        lines.append(
            f"| {r.ne:,} | {fmt_rate(r.numpy)} | **{fmt_rate(r.numba_1)}** | "
            f"{fmt_rate(r.numba_1_cpu)} | {fmt_rate(r.numba_n)} | {fmt_rate(r.skfem)} | "
            f"{fmt_rate(r.skfem_tangent)} | "
            f"{'-' if not np.isfinite(ratio_sk) else f'{ratio_sk:.0f}x'} | "
            f"{'-' if not np.isfinite(ratio_np) else f'{ratio_np:.0f}x'} |")
    return "\n".join(lines)


def newton_table(rows: list[NewtonRow]) -> str:
    lines = [
        "| elements | dofs | backend | matrix mode | assemble s | eliminate s | first solve s "
        "| solve s (analysis reused) | solve CPU s | iteration s | relative residual |",
        "| ---: | ---: | --- | --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: |",
    ]
    for r in rows:
        lines.append(
            f"| {r.ne:,} | {r.ndof:,} | {r.backend} | {r.mode} | {r.assemble_s:.3f} "
            f"| {r.eliminate_s:.3f} | {r.first_solve_s:.3f} | {r.solve_s:.3f} "
            f"| {r.solve_cpu_s:.3f} "
            f"| **{r.iteration_s:.3f}** | {r.residual:.1e} |")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="small sizes only (~1 minute)")
    parser.add_argument("--out", type=Path, default=Path(__file__).with_name("results.md"))
    args = parser.parse_args(argv)
    sizes = [1_000, 10_000] if args.quick else list(GRIDS)
    newton_sizes = [10_000] if args.quick else [10_000, 100_000]
    backends = ["superlu"] + (["pardiso"] if pardiso_available() else [])

    header = f"Machine: {machine()}"
    print(header, flush=True)
    check = check_skfem_matches()
    print(f"scikit-fem tangent/force agree with ours to {check:.1e} (relative)", flush=True)
    rows = []
    for ne in sizes:
        rows.append(assembly_row(ne, with_numpy=True, with_skfem=True))
        print(f"  assembled {ne:,} elements", flush=True)
    newton = []
    for ne in newton_sizes:
        newton += newton_rows(ne, backends)
        print(f"  Newton iteration at {ne:,} elements", flush=True)

    report = "\n\n".join([
        "# ntncontact benchmark results" + (" (--quick)" if args.quick else ""),
        header,
        f"scikit-fem's tangent and force match ours to {check:.1e} (relative, 12 x 8 mesh).",
        "## Neo-Hookean force + tangent assembly, million elements per second "
        "(best of several runs)",
        assembly_table(rows),
        "Numba serial is the Assembler's default; the threaded variant splits the elements "
        "into one block per thread (seam elements deferred). scikit-fem K+f: tangent and "
        "internal-force forms; "
        "scikit-fem K: tangent only. Basis construction (scikit-fem) is not included: "
        + ", ".join(f"{r.skfem_basis_s:.2f} s at {r.ne:,}" for r in rows) + ".",
        "## One Newton iteration of a clamped block (assemble + eliminate + factor + solve)",
        "Serial Numba assembly; MKL (PARDISO) uses all cores.",
        newton_table(newton),
        "iteration s = assemble + eliminate + solve with the analysis reused (every Newton "
        "iteration after the first of a sparsity pattern).",
    ])
    print("\n" + report)
    args.out.write_text(report + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
