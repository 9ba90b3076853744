"""Energy that contact adds is named (an independent user's check, session 35).

The rods of report 3.2 under the gap law in a dynamic run, which does not conserve energy
(report 5.5): the run ends with ~7x its energy. The energy balance closes (the ledger counts
the contact forces' work), so neither it nor the run's status tells; summary.json's
``contact_work`` does, and ``ntncontact run`` warns. Under the persistency law (the default)
the contact work is round-off and nothing is said.
"""

from __future__ import annotations

import json
from pathlib import Path

from ntncontact.cli import CONTACT_GAIN_WARNING, main

ROD = Path(__file__).resolve().parents[1] / "examples" / "rod_impact.toml"


def _run(tmp_path: Path, capsys, *sets: str) -> tuple[dict, str]:
    out = tmp_path / "out"
    args = ["run", str(ROD), "--out", str(out), "--quiet", "--set", "analysis.t_end=2.5"]
    for item in sets:
        args += ["--set", item]
    assert main(args) == 0
    return json.loads((out / "summary.json").read_text()), capsys.readouterr().err


def test_the_gap_law_in_a_dynamic_run_adds_energy_and_the_run_says_so(tmp_path, capsys):
    summary, err = _run(tmp_path, capsys, 'contact.0.law="gap"', "contact.0.penalty_normal=1e5")
    scale = summary["energy_balance_max_error"] / summary["energy_balance_max_relative_error"]
    assert summary["energy_balance_max_relative_error"] < 1e-9  # the ledger closes ...
    assert summary["contact_work"] > 0.1 * scale  # ... because contact did the work
    assert summary["energy_final"] > 2.0 * summary["energy_initial"]
    assert "warning: the contact forces added" in err
    assert "contact_work" in err and "persistency" in err


def test_the_persistency_law_adds_none_and_nothing_is_said(tmp_path, capsys):
    summary, err = _run(tmp_path, capsys)
    scale = summary["energy_balance_max_error"] / summary["energy_balance_max_relative_error"]
    assert abs(summary["contact_work"]) < 1e-6 * CONTACT_GAIN_WARNING * scale
    assert "warning" not in err
