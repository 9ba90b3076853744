"""Bodies whose edges lie along each other's overlap although no node is inside the other body:
the scenario is refused all the same (docs/scenarios.md, ``[[contact]]``), while bodies that
touch along an edge or at their ends still build (``mesh.overlap.deepest_overlap``)."""

import numpy as np
import pytest
from helpers import EXAMPLES

from ntncontact.cli import main
from ntncontact.engine.builder import build_model
from ntncontact.io.scenario import ScenarioError, load_config
from ntncontact.mesh.boundary import surface_chain
from ntncontact.mesh.generators import rectangle
from ntncontact.mesh.overlap import deepest_overlap

RODS = EXAMPLES / "rod_impact.toml"  # two rods 10 x 1, 40 x 1 elements: rod_right at x in [0, 10]


def build_rods(*sets):
    return build_model(load_config(RODS, list(sets)), RODS.parent)


@pytest.mark.parametrize("overlap", [10.0, 1.0, 0.3, 0.25])
def test_rods_overlapping_by_a_length_are_refused(overlap):
    """rod_left (one element thick, so each of its nodes lies on rod_right's top or bottom) ends
    ``overlap`` inside rod_right: 10 is the two rods on top of each other, 0.3 puts the nodes
    between rod_right's, 0.25 (one element) on them. Its end face, node 40 at (overlap, 0), is
    ``overlap`` deep: the length it must move back to clear rod_right."""
    with pytest.raises(ScenarioError) as info:
        build_rods(f"bodies.0.mesh.origin=[{overlap - 10.0!r}, 0.0]")
    message = str(info.value)
    assert "contact.0: bodies 'rod_left' and 'rod_right' overlap at t = 0" in message
    assert f"the face from node 40 of 'rod_left' at ({overlap:.6g}, 0) lies {overlap:.3g} " \
           "inside 'rod_right'" in message
    assert "place the bodies apart" in message


def test_a_rod_lying_along_a_longer_one_is_found_from_its_partner_side():
    """rod_left [-10, 20] x [0, 1] holds rod_right whole: rod_left's end face (x = 20) is outside
    rod_right, so it is rod_right's face (x = 0, walked from its top node 41) that is found, 20
    deep inside rod_left: the length it must move to clear rod_left."""
    with pytest.raises(ScenarioError) as info:
        build_rods("bodies.0.mesh.width=30.0", "bodies.0.mesh.nx=120",
                   "bodies.0.mesh.origin=[-10.0, 0.0]")
    assert ("the face from node 41 of 'rod_right' at (0, 1) lies 20 inside 'rod_left'"
            in str(info.value))


def test_the_cli_refuses_the_coincident_rods(tmp_path, capsys):
    """The tester's command: it used to run to 'completed', the rods passing through each other."""
    out = tmp_path / "o"
    assert main(["run", str(RODS), "--out", str(out), "--quiet", "--set", "analysis.t_end=0.2",
                 "--set", "bodies.0.mesh.origin=[0.0,0.0]"]) == 1
    err = capsys.readouterr().err
    assert "'rod_left' and 'rod_right' overlap at t = 0" in err and "lies 10 inside" in err
    assert not (out / "history.csv").exists()


@pytest.mark.parametrize("origin", ["[-10.0, 0.0]", "[-10.05, 0.0]", "[-9.0, 1.0]",
                                    "[-5.0, -1.0]", "[10.0, 0.0]"])
def test_rods_touching_end_to_end_or_along_a_side_build(origin):
    """End to end (exactly, and the example's 0.05 apart), rod_left lying on rod_right's top or
    under its bottom along part of it, rod_left beyond rod_right's far end: no overlap."""
    model = build_rods(f"bodies.0.mesh.origin={origin}")
    assert [ci.name for ci in model.interfaces] == ["rod_ends"]


BLOCKS = """
[analysis]
kind = "dynamic"
dt = 0.01
t_end = 0.1

[[bodies]]
name = "lower"
mesh = {{ type = "rectangle", width = 1.0, height = 1.0, nx = 4, ny = 3 }}
material = {{ model = "neo_hookean", E = 10.0, nu = 0.3, density = 1.0 }}

[[bodies]]
name = "upper"
mesh.type = "rectangle"
mesh.width = {width}
mesh.height = 1.0
mesh.nx = {nx}
mesh.ny = {ny}
mesh.origin = [{x}, {y}]
material = {{ model = "neo_hookean", E = 10.0, nu = 0.3, density = 1.0 }}

[[contact]]
body_1 = "upper"
surface_1 = "bottom"
body_2 = "lower"
surface_2 = "top"
penalty_normal = 10.0
"""


def build_blocks(tmp_path, width=1.0, nx=3, ny=2, x=0.0, y=1.0):
    path = tmp_path / "blocks.toml"
    path.write_text(BLOCKS.format(width=width, nx=nx, ny=ny, x=x, y=y))
    return build_model(load_config(path), tmp_path)


@pytest.mark.parametrize("width, nx, x", [(1.0, 3, 0.0), (1.0, 4, 0.0), (1.0, 1, 0.0),
                                          (0.5, 1, 0.25), (2.0, 5, -0.5)])
def test_blocks_touching_along_an_edge_build(tmp_path, width, nx, x):
    """The upper block on the lower one's top: the same edge (meshes matching or not, one
    element wide), a narrower block on part of it, a wider one over all of it."""
    model = build_blocks(tmp_path, width=width, nx=nx, x=x)
    assert len(model.interfaces) == 1


@pytest.mark.parametrize("y, place, depth", [(0.0, "(0, 0)", "1"), (0.5, "(0, 0.5)", "0.5")])
def test_blocks_one_element_wide_sunk_in_are_refused(tmp_path, y, place, depth):
    """The upper block one element wide (its bottom's two nodes on the lower block's sides) and
    sunk into the lower one by 1 - y: refused, the depth being how far it must rise."""
    with pytest.raises(ScenarioError) as info:
        build_blocks(tmp_path, nx=1, ny=1, y=y)
    assert (f"the face from node 0 of 'upper' at {place} lies {depth} inside 'lower'"
            in str(info.value))


def test_a_set_of_points_is_not_read_as_a_surface():
    """``chain=False`` (the default: the in-run check's boundary nodes, in no order) tests the
    points only; the same points as a surface (``chain=True``, body on the left, as the builder
    calls it) test the sides of their edges too."""
    lower = rectangle(1.0, 1.0, 4, 3)
    upper = rectangle(1.0, 1.0, 3, 2, origin=(0.0, 0.0))  # on top of ``lower``
    bottom = upper.nodes[surface_chain(upper, "bottom").nodes]
    assert deepest_overlap(bottom, lower.nodes, lower.cells, chain=False) is None
    assert deepest_overlap(bottom, lower.nodes, lower.cells) is None
    found = deepest_overlap(bottom, lower.nodes, lower.cells, chain=True)
    assert found is not None and found.edge and found.point == 0
    assert found.position == (0.0, 0.0) and found.depth == pytest.approx(1.0, rel=1e-12)
    # walked the other way (the body below them), the sides tested are outside ``lower``
    assert deepest_overlap(np.ascontiguousarray(bottom[::-1]), lower.nodes, lower.cells) is None
