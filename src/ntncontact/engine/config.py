"""The validated, typed scenario: the pydantic models a scenario's mapping must satisfy (every
key is in docs/scenarios.md) and the error a scenario that cannot be used raises. Reading and
overriding scenario files is io.scenario's."""

from __future__ import annotations

from typing import Annotated, Any, Literal, get_args

from pydantic import BaseModel, BeforeValidator, ConfigDict, Field, model_validator

from ..solvers.linear import Precision


class ScenarioError(ValueError):
    """A scenario file that cannot be used; the message names the file and the key."""


#: Default of ``analysis.max_steps``: a run of more steps is refused before it starts.
MAX_STEPS = 10**7


class Strict(BaseModel):
    # strict: no coercion (true is not 1, "0.02" is not a number, "yes" is not a boolean);
    # every float must be finite (TOML has inf and nan)
    model_config = ConfigDict(extra="forbid", frozen=True, populate_by_name=True, strict=True,
                              allow_inf_nan=False)


Positive = Annotated[float, Field(gt=0)]
NonNegative = Annotated[float, Field(ge=0)]
#: a body, interface or tie name: it labels output columns and messages, so never empty
Name = Annotated[str, Field(min_length=1)]
#: TOML arrays are lists; strict validation takes a tuple only from a tuple
Vector = Annotated[tuple[float, float],
                   BeforeValidator(lambda v: tuple(v) if isinstance(v, list) else v)]


class TimeFunctionConfig(Strict):
    """Piecewise-linear scale factor: values at strictly increasing times."""

    times: list[float] = Field(min_length=1)
    values: list[float] = Field(min_length=1)

    @model_validator(mode="after")
    def _same_length(self) -> TimeFunctionConfig:
        if len(self.times) != len(self.values):
            raise ValueError("'times' and 'values' must have the same length")
        if any(b <= a for a, b in zip(self.times, self.times[1:], strict=False)):
            raise ValueError("'times' must increase strictly")
        return self


class TransformConfig(Strict):
    rotate_deg: float = 0.0
    center: Vector = (0.0, 0.0)
    translate: Vector = (0.0, 0.0)


class RectangleMesh(Strict):
    type: Literal["rectangle"]
    width: Positive
    height: Positive
    nx: Annotated[int, Field(ge=1)]
    ny: Annotated[int, Field(ge=1)]
    origin: Vector = (0.0, 0.0)
    grading_x: Positive = 1.0
    grading_y: Positive = 1.0
    transform: TransformConfig | None = None


class AnnulusMesh(Strict):
    type: Literal["annulus"]
    r_inner: Positive
    r_outer: Positive
    n_radial: Annotated[int, Field(ge=1)]
    n_circ: Annotated[int, Field(ge=3)]
    center: Vector = (0.0, 0.0)
    start_angle_deg: float = -90.0
    transform: TransformConfig | None = None

    @model_validator(mode="after")
    def _radii(self) -> AnnulusMesh:
        if self.r_inner >= self.r_outer:
            raise ValueError("r_inner must be smaller than r_outer")
        return self


class HalfDiskMesh(Strict):
    type: Literal["half_disk"]
    radius: Positive
    n_arc: Annotated[int, Field(ge=2)]
    n_radial: Annotated[int, Field(ge=1)]
    bottom_size: Positive | None = None
    center: Vector = (0.0, 0.0)
    transform: TransformConfig | None = None


class DiskMesh(Strict):
    type: Literal["disk"]
    radius: Positive
    n_circ: Annotated[int, Field(ge=8, multiple_of=8)]
    n_radial: Annotated[int, Field(ge=1)]
    surface_size: Positive | None = None
    center: Vector = (0.0, 0.0)
    transform: TransformConfig | None = None


class GmshMesh(Strict):
    type: Literal["gmsh"]
    file: str
    transform: TransformConfig | None = None


MeshConfig = Annotated[
    RectangleMesh | AnnulusMesh | HalfDiskMesh | DiskMesh | GmshMesh, Field(discriminator="type")
]
MESH_TYPES = frozenset(get_args(m.model_fields["type"].annotation)[0]
                       for m in (RectangleMesh, AnnulusMesh, HalfDiskMesh, DiskMesh, GmshMesh))


class MaterialConfig(Strict):
    """Either (E, nu) or (lambda, mu), plus the density."""

    model: Literal["linear_elastic", "neo_hookean"]
    E: Positive | None = None
    nu: Annotated[float, Field(gt=-1.0, lt=0.5)] | None = None
    lam: float | None = Field(default=None, alias="lambda")
    mu: Positive | None = None
    density: Positive
    plane_stress: bool = False

    @model_validator(mode="after")
    def _one_pair(self) -> MaterialConfig:
        young = self.E is not None or self.nu is not None
        lame = self.lam is not None or self.mu is not None
        if young == lame:
            raise ValueError("give either E and nu, or lambda and mu (not both, not neither)")
        if young and (self.E is None or self.nu is None):
            raise ValueError("E and nu must be given together")
        if lame and (self.lam is None or self.mu is None):
            raise ValueError("lambda and mu must be given together")
        return self


class SupportConfig(Strict):
    """Prescribed displacement components on a node or edge set (omitted component is free)."""

    set: str
    x: float | None = None
    y: float | None = None
    function: TimeFunctionConfig | None = None

    @model_validator(mode="after")
    def _some_component(self) -> SupportConfig:
        if self.x is None and self.y is None:
            raise ValueError("a support must prescribe 'x', 'y' or both")
        return self


class LoadConfig(Strict):
    """pressure (scalar, on an edge set), traction / point (vector), body_force (vector per
    volume), gravity (acceleration vector: the body force density * vector)."""

    type: Literal["pressure", "traction", "point", "body_force", "gravity"]
    set: str | None = None
    value: float | None = None
    vector: Vector | None = None
    function: TimeFunctionConfig | None = None

    @model_validator(mode="after")
    def _fields(self) -> LoadConfig:
        if self.type == "pressure" and self.value is None:
            raise ValueError("a pressure load needs 'value'")
        if self.type == "pressure" and self.vector is not None:
            raise ValueError("a pressure load takes 'value' (normal to its edges), not 'vector'")
        if self.type != "pressure" and self.vector is None:
            raise ValueError(f"a {self.type} load needs 'vector'")
        if self.type != "pressure" and self.value is not None:
            raise ValueError(f"a {self.type} load takes 'vector', not 'value'")
        if self.type in ("body_force", "gravity") and self.set is not None:
            raise ValueError(f"a {self.type} load acts on the whole body: remove 'set'")
        if self.type not in ("body_force", "gravity") and self.set is None:
            raise ValueError(f"a {self.type} load needs 'set'")
        return self


class InitialConfig(Strict):
    velocity: Vector = (0.0, 0.0)
    angular_velocity: float = 0.0


class AleConfig(Strict):
    """How an ALE body's mesh follows its contact partners (report chapter 4)."""

    smoothing: Literal["laplacian", "angle", "weighted_angle"] = "laplacian"
    smoothing_layers: Annotated[int, Field(ge=0)] = 3
    sweeps: Annotated[int, Field(ge=0)] = 10
    remap: Literal["linear", "quadratic"] = "linear"
    conserve_momentum: bool = True
    # the remap's velocity correction also sets the kinetic energy: "total" (its value before
    # the remap minus the strain energy the remap changed and the repair below could not
    # restore: E exact), "kinetic" (its value before the remap) or "none"
    conserve_energy: Literal["total", "kinetic", "none"] = "total"
    # relabel the particles at the moved nodes (X at fixed x) so that the remap keeps the
    # strain energy: docs/theory.md, "The strain energy the remap changes"
    restore_strain_energy: bool = True
    respace: Literal["local", "reference"] = "local"
    # a surface node leaves a fixed end behind by at most this times their reference distance
    max_stretch: Annotated[float, Field(gt=1.0)] = 2.0
    interior: Literal["minimal", "displacement", "position"] = "minimal"
    slide_tolerance: Positive = 1e-8
    # "convective_term": remap only X and d, and add the report's C v to the step (5.7)
    convection: Literal["remap", "convective_term"] = "remap"


class BodyConfig(Strict):
    name: Name
    mesh: MeshConfig
    material: MaterialConfig
    mesh_motion: Literal["lagrangian", "ale"] = "lagrangian"
    ale: AleConfig = AleConfig()
    initial: InitialConfig = InitialConfig()
    supports: list[SupportConfig] = []
    loads: list[LoadConfig] = []


class NewtonConfig(Strict):
    rtol: Positive = 1e-10
    max_iterations: Annotated[int, Field(ge=1)] = 25
    inexact_augmentations: Annotated[float, Field(ge=0.0, lt=1.0)] = 1e-4
    factor_precision: Precision = "auto"
    #: kept-factor (modified Newton) steps in a row before a fresh factorization; 0 is full
    #: Newton, a fresh factorization every iteration (NewtonSettings.max_reused_steps)
    max_reused_steps: Annotated[int, Field(ge=0)] = 4


class AnalysisConfig(Strict):
    kind: Literal["static", "dynamic"]
    dt: Positive
    t_end: Positive
    mass: Literal["consistent", "lumped"] = "consistent"
    output_interval: Positive | None = None
    #: which steps' pairs contact.csv keeps: every step's, those of the field frames, or
    #: none (the summary's contact figures are taken from every step's pairs all the same)
    contact_output: Literal["steps", "frames", "none"] = "steps"
    checkpoint_interval: Positive | None = None
    max_cutbacks: Annotated[int, Field(ge=0, le=20)] = 4
    newton: NewtonConfig = NewtonConfig()
    energy_conserving: bool = False
    integrator: Literal["midpoint", "energy_momentum"] = "energy_momentum"
    max_steps: Annotated[int, Field(ge=1)] = MAX_STEPS
    #: "vtu" (fields.pvd + a VTU a frame) or "xdmf" (fields.xdmf + fields.h5, needs h5py)
    field_format: Literal["vtu", "xdmf"] = "vtu"

    @model_validator(mode="after")
    def _step_count(self) -> AnalysisConfig:
        """dt no larger than t_end, and at most max_steps steps (checked before any is run:
        t_end = 1e15 or dt = 5e-324 would otherwise run until killed)."""
        if self.dt > self.t_end:
            raise ValueError(f"analysis.dt = {self.dt!r} is larger than analysis.t_end = "
                             f"{self.t_end!r}")
        steps = self.t_end / self.dt  # a float: may be inf, never an overflowing int
        if steps > self.max_steps:
            raise ValueError(f"analysis.t_end / analysis.dt = {self.t_end!r} / {self.dt!r} = "
                             f"{steps:.3g} steps, more than analysis.max_steps = "
                             f"{self.max_steps} (raise it to allow a longer run)")
        return self


class AugmentationConfig(Strict):
    """Nested augmented-Lagrangian loop of report 5.4 (tolerances on the changes per update)."""

    max_iterations: Annotated[int, Field(ge=1)] = 20
    gap_tolerance: Positive = 1e-8
    slip_tolerance: Positive = 1e-8
    traction_tolerance: Positive = 1e-8
    update: Literal["uzawa", "newton"] = "uzawa"
    on_limit: Literal["cut_back", "accept"] = "cut_back"


class ContactConfig(Strict):
    """A contact interface between a surface of body 1 (carries the normal) and of body 2."""

    name: Name | None = None
    body_1: str
    surface_1: str
    body_2: str
    surface_2: str
    method: Literal["penalty", "augmented_lagrangian", "lagrange"] = "augmented_lagrangian"
    law: Literal["gap", "persistency"] | None = None
    penalty_normal: NonNegative = 0.0
    penalty_tangential: NonNegative = 0.0
    #: the penalties from the bodies and the mesh instead (engine.builder.interface_penalties)
    penalty_factor: Positive | None = None
    friction: NonNegative = 0.0
    exclude: list[str] = []
    corners: list[str] = []
    release_steps: Annotated[int, Field(ge=1)] = 2
    detection: Literal["penetration", "predicted"] | None = None
    moment_free: bool | None = None  # None: on in dynamic runs (docs/theory.md)
    gap_restoring: bool = False  # persistency law: a pair's first step closes its gap
    #: dynamic steps: nodes a solve ends inside surface 2 are taken in and the step solved
    #: again, as quasi-static steps always do (engine.simulation, docs/scenarios.md)
    active_set_pass: bool = False
    ale_normal: bool | None = None  # None: pairs facing an ALE body take its normal
    unpaired_share: bool | None = None  # None: on beside an ALE body (docs/theory.md)
    augmentation: AugmentationConfig = AugmentationConfig()

    @model_validator(mode="after")
    def _sides(self) -> ContactConfig:
        if self.body_1 == self.body_2:  # each pair's surfaces are checked apart at t = 0
            raise ValueError(f"body_1 and body_2 are the same body '{self.body_1}': contact of "
                             "a body with itself (self-contact) is not supported")
        scaled = self.penalty_factor is not None
        if scaled and self.penalty_normal > 0.0:
            raise ValueError("give penalty_normal or penalty_factor, not both "
                             "(penalty_normal = 0 leaves eps_N to penalty_factor)")
        if self.method != "lagrange" and self.penalty_normal <= 0.0 and not scaled:
            raise ValueError(f"method '{self.method}' needs penalty_normal > 0 "
                             "(or penalty_factor)")
        if self.friction > 0.0 and self.penalty_tangential <= 0.0 and not scaled:
            raise ValueError("friction > 0 needs penalty_tangential > 0 (or penalty_factor)")
        return self

    def resolved(self, kind: str) -> dict[str, Any]:
        """The values the run takes for the keys whose default depends on others (None
        here): ``law`` (persistency in a dynamic run, else gap), ``moment_free`` (on in a
        dynamic run) and ``detection`` (predicted for Lagrange under the gap law, else
        penetration). The build and a sweep's table read them from here."""
        law = self.law or ("persistency" if kind == "dynamic" else "gap")
        detection = self.detection or ("predicted" if self.method == "lagrange"
                                       and law == "gap" else "penetration")
        moment_free = kind == "dynamic" if self.moment_free is None else self.moment_free
        return {"law": law, "detection": detection, "moment_free": moment_free}

    def ineffective_keys(self) -> list[str]:
        """The keys given here that this interface's method and friction never read, each
        group as a clause naming the keys and why (the run is the same without them). Warned
        of, not refused: one scenario file serves every method through ``--set
        contact.N.method=...``.
        ``penalty_tangential`` without friction is not among them: friction > 0 requires it,
        so files that ``--set contact.N.friction`` switches on carry it (three examples)."""
        given = [k for k in AugmentationConfig.model_fields
                 if k in self.augmentation.model_fields_set]
        frictionless = self.friction == 0.0
        notes = []
        if self.method == "penalty" and given:
            notes.append(f"{_keys(given, 'augmentation.')} no effect with method = "
                         "\"penalty\": a penalty interface is solved once a step, without "
                         "augmentations")
        if self.method == "lagrange":
            notes += self._lagrange_notes(given, frictionless)
        if self.method == "augmented_lagrangian" and frictionless:
            tangential = [k for k in given if k in ("slip_tolerance", "traction_tolerance")]
            if tangential:
                notes.append(f"{_keys(tangential, 'augmentation.')} no effect on a "
                             "frictionless interface (friction = 0): they test the "
                             "tangential multipliers, which only friction has")
        return notes

    def _lagrange_notes(self, given: list[str], frictionless: bool) -> list[str]:
        """:meth:`ineffective_keys` of a Lagrange interface: its normal tractions are exact
        multipliers (no eps_N), and it is not augmented; only friction's eps_T is a penalty
        (``penalty_factor`` sets it when ``penalty_tangential`` is not given)."""
        notes = []
        if self.penalty_normal > 0.0:
            notes.append(f"penalty_normal = {self.penalty_normal!r} has no effect with method "
                         "= \"lagrange\": its normal tractions are exact multipliers")
        if self.penalty_factor is not None and (frictionless or self.penalty_tangential > 0.0):
            why = ("without friction no tangential penalty acts" if frictionless
                   else "penalty_tangential gives the tangential one")
            notes.append(f"penalty_factor = {self.penalty_factor!r} has no effect with method "
                         f"= \"lagrange\": its normal tractions are exact multipliers, and {why}")
        unread = [k for k in given if k not in ("max_iterations", "on_limit")]
        if unread:
            notes.append(f"{_keys(unread, 'augmentation.')} no effect with method = "
                         "\"lagrange\": its exact multipliers are not augmented "
                         "(augmentation.max_iterations and on_limit bound its passes that "
                         "release pairs in tension)")
        return notes


def _keys(names: list[str], prefix: str) -> str:
    """"a.x has" or "a.x, a.y have": the subject of a clause on the keys ``names``."""
    return ", ".join(prefix + n for n in names) + (" has" if len(names) == 1 else " have")


class TieConfig(Strict):
    """Nodes of surface 1 held at their coincident partners on surface 2 (x_a = x_b)."""

    name: Name
    body_1: str
    surface_1: str
    body_2: str
    surface_2: str
    tolerance: Positive | None = None  # default 1e-8 times the two bodies' extent


class ScenarioConfig(Strict):
    title: str = ""
    analysis: AnalysisConfig
    bodies: list[BodyConfig] = Field(min_length=1)
    contact: list[ContactConfig] = []
    tie: list[TieConfig] = []

    @model_validator(mode="after")
    def _unique_names(self) -> ScenarioConfig:
        names = [b.name for b in self.bodies]
        if len(set(names)) != len(names):
            raise ValueError(f"body names must be unique, got {names}")
        for table, items in (("contact", self.contact), ("tie", self.tie)):
            for i, item in enumerate(items):
                where = f"{table}.{i}" + (f" ('{item.name}')" if table == "tie" else "")
                for key in ("body_1", "body_2"):
                    if getattr(item, key) not in names:
                        raise ValueError(f"{where}.{key}: no body named '{getattr(item, key)}'")
        ties = [t.name for t in self.tie]
        if len(set(ties)) != len(ties):
            raise ValueError(f"tie names must be unique, got {ties}")
        # contact.csv's rows and summary.json's penalties are told apart by these names
        interfaces = [c.name or f"interface{i}" for i, c in enumerate(self.contact)]
        if len(set(interfaces)) != len(interfaces):
            raise ValueError(f"contact names must be unique, got {interfaces}")
        return self
