"""Placing the robot on the object (issue 10, ``ctp contacts --touch LINK``): the configuration
nearest the scene's ``q``, within the joint limits, at which each named link touches the object
and no link penetrates the object or a fixed body.

The problem, over the hand's joints ``q`` ``(M,)``:

    min  |q - q_0|^2
    s.t. d_k(q) = 0                      for each named link k and the object
         d_j(q) >= 0                     for every other (link, object) and (link, fixed body) pair
         lower <= q <= upper             (the URDF's joint limits; none for scene chains)

with ``d`` the signed distances of the detector's geometry (:func:`analysis.detect.link_distances`:
the link capsules, the object and fixed bodies as their shapes, through coal). The gradient of a
distance is ``u^T J(x)``, ``u`` the unit direction from the target to the link and ``J`` the
point Jacobian of the link at its witness point ``x`` (exact wherever the nearest features do not
switch). The problem is solved by sequential quadratic programming (scipy's SLSQP, with these
gradients), from ``q_0`` and then, where that ends off the constraints, from ``q_0`` moved a few
degrees at random (seeded); the answer is checked again on the distances, not trusted:
every named link within ``TOUCH_TOL`` of the object and no pair deeper than ``TOUCH_TOL``.

A link that is not named but ends within the detector's tolerance of the object (an adjacent
link sharing the contact's joint, a second link lying on the same face) is a contact as well;
one that ends in the band between ``TOUCH_TOL`` and the tolerance is pushed clear (``d >=
CLEAR_FACTOR * tolerance``) by one more solve, so every body is either on the object or
clearly off it.

Link-to-link collisions inside the hand are not constrained (the links of one chain meet at its
joints); the planner's collision model checks them along motions.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from pydantic import ValidationError
from scipy.optimize import minimize

from analysis._types import Array
from analysis.detect import DEFAULT_TOLERANCE, LinkDistance, UnplacedScene, link_distances, link_refs
from analysis.exceptions import SceneError
from analysis.kinematics import BodyRef, HandKinematics, segment_distance
from analysis.scene import Scene, clean_loc

#: A named link touches where its distance to the object is within this (scene units), and no
#: pair may penetrate deeper: ten times finer than the validation's ``GEOMETRY_TOL``.
TOUCH_TOL = 1e-5
#: A link pushed clear of the object stays at least this many detector tolerances away.
CLEAR_FACTOR = 2.0
#: SLSQP iterations per start.
MAX_ITER = 60
#: Random restarts (perturbations of ``q_0`` of about ``RESTART_SPREAD`` rad) after the first start.
RESTARTS = 4
RESTART_SPREAD = 0.1

__all__ = ["CLEAR_FACTOR", "TOUCH_TOL", "Placement", "place_touching", "placed_scene_data", "resolve_touch_links"]


@dataclass(frozen=True)
class Placement:
    """The configuration found: ``q`` ``(M,)`` (scene order), per finger ``q_by_finger``, the
    distance of every named link to the object at ``q`` (``touch``), the deepest penetration of
    any pair (``min_distance``, >= ``-TOUCH_TOL``), ``|q - q_0|`` and the solver's iterations."""

    q: Array
    q_by_finger: tuple[tuple[float, ...], ...]
    touch: tuple[tuple[str, float], ...]
    min_distance: float
    displacement: float
    iterations: int


def _joint_limits(hand: HandKinematics) -> tuple[Array, Array]:
    lo, hi = [], []
    for f in hand.fingers:
        lo.append(np.asarray(getattr(f, "lower", np.full(f.n_joints, -np.inf)), dtype=float))
        hi.append(np.asarray(getattr(f, "upper", np.full(f.n_joints, np.inf)), dtype=float))
    if not lo:
        return np.zeros(0), np.zeros(0)
    return np.concatenate(lo), np.concatenate(hi)


def resolve_touch_links(scene: Scene, hand: HandKinematics, names: list[str]) -> list[BodyRef]:
    """The finger links named by ``names`` (``"<finger>/<link>"``, or a link name that exactly one
    finger has: ``panda_link4``); SceneError at ``touch`` naming the valid links otherwise."""
    if not names:
        raise SceneError(("touch",), "names no link")
    links = link_refs(scene, hand)
    by_label: dict[str, list[BodyRef]] = {}
    for link in links:
        by_label.setdefault(link.name.split("/", 1)[1], []).append(link)
    out: list[BodyRef] = []
    for name in names:
        ref: BodyRef | None = hand.resolve_body(name)
        if ref is None and len(by_label.get(name, [])) == 1:
            ref = by_label[name][0]
        if ref is None or ref.finger is None:
            why = ("is a fixed body, which cannot move" if name in hand.fixed_names
                   else "is ambiguous: several fingers have it" if len(by_label.get(name, [])) > 1
                   else "is not a finger link")
            raise SceneError(("touch",), f"'{name}' {why}; the links are: "
                             f"{', '.join(r.name for r in links)}")
        if ref in out:
            raise SceneError(("touch",), f"'{name}' is named twice")
        out.append(ref)
    return out


class _Problem:
    """Distances and their gradients at ``q``, cached for the last ``q`` (SLSQP asks for the
    constraints and their Jacobian at the same point)."""

    def __init__(self, scene: Scene, hand: HandKinematics, touch: list[BodyRef], clear: dict[int, float],
                 shadow: bool = True):
        self.scene, self.hand, self.touch = scene, hand, touch
        self.links = link_refs(scene, hand)
        self.clear = clear  # index into the pairs -> lower bound on its distance
        self._q: Array | None = None
        self._pairs: list[LinkDistance] = []
        self._grad: Array = np.zeros((0, hand.M))
        self.shadowed = self._shadowed() if shadow else set()

    def _shadowed(self) -> set[int]:
        """Rows (link, object) of links that contain a named link of length 0 (a fingertip
        sphere at the end of the distal link's capsule): where the named link touches, so does
        the link around it, with the same gradient, and the two rows would make the constraints
        degenerate. Their rows are left out; :func:`place_touching` checks every pair at the end
        and solves again with them where one penetrates."""
        hand, q = self.hand, self.hand.q0
        out: set[int] = set()
        pairs, _ = self.pairs(q)
        for t in self.touch:
            a, b = hand.body_segment(t, q)
            if float(np.linalg.norm(np.asarray(b) - np.asarray(a))) > 0.0:
                continue
            for i, p in enumerate(pairs):
                k = p.link
                if p.target != "object" or k == t or k.finger != t.finger:
                    continue
                ka, kb = hand.body_segment(k, q)
                if (segment_distance(np.asarray(a), np.asarray(ka), np.asarray(kb)) <= 1e-9
                        and hand.body_radius(t) <= hand.body_radius(k)):
                    out.add(i)
        return out

    def pairs(self, q: Array) -> tuple[list[LinkDistance], Array]:
        if self._q is None or not np.array_equal(q, self._q):
            self._pairs = link_distances(self.scene, self.hand, q, self.links)
            G = np.zeros((len(self._pairs), self.hand.M))
            for i, p in enumerate(self._pairs):
                dim = self.scene.dim
                G[i] = p.direction[:dim] @ self.hand.point_jacobian(p.link, p.link_point[:dim], q)
            self._q, self._grad = q.copy(), G
        return self._pairs, self._grad

    def touch_rows(self, q: Array) -> list[int]:
        pairs, _ = self.pairs(q)
        return [next(i for i, p in enumerate(pairs) if p.link == ref and p.target == "object") for ref in self.touch]

    def eq(self, q: Array) -> Array:
        pairs, _ = self.pairs(q)
        return np.array([pairs[i].distance for i in self.touch_rows(q)])

    def eq_jac(self, q: Array) -> Array:
        _, G = self.pairs(q)
        return G[self.touch_rows(q)]

    def _ineq_rows(self, q: Array) -> list[int]:
        skip = set(self.touch_rows(q)) | self.shadowed
        return [i for i in range(len(self._pairs)) if i not in skip]

    def ineq(self, q: Array) -> Array:
        pairs, _ = self.pairs(q)
        rows = self._ineq_rows(q)
        return np.array([pairs[i].distance - self.clear.get(i, 0.0) for i in rows])

    def ineq_jac(self, q: Array) -> Array:
        _, G = self.pairs(q)
        return G[self._ineq_rows(q)]


def _solve(problem: _Problem, q0: Array, start: Array, lo: Array, hi: Array) -> tuple[Array, int]:
    bounds = [(None if not np.isfinite(a) else float(a), None if not np.isfinite(b) else float(b))
              for a, b in zip(lo, hi, strict=True)]
    cons = [{"type": "eq", "fun": problem.eq, "jac": problem.eq_jac}]
    if problem.ineq(start).size:
        cons.append({"type": "ineq", "fun": problem.ineq, "jac": problem.ineq_jac})
    res = minimize(lambda q: float((q - q0) @ (q - q0)), start, jac=lambda q: 2.0 * (q - q0),
                   method="SLSQP", bounds=bounds, constraints=cons,
                   options={"maxiter": MAX_ITER, "ftol": 1e-10})
    return _polish(problem, np.clip(np.asarray(res.x, dtype=float), lo, hi), lo, hi), int(res.nit)


def _settle_band(problem: _Problem, q0: Array, q: Array, lo: Array, hi: Array,
                 tolerance: float) -> tuple[_Problem, Array, float, int]:
    """Links that are not named but end between ``TOUCH_TOL`` and ``tolerance`` from the object
    (neither on it nor clear of it): each such link either touches as well (``d = 0``) or is
    pushed clear (``d >= CLEAR_FACTOR * tolerance``), whichever of the two solves succeeds nearer
    ``q_0``; unchanged when there are none. Returns the problem solved, ``q``, its violation and
    the iterations."""
    pairs, _ = problem.pairs(q)
    touch_rows = set(problem.touch_rows(q))
    band = [i for i, p in enumerate(pairs)
            if i not in touch_rows and p.target == "object" and TOUCH_TOL < p.distance <= tolerance]
    if not band:
        return problem, q, _violation(problem, q), 0
    base = problem
    snap = _Problem(base.scene, base.hand, [*base.touch, *(pairs[i].link for i in band)], {})
    clear = _Problem(base.scene, base.hand, base.touch, {i: CLEAR_FACTOR * tolerance for i in band})
    best: tuple[float, _Problem, Array, float] | None = None
    iterations = 0
    for candidate in (clear, snap):
        q2, nit = _solve(candidate, q0, q, lo, hi)
        iterations += nit
        viol = _violation(candidate, q2)
        pairs2, _ = candidate.pairs(q2)
        rows2 = set(candidate.touch_rows(q2))
        ambiguous = any(i not in rows2 and p.target == "object" and TOUCH_TOL < p.distance <= tolerance
                        for i, p in enumerate(pairs2))
        cost = float(np.linalg.norm(q2 - q0))
        if viol <= TOUCH_TOL and not ambiguous and (best is None or cost < best[0]):
            best = (cost, candidate, q2, viol)
    if best is None:
        return base, q, float("inf"), iterations
    return best[1], best[2], best[3], iterations


def _polish(problem: _Problem, q: Array, lo: Array, hi: Array, steps: int = 30) -> Array:
    """Newton steps of least norm on the named links' distances and on the pairs that penetrate
    or touch (``d < TOUCH_TOL``, held at their bound): SLSQP may stop a little short on these
    piecewise-smooth distances. Each step is kept only where it lowers the violation."""
    best, viol = q, _violation(problem, q)
    for _ in range(steps):
        if viol <= 1e-10:
            break
        pairs, G = problem.pairs(best)
        rows = problem.touch_rows(best)
        target = [0.0] * len(rows)
        for i, p in enumerate(pairs):
            bound = problem.clear.get(i, 0.0)
            if i not in rows and p.distance < bound + TOUCH_TOL:
                rows.append(i)
                lift = TOUCH_TOL / 10 if bound == 0.0 and p.distance < 0 else max(p.distance - bound, 0.0)
                target.append(bound + lift)
        r = np.array([pairs[i].distance for i in rows]) - np.array(target)
        dq, *_ = np.linalg.lstsq(G[rows], -r, rcond=None)
        trial = np.clip(best + dq, lo, hi)
        v = _violation(problem, trial)
        if v >= viol:
            break
        best, viol = trial, v
    return best


def _violation(problem: _Problem, q: Array) -> float:
    """The largest constraint violation at ``q`` (scene units), over every pair (the shadowed
    rows, left out of the solve, included)."""
    pairs, _ = problem.pairs(q)
    touch = set(problem.touch_rows(q))
    e = [abs(pairs[i].distance) for i in touch]
    g = [problem.clear.get(i, 0.0) - p.distance for i, p in enumerate(pairs) if i not in touch]
    return float(max(max(e, default=0.0), max(g, default=0.0)))


def _starts(problem: _Problem, q0: Array, lo: Array, hi: Array, rng: np.random.Generator,
            first: Array) -> tuple[float, Array, int]:
    """Solve from ``first``, then from ``q_0`` moved at random, until the violation is within
    ``TOUCH_TOL``; the best answer, its violation and the iterations spent."""
    best: tuple[float, Array] | None = None
    iterations = 0
    for attempt in range(1 + RESTARTS):
        start = first if attempt == 0 else np.clip(q0 + rng.normal(0.0, RESTART_SPREAD, q0.shape), lo, hi)
        q, nit = _solve(problem, q0, start, lo, hi)
        iterations += nit
        viol = _violation(problem, q)
        if best is None or viol < best[0]:
            best = (viol, q)
        if viol <= TOUCH_TOL:
            break
    assert best is not None
    return best[0], best[1], iterations


def place_touching(scene: Scene, touch: list[str], *, tolerance: float = DEFAULT_TOLERANCE,
                   seed: int = 0) -> Placement:
    """The configuration nearest the scene's ``q`` (within the joint limits) at which each link
    named in ``touch`` touches the object and no link penetrates the object or a fixed body (see
    the module docstring). SceneError at ``touch`` for a name that is not a finger link (the
    message lists the links) and when no such configuration is found (the message names the
    link left farthest from the object, or the pair that penetrates)."""
    if not (np.isfinite(tolerance) and tolerance > 0):
        raise SceneError(("tolerance",), f"must be a positive number (got {tolerance})")
    hand = HandKinematics.from_scene(scene)
    refs = resolve_touch_links(scene, hand, touch)
    lo, hi = _joint_limits(hand)
    q0 = hand.q0.copy()
    if np.any(q0 < lo - 1e-9) or np.any(q0 > hi + 1e-9):
        k = int(np.argmax(np.maximum(lo - q0, q0 - hi)))
        raise SceneError(("fingers",), f"q[{k}] = {q0[k]:.6g} (hand order) is outside its joint limits "
                         f"[{lo[k]:.6g}, {hi[k]:.6g}]")
    q0 = np.clip(q0, lo, hi)
    problem = _Problem(scene, hand, refs, {})
    rng = np.random.default_rng(seed)
    viol, q, iterations = _starts(problem, q0, lo, hi, rng, q0)
    if viol > TOUCH_TOL and problem.shadowed:  # a link around a named fingertip went in: keep its row
        problem = _Problem(scene, hand, refs, {}, shadow=False)
        viol, q, nit = _starts(problem, q0, lo, hi, rng, q)
        iterations += nit
    if viol <= TOUCH_TOL:
        problem, q, viol, nit = _settle_band(problem, q0, q, lo, hi, tolerance)
        iterations += nit
    pairs, _ = problem.pairs(q)
    if viol > TOUCH_TOL:
        rows = problem.touch_rows(q)
        far = max(rows, key=lambda i: abs(pairs[i].distance))
        deep = min(range(len(pairs)), key=lambda i: pairs[i].distance)
        if abs(pairs[far].distance) > TOUCH_TOL:
            why = f"'{pairs[far].link.name}' stays {pairs[far].distance:.4g} from the object"
        else:
            why = f"'{pairs[deep].link.name}' penetrates {pairs[deep].target} by {-pairs[deep].distance:.4g}"
        raise SceneError(("touch",), f"no configuration within the joint limits near the scene's q makes "
                         f"{', '.join(r.name for r in refs)} touch the object without penetrating anything "
                         f"({why} at the best one found)")
    touch_d = tuple((pairs[i].link.name, pairs[i].distance) for i in problem.touch_rows(q))
    by_finger = tuple(tuple(float(v) for v in q[hand.finger_slice(i)]) for i in range(len(hand.fingers)))
    return Placement(q=q, q_by_finger=by_finger, touch=touch_d,
                     min_distance=float(min(p.distance for p in pairs)),
                     displacement=float(np.linalg.norm(q - hand.q0)), iterations=iterations)


def placed_scene_data(data: dict[str, Any], touch: list[str], *, tolerance: float = DEFAULT_TOLERANCE,
                      seed: int = 0) -> tuple[dict[str, Any], Placement]:
    """The parsed scene ``data`` (its ``contacts`` ignored) with each finger's ``q`` replaced by
    the placement :func:`place_touching` finds, and the placement. SceneError naming the first
    bad field of the rest of the scene, or at ``touch``."""
    try:
        draft = UnplacedScene.model_validate({**data, "contacts": []})
    except ValidationError as e:
        first = e.errors()[0]
        raise SceneError(clean_loc(tuple(first["loc"])), first["msg"]) from None
    placement = place_touching(draft, touch, tolerance=tolerance, seed=seed)
    fingers = [{**f, "q": list(q)} for f, q in zip(data["fingers"], placement.q_by_finger, strict=True)]
    return {**data, "fingers": fingers}, placement
