"""history.csv failed_newton_iterations and summary.json's iteration totals: the Newton
iterations of attempts a halving discarded were dropped from every count (tester Y, session
42: disk_drop ran 1018 iterations and history.csv said 993)."""

from pathlib import Path

import pytest

from ntncontact import api
from ntncontact.engine import simulation
from ntncontact.solvers.newton import NewtonError
from ntncontact.studies.sweep import _results_row

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"


def counted_newton(monkeypatch) -> list[int]:
    """Every Newton solve's iterations, failed ones too (the tester's wrapped ``newton``)."""
    counts: list[int] = []
    plain = simulation.newton

    def wrapped(*args, **kwargs):
        try:
            result = plain(*args, **kwargs)
        except NewtonError as err:
            counts.append(err.iterations)
            raise
        counts.append(result.iterations)
        return result

    monkeypatch.setattr(simulation, "newton", wrapped)
    return counts


def test_the_iterations_of_halved_attempts_are_counted_apart(monkeypatch):
    """The spinning block allowed one Newton iteration a solve: every step's full-dt attempt
    fails and is halved (tester Y: 39 iterations run over two steps, 30 reported)."""
    counts = counted_newton(monkeypatch)
    results = api.run(api.load_scenario(EXAMPLES / "spinning_block.toml", [
        "analysis.newton.max_iterations=1", "analysis.t_end=0.04",
        "analysis.output_interval=0.02"]), None)
    history, summary = results.history, results.summary
    assert summary["cut_back_steps"] == 2
    failed = history["failed_newton_iterations"].tolist()
    assert failed[0] == 0 and all(f > 0 for f in failed[1:])  # the initial row, then halvings
    accepted = int(history["newton_iterations"].sum())
    assert accepted + sum(failed) == sum(counts)
    assert summary["newton_iterations"] == accepted
    assert summary["failed_newton_iterations"] == sum(failed)


def test_a_run_without_halvings_has_none_failed(monkeypatch):
    counts = counted_newton(monkeypatch)
    results = api.run(api.load_scenario(EXAMPLES / "spinning_block.toml",
                                        ["analysis.t_end=0.04"]), None)
    assert results.summary["cut_back_steps"] == 0
    assert results.history["failed_newton_iterations"].tolist() == [0, 0, 0]
    assert results.summary["failed_newton_iterations"] == 0
    assert results.summary["newton_iterations"] == sum(counts) > 0


@pytest.mark.parametrize("column", ["failed_newton_iterations"])
def test_the_folder_holds_the_column_and_totals(tmp_path, column):
    results = api.run(api.load_scenario(EXAMPLES / "spinning_block.toml", [
        "analysis.newton.max_iterations=1", "analysis.t_end=0.02"]), tmp_path / "out")
    header = (tmp_path / "out" / "history.csv").read_text().splitlines()[0].split(",")
    assert header[-1] == column  # last: the earlier columns keep their places
    assert results.summary[column] == int(results.history[column].sum()) > 0
    row = _results_row(api.read_results(tmp_path / "out"), {})  # a sweep.csv row
    assert row[column] == results.summary[column]
    assert row["newton_iterations"] == int(results.history["newton_iterations"].sum()) > 0
