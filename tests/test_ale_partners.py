"""ALE contact at any spacing ratio (issue 17, item 1; docs/theory.md, "Partners at any
spacing ratio"): a partner surface finer or coarser than the ALE surface, up to 4x either way.

- Property test: a block slides on an ALE base at a random speed, its bottom spacing a random
  1/4 to 4 times the base's; the ALE never fails and every active pair ends its step node to
  node (no offset across the contact normal beyond 1e-6 of the spacing).
- The user case of the issue: a Neo-Hookean disk with 64 outer nodes (radius 0.5, from gmsh)
  dropped with friction 0.3 and a body force on an ALE block 4 x 0.5 with nx = 40, i.e. a
  partner twice as fine as the ALE surface (it stopped at step 116: "surface nodes 226 and 225
  would swap order").
- Where no valid motion exists the step is cut back, and the run stops with one line naming
  the step, the time, the body and what to change.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
from helpers import Recorder, model_from_dict, offsets_across_normal

from ntncontact.ale.motion import AleMotionError
from ntncontact.engine import mesh_motion
from ntncontact.engine.simulation import Simulation, SimulationError
from ntncontact.mesh.quadmesh import MeshError

BASE_SPACING = 0.125  # the ALE base: 4.0 wide, 32 elements
#: node to node: no offset across the contact normal beyond this fraction of the spacing
NODE_TO_NODE = 1e-6
T_DISK = 0.3  # lands at t = 0.02, then rolls and slides: 56 contact steps


def sliding_block(ratio: float, speed: float, shift: float, steps: int = 10,
                  dt: float = 0.02) -> dict:
    """A 1.0 x 0.25 block (bottom spacing BASE_SPACING / ratio) landing slowly at x = 0.5 +
    shift on an ALE base, pressed by its weight and sliding at ``speed``; it stays clear of the
    base's corners (at most 0.6 of travel from x >= 0.5 on [-1, 3])."""
    nx_top = max(round(ratio / BASE_SPACING), 1)
    return {
        "analysis": {"kind": "dynamic", "dt": dt, "t_end": steps * dt},
        "bodies": [
            {"name": "block", "mesh": {"type": "rectangle", "width": 1.0, "height": 0.25,
                                       "nx": nx_top, "ny": 2, "origin": [0.5 + shift, 0.001]},
             "material": {"model": "neo_hookean", "lambda": 115.38, "mu": 76.92,
                          "density": 1.0},
             "initial": {"velocity": [speed, -0.1]},
             "loads": [{"type": "body_force", "vector": [0.0, -20.0]}]},
            {"name": "base", "mesh_motion": "ale", "ale": {"smoothing_layers": 1},
             "mesh": {"type": "rectangle", "width": 4.0, "height": 0.2, "nx": 32, "ny": 2,
                      "origin": [-1.0, -0.2]},
             "material": {"model": "neo_hookean", "lambda": 2884.6, "mu": 1923.1,
                          "density": 500.0}},
        ],
        "contact": [{"body_1": "block", "surface_1": "bottom", "body_2": "base",
                     "surface_2": "top", "method": "augmented_lagrangian",
                     "law": "persistency", "penalty_normal": 1000.0,
                     "penalty_tangential": 1000.0}],
    }


def test_any_spacing_ratio_from_a_quarter_to_four_keeps_pairs_node_to_node():
    rng = np.random.default_rng(17)
    ratios = np.exp(rng.uniform(np.log(0.25), np.log(4.0), 5))
    ratios[:2] = 0.25, 4.0  # both ends of the range, then random ones
    for ratio in ratios:
        speed, shift = rng.uniform(-3.0, 3.0), rng.uniform(0.0, BASE_SPACING)
        rec = Recorder()
        model = model_from_dict(sliding_block(ratio, speed, shift))
        Simulation(model, [rec]).run()  # the ALE never fails
        contact_steps = [r for r in rec.records[1:] if len(r.extra["contact_rows"]["node_1"])]
        assert len(contact_steps) >= len(rec.records) - 3, (ratio, speed)  # lands, stays
        surfaces = model.interfaces[0].interface
        for record in contact_steps:
            rows = record.extra["contact_rows"]
            assert np.unique(rows["node_2"]).size == rows["node_2"].size  # distinct partners
            # every node of the sparser side under the block is paired (but the two ends,
            # which may just have landed or be waiting for a partner within reach)
            x = record.state.x
            bottom = x[surfaces.surface1.nodes, 0]
            top = x[surfaces.surface2.nodes, 0]
            under = np.count_nonzero((top >= bottom.min()) & (top <= bottom.max()))
            sparser = min(bottom.size, under)
            assert rows["node_1"].size >= sparser - 2, (ratio, speed, record.state.step)
            worst = offsets_across_normal(model, record).max()
            assert worst <= NODE_TO_NODE * BASE_SPACING, (ratio, speed, record.state.step)


def write_gmsh_disk(path, n_outer: int = 64, radius: float = 0.5) -> None:
    """An all-quad gmsh disk with ``n_outer`` nodes on its outer circle (edge set ``outer``)."""
    gmsh = pytest.importorskip("gmsh")
    gmsh.initialize()
    try:
        gmsh.option.setNumber("General.Terminal", 0)
        gmsh.model.add("disk")
        disk = gmsh.model.occ.addDisk(0.0, 0.0, 0.0, radius, radius)
        gmsh.model.occ.synchronize()
        circle = [tag for _, tag in gmsh.model.getBoundary([(2, disk)], oriented=False)]
        gmsh.model.mesh.setTransfiniteCurve(circle[0], n_outer + 1)
        gmsh.option.setNumber("Mesh.MeshSizeMax", 3.2 * np.pi * radius / n_outer)
        gmsh.option.setNumber("Mesh.RecombineAll", 1)
        gmsh.option.setNumber("Mesh.Algorithm", 8)  # frontal-Delaunay for quads
        gmsh.option.setNumber("Mesh.RecombinationAlgorithm", 2)  # blossom: quads only
        gmsh.model.addPhysicalGroup(2, [disk], name="disk")
        gmsh.model.addPhysicalGroup(1, circle, name="outer")
        gmsh.model.mesh.generate(2)
        gmsh.option.setNumber("Mesh.MshFileVersion", 2.2)
        gmsh.write(str(path))
    finally:
        gmsh.finalize()


def disk_on_block(mesh_file, nx: int, t_end: float, dt: float = 0.005) -> dict:
    """The issue's case: the disk lands at v = (1, -1) (it rolls and slides) with friction
    0.3 and its weight on a supported ALE block 4 x 0.5 (nx elements across)."""
    return {
        "analysis": {"kind": "dynamic", "dt": dt, "t_end": t_end},
        "bodies": [
            {"name": "disk", "mesh": {"type": "gmsh", "file": str(mesh_file)},
             "material": {"model": "neo_hookean", "lambda": 461.54, "mu": 307.69,
                          "density": 2.0},
             "initial": {"velocity": [1.0, -1.0]},
             "loads": [{"type": "body_force", "vector": [0.0, -20.0]}]},
            {"name": "block", "mesh_motion": "ale",
             "ale": {"smoothing_layers": 1, "remap": "quadratic"},
             "mesh": {"type": "rectangle", "width": 4.0, "height": 0.5, "nx": nx, "ny": 4,
                      "origin": [-2.0, -1.02]},
             "material": {"model": "neo_hookean", "lambda": 230.77, "mu": 153.85,
                          "density": 20.0},
             "supports": [{"set": "bottom", "x": 0.0, "y": 0.0}]},
        ],
        "contact": [{"body_1": "disk", "surface_1": "outer", "body_2": "block",
                     "surface_2": "top", "method": "augmented_lagrangian",
                     "law": "persistency", "penalty_normal": 1000.0,
                     "penalty_tangential": 1000.0, "friction": 0.3,
                     "augmentation": {"gap_tolerance": 1e-6}}],
    }


def test_disk_with_a_finer_surface_rolls_on_a_coarser_ale_block(tmp_path):
    mesh = tmp_path / "disk.msh"
    write_gmsh_disk(mesh)
    rec = Recorder()
    model = model_from_dict(disk_on_block(mesh, nx=40, t_end=T_DISK))
    assert model.interfaces[0].interface.surface1.size == 64
    Simulation(model, [rec]).run()
    assert rec.records[-1].state.time == pytest.approx(T_DISK, abs=1e-12)
    contact_steps = [r for r in rec.records if len(r.extra.get("contact_rows", {"node_1": ()})
                                                  ["node_1"])]
    assert len(contact_steps) > 0.8 * (len(rec.records) - 5)  # lands at t = 0.02 and stays
    disk_spacing = 2 * np.pi * 0.5 / 64
    for record in contact_steps:
        rows = record.extra["contact_rows"]
        assert np.unique(rows["node_2"]).size == rows["node_2"].size
        assert offsets_across_normal(model, record).max() <= NODE_TO_NODE * disk_spacing



SLIDE_TOML = """
[analysis]
kind = "dynamic"
dt = 0.02
t_end = 0.1
max_cutbacks = 2

[[bodies]]
name = "block"
mesh = { type = "rectangle", width = 1.0, height = 0.25, nx = 8, ny = 2, origin = [0.5, 0.001] }
material = { model = "neo_hookean", lambda = 115.38, mu = 76.92, density = 1.0 }
initial = { velocity = [1.0, -0.1] }

[[bodies]]
name = "base"
mesh_motion = "ale"
mesh = { type = "rectangle", width = 4.0, height = 0.2, nx = 32, ny = 2, origin = [-1.0, -0.2] }
material = { model = "neo_hookean", lambda = 2884.6, mu = 1923.1, density = 500.0 }

[[contact]]
body_1 = "block"
surface_1 = "bottom"
body_2 = "base"
surface_2 = "top"
penalty_normal = 1000.0
"""  # noqa: E501 (a TOML inline table is one line)


def test_an_ale_move_without_valid_motion_is_cut_back_then_named_in_one_line(
        monkeypatch, tmp_path, capsys):
    """Every ALE move fails from the first contact step on (as when targets cross): the step
    is cut back max_cutbacks times, then the CLI prints one line with the step, its time, the
    failure (body, nodes) and the advice, and no traceback."""
    from ntncontact.cli import main

    calls = []

    def no_valid_motion(body, *args, **kwargs):
        calls.append(args[7])  # dt of the (sub-)step: X, d, v, a, nodes, targets, ends, dt
        raise AleMotionError(f"body '{body.name}': ALE surface nodes 3 and 4 would swap order: "
                             "... refine the ALE surface to at most 2x the partner surface's "
                             "spacing")

    monkeypatch.setattr(mesh_motion, "move_ale_body", no_valid_motion)
    path = tmp_path / "slide.toml"
    path.write_text(SLIDE_TOML)
    assert main(["run", str(path), "--out", str(tmp_path / "out"), "--quiet"]) == 1
    err = capsys.readouterr().err
    assert "Traceback" not in err
    message = err.strip().splitlines()[-1]  # (a first run may announce compiling kernels)
    assert sum(line.startswith("error:") for line in err.splitlines()) == 1
    assert message.startswith("error: step 2 (t = 0.02 -> 0.04) failed after 2 halvings")
    assert "body 'base': ALE surface nodes 3 and 4 would swap order" in message
    assert "2x the partner surface's spacing" in message
    assert calls == pytest.approx([0.02, 0.01, 0.005])  # tried at dt, dt/2, dt/4


def test_other_mesh_failures_of_an_ale_move_are_ale_motion_errors(monkeypatch):
    """A remap or inversion failure inside the move (a MeshError) is cut back like a crossing."""
    def outside(*args, **kwargs):
        raise MeshError("point [0.1, 0.2] lies 0.003 outside the old mesh; cannot remap it")

    monkeypatch.setattr(mesh_motion, "move_ale_body", outside)
    model = model_from_dict(sliding_block(1.0, 1.0, 0.0, steps=3))
    with pytest.raises(SimulationError, match=r"step 2 \(t = 0.02 -> 0.04\) failed after \d+ "
                       r"halvings of the step: ALE mesh motion: point .* outside the old mesh"):
        Simulation(model).run()


def crossing_pairs(lifted: bool, past: float = 0.3, *overrides: str):
    """The fast-sliding blocks (report's mesh) at t = 0 with two neighbouring pairs: upper
    bottom nodes i1 < i2 over lower top nodes j1 < j2. The end-of-step prediction puts i2 on
    j2, 1e-4 deep, and i1 ``past`` of a spacing past i2: lifted 0.01 off the surface when
    ``lifted`` (an open pair, as the neighbour of a leading corner held by friction rolls
    over it), else 1e-4 deep too. Returns (model, base, contact, x_pred, j1, j2)."""
    from helpers import model_from_example

    from ntncontact.contact import PairState
    from ntncontact.engine.simulation import initial_state

    model = model_from_example("blocks_fast_sliding.toml", list(overrides))
    base = initial_state(model)
    ci = model.interfaces[0].interface
    bottom, top = model.bodies[0].global_nodes("bottom"), ci.surface2.nodes
    i1, i2 = (int(n) for n in bottom[bottom.size // 2: bottom.size // 2 + 2])
    j1, j2 = (int(top[np.argmin(np.abs(base.x[top, 0] - base.x[i, 0]))]) for i in (i1, i2))
    h = model.ale_bodies[0].motion.min_spacing
    x_pred = base.x.copy()
    x_pred[model.bodies[0].nodes] -= [0.0, 0.096]  # the upper block lands on the lower
    x_pred[i2] = base.x[j2] + [0.0, -1e-4]
    x_pred[i1] = base.x[j2] + [past * h, 0.01 if lifted else -1e-4]
    return model, base, (PairState.from_pairs([[i1, j1], [i2, j2]]),), x_pred, j1, j2


def test_an_open_pair_whose_partner_crosses_a_neighbours_is_not_followed():
    """Issue 17 item 1: where a node cannot follow its partner because its neighbour's
    partner would be passed, the method does not fail. An open pair (its partner lifted off)
    carries no force along its normal: its ALE node is respaced instead, for the rest of the
    step (``MeshMotion.unfollowed``), and the pressed neighbour ends on its partner."""
    model, base, contact, x_pred, j1, j2 = crossing_pairs(lifted=True)
    motion = mesh_motion.move_meshes(model, base, contact, x_pred, 0.003, None)
    assert motion.unfollowed == {(j1, int(contact[0].pairs[0, 0]))}
    nodes, _, wanted = motion.requests[0]
    assert nodes.tolist() == [j2]
    x = motion.state.x
    assert x[j1, 0] < x[j2, 0]  # order kept: j1 respaced, not moved past j2
    # the decision holds for the step: the next augmentations (the ALE particles where the
    # move put them; the lower block is at rest) move without the pair, and the mesh settles
    # (geometrically: i1's lift tilts i2's normal, so j2 slides 2.6e-5, then 2e-6, ...)
    rows = model.bodies[1].nodes
    for _ in range(6):
        x_pred[rows] = motion.state.x[rows]
        if mesh_motion.mesh_settled(model, base, contact, x_pred, motion):
            break
        motion = mesh_motion.move_meshes(model, base, contact, x_pred, 0.003, motion)
        assert motion.unfollowed == {(j1, int(contact[0].pairs[0, 0]))}
        assert motion.requests[0][0].tolist() == [j2]
    else:
        raise AssertionError("the mesh motion did not settle in 6 augmentations")


def test_a_pair_predicted_open_that_carries_force_is_still_followed():
    """The open pair of the test above, but carrying traction at t_n (as a chattering corner
    under the persistency law does, whose traction goes by its rate): it is pressed, so the
    mesh must follow it, and with its neighbour pressed too no valid motion exists: the
    crossing is named, not hidden by leaving a loaded pair off node to node."""
    from dataclasses import replace

    from ntncontact.ale.motion import AleCrossingError

    model, base, contact, x_pred, j1, j2 = crossing_pairs(lifted=True)
    loaded = (replace(contact[0], t_N=np.array([5.0, 0.0])),)
    with pytest.raises(AleCrossingError, match="would swap order"):
        mesh_motion.move_meshes(model, base, loaded, x_pred, 0.003, None)
    carried = (replace(contact[0], lambda_N=np.array([5.0, 0.0])),)  # a multiplier alone
    with pytest.raises(AleCrossingError, match="would swap order"):
        mesh_motion.move_meshes(model, base, carried, x_pred, 0.003, None)


def test_under_the_gap_law_a_lifting_pair_is_judged_by_its_gap_and_multiplier():
    """Under the gap law the traction is <lambda + eps g>: the lifted pair, predicted open,
    carries none whatever it carried at t_n unless a multiplier holds it, so it is not
    followed; with a multiplier it is pressed and the crossing is named."""
    from dataclasses import replace

    from ntncontact.ale.motion import AleCrossingError

    model, base, contact, x_pred, j1, j2 = crossing_pairs(True, 0.3, 'contact.0.law="gap"')
    was_loaded = (replace(contact[0], t_N=np.array([5.0, 0.0])),)
    motion = mesh_motion.move_meshes(model, base, was_loaded, x_pred, 0.003, None)
    assert motion.unfollowed == {(j1, int(contact[0].pairs[0, 0]))}
    held = (replace(contact[0], lambda_N=np.array([5.0, 0.0])),)
    with pytest.raises(AleCrossingError, match="would swap order"):
        mesh_motion.move_meshes(model, base, held, x_pred, 0.003, None)


def test_unfollowed_pairs_are_released_from_the_step():
    """``without_unfollowed``: the active sets less the pairs the motion does not follow,
    matched either way round (the motion keys them (ALE node, partner)); None when it
    follows them all."""
    model, base, contact, x_pred, j1, j2 = crossing_pairs(lifted=True)
    motion = mesh_motion.move_meshes(model, base, contact, x_pred, 0.003, None)
    released = mesh_motion.without_unfollowed(contact, motion.unfollowed)
    assert released is not None
    assert released[0].pairs.tolist() == [contact[0].pairs[1].tolist()]
    assert mesh_motion.without_unfollowed(contact, frozenset()) is None
    assert mesh_motion.without_unfollowed(released, motion.unfollowed) is None


def test_pressed_pairs_whose_partners_cross_still_name_the_nodes():
    """Both pairs pressed: no valid motion exists, and the error names the two ALE nodes."""
    from ntncontact.ale.motion import AleCrossingError

    model, base, contact, x_pred, j1, j2 = crossing_pairs(lifted=False)
    with pytest.raises(AleCrossingError, match="would swap order") as err:
        mesh_motion.move_meshes(model, base, contact, x_pred, 0.003, None)
    offset = model.ale_bodies[0].node_offset
    assert sorted(err.value.nodes) == sorted([j1 - offset, j2 - offset])
    assert "folds" not in str(err.value)  # 30 % of a spacing apart: not crushed


def test_partners_that_cross_on_a_crushed_surface_are_named_as_a_fold():
    """Fast sliding refined 4x with mu = 0.2 stops where the upper block's leading corner,
    held by friction, folds: its bottom nodes 30 and 32 end 2.5 % of their reference distance
    apart and pass each other. A finer ALE surface or a smaller dt (what the plain crossing
    message suggests) cannot help there; the message names the partner body's nodes, how
    crushed the surface is between them, and what to change."""
    from ntncontact.ale.motion import AleCrossingError

    model, base, contact, x_pred, j1, j2 = crossing_pairs(lifted=False, past=0.02)
    i1, i2 = (int(i) for i in contact[0].pairs[:, 0])
    with pytest.raises(AleCrossingError, match="would swap order") as err:
        mesh_motion.move_meshes(model, base, contact, x_pred, 0.003, None)
    message = str(err.value)
    apart = np.linalg.norm(x_pred[i1] - x_pred[i2]) / np.linalg.norm(model.X0[i1] - model.X0[i2])
    assert apart < 0.1
    upper = model.bodies[0].node_offset
    names = (f"nodes {i1 - upper} and {i2 - upper} of body 'upper'",
             f"nodes {i2 - upper} and {i1 - upper} of body 'upper'")
    assert any(name in message for name in names)
    assert f"are {apart:.1%} of their reference distance apart" in message
    assert "folds between them" in message and "round the corner" in message
    assert 'join it to the contact surface (for example surface_1 = "bottom+right")' in message
    assert "make body 'upper' ALE as well" in message


FINE_DISK_ON_COARSE_BLOCK = """
title = "a fine disk (spacing 0.049) lands on a coarse ALE block"
[analysis]
kind = "dynamic"
dt = 0.002
t_end = 0.1
output_interval = 0.1
[[bodies]]
name = "disk"
mesh = { type = "disk", radius = 0.5, n_circ = 64, n_radial = 3, center = [0.0, 0.51] }
material = { model = "neo_hookean", E = 1000.0, nu = 0.3, density = 1.0 }
initial = { velocity = [1.0, -1.0] }
[[bodies]]
name = "block"
mesh_motion = "ale"
mesh = { type = "rectangle", width = 3.0, height = 0.5, nx = 12, ny = 3, origin = [-1.5, -0.5] }
material = { model = "neo_hookean", E = 10000.0, nu = 0.3, density = 1.0 }
supports = [{ set = "bottom", x = 0.0, y = 0.0 }]
[[contact]]
body_1 = "disk"
surface_1 = "outer"
body_2 = "block"
surface_2 = "top"
penalty_normal = 2000.0
"""


@pytest.mark.parametrize("nx", [12, 60])
def test_nodes_between_the_pairs_are_reported_where_they_go_deeper(tmp_path, capsys, nx):
    """A disk five times finer than its ALE block (nx = 12: spacing 0.25) has nodes between
    its pairs, which nothing holds: they went 0.0118 into the block while the deepest pair
    went 0.0093, all that max_penetration reported (a tester's puck: 41 % deeper). Now
    max_penetration_unpaired reports them and the command warns; at equal spacings (nx = 60)
    they lie no deeper than the pairs and nothing is said."""
    from ntncontact.cli import main

    path = tmp_path / "disk.toml"
    path.write_text(FINE_DISK_ON_COARSE_BLOCK)
    out = tmp_path / "out"
    assert main(["run", str(path), "--out", str(out), "--quiet",
                 "--set", f"bodies.1.mesh.nx={nx}"]) == 0
    err = capsys.readouterr().err
    summary = json.loads((out / "summary.json").read_text())
    unpaired, pairs = summary["max_penetration_unpaired"], summary["max_penetration"]
    if nx == 12:
        assert unpaired > 1.2 * pairs > 0.0
        at = summary["max_penetration_unpaired_at"]
        assert at["depth"] == unpaired and at["element_size"] == pytest.approx(0.0491, rel=0.01)
        assert "in no pair, went" in err and "max_penetration_unpaired" in err
    else:
        assert unpaired <= pairs and "in no pair" not in err


@pytest.mark.parametrize("ratio", [1.0, 4.0])
def test_crossing_advice_on_spacing_only_where_the_ale_surface_is_coarser(ratio):
    """"Would swap order" advises refining the ALE surface only where it is more than 2x
    coarser than its partner: a tester's spinning ALE disk in a ring (spacings 0.098 and
    0.098) was told to refine it, where only a shorter dt helped. The motion's own message
    names dt alone (the body does not know its partner); the time loop adds the rest."""
    model = model_from_dict(sliding_block(ratio, 1.0, 0.0))
    surfaces = model.interfaces[0].interface
    block, base = int(surfaces.surface1.nodes[0]), int(surfaces.surface2.nodes[0])
    err = mesh_motion.AleCrossingError(
        "body 'base': ALE surface nodes 3 and 4 (at ...) would swap order: ... exists; "
        "shorten the time step (analysis.dt)", (3, 4))
    message = str(mesh_motion._with_spacing_advice(err, model, base, block))
    assert message.startswith(str(err))
    if ratio == 1.0:
        assert message == str(err)  # equal spacings: no refining advice
    else:
        assert "refine the ALE surface to at most 2x" in message
        assert "0.125 against 0.0312" in message
