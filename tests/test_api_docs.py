"""Every Python example of docs/api.md runs, and the example studies run at reduced size."""

from __future__ import annotations

import re
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import ntncontact as ntc

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

ROOT = Path(__file__).resolve().parents[1]


def python_blocks() -> list[str]:
    return re.findall(r"```python\n(.*?)```", (ROOT / "docs" / "api.md").read_text(), re.S)


@pytest.mark.slow
def test_the_api_page_examples_run_in_order(tmp_path, monkeypatch, capsys):
    """The page's blocks in order, in one session; the sweep's block is a script of its own,
    run by python as a user runs it: its Dask workers import the script again (a tester's
    paste of the page into one unguarded script failed there: "Nanny failed to start")."""
    shutil.copytree(ROOT / "examples", tmp_path / "examples")
    monkeypatch.chdir(tmp_path)
    namespace: dict = {}
    *session, sweep = python_blocks()
    assert "ntc.sweep(" in sweep and 'if __name__ == "__main__":' in sweep
    for block in session:
        exec(compile(block, "docs/api.md", "exec"), namespace)
    printed = capsys.readouterr().out
    assert "completed" in printed and "(91, 3)" in printed
    (tmp_path / "small_sweep.py").write_text(sweep)
    done = subprocess.run([sys.executable, "small_sweep.py"], cwd=tmp_path,
                          capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr
    rows = [line.split() for line in done.stdout.splitlines()]
    rows = [row for row in rows if row[:1] in (["0"], ["1"])]  # the table's two cases
    assert len(rows) == 2 and all("completed" in row for row in rows)


def test_the_api_page_shows_the_sweep_file_it_documents():
    text = (ROOT / "docs" / "api.md").read_text()
    block = re.search(r"```toml\n(.*?)```", text, re.S).group(1)
    from ntncontact.studies.sweep import SweepSpec

    spec = SweepSpec.model_validate(tomllib.loads(block))
    assert len(spec.case_overrides()) == 6


def reduced(path: Path, tmp_path: Path, **replace: object) -> Path:
    """The study file with its scenario path made absolute and some tables replaced."""
    data = tomllib.loads(path.read_text())
    data["scenario"] = str((path.parent / data["scenario"]).resolve())
    from ntncontact.io.scenario import toml_value

    lines = [f"scenario = {toml_value(data['scenario'])}"]
    for table in ("set", "grid", "reductions"):
        values = replace.get(table, data.get(table))
        if values:
            lines.append(f"[{table}]")
            lines += [f'"{k}" = {toml_value(v)}' for k, v in values.items()]
    for case in replace.get("cases", data.get("cases", [])):
        lines.append("[[cases]]")
        lines += [f'"{k}" = {toml_value(v)}' for k, v in case.items()]
    out = tmp_path / path.name
    out.write_text("\n".join(lines) + "\n")
    return out


@pytest.mark.slow
def test_the_friction_study_dissipates_more_with_more_friction(tmp_path):
    study = reduced(ROOT / "examples/studies/fast_sliding_friction.toml", tmp_path,
                    set={"analysis.t_end": 0.15},
                    grid={"contact.0.friction": [0.0, 0.2], "analysis.mass": ["lumped"]})
    table = ntc.sweep(study, tmp_path / "out", workers=2, progress=False)
    assert (table["status"] == "completed").all(), table["error"].tolist()
    assert table["dissipation"].iloc[0] == 0.0  # frictionless
    assert table["dissipation"].iloc[1] > 0.0


@pytest.mark.slow
def test_the_ring_study_refines_the_time_step_and_the_mesh(tmp_path):
    study = reduced(ROOT / "examples/studies/ring_convergence.toml", tmp_path,
                    set={"analysis.t_end": 0.2})
    table = ntc.sweep(study, tmp_path / "out", workers=2, progress=False)
    assert (table["status"] == "completed").all(), table["error"].tolist()
    assert len(table) == 3
    # the ring hits the obstacle in every case: contact starts near the same time
    starts = table["contact_start_time"].to_numpy(float)
    assert np.all(np.isfinite(starts)) and np.ptp(starts) <= 0.02
