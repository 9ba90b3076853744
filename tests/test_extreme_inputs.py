"""Errors at extreme inputs say where and why (tester W, findings 5, 6, 8 and 10): an undefined
contact normal names its interface, bodies, nodes and step; NumPy's floating-point warnings
reach the user as one line naming the step, not raw; an overflowing element is "not finite",
not "inverted" with det J = +1; a frame that cannot be written stops the run at its step; a
matrix singular by its scale says so; and a friction coefficient above any measured one is
warned of."""

from __future__ import annotations

import errno
import json
import warnings
from pathlib import Path

import numpy as np
import pytest
from helpers import EXAMPLES, model_from_dict

from ntncontact.cli import main
from ntncontact.engine.diagnostics import PhysicsWarning
from ntncontact.engine.simulation import FloatingPointErrors
from ntncontact.fem.kernels_numba import _raise_inverted
from ntncontact.fem.q4 import InvertedElementError, NonFiniteElementError
from ntncontact.io import vtk
from ntncontact.io.vtk import read_pvd
from ntncontact.io.writers import read_csv_table

ROD = EXAMPLES / "rod_impact.toml"
RING = EXAMPLES / "ring_impact.toml"


def run_cli(out: Path, scenario: Path, *sets: str) -> int:
    args = ["run", str(scenario), "--out", str(out), "--quiet"]
    for item in sets:
        args += ["--set", item]
    return main(args)


def summary(out: Path) -> dict:
    return json.loads((out / "summary.json").read_text())


def test_an_undefined_contact_normal_names_interface_bodies_nodes_and_step(tmp_path, capsys):
    """A rod of zero height: its contact chain's neighbours coincide. The message named
    nothing ("a contact normal is undefined (coincident chain neighbours)") and two raw NumPy
    lines ("warning: divide by zero encountered in divide") came before it."""
    rc = run_cli(tmp_path / "rod", ROD, "bodies.1.mesh.height=1e-300")
    err = capsys.readouterr().err
    assert rc == 1
    assert "step 1 (t = 0 -> " in err and "interface 'rod_ends'" in err
    assert "node 0 of body 'rod_right'" in err and "coincide at (0, 0)" in err
    assert "encountered in" not in err  # NumPy's own warning lines
    assert "interface 'rod_ends'" in summary(tmp_path / "rod")["error"]


def test_an_overflowing_configuration_is_not_called_inverted(tmp_path, capsys):
    """A ring thrown at 1e300: the kernel's det F overflowed, and the message read "inverted
    in the current configuration (det J = 1.000e+00)", after two raw NumPy overflow lines."""
    rc = run_cli(tmp_path / "ring", RING, "bodies.0.initial.velocity=[1e300, -1.0]",
                 "analysis.t_end=0.01")
    err = capsys.readouterr().err
    assert rc == 1
    assert "element 0 of body 'ring'" in err and "not finite" in err
    assert "inverted" not in err and "encountered in" not in err


def test_a_non_finite_element_is_told_apart_from_an_inverted_one():
    X = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])
    cells = np.array([[0, 1, 2, 3]])
    huge = np.full((4, 2), 0.0)
    huge[:, 0] = [5e297, 5e297 * (1 + 1e-15), 5e297, 5e297]  # F = I + O(1e282): overflows
    with pytest.raises(NonFiniteElementError, match="not finite"):
        _raise_inverted(0, 2, X, [huge], cells)
    with pytest.raises(NonFiniteElementError, match="not finite"):
        _raise_inverted(0, 2, X, [np.full((4, 2), np.nan)], cells)
    flipped = np.array([[0.0, 0.0], [-2.0, 0.0], [-2.0, 0.0], [0.0, 0.0]])  # x -> -x
    with pytest.raises(InvertedElementError) as caught:
        _raise_inverted(0, 2, X, [flipped], cells)
    assert not isinstance(caught.value, NonFiniteElementError)
    assert caught.value.value < 0.0
    named = NonFiniteElementError(3, 1e300, "current configuration").named("element 1 of ring")
    assert named.startswith("element 1 of ring has a current")


def test_numpy_floating_point_errors_become_one_warning_naming_the_step():
    errors = FloatingPointErrors()
    with errors.recording(), warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        mark = errors.mark()
        np.array([1.0]) / np.array([0.0])  # a failed sub-step's: dropped
        errors.drop_since(mark)
        errors.tell(2, 0.1, 0.2)
        np.array([1e300]) * np.array([1e300])
        errors.tell(3, 0.2, 0.3)
        np.array([1e300]) * np.array([1e300])
        errors.tell(4, 0.3, 0.4)  # once a run
    lines = [str(w.message) for w in caught]
    assert len(lines) == 1, lines
    assert lines[0].startswith("step 3 (t = 0.2 -> 0.3): NumPy met floating-point errors "
                               "(overflow; 1 in the step)")


def test_a_frame_that_cannot_be_written_stops_the_run_at_its_step(tmp_path, monkeypatch, capsys):
    """A file-size limit failed the frame of step 15 (written in the background); the run
    went on to step 20, whose frame write raised it, and the summary said steps 20. Here the
    writer fails from the third frame (step 10) on, as a full disk does."""
    calls = []
    real = vtk.meshio.write

    def write(path, mesh, **kwargs):
        calls.append(path)
        if len(calls) >= 3:
            raise OSError(errno.EFBIG, "File too large")
        real(path, mesh, **kwargs)

    monkeypatch.setattr(vtk.meshio, "write", write)
    out = tmp_path / "spin"
    rc = run_cli(out, EXAMPLES / "spinning_block.toml", "analysis.t_end=0.4")
    err = capsys.readouterr().err
    assert rc == 1
    assert "File too large (the frame of step 10, t = 0.2" in err
    assert "fields_00010.vtu" in err and "the last frame written is t = 0.1" in err
    done = summary(out)
    assert done["status"] == "failed" and (done["steps"], done["time"]) == (10, 0.2)
    assert read_csv_table(out / "history.csv")["step"].max() == 10  # no step past it
    assert [round(t, 9) for t, _ in read_pvd(out / "fields.pvd")] == [0.0, 0.1]


@pytest.mark.parametrize(("key", "cause"), [
    ("bodies.0.material.E=1e300", "out of the floating-point range, pivots up to 1."),
    ("contact.0.penalty_normal=1e300", "out of the floating-point range, pivots up to 3."),
    ("bodies.0.material.density=1e-300", "body 'rod_left' has an inertia (density h^2/dt^2 "),
])
def test_a_matrix_singular_by_its_scale_says_so(tmp_path, capsys, key, cause):
    """E, a penalty or a density out of range were reported as "a body whose supports leave a
    rigid motion free"."""
    assert run_cli(tmp_path / "rod", ROD, key, "analysis.t_end=0.1") == 1
    err = capsys.readouterr().err
    assert "matrix is numerically singular" in err and cause in err
    if "density" not in key:
        assert "rigid motion free" not in err


def test_a_friction_coefficient_above_any_measured_one_is_warned_of():
    def build_warnings(mu: float) -> list[str]:
        data = {"analysis": {"kind": "static", "dt": 0.5, "t_end": 1.0},
                "bodies": [
                    {"name": name, "mesh": {"type": "rectangle", "width": 1.0, "height": 1.0,
                                            "nx": 2, "ny": 2, "origin": [0.0, y]},
                     "material": {"model": "linear_elastic", "E": 100.0, "nu": 0.3,
                                  "density": 1.0},
                     "supports": [{"set": "bottom", "x": 0.0, "y": 0.0}]}
                    for name, y in (("top", 1.0), ("base", 0.0))],
                "contact": [{"name": "c", "body_1": "top", "surface_1": "bottom",
                             "body_2": "base", "surface_2": "top", "friction": mu,
                             "penalty_normal": 100.0, "penalty_tangential": 100.0}]}
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            model_from_dict(data)
        return [str(w.message) for w in caught if issubclass(w.category, PhysicsWarning)]

    assert not [w for w in build_warnings(0.5) if "friction =" in w]
    warned = [w for w in build_warnings(1e300) if "friction =" in w]
    assert warned == ["contact.0 ('c'): friction = 1e+300 is a Coulomb coefficient far above "
                      "any measured one (dry friction stays below ~1.5; above 10 is warned "
                      "of): the pairs stick whatever the load; is it a percentage or an "
                      "angle?"]
