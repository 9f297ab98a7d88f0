"""The service's own HTTP error (its handler, and the mapping of every other error: :mod:`api.errors`).
A module of its own so that code run in workers as well (:mod:`api.body_rules`) raises it without
importing the server."""

from __future__ import annotations

from typing import Any


class ApiError(Exception):
    def __init__(self, status: int, detail: str, *, limit: float | None = None,
                 errors: list[dict[str, Any]] | None = None):
        super().__init__(detail)
        self.status = status
        self.detail = detail
        self.limit = limit
        self.errors = errors or []
