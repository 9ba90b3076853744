"""Residual and tangent of one step (quasi-static or mid-point rule), Dirichlet dofs eliminated.

Dynamic (report (5.15)-(5.19)), unknown d = d_{n+1/2}:
    R(d) = M a_{n+1/2}(d) + f_int(X + d) - f_ext(t_{n+1/2}) + f_extra(x, v),
    dR/dd = 4/dt^2 M + K + K_extra;
with ``analysis.integrator = "energy_momentum"`` the Neo-Hookean part of f_int is the
discrete-gradient force f_int(x_n, x_{n+1/2}) (docs/theory.md) and K its unsymmetric tangent.
Quasi-static, unknown d = d_{n+1}: R(d) = f_int(X + d) - f_ext(t_{n+1}) + f_extra.
``extra`` terms (contact, convection) are callables of (x_eval, v_eval, rate_factor, x_start)
returning a force vector and COO triplets of its derivative with respect to x_eval.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from functools import partial
from itertools import accumulate, pairwise
from typing import Protocol, runtime_checkable

import numpy as np
import scipy.sparse as sp
from numpy.typing import NDArray

from ..dynamics.midpoint import (
    inertia_factor,
    midpoint_acceleration,
    midpoint_velocity,
    prescribed_acceleration,
)
from ..fem.loads import dirichlet_rates, dirichlet_values
from ..fem.sparse import TripletUnion
from ..solvers.newton import norm2
from .model import Model

#: The residual scale's round-off floor, as a fraction of max |diag K| times the model size.
FLOOR_RATIO = 1e-4

ExtraTerm = Callable[
    [NDArray, NDArray | None, float | None, NDArray],
    tuple[NDArray, tuple[NDArray, NDArray, NDArray]],
]


@runtime_checkable
class ReservingTerm(Protocol):
    """An extra term that also names the tangent entries it may take next (same arguments
    as its call), for the union pattern to reserve (``fem.sparse.TripletUnion.add``)."""

    def reserve(self, x_eval: NDArray, v_eval: NDArray | None, rate: float | None,
                x_start: NDArray) -> tuple[NDArray, NDArray]: ...


@runtime_checkable
class ReleasingTerm(Protocol):
    """An extra term made of pairs that a Newton step can open (the gap law's contact pairs,
    ``interfaces.ContactNewtonTerm``): which ones a step from x_eval to x_trial opens, and
    those pairs' own force and COO tangent at x_eval (x_start: the step's start)."""

    def opened(self, x_eval: NDArray, x_trial: NDArray, x_start: NDArray) -> NDArray: ...

    def part(self, mask: NDArray, x_eval: NDArray, x_start: NDArray
             ) -> tuple[NDArray, tuple[NDArray, NDArray, NDArray]]: ...


#: Rounds of :meth:`StepProblem.active_set_step` on one linearization (each a solve, with the
#: step's factor, of the columns its new pairs add); Hertz refined 8x took at most 5
MAX_RELEASE_ROUNDS = 8
#: columns of K^-1 Q solved at once by ``_KeptColumns`` (the solver's work arrays are for
#: this many; the columns solved are kept through the step's rounds: 2 vectors of the
#: unknowns' size a pair let go, Hertz 8x at most 42 pairs, 84 x 123,178 x 8 B = 83 MB)
SOLVE_COLUMNS = 16
#: singular values of J_S below this fraction of its largest are zero (its rank: measured
#: exactly half its rows at 1e-12 and at 1e-8, Hertz 4x)
RANK_RTOL = 1e-12
#: the refinement ratio of those columns (a single-precision factor's, ``linear.Factorization``):
#: V K^-1 U is only the small system of the pairs let go, and the corrected step is an inexact
#: Newton step anyway (forcing terms up to 0.1). Hertz 4x: the same counts as at the step's
#: forcing term, 37 -> 9 refinement sweeps, CPU 0.741 -> 0.611 s a step
COLUMNS_RTOL = 1e-3
#: a direction of a round's J_S or f_S whose part outside the span of the columns already
#: solved (unit vectors: an absolute size) is below this adds no column: round-off of ~1e-16
#: otherwise, and far below the columns' own error (COLUMNS_RTOL)
NEW_DIRECTION_TOL = 1e-8


class ConstraintTerm(Protocol):
    """Exact constraints h(x) = 0 with multipliers (bordered Newton system, report 2.2.1).

    ``size`` multipliers start at ``initial``; a call at (x_eval, v_eval, rate, x_start, lam)
    returns the force, its tangent (COO), h, G = dh/dx (COO, rows = multiplier index),
    B = d force / d lam (COO, cols = multiplier index) and optionally C = dh/dlam (COO).
    """

    size: int
    initial: NDArray

    def __call__(self, x_eval: NDArray, v_eval: NDArray | None, rate: float | None,
                 x_start: NDArray, lam: NDArray) -> tuple: ...


@dataclass(frozen=True)
class StepState:
    """Kinematic state at one instant; X is the material position of the particle at each node."""

    step: int
    time: float
    X: NDArray
    d: NDArray
    v: NDArray
    a: NDArray
    contact: tuple = ()  # one contact.PairState per interface (active set and history)

    @property
    def x(self) -> NDArray:
        return self.X + self.d


@dataclass
class StepProblem:
    """The nonlinear equations of the step t_n -> t_n + dt, on the free dofs."""

    model: Model
    state: StepState
    dt: float
    mass: sp.csr_matrix | None = None  # on dofs; None for quasi-static
    extra: Sequence[ExtraTerm] = ()
    constraints: Sequence[ConstraintTerm] = ()
    #: the stiffness + extra terms' pattern; pass one instance to every step's problem so that
    #: the linear solver sees the same pattern (and reuses its analysis) across steps
    union: TripletUnion = field(default_factory=TripletUnion, repr=False)
    #: round-off floor of the residual scale (see ``_evaluate``); None: set by the first tangent.
    #: The augmentations of a step pass it on, so their first residuals need no tangent.
    scale_floor: float | None = None
    #: the velocity (n, 2) :meth:`initial_guess` advances d_n with; None: the state's v
    start_velocity: NDArray | None = None
    _cache: dict = field(default_factory=dict, repr=False)
    _row_scale: NDArray | None = field(default=None, repr=False)  # see _balanced_rows
    _same_pattern: bool | None = field(default=None, repr=False)
    #: per releasing term, the pairs active_set_step has let go of in this problem's solves
    _let_go: dict = field(default_factory=dict, repr=False)

    def __post_init__(self) -> None:
        ndof = self.model.ndof
        self.length_scale = float(np.ptp(self.model.X0, axis=0).max())
        t0, t1 = self.state.time, self.state.time + self.dt
        dofs, values = dirichlet_values(self.model.prescribed, t1, ndof)
        self.fixed_rates = np.zeros(dofs.size)
        if self.dynamic:
            _, values0 = dirichlet_values(self.model.prescribed, t0, ndof)
            values = 0.5 * (values + values0)
            _, self.fixed_rates = dirichlet_rates(self.model.prescribed, t1, ndof)
        self.fixed_dofs, self.fixed_values = dofs, values
        free = np.ones(ndof, dtype=bool)
        free[dofs] = False
        self.free_dofs = np.flatnonzero(free)
        t_eval = 0.5 * (t0 + t1) if self.dynamic else t1
        self.f_ext = self.model.loads(t_eval, ndof, self.state.X)  # X: ALE meshes move

    @property
    def dynamic(self) -> bool:
        return self.mass is not None

    def initial_guess(self) -> NDArray:
        """Start from the positions the step's contact detection predicted, x_n + dt v_n (the
        mid-point rule's unknown d_{n+1/2}: d_n + v_n dt/2; quasi-static d_{n+1}: d_n + the
        last step's increment, v_n dt), then the constraints' multipliers. Quasi-static
        steps started from d_n, where the predicted pairs were still open, and their first
        solve line-searched (Hertz: 9.4 -> 8.4 Newton iterations per step at k = 1, 12.7 ->
        10.7 at k = 2). ``start_velocity`` replaces v_n (the simulation gives persistency
        pairs their partners' normal velocity, ``interfaces.persistent_velocities``)."""
        d = self.state.d.ravel()
        v = self.state.v if self.start_velocity is None else self.start_velocity
        d = d + (0.5 if self.dynamic else 1.0) * self.dt * v.ravel()
        return np.concatenate([d[self.free_dofs]] + [c.initial for c in self.constraints])

    def full(self, y: NDArray) -> NDArray:
        """All dofs of the unknown displacement from the free ones (multipliers dropped)."""
        d = np.empty(self.model.ndof)
        d[self.free_dofs] = y[: self.free_dofs.size]
        d[self.fixed_dofs] = self.fixed_values
        return d

    def multipliers(self, y: NDArray) -> list[NDArray]:
        """The multipliers of each constraint term, in order."""
        # slices, not np.split: 0.8 against 8 us a call, on every Newton solve
        ends = accumulate((c.size for c in self.constraints), initial=self.free_dofs.size)
        return [y[a:b] for a, b in pairwise(ends)]

    def _evaluate(self, y: NDArray, need_tangent: bool) -> tuple[NDArray, sp.csr_matrix | None]:
        """R on all dofs and, if asked, its tangent K; sets ``self._scale``."""
        d = self.full(y)
        x = self.state.X.ravel() + d
        f_int, K = self._internal(d, need_tangent)
        R = f_int - self.f_ext
        scale = max(norm2(f_int), norm2(self.f_ext))
        v_eval, rate = None, None
        if self.dynamic:
            inertia = self.mass @ self._acceleration(d)
            R = R + inertia
            if K is not None:
                K = self._add_mass(K, inertia_factor(self.dt))
            scale = max(scale, norm2(inertia))
            v_eval = midpoint_velocity(d, self.state.d.ravel(), self.dt).reshape(-1, 2)
            rate = 2.0 / self.dt
        triplets, reserves = [], []
        for term in self.extra:
            f, coo = term(x.reshape(-1, 2), v_eval, rate, self.state.x)
            R = R + f
            scale = max(scale, norm2(f))
            triplets.append(coo)
            if isinstance(term, ReservingTerm):
                reserves.append(partial(term.reserve, x.reshape(-1, 2), v_eval, rate,
                                        self.state.x))
        h, G, B, f_c, k_c = self._constraints(x.reshape(-1, 2), v_eval, rate, y, R.size)
        if h.size:
            R = R + f_c
            triplets += k_c
        if K is not None:
            K = _add_triplets(K, triplets, self.union, reserves)
            # Forces computed from positions of size L carry round-off ~ eps |K| L: never ask
            # for less. Kept from the first tangent, so residual-only calls use it too.
            self.scale_floor = FLOOR_RATIO * np.abs(K.diagonal()).max() * self.length_scale
        if h.size:
            h, G = self._balanced_rows(h, G)
        self._blocks = (h, G, B)
        self._scale = float(max(scale, self.scale_floor))
        return R, K

    def _acceleration(self, d: NDArray) -> NDArray:
        """a_{n+1/2} at d = d_{n+1/2}: the mid-point rule's on the free dofs; on the prescribed
        ones the step's mean (v_{n+1} - v_n)/dt of their motion (``fixed_rates``), as
        ``dynamics.midpoint.end_of_step`` reports it. The rule's 2 (v_{n+1/2} - v_n)/dt there
        was twice the kink of a support's motion, and through a consistent mass it pushed the
        free neighbours with the odd-even velocity the rule left at the support."""
        d_n, v_n = self.state.d.ravel(), self.state.v.ravel()
        a = midpoint_acceleration(d, d_n, v_n, self.dt)
        a[self.fixed_dofs] = prescribed_acceleration(v_n[self.fixed_dofs], self.fixed_rates,
                                                     self.dt)
        return a

    def _balanced_rows(self, h: NDArray, G: sp.csr_matrix) -> tuple[NDArray, sp.csr_matrix]:
        """h, G and C with every constraint row in force units: row p times k / |G_p|, k the
        largest diagonal stiffness (``scale_floor``'s), fixed at the problem's first call. A
        row scale leaves the Newton step unchanged, but |R| then weighs a constraint error
        like the force that would cause it: unscaled, the gap law's L_c g (length^2) against
        forces made the line search reject the full step that closes a gap at first touch
        (its nonlinear force residual >> L_c g) and crawl in 1/16 steps (issue 16)."""
        if self._row_scale is None or self._row_scale.size != h.size:
            stiffness = self.scale_floor / (FLOOR_RATIO * self.length_scale)
            norms = np.sqrt(np.asarray(G.multiply(G).sum(axis=1)).ravel())
            self._row_scale = np.where(norms > 0.0, stiffness / np.maximum(norms, 1e-300), 1.0)
        rows = sp.diags(self._row_scale, format="csr")
        self._multiplier_block = (rows @ self._multiplier_block).tocsr()
        return self._row_scale * h, (rows @ G).tocsr()

    def _internal(self, d: NDArray, need_tangent: bool) -> tuple[NDArray, sp.csr_matrix | None]:
        """Internal force at displacement d (= d_{n+1/2} when dynamic) and its tangent; the
        energy-momentum integrator evaluates the Neo-Hookean stress between d_n and
        d_{n+1} = 2 d - d_n."""
        d_start = (self.state.d if self.dynamic
                   and self.model.analysis.integrator == "energy_momentum" else None)
        assembler = self.model.assembler
        f_int, K, _ = assembler.internal(self.state.X, d=d, need_tangent=need_tangent,
                                         d_start=d_start,
                                         spare=self.union.spare(assembler.pattern.nnz))
        return f_int, K

    def _add_mass(self, K: sp.csr_matrix, factor: float) -> sp.csr_matrix:
        """K + factor M, adding data arrays when M was assembled in K's pattern."""
        M = self.mass
        if self._same_pattern is None:
            self._same_pattern = (M.shape == K.shape and M.nnz == K.nnz
                                  and np.array_equal(M.indptr, K.indptr)
                                  and np.array_equal(M.indices, K.indices))
        if not self._same_pattern:
            return K + factor * M
        _add_scaled(K.data, factor, M.data)
        return K

    def _constraints(self, x, v_eval, rate, y, ndof):
        """h, G (m x ndof), B (ndof x m) of all constraint terms, their force and the COO
        triplets of its tangent."""
        if not self.constraints:
            return np.zeros(0), None, None, None, []
        force = np.zeros(ndof)
        hs, gs, bs, cs, tangents = [], [], [], [], []
        for c, lam in zip(self.constraints, self.multipliers(y), strict=True):
            f, k, h, (gr, gc, gv), (br, bc, bv), *rest = c(x, v_eval, rate, self.state.x, lam)
            # optional dh/dlam block of a term whose constraints depend on its own multipliers
            cs.append(sp.csr_matrix((rest[0][2], (rest[0][0], rest[0][1])),
                                    shape=(c.size, c.size)) if rest else
                      sp.csr_matrix((c.size, c.size)))
            force += f
            tangents.append(k)
            hs.append(h)
            gs.append(sp.csr_matrix((gv, (gr, gc)), shape=(c.size, ndof)))
            bs.append(sp.csr_matrix((bv, (br, bc)), shape=(ndof, c.size)))
        self._multiplier_block = sp.block_diag(cs, format="csr")
        return (np.concatenate(hs), sp.vstack(gs).tocsr(), sp.hstack(bs).tocsr(), force,
                tangents)

    def residual(self, y: NDArray) -> tuple[NDArray, float]:
        # without a floor, the first call also builds the tangent (for the floor and the first
        # Newton step); the cache is replaced, so its tangent goes first (not two alive)
        self._cache = {}
        R, K = self._evaluate(y, need_tangent=self.scale_floor is None)
        self._cache = {"y": y.copy(), "K": K, "blocks": self._blocks,
                       "C": getattr(self, "_multiplier_block", None), "R": R}
        h = self._blocks[0]
        return np.concatenate([R[self.free_dofs], h]), self._scale

    def active_set_step(self, y: NDArray, dy: NDArray,
                        solve: Callable[[NDArray, float], NDArray], eta: float
                        ) -> NDArray | None:
        """The Newton step dy = -K^-1 R at y, K factored (``solve``), corrected for the pairs
        it opens (quasi-static steps; ``newton``'s active_set): those pairs' force and tangent
        taken out of R and K, repeated while the corrected step opens more of them (a
        semismooth Newton's active-set loop on one linearization). Without it the pairs a
        step's start took in beyond the contact zone's edge were let go one a side per Newton
        iteration, each with a factorization: with every pair pressed the outermost pair
        alone pulls, and only once it is released does the next one inward go tensile
        (Hertz refined 8x: ~3 pairs a side at a step's start, benchmarks/README.md, session
        48). Pairs once let go stay so within the step; the next iteration's own branches
        decide from there. ``solve(B, rtol)``: K's factor; eta: dy's forcing term (the
        corrected step's). A pair is let go of once in the problem's solves: one whose
        solution lies at the kink (gap ~ 0) was otherwise pressed and let go in turn, every
        other iteration (delamination, step 13: no convergence in 60 iterations). None if
        the step opens no pair."""
        terms = [t for t in self.extra if isinstance(t, ReleasingTerm)]
        if self.dynamic or not terms:
            return None
        x_eval, x_start = self._positions(y), self.state.x
        let_go = [self._let_go.setdefault(id(t), np.zeros(len(t.state), bool)) for t in terms]
        opened = [np.zeros(0, bool)] * len(terms)
        kept = _KeptColumns(dy.size, partial(solve, rtol=max(eta, COLUMNS_RTOL)))
        step = None
        for _ in range(MAX_RELEASE_ROUNDS):
            x_trial = self._positions(y + (dy if step is None else step))
            now = [t.opened(x_eval, x_trial, x_start) & ~g
                   for t, g in zip(terms, let_go, strict=True)]
            grown = [n | o if o.size else n for n, o in zip(now, opened, strict=True)]
            if sum(int(g.sum()) for g in grown) == sum(int(o.sum()) for o in opened):
                break
            opened = grown
            parts = [t.part(o, x_eval, x_start)
                     for t, o in zip(terms, opened, strict=True) if o.any()]
            corrected = self._step_without(parts, dy, kept)
            if corrected is None:
                break
            step = corrected
        if step is not None:
            for g, o in zip(let_go, opened, strict=True):
                g |= o
        return step

    def _positions(self, y: NDArray) -> NDArray:
        return self.state.X + self.full(y).reshape(-1, 2)

    def _step_without(self, parts: list, dy: NDArray, kept: _KeptColumns
                      ) -> NDArray | None:
        """The Newton step x = -(K - J_S)^-1 (R - f_S) from dy = -K^-1 R, the force f_S and
        tangent J_S of the pairs S (``parts``) and ``kept``, the columns W = K^-1 Q of an
        orthonormal Q whose span holds the range of J_S and f_S (extended here by what
        these pairs add to it), by the Sherman-Morrison-Woodbury formula on J_S = Q V,
        V = Q^T J_S: with f_S = Q c, x = dy + W (c + t), (I - V W) t = V (dy + W c). No
        factorization, and no solve but the new columns of Q (to COLUMNS_RTOL: the step's
        correction W (c + t) is as accurate as t, which V W limits to that anyway). None if
        I - V W is singular (the pairs held a body alone)."""
        place = np.full(self.model.ndof, -1, dtype=np.int64)
        place[self.free_dofs] = np.arange(self.free_dofs.size)
        force = sum(f for f, _ in parts)
        rows, cols, vals = (np.concatenate([np.asarray(c[i]) for _, c in parts])
                            for i in range(3))
        inside = (place[rows] >= 0) & (place[cols] >= 0)
        J = sp.coo_matrix((vals[inside], (place[rows[inside]], place[cols[inside]])),
                          shape=(dy.size, dy.size)).tocsr()  # duplicates summed
        J.eliminate_zeros()  # the entries the pairs do not change
        loaded = place[np.flatnonzero(force)]
        where = np.union1d(np.flatnonzero(np.diff(J.indptr)), loaded[loaded >= 0])
        block = J[where]
        moved = np.unique(block.indices)  # the unknowns J_S reads
        tangent = block[:, moved].toarray()
        f_S = force[self.free_dofs[where]]
        kept.extend(where, _range_with(tangent, f_S))
        Q = kept.basis[np.searchsorted(kept.rows, where)]  # Q's rows at the unknowns where
        V = Q.T @ tangent
        VW = V @ kept.at(moved)
        c = Q.T @ f_S
        try:
            t = np.linalg.solve(np.eye(VW.shape[0]) - VW, V @ dy[moved] + VW @ c)
        except np.linalg.LinAlgError:
            return None
        return dy + kept.times(c + t)

    def full_residual(self, y: NDArray) -> NDArray:
        """R on all dofs, the prescribed ones included (there: the support reactions), from
        the last residual call when it was at y."""
        if "R" in self._cache and np.array_equal(self._cache["y"], y):
            return self._cache["R"]
        return self._evaluate(y, need_tangent=False)[0]

    def jacobian(self, y: NDArray) -> sp.csr_matrix:
        if ("y" not in self._cache or not np.array_equal(self._cache["y"], y)
                or self._cache.get("K", self._cache.get("Kff")) is None):
            self._cache = {}  # replaced: its tangent need not live beside the new one
            R, K = self._evaluate(y, need_tangent=True)
            self._cache = {"y": y.copy(), "K": K, "blocks": self._blocks,
                           "C": getattr(self, "_multiplier_block", None)}
        if "Kff" not in self._cache:
            # only the free block is kept: the whole K's data (an array of the union's size)
            # would otherwise live beside it through the factorization (issue 18, memory)
            self._cache["Kff"] = self._free_block(self._cache.pop("K"))  # K spent
        Kff = self._cache["Kff"]
        h, G, B = self._cache["blocks"]
        if not h.size:
            return Kff
        C = self._cache["C"]
        return sp.bmat([[Kff, B[self.free_dofs]], [G[:, self.free_dofs], C]], format="csr")

    def _free_block(self, K: sp.csr_matrix) -> sp.csr_matrix:
        """K restricted to the free dofs (all of K when nothing is prescribed), made in K's
        own data array: K is spent."""
        if self.fixed_dofs.size == 0:
            return K
        return self.union.free_block(K, self.free_dofs, spend=True)


def _range_with(tangent: NDArray, force: NDArray) -> NDArray:
    """Unit columns spanning the range of ``tangent`` (orthonormal: its left singular vectors
    above RANK_RTOL of the largest singular value) and ``force``'s direction (as a rule in
    that range already: a pair's force acts on both its nodes, like its tangent's rows)."""
    u, sigma, _ = np.linalg.svd(tangent, full_matrices=False)
    rank = int(np.count_nonzero(sigma > RANK_RTOL * sigma.max(initial=0.0)))
    size = np.linalg.norm(force)
    return np.column_stack([u[:, :rank]] + ([force / size] if size > 0.0 else []))


class _KeptColumns:
    """The columns W = K^-1 Q of one linearization's ``active_set_step``, Q orthonormal
    (nonzero on a few rows) and extended round by round by the directions a round's pairs
    add to its span: each round solves only those, not again those of the earlier rounds'
    pairs (Hertz 8x: 1-5 rounds a step, each round's pairs a superset of the last's).
    ``solve(B)``: K^-1 B with the step's factor."""

    def __init__(self, size: int, solve: Callable[[NDArray], NDArray]) -> None:
        self.size, self.solve = size, solve
        self.rows = np.zeros(0, dtype=np.int64)  # the unknowns Q is nonzero at, sorted
        self.basis = np.zeros((0, 0))  # Q on those rows
        self.blocks: list[NDArray] = []  # W, SOLVE_COLUMNS columns a block

    def extend(self, where: NDArray, directions: NDArray) -> None:
        """Q extended so that its span holds the columns of ``directions`` (unit vectors on
        the unknowns ``where``), to NEW_DIRECTION_TOL; W with it."""
        rows = np.union1d(self.rows, where)
        Q = np.zeros((rows.size, self.basis.shape[1]))
        Q[np.searchsorted(rows, self.rows)] = self.basis
        D = np.zeros((rows.size, directions.shape[1]))
        D[np.searchsorted(rows, where)] = directions
        for _ in range(2):  # Gram-Schmidt twice: orthogonal to round-off
            D -= Q @ (Q.T @ D)
        u, sigma, _ = np.linalg.svd(D, full_matrices=False)
        new = u[:, sigma > NEW_DIRECTION_TOL]
        new -= Q @ (Q.T @ new)  # D's round-off against Q, divided by a small sigma
        self.rows, self.basis = rows, np.column_stack([Q, new])
        for start in range(0, new.shape[1], SOLVE_COLUMNS):
            E = np.zeros((self.size, min(SOLVE_COLUMNS, new.shape[1] - start)))
            E[rows] = new[:, start:start + E.shape[1]]
            self.blocks.append(self.solve(E))

    def at(self, index: NDArray) -> NDArray:
        """W's rows at the unknowns ``index``."""
        return np.column_stack([b[index] for b in self.blocks]) if self.blocks else (
            np.zeros((index.size, 0)))

    def times(self, coefficients: NDArray) -> NDArray:
        """W times ``coefficients``."""
        ends = pairwise(accumulate((b.shape[1] for b in self.blocks), initial=0))
        return sum((b @ coefficients[i:j] for b, (i, j) in zip(self.blocks, ends, strict=True)),
                   np.zeros(self.size))


def _add_triplets(K: sp.csr_matrix, triplets: list, union: TripletUnion,
                  reserves: Sequence[Callable[[], tuple]] = ()) -> sp.csr_matrix:
    """K plus the COO triplets (rows, cols, values) of the extra terms, in the union pattern
    (explicit zeros kept, see :mod:`ntncontact.fem.sparse`), which reserves the entries of
    ``reserves`` (each () -> (rows, cols)) when it grows."""
    kept = [(r, c, v) for r, c, v in triplets if len(v)]
    if not kept:
        # no contact now, but once a union exists K goes on in its pattern (zeros in the
        # pairs' places): back to K's own pattern and to the union at the next touch were
        # two new analyses per contact episode (issue 18)
        return union.add(K, _NONE, _NONE, _NO_VALUES) if union.holds(K) else K
    rows, cols, vals = (np.concatenate([np.asarray(t[i]) for t in kept]) for i in range(3))
    return union.add(K, rows, cols, vals, partial(_reserved, reserves) if reserves else None)


#: entries :func:`_add_scaled` works on at a time
CHUNK = 1 << 16


def _add_scaled(out: NDArray, factor: float, values: NDArray) -> None:
    """``out += factor * values`` a chunk at a time: the same bits, and no temporary of the
    arrays' size beside them (the ring refined 8x's tangent and its mass data: issue 18)."""
    for start in range(0, out.size, CHUNK):
        stop = start + CHUNK
        out[start:stop] += factor * values[start:stop]


def _reserved(reserves: Sequence[Callable[[], tuple]]) -> tuple[NDArray, NDArray]:
    found = [reserve() for reserve in reserves]
    return (np.concatenate([r for r, _ in found]), np.concatenate([c for _, c in found]))


_NONE = np.zeros(0, dtype=np.int64)
_NO_VALUES = np.zeros(0)
