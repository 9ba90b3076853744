"""Newton updates of the normal multipliers (``augmentation.update = "newton"``): the same
converged steps as Uzawa's (the augmentation test and its tolerances are unchanged), reached in
fewer augmentations; with friction too (a slipping pair's friction is mu t_N: the sensitivity
carries it, tests/test_contact_augmentation.py)."""

import numpy as np
import pytest
from helpers import Recorder, model_from_example, recorded_ring_impact

from ntncontact.engine.simulation import Simulation, _newton_updated


def ring_impact(update: str) -> Recorder:
    return recorded_ring_impact(f'contact.0.augmentation.update="{update}"')


def test_ring_impact_with_newton_updates_matches_uzawa_in_fewer_augmentations():
    uzawa, newton = ring_impact("uzawa"), ring_impact("newton")
    assert max(r.extra["active_pairs"] for r in newton.records[1:]) >= 3
    # the augmentation test bounds gap-rate changes by 1e-6 (of the impact speed 1): the
    # energies then agree to ~1e-9 relative, as for inexact augmentations
    energy = [np.array([r.balance.total_energy for r in rec.records]) for rec in (uzawa, newton)]
    assert np.abs(energy[1] - energy[0]).max() <= 1e-8 * energy[0][0]
    for a, b in zip(uzawa.records[1:], newton.records[1:], strict=True):
        assert np.abs(a.state.d - b.state.d).max() <= 1e-8
        rows_a, rows_b = a.extra["contact_rows"], b.extra["contact_rows"]
        np.testing.assert_array_equal(rows_a["node_1"], rows_b["node_1"])
        np.testing.assert_allclose(rows_b["normal_traction"], rows_a["normal_traction"],
                                   rtol=0.0, atol=1e-4)  # eps_N x 1e-6 x a few
    augmentations = [sum(r.extra.get("augmentations", 0) for r in rec.records[1:])
                     for rec in (uzawa, newton)]
    # measured: 159 -> 131 augmentations over these 40 steps (905 -> 714 over the whole run)
    assert augmentations[1] < 0.9 * augmentations[0]


def fast_sliding(update: str) -> Recorder:
    rec = Recorder()
    Simulation(model_from_example("blocks_fast_sliding.toml", [
        "contact.0.friction=0.2", f'contact.0.augmentation.update="{update}"']), [rec]).run()
    assert rec.status == ("completed", None)
    return rec


def test_fast_sliding_blocks_with_friction_take_fewer_augmentations_for_the_same_steps():
    """The report's fast-sliding blocks, mu = 0.2 (ALE lower block), every contact pair
    slipping or sticking: Newton updates reach the same steps (report 5.4's test bounds the
    gap-rate changes by 1e-8) in fewer augmentations. Measured: 247 -> 218 augmentations, the
    dissipation equal to 10 digits."""
    uzawa, newton = fast_sliding("uzawa"), fast_sliding("newton")
    e0 = uzawa.records[0].balance.total_energy
    energy = [np.array([r.balance.total_energy for r in rec.records]) for rec in (uzawa, newton)]
    assert len(energy[0]) == len(energy[1])
    assert np.abs(energy[1] - energy[0]).max() <= 1e-8 * e0
    dissipated = [rec.records[-1].extra["frictional_dissipation"] for rec in (uzawa, newton)]
    assert dissipated[0] > 0.2 * e0
    assert dissipated[1] == pytest.approx(dissipated[0], rel=1e-7)
    augmentations = [sum(r.extra.get("augmentations", 0) for r in rec.records[1:])
                     for rec in (uzawa, newton)]
    assert augmentations[1] < 0.95 * augmentations[0]


@pytest.mark.parametrize(("overrides", "expected"), [
    ([], True),
    (['contact.0.augmentation.update="uzawa"'], False),
    (["contact.0.friction=0.2", "contact.0.penalty_tangential=1000.0"], True),
    (['contact.0.method="penalty"'], False),
])
def test_which_interfaces_take_newton_updates(overrides, expected):
    model = model_from_example("ring_impact.toml", overrides)
    assert _newton_updated(model.interfaces[0]) is expected


def test_sensitivity_is_one_solve_with_a_column_per_pressed_pair(monkeypatch):
    """Simulation._sensitivity: a single multi-right-hand-side solve per call, whatever the
    number of pressed pairs (its cost is pairs x one solve, no Python loop of solves), and
    S = G A^-1 B agrees with the solve of each column alone."""
    from ntncontact.engine.simulation import Simulation
    from ntncontact.solvers.linear import Factorization

    real_sensitivity, real_call = Simulation._sensitivity, Factorization.__call__
    inside: list = []  # the right-hand-side shapes of the current _sensitivity call
    columns = []  # pressed pairs per call

    def counted_call(self, b, *rtol):
        inside.append(np.shape(b))
        return real_call(self, b, *rtol)

    def by_column(self, b, *rtol):
        return np.column_stack([real_call(self, column, *rtol) for column in np.asarray(b).T])

    def checked_sensitivity(self, problem, y, d, ci, state, pressed, factors):
        inside.clear()
        S = real_sensitivity(self, problem, y, d, ci, state, pressed, factors)
        assert inside[-1:] == [(y.size, int(pressed.sum()))] and len(inside) == 1
        columns.append(int(pressed.sum()))
        # the same S from one solve per column (the former loop), with the factor it used
        monkeypatch.setattr(Factorization, "__call__", by_column)
        S_columns = real_sensitivity(self, problem, y, d, ci, state, pressed, factors)
        monkeypatch.setattr(Factorization, "__call__", counted_call)
        np.testing.assert_allclose(S, S_columns, rtol=1e-10, atol=1e-12 * np.abs(S).max())
        return S

    monkeypatch.setattr(Simulation, "_sensitivity", checked_sensitivity)
    monkeypatch.setattr(Factorization, "__call__", counted_call)
    recorded_ring_impact("analysis.t_end=0.1")
    assert columns and max(columns) >= 3  # several pressed pairs solved in one call


@pytest.mark.parametrize("overrides", [
    [],
    # slipping pairs: their friction mu t_N is in B's columns too
    ["contact.0.friction=0.2", "contact.0.penalty_tangential=1000.0"],
])
def test_sensitivity_solves_wide_contact_zones_by_blocks_of_pairs(monkeypatch, overrides):
    """More pressed pairs than ``SENSITIVITY_COLUMNS``: one solve a block of pairs, each with
    at most that many right-hand sides (the dense unknowns x pairs blocks stay bounded on a
    wide contact zone), and the same S as from one solve of every column."""
    import ntncontact.engine.simulation as simulation
    from ntncontact.engine.simulation import Simulation
    from ntncontact.solvers.linear import Factorization

    real_sensitivity, real_call = Simulation._sensitivity, Factorization.__call__
    widths: list = []  # right-hand sides of each solve of the current call
    checked = []

    def counted_call(self, b, *rtol):
        if np.ndim(b) == 2:  # Newton's own solves have one right-hand side
            widths.append(np.shape(b)[1])
        return real_call(self, b, *rtol)

    def checked_sensitivity(self, problem, y, d, ci, state, pressed, factors):
        pairs = int(pressed.sum())
        widths.clear()
        S = real_sensitivity(self, problem, y, d, ci, state, pressed, factors)
        assert widths == [min(2, pairs - first) for first in range(0, pairs, 2)]
        monkeypatch.setattr(simulation, "SENSITIVITY_COLUMNS", 10_000)
        S_whole = real_sensitivity(self, problem, y, d, ci, state, pressed, factors)
        monkeypatch.setattr(simulation, "SENSITIVITY_COLUMNS", 2)
        np.testing.assert_allclose(S, S_whole, rtol=1e-10, atol=1e-12 * np.abs(S).max())
        checked.append(pairs)
        return S

    monkeypatch.setattr(simulation, "SENSITIVITY_COLUMNS", 2)
    monkeypatch.setattr(Simulation, "_sensitivity", checked_sensitivity)
    monkeypatch.setattr(Factorization, "__call__", counted_call)
    recorded_ring_impact("analysis.t_end=0.1", *overrides)
    assert checked and max(checked) >= 3  # several blocks, one of them partial
