"""Newton-Raphson with backtracking line search on plain residual/Jacobian callables.

Knows nothing about mechanics: the caller gives ``residual(y) -> (R, scale)`` where ``scale`` is
the magnitude of the forces in play (so the tolerance is relative to them), and
``jacobian(y) -> sparse matrix``. Both act on the unknowns only (Dirichlet dofs eliminated).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp
from numpy.typing import NDArray

from .linear import Factorization


def norm2(v: NDArray) -> float:
    """Euclidean norm of a 1-D array: what ``np.linalg.norm`` computes (sqrt of the dot
    product), without its dispatch cost (~5 us, paid ~35 000 times in an impact run). A BLAS
    dot: a run keeps the BLAS on one thread (:func:`ntncontact.threads.serial_blas`). Squares
    that overflow (entries above ~1e154: a density of 1e300) are scaled first, so a finite
    vector has a finite norm and no NumPy warning reaches the user."""
    with np.errstate(over="ignore"):
        square = float(np.dot(v, v))
    if math.isfinite(square) or not np.all(np.isfinite(v)):
        return math.sqrt(square)
    scale = float(np.abs(v).max())
    return scale * math.sqrt(float(np.dot(v / scale, v / scale)))


class NewtonError(RuntimeError):
    """Newton did not converge: diverged, stalled or hit its iteration limit."""

    def __init__(self, message: str, residual_norm: float, iterations: int) -> None:
        super().__init__(message)
        self.residual_norm = residual_norm
        self.iterations = iterations


@dataclass(frozen=True)
class NewtonSettings:
    """Tolerances: converged when |R| <= rtol * scale + atol and |dy| <= dtol * (|y| + length)."""

    rtol: float = 1e-10
    atol: float = 0.0
    dtol: float = 1e-8
    max_iterations: int = 25
    line_search_steps: int = 5
    divergence_factor: float = 1e8
    #: modified Newton (see :class:`FactorCache`): a step with a kept factor is accepted if it
    #: shrinks |R| at least by this factor, else the Jacobian is factored afresh
    reuse_contraction: float = 0.1
    #: at most this many kept-factor steps in a row within one solve before a fresh
    #: factorization (bounds the linear convergence of modified Newton when the contraction
    #: setting is lax). The count restarts at each solve while a FactorCache's factor serves
    #: all the solves of a step, so a factor can serve longer runs over the augmentations
    #: (tester Y: 11 in the ring impact, 13 in the disk drop); a count kept with the cache was
    #: measured slower (benchmarks/README.md, session 42). 0 factors at every iteration: full
    #: Newton (``analysis.newton.max_reused_steps``)
    max_reused_steps: int = 4
    #: let a solve's first full step raise |R| on trial (:class:`_Watchdog`); the caller
    #: turns it on where it was measured to help (``Simulation``: runs without contact)
    watchdog: bool = False


@dataclass
class NewtonResult:
    y: NDArray
    iterations: int
    residual_norms: list[float] = field(default_factory=list)
    #: stopped at the caller's ``early_ratio`` before the tolerances were met
    early: bool = False


Residual = Callable[[NDArray], tuple[NDArray, float]]
Jacobian = Callable[[NDArray], sp.spmatrix]
LinearSolve = Callable[[sp.spmatrix, NDArray], NDArray]
Factorize = Callable[[sp.spmatrix], Callable[[NDArray], NDArray]]
#: (y, dy, solve, eta) -> the step corrected for the branches of the Jacobian it switches,
#: or None if it switches none; ``solve(B, rtol)`` solves with the factor that gave dy, eta
#: that step's forcing term (``newton``)
ActiveSetStep = Callable[[NDArray, NDArray, Callable[[NDArray, float], NDArray], float],
                         NDArray | None]


@dataclass
class FactorCache:
    """A factored Jacobian kept across Newton iterations and across Newton solves of nearby
    problems (the augmentations of one step, whose Jacobians differ only by the multiplier
    and mesh updates): modified Newton. Its steps are only accepted while they contract the
    residual (``NewtonSettings.reuse_contraction``), so the converged answer is unchanged;
    what is saved is the factorization, the dominant cost of small contact problems."""

    factorize: Factorize
    factor: Callable[[NDArray], NDArray] | None = None
    size: int = -1
    factorizations: int = 0
    reused_steps: int = 0

    def usable(self, size: int) -> bool:
        return (self.factor is not None and self.size == size
                and getattr(self.factor, "valid", True))

    def refresh(self, matrix: sp.spmatrix) -> None:
        self.factor, self.size = self.factorize(matrix), matrix.shape[0]
        self.factorizations += 1

    def drop(self) -> None:
        self.factor = None

    def solve(self, b: NDArray, rtol: float) -> NDArray:
        """The kept factor's solution of A x = b to |b - A x| <= rtol |b|, where the factor
        can stop there (a :class:`~ntncontact.solvers.linear.Factorization`; a factor of
        another kind solves as it does)."""
        if isinstance(self.factor, Factorization):
            return self.factor(b, rtol)
        return self.factor(b)


#: bounds of :func:`forcing_term`: the strictest is what every solve had before the forcing
#: term (``linear.MIXED_RTOL``), the loosest Eisenstat and Walker's usual cap
FORCING_MIN = 1e-6
FORCING_MAX = 0.1
#: Eisenstat and Walker's gamma of their "choice 2", gamma (|R_k| / |R_k-1|)^2
FORCING_GAMMA = 0.9


#: A kept-factor step (modified Newton) is solved to |R + A_kept dy| <= this fraction of
#: ``NewtonSettings.reuse_contraction`` times |R| at least (the forcing term where that is
#: looser): the step is taken only if it contracts |R| by reuse_contraction, the stale matrix
#: being what limits it, so solving A_kept further buys nothing, and a single-precision
#: factor's first solution (1e-7 to 2e-3 |R|) then needs no refinement sweep as a rule. Ring
#: refined 8x: 99 -> 17 sweeps, the same 10.0 Newton iterations and 5.94 augmentations a
#: contact step, 0.53 -> 0.47 s a step in benchmarks/scaling.py (benchmarks/README.md,
#: session 54)
KEPT_STEP_FRACTION = 1e-2


def forcing_term(norms: list[float]) -> float:
    """eta of the inexact Newton step |J dy + R| <= eta |R| at |R| = norms[-1]: Eisenstat and
    Walker's choice 2 from the last contraction (a step need not be solved much better than
    its Newton contraction will be; quadratic convergence asks eta ~ |R|), within
    [FORCING_MIN, FORCING_MAX], and FORCING_MIN at a solve's first step. Only a
    single-precision factor's refinement reads it (``linear.Factorization``): its first
    solution leaves 1e-7 to 2e-3 |R| (general mode, ring refined 8x), and a sweep costs a
    solve. Measured at k = 8 (benchmarks/README.md, session 44): ring 244 -> 130 sweeps, the
    same iterations; Hertz 54 -> 34, 138 -> 139 iterations. A term that also loosened the
    steps near the tolerance (a tenth of it in the linear residual) saved more sweeps (ring
    53, Hertz 11) but cost Hertz's load holds an augmentation each (142 iterations)."""
    eta = FORCING_MIN
    if len(norms) > 1 and norms[-2] > 0.0:
        eta = FORCING_GAMMA * (norms[-1] / norms[-2]) ** 2
    return min(max(eta, FORCING_MIN), FORCING_MAX)


def newton(
    residual: Residual,
    jacobian: Jacobian,
    solve: LinearSolve,
    y0: NDArray,
    settings: NewtonSettings = NewtonSettings(),
    length_scale: float = 1.0,
    factors: FactorCache | None = None,
    early_ratio: float = 0.0,
    active_set: ActiveSetStep | None = None,
) -> NewtonResult:
    """Solve R(y) = 0 from ``y0``; raise :class:`NewtonError` with the last residual if it fails.

    With ``factors``, a kept factorization is tried first (modified Newton) and replaced by a
    fresh one as soon as its step does not contract the residual enough. ``early_ratio``: also
    return (``early=True``) once |R| <= early_ratio |R(y0)|, for callers that only need a rough
    solution (the augmentations before the last, see ``Simulation._test_augmentation``).
    ``active_set``: called on every step of a fresh factor (with ``factors``) to correct it
    for the branches of a piecewise residual that the step itself switches (a semismooth
    Newton's active-set loop on the one linearization, ``StepProblem.active_set_step``);
    the next iteration then factors the Jacobian afresh."""
    y = np.array(y0, dtype=float)
    R, scale = residual(y)
    first = norm2(R)
    norms = [first]
    if y.size == 0 or first <= settings.atol or first == 0.0:
        return NewtonResult(y, 0, norms)
    reused = 0
    limit = settings.divergence_factor * max(first, 1e-300)
    watch = _Watchdog(limit, settings.watchdog)
    for it in range(1, settings.max_iterations + 1):
        step = None
        eta = forcing_term(norms)
        if reused < settings.max_reused_steps:
            step = _modified_step(residual, y, R, norms[-1], factors, settings, eta)
        reused = reused + 1 if step is not None else 0
        try:
            if step is not None:
                dy, y, R, scale = step
            else:
                if factors is None:
                    dy = -solve(jacobian(y), R)
                else:  # J factored and kept, the step solved to the forcing term eta
                    factors.refresh(jacobian(y))
                    dy = -factors.solve(R, eta)
                corrected = (active_set(y, dy, factors.solve, eta)
                             if active_set is not None and factors is not None else None)
                if corrected is not None:
                    # the factor's matrix presses the pairs the step opened: modified Newton
                    # with it took more iterations (Hertz 4x 5.6 -> 6.4 a step), and with it
                    # corrected as the step was (8x 6.1 -> 7.6, 45 -> 30 factorizations)
                    dy = corrected
                    factors.drop()
                if not np.all(np.isfinite(dy)):
                    raise NewtonError("linear solve returned non-finite values", norms[-1], it)
                watch.used = watch.used or it > 1  # only a solve's first step
                y, R, scale = watch.line_search(residual, y, dy, norms[-1], settings)
        except NewtonError:
            if not watch.pending:
                raise
            y, dy, R, scale = watch.revert(residual, settings)
        if watch.pending and not watch.progress(norm2(R)):
            y, dy, R, scale = watch.revert(residual, settings)
        norms.append(norm2(R))
        if not np.isfinite(norms[-1]) or norms[-1] > limit:
            raise NewtonError(f"diverged (|R| = {norms[-1]:.3e})", norms[-1], it)
        small_r = norms[-1] <= settings.rtol * scale + settings.atol
        small_d = norm2(dy) <= settings.dtol * (norm2(y) + length_scale)
        if small_r and (small_d or norms[-1] <= 1e-3 * settings.rtol * scale):
            return NewtonResult(y, it, norms)
        if norms[-1] <= early_ratio * first:
            return NewtonResult(y, it, norms, early=True)
    raise NewtonError(
        f"no convergence in {settings.max_iterations} iterations (|R| = {norms[-1]:.3e}, "
        f"tolerance {settings.rtol * scale + settings.atol:.3e}){_floor_note(norms, scale)}",
        norms[-1],
        settings.max_iterations,
    )


#: a residual that stalls below this fraction of its force scale is at its round-off floor
ROUNDOFF_FLOOR = 1e-9


def _floor_note(norms: list[float], scale: float) -> str:
    """Why a stalled Newton failed, when it stalled at round-off: the last 5 residuals within
    a factor 10 of each other, the smallest below ROUNDOFF_FLOOR of the force scale (a
    tester's rtol = 1e-12 on a free block: |R| 6.6e-11 against a tolerance of 2.8e-11, which
    the arithmetic cannot reach, reported as a plain failure)."""
    last = norms[-5:]
    floor = min(norms)
    if len(last) < 5 or max(last) > 10.0 * min(last) or not 0.0 < floor < ROUNDOFF_FLOOR * scale:
        return ""
    return (f": the residual stalled at its round-off floor, {floor / scale:.1e} of the force "
            "scale, which analysis.newton.rtol must stay above; the floor grows with the "
            "coordinates' size times the stiffest penalty (a tester's static contact 1000 "
            "units from the origin with a penalty 500 times the elements' stiffness: a "
            "smaller penalty_factor, or the model near the origin, lowers it)")


def _modified_step(residual: Residual, y: NDArray, R: NDArray, norm0: float,
                   factors: FactorCache | None, settings: NewtonSettings, eta: float):
    """(dy, y + dy, R, scale) with the kept factor, solved to the forcing term ``eta`` or
    KEPT_STEP_FRACTION of the contraction asked, whichever is looser, if that step contracts
    |R| enough; else None, and the kept factor is dropped so that the caller factors the
    current Jacobian."""
    if factors is None or not factors.usable(y.size):
        return None
    dy = -factors.solve(R, max(eta, KEPT_STEP_FRACTION * settings.reuse_contraction))
    try:
        R_new, scale = residual(y + dy)
    except (ValueError, FloatingPointError):  # the stale step inverted an element
        R_new, scale = None, 0.0
    if (R_new is None or not np.all(np.isfinite(dy))
            or not norm2(R_new) <= settings.reuse_contraction * norm0):
        factors.drop()
        return None
    factors.reused_steps += 1
    return dy, y + dy, R_new, scale


class _Watchdog:
    """Lets the first full Newton step of a solve raise |R| (the watchdog of Chamberlain et al.): a
    step that bends a slender body leaves an axial residual of order E theta^2 / 2 that the next
    step removes, so |R| first grows and then falls quadratically, and backtracking on |R|
    would cut every such step and creep (tester A, session 41: a Neo-Hookean cantilever with a
    2 % tip deflection, |R| 4.7e-2 -> 5.8 -> 7.3e-3 -> 6.2e-8 with full steps, while the cut
    steps failed after 25 iterations and 4 halvings). The step is kept if the next iterate's
    |R| is below the one before it; otherwise Newton goes back there and backtracks as before,
    so the line search still protects against divergence and inverted elements (a trial that
    inverts one is never taken in full)."""

    def __init__(self, limit: float, enabled: bool = True) -> None:
        self.limit = limit  # a full step beyond the divergence limit is never let through
        self.used = not enabled  # its one trial per solve spent, or never given
        self.pending = False
        self.saved: tuple[NDArray, NDArray, float] | None = None
        self.fresh = False

    def line_search(self, residual: Residual, y: NDArray, dy: NDArray, norm0: float,
                    settings: NewtonSettings) -> tuple[NDArray, NDArray, float]:
        """_line_search, but a full step that raised |R| is kept on trial once per solve."""
        growth = 0.0 if self.used else self.limit
        y_new, R, scale, grew = _line_search(residual, y, dy, norm0,
                                             settings.line_search_steps, growth)
        if grew:
            self.used = self.pending = self.fresh = True
            self.saved = (y, dy, norm0)
        return y_new, R, scale

    def progress(self, norm: float) -> bool:
        """Whether the iterate after the trial step is better than the one before it (the
        trial's own iteration always passes)."""
        if self.fresh:
            self.fresh = False
            return True
        self.pending = not norm < self.saved[2]
        return not self.pending

    def revert(self, residual: Residual, settings: NewtonSettings):
        """(y, dy, R, scale): back before the trial step, which is backtracked on |R|."""
        y, dy, norm0 = self.saved
        self.pending = self.fresh = False
        y_new, R, scale, _ = _line_search(residual, y, dy, norm0, settings.line_search_steps)
        return y_new, dy, R, scale


def _line_search(residual: Residual, y: NDArray, dy: NDArray, norm0: float, steps: int,
                 growth: float = 0.0) -> tuple[NDArray, NDArray, float, bool]:
    """Backtrack on |R| from the full step until |R| < norm0 and keep the best trial;
    (y, R, scale, grew). A full step that raised |R| but inverts no element and stays below
    ``growth`` is taken instead (grew = True: the watchdog's trial step) when the half step
    does not lower |R| either, i.e. when backtracking would cut the step to 1/4 or less."""
    alpha = 1.0
    best = last = full = None
    for _ in range(max(steps, 1)):
        try:
            R, scale = residual(y + alpha * dy)
        except (ValueError, FloatingPointError) as err:  # e.g. an element inverted by a
            alpha *= 0.5  # too-long step
            last = err
            continue
        norm = norm2(R)
        if best is None or norm < best[0]:
            best = (norm, alpha, R, scale)
        if norm < norm0:
            break
        if alpha == 0.5 and full is not None:  # backtracking would cut to 1/4 or less
            return y + dy, full[0], full[1], True
        if alpha == 1.0 and norm < growth:
            full = (R, scale)
        alpha *= 0.5
    if best is None:
        # the last trial's error names the element (the shortest step inverted it too)
        raise NewtonError(f"every line-search trial inverted an element (the last: {last})",
                          norm0, 0) from last
    _, alpha, R, scale = best
    return y + alpha * dy, R, scale, False
