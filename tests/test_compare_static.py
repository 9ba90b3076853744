"""`ntncontact compare` on a run whose energy starts at 0 (a static run): no division by the
initial energy, no raw NumPy warning, and a note on what the run has instead."""

from __future__ import annotations

import json
import warnings

import numpy as np
import pytest
from helpers import EXAMPLES

from ntncontact.cli import main
from ntncontact.io.writers import HistoryWriter, read_csv_table
from ntncontact.report.reference import compare, our_values


@pytest.fixture(scope="module")
def hertz(tmp_path_factory):
    """The Hertz example (quasi-static, report 6.2) over its first two load steps."""
    out = tmp_path_factory.mktemp("hertz") / "run"
    assert main(["run", str(EXAMPLES / "hertz.toml"), "--out", str(out), "--quiet",
                 "--set", "analysis.t_end=2.0"]) == 0
    return out


def test_compare_of_a_static_run_divides_by_no_zero_energy(hertz, capsys):
    energy = read_csv_table(hertz / "history.csv")["total_energy"]
    assert energy[0] == 0.0 and energy[-1] > 0.0  # the case of the defect
    capsys.readouterr()
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # a NumPy RuntimeWarning fails the test
        assert main(["compare", str(hertz)]) == 0
        ours = our_values(hertz)
    out, err = capsys.readouterr()
    assert "Warning" not in err and "Warning" not in out
    assert "energy_max_relative_variation" not in ours
    assert "energy_dissipated_fraction" not in ours
    assert ours["energy_max_change"] == pytest.approx(np.abs(energy).max())
    assert all(np.isfinite(v) for v in ours.values())
    lines = out.splitlines()
    assert lines[0] == "hertz (mu = 0, static run)"
    assert "the energy starts at 0 (a static run has no kinetic energy)" in out
    summary = json.loads((hertz / "summary.json").read_text())
    assert f"{summary['energy_balance_max_relative_error']:.3g}" in out


def test_compare_says_where_an_example_without_its_values_is_checked(hertz, capsys):
    """compare has the impact examples' values only; Hertz is checked by `validate`."""
    label, rows = compare(hertz)
    assert rows == []
    assert "`ntncontact validate` checks hertz (report 6.2)" in label
    assert main(["compare", str(hertz)]) == 0
    out = capsys.readouterr().out
    assert "no reference values for this example" not in out
    assert "(no value of the report to compare with)" in out
    assert (hertz / "comparison.csv").read_text().strip().count("\n") == 0  # the header only


def test_a_dynamic_run_from_rest_has_no_relative_energy_rows(tmp_path):
    """A body dropped from rest: E0 = 0 but kinetic energy later; the report's relative
    energy values get no row (ours is undefined), the others still do."""
    (tmp_path / "summary.json").write_text(json.dumps({
        "scenario": "examples/ring_impact.toml", "overrides": [], "contact_start_time": 0.065,
        "contact_end_time": 0.1, "max_penetration": 0.004, "max_active_pairs": 5}))
    with HistoryWriter(tmp_path) as w:
        for step, e in enumerate([0.0, 0.5, 0.4]):
            w.write({"step": step, "time": 0.05 * step, "kinetic_energy": e,
                     "strain_energy": 0.0, "total_energy": e, "linear_momentum_x": 0.0,
                     "linear_momentum_y": -e, "angular_momentum": 0.0, "newton_iterations": 1})
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        label, rows = compare(tmp_path)
    names = {r.quantity for r in rows}
    assert "energy_initial" in names and "contact_start_time" in names
    assert "energy_max_relative_variation" not in names
    # the momentum starts at 0 too: its change, not a "relative" one divided by 1
    ours = our_values(tmp_path)
    assert "linear_momentum_max_relative_variation" not in ours
    assert ours["linear_momentum_max_change"] == 0.5
    assert label.splitlines()[0] == "ring_impact (mu = 0, consistent mass)"
    assert "the energy starts at 0 (the bodies start at rest)" in label
    assert "largest change is 0.5" in label
