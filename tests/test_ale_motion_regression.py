"""Regression of ``move_ale_body`` against values stored before its speed-up (Nov 2026).

The cases are moves of the ring-impact obstacle (report 6.4) recorded from the time loop at four
t_n states (every augmentation of each, same body, so the per-state caches are exercised), the
same states under other options and larger slides (interior stages, clamping, reference
respacing, linear remap, the convective-term split), and small synthetic bodies: a closed chain
without corners (annulus), a closed chain with corners, a corner chain and a graded bent block.
Stored per case: the rows whose fields changed (all other rows must equal the input bit for
bit) and the scalar diagnostics. Regenerate (only when a change of results is intended) with
``.venv/bin/python tests/test_ale_motion_regression.py``.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from ntncontact.ale.motion import AleBody, move_ale_body
from ntncontact.mesh.generators import annulus, rectangle

DATA = Path(__file__).parent / "data" / "ale_motion_regression.npz"
# round-off of a reordered evaluation (Newton iterations, arc-length quadrature) of O(1) data
REL = 1e-12
DT = 0.005
FIELDS = ("X", "d", "v", "a", "x_mesh")
STAGES = ("none", "surface", "displacement", "position")


def ring_obstacle(**options) -> AleBody:
    mesh = rectangle(4.0, 0.5, 40, 4, origin=(-2.0, -0.5))
    options = {"smoothing_layers": 1, "remap": "quadratic", "density": 20.0} | options
    return AleBody.from_mesh(mesh, "top", name="obstacle", **options)


def _ring_cases(store):
    """(name, body factory, state, calls) of the recorded ring-impact moves and variants."""
    out = []
    for k in range(int(store["ring_states"])):
        state = tuple(store[f"ring{k}_{f}"] for f in "Xdva")
        calls = [_unpack_call(store, f"ring{k}_call{j}")
                 for j in range(int(store[f"ring{k}_calls"]))]
        out.append((f"ring{k}", ring_obstacle, state, calls))
        first = calls[-1]
        h = 0.1
        for label, shift, options in (
            ("linear", 0.3, {"remap": "linear"}),
            ("position", 0.3, {"interior": "position"}),
            ("displacement", 0.6, {"interior": "displacement", "smoothing_layers": 2}),
            ("reference", 0.3, {"respace": "reference"}),
            ("convective", 0.3, {"convection": "convective_term"}),
            ("far", 2.5, {"smoothing_layers": 3}),
            ("angle", 1.2, {"smoothing": "angle", "smoothing_layers": 2}),
        ):
            active, target, pred, start, dt = first
            moved = (active, target + [shift * h, 0.0], pred, start, dt)
            out.append((f"ring{k}_{label}", lambda o=options: ring_obstacle(**o), state,
                        [moved]))
    return out


def _smooth_state(mesh, scale=1.0):
    X = mesh.nodes.copy()
    d = scale * np.column_stack([0.05 * np.sin(2.0 * X[:, 0]) * X[:, 1],
                                 -0.04 * X[:, 0] ** 2 * X[:, 1]])
    v = np.column_stack([np.sin(X[:, 0] + 2.0 * X[:, 1]), np.cos(3.0 * X[:, 0])])
    return X, d, v, 0.5 * v


def _synthetic_cases():
    out = []
    # closed chain without corners: one node slides 2.5 elements
    mesh = annulus(0.6, 1.0, 4, 48)
    state = _smooth_state(mesh, 0.3)
    x = state[0] + state[1]
    bottom = int(mesh.node_sets["bottom"][0])
    theta = 2.5 * 2 * np.pi / 48
    target = np.array([[np.sin(theta), -np.cos(theta)]]) * 1.01
    out.append(("annulus", lambda: AleBody.from_mesh(mesh, "outer"), state,
                [(np.array([bottom]), target, x[[bottom]], x[[bottom]], DT)]))
    # closed chain with corners
    rect = rectangle(2.0, 0.8, 10, 4)
    loop = np.vstack([rect.edge_sets[k] for k in ("bottom", "right", "top", "left")])
    looped = rect.with_sets(edge_sets={"loop": loop})
    state = _smooth_state(looped)
    x = state[0] + state[1]
    active = looped.node_sets["top"][[3, 7]]
    out.append(("loop", lambda: AleBody.from_mesh(looped, "loop"), state,
                [(active, x[active] + [[0.13, 0.0], [-0.21, 0.0]], x[active], x[active], DT)]))
    # corner chain: right side and top, slides past the corner clamped
    edges = np.vstack([rect.edge_sets["right"], rect.edge_sets["top"]])
    cornered = rect.with_sets(edge_sets={"right_top": edges})
    state = _smooth_state(cornered, 0.5)
    x = state[0] + state[1]
    top = cornered.node_sets["top"]
    active = top[[2, 5, -3]]
    out.append(("corner", lambda: AleBody.from_mesh(cornered, "right_top", remap="quadratic"),
                state, [(active, x[active] + [[1.0, 0.0], [0.1, 0.0], [-0.8, 0.0]], x[active],
                         x[active], DT)]))
    # graded bent block: several moves from one state (cache), one single-node move
    bent = rectangle(2.0, 0.8, 10, 4, grading_x=2.0, grading_y=0.6)
    state = _smooth_state(bent)
    x = state[0] + state[1]
    top = bent.node_sets["top"]
    active = top[[2, 5, 8]]
    pred = x[active] + DT * state[2][active]
    calls = [(active, pred + [[s * 0.07, 0.0], [s * 0.02, 0.0], [-s * 0.05, 0.0]], pred,
              x[active], DT) for s in (1.0, 1.5, 3.0)]
    calls.append((top[[4]], x[top[[4]]] + [0.03, 0.0], x[top[[4]]], x[top[[4]]], DT))
    for remap in ("linear", "quadratic"):
        out.append((f"bent_{remap}", lambda r=remap: AleBody.from_mesh(bent, "top", remap=r),
                    state, calls))
    return out


def _cases(store):
    return _ring_cases(store) + _synthetic_cases()


def _run(factory, state, calls):
    """Every call's update, all from one body (so that the t_n caches are reused)."""
    body = factory()
    return [move_ale_body(body, *state, active, target, pred, dt, start)
            for active, target, pred, start, dt in calls]


def _changed_rows(state, up):
    return np.any(np.hstack([up.X != state[0], up.d != state[1], up.v != state[2],
                             up.a != state[3]]), axis=1)


def _unpack_call(store, key):
    xy = store[f"{key}_xy"]
    return store[f"{key}_active"], xy[:, 0:2], xy[:, 2:4], xy[:, 4:6], float(xy[0, 6])


def _record(name, state, up):
    """Three arrays per update: changed and moved masks, changed rows of FIELDS, scalars."""
    rows = _changed_rows(state, up)
    info = [up.mismatch, *up.momentum_change[0], up.momentum_change[1], up.resets,
            STAGES.index(up.interior), *up.clamped]
    return {f"{name}_masks": np.vstack([rows, up.moved]),
            f"{name}_values": np.hstack([getattr(up, f)[rows] for f in FIELDS]),
            f"{name}_info": np.array(info, dtype=float)}


def _close(new, old, scale, what):
    np.testing.assert_allclose(new, old, rtol=REL, atol=REL * max(scale, 1.0), err_msg=what)


@pytest.fixture(scope="module")
def store():
    with np.load(DATA) as data:
        return dict(data)


@pytest.mark.parametrize("case", range(4 * 8 + 5))
def test_moves_equal_the_stored_ones(store, case):
    cases = _cases(store)
    assert len(cases) == 4 * 8 + 5
    name, factory, state, calls = cases[case]
    scale = max(float(np.abs(f).max()) for f in state)
    for j, (up, call) in enumerate(zip(_run(factory, state, calls), calls, strict=True)):
        key = f"{name}_{j}"
        rows, moved = store[f"{key}_masks"]
        info = store[f"{key}_info"]
        np.testing.assert_array_equal(_changed_rows(state, up), rows, err_msg=key)
        np.testing.assert_array_equal(up.moved, moved, err_msg=key)
        np.testing.assert_array_equal(up.clamped, info[6:], err_msg=key)
        assert up.interior == STAGES[int(info[5])] and up.resets == info[4], key
        for f, old in zip("Xdva", state, strict=True):  # unchanged rows bit for bit
            np.testing.assert_array_equal(getattr(up, f)[~rows], old[~rows], err_msg=key)
        np.testing.assert_array_equal(up.x_mesh[~rows], (state[0] + state[1])[~rows])
        new = np.hstack([getattr(up, f)[rows] for f in FIELDS])
        _close(new, store[f"{key}_values"], scale, key)
        dt = float(call[4])
        _close(up.mesh_velocity, (up.x_mesh - state[0] - state[1]) / dt, scale / dt, key)
        _close(up.mismatch, info[0], 1.0, f"{key} mismatch")
        _close(np.append(*up.momentum_change), info[1:4], scale**3, f"{key} momentum")


def _generate(recording: Path) -> None:
    """Write DATA: the ring states chosen from a pickled recording of the ring run, then the
    stored results of every case computed with the current code."""
    import pickle

    with open(recording, "rb") as f:
        calls = pickle.load(f)["calls"]
    groups, last = [], None
    for i, (_, args, _) in enumerate(calls):
        key = args[0].tobytes() + args[1].tobytes()
        if key != last:
            groups.append([])
            last = key
        groups[-1].append(i)
    store: dict = {"ring_states": np.array(4)}
    for k, g in enumerate((0, 60, 80, 110)):
        args = calls[groups[g][0]][1]
        for f, arr in zip("Xdva", args[:4], strict=True):
            store[f"ring{k}_{f}"] = arr
        store[f"ring{k}_calls"] = np.array(len(groups[g]))
        for j, i in enumerate(groups[g]):
            active, target, pred, dt, start = calls[i][1][4:]
            store[f"ring{k}_call{j}_active"] = active
            store[f"ring{k}_call{j}_xy"] = np.hstack([target, pred, start,
                                                      np.full((len(active), 1), dt)])
    for name, factory, state, case_calls in _cases(store):
        for j, up in enumerate(_run(factory, state, case_calls)):
            store.update(_record(f"{name}_{j}", state, up))
            print(f"{name}_{j}: {up.interior}, moved {int(up.moved.sum())}, clamped "
                  f"{up.clamped.tolist()}, resets {up.resets}")
    DATA.parent.mkdir(exist_ok=True)
    np.savez_compressed(DATA, **store)


if __name__ == "__main__":
    import sys

    _generate(Path(sys.argv[1]))
