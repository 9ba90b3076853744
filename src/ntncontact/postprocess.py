"""Derived fields for output: element-averaged Cauchy and von Mises stress."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from .fem.q4 import kinematics
from .materials.models import cauchy_stress, von_mises
from .model import Model


def element_von_mises(model: Model, X: NDArray, x: NDArray) -> NDArray:
    """Von Mises stress of each element, averaged over its Gauss points (plane strain s_33)."""
    out = np.empty(len(model.cells))
    for body in model.bodies:
        cells = model.cells[body.cells]
        kin = kinematics(X[cells], x[cells])
        mat = body.material
        sigma, s33 = cauchy_stress(mat.kind, kin.F, mat.effective_lambda, mat.mu,
                                   mat.plane_stress)
        vm = von_mises(sigma, s33)
        out[body.cells] = (vm * kin.weight).sum(axis=1) / kin.weight.sum(axis=1)
    return out
