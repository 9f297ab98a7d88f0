"""Transitions: the edges of the contact-state graph (the steps of a plan) and their figures.

A :class:`Transition` is one checked step: a regrasp (eq. 33: ``release`` F -> D of one finger,
``contact`` D -> F of a free finger's tip) or an ``object_motion`` (eq. 30-32). Its ``figures``
are a typed frozen record of the analysis numbers that justify it, one record type per kind
(:class:`ReleaseFigures`, :class:`ContactFigures`, :class:`ObjectMotionFigures`). Its JSON
(``to_json``: ``equation`` and the fields in order, tuples as lists) is what a plan file holds;
:func:`figures_from_json` reads it back.
"""

from __future__ import annotations

from dataclasses import dataclass, fields
from typing import Any, ClassVar

from analysis._types import Array


class _Figures:
    """Base of the figures records (frozen dataclasses): their JSON."""

    equation: ClassVar[str]

    def to_json(self) -> dict[str, Any]:
        """``equation`` and the fields in order, tuples as lists (what a plan file holds under ``figures``)."""
        out: dict[str, Any] = {"equation": self.equation}
        for f in fields(self):  # type: ignore[arg-type]  # every subclass is a dataclass
            v = getattr(self, f.name)
            out[f.name] = list(v) if isinstance(v, tuple) else v
        return out


@dataclass(frozen=True)
class ReleaseFigures(_Figures):
    """Eq. (33), F -> D: why one finger may let go of all its contacts."""

    equation: ClassVar[str] = "33"
    stationary_margin: float  # margin of the stationary grasp (18) of the remaining contacts
    separation_rate: float  # smallest separation rate -J_d dq of the released contacts
    regrasp_rays: int  # rays of the regrasp cone A' (33)
    regrasp_lines: int  # lines of the regrasp cone A' (33)
    finger: str
    joint_path_length: float  # of the certified retreat


@dataclass(frozen=True)
class ContactFigures(_Figures):
    """Eq. (33), D -> F: a free finger's tip reaches a new contact along a certified OMPL transfer."""

    equation: ClassVar[str] = "33"
    finger: str
    contact_point: tuple[float, ...]  # (d,) world point of the new contact
    joint_path_length: float
    min_clearance: float  # smallest clearance along the free part of the transfer
    configurations_checked: int  # by the clearance certificate
    ompl_seconds: float


@dataclass(frozen=True)
class ObjectMotionFigures(_Figures):
    """Eq. (30)-(32): the object moves along a DAFC direction on the contact manifold."""

    equation: ClassVar[str] = "30-32"
    dafc_dim: int
    a_bar: int  # dimension of the motion space (a~)
    separation_rates: tuple[float, ...]  # (#D,) -A_d [dq; dr] of the separating contacts
    separations: tuple[float, ...]  # (#D,) final gap of each separating contact
    sliding_contacts: tuple[int, ...]  # indices of the contacts that slide (S)
    object_path_length: float
    manifold_residual: float  # largest |F(x)| over the dense path
    ompl_planner_states: int
    states_checked: int
    max_joint_step: float
    ompl_seconds: float


@dataclass(frozen=True)
class SlideFigures(_Figures):
    """Eq. (33) with an S-point and ``dr = 0``: one link's contact slides along a face of the object
    while the other contacts hold it (:mod:`planner.link_slide`)."""

    equation: ClassVar[str] = "33"
    finger: str
    body: str  # the link whose contact slides
    sliding_contact: int  # its index among the contacts
    start_point: tuple[float, ...]  # (3,) world point of the contact before
    end_point: tuple[float, ...]  # (3,) and after the slide
    displacement: tuple[float, ...]  # (3,) end - start, in the face's plane
    max_gap: float  # largest |gap| of the sliding contact's body point from the face along the path
    max_kept_drift: float  # largest motion of a kept contact's body point along the path
    stationary_margin: float  # smallest margin of (18) of the holding contacts over the waypoints
    waypoints: int
    joint_path_length: float
    min_clearance: float  # smallest clearance along the path (the touching links allowed to touch)


StepFigures = ReleaseFigures | ContactFigures | ObjectMotionFigures | SlideFigures
_FIGURES: dict[str, type[ReleaseFigures] | type[ContactFigures] | type[ObjectMotionFigures] | type[SlideFigures]] = {
    "release": ReleaseFigures, "contact": ContactFigures, "object_motion": ObjectMotionFigures,
    "slide": SlideFigures}


def figures_from_json(kind: str, data: dict[str, Any]) -> StepFigures:
    """The figures record of a transition ``kind`` from its JSON (inverse of ``to_json``)."""
    cls = _FIGURES[kind]
    values: dict[str, Any] = {f.name: tuple(v) if isinstance(v := data[f.name], list) else v for f in fields(cls)}
    return cls(**values)


@dataclass(frozen=True)
class Transition:
    """One edge of the contact-state graph (a step of a plan)."""

    kind: str  # "release" | "contact" | "object_motion" | "slide"
    combination: str  # the combination of the source state's contacts during the step
    contacts_before: tuple[str, ...]
    contacts_after: tuple[str, ...]
    q_path: Array  # (n, M) joint waypoints of the whole hand
    object_path: Array  # (n, D) object pose vectors
    tau_stationary: Array | None  # (M,) tau_st of (18) during the step
    tau: Array | None  # (M,) the chosen torque (object motion: a member of T, eq. 32)
    torque_set: dict[str, Any] | None  # summary of T: number of vertices/rays, dim of P, work
    figures: StepFigures  # the analysis numbers that justify the step
    cost: float
