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
    newton_update,
)
from .detection import Detection, detect, release_mask
from .evaluate import ContactResult, contact_term, evaluate_contact, pair_response
from .friction import SLIP, STICK, ReturnMapping, frictional_dissipation, return_mapping
from .kinematics import PairKinematics, pair_kinematics
from .lagrange import LagrangeBlocks, lagrange_blocks, release_tensile_pairs
from .laws import ContactLaw, normal_traction
from .pairing import Pairing, closest_pairs, ordered_partners
from .state import PairState
from .surfaces import ContactSurface, Interface, chord_normals, corner_mask

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
    "PairKinematics",
    "PairState",
    "Pairing",
    "ordered_partners",
    "ReturnMapping",
    "augment",
    "check_augmentation",
    "chord_normals",
    "closest_pairs",
    "commit_step",
    "contact_term",
    "corner_mask",
    "detect",
    "evaluate_contact",
    "frictional_dissipation",
    "lagrange_blocks",
    "newton_update",
    "normal_traction",
    "pair_kinematics",
    "pair_response",
    "release_mask",
    "release_tensile_pairs",
    "return_mapping",
]
