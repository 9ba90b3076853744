"""The report's reference values and the compare command."""

import csv
import json

import numpy as np
import pytest
from helpers import EXAMPLES

import ntncontact as ntc
from ntncontact.cli import main
from ntncontact.io.writers import HistoryWriter
from ntncontact.report.reference import (
    HERTZ_LOAD,
    Comparison,
    compare,
    first_slip_node,
    fit_hertz_ellipse,
    format_comparison,
    hertz_plane_strain,
    our_values,
    report_values,
    smoother_ranking,
    start_of_last_run,
    table,
    table_4_1,
    table_6_1_first_slip_node,
    write_comparison_csv,
)
from ntncontact.report.validation_cases import impact_tolerance


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


def test_comparison_modes():
    assert Comparison("q", 1.04, 1.0, 0.05).passed()
    assert not Comparison("q", 1.06, 1.0, 0.05).passed()
    assert Comparison("q", 1.06, 1.0, 0.05, atol=0.1).passed()  # either tolerance
    assert Comparison("q", 0.9, 1.0).passed() is None  # information only
    assert Comparison("q", 1.5, 1.0, 0.5, "absolute").passed()
    assert not Comparison("q", 1.6, 1.0, 0.5, "absolute").passed()
    assert Comparison("q", 0.0081, 0.008, 0.05, "at_most").passed()
    assert not Comparison("q", 0.009, 0.008, 0.05, "at_most").passed()
    assert Comparison("q", 33.0, 32.0, 0.0, "at_least").passed()
    assert not Comparison("q", 30.0, 32.0, 0.0, "at_least").passed()
    assert Comparison("q", 2.0, 38.1, 0.0, "same_sign").passed()
    assert not Comparison("q", -2.0, 38.1, 0.0, "same_sign").passed()
    assert Comparison("q", "L > W > S", "L > W > S", 0.0, "equal").passed()
    assert not Comparison("q", "W > L > S", "L > W > S", 0.0, "equal").passed()
    assert not Comparison("q", float("nan"), 1.0, 0.5).passed()  # not measured: fails
    assert np.isnan(Comparison("q", "a", "b").relative)
    with pytest.raises(ValueError, match="unknown comparison mode"):
        Comparison("q", 1.0, 1.0, 0.1, "roughly")


def test_hertz_formulas_and_the_ellipse_fit():
    a, p0 = hertz_plane_strain(HERTZ_LOAD)
    assert (a, p0) == pytest.approx((47.17, 3239.4), abs=0.01)  # docs/examples.md
    assert p0 * np.pi * a / 2.0 == pytest.approx(HERTZ_LOAD)  # the ellipse carries the load
    X = np.linspace(-45.0, 45.0, 16)
    p = 3000.0 * np.sqrt(1.0 - (X / 46.0) ** 2)
    assert fit_hertz_ellipse(X, p, a, p0) == pytest.approx((46.0, 3000.0), rel=1e-6)


def test_table_4_1_ranking_and_table_6_1_slip_boundary():
    t41 = table_4_1()
    assert t41["min_angle_deg"]["laplacian"] == 58.65
    assert smoother_ranking(t41["min_angle_deg"], True) == [
        "laplacian", "weighted_angle_based", "simple_angle_based"]
    assert smoother_ranking(t41["variance_angle"], False)[0] == "laplacian"
    # both columns of Table 6.1 reach the cone at node 16, as the report's text says
    assert table_6_1_first_slip_node("report") == 16
    assert table_6_1_first_slip_node("simo_laursen") == 16
    nodes = np.arange(2, 8)
    assert start_of_last_run(nodes, [0, 0, 1, 0, 1, 1]) == 6
    assert start_of_last_run(nodes, [1, 1, 1, 1, 1, 1]) == 2
    assert start_of_last_run(nodes, [1, 1, 1, 1, 1, 0]) is None
    assert first_slip_node(nodes, np.full(6, 10.0), np.array([0, 1, 2, 3, 5, -5.0]), 0.5) == 6


def test_report_values_over_a_shortened_run():
    t68 = table("blocks_fast_sliding_table_6_8")
    short = report_values("blocks_fast_sliding", 0.2, "consistent", until=0.075)
    row = int(np.flatnonzero(np.isclose(t68["time"], 0.075))[0])
    assert short["energy_dissipated_fraction"] == pytest.approx(
        (1.56 - t68["mu0.2_consistent"][row]) / 1.56)
    between = report_values("blocks_fast_sliding", 0.2, "consistent", until=0.078)
    e = np.interp(0.078, t68["time"], t68["mu0.2_consistent"])
    assert between["energy_dissipated_fraction"] == pytest.approx((1.56 - e) / 1.56)
    assert report_values("blocks_fast_sliding", 0.2, "consistent", until=1.0) == \
        report_values("blocks_fast_sliding", 0.2, "consistent")


def test_a_run_stopped_during_contact_has_no_contact_end(tmp_path):
    (tmp_path / "summary.json").write_text(json.dumps({
        "scenario": "examples/ring_impact.toml", "overrides": [], "contact_start_time": 0.065,
        "contact_end_time": 0.2, "max_penetration": 0.004, "max_active_pairs": 5}))
    with HistoryWriter(tmp_path) as w:
        for step, t in enumerate([0.0, 0.1, 0.2]):
            w.write({"step": step, "time": t, "kinetic_energy": 1.6, "strain_energy": 0.0,
                     "total_energy": 1.6, "linear_momentum_x": 0.0, "linear_momentum_y": -3.2,
                     "angular_momentum": 0.0, "newton_iterations": 1})
    ours = our_values(tmp_path)
    assert "contact_end_time" not in ours and "contact_duration" not in ours
    assert "max_active_pairs" not in ours and ours["contact_start_time"] == 0.065
    _, rows = compare(tmp_path)
    assert {r.quantity for r in rows} >= {"contact_start_time", "energy_initial"}
    assert "contact_end_time" not in {r.quantity for r in rows}
    path = tmp_path / "c.csv"
    write_comparison_csv(path, [Comparison("state", "stick", "slip", 0.0, "equal", note="n")])
    assert path.read_text().splitlines()[1] == "state,stick,slip,nan,nan,equal,FAIL,n"


def _ring_run(folder, start=0.065, end=0.2, energies=(1.6, 1.6, 1.6)):
    """A results folder of a (short) ring impact (dt 0.005): its summary and three history
    rows."""
    folder.mkdir(exist_ok=True)
    (folder / "summary.json").write_text(json.dumps({
        "scenario": "examples/ring_impact.toml", "overrides": [], "contact_start_time": start,
        "contact_end_time": end, "max_penetration": 0.004, "max_active_pairs": 5}))
    with HistoryWriter(folder) as w:
        for step, (t, e) in enumerate(zip([0.0, 0.005, 0.2], energies, strict=True)):
            w.write({"step": step, "time": t, "kinetic_energy": e, "strain_energy": 0.0,
                     "total_energy": e, "linear_momentum_x": 0.0, "linear_momentum_y": -3.2,
                     "angular_momentum": 0.0, "newton_iterations": 1})
    return folder


def test_compare_checks_the_rows_as_validate_does(tmp_path, capsys):
    """`ntncontact compare` shows a verdict, the tolerance and the reason of every row, with the
    example's tolerance from the case table (ring impact: 15 %), and so does comparison.csv."""
    _ring_run(tmp_path, start=0.1, end=0.15)  # starts 0.035 late: > 15 % and one step
    _, rows = compare(tmp_path)
    by = {r.quantity: r for r in rows}
    assert by["contact_start_time"].passed() is False
    assert by["energy_initial"].passed() is True  # 1.6 against 1.6014
    assert by["energy_initial"].tolerance == impact_tolerance("ring_impact") == 0.15
    assert by["max_penetration"].passed() is True and by["max_penetration"].mode == "at_most"
    assert by["contact_end_time"].passed() is None  # shown, not checked (no duration)
    assert all(r.note for r in rows)  # every row says why
    assert main(["compare", str(tmp_path)]) == 0
    out = capsys.readouterr().out.splitlines()
    assert out[1].split() == ["quantity", "ours", "report", "difference", "result", "tolerance",
                              "reason"]
    start = next(line for line in out if line.startswith("contact_start_time"))
    assert "FAIL" in start and "±0.15 rel." in start and "one time step" in start
    assert "+53.85%" in start  # (0.1 - 0.065) / 0.065
    info = next(line for line in out if line.startswith("contact_end_time"))
    assert " info " in info and "not checked" in info  # it said "checked as the duration"
    with (tmp_path / "comparison.csv").open() as fh:
        table_rows = {row["quantity"]: row for row in csv.DictReader(fh)}
    assert table_rows["contact_start_time"]["result"] == "FAIL"
    assert table_rows["energy_initial"]["result"] == "pass"
    assert table_rows["contact_start_time"]["tolerance"].startswith("±0.15 rel.")
    assert {row["result"] for row in table_rows.values()} == {"pass", "FAIL", "info"}


def test_a_reference_value_of_zero_shows_the_absolute_difference(tmp_path):
    row = Comparison("angular_momentum_max", 2.5e-14, 0.0, 0.15, "at_most", atol=1e-12)
    assert row.passed() and row.difference_text() == "+2.5e-14 abs."
    assert Comparison("q", 0.0, 0.5).difference_text() == "-100.00%"  # ours 0: really -100 %
    assert Comparison("q", "a", "b").difference_text() == ""
    assert "+2.5e-14 abs." in format_comparison("label", [row])
    path = tmp_path / "c.csv"
    write_comparison_csv(path, [row])
    with path.open() as fh:
        (written,) = csv.DictReader(fh)
    assert written["relative_difference"] == "" and float(written["difference"]) == 2.5e-14


def test_an_example_without_a_tolerance_is_shown_only(tmp_path, monkeypatch):
    from ntncontact.report import validation_cases

    _ring_run(tmp_path)
    monkeypatch.setattr(validation_cases, "CASES", ())
    _, rows = compare(tmp_path)
    assert rows and all(r.passed() is None and "no tolerance" in r.note for r in rows)


@pytest.mark.parametrize("make, message", [
    (lambda d: d / "missing", "does not exist"),
    (lambda d: d, "has no summary.json or history.csv"),
    (lambda d: _ring_run(d / "run").joinpath("history.csv").unlink() or d / "run",
     "has no history.csv"),
])
def test_compare_outside_a_results_folder_says_what_it_expected(tmp_path, capsys, make,
                                                                message):
    folder = make(tmp_path)
    assert main(["compare", str(folder)]) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and message in err and str(folder) in err
    assert "expected the results folder of `ntncontact run" in err
    assert "Errno" not in err and "Traceback" not in err


def test_compare_takes_the_friction_and_mass_the_run_used_not_only_its_overrides(tmp_path):
    """A tester's copy of the fast-sliding blocks with friction = 0.2 and mass = "lumped" in
    the file itself was compared with the report's frictionless, consistent-mass row (the
    case was read from the --set overrides only). The run's summary now records both."""
    from pathlib import Path

    import ntncontact as ntc

    example = Path(__file__).resolve().parents[1] / "examples" / "blocks_fast_sliding.toml"
    text = example.read_text().replace("friction = 0.0", "friction = 0.2")
    text = text.replace('mass = "consistent"', 'mass = "lumped"')
    assert "friction = 0.2" in text and 'mass = "lumped"' in text
    copy = tmp_path / "blocks_fast_sliding.toml"
    copy.write_text(text)
    out = tmp_path / "run"
    ntc.run(ntc.load_scenario(copy, {"analysis.t_end": 0.06}), out)
    summary = json.loads((out / "summary.json").read_text())
    assert list(summary["contact_friction"].values()) == [0.2]
    assert summary["mass"] == "lumped"
    label, _ = compare(out)
    assert "mu = 0.2" in label and "lumped" in label, label


@pytest.mark.parametrize(("status", "error", "said"), [
    ("failed", "SimulationError: step 3 failed", "the run is failed (at t = 0.2: Simulation"),
    ("interrupted", "interrupted by SIGINT", "the run is interrupted (at t = 0.2"),
    ("running", None, "the run is stale (at t = 0.2)"),  # killed: no live process holds it
    ("completed", None, None)])
def test_compare_says_when_the_run_did_not_complete(tmp_path, status, error, said):
    """A tester's failed and interrupted runs were compared as if they had completed."""
    (tmp_path / "summary.json").write_text(json.dumps({
        "scenario": "examples/ring_impact.toml", "overrides": [], "status": status,
        "error": error, "time": 0.2, "contact_start_time": 0.065, "max_penetration": 0.004,
        "max_active_pairs": 5}))
    with HistoryWriter(tmp_path) as w:
        for step, t in enumerate([0.0, 0.1, 0.2]):
            w.write({"step": step, "time": t, "kinetic_energy": 1.6, "strain_energy": 0.0,
                     "total_energy": 1.6, "linear_momentum_x": 0.0, "linear_momentum_y": -3.2,
                     "angular_momentum": 0.0, "newton_iterations": 1})
    label, _ = compare(tmp_path)
    notes = [line for line in label.splitlines() if "the run is" in line]
    assert notes == ([] if said is None else [notes[0]]) and (said is None or said in notes[0])


def test_compare_names_the_overrides_and_a_contact_that_had_not_ended(tmp_path):
    """A tester's rod impact cut at t = 1.0, still in contact: compare said it had the
    report's values of "rod_impact" among others, and of a shortened run it said nothing."""
    (tmp_path / "summary.json").write_text(json.dumps({
        "scenario": "examples/rod_impact.toml", "overrides": ["analysis.t_end=1.0"],
        "status": "completed", "time": 1.0, "contact_start_time": 0.05,
        "contact_end_time": 1.0, "max_penetration": 0.0, "max_active_pairs": 31}))
    with HistoryWriter(tmp_path) as w:
        for step, t in enumerate([0.0, 0.5, 1.0]):
            w.write({"step": step, "time": t, "kinetic_energy": 5.0, "strain_energy": 0.0,
                     "total_energy": 5.0, "linear_momentum_x": 10.0, "linear_momentum_y": 0.0,
                     "angular_momentum": 0.0, "newton_iterations": 1})
    label, rows = compare(tmp_path)
    assert rows == []
    assert "--set analysis.t_end=1.0" in label
    assert "still in contact at the run's end (t = 1)" in label
    assert "only" not in label  # not the list of examples compare knows


def test_the_summary_says_whether_contact_was_still_on_at_the_runs_end(tmp_path):
    """A tester's rod impact cut at t = 1.0 read contact_end_time 1.0, a duration of 0.95
    beside the full run's 2.05, with nothing to tell them apart."""
    scenario = EXAMPLES / "rod_impact.toml"
    cut = ntc.run(ntc.load_scenario(scenario, {"analysis.t_end": 1.0})).summary
    full = ntc.run(ntc.load_scenario(scenario, {"analysis.t_end": 2.5})).summary
    assert cut["contact_at_end"] is True and cut["contact_end_time"] == pytest.approx(1.0)
    assert full["contact_at_end"] is False and full["contact_end_time"] < 2.5
