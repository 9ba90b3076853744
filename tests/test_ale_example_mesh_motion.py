"""The report 4.2 mesh-motion example (Table 4.1 analogue)."""

import numpy as np
import pytest

from ntncontact.ale.example_mesh_motion import STAGES, layer_mesh, mesh_motion_example
from ntncontact.mesh.quality import check_elements, corner_jacobians

# the row names of reference/mesh_smoothing_table_4_1.csv (report Table 4.1)
TABLE_MEASURES = [
    "min_edge", "max_edge", "average_edge", "variance_edge",
    "min_angle_deg", "max_angle_deg", "average_angle_deg", "variance_angle",
]
SMOOTHED = ("laplacian", "simple_angle_based", "weighted_angle_based")


def test_layer_mesh_is_valid_and_irregular():
    mesh = layer_mesh()
    check_elements(mesh)
    assert mesh.n_cells == 30 * 7
    # outward normals of the top edges point up: (dy, -dx) / len with the body on the left
    a, b = mesh.nodes[mesh.edge_sets["top"].T]
    normal_y = -(b[:, 0] - a[:, 0])
    assert np.all(normal_y > 0)


@pytest.mark.parametrize(("shift", "sweeps"), [(1.0, 5), (2.5, 100)])
def test_smoothing_repairs_the_moved_mesh(shift, sweeps):
    out = mesh_motion_example(shift_elements=shift, max_sweeps=sweeps)
    stats, meshes = out["statistics"], out["meshes"]
    assert set(stats) == set(STAGES)
    top = meshes["original"].node_sets["top"]
    active = out["active_nodes"]
    moved = meshes["before_smoothing"].nodes[active, 0] - meshes["original"].nodes[active, 0]
    expected = shift * 2.0 / 30
    np.testing.assert_allclose(moved, expected, rtol=1e-12)  # straight surface: exact shift
    # respacing keeps the top nodes in order on the straight top surface
    x_top = meshes["before_smoothing"].nodes[top]
    assert np.all(np.diff(x_top[:, 0]) > 0)
    np.testing.assert_allclose(x_top[:, 1], meshes["original"].nodes[top, 1], atol=1e-12)
    for stage in SMOOTHED:
        assert (corner_jacobians(meshes[stage]) > 0).all(), stage
        assert stats[stage]["min_angle_deg"] > stats["before_smoothing"]["min_angle_deg"] + 10
        assert stats[stage]["max_angle_deg"] < stats["before_smoothing"]["max_angle_deg"]
        # the smoothers never move the boundary
        np.testing.assert_array_equal(meshes[stage].nodes[top], x_top)
        assert stats[stage]["average_angle_deg"] == pytest.approx(90.0, abs=1e-9)


def test_statistics_use_the_table_measures():
    out = mesh_motion_example()
    assert list(out["statistics"]["original"]) == TABLE_MEASURES
