"""Time each figure of a results folder in one warm process.

    python benchmarks/figures.py RESULTS_DIR OUT_DIR [--repeat N]

Prints, per figure, the minima over ``N`` repetitions of its wall and CPU times (seconds; the
CPU time of this process is less disturbed by other processes on a shared machine). The figures
are written to OUT_DIR (the results folder is only read), so that two versions of the code can
be compared image by image (benchmarks/compare_images.py): run it with
``PYTHONPATH=<other checkout>/src`` for the other version. The first repetition pays the
process's one-off work (fonts, colour maps); the minima leave it out.
"""

from __future__ import annotations

import argparse
import shutil
import time
from pathlib import Path

TIMES = (0.075, 0.145, 0.285, 0.425, 0.565, 0.805)  # the demo's snapshots


def _figures(results: Path, out: Path) -> dict:
    from ntncontact.report import plotting as p

    return {
        "snapshots": lambda: p.plot_deformed(results, TIMES, path=out / "snapshots.png"),
        "animation": lambda: p.animate(results, out / "animation.gif"),
        "pair_history": lambda: p.plot_pair_history(results, out / "pair_history.png"),
        "contact_tractions": lambda: p.plot_contact_tractions(
            results, path=out / "contact_tractions.png"),
        "energies": lambda: p.plot_energies(results, out / "energies.png"),
        "momenta": lambda: p.plot_momenta(results, out / "momenta.png"),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("results", type=Path)
    parser.add_argument("out", type=Path)
    parser.add_argument("--repeat", type=int, default=5)
    args = parser.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    from ntncontact.report import plotting

    best: dict[str, tuple[float, float]] = {}
    for _ in range(args.repeat):
        for name, make in _figures(args.results, args.out).items():
            wall, cpu = time.perf_counter(), time.process_time()
            make()
            wall, cpu = time.perf_counter() - wall, time.process_time() - cpu
            old = best.get(name, (wall, cpu))
            best[name] = (min(old[0], wall), min(old[1], cpu))
    for name, (wall, cpu) in best.items():
        print(f"{name:18s} wall {wall:.3f}  cpu {cpu:.3f}")
    print(f"{'all':18s} wall {sum(w for w, _ in best.values()):.3f}  "
          f"cpu {sum(c for _, c in best.values()):.3f}")
    shutil.copy(Path(plotting.__file__), args.out / "plotting_used.py")  # which code drew


if __name__ == "__main__":
    main()
