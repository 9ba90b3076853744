"""The energy warnings name the cause the run's settings point to (tester P, session 40):

- the ALE unreturned-energy warning said "no Lagrangian body, or none with the kinetic energy"
  beside a Lagrangian block in motion: the hand-over keeps each body's momenta, so only the
  kinetic energy beyond a body's rigid motion can be given back;
- a persistency-law run with ``gap_restoring = true`` (+20 %) was told the gap law added the
  energy, and advised the persistency law it had;
- ``ale.convection = "convective_term"`` (momentum off by 1.2 %, energy by 0.054) was told
  the time integration did it;
- the linear elastic rotation warning did not say that such a body, turned and deformed, does
  not keep its angular momentum.
"""

from __future__ import annotations

from helpers import model_from_example

from ntncontact.io.results import contact_setup, outside_ledger
from ntncontact.report.run_warnings import result_warnings

SETUP = {"index": 0, "method": "augmented_lagrangian", "law": "persistency",
         "detection": "penetration", "spacing_1": 0.1, "spacing_2": 0.1, "ale_1": False,
         "ale_2": False}


def summary(**keys: object) -> dict:
    """A dynamic run's summary whose energy scale is 1."""
    return {"integrator": "energy_momentum", "energy_balance_max_error": 1e-12,
            "energy_balance_max_relative_error": 1e-12, "outside_ledger": [],
            "contact_setup": {"hit": SETUP}} | keys


def test_the_unreturned_energy_warning_says_only_non_rigid_kinetic_energy_can_be_given():
    (line,) = [w for w in result_warnings(summary(ale_unreturned_energy=0.002))
               if "ale_unreturned_energy" in w]
    assert "keeps each body's linear and angular momentum" in line
    assert "beyond its rigid motion" in line
    assert "no Lagrangian body" not in line  # there was one, moving


def test_a_gain_with_gap_restoring_names_it_not_the_gap_law():
    restoring = summary(contact_work=0.157, contact_setup={"hit": SETUP | {
        "gap_restoring": True}})
    (line,) = [w for w in result_warnings(restoring) if "contact_work" in w]
    assert "gap_restoring = true (hit)" in line
    assert "the gap law does so" not in line
    # without it, the gap law is still what is named
    plain = summary(contact_work=0.157, contact_setup={"hit": SETUP | {"law": "gap"}})
    (line,) = [w for w in result_warnings(plain) if "contact_work" in w]
    assert "the gap law does so" in line


def test_the_summary_records_gap_restoring_per_interface():
    on = model_from_example("rod_impact.toml", ["contact.0.gap_restoring=true"])
    off = model_from_example("rod_impact.toml")
    assert [s["gap_restoring"] for s in contact_setup(on).values()] == [True]
    assert [s["gap_restoring"] for s in contact_setup(off).values()] == [False]


def test_the_convective_term_is_named_as_outside_the_ledger_with_the_momenta():
    model = model_from_example("ring_impact.toml",
                               ['bodies.1.ale.convection="convective_term"'])
    left_out = outside_ledger(model)
    assert len(left_out) == 1 and "convective_term" in left_out[0]
    assert "momentum" in left_out[0]
    assert outside_ledger(model_from_example("ring_impact.toml")) == []
    lines = result_warnings(summary(energy_balance_max_error=0.054,
                                    energy_balance_max_relative_error=0.054,
                                    outside_ledger=left_out))
    (line,) = [w for w in lines if "energy balance is off" in w]
    assert "convective term" in line and "linear and angular momentum" in line


def test_the_linear_rotation_warning_says_the_angular_momentum_is_not_kept():
    """Tester P: a linear elastic disk and block after an oblique impact drifted 16 % of |L0|
    in 8 steps of free flight; the warning spoke of the stretch only."""
    lines = result_warnings(summary(max_linear_elastic_rotation=0.673,
                                    max_linear_elastic_rotation_at={"time": 0.4,
                                                                    "body": "disk"}))
    (line,) = [w for w in lines if "max_linear_elastic_rotation" in w]
    assert "does not keep its angular momentum" in line
