"""The warnings a run's summary calls for, one line each: ``ntncontact run`` prints them
(``warning: ...``) and ``ntncontact.run`` issues them as :class:`PhysicsWarning`. They are
computed from summary.json's data alone, so that a run read back says the same."""

from __future__ import annotations

import math

from ..engine.diagnostics import (
    ALE_ANGLE_LIMIT,
    LINEAR_ROTATION_LIMIT,
    LINEAR_STRAIN_LIMIT,
    PhysicsWarning,
)

__all__ = ["PhysicsWarning", "result_warnings"]

#: a node off the contact surfaces inside another body deeper than this fraction of that
#: body's element size is worth a warning
OFF_SURFACE_WARNING = 0.01

#: a pair's penetration above this fraction of its interface's surface spacing is worth a
#: warning: the examples' deepest are 2.8 % (tilted blocks, ring impact), a disk four times
#: finer than the ALE block it falls on 29 % of the disk's spacing
PENETRATION_WARNING = 0.1

#: surfaces whose median spacings differ by more than this ratio are "non-matching": node-to-
#: node pairs then hold only the coarser surface's nodes (the example pairs are within 1.1)
SPACING_RATIO = 1.5

#: a boundary node inside its own body's cells deeper than this fraction of the body's
#: boundary spacing is a body that passed through itself (the examples: none at all)
SELF_PENETRATION_WARNING = 0.01

#: more than this share of a run's steps halved says that its dt is too large (the examples
#: halve at most 3 of 30 load steps, the delamination's onset; a block at 82 % of c 18 of 30)
CUT_BACK_SHARE = 0.25

#: an ALE node ending farther than this fraction of the surface spacing from its partner's
#: place is a pair the mesh motion did not follow: ~1e-9 of it where the motion follows
MISMATCH_WARNING = 0.1

#: a pressed pair open by more than this fraction of its interface's surface spacing is worth
#: a warning, as a penetration is (the ring impact holds 8.1e-4, 0.8 %; a soft block between
#: walls 0.022, 18 %)
OPENING_WARNING = 0.1

#: an element of a linear elastic body turned by more than this (radians) is worth a warning:
#: the linear strain then holds the rotation's 1 - cos(theta) = 0.5 % as a stretch without
#: stress (``engine.diagnostics.LINEAR_ROTATION_LIMIT``)
ROTATION_WARNING = LINEAR_ROTATION_LIMIT

#: a linear elastic element's largest principal stretch above this (it more than doubled) says
#: the rotation warning's polar rotation is not how far the body turned: a block spun 6 rad
#: in free flight stretched 6.1-fold, and its polar rotation atan(6) read 1.41 rad
STRETCH_WARNING = 2.0

#: a linear elastic body's principal Green-Lagrange strain above this is worth a warning
#: (``engine.diagnostics.LINEAR_STRAIN_LIMIT``, where a compressed block's linear and
#: Neo-Hookean reactions differ by 9 %)
LINEAR_STRAIN_WARNING = LINEAR_STRAIN_LIMIT

#: net positive work of the contact forces (energy contact added) above this fraction of the
#: run's energy scale is worth a warning: the persistency law's is ~1e-10 of it, the gap law's
#: in a dynamic run 0.83 (rod impact, penalty_normal = 1e5, touch inside a step: 5.0 -> 29.1)
CONTACT_GAIN_WARNING = 1e-3

#: energy the penalty method's dashpot (persistency law) took, beyond friction's, above this
#: fraction of the run's energy scale is worth a warning: the augmented Lagrangian's is ~1e-10
#: of it, a disk dropped on a slab with a penalty 100 times the impedance lost 8.3 %
CONTACT_LOSS_WARNING = 1e-2

#: energy the ALE remaps added and no body gave back, above this fraction of the run's energy
#: scale, is worth a warning (the ledger's own round-off is ~1e-12 of it)
UNRETURNED_WARNING = 1e-8

#: the net moment of an interface's contact forces above this fraction of their sum |f| times
#: the contact zone's extent is worth a warning (summary.json max_contact_moment_imbalance):
#: on a press, moment-free pair forces leave round-off, 1e-17 of it, and an ALE base
#: (pairs node to node) 1.4e-7; the report's forces on a non-matching Lagrangian base 1.5e-2
#: (nx = 10: reaction moment 2.3 % off the loads') and, nearly matching (spacing 0.099 against
#: 0.1), 9.7e-3 (1.3 % off); the examples at most 1.1e-9 (delamination)
MOMENT_WARNING = 1e-3

#: a dynamic run's energy balance error above this fraction of its energy scale is worth a
#: warning: the examples' dynamic runs close it to 1e-7 or better (most to 1e-10), the mid-point
#: rule's spinning Neo-Hookean block drifts 7.9e-4 in 1000 steps, and a soft block between
#: walls under it gained 6.6 % of E0 in 12 impacts (0.062 of the energy scale) in silence; the
#: threshold is the one of contact's energy gain, on the same scale
BALANCE_WARNING = 1e-3


def result_warnings(summary: dict, static: bool | None = None) -> list[str]:
    """The warnings a run's summary calls for, one line each, without the ``warning:``
    prefix (``static``: an ``analysis.kind = "static"`` run; None: as the summary's
    ``integrator`` says, null in a static run)."""
    if static is None:
        static = "integrator" in summary and summary["integrator"] is None
    found = (_off_surfaces(summary), _unreturned_energy(summary),
             _contact_energy(summary, static), _contact_loss(summary, static),
             _balance(summary, static),
             _penetration(summary, static), _unpaired(summary, static),
             _surface_2(summary, static), _self_crossing(summary), _opening(summary),
             _mismatch(summary), _degraded_mesh(summary), _surface_spacing(summary),
             _contact_moment(summary, static),
             _linear_rotation(summary, static), _linear_strain(summary), _cut_backs(summary),
             _unconverged_augmentations(summary))
    return [line for line in found if line]


def _off_surfaces(summary: dict) -> str | None:
    """A boundary node on no contact surface went inside another body (summary.json
    ``max_penetration_off_surfaces``)."""
    at = summary.get("max_penetration_off_surfaces_at")
    depth = summary.get("max_penetration_off_surfaces") or 0.0
    if not at or depth <= OFF_SURFACE_WARNING * at["element_size"]:
        return None
    cure = ("make that face a contact surface too, joined to the one beside it (for example "
            "surface_1 = \"bottom+right\"")
    if not at.get("joined", True):
        cure = f"no [[contact]] joins '{at['body']}' and '{at['inside']}' (add one"
    return (f"node {at['node']} of body '{at['body']}', on no contact surface, went "
            f"{depth:.3g} inside '{at['inside']}' (t = {at['time']:.6g}) where nothing resists "
            f"it: {cure}; summary.json max_penetration_off_surfaces)")


def _setup(summary: dict, name: str) -> dict | None:
    """The interface's settings as summary.json's ``contact_setup`` holds them (None in a
    summary written before it did)."""
    return (summary.get("contact_setup") or {}).get(name)


def _spacings(setup: dict) -> str:
    """The two surfaces' spacings, and which is finer when they do not match: node-to-node
    pairs hold the coarser surface's nodes only."""
    h1, h2 = setup["spacing_1"], setup["spacing_2"]
    if max(h1, h2) <= SPACING_RATIO * min(h1, h2):
        return (f"the surfaces' spacings are similar ({h1:.3g} and {h2:.3g}), so their "
                "mismatch is not the cause")
    finer, coarser = ("surface_1", "surface_2") if h1 < h2 else ("surface_2", "surface_1")
    return (f"{finer} (spacing {min(h1, h2):.3g}) is {max(h1, h2) / min(h1, h2):.2g} times "
            f"finer than {coarser} ({max(h1, h2):.3g}) and node-to-node pairs hold only the "
            "coarser surface's nodes: similar spacings, or the finer body ALE, pair them")


def _cures(setup: dict, static: bool) -> list[str]:
    """What keeps an interface's pairs closer, as far as it applies to its settings: the
    predicted detection in dynamic runs only (a quasi-static step takes in what its solution
    ends inside anyway), the penalty for the penalty method only (the augmented Lagrangian
    converges to the constraint whatever its penalty)."""
    where = f"contact.{setup['index']}"
    cures = []
    if setup["detection"] == "penetration" and not static:  # a step late
        cures.append(f"{where}.detection = \"predicted\" (a node that goes inside within a "
                     "step is found only at the next step's start; predicted, it may hold a "
                     "small opening instead)")
    if not (setup["ale_1"] or setup["ale_2"]):
        cures.append("the partner body ALE (mesh_motion = \"ale\") where the surfaces slide "
                     "along each other (a smaller dt does not help there)")
    if setup["method"] == "penalty":
        cures.append(f"a stiffer penalty ({where}.penalty_normal or penalty_factor: the depth "
                     "is traction / penalty)")
    return cures


def _advice(summary: dict, name: str, static: bool) -> str:
    """The part of a penetration warning that says what applies to this interface."""
    setup = _setup(summary, name)
    if setup is None:
        return "surfaces of similar spacing keep the pairs closer"
    cures = _cures(setup, static)
    text = _spacings(setup)
    return text + (". What keeps the pairs closer: " + "; or ".join(cures) if cures else "")


def _penetration(summary: dict, static: bool) -> str | None:
    """A contact pair went deeper than PENETRATION_WARNING of its interface's surface spacing
    (summary.json ``max_penetration_at``)."""
    at = summary.get("max_penetration_at")
    if not at or at["depth"] <= PENETRATION_WARNING * at["element_size"]:
        return None
    return (f"{_went(at, '', 'its partner surface', 'max_penetration_at')}): "
            f"{_advice(summary, at['interface'], static)}")


def _went(at: dict, which: str, inside: str, key: str) -> str:
    """The head of a penetration warning: the node, how deep and where, the summary's key."""
    return (f"node {_node(at)} of interface '{at['interface']}'{which} went {at['depth']:.3g} "
            f"inside {inside} ({at['depth'] / at['element_size']:.2g} of the surface spacing, "
            f"t = {at['time']:.6g}; summary.json {key}")


def _unpaired(summary: dict, static: bool) -> str | None:
    """A contact-surface node in no pair went deeper into the partner body than the deepest
    pair, and than PENETRATION_WARNING of the surface spacing (summary.json
    ``max_penetration_unpaired_at``)."""
    at = summary.get("max_penetration_unpaired_at")
    if not at or at["depth"] <= max(PENETRATION_WARNING * at["element_size"],
                                    summary.get("max_penetration") or 0.0):
        return None
    return (f"{_went(at, ', in no pair,', 'its partner body', 'max_penetration_unpaired')}), "
            "deeper than any pair, with nothing holding it: "
            f"{_advice(summary, at['interface'], static)}")


def _surface_2(summary: dict, static: bool) -> str | None:
    """A surface-2 node went deeper into surface 1's body than the deepest pair by more than
    PENETRATION_WARNING of the surface spacing (summary.json ``max_penetration_surface_2_at``):
    pairs measure their depth at surface 1's nodes, so a surface-2 corner between them cuts
    in unmeasured. A paired surface-2 node's distance to the boundary reads about its pair's
    depth, which the penetration warning reports already: hence the margin."""
    at = summary.get("max_penetration_surface_2_at")
    if not at or at["depth"] <= (PENETRATION_WARNING * at["element_size"]
                                 + (summary.get("max_penetration") or 0.0)):
        return None
    head = _went(at, ", on surface_2,", "surface_1's body", "max_penetration_surface_2")
    return (f"{head}), deeper than any pair measured: a pair measures its "
            "depth at its surface_1 node, along that node's normal, so a surface_2 node "
            "between surface_1's nodes (a corner) cuts in unmeasured; with that face as "
            "surface_1 (its body as body_1) its nodes are the pairs' own")


def _self_crossing(summary: dict) -> str | None:
    """A body passed through itself (summary.json ``max_self_penetration_at``): self contact
    is not modelled, so nothing resisted it."""
    at = summary.get("max_self_penetration_at")
    depth = summary.get("max_self_penetration") or 0.0
    if not at or depth <= SELF_PENETRATION_WARNING * at["element_size"]:
        return None
    return (f"body '{at['body']}' passed through itself: its node {_node(at)} went "
            f"{depth:.3g} inside its own cells (t = {at['time']:.6g}; summary.json "
            "max_self_penetration). Self contact is not modelled, so the results are not "
            f"physical from t = {at['first_time']:.6g} on (the first step that found a "
            "crossing)")


def _cut_backs(summary: dict) -> str | None:
    """Steps whose solve failed at the full dt and were solved in halved sub-steps
    (summary.json ``cut_back_steps``): the run's results hold, but only the summary said
    so."""
    cut, steps = summary.get("cut_back_steps") or 0, summary.get("steps") or 0
    if not cut:
        return None
    line = (f"{cut} of {steps} steps needed halving (summary.json cut_back_steps): their "
            "solve failed at the full analysis.dt and was redone in halved sub-steps")
    if cut > CUT_BACK_SHARE * steps:  # the delamination example halves 3 of 30, on purpose
        line += ": analysis.dt is too large for this case"
    return line


def _unconverged_augmentations(summary: dict) -> str | None:
    """Steps that kept their last augmentation unconverged (``augmentation.on_limit =
    "accept"``, summary.json ``unconverged_steps``): else only the summary says so."""
    unconverged, steps = summary.get("unconverged_steps") or 0, summary.get("steps") or 0
    if not unconverged:
        return None
    deepest = summary.get("max_penetration")
    depth = f" (the run's largest penetration {deepest:.3g})" if deepest else ""
    return (f"{unconverged} of {steps} steps kept an unconverged contact augmentation "
            "(augmentation.on_limit = \"accept\"; summary.json unconverged_steps, history.csv "
            "augmentations_converged = 0): their gaps and tractions did not pass report 5.4's "
            f"test and are off by up to the last augmentation's change{depth}; raise "
            "augmentation.max_iterations to converge them")


def _node(at: dict) -> str:
    """A global node, with its number in the user's mesh file where it has one: a gmsh user
    cannot find the global number in their file."""
    file_node = at.get("file_node", -1)
    return f"{at['node']}" + (f" (file node {file_node})" if file_node >= 0 else "")


def _opening(summary: dict) -> str | None:
    """A pressed pair was open by more than OPENING_WARNING of its surface spacing (summary.json
    ``max_separation_under_traction_at``): the persistency law held an opening it had got to
    in a step without traction."""
    at = summary.get("max_separation_under_traction_at")
    if not at or at["opening"] <= OPENING_WARNING * at["element_size"]:
        return None
    setup = _setup(summary, at["interface"]) or {}
    if setup.get("detection") == "predicted":
        cause = ("a pair entered early (detection = \"predicted\" tests x + dt v) and the "
                 "persistency law holds the opening it entered with: the detection lag shows "
                 "as this opening, or with detection = \"penetration\" as a penetration of "
                 "the same size, up to the approach speed times dt either way")
    else:
        cause = ("the persistency law holds a pair's gap where a step without traction left "
                 "it; release_steps = 1 releases such pairs (at the cost of deeper entries)")
    return (f"node {_node(at)} of interface '{at['interface']}' was pressed across an open gap "
            f"of {at['opening']:.3g} ({at['opening'] / at['element_size']:.2g} of the surface "
            f"spacing, t = {at['time']:.6g}; summary.json max_separation_under_traction): "
            f"{cause}")


def _linear_rotation(summary: dict, static: bool) -> str | None:
    """An element of a linear elastic body turned by more than ROTATION_WARNING (summary.json
    ``max_linear_elastic_rotation``): the stretch, and in a dynamic run the angular momentum,
    which a body that turns and deforms does not keep (small strain is not objective). Where
    an element also stretched (``max_linear_elastic_stretch``), the polar rotation is not how
    far the body turned (:func:`_turn`)."""
    at = summary.get("max_linear_elastic_rotation_at")
    angle = summary.get("max_linear_elastic_rotation") or 0.0
    if not at or angle <= ROTATION_WARNING:
        return None
    momentum = ("" if static else
                ", and a body that turns and deforms does not keep its angular momentum (its "
                "stress is not rotated with it: a tester's linear disk drifted 16 % of |L0| in "
                "8 steps of free flight after an impact)")
    return (f"{_turn(summary, angle, at)}{momentum}; model = \"neo_hookean\" is valid for any "
            "rotation" + ("" if static else " and keeps it"))


def _turn(summary: dict, angle: float, at: dict) -> str:
    """What the rotation did: read as a stretch 1 - cos(theta), with the largest stretch
    beside it; where an element more than doubled (STRETCH_WARNING), the polar rotation is
    not how far the body turned, and the warning says so."""
    stretch = summary.get("max_linear_elastic_stretch") or 0.0
    where = summary.get("max_linear_elastic_stretch_at")
    turned = (f"small-strain elasticity reads a rotation as a stretch of 1 - cos = "
              f"{1 - math.cos(angle):.2g} without stress")
    rotated = (f"an element of the linear elastic body '{at['body']}' turned by {angle:.3g} rad "
               f"(t = {at['time']:.6g}; summary.json max_linear_elastic_rotation)")
    if not where:  # a summary written before the stretch was kept
        return f"{rotated}: {turned}"
    if stretch <= STRETCH_WARNING:
        return (f"{rotated} and the largest principal stretch was {stretch:.3g} "
                f"('{where['body']}', t = {where['time']:.6g}; max_linear_elastic_stretch): "
                f"{turned}")
    return (f"an element of the linear elastic body '{where['body']}' stretched "
            f"{stretch:.3g}-fold (largest principal stretch, t = {where['time']:.6g}; "
            "summary.json max_linear_elastic_stretch), and the polar rotation of F reached "
            f"{angle:.3g} rad (t = {at['time']:.6g}; max_linear_elastic_rotation), which is not "
            "how far the body turned: a spinning linear body flies apart on straight lines, "
            "x = X + t omega x X, whose polar rotation atan(omega t) stays below pi/2, with no "
            "strain or stress (small-strain elasticity is not rotation-invariant: it also "
            "reads a rigid rotation theta as a stretch 1 - cos(theta))")


def _linear_strain(summary: dict) -> str | None:
    """A linear elastic body's principal Green-Lagrange strain passed LINEAR_STRAIN_WARNING
    (summary.json ``max_linear_elastic_strain``): its stress is then far from a finite-strain
    one."""
    at = summary.get("max_linear_elastic_strain_at")
    strain = summary.get("max_linear_elastic_strain") or 0.0
    if not at or strain <= LINEAR_STRAIN_WARNING:
        return None
    return (f"an element of the linear elastic body '{at['body']}' reached a principal "
            f"Green-Lagrange strain of {strain:.2g} in magnitude, in tension or compression "
            f"(t = {at['time']:.6g}; summary.json "
            f"max_linear_elastic_strain): above {LINEAR_STRAIN_WARNING:g} small-strain "
            "elasticity departs from a finite-strain law (a block compressed to a Green "
            "strain of 0.1 carries 9 % less than a Neo-Hookean one, to 0.32 (40 %) 38 % "
            "less); model = \"neo_hookean\" is valid at any strain")


def _mismatch(summary: dict) -> str | None:
    """An ALE node ended far from its partner's place (summary.json ``max_ale_mismatch``):
    the pair is then no longer node to node. At a fixed end of the ALE surface
    (``fixed_end``) nothing slides: a partner node off the ALE grid there is out of every
    node's reach, and the slide advice does not apply. Nor does it to a slide longer than
    the partner: the advice names the partner's length as the bound."""
    at = summary.get("max_ale_mismatch_at")
    if not at or summary["max_ale_mismatch"] <= MISMATCH_WARNING * at["element_size"]:
        return None
    mismatch = summary["max_ale_mismatch"]
    head = (f"an ALE contact node{_mismatch_where(at)} ended {mismatch:.3g} from its "
            f"partner's place ({mismatch / at['element_size']:.2g} of the surface spacing, t = "
            f"{at['time']:.6g}; summary.json max_ale_mismatch): the mesh motion did not follow "
            "that pair, which is no longer node to node. ")
    if at.get("fixed_end"):
        return head + (
            "That node is a fixed end of its ALE surface (a corner or a chain end: it stays "
            "in place whatever the ALE settings), and its partner is off the ALE surface's "
            "grid there (placed so from the start, slid past that end, or sliding away from "
            "it: such a pair is released once farther off than twice the end segment's "
            "original length, however far the mesh motion stretched that segment), beyond "
            "the reach of every ALE node; start the two surfaces with matching end nodes, or "
            "extend the ALE surface past the partner's end (or past its slide)")
    return head + (
        "A larger ale.max_stretch (a node "
        "leaves a fixed end behind by at most that times their original distance, so a "
        "slide away from an end runs out of it even on a long surface), an ALE surface "
        "longer than the slide (its ends and corners stay fixed, its kinks too: no node "
        "crosses them) or ale.respace = \"reference\" may let it follow a slide of up to "
        "about the partner's own length. Where the partner slides on farther (a tester's "
        "block sliding 5 of its lengths over an ALE base: no setting helped, max_stretch = "
        "100 left base cells of 4 degrees) or its surface runs on through the contact (a "
        "spinning or rolling body that slips) none does: the partner's nodes carry this "
        "body's along and bunch them up; make the ALE body Lagrangian there "
        "(mesh_motion = \"lagrangian\")")


def _degraded_mesh(summary: dict) -> str | None:
    """An ALE body's cell got a corner below ALE_ANGLE_LIMIT degrees (or above 180 minus it)
    where its initial mesh had none so bad (summary.json ``ale_mesh_degraded_at``, recorded by
    ``engine.diagnostics.AleQualityCheck``): a sliver the next steps may invert, whose
    stiffness and remaps are poor."""
    at = summary.get("ale_mesh_degraded_at")
    if not at:
        return None
    x, y = at["centroid"]
    first = (f", first below {ALE_ANGLE_LIMIT:g} deg at t = {at['first_time']:.6g}"
             if at["first_time"] != at["time"] else "")
    return (f"cell {at['cell']} of the ALE body '{at['body']}' (centroid ({x:.4g}, {y:.4g})) "
            f"was flattened to a corner of {at['angle']:.2f} deg (its sine "
            f"{at['min_sine']:.2g}, t = {at['time']:.6g}{first}; "
            f"{at['initial_angle']:.3g} deg at t = 0; summary.json ale_mesh_degraded_at): the "
            "mesh motion made it a sliver, which a few more steps of the same may invert and "
            f"whose stiffness and remaps are poor; {_reshaping(at)}")


def _surface_spacing(summary: dict) -> str | None:
    """An ALE contact surface's segment went beyond the SQUARE of the respacing's band of its
    ORIGINAL length, [(1 - t)^2, 1 / (1 - t)^2] = [0.25, 4] (summary.json
    ``ale_surface_spacing_at`` records what left the band itself, ``engine.diagnostics.
    AleSpacingCheck``). The respacing keeps its band only around each run's current mean stretch
    within one move; a partner dragged along the surface bunches the nodes ahead of it and spreads
    those behind. The examples leave the band a little where their bodies deform (the disk drop's
    block: 0.46x, 2.43x; the ring impact's obstacle 0.46x), which is not news: hence the square."""
    at = summary.get("ale_surface_spacing_at") or {}
    sides = [(word, at[key]) for word, key in (("squeezed", "shortest"),
                                                ("stretched", "longest")) if at.get(key)]
    if not any(seg["ratio"] < seg["band"][0] ** 2 or seg["ratio"] > seg["band"][1] ** 2
               for _, seg in sides):
        return None
    parts = [f"{word} to {seg['ratio']:.2f} of its original length "
             f"({seg['length']:.3g} of {seg['reference_length']:.3g}, nodes "
             f"{seg['nodes'][0]}-{seg['nodes'][1]} of '{seg['body']}' at "
             f"({seg['midpoint'][0]:.4g}, {seg['midpoint'][1]:.4g}), t = {seg['time']:.6g})"
             for word, seg in sides]
    band = sides[0][1]["band"]
    return ("an ALE contact surface segment was " + " and one ".join(parts)
            + f" (summary.json ale_surface_spacing_at; the respacing's band is "
            f"[{band[0]:g}, {band[1]:g}] of a segment's share of its stretch, not of its "
            "original length): the partner dragged the surface nodes along, bunching them "
            "ahead of it and spreading them behind, which coarsens the contact and flattens "
            "the cells there; a longer ALE body (more free segments each side of the "
            "contact), contact nodes spaced like this body's, or mesh_motion = "
            "\"lagrangian\" for it keep its spacing")


def _reshaping(at: dict) -> str:
    """What keeps a degraded ALE body's cells shaped, leaving out the smoothing rule it has
    already: the angle-based rules' fixed point beside an unevenly dragged surface can be a
    sliver (docs/scenarios.md, ale.smoothing), the Laplacian rule's is not."""
    cures = []
    if at.get("smoothing", "laplacian") != "laplacian":
        cures.append(f"ale.smoothing = \"laplacian\" (the default; \"{at['smoothing']}\" "
                     "can make slivers beside a dragged surface)")
    layers = at.get("smoothing_layers")
    cures.append("more ale.smoothing_layers" + (f" (now {layers})" if layers is not None else ""))
    cures.append("mesh_motion = \"lagrangian\" for that body (where a partner slides on "
                 "along its surface, its nodes drag this body's along)")
    return ", ".join(cures[:-1]) + " or " + cures[-1] + " keep its cells shaped"


def _mismatch_where(at: dict) -> str:
    """" (node N of body 'B', paired with node M of 'P' in interface 'I')", or "" for a
    summary written before the place was recorded."""
    if "body" not in at:
        return ""
    return (f" (node {at['body_node']} of body '{at['body']}', paired with node "
            f"{at['partner_body_node']} of '{at['partner_body']}' in interface "
            f"'{at['interface']}')")


def _contact_moment(summary: dict, static: bool) -> str | None:
    """The contact forces of an interface exert a net moment (summary.json
    ``max_contact_moment_imbalance``, ``engine.diagnostics.contact_moment``): the report's
    pair force of a pair whose nodes are offset along the surface is a couple. The supports
    take it up (off the loads' moment); free bodies gain angular momentum from it."""
    relative = summary.get("max_contact_moment_imbalance") or 0.0
    at = summary.get("max_contact_moment_imbalance_at")
    if not at or relative <= MOMENT_WARNING:
        return None
    taken = ("the supports' reaction moments take it up, off the loads' by that much"
             if static else "it changes the bodies' angular momentum, or the supports take "
             "it up")
    return (f"the contact forces of interface '{at['interface']}' exert a net moment of "
            f"{at['moment']:.3g} (step {at['step']}, t = {at['time']:.6g}; {relative:.2g} of "
            f"their sum |f| {at['force']:.3g} times the contact zone's extent {at['length']:.3g}; "
            f"summary.json max_contact_moment_imbalance): {taken}. The report's pair forces "
            "(moment_free = false, the static default) make a couple where a pair's nodes are "
            "offset along the surface (non-matching Lagrangian meshes, or pairs that drift "
            "apart); moment_free = true on that interface balances it, as does an ALE body "
            "(mesh_motion = \"ale\") that keeps the pairs node to node")


def _energy_scale(summary: dict) -> float | None:
    """The energy scale the summary's relative balance error was taken against (None when
    the balance error is zero or missing)."""
    error, relative = (summary.get("energy_balance_max_error"),
                       summary.get("energy_balance_max_relative_error"))
    return error / relative if error and relative else None


def _contact_energy(summary: dict, static: bool) -> str | None:
    """The contact forces did net positive work on the bodies (summary.json
    ``contact_work``): the energy balance closes, since the ledger counts that work, but the
    energy came from contact, which frictionless contact cannot give. Dynamic runs: the gap
    law (report 5.5). Static runs, where the gap law is the only one: the report's pair forces
    on pairs whose nodes move apart along the surface, or the load steps
    (:func:`_static_gain_cause`). Under the persistency law ``gap_restoring`` is named
    instead when an interface that adds energy has it."""
    gain = summary.get("contact_work") or 0.0
    scale = _energy_scale(summary)
    if gain <= 0.0 or not scale or gain <= CONTACT_GAIN_WARNING * scale:
        return None
    cause = ("the gap law does so in a dynamic run (report 5.5); the persistency law, or "
             "method = \"lagrange\" with analysis.energy_conserving = true, conserves it")
    restoring = _gap_restoring(summary)
    if restoring:
        cause = (f"gap_restoring = true ({', '.join(restoring)}) does so: a pair's first step "
                 "closes its entry gap within that step (gdot + g/dt), pushing the bodies "
                 "apart; without it the persistency law conserves the energy, and "
                 "detection = \"predicted\" keeps the entry gaps small")
    unmet = summary.get("energy_equation_unmet_steps")
    if unmet:  # analysis.energy_conserving is on, and could not conserve at these steps
        cause = (f"report 5.5's energy equation had no root at {unmet} step(s) (summary.json "
                 "energy_equation_unmet_steps), where no relaxation of the gaps conserves the "
                 "energy; the persistency law conserves it")
    if static:
        cause = _static_gain_cause(summary)
    initial = summary.get("energy_initial") or 0.0
    # the scale holds the largest energy of the run, gain included: a gain of 4.8 E0 read
    # "0.83 of its scale", so the initial energy's ratio is given too
    against = f"{gain / initial:.2g} times the initial energy, " if initial > 0.0 else ""
    return (f"the contact forces added {gain:.3g} to the bodies' energy "
            f"({against}{gain / scale:.2g} of its scale; summary.json contact_work): {cause}")


def _static_gain_cause(summary: dict) -> str:
    """Why contact gained energy in a quasi-static run. Between Lagrangian bodies under the
    report's pair forces (``moment_free = false``, the static default): pairs whose nodes
    move apart along the surface, whose two forces along surface 1's normal then make a
    couple that does work. Matching nodes at t = 0 drift apart too where the bodies stretch
    sideways differently (a 3-block stack gained 2.3e-4 at any load step; with moment_free =
    true, -5.2e-6). Else the load steps: the work is summed by the trapezoid rule, exact only
    for a force linear over each step (the Hertz cylinder loaded and unloaded to zero gained
    6,599, in steps half as long 1,764)."""
    report_forces = {name: setup for name, setup in (summary.get("contact_setup") or {}).items()
                     if not (setup.get("ale_1") or setup.get("ale_2"))
                     and not setup.get("moment_free")}  # absent: a summary before it, static
    if report_forces:
        cures = " and ".join(f"contact.{setup['index']}.moment_free = true"
                             for setup in report_forces.values())
        verb = "give" if len(report_forces) > 1 else "gives"
        return (f"the report's pair forces (moment_free = false, the static default) on "
                f"{', '.join(report_forces)} do so where a pair's nodes move apart along the "
                "surface (bodies that stretch sideways differently, matching nodes at t = 0 "
                "too, or non-matching Lagrangian surfaces): its forces along surface 1's "
                "normal at the two nodes make a couple that does work, which smaller load "
                f"steps do not remove; {cures} {verb} the pairs the gap's full gradient, "
                "whose work vanishes with the step (docs/theory.md, \"Moment-free pair "
                "forces\"), as does an ALE body (mesh_motion = \"ale\") that keeps its "
                "contact nodes on their partners")
    return ("the load steps: each step's work is taken by the trapezoid rule, exact only "
            "where the contact forces change linearly over the step (a contact zone that "
            "grows or shrinks does not), and on a path that comes back the errors do not "
            "cancel; smaller load steps shrink it as their length squared")


def _gap_restoring(summary: dict) -> list[str]:
    """The interfaces that set ``gap_restoring`` under the persistency law, when no interface
    uses the gap law (which would add energy itself)."""
    setups = (summary.get("contact_setup") or {}).items()
    if any(setup["law"] == "gap" for _, setup in setups):
        return []
    return [name for name, setup in setups if setup.get("gap_restoring")]


def _contact_loss(summary: dict, static: bool) -> str | None:
    """Penalty interfaces under the persistency law took more than CONTACT_LOSS_WARNING of the
    energy scale beyond friction (summary.json ``contact_work`` + ``frictional_dissipation``):
    that law's penalty resists the gap's rate, a dashpot."""
    lost = -((summary.get("contact_work") or 0.0) + (summary.get("frictional_dissipation")
                                                     or 0.0))
    scale = _energy_scale(summary)
    dashpots = [name for name, setup in (summary.get("contact_setup") or {}).items()
                if setup["method"] == "penalty" and setup["law"] == "persistency"]
    if static or not dashpots or not scale or lost <= CONTACT_LOSS_WARNING * scale:
        return None
    return (f"the contact forces took {lost:.3g} of the bodies' energy beyond friction "
            f"({lost / scale:.2g} of its scale; summary.json contact_work): method = "
            f"\"penalty\" under the persistency law ({', '.join(dashpots)}) is a dashpot, its "
            "penalty resisting the gap's rate; a stiffer penalty takes less, method = "
            "\"augmented_lagrangian\" none")


def _unreturned_energy(summary: dict) -> str | None:
    """The ALE remaps changed the total energy by more than their conservation could give
    back (summary.json ``ale_unreturned_energy``): the energy balance error then holds it,
    and this names its cause. Only the kinetic energy beyond each body's rigid motion can be
    given back (``engine.remap_conservation.hand_over_energy`` keeps the momenta)."""
    unreturned = summary.get("ale_unreturned_energy") or 0.0
    scale = _energy_scale(summary)
    if not unreturned or not scale or abs(unreturned) <= UNRETURNED_WARNING * scale:
        return None
    return (f"the ALE remaps changed the total energy by {unreturned:.3g} "
            f"({unreturned / scale:.2g} of its scale) that no body's velocities could give "
            "back: the hand-over keeps each body's linear and angular momentum, so a body can "
            "give only its kinetic energy beyond its rigid motion (its vibration), and no "
            "body, ALE or Lagrangian, had enough of it where it happened (bodies that move "
            "nearly rigidly have almost none, however fast they move or spin); keeping a "
            "moving curved body Lagrangian (only its partner ALE) avoids such remaps: "
            "summary.json ale_unreturned_energy")


def _balance(summary: dict, static: bool) -> str | None:
    """A dynamic run's energy ledger is off by more than BALANCE_WARNING of its scale
    (summary.json ``energy_balance_max_relative_error``): energy the loads, contact and the
    remaps do not account for came from the time integration. Static runs are left out: their
    works are trapezoidal sums over load steps, not a conservation law (the delamination
    example's 2.7e-3)."""
    relative = summary.get("energy_balance_max_relative_error") or 0.0
    if static or relative <= BALANCE_WARNING:
        return None
    if summary.get("ale_unreturned_energy") and _unreturned_energy(summary):
        return None  # that warning names the cause already
    cause = ("the time integration or an unconverged step did (history.csv's total_energy "
             "against external_work and contact_work shows when)")
    left_out = summary.get("outside_ledger") or []
    if left_out:
        cause = ("the balance leaves out " + " and ".join(left_out) + ", which may account "
                 "for it; else " + cause)
    elif summary.get("integrator") == "midpoint":
        cause = ("the mid-point rule (analysis.integrator = \"midpoint\") does not conserve "
                 "energy with a nonlinear (Neo-Hookean) material; analysis.integrator = "
                 "\"energy_momentum\" (the default) does")
    return (f"the energy balance is off by {relative:.2g} of the energy scale (summary.json "
            "energy_balance_max_relative_error: energy that no load, contact or remap "
            f"accounts for){_against_initial(summary)}: {cause}")


def _against_initial(summary: dict) -> str:
    """The balance error against the initial energy E0, where it exceeds E0: the relative
    figure's scale is the largest |E|, which a blow-up raises with it, so it cannot pass 1."""
    initial, error = summary.get("energy_initial"), summary.get("energy_balance_max_error")
    if not initial or not error or error <= abs(initial):
        return ""
    return (f", by {error / abs(initial):.3g} times the initial energy E0 = {initial:.3g} "
            "(energy_balance_max_error / energy_initial; the energy changed by up to "
            f"{summary.get('energy_max_relative_variation') or 0.0:.3g} E0, "
            "energy_max_relative_variation)")
