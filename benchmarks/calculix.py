"""CalculiX comparison (issue 18): the same problems written as CalculiX decks and run by both
codes as processes, interleaved (ccx, ntncontact, ccx, ntncontact, ...).

Usage::

    .venv/bin/python benchmarks/calculix.py                     # Hertz k = 1, 2, 4 and two bars
    .venv/bin/python benchmarks/calculix.py --cases hertz --k 1 --repeats 1
    .venv/bin/python benchmarks/calculix.py --deck hertz 1 hertz.inp   # only write a deck

Without ``ccx`` on the PATH (Debian: ``apt-get install calculix-ccx``) it prints one line and
exits 0: the project does not depend on CalculiX.

The deck generator reads a scenario with ntncontact's own loader (``load_config``) and takes
every body's mesh from ntncontact's mesh generators (``build_mesh``), then extrudes it one
element thick (``THICKNESS``) into C3D8 elements with the out-of-plane displacement of every
node fixed (plane strain; full 2x2x2 integration like ntncontact's 2x2 Q4). Per unit thickness
the loads and results are those of the 2D problem. Translated: linear elastic materials,
supports (fixed or prescribed, with their time functions as amplitudes), pressure loads on
edge sets, contact interfaces as surface-to-surface penalty pairs (*CONTACT PAIR, TYPE=SURFACE
TO SURFACE, linear pressure-overclosure with slope K = the interface's penalty_normal, which
ntncontact's gap law also takes as a stiffness per area), and a static analysis with
ntncontact's fixed load steps (*STATIC, DIRECT: the same increments). Anything else is refused
with a one-line error.

Problems:

- ``hertz``: examples/hertz.toml (report 6.2) with the cylinder and foundation refined k times
  in each direction (``scaling.hertz_mesh``): 950, 3,800, 15,200 elements for k = 1, 2, 4.
  18 load steps (15 ramp + 3 holds). Analytic: p0 = 3239, a = 47.2, P = 240,000.
- ``bars``: two bars 10 x 1 (E = 100, nu = 0.3), 40k x k elements each (80, 1,280, 5,120 for
  k = 1, 4, 8), a gap of 0.05 between them; the left bar's left end is held, the right bar's
  right end is pushed by 0.25 in 10 steps. Analytic end force once closed: plane strain, free
  lateral faces: E / (1 - nu^2) * (u - gap) / (2 L) per unit height.

Figures compared (the same problem in both codes): the end force (reaction of the held
support), the strain energy and the largest contact pressure at the end of the run.
Times: process wall time and CPU time (``resource.getrusage`` of the child), ccx with
OMP_NUM_THREADS=2, ntncontact's CLI (``python -m ntncontact.cli run``) with its defaults and
the package's Numba cache (``NUMBA_CACHE_DIR`` or the package's default, where ``make``'s
warm-up compiled); one untimed ntncontact run first, so that no timed run compiles.
"""

from __future__ import annotations

import argparse
import csv
import json
import math
import os
import re
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
os.environ.setdefault("MPLBACKEND", "Agg")
sys.path.insert(0, str(Path(__file__).resolve().parent))

import numpy as np  # noqa: E402

from ntncontact.engine.builder import build_mesh  # noqa: E402
from ntncontact.engine.config import ScenarioConfig  # noqa: E402
from ntncontact.io.scenario import load_config  # noqa: E402
from ntncontact.mesh.quadmesh import QuadMesh  # noqa: E402

EXAMPLES = ROOT / "examples"
#: extrusion depth of the one-element layer; results are per unit thickness (divided by it)
THICKNESS = 1.0
#: C3D8 faces (S3..S6) of the quad edges n0-n1, n1-n2, n2-n3, n3-n0
FACE_OF_EDGE = (3, 4, 5, 6)
HERTZ_K = (1, 2, 4)
BARS_K = (1, 4, 8)
BAR_LENGTH, BAR_GAP, BAR_PUSH, BAR_E, BAR_NU = 10.0, 0.05, 0.25, 100.0, 0.3


class DeckError(ValueError):
    """A scenario feature this translator does not write."""


# ---------------------------------------------------------------------------------------------
# problems


def bars_scenario(k: int) -> dict:
    """Two bars pressed end to end, quasi-static (a scenario mapping, ntncontact's keys)."""
    material = {"model": "linear_elastic", "E": BAR_E, "nu": BAR_NU, "density": 1.0}
    ramp = {"times": [0.0, 1.0], "values": [0.0, 1.0]}
    return {
        "title": f"Two bars pressed end to end, k = {k} (CalculiX comparison)",
        "analysis": {"kind": "static", "dt": 0.1, "t_end": 1.0, "max_cutbacks": 6},
        "bodies": [
            {"name": "bar_left", "material": material,
             "mesh": {"type": "rectangle", "width": BAR_LENGTH, "height": 1.0, "nx": 40 * k,
                      "ny": k, "origin": [-BAR_LENGTH - BAR_GAP, 0.0]},
             "supports": [{"set": "left", "x": 0.0},
                          {"set": "corner_bottom_left", "y": 0.0}]},
            {"name": "bar_right", "material": material,
             "mesh": {"type": "rectangle", "width": BAR_LENGTH, "height": 1.0, "nx": 40 * k,
                      "ny": k, "origin": [0.0, 0.0]},
             "supports": [{"set": "right", "x": -BAR_PUSH, "function": ramp},
                          {"set": "corner_bottom_right", "y": 0.0}]},
        ],
        "contact": [{"name": "bar_ends", "body_1": "bar_left", "surface_1": "right",
                     "body_2": "bar_right", "surface_2": "left",
                     "method": "augmented_lagrangian", "law": "gap",
                     "penalty_normal": 1.0e4,
                     "augmentation": {"max_iterations": 30, "gap_tolerance": 1e-7}}],
    }


def bars_force() -> float:
    """Analytic end force per unit thickness (plane strain, free lateral faces)."""
    return BAR_E / (1.0 - BAR_NU**2) * (BAR_PUSH - BAR_GAP) / (2.0 * BAR_LENGTH)


def bars_pressure() -> float:
    """The end force over the current end face, widened by Poisson's effect (plane strain:
    eps_y = nu (1 + nu) / E * |sigma_x|); both codes report pressure on the current face."""
    force = bars_force()
    return force / (1.0 + BAR_NU * (1.0 + BAR_NU) * force / BAR_E)


def toml_text(value, top: bool = True) -> str:
    """A scenario mapping as TOML: top-level keys, every nested value inline."""
    if top:
        return "".join(f"{key} = {toml_text(v, False)}\n" for key, v in value.items())
    if isinstance(value, dict):
        return "{ " + ", ".join(f"{k} = {toml_text(v, False)}" for k, v in value.items()) + " }"
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(toml_text(v, False) for v in value) + "]"
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, str):
        return json.dumps(value)
    return repr(value)


#: CalculiX only: rigid shifts (body index -> (dx, dy)) of bodies held by contact alone in a
#: direction. Hertz's cylinder is free in y; started 1e-3 inside the foundation (7e-4 of its
#: smallest contact element, k = 4) its contact is active from ccx's first iteration. Without
#: it ccx's first increment starts on a singular matrix: 27 iterations at k = 1 and no
#: convergence after 461 at k = 2 (its fixed increments cannot cut back). A rigid shift of a
#: body that is free in that direction changes neither stresses nor contact pressures at
#: equilibrium.
CCX_SHIFT = {"hertz": {0: (0.0, -1e-3)}, "bars": {}}


def problem(case: str, k: int, folder: Path) -> tuple[Path, list[str]]:
    """The scenario file and ``--set`` overrides of one problem (written into ``folder``)."""
    folder.mkdir(parents=True, exist_ok=True)
    if case == "bars":
        path = folder / f"bars_k{k}.toml"
        path.write_text(toml_text(bars_scenario(k)))
        return path, []
    if case == "hertz":
        import scaling

        mesh = scaling.hertz_mesh(k, folder)
        return EXAMPLES / "hertz.toml", [f"bodies.0.mesh.file={mesh}",
                                        f"bodies.1.mesh.nx={50 * k}", f"bodies.1.mesh.ny={3 * k}"]
    raise DeckError(f"unknown problem '{case}' (hertz, bars)")


# ---------------------------------------------------------------------------------------------
# deck


def set_nodes(mesh: QuadMesh, name: str) -> np.ndarray:
    if name in mesh.node_sets:
        return np.asarray(mesh.node_sets[name])
    if name in mesh.edge_sets:
        return np.unique(mesh.edge_sets[name])
    raise DeckError(f"body '{mesh.name}': no node or edge set '{name}'")


def edge_faces(mesh: QuadMesh, name: str) -> list[tuple[int, int]]:
    """(cell index, C3D8 face number) of every edge of the edge set ``name``."""
    owner = {}
    for cell, quad in enumerate(mesh.cells):
        for j in range(4):
            owner[frozenset((int(quad[j]), int(quad[(j + 1) % 4])))] = (cell, FACE_OF_EDGE[j])
    try:
        return [owner[frozenset(map(int, edge))] for edge in mesh.edge_sets[name]]
    except KeyError:
        raise DeckError(f"body '{mesh.name}': edge set '{name}' is not on its cells") from None


def num(x) -> str:
    """A float as CalculiX reads it (shortest round-trip text of a Python float)."""
    return repr(float(x))


def lines(rows, per_line: int = 8) -> str:
    rows = [str(r) for r in rows]
    return "".join(", ".join(rows[i:i + per_line]) + "\n" for i in range(0, len(rows), per_line))


class Deck:
    """Node and element numbering of the extruded bodies (CalculiX numbers from 1)."""

    def __init__(self, config: ScenarioConfig, base_dir: Path,
                 shift: dict[int, tuple[float, float]] | None = None) -> None:
        self.config = config
        self.meshes = [build_mesh(b.mesh, b.name, base_dir) for b in config.bodies]
        for body, offset in (shift or {}).items():
            mesh = self.meshes[body]
            self.meshes[body] = mesh.with_nodes(mesh.nodes + np.asarray(offset))
        self.node_offset, self.cell_offset = [], []
        n_nodes = n_cells = 0
        for mesh in self.meshes:
            self.node_offset.append(n_nodes)
            self.cell_offset.append(n_cells)
            n_nodes += 2 * mesh.n_nodes
            n_cells += mesh.n_cells
        self.n_nodes, self.n_cells = n_nodes, n_cells
        self.amplitudes: dict[tuple, str] = {}

    def nodes(self, body: int, local: np.ndarray) -> np.ndarray:
        """Both layers' node numbers of the body's local 2D nodes."""
        base = self.node_offset[body] + 1 + np.asarray(local)
        return np.concatenate((base, base + self.meshes[body].n_nodes))

    def amplitude(self, function) -> str:
        """Name of the *AMPLITUDE of a time function (None: constant, no amplitude)."""
        if function is None:
            return ""
        key = (tuple(function.times), tuple(function.values))
        return self.amplitudes.setdefault(key, f"A{len(self.amplitudes) + 1}")

    def text(self) -> str:
        out = ["*HEADING\n", f"{self.config.title or 'ntncontact scenario'}\n"]
        out += self._mesh() + self._materials() + self._contact_pairs()
        step = self._step()  # before the amplitudes: it names them
        for (times, values), name in self.amplitudes.items():
            out += [f"*AMPLITUDE, NAME={name}\n", lines(
                [f"{num(t)}, {num(v)}" for t, v in zip(times, values, strict=True)], 4)]
        return "".join(out + step)

    def _mesh(self) -> list[str]:
        out = ["*NODE, NSET=NALL\n"]
        for body, mesh in enumerate(self.meshes):
            for layer, z in enumerate((0.0, THICKNESS)):
                first = self.node_offset[body] + 1 + layer * mesh.n_nodes
                out += [f"{first + i}, {num(x)}, {num(y)}, {num(z)}\n"
                        for i, (x, y) in enumerate(mesh.nodes)]
        for body, mesh in enumerate(self.meshes):
            out.append(f"*ELEMENT, TYPE=C3D8, ELSET=E{body}\n")
            first = self.cell_offset[body] + 1
            lower = mesh.cells + self.node_offset[body] + 1
            upper = lower + mesh.n_nodes
            out += [f"{first + i}, " + ", ".join(map(str, (*a, *b))) + "\n"
                    for i, (a, b) in enumerate(zip(lower, upper, strict=True))]
        out += ["*ELSET, ELSET=EALL\n"] + [f"E{body}\n" for body in range(len(self.meshes))]
        return out

    def _materials(self) -> list[str]:
        out = []
        for body, cfg in enumerate(self.config.bodies):
            m = cfg.material
            if m.model != "linear_elastic" or m.E is None or m.plane_stress:
                raise DeckError(f"body '{cfg.name}': only linear_elastic with E, nu, plane "
                                "strain is written")
            out += [f"*MATERIAL, NAME=M{body}\n", "*ELASTIC\n", f"{num(m.E)}, {num(m.nu)}\n",
                    f"*SOLID SECTION, ELSET=E{body}, MATERIAL=M{body}\n"]
        return out

    def surface(self, body: int, edge_set: str) -> str:
        name = f"S{body}_{edge_set}".upper()
        faces = edge_faces(self.meshes[body], edge_set)
        rows = [f"{self.cell_offset[body] + 1 + cell}, S{face}\n" for cell, face in faces]
        self._surfaces.append(f"*SURFACE, NAME={name}, TYPE=ELEMENT\n" + "".join(rows))
        return name

    def _contact_pairs(self) -> list[str]:
        self._surfaces: list[str] = []
        names = [b.name for b in self.config.bodies]
        out = []
        for index, c in enumerate(self.config.contact):
            if c.friction or c.penalty_normal is None:
                raise DeckError(f"contact '{c.name}': only frictionless penalty contact is "
                                "written")
            slave = self.surface(names.index(c.body_1), c.surface_1)
            master = self.surface(names.index(c.body_2), c.surface_2)
            out += [f"*SURFACE INTERACTION, NAME=I{index}\n",
                    "*SURFACE BEHAVIOR, PRESSURE-OVERCLOSURE=LINEAR\n",
                    f"{num(c.penalty_normal)}\n",
                    f"*CONTACT PAIR, INTERACTION=I{index}, TYPE=SURFACE TO SURFACE\n",
                    f"{slave}, {master}\n"]
        return self._surfaces + out

    def _step(self) -> list[str]:
        a = self.config.analysis
        if a.kind != "static":
            raise DeckError("only static analyses are written")
        out = ["*BOUNDARY\n", "NALL, 3, 3, 0.0\n"]
        reaction_sets = []
        loads = []
        for body, cfg in enumerate(self.config.bodies):
            mesh = self.meshes[body]
            for s in cfg.supports:
                nodes = self.nodes(body, set_nodes(mesh, s.set))
                nset = f"N{body}_{s.set}".upper()
                out += [f"*NSET, NSET={nset}\n", lines(nodes, 16)]
                reaction_sets.append(nset)
                for dof, value in ((1, s.x), (2, s.y)):
                    if value is None:
                        continue
                    amp = self.amplitude(s.function) if value else ""
                    loads += [f"*BOUNDARY{', AMPLITUDE=' + amp if amp else ''}\n",
                              f"{nset}, {dof}, {dof}, {num(value)}\n"]
            for load in cfg.loads:
                if load.type != "pressure":
                    raise DeckError(f"body '{cfg.name}': only pressure loads are written")
                amp = self.amplitude(load.function)
                loads.append(f"*DLOAD{', AMPLITUDE=' + amp if amp else ''}\n")
                loads += [f"{self.cell_offset[body] + 1 + cell}, P{face}, {num(load.value)}\n"
                          for cell, face in edge_faces(mesh, load.set)]
        n_steps = round(a.t_end / a.dt)
        out += ["*STEP, INC=1000\n", "*STATIC, DIRECT\n", f"{num(a.dt)}, {num(a.t_end)}\n"]
        out += loads
        for nset in reaction_sets:
            out += [f"*NODE PRINT, NSET={nset}, TOTALS=ONLY\n", "RF\n"]
        out += ["*EL PRINT, ELSET=EALL, TOTALS=ONLY\n", "ELSE\n",
                "*NODE FILE\n", "U\n", "*EL FILE\n", "S\n", "*CONTACT FILE\n", "CDIS, CSTR\n",
                "*END STEP\n"]
        self.n_increments = n_steps
        return out


def write_deck(config: ScenarioConfig, base_dir: Path, path: Path,
               shift: dict[int, tuple[float, float]] | None = None) -> Deck:
    deck = Deck(config, base_dir, shift)
    path.write_text(deck.text())
    return deck


# ---------------------------------------------------------------------------------------------
# runs


def timed(command: list[str], cwd: Path, env: dict | None = None) -> tuple[float, float, int]:
    """Run a process to its end: (wall s, CPU s of the process and its children, exit code)."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    start = time.perf_counter()
    proc = subprocess.run(command, cwd=cwd, env=os.environ | (env or {}),
                          stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    wall = time.perf_counter() - start
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    if proc.returncode != 0:
        print(f"{command[0]}: exit {proc.returncode}: {proc.stderr.strip()[-300:]}",
              file=sys.stderr)
    return wall, cpu, proc.returncode


def run_ccx(deck: Path, threads: int = 2) -> dict:
    """ccx on ``deck`` in its folder; the figures of its last increment."""
    wall, cpu, code = timed(["ccx", "-i", deck.stem], deck.parent,
                            {"OMP_NUM_THREADS": str(threads)})
    result = {"wall": wall, "cpu": cpu, "ok": code == 0} | ccx_figures(deck.with_suffix(""))
    deck.with_suffix(".frd").unlink(missing_ok=True)  # tens of MB at 15,200 elements
    return result


def run_ntncontact(scenario: Path, overrides: list[str], out: Path) -> dict:
    command = [sys.executable, "-m", "ntncontact.cli", "run", str(scenario), "--out", str(out),
               "--overwrite", "--quiet"]
    for item in overrides:
        command += ["--set", item]
    wall, cpu, code = timed(command, out.parent)
    return {"wall": wall, "cpu": cpu, "ok": code == 0} | ntncontact_figures(out)


def ccx_figures(job: Path) -> dict:
    """End force per reaction set, strain energy (.dat totals) and the largest contact
    pressure (.frd, last CONTACT block) of the last increment, per unit thickness."""
    dat = job.with_suffix(".dat").read_text() if job.with_suffix(".dat").exists() else ""
    forces, energy = {}, math.nan
    pattern = re.compile(r"total (force \(fx,fy,fz\) for set (\S+)|internal energy for set "
                         r"\S+) and time\s+(\S+)\s+([-+.\dE ]+)")
    for match in pattern.finditer(dat):
        values = [float(v) for v in match.group(4).split()]
        if match.group(2):
            forces[match.group(2)] = [v / THICKNESS for v in values[:2]]
        else:
            energy = values[0] / THICKNESS
    return {"forces": forces, "strain_energy": energy,
            "max_pressure": frd_max_pressure(job.with_suffix(".frd")),
            "iterations": sta_iterations(job.with_suffix(".sta"))}


def sta_iterations(sta: Path) -> int:
    """Newton iterations of all increments and attempts (the .sta file's ITRS column)."""
    if not sta.exists():
        return 0
    rows = [line.split() for line in sta.read_text().splitlines()]
    return sum(int(r[3]) for r in rows if len(r) == 7 and r[0].isdigit())


def frd_max_pressure(frd: Path) -> float:
    """Largest CPRESS of the last CONTACT block (fixed columns: node I10, values 6 x E12)."""
    if not frd.exists():
        return math.nan
    text = frd.read_text().splitlines()
    starts = [i for i, line in enumerate(text) if line.startswith(" -4  CONTACT")]
    if not starts:
        return math.nan
    i, largest = starts[-1] + 1, 0.0
    while text[i].startswith(" -5"):
        i += 1
    column = 13 + 12 * 3  # CPRESS is the 4th component
    while text[i].startswith(" -1"):
        largest = max(largest, float(text[i][column:column + 12]))
        i += 1
    return largest


def ntncontact_figures(out: Path) -> dict:
    """The same figures from history.csv and contact.csv (last step)."""
    history = out / "history.csv"
    if not history.exists():
        return {"forces": {}, "strain_energy": math.nan, "max_pressure": math.nan}
    with open(history) as f:
        last = list(csv.DictReader(f))[-1]
    forces = {key[len("reaction_"):-2]: [float(last[key]), float(last[key[:-1] + "y"])]
              for key in last if key.startswith("reaction_") and key.endswith("_x")}
    pressure = 0.0
    with open(out / "contact.csv") as f:
        for row in csv.DictReader(f):
            if row["step"] == last["step"]:
                pressure = max(pressure, float(row["normal_traction"]))
    summary = json.loads((out / "summary.json").read_text())
    with open(history) as f:
        iterations = sum(int(row["newton_iterations"]) for row in csv.DictReader(f))
    return {"forces": forces, "strain_energy": float(last["strain_energy"]),
            "max_pressure": pressure, "status": summary.get("status"), "iterations": iterations,
            "loop_wall": summary.get("wall_time_s")}


#: the reaction compared per problem: (ccx node set, ntncontact support name, component)
FORCE_OF = {"hertz": ("N1_BOTTOM", "foundation_bottom", 1),
            "bars": ("N1_RIGHT", "bar_right_right", 0)}
#: analytic figures per problem: (end force, largest contact pressure)
ANALYTIC = {"hertz": (240000.0, 3239.0), "bars": (bars_force(), bars_pressure())}


def measure(case: str, k: int, repeats: int, folder: Path) -> dict:
    """``repeats`` interleaved pairs of runs (ccx, ntncontact, ccx, ...) of one problem."""
    scenario, overrides = problem(case, k, folder)
    config = load_config(scenario, overrides)
    deck_path = folder / f"{case}_k{k}.inp"
    deck = write_deck(config, scenario.parent, deck_path, CCX_SHIFT[case])
    runs = {"ccx": [], "ntncontact": []}
    loads = []
    for _ in range(repeats):
        runs["ccx"].append(run_ccx(deck_path))
        runs["ntncontact"].append(run_ntncontact(scenario, overrides, folder / f"{case}_k{k}_out"))
        print(f"{case} k={k}: ccx {runs['ccx'][-1]['wall']:.1f} s ({runs['ccx'][-1]['cpu']:.1f} "
              f"CPU), ntncontact {runs['ntncontact'][-1]['wall']:.1f} s "
              f"({runs['ntncontact'][-1]['cpu']:.1f} CPU), load {os.getloadavg()[0]:.1f}",
              flush=True)
        loads.append(os.getloadavg()[0])
    return {"case": case, "k": k, "elements": deck.n_cells, "steps": deck.n_increments,
            "loads": loads, "runs": runs}


def span(values) -> str:
    lo, hi = min(values), max(values)
    return f"{lo:.1f}" if f"{lo:.1f}" == f"{hi:.1f}" else f"{lo:.1f}-{hi:.1f}"


def ratio_span(a: list[float], b: list[float]) -> str:
    """Range of the ratios of the interleaved pairs a_i / b_i."""
    ratios = [x / y for x, y in zip(a, b, strict=True)]
    lo, hi = min(ratios), max(ratios)
    return f"{lo:.1f}x" if f"{lo:.1f}" == f"{hi:.1f}" else f"{lo:.1f}-{hi:.1f}x"


def report(rows: list[dict]) -> str:
    head = ("| problem | elements | steps | ccx wall s | ccx CPU s | ntncontact wall s | "
            "ntncontact CPU s | ntncontact run only, wall s | ccx / ntncontact wall | "
            "ccx / ntncontact CPU | load (1 min) |")
    out = [head, "|" + " --- |" + " ---: |" * 10]
    agree = ["| problem | elements | end force ccx | end force ntncontact | analytic | "
             "strain energy ccx | strain energy ntncontact | rel. diff | max pressure ccx | "
             "max pressure ntncontact | analytic | Newton iterations ccx / ntncontact |",
             "|" + " --- |" + " ---: |" * 11]
    for r in rows:
        ccx, ntc = r["runs"]["ccx"], r["runs"]["ntncontact"]
        loads = span(r["loads"])
        out.append(
            f"| {r['case']} k={r['k']} | {r['elements']:,} | {r['steps']} | "
            f"{span([x['wall'] for x in ccx])} | {span([x['cpu'] for x in ccx])} | "
            f"{span([x['wall'] for x in ntc])} | {span([x['cpu'] for x in ntc])} | "
            f"{span([x.get('loop_wall') or math.nan for x in ntc])} | "
            f"{ratio_span([x['wall'] for x in ccx], [x['wall'] for x in ntc])} | "
            f"**{ratio_span([x['cpu'] for x in ccx], [x['cpu'] for x in ntc])}** | {loads} |")
        nset, support, comp = FORCE_OF[r["case"]]
        c, n = ccx[-1], ntc[-1]
        fc = abs(c["forces"].get(nset, [math.nan] * 2)[comp])
        fn = abs(n["forces"].get(support, [math.nan] * 2)[comp])
        force, pressure = ANALYTIC[r["case"]]
        diff = abs(c["strain_energy"] - n["strain_energy"]) / abs(n["strain_energy"])
        agree.append(
            f"| {r['case']} k={r['k']} | {r['elements']:,} | {fc:.6g} | {fn:.6g} | {force:.6g} | "
            f"{c['strain_energy']:.6g} | {n['strain_energy']:.6g} | {diff:.1e} | "
            f"{c['max_pressure']:.5g} | {n['max_pressure']:.5g} | {pressure:.5g} | "
            f"{c.get('iterations', '-')} / {n.get('iterations', '-')} |")
    return "\n".join(out + [""] + agree)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cases", nargs="+", choices=("hertz", "bars"), default=["hertz", "bars"])
    parser.add_argument("--k", nargs="+", type=int,
                        help=f"refinements (default: hertz {HERTZ_K}, bars {BARS_K})")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "calculix_results.md")
    parser.add_argument("--deck", nargs=3, metavar=("CASE", "K", "FILE"),
                        help="only write the deck of one problem")
    args = parser.parse_args()
    if args.deck:
        case, k, path = args.deck
        path = Path(path).resolve()
        scenario, overrides = problem(case, int(k), path.parent)
        deck = write_deck(load_config(scenario, overrides), scenario.parent, path,
                          CCX_SHIFT[case])
        print(f"{path}: {deck.n_nodes} nodes, {deck.n_cells} C3D8 elements")
        return
    if shutil.which("ccx") is None:
        print("CalculiX comparison skipped: no ccx on the PATH (Debian: calculix-ccx)")
        return
    rows = []
    progress = args.out.with_suffix(".jsonl")  # every problem's runs as soon as they end
    progress.write_text("")
    with tempfile.TemporaryDirectory() as tmp:
        # untimed: a kernel the cache lacks is compiled here, not in the first timed run
        scenario, overrides = problem("bars", 1, Path(tmp))
        run_ntncontact(scenario, overrides, Path(tmp) / "warm_up")
        for case in args.cases:
            for k in args.k or (HERTZ_K if case == "hertz" else BARS_K):
                rows.append(measure(case, k, args.repeats, Path(tmp)))
                with open(progress, "a") as f:
                    f.write(json.dumps(rows[-1]) + "\n")
    text = report(rows)
    print(text)
    args.out.write_text("# CalculiX comparison (benchmarks/calculix.py)\n\n" + text + "\n")


if __name__ == "__main__":
    main()
