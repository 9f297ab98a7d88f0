"""The friction cone of one contact (paper eq. 13) as facets and generators.

A contact with unit normal ``n`` (into the object), tangent basis ``T`` ``(d-1, d)`` and friction
coefficient ``mu`` admits the forces ``f`` with ``|f - (n^T f) n| <= mu n^T f``:

* 2-D: exactly, two facets ``(+-t - mu n)^T f <= 0`` and two generators ``n +- mu t``;
* 3-D: the ``k``-sided pyramid inscribed in the cone, generators
  ``n + mu (cos phi_j t1 + sin phi_j t2)`` with ``phi_j = 2 pi j / k``, and facets
  ``(cos psi_j t1 + sin psi_j t2)^T f <= mu cos(pi/k) n^T f`` with ``psi_j = (2 j + 1) pi / k``.

:class:`analysis.contacts.GraspSystem` caches these per contact; :mod:`analysis.friction`
stacks them into the friction set ``F`` of a combination (eq. 16).
"""

from __future__ import annotations

import numpy as np

from analysis._types import Array


def friction_pyramid(n: Array, T: Array, mu: float, d: int, k: int) -> tuple[Array, Array]:
    """Facet normals ``(k', d)`` (not normalised) and generators ``(k', d)`` of the friction cone
    of one contact; ``k' = 2`` in 2-D, ``k`` in 3-D."""
    if d == 2:
        return np.array([T[0] - mu * n, -T[0] - mu * n]), np.array([n + mu * T[0], n - mu * T[0]])
    psi = (2 * np.arange(k) + 1) * np.pi / k
    phi = 2 * np.arange(k) * np.pi / k
    c = np.cos(np.pi / k)
    facets = np.cos(psi)[:, None] * T[0] + np.sin(psi)[:, None] * T[1] - mu * c * n
    gens = n + mu * (np.cos(phi)[:, None] * T[0] + np.sin(phi)[:, None] * T[1])
    return facets, gens
