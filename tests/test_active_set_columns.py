"""The rounds of one ``StepProblem.active_set_step`` keep the columns K^-1 Q they solved:
each round solves only the directions its newly opened pairs add to the range of J_S and
f_S (2 a pair: a pair's tangent has rank 2 and its force lies in that range), not again
those of the pairs of the earlier rounds, and forms the corrected step from those columns
without a further solve. Before, each round solved 2 columns for every pair opened so far,
the force's column and the step once more (Hertz refined 8x: 744 of the run's 857
right-hand-side columns).

Hertz mesh 2 with the penalty from the mesh (``penalty_factor``), as in
test_active_set_step.py, at a Newton start whose step takes two or more rounds.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse.linalg as spla
from helpers import check_step_without, model_from_example

from ntncontact.engine.interfaces import ContactNewtonTerm
from ntncontact.engine.problem import StepProblem
from ntncontact.engine.simulation import Simulation

OVERRIDES = ["bodies.0.mesh.file=meshes/hertz_cylinder_2.msh", "bodies.1.mesh.nx=75",
             "contact.0.penalty_normal=0", "contact.0.penalty_tangential=0",
             "contact.0.penalty_factor=89", "analysis.t_end=3"]


def _start_of_several_rounds(monkeypatch) -> tuple[StepProblem, np.ndarray]:
    """(problem, y) of the first Newton start whose active-set step took 2 or more rounds."""
    found, parts = [], []
    original_step, original_part = StepProblem.active_set_step, ContactNewtonTerm.part

    def spy(self, y, dy, solve, eta):
        parts.clear()
        step = original_step(self, y, dy, solve, eta)
        if step is not None and len(parts) >= 2 and not found:
            found.append((self, y.copy()))
        return step

    def counted_part(self, mask, x_eval, x_start):
        parts.append(mask.sum())
        return original_part(self, mask, x_eval, x_start)

    monkeypatch.setattr(StepProblem, "active_set_step", spy)
    monkeypatch.setattr(ContactNewtonTerm, "part", counted_part)
    Simulation(model_from_example("hertz.toml", OVERRIDES)).run()
    monkeypatch.undo()
    assert found, "a step of Hertz mesh 2 opens pairs over two or more rounds"
    return found[0]


def test_each_round_solves_only_the_columns_of_its_new_pairs(monkeypatch):
    problem, y = _start_of_several_rounds(monkeypatch)
    problem._cache, problem._let_go = {}, {}  # as at that step
    R, _ = problem.residual(y)
    lu = spla.splu(problem.jacobian(y).tocsc())
    masks, columns = [], []
    part = ContactNewtonTerm.part

    def record(self, mask, x_eval, x_start):
        masks.append((self, mask.copy()))
        return part(self, mask, x_eval, x_start)

    def solve(b, rtol):
        columns.append(1 if b.ndim == 1 else b.shape[1])
        return lu.solve(b)

    monkeypatch.setattr(ContactNewtonTerm, "part", record)
    step = problem.active_set_step(y, -lu.solve(R), solve, 1e-6)
    monkeypatch.undo()
    assert len(masks) >= 2, "the exact factor's step takes two or more rounds too"
    term, mask = masks[-1]
    assert 0 < mask.sum() < mask.size
    # every direction solved once: 2 columns a pair let go, nothing for f_S or the step
    assert sum(columns) == 2 * mask.sum(), (columns, mask.sum())
    # and the step is the Newton step without those pairs, to round-off of the exact factor
    check_step_without(problem, y, step, term, mask)
