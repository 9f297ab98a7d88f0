"""Goals of a plan: the closure the grasp should reach (issue: planner)."""

from __future__ import annotations

from typing import Annotated, Literal

from pydantic import BaseModel, ConfigDict, Field, model_validator

FiniteFloat = Annotated[float, Field(allow_inf_nan=False)]


class Goal(BaseModel):
    """Where the search stops.

    * ``active``: the object can be moved in every direction (motion space of dimension D and
      DAFC the whole sphere);
    * ``passive``: DPFC balances every wrench of ``wrenches`` (default: the external wrench and
      its negative) without changing the joint torques;
    * ``combination``: a named contact-state combination (one letter per contact of the scene
      the search reached), ``combination`` field;
    * ``fingertips``: every finger touches the object, each only with the tip of its last link
      (contacts on fixed bodies such as the palm may remain), and the contacts hold the object
      (a stationary grasp, 18): a regrasp from an enveloping grasp to a fingertip grasp (the
      paper's Fig. 5, steps 1 to 3, the palm still holding);
    * ``pose``: the object pose ``pose`` (2-D ``[x, y, theta]``, 3-D ``[x, y, z, rx, ry, rz]`` with
      a rotation vector) within ``tolerance`` (Euclidean, scene units and radians).
    """

    model_config = ConfigDict(extra="forbid", frozen=True)

    type: Literal["active", "passive", "combination", "pose", "fingertips"]
    combination: Annotated[str, Field(min_length=1, pattern=r"^[FNSDfnsd]+$")] | None = None
    pose: list[FiniteFloat] | None = None
    tolerance: Annotated[float, Field(gt=0, allow_inf_nan=False)] = 0.05
    wrenches: list[list[FiniteFloat]] | None = None

    @model_validator(mode="after")
    def _fields_for_type(self) -> Goal:
        if self.type == "combination" and self.combination is None:
            raise ValueError("goal type 'combination' needs the field 'combination' (e.g. \"FSDD\")")
        if self.type == "pose" and self.pose is None:
            raise ValueError("goal type 'pose' needs the field 'pose'")
        if self.pose is not None and len(self.pose) not in (3, 6):
            raise ValueError("pose must have 3 (2-D: x, y, theta) or 6 (3-D: x, y, z, rotation vector) values")
        return self
