"""Tuning of the contact-state graph's expansion (:class:`PlannerOptions`)."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class PlannerOptions:
    """Tuning of the graph expansion (lengths in units of the object size)."""

    surface_candidates: int = 8  # candidate new-contact points on the object surface
    min_contact_spacing: float = 0.3  # new contacts stay this far from existing ones
    approach: float = 0.06  # pre-contact back-off distance
    clearance: float = 0.04  # separation reached by an object motion
    effort_weight: float = 0.1
    #: an OMPL query (one transfer, one object motion) ends after this many state-validity checks,
    #: so that a plan does not depend on the machine's speed (:class:`planner.budget.CheckBudget`)
    ompl_checks: int = 300
    #: wall-clock safety net of one OMPL query (seconds), far above what ``ompl_checks`` takes
    ompl_time: float = 30.0
    dafc_samples: int = 64
    seed: int = 0
    #: object motions may also separate single finger contacts (more edges, slower); by default
    #: they separate the contacts on fixed bodies (the palm lets go, Fig. 5 (3) -> (4))
    separate_finger_contacts: bool = False
    #: object motions in which the contacts on fixed bodies slide (S, eq. 5, 11-12) while the
    #: fingers stick: ``None`` for pose goals only (where the object must get somewhere), or
    #: always / never. Any object shape: disks and spheres keep touching by their radius, other
    #: shapes (a box's corners on a table) keep the contact point on the fixed body.
    sliding_motions: bool | None = None
    #: object motions towards a goal pose in which the contacts of a whole arm's distal link
    #: slide along the object's faces (S at links, :func:`planner.motion_edges._link_slide_sets`),
    #: off by default: on Baxter's hug with line contacts (examples/baxter_hug_box_lines.json) the
    #: straight lift with the forearms sliding replays in MuJoCo for its first 2 cm only, needs the
    #: elbows to roll along the faces, which glued points follow to first order only (the capsule
    #: sinks rho (1 - cos) into the face, 1.5 um after 1 cm, refused by planner.verify), and the
    #: third re-analysed motion has no torque set (32)
    link_sliding: bool = False
    #: lazy edges that lay a link an arm let go of (a link that touched the object in the scene)
    #: flat on a face of a box object again, the other fingers' joints pinned and the arm's kept
    #: contacts held (:mod:`planner.link_replace`); off by default: they add states to every search
    #: on a box (the bundled plans are planned without them)
    link_replacement: bool = False
    #: edges in which one link's contact slides along a face of a box object while the other
    #: contacts hold it still (eq. 33 with an S-point, :mod:`planner.link_slide`), ``slide_length``
    #: object sizes both ways along the face's two axes; off by default: they add states to every
    #: search on a box (the bundled plans are planned without them)
    contact_slides: bool = False
    slide_length: float = 0.05
    #: longest object motion towards a goal pose, and length of a sliding motion (object sizes):
    #: the torque of T is chosen for the start of the motion (first order), so a longer way is
    #: taken in several motions, each re-analysed
    motion_step: float = 0.03
    #: A* heuristic for the ``active`` goal: ``heuristic_weight`` per fingertip contact still
    #: missing (2 in 2-D, 3 in 3-D: the fewest point contacts with friction that can give active
    #: closure) plus one if a fixed body still touches; for the ``fingertips`` goal,
    #: ``heuristic_weight`` per finger not yet touching with its tip only. It never overestimates
    #: when every contact and object-motion edge costs at least ``heuristic_weight``; 0 gives plain
    #: Dijkstra.
    heuristic_weight: float = 1.0
    #: latitudes (degrees) of the candidate rings on a sphere
    sphere_latitudes: tuple[float, ...] = (-10.0, 0.0, 15.0)
    #: a candidate faces a finger when cos(outward normal, direction to its base) exceeds this
    facing: float = 0.3
    #: at most this many fingers are free (without contact) at a time: a finger is released only
    #: while fewer are in transit (regrasping one finger at a time prunes the graph)
    max_free_fingers: int = 1
