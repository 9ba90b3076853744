"""Time each figure of a results folder in one warm process, as a figure worker draws it.

    python benchmarks/figures.py RESULTS_DIR OUT_DIR [--repeat N] [--prepare]

Prints, per figure, the minima over ``N`` repetitions of its wall and CPU times (seconds; the
CPU time of this process is less disturbed by other processes on a shared machine). The figures
are written to OUT_DIR (the results folder is only read), so that two versions of the code can
be compared image by image (benchmarks/compare_images.py): run it with
``PYTHONPATH=<other checkout>/src`` for the other version. ``--prepare``: before each figure,
untimed, what a figure worker does while the run goes on (the empty figure made ahead, the
frames read), if this code does it.
"""

from __future__ import annotations

import argparse
import inspect
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


def _prepare(name: str, results: Path) -> None:
    """What a figure worker does for this figure during the run (nothing in older code)."""
    from ntncontact import plotting as p

    if not hasattr(p, "prepare_figures"):
        return
    shapes = {"snapshots": p.panels_shape(len(TIMES)), "animation": p.ANIMATION_SHAPE,
              "pair_history": p.PAIR_SHAPE}
    p.prepare_figures([shapes.get(name, p.HISTORY_SHAPE)])
    if hasattr(p, "prefetch_frames") and name in ("snapshots", "animation", "pair_history"):
        if name == "animation" and "meshes" in inspect.signature(p.prefetch_frames).parameters:
            p.prefetch_frames(results, meshes=True)
        else:
            p.prefetch_frames(results)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("results", type=Path)
    parser.add_argument("out", type=Path)
    parser.add_argument("--repeat", type=int, default=5)
    parser.add_argument("--prepare", action="store_true")
    args = parser.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    from ntncontact import plotting

    plotting.warm_up()
    best: dict[str, tuple[float, float]] = {}
    for _ in range(args.repeat):
        for name, make in _figures(args.results, args.out).items():
            if args.prepare:
                _prepare(name, args.results)
            wall, cpu = time.perf_counter(), time.process_time()
            make()
            wall, cpu = time.perf_counter() - wall, time.process_time() - cpu
            old = best.get(name, (wall, cpu))
            best[name] = (min(old[0], wall), min(old[1], cpu))
    for name, (wall, cpu) in best.items():
        print(f"{name:18s} wall {wall:.3f}  cpu {cpu:.3f}")
    after = [v for k, v in best.items() if k != "snapshots"]
    print(f"{'after the run':18s} wall {sum(w for w, _ in after):.3f}  "
          f"cpu {sum(c for _, c in after):.3f} (sum: the GIF and the four others)")
    shutil.copy(Path(plotting.__file__), args.out / "plotting_used.py")  # which code drew


if __name__ == "__main__":
    main()
