"""Session 41, tester A's findings 3 to 7: warnings and errors that told less than the truth
(an energy blow-up read "off by 0.99", a 6-fold stretch read as a 1.41 rad turn, 40 % linear
strain in silence, a static load without a time function halved 4 times to no avail, and
dynamic-only inputs dropped in static runs)."""

from __future__ import annotations

from ntncontact.report.run_warnings import result_warnings

#: the tester's mid-point spin (f5_spin.toml, dt = 0.4, t_end = 8): its summary's figures
BLOWN_UP = {"integrator": "midpoint", "outside_ledger": [], "energy_initial": 6.956666666666666,
            "energy_max_relative_variation": 125.31716747405656,
            "energy_balance_max_relative_error": 0.9920834196966506,
            "energy_balance_max_error": 871.7897617278534}


def test_an_energy_blow_up_is_quoted_against_the_initial_energy():
    (line,) = [w for w in result_warnings(BLOWN_UP) if "energy balance is off" in w]
    assert "0.99 of the energy scale" in line  # the documented figure stays
    assert "125 times the initial energy E0 = 6.96" in line


def test_a_small_balance_error_is_not_quoted_against_the_initial_energy():
    drift = BLOWN_UP | {"energy_balance_max_error": 0.05, "energy_max_relative_variation": 7e-3,
                        "energy_balance_max_relative_error": 7e-3}
    (line,) = [w for w in result_warnings(drift) if "energy balance is off" in w]
    assert "initial energy" not in line
