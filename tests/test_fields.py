"""Fields of a VTU frame (issue 20 §1): stress and strain per cell and node, contact-node fields,
mesh velocity and material positions."""

from __future__ import annotations

import shutil

import meshio
import numpy as np
import pandas as pd
import pytest
from helpers import EXAMPLES, model_from_dict

from ntncontact import api
from ntncontact.engine.postprocess import frame_fields, mesh_velocity, stress_fields
from ntncontact.fem.q4 import InvertedElementError
from ntncontact.io.vtk import read_pvd, read_vtu

P = 7.0  # applied pressure


def _block(kind: str, grading: float = 1.0, plane_stress: bool = False) -> dict:
    """A 2 x 1 block on rollers (bottom y, left x) under a uniform pressure on top: a uniform
    uniaxial stress state, exact for any mesh of the block."""
    return {
        "analysis": {"kind": "static", "dt": 0.5, "t_end": 1.0},
        "bodies": [{
            "name": "block",
            "mesh": {"type": "rectangle", "width": 2.0, "height": 1.0, "nx": 5, "ny": 4,
                     "grading_x": grading, "grading_y": 1.0 / grading},
            "material": {"model": kind, "E": 100.0, "nu": 0.3, "density": 1.0,
                         "plane_stress": plane_stress},
            "supports": [{"set": "bottom", "y": 0.0}, {"set": "left", "x": 0.0}],
            "loads": [{"type": "pressure", "set": "top", "value": P,
                       "function": {"times": [0.0, 1.0], "values": [0.0, 1.0]}}],
        }],
    }


def _last_frame(folder):
    (time, path), = read_pvd(folder / "fields.pvd")[-1:]
    return read_vtu(path, time)


def _run(tmp_path, data: dict):
    return api.run(api.scenario_from_dict(data), out=tmp_path / "out")


@pytest.mark.parametrize("grading", [1.0, 3.0])
def test_uniform_pressure_gives_the_exact_stress_in_every_cell_and_node(tmp_path, grading):
    _run(tmp_path, _block("linear_elastic", grading))
    frame = _last_frame(tmp_path / "out")
    nu = 0.3
    # plane strain: sigma_zz = nu (sigma_xx + sigma_yy)
    exact = np.array([0.0, -P, -nu * P, 0.0, 0.0, 0.0])
    scale = 1e-9 * P
    for stress in (frame.cell_data["stress"], frame.point_data["stress_nodal"]):
        assert np.abs(stress - exact).max() < scale
    pressure = -(exact[0] + exact[1] + exact[2]) / 3.0
    s = exact
    vm = np.sqrt(0.5 * ((s[0] - s[1]) ** 2 + (s[1] - s[2]) ** 2 + (s[2] - s[0]) ** 2))
    for name in ("pressure", "von_mises"):
        value = pressure if name == "pressure" else vm
        assert np.abs(frame.cell_data[name] - value).max() < scale
        assert np.abs(frame.point_data[f"{name}_nodal"] - value).max() < scale
    # the Green-Lagrange strain of the uniform displacement field, from the displacements
    u = frame.point_data["displacement"]
    X = frame.points
    exx = np.polyfit(X[:, 0], u[:, 0], 1)[0]
    eyy = np.polyfit(X[:, 1], u[:, 1], 1)[0]
    strain = frame.cell_data["strain"]
    assert np.allclose(strain[:, 0], exx + 0.5 * exx**2, rtol=1e-9, atol=0)
    assert np.allclose(strain[:, 1], eyy + 0.5 * eyy**2, rtol=1e-9, atol=0)
    assert np.abs(strain[:, 2]).max() == 0.0  # plane strain: E_zz = 0
    assert np.abs(strain[:, 3:]).max() < 1e-12 * abs(eyy)
    assert np.allclose(frame.point_data["strain_nodal"], strain[0], rtol=1e-9, atol=1e-15)
    assert np.array_equal(frame.point_data["material_position"], frame.points)


def test_neo_hookean_block_carries_the_pressure_over_its_current_width(tmp_path):
    _run(tmp_path, _block("neo_hookean", grading=2.0))
    frame = _last_frame(tmp_path / "out")
    x = frame.deformed_points
    width = np.ptp(x[:, 0])  # the dead load P on the reference width 2: force 2 P
    sigma_yy = -P * 2.0 / width
    stress = frame.cell_data["stress"]
    assert width > 2.0 + 1e-3  # the block widens: a case that tells Cauchy from nominal stress
    assert np.allclose(stress[:, 1], sigma_yy, rtol=1e-9, atol=0)
    assert np.abs(stress[:, [0, 3]]).max() < 1e-9 * P
    assert np.allclose(frame.point_data["stress_nodal"][:, 1], sigma_yy, rtol=1e-9, atol=0)


@pytest.mark.parametrize("kind", ["neo_hookean", "linear_elastic"])
def test_rigid_rotation_gives_zero_strain_and_neo_hookean_zero_stress(kind):
    model = model_from_dict(_block(kind, grading=2.0))
    X = model.X0
    angle = 1.1
    R = np.array([[np.cos(angle), -np.sin(angle)], [np.sin(angle), np.cos(angle)]])
    x = X @ R.T + np.array([3.0, -2.0])
    cell, nodal = stress_fields(model, X, x)
    assert np.abs(cell["strain"]).max() < 1e-14
    assert np.abs(nodal["strain_nodal"]).max() < 1e-14
    if kind == "neo_hookean":  # linear elasticity is not objective (docs/outputs.md)
        E = 100.0
        for data in (cell, nodal):
            for name, value in data.items():
                assert np.abs(value).max() < 1e-12 * E, name
    else:
        assert np.abs(cell["stress"]).max() > 1.0  # the small-strain stress of a rotation


def test_plane_stress_has_no_out_of_plane_stress_and_its_strain():
    model = model_from_dict(_block("linear_elastic", plane_stress=True))
    X = model.X0
    x = X * np.array([1.0 + 1e-3, 1.0 - 2e-3])
    cell, _ = stress_fields(model, X, x)
    assert np.abs(cell["stress"][:, 2]).max() == 0.0
    nu = 0.3
    exx, eyy = cell["strain"][0, 0], cell["strain"][0, 1]
    assert np.allclose(cell["strain"][:, 2], -nu / (1.0 - nu) * (exx + eyy), rtol=1e-12)


def test_mesh_velocity_of_a_node_that_changes_particle():
    v = np.array([[1.0, 2.0]])
    F = np.array([[[2.0, 0.0], [0.5, 1.0]]])
    X, X_before = np.array([[0.3, 0.0]]), np.array([[0.1, 0.0]])
    # x_node = phi(X(t), t): w = v + F dX/dt = (1, 2) + F (2, 0)
    assert np.allclose(mesh_velocity(v, X, X_before, 0.1, F), [[5.0, 3.0]], rtol=1e-14)
    assert np.array_equal(mesh_velocity(v, X, X, 0.1, F), v)


def test_frame_fields_give_the_nodal_deformation_gradient_of_the_bodies_asked_for():
    """The mesh velocity's F comes from the stress's kinematics: under an affine map x = A X
    it is A at every node of the bodies asked for (on a graded mesh, whose cells differ),
    and the stress fields are those of stress_fields."""
    model = model_from_dict(_block("neo_hookean", grading=1.5))
    A = np.array([[1.02, 0.3], [-0.1, 0.97]])
    X = model.X0
    x = X @ A.T
    cell, nodal, F = frame_fields(model, X, x - X, [0])
    assert np.allclose(F, A, rtol=0.0, atol=1e-14)
    reference = stress_fields(model, X, x)
    for got, want in ((cell, reference[0]), (nodal, reference[1])):
        assert all(np.array_equal(got[name], want[name]) for name in want)
    assert frame_fields(model, X, x - X)[2] is None  # no body asked for: no F


def _two_blocks(kind_1: str, kind_2: str, plane_stress: bool) -> dict:
    """Two blocks of different materials side by side (no contact: only their fields)."""
    data = _block(kind_1, grading=1.5, plane_stress=plane_stress)
    other = _block(kind_2, plane_stress=plane_stress)["bodies"][0]
    other |= {"name": "other", "material": other["material"] | {"E": 250.0, "nu": 0.4}}
    other["mesh"] = other["mesh"] | {"origin": [3.0, 0.0]}
    return data | {"bodies": data["bodies"] + [other]}


@pytest.mark.parametrize("kinds, plane_stress", [
    (("neo_hookean", "linear_elastic"), False),
    (("linear_elastic", "neo_hookean"), False),
    (("linear_elastic", "linear_elastic"), True),
])
def test_compiled_cell_fields_match_the_numpy_oracle_on_a_distorted_deformed_mesh(
        kinds, plane_stress):
    """frame_fields (the compiled cell_fields kernel, stress from the element kernel's law in
    H) against tests/element_oracle.py (F from the positions, Cauchy stress in F's closed
    forms), body by body, on distorted reference cells under a finite rotation (0.4 rad) and
    random strains of ~10 %: the same quantities in other orders of operation, so they agree
    to the round-off of O(1) stresses, ~1e-14 of the largest value; 1e-11 leaves room and
    still fails on a wrong sign, weight or component."""
    import element_oracle as oracle

    model = model_from_dict(_two_blocks(*kinds, plane_stress))
    rng = np.random.default_rng(7)
    X = model.X0 + 0.06 * rng.uniform(-1.0, 1.0, model.X0.shape)  # h = 0.25-0.4
    c, s = np.cos(0.4), np.sin(0.4)
    x = (X + 0.025 * rng.standard_normal(X.shape)) @ np.array([[c, -s], [s, c]]).T
    cell, nodal, F_nodal = frame_fields(model, X, x - X, [0, 1])
    F_want = np.zeros((len(X), 2, 2))
    for body in model.bodies:
        cells, mat = model.cells[body.cells], body.material
        want = oracle.cell_fields(mat.kind, X[cells], x[cells], mat.effective_lambda, mat.mu,
                                  plane_stress)
        for name in ("stress", "strain"):
            got = cell[name][body.cells]
            assert np.all(got[:, 4:] == 0.0)
            assert np.abs(got[:, :4] - want[name]).max() < 1e-11 * np.abs(want[name]).max()
        for name in ("von_mises", "pressure"):
            error = np.abs(cell[name][body.cells] - want[name][:, 0]).max()
            assert error < 1e-11 * np.abs(want[name]).max()
        reference_area = oracle.reference_gradients(X[cells])[1].sum(axis=1)
        nodes = cells.ravel()
        total = np.bincount(nodes, np.repeat(reference_area, 4), minlength=len(X))
        for i, j in np.ndindex(2, 2):
            share = np.repeat(reference_area * want["F"][:, i, j], 4)
            F_want[np.unique(cells), i, j] = (np.bincount(nodes, share, minlength=len(X))
                                              / np.maximum(total, 1e-300))[np.unique(cells)]
        # the nodal stress: current-area averages of the cells around each node
        share = np.repeat(want["area"], 4)
        node_area = np.bincount(nodes, share, minlength=len(X))[np.unique(cells)]
        yy = np.bincount(nodes, share * np.repeat(want["stress"][:, 1], 4), minlength=len(X))
        got = nodal["stress_nodal"][np.unique(cells), 1]
        want_yy = yy[np.unique(cells)] / node_area
        assert np.abs(got - want_yy).max() < 1e-11 * np.abs(want_yy).max()
    assert np.abs(F_nodal - F_want).max() < 1e-13


def test_a_stiff_body_far_from_the_origin_keeps_the_digits_of_its_stress():
    """Hertz's foundation in miniature: E = 2e8 at |X| ~ 400 under a strain of 1e-6. The fields
    take d, as the internal force does: the uniform stress to 1e-12 (from positions x = X + d,
    eps |x| / h ~ 2e-13 of round-off in the strain was ~1e-7 of this stress)."""
    data = _block("linear_elastic")
    data["bodies"][0]["material"] |= {"E": 2e8}
    data["bodies"][0]["mesh"] |= {"origin": [400.0, -300.0]}
    model = model_from_dict(data)
    X = model.X0
    strain = np.array([[1e-6, 3e-7], [3e-7, -2e-6]])
    cell, _, _ = frame_fields(model, X, (X - X.mean(axis=0)) @ strain.T)
    mat = model.bodies[0].material
    lam, mu = mat.effective_lambda, mat.mu
    tr = np.trace(strain)
    exact = [lam * tr + 2 * mu * strain[0, 0], lam * tr + 2 * mu * strain[1, 1], lam * tr,
             2 * mu * strain[0, 1]]
    assert np.abs(cell["stress"][:, :4] - exact).max() < 1e-12 * np.abs(exact).max()


def test_an_inverted_reference_cell_is_named_by_the_fields():
    model = model_from_dict(_block("neo_hookean"))
    X = model.X0.copy()
    cells = model.cells
    X[cells[7, [0, 2]]] = X[cells[7, [2, 0]]]  # two opposite corners swapped: inverted
    with pytest.raises(InvertedElementError, match="element 7 is inverted in the reference"):
        stress_fields(model, X, X)


def test_contact_node_fields_match_the_contact_rows_of_the_same_step(tmp_path):
    scenario = api.load_scenario(EXAMPLES / "block_sliding.toml",
                                 {"analysis.t_end": 1.5, "analysis.output_interval": 0.5})
    results = api.run(scenario, out=tmp_path / "out")
    contact = results.contact
    checked = 0
    for time, path in read_pvd(tmp_path / "out" / "fields.pvd")[1:]:
        frame = read_vtu(path, time)
        rows = contact[np.isclose(contact["time"], time, rtol=0, atol=1e-12)]
        assert len(rows)
        p = frame.point_data
        nodes = rows["node_1"].to_numpy()
        assert np.allclose(p["contact_pressure"][nodes], rows["normal_traction"], rtol=1e-12)
        assert np.allclose(p["contact_tangential_traction"][nodes], rows["tangential_traction"],
                           rtol=1e-12, atol=1e-12 * P)
        assert np.allclose(p["contact_gap"][nodes], rows["gap"], rtol=1e-12, atol=1e-300)
        assert np.allclose(p["contact_gap_rate"][nodes], rows["gap_rate"], rtol=1e-12,
                           atol=1e-300, equal_nan=True)  # NaN: quasi-static
        status = np.where(rows["status"] == "slip", 2, 1)
        assert np.array_equal(p["contact_status"][nodes], status)
        assert np.array_equal(p["contact_partner"][nodes], rows["node_2"])
        others = np.setdiff1d(np.arange(len(frame.points)), nodes)
        assert np.all(p["contact_partner"][others] == -1)
        assert np.all(p["contact_status"][others] == 0)
        assert not np.any(p["contact_pressure"][others])
        # the mesh points are the material positions, which move on the ALE foundation
        assert np.array_equal(p["material_position"], frame.points)
        checked += 1
    assert checked == 3
    assert isinstance(contact, pd.DataFrame)


@pytest.fixture(scope="module")
def vtu_and_xdmf_runs(tmp_path_factory):
    """Block sliding (its foundation's ALE mesh moves) written as VTU frames and as XDMF."""
    folder = tmp_path_factory.mktemp("formats")
    overrides = {"analysis.t_end": 1.25, "analysis.output_interval": 0.5}
    for fmt in ("vtu", "xdmf"):
        scenario = api.load_scenario(EXAMPLES / "block_sliding.toml",
                                     overrides | {"analysis.field_format": fmt})
        api.run(scenario, out=folder / fmt)
    return folder / "vtu", folder / "xdmf"


def test_results_fields_of_an_xdmf_run_are_the_meshes_of_the_vtu_run(vtu_and_xdmf_runs):
    vtu, xdmf = (api.read_results(folder) for folder in vtu_and_xdmf_runs)
    assert not (vtu_and_xdmf_runs[1] / "fields.pvd").exists()
    assert len(xdmf.times) == 4  # t = 0, 0.5, 1.0 and the end
    assert xdmf.times == pytest.approx(vtu.times, rel=0, abs=1e-12)
    for t in vtu.times:
        a, b = vtu.fields(t), xdmf.fields(t)
        assert a.points.shape == b.points.shape
        assert np.allclose(a.points, b.points, rtol=0, atol=1e-12)
        assert [c.type for c in a.cells] == [c.type for c in b.cells] == ["quad"]
        assert np.array_equal(a.cells[0].data, b.cells[0].data)
        assert set(a.point_data) == set(b.point_data)
        assert set(a.cell_data) == set(b.cell_data)
        for name, value in a.point_data.items():
            assert np.allclose(value, b.point_data[name], rtol=0, atol=1e-12,
                               equal_nan=True), name
        for name, blocks in a.cell_data.items():
            assert np.allclose(blocks[0], b.cell_data[name][0], rtol=0, atol=1e-12), name
    moved = np.abs(vtu.fields(vtu.times[-1]).points - vtu.fields(0.0).points).max()
    assert moved > 1e-6  # the ALE foundation's material positions did move


def test_xdmf_frames_read_back_as_the_vtu_frames(vtu_and_xdmf_runs):
    import meshio

    from ntncontact.io.vtk import read_xdmf

    folder_vtu, folder_xdmf = vtu_and_xdmf_runs
    vtu = [read_vtu(path, t) for t, path in read_pvd(folder_vtu / "fields.pvd")]
    xdmf = read_xdmf(folder_xdmf / "fields.xdmf")
    assert [f.time for f in xdmf] == pytest.approx([f.time for f in vtu], abs=1e-12)
    for a, b in zip(vtu, xdmf, strict=True):
        assert np.array_equal(a.cells, b.cells) and np.array_equal(a.points, b.points)
        assert set(a.point_data) == set(b.point_data) and set(a.cell_data) == set(b.cell_data)
        for name, value in a.point_data.items():
            assert np.array_equal(value, b.point_data[name], equal_nan=True), name
        for name, value in a.cell_data.items():
            assert np.array_equal(value, b.cell_data[name]), name
    # in the file, the mesh is stored once and node_displacement puts every node where it is
    with meshio.xdmf.TimeSeriesReader(folder_xdmf / "fields.xdmf") as reader:
        stored, _ = reader.read_points_cells()
        _, point_data, _ = reader.read_data(reader.num_steps - 1)
    current = stored[:, :2] + point_data["node_displacement"][:, :2]
    assert np.allclose(current, vtu[-1].deformed_points, rtol=0, atol=1e-12)


def test_the_figures_of_an_xdmf_run_are_those_of_the_vtu_run(vtu_and_xdmf_runs, tmp_path):
    from ntncontact.cli import main
    from ntncontact.report.plotting import frames_at, plot_all

    made = {}
    for folder in vtu_and_xdmf_runs:
        copy = tmp_path / folder.name  # the figures go into the folder: keep the fixture's
        shutil.copytree(folder, copy)
        made[folder.name] = sorted(p.name for p in plot_all(copy, times=[0.75], gif=True))
        assert main(["plot", str(copy)]) == 0
    assert made["xdmf"] == made["vtu"]
    assert {"snapshots.png", "animation.gif", "pair_history.png"} <= set(made["xdmf"])
    # an interpolated state between two XDMF frames is the VTU run's
    (a, between_a), (b, between_b) = (frames_at(folder, [0.75])[0]
                                      for folder in vtu_and_xdmf_runs)
    assert between_a and between_b
    assert np.array_equal(a.deformed_points, b.deformed_points)
    assert np.array_equal(a.cell_data["von_mises"], b.cell_data["von_mises"])


def test_a_damaged_xdmf_index_is_reported_naming_the_file(tmp_path):
    from ntncontact.report.plotting import ResultsNotFoundError, load_frames

    (tmp_path / "fields.xdmf").write_text("<Xdmf Version='3.0'><Domain/></Xdmf>")
    with pytest.raises(ResultsNotFoundError, match=r"fields.xdmf is not a readable XDMF"):
        load_frames(tmp_path)


def test_an_unknown_field_format_is_refused_naming_the_key():
    data = _block("linear_elastic")
    data["analysis"]["field_format"] = "hdf5"
    with pytest.raises(api.ScenarioError, match="field_format"):
        api.scenario_from_dict(data)


def test_the_docs_figure_script_plots_the_contact_pressure_of_the_frames(tmp_path, monkeypatch):
    import importlib.util
    import sys

    script = EXAMPLES.parent / "docs" / "contact_pressure_figure.py"
    spec = importlib.util.spec_from_file_location("contact_pressure_figure", script)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    scenario = api.load_scenario(EXAMPLES / "block_sliding.toml", {"analysis.t_end": 0.5})
    results = api.run(scenario, out=tmp_path / "out")
    time, path = read_pvd(tmp_path / "out" / "fields.pvd")[-1]
    x, p = module.pressure_along_surface(read_vtu(path, time))
    rows = results.contact[np.isclose(results.contact["time"], time, rtol=0, atol=1e-12)]
    assert np.all(np.diff(x) > 0) and len(x) == len(rows)
    assert np.allclose(np.sort(p), np.sort(rows["normal_traction"]), rtol=1e-12)
    figure = tmp_path / "figure.png"
    monkeypatch.setattr(sys, "argv", ["x", str(tmp_path / "out"), str(figure), "--frames", "2"])
    module.main()
    assert figure.stat().st_size > 10_000


def test_xdmf_without_h5py_stops_before_writing_any_file(tmp_path, monkeypatch):
    import sys

    monkeypatch.setitem(sys.modules, "h5py", None)  # import h5py raises ImportError
    data = _block("linear_elastic")
    data["analysis"]["field_format"] = "xdmf"
    with pytest.raises(RuntimeError, match=r"needs h5py: pip install 'ntncontact\[xdmf\]'"):
        api.run(api.scenario_from_dict(data), out=tmp_path / "out")
    assert not [p.name for p in (tmp_path / "out").iterdir() if p.suffix in (".csv", ".json")]


def test_frames_give_each_node_its_number_in_the_mesh_file(tmp_path):
    """Outputs number the nodes 0..n-1 over all bodies; a gmsh user could not find such a node
    in the file. The frames' ``file_node_id`` gives the file's number (node 1 unused and
    dropped here, so the block's nodes are 2..7) and -1 for a generated body's nodes."""
    points = np.array([[9, 9, 0], [0, 0, 0], [1, 0, 0], [2, 0, 0], [0, 1, 0], [1, 1, 0],
                       [2, 1, 0]], dtype=float)
    mesh = meshio.Mesh(points, [("quad", np.array([[1, 2, 5, 4], [2, 3, 6, 5]])),
                                ("line", np.array([[1, 2], [2, 3]]))],
                       cell_data={"gmsh:physical": [np.array([1, 1]), np.array([2, 2])],
                                  "gmsh:geometrical": [np.array([1, 1]), np.array([1, 1])]},
                       field_data={"body": np.array([1, 2]), "bottom": np.array([2, 1])})
    meshio.write(tmp_path / "block.msh", mesh, file_format="gmsh22", binary=False)
    data = _block("linear_elastic")
    data["bodies"][0]["mesh"] = {"type": "rectangle", "width": 1.0, "height": 1.0, "nx": 1,
                                 "ny": 1, "origin": [5.0, 0.0]}
    data["bodies"].append({
        "name": "read", "mesh": {"type": "gmsh", "file": str(tmp_path / "block.msh")},
        "material": {"model": "linear_elastic", "E": 100.0, "nu": 0.3, "density": 1.0},
        "supports": [{"set": "bottom", "x": 0.0, "y": 0.0}]})
    _run(tmp_path, data)
    ids = _last_frame(tmp_path / "out").point_data["file_node_id"]
    assert ids.dtype.kind == "i"  # node numbers, as contact_partner (it was float64)
    assert ids.tolist() == [-1] * 4 + [2, 3, 4, 5, 6, 7]
