"""The observer that writes a run folder: history every step, fields at output times."""

from __future__ import annotations

import math
from collections.abc import Callable
from pathlib import Path

import numpy as np

from ..contact import ContactLaw
from ..contact.evaluate import TOUCH_ROUNDOFF
from ..engine.diagnostics import EnergyAudit, linear_elastic_measures
from ..engine.model import Model
from ..engine.postprocess import (
    contact_node_fields,
    frame_fields,
    mesh_velocity,
)
from ..engine.reactions import reaction_columns
from ..engine.simulation import StepRecord
from ..mesh.boundary import chain_edge_lengths
from ..mesh.quality import quality_statistics
from .run_folder import RunLock
from .vtk import VtuSeriesWriter
from .writers import MemoryResults, ResultsDirectory

CONTACT_HISTORY = ("active_pairs", "frictional_dissipation", "contact_work", "augmentations",
                   "ale_mismatch", "energy_multiplier", "augmentations_converged",
                   "ale_remap_energy", "penetration_off_surfaces", "ale_unreturned_energy")
#: without interfaces, runs of several bodies still measure one body going inside another
OFF_SURFACE_HISTORY = ("penetration_off_surfaces",)
OFF_SURFACE_SUMMARY = {"max_penetration_off_surfaces": 0.0,
                       "max_penetration_off_surfaces_at": None}
#: a Lagrange multiplier below this fraction of the run's largest so far is round-off for
#: the contact times (``ResultWriter._contact_summary``): the solve's relative accuracy is
#: ~1e-15, and a block at zero load kept t_N ~ 2e-30 against 1 under load
LAGRANGE_ROUNDOFF = 1e-12
HISTORY_DEFAULTS = {"augmentations_converged": 1,  # of the initial row and contact-free steps
                    "failed_newton_iterations": 0}  # the initial row (an integer column)


def tie_history(model: Model) -> tuple[str, ...]:
    """history.csv columns of the model's ties (see ``Simulation._tie_extra``)."""
    columns = ["tie_violation"]
    for tie in model.ties:
        columns += [f"tie_{tie.name}_force_x", f"tie_{tie.name}_force_y"]
    return tuple(columns)


def contact_setup(model: Model) -> dict[str, dict]:
    """Per interface, what its penetration warning's advice depends on (report.run_warnings):
    its ``[[contact]]`` index, method, law and detection, both surfaces' median edge lengths
    in the original mesh, whether each side's body is ALE, whether its persistency law
    has ``gap_restoring``, and whether its pair forces are ``moment_free``."""
    body = model.body_of_node()
    setup = {}
    for index, ci in enumerate(model.interfaces):
        sides = (ci.interface.surface1, ci.interface.surface2)
        spacings = [float(np.median(chain_edge_lengths(model.X0[s.nodes], s.closed)))
                    for s in sides]
        ale = [model.bodies[body[s.nodes[0]]].mesh_motion == "ale" for s in sides]
        setup[ci.name] = {"index": index, "method": ci.law.method,
                          "law": "persistency" if ci.persistency else "gap",
                          "detection": "predicted" if ci.predicted_detection else "penetration",
                          "spacing_1": spacings[0], "spacing_2": spacings[1],
                          "ale_1": ale[0], "ale_2": ale[1],
                          # the energy warning names it as the cause of a gain
                          "gap_restoring": bool(ci.law.gap_restoring and ci.persistency),
                          # and the report's forces (false) where pairs drift apart
                          "moment_free": bool(ci.law.moment_free)}
    return setup


def used_penalties(law: ContactLaw) -> dict[str, float | None]:
    """The ``normal`` and ``tangential`` penalties an interface's run used (from
    ``penalty_factor`` too), None for one it does not use: the normal one under Lagrange
    (exact multipliers) and the tangential one without friction."""
    return {"normal": None if law.method == "lagrange" else law.eps_N,
            "tangential": law.eps_T if law.frictional else None}


def outside_ledger(model: Model) -> list[str]:
    """The energies the balance (``energy_balance_*``) leaves out by design, which its warning
    names (report.run_warnings): the work of supports with prescribed motion, the ALE
    remaps' energy where a body does not conserve the total (history's ale_remap_energy), and
    the ALE convective term's work, which conserves no momentum either."""
    terms = []
    # a nonzero value held from t = 0 moves too: the run starts at d = 0
    if any(np.any(p.values != 0.0) and any(p.function.values) for p in model.prescribed):
        terms.append("the work of supports with prescribed motion")
    if any(setup.conserve_energy != "total" for setup in model.ale_bodies):
        terms.append("the ALE remaps' energy (ale.conserve_energy is not \"total\": "
                     "history.csv's ale_remap_energy)")
    convective = [f"'{model.bodies[setup.body_index].name}'" for setup in model.ale_bodies
                  if setup.motion.convection == "convective_term"]
    if convective:
        terms.append("the work of the ALE convective term (ale.convection = "
                     f"\"convective_term\" on {', '.join(convective)}: it keeps neither the "
                     "energy nor the linear and angular momentum, docs/theory.md; "
                     "convection = \"remap\", the default, keeps all three)")
    return terms


def _if_larger(summary: dict, key: str, value: float, at: Callable[[], dict]) -> dict:
    """``key`` = ``value`` and ``key_at`` = ``at()`` (when and where) if ``value`` is above
    the run's largest so far in ``summary`` (0 before any), else nothing. ``at`` is called
    only then: a check that found nothing gives depth 0 (its callers' ``found`` None too) and
    no interface to look up."""
    return {} if value <= (summary.get(key) or 0.0) else {key: value, f"{key}_at": at()}


#: the figures summary.json keeps of linear elastic bodies, max_linear_elastic_<key>(_at)
LINEAR_MEASURES = ("rotation", "stretch", "strain")

class ResultWriter:
    """Writes history.csv, summary.json and fields.pvd/VTU as the simulation advances (or,
    with ``directory`` None, keeps the same results in memory: :class:`MemoryResults`)."""

    def __init__(self, directory: str | Path | None, model: Model,
                 extra_history: tuple[str, ...] = (),
                 overwrite: bool = False, resume: dict | None = None,
                 lock: RunLock | None = None, **summary_extra: object) -> None:
        """``resume``: a restart from a checkpoint (``checkpoint_state``'s values, with the
        state it was taken at under "state"): the folder's files are cut back to it.
        ``lock``: the folder's lock if the caller holds it already (``ResultsDirectory``)."""
        extra_history = ("external_work",) + extra_history
        if len(model.bodies) > 1 and not model.interfaces:  # bodies no interface joins
            extra_history = extra_history + OFF_SURFACE_HISTORY
            summary_extra = OFF_SURFACE_SUMMARY | summary_extra
        if any(body.material.kind == "linear_elastic" for body in model.bodies):
            summary_extra = {f"max_linear_elastic_{key}{at}": None if at else 0.0
                             for key in LINEAR_MEASURES for at in ("", "_at")} | summary_extra
        if model.ale_bodies:  # the worst sliver of the mesh motion (AleQualityCheck)
            summary_extra = {"ale_mesh_degraded_at": None,
                             "ale_surface_spacing_at": None} | summary_extra
        if model.ale_bodies and model.interfaces:
            summary_extra = {"max_ale_mismatch": 0.0, "max_ale_mismatch_at": None} | summary_extra
        if model.interfaces:
            extra_history = extra_history + CONTACT_HISTORY
            summary_extra = {"contact_start_time": None, "contact_end_time": None,
                             "contact_at_end": False,
                             "max_penetration": 0.0, "max_penetration_at": None,
                             "max_active_pairs": 0, "unconverged_steps": 0,
                             "max_contact_moment_imbalance": 0.0,
                             "max_contact_moment_imbalance_at": None,
                             "max_penetration_unpaired": 0.0,
                             "max_penetration_unpaired_at": None,
                             "max_penetration_surface_2": 0.0,
                             "max_penetration_surface_2_at": None,
                             "max_separation_under_traction": 0.0,
                             "max_separation_under_traction_at": None,
                             **OFF_SURFACE_SUMMARY, "ale_unreturned_energy": 0.0,
                             "contact_penalties": {ci.name: used_penalties(ci.law)
                                                   for ci in model.interfaces},
                             # what `compare` picks the report's case by
                             "contact_friction": {ci.name: ci.law.mu
                                                  for ci in model.interfaces},
                             # what the penetration warning's advice depends on
                             "contact_setup": contact_setup(model)} | summary_extra
        if model.analysis.energy_conserving:  # steps whose energy equation had no root
            summary_extra = {"energy_equation_unmet_steps": 0} | summary_extra
        extra_history = extra_history + reaction_columns(model)
        if model.ties:
            extra_history = extra_history + tie_history(model)
            summary_extra = {"max_tie_violation": 0.0} | summary_extra
        summary_extra = {
            # the energy warning names the mid-point rule as the cause of a gain
            "integrator": None if model.analysis.kind == "static" else model.analysis.integrator,
            "outside_ledger": outside_ledger(model),
            "mass": model.analysis.mass,  # as `compare` needs it
            # Newton iterations of the accepted sub-steps, and of the attempts halvings discarded
            "newton_iterations": 0, "failed_newton_iterations": 0,
            "cut_back_steps": 0,  # steps solved in sub-steps
            **dict.fromkeys(EnergyAudit.KEYS),  # energy balance
            "max_self_penetration": 0.0, "max_self_penetration_at": None,  # a body through itself
        } | summary_extra
        self._energy = EnergyAudit()
        # last, so that the earlier columns keep their places
        extra_history = extra_history + ("failed_newton_iterations",)
        self.results: ResultsDirectory | MemoryResults
        if directory is None:  # ntncontact.run(out=None): nothing written
            self.results = MemoryResults(history_columns=extra_history, **summary_extra)
        else:
            self.results = ResultsDirectory(directory, history_columns=extra_history,
                                            overwrite=overwrite,
                                            resume=None if resume is None else resume["files"],
                                            field_format=model.analysis.field_format,
                                            lock=lock, **summary_extra)
        self.model = model
        self.extra_history = extra_history
        self.interval = model.analysis.output_interval
        self._next_output = 0.0
        self._body_id = model.body_of_cell().astype(float)
        # each node's number in its body's mesh file (-1: a generated mesh), so that a global
        # node of contact.csv can be found in the file the user meshed
        self._file_node_id = np.concatenate([
            np.full(b.mesh.n_nodes, -1) if b.mesh.file_node_ids is None else b.mesh.file_node_ids
            for b in model.bodies]).astype(np.int64)
        self._spacing = {ci.name: ci.spacing for ci in model.interfaces}
        self._persistency = [ci.name for ci in model.interfaces if ci.persistency]
        self._last: StepRecord | None = None
        self._before: StepRecord | None = None  # the step before _last (the mesh velocity)
        self._largest_multiplier = 0.0  # the largest Lagrange t_N so far (_contact_summary)
        self._framed_step: int | None = None  # the step of the last frame written
        if resume is not None:
            self._resume(resume)

    def checkpoint_state(self) -> dict:
        """This writer's running values after the last step (JSON types): the output cursor,
        the energy audit, and its files' (see ``ResultsDirectory.checkpoint_state``)."""
        step = self._last.state.step if self._last is not None else 0
        audit = self._energy
        return {"next_output": self._next_output,
                "energy_audit": [audit.initial, audit.scale, audit.max_error, audit.max_change],
                "files": self.results.checkpoint_state(step)}

    def _resume(self, saved: dict) -> None:
        self._next_output = float(saved["next_output"])
        audit = self._energy
        audit.initial, audit.scale, audit.max_error, audit.max_change = saved["energy_audit"]
        # the mesh-quality table at the end needs the last state (also with no step left)
        self._last = StepRecord(saved["state"], None, 0, 0.0)  # type: ignore[arg-type]
        self._framed_step = self._last.state.step  # a stand-in, no frame of its own to write

    def on_step(self, model: Model, record: StepRecord) -> None:
        self._previous_frame_written()
        s, b = record.state, record.balance
        row = {
            "step": s.step, "time": s.time,
            "kinetic_energy": b.kinetic_energy, "strain_energy": b.strain_energy,
            "total_energy": b.total_energy,
            "linear_momentum_x": b.linear_momentum[0], "linear_momentum_y": b.linear_momentum[1],
            "angular_momentum": b.angular_momentum,
            "newton_iterations": record.newton_iterations,
        }
        row |= {k: record.extra.get(k, HISTORY_DEFAULTS.get(k, 0.0)) for k in self.extra_history}
        summary = self.results.summary.data
        # the summary's new values: written once, with the history row
        fields = self._energy.add(row["total_energy"], row["external_work"],
                                  row.get("contact_work", 0.0))
        if "tie_violation" in record.extra:
            fields["max_tie_violation"] = max(record.extra["tie_violation"],
                                              summary.get("max_tie_violation", 0.0))
        # cumulative: the summary keeps the last
        fields |= {k: row[k] for k in ("contact_work", "frictional_dissipation") if k in row}
        fields |= self._rotation_summary(model, s, summary)
        if row.get("ale_unreturned_energy"):  # cumulative: the summary keeps the last
            fields["ale_unreturned_energy"] = row["ale_unreturned_energy"]
        fields |= {key: summary.get(key, 0) + int(row[key])  # running totals
                   for key in ("newton_iterations", "failed_newton_iterations")}
        if record.extra.get("cut_back"):
            fields["cut_back_steps"] = summary["cut_back_steps"] + 1
        if record.extra.get("energy_equation_unmet"):  # report 5.5: no theta conserves
            fields["energy_equation_unmet_steps"] = summary["energy_equation_unmet_steps"] + 1
        if row.get("augmentations_converged") == 0:  # augmentation.on_limit = "accept"
            fields["unconverged_steps"] = summary["unconverged_steps"] + 1
        fields |= self._off_surface_summary(
            s.time, record.extra.get("penetration_off_surfaces_at"), summary)
        fields |= self._mismatch_summary(s.time, row.get("ale_mismatch", 0.0),
                                         record.extra.get("ale_mismatch_at"), summary)
        fields |= self._moment_summary(s, record.extra.get("contact_moment"), summary)
        for key, found in (("max_penetration_unpaired", "penetration_unpaired_at"),
                           ("max_penetration_surface_2", "penetration_surface_2_at")):
            fields |= self._interface_depth_summary(key, s.time, record.extra.get(found),
                                                    summary)
        fields |= self._self_summary(s.time, record.extra.get("self_penetration_at"), summary)
        fields |= self._degraded_summary(s.time, record.extra.get("ale_degraded_cell"), summary)
        fields |= self._spacing_summary(s.time, record.extra.get("ale_spaced_segments"),
                                        summary)
        framed = self._due(s.time, model)  # before the rows: "frames" keeps those steps'
        rows = record.extra.get("contact_rows")
        if model.interfaces:  # set again below by a step that carries contact
            fields["contact_at_end"] = False
        if rows is not None and len(rows["node_1"]):
            if self._keeps_contact_rows(framed):
                self.results.contact.write_step(s.step, s.time, rows)
            fields |= self._contact_summary(s.time, record.dt, rows, summary)
            # max_penetration and where it is, when this step's deepest pair is the deepest
            # so far; measured at the step's end, as the frame shows it (the law's gap is at
            # t_{n+1/2} in a dynamic step: the gap law's rod impact 2e-12 there, 0.058 at the
            # step ends)
            fields |= self._largest_pair("max_penetration", "depth", rows["end_gap"], s.time,
                                         rows, summary)
            fields |= self._widest_pressed_opening(s.time, rows, summary)
        self.results.write_history(row, **fields)
        self._before, self._last = self._last, record
        if framed:
            self._write_fields(model, record, self._before)

    def _previous_frame_written(self) -> None:
        """Wait for the frame in flight (a VTU written in the background) before this step's
        rows: if its writing failed, the run stops at the frame's own step, the last one
        history.csv has a row of, and the final frame is tried again. The frame still
        overlaps this step's solve."""
        if not isinstance(self.results.fields, VtuSeriesWriter):
            return
        try:
            self.results.fields.flush()
        except BaseException:
            self._framed_step = None  # on_finish tries this step's frame again
            raise

    def _keeps_contact_rows(self, framed: bool) -> bool:
        """Whether contact.csv gets this step's pairs (``analysis.contact_output``): ~168 bytes a
        pair a step made 3.4 GB for a 2,000-pair interface over 10^4 steps, so a long run can keep
        the frames' steps only, or none. Only the writing is skipped: the summary's contact figures
        still come from every step's pairs."""
        wanted = self.model.analysis.contact_output
        return wanted == "steps" or (wanted == "frames" and framed)

    def _contact_summary(self, time: float, dt: float, rows: dict, summary: dict) -> dict:
        """The contact summary after a step with contact rows. Contact lasts from the start of
        the first step that carried a normal traction above round-off to the end of the last
        such step. Round-off: the traction eps_N g_r that a gap g_r within the kernel's touch
        tolerance (TOUCH_ROUNDOFF times the pair's largest coordinate) gives, and under the
        persistency law the rate 2 g_r / dt of such a gap; the multipliers gather such
        increments (at exactly zero load t_N <= 3.3e-11 remained). Lagrange multipliers (no
        eps_N): above LAGRANGE_ROUNDOFF times the largest of the run so far."""
        fields = {"max_active_pairs": max(len(rows["node_1"]), summary["max_active_pairs"])}
        laws = {ci.name: ci for ci in self.model.interfaces}
        lagrange = np.array([laws[name].law.method == "lagrange" for name in rows["interface"]])
        eps = np.array([laws[name].law.eps_N * (2.0 / dt if laws[name].persistency else 1.0)
                        if laws[name].law.method != "lagrange" else 0.0
                        for name in rows["interface"]])
        roundoff = eps * TOUCH_ROUNDOFF * np.maximum(np.abs(rows["x"]), np.abs(rows["y"]))
        if lagrange.any():
            self._largest_multiplier = max(self._largest_multiplier,
                                           float(rows["normal_traction"][lagrange].max()))
            roundoff[lagrange] = LAGRANGE_ROUNDOFF * self._largest_multiplier
        if np.any(rows["normal_traction"] > roundoff):
            if summary.get("contact_start_time") is None:
                fields["contact_start_time"] = time - dt
            fields["contact_end_time"] = time
            # the last step's contact: its end time is then the run's, not the contact's
            fields["contact_at_end"] = True
        return fields

    def _largest_pair(self, key: str, name: str, values: np.ndarray, time: float, rows: dict,
                      summary: dict) -> dict:
        """``key`` and ``key_at`` (:func:`_if_larger`) by the pair of this step's largest
        ``values`` (one a contact row, shown as ``name``): the time, the interface, its
        surface-1 node and the interface's surface spacing."""
        k = int(np.argmax(values))
        interface = str(rows["interface"][k])
        return _if_larger(summary, key, float(values[k]), lambda: {
            "time": time, "interface": interface, "node": int(rows["node_1"][k]),
            "file_node": self._file_node(rows["node_1"][k]), name: float(values[k]),
            "element_size": self._spacing[interface]})

    @staticmethod
    def _rotation_summary(model: Model, s, summary: dict) -> dict:
        """``max_linear_elastic_rotation``, ``_stretch`` and ``_strain`` and when and where:
        the largest of a linear elastic body so far
        (``engine.diagnostics.linear_elastic_measures``)."""
        if "max_linear_elastic_rotation" not in summary:
            return {}
        fields: dict = {}
        for key, (value, body) in linear_elastic_measures(model, s.X, s.d).items():
            if value > (summary.get(f"max_linear_elastic_{key}") or 0.0):
                fields |= {f"max_linear_elastic_{key}": value,
                           f"max_linear_elastic_{key}_at": {"time": s.time, "body": body}}
        return fields

    def _file_node(self, node: int) -> int:
        """A global node's number in its body's mesh file (-1: a generated mesh)."""
        return int(self._file_node_id[int(node)])

    def _widest_pressed_opening(self, time: float, rows: dict, summary: dict) -> dict:
        """``max_separation_under_traction`` and where: the widest open gap (``end_gap`` < 0)
        of a pair that carries a positive normal traction. The persistency law holds a pair's
        gap where it is, so a pair that opened in a step without traction and pressed again
        (the release test waits ``release_steps``) pushes across that opening; up to v dt,
        the mirror of the detection lag's penetration."""
        # the gap law holds its mid-step gap at zero, its step-end gap swings (rod: 0.058)
        pressed = (rows["normal_traction"] > 0.0) & np.isin(rows["interface"], self._persistency)
        opening = np.where(pressed, -np.asarray(rows["end_gap"]), 0.0)
        return self._largest_pair("max_separation_under_traction", "opening", opening, time,
                                  rows, summary)

    def _mismatch_summary(self, time: float, mismatch: float, where: dict | None,
                          summary: dict) -> dict:
        """``max_ale_mismatch`` and when, with the smallest surface spacing of the interfaces
        (``ntncontact run`` compares the two) and where (``where``: the interface, the ALE
        node and its partner, ``engine.mesh_motion.end_of_step_mismatch``; the file numbers
        added): an ALE node that ends far from its partner's place is a pair the mesh motion
        did not follow (~1e-9 of the spacing where it follows)."""
        if "max_ale_mismatch" not in summary or mismatch <= summary["max_ale_mismatch"]:
            return {}
        at = {"time": time, "element_size": min(self._spacing.values())}
        if where is not None:
            at |= where | {"file_node": self._file_node(where["node"]),
                           "partner_file_node": self._file_node(where["partner"])}
        return {"max_ale_mismatch": float(mismatch), "max_ale_mismatch_at": at}

    @staticmethod
    def _moment_summary(s, found, summary: dict) -> dict:
        """``max_contact_moment_imbalance`` and where: the largest net moment of an
        interface's contact forces so far, relative to their sum |f| times the contact
        zone's extent (``engine.diagnostics.contact_moment``), with the step, the time, the
        interface and the moment itself (about the origin: in a static step the reactions'
        moment plus the loads')."""
        if found is None or not found.interface:
            return {}
        if (summary.get("max_contact_moment_imbalance_at") is not None
                and found.relative <= summary["max_contact_moment_imbalance"]):
            return {}  # the first measured step is kept even if its moment is exactly 0
        return {"max_contact_moment_imbalance": found.relative,
                "max_contact_moment_imbalance_at": {
                    "step": s.step, "time": s.time, "interface": found.interface,
                    "moment": found.moment, "force": found.force, "length": found.length}}

    def _interface_depth_summary(self, key: str, time: float, found, summary: dict) -> dict:
        """``key`` and ``key_at``: the deepest node so far that an interface's check found
        inside a body, and where, with the interface's surface spacing: the surface-1 nodes
        in no pair (``max_penetration_unpaired``, ``engine.diagnostics.UnpairedCheck``) and
        the surface-2 nodes inside surface 1's body (``max_penetration_surface_2``,
        ``SurfaceTwoCheck``)."""
        return _if_larger(summary, key, 0.0 if found is None else found.depth, lambda: {
            "time": time, "interface": found.interface, "node": found.node,
            "depth": found.depth, "file_node": self._file_node(found.node),
            "element_size": self._spacing[found.interface]})

    def _self_summary(self, time: float, found, summary: dict) -> dict:
        """The deepest boundary node inside its own body so far, and where
        (``engine.diagnostics.SelfCrossingCheck``); ``first_time``: the end of the first step
        that found one, from which on the results are not physical."""
        before = summary.get("max_self_penetration_at") or {}
        depth = 0.0 if found is None else found.depth
        return _if_larger(summary, "max_self_penetration", depth, lambda: {
            "time": time, "body": found.body, "node": found.node,
            "file_node": self._file_node(found.node), "depth": found.depth,
            "element_size": found.size, "first_time": before.get("first_time", time)})

    @staticmethod
    def _degraded_summary(time: float, found, summary: dict) -> dict:
        """``ale_mesh_degraded_at``: the ALE bodies' worst cell so far below its quality limit
        (``engine.diagnostics.AleQualityCheck``), where and when; ``first_time``: the end of
        the first step that found one, kept as the cell worsens."""
        before = summary.get("ale_mesh_degraded_at")
        if found is None or (before and found.sine >= before["min_sine"]):
            return {}
        return {"ale_mesh_degraded_at": {
            "time": time, "body": found.body, "cell": found.cell,
            "centroid": list(found.centroid), "angle": found.angle,
            "initial_angle": found.initial_angle, "min_sine": found.sine,
            "smoothing": found.smoothing, "smoothing_layers": found.smoothing_layers,
            "first_time": (before or {}).get("first_time", time)}}

    @staticmethod
    def _spacing_summary(time: float, found, summary: dict) -> dict:
        """``ale_surface_spacing_at``: the ALE contact-surface segments squeezed the most
        below (``shortest``), and stretched the most above (``longest``), the respacing's band
        of their original length so far (``engine.diagnostics.AleSpacingCheck``), each with
        ``first_time``, the end of the first step that found one on that side."""
        if found is None or found == (None, None):
            return {}
        before = {"shortest": None, "longest": None} | (summary.get("ale_surface_spacing_at")
                                                        or {})
        out = dict(before)
        for key, seg, sign in (("shortest", found[0], 1.0), ("longest", found[1], -1.0)):
            old = before[key]
            if seg is None or (old and sign * seg.ratio >= sign * old["ratio"]):
                continue
            out[key] = {"time": time, "body": seg.body, "nodes": list(seg.nodes),
                        "midpoint": list(seg.midpoint), "length": seg.length,
                        "reference_length": seg.reference_length, "ratio": seg.ratio,
                        "band": list(seg.band),
                        "first_time": (old or {}).get("first_time", time)}
        return {"ale_surface_spacing_at": out} if out != before else {}

    @staticmethod
    def _off_surface_summary(time: float, found, summary: dict) -> dict:
        """The deepest boundary node inside another body off the contact surfaces so far, and
        where (``engine.diagnostics.PenetrationCheck``)."""
        return _if_larger(summary, "max_penetration_off_surfaces",
                          0.0 if found is None else found.depth, lambda: {
            "time": time, "body": found.body, "node": found.node, "inside": found.other,
            "element_size": found.size, "joined": found.joined})

    def _due(self, time: float, model: Model) -> bool:
        last = time >= model.analysis.t_end - 1e-9 * model.analysis.dt
        if self.interval is None or last or time >= self._next_output - 1e-9 * model.analysis.dt:
            if self.interval is not None:  # the next multiple of the interval: a schedule
                # from the last frame's time drifted to the dt grid
                self._next_output = (math.floor(time / self.interval + 1e-6) + 1) * self.interval
            return True
        return False

    def _write_fields(self, model: Model, record: StepRecord,
                      before: StepRecord | None = None) -> None:
        """One frame: kinematics, stress and strain (cells and nodes), contact-node fields and
        the mesh velocity (``before``: the previous step's record, for the ALE remap rate)."""
        s = record.state
        moving = before is not None and record.dt > 0.0
        F_bodies = [a.body_index for a in model.ale_bodies] if moving else []
        cell, nodal, F = frame_fields(model, s.X, s.d, F_bodies)
        # Lagrangian meshes (F None) move with the material: the mesh velocity is v
        point = {"displacement": s.d, "velocity": s.v, "acceleration": s.a,
                 "mesh_velocity": mesh_velocity(s.v, s.X, before.state.X if moving else s.X,
                                                record.dt, F),
                 "material_position": s.X, "file_node_id": self._file_node_id}
        point |= nodal | contact_node_fields(record.extra.get("contact_rows"), len(s.X),
                                             record.extra.get("contact_shares"))
        self.results.fields.write(s.step, s.time, s.X, model.cells, point_data=point,
                                  cell_data=cell | {"body_id": self._body_id})
        self._framed_step = s.step

    def on_finish(self, status: str, error: str | None) -> None:
        """Close the files, write the final summary and release the folder (once: later calls,
        such as the CLI's for an interruption before the time loop, do nothing)."""
        if self.results.closed:
            return
        if status != "completed":
            self._write_last_frame()
        try:
            quality = self._mesh_quality()
        except Exception:
            self.results.close(status, error)
            raise
        self.results.close(status, error, mesh_quality=quality)

    def _write_last_frame(self) -> None:
        """A frame of the last completed step when the output interval left it without one:
        an interrupted or failed run keeps the fields where it stopped. One frame, and best
        effort: a second signal (KeyboardInterrupt) or an error of its own (the full disk
        that failed the run) gives it up, and the files are closed anyway. Off the output
        schedule, so it adds no contact.csv rows under contact_output = "frames", and a
        restart drops it: the restarted run's files are the uninterrupted run's."""
        last = self._last
        if last is None or last.state.step == self._framed_step:
            return
        try:
            self._write_fields(self.model, last, self._before)
            if hasattr(self.results.fields, "flush"):
                self.results.fields.flush()  # its error here, not in place of the run's
        except BaseException:  # noqa: BLE001 - the summary must still be written
            return

    def _mesh_quality(self) -> dict:
        """Table 4.1 statistics of each body's current mesh (node positions x) at the end."""
        if self._last is None:
            return {}
        x = self._last.state.x
        return {b.name: quality_statistics(x[b.nodes], b.mesh.cells) for b in self.model.bodies}

