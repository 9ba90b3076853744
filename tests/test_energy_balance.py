"""Energy diagnostics that hold with loads (issue 14 section 4).

A column standing on its base, thrown upwards and loaded by its weight (a body force ramped
up over 0.3 s): the loads pump many times the initial energy into it, so the raw variation
max |E - E0| / |E0| is large, while the balance E - E0 - W_ext - W_contact closes to the
integrator's own error: second order in dt with the report's mid-point rule, and at the
Newton tolerance with the energy-momentum integrator (the default).
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from ntncontact.cli import main
from ntncontact.engine.diagnostics import EnergyAudit, energy_balance
from ntncontact.io.writers import read_csv_table
from ntncontact.report.plotting import plot_energies

COLUMN = """
[analysis]
kind = "dynamic"
dt = DT
t_end = 1.0
integrator = "INTEGRATOR"

[[bodies]]
name = "column"
mesh = { type = "rectangle", width = 0.5, height = 2.0, nx = 2, ny = 8 }
material = { model = "neo_hookean", E = 100.0, nu = 0.3, density = 1.0 }
initial = { velocity = [0.0, 0.2] }
supports = [{ set = "bottom", x = 0.0, y = 0.0 }]
loads = [{ type = "body_force", vector = [0.0, -3.0], function = { times = [0.0, 0.3], values = [0.0, 1.0] } }]
"""  # noqa: E501 (a TOML inline table is one line)


def _run(tmp_path, dt: float, integrator: str) -> tuple[dict, dict]:
    scenario = tmp_path / f"column_{integrator}_{dt}.toml"
    scenario.write_text(COLUMN.replace("DT", repr(dt)).replace("INTEGRATOR", integrator))
    out = tmp_path / f"out_{integrator}_{dt}"
    assert main(["run", str(scenario), "--out", str(out), "--quiet"]) == 0
    summary = json.loads((out / "summary.json").read_text())
    return summary, read_csv_table(out / "history.csv") | {"folder": out}


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("column")
    runs = {dt: _run(tmp, dt, "midpoint") for dt in (0.01, 0.005)}
    return runs | {"energy_momentum": _run(tmp, 0.01, "energy_momentum")}


def test_loads_change_the_energy_a_lot_but_the_balance_closes(runs):
    summary, history = runs[0.01]
    total, work = history["total_energy"], history["external_work"]
    change = np.abs(total - total[0]).max()
    # the raw figures keep their meaning: large here, by design of the loads
    assert summary["energy_max_relative_variation"] == pytest.approx(change / total[0],
                                                                     rel=1e-12)
    assert summary["energy_max_relative_variation"] > 5.0
    assert summary["energy_max_change"] == pytest.approx(change, rel=1e-12)
    # the headline: the balance, relative to the largest energy of the ledger
    error, scale = energy_balance(total, work)
    assert summary["energy_balance_max_error"] == pytest.approx(np.abs(error).max(), rel=1e-12)
    assert summary["energy_balance_max_relative_error"] == pytest.approx(
        np.abs(error).max() / scale, rel=1e-12)
    assert summary["energy_balance_max_relative_error"] < 1e-3
    # without the external work the same ledger does not close: the figure can fail
    unbalanced, _ = energy_balance(total, 0.0 * work)
    assert np.abs(unbalanced).max() / scale > 0.5


def test_the_balance_error_is_the_integrators_second_order_error(runs):
    """Halving dt divides the balance error by about 4 (mid-point rule): it is the time
    integration's error, not a missing term of the ledger (which would not shrink)."""
    coarse = runs[0.01][0]["energy_balance_max_error"]
    fine = runs[0.005][0]["energy_balance_max_error"]
    assert 3.0 < coarse / fine < 5.0


def test_with_the_energy_momentum_integrator_the_balance_closes_to_the_newton_tolerance(runs):
    """The discrete-gradient stress makes the step's energy change equal the work of the loads
    exactly: what is left is the Newton solve's residual (rtol 1e-10 of forces ~1 over
    displacements ~1), far below the mid-point rule's 1e-5."""
    summary = runs["energy_momentum"][0]
    assert summary["energy_balance_max_relative_error"] < 1e-9
    assert summary["energy_balance_max_relative_error"] < \
        1e-3 * runs[0.01][0]["energy_balance_max_relative_error"]


def test_audit_matches_the_history_function_and_scales_by_the_largest_energy():
    rng = np.random.default_rng(3)
    total = np.concatenate(([0.0], rng.normal(size=30)))  # starts at rest: E0 = 0
    external, contact = rng.normal(size=31), rng.normal(size=31)
    external[0] = contact[0] = 0.0
    audit = EnergyAudit()
    fields = [audit.add(*row) for row in zip(total, external, contact, strict=True)][-1]
    error, scale = energy_balance(total, external, contact)
    assert scale == max(np.abs(total).max(), np.abs(external).max(), np.abs(contact).max())
    assert fields["energy_balance_max_relative_error"] == pytest.approx(
        np.abs(error).max() / scale, rel=1e-12)
    assert fields["energy_max_change"] == pytest.approx(np.abs(total).max(), rel=1e-12)
    assert EnergyAudit().add(0.0, 0.0)["energy_balance_max_relative_error"] is None


def test_energies_figure_draws_the_external_work_and_the_balance(runs, monkeypatch):
    from ntncontact.report import plotting

    drawn = {}
    save = plotting._save

    def keep(fig, path):
        drawn["axes"] = fig.axes
        return save(fig, path)

    monkeypatch.setattr(plotting, "_save", keep)
    history = runs[0.01][1]
    path = plot_energies(history["folder"], history["folder"] / "energies_test.png")
    assert path.stat().st_size > 0
    top, bottom = drawn["axes"][0], drawn["axes"][1]
    lines = {line.get_label(): line.get_ydata() for line in top.get_lines()}
    np.testing.assert_array_equal(lines["external work"], history["external_work"])
    error, scale = energy_balance(history["total_energy"], history["external_work"])
    (balance,) = bottom.get_lines()
    np.testing.assert_allclose(balance.get_ydata(), error / scale, rtol=0, atol=1e-15)
    assert np.abs(balance.get_ydata()).max() < 1e-3  # the drift panel no longer peaks at 1000 %


BLOCK = """
[analysis]
kind = "static"
dt = DT
t_end = 1.0

[[bodies]]
name = "block"
mesh = { type = "rectangle", width = 2.0, height = 1.0, nx = 4, ny = 3 }
material = { model = "linear_elastic", E = 100.0, nu = 0.3, density = 1.0 }
supports = [{ set = "bottom", y = 0.0 }, { set = "corner_bottom_left", x = 0.0 }]
loads = [{ type = "traction", set = "top", vector = [0.0, 10.0] LOADFUNCTION}]
"""  # noqa: E501 (a TOML inline table is one line)


RAMP = ", function = { times = [0.0, 1.0], values = [0.0, 1.0] }"


@pytest.mark.parametrize("dt", [1.0, 0.25])
@pytest.mark.parametrize("function", ["", RAMP])
def test_a_static_load_on_from_t0_is_counted_as_applied_over_the_first_step(tmp_path, dt,
                                                                            function):
    """A linear block pulled by a traction that is on at full value from t = 0 (no time
    function): the undeformed initial state balances no load, so the quasi-static path applies
    it over the first step and the external work is the strain energy, 1/2 f.u (not f.u, which
    the loads at t = 0 gave: a balance error of 0.5). The ramped load is the control."""
    scenario = tmp_path / "block.toml"
    scenario.write_text(BLOCK.replace("DT", repr(dt)).replace("LOADFUNCTION", function))
    out = tmp_path / "out"
    assert main(["run", str(scenario), "--out", str(out), "--quiet"]) == 0
    summary = json.loads((out / "summary.json").read_text())
    history = read_csv_table(out / "history.csv")
    strain = history["strain_energy"][-1]
    assert strain > 0.5  # the block is loaded (0.91 for this mesh)
    # a linear problem: the trapezoid is exact for the ramp; the step load is one step's ramp
    assert history["external_work"][-1] == pytest.approx(strain, rel=1e-12)
    assert summary["energy_balance_max_relative_error"] < 1e-12
