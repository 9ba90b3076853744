"""XDMF series: tensors stored as full 3x3 XDMF ``Tensor`` arrays (meshio labelled VTK's 6
components ``Tensor6``, whose XDMF order differs: ParaView's "XDMF Reader" showed sigma_yy as
sigma_xy), read back in the VTU frames' 6-component layout; ``read_xdmf`` of a results folder."""

from __future__ import annotations

import re

import numpy as np
import pytest

from ntncontact import api
from ntncontact.io.vtk import XdmfSeriesWriter, read_pvd, read_vtu, read_xdmf, symmetric_tensor

h5py = pytest.importorskip("h5py")

P = 7.0  # applied pressure
NU = 0.3


def _pressed_block(field_format: str) -> dict:
    """A 2 x 1 block on rollers (bottom y, left x) pressed on top: sigma_xx = 0,
    sigma_yy = -P, sigma_zz = -nu P (plane strain), sigma_xy = 0 in every cell and node."""
    return {
        "analysis": {"kind": "static", "dt": 0.5, "t_end": 1.0, "field_format": field_format},
        "bodies": [{
            "name": "block",
            "mesh": {"type": "rectangle", "width": 2.0, "height": 1.0, "nx": 4, "ny": 2},
            "material": {"model": "linear_elastic", "E": 100.0, "nu": NU, "density": 1.0},
            "supports": [{"set": "bottom", "y": 0.0}, {"set": "left", "x": 0.0}],
            "loads": [{"type": "pressure", "set": "top", "value": P,
                       "function": {"times": [0.0, 1.0], "values": [0.0, 1.0]}}],
        }],
    }


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    folder = tmp_path_factory.mktemp("tensors")
    for fmt in ("vtu", "xdmf"):
        api.run(api.scenario_from_dict(_pressed_block(fmt)), out=folder / fmt)
    return folder / "vtu", folder / "xdmf"


def _stored(folder, name: str, time: float) -> tuple[str, np.ndarray]:
    """(AttributeType, the HDF5 array) of attribute ``name`` at ``time`` in fields.xdmf."""
    xml = (folder / "fields.xdmf").read_text()
    frame = xml[xml.index(f'<Time Value="{time}"'):]
    kind, dataset = re.search(rf'Name="{name}" AttributeType="(\w+)".*?fields\.h5:/(\w+)<',
                              frame, re.S).groups()
    with h5py.File(folder / "fields.h5", "r") as h5:
        return kind, h5[dataset][()]


@pytest.mark.parametrize("name", ["stress", "stress_nodal", "strain", "strain_nodal"])
def test_xdmf_files_hold_full_tensors_in_the_xdmf_convention(runs, name):
    kind, stored = _stored(runs[1], name, 1.0)
    assert kind == "Tensor"  # 9 components, row-major: the same in every XDMF reader
    assert stored.shape[1] == 9
    tensors = stored.reshape(-1, 3, 3)
    assert np.array_equal(tensors, tensors.transpose(0, 2, 1))
    if name.startswith("stress"):
        exact = np.array([[0.0, 0.0, 0.0], [0.0, -P, 0.0], [0.0, 0.0, -NU * P]])
        assert np.abs(tensors - exact).max() < 1e-9 * P
    else:  # the block shortens in y, lengthens in x, not in z (plane strain)
        assert np.all(tensors[:, 1, 1] < -1e-3) and np.all(tensors[:, 0, 0] > 1e-3)
        assert not np.any(tensors[:, 2, 2])


def test_the_package_reads_xdmf_tensors_back_as_the_vtu_holds_them(runs):
    vtu_folder, xdmf_folder = runs
    vtu = [read_vtu(path, t) for t, path in read_pvd(vtu_folder / "fields.pvd")]
    xdmf = read_xdmf(xdmf_folder)  # the folder, as read_results takes it
    assert len(xdmf) == len(vtu) == 3
    for a, b in zip(vtu, xdmf, strict=True):
        for name in ("stress", "strain"):
            assert b.cell_data[name].shape[1] == 6
            assert np.array_equal(a.cell_data[name], b.cell_data[name]), name
            assert np.array_equal(a.point_data[f"{name}_nodal"], b.point_data[f"{name}_nodal"])
    assert xdmf[-1].cell_data["stress"][0, 1] == pytest.approx(-P, abs=1e-9 * P)
    a, b = (api.read_results(folder).fields(1.0) for folder in runs)
    assert np.array_equal(a.cell_data["stress"][0], b.cell_data["stress"][0])
    assert np.array_equal(a.point_data["strain_nodal"], b.point_data["strain_nodal"])


def test_every_six_component_array_keeps_its_components_in_place(tmp_path):
    # distinct values in VTK's order XX, YY, ZZ, XY, YZ, XZ pin each component's position
    vtk6 = np.array([[11.0, 22.0, 33.0, 12.0, 23.0, 13.0]] * 2)
    writer = XdmfSeriesWriter(tmp_path)
    writer.write(0, 0.0, [[0, 0], [1, 0], [1, 1], [0, 1], [2, 0], [2, 1]],
                 [[0, 1, 2, 3], [1, 4, 5, 2]],
                 {"displacement": np.zeros((6, 2)), "velocity": np.zeros((6, 2)),
                  "other6": np.tile(vtk6[0], (6, 1))},
                 {"von_mises": np.zeros(2), "body_id": np.zeros(2, dtype=np.int64),
                  "stress": vtk6})
    writer.close()
    for name in ("stress", "other6"):
        kind, stored = _stored(tmp_path, name, 0.0)
        assert kind == "Tensor"
        assert np.array_equal(stored[0].reshape(3, 3),
                              [[11.0, 12.0, 13.0], [12.0, 22.0, 23.0], [13.0, 23.0, 33.0]])
    frame, = read_xdmf(tmp_path / "fields.xdmf")
    assert np.array_equal(frame.cell_data["stress"], vtk6)
    assert np.array_equal(frame.point_data["other6"][0], vtk6[0])


def test_a_non_symmetric_nine_component_array_is_left_whole():
    value = np.arange(18.0).reshape(2, 9)
    assert np.array_equal(symmetric_tensor(value), value)


def test_read_xdmf_of_a_folder_without_a_series_says_so(runs, tmp_path):
    with pytest.raises(FileNotFoundError,
                       match=r"^no fields\.xdmf in results folder .*vtu \(its frames are VTU "
                             r"files: fields\.pvd\)$"):
        read_xdmf(runs[0])
    with pytest.raises(FileNotFoundError, match=r"^no fields\.xdmf in results folder \S+$"):
        read_xdmf(tmp_path)
    with pytest.raises(FileNotFoundError, match=r"^no XDMF series .*missing\.xdmf$"):
        read_xdmf(tmp_path / "missing.xdmf")
    (tmp_path / "bad.xdmf").write_text("not xml")
    with pytest.raises(ValueError, match=r"bad\.xdmf is not a readable XDMF time series"):
        read_xdmf(tmp_path / "bad.xdmf")
