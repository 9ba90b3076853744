"""A sweep's overhead per case: scheduling, worker start-up, writing (issue 19, "Speed").

Runs N copies of the ring impact (report 6.4, t_end as given) as one sweep on a LocalCluster of
W single-threaded workers, and compares the sweep's wall time with the cases' own run times
(``wall_time_s`` of each summary, the time loop and its writing):

    overhead per case = (W * sweep wall time - sum of the cases' run times) / N

which counts the cluster's start-up, the workers' imports and kernel loading, the scheduling
and the results' collection. Usage: python benchmarks/sweep_overhead.py [N] [W] [T_END]
"""

from __future__ import annotations

import sys
import tempfile
import time
from pathlib import Path

import ntncontact as ntc

ROOT = Path(__file__).resolve().parents[1]


def main(cases: int = 6, workers: int = 2, t_end: float = 1.0) -> None:
    with tempfile.TemporaryDirectory() as tmp:
        spec = Path(tmp) / "ring.toml"
        spec.write_text(f'scenario = "{ROOT / "examples" / "ring_impact.toml"}"\n'
                        f'[set]\n"analysis.t_end" = {t_end}\n'
                        f'[grid]\n"bodies.0.material.density" = '
                        f'{[1.0 + 1e-6 * k for k in range(cases)]}\n')
        start = time.perf_counter()
        table = ntc.sweep(spec, Path(tmp) / "out", workers=workers, progress=False)
        wall = time.perf_counter() - start
    runs = table["wall_time_s"].astype(float)
    overhead = (workers * wall - runs.sum()) / cases
    print(f"{cases} ring cases (t_end {t_end}) on {workers} workers: sweep {wall:.2f} s, "
          f"case run times {runs.min():.2f}-{runs.max():.2f} s (mean {runs.mean():.2f})")
    print(f"overhead per case {overhead:.2f} s = {100 * overhead / runs.mean():.1f} % of a case")


if __name__ == "__main__":
    main(*(int(a) if i < 2 else float(a) for i, a in enumerate(sys.argv[1:])))
