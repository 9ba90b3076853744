"""Write the gmsh meshes of the quasi-static examples (report 6.1 and 6.3).

The scenario generators have no way to name single interior nodes of a surface, which these
examples need (a contact interface restricted to some nodes, point loads on chosen top nodes),
so their meshes are written here as gmsh 2.2 files with physical groups::

    .venv/bin/python examples/meshes/make_meshes.py

- ``block_sliding_block.msh``: the report 6.1 block, 20 x 10 unit squares at (5, 10), node for
  node the ``rectangle`` generator's mesh (same numbering, same edge/node sets) plus the node
  set ``bottom_inner`` (interface nodes 2-20 of the report, the corners left out).
- ``delamination_layers.msh``: the two layers of report 6.3 as ONE body (the engine cannot tie
  two bodies), 64 wide, 32 x 5 elements of 2 x 2 per layer. The lower layer fills
  0 <= y <= 10; the upper layer's bottom is the lower layer's top where the layers are tied
  (shared nodes) and lies on y = 10.2 over the delamination, a slit with 15 candidate pairs at
  x = 18, 20, ..., 46 whose tips x = 16 and 48 are shared nodes; the upper rows are spread
  evenly up to y = 20.2. Edge sets bottom/right/top/left (outer boundary), ``slit_upper`` (the
  slit's upper face, tip to tip), ``slit_lower`` (its lower face between the first and last
  candidate: an interface's surfaces may not share the tips); node sets ``slit_tips``,
  ``delaminated`` and ``delaminated_lower`` (the 15 candidate nodes of each face),
  ``interface_tied`` (the shared interface nodes outside the slit), ``load_18`` ...
  ``load_46`` (the top node at that x).
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


def delamination_layers() -> tuple[QuadMesh, dict, dict]:
    """Both layers as one mesh: the lower layer's grid, then the upper layer's, whose bottom
    row reuses the lower layer's top nodes where the layers are tied."""
    nx, ny = LAYER_NX, LAYER_NY
    xs = np.linspace(0.0, LAYER_WIDTH, nx + 1)
    lower_y = np.linspace(0.0, LAYER_THICKNESS, ny + 1)
    lower = np.arange((nx + 1) * (ny + 1)).reshape(ny + 1, nx + 1)
    nodes = [np.column_stack([np.tile(xs, ny + 1), np.repeat(lower_y, nx + 1)])]
    slit = np.isin(np.round(xs, 9), DELAMINATION_X)
    bottom_y = LAYER_THICKNESS + np.where(slit, DELAMINATION_GAP, 0.0)
    top_y = 2.0 * LAYER_THICKNESS + DELAMINATION_GAP
    upper = np.empty((ny + 1, nx + 1), dtype=np.int64)
    upper[0] = lower[-1]
    n = lower.size
    upper[0, slit] = n + np.arange(slit.sum())  # the slit's upper face: new nodes
    nodes.append(np.column_stack([xs[slit], bottom_y[slit]]))
    n += slit.sum()
    for j in range(1, ny + 1):
        upper[j] = n + np.arange(nx + 1)
        nodes.append(np.column_stack([xs, bottom_y + j / ny * (top_y - bottom_y)]))
        n += nx + 1
    xy = np.vstack(nodes)

    def cells(grid: np.ndarray) -> np.ndarray:
        return np.stack((grid[:-1, :-1], grid[:-1, 1:], grid[1:, 1:], grid[1:, :-1]),
                        axis=-1).reshape(-1, 4)

    mesh = QuadMesh(xy, np.vstack([cells(lower), cells(upper)]), name="layers")
    tips = np.flatnonzero(np.isin(np.round(xs, 9), DELAMINATION_X[[0, -1]] + [-2.0, 2.0]))
    span = slice(tips[0], tips[1] + 1)
    lines = {
        "bottom": np.column_stack([lower[0, :-1], lower[0, 1:]]),
        "right": np.column_stack([np.r_[lower[:-1, -1], upper[:-1, -1]],
                                  np.r_[lower[1:, -1], upper[1:, -1]]]),
        "top": np.column_stack([upper[-1, 1:], upper[-1, :-1]]),
        "left": np.column_stack([np.r_[lower[1:, 0], upper[1:, 0]],
                                 np.r_[lower[:-1, 0], upper[:-1, 0]]]),
        "slit_upper": np.column_stack([upper[0, span][:-1], upper[0, span][1:]]),
        "slit_lower": np.column_stack([lower[-1, slit][1:], lower[-1, slit][:-1]]),
    }
    points = {"slit_tips": lower[-1, tips], "delaminated": upper[0, slit],
              "delaminated_lower": lower[-1, slit],
              "interface_tied": lower[-1, ~slit & ~np.isin(np.arange(nx + 1), tips)]}
    for x_load in LOAD_X:
        points[f"load_{x_load:.0f}"] = upper[-1, np.isclose(xs, x_load)]
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
    "delamination_layers.msh": delamination_layers,
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
