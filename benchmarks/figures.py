"""Time each figure of a results folder in one warm process, as a figure worker draws it.

    python benchmarks/figures.py RESULTS_DIR OUT_DIR [--repeat N]

Prints, per figure, the minimum over ``N`` repetitions (seconds). The figures are written to
OUT_DIR (the results folder is only read), so that two versions of the code can be compared
image by image: run it with ``PYTHONPATH=<other checkout>/src`` for the other version.
"""

from __future__ import annotations

import argparse
import shutil
import time
from pathlib import Path

TIMES = (0.075, 0.145, 0.285, 0.425, 0.565, 0.805)  # the demo's snapshots


def _figures(results: Path, out: Path) -> dict:
    from ntncontact import plotting as p

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
    from ntncontact import plotting

    plotting.warm_up()
    best: dict[str, float] = {}
    for _ in range(args.repeat):
        for name, make in _figures(args.results, args.out).items():
            start = time.perf_counter()
            make()
            best[name] = min(best.get(name, float("inf")), time.perf_counter() - start)
    for name, seconds in best.items():
        print(f"{name:18s} {seconds:.3f}")
    print(f"{'after the run':18s} {sum(v for k, v in best.items() if k != 'snapshots'):.3f}"
          f" (sum, GIF and the four others)")
    shutil.copy(Path(plotting.__file__), args.out / "plotting_used.py")  # which code drew


if __name__ == "__main__":
    main()
