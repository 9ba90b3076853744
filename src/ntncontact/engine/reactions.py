"""Support reactions: the resultant force and moment each support set exerts on its body.

At a converged step the residual R = f_int (+ M a) - f_ext + f_contact vanishes on the free
dofs; on a prescribed dof it is the force the support must add for equilibrium, the reaction.
Each prescribed dof belongs to the last support that prescribes it (as the displacement does,
``fem.loads.dirichlet_values``), so a node in two sets is counted once. The build refuses two
supports that give a dof different motions, and two (body, set) pairs whose labels
``<body>_<set>`` coincide (their columns would merge into one holding the sum).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from .model import Model


def support_sets(model: Model) -> dict[str, NDArray]:
    """Prescribed dofs of each support set (label ``<body>_<set>``), in first-seen order."""
    owner: dict[int, str] = {}
    for p in model.prescribed:
        owner.update(dict.fromkeys(np.asarray(p.dofs).tolist(), p.label))
    labels = list(dict.fromkeys(p.label for p in model.prescribed))
    dofs = np.fromiter(owner.keys(), dtype=np.int64, count=len(owner))
    names = np.array(list(owner.values()), dtype=object)
    return {label: np.sort(dofs[names == label]) for label in labels if np.any(names == label)}


def reaction_columns(model: Model) -> tuple[str, ...]:
    """history.csv columns: ``reaction_<body>_<set>_x``, ``_y`` and ``_moment``."""
    return tuple(f"reaction_{label}_{part}" for label in support_sets(model)
                 for part in ("x", "y", "moment"))


def support_reactions(sets: dict[str, NDArray], residual: NDArray, x: NDArray) -> dict:
    """Resultant force (x, y) and moment about the origin (at the positions x where the
    residual was evaluated) of the reactions of each support set."""
    R, pos = residual.ravel(), x.ravel()
    out = {}
    for label, dofs in sets.items():
        comp = dofs % 2
        force = R[dofs]
        lever = pos[dofs + 1 - 2 * comp]  # the other coordinate of the node
        # M = x F_y - y F_x
        moment = float(np.sum(np.where(comp == 1, lever, -lever) * force))
        out |= {f"reaction_{label}_x": float(force[comp == 0].sum()),
                f"reaction_{label}_y": float(force[comp == 1].sum()),
                f"reaction_{label}_moment": moment}
    return out
