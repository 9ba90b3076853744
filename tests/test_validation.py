"""The validation report: cases run, a failing case is shown, HTML and Markdown written."""

from ntncontact.validation import Case, validate


def test_validate_writes_reports_and_survives_a_failing_case(tmp_path):
    cases = (
        Case("rod_impact", "rod_impact.toml", ("analysis.t_end=2.5",), tolerance=0.03),
        Case("broken", "rod_impact.toml", ("analysis.dt=-1.0",)),
    )
    results = validate(tmp_path, quick=True, cases=cases)
    good, bad = results
    assert good.error is None and good.passed(), good.rows
    duration = {r.quantity: r for r in good.rows}["contact_duration"]
    assert abs(duration.ours - 2.05) < 0.06  # report 2.05, theory 2
    assert bad.error is not None and not bad.passed()
    html = (tmp_path / "report.html").read_text()
    assert "rod_impact" in html and "broken" in html and "FAIL" in html and "<img" in html
    md = (tmp_path / "report.md").read_text()
    assert "## rod_impact: PASS" in md and "## broken: FAIL" in md
