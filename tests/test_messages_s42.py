"""Messages a tester (W) found unhelpful: a sweep.csv column of Python traceback for a diverged
solve, a gmsh group named as another dimension's group reported as having no name, mesh
checks naming 0-based indices where the file says other numbers, and small command-line slips
(a folder for the scenario, a file for --out, an empty --set key, a sweep's missing scenario).
"""


from helpers import EXAMPLES

from ntncontact.engine.simulation import SimulationError
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
