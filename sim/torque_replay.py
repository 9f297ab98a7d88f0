"""Physics cross-check: replay joint torques in MuJoCo, quasi-statically.

A closure analysis predicts how the object moves (a DAFC direction) and what each contact
does (the combination string, e.g. ``"FSDDD"``) when the hand applies a torque from the set
``T`` (eq. 32). :func:`simulate_torques` applies such a torque to the same hand and object in
MuJoCo and reports what happened: the object displacement ``dr`` in the paper's coordinates,
the final joint angles, whether the object was dropped, and per scene contact whether it
stuck, slid or separated, with its mean normal force and its slip distance.

The MuJoCo model (:func:`build_mjcf`, :func:`build_model`)
-----------------------------------------------------------
Frames and coordinates are the scene's (world frame, scene length units).

* **2-D scenes** live in the world xy-plane (``z = 0``). The object body sits at ``p_o`` with
  three joints ``slide x``, ``slide y``, ``hinge z`` (world axes, through ``p_o``), so the object
  coordinates are the paper's ``r = (x, y, theta)``. A disk is modelled as a *sphere* of the same
  radius: its section by the plane ``z = 0`` is the disk, and sphere-capsule contacts are exact
  (analytic) and lie in that plane. Boxes are boxes and polygons convex prisms; their extent in
  ``z`` is immaterial. Fingers are chains of hinges about ``z``.
* **3-D scenes**: the object has a free joint (body origin at ``p_o``); ``dr = (dp, w)`` with
  ``dp`` the displacement of ``p_o`` and ``w`` the rotation vector of ``R_end R_start^T`` (world
  frame), the paper's ``dr``.
* **Fingers** are built from the kinematic model (:class:`analysis.kinematics.FingerModel`, so
  serial chains and URDF fingers alike) by reading it at ``q = 0``: body ``k`` is placed
  relative to body ``k - 1`` as the model places it; the joint between them (the one joint in
  ``joints_moving(k)`` but not in ``joints_moving(k - 1)``) is a hinge whose axis, in body
  ``k``'s frame through its origin, is the rotation axis of body ``k`` when that joint alone
  turns; a body with no new joint (a URDF tip link behind a fixed joint) is welded. So the
  MuJoCo chain is the scene's chain exactly and the MuJoCo ``qpos`` of each finger joint equals
  the scene's ``q`` (``tests/analysis/test_simulate.py`` checks the link end points for random
  ``q``). Each body is a capsule along its
  :meth:`~analysis.kinematics.HandKinematics.body_segment` (a sphere if the segment has zero
  length), named ``"<finger>/<k>"``, with sites ``"<finger>/<k>:a"``, ``"<finger>/<k>:b"`` at
  the segment's end points; joints and motors are ``"<finger>:q<j>"``.
* **Fixed bodies** are static world geoms: segment -> capsule, box -> box, disk/sphere -> sphere
  (centred at the world origin, as in :mod:`analysis.geometry`), polygon -> convex prism.
* **Collision radius ``eps``** (``eps_rel`` times the object size, default 1 %). Scene links may
  have radius 0 and segments are lines, which MuJoCo cannot collide. Every hand geom (links and
  fixed bodies) is therefore the scene shape *grown* by ``eps`` (capsule radius ``radius + eps``,
  box half-sizes ``+ eps``, sphere radius ``+ eps``, polygons offset outwards by ``eps``), and the
  object is the scene shape *shrunk* by ``eps`` (sphere/disk radius ``- eps``, box half-sizes
  ``- eps``, polygon offset inwards, cylinder radius and half-height ``- eps``). Growing one body
  and shrinking the other by the same amount leaves the distance between them unchanged
  (exactly for disks, spheres, capsules and the faces of boxes and polygons; corners of boxes
  and polygons are rounded or sharpened by at most ``eps``), so every scene contact is exactly
  touching in MuJoCo at the scene configuration. MuJoCo's contact point then lies at
  ``p + eps n`` (``p`` the scene point, ``n`` its normal), which is all the difference.
* **Collisions** are explicit ``<pair>`` elements only: every link and every fixed body against
  the object, with the scene contact's ``mu`` (``default_mu`` for bodies without a scene contact;
  the mean if a body has several scene contacts). Links do not collide with each other nor with
  fixed bodies (the cross-check is local: small motions about the scene configuration). Friction
  cones are elliptic (the true Coulomb cone ``|t| <= mu n``, which the paper's 2-D cone is exactly
  and its 3-D ``k``-sided pyramid approximates from inside); ``condim`` 3 (1 for ``mu = 0``).
  Pairs push only at penetration (``margin = 0``) but also report geoms closer than
  ``detect_rel`` times the object size (``gap``, inactive contacts), for gap measurements.
* **External wrench**: gravity is off; ``w_ex`` is applied every step at ``p_o`` through
  ``xfrc_applied`` of the object body, whose centre of mass is placed at ``p_o`` (2-D
  ``(fx, fy, m)`` -> force ``(fx, fy, 0)``, torque ``(0, 0, m)``).
* **Actuators**: one torque motor per finger joint, scene order (``ctrl = tau``, gear 1,
  unlimited).

Quasi-static model
------------------
The paper's analysis is quasi-static: the object moves in a direction in which the fingers do
positive work, without inertia. The simulation realises this with damping that dominates
inertia: the object is damped *equally in each of its coordinates* (2-D: ``x, y, theta``; 3-D:
the 6 free-joint dofs, isotropic, so frame independent), i.e. ``b_r dr/dt = w_net`` whenever the
object is not stopped by contacts, with ``b_r = F / (2 s)`` (:func:`damping`; ``F`` the force
scale of the run, so a net force ``F`` moves the object two object sizes per second). The
object's velocity is therefore the unbalanced wrench in the Euclidean metric of the paper's
coordinates, the metric in which DAFC directions are unit vectors. Masses and inertias are
small (time constants ``m / b`` of ``inertia_time``, a millisecond), so the response to a change
of force settles within a few milliseconds. Finger joints are damped lightly,
``b_q = 0.04 b_r s^2`` (``s`` the object size, the scale of the fingers' lever arms), so that
the torque spent on damping the fingers, ``b_q |dq/dt|``, is a few per cent of the torque that
reaches the contacts, at any scene scale. Masses scale with the damping, so contact stiffness
scales with the forces and penetrations stay near ``1e-5 s``. MuJoCo's ``discrete`` integrator
solves the contacts in the metric ``M + h D`` that includes this damping (the constraint forces
are computed against the same damped inertia that performs the update; ``implicitfast`` gives
the same directions to about 1e-3 at the default parameters), and the contacts are stiff
(``solref`` time constant 5 steps, ``solimp`` impedance 0.99-0.999, ``impratio`` 10 so that
sticking friction creeps little).

Torques and external wrench rise together from zero over ``ramp_time`` (a smooth step): a
sudden load on contacts that are exactly touching would start with an impact (a contact at zero
distance is only switched on after the first step), while scaling a stationary pair
``(tau_st, w_ex)`` together with ``tau_ad`` changes neither the predicted direction nor the
states.

Known properties of the replay, worth knowing when reading its results:

* MuJoCo's contact model is convex, not complementarity-based: a *sliding* contact also moves
  apart along its normal at about ``mu |v_t|`` (the "only way to initiate slip is to generate
  some motion in the normal direction" of MuJoCo's documentation). Under quasi-static damping
  this makes sliding contacts chatter (a disk sliding on the palm is loaded about half of the
  time, with twice the force); time averages (forces, directions) are right, e.g. the tests'
  sliding push matches the closed-form answer to a cosine of 0.9999.
* Statically indeterminate grasps: joint torques fix the contact forces only up to internal
  forces in ``null(J_c^T)`` (the paper's ``Gamma xi~``). MuJoCo settles them itself (normal
  forces from the contacts' penetrations, friction from its regularised least-force solution),
  so the forces it reports satisfy ``G f = -w_ex`` and ``J^T f = tau`` but need not equal the
  analysis's ``f_c``; with fingers squeezing against each other through F-points the realised
  internal forces can differ enough to change which contacts slide.
* Results are first order only for small motions: use ``stop_distance`` (e.g. 2 % of the
  object size) so the geometry does not change much during the run.

Outcome of a contact
--------------------
Every sampled step, each MuJoCo contact between a hand body and the object is assigned to the
scene contact on that body (to the nearest one if the body has several; bodies welded together,
such as a URDF tip link, count as one body; contacts of bodies without a scene contact are
reported as ``extra_contacts``). Over the samples after the ramp (or the second half of a run
that stopped early) each scene contact gets its mean normal force (``n . f``, ``f`` the force
the hand applies on the object, ``n`` MuJoCo's contact normal, which points from the hand into
the object like the scene's; zero while not touching), its *slip*: the path length of the
tangential relative velocity of the two material points at the contact, and its *travel*: the
path length of the faster of those two points. Then

* ``separate``: the contact ends with a gap larger than ``gap_tol_rel`` times the object size,
  or it carried (almost) no load (mean normal force at most ``force_tol_rel`` times the larger
  of the largest mean normal force and ``|w_ex|`` (force part));
* ``slide``: otherwise, if ``slip > max(slip_tol_rel * travel, slip_abs_rel * size,
  slip_pen_factor * p_typ)``, ``p_typ`` the median over the run of the deepest contact
  penetration (soft contacts deform; tangential motion on the scale of that deformation is
  elastic creep while the internal forces of a statically indeterminate grasp settle, not
  sliding);
* ``stick``: otherwise (rolling without slipping is sticking: the material points move
  together to first order, as at an F-point).

Expected states of a combination: ``F -> stick``, ``S -> slide``, ``D -> separate`` (which
includes "touching with zero force"), ``N -> stick`` or ``slide``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import mujoco
import numpy as np
from numpy.typing import NDArray

from analysis._types import Array
from analysis.exceptions import SceneError
from analysis.geometry import object_origin, object_rotation, object_size
from analysis.kinematics import FingerModel, HandKinematics
from analysis.rotations import matrix_to_quat_wxyz, matrix_to_rotvec

if TYPE_CHECKING:
    from analysis.scene import Scene


OBJECT_BODY = "object"
OBJECT_GEOM = "object"
EXPECTED_STATE = {"F": ("stick",), "S": ("slide",), "D": ("separate",), "N": ("stick", "slide")}


# --------------------------------------------------------------------------------------------
# Parameters


@dataclass(frozen=True)
class SimulationParams:
    """Physical and numerical parameters of the quasi-static replay.

    Lengths are scene units, times seconds; ``*_rel`` lengths are fractions of the object size
    ``s`` (:func:`object_size`). Damping, masses and hence contact stiffness scale with the
    force scale ``F`` of the run (:func:`force_scale`: the external wrench and the torques), so
    the replay behaves alike for a 0.5 m disk under 1 N and a 3 cm bar under 0.5 N, and for
    small or large torques: the object damping is ``b_r = F / (speed_rel s)``, the same number for
    every coordinate (force per length/s = moment per rad/s); a net force ``F`` moves the object
    ``speed_rel`` object sizes per second.
    """

    timestep: float = 2e-4
    integrator: str = "discrete"
    speed_rel: float = 2.0  # object sizes per second under a net force of the force scale
    inertia_time: float = 1e-3  # inertia / damping of object and fingers (s); masses follow
    finger_damping_rel: float = 0.04  # b_q = finger_damping_rel * b_r * s^2 per joint
    eps_rel: float = 0.01  # collision radius of lines/segments, fraction of s
    detect_rel: float = 0.02  # contact detection distance (inactive below it), fraction of s
    solref_timeconst: float = 1e-3  # contact spring-damper time constant (s), 5 steps
    solref_dampratio: float = 1.0
    solimp: tuple[float, float, float, float, float] = (0.99, 0.999, 0.001, 0.5, 2.0)  # width: fraction of s
    impratio: float = 10.0
    cone: str = "elliptic"
    solver_iterations: int = 100
    solver_tolerance: float = 1e-10
    ramp_time: float = 0.01  # torques and external wrench rise smoothly from 0 over this time (s)
    default_mu: float = 0.5
    # outcome classification
    gap_tol_rel: float = 1e-3
    force_tol_rel: float = 1e-2
    slip_tol_rel: float = 0.1
    slip_abs_rel: float = 1e-3
    slip_pen_factor: float = 3.0  # slip below this * the typical penetration is elastic creep
    drop_rel: float = 0.5  # the object is "dropped" when it has moved farther than this * s


DEFAULT_PARAMS = SimulationParams()


@dataclass(frozen=True)
class Damping:
    """Damping, masses and inertias of one run (object size ``s``, force scale ``F``)."""

    force_scale: float  # F
    object_damping: float  # b_r = F / (speed_rel s), every object coordinate
    object_mass: float  # = inertia_time * b_r
    object_inertia: float  # isotropic about p_o, = inertia_time * b_r (the same number)
    finger_damping: float  # b_q = finger_damping_rel * b_r * s^2 per joint (torque per rad/s)
    finger_armature: float  # rotor inertia per joint, inertia_time * b_q / 2
    link_mass: float  # per link, at its joint: inertia_time * b_q / (2 s^2)
    link_inertia: float  # link_mass * (s / 10)^2


def force_scale(scene: Scene, tau: Array | None = None) -> float:
    """``F = max(|f_ex|, |m_ex| / s, max_j |tau_j| / s)`` (1 if all are zero), ``s`` the object
    size: the force scale of a run with joint torques ``tau`` ``(M,)``."""
    s = object_size(scene)
    w = np.asarray(scene.external_wrench, dtype=float)  # (D,)
    d = scene.dim
    cands = [float(np.linalg.norm(w[:d])), float(np.linalg.norm(w[d:])) / s]
    if tau is not None and np.size(tau):
        cands.append(float(np.max(np.abs(tau))) / s)
    F = max(cands)
    return F if F > 0 else 1.0


def damping(scene: Scene, tau: Array | None = None, params: SimulationParams = DEFAULT_PARAMS) -> Damping:
    """The damping, masses and inertias :func:`simulate_torques` uses for these torques."""
    s = object_size(scene)
    F = force_scale(scene, tau)
    b_r = F / (params.speed_rel * s)
    b_q = params.finger_damping_rel * b_r * s * s
    link_mass = params.inertia_time * b_q / (2.0 * s * s)
    return Damping(
        force_scale=F,
        object_damping=b_r,
        object_mass=params.inertia_time * b_r,
        object_inertia=params.inertia_time * b_r,
        finger_damping=b_q,
        finger_armature=0.5 * params.inertia_time * b_q,
        link_mass=link_mass,
        link_inertia=link_mass * (0.1 * s) ** 2,
    )


# --------------------------------------------------------------------------------------------
# Names in the MJCF


def link_body_name(finger: str, k: int) -> str:
    """MuJoCo body (and geom) name of body ``k`` of a finger (``k`` = the index of
    :meth:`~analysis.kinematics.FingerModel.body_index`; for serial chains the scene's
    ``"<finger>/<k>"``, for URDF fingers the k-th link on the chain)."""
    return f"{finger}/{k}"


def link_site_names(finger: str, k: int) -> tuple[str, str]:
    """Sites at the two end points of the link's segment (``body_segment``)."""
    return f"{finger}/{k}:a", f"{finger}/{k}:b"


def joint_name(finger: str, j: int) -> str:
    """MuJoCo joint (and actuator) name of joint ``j`` of a finger (index into its ``q``)."""
    return f"{finger}:q{j}"


def fixed_geom_name(body: str) -> str:
    return f"fixed:{body}"


# --------------------------------------------------------------------------------------------
# MJCF


def _f(x: float) -> str:
    return repr(float(x))


def _v(xs: Array | list[float] | tuple[float, ...]) -> str:
    return " ".join(_f(x) for x in np.asarray(xs, dtype=float).ravel())


def _offset_polygon(V: Array, delta: float) -> Array:
    """Offset a convex CCW polygon ``(n, 2)``: edges move outwards by ``delta`` (inwards if < 0)."""
    n = len(V)
    normals = np.zeros((n, 2))
    offsets = np.zeros(n)
    for i in range(n):
        e = V[(i + 1) % n] - V[i]
        nrm = np.array([e[1], -e[0]]) / np.linalg.norm(e)
        normals[i] = nrm
        offsets[i] = nrm @ V[i] + delta
    out = np.zeros_like(V)
    for i in range(n):
        A = np.vstack([normals[i - 1], normals[i]])
        out[i] = np.linalg.solve(A, [offsets[i - 1], offsets[i]])
    return out


def _prism_vertices(V2: Array, half_z: float) -> Array:
    """Vertices ``(2n, 3)`` of the prism over a polygon ``(n, 2)``, ``|z| <= half_z``."""
    lo = np.column_stack([V2, np.full(len(V2), -half_z)])
    hi = np.column_stack([V2, np.full(len(V2), half_z)])
    return np.vstack([lo, hi])


@dataclass(frozen=True)
class _LinkSpec:
    name: str  # "<finger>/<k>", k the body index
    rel_pos: Array  # (3,) in the parent body's frame at q = 0
    rel_quat: Array  # (4,) wxyz
    joint: int | None  # the chain joint that turns this body relative to its parent (None: welded)
    axis: Array  # (3,) hinge axis in this body's frame (through its origin)
    seg_a: Array  # (3,) segment end points in this body's frame
    seg_b: Array  # (3,)
    radius: float


def _finger_links(finger: FingerModel) -> list[_LinkSpec]:
    """Read a finger model at ``q = 0``: relative placements and hinge axes of its bodies.

    Body ``k`` hangs from body ``k - 1`` (the world for ``k = 0``); the joints between them are
    ``joints_moving(k)`` minus ``joints_moving(k - 1)``: one (a hinge, whose axis is read off by
    turning that joint alone) or none (the body is welded, e.g. a URDF tip link behind a fixed
    joint)."""
    n = finger.n_joints
    n_bodies = len(finger.body_names())
    z = np.zeros(n)
    delta = 0.5
    out: list[_LinkSpec] = []
    R_par, p_par = np.eye(3), np.zeros(3)
    moved_before: set[int] = set()
    for k in range(n_bodies):
        R_k, p_k = finger.body_pose(k, z)
        moving = set(finger.joints_moving(k))
        new = sorted(moving - moved_before)
        if len(new) > 1 or not moved_before <= moving:
            raise SceneError(
                ("fingers", finger.name),
                f"body {k} is not one joint further down the chain than body {k - 1}; cannot simulate",
            )
        joint = new[0] if new else None
        axis = np.array([0.0, 0.0, 1.0])
        if joint is not None:
            qd = z.copy()
            qd[joint] = delta
            R_d, p_d = finger.body_pose(k, qd)
            scale = 1.0 + float(np.linalg.norm(p_k))
            rotvec = matrix_to_rotvec(R_k.T @ R_d) / delta
            if np.linalg.norm(p_d - p_k) > 1e-9 * scale or abs(np.linalg.norm(rotvec) - 1.0) > 1e-6:
                raise SceneError(
                    ("fingers", finger.name),
                    f"joint {joint} is not a revolute joint about the origin of body {k}; cannot simulate",
                )
            axis = rotvec / np.linalg.norm(rotvec)
        a, b = finger.body_segment(k, z)
        out.append(
            _LinkSpec(
                name=link_body_name(finger.name, k),
                rel_pos=R_par.T @ (p_k - p_par),
                rel_quat=matrix_to_quat_wxyz(R_par.T @ R_k),
                joint=joint,
                axis=axis,
                seg_a=R_k.T @ (np.asarray(a, dtype=float) - p_k),
                seg_b=R_k.T @ (np.asarray(b, dtype=float) - p_k),
                radius=finger.body_radius(k),
            )
        )
        R_par, p_par = R_k, p_k
        moved_before = moving
    if moved_before != set(range(n)):
        raise SceneError(("fingers", finger.name), "some joints move no body; cannot simulate")
    return out


def _segment_geom(name: str, a: Array, b: Array, radius: float) -> str:
    """A capsule about the segment ``[a, b]`` (a sphere at ``a`` if it has zero length)."""
    if np.linalg.norm(np.asarray(b) - np.asarray(a)) < 1e-12:
        return f'<geom name="{name}" type="sphere" pos="{_v(a)}" size="{_f(radius)}"/>'
    return f'<geom name="{name}" type="capsule" fromto="{_v(a)} {_v(b)}" size="{_f(radius)}"/>'


def _object_geom(scene: Scene, eps: float, s: float, assets: list[str]) -> str:
    from analysis.scene import Box, Cylinder, Disk, Polygon, Sphere

    shape = scene.object.shape
    name = OBJECT_GEOM
    if isinstance(shape, Disk | Sphere):
        if shape.radius <= eps:
            raise SceneError(("object", "shape", "radius"), "is too small for the simulation's contact radius")
        return f'<geom name="{name}" type="sphere" size="{_f(shape.radius - eps)}"/>'
    if isinstance(shape, Box):
        half = np.asarray(shape.size, dtype=float) / 2.0 - eps
        if np.any(half <= 0):
            raise SceneError(("object", "shape", "size"), "is too small for the simulation's contact radius")
        pos = np.zeros(3)
        if shape.position is not None:
            pos[: scene.dim] = shape.position
        if scene.dim == 2:
            half = np.array([half[0], half[1], s])
        return f'<geom name="{name}" type="box" pos="{_v(pos)}" size="{_v(half)}"/>'
    if isinstance(shape, Polygon):
        V = _offset_polygon(np.asarray(shape.vertices, dtype=float), -eps)
        assets.append(f'<mesh name="object_mesh" vertex="{_v(_prism_vertices(V, s))}"/>')
        return f'<geom name="{name}" type="mesh" mesh="object_mesh"/>'
    if isinstance(shape, Cylinder):
        r, hz = shape.radius - eps, shape.height / 2.0 - eps
        if r <= 0 or hz <= 0:
            raise SceneError(("object", "shape"), "is too small for the simulation's contact radius")
        return f'<geom name="{name}" type="cylinder" size="{_f(r)} {_f(hz)}"/>'
    raise SceneError(("object", "shape", "type"), f"simulation does not support '{shape.type}' objects")


def _fixed_geom(scene: Scene, i: int, eps: float, s: float, assets: list[str]) -> str:
    from analysis.scene import Box, Disk, Polygon, Segment, Sphere

    body = scene.fixed_bodies[i]
    shape = body.shape
    name = fixed_geom_name(body.name)
    dim = scene.dim

    def pad(p: list[float] | None) -> Array:
        out = np.zeros(3)
        if p is not None:
            out[:dim] = p
        return out

    if isinstance(shape, Segment):
        return _segment_geom(name, pad(shape.points[0]), pad(shape.points[1]), eps)
    if isinstance(shape, Box):
        half = np.asarray(shape.size, dtype=float) / 2.0 + eps
        if dim == 2:
            half = np.array([half[0], half[1], s])
        return f'<geom name="{name}" type="box" pos="{_v(pad(shape.position))}" size="{_v(half)}"/>'
    if isinstance(shape, Disk | Sphere):
        return f'<geom name="{name}" type="sphere" size="{_f(shape.radius + eps)}"/>'
    if isinstance(shape, Polygon):
        V = _offset_polygon(np.asarray(shape.vertices, dtype=float), eps)
        assets.append(f'<mesh name="fixed_mesh_{i}" vertex="{_v(_prism_vertices(V, s))}"/>')
        return f'<geom name="{name}" type="mesh" mesh="fixed_mesh_{i}"/>'
    raise SceneError(("fixed_bodies", i, "shape"), f"simulation does not support '{shape.type}' fixed bodies")


def _geom_of_contact(hand: HandKinematics, body: str) -> str:
    """MuJoCo geom name of the body a scene contact names (``"<finger>/<k>"`` for links, also
    when the scene names a URDF link by its own name)."""
    ref = hand.resolve_body(body)
    if ref is None:  # validated by Scene
        raise SceneError(("contacts",), f"unknown body '{body}'")
    if ref.finger is None:
        return fixed_geom_name(ref.name)
    return link_body_name(hand.fingers[ref.finger].name, ref.link)


def _geom_mu(scene: Scene, hand: HandKinematics, geom: str, default: float) -> float:
    mus = [c.mu for c in scene.contacts if _geom_of_contact(hand, c.body) == geom]
    return float(np.mean(mus)) if mus else float(default)


def build_mjcf(scene: Scene, params: SimulationParams = DEFAULT_PARAMS, tau: Array | None = None) -> str:
    """MJCF (XML text) of the scene at its configuration; see the module docstring.

    ``tau`` ``(M,)``: the joint torques the model is for (they set the force scale, hence
    damping and masses; :func:`damping`). The keyframe ``"scene"`` holds the scene's
    configuration (object pose, finger ``q``); the model's reference configuration ``qpos0`` has
    the object at its scene pose and ``q = 0``.
    """
    hand = HandKinematics.from_scene(scene)
    s = object_size(scene)
    der = damping(scene, tau, params)
    eps = params.eps_rel * s
    dim = scene.dim
    assets: list[str] = []
    body_geoms: list[tuple[str, str]] = []  # (scene body name, MuJoCo geom name)

    world: list[str] = []
    for i, fb in enumerate(scene.fixed_bodies):
        world.append(_fixed_geom(scene, i, eps, s, assets))
        body_geoms.append((fb.name, fixed_geom_name(fb.name)))

    # object
    p_o = np.zeros(3)
    p_o[:dim] = object_origin(scene)
    b_r = der.object_damping
    inertial = f'<inertial pos="0 0 0" mass="{_f(der.object_mass)}" diaginertia="{_v([der.object_inertia] * 3)}"/>'
    if dim == 2:
        joints = (
            f'<joint name="object:x" type="slide" axis="1 0 0" damping="{_f(b_r)}"/>'
            f'<joint name="object:y" type="slide" axis="0 1 0" damping="{_f(b_r)}"/>'
            f'<joint name="object:theta" type="hinge" axis="0 0 1" damping="{_f(b_r)}"/>'
        )
        quat = np.array([1.0, 0.0, 0.0, 0.0])  # the angle is the hinge's qpos
    else:
        joints = f'<joint name="object:free" type="free" damping="{_f(b_r)}"/>'
        quat = matrix_to_quat_wxyz(object_rotation(scene))
    world.append(
        f'<body name="{OBJECT_BODY}" pos="{_v(p_o)}" quat="{_v(quat)}">{inertial}{joints}'
        f"{_object_geom(scene, eps, s, assets)}</body>"
    )

    # fingers
    actuators: list[str] = []
    for fm in hand.fingers:
        links = _finger_links(fm)
        xml = ""
        for k in reversed(range(len(links))):
            lk = links[k]
            a_name, b_name = link_site_names(fm.name, k)
            hinge = ""
            if lk.joint is not None:
                hinge = (
                    f'<joint name="{joint_name(fm.name, lk.joint)}" type="hinge" axis="{_v(lk.axis)}" '
                    f'damping="{_f(der.finger_damping)}" armature="{_f(der.finger_armature)}"/>'
                )
            xml = (
                f'<body name="{lk.name}" pos="{_v(lk.rel_pos)}" quat="{_v(lk.rel_quat)}">'
                f'<inertial pos="0 0 0" mass="{_f(der.link_mass)}" '
                f'diaginertia="{_v([der.link_inertia] * 3)}"/>'
                + hinge
                + _segment_geom(lk.name, lk.seg_a, lk.seg_b, lk.radius + eps)
                + f'<site name="{a_name}" pos="{_v(lk.seg_a)}"/><site name="{b_name}" pos="{_v(lk.seg_b)}"/>'
                + xml
                + "</body>"
            )
            body_geoms.append((lk.name, lk.name))
        world.append(xml)
        for k in range(fm.n_joints):
            jn = joint_name(fm.name, k)
            actuators.append(f'<motor name="{jn}" joint="{jn}" gear="1"/>')

    # contact pairs
    tc, dr = params.solref_timeconst, params.solref_dampratio
    solimp = list(params.solimp)
    solimp[2] *= s
    detect = params.detect_rel * s
    pairs = []
    for _body, geom in body_geoms:
        mu = max(_geom_mu(scene, hand, geom, params.default_mu), 0.0)
        condim = 3 if mu > 0 else 1
        pairs.append(
            f'<pair geom1="{geom}" geom2="{OBJECT_GEOM}" condim="{condim}" '
            f'friction="{_f(max(mu, 1e-5))} {_f(max(mu, 1e-5))} 0 0 0" '
            f'solref="{_f(tc)} {_f(dr)}" solimp="{_v(solimp)}" margin="0" gap="{_f(detect)}"/>'
        )

    # keyframe
    key_qpos: list[float] = []
    if dim == 2:
        key_qpos += [0.0, 0.0, float(scene.object.pose.angle or 0.0)]
    else:
        key_qpos += [*p_o, *quat]
    key_qpos += [float(x) for x in hand.q0]

    opt = (
        f'<option timestep="{_f(params.timestep)}" gravity="0 0 0" integrator="{params.integrator}" '
        f'cone="{params.cone}" impratio="{_f(params.impratio)}" solver="Newton" '
        f'iterations="{params.solver_iterations}" tolerance="{_f(params.solver_tolerance)}"/>'
    )
    return "\n".join(
        [
            f'<mujoco model="{_xml_escape(scene.name)}">',
            '<compiler angle="radian" inertiafromgeom="false" autolimits="true"/>',
            opt,
            '<default><geom contype="0" conaffinity="0"/><site size="0.001"/></default>',
            "<asset>" + "".join(assets) + "</asset>" if assets else "",
            "<worldbody>",
            *world,
            "</worldbody>",
            "<contact>",
            *pairs,
            "</contact>",
            "<actuator>",
            *actuators,
            "</actuator>",
            f'<keyframe><key name="scene" qpos="{_v(key_qpos)}"/></keyframe>',
            "</mujoco>",
        ]
    )


def _xml_escape(text: str) -> str:
    return text.replace("&", "&amp;").replace('"', "&quot;").replace("<", "&lt;").replace(">", "&gt;")


def build_model(scene: Scene, params: SimulationParams = DEFAULT_PARAMS, tau: Array | None = None) -> mujoco.MjModel:
    """Compile :func:`build_mjcf`."""
    return mujoco.MjModel.from_xml_string(build_mjcf(scene, params, tau))


def finger_qpos_addresses(model: mujoco.MjModel, scene: Scene) -> NDArray[np.int64]:
    """``qpos`` indices ``(M,)`` of the finger joints in scene order (``qvel`` likewise via
    :func:`finger_dof_addresses`)."""
    names = [joint_name(f.name, k) for f in scene.fingers for k in range(len(f.q))]
    return np.array([model.jnt_qposadr[model.joint(n).id] for n in names], dtype=np.int64)


def finger_dof_addresses(model: mujoco.MjModel, scene: Scene) -> NDArray[np.int64]:
    names = [joint_name(f.name, k) for f in scene.fingers for k in range(len(f.q))]
    return np.array([model.jnt_dofadr[model.joint(n).id] for n in names], dtype=np.int64)


def reset_to_scene(model: mujoco.MjModel, data: mujoco.MjData) -> None:
    """Put ``data`` at the scene configuration (keyframe ``"scene"``), at rest, and run
    ``mj_forward``."""
    mujoco.mj_resetDataKeyframe(model, data, model.key("scene").id)
    mujoco.mj_forward(model, data)


# --------------------------------------------------------------------------------------------
# Results


@dataclass(frozen=True)
class ContactOutcome:
    """What one scene contact did during the run (see the module docstring for the rules)."""

    index: int
    body: str
    observed: str  # 'stick' | 'slide' | 'separate'
    mean_normal_force: float  # time average of n . f over the run (0 while not touching)
    mean_force: Array  # (d,) time average of the force the hand applied on the object, world
    max_normal_force: float
    loaded_fraction: float  # fraction of samples with a positive normal force
    slip: float  # path length of the tangential relative motion of the material points
    travel: float  # path length of the faster of the two material points
    final_gap: float  # distance between the body and the object at the end (< 0: penetration)
    expected: str | None = None  # the combination's letter (F, S, D, N), if given
    agrees: bool | None = None

    @property
    def slip_ratio(self) -> float:
        return self.slip / self.travel if self.travel > 0 else 0.0


@dataclass(frozen=True)
class SimulationResult:
    """Outcome of :func:`simulate_torques`.

    ``dr`` is the object displacement in the paper's coordinates: 2-D ``(dx, dy, dtheta)``,
    3-D ``(dp, w)`` with ``w`` the world rotation vector of ``R_end R_start^T``; ``direction``
    is ``dr / |dr|`` (zero if the object did not move).
    """

    dim: int
    duration: float  # simulated time (s); less than requested if stopped early
    dr: Array  # (D,)
    direction: Array  # (D,)
    q0: Array  # (M,)
    q: Array  # (M,) final joint angles
    tau: Array  # (M,) applied joint torques
    dropped: bool
    drop_reason: str
    contacts: tuple[ContactOutcome, ...]
    extra_contacts: tuple[tuple[str, float], ...]  # other bodies that touched: (name, mean normal force)
    times: Array  # (n,) sample times
    trajectory: Array  # (n, D) dr at the sample times
    combination: str | None = None
    stopped_early: bool = False
    object_size: float = 1.0
    damping: Damping | None = None  # damping, masses and force scale of the run
    params: SimulationParams = field(default=DEFAULT_PARAMS)

    @property
    def dq(self) -> Array:
        return self.q - self.q0  # (M,)

    @property
    def agrees(self) -> bool | None:
        """All contacts behaved as the combination says (``None`` without a combination)."""
        if self.combination is None:
            return None
        return all(bool(c.agrees) for c in self.contacts)

    def cosine(self, direction: Array) -> float:
        """Cosine between the observed ``dr`` and a direction ``(D,)`` (0 if either is zero)."""
        d = np.asarray(direction, dtype=float)
        n1, n2 = float(np.linalg.norm(self.dr)), float(np.linalg.norm(d))
        return float(self.dr @ d / (n1 * n2)) if n1 > 0 and n2 > 0 else 0.0

    def displacement_between(self, t0: float, t1: float | None = None) -> Array:
        """``dr(t1) - dr(t0)`` ``(D,)`` from the recorded trajectory (``t1`` default: the end).
        E.g. ``t0 = params.ramp_time`` gives the motion under the full torques."""
        k0 = int(np.clip(np.searchsorted(self.times, t0), 0, len(self.times) - 1))
        k1 = (
            len(self.times) - 1 if t1 is None else int(np.clip(np.searchsorted(self.times, t1), 0, len(self.times) - 1))
        )
        return np.asarray(self.trajectory[k1] - self.trajectory[k0])

    def speed(self) -> float:
        """Mean rate of ``|dr|`` over the run (scene units per second)."""
        return float(np.linalg.norm(self.dr) / self.duration) if self.duration > 0 else 0.0


# --------------------------------------------------------------------------------------------
# Simulation


def _object_dr(scene: Scene, model: mujoco.MjModel, data: mujoco.MjData, p0: Array, R0: Array) -> Array:
    """Object displacement ``(D,)`` in the paper's coordinates relative to the start pose
    (2-D: ``p0`` is ``(theta0,)`` and ``R0`` unused)."""
    if scene.dim == 2:
        adr = model.jnt_qposadr[model.joint("object:x").id]
        x, y, th = data.qpos[adr : adr + 3]
        return np.array([x, y, th - p0[0]])
    adr = model.jnt_qposadr[model.joint("object:free").id]
    p = np.array(data.qpos[adr : adr + 3])
    quat = np.array(data.qpos[adr + 3 : adr + 7])
    R = np.zeros(9)
    mujoco.mju_quat2Mat(R, quat / np.linalg.norm(quat))
    return np.concatenate([p - p0, matrix_to_rotvec(R.reshape(3, 3) @ R0.T)])


def _cross(a: Array, b: Array) -> Array:
    """Row-wise ``a x b`` of ``(3,)`` or ``(k, 3)`` arrays (``np.cross`` is slow on small arrays)."""
    a1, a2, a3 = a[..., 0], a[..., 1], a[..., 2]
    b1, b2, b3 = b[..., 0], b[..., 1], b[..., 2]
    return np.stack([a2 * b3 - a3 * b2, a3 * b1 - a1 * b3, a1 * b2 - a2 * b1], axis=-1)


def _ramp(t: float, T: float) -> float:
    """Smooth ramp from 0 (``t = 0``) to 1 (``t >= T``): ``3x^2 - 2x^3``."""
    if T <= 0 or t >= T:
        return 1.0
    x = max(t, 0.0) / T
    return x * x * (3.0 - 2.0 * x)


class _ContactTracker:
    """Assigns MuJoCo's contacts with the object to scene contacts and records, per sample and
    scene contact, forces, slip and travel.

    A MuJoCo contact belongs to the scene contacts on the same *rigid piece* of the hand: a
    static geom (fixed body) on its own, or all geoms of finger bodies welded together (a URDF
    tip link behind a fixed joint is part of its parent link). Among several scene contacts on
    one piece the one whose object point is nearest wins. Contacts on pieces without a scene
    contact are reported as extra contacts."""

    def __init__(self, scene: Scene, hand: HandKinematics, model: mujoco.MjModel, params: SimulationParams):
        self.scene, self.model, self.params = scene, model, params
        self.dim, self.L = scene.dim, len(scene.contacts)
        self.s = object_size(scene)
        self.obj_id = model.body(OBJECT_BODY).id
        self.obj_geom = model.geom(OBJECT_GEOM).id
        # scene body names of the hand geoms (for extra contacts)
        self.name_of_geom: dict[int, str] = {
            model.geom(fixed_geom_name(fb.name)).id: fb.name for fb in scene.fixed_bodies
        }
        for fm in hand.fingers:
            for k, label in enumerate(fm.body_names()):
                self.name_of_geom[model.geom(link_body_name(fm.name, k)).id] = label
        # rigid piece of every geom: -1 - geom for static geoms, the weld id for the others
        weld = model.body_weldid[model.geom_bodyid]  # (ngeom,)
        self.piece = np.where(weld == 0, -1 - np.arange(model.ngeom), weld)  # (ngeom,)
        self.contact_geom = np.array(
            [model.geom(_geom_of_contact(hand, c.body)).id for c in scene.contacts], dtype=int
        )  # (L,)
        self.contact_piece = self.piece[self.contact_geom]  # (L,)
        self.n_on_piece = {int(p): int(np.sum(self.contact_piece == p)) for p in self.contact_piece}
        # each scene contact's material point on the object, object frame
        R_o, p_o = object_rotation(scene), np.zeros(3)
        p_o[: self.dim] = object_origin(scene)
        pts = np.zeros((self.L, 3))
        for i, c in enumerate(scene.contacts):
            pts[i, : self.dim] = c.point
        self.pts_local = (pts - p_o) @ R_o  # (L, 3): R_o^T (p - p_o) per row
        # per sample (appended by `sample`): time, normal force (L,), force (L, 3), slip and
        # travel increments (L,), deepest penetration of a loaded contact
        self.t: list[float] = []
        self.normal: list[Array] = []
        self.force: list[Array] = []
        self.slip: list[Array] = []
        self.travel: list[Array] = []
        self.penetration: list[float] = []
        self.extra: list[dict[str, float]] = []
        self._f6 = np.zeros(6)
        self._v6 = np.zeros(6)

    def _contacts_with_object(self, data: mujoco.MjData) -> tuple[Array, Array, Array, Array]:
        """MuJoCo contacts with the object: indices ``(k,)``, hand geoms ``(k,)``, the sign that
        turns MuJoCo's geom1 -> geom2 frame into hand -> object ``(k,)``, and positions ``(k, 3)``
        (``z = 0`` in 2-D: boxes and prisms may touch off the plane, the motion is planar)."""
        ncon = data.ncon
        con = data.contact
        g1, g2 = con.geom1[:ncon], con.geom2[:ncon]
        idx = np.flatnonzero((g1 == self.obj_geom) | (g2 == self.obj_geom))
        sign = np.where(g2[idx] == self.obj_geom, 1.0, -1.0)
        hand_geom = np.where(sign > 0, g1[idx], g2[idx])
        pos = np.array(con.pos[idx]).reshape(len(idx), 3)
        if self.dim == 2:
            pos[:, 2] = 0.0
        return idx, hand_geom, sign, pos

    def _assign(self, data: mujoco.MjData, hand_geom: Array, pos: Array) -> Array:
        """Scene contact ``(k,)`` of each MuJoCo contact (-1: no scene contact on that piece)."""
        k = len(hand_geom)
        if k == 0 or self.L == 0:
            return np.full(k, -1, dtype=int)
        xo = data.xpos[self.obj_id]
        Ro = data.xmat[self.obj_id].reshape(3, 3)
        cand = xo + self.pts_local @ Ro.T  # (L, 3) the scene contacts' object points, now
        dist = np.linalg.norm(pos[:, None, :] - cand[None, :, :], axis=2)  # (k, L)
        same = self.piece[hand_geom][:, None] == self.contact_piece[None, :]  # (k, L)
        dist[~same] = np.inf
        nearest = np.argmin(dist, axis=1)
        return np.where(same.any(axis=1), nearest, -1)

    def _contact_forces(self, data: mujoco.MjData, idx: Array) -> Array:
        """Contact-frame forces ``(k, 3)`` (normal, tangent 1, tangent 2) of MuJoCo contacts."""
        out = np.zeros((len(idx), 3))
        if self.model.opt.cone == mujoco.mjtCone.mjCONE_ELLIPTIC:
            adr = data.contact.efc_address[idx]
            dims = data.contact.dim[idx]
            out[:, 0] = data.efc_force[adr]
            has_t = dims >= 3
            out[has_t, 1] = data.efc_force[adr[has_t] + 1]
            out[has_t, 2] = data.efc_force[adr[has_t] + 2]
            return out
        for r, ci in enumerate(idx):  # pyramidal cones: let MuJoCo convert
            mujoco.mj_contactForce(self.model, data, int(ci), self._f6)
            out[r] = self._f6[:3]
        return out

    def _velocity(self, data: mujoco.MjData, body: int) -> tuple[Array, Array]:
        """Angular and linear velocity ``(3,)``, ``(3,)`` of a body (world frame; linear at the
        body's centre of mass, its origin in this model) at the start of the last step."""
        mujoco.mj_objectVelocity(self.model, data, mujoco.mjtObj.mjOBJ_BODY, body, self._v6, 0)
        return self._v6[:3].copy(), self._v6[3:].copy()

    def sample(self, data: mujoco.MjData, t: float, dt: float) -> bool:
        """Record the contacts of the last step (ending at time ``t``, lasting ``dt``); returns
        whether any contact pushes on the object.

        Forces are those the solver applied during the step, velocities those at its start (the
        state the contacts were detected in)."""
        model, L = self.model, self.L
        normal_now = np.zeros(L)
        force_now = np.zeros((L, 3))
        slip_now = np.zeros(L)
        travel_now = np.zeros(L)
        extra: dict[str, float] = {}
        self.t.append(t)
        self.normal.append(normal_now)
        self.force.append(force_now)
        self.slip.append(slip_now)
        self.travel.append(travel_now)
        self.extra.append(extra)
        idx, hand_geom, sign, pos = self._contacts_with_object(data)
        con = data.contact
        active = (con.exclude[idx] == 0) & (con.efc_address[idx] >= 0)
        idx, hand_geom, sign, pos = idx[active], hand_geom[active], sign[active], pos[active]
        f_loc = self._contact_forces(data, idx)  # (k, 3)
        pushing = f_loc[:, 0] > 0.0
        idx, hand_geom, sign, pos, f_loc = idx[pushing], hand_geom[pushing], sign[pushing], pos[pushing], f_loc[pushing]
        k = len(idx)
        self.penetration.append(float(-np.min(con.dist[idx], initial=0.0)))
        if k == 0:
            return False
        # orient as hand -> object (MuJoCo: frame[0] is the normal geom1 -> geom2, frame^T f the
        # force on geom2)
        frames = con.frame[idx].reshape(k, 3, 3)
        f_world = sign[:, None] * np.einsum("kij,ki->kj", frames, f_loc)  # (k, 3) hand on object
        n = sign[:, None] * frames[:, 0, :]  # (k, 3)
        which_all = self._assign(data, hand_geom, pos)  # (k,)
        for r in np.flatnonzero(which_all < 0):
            g = int(hand_geom[r])
            name = self.name_of_geom.get(g, model.geom(g).name)
            extra[name] = extra.get(name, 0.0) + float(f_loc[r, 0])
        rows = np.flatnonzero(which_all >= 0)
        which = which_all[rows]  # (r,)
        # velocities of the two material points at each contact
        bodies = model.geom_bodyid[hand_geom[rows]]  # (r,)
        p_r = pos[rows]  # (r, 3)
        xo = data.xpos[self.obj_id]
        w_o, v_o = self._velocity(data, self.obj_id)
        w_h = np.zeros((len(rows), 3))  # (r, 3) angular velocity of the hand body
        v_h = np.zeros((len(rows), 3))  # (r, 3) velocity of its centre (its origin)
        for b in set(bodies.tolist()) - {0}:
            sel = bodies == b
            w_h[sel], v_h[sel] = self._velocity(data, b)
        v_h = v_h + _cross(w_h, p_r - data.xipos[bodies])  # material point of the hand body
        v_obj = v_o + _cross(w_o, p_r - xo)  # (r, 3) material point of the object
        v_rel = v_obj - v_h
        nr = n[rows]
        v_t = v_rel - np.sum(v_rel * nr, axis=1)[:, None] * nr  # tangential relative velocity
        np.maximum.at(slip_now, which, np.linalg.norm(v_t, axis=1) * dt)
        np.maximum.at(travel_now, which, np.maximum(np.linalg.norm(v_obj, axis=1), np.linalg.norm(v_h, axis=1)) * dt)
        np.add.at(normal_now, which, f_loc[rows, 0])
        np.add.at(force_now, which, f_world[rows])
        return True

    def window(self, t_from: float) -> NDArray[np.bool_]:
        """Samples ``(n,)`` to evaluate: those after ``t_from`` (the ramp), or, if the run ended
        before a quarter of its samples lie there, its second half."""
        t = np.asarray(self.t)
        after = t > t_from
        if after.sum() >= max(1, len(t) // 4):
            return after
        return np.arange(len(t)) >= len(t) // 2

    def final_gaps(self, data: mujoco.MjData) -> Array:
        """Gap ``(L,)`` between each contact's hand piece and the object at the current state
        (negative: penetration). For a piece with one scene contact, the smallest geom distance;
        with several, the distance of the MuJoCo contacts assigned to each (at least the detection
        distance when none is assigned)."""
        model, L = self.model, self.L
        fromto = np.zeros(6)
        dist_geom = {
            g: float(mujoco.mj_geomDistance(model, data, g, self.obj_geom, self.s, fromto))
            for g in range(model.ngeom)
            if g != self.obj_geom and int(self.piece[g]) in self.n_on_piece
        }
        gaps = np.array(
            [min(d for g, d in dist_geom.items() if self.piece[g] == self.contact_piece[i]) for i in range(L)]
        )
        idx, hand_geom, _, pos = self._contacts_with_object(data)
        which = self._assign(data, hand_geom, pos)
        local = np.full(L, np.inf)
        for r, i in enumerate(which):
            if i >= 0:
                local[i] = min(local[i], float(data.contact.dist[idx[r]]))
        detect = self.params.detect_rel * self.s
        for i in range(L):
            if self.n_on_piece[int(self.contact_piece[i])] >= 2:
                gaps[i] = local[i] if np.isfinite(local[i]) else max(gaps[i], detect)
        return gaps


def simulate_torques(
    scene: Scene,
    tau: Array,
    *,
    duration: float,
    combination: str | None = None,
    params: SimulationParams = DEFAULT_PARAMS,
    stop_distance: float | None = None,
    sample_every: int = 1,
) -> SimulationResult:
    """Apply constant joint torques ``tau`` ``(M,)`` (scene finger order; ``tau = J^T f`` for
    contact forces ``f`` the fingers apply on the object) together with the scene's external
    wrench, for ``duration`` seconds, starting at rest at the scene configuration.

    Torques and wrench rise together from zero over ``params.ramp_time`` (a smooth ramp; scaling
    a stationary pair ``(tau_st, w_ex)`` and ``tau_ad`` by the same factor changes neither the
    predicted direction nor the contact states, and a sudden load would start with an impact).
    Forces, slip and travel are evaluated over the samples after the ramp (during the ramp the
    contacts also deform elastically, which is not sliding), or over the second half of the run
    if it stopped early, before a quarter of it lay after the ramp.

    ``stop_distance``: stop early once ``|dr|`` exceeds it (keeps the motion small, where the
    first-order analysis applies). ``sample_every``: contacts are read every this many steps.
    ``combination``: a string such as ``"FSDDD"``; each contact outcome then carries the expected
    state and whether it agrees. Raises :class:`SceneError` for a wrong ``tau`` length, a
    non-positive duration or a bad combination.
    """
    from analysis.contacts import build_system, parse_combination

    hand = HandKinematics.from_scene(scene)
    tau = np.asarray(tau, dtype=float).ravel()  # (M,)
    if tau.shape != (hand.M,) or not np.all(np.isfinite(tau)):
        raise SceneError(("tau",), f"must be {hand.M} finite joint torques (got shape {tau.shape})")
    if not duration > 0:
        raise SceneError(("duration",), "must be positive")
    comb = None if combination is None else parse_combination(combination, build_system(scene, hand))

    dim, D = scene.dim, scene.D
    s = object_size(scene)
    model = build_model(scene, params, tau)
    data = mujoco.MjData(model)
    reset_to_scene(model, data)
    tracker = _ContactTracker(scene, hand, model, params)
    obj_id = tracker.obj_id

    w_ex = np.asarray(scene.external_wrench, dtype=float)  # (D,)
    xfrc = np.zeros(6)  # force, torque at the object's centre of mass (= p_o), world frame
    if dim == 2:
        xfrc[:2], xfrc[5] = w_ex[:2], w_ex[2]
    else:
        xfrc[:] = w_ex
    qadr = finger_qpos_addresses(model, scene)
    q0 = np.array(data.qpos[qadr])  # (M,)
    if dim == 2:
        p0, R0 = np.array([float(scene.object.pose.angle or 0.0)]), np.eye(3)
    else:
        p0, R0 = np.array(data.xpos[obj_id]), np.array(data.xmat[obj_id]).reshape(3, 3)

    h = params.timestep
    n_steps = max(1, math.ceil(duration / h - 1e-9))
    times: list[float] = [0.0]
    traj: list[Array] = [np.zeros(D)]
    n_samples = 0
    stopped, dropped, reason = False, False, ""
    unloaded_run = 0  # consecutive samples without any contact pushing on the object
    for step in range(1, n_steps + 1):
        lam = _ramp((step - 0.5) * h, params.ramp_time)
        data.ctrl[:] = lam * tau
        data.xfrc_applied[obj_id] = lam * xfrc
        mujoco.mj_step(model, data)
        if step % sample_every and step != n_steps:
            continue
        n_samples += 1
        t = step * h
        loaded = tracker.sample(data, t, h * sample_every)
        unloaded_run = 0 if loaded else unloaded_run + 1
        dr_now = _object_dr(scene, model, data, p0, R0)
        times.append(t)
        traj.append(dr_now)
        if not np.all(np.isfinite(dr_now)):
            dropped, reason = True, "the simulation diverged"
            break
        moved = float(np.linalg.norm(dr_now[:dim])) + s * float(np.linalg.norm(dr_now[dim:]))
        if moved > params.drop_rel * s:
            dropped, reason = True, f"the object moved {moved:.3g} > {params.drop_rel * s:.3g}"
            break
        if stop_distance is not None and float(np.linalg.norm(dr_now)) > stop_distance:
            stopped = True
            break
    if not dropped and n_samples and unloaded_run >= max(1, n_samples // 10):
        dropped, reason = True, "the object lost all contacts"
    mujoco.mj_forward(model, data)  # contacts at the final state
    final_gap = tracker.final_gaps(data)

    L = len(scene.contacts)
    win = tracker.window(params.ramp_time)  # (n,)
    nf = max(int(win.sum()), 1)
    normal = np.array(tracker.normal).reshape(-1, L)[win]  # (nf, L)
    mean_normal = normal.sum(axis=0) / nf  # (L,)
    mean_force = np.array(tracker.force).reshape(-1, L, 3)[win].sum(axis=0)[:, :dim] / nf  # (L, d)
    max_normal = normal.max(axis=0, initial=0.0)  # (L,)
    loaded_fraction = (normal > 0).sum(axis=0) / nf  # (L,)
    slip = np.array(tracker.slip).reshape(-1, L)[win].sum(axis=0)  # (L,)
    travel = np.array(tracker.travel).reshape(-1, L)[win].sum(axis=0)  # (L,)
    extra: dict[str, float] = {}
    for k in np.flatnonzero(win):
        for name, fn in tracker.extra[k].items():
            extra[name] = extra.get(name, 0.0) + fn / nf
    f_ref = max(float(np.max(mean_normal)) if L else 0.0, float(np.linalg.norm(w_ex[:dim])))
    pens = np.asarray(tracker.penetration)[win]
    p_typical = float(np.median(pens)) if len(pens) else 0.0
    outcomes = []
    for i in range(L):
        if final_gap[i] > params.gap_tol_rel * s or mean_normal[i] <= params.force_tol_rel * f_ref:
            observed = "separate"
        elif slip[i] > max(
            params.slip_tol_rel * travel[i],
            params.slip_abs_rel * s,
            params.slip_pen_factor * p_typical,
        ):
            observed = "slide"
        else:
            observed = "stick"
        expected = comb[i] if comb is not None else None
        outcomes.append(
            ContactOutcome(
                index=i,
                body=scene.contacts[i].body,
                observed=observed,
                mean_normal_force=float(mean_normal[i]),
                mean_force=mean_force[i],
                max_normal_force=float(max_normal[i]),
                loaded_fraction=float(loaded_fraction[i]),
                slip=float(slip[i]),
                travel=float(travel[i]),
                final_gap=float(final_gap[i]),
                expected=expected,
                agrees=None if expected is None else observed in EXPECTED_STATE[expected],
            )
        )
    dr = traj[-1]
    nrm = float(np.linalg.norm(dr))
    return SimulationResult(
        dim=dim,
        duration=float(times[-1]),
        dr=dr,
        direction=dr / nrm if nrm > 0 else np.zeros(D),
        q0=q0,
        q=np.array(data.qpos[qadr]),
        tau=tau,
        dropped=dropped,
        drop_reason=reason,
        contacts=tuple(outcomes),
        extra_contacts=tuple(sorted(extra.items())),
        times=np.array(times),
        trajectory=np.array(traj),
        combination=comb,
        stopped_early=stopped,
        object_size=s,
        damping=damping(scene, tau, params),
        params=params,
    )


# --------------------------------------------------------------------------------------------
# Report


def format_report(result: SimulationResult, direction: Array | None = None) -> str:
    """A readable summary (the ``ctp simulate`` output); with ``direction`` ``(D,)`` (e.g. the
    DAFC direction the torques were chosen for) also the cosine between it and ``dr``."""
    names = ["dx", "dy", "dtheta"] if result.dim == 2 else ["dx", "dy", "dz", "wx", "wy", "wz"]
    lines = [
        f"simulated {result.duration:.4g} s"
        + (" (stopped early: moved the requested distance)" if result.stopped_early else ""),
        "object dr   " + "  ".join(f"{n}={v:+.4g}" for n, v in zip(names, result.dr, strict=True)),
        "direction   " + "  ".join(f"{v:+.4f}" for v in result.direction),
    ]
    if direction is not None:
        lines.append(f"cosine      {result.cosine(direction):+.4f} to the requested direction")
    lines += [
        f"|dr| rate   {result.speed():.4g} per s",
        "dropped     " + (f"YES ({result.drop_reason})" if result.dropped else "no"),
        "joints dq   " + "  ".join(f"{v:+.4g}" for v in result.dq),
        "",
    ]
    has_comb = result.combination is not None
    w = max([4, *(len(c.body) for c in result.contacts)])
    header = f"{'#':>2}  {'body':<{w}}"
    if has_comb:
        header += f" {'exp':>3}"
    header += (
        f" {'observed':<9} {'mean n':>9} {'max n':>9} {'loaded':>6} {'slip':>10} {'travel':>10} {'gap':>10}"
        "  mean force (world)      "
    )
    if has_comb:
        header += "  ok"
    lines.append(header)
    lines.append("-" * len(header))
    for c in result.contacts:
        row = f"{c.index:>2}  {c.body:<{w}}"
        if has_comb:
            row += f" {c.expected or '':>3}"
        force = "(" + ", ".join(f"{v:+.3g}" for v in c.mean_force) + ")"
        row += (
            f" {c.observed:<9} {c.mean_normal_force:>9.4g} {c.max_normal_force:>9.4g} "
            f"{c.loaded_fraction:>6.0%} {c.slip:>10.3g} {c.travel:>10.3g} {c.final_gap:>10.3g}  {force:<24}"
        )
        if has_comb:
            row += "  " + ("yes" if c.agrees else "NO")
        lines.append(row)
    if result.extra_contacts:
        lines.append("")
        lines.append(
            "other bodies touching the object: "
            + ", ".join(f"{n} (mean normal force {f:.3g})" for n, f in result.extra_contacts)
        )
    if has_comb:
        lines.append("")
        lines.append(
            f"combination {result.combination}: " + ("all contacts agree" if result.agrees else "contacts DISAGREE")
        )
    return "\n".join(lines)


__all__ = [
    "DEFAULT_PARAMS",
    "ContactOutcome",
    "Damping",
    "SimulationParams",
    "SimulationResult",
    "build_mjcf",
    "build_model",
    "damping",
    "finger_dof_addresses",
    "finger_qpos_addresses",
    "fixed_geom_name",
    "force_scale",
    "format_report",
    "joint_name",
    "link_body_name",
    "link_site_names",
    "reset_to_scene",
    "simulate_torques",
]
