"""Contact kernels: surfaces, pairing, kinematics, constraint laws, friction, detection.

Pure functions over arrays in GLOBAL numbering (node = body offset + local node,
dof = 2 node + component). See :mod:`.evaluate` for the force/tangent convention and
:mod:`.lagrange`, :mod:`.augmentation`, :mod:`.detection` for the step-level procedures.
"""

from .augmentation import (
    AugmentationCheck,
    AugmentationTolerances,
    augment,
    check_augmentation,
    commit_step,
    extrapolated_update,
    max_contraction,
    newton_update,
)
from .detection import Detection, detect, entering, release_mask
from .evaluate import ContactResult, evaluate_contact
from .friction import SLIP, STICK
from .kinematics import facing, pair_gaps, rate_roundoff
from .lagrange import LagrangeBlocks, blocks_of, lagrange_blocks, release_tensile_pairs
from .laws import ContactLaw
from .pairing import (
    Pairing,
    beyond_ends,
    beyond_reach,
    closest_pairs,
    neighbour_pairs,
    ordered_partners,
)
from .state import PairState
from .surfaces import ContactSurface, Interface, corner_mask

__all__ = [
    "SLIP",
    "STICK",
    "AugmentationCheck",
    "AugmentationTolerances",
    "ContactLaw",
    "ContactResult",
    "ContactSurface",
    "Detection",
    "Interface",
    "LagrangeBlocks",
    "PairState",
    "Pairing",
    "neighbour_pairs",
    "ordered_partners",
    "augment",
    "beyond_ends",
    "beyond_reach",
    "blocks_of",
    "check_augmentation",
    "closest_pairs",
    "commit_step",
    "corner_mask",
    "detect",
    "entering",
    "max_contraction",
    "evaluate_contact",
    "extrapolated_update",
    "lagrange_blocks",
    "facing",
    "pair_gaps",
    "rate_roundoff",
    "newton_update",
    "release_mask",
    "release_tensile_pairs",
]
