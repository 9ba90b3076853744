"""The command line end to end: run, results folder contract, plot, errors."""

import json

import numpy as np
import pytest
from helpers import EXAMPLES

from ntncontact.cli import main
from ntncontact.io.writers import HISTORY_COLUMNS, read_csv_table


def test_run_writes_history_summary_and_fields_then_plot(tmp_path, capsys):
    out = tmp_path / "res"
    code = main(["run", str(EXAMPLES / "spinning_block.toml"), "--out", str(out), "--quiet",
                 "--set", "analysis.t_end=0.2"])
    assert code == 0
    table = read_csv_table(out / "history.csv")
    assert list(table)[: len(HISTORY_COLUMNS)] == list(HISTORY_COLUMNS)
    assert len(table["step"]) == 11 and table["time"][-1] == np.float64(0.2)
    summary = json.loads((out / "summary.json").read_text())
    assert summary["status"] == "completed" and summary["steps"] == 10
    for key in ("wall_time_s", "cpu_time_s", "energy_initial", "energy_final",
                "energy_max_relative_variation"):
        assert key in summary
    assert (out / "fields.pvd").is_file() and len(list((out / "fields").glob("*.vtu"))) == 3
    assert main(["plot", str(out)]) == 0
    assert len(list(out.glob("*.png"))) >= 3


def test_run_with_bad_scenario_reports_and_fails(tmp_path, capsys):
    bad = tmp_path / "bad.toml"
    bad.write_text((EXAMPLES / "spinning_block.toml").read_text().replace("dt =", "dtt ="))
    assert main(["run", str(bad), "--out", str(tmp_path / "o"), "--quiet"]) == 1
    err = capsys.readouterr().err
    assert "analysis.dtt: unknown key" in err and "analysis.dt: Field required" in err


def test_a_failing_run_leaves_readable_results(tmp_path, capsys):
    """A load far too large for one step with no cut-backs: error names the step, files stay."""
    case = tmp_path / "crush.toml"
    case.write_text("""
[analysis]
kind = "static"
dt = 0.5
t_end = 1.0
max_cutbacks = 1
newton = { max_iterations = 6 }
[[bodies]]
name = "pad"
mesh = { type = "rectangle", width = 1.0, height = 1.0, nx = 4, ny = 4 }
material = { model = "neo_hookean", E = 1.0, nu = 0.3, density = 1.0 }
supports = [ { set = "bottom", x = 0.0, y = 0.0 } ]
[[bodies.loads]]
type = "pressure"
set = "top"
value = 50.0
function = { times = [0.0, 0.5, 1.0], values = [0.0, 0.0001, 1.0] }
""")
    assert main(["run", str(case), "--out", str(tmp_path / "o"), "--quiet"]) == 1
    err = capsys.readouterr().err
    assert "step 2" in err and "halvings" in err
    summary = json.loads((tmp_path / "o" / "summary.json").read_text())
    assert summary["status"] == "failed" and "step 2" in summary["error"]
    assert len(read_csv_table(tmp_path / "o" / "history.csv")["step"]) == 2


def test_contact_run_writes_contact_csv_summary_and_pair_plots(tmp_path):
    out = tmp_path / "rods"
    assert main(["run", str(EXAMPLES / "rod_impact.toml"), "--out", str(out), "--quiet",
                 "--set", "analysis.t_end=0.5"]) == 0
    rows = read_csv_table(out / "contact.csv")
    assert set(rows["interface"]) == {"rod_ends"} and np.all(rows["normal_traction"] > 0)
    summary = json.loads((out / "summary.json").read_text())
    # the rods touch at t = 0.05, a step end, with a gap zero to round-off: the pair enters
    # then (interfaces.touch_tolerance), so persistency freezes no step's approach v dt = 0.05
    assert summary["contact_start_time"] == 0.05 and summary["max_active_pairs"] == 2
    assert abs(summary["max_penetration"]) < 1e-9
    history = read_csv_table(out / "history.csv")
    assert {"active_pairs", "frictional_dissipation", "augmentations"} <= set(history)
    assert main(["plot", str(out), "--gif", "--times", "0.1", "0.3"]) == 0
    assert (out / "pair_history.png").is_file() and (out / "contact_tractions.png").is_file()
    assert (out / "snapshots.png").is_file() and (out / "animation.gif").stat().st_size > 1000


def test_mesh_quality_command_and_summary(tmp_path, capsys):
    assert main(["mesh-quality", str(EXAMPLES / "spinning_block.toml")]) == 0
    out = capsys.readouterr().out
    assert "block:" in out and "min_angle_deg" in out and "90" in out
    res = tmp_path / "r"
    assert main(["run", str(EXAMPLES / "spinning_block.toml"), "--out", str(res), "--quiet",
                 "--set", "analysis.t_end=0.04"]) == 0
    quality = json.loads((res / "summary.json").read_text())["mesh_quality"]["block"]
    # a spinning, deforming block: angles move away from 90 but the mesh stays valid
    assert 45.0 < quality["min_angle_deg"] < 90.0 < quality["max_angle_deg"] < 135.0
    vtu = sorted((res / "fields").glob("*.vtu"))[-1]
    assert main(["mesh-quality", str(vtu)]) == 0
    # the results folder itself: its summary's final meshes (a tester's got "no such file")
    capsys.readouterr()
    assert main(["mesh-quality", str(res)]) == 0
    assert f"{quality['min_angle_deg']:.6g}" in capsys.readouterr().out
    assert main(["mesh-quality", str(tmp_path)]) == 1
    assert "a folder without summary.json" in capsys.readouterr().err


def test_output_into_a_closed_pipe_ends_quietly(tmp_path):
    """`ntncontact mesh-quality ... | head -1`: the reader closed the pipe; the command used to
    say "error: [Errno 32] Broken pipe"."""
    import subprocess
    import sys

    code = ("import sys; sys.argv = ['ntncontact', 'mesh-quality', "
            f"{str(EXAMPLES / 'ring_impact.toml')!r}]; "
            "from ntncontact.cli import console_main; console_main()")
    child = subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE,
                             stderr=subprocess.PIPE, text=True)
    child.stdout.close()  # before the command writes anything
    err = child.stderr.read()
    assert child.wait(timeout=120) == 141 and err == "", err


def test_mesh_quality_of_a_plain_vtu_mesh_reads_its_points(tmp_path, capsys):
    """A VTU that is not a results frame (no displacement field) is a mesh: its points are
    measured (a tester's plain quad mesh gave a KeyError traceback)."""
    import meshio
    import numpy as np

    points = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 1.0, 0.0], [0.0, 1.0, 0.0],
                       [2.0, 0.0, 0.0], [2.0, 1.0, 0.0]])
    path = tmp_path / "plain.vtu"
    meshio.write(path, meshio.Mesh(points, [("quad", np.array([[0, 1, 2, 3], [1, 4, 5, 2]]))]))
    assert main(["mesh-quality", str(path)]) == 0
    out = capsys.readouterr().out
    assert "plain.vtu" in out and "90" in out  # unit squares: every angle 90 degrees


@pytest.mark.parametrize("content", [b"garbage", b"<VTKFile type=\"UnstructuredGrid\""])
def test_mesh_quality_of_a_corrupt_vtu_is_one_error_line(tmp_path, capsys, content):
    """A frame that is not VTU, or cut short: before, meshio's ReadError or the XML parser's
    error reached the user as a traceback."""
    bad = tmp_path / "frame.vtu"
    bad.write_bytes(content)
    assert main(["mesh-quality", str(bad)]) == 1
    err = capsys.readouterr().err
    assert err.startswith(f"error: {bad} is not a readable VTU file")
    assert len(err.strip().splitlines()) == 1


def test_run_with_compare_prints_and_writes_the_comparison(tmp_path, capsys):
    out = tmp_path / "ring"
    assert main(["run", str(EXAMPLES / "ring_impact.toml"), "--out", str(out), "--quiet",
                 "--set", "analysis.t_end=0.1", "--compare"]) == 0
    printed = capsys.readouterr().out
    assert "ring_impact" in printed and "energy_initial" in printed
    assert printed.index("results written") < printed.index("energy_initial")
    assert (out / "comparison.csv").is_file()


def _console(args: list[str]):
    """The installed command's entry point, in a child process (it exits)."""
    import os
    import subprocess
    import sys

    code = f"import sys; sys.argv = ['ntncontact'] + {args!r}; " \
           "from ntncontact.cli import console_main; console_main()"
    # buffered streams, as for a user's pipe (PYTHONUNBUFFERED would hide a missing flush)
    env = {k: v for k, v in os.environ.items() if k != "PYTHONUNBUFFERED"}
    return subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          timeout=120, env=env)


def test_console_command_flushes_its_output_and_keeps_the_exit_code(tmp_path, capsys):
    """What main printed arrives whole through the installed command's entry point (the
    streams are pipes here, so block-buffered), and main's exit code is the process's."""
    scenario = str(EXAMPLES / "ring_impact.toml")
    assert main(["mesh-quality", scenario]) == 0
    expected = capsys.readouterr().out
    done = _console(["mesh-quality", scenario])
    assert done.returncode == 0 and done.stdout == expected and len(expected) > 100
    bad = tmp_path / "bad.toml"
    bad.write_text((EXAMPLES / "spinning_block.toml").read_text().replace("dt =", "dtt ="))
    failed = _console(["run", str(bad), "--out", str(tmp_path / "o"), "--quiet"])
    assert failed.returncode == 1 and "analysis.dtt: unknown key" in failed.stderr


def _demo_recipe() -> tuple[list[str], str]:
    """The Makefile's demo target: the ntncontact command's arguments and what it echoes."""
    import shlex

    lines = (EXAMPLES.parent / "Makefile").read_text().split("\ndemo:", 1)[1].splitlines()[1:]
    recipe = []
    for line in lines:
        if not line.startswith("\t"):
            break
        recipe.append(line.strip())
    command = " ".join(recipe).split("@echo")[0].replace("\\", " ")
    words = shlex.split(command)
    run = words[words.index("$(BIN)/ntncontact") + 1:]
    echoed = " ".join(line for line in recipe if line.startswith("@echo"))
    return run, echoed


def test_the_demo_runs_the_ring_impact_and_writes_what_it_says(tmp_path):
    """`make demo`'s command, run as the installed command (into another folder): the whole
    ring impact, completed, with the comparison printed, and every file its closing lines
    point to."""
    import json

    run, echoed = _demo_recipe()
    assert run[:2] == ["run", "examples/ring_impact.toml"] and "--gif" in run
    folder = run[run.index("--out") + 1]
    run[run.index("--out") + 1] = str(tmp_path)
    run[1] = str(EXAMPLES / "ring_impact.toml")
    done = _console(run)
    assert done.returncode == 0, done.stderr
    assert "energy_max_relative_variation" in done.stdout  # --compare
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["status"] == "completed" and summary["unconverged_steps"] == 0
    named = {word.strip(',;:"') for word in echoed.replace(folder + "/", " ").split()}
    files = {"fields.pvd", "history.csv", "contact.csv", "summary.json", "animation.gif"}
    assert files <= named
    assert all((tmp_path / name).is_file() for name in files)
    assert {"snapshots.png", "energies.png"} <= {p.name for p in tmp_path.glob("*.png")}


@pytest.mark.parametrize(("sets", "warned"), [
    (["bodies.0.material.nu=0.49"], True),
    (["bodies.0.material.nu=0.3"], False),
    (["bodies.0.material.nu=0.49", "bodies.0.material.plane_stress=true",
      'bodies.0.material.model="linear_elastic"'], False),  # plane stress does not lock
])
def test_a_nearly_incompressible_plane_strain_body_is_warned_of_locking(tmp_path, capsys, sets,
                                                                        warned):
    """A tester's cantilever deflected 0.50 of beam theory at nu = 0.49 without a word."""
    args = [item for s in sets for item in ("--set", s)]
    assert main(["run", str(EXAMPLES / "spinning_block.toml"), "--out", str(tmp_path / "o"),
                 "--quiet", "--set", "analysis.t_end=0.04", *args]) == 0
    err = capsys.readouterr().err
    assert err.count("lock near incompressibility") == (1 if warned else 0), err
