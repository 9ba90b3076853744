"""The time loop: Newton per step, step cut-back, diagnostics, observers."""

from __future__ import annotations

import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
from functools import partial
from typing import Protocol

import numpy as np
import scipy.sparse as sp
from numpy.typing import NDArray

from ..ale.motion import AleMotionError
from ..contact import (
    SLIP,
    PairState,
    extrapolated_update,
    lagrange_blocks,
    max_contraction,
    newton_update,
)
from ..contact.kinematics import UndefinedNormalError
from ..dynamics.energy import EndEnergy, EnergyConsistentContact
from ..dynamics.mass import MovingMass
from ..dynamics.midpoint import end_of_step, midpoint_velocity, velocity_factor
from ..fem.loads import TimeFunction, dirichlet_rates, dirichlet_values
from ..fem.q4 import InvertedElementError
from ..fem.sparse import TripletUnion
from ..solvers.linear import LinearSolver, LinearSolverError, Precision
from ..solvers.newton import FactorCache, NewtonError, NewtonSettings, newton
from ..threads import serial_blas
from .convection import convective_terms
from .diagnostics import (
    AleQualityCheck,
    AleSpacingCheck,
    Balance,
    ContactMoment,
    PenetrationCheck,
    SelfCrossingCheck,
    SurfaceTwoCheck,
    UnpairedCheck,
    balance,
    check_end_of_step,
    contact_moment,
    named_failure,
)
from .initial import initial_state
from .interfaces import (
    AugmentationFailure,
    LagrangeTerm,
    augment_all,
    augmentation_advice,
    commit_all,
    contact_rows,
    contact_terms,
    detect_all,
    entered_at_step_end,
    evaluate_all,
    gap_roundoff,
    lagrange_terms,
    persistent_velocities,
    unconverged_interfaces,
    unpaired_shares,
    with_solved_multipliers,
)
from .mesh_motion import (
    MeshMotion,
    end_of_step_mismatch,
    mesh_settled,
    move_meshes,
    without_unfollowed,
)
from .model import Model
from .problem import StepProblem, StepState
from .reactions import support_reactions, support_sets
from .ties import tie_forces, tie_terms, tie_violation


def _static_dissipation(result, used: PairState, x_start: NDArray, law) -> float:
    """Frictional dissipation of a quasi-static step over its SLIP pairs.

    Only the slip part of the tangential increment dissipates: the regularized law's
    s_p = (t^trial - t_T) / eps_T (friction.py), the increment beyond the cone; the rest is
    the stick's elastic part (under the augmented Lagrangian, whose converged multiplier makes
    the stick exact, s_p is all of delta g_T). A pair slips on the Coulomb cone, so s_p is
    priced by the trapezoidal rule of the cone's mu t_N L_c at the step's start (``used.t_N``,
    L_c at ``x_start``) and end. Where the pair slipped at the start too, that is the
    trapezoid of its start and end tangential forces, which a load ramp needs (the end force
    alone over-counted report 6.1's ramp to first order in the step: 22.2, 12.5, 11.4 in 1,
    8, 32 steps against -contact_work 11.1). Where it stuck at the start, or its force
    reverses within the step, it slips only after its force has reached the cone, its stick
    part being elastic: the trapezoid of its start and end forces counted half of a first
    slip and ~0 of a reversal's (+mu t_N, -mu t_N), so that a block dragged back and forth
    lost mu N times the slip of each step where it started or reversed (tester Z, session 43:
    D 2.341 / 2.369 at dt 0.05 / 0.025, ~2.39 in the limit).

    ``contact_work`` keeps the trapezoid of the contact forces: with the loads' it is the
    static ledger's (E_{n+1} - E_n = W_ext + W_contact at both ends' equilibria), and the
    loads' and supports' work along the stick-then-slip path is not known either."""
    slip = result.status == SLIP
    x0 = result.transfer.positions(x_start) if result.transfer is not None else x_start
    nodes = result.slots[slip]  # slots 0, 4, 5: the node and its surface neighbours
    back = np.linalg.norm(x0[nodes[:, 0]] - x0[nodes[:, 4]], axis=1)
    ahead = np.linalg.norm(x0[nodes[:, 5]] - x0[nodes[:, 0]], axis=1)
    end = result.t_T[slip] * result.length[slip]
    cone = np.sign(end) * law.mu * used.t_N[slip] * 0.5 * (back + ahead)  # along the end force
    slipped = (result.trial_T[slip] - result.t_T[slip]) / law.eps_T
    return float(np.sum(0.5 * (cone + end) * slipped))  # >= 0: end * slipped >= 0


def _last_attempt(step_start: float, start: float, h: float, halvings: int) -> str:
    """Where a step that ran out of halvings stopped: its last attempt's sub-step, and how far
    the sub-steps before it got (the message gave only the whole step: one step to 110 %
    compression said "step 1 (t = 0 -> 1) failed" after converging to 0.99)."""
    if halvings == 0:
        return ""
    done = (f"sub-steps converged to t = {start:.6g}" if start > step_start
            else "no sub-step converged")
    return f"; {done}, the last attempt was t = {start:.6g} -> {start + h:.6g}"


def _constant_over(function: TimeFunction, a: float, b: float) -> bool:
    """Whether a piecewise-linear time function takes one value all over [a, b]."""
    inside = [t for t in function.times if a < t < b]
    return all(function(t) == function(a) for t in [*inside, b])


def _same_problem(model: Model, state: StepState, h: float) -> bool:
    """Whether a static sub-step of h/2 from ``state`` would solve the very problem that
    failed over h: its loads and supports take the same values at both ends (none has a time
    function, or theirs is constant there), it starts from the same guess (no rate to
    extrapolate, v = 0) and no contact or ALE motion depends on the step's length. A tester's
    cantilever under a load without a time function was solved 5 times from the same |R0| =
    4.7e-2 to the same |R| = 6.8e-4, and the error's "the last attempt was t = 0 -> 0.0625"
    suggested 1/16 of the load was tried."""
    if model.analysis.kind != "static" or model.interfaces or model.ale_bodies \
            or np.any(state.v):
        return False
    functions = [*model.loads.functions, *(load.function for load in model.loads.on_mesh),
                 *(support.function for support in model.prescribed)]
    return all(_constant_over(f, state.time + 0.5 * h, state.time + h) for f in functions)


def _cycling_active_set(interfaces, used: tuple) -> str:
    """The message of a step whose active set did not settle (:data:`ACTIVE_SET_REPEATS`):
    what it means and its usual cause."""
    released = [ci.name for ci in interfaces if ci.law.method == "lagrange"]
    why = (f"; Lagrange interface(s) {released} release their pairs in tension at each solve, "
           "and the released pairs penetrate again" if released else "")
    pressed = sum(len(u) for u in used)
    return (f"the contact active set did not settle: {ACTIVE_SET_REPEATS + 1} passes of the "
            "step took in again pairs an earlier pass had held (ACTIVE_SET_REPEATS; "
            f"{pressed} pairs pressed at the last){why}: a body held only by contact pairs "
            "that open, as at zero load, has no equilibrium (a support missing?)")


def _why_not_halved(err: BaseException) -> str:
    """The error's tail when halving was skipped as :func:`_same_problem`: the truth, and
    what helps where Newton ran out of iterations."""
    cure = ""
    if isinstance(err, NewtonError) and getattr(err.__cause__, "columns", None) is None:
        cure = (": give the load a ramp (function = {times = [0.0, 1.0], values = [0.0, "
                "1.0]}) or raise analysis.newton.max_iterations")
    return ("; the step was not halved, since its loads and supports do not change over it "
            "(no time function, or one constant there): a shorter step applies the same load "
            f"and solves the same problem{cure}")


class SimulationError(RuntimeError):
    """A step could not be completed even after cutting it back."""


class RunInterrupted(KeyboardInterrupt):
    """Raised between steps when the run was asked to stop (``Simulation.run``'s
    ``stop_reason``; the CLI's signal handlers)."""


class ActiveSetError(RuntimeError):
    """A quasi-static step's active set cycled (:data:`ACTIVE_SET_REPEATS`): the step is cut
    back, like a failed Newton solve."""


class AugmentationError(RuntimeError):
    """A step's contact multipliers did not pass report 5.4's test within
    ``augmentation.max_iterations``: the step is cut back, like a failed Newton solve, unless
    ``halving_helps`` is False (one augmentation allowed, a tolerance below round-off: a
    tester's step was halved 4 times for nothing)."""

    halving_helps = True


@dataclass(frozen=True)
class StepRecord:
    """What observers receive after every completed step."""

    state: StepState
    balance: Balance
    newton_iterations: int
    dt: float
    extra: dict = field(default_factory=dict)


#: Energy ledger columns accumulated over the run (history.csv).
LEDGER = ("external_work", "contact_work", "frictional_dissipation", "ale_remap_energy",
          "ale_unreturned_energy")

#: The first augmentation of a quasi-static pass whose pairs came with multipliers stops at
#: this fraction of its starting residual to look for new penetrating pairs
#: (``Simulation._solve_augmentation``): after one Newton iteration, as a rule, where the
#: contact zone's next nodes already penetrate (Hertz k = 4: 9.3 -> 8.2 iterations a step;
#: 1e-2 gave 8.8, since it often took a second iteration first)
NEW_PAIR_PROBE = 0.1

#: ``Simulation._sensitivity`` solves for at most this many pressed pairs at a time: one
#: solve with a right-hand side per pair sweeps the factor once for all its columns (a
#: 37-column PARDISO solve 12-17 ms against 33-35 ms for 37 single ones, ring k = 8), but
#: its dense unknowns x pairs blocks grow as n^1.5 on a 2D mesh. Hertz refined 8x with
#: Newton updates (~130 pressed pairs, 124k unknowns; load ~1.5): peak memory 1,323 -> 1,185
#: MB, 3.98 -> 4.13 s a step (three solves a sensitivity instead of one) with 64 columns.
#: 64 -> 16 columns, ring k = 8 (37 pressed pairs, 46k unknowns; two runs each, load ~6): peak
#: 502 / 501 -> 468 / 472 MB (10.6 -> 9.1 KB an element), the sensitivities' CPU 2.6 / 2.4 ->
#: 2.75 / 2.4 s of ~26 s a run; 8 columns saved nothing more (466 MB), 32 nothing (503 MB)
SENSITIVITY_COLUMNS = 16
#: |B - A X| <= SENSITIVITY_RTOL |B| per column of S's solve, where a single-precision factor
#: stops its refinement there: S only has to contract the multipliers' error (it is kept for
#: the step's augmentations anyway). Ring refined 8x: the first solution's worst column
#: 3e-6 to 5e-4, each of 17 solves had a sweep of all its ~30 columns at 1e-6 and none now,
#: 4.5 -> 2.4 s of CPU; the same augmentations and iterations
SENSITIVITY_RTOL = 1e-3

#: The adapted inexact ratio of an augmentation's Newton solve stays at or below this
#: (``Simulation._adapted_early_ratio``)
MAX_EARLY_RATIO = 1e-2

#: Quasi-static steps are re-solved at most this many times when new pairs penetrate at a
#: converged solve (passes stopped at an unconverged augmentation for new pairs not counted).
ACTIVE_SET_PASSES = 5
#: ... and at most this many passes a step stopped for "new" pairs (``SolvedStep.grown``)
#: that all had been in an earlier pass of the step (a pass that takes in a node never tried
#: is not counted: there are finitely many). A Lagrange interface releases its tensile pairs
#: at each solve and they can penetrate again, so its active set can cycle: a tester's block
#: unloaded to zero (held by contact only) cycled 9 -> 3 -> 9 pairs without end (11 min in
#: one step, no message), where the augmented Lagrangian failed at once as singular
ACTIVE_SET_REPEATS = 10
#: fixed-theta solves of report 5.5's energy equation by bracketing, where its bordered Newton
#: failed (``Simulation._theta_by_bracket``)
THETA_BRACKET_ITERATIONS = 8


@dataclass(frozen=True)
class SolvedStep:
    """The converged solution of one step before the kinematic update."""

    state: StepState  # the t_n state the step was solved from (ALE: the moved mesh)
    d: NDArray  # d_{n+1/2} (dynamic) or d_{n+1} (static), (n, 2)
    used: tuple  # the contact states the final solve used
    results: tuple
    augmentations: int
    iterations: int
    mismatch: float
    tie_forces: dict = field(default_factory=dict)  # per tie: force on its body-1 nodes
    reactions: dict = field(default_factory=dict)  # history columns of the support reactions
    remap_energy: float = 0.0  # strain energy the ALE remaps changed
    unreturned_energy: float = 0.0  # energy the remaps added that no body gave back
    #: quasi-static: the active sets grown by pairs that penetrate at an unconverged
    #: augmentation's solution; the step's solve stopped there to start a new pass
    grown: tuple | None = None
    #: per interface, the surface-1 nodes whose pairs the solve released because the mesh
    #: motion could not follow them (``mesh_motion.without_unfollowed``); () if none
    released: tuple = ()


class Observer(Protocol):
    def on_step(self, model: Model, record: StepRecord) -> None: ...

    def on_finish(self, status: str, error: str | None) -> None: ...


def default_linear_solve(precision: Precision = "auto", check_pivots: bool = False
                         ) -> Callable[[sp.spmatrix, NDArray], NDArray]:
    """The project's sparse solver, PARDISO factoring in ``precision``, SuperLU's factors
    checked for singularity at each factorization with ``check_pivots`` (see
    :class:`~ntncontact.solvers.linear.LinearSolver`)."""
    return LinearSolver(precision=precision, check_pivots=check_pivots).solve


def _newton_updated(ci) -> bool:
    """Whether an interface's multipliers take Newton updates (``contact.newton_update``)."""
    return ci.multiplier_update == "newton" and ci.law.method == "augmented_lagrangian"


def _augmented_only(interfaces, states: tuple) -> bool:
    """Whether every interface with pairs is augmented Lagrangian: a Lagrange interface
    releases its tensile pairs at every solve, and a first solution, not converged, can show
    them penetrating again (the static blocks of test_exact_touch, a Lagrange interface, did
    not finish in 10 minutes with the first solution looked at)."""
    return all(ci.law.method == "augmented_lagrangian"
               for ci, state in zip(interfaces, states, strict=True) if len(state))


def _no_nodes(interfaces) -> tuple:
    return tuple(np.zeros(0, np.int64) for _ in interfaces)


def _nodes_left(before: tuple, after: tuple, known: tuple, exclude: tuple | None = None
                ) -> tuple:
    """Per interface, ``known`` and the surface-1 nodes of ``before``'s pairs not in
    ``after``'s, less those of ``exclude``."""
    exclude = exclude or _no_nodes(before)
    return tuple(np.union1d(k, np.setdiff1d(np.setdiff1d(b.pairs[:, 0], a.pairs[:, 0]), e))
                 for b, a, k, e in zip(before, after, known, exclude, strict=True))


def _measured_contraction(results: tuple, previous: tuple) -> float:
    """The largest contraction of the pressed pairs' normal measure over the interfaces
    between two augmentations (``contact.max_contraction``), 0 where none was measured."""
    rate = 0.0
    for now, before in zip(results, previous, strict=True):
        if now is None or before is None or not np.array_equal(now.pairs, before.pairs):
            continue  # a Lagrangian interface re-paired: no contraction to measure
        rate = max(rate, max_contraction(now, before))
    return rate


def _early_ratio_for(rate: float, floor: float) -> float:
    """A tenth of the contraction ``rate``, within [``floor``, MAX_EARLY_RATIO]
    (``Simulation._adapted_early_ratio``)."""
    return float(min(max(0.1 * rate, floor), MAX_EARLY_RATIO))


def _force_columns(b, keep: NDArray, position: NDArray, column: NDArray, size: int,
                   block: slice) -> NDArray:
    """The columns ``block`` of B (d force / d lambda of the pressed pairs) on the unknowns,
    dense and in the column order PARDISO takes (a C-order block was copied for it)."""
    take = keep & (column[b.b_cols] >= block.start) & (column[b.b_cols] < block.stop)
    forces = np.zeros((size, block.stop - block.start), order="F")
    np.add.at(forces, (position[b.b_rows[take]], column[b.b_cols[take]] - block.start),
              b.b_vals[take])
    return forces


class Simulation:
    """Advances a model in time; the state is replaced (never mutated) each step."""

    def __init__(self, model: Model, observers: Sequence[Observer] = (),
                 linear_solve: Callable | None = None) -> None:
        self.model = model
        self.observers = list(observers)
        self.solve = linear_solve or default_linear_solve(
            model.analysis.factor_precision, check_pivots=model.analysis.kind == "static")
        # the watchdog only without contact: with contact it changed the active sets' path
        # (a Lagrange block touching on a step boundary then cycled, and 4 more tests moved
        # beyond their tolerances), where the plain line search was tuned and tested
        self.settings = NewtonSettings(rtol=model.analysis.newton_rtol,
                                       max_iterations=model.analysis.newton_max_iterations,
                                       max_reused_steps=model.analysis.newton_max_reused_steps,
                                       watchdog=not model.interfaces)
        self.dynamic = model.analysis.kind == "dynamic"
        self.lumped = model.analysis.mass == "lumped"
        ale_cells = np.concatenate(
            [model.bodies[a.body_index].cells for a in model.ale_bodies] or [np.zeros(0, int)])
        # masses for dynamic runs only: a static run has no inertia (see balance); at Hertz
        # refined 4x the two mass matrices were 8.8 of the 100 MB of arrays traced at a
        # factorization
        self._nodal_mass = (model.assembler.nodal_mass(model.X0, self.lumped) if self.dynamic
                            else None)
        # only the ALE bodies' element masses change (their nodes carry new particles)
        self._moving_mass = (MovingMass(model.assembler, model.X0, self.lumped, ale_cells)
                             if self.dynamic else None)
        # kept only without ALE bodies (with them, _dof_mass asks _moving_mass each time)
        self._mass = (self._moving_mass.matrix(model.X0)
                      if self.dynamic and not model.ale_bodies else None)
        self.length_scale = float(np.ptp(model.X0, axis=0).max())
        self.max_augmentations = max([ci.max_augmentations for ci in model.interfaces] or [1])
        self.state = replace(initial_state(model),
                             contact=tuple(PairState.empty() for _ in model.interfaces))
        self._last_contact: tuple = ((), 0)
        self._fp_errors = FloatingPointErrors()  # run() starts a new one
        self.ledger = dict.fromkeys(LEDGER, 0.0)  # cumulative energy ledger
        self._step_work = dict.fromkeys(LEDGER, 0.0)
        self._last_mismatch, self._last_mismatch_at = 0.0, None
        self._last_moment = ContactMoment()  # the contact forces' net moment (diagnostics)
        self._augmentations_converged = True  # False: a sub-step accepted its last augmentation
        self._last_tie_forces: dict = {}
        self._supports = support_sets(model)
        self._last_reactions: dict = {}
        self._cut_back = False  # the last step was solved in sub-steps
        self._newton_run = 0  # Newton iterations run so far, failed solves' too (_newton)
        self._failed_iterations = 0  # the last step's, in attempts a halving discarded
        self._energy_multiplier = 0.0
        self._energy_unmet = False  # the energy equation had no root (report 5.5)
        self._penetration = PenetrationCheck(model) if len(model.bodies) > 1 else None
        self._unpaired = UnpairedCheck(model) if model.interfaces else None
        self._surface_2 = SurfaceTwoCheck(model) if model.interfaces else None
        self._self_crossing = SelfCrossingCheck(model)
        self._ale_quality = AleQualityCheck(model) if model.ale_bodies else None
        self._ale_spacing = AleSpacingCheck(model) if model.ale_bodies else None
        # the energy-conserving solve (report 5.5) starts from each augmentation's exact one
        self._early_ratio = (0.0 if model.analysis.energy_conserving
                             else model.analysis.newton_inexact_augmentations)
        #: the contraction of the first multiplier update in the last step that measured one
        #: (``_first_early_ratio``)
        self._first_rate = 0.0
        self._union = TripletUnion()  # one stiffness pattern for all steps (fem.sparse)
        self._newton_updates = any(_newton_updated(ci) for ci in model.interfaces)
        self._last_substep: float | None = None  # the last sub-step after cut-backs
        self._state_substep: float | None = None  # the sub-step that ended at advance's state
        self._resumed = False  # restored from a checkpoint: no initial record
        self._stop_reason: Callable[[], str | None] | None = None  # run's, asked in steps too
        #: static runs: the contact forces at the end of the last step (the trapezoidal work)
        self._contact_force = np.zeros(model.ndof)

    def checkpoint_state(self) -> dict:
        """Everything of the run that outlives a step (io.checkpoint saves it): the state
        (X, d, v, a, the interfaces' pair states), the energy ledger, the energy multiplier
        (kept by steps without contact) and the last sub-step after cut-backs. The rest of
        this object is rebuilt identically from the model, or reset by every step."""
        solver = getattr(self.solve, "__self__", None)
        analysis = solver.analysis_state() if hasattr(solver, "analysis_state") else ({}, {})
        return {"state": self.state, "ledger": dict(self.ledger),
                "energy_multiplier": self._energy_multiplier, "last_substep": self._last_substep,
                # the linear solver's orderings: the next factorization takes the same path
                "linear_solver": analysis, "union_keys": self._union.keys,
                "contact_force": self._contact_force, "first_rate": self._first_rate}

    def restore_state(self, saved: dict) -> None:
        """Continue from :meth:`checkpoint_state`'s values; :meth:`run` then goes on with
        the step after ``saved["state"]`` (observers are restored by their owners)."""
        self.state = saved["state"]
        self.ledger = dict.fromkeys(LEDGER, 0.0) | dict(saved["ledger"])
        self._energy_multiplier = float(saved["energy_multiplier"])
        self._last_substep = saved.get("last_substep")
        solver = getattr(self.solve, "__self__", None)
        if hasattr(solver, "restore_analysis") and "linear_solver" in saved:
            solver.restore_analysis(*saved["linear_solver"])
        if "union_keys" in saved:
            self._union.restore(saved["union_keys"])
        self._first_rate = float(saved.get("first_rate", 0.0))
        if saved.get("contact_force") is not None:
            self._contact_force = np.asarray(saved["contact_force"], dtype=float)
        self._resumed = True

    def balance(self, state: StepState) -> Balance:
        _, _, energy = self.model.assembler.internal(state.X, d=state.d, need_tangent=False)
        if not self.dynamic:
            # no inertia: a static run's rates (d_{n+1} - d_n) / dt are load-step increments,
            # not velocities, and carry no kinetic energy or momentum (Hertz reported a
            # kinetic energy of 11.5 times its strain energy at step 1)
            return Balance(0.0, energy, (0.0, 0.0), 0.0)
        # ALE bodies: the dof mass of the step's mesh, which the solve built already
        mass = self._dof_mass(state) if self.model.ale_bodies else self._nodal_mass
        return balance(mass, state.x, state.v, energy)

    def advance(self, state: StepState, dt: float) -> tuple[StepState, int]:
        """One step of size dt from ``state`` (report 5.4): detection, then the augmented
        solve; quasi-static steps repeat the solve while the converged configuration shows
        new penetrations (an active-set iteration), dynamic ones where an interface asks for
        it (``active_set_pass``), then the kinematic update."""
        interfaces = self.model.interfaces
        contact = detect_all(interfaces, state.contact, state.x, state.v, dt)
        iterations, start, converged_passes, repeats = 0, None, 0, 0
        tried = tuple(c.pairs[:, 0] for c in contact)  # per interface: nodes of any pass
        # per interface: nodes whose pairs were released as unfollowed (taken in again if
        # they end inside), and those the solves released (not taken in again)
        retake = let_go = _no_nodes(interfaces)
        # a pass stopped early for new pairs (SolvedStep.grown) does not count: each adds pairs
        while converged_passes < ACTIVE_SET_PASSES:
            self._check_stop()  # a long step still ends at a signal (tester B F2: 11 min)
            solved = self._solve_step(state, contact, dt, start, may_grow=True)
            iterations += solved.iterations
            converged_passes += solved.grown is None
            if solved.grown is not None:
                # every pair of the grown active sets has a surface-1 node tried before
                repeats += all(bool(np.isin(g.pairs[:, 0], t).all())
                               for g, t in zip(solved.grown, tried, strict=True))
                tried = tuple(np.union1d(t, g.pairs[:, 0]) for t, g in zip(tried, solved.grown,
                                                                           strict=True))
                if repeats > ACTIVE_SET_REPEATS:
                    raise ActiveSetError(_cycling_active_set(interfaces, solved.used))
            if solved.released:
                retake = tuple(np.union1d(r, n) for r, n in zip(retake, solved.released,
                                                                 strict=True))
            if solved.grown is None:
                let_go = _nodes_left(contact, solved.used, let_go, exclude=retake)
            grown = self._grown(solved, dt, retake, let_go) if interfaces else None
            if grown is None:
                break
            # the next pass starts from this one's solution, not from the step's start: the
            # new pairs change it locally (Hertz k = 2: 4-7 line-searched iterations saved)
            contact, start = grown, (solved.d.ravel(), solved.state.d)
        s, d = solved.state, solved.d
        if self.dynamic:
            d1, v1, a1 = end_of_step(d, s.d, s.v, dt, self._prescribed_rates(s.time + dt))
        else:
            d1, v1, a1 = d, (d - s.d) / dt, np.zeros_like(d)
        check_end_of_step(self.model, s.X + d1, s.time + dt)  # inverted: cut back (issue 14)
        results = solved.results
        committed = commit_all(interfaces, solved.used, results)
        self._last_contact = (results, solved.augmentations)
        # over the pressed pairs at the step's end (end_of_step_mismatch), and where
        self._last_mismatch, self._last_mismatch_at = (
            end_of_step_mismatch(self.model, results, s.X + d1)
            if self.model.ale_bodies and interfaces else (solved.mismatch, None))
        # where the solve evaluated the forces (the mid-point of a dynamic step)
        self._last_moment = contact_moment(interfaces, results, s.X + d)
        self._last_tie_forces = solved.tie_forces
        self._last_reactions = solved.reactions
        out_of_balance = (self._remap_out_of_balance_work(s, state, d1)
                          if not self.dynamic and s is not state else 0.0)
        self._accumulate_work(s, d1, results, dt, solved.used)
        self._step_work["ale_remap_energy"] += solved.remap_energy + out_of_balance
        self._step_work["ale_unreturned_energy"] += solved.unreturned_energy
        new = StepState(s.step + 1, s.time + dt, s.X, d1, v1, a1, committed)
        return new, iterations

    def _prescribed_rates(self, time: float) -> tuple[NDArray, NDArray]:
        """The prescribed dofs and their velocities at the end ``time`` of a dynamic step
        (``fem.loads.dirichlet_rates``), which ``end_of_step`` gives them."""
        return dirichlet_rates(self.model.prescribed, time, self.model.ndof)

    def _remap_out_of_balance_work(self, moved: StepState, state: StepState,
                                   d1: NDArray) -> float:
        """Static runs: the work over the step of the out-of-balance force r the step's ALE
        remap left at t_n (the remapped fields on the moved mesh ``moved`` are not in
        equilibrium with the loads and the contact forces of t_n), by the trapezoidal rule:
        r . dx / 2 (r is 0 at the step's end). With it in ``ale_remap_energy``,
        E - E0 - W_ext - W_contact - ale_remap_energy closes to the Newton tolerance
        (delamination, its lower layer ALE: 2.2e-3 of the scale -> 3.7e-13). Not at prescribed
        dofs: there the residual is the support's reaction, whose work the ledger leaves out."""
        f_int, _, _ = self.model.assembler.internal(moved.X, d=moved.d, need_tangent=False)
        dx = (moved.X + d1 - moved.x).ravel()
        residual = f_int + self._contact_force - self._static_start_load(moved, dx.size)
        prescribed, _ = dirichlet_values(self.model.prescribed, moved.time, dx.size)
        residual[prescribed] = 0.0
        return 0.5 * float(residual @ dx)

    def _grown(self, solved: SolvedStep, dt: float, retake: tuple, let_go: tuple
               ) -> tuple[PairState, ...] | None:
        """The active sets for another pass of this step, or None. Quasi-static: every pair
        that penetrates at the solve's end. Dynamic: the nodes inside surface 2 at the end of
        the step (positions and velocities from the mid-point solution) on the interfaces
        with ``active_set_pass``, and on every interface those of ``retake``
        (``interfaces.entered_at_step_end``)."""
        if not self.dynamic:
            return solved.grown or self._with_new_penetrations(solved.used,
                                                               solved.state.X + solved.d)
        if not (any(ci.active_set_pass for ci in self.model.interfaces)
                or any(r.size for r in retake)):
            return None
        s = solved.state
        d1, v1, _ = end_of_step(solved.d, s.d, s.v, dt, self._prescribed_rates(s.time + dt))
        return entered_at_step_end(self.model.interfaces, solved.used, s.X + d1, v1, retake,
                                   let_go)

    def _with_new_penetrations(self, contact, x_end: NDArray):
        """The active sets grown by the pairs that penetrate at x_end, or None if none do."""
        found = detect_all(self.model.interfaces, contact, x_end, np.zeros_like(x_end), 0.0)
        grown, added = [], False
        for old, new in zip(contact, found, strict=True):
            fresh = ~np.isin(new.pairs[:, 0], old.pairs[:, 0])
            added |= bool(fresh.any())
            grown.append(old.concat(PairState.from_pairs(new.pairs[fresh])))
        return tuple(grown) if added else None

    def _solve_step(self, state: StepState, contact, dt: float,
                    start: tuple | None = None, may_grow: bool = False) -> SolvedStep:
        """Per augmentation: the ALE mesh motion and Newton with the contact multipliers
        fixed, then the multiplier update, until report 5.4's test is met. ``start``: (d, the
        d of the state it was solved on) of an earlier solve of this step, to start from.
        ``may_grow`` (quasi-static): an unconverged augmentation (the second or a later one;
        also the first where every interface with pairs is augmented Lagrangian)
        whose solution shows new penetrating pairs ends the solve there
        (``SolvedStep.grown``): the step's next active-set pass takes them in at once instead
        of after the augmentations converge."""
        interfaces = self.model.interfaces
        base, motion = state, None
        x_pred = state.x + dt * state.v  # first prediction of the end-of-step positions
        if start is not None:
            x_pred = state.X + (start[0] + (state.d - start[1]).ravel()).reshape(-1, 2)
        previous, before, iterations, guess, floor = None, None, 0, start, None
        # one factor serves the augmentations (modified Newton), where the solver keeps factors
        factorize = getattr(getattr(self.solve, "__self__", None), "factorize", None)
        factors = FactorCache(factorize) if factorize is not None else None
        sensitivities: dict = {}  # per interface and pressed set, for Newton multiplier updates
        first_looks = _augmented_only(interfaces, contact)  # see grown below
        # the pairs come with augmented-Lagrangian multipliers (some lambda_N > 0), and every
        # interface with pairs is augmented Lagrangian: see probe below
        carried = first_looks and any(bool(np.any(s.lambda_N > 0.0)) for s in contact)
        early_ratio = self._first_early_ratio()
        for augmentation in range(1, self.max_augmentations + 1):  # noqa: B007 (used after)
            if self.model.ale_bodies and any(len(c) for c in contact):
                motion = move_meshes(self.model, base, contact, x_pred, dt, motion)
                state = motion.state
                kept = without_unfollowed(contact, motion.unfollowed)
                if kept is not None:  # the step again without them (rare: partners cross)
                    return self._solved_without(base, contact, kept, dt, start, may_grow,
                                                iterations)
            mass = self._dof_mass(state) if self.dynamic else None
            last_contact: dict = {}  # the contact terms' latest evaluation (reused below)
            problem, y0 = self._augmentation_problem(state, contact, dt, mass, motion, floor,
                                                     guess, last_contact)
            # Inexact augmentations: the multiplier update and mesh move that follow change the
            # problem by far more than rtol, so the solve stops at early_ratio x its start;
            # the augmentation that meets report 5.4's test is then solved to rtol and tested
            # again (ring impact: 2742 -> 1802 Newton iterations, the largest energy variation
            # 1.525448e-3 -> 1.525451e-3; docs/scenarios.md, newton.inexact_augmentations).
            probe = may_grow and carried and augmentation == 1 and not self.dynamic
            result, its, grown = self._solve_augmentation(problem, y0, factors, contact, probe,
                                                          early_ratio)
            iterations += its
            if grown is not None:
                return SolvedStep(state, problem.full(result.y).reshape(-1, 2), contact, (), 1,
                                  iterations, 0.0, grown=grown)
            floor = problem.scale_floor
            split = None
            if self.model.analysis.energy_conserving and any(len(c) for c in contact):
                problem, result, its, split = self._conserve_energy(problem, result, mass)
                iterations += its
            moves_again = (partial(self._moves_again, base, motion)
                           if augmentation < self.max_augmentations else None)
            result, d, used, results, contact, done, its = self._test_augmentation(
                problem, result, split, contact, previous, last_contact, factors, moves_again)
            iterations += its
            if augmentation == 2:
                self._first_rate = _measured_contraction(results, previous)
            if not done:
                contact = self._next_multipliers(problem, result.y, d, used, contact, results,
                                                 previous, (factors, sensitivities))
            # after the first augmentation too (augmented-Lagrangian interfaces): with the
            # pass's pairs carrying multipliers the new pairs are the contact zone's next
            # nodes (Hertz k = 4: 220 -> 196 solves, same solution); without (a first
            # contact), its solution holds the whole load on penalty pairs of a set that may
            # be far from complete, but the next pass, started from it, converges (Hertz's
            # step 1: 12 / 15 / 15 / 20 -> 10 / 12 / 13 / 17 Newton iterations at k = 1 / 2
            # / 4 / 8; the pass it started once went in 0.6 deep and failed at k = 4)
            grown = (self._with_new_penetrations(contact, state.X + d)
                     if may_grow and not done and not self.dynamic
                     and (augmentation > 1 or first_looks) else None)
            if grown is not None:
                return SolvedStep(state, d, used, results, augmentation, iterations, 0.0,
                                  grown=grown)
            guess = (d.ravel(), state.d)
            x_pred = self._predicted_end(state, d)
            # converged multipliers on a mesh moved for the previous solution: once more on
            # the mesh moved for this one, so that pairs end node to node (mesh_settled)
            if done and (augmentation == self.max_augmentations
                         or mesh_settled(self.model, base, contact, x_pred, motion)):
                break
            early_ratio = self._adapted_early_ratio(results, previous)
            previous, before = results, previous
        if not done:
            self._require_accepted(augmentation, unconverged_interfaces(
                interfaces, used, before, previous, gap_roundoff(state.X + d), dt))
            self._augmentations_converged = False
        return SolvedStep(state, d, used, results, augmentation, iterations,
                          **self._step_figures(problem, result, motion, state.X + d))

    def _solved_without(self, state: StepState, contact: tuple, kept: tuple, dt: float,
                        start: tuple | None, may_grow: bool, iterations: int) -> SolvedStep:
        """The step solved again from its start with the pairs ``kept`` only (the others
        released: the mesh cannot follow them); ``iterations`` spent before count too."""
        again = self._solve_step(state, kept, dt, start, may_grow)
        released = _nodes_left(contact, kept, again.released or _no_nodes(contact))
        return replace(again, iterations=again.iterations + iterations, released=released)

    def _augmentation_problem(self, state: StepState, contact: tuple, dt: float,
                              mass: sp.spmatrix | None, motion: MeshMotion | None,
                              floor: float | None, guess: tuple | None,
                              last_contact: dict) -> tuple[StepProblem, NDArray]:
        """The step's problem with the multipliers of ``contact`` fixed, on the mesh of
        ``state``, and its Newton start: the last augmentation's solution (``guess``: d, the
        d of the state it was solved on) shifted by the remap, else the predictor."""
        interfaces = self.model.interfaces
        problem = StepProblem(self.model, state, dt, mass,
                              [*contact_terms(interfaces, contact, dt, last_contact),
                               *convective_terms(self.model, motion, dt)],
                              # ties after the contact multipliers (see TieTerm.order)
                              [*lagrange_terms(interfaces, contact, dt),
                               *tie_terms(self.model.ties)], union=self._union,
                              scale_floor=floor,
                              start_velocity=(persistent_velocities(
                                  interfaces, contact, state.x, self._start_velocity(state))
                                  if self.dynamic and guess is None else None))
        y0 = problem.initial_guess()
        if guess is not None:  # warm start: the last solution, shifted by the remap
            d_guess = guess[0] + (state.d - guess[1]).ravel()
            y0[: problem.free_dofs.size] = d_guess[problem.free_dofs]
        return problem, y0

    def _next_multipliers(self, problem: StepProblem, y: NDArray, d: NDArray, used: tuple,
                          updated: tuple, results: tuple, previous: tuple | None,
                          caches: tuple) -> tuple:
        """The multipliers of the next augmentation: the Uzawa ones ``updated``, extrapolated
        (quasi-static) and Newton-updated where the interfaces ask for it. ``caches``: the
        step's factor cache and multiplier sensitivities."""
        factors, sensitivities = caches
        if not self.dynamic and previous is not None:
            updated = self._extrapolated_multipliers(used, updated, results, previous)
        if self._newton_updates:
            updated = self._newton_multipliers(problem, y, d, used, updated, results, factors,
                                               sensitivities)
        return updated

    def _step_figures(self, problem: StepProblem, result, motion: MeshMotion | None,
                      x_end: NDArray) -> dict:
        """What the final solve and the mesh motion give beside d (SolvedStep's fields): the
        ALE mismatch and energies, the tie forces and the support reactions."""
        figures: dict = {"mismatch": 0.0}
        if motion is not None:
            figures = {"mismatch": motion.mismatch, "remap_energy": motion.remap_strain_change,
                       "unreturned_energy": motion.unreturned_energy}
        figures["tie_forces"] = (tie_forces(problem.constraints, problem.multipliers(result.y))
                                 if self.model.ties else {})
        figures["reactions"] = (support_reactions(self._supports,
                                                  problem.full_residual(result.y), x_end)
                                if self._supports else {})
        return figures

    def _adapted_early_ratio(self, results: tuple, previous: tuple | None) -> float:
        """The inexact ratio of the next augmentation's Newton solve: a tenth of the rate at
        which the last multiplier update contracted the pressed pairs' normal measure (gdot,
        g under the gap law), never below ``newton.inexact_augmentations``, at most
        MAX_EARLY_RATIO. The error an early stop leaves in the solution moves the next
        multipliers by that ratio times this update, so where the update contracts by rho
        only a solve to ~rho / 10 pays. rho grows as the mesh is refined, since the ALE
        remap between augmentations adds a response to the multipliers that S = G A^-1 B
        does not see (benchmarks/README.md, issue 18, session 44). Dynamic steps only: a
        quasi-static step's path goes through active-set passes and, with friction, the
        slip history, which the rougher solves moved (delamination: tangential tractions by
        5.7e-4 of their largest, contact work by 5.7e-5 of the energy scale), for 6 of its
        631 iterations."""
        if not self._early_ratio or previous is None or not self.dynamic:
            return self._early_ratio
        return _early_ratio_for(_measured_contraction(results, previous), self._early_ratio)

    def _first_early_ratio(self) -> float:
        """The inexact ratio of a dynamic step's first augmentation, where the step has
        measured no contraction yet: from the first multiplier update's contraction in the
        last step that measured one, as ``_adapted_early_ratio`` takes it. That contraction
        changes little from step to step (ring refined 8x: ~0.1, set by the error of the
        first mesh move, ~0.1 of the surface spacing; ~1e-3 at k = 1), and the first solve
        starts farthest from its solution (ring 8x: 3.5 Newton iterations at 1e-4). The
        second solve keeps the configured ratio: stopped early at the last step's second
        contraction, its error fed the contraction it was set from (ring 1x: 4.29 -> 4.88
        augmentations a contact step). Only with Newton multiplier updates, whose first
        contraction is the mesh move's: under Uzawa's, tester C's row of blocks (friction,
        a first contact each step) stopped its second contact step's first solve at 1e-3,
        failed a Newton solve later in that step and went on on another path
        (tests/test_ale_mismatch_warning.py)."""
        if not (self._early_ratio and self.dynamic and self._newton_updates):
            return self._early_ratio
        return _early_ratio_for(self._first_rate, self._early_ratio)

    def _solve_augmentation(self, problem: StepProblem, y0: NDArray,
                            factors: FactorCache | None, contact: tuple, probe: bool,
                            early_ratio: float):
        """Newton for one augmentation, stopped at the inexact ratio: (result, iterations,
        None). With ``probe`` (the first augmentation of a quasi-static pass whose pairs came
        with multipliers) the solve stops first at NEW_PAIR_PROBE x its start and looks for new
        penetrating pairs there: if any, (result, iterations, the grown active sets) ends the
        pass before the rest of the solve (Hertz k = 4: 189 -> 165 solves); else it goes on
        to the inexact ratio of its start, as without the probe."""
        solve = self._newton_on(problem, factors)
        if not probe:
            result = solve(y0, early_ratio=early_ratio)
            return result, result.iterations, None
        result = solve(y0, early_ratio=NEW_PAIR_PROBE)
        iterations, first = result.iterations, result.residual_norms[0]
        grown = self._with_new_penetrations(
            contact, problem.state.X + problem.full(result.y).reshape(-1, 2))
        if grown is None and result.early and result.residual_norms[-1] > early_ratio * first:
            result = solve(result.y, early_ratio=early_ratio * first
                           / result.residual_norms[-1])
            iterations += result.iterations
        return result, iterations, grown

    @staticmethod
    def _require_accepted(augmentations: int, failed: list[AugmentationFailure]) -> None:
        """Unless every interface that failed the test asked for its last augmentation to be
        kept (``augmentation.on_limit = "accept"``), the step fails and is cut back, like a
        failed Newton solve; not where no shorter step can pass the test
        (``AugmentationError.halving_helps``). The message names the failed tests and what
        can help with them (``augmentation_advice``)."""
        if all(f.interface.accept_unconverged for f in failed):
            return
        helps = all(f.halving_helps for f in failed)
        error = AugmentationError(
            f"contact augmentations did not converge in {augmentations} (report 5.4; "
            "augmentation.max_iterations): "
            + "; ".join(f"interface {f.interface.name!r}: {f.reason}" for f in failed)
            + (augmentation_advice(failed) if helps else ""))
        error.halving_helps = helps
        raise error

    def _test_augmentation(self, problem: StepProblem, result, split, contact, previous,
                           last_contact: dict, factors,
                           moves_again: Callable[[StepState, NDArray, tuple], bool] | None = None):
        """Report 5.4's test on an augmentation's solution: (result, d, the pair states used
        with their solved multipliers, contact results, the updated pair states, converged,
        extra Newton iterations). A test passed on an early-stopped solve is repeated after
        solving on to the tolerances, so that a step always ends with a complete solve;
        not where ``moves_again`` (state, d, pair states) says the ALE mesh must move again
        for that solution: the next augmentation solves on the moved mesh, and finishing
        this solve would not serve (ring refined 8x: 5 of 17 contact steps, 1-2 Newton
        iterations each)."""
        interfaces, state, dt = self.model.interfaces, problem.state, problem.dt
        iterations = 0
        while True:
            d = problem.full(result.y).reshape(-1, 2)
            solved = self._lagrange_multipliers(problem, result, split)
            used = with_solved_multipliers(interfaces, contact, solved)
            results = self._contact_results(interfaces, used, state, d, dt, last_contact)
            updated, done = augment_all(interfaces, used, previous, results)
            if not (done and result.early) or (moves_again is not None
                                                and moves_again(state, d, updated)):
                return result, d, used, results, updated, done, iterations
            result = self._newton_on(problem, factors)(result.y)
            iterations += result.iterations

    def _newton_on(self, problem: StepProblem, factors: FactorCache | None) -> Callable:
        """Newton on an augmentation's ``problem`` from a start y, with the step's factor
        cache and the problem's active-set step (``solvers.newton.newton``'s arguments)."""
        return partial(self._newton, problem.residual, problem.jacobian, self.solve,
                       settings=self.settings, length_scale=self.length_scale, factors=factors,
                       active_set=problem.active_set_step)

    def _predicted_end(self, state: StepState, d: NDArray) -> NDArray:
        """The end-of-step positions the next mesh motion aims at, from the solution d on
        the mesh of ``state``: the mid-point's in a dynamic step."""
        return state.X + (2.0 * d - state.d if self.dynamic else d)

    def _moves_again(self, base: StepState, motion: MeshMotion | None, state: StepState,
                     d: NDArray, contact: tuple) -> bool:
        """Whether the ALE meshes, moved from the t_n state ``base`` by ``motion``, would move
        again for the solution d on the mesh of ``state`` (``mesh_settled``)."""
        return motion is not None and not mesh_settled(self.model, base, contact,
                                                       self._predicted_end(state, d), motion)

    def _extrapolated_multipliers(self, used: tuple, updated: tuple, results: tuple,
                                  previous: tuple) -> tuple:
        """Quasi-static steps: the Uzawa multipliers ``updated`` of the frictionless
        augmented interfaces extrapolated over the rest of their sequence
        (``contact.extrapolated_update``; Hertz k = 4: 4.9 -> 4.5 augmentations a step). Not
        for interfaces that converged already or take Newton updates, nor in dynamic steps,
        whose mesh moves between augmentations change the sequence."""
        return tuple(
            new if (res is None or prev is None or not ci.law.frictionless_augmented
                    or _newton_updated(ci) or new is state)
            else extrapolated_update(new, res, prev, ci.law)
            for ci, state, new, res, prev in zip(self.model.interfaces, used, updated, results,
                                                 previous, strict=True))

    def _newton_multipliers(self, problem: StepProblem, y: NDArray, d: NDArray, used: tuple,
                            updated: tuple, results: tuple, factors: FactorCache | None,
                            sensitivities: dict) -> tuple:
        """The Uzawa multipliers ``updated`` of the interfaces with ``multiplier_update =
        "newton"`` replaced by ``contact.newton_update``'s. The sensitivity S of an interface
        is computed once per step and set of pressed pairs, at the first augmentation that
        needs it: within a step it changes with the mesh motion and the multipliers only, and
        an S that is off by a little still contracts the error far faster than Uzawa."""
        out = list(updated)
        for index, (ci, state, res) in enumerate(zip(self.model.interfaces, used, results,
                                                     strict=True)):
            if res is None or not _newton_updated(ci) or updated[index] is state:
                continue  # no pairs, another update, or this interface converged already
            pressed = res.t_N > 0.0
            if not pressed.any():
                continue
            key = (index, pressed.tobytes())
            if key not in sensitivities:
                sensitivities[key] = self._sensitivity(problem, y, d, ci, state, pressed, factors)
            try:
                out[index] = newton_update(state, updated[index], res, sensitivities[key])
            except np.linalg.LinAlgError:
                pass  # a singular S (pairs that act alike): keep the Uzawa update
        return tuple(out)

    def _sensitivity(self, problem: StepProblem, y: NDArray, d: NDArray, ci, state: PairState,
                     pressed: NDArray, factors: FactorCache | None) -> NDArray:
        """S = G A^-1 B over the pressed pairs (``contact.newton_update``), A the Newton matrix
        at hand (the kept factor of modified Newton, else factored at y)."""
        start, dt = problem.state, problem.dt
        v_eval = midpoint_velocity(d, start.d, dt) if self.dynamic and ci.persistency else None
        rate = velocity_factor(dt) if v_eval is not None else None
        b = lagrange_blocks(start.X + d, v_eval, rate, ci.interface, state, ci.law, start.x)
        # dense blocks on the unknowns straight from the triplets (sparse matrices and their
        # fancy indexing took half of this function's time): position of each dof among them
        position = np.full(self.model.ndof, -1)
        position[problem.free_dofs] = np.arange(problem.free_dofs.size)
        column = np.cumsum(pressed) - 1  # pressed pair -> column of S
        if factors is None:
            factor = partial(self.solve, problem.jacobian(y))
        else:
            if not factors.usable(y.size):
                factors.refresh(problem.jacobian(y))
            factor = partial(factors.solve, rtol=SENSITIVITY_RTOL)
        b_keep = pressed[b.b_cols] & (position[b.b_rows] >= 0)
        g_keep = pressed[b.g_rows] & (position[b.g_cols] >= 0)
        g_row, g_at, g_val = column[b.g_rows[g_keep]], position[b.g_cols[g_keep]], b.g_vals[g_keep]
        pairs = int(pressed.sum())
        # blocks only with a kept factor: a plain solve would factor A again for each block
        width = SENSITIVITY_COLUMNS if factors is not None else max(pairs, 1)
        S = np.zeros((pairs, pairs))
        for first in range(0, pairs, width):  # one solve a block of pairs
            block = slice(first, min(first + width, pairs))
            response = factor(_force_columns(b, b_keep, position, column, y.size, block))
            np.add.at(S[:, block], g_row, g_val[:, None] * response[g_at])
        return S

    def _conserve_energy(self, problem: StepProblem, result, mass):
        """Report 5.5 (see ``dynamics.energy``): if the Lagrange step changed the total energy,
        solve it again with the energy equation and theta, which relaxes the gap constraints
        towards persistency just enough. When the step already conserves energy (persistency,
        or no residual gap) theta would be undetermined, so it is only added when needed."""
        state, dt = problem.state, problem.dt
        load = self.model.loads(state.time + 0.5 * dt, state.d.size, state.X)
        end_energy = EndEnergy(self.model.assembler, mass, state.X, state.d.ravel(),
                               state.v.ravel(), dt, load, state.x.ravel())
        energy_n = self.balance(state).total_energy
        violation_signed = end_energy(problem.full(result.y))[0] - energy_n
        violation = abs(violation_signed)
        self._energy_multiplier = 0.0
        self._energy_unmet = False
        gap_terms = [t for t in problem.constraints if isinstance(t, LagrangeTerm)
                     and not t.ci.persistency]
        tolerance = self.settings.rtol * max(abs(energy_n), 1e-300)
        if not gap_terms or violation <= tolerance:
            return problem, result, 0, None
        others = [t for t in problem.constraints if t not in gap_terms]
        combined = EnergyConsistentContact(gap_terms, [t.h_at(state.x) for t in gap_terms],
                                           end_energy, energy_n)
        y0 = np.concatenate([result.y[: problem.free_dofs.size]]
                            + [t.initial for t in others] + [combined.initial])
        y0[-combined.size:-1] = np.concatenate(
            [m for t, m in zip(problem.constraints, problem.multipliers(result.y), strict=True)
             if t in gap_terms])
        if np.abs(np.concatenate(combined.h_start)).max() <= 1e-12 * self.length_scale**2:
            combined = combined.with_theta(1.0)  # no gap to relax: theta is undetermined
        try:
            bordered, new = self._solve_bordered(problem, others, combined, y0)
        except (NewtonError, LinearSolverError):
            bordered, new = self._theta_by_bracket(problem, others, combined, y0,
                                                   violation_signed, tolerance)
        if combined.fixed_theta is not None:  # no equation solved: did theta = 1 conserve?
            self._energy_unmet = abs(combined.excess(bordered.full(new.y))) > tolerance
        lams, theta = combined.split(bordered.multipliers(new.y)[-1])
        self._energy_multiplier = theta
        return bordered, new, new.iterations, (others, lams)

    def _theta_by_bracket(self, problem: StepProblem, others: list, combined,
                          y0: NDArray, excess_0: float, tolerance: float):
        """The energy equation as a root in theta alone, where the bordered Newton failed:
        the step solved at fixed theta, from theta = 0 (the step already solved, its excess
        energy over E_n + W ``excess_0``) and theta = 1 (persistency), by secant steps, and by
        the Illinois rule once the root is bracketed. A tester's block bouncing under gravity
        left +3e-5 (1e-3 of its energy) at each step where the bordered Newton had failed and
        theta = 1 was taken in silence. There no theta conserves the energy: the excess is
        least, 2.4e-5 of an energy of 0.02, near theta = 1.02, where a new pair's gap is
        the only one to relax. Without a root the step keeps the theta of the least excess
        and counts as unmet (summary.json ``energy_equation_unmet_steps``)."""
        def solved(theta: float, y: NDArray):
            y = y.copy()
            y[-1] = theta
            bordered, new = self._solve_bordered(problem, others, combined.with_theta(theta), y)
            return bordered, new, combined.excess(bordered.full(new.y))

        best = found = solved(1.0, y0)
        (a, e_a), (b, e_b) = (0.0, excess_0), (1.0, found[2])
        for _ in range(THETA_BRACKET_ITERATIONS):
            if abs(e_b) <= tolerance:
                return found[:2]
            if e_b == e_a:
                break
            theta = (a * e_b - b * e_a) / (e_b - e_a)
            try:
                found = solved(theta, found[1].y)
            except (NewtonError, LinearSolverError):
                break
            if found[2] * e_b < 0.0:  # bracketed by the last two: keep it so
                a, e_a = b, e_b
            elif found[2] * e_a < 0.0:
                e_a *= 0.5  # Illinois: the end that stays is halved
            else:
                a, e_a = b, e_b  # not bracketed: a secant step from the last two
            b, e_b = theta, found[2]
            best = min(best, found, key=lambda f: abs(f[2]))
        self._energy_unmet = True
        return best[:2]

    def _solve_bordered(self, problem: StepProblem, others: list, combined, y0: NDArray):
        bordered = StepProblem(self.model, problem.state, problem.dt, problem.mass,
                               problem.extra, others + [combined], union=self._union)
        new = self._newton(bordered.residual, bordered.jacobian, self.solve, y0, self.settings,
                           self.length_scale)
        return bordered, new

    def _newton(self, *args, **kwargs):
        """``newton``, counting its iterations in ``_newton_run`` also when it fails (its
        ``NewtonError.iterations``): a halved step's discarded attempts are told apart from
        the accepted sub-steps' by this count (history.csv failed_newton_iterations)."""
        try:
            result = newton(*args, **kwargs)
        except NewtonError as err:
            self._newton_run += err.iterations
            raise
        self._newton_run += result.iterations
        return result

    @staticmethod
    def _lagrange_multipliers(problem: StepProblem, result, split) -> list:
        """Multipliers of the Lagrange interfaces in interface order (see _conserve_energy)."""
        values = problem.multipliers(result.y)
        if split is None:
            return values
        others, lams = split
        by_term = dict(zip(map(id, others), values[:-1], strict=True))
        combined = problem.constraints[-1]
        by_term |= dict(zip(map(id, combined.terms), lams, strict=True))
        order = sorted(list(others) + list(combined.terms), key=lambda t: t.order)
        return [by_term[id(t)] for t in order]

    def _start_velocity(self, state: StepState) -> NDArray:
        """The velocity a step's first Newton start advances the nodes with: the mid-point
        velocity of the sub-step that ended at ``state``, v_n - h/2 a_n (a_n = (v_n -
        v_{n-1}) / h), not v_n. The end velocities of the mid-point rule carry its undamped
        odd-even mode wherever contact holds a velocity constraint (v_n = 2 v_{n-1/2} -
        v_{n-1}: the held nodes and the rows behind them flip by ~2 |v| from step to step),
        the mid-point velocities do not. Started from x_n + dt/2 v_n, the fast-sliding blocks
        refined 8x (contact-side row 2.1e-3 thick) started the step at t = 0.057 inside an
        inverted element (det J -0.33), and most contact steps were halved (docs/theory.md,
        "Newton start of held pairs")."""
        h = self._state_substep
        return state.v if h is None else state.v - 0.5 * h * state.a

    def _dof_mass(self, state: StepState) -> sp.csr_matrix:
        """The mass on dofs; ALE bodies carry new particles at their nodes, so it is rebuilt."""
        if not self.model.ale_bodies:
            return self._mass
        return self._moving_mass.matrix(state.X)

    def _contact_results(self, interfaces, contact, state: StepState, d: NDArray, dt: float,
                         last: dict):
        x_eval = state.X + d
        v_eval = midpoint_velocity(d, state.d, dt) if self.dynamic else None
        rate = velocity_factor(dt) if self.dynamic else None
        return evaluate_all(interfaces, contact, x_eval, v_eval, rate, state.x, dt, last)

    def step_with_cutback(self, dt: float) -> tuple[StepState, int, float]:
        """Advance by dt, halving (up to max_cutbacks times) sub-steps that fail; (the state,
        the accepted sub-steps' Newton iterations, the last sub-step). The iterations of the
        attempts the halvings discarded are kept apart in ``_failed_iterations``."""
        state, remaining, iterations, cuts, h = self.state, dt, 0, 0, dt
        self._step_work = dict.fromkeys(LEDGER, 0.0)  # summed over the accepted sub-steps
        self._augmentations_converged = True
        self._state_substep = self._last_substep
        self._failed_iterations = 0
        substeps: list[tuple[float, dict, dict]] = []  # each one's length, reactions, tie forces
        while remaining > 1e-12 * dt:
            h = min(h, remaining)
            run_before = self._newton_run
            fp_mark = self._fp_errors.mark()
            try:
                before = dict(self._step_work)
                state, its = self.advance(state, h)
                substeps.append((h, self._last_reactions, self._last_tie_forces))
            except (NewtonError, InvertedElementError, AleMotionError, np.linalg.LinAlgError,
                    RuntimeError, UndefinedNormalError) as err:
                cuts += 1
                self._failed_iterations += self._newton_run - run_before
                self._fp_errors.drop_since(fp_mark)  # the failure, or the halving, tells them
                failed = (f"step {self.state.step + 1} (t = {self.state.time:.6g} -> "
                          f"{self.state.time + dt:.6g}) failed")
                if not getattr(err, "halving_helps", True):
                    raise SimulationError(f"{failed}: {named_failure(self.model, err)}; the step "
                                          "was not halved: a shorter one cannot pass this test"
                                          ) from err
                if _same_problem(self.model, state, h):
                    raise SimulationError(f"{failed}: {named_failure(self.model, err)}"
                                          f"{_why_not_halved(err)}") from err
                if cuts > self.model.analysis.max_cutbacks:
                    raise SimulationError(
                        f"{failed} after {cuts - 1} halvings of the step: "
                        f"{named_failure(self.model, err)}"
                        f"{_last_attempt(self.state.time, state.time, h, cuts - 1)}") from err
                self._step_work = before
                h *= 0.5
                continue
            iterations += its
            remaining -= h
            self._state_substep = h
        self._cut_back = len(substeps) > 1
        if self.dynamic and self._cut_back:
            self._last_reactions, self._last_tie_forces = _mean_forces(substeps, dt)
        return replace(state, step=self.state.step + 1, time=self.state.time + dt), iterations, h

    def run(self, progress: Callable[[float], None] | None = None,
            stop_reason: Callable[[], str | None] | None = None) -> StepState:
        """Run to t_end; observers get every step; on error they are told and it re-raises.

        ``stop_reason`` is asked before every step: a reason (not None) ends the run there with
        :class:`RunInterrupted`. A signal handler that only records the request this way
        stops the run between steps, or between a step's active-set passes (:meth:`advance`),
        never inside a compiled kernel. NumPy's BLAS runs on one thread meanwhile
        (:func:`ntncontact.threads.serial_blas`)."""
        self._stop_reason = stop_reason
        self._fp_errors = FloatingPointErrors()
        try:
            with serial_blas(), self._fp_errors.recording():
                self._run_steps(progress, stop_reason)
        except KeyboardInterrupt as err:
            self._finish("interrupted", str(err) or "interrupted by the user")
            raise
        except Exception as err:
            # asked to stop, then an error (a second Ctrl-C inside a kernel): interrupted
            reason = stop_reason() if stop_reason is not None else None
            self._finish("interrupted" if reason else "failed", reason or str(err))
            raise
        self._finish("completed", None)
        return self.state

    def _run_steps(self, progress: Callable[[float], None] | None,
                   stop_reason: Callable[[], str | None] | None) -> None:
        """The time loop of :meth:`run`: every step to t_end, each told to the observers."""
        analysis = self.model.analysis
        n_steps = int(np.ceil(analysis.t_end / analysis.dt - 1e-9))
        if not self._resumed:
            self._notify(StepRecord(self.state, self.balance(self.state), 0, 0.0))
        for k in range(self.state.step, n_steps):  # a restored run: from its step on
            self._check_stop()
            # target times k dt (not accumulated sums) so output times are exact
            t_next = min((k + 1) * analysis.dt, analysis.t_end)
            dt = t_next - self.state.time
            self.state, its, self._last_substep = self.step_with_cutback(dt)
            self.state = replace(self.state, time=t_next)
            self._fp_errors.tell(self.state.step, t_next - dt, t_next)
            extra = (self._ledger_extra() | self._contact_extra() | self._penetration_extra()
                     | self._tie_extra() | self._last_reactions | {"cut_back": self._cut_back}
                     | {"failed_newton_iterations": self._failed_iterations})
            self._notify(StepRecord(self.state, self.balance(self.state), its, dt, extra))
            if progress is not None:
                progress(self.state.time)

    def _check_stop(self) -> None:
        """Raise :class:`RunInterrupted` if the run was asked to stop (``run``'s
        ``stop_reason``)."""
        reason = self._stop_reason() if self._stop_reason is not None else None
        if reason is not None:
            raise RunInterrupted(reason)

    def _accumulate_work(self, s: StepState, d1: NDArray, results, dt: float,
                         used: tuple = ()) -> None:
        """Work of the external and contact forces over the step, and the frictional
        dissipation: E_{n+1} - E_n = external + contact work (+ the scheme's own error).
        ``used``: the contact states the step was solved with (their t_T is the step
        start's), for the static dissipation's trapezoidal rule."""
        dx = (s.X + d1 - s.x).ravel()
        active = [r for r in results if r is not None]
        force = sum(r.force for r in active) if active else np.zeros(dx.size)
        if self.dynamic:  # the mid-point rule's forces at t_{n+1/2}
            load = self.model.loads(s.time + 0.5 * dt, dx.size, s.X)
        else:
            # the trapezoidal rule over the load step, exact where the forces change linearly
            # with the displacements (the end-of-step forces alone over-counted the work of a
            # load ramp by 1/2 of a step's share: Hertz's balance error 6 % of its scale)
            load = 0.5 * (self._static_start_load(s, dx.size)
                          + self.model.loads(s.time + dt, dx.size, s.X))
            force, self._contact_force = 0.5 * (self._contact_force + force), force
        self._step_work["external_work"] += float(load @ dx)
        if not active:
            return
        self._step_work["contact_work"] -= float(force @ dx)
        if self.dynamic:
            self._step_work["frictional_dissipation"] += sum(r.dissipation for r in active)
            return
        self._step_work["frictional_dissipation"] += sum(
            _static_dissipation(r, u, s.x, ci.law)
            for ci, r, u in zip(self.model.interfaces, results, used, strict=True)
            if r is not None and ci.law.frictional)

    def _static_start_load(self, s: StepState, ndof: int) -> NDArray:
        """The external load that the state ``s`` at a static step's start balances: the
        loads at t_n, except at the run's first step, whose undeformed initial state balances
        none. A load that is on at full value from t = 0 is then counted as applied over the
        first step, as a quasi-static path applies it (a linear block under a traction set at
        t = 0: external work twice its strain energy, a balance error of 0.5 -> round-off)."""
        return np.zeros(ndof) if s.step == 0 else self.model.loads(s.time, ndof, s.X)

    def _ledger_extra(self) -> dict:
        for key, value in self._step_work.items():
            self.ledger[key] += value
        return {"external_work": self.ledger["external_work"]}

    def _contact_extra(self) -> dict:
        """History columns and contact.csv rows of the step just completed."""
        results, augmentations = self._last_contact
        if not self.model.interfaces:
            return {}
        return {
            "active_pairs": sum(len(r.pairs) for r in results if r is not None),
            "frictional_dissipation": self.ledger["frictional_dissipation"],
            "contact_work": self.ledger["contact_work"],
            "augmentations": augmentations,
            "augmentations_converged": int(self._augmentations_converged),
            "ale_mismatch": self._last_mismatch,
            "ale_mismatch_at": self._last_mismatch_at,
            "contact_moment": self._last_moment,
            "ale_remap_energy": self.ledger["ale_remap_energy"],
            "ale_unreturned_energy": self.ledger["ale_unreturned_energy"],
            "energy_multiplier": self._energy_multiplier,
            "energy_equation_unmet": self._take_energy_unmet(),
            "contact_rows": contact_rows(self.model.interfaces, results, self.state.x),
            "contact_shares": unpaired_shares(self.model.interfaces, results, self.state.x),
        }

    def _take_energy_unmet(self) -> bool:
        """Whether the step just completed found no theta that conserves its energy (reset
        here: a step without contact solves no energy equation)."""
        unmet, self._energy_unmet = self._energy_unmet, False
        return unmet

    def _penetration_extra(self) -> dict:
        """The step's deepest boundary node inside another body off the contact surfaces
        (``diagnostics.PenetrationCheck``): its depth for history.csv, and where it is; and
        the deepest contact-surface node in no pair (``diagnostics.UnpairedCheck``), the
        deepest surface-2 node inside body 1 (``diagnostics.SurfaceTwoCheck``), the deepest
        boundary node inside its own body (``diagnostics.SelfCrossingCheck``) and the ALE
        bodies' worst sliver (``diagnostics.AleQualityCheck``) and their surface segments
        farthest outside the respacing's band (``diagnostics.AleSpacingCheck``)."""
        extra = {}
        if self._penetration is not None:
            found = self._penetration.deepest(self.state.x)
            extra = {"penetration_off_surfaces": found.depth,
                     "penetration_off_surfaces_at": found}
        if self._unpaired is not None:  # contact-surface nodes in no pair (UnpairedCheck)
            extra["penetration_unpaired_at"] = self._unpaired.deepest(self.state.x,
                                                                      self.state.contact)
        if self._surface_2 is not None:  # surface-2 nodes inside body 1 (SurfaceTwoCheck)
            extra["penetration_surface_2_at"] = self._surface_2.deepest(self.state.x)
        extra["self_penetration_at"] = self._self_crossing.deepest(self.state.x)
        if self._ale_quality is not None:  # an ALE body's cell flattened to a sliver
            extra["ale_degraded_cell"] = self._ale_quality.worst(self.state.x)
        if self._ale_spacing is not None:  # ALE surface segments bunched or spread
            extra["ale_spaced_segments"] = self._ale_spacing.extremes(self.state.x)
        return extra

    def _tie_extra(self) -> dict:
        """History columns of the ties: the resultant force each transmits to body 1 over the
        step (the reaction of the bond) and the largest distance between tied nodes."""
        if not self.model.ties:
            return {}
        out = {"tie_violation": tie_violation(self.model.ties, self.state.x)}
        for tie in self.model.ties:
            total = self._last_tie_forces.get(tie.name, np.zeros((0, 2))).sum(axis=0)
            out |= {f"tie_{tie.name}_force_x": float(total[0]),
                    f"tie_{tie.name}_force_y": float(total[1])}
        return out

    def _notify(self, record: StepRecord) -> None:
        for obs in self.observers:
            obs.on_step(self.model, record)

    def _finish(self, status: str, error: str | None) -> None:
        for obs in self.observers:
            obs.on_finish(status, error)


class FloatingPointErrors:
    """NumPy's floating-point errors (divide by zero, overflow, invalid value) in a run's
    steps, told once as one warning that names the step, instead of NumPy's own lines
    ("warning: overflow encountered in multiply", a tester's ring thrown at 1e300) that say
    neither where nor why. Those of a sub-step that failed are dropped: its error, or the
    halving that passed, is the story. Not the package's own warnings: only NumPy's errors
    reach :meth:`__call__` (``np.errstate(call=...)``)."""

    def __init__(self) -> None:
        self.kinds: list[str] = []
        self.told = False

    def __call__(self, kind: str, _flag: int) -> None:
        self.kinds.append(kind)

    def recording(self) -> np.errstate:
        """The context in which NumPy calls this object instead of warning (underflow stays
        ignored, as by default)."""
        return np.errstate(divide="call", over="call", invalid="call", call=self)

    def mark(self) -> int:
        return len(self.kinds)

    def drop_since(self, mark: int) -> None:
        del self.kinds[mark:]

    def tell(self, step: int, t_start: float, t_end: float) -> None:
        """Warn, once a run, of the errors the step just completed met."""
        if self.kinds and not self.told:
            self.told = True
            kinds = ", ".join(sorted(set(self.kinds)))
            warnings.warn(
                f"step {step} (t = {t_start:.6g} -> {t_end:.6g}): NumPy met floating-point "
                f"errors ({kinds}; {len(self.kinds)} in the step): values out of the "
                "floating-point range, the results may hold inf or NaN; check the units and "
                "scale of the inputs", RuntimeWarning, stacklevel=2)
        self.kinds.clear()


def _mean_forces(substeps: list[tuple[float, dict, dict]], dt: float) -> tuple[dict, dict]:
    """A cut-back dynamic step's support reactions and tie forces as the means over its
    sub-steps, weighted by their lengths: the history row's force times dt is then the step's
    impulse, which the momentum's change equals (a tester's cut-back steps, where the last
    sub-step's forces were reported, missed it by up to 6 % of the largest momentum)."""
    reactions = {key: sum(h * r[key] for h, r, _ in substeps) / dt for key in substeps[-1][1]}
    ties = {name: sum(h * t[name] for h, _, t in substeps) / dt for name in substeps[-1][2]}
    return reactions, ties
