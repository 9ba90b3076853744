"""Per-pair contact geometry: slots, normals, gaps (report 2.1.1, 5.1.2).

Every quantity of a pair (node1 ``i`` on surface 1, node2 ``j`` on surface 2) depends on the
positions of at most six nodes, its SLOTS:

    slot 0: i,   slot 1: j,
    slots 2, 3: the nodes (a, b) defining the normal, n = rot(-90)(x_b - x_a)/|x_b - x_a|
                (a, b) = (prev(i), next(i)) on surface 1, or (next(j), prev(j)) on surface 2
                when i is a corner, i.e. n = -n2(j) (report 6.6),
    slots 4, 5: the chain neighbours of i entering L_c = (L_{i-1,i} + L_{i,i+1})/2 (5.5).

The compiled contact kernel (``evaluate.py``) stores gradients per slot: a scalar's gradient is
(P, 6, 2), [p, k, c] = d(value)/d(x_{slot k, c}). Repeated slots (e.g. a = i at a chain end) add
up when assembled. Pairing and detection need only the values, :func:`pair_gaps`.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from .surfaces import Interface

__all__ = ["FACING_COS", "N_SLOTS", "facing", "pair_gaps", "rate_roundoff"]

N_SLOTS = 6
_ROT_M90 = np.array([[0.0, 1.0], [-1.0, 0.0]])  # n = R u rotates the chord by -90 degrees


def _slots(interface: Interface, pairs: NDArray[np.int64]) -> NDArray[np.int64]:
    """Global node of every slot (module docstring), corners swapped to the partner normal."""
    s1, s2 = interface.surface1, interface.surface2
    i, j = pairs[:, 0], pairs[:, 1]
    k1 = s1.index_of(i)
    k2 = s2.index_of(j)
    corner = s1.takes_partner_normal[k1]
    a = np.where(corner, s2.next[k2], s1.prev[k1])
    b = np.where(corner, s2.prev[k2], s1.next[k1])
    return np.column_stack((i, j, a, b, s1.prev[k1], s1.next[k1]))


class UndefinedNormalError(ValueError):
    """A pair whose normal chord has zero length (its two chain neighbours coincide: a crushed
    surface, or a mesh of zero size). It keeps the nodes and their position, which the engine
    names by interface and body (``engine.diagnostics.named_failure``): the bare message gave
    a tester no place to look."""

    def __init__(self, node: int, partner: int, chord: tuple[int, int],
                 position: NDArray | None) -> None:
        self.node, self.partner = int(node), int(partner)
        self.chord = (int(chord[0]), int(chord[1]))
        self.position = None if position is None else np.asarray(position, dtype=float)
        where = ("" if self.position is None else
                 f" at ({self.position[0]:.6g}, {self.position[1]:.6g})")
        super().__init__(f"a contact normal is undefined (coincident chain neighbours: nodes "
                         f"{self.chord[0]} and {self.chord[1]}{where}, the normal chord of "
                         f"the pair of nodes {self.node} and {self.partner})")


def raise_undefined_normal(x: NDArray, interface: Interface, pairs: NDArray) -> None:
    """Raise :class:`UndefinedNormalError` for the first pair whose normal chord has zero
    length at the positions ``x`` (a generic one when none has: the kernel's positions)."""
    _unit_chord(x, _slots(interface, pairs), nan_too=True)
    raise ValueError("a contact normal is undefined (coincident chain neighbours)")


def _unit_chord(x: NDArray, slots: NDArray, nan_too: bool = False) -> tuple[NDArray, NDArray]:
    """e = (x_b - x_a)/l and l of every pair's normal chord (slots 2, 3); raises
    :class:`UndefinedNormalError` for the first of length 0 (or NaN with ``nan_too``)."""
    chord = x[slots[:, 3]] - x[slots[:, 2]]
    length = np.linalg.norm(chord, axis=1)
    zero = np.flatnonzero(~(length > 0.0) if nan_too else length == 0.0)
    if zero.size:
        i, j, a, b = slots[zero[0], :4]
        raise UndefinedNormalError(i, j, (a, b), x[a])
    return chord / length[:, None], length


def pair_gaps(
    x: NDArray[np.float64],
    interface: Interface,
    pairs: NDArray[np.int64],
    v: NDArray[np.float64] | None = None,
    objective: bool = False,
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64] | None]:
    """Normal n, gap g (2.4) and, with ``v``, the report's gap rate gdot = (v_i - v_j).n (2.9)
    of ``pairs``, without derivatives: what pairing and detection need. ``objective``: the
    rate dg/dx . v = (v_i - v_j).n + (s/l) n.(v_a - v_b) of the moment-free law instead
    (s = (x_i - x_j).e, l the normal's chord; docs/theory.md, "Moment-free pair forces")."""
    pairs = np.asarray(pairs, dtype=np.int64).reshape(-1, 2)
    slots = _slots(interface, pairs)
    e, chord = _unit_chord(x, slots)
    n = e @ _ROT_M90.T
    i, j = pairs[:, 0], pairs[:, 1]
    gap = np.einsum("pr,pr->p", x[i] - x[j], n)
    rate = None if v is None else np.einsum("pr,pr->p", v[i] - v[j], n)
    if rate is not None and objective:
        offset = np.einsum("pr,pr->p", x[i] - x[j], e)
        turn = np.einsum("pr,pr->p", v[slots[:, 2]] - v[slots[:, 3]], n)
        rate = rate + offset / chord * turn
    return n, gap, rate


#: A pair enters contact only if its normal is within 60 degrees of its partner's reversed
#: normal (cos >= 0.5). Surfaces in contact face each other; a node whose nearest partner
#: node lies along its own tangent has a normal gap of zero at any distance (a tester's disk
#: equator node 0.10 above a plate node paired with it and pushed the falling disk sideways,
#: -0.265 of its 10 speed, where symmetry gives 0, and a 1e-7 shift removed it). A corner
#: node takes its partner's normal and always faces it.
FACING_COS = 0.5


def facing(x: NDArray[np.float64], interface: Interface,
           pairs: NDArray[np.int64]) -> NDArray[np.bool_]:
    """Whether each pair's normal n and the reversed normal of its partner node, -n2(j) (the
    normal a corner node takes, from surface 2's chord prev(j) -> next(j)), are within
    :data:`FACING_COS` of each other."""
    pairs = np.asarray(pairs, dtype=np.int64).reshape(-1, 2)
    if not len(pairs):
        return np.zeros(0, bool)
    slots = _slots(interface, pairs)
    n = _unit_chord(x, slots)[0] @ _ROT_M90.T
    s2 = interface.surface2
    k2 = s2.index_of(pairs[:, 1])
    chord = x[s2.prev[k2]] - x[s2.next[k2]]
    partner = chord @ _ROT_M90.T
    length = np.linalg.norm(partner, axis=1)
    return np.einsum("pr,pr->p", n, partner) >= FACING_COS * length


def rate_roundoff(x: NDArray[np.float64], v: NDArray[np.float64], interface: Interface,
                  pairs: NDArray[np.int64], gap_tol: float) -> NDArray[np.float64]:
    """The round-off of each pair's normal rate (v_i - v_j).n: |v_i - v_j| times the normal's
    direction error that a position error of ``gap_tol`` across its chord makes. A face
    sliding along its partner has a rate of exactly 0 only where n is exact: a tester's block
    sliding on a base rotated by 30 degrees had rates of +-1e-16, and the pairs with the
    negative ones entered a step late and kept 2.6e-6 of penetration."""
    pairs = np.asarray(pairs, dtype=np.int64).reshape(-1, 2)
    if not len(pairs):
        return np.zeros(0)
    chord = _unit_chord(x, _slots(interface, pairs))[1]
    relative = np.linalg.norm(v[pairs[:, 0]] - v[pairs[:, 1]], axis=1)
    return relative * abs(gap_tol) / chord
