"""The CalculiX deck generator of benchmarks/calculix.py (issue 18): a tiny two-bar deck is
read back (counts, element orientation, faces on the right boundaries) and, where ``ccx`` is
installed, run to its end; its end force is the series-spring value of the bars and the
penalty."""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import tomllib

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
import calculix  # noqa: E402

from ntncontact.io.scenario import parse_scenario  # noqa: E402

#: C3D8 face S3..S6 -> its local nodes (CalculiX's numbering, 0-based)
FACE_NODES = {3: (0, 1, 5, 4), 4: (1, 2, 6, 5), 5: (2, 3, 7, 6), 6: (3, 0, 4, 7)}


def tiny_bars(nx: int = 3, steps: int = 4) -> dict:
    data = calculix.bars_scenario(1)
    for body in data["bodies"]:
        body["mesh"]["nx"] = nx
    data["analysis"]["dt"] = 1.0 / steps
    return data


def read_deck(path: Path) -> tuple[dict, dict, dict, list]:
    """Nodes, elements, surfaces (name -> [(element, face)]) and DLOAD faces of a deck."""
    nodes, elements, surfaces, dloads = {}, {}, {}, []
    block = None
    for line in path.read_text().splitlines():
        if line.startswith("*"):
            keyword = line.upper()
            block = ("node" if keyword.startswith("*NODE,") or keyword == "*NODE" else
                     "element" if keyword.startswith("*ELEMENT") else
                     "dload" if keyword.startswith("*DLOAD") else None)
            if keyword.startswith("*SURFACE,"):
                block = re.search(r"NAME=([^,\s]+)", keyword).group(1)
                surfaces[block] = []
            continue
        fields = [f.strip() for f in line.split(",")]
        if block == "node":
            nodes[int(fields[0])] = np.array([float(v) for v in fields[1:4]])
        elif block == "element":
            elements[int(fields[0])] = [int(v) for v in fields[1:9]]
        elif block == "dload":
            dloads.append((int(fields[0]), int(fields[1][1:])))
        elif block in surfaces:
            surfaces[block].append((int(fields[0]), int(fields[1][1:])))
    return nodes, elements, surfaces, dloads


def face_points(nodes: dict, elements: dict, element: int, face: int) -> np.ndarray:
    return np.array([nodes[elements[element][i]] for i in FACE_NODES[face]])


def hex_volume_sign(points: np.ndarray) -> float:
    """det of the hexahedron's Jacobian at its centre (CalculiX needs it positive)."""
    dx = points[[1, 2, 6, 5]].sum(0) - points[[0, 3, 7, 4]].sum(0)
    dy = points[[3, 2, 6, 7]].sum(0) - points[[0, 1, 5, 4]].sum(0)
    dz = points[4:].sum(0) - points[:4].sum(0)
    return float(np.linalg.det(np.array([dx, dy, dz])))


def test_scenario_text_is_the_mapping():
    data = calculix.bars_scenario(2)
    assert tomllib.loads(calculix.toml_text(data)) == data


@pytest.fixture
def bars_deck(tmp_path):
    config = parse_scenario(tiny_bars(), tmp_path / "bars.toml")
    path = tmp_path / "bars.inp"
    return path, calculix.write_deck(config, tmp_path, path)


def test_bars_deck_reads_back(bars_deck):
    path, deck = bars_deck
    nodes, elements, surfaces, _ = read_deck(path)
    # two bars of 3 x 1 quads: 8 nodes each, two layers
    assert len(nodes) == deck.n_nodes == 2 * 2 * 8
    assert len(elements) == deck.n_cells == 6
    for element, connectivity in elements.items():
        assert hex_volume_sign(np.array([nodes[n] for n in connectivity])) > 0, element
    zs = {round(p[2], 12) for p in nodes.values()}
    assert zs == {0.0, calculix.THICKNESS}
    # the contact faces lie on the bars' facing ends, one face per end
    left_end = -calculix.BAR_GAP
    assert set(surfaces) == {"S0_RIGHT", "S1_LEFT"}
    for name, x in (("S0_RIGHT", left_end), ("S1_LEFT", 0.0)):
        (face,) = surfaces[name]
        assert np.allclose(face_points(nodes, elements, *face)[:, 0], x, atol=1e-12)


def test_hertz_pressure_faces_on_the_flat_face(tmp_path):
    scenario, overrides = calculix.problem("hertz", 1, tmp_path)
    config = calculix.load_config(scenario, overrides)
    shift = calculix.CCX_SHIFT["hertz"]
    deck = calculix.write_deck(config, scenario.parent, tmp_path / "hertz.inp", shift)
    nodes, elements, surfaces, dloads = read_deck(tmp_path / "hertz.inp")
    assert deck.n_cells == len(elements) == 950
    assert dloads, "no pressure faces"
    dy = shift[0][1]
    for face in dloads:  # the cylinder's flat face, y = R = 400, shifted by dy
        assert np.allclose(face_points(nodes, elements, *face)[:, 1], 400.0 + dy, atol=1e-9)
    lowest = min(nodes[n][1] for n in range(1, deck.node_offset[1] + 1))  # the cylinder's
    assert lowest == pytest.approx(dy, abs=1e-12)
    for face in surfaces["S1_TOP"]:
        assert np.allclose(face_points(nodes, elements, *face)[:, 1], 0.0, atol=1e-9)


def test_unsupported_features_are_named(tmp_path):
    data = tiny_bars()
    data["contact"][0]["friction"] = 0.3
    data["contact"][0]["penalty_tangential"] = 1e4
    config = parse_scenario(data, tmp_path / "bars.toml")
    with pytest.raises(calculix.DeckError, match="frictionless"):
        calculix.write_deck(config, tmp_path, tmp_path / "x.inp")


def test_skipped_without_ccx(monkeypatch, capsys):
    monkeypatch.setattr(shutil, "which", lambda name: None)
    monkeypatch.setattr(sys, "argv", ["calculix.py"])
    calculix.main()
    assert capsys.readouterr().out.strip().startswith("CalculiX comparison skipped")


@pytest.mark.skipif(shutil.which("ccx") is None, reason="ccx (calculix-ccx) not installed")
def test_ccx_runs_the_tiny_deck(bars_deck):
    path, _ = bars_deck
    proc = subprocess.run(["ccx", "-i", path.stem], cwd=path.parent, capture_output=True,
                          text=True, env=os.environ | {"OMP_NUM_THREADS": "1"}, timeout=60)
    assert proc.returncode == 0, proc.stdout[-500:]
    assert path.with_suffix(".frd").stat().st_size > 0
    figures = calculix.ccx_figures(path.with_suffix(""))
    # bars (plane strain, free sides: E' / (2 L) per unit height) in series with the penalty
    # K once the gap is closed: F = (u - gap) / (2 L / E' + 1 / K). rel 1e-5: the .dat holds 7
    # digits and ccx stops its contact iterations on its own residual test (1.2e-6 measured)
    e_plane = calculix.BAR_E / (1 - calculix.BAR_NU**2)
    k_penalty = tiny_bars()["contact"][0]["penalty_normal"]
    expected = (calculix.BAR_PUSH - calculix.BAR_GAP) / (
        2 * calculix.BAR_LENGTH / e_plane + 1 / k_penalty)
    assert figures["forces"]["N1_RIGHT"][0] == pytest.approx(-expected, rel=1e-5)
    assert figures["forces"]["N0_LEFT"][0] == pytest.approx(expected, rel=1e-5)
    # the bars' uniform strain energy (the penalty's is not in ELSE)
    compliance = 2 * calculix.BAR_LENGTH / e_plane
    assert figures["strain_energy"] == pytest.approx(expected**2 * compliance / 2, rel=1e-5)
