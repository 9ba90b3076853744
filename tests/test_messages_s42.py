"""Messages a tester (W) found unhelpful: a sweep.csv column of Python traceback for a diverged
solve, a gmsh group named as another dimension's group reported as having no name, mesh
checks naming 0-based indices where the file says other numbers, and small command-line slips
(a folder for the scenario, a file for --out, an empty --set key, a sweep's missing scenario).
"""

import re

import numpy as np
import pytest
from helpers import EXAMPLES

from ntncontact.cli import main
from ntncontact.engine.simulation import SimulationError
from ntncontact.mesh.gmsh_io import read_msh
from ntncontact.studies import sweep as sweep_module

BLOCK_MSH = EXAMPLES / "meshes" / "block_sliding_block.msh"
#: the example block's first quad of its second row: file element 51, file nodes 53 54 75 74
ELEMENT_51 = "51 3 2 1 1 53 54 75 74\n"


def _failing_run(err: Exception):
    def run(*_, **__):
        raise err
    return run


def test_a_diverged_case_keeps_its_one_line_error_and_no_traceback(tmp_path, monkeypatch):
    """A SimulationError is the run's own verdict: sweep.csv had a `traceback` column of
    2,486 characters for it; now only the one-line error, and no traceback file."""
    monkeypatch.setattr(sweep_module, "run", _failing_run(
        SimulationError("step 2 (t = 0.05 -> 0.1) failed: Newton diverged")))
    folder = tmp_path / "case-a"
    row = sweep_module.run_case(str(EXAMPLES / "rod_impact.toml"), {"analysis.t_end": 0.2},
                                str(folder), {})
    assert "traceback" not in row
    assert row["status"] == "failed"
    assert row["error"] == "SimulationError: step 2 (t = 0.05 -> 0.1) failed: Newton diverged"
    assert not (folder / sweep_module.TRACEBACK_FILE).exists()


def test_an_internal_error_of_a_case_keeps_its_traceback_in_the_case_folder(tmp_path,
                                                                           monkeypatch):
    """A bug (an unexpected exception type) keeps its traceback, in CASE/traceback.txt, named
    by the error column; a later run of the case that does not fail removes it."""
    monkeypatch.setattr(sweep_module, "run", _failing_run(KeyError("gap")))
    folder = tmp_path / "case-b"
    row = sweep_module.run_case(str(EXAMPLES / "rod_impact.toml"), {}, str(folder), {})
    saved = folder / sweep_module.TRACEBACK_FILE
    assert "traceback" not in row and "\n" not in row["error"]
    assert row["error"] == (f"KeyError: 'gap' (an internal error; its traceback is in "
                            f"{saved})")
    text = saved.read_text()
    assert text.startswith("Traceback (most recent call last)") and "KeyError: 'gap'" in text
    monkeypatch.setattr(sweep_module, "run", _failing_run(SimulationError("diverged")))
    sweep_module.run_case(str(EXAMPLES / "rod_impact.toml"), {}, str(folder), {})
    assert not saved.exists()


def test_a_point_group_named_as_a_line_group_is_named_in_the_warning(tmp_path):
    """gmsh allows a point group "bottom" beside the line group "bottom"; meshio keeps one.
    The warning said the point group had no name."""
    text = BLOCK_MSH.read_text().replace('0 10 "bottom_inner"', '0 10 "bottom"')
    (tmp_path / "dup.msh").write_text(text)
    with pytest.warns(UserWarning) as caught:
        mesh = read_msh(tmp_path / "dup.msh")
    (message,) = [str(w.message) for w in caught]
    assert ('physical point group 10 and line group 2 are both named "bottom"' in message
            and 'the set "bottom" is the line group 2, and the point group is the set "10"'
            in message), message
    assert "no name" not in message
    original = read_msh(BLOCK_MSH)
    assert np.array_equal(mesh.edge_sets["bottom"], original.edge_sets["bottom"])
    assert np.array_equal(mesh.node_sets["10"], original.node_sets["bottom_inner"])


def _run_error(tmp_path, capsys, mesh_text: str) -> str:
    """The error line of `ntncontact run` on a block of this mesh text dropped on a base."""
    (tmp_path / "block.msh").write_text(mesh_text)
    scenario = (EXAMPLES / "block_sliding.toml").read_text()
    scenario = re.sub(r'file = "[^"]*block_sliding_block.msh"', 'file = "block.msh"', scenario)
    assert 'file = "block.msh"' in scenario
    (tmp_path / "s.toml").write_text(scenario)
    assert main(["run", str(tmp_path / "s.toml"), "--out", str(tmp_path / "o"), "--quiet"]) == 1
    return capsys.readouterr().err


@pytest.mark.parametrize("tag", [51, 9051])
def test_a_degenerate_file_element_is_named_by_the_file_numbers(tmp_path, capsys, tag):
    """Element 51 with the node 53 twice was "element 50 ... at node 52" (0-based indices);
    with its tag changed to 9051, the message follows the file's tag, not the position."""
    text = BLOCK_MSH.read_text().replace(ELEMENT_51, f"{tag} 3 2 1 1 53 54 75 53\n")
    err = _run_error(tmp_path, capsys, text)
    assert (f"body 'block': file element {tag} is degenerate (corner Jacobian 0 at file node "
            "53)") in err, err


def test_a_twisted_file_element_is_named_by_the_file_numbers(tmp_path, capsys):
    """A bow-tie was "cell 50 has (near) zero area"."""
    text = BLOCK_MSH.read_text().replace(ELEMENT_51, "51 3 2 1 1 54 53 75 74\n")
    err = _run_error(tmp_path, capsys, text)
    assert "file element 51 (nodes 54 53 75 74) has (near) zero area" in err, err
    assert "cell 50" not in err


@pytest.mark.parametrize(("version", "binary"), [(4.1, 0), (4.1, 1), (2.2, 0), (2.2, 1)])
def test_the_file_element_numbers_are_read_in_every_format(tmp_path, version, binary):
    """The quads' element numbers of gmsh's own files (which start after the line and point
    elements, 11 here, not at 1), ASCII and binary, formats 4.1 and 2.2."""
    gmsh = pytest.importorskip("gmsh")
    gmsh.initialize()
    try:
        gmsh.option.setNumber("General.Terminal", 0)
        gmsh.model.add("plate")
        surface = gmsh.model.occ.addRectangle(0, 0, 0, 2, 1)
        gmsh.model.occ.synchronize()
        gmsh.model.addPhysicalGroup(2, [surface], name="plate")
        lines = [tag for _, tag in gmsh.model.getBoundary([(2, surface)], oriented=False)]
        gmsh.model.addPhysicalGroup(1, lines[:1], name="bottom")
        gmsh.option.setNumber("Mesh.RecombineAll", 1)
        gmsh.option.setNumber("Mesh.MeshSizeMax", 0.3)
        gmsh.model.mesh.generate(2)
        tags = np.asarray(gmsh.model.mesh.getElementsByType(3)[0], np.int64)
        gmsh.option.setNumber("Mesh.MshFileVersion", version)
        gmsh.option.setNumber("Mesh.Binary", binary)
        gmsh.write(str(tmp_path / "plate.msh"))
    finally:
        gmsh.finalize()
    mesh = read_msh(tmp_path / "plate.msh")
    assert tags.min() > 1 and mesh.file_element_ids is not None
    assert np.array_equal(mesh.file_element_ids, tags)


def test_a_folder_given_as_the_scenario_is_named_a_folder(capsys, tmp_path):
    assert main(["run", str(EXAMPLES), "--out", str(tmp_path / "o")]) == 1
    err = capsys.readouterr().err
    assert f"{EXAMPLES}: is a folder; expected a TOML file (it holds " in err, err
    assert "not found" not in err


def test_an_existing_file_as_out_is_refused_by_name(capsys, tmp_path):
    (tmp_path / "taken").write_text("mine")
    for command in (["run", str(EXAMPLES / "rod_impact.toml")],
                    ["sweep", str(EXAMPLES / "studies" / "fast_sliding_friction.toml")]):
        assert main([*command, "--out", str(tmp_path / "taken")]) == 1
        err = capsys.readouterr().err
        assert f"--out {tmp_path / 'taken'}: is a file; --out names the results folder" in err
        assert "Errno" not in err
    assert (tmp_path / "taken").read_text() == "mine"


def test_an_empty_set_key_is_named(capsys, tmp_path):
    assert main(["run", str(EXAMPLES / "rod_impact.toml"), "--out", str(tmp_path / "o"),
                 "--set", "=1"]) == 1
    err = capsys.readouterr().err
    assert "override '=1' has an empty key; it must look like key.path=value" in err, err


def test_a_sweep_s_missing_scenario_names_the_sweep_file_and_the_folder(capsys, tmp_path):
    sweep_file = tmp_path / "study.toml"
    sweep_file.write_text('scenario = "nosuch.toml"\n[grid]\n"analysis.t_end" = [0.1]\n')
    assert main(["sweep", str(sweep_file), "--out", str(tmp_path / "o")]) == 1
    err = capsys.readouterr().err
    assert (f'{sweep_file}: scenario = "nosuch.toml": no such file (looked for '
            f"{tmp_path.resolve() / 'nosuch.toml'}; the path is relative to the sweep file's "
            f"folder {tmp_path.resolve()})") in err, err
