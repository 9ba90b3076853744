"""Build a :class:`Model` from a validated scenario configuration."""

from __future__ import annotations

import warnings
from itertools import combinations
from pathlib import Path

import numpy as np

from ..ale.motion import AleBody
from ..ale.multisurface import check_surfaces
from ..contact import AugmentationTolerances, ContactLaw, ContactSurface, Interface, corner_mask
from ..fem.loads import (
    LoadCase,
    MeshBodyForce,
    Prescribed,
    TimeFunction,
    body_force_vector,
    conflicting_dofs,
    edge_traction_vector,
    point_load_vector,
    same_motions,
)
from ..materials.models import Material, MaterialError
from ..mesh import generators
from ..mesh.boundary import boundary_edges, chain_edge_lengths, surface_chain
from ..mesh.overlap import deepest_overlap, facing_away
from ..mesh.quadmesh import MeshError, QuadMesh
from ..mesh.quality import check_elements
from .config import (
    BodyConfig,
    ContactConfig,
    LoadConfig,
    MaterialConfig,
    MeshConfig,
    ScenarioConfig,
    ScenarioError,
    TieConfig,
    TimeFunctionConfig,
)
from .diagnostics import PhysicsWarning
from .initial import warn_overridden_velocities, warn_tied_velocities
from .model import AleSetup, AnalysisSettings, Body, ContactInterface, Model, stack_bodies
from .ties import (
    Tie,
    TieError,
    held_on_edges,
    make_tie,
    pair_tie,
    redundant_tie,
    tied_partner,
)


def build_mesh(cfg: MeshConfig, name: str, base_dir: Path) -> QuadMesh:
    """Generate or read the mesh of one body, then apply its rigid placement."""
    if cfg.type == "rectangle":
        mesh = generators.rectangle(cfg.width, cfg.height, cfg.nx, cfg.ny, cfg.origin,
                                    cfg.grading_x, cfg.grading_y, name=name)
    elif cfg.type == "annulus":
        mesh = generators.annulus(cfg.r_inner, cfg.r_outer, cfg.n_radial, cfg.n_circ,
                                  cfg.center, name=name, start_angle_deg=cfg.start_angle_deg)
    elif cfg.type == "half_disk":
        mesh = generators.half_disk(cfg.radius, cfg.n_arc, cfg.n_radial, cfg.bottom_size,
                                    cfg.center, name=name)
    elif cfg.type == "disk":
        mesh = generators.disk(cfg.radius, cfg.n_circ, cfg.n_radial, cfg.surface_size,
                               cfg.center, name=name)
    else:
        from ..mesh.gmsh_io import read_msh

        path = (base_dir / cfg.file).resolve()
        if not path.is_file():
            raise ScenarioError(f"body '{name}': mesh file not found: {path}")
        mesh = read_msh(path, name=name)
    if cfg.transform is not None:
        t = cfg.transform
        mesh = mesh.transformed(t.rotate_deg, t.translate, t.center)
    check_elements(mesh, body_name=name)  # a file's mesh named by the file's numbers
    return mesh


def build_material(cfg: MaterialConfig) -> Material:
    if cfg.E is not None:
        return Material.from_young(cfg.model, cfg.E, cfg.nu, cfg.density, cfg.plane_stress)
    return Material(cfg.model, cfg.lam, cfg.mu, cfg.density, cfg.plane_stress)


#: Poisson's ratio from which the fully integrated Q4 element's volumetric locking is worth a
#: warning (lambda / mu = 9): an independent tester's cantilever deflected 0.90 of beam theory
#: at nu = 0.3, 0.50 at 0.49 and 0.11 at 0.499
LOCKING_NU = 0.45


def _warn_locking(where: str, material: Material) -> None:
    """Warn of a nearly incompressible body in plane strain: the Q4 elements (2 x 2 Gauss
    points, no selective or reduced integration) lock, and it comes out too stiff."""
    nu = material.lam / (2.0 * (material.lam + material.mu))
    if not material.plane_stress and nu >= LOCKING_NU:
        warnings.warn(f"{where}: nu = {nu:.3g} (lambda/mu = {material.lam / material.mu:.3g}): "
                      "the fully integrated Q4 elements lock near incompressibility in plane "
                      "strain, and the body comes out too stiff (a cantilever: 0.50 of beam "
                      "theory's deflection at nu = 0.49, 0.11 at 0.499; refining eases it "
                      "slowly): compare with a run at nu = 0.45", PhysicsWarning, stacklevel=2)


def _warn_penalty_rate_law(config: ScenarioConfig) -> None:
    """Warn of penalty interfaces under the persistency (rate) law in a dynamic run with a load
    still on at t_end: that law's penalty relates the traction to the gap rate, a dashpot, so
    a sustained load sinks the body at t_N / eps_N without bound (a tester's block resting
    under gravity: 0.009, 0.019, 0.029, 0.039 deep at t = 1..4). Prescribed motions are not
    looked at: whether they press the bodies together is not known before the run."""
    if config.analysis.kind != "dynamic":
        return
    for i, c in enumerate(config.contact):
        loads = _sustained_loads(config, _joined(config, {c.body_1, c.body_2}),
                                 first=(c.body_1, c.body_2))
        if c.method == "penalty" and (c.law or "persistency") == "persistency" and loads:
            warnings.warn(f"contact.{i} ('{c.name or f'interface{i}'}'): method = \"penalty\" "
                          f"under the persistency law cannot carry the sustained {loads[0]}: its "
                          "penalty resists the gap's rate, not the gap, so the bodies sink into "
                          "each other at traction / penalty_normal without bound; use method = "
                          "\"augmented_lagrangian\", or law = \"gap\" with a penalty in stress "
                          "per length (docs/scenarios.md, \"Choosing penalty_normal, dt and the "
                          "ALE body\")", PhysicsWarning, stacklevel=3)


#: Coulomb coefficients above this are warned of: measured dry-friction coefficients stay
#: below ~1.5 (rubber on dry rock), and a tester's friction = 1e300 ran silently.
LARGE_FRICTION = 10.0


def _warn_large_friction(config: ScenarioConfig) -> None:
    """Warn of a friction coefficient no pair of materials has: likely a unit or typing slip
    (a percentage, an angle). A warning, not an error: a large mu is a valid way to make the
    interface stick."""
    for i, c in enumerate(config.contact):
        if c.friction > LARGE_FRICTION:
            warnings.warn(f"contact.{i} ('{c.name or f'interface{i}'}'): friction = "
                          f"{c.friction:.3g} is a Coulomb coefficient far above any measured "
                          f"one (dry friction stays below ~1.5; above {LARGE_FRICTION:g} is "
                          "warned of): the pairs stick whatever the load; is it a percentage "
                          "or an angle?", PhysicsWarning, stacklevel=3)


def _joined(config: ScenarioConfig, bodies: set[str]) -> set[str]:
    """``bodies`` and every body joined to them through contact interfaces and ties: a load
    on a block stacked on top presses the interface below it too."""
    links = [(c.body_1, c.body_2) for c in (*config.contact, *config.tie)]
    grown = set(bodies)
    while True:
        more = {b for a, b in links if a in grown} | {a for a, b in links if b in grown}
        if more <= grown:
            return grown
        grown |= more


def _warn_ineffective_keys(config: ScenarioConfig) -> None:
    """Warn, once per interface and reason, of the keys given that the interface's method
    and friction never read (:meth:`ContactConfig.ineffective_keys`): a tester's penalty run
    with an augmentation table and Lagrange runs at penalty_normal = 1000 / 10 were identical
    to runs without, silently. Warnings, not errors: one file serves every method through
    --set. Issued by the build, as the other build warnings, so that a run prints them once
    and keeps them in summary.json ``build_warnings``."""
    static = config.analysis.kind == "static"
    for i, c in enumerate(config.contact):
        for note in c.ineffective_keys() + _unread_in_this_run(c, static):
            warnings.warn(f"contact.{i} ('{c.name or f'interface{i}'}'): {note}",
                          PhysicsWarning, stacklevel=3)


def _unread_in_this_run(c: ContactConfig, static: bool) -> list[str]:
    """The keys of ``c`` that the method or the analysis kind leaves unread: release_steps
    under Lagrange (its multipliers release a pair in tension at once: tester B's ring impact
    identical with 1 and 2) and under the gap law (a pair is released when its gap opens:
    tester R's ring identical with 1 and 4); gap_restoring and active_set_pass in a static
    run (its steps always solve again with the nodes they end inside; tester R: contact.csv
    byte for byte the plain run's)."""
    given = c.model_fields_set
    law = c.law or ("gap" if static else "persistency")
    notes = []
    if "release_steps" in given and c.method == "lagrange":
        notes.append("release_steps has no effect with method = \"lagrange\": its "
                     "multipliers release a pair in tension at once, in the step that finds it "
                     "(docs/scenarios.md, release_steps)")
    elif "release_steps" in given and law == "gap":
        notes.append("release_steps has no effect under the gap law: a pair is released "
                     "when its gap opens (the key counts steps of the persistency law)")
    unread = [k for k in ("gap_restoring", "active_set_pass") if getattr(c, k) and static]
    if unread:
        notes.append(f"{' and '.join(unread)} {'have' if len(unread) > 1 else 'has'} no "
                     "effect in a static run, which solves each step again with the nodes it "
                     "ends inside")
    return notes


def _warn_support_jumps(config: ScenarioConfig) -> None:
    """A dynamic run's support that prescribes a displacement other than 0 at t = 0: the run
    starts from the reference (d = 0), so the held nodes jump there in the first step and the
    mid-point rule keeps them swinging about it (a tester's x = 0.01: the nodes between 0 and
    0.02, their speed growing 4, 8, 12, 16, 20 and the energy 0 -> 2.33; x = 0.1 inverted an
    element)."""
    if config.analysis.kind != "dynamic":
        return
    for body in config.bodies:
        for i, support in enumerate(body.supports):
            start = 1.0 if support.function is None else float(np.interp(
                0.0, support.function.times, support.function.values))
            if start and ((support.x or 0.0) or (support.y or 0.0)):
                warnings.warn(f"bodies '{body.name}' supports.{i} (set '{support.set}'): it "
                              "prescribes a displacement other than 0 at t = 0, where the run "
                              "starts at rest in the reference, so its nodes jump in the first "
                              "step and swing about the value; give it a function that starts "
                              "at 0 (a ramp)", PhysicsWarning, stacklevel=3)


def _sustained_loads(config: ScenarioConfig, bodies: set[str],
                     first: tuple[str, ...] = ()) -> list[str]:
    """The loads on ``bodies`` still on at t_end, as "gravity on 'block'" (a time function
    ending at zero is a load that returns; a load on a body the interface does not join was
    warned about too, a tester's third body 10 units away). Only unsupported bodies: a
    supported body's own load goes to its supports (a tester's supported slab under gravity
    was told its bodies sink without bound; 1.7e-5 in 2 s). The loads on the ``first``
    bodies (an interface's own two) come first, in that order: a tester's 4-block stack was
    told for every interface, the top one's too, that it could not carry the gravity on the
    lowest free block."""
    t_end = config.analysis.t_end
    rank = {name: k for k, name in enumerate(first)}
    loaded = sorted((body for body in config.bodies if body.name in bodies),
                    key=lambda body: rank.get(body.name, len(first)))
    return [f"{load.type} on '{body.name}'" for body in loaded for load in body.loads
            if not body.supports and _nonzero(load)
            and (load.function is None
                 or np.interp(t_end, load.function.times, load.function.values) != 0.0)]


def _nonzero(load: LoadConfig) -> bool:
    """A load of some size (a tester's gravity [0, 0] and zero traction were warned about)."""
    size = load.value if load.value is not None else np.abs(load.vector or [0.0]).max()
    return bool(size)


def time_function(cfg: TimeFunctionConfig | None) -> TimeFunction:
    if cfg is None:
        return TimeFunction()
    return TimeFunction(tuple(cfg.times), tuple(cfg.values))


def _body_loads(body: Body, cfg: BodyConfig, ndof: int, X0: np.ndarray):
    """Fixed nodal patterns with their time functions, and the body forces that follow an ALE
    body's moving reference mesh (gravity there)."""
    patterns, functions, on_mesh = [], [], []
    cells = body.mesh.cells + body.node_offset
    for load in cfg.loads:
        if load.type == "gravity":
            force = body.material.density * np.asarray(load.vector, dtype=float)
            gravity = MeshBodyForce(cells, force, time_function(load.function))
            if body.mesh_motion == "ale":
                on_mesh.append(gravity)
                continue
            f = gravity.vector(X0, ndof)
        elif load.type in ("pressure", "traction"):
            edges = body.global_edges(load.set)
            f = edge_traction_vector(X0, edges, load.vector, load.value, ndof)
        elif load.type == "point":
            f = point_load_vector(body.global_nodes(load.set), load.vector, ndof)
        else:
            f = body_force_vector(X0, cells, load.vector, ndof)
        patterns.append(f)
        functions.append(time_function(load.function))
    return patterns, functions, on_mesh


def _body_supports(i: int, body: Body, cfg: BodyConfig,
                   bodies: tuple[Body, ...]) -> list[Prescribed]:
    """One :class:`Prescribed` per support and component; two that give a dof different
    motions are refused (``_check_support_conflicts``)."""
    out = []
    for j, sup in enumerate(cfg.supports):
        nodes = body.global_nodes(sup.set)
        for comp, value in ((0, sup.x), (1, sup.y)):
            if value is not None:
                out.append((j, Prescribed(2 * nodes + comp, np.full(len(nodes), value),
                                          time_function(sup.function), f"{body.name}_{sup.set}")))
    _check_support_conflicts(i, cfg, out, bodies)
    return [p for _, p in out]


def _check_support_conflicts(i: int, cfg: BodyConfig, entries: list[tuple[int, Prescribed]],
                             bodies: tuple[Body, ...]) -> None:
    """Refuse two supports of a body that prescribe one dof different motions (value or time
    function): the later one held and the other was dropped unsaid, so the result depended
    on the order in the file (tester V: a corner in 'bottom' y = 0 and in
    'corner_bottom_left' y = 0.05 ended at 0.05 or 0.0 by the order). The same motion twice
    (a corner held by 'bottom' and 'left') is accepted."""
    for (j, a), (jb, b) in combinations(entries, 2):
        dofs, va, vb = conflicting_dofs(a, b)
        if not dofs.size:
            continue
        sa, sb = cfg.supports[j], cfg.supports[jb]
        raise ScenarioError(
            f"bodies.{i} ('{cfg.name}'): supports.{j} (set '{sa.set}') and supports.{jb} "
            f"(set '{sb.set}') prescribe different {'xy'[dofs[0] % 2]} displacements to "
            f"{_node_where(bodies, int(dofs[0]) // 2)}: {_motion_text(va[0], a.function)} "
            f"and {_motion_text(vb[0], b.function)}: only one can hold, and which one "
            "would depend on their order in the file; give the node one motion: leave "
            "that component out of one support, or use a set without the node")


def _motion_text(value: float, function: TimeFunction) -> str:
    """A prescribed component as the scenario gives it: "0.05", or "0.05 x s(t) (times
    [...], values [...])" with a time function."""
    if function == TimeFunction():
        return f"{value:g}"
    return (f"{value:g} x s(t) (times {[float(t) for t in function.times]}, values "
            f"{[float(v) for v in function.values]})")


def _check_reaction_labels(config: ScenarioConfig) -> None:
    """Refuse two (body, set) pairs whose reaction columns ``reaction_<body>_<set>_*`` share
    a name: ``engine.reactions.support_sets`` keys by that name, and history.csv had one
    column holding the sum of both reactions (tester V: body 'blk' set 'top_left' and body
    'blk_top' set 'left', -5 and -7 written as one -12). The names are a public contract,
    so the clash is refused rather than the columns renamed."""
    seen: dict[str, tuple[int, str, str]] = {}
    for i, body in enumerate(config.bodies):
        for sup in body.supports:
            label = f"{body.name}_{sup.set}"
            first = seen.setdefault(label, (i, body.name, sup.set))
            if first[1:] != (body.name, sup.set):
                raise ScenarioError(
                    f"bodies.{first[0]} ('{first[1]}') set '{first[2]}' and bodies.{i} "
                    f"('{body.name}') set '{sup.set}' would both write the reaction columns "
                    f"reaction_{label}_x, _y and _moment of history.csv (named "
                    "reaction_<body>_<set>_...), which would hold the sum of the two; rename "
                    "one of the sets or bodies")


def build_model(config: ScenarioConfig, base_dir: str | Path = ".") -> Model:
    """Meshes, materials, loads and supports of every body; errors name the body and key."""
    base_dir = Path(base_dir)
    entries = []
    for i, bc in enumerate(config.bodies):
        where = f"bodies.{i} ('{bc.name}')"
        try:
            entries.append((bc.name, build_mesh(bc.mesh, bc.name, base_dir),
                            build_material(bc.material)))
        except (MeshError, MaterialError) as err:
            raise ScenarioError(f"{where}: {err}") from None
        _warn_locking(where, entries[-1][2])
    placed, X0, cells, assembler = stack_bodies(entries)
    bodies = tuple(
        Body(name, mesh, mat, noff, coff, bc.initial.velocity, bc.initial.angular_velocity,
             bc.mesh_motion)
        for (name, mesh, mat, noff, coff), bc in zip(placed, config.bodies, strict=True)
    )
    ndof = 2 * len(X0)
    _check_reaction_labels(config)
    patterns, functions, on_mesh, prescribed = [], [], [], []
    for i, (body, bc) in enumerate(zip(bodies, config.bodies, strict=True)):
        try:
            p, f, m = _body_loads(body, bc, ndof, X0)
            prescribed += _body_supports(i, body, bc, bodies)
        except MeshError as err:
            raise ScenarioError(f"bodies.{i} ('{body.name}'): {err}") from None
        patterns += p
        functions += f
        on_mesh += m
    a = config.analysis
    interfaces = tuple(_interface(c, i, bodies, a.kind) for i, c in enumerate(config.contact))
    for i, (c, ci) in enumerate(zip(config.contact, interfaces, strict=True)):
        _check_no_overlap(i, c, ci, bodies)
        _check_facing(i, c, ci, bodies)
    _check_paired_once(interfaces, config.contact, bodies)
    _check_unjoined_overlaps(config, bodies)
    _check_analysis_options(config)
    _warn_penalty_rate_law(config)
    _warn_ineffective_keys(config)
    _warn_large_friction(config)
    _warn_support_jumps(config)
    ale_bodies = tuple(_ale_setup(i, body, bc, config) for i, (body, bc)
                       in enumerate(zip(bodies, config.bodies, strict=True))
                       if bc.mesh_motion == "ale")
    analysis = AnalysisSettings(a.kind, a.dt, a.t_end, a.mass, a.output_interval,
                                a.max_cutbacks, a.newton.rtol, a.newton.max_iterations,
                                a.newton.inexact_augmentations,
                                factor_precision=a.newton.factor_precision,
                                newton_max_reused_steps=a.newton.max_reused_steps,
                                energy_conserving=a.energy_conserving,
                                integrator=a.integrator, field_format=a.field_format,
                                contact_output=a.contact_output)
    fixed = np.unique(np.concatenate([p.dofs for p in prescribed] or [np.zeros(0, int)]))
    ties = tuple(_tie(t, i, bodies, fixed) for i, t in enumerate(config.tie))
    _check_ale_ties(ties, ale_bodies, bodies)
    _check_tied_multipliers(ties, interfaces, config.contact, bodies)
    _check_redundant_ties(ties, bodies, fixed)
    _check_tied_prescriptions(ties, tuple(prescribed), bodies)
    _check_tied_lagrange_pairs(ties, interfaces, config.contact, bodies)
    loads = LoadCase(tuple(patterns), tuple(functions), tuple(on_mesh), X0)
    model = Model(bodies, analysis, loads,
                  tuple(prescribed), X0, cells, assembler, interfaces, ale_bodies, ties)
    warn_overridden_velocities(model)
    warn_tied_velocities(model)
    return model


def _check_analysis_options(config: ScenarioConfig) -> None:
    """Options that the analysis would otherwise ignore, or that fail only steps later: each is
    refused, naming the key (an independent user's check found them accepted in silence)."""
    a = config.analysis
    if a.kind == "static":
        if a.energy_conserving:
            raise ScenarioError("analysis.energy_conserving: only for dynamic analyses "
                                "(report 5.5)")
        if "integrator" in a.model_fields_set:
            raise ScenarioError("analysis.integrator: only for dynamic analyses (a static run "
                                "has no time integrator)")
        for i, c in enumerate(config.contact):
            if c.law == "persistency":  # the rate law of 2.34 needs velocities
                raise ScenarioError(f"contact.{i}.law = \"persistency\": the rate law needs a "
                                    "dynamic analysis; a static run takes the gap law")
        _check_static_inertia(config)
    if a.energy_conserving and not any(
            c.method == "lagrange" and (c.law or "persistency") == "gap" for c in config.contact):
        raise ScenarioError("analysis.energy_conserving: report 5.5's variant acts on the "
                            "interfaces with method = \"lagrange\" and law = \"gap\", and "
                            "this scenario has none (the persistency law conserves energy by "
                            "itself)")
    if a.energy_conserving:
        _check_energy_equation(config)


def _check_static_inertia(config: ScenarioConfig) -> None:
    """A static run has no inertia: an initial velocity and the mass matrix were dropped in
    silence (a tester's block given velocity [1, 0] ran with zero kinetic energy, told only that
    its supported nodes start at their supports' velocity), so they are refused, naming the
    key, as analysis.integrator is."""
    if "mass" in config.analysis.model_fields_set:
        raise ScenarioError("analysis.mass: only for dynamic analyses (a static run has no "
                            "inertia)")
    for i, body in enumerate(config.bodies):
        for key in ("velocity", "angular_velocity"):
            # a zero is what a static run does anyway (a tester's explicit [0, 0] was refused)
            if key in body.initial.model_fields_set and np.any(getattr(body.initial, key)):
                raise ScenarioError(f"bodies.{i}.initial.{key} (body '{body.name}'): only for "
                                    "dynamic analyses (a static run starts at rest)")


def _check_energy_equation(config: ScenarioConfig) -> None:
    """Report 5.5's energy equation holds the step's energy change to the loads' work. Friction
    and a moving support also change it, by work that is not in the equation, which theta then
    made the normal contact forces do instead (a tester's oblique impact with mu = 0.3: +3.3 %
    of the energy from normal contact, hidden behind the friction's losses)."""
    for i, c in enumerate(config.contact):
        if c.friction > 0.0:
            raise ScenarioError(
                f"analysis.energy_conserving with contact.{i}.friction = {c.friction:g}: the "
                "energy equation of report 5.5 does not include the friction's dissipation, so "
                "the normal contact forces would make up for it; use the persistency law (which "
                "conserves the energy that friction does not take) or friction = 0")
    for b, body in enumerate(config.bodies):
        for s, support in enumerate(body.supports):
            if any(value not in (None, 0.0) for value in (support.x, support.y)):
                raise ScenarioError(
                    f"analysis.energy_conserving with bodies.{b}.supports.{s} prescribing a "
                    "motion: the reactions' work is not in report 5.5's energy equation; use "
                    "the persistency law, or fixed supports")


def _tie(cfg: TieConfig, index: int, bodies: tuple[Body, ...], fixed_dofs: np.ndarray) -> Tie:
    """Pair the coincident nodes of one ``[[tie]]`` entry; errors name the entry."""
    where = f"tie.{index} ('{cfg.name}')"
    b1, b2 = _bodies_of(cfg, bodies)
    try:
        local_1, local_2 = b1.mesh.node_set(cfg.surface_1), b2.mesh.node_set(cfg.surface_2)
    except MeshError as err:
        raise ScenarioError(f"{where}: {err}") from None
    extent = np.ptp(np.vstack([b1.mesh.nodes, b2.mesh.nodes]), axis=0).max()
    tolerance = cfg.tolerance if cfg.tolerance is not None else 1e-8 * extent
    try:
        nodes_1, nodes_2 = pair_tie(cfg.name, b1.name, b1.mesh.nodes[local_1],
                                    local_1 + b1.node_offset, b2.name, b2.mesh.nodes[local_2],
                                    local_2 + b2.node_offset, tolerance)
    except TieError as err:
        raise ScenarioError(f"{where}: {err}") from None
    return make_tie(cfg.name, b1.name, b2.name, nodes_1, nodes_2, fixed_dofs,
                    _held_on_edges(b1, local_1, cfg.surface_1, b2, local_2, nodes_2, tolerance))


def _held_on_edges(b1: Body, local_1: np.ndarray, surface_1: str, b2: Body,
                   local_2: np.ndarray, paired_2: np.ndarray, tolerance: float
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The nodes of a tie's surface 2 that no node of surface 1 coincides with but that lie
    on one of its edges (global), those edges' end nodes (global) and the nodes' parameters
    on them (``ties.held_on_edges``); surface 1's edges are its edge set's, or body 1's
    boundary edges between its nodes. Nodes on no edge (surface 2 reaching past surface 1)
    stay free."""
    extra = np.setdiff1d(local_2 + b2.node_offset, paired_2) - b2.node_offset
    if surface_1 in b1.mesh.edge_sets:
        edges = b1.mesh.edge_sets[surface_1]
    else:
        edges = boundary_edges(b1.mesh.cells)
        edges = edges[np.isin(edges, local_1).all(axis=1)]
    edge, xi = held_on_edges(b2.mesh.nodes[extra], b1.mesh.nodes, edges, tolerance)
    held = edge >= 0
    return (extra[held] + b2.node_offset, edges[edge[held]] + b1.node_offset, xi[held])


def _check_ale_ties(ties: tuple[Tie, ...], ale_bodies: tuple[AleSetup, ...],
                    bodies: tuple[Body, ...]) -> None:
    """A tied node of an ALE body must be one the mesh motion never moves (a boundary node
    off its contact surface, or an end or corner of it): the tie holds material points."""
    for setup in ale_bodies:
        sliding = np.zeros(setup.n_nodes, bool)
        for motion in setup.motions:
            sliding[motion.surface] |= ~motion.corner
        for motion in setup.motions:  # ends of open chains (corners shared by two) are fixed
            if not motion.closed:
                sliding[motion.surface[[0, -1]]] = False
        movable = sliding | ~setup.motion.boundary
        for tie in ties:
            for nodes in (tie.nodes_1, tie.nodes_2, np.unique(tie.edge_dofs // 2)):
                local = nodes - setup.node_offset
                local = local[(local >= 0) & (local < setup.n_nodes)]
                if movable[local].any():
                    name = bodies[setup.body_index].name
                    raise ScenarioError(
                        f"tie '{tie.name}': nodes {local[movable[local]].tolist()} of the ALE "
                        f"body '{name}' may be moved by its mesh motion (interior or on its "
                        "contact surface); tie only its fixed boundary nodes")


def _ale_setup(index: int, body: Body, cfg: BodyConfig, config: ScenarioConfig) -> AleSetup:
    """The ALE body's contact surfaces are the ones it has in the scenario's interfaces; each
    follows its own partners (``ale.multisurface``)."""
    surfaces = [c.surface_1 for c in config.contact if c.body_1 == body.name]
    surfaces += [c.surface_2 for c in config.contact if c.body_2 == body.name]
    surfaces = list(dict.fromkeys(surfaces))  # in scenario order, each once
    where = f"bodies.{index} ('{body.name}').mesh_motion"
    if not surfaces:
        raise ScenarioError(f"{where}: an ALE body needs a contact surface, found none")
    opts = cfg.ale
    # the engine corrects the remapped velocities with the model's own mass matrix
    motions = tuple(
        AleBody.from_mesh(body.mesh, surface, smoothing=opts.smoothing,
                          smoothing_layers=opts.smoothing_layers, sweeps=opts.sweeps,
                          remap=opts.remap, conserve_momentum=False,
                          respace=opts.respace, max_stretch=opts.max_stretch,
                          interior=opts.interior,
                          slide_tolerance=opts.slide_tolerance, convection=opts.convection,
                          density=body.material.density, name=body.name)
        for surface in surfaces)
    try:
        check_surfaces(motions, surfaces)
    except ValueError as err:
        raise ScenarioError(f"{where}: {err}") from None
    return AleSetup(index, body.node_offset, body.mesh.n_nodes, motions[0], motions[1:],
                    opts.conserve_momentum, opts.conserve_energy, opts.restore_strain_energy)


def _interface(cfg: ContactConfig, index: int, bodies: tuple[Body, ...],
               kind: str) -> ContactInterface:
    """Surfaces, law and settings of one ``[[contact]]`` entry; errors name the entry."""
    where = f"contact.{index}"
    b1, b2 = _bodies_of(cfg, bodies)
    try:
        chain1 = surface_chain(b1.mesh, cfg.surface_1)
        chain2 = surface_chain(b2.mesh, cfg.surface_2)
        excluded = np.concatenate([b1.global_nodes(n) for n in cfg.exclude] or [np.zeros(0, int)])
        corners = np.concatenate([b1.global_nodes(n) for n in cfg.corners] or [np.zeros(0, int)])
    except MeshError as err:
        raise ScenarioError(f"{where}: {err}") from None
    surface1 = ContactSurface.from_chain(chain1, b1.node_offset)
    for key in ("exclude", "corners"):  # a set off the surface does nothing: a typo
        for name in getattr(cfg, key):
            if not np.isin(b1.global_nodes(name), surface1.nodes).any():
                raise ScenarioError(f"{where}.{key}: node set '{name}' has no node on "
                                    f"surface_1 '{cfg.surface_1}' of '{b1.name}'")
    # corners of body 1 (kinks and the ends of an open surface) take the partner's normal (6.6)
    auto = surface1.nodes[corner_mask(_xy(b1, surface1), surface1, include_ends=True)]
    # a node facing an ALE surface takes that surface's normal: the ALE node slides along its
    # own surface, across which the slide then changes no gap to first order (docs/theory.md,
    # "The gap across an ALE move")
    facing_ale = b2.mesh_motion == "ale" and b1.mesh_motion == "lagrangian"
    surface1 = ContactSurface(surface1.nodes, surface1.closed,
                              np.isin(surface1.nodes, np.concatenate([auto, corners])),
                              facing_ale if cfg.ale_normal is None else cfg.ale_normal)
    surface2 = ContactSurface.from_chain(chain2, b2.node_offset)
    # moment-free pair forces conserve angular momentum under the mid-point rule: the default
    # of dynamic runs; static runs keep the report's forces (docs/theory.md, "Moment-free
    # pair forces")
    resolved = cfg.resolved(kind)
    moment_free = resolved["moment_free"]
    # unpaired nodes between pairs share the pair forces where an ALE body ends the pairs node
    # to node; offset Lagrangian pairs would share them at the wrong places (docs/theory.md)
    lagrangian = b1.mesh_motion == "lagrangian" and b2.mesh_motion == "lagrangian"
    share = not lagrangian if cfg.unpaired_share is None else cfg.unpaired_share
    persistency = resolved["law"] == "persistency"
    spacing = min(_median_spacing(b.mesh.nodes[c.nodes], c.closed)
                  for b, c in ((b1, chain1), (b2, chain2)))
    law = ContactLaw(cfg.method, *interface_penalties(cfg, (b1.material, b2.material), spacing,
                                                      persistency),
                     cfg.friction, moment_free, cfg.gap_restoring, share)
    aug = cfg.augmentation
    tol = AugmentationTolerances(aug.gap_tolerance, aug.slip_tolerance, aug.traction_tolerance)
    candidates = surface1.nodes[~np.isin(surface1.nodes, excluded)]
    max_aug = 1 if cfg.method == "penalty" else aug.max_iterations
    ordered = "ale" in (b1.mesh_motion, b2.mesh_motion)
    # exact gap constraints must not inherit a step's penetration: detect before touching
    predicted = resolved["detection"] == "predicted"
    # the arc length of every node along surface 2's (open) chain
    arc2 = np.concatenate([[0.0], np.cumsum(chain_edge_lengths(b2.mesh.nodes[chain2.nodes],
                                                               False))])
    return ContactInterface(cfg.name or f"interface{index}", Interface(surface1, surface2), law,
                            persistency, candidates, cfg.release_steps, tol, max_aug, ordered,
                            predicted, aug.update, aug.on_limit == "accept",
                            reference_arc2=arc2,
                            active_set_pass=cfg.active_set_pass, spacing=spacing)


def _check_paired_once(interfaces: tuple[ContactInterface, ...],
                       configs: list[ContactConfig], bodies: tuple[Body, ...]) -> None:
    """Refuse a node of body 1 that is a candidate of two interfaces against one partner
    surface (the corner between two faces, each its own interface): it would be paired twice,
    its contact force counted twice, and an ALE partner surface would send two of its nodes
    onto it. Joining the faces into one surface pairs it once."""
    for j, (cfg_j, face_j) in enumerate(zip(configs, interfaces, strict=True)):
        for i in range(j):
            cfg_i, face_i = configs[i], interfaces[i]
            _check_not_both_ways(i, j, face_i, face_j)
            facing = np.intersect1d(face_i.interface.surface2.nodes,
                                    face_j.interface.surface2.nodes)
            twice = np.intersect1d(face_i.candidates, face_j.candidates)
            if facing.size < 2 or twice.size == 0:  # one shared node: surfaces meeting at a corner
                continue
            body = next(b for b in bodies if b.name == cfg_j.body_1)
            raise ScenarioError(
                f"contact.{i} and contact.{j}: nodes {(twice - body.node_offset).tolist()[:6]} "
                f"of body '{body.name}' are on both '{cfg_i.surface_1}' and "
                f"'{cfg_j.surface_1}', which face the same surface of '{cfg_j.body_2}': they "
                f"would be paired twice. Make one interface of both: surface_1 = "
                f"\"{cfg_i.surface_1}+{cfg_j.surface_1}\", or exclude those nodes from one of "
                "them (exclude = [node set])")


def _check_tied_multipliers(ties: tuple[Tie, ...], interfaces: tuple[ContactInterface, ...],
                            configs: list[ContactConfig], bodies: tuple[Body, ...]) -> None:
    """Refuse two tied nodes that two ``method = "lagrange"`` interfaces hold against the same
    surface: both pair with the same partner node and their gap constraints are one, so the
    multiplier system is singular (a tester's two tied blocks on one foundation failed with
    "SuperLU: Factor is exactly singular"). The penalty-based methods take both."""
    exact = [(k, ci, set(ci.candidates.tolist()))
             for k, (ci, c) in enumerate(zip(interfaces, configs, strict=True))
             if c.method == "lagrange"]
    same_surface = [(i, j, cands_j) for i, face_i, _ in exact for j, face_j, cands_j in exact
                    if i != j and np.intersect1d(face_i.interface.surface2.nodes,
                                                 face_j.interface.surface2.nodes).size >= 2]
    for tie in ties:
        tied = dict(zip(tie.nodes_1.tolist(), tie.nodes_2.tolist(), strict=True))
        for i, j, cands_j in same_surface:
            both = [a for a in interfaces[i].candidates.tolist() if tied.get(a, -1) in cands_j]
            if both:
                _refuse_tied_twice(tie, both, tied, i, j, configs, bodies)


def _refuse_tied_twice(tie: Tie, both: list[int], tied: dict, i: int, j: int,
                       configs: list[ContactConfig], bodies: tuple[Body, ...]) -> None:
    by_name = {b.name: b for b in bodies}
    b1, b2 = by_name[configs[i].body_1], by_name[configs[j].body_1]
    raise ScenarioError(
        f"contact.{i} and contact.{j} (method = \"lagrange\") hold the nodes "
        f"{[a - b1.node_offset for a in both[:4]]} of body '{b1.name}' and "
        f"{[tied[a] - b2.node_offset for a in both[:4]]} of body '{b2.name}', tied together by "
        f"tie '{tie.name}', against the same surface: their two gap constraints are one and "
        f"the multiplier system is singular. Exclude those nodes from one interface "
        f"(contact.{j}.exclude), or use method = \"augmented_lagrangian\" there")


def _node_where(bodies: tuple[Body, ...], node: int) -> str:
    """A global node as "node 4 of body 'A' at (0, 0.5)"."""
    body = next(b for b in bodies if b.node_offset <= node < b.node_offset + b.mesh.n_nodes)
    x, y = body.mesh.nodes[node - body.node_offset]
    return f"node {node - body.node_offset} of body '{body.name}' at ({x:.6g}, {y:.6g})"


def _check_redundant_ties(ties: tuple[Tie, ...], bodies: tuple[Body, ...],
                          fixed: np.ndarray) -> None:
    """Refuse a tied pair that other ties (or the supports) already hold together: its
    constraint repeats theirs and the step's matrix is singular (a tester's three parts tied
    around one corner, A-B, C-B and A-C, ended "SuperLU: Factor is exactly singular" after
    every halving; without the A-C tie it ran, exact)."""
    found = redundant_tie(ties, fixed)
    if found is None:
        return
    through = "the supports and " * found.supports
    ties_named = ", ".join(f"'{name}'" for name in found.route)
    raise ScenarioError(
        f"tie '{found.tie}' holds {_node_where(bodies, found.node_1)} to "
        f"{_node_where(bodies, found.node_2)}, which {through}tie(s) {ties_named} already "
        "hold together: the constraint is given twice and the step's matrix is singular; "
        f"drop one of the ties there (tie '{found.tie}', or give it a node set without "
        "that node)")


def _check_tied_prescriptions(ties: tuple[Tie, ...], prescribed: tuple[Prescribed, ...],
                              bodies: tuple[Body, ...]) -> None:
    """Refuse a tied pair whose two nodes are prescribed different motions in one component:
    the tie leaves such a component to the supports, which pull the pair apart (a tester's
    tied corners held at x = 0 and x = 0.01 ran to "completed" 0.01 apart, only
    ``max_tie_violation`` telling). Equal motions are the supports' own business."""
    motion: dict[int, tuple[float, Prescribed]] = {}
    for p in prescribed:  # the build refused different motions of one dof: any entry will do
        for dof, value in zip(p.dofs.tolist(), p.values.tolist(), strict=True):
            motion[dof] = (value, p)
    for tie in ties:
        for n1, n2 in zip(tie.nodes_1.tolist(), tie.nodes_2.tolist(), strict=True):
            for c in (0, 1):
                a, b = motion.get(2 * n1 + c), motion.get(2 * n2 + c)
                if a is None or b is None or same_motions(  # value * s(t) equal at all times
                        np.array([a[0]]), a[1].function, np.array([b[0]]), b[1].function)[0]:
                    continue
                raise ScenarioError(
                    f"tie '{tie.name}': {_node_where(bodies, n1)} and "
                    f"{_node_where(bodies, n2)} are tied, and their supports prescribe "
                    f"different {'xy'[c]} motions ('{a[1].label}', '{b[1].label}'), which pull "
                    "the tie apart: prescribe one of them, or the same motion on both")


def _check_tied_lagrange_pairs(ties: tuple[Tie, ...],
                               interfaces: tuple[ContactInterface, ...],
                               configs: list[ContactConfig], bodies: tuple[Body, ...]) -> None:
    """Refuse a candidate of a ``method = "lagrange"`` interface tied (directly or through
    other ties) to a node of its partner surface: the two coincide, so they pair at once and
    the pair's exact gap constraint repeats the tie's (the delamination example with
    ``method = "lagrange"`` and ``exclude = []`` ended "SuperLU: Factor is exactly singular"
    after 6 halvings; its ``exclude = ["tips"]`` avoids it). A penalty or augmented
    Lagrangian pair adds a force, no constraint, and is not refused."""
    for i, (face, cfg) in enumerate(zip(interfaces, configs, strict=True)):
        if cfg.method != "lagrange":
            continue
        found = tied_partner(ties, face.candidates, face.interface.surface2.nodes)
        if found is None:
            continue
        node, partner, route = found
        ties_named = ", ".join(f"'{name}'" for name in route)
        raise ScenarioError(
            f"contact.{i} ('{face.name}', method = \"lagrange\"): {_node_where(bodies, node)} "
            f"is a contact candidate and tie(s) {ties_named} hold it to "
            f"{_node_where(bodies, partner)} on its partner surface: the pair's gap "
            "constraint repeats the tie and the step's matrix is singular; leave the tied "
            f"nodes out of the interface (contact.{i}.exclude = [a node set of them], as the "
            "delamination example's exclude = [\"tips\"] does), or use method = "
            "\"augmented_lagrangian\" there")


def _check_not_both_ways(i: int, j: int, face_i: ContactInterface,
                         face_j: ContactInterface) -> None:
    """Two interfaces whose candidates each lie on the other's partner surface pair the same
    faces both ways round, and both pairs act (a tester's second interface with the roles
    swapped split the load 4.16 + 5.84 and changed the strain energy 0.0381 -> 0.0367)."""
    one_way = np.intersect1d(face_i.candidates, face_j.interface.surface2.nodes)
    other_way = np.intersect1d(face_j.candidates, face_i.interface.surface2.nodes)
    if one_way.size >= 2 and other_way.size >= 2:
        raise ScenarioError(
            f"contact.{i} and contact.{j} join the same faces with the roles of the bodies "
            f"swapped ('{face_i.name}', '{face_j.name}'): their pairs would both act; keep "
            "one of them")


def interface_penalties(cfg: ContactConfig, materials: tuple[Material, Material],
                        spacing: float, persistency: bool) -> tuple[float, float]:
    """(eps_N, eps_T) of an interface: ``penalty_normal`` and ``penalty_tangential`` as given,
    or ``penalty_factor`` f times the softer body's stiffness as docs/scenarios.md ("Choosing
    penalty_normal") advises: under the gap law f (lambda + 2 mu) / h, the P-wave modulus of
    the 2D model over the contact spacing h, so that a pair's spring eps_N L_c keeps its ratio
    to the elements' stiffness, and with it the Uzawa contraction ~(lambda + 2 mu) / (eps_N h),
    when the mesh is refined; under the persistency law f rho c, the impedance (traction per
    velocity), which does not depend on the mesh. eps_T is eps_N unless given."""
    if cfg.penalty_factor is None:
        return cfg.penalty_normal, cfg.penalty_tangential
    moduli = [m.effective_lambda + 2.0 * m.mu for m in materials]
    if persistency:
        stiffness = min(np.sqrt(modulus * m.density) for modulus, m in zip(moduli, materials,
                                                                        strict=True))
    else:
        stiffness = min(moduli) / spacing
    eps_N = cfg.penalty_factor * float(stiffness)
    return eps_N, cfg.penalty_tangential or eps_N


def _median_spacing(xy: np.ndarray, closed: bool) -> float:
    """The median edge length of a surface chain: its contact spacing h (the median, so that
    a few long edges away from the contact zone, as in a graded mesh, do not set it)."""
    return float(np.median(chain_edge_lengths(xy, closed)))


def _check_no_overlap(index: int, cfg: ContactConfig, ci: ContactInterface,
                      bodies: tuple[Body, ...]) -> None:
    """Refuse bodies that overlap at t = 0: node-to-node contact would not push them apart
    (they would pass through each other). Each side's surface nodes are tested against the
    other body's elements; the message gives the deepest node, its place and its depth below
    the other body's boundary."""
    b1, b2 = _bodies_of(cfg, bodies)
    sides = ((b1, ci.interface.surface1, b2), (b2, ci.interface.surface2, b1))
    for body, surface, other in sides:
        local = surface.nodes - body.node_offset
        if surface.closed:  # the closing edge's side is tested too
            local = np.append(local, local[0])
        found = deepest_overlap(body.mesh.nodes[local], other.mesh.nodes, other.mesh.cells,
                                chain=True)
        if found is not None:
            x, y = found.position
            where = (f"the face from node {int(local[found.point])} of '{body.name}' at "
                     f"({x:.6g}, {y:.6g}) lies {found.depth:.3g} inside" if found.edge else
                     f"node {int(local[found.point])} of '{body.name}' at ({x:.6g}, {y:.6g}) "
                     f"is {found.depth:.3g} deep inside")
            raise ScenarioError(
                f"contact.{index}: bodies '{body.name}' and '{other.name}' overlap at t = 0: "
                f"{where} '{other.name}'; place the bodies apart "
                "(bodies.*.mesh origin, center or transform)")


def _check_facing(index: int, cfg: ContactConfig, ci: ContactInterface,
                  bodies: tuple[Body, ...]) -> None:
    """Refuse an interface whose surfaces face away from each other at t = 0
    (``mesh.overlap.facing_away``): a surface declared on the far side of its body lets the
    partner in through the near side unresisted. Refused, not warned: no run of such a pair
    is valid, and surfaces facing each other (a ring far above a floor, a disk in a ring, a
    pin in a hole) have opposed normals at their nearest points, near or far."""
    b1, b2 = _bodies_of(cfg, bodies)
    s1, s2 = ci.interface.surface1, ci.interface.surface2
    found = facing_away(b1.mesh.nodes[s1.nodes - b1.node_offset], s1.closed,
                        b2.mesh.nodes[s2.nodes - b2.node_offset], s2.closed)
    if found is None:
        return
    node = int(s1.nodes[found] - b1.node_offset)
    x, y = b1.mesh.nodes[node]
    raise ScenarioError(
        f"contact.{index} ('{ci.name}'): surface_1 '{cfg.surface_1}' of '{b1.name}' and "
        f"surface_2 '{cfg.surface_2}' of '{b2.name}' face away from each other at t = 0 (at "
        f"node {node} of '{b1.name}' at ({x:.6g}, {y:.6g}), the nearest to '{b2.name}', both "
        "outward normals point the same way and the partner lies behind a surface): one is "
        f"the face on the far side of its body; change contact.{index}.surface_1 or "
        "surface_2 to the faces that meet")


def _check_unjoined_overlaps(config: ScenarioConfig, bodies: tuple[Body, ...]) -> None:
    """Refuse two bodies that no interface joins and that overlap at t = 0: nothing pushes
    them apart (a tester's block placed 0.2 deep inside another ran to "completed", warned of
    a node "0.209 inside 'C' (t = 0.02)" as if it had gone there in the run). Each body's
    boundary nodes are tested against the other's elements (``deepest_overlap``); bodies that
    touch, tied ones too, are not an overlap."""
    joined = {frozenset((c.body_1, c.body_2)) for c in config.contact}
    outline = {b.name: boundary_edges(b.mesh.cells) for b in bodies}
    for j, other in enumerate(bodies):
        for body in bodies[:j]:
            if frozenset((body.name, other.name)) in joined:
                continue  # the interface's own check names its surfaces (_check_no_overlap)
            for one, two in ((body, other), (other, body)):
                nodes = np.unique(outline[one.name])
                found = deepest_overlap(one.mesh.nodes[nodes], two.mesh.nodes, two.mesh.cells,
                                        outline[two.name])
                if found is not None:
                    x, y = found.position
                    raise ScenarioError(
                        f"bodies '{one.name}' and '{two.name}' overlap at t = 0 and no "
                        f"[[contact]] joins them: node {int(nodes[found.point])} of "
                        f"'{one.name}' at ({x:.6g}, {y:.6g}) is {found.depth:.3g} deep inside "
                        f"'{two.name}', and nothing would push it out; place the bodies apart "
                        "(bodies.*.mesh origin, center or transform)")


def _bodies_of(cfg: ContactConfig | TieConfig, bodies: tuple[Body, ...]) -> tuple[Body, Body]:
    """The bodies ``body_1`` and ``body_2`` of a contact or tie entry."""
    by_name = {b.name: b for b in bodies}
    return by_name[cfg.body_1], by_name[cfg.body_2]


def _xy(body: Body, surface: ContactSurface) -> np.ndarray:
    """Reference coordinates indexed by global node (only the surface's rows are filled)."""
    xy = np.zeros((surface.nodes.max() + 1, 2))
    xy[surface.nodes] = body.mesh.nodes[surface.nodes - body.node_offset]
    return xy
