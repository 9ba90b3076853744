"""contact.penalty_factor: the penalty from the bodies' stiffness and the mesh spacing.

Under the gap law eps_N = f (lambda + 2 mu) / h keeps a pair's spring eps_N L_c in a fixed
ratio to the elements' stiffness when the mesh is refined. Two consequences are checked on a
block pressed onto a stiffer foundation (matching meshes, refined k = 1, 2, 4), each against
the same runs with the k = 1 penalty held fixed:
- pure penalty: the penetration p / eps_N stays the same fraction of the spacing;
- augmented Lagrangian: the augmentations a step stay the same (the Uzawa contraction
  ~(lambda + 2 mu) / (eps_N h) does not grow).
"""

import math

import pytest
from helpers import model_from_dict

from ntncontact import api
from ntncontact.io.scenario import ScenarioError

PRESSURE = 5.0
BLOCK_MODULUS = 100.0 * 0.7 / (1.3 * 0.4)  # lambda + 2 mu = E (1 - nu) / ((1 + nu)(1 - 2 nu))
SPACING = 0.5  # at k = 1: width 2 over 4 elements


def pressed_block(k: int, contact: dict, kind: str = "static") -> dict:
    """A 2 x 1 block (E 100) under a uniform pressure, on a 2 x 1 foundation (E 1000) with the
    same nodes along the contact; 4k x 2k elements each."""
    ramp = {"times": [0.0, 1.0], "values": [0.0, 1.0]}
    return {
        "analysis": {"kind": kind, "dt": 0.5, "t_end": 1.0},
        "bodies": [
            {"name": "block",
             "mesh": {"type": "rectangle", "width": 2.0, "height": 1.0, "nx": 4 * k, "ny": 2 * k},
             "material": {"model": "linear_elastic", "E": 100.0, "nu": 0.3, "density": 2.0},
             "supports": [{"set": "left", "x": 0.0}],
             "loads": [{"type": "pressure", "set": "top", "value": PRESSURE, "function": ramp}]},
            {"name": "foundation",
             "mesh": {"type": "rectangle", "width": 2.0, "height": 1.0, "nx": 4 * k,
                      "ny": 2 * k, "origin": [0.0, -1.0]},
             "material": {"model": "linear_elastic", "E": 1000.0, "nu": 0.3, "density": 1.0},
             "supports": [{"set": "bottom", "x": 0.0, "y": 0.0}]}],
        "contact": [{"body_1": "block", "surface_1": "bottom", "body_2": "foundation",
                     "surface_2": "top"} | contact],
    }


def run(k: int, contact: dict) -> api.Results:
    return api.run(api.scenario_from_dict(pressed_block(k, contact)), out=None)


def test_gap_law_penalty_is_the_softer_bodys_modulus_over_the_spacing():
    for k in (1, 3):
        law = model_from_dict(pressed_block(k, {"penalty_factor": 10.0})).interfaces[0].law
        assert law.eps_N == pytest.approx(10.0 * BLOCK_MODULUS / (SPACING / k), rel=1e-12)
        assert law.eps_T == law.eps_N  # unless given


def test_persistency_penalty_is_the_softer_bodys_impedance_and_mesh_free():
    impedance = min(math.sqrt(BLOCK_MODULUS * 2.0), math.sqrt(10.0 * BLOCK_MODULUS * 1.0))
    for k in (1, 2):
        data = pressed_block(k, {"penalty_factor": 50.0, "penalty_tangential": 7.0}, "dynamic")
        law = model_from_dict(data).interfaces[0].law
        assert law.eps_N == pytest.approx(50.0 * impedance, rel=1e-12)
        assert law.eps_T == 7.0  # given: kept


def test_penalty_factor_is_refused_beside_penalty_normal_and_must_be_positive():
    with pytest.raises(ScenarioError, match="contact.0.*penalty_normal or penalty_factor"):
        api.scenario_from_dict(pressed_block(1, {"penalty_factor": 10.0,
                                                 "penalty_normal": 1.0}))
    with pytest.raises(ScenarioError, match="penalty_factor"):
        api.scenario_from_dict(pressed_block(1, {"penalty_factor": 0.0}))
    # friction needs a tangential penalty: the factor gives it
    api.scenario_from_dict(pressed_block(1, {"penalty_factor": 10.0, "friction": 0.3}))


def test_pure_penalty_penetration_stays_a_fixed_fraction_of_the_spacing():
    fixed = {"method": "penalty", "penalty_normal": 10.0 * BLOCK_MODULUS / SPACING}
    scaled = {"method": "penalty", "penalty_factor": 10.0}
    relative = {}
    for k in (1, 2, 4):
        for name, contact in (("fixed", fixed), ("scaled", scaled)):
            results = run(k, contact)
            assert results.summary["status"] == "completed"
            relative[name, k] = results.summary["max_penetration"] / (SPACING / k)
            if name == "scaled":
                penalty = results.summary["contact_penalties"]["interface0"]["normal"]
                # the pressure passes through the contact: g = p / eps_N, up to the traction's
                # non-uniformity near the free edge (1.3 % measured)
                assert results.summary["max_penetration"] == pytest.approx(
                    PRESSURE / penalty, rel=0.03)
    for k in (2, 4):
        assert relative["scaled", k] == pytest.approx(relative["scaled", 1], rel=0.01)
        # the case the factor is for: a fixed eps_N penetrates k times more, relative to h
        assert relative["fixed", k] == pytest.approx(k * relative["fixed", 1], rel=0.01)


def test_augmentations_do_not_grow_with_refinement_under_the_factor():
    """f = 2 (a soft penalty, so that the contraction shows): 12 augmentations over the two
    steps at every k with the factor; 12, 15, 18 with the k = 1 penalty held (measured)."""
    counts = {}
    for k in (1, 4):
        for name, contact in (("fixed", {"penalty_normal": 2.0 * BLOCK_MODULUS / SPACING}),
                              ("scaled", {"penalty_factor": 2.0})):
            history = run(k, contact).history
            counts[name, k] = int(history["augmentations"].iloc[1:].sum())
            assert history["augmentations_converged"].iloc[1:].all()
    assert counts["scaled", 4] <= counts["scaled", 1]
    assert counts["fixed", 4] >= counts["fixed", 1] + 4


def test_finer_surface_and_softer_body_set_the_gap_law_penalty():
    """Beyond the uniform case: the foundation meshed 3x finer along the contact sets h, and a
    foundation in plane stress (E 50, nu 0.3: lambda + 2 mu of the 2D model is E / (1 - nu^2))
    softer than the block sets the modulus."""
    data = pressed_block(1, {"penalty_factor": 4.0})
    foundation = data["bodies"][1]
    foundation["mesh"]["nx"] = 12
    foundation["material"] = {"model": "linear_elastic", "E": 50.0, "nu": 0.3,
                              "density": 1.0, "plane_stress": True}
    law = model_from_dict(data).interfaces[0].law
    modulus = 50.0 / (1.0 - 0.3**2)
    assert modulus < BLOCK_MODULUS
    assert law.eps_N == pytest.approx(4.0 * modulus / (2.0 / 12), rel=1e-12)
