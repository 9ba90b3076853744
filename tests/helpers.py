"""Small builders shared by the tests."""

from __future__ import annotations

import subprocess
import time
from pathlib import Path

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from ntncontact.contact import pair_gaps
from ntncontact.engine import interfaces
from ntncontact.engine.builder import build_model
from ntncontact.engine.model import Model
from ntncontact.engine.simulation import Simulation
from ntncontact.fem.assembly import Assembler, MaterialGroup
from ntncontact.io.scenario import load_config, parse_scenario
from ntncontact.io.writers import read_csv_table
from ntncontact.mesh.generators import rectangle

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"


def lagrange_matrices(blocks, ndof: int) -> tuple[sp.csr_matrix, sp.csr_matrix]:
    """(G, B) of ``contact.lagrange.LagrangeBlocks`` as CSR matrices of shapes (P, ndof) and
    (ndof, P)."""
    p = blocks.values.size
    return (sp.csr_matrix((blocks.g_vals, (blocks.g_rows, blocks.g_cols)), shape=(p, ndof)),
            sp.csr_matrix((blocks.b_vals, (blocks.b_rows, blocks.b_cols)), shape=(ndof, p)))

#: A block sliding at 2 off the right end of a base under gravity (frictionless); the base's
#: ``motion`` (lagrangian or ale) and ``t_end`` to fill in (tests/test_sliding_pairs.py,
#: tests/test_ale_mismatch_warning.py)
LEDGE = """
[analysis]
kind = "dynamic"
dt = 0.005
t_end = {t_end}
output_interval = 0.05

[[bodies]]
name = "block"
mesh = {{ type = "rectangle", width = 0.5, height = 0.25, nx = 4, ny = 2, origin = [-0.5, 0.0] }}
material = {{ model = "neo_hookean", E = 1000.0, nu = 0.3, density = 1.0 }}
initial = {{ velocity = [2.0, 0.0] }}
loads = [ {{ type = "gravity", vector = [0.0, -10.0] }} ]

[[bodies]]
name = "base"
mesh_motion = "{motion}"
mesh = {{ type = "rectangle", width = 1.0, height = 0.25, nx = 8, ny = 2, origin = [-1.0, -0.25] }}
material = {{ model = "neo_hookean", E = 10000.0, nu = 0.3, density = 5.0 }}
supports = [ {{ set = "bottom", x = 0.0, y = 0.0 }} ]

[[contact]]
body_1 = "block"
surface_1 = "bottom"
body_2 = "base"
surface_2 = "top"
method = "augmented_lagrangian"
penalty_normal = 2000.0
"""


def run_example(name: str, out: Path, capsys, *sets: str) -> tuple[dict, str]:
    """``ntncontact run`` of examples/``name`` into ``out`` with ``--set`` overrides ``sets``:
    (summary.json, what it wrote on stderr)."""
    import json

    from ntncontact.cli import main

    args = ["run", str(EXAMPLES / name), "--out", str(out), "--quiet"]
    for item in sets:
        args += ["--set", item]
    assert main(args) == 0
    return json.loads((out / "summary.json").read_text()), capsys.readouterr().err


def model_from_dict(data: dict, base: Path = Path(".")) -> Model:
    return build_model(parse_scenario(data, Path("test.toml")), base)


def model_from_example(name: str, overrides: list[str] | None = None) -> Model:
    path = EXAMPLES / name
    return build_model(load_config(path, overrides), path.parent)


class Recorder:
    """Observer keeping every step record in memory."""

    def __init__(self) -> None:
        self.records = []
        self.status = None

    def on_step(self, model, record) -> None:
        self.records.append(record)

    def on_finish(self, status, error) -> None:
        self.status = (status, error)


def recorded_ring_impact(*overrides: str) -> Recorder:
    """The ring impact example's first 0.2 s (27 contact steps), every step recorded."""
    from ntncontact.engine.simulation import Simulation

    recorder = Recorder()
    model = model_from_example("ring_impact.toml", ["analysis.t_end=0.2", *overrides])
    Simulation(model, [recorder]).run()
    return recorder


def history_steps(out: Path) -> list[int]:
    """Steps of the complete rows of a run folder's history.csv (a row being written is not
    counted); empty before the file or its header exists."""
    try:
        return [int(s) for s in read_csv_table(out / "history.csv")["step"]]
    except (FileNotFoundError, ValueError):  # not created yet, or its header not written yet
        return []


def wait_until(condition, child: subprocess.Popen, what: str, timeout: float,
               poll: float = 0.005) -> None:
    """Poll ``condition`` while the child run goes on; fail (killing it on a time-out) if the
    run ends or ``timeout`` seconds pass first."""
    end = time.monotonic() + timeout
    while not condition():
        if child.poll() is not None:
            raise AssertionError(f"the run ended (rc {child.returncode}) before {what}: "
                                 f"{child.stderr.read()}")
        if time.monotonic() > end:
            child.kill()
            raise AssertionError(f"timed out waiting for {what}")
        time.sleep(poll)


def offsets_across_normal(model, record) -> np.ndarray:
    """|offset of the two nodes of every active pair across its line of action|: the pair's
    contact normal where it is closed (g >= 0), the ALE surface's normal where it is open."""
    rows = record.extra["contact_rows"]
    pairs = np.column_stack([rows["node_1"], rows["node_2"]]).astype(np.int64)
    x = record.state.x
    surfaces = model.interfaces[0].interface
    normal, gap, _ = pair_gaps(x, surfaces, pairs)
    k = surfaces.surface2.index_of(pairs[:, 1])
    chord = x[surfaces.surface2.next[k]] - x[surfaces.surface2.prev[k]]
    own = np.column_stack([chord[:, 1], -chord[:, 0]]) / np.linalg.norm(chord, axis=1)[:, None]
    normal[gap < 0.0] = own[gap < 0.0]
    offset = x[pairs[:, 0]] - x[pairs[:, 1]]
    across = offset - np.einsum("ij,ij->i", offset, normal)[:, None] * normal
    return np.linalg.norm(across, axis=1)


def energy_after_each_episode(recorder) -> tuple[np.ndarray, np.ndarray]:
    """(E/E0 - 1 per record, the records that end a contact episode: a step with pairs, then
    one without)."""
    energy = np.array([r.balance.total_energy for r in recorder.records])
    active = np.array([sum(len(c.pairs) for c in r.state.contact) for r in recorder.records])
    ends = np.flatnonzero((active[1:] == 0) & (active[:-1] > 0)) + 1
    return energy / energy[0] - 1.0, ends


class SubStepCounting(Simulation):
    """Records every sub-step attempt: (t_n, dt, completed)."""

    def __init__(self, model) -> None:
        super().__init__(model)
        self.attempts: list[tuple[float, float, bool]] = []

    def advance(self, state, dt):
        try:
            out = super().advance(state, dt)
        except Exception:
            self.attempts.append((state.time, dt, False))
            raise
        self.attempts.append((state.time, dt, True))
        return out


def refined(factor: int, t_end: float) -> list[str]:
    return [f"bodies.0.mesh.nx={8 * factor}", f"bodies.0.mesh.ny={21 * factor}",
            f"bodies.1.mesh.nx={36 * factor}", f"bodies.1.mesh.ny={5 * factor}",
            f"analysis.t_end={t_end}"]


def fast_sliding(k: int, friction: float, *overrides: str):
    """The fast-sliding blocks refined k times (dt unchanged), friction ``friction``, one frame
    at t_end = 0.2, and ``overrides`` (an api Scenario)."""
    from ntncontact import api

    return api.load_scenario(EXAMPLES / "blocks_fast_sliding.toml",
                             [*refined(k, 0.2)[:4], f"contact.0.friction={friction}",
                              "analysis.output_interval=0.2", *overrides])


def headline(k: int, friction: float, *overrides: str) -> dict:
    """The headline numbers of the fast-sliding blocks refined k times (``headline_of``)."""
    from ntncontact import api

    return headline_of(api.run(fast_sliding(k, friction, *overrides)))


def headline_of(results) -> dict:
    """Contact start and end (summary.json's), the dissipated fraction of the initial energy,
    and the upper block's exit velocity (its centre-of-mass velocity at t_end, free since
    ~0.13-0.16: the consistent mass's row sums weigh the nodes exactly, rho uniform) of a
    fast-sliding run's results."""
    from ntncontact.fem.q4 import element_mass

    frame = results.fields(0.2)
    cells = frame.cells_dict["quad"][frame.cell_data["body_id"][0] == 0]
    X = frame.point_data["material_position"][:, :2]
    weight = np.bincount(cells.ravel(), element_mass(X[cells], np.ones(len(cells)))
                         .sum(axis=2).ravel(), len(X))
    history = results.history
    return {"start": results.summary["contact_start_time"],
            "end": results.summary["contact_end_time"],
            "dissipated": history["frictional_dissipation"].iloc[-1]
            / history["total_energy"].iloc[0],
            "exit": weight @ frame.point_data["velocity"][:, :2] / weight.sum(),
            "penetration": results.summary["max_penetration"],  # at the step ends
            "law_penetration": float(results.contact["gap"].max()),  # mid-step (dynamic)
            "off_surfaces": results.summary["max_penetration_off_surfaces"],
            "ledger": results.summary["energy_balance_max_relative_error"],
            "status": results.summary["status"]}


def neo_hookean_assembler(mesh, seed: int) -> tuple[Assembler, np.ndarray, np.ndarray]:
    """One neo-Hookean group over ``mesh`` (mu 3, lambda 2, unit thickness), its reference
    nodes and a random displacement of 1e-2 (``seed``)."""
    ne = len(mesh.cells)
    asm = Assembler(mesh.cells, len(mesh.nodes), [MaterialGroup("neo_hookean", np.arange(ne))],
                    np.full(ne, 3.0), np.full(ne, 2.0), np.ones(ne))
    X = np.asarray(mesh.nodes, dtype=float)
    return asm, X, 1e-2 * np.random.default_rng(seed).normal(size=X.shape)


def reflex_cell_block():
    """A 2 x 1 block of 8 x 4 cells whose top node at x = 1 is pushed 0.15 down and left,
    leaving a reflex cell (sine -0.38): (mesh, X, d, node, x = X + d)."""
    mesh = rectangle(2.0, 1.0, 8, 4)
    X = mesh.nodes.copy()
    node = int(np.flatnonzero(np.isclose(X[:, 0], 1.0) & np.isclose(X[:, 1], 1.0))[0])
    d = np.zeros_like(X)
    d[node] = [-0.15, -0.15]
    return mesh, X, d, node, X + d


def same_pressed_pairs(records_a, records_b):
    """Per step after the first of two runs' step records: (rows_a, rows_b, the pressed
    pairs' first nodes), asserting that both runs pressed the same pairs (t_N > 0)."""
    for a, b in zip(records_a[1:], records_b[1:], strict=True):
        rows_a, rows_b = a.extra["contact_rows"], b.extra["contact_rows"]
        pressed_a = rows_a["node_1"][rows_a["normal_traction"] > 0.0]
        pressed_b = rows_b["node_1"][rows_b["normal_traction"] > 0.0]
        np.testing.assert_array_equal(np.sort(pressed_a), np.sort(pressed_b))
        yield rows_a, rows_b, pressed_a


def same_converged_contact(sim_a, records_a, sim_b, records_b, atol: float) -> None:
    """Two runs of one quasi-static contact problem by different iteration paths end each
    step the same: displacements within ``atol`` of the largest, the same pressed pairs, and
    their tractions within what the augmentation test fixes them to, eps_N x the gap
    tolerance (it stops where the gaps change by less than that)."""
    scale = np.abs(sim_b.state.d).max()
    np.testing.assert_allclose(sim_a.state.d, sim_b.state.d, rtol=0, atol=atol * scale)
    ci = sim_a.model.interfaces[0]
    bound = ci.law.eps_N * ci.tolerances.normal
    for rows_a, rows_b, pressed_a in same_pressed_pairs(records_a, records_b):
        traction_a = dict(zip(rows_a["node_1"], rows_a["normal_traction"], strict=True))
        traction_b = dict(zip(rows_b["node_1"], rows_b["normal_traction"], strict=True))
        for node in pressed_a:
            assert abs(traction_a[node] - traction_b[node]) <= bound


def released_nodes_wait(monkeypatch) -> None:
    """Detection as it was before session 48: the nodes of the pairs it releases are not
    candidates in that same detection (a quasi-static pair that ended a step open waited for
    the step's first pass to end, though x + dt v put it inside; test_hertz_passes.py)."""
    monkeypatch.setattr(interfaces, "_staying", lambda ci, state, released: state)



def check_step_without(problem, y: np.ndarray, step: np.ndarray, term, mask: np.ndarray) -> None:
    """``step`` (an active-set step at y that let go the pairs ``mask`` of ``term``) is the
    Newton step with the residual and Jacobian evaluated without those pairs, solved afresh,
    to 1e-8 of its largest entry, and it opens no pair beyond them."""
    full_state = term.state
    term.state = full_state.take(~mask)
    problem._cache = {}
    R_without, _ = problem.residual(y)
    expected = -spla.spsolve(problem.jacobian(y).tocsc(), R_without)
    term.state = full_state
    assert np.abs(step - expected).max() <= 1e-8 * np.abs(expected).max()
    x_trial = problem.state.X + problem.full(y + step).reshape(-1, 2)
    x_eval = problem.state.X + problem.full(y).reshape(-1, 2)
    assert not np.any(term.opened(x_eval, x_trial, problem.state.x) & ~mask)
