"""The report's reference values and the compare command."""

import json

import numpy as np
import pytest

from ntncontact.cli import main
from ntncontact.io.writers import HistoryWriter
from ntncontact.reference import compare, report_values, table


def test_reference_tables_ship_with_the_package():
    t = table("blocks_fast_sliding_table_6_8")
    assert t["mu0.2_consistent"][-1] == pytest.approx(1.2105)
    assert len(table("block_sliding_table_6_1")["node"]) == 19


def test_report_values_derive_the_dissipation_from_table_6_8():
    v = report_values("blocks_fast_sliding", 0.2, "consistent")
    assert v["energy_dissipated_fraction"] == pytest.approx((1.56 - 1.2105) / 1.56)
    assert v["contact_start_time"] == 0.048
    tilted = report_values("tilted_blocks", 10.0)
    assert tilted["angular_momentum_max"] == pytest.approx(0.00052)


def test_compare_reads_a_results_folder(tmp_path, capsys):
    (tmp_path / "summary.json").write_text(json.dumps({
        "scenario": "examples/blocks_fast_sliding.toml", "overrides": ["contact.0.friction=0.1"],
        "contact_start_time": 0.048, "contact_end_time": 0.13, "max_penetration": 0.01,
        "max_active_pairs": 9}))
    with HistoryWriter(tmp_path) as w:
        for step, e in enumerate([1.56, 1.50, 1.34]):
            w.write({"step": step, "time": 0.1 * step, "kinetic_energy": e, "strain_energy": 0.0,
                     "total_energy": e, "linear_momentum_x": 0.72, "linear_momentum_y": -0.48,
                     "angular_momentum": 0.0, "newton_iterations": 1})
    label, rows = compare(tmp_path)
    by_name = {r.quantity: r for r in rows}
    assert "mu = 0.1" in label
    assert by_name["energy_dissipated_fraction"].ours == pytest.approx(0.22 / 1.56)
    assert by_name["contact_start_time"].relative == 0.0
    assert main(["compare", str(tmp_path)]) == 0
    assert "energy_dissipated_fraction" in capsys.readouterr().out
    assert np.isfinite(float((tmp_path / "comparison.csv").read_text().splitlines()[1]
                             .split(",")[1]))
