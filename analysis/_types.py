"""Shared type aliases."""

from typing import Any, TypeAlias

from numpy.typing import NDArray

#: A numpy array; shapes are given in comments where arrays are built, e.g. ``# (L_c, M)``.
Array: TypeAlias = NDArray[Any]
