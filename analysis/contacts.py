"""Contact kinematics and selection matrices (paper eq. 1-6).

``GraspSystem`` holds, for one configuration, every per-contact quantity of section III-A:
the point Jacobians ``J_ij``, the grasp matrices ``G_ij = [I; [(p_C - p_o) x]]``, the contact
frames (unit normal into the object, tangent basis) and ``A = [J, -G^T]``. ``Selection``
applies a combination string (one letter per contact: F stick, N frictionless, S slide,
D about to detach) to get ``H_c, H_s, H_d`` and ``A_c = H_c A``, ``A_s = H_s A``, ``A_d = H_d A``.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass, field
from functools import cached_property

import numpy as np
from numpy.typing import NDArray

from analysis._types import Array
from analysis.exceptions import CombinationError
from analysis.friction_cone import friction_pyramid
from analysis.geometry import object_origin, object_size
from analysis.kinematics import BodyRef, HandKinematics
from analysis.scales import Scales, grasp_scales
from analysis.scene import Scene
from analysis.torque_limits import hand_torque_limits

STATES = "FNSD"


def tangent_basis(n: Array) -> Array:
    """Orthonormal tangent vectors ``(d-1, d)`` of the unit normal ``n``.

    2-D: ``t = R(+90 deg) n``. 3-D: ``t1`` orthogonal to ``n`` built from the world axis least
    aligned with it, ``t2 = n x t1`` (so ``(t1, t2, n)`` is right-handed).
    """
    n = np.asarray(n, dtype=float)
    if n.shape[0] == 2:
        return np.array([[-n[1], n[0]]])
    e = np.eye(3)[int(np.argmin(np.abs(n)))]
    t1 = np.cross(n, e)
    t1 /= np.linalg.norm(t1)
    t2 = np.cross(n, t1)
    return np.vstack([t1, t2])


def grasp_block(p_C: Array, p_o: Array) -> Array:
    """``G_ij = [I; [(p_C - p_o) x]]`` (eq. 1): ``(D, d)``, maps a contact force to a wrench at
    ``p_o``; its transpose maps an object twist ``dr`` to the motion of the object point."""
    r = np.asarray(p_C, dtype=float) - np.asarray(p_o, dtype=float)
    if r.shape[0] == 2:
        return np.array([[1.0, 0.0], [0.0, 1.0], [-r[1], r[0]]])  # (3, 2)
    rx = np.array([[0.0, -r[2], r[1]], [r[2], 0.0, -r[0]], [-r[1], r[0], 0.0]])
    return np.vstack([np.eye(3), rx])  # (6, 3)


@dataclass(frozen=True)
class GraspSystem:
    """Contact kinematics of one configuration of hand and object (eq. 1-2).

    Shapes: ``L`` contacts, ``d`` force components, ``D`` object coordinates, ``M`` joints.
    """

    dim: int
    q: Array  # (M,)
    p_o: Array  # (d,)
    w_ex: Array  # (D,)
    points: Array  # (L, d)
    normals: Array  # (L, d), unit, into the object
    tangents: Array  # (L, d-1, d)
    mu: Array  # (L,)
    bodies: tuple[BodyRef, ...]
    J_blocks: Array  # (L, d, M)
    G_blocks: Array  # (L, D, d)
    friction_sides: int = 16
    contact_names: tuple[str, ...] = field(default=())
    object_size: float = 0.0  # the object's characteristic size [m]; 0: unknown (lever arms used)
    tau_max: Array | None = None  # (M,) joint torque limits [N m] (inf: unlimited); None: no limit
    joint_labels: tuple[str, ...] = field(default=())  # (M,) names of the joints, for messages

    def __post_init__(self) -> None:
        L, d = self.points.shape
        assert d == self.dim and self.normals.shape == (L, d)
        assert self.J_blocks.shape[:2] == (L, d)
        assert self.G_blocks.shape == (L, self.D, d)
        assert np.allclose(np.linalg.norm(self.normals, axis=1), 1.0, atol=1e-6)
        assert self.tau_max is None or (self.tau_max.shape == (self.M,) and np.all(self.tau_max > 0))

    @property
    def L(self) -> int:
        return int(self.points.shape[0])

    @property
    def d(self) -> int:
        return self.dim

    @property
    def D(self) -> int:
        return 3 if self.dim == 2 else 6

    @property
    def M(self) -> int:
        return int(self.J_blocks.shape[2])

    @property
    def J(self) -> Array:
        """``J``: ``(L d, M)`` stacked point Jacobians."""
        return self.J_blocks.reshape(self.L * self.d, self.M)

    @property
    def G(self) -> Array:
        """``G = [G_11 ... G_NL]``: ``(D, L d)``."""
        return np.concatenate(list(self.G_blocks), axis=1) if self.L else np.zeros((self.D, 0))

    @property
    def A(self) -> Array:
        """``A = [J, -G^T]``: ``(L d, M + D)`` with ``A [dq; dr] = -dp_C`` (eq. 2)."""
        return np.hstack([self.J, -self.G.T])

    def contact_A(self, i: int) -> Array:
        """Rows of ``A`` of contact ``i``: ``(d, M + D)``."""
        return np.hstack([self.J_blocks[i], -self.G_blocks[i].T])

    @cached_property
    def pyramid(self) -> tuple[Array, Array]:
        """Per contact, the facet normals ``(L, k', d)`` and generators ``(L, k', d)`` of its
        friction cone (2-D: the two edges, exact; 3-D: the inscribed ``k``-sided pyramid), see
        :mod:`analysis.friction_cone`. Computed once per configuration."""
        L, d, k = self.L, self.d, self.friction_sides
        kk = 2 if d == 2 else k
        facets = np.zeros((L, kk, d))
        gens = np.zeros((L, kk, d))
        for i in range(L):
            facets[i], gens[i] = friction_pyramid(self.normals[i], self.tangents[i], self.mu[i], d, k)
        return facets, gens

    @cached_property
    def scales(self) -> Scales:
        """Force and length scales in which the LPs are posed and certified (:mod:`analysis.scales`)."""
        return grasp_scales(self.dim, self.w_ex, self.points - self.p_o, self.object_size or None)

    def frictional(self) -> NDArray[np.bool_]:
        return self.mu > 0.0

    def joint_groups(self) -> list[tuple[list[int], list[int]]]:
        """Contacts linked by shared joints: the connected components ``(C, Q)`` of the contacts
        whose ``J_ij`` blocks have a nonzero column in common, each with the sorted joints its
        contacts use (a contact on a fixed body is a group of its own with no joints)."""
        L = self.L
        uses = [set(np.flatnonzero(np.any(self.J_blocks[i] != 0.0, axis=0)).tolist()) for i in range(L)]
        parent = list(range(L))

        def find(a: int) -> int:
            while parent[a] != a:
                parent[a] = parent[parent[a]]
                a = parent[a]
            return a

        for a in range(L):
            for b in range(a + 1, L):
                if uses[a] & uses[b]:
                    parent[find(a)] = find(b)
        groups: dict[int, list[int]] = {}
        for a in range(L):
            groups.setdefault(find(a), []).append(a)
        return [(C, sorted(set().union(*(uses[i] for i in C)))) for C in groups.values()]


def system_from_arrays(
    points: Array,
    normals: Array,
    p_o: Array,
    J_blocks: Array | None = None,
    mu: Array | float = 0.5,
    w_ex: Array | None = None,
    q: Array | None = None,
    bodies: tuple[BodyRef, ...] | None = None,
    friction_sides: int = 16,
    contact_names: tuple[str, ...] = (),
    object_size: float = 0.0,
    tau_max: Array | None = None,
    joint_labels: tuple[str, ...] = (),
) -> GraspSystem:
    """A :class:`GraspSystem` from contact points ``(L, d)``, normals ``(L, d)`` (normalised here)
    and point Jacobians ``(L, d, M)`` (default: contacts on fixed bodies, ``M = 0``); builds the
    tangent bases and ``G_ij`` (eq. 1)."""
    points = np.asarray(points, dtype=float)
    L, d = points.shape
    D = 3 if d == 2 else 6
    normals = np.asarray(normals, dtype=float).reshape(L, d)
    normals = normals / np.linalg.norm(normals, axis=1, keepdims=True)
    p_o = np.asarray(p_o, dtype=float)
    J_blocks = np.zeros((L, d, 0)) if J_blocks is None else np.asarray(J_blocks, dtype=float)
    return GraspSystem(
        dim=d,
        q=np.zeros(J_blocks.shape[2]) if q is None else np.asarray(q, dtype=float),
        p_o=p_o,
        w_ex=np.zeros(D) if w_ex is None else np.asarray(w_ex, dtype=float),
        points=points,
        normals=normals,
        tangents=np.array([tangent_basis(n) for n in normals]).reshape(L, d - 1, d),
        mu=np.broadcast_to(np.asarray(mu, dtype=float), (L,)).copy(),
        bodies=tuple(BodyRef("b") for _ in range(L)) if bodies is None else bodies,
        J_blocks=J_blocks,
        G_blocks=np.array([grasp_block(p, p_o) for p in points]).reshape(L, D, d),
        friction_sides=friction_sides,
        contact_names=contact_names,
        object_size=float(object_size),
        tau_max=None if tau_max is None else np.asarray(tau_max, dtype=float),
        joint_labels=joint_labels,
    )


def build_system(scene: Scene, hand: HandKinematics | None = None, q: Array | None = None) -> GraspSystem:
    """Evaluate the contact kinematics of a scene at its configuration (or at ``q``)."""
    hand = hand or HandKinematics.from_scene(scene)
    q = hand.q0 if q is None else np.asarray(q, dtype=float)
    d = scene.dim
    L = len(scene.contacts)
    points = np.array([c.point for c in scene.contacts], dtype=float).reshape(L, d)
    bodies = []
    J_blocks = np.zeros((L, d, hand.M))
    for i, c in enumerate(scene.contacts):
        ref = hand.resolve_body(c.body)
        if ref is None:  # validated by Scene already
            raise CombinationError(("contacts", i, "body"), f"unknown body '{c.body}'")
        bodies.append(ref)
        J_blocks[i] = hand.point_jacobian(ref, points[i], q)
    return system_from_arrays(
        points,
        np.array([c.normal for c in scene.contacts], dtype=float),
        object_origin(scene),
        J_blocks,
        mu=np.array([c.mu for c in scene.contacts], dtype=float),
        w_ex=np.asarray(scene.external_wrench, dtype=float),
        q=q,
        bodies=tuple(bodies),
        friction_sides=scene.friction_cone_sides,
        contact_names=tuple(c.body for c in scene.contacts),
        object_size=object_size(scene),
        tau_max=hand_torque_limits(scene, hand),
        joint_labels=tuple(hand.joint_labels()),
    )


# --------------------------------------------------------------------------------------------
# Combinations and selection matrices


def parse_combination(combination: str, system: GraspSystem) -> str:
    """Check a combination string against the scene; raise :class:`CombinationError`.

    One letter per contact in scene order; frictional contacts (``mu > 0``) take F/S/D,
    frictionless ones N/D.
    """
    c = combination.strip().upper()
    if len(c) != system.L:
        raise CombinationError(
            ("combination",), f"has {len(c)} letters but the scene has {system.L} contacts"
        )
    for i, s in enumerate(c):
        if s not in STATES:
            raise CombinationError(("combination", i), f"'{s}' is not a contact state (use F, N, S or D)")
        if system.mu[i] > 0 and s == "N":
            raise CombinationError(
                ("combination", i), f"contact {i} has mu={system.mu[i]:g}: use F, S or D (N is for mu = 0)"
            )
        if system.mu[i] == 0 and s in "FS":
            raise CombinationError(("combination", i), f"contact {i} is frictionless (mu = 0): use N or D")
    return c


def all_combinations(system: GraspSystem) -> list[str]:
    """Every combination: F/S/D for frictional contacts, N/D for frictionless ones."""
    letters = ["FSD" if m > 0 else "ND" for m in system.mu]
    return ["".join(p) for p in itertools.product(*letters)]


#: Base-3 code of each letter (F 0, S/N 1, D 2; the force class is 2 minus it), by byte; -1 elsewhere.
_LETTER_CODE = np.full(256, -1, dtype=np.intp)
for _letter, _code in {"F": 0, "S": 1, "N": 1, "D": 2}.items():
    _LETTER_CODE[ord(_letter)] = _code


def letter_codes(combinations: list[str], L: int) -> NDArray[np.intp]:
    """``(R, L)`` codes of the combinations' letters (F 0, S/N 1, D 2), read as bytes at once.

    Raise ``ValueError`` naming the first combination that is not ``L`` letters F, S, N or D."""
    if not combinations:
        return np.zeros((0, L), dtype=np.intp)
    for c in combinations:
        if len(c) != L:
            raise ValueError(f"combination {c!r} has {len(c)} letters, not {L}")
    try:
        raw = np.frombuffer("".join(combinations).encode("ascii"), dtype=np.uint8).reshape(len(combinations), L)
    except UnicodeEncodeError:
        raw = None
    out = _LETTER_CODE[raw] if raw is not None else None
    if out is None or bool(np.any(out < 0)):
        bad = next(c for c in combinations if any(x not in "FSND" for x in c))
        raise ValueError(f"combination {bad!r} has a letter other than F, S, N, D")
    return out


@dataclass(frozen=True)
class Selection:
    """Selection matrices of one combination (eq. 3) and the blocks they pick.

    ``f_c = H_c f`` stacks, per contact in scene order, the full force (F) or the normal
    component (S, N); ``c_slices[i]`` is contact ``i``'s slice of ``f_c`` (empty for D).
    """

    combination: str
    H_c: Array  # (L_c, L d)
    H_s: Array  # (L_s, L d), L_s = d * #S
    H_d: Array  # (L_D, L d), one normal row per D-point
    c_slices: tuple[slice, ...]
    s_index: tuple[int, ...]  # contacts in state S, scene order
    d_index: tuple[int, ...]  # contacts in state D
    f_index: tuple[int, ...]  # contacts in state F
    n_index: tuple[int, ...]  # contacts in state N

    @property
    def L_c(self) -> int:
        return int(self.H_c.shape[0])


def selection(system: GraspSystem, combination: str) -> Selection:
    """Build ``H_c, H_s, H_d`` (eq. 3) for a combination string."""
    comb = parse_combination(combination, system)
    d, L = system.d, system.L
    rows_c: list[Array] = []
    rows_s: list[Array] = []
    rows_d: list[Array] = []
    slices: list[slice] = []
    k = 0
    for i, s in enumerate(comb):
        block = np.zeros((d, L * d))
        block[:, i * d : (i + 1) * d] = np.eye(d)
        n_row = system.normals[i] @ block  # (L d,)
        if s == "F":
            rows_c.extend(block)
            slices.append(slice(k, k + d))
            k += d
        elif s in "SN":
            rows_c.append(n_row)
            slices.append(slice(k, k + 1))
            k += 1
            if s == "S":
                rows_s.extend(block)
        else:
            rows_d.append(n_row)
            slices.append(slice(k, k))

    def stack(rows: list[Array]) -> Array:
        return np.array(rows).reshape(len(rows), L * d)

    return Selection(
        combination=comb,
        H_c=stack(rows_c),
        H_s=stack(rows_s),
        H_d=stack(rows_d),
        c_slices=tuple(slices),
        s_index=tuple(i for i, s in enumerate(comb) if s == "S"),
        d_index=tuple(i for i, s in enumerate(comb) if s == "D"),
        f_index=tuple(i for i, s in enumerate(comb) if s == "F"),
        n_index=tuple(i for i, s in enumerate(comb) if s == "N"),
    )


def constrained_matrices(system: GraspSystem, sel: Selection) -> tuple[Array, Array, Array]:
    """``A_c = H_c A`` (eq. 4), ``A_s = H_s A`` (eq. 6), ``A_d = H_d A`` (eq. 5)."""
    A = system.A
    return sel.H_c @ A, sel.H_s @ A, sel.H_d @ A
