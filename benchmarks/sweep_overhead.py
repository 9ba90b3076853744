"""A sweep's overhead per case: scheduling, worker start-up, writing (issue 19, "Speed").

Runs N copies of the ring impact (report 6.4, t_end as given) as one sweep on a LocalCluster of
W single-threaded workers, and compares the sweep with the cases' own run times (each
summary's ``wall_time_s`` and ``cpu_time_s``: the time loop and its writing):

    wall overhead per case = (W * sweep wall time - sum of the cases' wall times) / N
    CPU overhead per case  = (CPU of the sweep's processes - sum of the cases' CPU times) / N

Both count the cluster's start-up and shut-down, the workers' imports and kernel loading,
the scheduling, the scenario loading, the model building and the results' collection. The
CPU figure (this process and every process it started, waited for) holds on a loaded
machine, where the wall figure does not.

With ``--warm`` the cases run on a cluster started (and warmed by one case) before the
timing, as a sweep on a running cluster (``--scheduler``) does: that measures what each case
costs beyond its own run, without the one-off start-up.

Usage: python benchmarks/sweep_overhead.py [N] [W] [T_END] [--warm]
"""

from __future__ import annotations

import resource
import sys
import tempfile
import time
from pathlib import Path

import ntncontact as ntc

ROOT = Path(__file__).resolve().parents[1]


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


def _spec(folder: Path, cases: int, t_end: float, offset: int = 0) -> Path:
    spec = folder / f"ring{offset}.toml"
    spec.write_text(f'scenario = "{ROOT / "examples" / "ring_impact.toml"}"\n'
                    f'[set]\n"analysis.t_end" = {t_end}\n'
                    f'[grid]\n"bodies.0.material.density" = '
                    f'{[1.0 + 1e-6 * (k + offset) for k in range(cases)]}\n')
    return spec


def main(cases: int = 6, workers: int = 2, t_end: float = 1.0, warm: bool = False) -> None:
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        cluster = scheduler = None
        if warm:
            from dask.distributed import LocalCluster

            cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                                   dashboard_address=None)
            scheduler = cluster.scheduler_address
            ntc.sweep(_spec(tmp, workers, 0.05, offset=10**6), tmp / "warm",
                      scheduler=scheduler, progress=False)  # imports and kernels loaded
        cpu, start = _cpu(scheduler), time.perf_counter()
        table = ntc.sweep(_spec(tmp, cases, t_end), tmp / "out", workers=workers,
                          scheduler=scheduler, progress=False)
        wall = time.perf_counter() - start
        cpu = _cpu(scheduler) - cpu  # a new cluster's workers are waited for by now
        if cluster is not None:
            cluster.close()
    runs, run_cpu = (table[k].astype(float) for k in ("wall_time_s", "cpu_time_s"))
    wall_overhead = (workers * wall - runs.sum()) / cases
    cpu_overhead = (cpu - run_cpu.sum()) / cases
    kind = "a warm running cluster" if warm else "a new LocalCluster"
    print(f"{cases} ring cases (t_end {t_end}) on {workers} workers of {kind}: sweep wall "
          f"{wall:.2f} s, CPU {cpu:.2f} s; case wall {runs.min():.2f}-{runs.max():.2f} s "
          f"(mean {runs.mean():.2f}), case CPU mean {run_cpu.mean():.2f} s")
    print(f"overhead per case: wall {wall_overhead:.2f} s = "
          f"{100 * wall_overhead / runs.mean():.1f} % of a case; CPU {cpu_overhead:.2f} s = "
          f"{100 * cpu_overhead / run_cpu.mean():.1f} % of a case")


if __name__ == "__main__":
    flags = [a for a in sys.argv[1:] if a.startswith("--")]
    numbers = [a for a in sys.argv[1:] if not a.startswith("--")]
    main(*(int(a) if i < 2 else float(a) for i, a in enumerate(numbers)), warm="--warm" in flags)
