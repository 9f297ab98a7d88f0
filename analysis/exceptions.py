"""The project's exceptions. Solver back-ends re-raise their failures as these types, and the
service maps them to HTTP status codes in one place (``api/errors.py``)."""

from __future__ import annotations

from typing import Any


class CTPError(Exception):
    """Base class of every error this project raises on purpose."""


class SceneError(CTPError, ValueError):
    """A scene (or a request about it) is malformed. ``loc`` names the field."""

    def __init__(self, loc: tuple[str | int, ...], reason: str, errors: list[Any] | None = None):
        self.loc = tuple(loc)
        self.reason = reason
        self.errors = errors or [{"loc": list(self.loc), "msg": reason, "type": "scene"}]
        where = ".".join(str(p) for p in self.loc) if self.loc else "scene"
        super().__init__(f"{where}: {reason}")


class CombinationError(SceneError):
    """A combination string does not fit the scene (length or letters)."""


class SolverError(CTPError):
    """A numerical back-end (HiGHS, IPOPT, cdd, OMPL) failed for a reason other than the
    mathematical answer (infeasible/unbounded are answers, not errors)."""

    def __init__(self, backend: str, message: str):
        self.backend = backend
        super().__init__(f"{backend}: {message}")


class SolverTimeLimit(SolverError):
    """A back-end hit its time or iteration limit."""


class NoStationaryGrasp(CTPError):
    """Equation (18) has no solution: the contacts cannot hold the object still."""


class NotInDAFC(CTPError):
    """A requested motion direction is not a direction of active force closure (22)."""


class EmptyTorqueSet(CTPError):
    """The torque set (32) for the requested direction is empty."""
