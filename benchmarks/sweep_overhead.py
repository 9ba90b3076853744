"""A sweep's overhead per case: scheduling, worker start-up, writing (issue 19, "Speed").

Runs N copies of the ring impact (report 6.4, t_end as given), or the sweep file given with
``--spec``, as one sweep on a LocalCluster of W single-threaded workers, and compares the
sweep with the cases' own run times (each summary's ``wall_time_s``: the time loop and its
writing, from the results writer's start to the summary's last write):

    wall overhead per case = (W * sweep wall time - sum of the cases' wall times) / N
    CPU overhead per case  = (CPU of the sweep's processes - sum of the cases' CPU) / N

Both count the cluster's start and close, the workers' imports and kernel loading, the
scheduling, each case's scenario loading, model building and reading back, the client's
writing of sweep.csv and figures, and any worker left idle while the other finishes. A
case's CPU is its summary's ``cpu_time_s`` less the CPU of the worker's other threads (Dask's
event loop, profiler, monitors) over the case: that is overhead, not the case's. The run
folder's frame-writing thread is the case's own and is counted back (from session 19;
sessions 16-18 counted it as overhead, ~0.17 s of a 1.9 s ring case).

``run_case`` is wrapped here (shipped by value) to stamp each case on its worker, so that the
overhead is also split into: before each worker's first case, around each run on its worker
(run_case's span - the case's own), between cases, and after each worker's last case.

Dask is imported by the sweep, inside the timing (as the ``ntncontact sweep`` command does).

Options: ``--warm``: the cases run on a cluster started (and warmed by one case) before the
timing, as a sweep on a running cluster (``--scheduler``) does. ``--dask-defaults``: the
LocalCluster with Dask's default settings instead of the sweep's ``LOCAL_DASK_CONFIG``.
``--base FILE``: the sweep module FILE (an earlier studies/sweep.py) instead of the package's,
for A/B comparisons.

Usage: python benchmarks/sweep_overhead.py [N] [W] [T_END] [--spec FILE] [--warm]
       [--dask-defaults] [--base FILE]
"""

from __future__ import annotations

import argparse
import importlib.util
import os
import resource
import sys
import tempfile
import time
from pathlib import Path

import pandas as pd

from ntncontact.studies import sweep as sweep_module

ROOT = Path(__file__).resolve().parents[1]
_run_case = sweep_module.run_case


def _frame_writers_cpu() -> float:
    """CPU seconds of this worker's frame-writing thread so far (``VtuSeriesWriter`` with
    ``background=True``, session 16): the case's own writing, not Dask's, but it runs beside
    the case's thread, so the thread-CPU split below would count it as overhead (~0.17 s of a
    1.9 s ring case, measured in session 19). The first call wraps the writer to count it;
    the count lives on the wrapper, in the worker's module, since this function is shipped by
    value with every case."""
    from ntncontact.io import vtk

    if not hasattr(vtk.VtuSeriesWriter._write_frame, "cpu"):
        original = vtk.VtuSeriesWriter._write_frame

        def counted(self, *args, **kwargs):
            start = time.thread_time()
            try:
                return original(self, *args, **kwargs)
            finally:
                counted.cpu += time.thread_time() - start

        counted.cpu = 0.0
        vtk.VtuSeriesWriter._write_frame = counted
    return vtk.VtuSeriesWriter._write_frame.cpu


def stamped_run_case(*args, **kwargs):
    """run_case with its worker, start and end (wall clock, comparable across the machine's
    processes), the CPU of its thread and of its whole worker process over its span, and the
    CPU of its frame-writing thread."""
    writer = _frame_writers_cpu()
    start, cpu, thread = time.time(), time.process_time(), time.thread_time()
    row = _run_case(*args, **kwargs)
    return row | {"_pid": os.getpid(), "_start": start, "_end": time.time(),
                  "_cpu": time.process_time() - cpu, "_thread_cpu": time.thread_time() - thread,
                  "_writer_cpu": _frame_writers_cpu() - writer}


def _cpu(scheduler: str | None = None) -> float:
    """CPU seconds of this process and of the workers: those of a running cluster asked
    directly (their earlier CPU is not the sweep's), those of a LocalCluster the sweep
    starts and closes counted as waited-for children."""
    own = resource.getrusage(resource.RUSAGE_SELF)
    total = own.ru_utime + own.ru_stime
    if scheduler is None:
        children = resource.getrusage(resource.RUSAGE_CHILDREN)
        return total + children.ru_utime + children.ru_stime
    from dask.distributed import Client

    with Client(scheduler) as client:
        return total + sum(client.run(time.process_time).values())


def _ring_spec(folder: Path, cases: int, t_end: float, offset: int = 0) -> Path:
    spec = folder / f"ring{offset}.toml"
    spec.write_text(f'scenario = "{ROOT / "examples" / "ring_impact.toml"}"\n'
                    f'[set]\n"analysis.t_end" = {t_end}\n'
                    f'[grid]\n"bodies.0.material.density" = '
                    f'{[1.0 + 1e-6 * (k + offset) for k in range(cases)]}\n')
    return spec


def _module(base: str | None):
    """The sweep module to time: the package's, or an earlier copy (client side only: the
    cases run the package's run_case through the stamped wrapper either way)."""
    if base is None:
        return sweep_module
    spec = importlib.util.spec_from_file_location("ntncontact.studies._sweep_base", base)
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # pydantic resolves the module's annotations through it
    spec.loader.exec_module(module)
    return module


def _breakdown(table: pd.DataFrame, t0: float, t1: float, workers: int) -> dict[str, float]:
    """Worker-seconds of the sweep that are no case's own, by where they fall."""
    parts = dict.fromkeys(("before the first case", "around the runs", "between cases",
                           "after the last case"), 0.0)
    idle_workers = workers - table["_pid"].nunique()  # a worker that ran no case at all
    parts["after the last case"] += idle_workers * (t1 - t0)
    for _, group in table.groupby("_pid"):
        group = group.sort_values("_start")
        starts, ends = group["_start"].to_numpy(), group["_end"].to_numpy()
        parts["before the first case"] += starts[0] - t0
        parts["between cases"] += (starts[1:] - ends[:-1]).sum()
        parts["around the runs"] += ((ends - starts) - group["wall_time_s"]).sum()
        parts["after the last case"] += t1 - ends[-1]
    return parts


def main(cases: int, workers: int, t_end: float, spec_file: str | None, warm: bool,
         dask_defaults: bool, base: str | None) -> None:
    module = _module(base)
    module.run_case = stamped_run_case
    if dask_defaults:
        module.LOCAL_DASK_CONFIG = {}
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        cluster = scheduler = None
        if warm:
            from dask.distributed import LocalCluster

            cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                                   dashboard_address=None,
                                   scheduler_kwargs=sweep_module.SCHEDULER_HTTP)
            scheduler = cluster.scheduler_address
            module.sweep(_ring_spec(tmp, workers, 0.05, offset=10**6), tmp / "warm",
                         scheduler=scheduler, progress=False)  # imports and kernels loaded
        spec = Path(spec_file).resolve() if spec_file else _ring_spec(tmp, cases, t_end)
        load = os.getloadavg()[0]
        cpu, start, t0 = _cpu(scheduler), time.perf_counter(), time.time()
        table = module.sweep(spec, tmp / "out", workers=workers, scheduler=scheduler,
                             progress=False)
        wall, t1 = time.perf_counter() - start, time.time()
        cpu = _cpu(scheduler) - cpu  # a new cluster's workers are waited for by now
        if cluster is not None:
            cluster.close()
    cases = len(table)
    runs = table["wall_time_s"].astype(float)
    # the worker's other threads, but the case's own frame writer
    dask_threads = table["_cpu"] - table["_thread_cpu"] - table["_writer_cpu"]
    run_cpu = table["cpu_time_s"].astype(float) - dask_threads
    wall_overhead = (workers * wall - runs.sum()) / cases
    cpu_overhead = (cpu - run_cpu.sum()) / cases
    kind = ("a warm running cluster" if warm else "a new LocalCluster") + (
        ", Dask's default settings" if dask_defaults else "") + (f", {base}" if base else "")
    what = spec_file or f"ring cases (t_end {t_end})"
    print(f"{cases} {what} on {workers} workers of {kind}; load {load:.1f} -> "
          f"{os.getloadavg()[0]:.1f}: sweep wall {wall:.2f} s, CPU {cpu:.2f} s; case wall "
          f"{runs.min():.2f}-{runs.max():.2f} s (mean {runs.mean():.2f}), case CPU mean "
          f"{run_cpu.mean():.2f} s (+ {dask_threads.mean():.3f} s of Dask's threads)")
    print(f"overhead per case: wall {wall_overhead:.3f} s = "
          f"{100 * wall_overhead / runs.mean():.1f} % of a case; CPU {cpu_overhead:.3f} s = "
          f"{100 * cpu_overhead / run_cpu.mean():.1f} % of a case")
    parts = _breakdown(table, t0, t1, workers)
    print("  worker-seconds: " + ", ".join(f"{name} {value:.2f}" for name, value in parts.items())
          + f" (sum {sum(parts.values()):.2f} = W x wall - sum of case walls "
          f"{workers * wall - runs.sum():.2f})")


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("numbers", nargs="*", type=float, help="N W T_END (6 2 1.0)")
    parser.add_argument("--spec", help="a sweep file instead of N ring cases")
    parser.add_argument("--warm", action="store_true")
    parser.add_argument("--dask-defaults", action="store_true")
    parser.add_argument("--base", help="an earlier sweep module to time instead")
    args = parser.parse_args()
    n, w, t = (list(args.numbers) + [6, 2, 1.0][len(args.numbers):])[:3]
    main(int(n), int(w), t, args.spec, args.warm, args.dask_defaults, args.base)
