"""engine.problem.StepProblem keeps only the free-dof block of its tangent (issue 18, memory)."""

import numpy as np
import scipy.sparse as sp
from helpers import model_from_dict

from ntncontact.engine.problem import StepProblem
from ntncontact.engine.simulation import initial_state


def _clamped_strip():
    return model_from_dict({
        "analysis": {"kind": "static", "dt": 1.0, "t_end": 1.0},
        "bodies": [{
            "name": "beam",
            "mesh": {"type": "rectangle", "width": 4.0, "height": 1.0, "nx": 8, "ny": 2},
            "material": {"model": "neo_hookean", "E": 100.0, "nu": 0.3, "density": 1.0},
            "supports": [{"set": "left", "x": 0.0, "y": 0.0}],
            "loads": [{"type": "traction", "set": "right", "vector": [0.0, -1.0]}],
        }],
    })


def test_the_jacobian_is_the_free_block_and_the_whole_tangent_is_not_kept():
    """The Newton matrix is K[free][:, free] of the whole tangent, and after it is made the
    problem holds no matrix of all the dofs: the whole K's data (an array of the pattern's
    size) would otherwise live beside the free block through the factorization."""
    model = _clamped_strip()
    problem = StepProblem(model, initial_state(model), 1.0)
    y = problem.initial_guess() + 1e-3 * np.sin(np.arange(problem.free_dofs.size))
    problem.residual(y)
    J = problem.jacobian(y)
    _, K, _ = model.assembler.internal(model.X0, d=problem.full(y))
    free = problem.free_dofs
    assert 0 < free.size < model.ndof
    np.testing.assert_array_equal(J.toarray(), K[free][:, free].toarray())
    held = [v for v in problem._cache.values() if sp.issparse(v)]
    assert all(m.shape[0] < model.ndof for m in held)
    np.testing.assert_array_equal(problem.jacobian(y).toarray(), J.toarray())
