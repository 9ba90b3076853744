"""Write the gmsh meshes of the quasi-static examples (report 6.1 and 6.3).

The scenario generators have no way to name single nodes or parts of a surface, which these
examples need (a contact interface restricted to some nodes, point loads on chosen top nodes),
so their meshes are written here as gmsh 2.2 files with physical groups::

    .venv/bin/python examples/meshes/make_meshes.py

- ``block_sliding_block.msh``: the report 6.1 block, 20 x 10 unit squares at (5, 10), node for
  node the ``rectangle`` generator's mesh (same numbering, same edge/node sets) plus the node
  set ``bottom_inner`` (interface nodes 2-20 of the report, the corners left out).
- ``delamination_upper.msh``, ``delamination_lower.msh``: the two layers of report 6.3, 64 wide,
  32 x 5 elements of 2 x 2 each. The lower layer fills 0 <= y <= 10; the upper layer's bottom
  lies on y = 10 where the layers are tied and on y = 10.2 over the delamination (15 candidate
  pairs at x = 18, 20, ..., 46; its tips x = 16 and 48 are tied), its top on y = 20.2. Each
  has edge sets bottom/right/top/left (counter-clockwise) and ``delaminated_face`` (the
  interface face over the delamination, tip to tip), node sets ``tied`` (interface nodes
  x <= 16 and x >= 48), ``tips`` and ``delaminated`` (the 15 candidate nodes); the upper layer
  also ``load_18`` ... ``load_46`` (the top node at that x).
- ``hertz_cylinder_{1,2,3}.msh``: the report 6.2 half cylinder R = 400, flat face up on
  y = 400, lowest point at the origin, from ``hertz_cylinder_mesh(level)`` (contact-zone element
  size 6, 4, 3, uniform within 60 of the lowest point; the ``half_disk`` scenario type cannot set
  that uniform zone). Edge sets ``arc``, ``flat``; node sets ``bottom``, ``flat_center``.
"""

from __future__ import annotations

from pathlib import Path

import meshio
import numpy as np

from ntncontact.mesh.generators import hertz_cylinder_mesh, rectangle
from ntncontact.mesh.quadmesh import QuadMesh

HERE = Path(__file__).resolve().parent

# report 6.3 geometry
LAYER_WIDTH, LAYER_NX, LAYER_NY = 64.0, 32, 5
LAYER_THICKNESS, DELAMINATION_GAP = 10.0, 0.2
DELAMINATION_X = np.arange(18.0, 47.0, 2.0)  # the 15 candidate pairs, centred on x = 32
LOAD_X = DELAMINATION_X  # the loading length L = 28 lies over the delamination
HERTZ_RADIUS = 400.0


def write_msh(path: Path, mesh: QuadMesh, line_groups: dict[str, np.ndarray],
              point_groups: dict[str, np.ndarray]) -> None:
    """Quads in surface group 1 and one line/vertex block per named group (format 2.2)."""
    cells = [("quad", mesh.cells)]
    physical = [np.ones(mesh.n_cells, int)]
    field_data = {mesh.name: np.array([1, 2])}
    tag = 1
    for dim, groups in ((1, line_groups), (0, point_groups)):
        for name, members in groups.items():
            tag += 1
            data = np.asarray(members, dtype=np.int64).reshape(len(members), -1)
            cells.append(("line" if dim == 1 else "vertex", data))
            physical.append(np.full(len(data), tag))
            field_data[name] = np.array([tag, dim])
    points = np.column_stack([mesh.nodes, np.zeros(mesh.n_nodes)])
    out = meshio.Mesh(points, cells, cell_data={"gmsh:physical": physical,
                                                "gmsh:geometrical": physical},
                      field_data=field_data)
    meshio.gmsh.write(str(path), out, fmt_version="2.2", binary=False)


def block_sliding_block() -> tuple[QuadMesh, dict, dict]:
    mesh = rectangle(20.0, 10.0, 20, 10, origin=(5.0, 10.0), name="block")
    points = {name: mesh.node_sets[name] for name in (
        "corner_bottom_left", "corner_bottom_right", "corner_top_right", "corner_top_left")}
    points["bottom_inner"] = mesh.node_sets["bottom"][1:-1]
    lines = {name: mesh.edge_sets[name] for name in ("bottom", "right", "top", "left")}
    return mesh, lines, points


def _grid_cells(grid: np.ndarray) -> np.ndarray:
    return np.stack((grid[:-1, :-1], grid[:-1, 1:], grid[1:, 1:], grid[1:, :-1]),
                    axis=-1).reshape(-1, 4)


def _layer(bottom_y: np.ndarray, top_y: float, name: str) -> tuple[QuadMesh, np.ndarray]:
    """One layer: LAYER_NY rows spread evenly from ``bottom_y`` (per column) up to ``top_y``."""
    xs = np.linspace(0.0, LAYER_WIDTH, LAYER_NX + 1)
    t = np.linspace(0.0, 1.0, LAYER_NY + 1)[:, None]
    ys = bottom_y[None, :] + t * (top_y - bottom_y[None, :])
    grid = np.arange((LAYER_NX + 1) * (LAYER_NY + 1)).reshape(LAYER_NY + 1, LAYER_NX + 1)
    nodes = np.column_stack([np.tile(xs, LAYER_NY + 1), ys.ravel()])
    return QuadMesh(nodes, _grid_cells(grid), name=name), grid


def _layer_sets(grid: np.ndarray, face_row: int) -> tuple[dict, dict]:
    """Outer boundary edge sets and the interface sets of the layer face in row ``face_row``
    (0: the upper layer's bottom, -1: the lower layer's top)."""
    xs = np.linspace(0.0, LAYER_WIDTH, LAYER_NX + 1)
    slit = np.isin(np.round(xs, 9), DELAMINATION_X)
    tips = np.isin(np.round(xs, 9), DELAMINATION_X[[0, -1]] + [-2.0, 2.0])
    face = grid[face_row]
    span = face[np.flatnonzero(tips)[0]:np.flatnonzero(tips)[1] + 1]
    if face_row == -1:  # counter-clockwise: the lower layer's top runs right to left
        span = span[::-1]
    lines = {
        "bottom": np.column_stack([grid[0, :-1], grid[0, 1:]]),
        "right": np.column_stack([grid[:-1, -1], grid[1:, -1]]),
        "top": np.column_stack([grid[-1, 1:], grid[-1, :-1]]),
        "left": np.column_stack([grid[1:, 0], grid[:-1, 0]]),
        "delaminated_face": np.column_stack([span[:-1], span[1:]]),
    }
    points = {"tips": face[tips], "delaminated": face[slit], "tied": face[~slit]}
    return lines, points


def delamination_lower() -> tuple[QuadMesh, dict, dict]:
    """The lower layer of report 6.3 (body 2, E2 = 5e4), 0 <= y <= 10."""
    mesh, grid = _layer(np.zeros(LAYER_NX + 1), LAYER_THICKNESS, "lower")
    lines, points = _layer_sets(grid, -1)
    return mesh, lines, points


def delamination_upper() -> tuple[QuadMesh, dict, dict]:
    """The upper layer (body 1, E1 = 2e4): its bottom is on y = 10 where it is tied to the
    lower layer and on y = 10.2 over the delamination; top on y = 20.2."""
    xs = np.linspace(0.0, LAYER_WIDTH, LAYER_NX + 1)
    slit = np.isin(np.round(xs, 9), DELAMINATION_X)
    bottom_y = LAYER_THICKNESS + np.where(slit, DELAMINATION_GAP, 0.0)
    mesh, grid = _layer(bottom_y, 2.0 * LAYER_THICKNESS + DELAMINATION_GAP, "upper")
    lines, points = _layer_sets(grid, 0)
    for x_load in LOAD_X:
        points[f"load_{x_load:.0f}"] = grid[-1, np.isclose(xs, x_load)]
    return mesh, lines, points


def hertz_cylinder(level: int) -> tuple[QuadMesh, dict, dict]:
    mesh = hertz_cylinder_mesh(level, radius=HERTZ_RADIUS, center=(0.0, HERTZ_RADIUS))
    # the lowest point exactly on y = 0 (the foundation top): touching, not 1e-14 above it
    nodes = mesh.nodes.copy()
    nodes[np.abs(nodes) < 1e-9 * HERTZ_RADIUS] = 0.0
    mesh = mesh.with_nodes(nodes)
    lines = {name: mesh.edge_sets[name] for name in ("arc", "flat")}
    points = {name: mesh.node_sets[name] for name in ("bottom", "flat_center")}
    return mesh, lines, points


MESHES = {
    "block_sliding_block.msh": block_sliding_block,
    "delamination_lower.msh": delamination_lower,
    "delamination_upper.msh": delamination_upper,
    **{f"hertz_cylinder_{k}.msh": (lambda k=k: hertz_cylinder(k)) for k in (1, 2, 3)},
}


def main(directory: Path = HERE) -> list[Path]:
    written = []
    for filename, build in MESHES.items():
        mesh, lines, points = build()
        path = directory / filename
        write_msh(path, mesh, lines, points)
        written.append(path)
    return written


if __name__ == "__main__":
    for p in main():
        print(p)
