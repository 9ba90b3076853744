"""ALE mesh update of one body (ale.motion): exactness of the remap under uniform motion and
homogeneous deformation, large slides (Fig. 4.2), momentum correction, corners and clamping."""

import numpy as np
import pytest
from helpers import reflex_cell_block

from ntncontact.ale.example_mesh_motion import layer_mesh
from ntncontact.ale.motion import AleBody, AleMotionError, lumped_masses, move_ale_body
from ntncontact.ale.remap import momenta
from ntncontact.mesh.generators import annulus, rectangle
from ntncontact.mesh.quadmesh import MeshError
from ntncontact.mesh.quality import cell_min_sines, check_move, corner_angles_deg, corner_jacobians

DT = 0.01
# coordinates and fields are O(1): round-off of a few interpolations and arc-length inversions
ROUND = 1e-12


def fields(mesh, F=((1.0, 0.0), (0.0, 1.0)), shift=(0.0, 0.0), v=(0.0, 0.0), a=(0.0, 0.0)):
    """t_n state of a body under x = F X + shift with uniform v and a."""
    X = mesh.nodes.copy()
    d = X @ (np.asarray(F) - np.eye(2)).T + np.asarray(shift)
    n = len(X)
    return X, d, np.tile(np.asarray(v, float), (n, 1)), np.tile(np.asarray(a, float), (n, 1))


def slide_targets(x, nodes, shifts, tangent, v, gap=(0.0, 0.0)):
    """x_pred = x_n + dt v and targets shifted along the surface (plus an optional normal gap)."""
    x_pred = x[nodes] + DT * v[nodes]
    return np.asarray(shifts)[:, None] * np.asarray(tangent) + x_pred + np.asarray(gap), x_pred


def element_F(X, x, cells):
    """Deformation gradient at the corners of every cell: (dx/dxi)(dX/dxi)^-1, (m, 4, 2, 2)."""
    xi = np.array([[-1.0, -1.0], [1.0, -1.0], [1.0, 1.0], [-1.0, 1.0]])
    dn = 0.25 * np.stack([xi[:, 0] * (1 + xi[:, 1] * xi[:, 1:2]),
                          xi[:, 1] * (1 + xi[:, 0] * xi[:, 0:1])], axis=-1)  # (corner, a, k)
    jx = np.einsum("gak,eai->egik", dn, x[cells])
    jX = np.einsum("gak,eai->egik", dn, X[cells])
    return jx @ np.linalg.inv(jX)


def reference_area(X, cells):
    return lumped_masses(X, cells).sum()


def test_no_active_node_returns_the_input_unchanged():
    mesh = rectangle(2.0, 1.0, 8, 4)
    body = AleBody.from_mesh(mesh, "top")
    rng = np.random.default_rng(0)
    X, d, v, a = (rng.normal(size=(mesh.n_nodes, 2)) for _ in range(4))
    out = move_ale_body(body, X, d, v, a, [], np.zeros((0, 2)), np.zeros((0, 2)), DT)
    for new, old in ((out.X, X), (out.d, d), (out.v, v), (out.a, a)):
        np.testing.assert_array_equal(new, old)
    np.testing.assert_array_equal(out.x_mesh, X + d)
    assert not out.mesh_velocity.any() and out.clamped.size == 0 and not out.moved.any()


@pytest.mark.parametrize("method", ["laplacian", "angle", "weighted_angle"])
def test_uniform_translation_is_unchanged_by_an_arbitrary_surface_move(method):
    """METHOD_NOTES test 1: a translating body's physics does not see the mesh motion."""
    mesh = rectangle(3.0, 1.0, 15, 5, grading_x=2.0, grading_y=0.5)
    body = AleBody.from_mesh(mesh, "top", smoothing=method)
    X, d, v, a = fields(mesh, shift=(0.3, -0.1), v=(2.0, -1.0), a=(0.5, 0.25))
    x = X + d
    top = body.surface  # walks right to left: tangent -x
    active = top[[3, 7, 11]]
    h = 0.2
    x_target, x_pred = slide_targets(x, active, [1.7 * h, -0.8 * h, 1.3 * h], (-1.0, 0.0), v,
                                     gap=(0.0, -0.01))
    out = move_ale_body(body, X, d, v, a, active, x_target, x_pred, DT)
    # the normal gap is not the mesh's business: the node lands on the target's tangential part
    np.testing.assert_allclose(out.x_mesh[active, 0], x_target[:, 0] - DT * v[active, 0],
                               atol=ROUND)
    np.testing.assert_allclose(out.x_mesh[active, 1], x[active, 1], atol=ROUND)
    assert out.mismatch < ROUND and out.clamped.size == 0
    assert out.moved.sum() > 3 * len(active)  # surface respaced, interior followed
    np.testing.assert_allclose(out.X + out.d, out.x_mesh, atol=ROUND)
    np.testing.assert_allclose(out.d, d, atol=ROUND)
    np.testing.assert_allclose(out.v, v, atol=ROUND)
    np.testing.assert_allclose(out.a, a, atol=ROUND)
    lo, hi = mesh.nodes.min(axis=0), mesh.nodes.max(axis=0)
    assert np.all(out.X >= lo - ROUND) and np.all(out.X <= hi + ROUND)
    np.testing.assert_allclose(out.X[top, 1], 1.0, atol=ROUND)  # still on the reference surface
    np.testing.assert_allclose(out.mesh_velocity, (out.x_mesh - x) / DT)
    assert np.abs(out.mesh_velocity).max() > 1.0  # the mesh did move


@pytest.mark.parametrize("remap", ["linear", "quadratic"])
def test_homogeneous_deformation_is_remapped_exactly(remap):
    """Linear fields (X, v of x = F X + c) are reproduced by both interpolants: F is unchanged
    in every element and the X-image keeps its area, so the strain energy W(F) A is unchanged."""
    mesh = layer_mesh(width=2.0, height=0.5, nx=20, ny=6, jitter=0.25)
    body = AleBody.from_mesh(mesh, "top", remap=remap, conserve_momentum=False)
    F = np.array([[1.1, 0.3], [-0.05, 0.9]])
    X, d, _, a = fields(mesh, F=F, shift=(0.2, 0.1))
    v = X @ np.array([[0.5, -1.0], [2.0, 0.3]]).T + [1.0, -2.0]  # linear velocity field
    x = X + d
    top = body.surface
    tangent = F @ [-1.0, 0.0] / np.linalg.norm(F @ [-1.0, 0.0])
    active = top[[5, 12]]
    x_target, x_pred = slide_targets(x, active, [0.25, -0.15], tangent, v)
    out = move_ale_body(body, X, d, v, a, active, x_target, x_pred, DT)
    assert out.moved.sum() > 2 and out.mismatch < ROUND
    np.testing.assert_allclose(element_F(out.X, out.x_mesh, mesh.cells), np.broadcast_to(
        F, (mesh.n_cells, 4, 2, 2)), atol=1e-10)  # cond(dX/dxi) ~ 10 on the thin top row
    np.testing.assert_allclose(out.x_mesh, out.X @ F.T + [0.2, 0.1], atol=ROUND)
    np.testing.assert_allclose(out.v, out.X @ np.array([[0.5, -1.0], [2.0, 0.3]]).T
                               + [1.0, -2.0], atol=1e-11)
    np.testing.assert_allclose(reference_area(out.X, mesh.cells), reference_area(X, mesh.cells),
                               rtol=ROUND)


@pytest.mark.parametrize("n_active", [1, 5])
def test_slide_over_several_elements_lands_on_target_without_inversion(n_active):
    """Fig. 4.2: a node dragged 3.6 element lengths; order kept, mesh valid, smoothing helps."""
    mesh = layer_mesh()  # 30 x 7, graded to the top, jittered
    h = 2.0 / 30
    X, d, v, a = fields(mesh, v=(-1.0, 0.0))
    x = X + d
    top_chain = AleBody.from_mesh(mesh, "top").surface
    active = top_chain[13:13 + n_active]
    x_target, x_pred = slide_targets(x, active, np.full(n_active, 3.6 * h), (1.0, 0.0), v)
    smoothed = move_ale_body(AleBody.from_mesh(mesh, "top"), X, d, v, a, active, x_target,
                             x_pred, DT)
    # moving the surface alone inverts a thin top element of the jittered mesh (cf. Fig. 4.2)
    surface_only = AleBody.from_mesh(mesh, "top", smoothing_layers=0)
    with pytest.raises(MeshError, match=r"body 'layer': element \d+ is inverted"):
        move_ale_body(surface_only, X, d, v, a, active, x_target, x_pred, DT)
    assert smoothed.mismatch < ROUND and smoothed.clamped.size == 0
    np.testing.assert_allclose(smoothed.x_mesh[active], x[active] + [3.6 * h, 0.0], atol=ROUND)
    assert np.all(np.diff(smoothed.x_mesh[top_chain, 0]) < 0)  # chain order preserved
    assert corner_jacobians(smoothed.x_mesh, mesh.cells).min() > 0
    assert corner_jacobians(smoothed.X, mesh.cells).min() > 0
    assert corner_angles_deg(smoothed.x_mesh, mesh.cells).min() > 20.0
    # nodes beyond the smoothing layers keep their position and fields exactly
    far = mesh.nodes[:, 1] < 0.1
    np.testing.assert_array_equal(smoothed.x_mesh[far], x[far])
    np.testing.assert_array_equal(smoothed.X[far], X[far])


def test_ring_slide_stays_on_the_circle():
    """A closed chain with no corner: the node slides along the circle (curve error O(h^3))."""
    radius = 1.0
    mesh = annulus(0.6, radius, 4, 48)
    body = AleBody.from_mesh(mesh, "outer")
    assert body.closed and not body.corner.any()
    X, d, v, a = fields(mesh)
    bottom = int(mesh.node_sets["bottom"][0])
    theta = 2.5 * 2 * np.pi / 48  # 2.5 element lengths counter-clockwise
    start = np.array([[0.0, -radius]])
    target = radius * np.array([[np.sin(theta), -np.cos(theta)]]) * 1.01  # with a normal gap
    out = move_ale_body(body, X, d, v, a, [bottom], target, start, DT)
    h = 2 * np.pi * radius / 48
    # the quadratic surface curve misses the circle by O(h^3 / R^2) (measured 0.003 h^3)
    np.testing.assert_allclose(np.linalg.norm(out.x_mesh[body.surface], axis=1), radius,
                               atol=0.01 * h**3 / radius**2)
    angle = np.arctan2(out.x_mesh[bottom, 0], -out.x_mesh[bottom, 1])
    assert abs(angle - theta) < 1e-6 * theta  # the radial gap is projected away exactly
    assert out.mismatch < ROUND and out.clamped.size == 0
    far = body.surface[24]  # the opposite node anchors the opened chain
    np.testing.assert_array_equal(out.x_mesh[far], X[far])


def momentum_case(conserve: bool):
    mesh = layer_mesh(width=2.0, height=0.5, nx=20, ny=6, jitter=0.25)
    body = AleBody.from_mesh(mesh, "top", conserve_momentum=conserve, density=7.8)
    X, d, _, a = fields(mesh, F=[[1.05, 0.1], [0.0, 0.97]])
    x = X + d
    v = 0.8 * np.column_stack([-x[:, 1], x[:, 0]]) + np.column_stack(
        [np.sin(3 * x[:, 0]) + 2.0, np.cos(5 * x[:, 1]) * x[:, 0]])  # rotation plus a wave
    active = body.surface[[6, 7, 8]]
    x_target, x_pred = slide_targets(x, active, [0.21, 0.21, 0.21], (-1.0, 0.0), v)
    out = move_ale_body(body, X, d, v, a, active, x_target, x_pred, DT)
    old = momenta(lumped_masses(X, mesh.cells, 7.8), x, v)
    new = momenta(lumped_masses(out.X, mesh.cells, 7.8), out.x_mesh, out.v)
    m = lumped_masses(X, mesh.cells, 7.8)
    scale_p = m @ np.linalg.norm(v, axis=1)
    scale_l = m @ (np.linalg.norm(x, axis=1) * np.linalg.norm(v, axis=1))
    drift = (np.linalg.norm(new[0] - old[0]) / scale_p, abs(new[1] - old[1]) / scale_l)
    return out, v, drift


def test_momentum_correction_restores_linear_and_angular_momentum():
    out, v, drift = momentum_case(conserve=True)
    assert drift[0] < ROUND and drift[1] < ROUND
    np.testing.assert_array_equal(out.v[~out.moved], v[~out.moved])  # supports keep their v
    plain, _, plain_drift = momentum_case(conserve=False)
    # plain interpolation drifts (measured 6.5e-4 and 7.8e-4 here): the correction works
    assert plain_drift[0] > 1e-4 and plain_drift[1] > 1e-4
    change = np.linalg.norm(plain.momentum_change[0])
    assert change > 0 and np.allclose(plain.momentum_change[0], out.momentum_change[0])
    # a small rigid velocity on the remapped nodes (drift / their mass fraction), not a rewrite
    assert np.abs(out.v - plain.v).max() < 1e-2 * np.abs(v).max()


def corner_body(**options):
    """A 10 x 4 rectangle whose contact chain runs up the right side and left along the top."""
    mesh = rectangle(2.0, 0.8, 10, 4)
    edges = np.vstack([mesh.edge_sets["right"], mesh.edge_sets["top"]])
    mesh = mesh.with_sets(edge_sets={"right_top": edges})
    return mesh, AleBody.from_mesh(mesh, "right_top", **options)


def test_corners_stay_fixed_and_slides_past_them_are_clamped():
    mesh, body = corner_body()
    corner = int(mesh.node_sets["corner_top_right"][0])
    end = int(mesh.node_sets["corner_top_left"][0])
    np.testing.assert_array_equal(body.surface[body.corner], [corner])  # detected by its angle
    X, d, v, a = fields(mesh)
    x = X + d
    h = 0.2
    top = mesh.node_sets["top"]  # right to left
    near_corner, near_end, free = top[2], top[-3], top[5]
    active = np.array([near_corner, free, near_end, corner])
    shifts = [5 * h, 0.5 * h, -4 * h, 0.3 * h]  # past the corner, free, past the end, outward
    x_target, x_pred = slide_targets(x, active, shifts, (1.0, 0.0), v)
    out = move_ale_body(body, X, d, v, a, active, x_target, x_pred, DT)
    np.testing.assert_array_equal(np.sort(out.clamped), np.sort([near_corner, near_end, corner]))
    np.testing.assert_array_equal(out.x_mesh[[corner, end]], x[[corner, end]])
    # clamped 2 segments before the break with min_spacing_ratio 0.25 of the smallest spacing
    np.testing.assert_allclose(out.x_mesh[near_corner], [2.0 - 2 * 0.25 * h, 0.8], atol=ROUND)
    np.testing.assert_allclose(out.x_mesh[near_end], [2 * 0.25 * h, 0.8], atol=ROUND)
    np.testing.assert_allclose(out.x_mesh[free], x[free] + [0.5 * h, 0.0], atol=ROUND)
    right = mesh.node_sets["right"]
    np.testing.assert_array_equal(out.x_mesh[right], x[right])  # nothing slid round the corner
    # the clamp shows in the mismatch: 5 h wanted, 1.5 h allowed
    np.testing.assert_allclose(out.mismatch, 3.5 * h, atol=ROUND)


def test_a_node_held_before_a_corner_step_after_step_keeps_its_reference_distance():
    """The clamp keeps min_spacing_ratio times the stretch's smallest REFERENCE segment. With
    the segments at t_n it ratcheted: a node held at the clamp shortens its stretch's smallest
    segment, and the next step lets it nearer (0.0144, 0.002, 0.00012 from the corner in three
    steps of the fast-sliding blocks with both bodies ALE, whose cell at the corner then
    inverted). Five steps that each want the node 5 h past the corner: it stays two clamped
    segments (2 x 0.25 h) before it."""
    mesh, body = corner_body()
    corner = int(mesh.node_sets["corner_top_right"][0])
    near_corner = mesh.node_sets["top"][2]
    X, d, v, a = fields(mesh)
    h = 0.2
    for _ in range(5):
        x = X + d
        x_target, x_pred = slide_targets(x, [near_corner], [5 * h], (1.0, 0.0), v)
        out = move_ale_body(body, X, d, v, a, [near_corner], x_target, x_pred, DT)
        X, d, v, a = out.X, out.d, out.v, out.a
        np.testing.assert_allclose(out.x_mesh[near_corner], [2.0 - 2 * 0.25 * h, 0.8],
                                   atol=ROUND)
        np.testing.assert_array_equal(out.x_mesh[corner], [2.0, 0.8])


def test_a_node_leaving_a_corner_is_held_at_twice_its_reference_distance():
    """The mirror of the clamp before a break: a node whose partner slides away from the
    corner stops where the stretch between it and the corner is ``max_stretch`` (2) times its
    reference length (scaled by the run's mean stretch, 1 here), step after step. The next
    node behind it follows its own partner: between two active nodes the spacing is their
    partners' (with both bodies ALE the held node's partner comes to it, ``engine.
    mesh_motion``). Without the bound the corner cell grew without limit: the fast-sliding
    blocks refined 4x with both blocks ALE stretched the upper block's leading cell to 9 times
    its length and inverted its neighbour."""
    mesh, body = corner_body()
    corner = int(mesh.node_sets["corner_top_right"][0])
    first, second = mesh.node_sets["top"][1], mesh.node_sets["top"][2]  # right to left
    X, d, v, a = fields(mesh)
    h = 0.2
    for _ in range(2):  # a third would push the second node into the clamp before x = 0
        x = X + d
        x_target, x_pred = slide_targets(x, [first, second], [-3 * h, -3 * h], (1.0, 0.0), v)
        out = move_ale_body(body, X, d, v, a, [first, second], x_target, x_pred, DT)
        X, d, v, a = out.X, out.d, out.v, out.a
        np.testing.assert_allclose(out.x_mesh[first], [2.0 - 2 * h, 0.8], atol=ROUND)
        np.testing.assert_allclose(out.x_mesh[second] - x[second], [-3 * h, 0.0], atol=ROUND)
        np.testing.assert_array_equal(out.clamped, [first])
        np.testing.assert_array_equal(out.x_mesh[corner], [2.0, 0.8])
    unbounded = AleBody.from_mesh(mesh, "right_top", max_stretch=np.inf)
    X, d, v, a = fields(mesh)
    x_target, x_pred = slide_targets(X + d, [first], [-3 * h], (1.0, 0.0), v)
    out = move_ale_body(unbounded, X, d, v, a, [first], x_target, x_pred, DT)
    np.testing.assert_allclose(out.x_mesh[first], [2.0 - 4 * h, 0.8], atol=ROUND)


def test_crossing_targets_raise_mesh_error_naming_the_body():
    mesh = rectangle(2.0, 0.8, 10, 4, name="foundation")
    body = AleBody.from_mesh(mesh, "top")
    X, d, v, a = fields(mesh)
    x = X + d
    active = body.surface[[3, 4]]
    x_target, x_pred = slide_targets(x, active, [0.3, -0.3], (-1.0, 0.0), v)
    with pytest.raises(AleMotionError, match="body 'foundation'.*swap order") as err:
        move_ale_body(body, X, d, v, a, active, x_target, x_pred, DT)
    message = str(err.value)
    assert isinstance(err.value, MeshError) and "\n" not in message
    # the two nodes (local numbers, with their positions) and what to change
    for node in active:
        assert f" {node}" in message and f"({x[node, 0]:.6g}, {x[node, 1]:.6g})" in message
    # the body does not know its partner's spacing: the time loop adds that advice where
    # it applies (test_ale_partners)
    assert "analysis.dt" in message and "2x the partner surface's spacing" not in message


def test_later_augmentation_from_the_original_state_with_x_start():
    """Augmentation 2 from the t_n state with x_start = the moved node equals a direct move."""
    mesh = rectangle(2.0, 0.8, 10, 4)
    body = AleBody.from_mesh(mesh, "top")
    X, d, v, a = fields(mesh, v=(1.0, -0.5))
    x = X + d
    node = body.surface[[4]]
    t1, p1 = slide_targets(x, node, [0.13], (-1.0, 0.0), v)
    first = move_ale_body(body, X, d, v, a, node, t1, p1, DT)
    t2 = x[node] + DT * v[node] + [-0.27, 0.0]
    p2 = first.x_mesh[node] + DT * v[node]  # last iterate of the particle at the moved node
    second = move_ale_body(body, X, d, v, a, node, t2, p2, DT, x_start=first.x_mesh[node])
    direct = move_ale_body(body, X, d, v, a, node, t2, x[node] + DT * v[node], DT)
    np.testing.assert_allclose(second.x_mesh, direct.x_mesh, atol=ROUND)
    np.testing.assert_allclose(second.x_mesh[node], x[node] + [-0.27, 0.0], atol=ROUND)
    assert second.mismatch < ROUND


def test_options_are_validated():
    mesh = rectangle(2.0, 0.8, 10, 4)
    with pytest.raises(ValueError, match="smoothing"):
        AleBody.from_mesh(mesh, "top", smoothing="spline")
    body = AleBody.from_mesh(mesh, "top")
    X, d, v, a = fields(mesh)
    with pytest.raises(ValueError, match="not on the ALE contact surface"):
        move_ale_body(body, X, d, v, a, [0], X[[5]], X[[5]], DT)  # node 0 is on the bottom


def test_reference_respacing_keeps_the_original_mesh_proportions():
    """respace="reference": free surface nodes are placed in the ORIGINAL spacing proportions
    between the anchors, not the current (non-uniformly stretched) ones."""
    mesh = rectangle(2.0, 0.8, 10, 4, grading_x=3.0)
    body = AleBody.from_mesh(mesh, "top", respace="reference")
    X = mesh.nodes.copy()
    d = np.column_stack([0.15 * X[:, 0] ** 2, np.zeros(len(X))])  # stretched non-uniformly
    v, a = np.zeros_like(X), np.zeros_like(X)
    x = X + d
    top = body.surface  # right to left; ends are the top corners
    node = top[[6]]
    out = move_ale_body(body, X, d, v, a, node, x[node] + [0.1, 0.0], x[node], DT)
    free = top[6:]  # from the moved node to the left end
    ratio_new = (out.x_mesh[free, 0] - x[top[-1], 0]) / (out.x_mesh[node, 0] - x[top[-1], 0])
    ratio_ref = (X[free, 0] - X[top[-1], 0]) / (X[node, 0] - X[top[-1], 0])
    np.testing.assert_allclose(ratio_new, ratio_ref, atol=ROUND)
    ratio_cur = (x[free, 0] - x[top[-1], 0]) / (x[node, 0] - x[top[-1], 0])
    assert np.abs(ratio_cur - ratio_ref).max() > 0.01  # the current spacing is different


def test_closed_chain_with_corners_moves_only_its_own_side():
    """The whole boundary as one closed chain: cut at a corner, every corner stays a break."""
    mesh = rectangle(2.0, 0.8, 10, 4)
    loop = np.vstack([mesh.edge_sets[k] for k in ("bottom", "right", "top", "left")])
    mesh = mesh.with_sets(edge_sets={"loop": loop})
    body = AleBody.from_mesh(mesh, "loop")
    assert body.closed and body.corner.sum() == 4
    X, d, v, a = fields(mesh, shift=(0.1, 0.0))
    x = X + d
    top = mesh.node_sets["top"]
    active = top[[3, 7]]
    out = move_ale_body(body, X, d, v, a, active, x[active] + [[0.13, 0.0], [-0.21, 0.0]],
                        x[active], DT)
    np.testing.assert_allclose(out.x_mesh[active], x[active] + [[0.13, 0.0], [-0.21, 0.0]],
                               atol=ROUND)
    others = np.setdiff1d(np.concatenate([mesh.node_sets[k] for k in
                                          ("bottom", "right", "left")]), top[1:-1])
    np.testing.assert_array_equal(out.x_mesh[others], x[others])
    assert out.mismatch < ROUND and out.clamped.size == 0


def bent_block(**options):
    """A graded block under a non-uniform deformation (no fixed point of any smoother) with a
    smooth velocity field."""
    mesh = rectangle(2.0, 0.8, 10, 4, grading_x=2.0, grading_y=0.6)
    body = AleBody.from_mesh(mesh, "top", **options)
    X = mesh.nodes.copy()
    d = np.column_stack([0.05 * np.sin(2.0 * X[:, 0]) * X[:, 1], -0.04 * X[:, 0] ** 2 * X[:, 1]])
    v = np.column_stack([np.sin(X[:, 0] + 2.0 * X[:, 1]), np.cos(3.0 * X[:, 0])])
    return mesh, body, X, d, v, 0.5 * v


def spacing_near(x, body, node):
    chain = list(body.surface)
    i = chain.index(node)
    return min(np.linalg.norm(x[chain[i + 1]] - x[node]), np.linalg.norm(x[chain[i - 1]] - x[node]))


def sliding_setup():
    """The bent block and its fields, surface node 4, the spacing there and the tangent."""
    mesh, body, X, d, v, a = bent_block()
    x = X + d
    node = body.surface[[4]]
    chord = x[body.surface[5]] - x[body.surface[3]]
    h = spacing_near(x, body, node[0])
    return mesh, body, X, d, v, a, x, node, h, chord / np.linalg.norm(chord)


def test_slides_below_the_tolerance_move_nothing_and_keep_the_fields_bit_for_bit():
    mesh, body, X, d, v, a, x, node, h, tangent = sliding_setup()
    for shift, moves in ((0.5e-8 * h, False), (2e-8 * h, True)):  # slide_tolerance = 1e-8
        out = move_ale_body(body, X, d, v, a, node, x[node] + shift * tangent, x[node], DT)
        assert out.moved.any() == moves
        if not moves:
            for new, old in ((out.X, X), (out.d, d), (out.v, v), (out.a, a)):
                np.testing.assert_array_equal(new, old)
            # the miss is reported (up to the curve's projection round-off)
            assert out.mismatch == pytest.approx(shift, rel=1e-4)
        else:
            assert out.mismatch < ROUND


def test_exact_targets_on_a_deformed_mesh_move_nothing_unlike_full_respacing_and_smoothing():
    """The diagnosis of the dissipation: respacing the surface in reference proportions and
    smoothing the interior moves (and remaps) nodes of a deformed mesh at every update even
    when no contact node slides; the incremental update moves none."""
    mesh, body, X, d, v, a = bent_block()
    x = X + d
    active = body.surface[[3, 4, 5]]
    out = move_ale_body(body, X, d, v, a, active, x[active] + DT * v[active],
                        x[active] + DT * v[active], DT)
    assert not out.moved.any() and out.interior == "none" and out.mismatch == 0.0
    full = AleBody.from_mesh(mesh, "top", respace="reference", interior="position")
    old = move_ale_body(full, X, d, v, a, active, x[active] + DT * v[active],
                        x[active] + DT * v[active], DT)
    assert old.moved.sum() > 10  # of 55 nodes


def test_small_slide_moves_only_surface_nodes_next_to_the_sliding_node():
    mesh, body, X, d, v, a, x, node, h, tangent = sliding_setup()
    out = move_ale_body(body, X, d, v, a, node, x[node] + 0.2 * h * tangent, x[node], DT)
    assert out.interior == "surface" and out.mismatch < ROUND
    moved = np.flatnonzero(out.moved)
    assert node[0] in moved and np.isin(moved, body.surface).all() and moved.size <= 3
    still = ~out.moved
    for new, old in ((out.X, X), (out.d, d), (out.a, a)):
        np.testing.assert_array_equal(new[still], old[still])
    # a single remapped node cannot take the rigid momentum correction alone: the nodes of the
    # cells around it share it, every other velocity is kept
    around = np.zeros(mesh.n_nodes, bool)
    around[mesh.cells[np.isin(mesh.cells, moved).any(axis=1)].ravel()] = True
    np.testing.assert_array_equal(out.v[~around], v[~around])
    assert not np.array_equal(out.v[around & still], v[around & still])
    # slid along the curved surface by 0.2 h (chord vs arc: relative O(h^2 curvature^2))
    assert np.linalg.norm(out.x_mesh[node] - x[node]) == pytest.approx(0.2 * h, rel=1e-3)


@pytest.mark.parametrize("least", ["displacement", "position"])
def test_a_move_keeps_at_least_the_stage_of_the_steps_previous_move(least):
    """The stage is a threshold on the mesh quality: augmentations whose surface positions
    differ by round-off could alternate between moving the interior and not, and the remapped
    fields with them (the disk drop refined 4x cycled so at step 68 with a period of 3). With
    the previous move's stage as the least, a slide that alone would stay on the surface moves
    the interior as that stage does, within the smoothing layers."""
    mesh, body, X, d, v, a, x, node, h, tangent = sliding_setup()
    target = x[node] + 0.2 * h * tangent
    alone = move_ale_body(body, X, d, v, a, node, target, x[node], DT)
    assert alone.interior == "surface"
    kept = move_ale_body(body, X, d, v, a, node, target, x[node], DT, least_interior=least)
    assert kept.interior == least and kept.mismatch < ROUND
    interior = kept.moved & ~np.isin(np.arange(mesh.n_nodes), body.surface)
    assert interior.any()
    reach = body.within_layers(alone.moved, body.smoothing_layers)
    assert np.all(reach[interior])
    np.testing.assert_allclose(kept.x_mesh[node], alone.x_mesh[node], atol=ROUND)


def test_a_move_smooths_at_least_around_the_surface_nodes_of_the_steps_previous_move():
    """Whether a surface node moves is a threshold on its slide (slide_tolerance), and the
    interior is smoothed around the nodes that moved. Without a floor, a slide just above the
    tolerance smooths a region that a slide just below it leaves alone: the interior jumps
    with a change of the slide of 1e-7 of the spacing (the disk drop refined 4x with its remap
    energy handed over cycled so at step 63, interior nodes 5.9e-5 to and fro). With the
    previous move's seeds as the least, the two moves agree to the change of the slide."""
    mesh, body, X, d, v, a, x, node, h, tangent = sliding_setup()
    first = move_ale_body(body, X, d, v, a, node, x[node] + 0.2 * h * tangent, x[node], DT,
                          least_interior="position")
    assert first.interior == "position" and first.seeds[node].all()
    assert not first.seeds[~np.isin(np.arange(mesh.n_nodes), body.surface)].any()

    def moves(least_seeds):
        return [move_ale_body(body, X, d, v, a, node, x[node] + shift * tangent, x[node], DT,
                              least_interior="position", least_seeds=least_seeds)
                for shift in (2e-8 * h, 0.5e-8 * h)]  # just above, just below slide_tolerance

    above, below = moves(None)
    assert above.moved.sum() > 3 and not below.moved.any()
    assert np.abs(above.x_mesh - below.x_mesh).max() > 1e-3 * h  # the jump
    above, below = moves(first.seeds)
    assert np.array_equal(above.seeds, below.seeds)
    assert np.abs(above.x_mesh - below.x_mesh).max() < 1e-7 * h


@pytest.mark.parametrize("layers", [1, 2])
def test_displacement_stage_moves_nothing_beyond_the_smoothing_layers(layers):
    mesh = rectangle(2.0, 0.8, 20, 8)
    body = AleBody.from_mesh(mesh, "top", interior="displacement", smoothing_layers=layers)
    X, d, v, a = fields(mesh, F=[[1.02, 0.05], [0.0, 0.97]], v=(0.3, -0.2))
    x = X + d
    active = body.surface[[9, 10, 11]]
    tangent = (x[active[1]] - x[active[0]]) / np.linalg.norm(x[active[1]] - x[active[0]])
    x_target, x_pred = slide_targets(x, active, [0.04, 0.04, 0.04], tangent, v)
    out = move_ale_body(body, X, d, v, a, active, x_target, x_pred, DT)
    assert out.interior == "displacement" and out.mismatch < ROUND
    surface_moved = out.moved & np.isin(np.arange(mesh.n_nodes), body.surface)
    reach = body.within_layers(surface_moved, layers) & ~body.boundary
    interior_moved = out.moved & ~surface_moved
    assert interior_moved.any() and np.all(reach[interior_moved])
    np.testing.assert_array_equal(out.x_mesh[~out.moved], x[~out.moved])
    # under a homogeneous deformation the remap is exact: F and the fields are unchanged
    np.testing.assert_allclose(out.x_mesh, out.X @ np.array([[1.02, 0.05], [0.0, 0.97]]).T,
                               atol=ROUND)


def test_interior_follows_when_surface_only_would_spoil_the_cells():
    """Escalation: a slide of a thin top element's width cannot stay surface-only; every cell
    the update changes keeps min_quality of its original quality (or its t_n quality)."""
    mesh = layer_mesh(width=2.0, height=0.4, nx=20, ny=6, jitter=0.0)
    X, d, v, a = fields(mesh)
    x = X + d
    active = AleBody.from_mesh(mesh, "top").surface[[9, 10]]
    stages = {}
    for shift in (0.01, 0.1, 0.3):  # top row 0.04 high, 0.1 wide
        for interior in ("minimal", "displacement"):
            body = AleBody.from_mesh(mesh, "top", interior=interior)
            x_target, x_pred = slide_targets(x, active, [shift, shift], (-1.0, 0.0), v)
            out = move_ale_body(body, X, d, v, a, active, x_target, x_pred, DT)
            stages[shift, interior] = out.interior
            q_new = cell_min_sines(out.x_mesh, mesh.cells)
            floor = np.minimum(0.5 * cell_min_sines(mesh.nodes, mesh.cells),
                               cell_min_sines(x, mesh.cells))
            if out.interior != "position":  # the last stage is taken as it comes
                assert np.all(q_new >= floor)
            assert q_new.min() > 0.3 and out.mismatch < ROUND
    assert stages[0.01, "minimal"] == "surface"
    assert stages[0.1, "minimal"] in ("displacement", "position")
    assert stages[0.3, "minimal"] == stages[0.3, "displacement"] == "position"


def repeated_slides(n, remap, cycles=10, frac=0.3):
    """Slide the top nodes of an n x n unit square by frac h and back, ``cycles`` times (each
    update remapping from the last): the mesh returns exactly, so the kinetic energy change is
    the accumulated remap error alone."""
    mesh = rectangle(1.0, 1.0, n, n)
    body = AleBody.from_mesh(mesh, "top", remap=remap, conserve_momentum=False)
    X, d, a = mesh.nodes.copy(), np.zeros((mesh.n_nodes, 2)), np.zeros((mesh.n_nodes, 2))
    v = np.column_stack([np.sin(2.0 * X[:, 0] + X[:, 1]), np.cos(X[:, 0] - 2.0 * X[:, 1])])
    energy = lambda X, v: 0.5 * lumped_masses(X, mesh.cells) @ np.sum(v**2, axis=1)  # noqa: E731
    ke0 = energy(X, v)
    active = body.surface[2:-2]
    home = mesh.nodes[active]
    for _ in range(cycles):
        for shift in (frac / n, 0.0):
            x = X + d
            out = move_ale_body(body, X, d, v, a, active, home + [shift, 0.0], x[active], DT)
            assert out.interior == "surface"
            X, d, v, a = out.X, out.d, out.v, out.a
    np.testing.assert_array_equal(X + d, mesh.nodes)  # back home exactly
    return (energy(X, v) - ke0) / ke0


def test_remapped_kinetic_energy_of_a_smooth_field_is_kept_to_the_interpolation_order():
    """Per update the nodal error is O(h^2) (linear) or O(h^3) (quadratic) on O(1/h) surface
    nodes of mass O(h^2): the energy error of a cycle is O(h^3) or O(h^4). Measured rates
    2.4-2.8 (linear, still pre-asymptotic) and 4.4-4.8 (quadratic); both lose energy."""
    errors = {r: np.array([repeated_slides(n, r) for n in (8, 16, 32)])
              for r in ("linear", "quadratic")}
    assert np.all(errors["linear"] < 0) and np.all(errors["quadratic"] < 0)
    rates = {r: np.log2(e[:-1] / e[1:]) for r, e in errors.items()}
    assert np.all(rates["linear"] > 2.2), rates
    assert np.all(rates["quadratic"] > 3.8), rates
    assert np.all(np.abs(errors["quadratic"]) < 0.05 * np.abs(errors["linear"]))


def test_t_n_data_are_reused_only_for_the_same_state():
    """The per-state cache (curve, locator, gradients) must never serve another state."""
    mesh, body, X, d, v, a = bent_block(remap="quadratic")
    x = X + d
    node = body.surface[[4]]
    states = [(X, d, v, a), (X, 1.1 * d, v, a), (X, d, 2.0 * v, a)]
    shift = np.array([[0.03, 0.0]])
    results = [move_ale_body(body, *s, node, (s[0] + s[1])[node] - shift, (s[0] + s[1])[node],
                             DT) for s in states + states[::-1]]
    for i, s in enumerate(states + states[::-1]):
        fresh = move_ale_body(bent_block(remap="quadratic")[1], *s, node,
                              (s[0] + s[1])[node] - shift, (s[0] + s[1])[node], DT)
        for field in ("X", "d", "v", "a", "x_mesh"):
            np.testing.assert_array_equal(getattr(results[i], field), getattr(fresh, field))
    assert not np.array_equal(results[0].v, results[2].v)
    assert np.abs(x).max() > 0


@pytest.mark.parametrize("slide", [0.03, -0.03])
def test_a_reflex_cell_left_by_the_deformation_does_not_block_a_move_that_improves_it(slide):
    """A top node the material pushed 0.15 down and left turns its cell's corner reflex at
    t_n (sine -0.38); sliding the node either way along the surface makes that cell better
    (measured -0.13 and -0.32), so the move is kept (``mesh.quality.check_move``), where every
    move touching the cell was refused before. (A move that inverts a valid cell still raises:
    test_slide_over_several_elements_lands_on_target_without_inversion.) Without position
    sweeps: with them the region around such a cell is smoothed (``SLIVER_SINE``,
    tests/test_ale_robust.py), and this move is the surface's alone."""
    mesh, X, d, node, x = reflex_cell_block()
    zero = np.zeros_like(X)
    before = cell_min_sines(x, mesh.cells)
    cell = int(np.argmin(before))
    assert before[cell] < -0.3 and node in mesh.cells[cell]
    body = AleBody.from_mesh(mesh, "top", sweeps=0)
    out = move_ale_body(body, X, d, zero, zero, [node], x[[node]] + [[slide, 0.0]], x[[node]],
                        DT)
    assert out.moved[node]
    after = cell_min_sines(out.x_mesh, mesh.cells)
    assert before[cell] < after[cell] < 0.0


def test_an_inverted_cell_beside_slid_surface_nodes_names_the_cause():
    """Tester C (session 41): a frictionless disk sliding around the inside of an ALE ring
    dragged the ring's surface nodes along (segments 0.098 -> 0.019 ahead of it) until "body
    'ring': element 142 is inverted", with no advice; a Lagrangian ring completes. A refused
    cell that holds a surface node the move slid now names the drag and the cure; any other
    refused cell keeps the plain message."""
    from ntncontact.ale.motion import _explained

    mesh = annulus(1.0, 1.3, 2, 16, name="ring")
    body = AleBody.from_mesh(mesh, "inner")
    old = mesh.nodes.copy()
    surface = body.surface[3]
    cell = int(np.flatnonzero((mesh.cells == surface).any(axis=1))[0])
    new = old.copy()
    new[surface] *= 1.3  # pushed past the next ring of nodes: its cells invert
    assert (cell_min_sines(new, mesh.cells[[cell]]) < 0).all()
    with pytest.raises(MeshError, match="body 'ring': element") as refused:
        check_move(new, old, mesh.cells, "ring")
    err = refused.value
    assert surface in mesh.cells[err.cell]  # the cell it names holds the slid node
    message = str(_explained(body, np.array([surface]), err))
    assert message.startswith(str(err)) and "\n" not in message
    assert "runs on through the contact" in message
    assert "make body 'ring' Lagrangian (mesh_motion = \"lagrangian\")" in message
    # the same cell, no surface node slid (an interior move): no guess at the cause
    assert _explained(body, np.array([], np.int64), err) is err
