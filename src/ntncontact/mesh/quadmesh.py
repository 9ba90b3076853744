"""The immutable Q4 mesh type shared by every layer of ntncontact."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from types import MappingProxyType

import numpy as np
from numpy.typing import ArrayLike, NDArray

#: joins edge-set names into one surface: ``surface_1 = "bottom+right"``
JOIN = "+"


class MeshError(ValueError):
    """A mesh that cannot be used: bad connectivity, unknown set, inverted element;
    ``cell``: the cell the message names (-1: none)."""

    def __init__(self, message: str, cell: int = -1) -> None:
        super().__init__(message)
        self.cell = cell


def frozen_array(values: ArrayLike, dtype: type) -> NDArray:
    """A read-only copy of ``values`` as ``dtype`` (the arrays of the package's immutable types)."""
    out = np.array(values, dtype=dtype, copy=True)
    out.setflags(write=False)
    return out


def cell_edges(cells: NDArray[np.int64]) -> NDArray[np.int64]:
    """All cell edges ``(c_k, c_k+1)``, cell by cell; with CCW cells each has its cell on the
    left."""
    return np.stack((cells, np.roll(cells, -1, axis=1)), axis=-1).reshape(-1, 2)


def unique_pairs(pairs: NDArray[np.int64], **returns: bool) -> NDArray | tuple:
    """``np.unique(pairs, axis=0, **returns)`` for pairs (m, 2) of integers (node numbers),
    with the same results, through one int64 key a pair: NumPy's row-wise unique sorts the
    rows as opaque records, ~10x slower (the 250 x 250 mesh's 250,000 cell edges: 69 against
    7 ms; a 61,000-cell build called it 15 times)."""
    pairs = np.asarray(pairs, dtype=np.int64).reshape(-1, 2)
    low = int(pairs.min(initial=0))  # a negative number (bad input) keeps its own key
    span = int(pairs.max(initial=0)) - low + 1
    found = np.unique((pairs[:, 0] - low) * span + (pairs[:, 1] - low), **returns)
    keys, rest = (found[0], found[1:]) if isinstance(found, tuple) else (found, ())
    rows = np.column_stack([keys // span + low, keys % span + low])
    return (rows, *rest) if isinstance(found, tuple) else rows


@dataclass(frozen=True)
class QuadMesh:
    """Node coordinates and counter-clockwise Q4 connectivity with named sets.

    ``node_sets`` map a name to node indices; ``edge_sets`` (surfaces) map a name to an
    (m, 2) array of node pairs, each pair ordered so that the body lies on its left
    (counter-clockwise boundary orientation), i.e. the outward normal of edge (a, b) is
    ``rot(-90)(x_b - x_a)``. ``file_node_ids`` are the node numbers of the file a mesh was read
    from (a reader renumbers the nodes 0..n-1; messages and outputs use those), None for a
    generated mesh; ``file_element_ids`` likewise the file's element numbers of the cells
    (messages name an element of a file mesh by them); -1 where a number is unknown.
    """

    nodes: NDArray[np.float64]
    cells: NDArray[np.int64]
    node_sets: Mapping[str, NDArray[np.int64]] = field(default_factory=dict)
    edge_sets: Mapping[str, NDArray[np.int64]] = field(default_factory=dict)
    name: str = "body"
    file_node_ids: NDArray[np.int64] | None = None
    file_element_ids: NDArray[np.int64] | None = None

    def __post_init__(self) -> None:
        nodes = frozen_array(self.nodes, np.float64)
        cells = frozen_array(self.cells, np.int64)
        if nodes.ndim != 2 or nodes.shape[1] != 2:
            raise MeshError(f"{self.name}: nodes must have shape (n, 2), got {nodes.shape}")
        if cells.ndim != 2 or cells.shape[1] != 4:
            raise MeshError(f"{self.name}: cells must have shape (m, 4), got {cells.shape}")
        if cells.size and (cells.min() < 0 or cells.max() >= len(nodes)):
            raise MeshError(f"{self.name}: cell connectivity refers to a node that does not exist")
        node_sets = {k: frozen_array(v, np.int64).reshape(-1) for k, v in self.node_sets.items()}
        edge_sets = {k: frozen_array(v, np.int64).reshape(-1, 2) for k, v in self.edge_sets.items()}
        for label, sets in (("node set", node_sets), ("edge set", edge_sets)):
            for key, idx in sets.items():
                if idx.size and (idx.min() < 0 or idx.max() >= len(nodes)):
                    raise MeshError(f"{self.name}: {label} '{key}' refers to a missing node")
        for key, things, count in (("file_node_ids", "nodes", len(nodes)),
                                   ("file_element_ids", "cells", len(cells))):
            if getattr(self, key) is not None:
                ids = frozen_array(getattr(self, key), np.int64).reshape(-1)
                if ids.size != count:
                    raise MeshError(f"{self.name}: {ids.size} {key.replace('_', ' ')} for {count} "
                                    f"{things}")
                object.__setattr__(self, key, ids)
        object.__setattr__(self, "nodes", nodes)
        object.__setattr__(self, "cells", cells)
        object.__setattr__(self, "node_sets", MappingProxyType(node_sets))
        object.__setattr__(self, "edge_sets", MappingProxyType(edge_sets))

    @property
    def n_nodes(self) -> int:
        return int(self.nodes.shape[0])

    @property
    def n_cells(self) -> int:
        return int(self.cells.shape[0])

    def node_set(self, name: str) -> NDArray[np.int64]:
        """Nodes of a node set, or of an edge set of that name (its nodes, sorted); a joined
        surface ``"a+b"`` (see :meth:`edge_set`) gives the nodes of its edges."""
        if name in self.node_sets:
            return self.node_sets[name]
        if name in self.edge_sets or JOIN in name:
            return np.unique(self.edge_set(name))
        known = sorted(set(self.node_sets) | set(self.edge_sets))
        raise MeshError(f"{self.name}: no node or edge set named '{name}' (known: {known})")

    def edge_set(self, name: str) -> NDArray[np.int64]:
        """The edges of a surface. A name ``"bottom+right"`` that is not itself a set joins
        the named edge sets into one surface (their edges together), as a surface made of
        several faces: a node they share, such as the corner between a block's bottom and its
        leading face, is then one node of one surface, paired once in contact."""
        if name in self.edge_sets:
            return self.edge_sets[name]
        parts = name.split(JOIN) if JOIN in name else [name]
        missing = [p for p in parts if p not in self.edge_sets]
        if len(set(parts)) < len(parts):  # a typo for another face, most likely
            raise MeshError(f"{self.name}: surface '{name}' names a part twice")
        if missing and missing[0] in self.node_sets:
            raise MeshError(
                f"{self.name}: '{missing[0]}' is a node set only (a physical point or surface "
                "group, or a line inside the mesh); a surface needs a physical line group on "
                f"the boundary (surfaces: {sorted(self.edge_sets)})"
            )
        if missing:
            raise MeshError(
                f"{self.name}: no surface (edge set) named '{missing[0]}' "
                f"(known: {sorted(self.edge_sets)}; join several with '{JOIN}')"
            )
        return np.unique(np.vstack([self.edge_sets[p] for p in parts]), axis=0)

    def with_nodes(self, nodes: NDArray[np.float64]) -> QuadMesh:
        """The same topology and sets at new node coordinates."""
        return replace(self, nodes=nodes)

    def with_sets(
        self,
        node_sets: Mapping[str, NDArray[np.int64]] | None = None,
        edge_sets: Mapping[str, NDArray[np.int64]] | None = None,
    ) -> QuadMesh:
        """A copy with extra (or replaced) named sets."""
        return replace(self, node_sets=dict(self.node_sets) | dict(node_sets or {}),
                       edge_sets=dict(self.edge_sets) | dict(edge_sets or {}))

    def transformed(
        self, angle_deg: float = 0.0, translation: tuple[float, float] = (0.0, 0.0),
        center: tuple[float, float] = (0.0, 0.0),
    ) -> QuadMesh:
        """Rotate by ``angle_deg`` about ``center`` (counter-clockwise), then translate."""
        theta = np.deg2rad(angle_deg)
        rot = np.array([[np.cos(theta), -np.sin(theta)], [np.sin(theta), np.cos(theta)]])
        c = np.asarray(center, dtype=float)
        moved = (self.nodes - c) @ rot.T + c + np.asarray(translation, dtype=float)
        return self.with_nodes(moved)
