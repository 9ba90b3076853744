"""External loads and prescribed displacements, each scaled by a function of time.

Loads are dead loads defined on the reference configuration: a traction or pressure on an edge
set (per unit reference length), point forces on a node set, a body force per unit reference
volume, gravity (an acceleration g: the body force rho g). Their nodal vectors are computed once;
at time t the external force is sum_k s_k(t) f_k. Gravity on an ALE body is the exception: its
nodal vector follows the body's moving reference mesh (``MeshBodyForce``).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from .q4 import N_GP, reference_gradients

#: A time within this fraction of the time scale of a function's time point is at the point
#: (``TimeFunction.rate_before``).
KINK_ROUNDOFF = 1e-9


@dataclass(frozen=True)
class TimeFunction:
    """Piecewise-linear function of time through ``points`` (t, value), constant outside."""

    times: tuple[float, ...] = (0.0,)
    values: tuple[float, ...] = (1.0,)

    def __post_init__(self) -> None:
        if len(self.times) != len(self.values) or not self.times:
            raise ValueError("a time function needs as many times as values (at least one)")
        if np.any(np.diff(self.times) <= 0):
            raise ValueError(f"time function times must increase strictly: {self.times}")

    def __call__(self, t: float) -> float:
        return float(np.interp(t, self.times, self.values))

    def rate(self, t: float) -> float:
        """ds/dt just after t: the slope of the segment that t starts (0 outside the times)."""
        return self._slope(int(np.searchsorted(self.times, t, side="right")))

    def rate_before(self, t: float) -> float:
        """ds/dt just before t: the slope of the segment that ends at t (0 outside the times).
        A step ending at t gives its prescribed dofs this rate (docs/theory.md, "Prescribed
        motion"): the segment after t is motion the step has not made. A t within round-off
        of a time point (1e-9 of the time scale) is that point: step 12 of dt = 0.025 ends at
        0.30000000000000004, which must take the rate of the segment that ends at 0.3."""
        scale = max(abs(self.times[0]), abs(self.times[-1]), abs(t), 1e-300)
        t = t - KINK_ROUNDOFF * scale  # just before t: a point within round-off counts as t
        return self._slope(int(np.searchsorted(self.times, t, side="left")))

    def _slope(self, k: int) -> float:
        """The slope of the segment that ends at time point k (0 outside the times)."""
        if k == 0 or k == len(self.times):
            return 0.0
        return (self.values[k] - self.values[k - 1]) / (self.times[k] - self.times[k - 1])


def edge_traction_vector(
    X: NDArray, edges: NDArray, traction: NDArray | None, pressure: float | None, ndof: int
) -> NDArray:
    """Consistent nodal forces of a uniform traction (vector) or pressure on linear edges.

    Edges are oriented body-on-left, so the outward reference normal of (a, b) is
    (dy, -dx)/L; a positive pressure pushes against the surface (along -n).
    """
    a, b = edges[:, 0], edges[:, 1]
    d = X[b] - X[a]
    length = np.hypot(d[:, 0], d[:, 1])
    if pressure is not None:
        normal = np.column_stack([d[:, 1], -d[:, 0]]) / length[:, None]
        per_edge = -pressure * normal * length[:, None]
    else:
        per_edge = np.outer(length, np.asarray(traction, dtype=float))
    f = np.zeros((ndof // 2, 2))
    np.add.at(f, a, 0.5 * per_edge)
    np.add.at(f, b, 0.5 * per_edge)
    return f.ravel()


def point_load_vector(nodes: NDArray, force: NDArray, ndof: int) -> NDArray:
    """The same force vector on every node of the set."""
    f = np.zeros((ndof // 2, 2))
    np.add.at(f, nodes, np.asarray(force, dtype=float))
    return f.ravel()


def body_force_vector(X: NDArray, cells: NDArray, force: NDArray, ndof: int) -> NDArray:
    """int N_a b dV over the reference configuration for a uniform body force b."""
    _, weight = reference_gradients(X[cells])
    nodal = np.einsum("eg,ga->ea", weight, N_GP)
    per_node = np.bincount(cells.ravel(), weights=nodal.ravel(), minlength=ndof // 2)
    return (per_node[:, None] * np.asarray(force, dtype=float)).ravel()


@dataclass(frozen=True)
class MeshBodyForce:
    """A uniform body force per unit volume of a body's CURRENT reference mesh (gravity rho g
    on an ALE body): its nodal vector int N_a b dX is rebuilt from the step's reference
    coordinates, so that it stays the row sums of the rebuilt mass matrix times g (an ALE
    remap moves the nodes, hence the particles, the volumes and the masses they carry)."""

    cells: NDArray  # global node numbers of the body's cells
    force: NDArray  # (2,) per unit volume
    function: TimeFunction

    def vector(self, X: NDArray, ndof: int) -> NDArray:
        return body_force_vector(np.asarray(X).reshape(-1, 2), self.cells, self.force, ndof)


@dataclass(frozen=True)
class LoadCase:
    """Nodal force patterns and their time functions: f_ext(t) = sum_k s_k(t) f_k, plus the
    body forces that follow a moving (ALE) reference mesh, evaluated on ``X`` (default: the
    reference coordinates ``X0`` they were built with, i.e. an unmoved mesh)."""

    patterns: tuple[NDArray, ...]
    functions: tuple[TimeFunction, ...]
    on_mesh: tuple[MeshBodyForce, ...] = ()
    X0: NDArray | None = None

    def __call__(self, t: float, ndof: int, X: NDArray | None = None) -> NDArray:
        f = np.zeros(ndof)
        for pattern, func in zip(self.patterns, self.functions, strict=True):
            f += func(t) * pattern
        coordinates = self.X0 if X is None else X
        for load in self.on_mesh:
            f += load.function(t) * load.vector(coordinates, ndof)
        return f


@dataclass(frozen=True)
class Prescribed:
    """Prescribed displacement components: u[dofs] = values * s(t)."""

    dofs: NDArray
    values: NDArray
    function: TimeFunction
    #: the support set it comes from, ``<body>_<set>`` (history.csv's reaction columns)
    label: str = "prescribed"

    def at(self, t: float) -> NDArray:
        return self.values * self.function(t)

    def rate_before(self, t: float) -> NDArray:
        """The dofs' velocity at t as a step ending at t reaches it
        (``TimeFunction.rate_before``)."""
        return self.values * self.function.rate_before(t)


def same_motions(values_a: NDArray, function_a: TimeFunction, values_b: NDArray,
                 function_b: TimeFunction) -> NDArray:
    """Whether each pair of prescribed components values_a * s_a(t) and values_b * s_b(t)
    agree at all times (to 1e-12 relative), compared as functions of time, not as objects:
    0.2 x ramp and 0.1 x (twice the ramp) are one motion. Both are linear between their
    functions' points and constant outside them, so comparing at those points suffices."""
    times = np.union1d(function_a.times, function_b.times)
    ua = np.outer(values_a, [function_a(t) for t in times])
    ub = np.outer(values_b, [function_b(t) for t in times])
    scale = np.maximum(np.abs(ua).max(axis=1), np.abs(ub).max(axis=1))
    return np.all(np.abs(ua - ub) <= 1e-12 * scale[:, None] + 1e-12 * np.abs(ub), axis=1)


def conflicting_dofs(a: Prescribed, b: Prescribed) -> tuple[NDArray, NDArray, NDArray]:
    """The dofs that both ``a`` and ``b`` prescribe with different motions, with their values
    in ``a`` and in ``b``: the build refuses them, since only one of the two would hold."""
    common, ia, ib = np.intersect1d(a.dofs, b.dofs, return_indices=True)
    differ = ~same_motions(a.values[ia], a.function, b.values[ib], b.function)
    return common[differ], a.values[ia][differ], b.values[ib][differ]


def dirichlet_values(prescribed: tuple[Prescribed, ...], t: float, ndof: int) -> tuple[NDArray,
                                                                                        NDArray]:
    """Sorted unique constrained dofs and their values at time t (later entries win; the
    build refuses two entries that give a dof different motions, ``conflicting_dofs``, so
    the order only decides which entry a dof's reaction is reported with)."""
    return _prescribed(prescribed, ndof, lambda p: p.at(t))


def dirichlet_rates(prescribed: tuple[Prescribed, ...], t: float, ndof: int) -> tuple[NDArray,
                                                                                       NDArray]:
    """The dofs of :func:`dirichlet_values` and their velocities at the end t of a step (the
    rate of the segment that ends at t; later entries win, as for the values)."""
    return _prescribed(prescribed, ndof, lambda p: p.rate_before(t))


def _prescribed(prescribed: tuple[Prescribed, ...], ndof: int,
                of: Callable[[Prescribed], NDArray]) -> tuple[NDArray, NDArray]:
    """Sorted unique constrained dofs and ``of`` each entry at them (later entries win)."""
    if not prescribed:
        return np.zeros(0, dtype=np.int64), np.zeros(0)
    vals = np.full(ndof, np.nan)
    for p in prescribed:
        vals[p.dofs] = of(p)
    dofs = np.flatnonzero(~np.isnan(vals))
    return dofs, vals[dofs]
