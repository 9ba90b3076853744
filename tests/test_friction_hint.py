"""The hint a Newton failure gets on an interface with friction (``engine.diagnostics``): it
calls the tangential penalty stiff only where it is not small against the normal one (a
tester's penalty_tangential of 0.01 was called "stiff"), and names the exact multipliers'
moving Coulomb cap with method = "lagrange"."""

from __future__ import annotations

from types import SimpleNamespace

import pytest

from ntncontact.contact import ContactLaw
from ntncontact.engine.diagnostics import named_failure
from ntncontact.solvers.newton import NewtonError


def failure_message(law: ContactLaw) -> str:
    model = SimpleNamespace(interfaces=[SimpleNamespace(name="slide", law=law)], cells=[])
    return named_failure(model, NewtonError("no convergence", 1.0, 40))


def test_a_stiff_tangential_penalty_is_named():
    message = failure_message(ContactLaw("penalty", eps_N=1e6, eps_T=1e6, mu=0.3))
    assert "stiff penalty_tangential (1e+06)" in message and "interface 'slide'" in message


def test_a_soft_tangential_penalty_is_not_called_stiff():
    assert failure_message(ContactLaw("penalty", eps_N=1e6, eps_T=0.01, mu=0.3)) \
        == "no convergence"


@pytest.mark.parametrize("eps_T", [0.01, 1e6])
def test_exact_multipliers_are_named_whatever_the_tangential_penalty(eps_T):
    message = failure_message(ContactLaw("lagrange", eps_T=eps_T, mu=0.3))
    assert "augmented_lagrangian" in message and "softer penalty_tangential" in message
    assert "stiff" not in message  # no normal penalty to call it stiff against


def test_frictionless_interfaces_get_no_hint():
    assert failure_message(ContactLaw("penalty", eps_N=1e6)) == "no convergence"
