"""Tests of reading gmsh .msh files into QuadMesh (gmsh API round trip and meshio-written files)."""

from __future__ import annotations

import meshio
import numpy as np
import pytest

from ntncontact.mesh.boundary import boundary_edges, surface_chain
from ntncontact.mesh.gmsh_io import read_msh
from ntncontact.mesh.quadmesh import MeshError

gmsh = pytest.importorskip("gmsh")

EPS = np.finfo(float).eps
# L-shaped domain, counter-clockwise corners; area 3
L_CORNERS = [(0, 0), (2, 0), (2, 1), (1, 1), (1, 2), (0, 2)]


def signed_areas(nodes, cells):
    x, y = nodes[cells, 0], nodes[cells, 1]
    return 0.5 * np.sum(x * np.roll(y, -1, axis=1) - np.roll(x, -1, axis=1) * y, axis=1)


def write_l_shape(path, version=4.1, recombine=True, reverse=False, size=0.2):
    """Mesh the L shape with gmsh; physical groups: surface, two lines, one point."""
    gmsh.initialize()
    try:
        gmsh.option.setNumber("General.Terminal", 0)
        gmsh.model.add("lshape")
        geo = gmsh.model.geo
        points = [geo.addPoint(x, y, 0.0, size) for x, y in L_CORNERS]
        lines = [geo.addLine(points[k], points[(k + 1) % 6]) for k in range(6)]
        # curve 4 drawn from (1, 2) to (1, 1): its line elements run against the body
        lines[3] = geo.addLine(points[4], points[3])
        loop = geo.addCurveLoop([lines[0], lines[1], lines[2], -lines[3], lines[4], lines[5]])
        surface = geo.addPlaneSurface([loop])
        geo.synchronize()
        gmsh.model.addPhysicalGroup(2, [surface], name="body")
        gmsh.model.addPhysicalGroup(1, [lines[0]], name="bottom")
        # the two edges of the re-entrant corner
        gmsh.model.addPhysicalGroup(1, [lines[2], lines[3]], name="step")
        gmsh.model.addPhysicalGroup(0, [points[0]], name="origin")
        # entities in two groups each (format 2.2 then repeats their elements)
        gmsh.model.addPhysicalGroup(1, lines, name="outline")
        gmsh.model.addPhysicalGroup(2, [surface], name="domain")
        if recombine:
            gmsh.option.setNumber("Mesh.Algorithm", 8)  # frontal-Delaunay for quads
            gmsh.option.setNumber("Mesh.RecombinationAlgorithm", 3)  # blossom full-quad
            gmsh.model.mesh.setRecombine(2, surface)
        gmsh.model.mesh.generate(2)
        if reverse:
            gmsh.model.mesh.reverse()
        gmsh.option.setNumber("Mesh.MshFileVersion", version)
        gmsh.write(str(path))
    finally:
        gmsh.finalize()
    return path


@pytest.mark.parametrize("version", [4.1, 2.2])
@pytest.mark.parametrize("reverse", [False, True])
def test_gmsh_round_trip(tmp_path, version, reverse):
    path = write_l_shape(tmp_path / "lshape.msh", version=version, reverse=reverse)
    mesh = read_msh(path)
    assert mesh.name == "lshape"
    areas = signed_areas(mesh.nodes, mesh.cells)
    assert np.all(areas > 0)  # clockwise cells were flipped
    # straight-sided polygon: tiled exactly up to the 17-digit coordinates in the file
    assert areas.sum() == pytest.approx(3.0, rel=1e3 * EPS)
    assert set(mesh.node_sets) == {"body", "domain", "bottom", "step", "origin", "outline"}
    assert set(mesh.edge_sets) == {"bottom", "step", "outline"}
    assert np.array_equal(mesh.node_sets["domain"], mesh.node_sets["body"])
    outline = surface_chain(mesh, "outline")
    assert outline.closed and len(outline.nodes) == len(boundary_edges(mesh))
    assert len(mesh.node_sets["body"]) == mesh.n_nodes  # unused nodes removed
    assert np.allclose(mesh.nodes[mesh.node_sets["origin"]], [[0.0, 0.0]], atol=0.0)
    xy = mesh.nodes
    bottom = mesh.edge_sets["bottom"]
    assert np.all(np.abs(xy[bottom, 1]) <= 10 * EPS)
    assert np.all(xy[bottom[:, 1], 0] > xy[bottom[:, 0], 0])  # left to right: body above
    # every edge set lies on the boundary with the body on its left
    oriented = {tuple(e) for e in boundary_edges(mesh).tolist()}
    for edges in mesh.edge_sets.values():
        assert all(tuple(e) in oriented for e in edges.tolist())
    step = surface_chain(mesh, "step")
    # walking with the body on the left goes (2,1) -> (1,1) -> (1,2)
    assert not step.closed
    assert np.allclose(xy[step.nodes[[0, -1]]], [[2.0, 1.0], [1.0, 2.0]], atol=10 * EPS)
    assert any(np.allclose(p, [1.0, 1.0], atol=10 * EPS) for p in xy[step.nodes])


def test_triangles_are_rejected_with_file_name(tmp_path):
    path = write_l_shape(tmp_path / "triangles.msh", recombine=False)
    with pytest.raises(MeshError, match=r"triangles\.msh.*triangles"):
        read_msh(path)


def test_an_interior_line_group_is_a_node_set_only(tmp_path):
    gmsh.initialize()
    try:
        gmsh.option.setNumber("General.Terminal", 0)
        geo = gmsh.model.geo
        p = [geo.addPoint(x, y, 0.0) for x, y in [(0, 0), (1, 0), (2, 0), (2, 1), (1, 1),
                                                  (0, 1)]]
        lines = [geo.addLine(p[k], p[(k + 1) % 6]) for k in range(6)]
        middle = geo.addLine(p[1], p[4])
        left = geo.addPlaneSurface([geo.addCurveLoop([lines[0], middle, lines[4], lines[5]])])
        right = geo.addPlaneSurface([geo.addCurveLoop([lines[1], lines[2], lines[3], -middle])])
        geo.synchronize()
        for curve in [*lines, middle]:
            gmsh.model.mesh.setTransfiniteCurve(curve, 3)
        for s in (left, right):
            gmsh.model.mesh.setTransfiniteSurface(s)
            gmsh.model.mesh.setRecombine(2, s)
        gmsh.model.addPhysicalGroup(2, [left, right], name="body")
        gmsh.model.addPhysicalGroup(1, [middle], name="interface")
        gmsh.model.mesh.generate(2)
        gmsh.write(str(tmp_path / "two.msh"))
    finally:
        gmsh.finalize()
    # a line inside the mesh is a node set, not a surface (a tester's mesh with such a line,
    # never used, was refused as a whole)
    with pytest.warns(UserWarning, match="'interface'.*inside the quad mesh.*node set only"):
        mesh = read_msh(tmp_path / "two.msh")
    assert "interface" in mesh.node_sets and "interface" not in mesh.edge_sets
    assert mesh.node_sets["interface"].size == 3  # the line's three nodes
    with pytest.raises(MeshError, match="'interface' is a node set only"):
        mesh.edge_set("interface")


def test_meshio_written_file_renumbers_and_flips(tmp_path):
    # node 0 is unused; cell 1 is clockwise
    points = np.array([[9.0, 9.0, 0.0], [0, 0, 0], [1, 0, 0], [2, 0, 0], [0, 1, 0], [1, 1, 0],
                       [2, 1, 0]], dtype=float)
    quads = np.array([[1, 2, 5, 4], [2, 5, 6, 3]])
    lines = np.array([[6, 3]])  # right side, written top to bottom (against the body)
    mesh = meshio.Mesh(
        points,
        [("quad", quads), ("line", lines)],
        cell_data={"gmsh:physical": [np.array([1, 1]), np.array([2])],
                   "gmsh:geometrical": [np.array([1, 1]), np.array([1])]},
        field_data={"body": np.array([1, 2]), "right": np.array([2, 1])},
    )
    path = tmp_path / "tiny.msh"
    meshio.write(path, mesh, file_format="gmsh22", binary=False)
    out = read_msh(path, name="tiny")
    assert out.name == "tiny" and out.n_nodes == 6
    assert np.allclose(out.nodes[0], [0.0, 0.0], atol=0.0)  # unused node dropped
    assert np.all(signed_areas(out.nodes, out.cells) == pytest.approx(1.0, rel=10 * EPS))
    right = out.edge_sets["right"]
    assert np.allclose(out.nodes[right[0]], [[2.0, 0.0], [2.0, 1.0]], atol=0.0)  # bottom -> top


def test_unreadable_and_missing_files(tmp_path):
    bad = tmp_path / "bad.msh"
    bad.write_text("this is not a mesh\n")
    with pytest.raises(MeshError, match=r"bad\.msh: not a gmsh \.msh file"):
        read_msh(bad)
    with pytest.raises(FileNotFoundError, match="missing"):
        read_msh(tmp_path / "missing.msh")


def test_non_planar_mesh_is_rejected(tmp_path):
    points = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0.5], [0, 1, 0]], dtype=float)
    mesh = meshio.Mesh(points, [("quad", np.array([[0, 1, 2, 3]]))],
                       cell_data={"gmsh:physical": [np.array([1])],
                                  "gmsh:geometrical": [np.array([1])]})
    path = tmp_path / "warped.msh"
    meshio.write(path, mesh, file_format="gmsh22", binary=False)
    with pytest.raises(MeshError, match="plane"):
        read_msh(path)


def test_coincident_nodes_are_refused(tmp_path):
    """Two quads side by side whose shared edge has its nodes twice (parts meshed apart and
    not merged): the cells are not joined, a crack. Before, the file was read and a pressed
    block ran as two halves overlapping by 0.0125; now it is refused, with where and what
    to do. The same quads on shared nodes are read."""
    points = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0],
                       [1, 0, 0], [2, 0, 0], [2, 1, 0], [1, 1, 0]], dtype=float)
    apart = np.array([[0, 1, 2, 3], [4, 5, 6, 7]])
    joined = np.array([[0, 1, 2, 3], [1, 5, 6, 2]])
    for name, quads in (("apart", apart), ("joined", joined)):
        mesh = meshio.Mesh(points, [("quad", quads)],
                           cell_data={"gmsh:physical": [np.array([1, 1])],
                                      "gmsh:geometrical": [np.array([1, 1])]})
        meshio.write(tmp_path / f"{name}.msh", mesh, file_format="gmsh22", binary=False)
    with pytest.raises(MeshError, match=r"apart\.msh: 2 pair\(s\) of nodes coincide, the first "
                                        r"at \(1, 0\).*Coherence"):
        read_msh(tmp_path / "apart.msh")
    assert read_msh(tmp_path / "joined.msh").n_nodes == 6


def test_unnamed_physical_groups_are_sets_by_number(tmp_path):
    """gmsh writes a physical group without a name when the name went to another group
    already (two lines both named "top"), and legacy .geo files number them only. Before,
    such a group was dropped without a word (a tester's top pressure acted on half the top);
    now it is the set "5", with a warning. Tag 0 (no group) makes no set."""
    points = np.array([[0, 0, 0], [1, 0, 0], [2, 0, 0], [0, 1, 0], [1, 1, 0], [2, 1, 0]],
                      dtype=float)
    quads = np.array([[0, 1, 4, 3], [1, 2, 5, 4]])
    lines = np.array([[5, 4], [4, 3], [0, 1]])  # the top, right to left, then a bottom edge
    mesh = meshio.Mesh(points, [("quad", quads), ("line", lines)],
                       cell_data={"gmsh:physical": [np.array([1, 1]), np.array([4, 5, 0])],
                                  "gmsh:geometrical": [np.array([1, 1]), np.array([1, 2, 3])]},
                       field_data={"body": np.array([1, 2]), "top": np.array([4, 1])})
    meshio.write(tmp_path / "numbered.msh", mesh, file_format="gmsh22", binary=False)
    with pytest.warns(UserWarning, match=r'physical group 5 \(lines\) has no name; it is the '
                                         r'set "5"'):
        out = read_msh(tmp_path / "numbered.msh")
    assert sorted(out.edge_sets) == ["5", "top"]
    assert np.allclose(out.nodes[out.edge_sets["5"][0]], [[1.0, 1.0], [0.0, 1.0]], atol=0.0)
    assert "0" not in out.node_sets


def test_hanging_nodes_are_refused(tmp_path):
    """Two cells stacked beside one cell of twice their height, merged at the corners only: the
    middle node (1, 0.5) hangs on the big cell's edge, a crack (a tester's 4 x 4 beside 2 x 2
    block opened by 3.4 % of its displacement under a body force, read without a word). Now it
    is refused, with where, the body and the cure; the right part split in two is read."""
    points = np.array([[0, 0, 0], [1, 0, 0], [1, 0.5, 0], [0, 0.5, 0], [1, 1, 0], [0, 1, 0],
                       [2, 0, 0], [2, 1, 0], [2, 0.5, 0]], dtype=float)
    left = [[0, 1, 2, 3], [3, 2, 4, 5]]
    meshes = {"hanging": left + [[1, 6, 7, 4]], "conformal": left + [[1, 6, 8, 2], [2, 8, 7, 4]]}
    for name, quads in meshes.items():
        tags = np.ones(len(quads), dtype=int)
        mesh = meshio.Mesh(points, [("quad", np.array(quads))],
                           cell_data={"gmsh:physical": [tags], "gmsh:geometrical": [tags]})
        meshio.write(tmp_path / f"{name}.msh", mesh, file_format="gmsh22", binary=False)
    with pytest.raises(MeshError, match=r"hanging\.msh \(body 'blk'\): 1 node\(s\) hang on "
                                        r"another cell's edge.*at \(1, 0\.5\) \(file node 3\) "
                                        r"on the edge from \(1, 1\) to \(1, 0\).*Coherence.*"
                                        r"\[\[tie\]\]"):
        read_msh(tmp_path / "hanging.msh", name="blk")
    assert read_msh(tmp_path / "conformal.msh").n_cells == 4


# one quad with its bottom edge in the line group "bottom" (format 4.1); the line block's
# entity tag is {curve}: 1 is the curve $Entities lists, 2 is none; node tags from {t1}
V41_ONE_QUAD = """$MeshFormat
4.1 0 8
$EndMeshFormat
$PhysicalNames
2
1 2 "bottom"
2 1 "body"
$EndPhysicalNames
$Entities
0 1 1 0
1 0 0 0 1 0 0 1 2 0
1 0 0 0 1 1 0 1 1 0
$EndEntities
$Nodes
1 4 {t1} {t4}
2 1 0 4
{t1}
{t2}
{t3}
{t4}
0 0 0
1 0 0
1 1 0
0 1 0
$EndNodes
$Elements
2 2 1 2
1 {curve} 1 1
1 {t1} {t2}
2 1 3 1
2 {t1} {t2} {t3} {t4}
$EndElements
"""


def _one_quad_v41(curve: int = 1, first_tag: int = 1) -> str:
    return V41_ONE_QUAD.format(curve=curve, **{f"t{k}": first_tag + k - 1 for k in range(1, 5)})


def test_other_formats_are_refused_with_the_formats_read(tmp_path):
    """An Abaqus .inp or a .vtu given as a gmsh mesh was refused with "(ReadError: )"; now
    the message says which formats are read and how to convert."""
    mesh = meshio.Mesh(np.array([[0, 0], [1, 0], [1, 1], [0, 1]], dtype=float),
                       [("quad", np.array([[0, 1, 2, 3]]))])
    for suffix in ("inp", "vtu"):
        meshio.write(tmp_path / f"block.{suffix}", mesh)
        with pytest.raises(MeshError, match=rf"block\.{suffix}: not a gmsh \.msh file.*format "
                                            r"2\.2 or 4\.1.*meshio convert in\.inp out\.msh"):
            read_msh(tmp_path / f"block.{suffix}")


def test_inconsistent_v41_entities_are_named(tmp_path):
    """A v4.1 file whose line block names an entity $Entities lacks gave "(KeyError:
    np.int32(2))"; the consistent file is read."""
    for curve in (1, 2):
        (tmp_path / f"curve{curve}.msh").write_text(_one_quad_v41(curve))
    assert read_msh(tmp_path / "curve1.msh").edge_sets["bottom"].shape == (1, 2)
    with pytest.raises(MeshError, match=r"curve2\.msh: the file's entities and physical groups "
                                        r"are inconsistent.*entity 2,"):
        read_msh(tmp_path / "curve2.msh")


def test_second_order_quads_get_the_element_order_hint(tmp_path):
    points = np.array([[0, 0, 0], [2, 0, 0], [2, 2, 0], [0, 2, 0], [1, 0, 0], [2, 1, 0],
                       [1, 2, 0], [0, 1, 0], [1, 1, 0]], dtype=float)
    mesh = meshio.Mesh(points, [("quad9", np.arange(9)[None, :])],
                       cell_data={"gmsh:physical": [np.array([1])],
                                  "gmsh:geometrical": [np.array([1])]})
    meshio.write(tmp_path / "q9.msh", mesh, file_format="gmsh22", binary=False)
    with pytest.raises(MeshError, match=r"\['quad9'\].*Mesh\.ElementOrder = 1"):
        read_msh(tmp_path / "q9.msh")


def test_the_files_node_numbers_are_kept(tmp_path):
    """The reader numbers the nodes 0..n-1 and messages and outputs use those; the file's own
    numbers (sparse here: 11..14; 4.1's reader gives them less one) are kept as
    ``file_node_ids``, through a rigid placement, and a generated mesh has none."""
    (tmp_path / "sparse.msh").write_text(_one_quad_v41(first_tag=11))
    mesh = read_msh(tmp_path / "sparse.msh")
    assert mesh.file_node_ids.tolist() == [11, 12, 13, 14]
    assert mesh.transformed(30.0, (1.0, 2.0)).file_node_ids.tolist() == [11, 12, 13, 14]
    assert mesh.with_sets({"a": [0]}).file_node_ids.tolist() == [11, 12, 13, 14]


def _one_quad_v22(nodes: str, element: str = "1 3 2 1 1 1 2 3 4") -> str:
    return ("$MeshFormat\n2.2 0 8\n$EndMeshFormat\n$PhysicalNames\n1\n2 1 \"block\"\n"
            f"$EndPhysicalNames\n$Nodes\n4\n{nodes}$EndNodes\n$Elements\n1\n{element}\n"
            "$EndElements\n")


SQUARE = "1 0 0 0\n2 1 0 0\n3 1 1 0\n4 0 1 0\n"


def test_malformed_gmsh_files_are_named_for_what_they_are(tmp_path):
    """A tester's malformed gmsh files: a NaN coordinate ("data must be finite", naming
    nothing), an element citing an undefined node and a format 4.0 file (both told to convert
    an Abaqus file with meshio)."""
    (tmp_path / "good.msh").write_text(_one_quad_v22(SQUARE))
    assert read_msh(tmp_path / "good.msh").n_cells == 1
    (tmp_path / "nan.msh").write_text(_one_quad_v22(SQUARE.replace("2 1 0 0", "2 nan 0 0")))
    with pytest.raises(MeshError, match=r"nan\.msh: 1 node\(s\) with a coordinate that is not "
                                        r"a number, the first file node 2"):
        read_msh(tmp_path / "nan.msh")
    (tmp_path / "orphan.msh").write_text(_one_quad_v22(SQUARE, "1 3 2 1 1 1 2 3 999"))
    with pytest.raises(MeshError, match=r"orphan\.msh: a gmsh format 2\.2 file that cannot be "
                                        r"read: an element may cite a node"):
        read_msh(tmp_path / "orphan.msh")
    (tmp_path / "old.msh").write_text(_one_quad_v22(SQUARE).replace("2.2 0 8", "4 0 8"))
    with pytest.raises(MeshError, match=r"old\.msh: gmsh format 4; ntncontact reads formats "
                                        r"2\.2 and 4\.1"):
        read_msh(tmp_path / "old.msh")


def test_a_t_junction_on_a_curved_shared_line_is_refused():
    """A tester's quarter ring, r 1 to 1.2 meshed with 8 cells around and r 1.2 to 1.5 with 4
    (every other node on r = 1.2 shared): the finer part's loose nodes sit on the arc, off the
    coarser cells' chords (straight-edge T-junction test: not seen), and the run was 5.8 % off
    at the inner surface. They lie inside the coarser cells, which is refused; the conformal
    ring is read."""
    from pathlib import Path

    data = Path(__file__).parent / "data"
    assert read_msh(data / "quarter_ring_conformal.msh").n_cells > 0
    with pytest.raises(MeshError, match=r"4 boundary node\(s\) lie inside another cell of the "
                                        r"body.*different divisions on a curved shared line"):
        read_msh(data / "quarter_ring_curved_junction.msh")
