"""Size and write time of the field frames: VTU (a file a frame + PVD) against one XDMF + HDF5
time series (``analysis.field_format``), on the ring impact mesh refined ``--refine`` times in
each direction (ring n_radial, n_circ; obstacle nx, ny).

Usage: .venv/bin/python benchmarks/field_formats.py [--refine 4 8] [--frames 40] [--rounds 2]

The frames are those a run writes (every field of docs/outputs.md, "Fields of a frame"), of a
state with a smooth deformation (the field computation is timed apart: the same for both
formats). Rounds alternate the formats (VTU, XDMF, VTU, XDMF, ...) so that the load of a
shared machine falls on both alike; per format the best round is reported, with process CPU
time beside wall time.
"""

from __future__ import annotations

import argparse
import shutil
import tempfile
import time
from pathlib import Path

import numpy as np

from ntncontact.engine.builder import build_model
from ntncontact.engine.postprocess import contact_node_fields, stress_fields
from ntncontact.io.scenario import load_config
from ntncontact.io.vtk import VtuSeriesWriter, XdmfSeriesWriter

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"
DISTINCT = 5  # distinct frames, written in turn


def refined_ring(factor: int):
    overrides = [f"bodies.0.mesh.n_radial={4 * factor}", f"bodies.0.mesh.n_circ={48 * factor}",
                 f"bodies.1.mesh.nx={40 * factor}", f"bodies.1.mesh.ny={4 * factor}"]
    path = EXAMPLES / "ring_impact.toml"
    return build_model(load_config(path, overrides), path.parent)


def frame_data(model, k: int):
    """Point and cell data of frame k: a smooth, frame-dependent deformation."""
    X = model.X0
    s = 1e-3 * (k + 1)
    d = np.column_stack([s * np.sin(X[:, 1]), -s * X[:, 0] ** 2])
    x = X + d
    t0 = time.perf_counter()
    cell, nodal = stress_fields(model, X, x)
    compute = time.perf_counter() - t0
    point = {"displacement": d, "velocity": d, "acceleration": d, "mesh_velocity": d,
             "material_position": X} | nodal | contact_node_fields(None, len(X))
    cell = cell | {"body_id": model.body_of_cell().astype(float)}
    return X, point, cell, compute


def write_series(kind, model, frames, count: int, folder: Path) -> tuple[float, float, int]:
    """(wall s, CPU s, bytes on disk) of writing ``count`` frames (cycling ``frames``)."""
    if folder.exists():
        shutil.rmtree(folder)
    wall, cpu = time.perf_counter(), time.process_time()
    writer = kind(folder)
    for k in range(count):
        X, point, cell = frames[k % len(frames)]
        writer.write(k, 0.01 * k, X, model.cells, point, cell)
    if hasattr(writer, "close"):
        writer.close()
    wall, cpu = time.perf_counter() - wall, time.process_time() - cpu
    size = sum(f.stat().st_size for f in folder.rglob("*") if f.is_file())
    return wall, cpu, size


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--refine", type=int, nargs="+", default=[4, 8])
    parser.add_argument("--frames", type=int, default=40)
    parser.add_argument("--rounds", type=int, default=2)
    args = parser.parse_args()
    print("| refine | elements | nodes | format | frames | size (MB) | per frame (kB) | "
          "write wall (s) | write CPU (s) | per frame (ms) |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for factor in args.refine:
        model = refined_ring(factor)
        data, computes = [], []
        for k in range(min(args.frames, DISTINCT)):  # memory: 8x holds 23k nodes x 60 values
            X, point, cell, compute = frame_data(model, k)
            data.append((X, point, cell))
            computes.append(compute)
        best: dict = {}
        with tempfile.TemporaryDirectory() as tmp:
            for _ in range(args.rounds):
                for name, kind in (("vtu", VtuSeriesWriter), ("xdmf", XdmfSeriesWriter)):
                    result = write_series(kind, model, data, args.frames, Path(tmp) / name)
                    if name not in best or result[0] < best[name][0]:
                        best[name] = result
        for name, (wall, cpu, size) in best.items():
            print(f"| {factor}x | {len(model.cells)} | {model.n_nodes} | {name} | {args.frames} "
                  f"| {size / 1e6:.1f} | {size / 1e3 / args.frames:.0f} | {wall:.2f} | {cpu:.2f} "
                  f"| {1e3 * wall / args.frames:.1f} |")
        print(f"|   field computation (both formats): {1e3 * np.median(computes):.1f} ms a "
              "frame (median) |||||||||")


if __name__ == "__main__":
    main()
