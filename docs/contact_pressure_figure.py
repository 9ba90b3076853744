"""The figure of docs/outputs.md, "Contact pressure in ParaView": contact pressure along the
surface at a few times, from the field frames (VTU or XDMF), and over time at a few nodes,
from contact.csv.

Usage (from the repository root):

    .venv/bin/ntncontact run examples/hertz.toml --out results/hertz --set analysis.t_end=11
    .venv/bin/python docs/contact_pressure_figure.py results/hertz docs/figures/contact_pressure.png

The left panel is what ParaView shows with the frames coloured by ``contact_pressure`` and
"Plot Over Line" along the surface; the right one is its "Plot Data Over Time" of a node.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np
import pandas as pd

from ntncontact.io.vtk import find_field_series, read_frame, read_series


def pressure_along_surface(frame) -> tuple[np.ndarray, np.ndarray]:
    """(current x, contact pressure) of the nodes in contact, sorted along x."""
    nodes = np.flatnonzero(frame.point_data["contact_partner"] >= 0)
    x = frame.deformed_points[nodes, 0]
    order = np.argsort(x)
    return x[order], frame.point_data["contact_pressure"][nodes][order]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("results", type=Path)
    parser.add_argument("figure", type=Path)
    parser.add_argument("--frames", type=int, default=4, help="frames in the left panel")
    parser.add_argument("--nodes", type=int, default=3, help="nodes in the right panel")
    args = parser.parse_args()

    source = find_field_series(args.results)  # fields.pvd, or fields.xdmf
    if source is None:
        parser.error(f"no fields.pvd or fields.xdmf in {args.results}")
    series = [(t, frame) for t, frame in read_series(source) if t > 0.0]
    picked = [series[int(k)] for k in np.linspace(0, len(series) - 1, args.frames).round()]
    fig, (along, over) = plt.subplots(1, 2, figsize=(10, 4), constrained_layout=True)
    for time, frame in dict(picked).items():
        x, p = pressure_along_surface(read_frame(frame, time))
        along.plot(x, p, "o-", ms=3, label=f"t = {time:g}")
    along.set(xlabel="x (current position)", ylabel="contact_pressure (force / length)",
              title="along the surface (field frames)")
    along.legend()

    contact = pd.read_csv(args.results / "contact.csv")
    last = contact[contact["time"] == contact["time"].max()]
    for node in last.nlargest(args.nodes, "normal_traction")["node_1"]:
        rows = contact[contact["node_1"] == node]
        over.plot(rows["time"], rows["normal_traction"], "o-", ms=3, label=f"node {node}")
    over.set(xlabel="time", ylabel="normal_traction (force / length)",
             title="over time (contact.csv)")
    over.legend()
    args.figure.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(args.figure, dpi=110)
    print(f"wrote {args.figure}")


if __name__ == "__main__":
    main()
