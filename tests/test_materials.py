"""Constitutive models: derivatives by finite differences, closed-form stresses, bad input.

P, A and W come from the NumPy oracle (tests/element_oracle.py) that the compiled kernel is
compared with in test_kernels_numba.py; so do cauchy_stress and von_mises, the closed forms
that test_fields.py checks the output's compiled stresses with."""

import numpy as np
import pytest
from element_oracle import cauchy_stress, linear_elastic, neo_hookean, von_mises

from ntncontact.materials.models import Material, MaterialError

RNG = np.random.default_rng(0)
F_SAMPLES = np.eye(2) + 0.3 * RNG.standard_normal((5, 2, 2))


@pytest.mark.parametrize("model", [neo_hookean, linear_elastic])
def test_stress_is_energy_derivative_and_tangent_is_stress_derivative(model):
    lam, mu, h = 2.0, 1.3, 1e-6
    P, A, _ = model(F_SAMPLES, lam, mu)
    for i in range(2):
        for J in range(2):
            dF = np.zeros((2, 2))
            dF[i, J] = h
            Pp, _, Wp = model(F_SAMPLES + dF, lam, mu)
            Pm, _, Wm = model(F_SAMPLES - dF, lam, mu)
            # central differences: error O(h^2) ~ 1e-12 relative to O(1) stresses
            np.testing.assert_allclose((Wp - Wm) / (2 * h), P[:, i, J], rtol=1e-7, atol=1e-8)
            np.testing.assert_allclose((Pp - Pm) / (2 * h), A[:, :, :, i, J], rtol=1e-7,
                                       atol=1e-8)


def test_neo_hookean_uniaxial_plane_strain_stretch_closed_form():
    lam, mu, s = 3.0, 2.0, 1.7
    F = np.diag([s, 1.0])
    P, _, W = neo_hookean(F, lam, mu)
    # P11 = mu (s - 1/s) + lam ln s / s, P22 = lam ln s, W = mu/2 (s^2 - 1) - mu ln s + lam/2 ln^2 s
    assert P[0, 0] == pytest.approx(mu * (s - 1 / s) + lam * np.log(s) / s, rel=1e-14)
    assert P[1, 1] == pytest.approx(lam * np.log(s), rel=1e-14)
    assert P[0, 1] == 0.0 and P[1, 0] == 0.0
    assert W == pytest.approx(mu / 2 * (s * s - 1) - mu * np.log(s) + lam / 2 * np.log(s) ** 2)
    sigma, s33 = cauchy_stress("neo_hookean", F, lam, mu)
    assert sigma[0, 0] == pytest.approx(P[0, 0] * s / s, rel=1e-14)
    assert s33 == pytest.approx(lam * np.log(s) / s, rel=1e-14)


def test_neo_hookean_is_stress_free_and_frame_indifferent():
    lam, mu = 3.0, 2.0
    P, A, W = neo_hookean(np.eye(2), lam, mu)
    assert np.abs(P).max() == 0.0 and W == 0.0
    # small strain limit: tangent at identity equals the linear elastic moduli
    _, A_lin, _ = linear_elastic(np.eye(2), lam, mu)
    np.testing.assert_allclose(A, A_lin, atol=1e-14)
    th = 0.7
    R = np.array([[np.cos(th), -np.sin(th)], [np.sin(th), np.cos(th)]])
    F = F_SAMPLES[0]
    _, _, W1 = neo_hookean(F, lam, mu)
    _, _, W2 = neo_hookean(R @ F, lam, mu)
    assert W2 == pytest.approx(W1, rel=1e-13)


def test_von_mises_of_pure_shear_and_hydrostatic():
    sig = np.array([[0.0, 2.0], [2.0, 0.0]])
    assert von_mises(sig, 0.0) == pytest.approx(np.sqrt(3.0) * 2.0)
    assert von_mises(np.eye(2) * 5.0, 5.0) == pytest.approx(0.0, abs=1e-14)


@pytest.mark.parametrize(
    "kwargs, match",
    [
        ({"E": 1.0, "nu": 0.5}, "Poisson"),
        ({"E": -1.0, "nu": 0.3}, "Young"),
        ({"E": 1.0, "nu": 0.3, "density": 0.0}, "density"),
    ],
)
def test_nonphysical_parameters_are_clear_errors(kwargs, match):
    args = {"density": 1.0} | kwargs
    with pytest.raises(MaterialError, match=match):
        Material.from_young("neo_hookean", **args)


def test_lame_round_trip():
    m = Material.from_young("linear_elastic", 800.0, 0.3, 2.0)
    assert m.lam == pytest.approx(461.538, rel=1e-5) and m.mu == pytest.approx(307.692, rel=1e-5)
    with pytest.raises(MaterialError, match="shear"):
        Material("neo_hookean", 1.0, 0.0, 1.0)


@pytest.mark.parametrize("kind", ["neo_hookean", "linear_elastic"])
def test_cauchy_stress_is_p_f_transpose_over_j(kind):
    """cauchy_stress's closed forms against sigma = P F^T / J from the oracle's P (the same law
    in another order of operations: round-off of the O(1) stresses), and sigma_33."""
    lam, mu = 2.0, 1.3
    P, _, _ = (neo_hookean if kind == "neo_hookean" else linear_elastic)(F_SAMPLES, lam, mu)
    J = np.linalg.det(F_SAMPLES)
    assert np.all(J > 0.0)
    sigma, s33 = cauchy_stress(kind, F_SAMPLES, lam, mu)
    if kind == "linear_elastic":  # small strain: sigma = P, sigma_33 = lam tr(eps)
        np.testing.assert_array_equal(sigma, P)
        np.testing.assert_allclose(s33, lam * (np.trace(F_SAMPLES, axis1=1, axis2=2) - 2.0),
                                   rtol=1e-14)
        assert np.all(cauchy_stress(kind, F_SAMPLES, lam, mu, plane_stress=True)[1] == 0.0)
        return
    expected = np.einsum("...iJ,...kJ->...ik", P, F_SAMPLES) / J[:, None, None]
    np.testing.assert_allclose(sigma, expected, rtol=0, atol=1e-14 * np.abs(expected).max())
    np.testing.assert_allclose(s33, lam * np.log(J) / J, rtol=1e-14)
