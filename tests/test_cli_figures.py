"""Figures written after a run (``ntncontact run --plot``) and by ``ntncontact plot``."""

import json

from helpers import EXAMPLES

from ntncontact.cli import main

TIMES = ["0.1", "0.3"]


def _figures(folder):
    return {p.name for p in folder.glob("*.png")} | {p.name for p in folder.glob("*.gif")}


def test_run_with_plot_writes_the_figures_of_plot(tmp_path, capsys):
    live, after = tmp_path / "live", tmp_path / "after"
    args = [str(EXAMPLES / "rod_impact.toml"), "--quiet", "--set", "analysis.t_end=0.5"]
    assert main(["run", *args, "--out", str(live), "--gif", "--times", *TIMES]) == 0
    printed = capsys.readouterr().out
    assert main(["run", *args, "--out", str(after)]) == 0
    assert main(["plot", str(after), "--gif", "--times", *TIMES]) == 0
    names = _figures(live)
    assert names == _figures(after)
    assert {"snapshots.png", "animation.gif", "energies.png", "pair_history.png"} <= names
    assert "deformed_von_mises.png" not in names  # the snapshots at the times take its place
    assert all(str(live / name) in printed for name in names)
    assert main(["plot", str(after)]) == 0  # no times: six evenly spaced meshes
    assert (after / "deformed_von_mises.png").is_file()


def test_failed_run_with_plot_draws_nothing_and_keeps_the_folder(tmp_path, capsys):
    out = tmp_path / "o"
    code = main(["run", str(EXAMPLES / "rod_impact.toml"), "--out", str(out), "--quiet", "--gif",
                 "--set", "analysis.t_end=0.5", "--set", "analysis.max_cutbacks=0",
                 "--set", "analysis.newton.max_iterations=1"])
    assert code == 1 and "error" in capsys.readouterr().err
    assert json.loads((out / "summary.json").read_text())["status"] == "failed"
    assert not _figures(out)  # nothing drawn
    assert main(["plot", str(out)]) == 0  # but the folder is still plottable
    assert (out / "energies.png").is_file()
