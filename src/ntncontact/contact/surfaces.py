"""Contact surfaces in global numbering and the interface of two of them.

A :class:`ContactSurface` is an ordered chain of GLOBAL node indices (body offset + local node)
walked with the body on the left, so the outward normal at a node is
``rot(-90)(x_next - x_prev)`` normalized (report 2.1.1), one-sided at the ends of an open chain.
Nodes flagged as corners have no usable normal of their own; the contact kernels then use the
partner surface's normal negated (report 6.6).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ntncontact.mesh.boundary import SurfaceChain
from ntncontact.mesh.quadmesh import frozen_array

__all__ = ["ContactSurface", "Interface", "corner_mask"]


@dataclass(frozen=True, eq=False)
class ContactSurface:
    """Ordered global node indices of one contact surface (body on the left when walking).

    ``corner`` is a boolean mask aligned with ``nodes``: True where the body surface has a kink
    and the node takes the partner's normal (report 6.6). ``partner_normal``: every node takes
    the partner's normal, as a node facing an ALE surface does (docs/theory.md, "The gap across
    an ALE move").
    """

    nodes: NDArray[np.int64]
    closed: bool = False
    corner: NDArray[np.bool_] | None = None
    partner_normal: bool = False

    def __post_init__(self) -> None:
        nodes = frozen_array(self.nodes, np.int64).reshape(-1)
        if nodes.size < (3 if self.closed else 2):
            raise ValueError("a contact surface needs >= 2 nodes (>= 3 when closed)")
        if np.unique(nodes).size != nodes.size:
            raise ValueError("a contact surface lists a node twice")
        corner = np.zeros(nodes.size, bool) if self.corner is None else self.corner
        corner = frozen_array(corner, np.bool_).reshape(-1)
        if corner.size != nodes.size:
            raise ValueError("corner mask must have one entry per surface node")
        object.__setattr__(self, "nodes", nodes)
        object.__setattr__(self, "corner", corner)

    @classmethod
    def from_chain(
        cls, chain: SurfaceChain, offset: int = 0, corner_nodes: ArrayLike = ()
    ) -> ContactSurface:
        """From a body's :class:`SurfaceChain` (local nodes) shifted by the body's node offset;
        ``corner_nodes`` are GLOBAL node indices to flag as corners."""
        nodes = np.asarray(chain.nodes, dtype=np.int64) + int(offset)
        corner = np.isin(nodes, np.asarray(corner_nodes, dtype=np.int64))
        return cls(nodes, bool(chain.closed), corner)

    @property
    def size(self) -> int:
        return int(self.nodes.size)

    @cached_property
    def prev(self) -> NDArray[np.int64]:
        """Global index of each node's predecessor; an open chain's first node is its own."""
        prev = np.roll(self.nodes, 1)
        if not self.closed:
            prev[0] = self.nodes[0]
        return prev

    @cached_property
    def next(self) -> NDArray[np.int64]:
        """Global index of each node's successor; an open chain's last node is its own."""
        nxt = np.roll(self.nodes, -1)
        if not self.closed:
            nxt[-1] = self.nodes[-1]
        return nxt

    @cached_property
    def _sorted(self) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
        order = np.argsort(self.nodes)
        return self.nodes[order], order

    @property
    def takes_partner_normal(self) -> NDArray[np.bool_]:
        """Per node: its pairs' normal is the partner's, negated (a corner, or every node with
        ``partner_normal``)."""
        return self.corner | self.partner_normal

    @cached_property
    def kernel_table(self) -> NDArray[np.int64]:
        """(5, size) lookup table of the compiled contact kernel: sorted global nodes, their
        chain positions, then prev, next and the flag ``takes_partner_normal`` per chain
        position (the kernel takes the normal from the partner's chain where it is set)."""
        keys, order = self._sorted
        table = np.vstack((keys, order, self.prev, self.next, self.takes_partner_normal)
                          ).astype(np.int64)
        table.setflags(write=False)
        return table

    def index_of(self, global_nodes: ArrayLike) -> NDArray[np.int64]:
        """Position in the chain of each global node; ValueError if one is not on the surface."""
        query = np.asarray(global_nodes, dtype=np.int64)
        keys, order = self._sorted
        pos = np.clip(np.searchsorted(keys, query), 0, keys.size - 1)
        if np.any(keys[pos] != query):
            missing = query[keys[pos] != query]
            raise ValueError(f"nodes {missing[:5].tolist()} are not on this contact surface")
        return order[pos]

    def edges(self) -> NDArray[np.int64]:
        """Surface segments (a, b) in walking order (closing segment included if closed)."""
        pairs = np.column_stack((self.nodes, self.next))  # an open chain's last is its own
        return pairs if self.closed else pairs[:-1]


@dataclass(frozen=True, eq=False)
class Interface:
    """Body-1 surface (carries the normal, the tributary lengths and the pair's first node)
    and body-2 surface (the partners)."""

    surface1: ContactSurface
    surface2: ContactSurface

    def __post_init__(self) -> None:
        if np.intersect1d(self.surface1.nodes, self.surface2.nodes).size:
            raise ValueError("the two surfaces of an interface share nodes")


def corner_mask(
    x: NDArray[np.float64], surface: ContactSurface, angle_deg: float = 30.0,
    include_ends: bool = False,
) -> NDArray[np.bool_]:
    """True at nodes where consecutive segments turn by more than ``angle_deg``
    (optionally also at the ends of an open chain, the body corners of report 6.6)."""
    before = x[surface.nodes] - x[surface.prev]
    after = x[surface.next] - x[surface.nodes]
    cross = before[:, 0] * after[:, 1] - before[:, 1] * after[:, 0]
    turn = np.abs(np.arctan2(cross, np.einsum("ij,ij->i", before, after)))
    mask = turn > np.deg2rad(angle_deg)
    if not surface.closed:
        mask[[0, -1]] = include_ends  # one-sided ends have no turn angle
    return mask
