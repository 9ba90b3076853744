"""Penetration where contact cannot see it (summary.json ``max_penetration_off_surfaces``,
``engine.diagnostics.PenetrationCheck``): a boundary node on none of the contact surfaces
between two bodies goes inside the other. Contact acts on its surfaces only, so nothing
resists it; the run completes, and only this figure and the CLI's warning tell.

Own case: a block slides sideways into a neighbour; the only interface joins the block's
bottom to the neighbour's top (which never meet), so the block's right face passes into the
neighbour. With that face a contact surface too, nothing goes inside unresisted.
"""

from __future__ import annotations

import json

import pytest

from ntncontact.cli import main

SLIDE = """
analysis = {{ kind = "dynamic", dt = 0.01, t_end = 0.1 }}

[[bodies]]
name = "block"
mesh = {{ type = "rectangle", width = 0.5, height = 0.5, nx = 2, ny = 2, origin = [0.0, 0.0] }}
material = {{ model = "neo_hookean", lambda = 115.38, mu = 76.92, density = 1.0 }}
initial = {{ velocity = [1.0, 0.0] }}

[[bodies]]
name = "neighbour"
mesh = {{ type = "rectangle", width = 0.5, height = 0.5, nx = 2, ny = 2, origin = [0.55, 0.0] }}
material = {{ model = "neo_hookean", lambda = 115.38, mu = 76.92, density = 1.0 }}

[[contact]]
body_1 = "block"
surface_1 = "{surface_1}"
body_2 = "neighbour"
surface_2 = "{surface_2}"
method = "augmented_lagrangian"
penalty_normal = 100.0
"""


def run(tmp_path, surface_1: str, surface_2: str, capsys) -> tuple[dict, str]:
    path = tmp_path / f"{surface_1}.toml"
    path.write_text(SLIDE.format(surface_1=surface_1, surface_2=surface_2))
    out = tmp_path / surface_1
    assert main(["run", str(path), "--out", str(out), "--quiet"]) == 0
    return json.loads((out / "summary.json").read_text()), capsys.readouterr().err


def test_a_face_on_no_contact_surface_that_goes_inside_is_measured_and_warned(tmp_path, capsys):
    """The right face moves 0.1 in 0.1 s against a gap of 0.05 (the neighbour is pushed by
    nothing): its nodes end about 0.05 inside, the figure names the block's face node, and
    the CLI warns with the node, the depth and what to do."""
    summary, err = run(tmp_path, "bottom", "top", capsys)
    depth = summary["max_penetration_off_surfaces"]
    assert depth == pytest.approx(0.05, abs=0.01)
    at = summary["max_penetration_off_surfaces_at"]
    assert (at["body"], at["inside"]) == ("block", "neighbour")
    assert at["node"] in (2, 5, 8)  # the right face of a 2 x 2 rectangle (row-major nodes)
    assert at["time"] == pytest.approx(0.1)
    assert f"node {at['node']} of body 'block', on no contact surface, went" in err
    assert "make that face a contact surface too, joined to the one beside it" in err


@pytest.mark.parametrize("surface_1, surface_2", [("right", "left"),
                                                   ("bottom+right", "top+left")])
def test_with_the_face_a_contact_surface_nothing_goes_inside_unresisted(
        tmp_path, capsys, surface_1, surface_2):
    """The face as the surface, or joined to the bottom as the warning advises (each side
    one chain around its corner)."""
    summary, err = run(tmp_path, surface_1, surface_2, capsys)
    assert summary["max_penetration_off_surfaces"] == 0.0
    assert summary["max_penetration_off_surfaces_at"] is None
    assert "warning" not in err


TWO_BODIES = """
analysis = {{ kind = "dynamic", dt = 0.01, t_end = 0.1 }}

[[bodies]]
name = "block"
mesh = {{ type = "rectangle", width = 0.5, height = 0.5, nx = 2, ny = 2, origin = [0.0, 0.0] }}
material = {{ model = "neo_hookean", lambda = 115.38, mu = 76.92, density = 1.0 }}
initial = {{ velocity = [{speed}, 0.0] }}

[[bodies]]
name = "neighbour"
mesh = {{ type = "rectangle", width = 0.5, height = 0.5, nx = 2, ny = 2, origin = [{x2}, 0.0] }}
material = {{ model = "neo_hookean", lambda = 115.38, mu = 76.92, density = 1.0 }}
{joint}
"""

TIE = """
[[tie]]
name = "bond"
body_1 = "block"
surface_1 = "right"
body_2 = "neighbour"
surface_2 = "left"
"""


def run_two_bodies(tmp_path, capsys, name: str, **values) -> tuple[dict, str, str]:
    path = tmp_path / f"{name}.toml"
    path.write_text(TWO_BODIES.format(**values))
    out = tmp_path / name
    assert main(["run", str(path), "--out", str(out), "--quiet"]) == 0
    history = (out / "history.csv").read_text()
    return json.loads((out / "summary.json").read_text()), capsys.readouterr().err, history


def test_bodies_no_interface_joins_are_measured_and_warned(tmp_path, capsys):
    """Two bodies with no [[contact]] between them (a body named in the wrong interface, or
    the interface forgotten): the block's right face passes 0.05 into the neighbour, and the
    figure, its history column and the warning name the missing interface."""
    summary, err, history = run_two_bodies(tmp_path, capsys, "apart", speed=1.0, x2=0.55,
                                           joint="")
    assert summary["max_penetration_off_surfaces"] == pytest.approx(0.05, abs=0.01)
    at = summary["max_penetration_off_surfaces_at"]
    assert (at["body"], at["inside"], at["joined"]) == ("block", "neighbour", False)
    assert at["node"] in (2, 5, 8)
    assert "penetration_off_surfaces" in history.splitlines()[0].split(",")
    assert "no [[contact]] joins 'block' and 'neighbour'" in err


def test_tied_bodies_are_not_reported(tmp_path, capsys):
    """Tied bodies share their tied face (depth 0 on each other's boundary): a tied pair
    moving together, pushed by the block's speed, reports no penetration. (The neighbour
    starts at rest: the build warns that the tied nodes start 1 apart, a difference the tie
    never removes.)"""
    summary, err, _ = run_two_bodies(tmp_path, capsys, "tied", speed=1.0, x2=0.5, joint=TIE)
    assert summary["max_penetration_off_surfaces"] == 0.0
    assert summary["max_penetration_off_surfaces_at"] is None
    assert "went" not in err and "no [[contact]] joins" not in err
    assert "its nodes start with velocities up to 1 apart" in err
    assert "Give the tied parts the same initial.velocity" in err
    assert "angular_velocity" not in err  # no part spins: no spin advice


def test_bodies_apart_that_stay_apart_report_nothing(tmp_path, capsys):
    summary, err, history = run_two_bodies(tmp_path, capsys, "slow", speed=0.1, x2=0.55,
                                           joint="")
    assert summary["max_penetration_off_surfaces"] == 0.0
    assert "warning" not in err
