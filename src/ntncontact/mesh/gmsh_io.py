"""Read 2D all-quad gmsh ``.msh`` meshes (formats 2.2 and 4.x) into a :class:`QuadMesh`.

Named physical groups become named sets: point groups -> node sets; line groups -> edge sets
oriented with the body on the left (plus node sets); surface groups -> node sets. Only
first-order quads are accepted: a triangle would need a different element in every layer.
"""

from __future__ import annotations

import warnings
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import BinaryIO

import meshio
import numpy as np
from meshio._common import num_nodes_per_cell
from numpy.typing import NDArray
from scipy.spatial import cKDTree

from ntncontact.mesh.boundary import boundary_edges, hanging_nodes, nodes_inside_cells
from ntncontact.mesh.quadmesh import MeshError, QuadMesh

__all__ = ["read_msh"]

_TRIANGLES = {"triangle", "triangle6", "triangle7", "triangle10"}
_DIMENSION = {"vertex": 0, "line": 1, "quad": 2}


def read_msh(path: str | Path, name: str | None = None) -> QuadMesh:
    """Read a gmsh mesh of first-order quadrilaterals lying in a plane ``z = const``.

    Unused nodes are dropped and the rest renumbered in file order; clockwise cells are
    flipped to counter-clockwise. ``name`` defaults to the file stem. Raises
    :class:`MeshError` (naming the file) for triangles, higher-order or 3D cells, a
    non-planar mesh, coincident nodes, hanging nodes (T-junctions), degenerate cells, or a
    line group not on the boundary.
    """
    path = Path(path)
    raw = _read_meshio(path)
    label = str(path)
    blocks = [(block.type, np.asarray(block.data, dtype=np.int64)) for block in raw.cells]
    _check_cell_types(blocks, label)
    quads = np.vstack([data for kind, data in blocks if kind == "quad"] or [np.zeros((0, 4))])
    if quads.shape[0] == 0:
        raise MeshError(f"{label}: no quadrilateral cells (is the surface in a physical group?)")
    # format 2.2 repeats an element once per physical group it belongs to
    _, first = np.unique(np.sort(quads, axis=1), axis=0, return_index=True)
    # the file's element numbers: messages name a file's element by them, not by an index
    element_ids = _file_ids(path, b"$Elements", quads.shape[0], _quad_ids)[np.sort(first)]
    quads = quads[np.sort(first)]
    xy = _planar_points(np.asarray(raw.points, dtype=float), label)
    _check_finite(xy, path)
    used = np.unique(quads)
    renumber = np.full(xy.shape[0], -1, dtype=np.int64)
    renumber[used] = np.arange(used.size)
    _check_distinct(xy[used], label)
    # the file's node numbers (meshio's point order): outputs give them so that a node of
    # contact.csv can be found in the file
    node_ids = _file_ids(path, b"$Nodes", xy.shape[0], _node_ids)[used]
    cells = _counter_clockwise(xy[used], renumber[quads], label, element_ids, node_ids)
    mesh = QuadMesh(xy[used], cells, name=name or path.stem, file_node_ids=node_ids,
                    file_element_ids=element_ids)
    _check_conforming(mesh, label)
    groups = _physical_groups(raw, blocks, label, _file_group_names(path))
    node_sets, edge_sets = _named_sets(mesh, groups, renumber, label)
    return mesh.with_sets(node_sets, edge_sets)


#: what every refusal of an unreadable file says: the formats read and how to get one
_FORMATS = ("only gmsh .msh files (format 2.2 or 4.1) are read; convert another format with "
            "`meshio convert in.inp out.msh`, then give the boundary curves physical line "
            "groups (surfaces, supports, loads) in gmsh")


def _read_meshio(path: Path) -> meshio.Mesh:
    """meshio's gmsh reader, called directly: ``meshio.read`` exits the process on bad files,
    and its own errors say nothing a user can act on ("KeyError: np.int32(2)")."""
    if not path.is_file():
        raise FileNotFoundError(f"gmsh mesh file not found: {path}")
    with path.open("rb") as stream:
        first = stream.readline(64).strip()
    if not first.startswith(b"$MeshFormat"):
        raise MeshError(f"{path}: not a gmsh .msh file (it does not begin with $MeshFormat): "
                        f"{_FORMATS}")
    try:
        return meshio.gmsh.read(path)
    except KeyError as err:  # an entity tag that $Entities does not hold
        tag = err.args[0] if err.args else "?"
        tag = int(tag) if isinstance(tag, (int, np.integer)) else tag
        raise MeshError(f"{path}: the file's entities and physical groups are inconsistent (an "
                        f"element block refers to entity {tag}, which $Entities does not list); "
                        "write it again from gmsh (File > Export, format 4.1 or 2.2)") from err
    except Exception as err:  # meshio raises ReadError, ValueError, ... on bad input
        raise MeshError(f"{path}: {_unreadable(path)} ({type(err).__name__}: {err})") from err


def _unreadable(path: Path) -> str:
    """Why a file that begins as a gmsh file could not be read, by its format's version."""
    with path.open("rb") as stream:
        stream.readline()
        version = stream.readline().split()[:1]
    version = version[0].decode(errors="replace") if version else "?"
    if version not in ("2.2", "4.1"):
        return (f"gmsh format {version}; ntncontact reads formats 2.2 and 4.1 (in gmsh: "
                "Mesh.MshFileVersion = 4.1, or File > Export)")
    return (f"a gmsh format {version} file that cannot be read: an element may cite a node "
            "that $Nodes does not define, or a section is cut short; write it again from gmsh")


def _file_ids(path: Path, section: bytes, count: int,
              read: Callable[[BinaryIO, str, bool, int], NDArray]) -> NDArray[np.int64]:
    """The numbers meshio reads and drops, by ``read`` from the first line of ``section`` on;
    -1 for all ``count`` entries if that fails (a format read differently), since they only
    help find an entry in the file."""
    try:
        with path.open("rb") as stream:
            stream.readline()  # $MeshFormat, checked by _read_meshio
            version, data_size, is_ascii = meshio.gmsh.main._read_header(stream)
            while stream.readline().strip() != section:
                pass
            ids = np.asarray(read(stream, version, is_ascii, data_size), np.int64).reshape(-1)
    except Exception:  # noqa: BLE001 - the ids are a help for finding entries, not the mesh
        ids = np.zeros(0, np.int64)
    return ids if ids.size == count else np.full(count, -1, np.int64)


def _node_ids(stream: BinaryIO, version: str, is_ascii: bool,
              data_size: int) -> NDArray[np.int64]:
    """The node numbers of a $Nodes section, by meshio's own node readers."""
    if version == "2.2":
        return np.asarray(meshio.gmsh._gmsh22._read_nodes(stream, is_ascii)[1], np.int64)
    if version == "4.1":  # its reader returns the tags less one
        return np.asarray(meshio.gmsh._gmsh41._read_nodes(stream, is_ascii, data_size)[1],
                          np.int64) + 1
    return np.zeros(0, np.int64)


#: gmsh's element type number of a first-order quadrilateral
_GMSH_QUAD = 3


def _quad_ids(stream: BinaryIO, version: str, is_ascii: bool,
              data_size: int) -> NDArray[np.int64]:
    """The quads' element numbers of an $Elements section read from its first line on."""
    if version not in ("2.2", "4.1"):
        return np.zeros(0, np.int64)
    ids: list[NDArray[np.int64]] = []
    if version == "2.2" and is_ascii:
        for _ in range(int(stream.readline())):
            tag, kind = stream.readline().split()[:2]
            if int(kind) == _GMSH_QUAD:
                ids.append(np.array([int(tag)], np.int64))
    elif version == "2.2":  # binary: blocks of (type, count, number of tags) headers
        total = int(stream.readline())
        while total > 0:
            kind, count, n_tags = np.fromfile(stream, count=3, dtype=np.int32)
            width = 1 + n_tags + _nodes_of(kind)
            rows = np.fromfile(stream, count=count * width, dtype=np.int32).reshape(count, width)
            if kind == _GMSH_QUAD:
                ids.append(rows[:, 0].astype(np.int64))
            total -= count
    else:  # 4.1: entity blocks of (dim, entity, type, count), then tag and nodes per element
        size = np.uint64 if data_size == 8 else np.uint32
        read = (lambda d, n: np.fromfile(stream, dtype=d, count=n, sep=" ")) if is_ascii else (
            lambda d, n: np.fromfile(stream, dtype=d, count=n))
        blocks = int(read(size, 4)[0])
        for _ in range(blocks):
            kind = int(read(np.int32, 3)[2])
            count = int(read(size, 1)[0])
            rows = read(size, count * (1 + _nodes_of(kind))).reshape(count, -1)
            if kind == _GMSH_QUAD:
                ids.append(rows[:, 0].astype(np.int64))
    return np.concatenate(ids) if ids else np.zeros(0, np.int64)


def _nodes_of(kind: int) -> int:
    """The number of nodes of gmsh element type ``kind``."""
    return int(num_nodes_per_cell[meshio.gmsh.common._gmsh_to_meshio_type[int(kind)]])


def _file_group_names(path: Path) -> dict[tuple[int, int], str]:
    """(dimension, tag) -> name of the file's $PhysicalNames: meshio keys the groups by name
    alone, and of a point and a line group that share a name (gmsh's names are per
    dimension) keeps one; the other's name is needed to say so. Empty if it cannot be read."""
    names: dict[tuple[int, int], str] = {}
    try:
        with path.open("rb") as stream:
            for line in stream:
                if line.strip() in (b"$Nodes", b"$Entities", b"$Elements"):
                    break
                if line.strip() == b"$PhysicalNames":
                    for _ in range(int(stream.readline())):
                        dim, tag, name = stream.readline().decode().split(maxsplit=2)
                        names[(int(dim), int(tag))] = name.strip().strip('"')
                    break
    except (OSError, ValueError):  # the names only improve a warning
        return {}
    return names


def _check_finite(xy: NDArray[np.float64], path: Path) -> None:
    """Every coordinate a number, the first that is not named by its file node."""
    bad = np.flatnonzero(~np.all(np.isfinite(xy), axis=1))
    if bad.size:
        tag = _file_ids(path, b"$Nodes", xy.shape[0], _node_ids)[bad[0]]
        raise MeshError(f"{path}: {bad.size} node(s) with a coordinate that is not a number, "
                        f"the first file node {tag} at {tuple(xy[bad[0]].tolist())}")


def _check_cell_types(blocks: list[tuple[str, NDArray]], label: str) -> None:
    kinds = {kind for kind, _ in blocks}
    if kinds & _TRIANGLES:
        raise MeshError(f"{label}: contains triangles; ntncontact needs an all-quad mesh "
                        "(recombine in gmsh: Mesh.RecombineAll = 1 or setRecombine)")
    unsupported = kinds - set(_DIMENSION)
    if unsupported:
        higher = [kind for kind in unsupported if kind.startswith(("quad", "line"))]
        hint = (" (second-order cells: mesh with Mesh.ElementOrder = 1 in gmsh, or `gmsh -order "
                "1`)" if higher else "")
        raise MeshError(f"{label}: unsupported cell types {sorted(unsupported)}; only first-order "
                        f"quads (with line and vertex cells for physical groups) are read{hint}")


def _planar_points(points: NDArray[np.float64], label: str) -> NDArray[np.float64]:
    """The x, y columns; the mesh must lie in one plane z = const."""
    if points.shape[1] == 3:
        z = points[:, 2]
        scale = max(float(np.ptp(points[:, :2])), 1.0)
        # gmsh writes 17 significant digits, so a planar mesh has z spread at round-off level
        if z.size and float(np.ptp(z)) > 1e3 * np.finfo(float).eps * scale:
            raise MeshError(f"{label}: nodes do not lie in a plane z = const (z spread "
                            f"{np.ptp(z):.3g}); only 2D meshes are supported")
    return np.ascontiguousarray(points[:, :2])


#: nodes closer than this fraction of the mesh's extent are the same point (gmsh's own
#: Geometry.Tolerance default, as the ties' coincidence test)
COINCIDENT_RTOL = 1e-8


def _check_distinct(xy: NDArray, label: str) -> None:
    """Refuses coincident nodes: the cells on either side of them are not joined, so the mesh
    holds a crack whose faces nothing keeps apart (parts meshed separately and not merged)."""
    tolerance = COINCIDENT_RTOL * float(np.ptp(xy, axis=0).max())
    pairs = cKDTree(xy).query_pairs(tolerance, output_type="ndarray")
    if len(pairs) == 0:
        return
    x, y = xy[int(pairs[:, 0].min())]
    raise MeshError(
        f"{label}: {len(pairs)} pair(s) of nodes coincide, the first at ({x:.6g}, {y:.6g}): "
        "the cells on either side are not joined (a crack). Merge them (gmsh: Coherence "
        "Mesh, Geometry.AutoCoherence), or make the parts separate bodies joined by a "
        "[[tie]] or a [[contact]]")


def _check_conforming(mesh: QuadMesh, label: str) -> None:
    """Refuses hanging nodes (T-junctions): parts meshed with different divisions and merged at
    their corners only leave the finer part's nodes loose on the coarser part's edges, a crack
    that opens under load (see :func:`hanging_nodes`)."""
    hanging = hanging_nodes(mesh)
    if hanging.shape[0] == 0:
        _check_nothing_inside(mesh, label)
        return
    (x, y), (ax, ay), (bx, by) = mesh.nodes[hanging[0]]
    file_id = -1 if mesh.file_node_ids is None else int(mesh.file_node_ids[hanging[0, 0]])
    raise MeshError(
        f"{label} (body '{mesh.name}'): {hanging.shape[0]} node(s) hang on another cell's edge "
        f"(a non-conformal mesh), the first at ({x:.6g}, {y:.6g}) (file node {file_id}) on "
        f"the edge from ({ax:.6g}, {ay:.6g}) to ({bx:.6g}, {by:.6g}): nothing joins them (a "
        "crack). Mesh "
        "conformally: one surface, or matching divisions on the shared line (gmsh Coherence "
        "merges coincident nodes only, it does not make a mesh conformal); or make the parts "
        "separate bodies joined by a [[tie]], which holds a finer side's nodes on the other's "
        "edges")


def _check_nothing_inside(mesh: QuadMesh, label: str) -> None:
    """Refuses a boundary node inside another cell of the body (:func:`nodes_inside_cells`):
    a T-junction on a curved shared line, or parts that overlap."""
    inside = nodes_inside_cells(mesh)
    if inside.shape[0] == 0:
        return
    node, cell = inside[0]
    x, y = mesh.nodes[node]
    file_id = -1 if mesh.file_node_ids is None else int(mesh.file_node_ids[node])
    raise MeshError(
        f"{label} (body '{mesh.name}'): {np.unique(inside[:, 0]).size} boundary node(s) lie "
        f"inside another cell of the body, the first at ({x:.6g}, {y:.6g}) (file node "
        f"{file_id}) inside the cell with corners at "
        f"{', '.join(f'({cx:.6g}, {cy:.6g})' for cx, cy in mesh.nodes[mesh.cells[cell]])}: "
        "parts meshed with different divisions on a curved "
        "shared line (the finer part's nodes sit on the arc, off the coarser cell's edge), or "
        "parts that overlap. Mesh conformally (matching divisions on the shared line), or make "
        "the parts separate bodies joined by a [[tie]]")


def _counter_clockwise(xy: NDArray, cells: NDArray[np.int64], label: str,
                       element_ids: NDArray[np.int64], node_ids: NDArray[np.int64]
                       ) -> NDArray[np.int64]:
    """Flip clockwise cells (negative shoelace area) to counter-clockwise. A cell of (near)
    zero area is refused, named by the file's element and node numbers (``element_ids``,
    ``node_ids``; -1 where unknown, then by its index and the 0-based node indices)."""
    x, y = xy[cells, 0], xy[cells, 1]
    area = 0.5 * np.sum(x * np.roll(y, -1, axis=1) - np.roll(x, -1, axis=1) * y, axis=1)
    scale = float(np.ptp(xy, axis=0).max()) ** 2
    if np.any(np.abs(area) <= 1e3 * np.finfo(float).eps * scale):
        cell = int(np.argmin(np.abs(area)))
        tag, corners = int(element_ids[cell]), node_ids[cells[cell]]
        which = (f"file element {tag} (nodes {' '.join(map(str, corners))})" if tag >= 0
                 and np.all(corners >= 0) else f"cell {cell} (0-based, in file order)")
        raise MeshError(f"{label}: {which} has (near) zero area (a twisted or collapsed "
                        "quadrilateral)")
    return np.where((area < 0)[:, None], cells[:, [0, 3, 2, 1]], cells)


def _physical_groups(raw: meshio.Mesh, blocks: list[tuple[str, NDArray]], label: str,
                     file_names: Mapping[tuple[int, int], str]
                     ) -> dict[str, tuple[int, list[NDArray]]]:
    """name -> (dimension, list of cell connectivity arrays of that group); ``file_names``:
    the file's (dimension, tag) -> name, for the warning on a group whose name is taken."""
    groups: dict[str, tuple[int, list[NDArray]]] = {}
    tags = raw.cell_data.get("gmsh:physical")
    for group_name, (tag, dim) in ((k, tuple(int(t) for t in v[:2]))
                                   for k, v in raw.field_data.items()):
        members = []
        for k, (kind, data) in enumerate(blocks):
            if _DIMENSION[kind] != dim:
                continue
            if raw.cell_sets.get(group_name) is not None:  # format 4.x: explicit membership
                chosen = raw.cell_sets[group_name][k]
                index = np.zeros(0, np.int64) if chosen is None else np.asarray(chosen, np.int64)
            elif tags is not None:  # format 2.2: one physical tag per cell
                index = np.flatnonzero(np.asarray(tags[k]) == tag)
            else:
                raise MeshError(f"{label}: physical group '{group_name}' has no cell data")
            members.append(data[index])
        groups[group_name] = (dim, members)
    return groups | _unnamed_groups(raw, blocks, label, groups, file_names)


def _unnamed_groups(raw: meshio.Mesh, blocks: list[tuple[str, NDArray]], label: str,
                    named: Mapping[str, tuple[int, list[NDArray]]],
                    file_names: Mapping[tuple[int, int], str]
                    ) -> dict[str, tuple[int, list[NDArray]]]:
    """Physical line and point groups without a name, each under its number (``set = "5"``),
    with a warning: gmsh writes a group without a name when its name was given to another
    group already (the second of two lines named "top"), and legacy .geo files number them
    only (``Physical Line(5) = {...}``): ignored, a load on them would be lost in silence. A
    group whose name another group of another dimension has too (gmsh's names are per
    dimension, meshio keeps one of them) is one of these, and its warning says so."""
    tags = raw.cell_data.get("gmsh:physical")
    if tags is None:
        return {}
    known = {(int(v[1]), int(v[0])) for v in raw.field_data.values()}  # (dimension, tag)
    groups: dict[str, tuple[int, list[NDArray]]] = {}
    for (kind, data), block_tags in zip(blocks, tags, strict=True):
        block_tags, dim = np.asarray(block_tags), _DIMENSION[kind]
        for tag in np.unique(block_tags):
            if tag <= 0 or dim == 2 or (dim, int(tag)) in known or str(tag) in named:
                continue  # 0: in no group (Mesh.SaveAll); a numbered surface saves the quads
            members = groups.setdefault(str(tag), (dim, []))[1]
            members.append(data[block_tags == tag])
    for name, (dim, _) in groups.items():
        warnings.warn(f"{label}: {_unnamed_text(raw, name, dim, file_names)}", stacklevel=4)
    return groups


_DIMENSION_NAMES = ("point", "line", "surface")


def _unnamed_text(raw: meshio.Mesh, tag: str, dim: int,
                  file_names: Mapping[tuple[int, int], str]) -> str:
    """The warning on the physical group ``tag`` of dimension ``dim`` that is a set by its
    number: it has no name, or its name is another dimension's group's."""
    own = file_names.get((dim, int(tag)))
    if own is None or own not in raw.field_data:
        return (f"physical group {tag} ({_DIMENSION_NAMES[dim]}s) has no name; it is the "
                f"set \"{tag}\"")
    other_tag, other_dim = (int(v) for v in raw.field_data[own][:2])
    return (f"physical {_DIMENSION_NAMES[dim]} group {tag} and {_DIMENSION_NAMES[other_dim]} "
            f"group {other_tag} are both named \"{own}\" (gmsh allows a name once per "
            f"dimension; a set name means one group): the set \"{own}\" is the "
            f"{_DIMENSION_NAMES[other_dim]} group {other_tag}, and the "
            f"{_DIMENSION_NAMES[dim]} group is the set \"{tag}\" (rename one in gmsh to "
            "use both by name)")


def _named_sets(mesh: QuadMesh, groups: Mapping[str, tuple[int, list[NDArray]]],
                renumber: NDArray[np.int64], label: str
                ) -> tuple[dict[str, NDArray], dict[str, NDArray]]:
    node_sets: dict[str, NDArray] = {}
    edge_sets: dict[str, NDArray] = {}
    for group_name, (dim, members) in groups.items():
        width = {0: 1, 1: 2, 2: 4}[dim]
        cells = renumber[np.vstack(members or [np.zeros((0, width), np.int64)])]
        if np.any(cells < 0):
            raise MeshError(f"{label}: physical group '{group_name}' uses nodes that belong to "
                            "no quadrilateral")
        nodes = np.unique(cells)
        if group_name in node_sets:  # same name on groups of different dimension: merge
            nodes = np.union1d(node_sets[group_name], nodes)
        node_sets[group_name] = nodes
        if dim == 1:
            edges = _orient_on_boundary(mesh, cells, group_name, label)
            if edges is not None:
                edge_sets[group_name] = edges
    return node_sets, edge_sets


def _orient_on_boundary(mesh: QuadMesh, edges: NDArray[np.int64], group_name: str,
                        label: str) -> NDArray[np.int64] | None:
    """The group's edges (file order) with the orientation of the matching boundary edge;
    None, with a warning, for a line inside the mesh (a material boundary, a line kept for
    post-processing): a node set only, since surfaces and edge loads need boundary curves."""
    boundary = boundary_edges(mesh)
    n = np.int64(mesh.n_nodes)
    boundary_keys = np.sort(boundary, axis=1) @ np.array([n, 1])
    order = np.argsort(boundary_keys)
    keys = np.sort(edges, axis=1) @ np.array([n, 1])
    pos = np.clip(np.searchsorted(boundary_keys, keys, sorter=order), 0, order.size - 1)
    found = boundary_keys[order[pos]] == keys
    if not np.all(found):
        a, b = edges[np.argmin(found)]
        if mesh.file_node_ids is not None and min(mesh.file_node_ids[[a, b]]) >= 0:
            a, b = mesh.file_node_ids[[a, b]]  # the numbers a user finds in the file
        warnings.warn(f"{label}: line group '{group_name}' has edge ({a}, {b}) inside the quad "
                      "mesh: it is a node set only (surfaces and edge loads need boundary "
                      "curves)", stacklevel=5)
        return None
    return boundary[order[pos]]
