"""``ale.smoothing`` and ``ale.sweeps`` with ``ale.interior = "displacement"`` (tester X,
finding 6: bit-identical runs for the three rules and for sweeps 0 vs 10). They are not
ineffective there: they are the position smoothing's, stage (c) of ale/motion.py, which
"displacement" (as "minimal") runs only where the diffused surface move (b) leaves a cell
below its quality floor. So the build must not call them ineffective, and docs/scenarios.md
says when they act. Measured on a slide with max_stretch = 4 in "displacement" mode: the
base's smallest angle 22.4 deg with "laplacian", 1.1 deg with "angle"."""

import copy
import warnings

import numpy as np
import pytest

from ntncontact import api
from ntncontact.ale.example_mesh_motion import layer_mesh
from ntncontact.ale.motion import AleBody, move_ale_body
from ntncontact.engine.builder import _warn_ineffective_keys as warn_ineffective_keys

DT = 0.01


def slide(shift: float, **options):
    """Two top nodes of a thin-topped layer mesh (top row 0.04 high, 0.1 wide) slid by
    ``shift``; the update of ale.motion with ``options``."""
    mesh = layer_mesh(width=2.0, height=0.4, nx=20, ny=6, jitter=0.0)
    X = mesh.nodes.copy()
    zero = np.zeros_like(X)
    body = AleBody.from_mesh(mesh, "top", interior="displacement", **options)
    active = body.surface[[9, 10]]
    x_pred = X[active]
    return move_ale_body(body, X, zero, zero, zero, active, x_pred + [-shift, 0.0], x_pred, DT)


def test_displacement_mode_reads_smoothing_and_sweeps_where_the_diffused_move_is_not_enough():
    """A slide of three cell widths: the diffused move spoils the thin cells, stage (c) runs,
    and the rule and the sweeps change the mesh."""
    laplacian, angle = slide(0.3, smoothing="laplacian"), slide(0.3, smoothing="angle")
    assert laplacian.interior == angle.interior == "position"
    assert np.abs(laplacian.x_mesh - angle.x_mesh).max() > 1e-3
    assert np.abs(slide(0.3, sweeps=3).x_mesh - laplacian.x_mesh).max() > 1e-6
    # sweeps = 0 turns stage (c) off: the diffused move is kept whatever its quality
    assert slide(0.3, sweeps=0).interior == "displacement"


def test_displacement_mode_ignores_them_where_the_diffused_move_suffices():
    """A small slide: stage (b) is enough and the three rules give the same mesh bit for bit
    (tester X's free block, where this held at every update)."""
    outs = [slide(0.01, smoothing=rule, sweeps=sweeps)
            for rule in ("laplacian", "angle", "weighted_angle") for sweeps in (0, 10)]
    assert all(out.interior == "displacement" for out in outs)
    for out in outs[1:]:
        np.testing.assert_array_equal(out.x_mesh, outs[0].x_mesh)


ALE_BASE = {
    "analysis": {"kind": "dynamic", "dt": 0.01, "t_end": 0.02},
    "bodies": [
        {"name": "block", "mesh": {"type": "rectangle", "width": 1.0, "height": 0.5, "nx": 4,
                                   "ny": 2, "origin": [0.5, 0.0]},
         "material": {"model": "neo_hookean", "E": 1000.0, "nu": 0.3, "density": 1.0}},
        {"name": "base", "mesh_motion": "ale",
         "mesh": {"type": "rectangle", "width": 2.0, "height": 0.5, "nx": 8, "ny": 2,
                  "origin": [0.0, -0.5]},
         "material": {"model": "neo_hookean", "E": 1000.0, "nu": 0.3, "density": 1.0},
         "supports": [{"set": "bottom", "x": 0.0, "y": 0.0}]}],
    "contact": [{"name": "c", "body_1": "block", "surface_1": "bottom", "body_2": "base",
                 "surface_2": "top", "penalty_normal": 1e4}],
}


@pytest.mark.parametrize("interior", ["minimal", "displacement", "position"])
def test_the_build_does_not_call_smoothing_or_sweeps_ineffective(interior):
    """Every interior mode can reach the position smoothing, so no mode's build warns of
    them as keys without effect (their docs say when they act)."""
    data = copy.deepcopy(ALE_BASE)
    data["bodies"][1]["ale"] = {"interior": interior, "smoothing": "angle", "sweeps": 0}
    config = api.scenario_from_dict(data).config
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        warn_ineffective_keys(config)
    assert not [w for w in caught if "smoothing" in str(w.message) or "sweeps" in
                str(w.message)]
