"""The MuJoCo model of a scene: simulation parameters, damping, names, MJCF and addresses.

:func:`build_mjcf` writes the scene (hand, fixed bodies, object, contact pairs, motors) as MJCF
text and :func:`build_model` compiles it; the quasi-static replays (:mod:`sim.torque_replay`,
:mod:`sim.plan_replay`) run on this model. Object coordinates are the paper's ``r`` (eq. 30-32):
2-D ``(x, y, theta)``, 3-D ``(p, R)``; :func:`object_pose` reads them back as an
:class:`analysis.pose.Pose`.

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
  the scene's ``q`` (``tests/sim/test_mjcf.py`` checks the link end points for random
  ``q``). Each body is a capsule along its
  :meth:`~analysis.kinematics.HandKinematics.body_segment` (a sphere if the segment has zero
  length), named ``"<finger>/<k>"``, with sites ``"<finger>/<k>:a"``, ``"<finger>/<k>:b"`` at
  the segment's end points; joints and motors are ``"<finger>:q<j>"``.
* **Fixed bodies** are static world geoms: segment -> capsule, box -> box, disk/sphere -> sphere
  (centred at the world origin, as in :mod:`analysis.geometry`), polygon -> convex prism.
* **Collision radius ``eps``** (``eps_rel`` times the object size, default 1 %). Scene links may
  have radius 0 and segments are lines, which MuJoCo cannot collide. Every capsule link and
  fixed body is therefore the scene shape *grown* by ``eps`` (capsule radius ``radius + eps``,
  box half-sizes ``+ eps``, sphere radius ``+ eps``, polygons offset outwards by ``eps``), and the
  object is the scene shape *shrunk* by ``eps`` (sphere/disk radius ``- eps``, box half-sizes
  ``- eps``, polygon offset inwards, cylinder radius and half-height ``- eps``). Growing one body
  and shrinking the other by the same amount leaves the distance between them unchanged
  (exactly for disks, spheres, capsules and the faces of boxes and polygons; corners of boxes
  and polygons are rounded or sharpened by at most ``eps``), so every scene contact is exactly
  touching in MuJoCo at the scene configuration. MuJoCo's contact point then lies at
  ``p + eps n`` (``p`` the scene point, ``n`` its normal), which is all the difference.
  A URDF collision shape keeps its own size and its pair with the object has ``margin = eps``:
  MuJoCo's contact constraint acts on ``dist - margin`` (the solver's violation ``efc_pos -
  efc_margin``), so the shape behaves as its exact dilation by the ball of radius ``eps`` (the
  Minkowski sum, edges and corners of a box rounded by ``eps``, not grown square), and every
  scene contact on it touches at the scene configuration: MuJoCo's ``dist`` is ``eps`` there,
  its contact point halfway between the shape's surface and the shrunk object's, ``p + eps n /
  2``. (Growing a box by ``eps`` would push its edges ``(sqrt(2) - 1) eps`` and its corners
  ``(sqrt(3) - 1) eps`` into an object they touch.)
* **Collisions** are explicit ``<pair>`` elements only: every link geom and every fixed body
  against the object, with the scene contact's ``mu`` (``default_mu`` for bodies without a scene
  contact; the mean if a body has several scene contacts; every geom of a link the link's).
  Links do not collide with each other nor with fixed bodies (the cross-check is local: small
  motions about the scene configuration). Friction cones are elliptic (the true Coulomb cone
  ``|t| <= mu n``, which the paper's 2-D cone is exactly and its 3-D ``k``-sided pyramid
  approximates from inside); ``condim`` 3 (1 for ``mu = 0``). Pairs push only at penetration
  (``margin = 0``; a URDF shape's: ``eps``, above) but also report geoms closer than
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
``b_q = 0.04 b_r s^2 / max(1, (s phi)^2)`` (``s`` the object size, the scale of the fingers' lever
arms; ``phi`` the joint speed per unit object speed of the fastest object motion the run
replays, eq. 31's ``phi = |dq|`` for a unit ``dr``), so that the power the fingers' damping
takes, ``b_q |dq/dt|^2``, is at most 4 % of the object's, ``b_r |dr/dt|^2``, at any scene scale
and however fast the fingers turn. The analysis' fingers are massless and undamped (``tau = J_c^T
f_c``, eq. 29): the damping's torque ``b_q dq/dt`` is balanced by contact forces the analysis does
not have, tangential ones at the tips of fast-turning joints. With ``b_q = 0.04 b_r s^2`` alone
the wrap's lift (examples/sphere_four_finger_wrap.json, ``s phi = 3.1``: the fingers' abduction
joints turn 4.2 rad per unit object motion about axes 0.12 m from their tips) put 28 % of the
power into the fingers, and its sticking contacts would have needed ``|t|/n = 1.12`` at f4/2 and
0.32 at the tips f1/3 and f3/3 where the analysis has 0 (the rigid damped model, constraint forces
from ``A^T lambda = [tau; w_ex] - B [dq; dr]``): f4/2 slid from the start in MuJoCo. Masses
scale with the damping, so contact stiffness scales with the forces and penetrations stay near
``1e-5 s``. MuJoCo's ``discrete`` integrator solves the contacts in the metric ``M + h D`` that
includes this damping (the constraint forces are computed against the same damped inertia that
performs the update; ``implicitfast`` gives the same directions to about 1e-3 at the default
parameters), and the contacts are stiff (``solref`` time constant 5 steps, ``solimp`` impedance
0.99-0.999, ``impratio`` 10 so that sticking friction creeps little).

"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np
from numpy.typing import NDArray

from analysis._types import Array
from analysis.exceptions import SceneError
from analysis.geometry import object_origin, object_rotation, object_size
from analysis.kinematics import FingerModel, HandKinematics
from analysis.mesh import primitive_of
from analysis.pose import Pose
from analysis.rotations import matrix_to_quat_wxyz, matrix_to_rotvec, rotz
from analysis.scene import Box, Cylinder, Disk, Polygon, Scene, Segment, Sphere

OBJECT_BODY = "object"
OBJECT_GEOM = "object"


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
    finger_damping_rel: float = 0.04  # b_q = finger_damping_rel * b_r * s^2 / max(1, (s phi)^2) per joint
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
    finger_damping: float  # b_q = finger_damping_rel * b_r * s^2 / max(1, (s phi)^2) per joint (torque per rad/s)
    finger_armature: float  # rotor inertia per joint, inertia_time * b_q0 / 2 (b_q0: the damping at phi <= 1/s)
    link_mass: float  # per link, at its joint: inertia_time * b_q0 / (2 s^2)
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


def damping(scene: Scene, tau: Array | None = None, params: SimulationParams = DEFAULT_PARAMS,
            phi: float | None = None) -> Damping:
    """The damping, masses and inertias of a run with these torques ``tau`` ``(M,)`` whose object
    motion turns the joints ``phi`` (rad per unit of ``|dr|``, eq. 31; ``None``: no object motion
    known) per unit object motion: ``b_q = finger_damping_rel b_r s^2 / max(1, (s phi)^2)`` (the
    module docstring); the fingers' masses and armature are those of the nominal damping
    ``finger_damping_rel b_r s^2`` whatever ``phi`` (so the continuous replay, which lowers the
    damping only while an object moves, keeps one set of masses)."""
    s = object_size(scene)
    F = force_scale(scene, tau)
    b_r = F / (params.speed_rel * s)
    b_q0 = params.finger_damping_rel * b_r * s * s
    b_q = b_q0 / joint_speed_factor(s, phi)
    link_mass = params.inertia_time * b_q0 / (2.0 * s * s)
    return Damping(
        force_scale=F,
        object_damping=b_r,
        object_mass=params.inertia_time * b_r,
        object_inertia=params.inertia_time * b_r,
        finger_damping=b_q,
        finger_armature=0.5 * params.inertia_time * b_q0,
        link_mass=link_mass,
        link_inertia=link_mass * (0.1 * s) ** 2,
    )


def joint_speed_factor(s: float, phi: float | None) -> float:
    """``max(1, (s phi)^2)``: by how much the finger damping is lowered for object motions that
    turn the joints ``phi`` (rad per unit object motion) with lever arms of the object size ``s``."""
    if phi is None or not np.isfinite(phi):
        return 1.0
    return max(1.0, (s * float(phi)) ** 2)


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
    #: the URDF collision shapes in this body's frame, ``(coal geometry, R (3, 3), t (3,))``
    #: (meshes as their convex hulls); None: the body is the capsule about its segment
    shapes: tuple[tuple[object, Array, Array], ...] | None = None


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
        local = getattr(finger, "collision_shapes", None)
        shapes = None if local is None else local(k)
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
                shapes=None if shapes is None else tuple(
                    (g, np.asarray(R, dtype=float), np.asarray(t, dtype=float)) for g, R, t in shapes),
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


def link_geom_name(finger: str, k: int, i: int = 0) -> str:
    """MuJoCo geom name of the ``i``-th collision shape of body ``k`` of a finger (the capsule
    of a capsule link, and the first URDF shape, are named as the body)."""
    base = link_body_name(finger, k)
    return base if i == 0 else f"{base}#{i}"


def _shape_geom(name: str, geom: object, R: Array, t: Array, assets: list[str]) -> str:
    """A URDF collision shape (coal geometry placed by ``R`` ``(3, 3)``, ``t`` ``(3,)`` in its
    body's frame) as a MuJoCo geom of the same size; a mesh as its convex hull's vertices."""
    place = f'pos="{_v(t)}" quat="{_v(matrix_to_quat_wxyz(R))}"'
    prim = primitive_of(geom)  # SceneError for a shape the detector does not take either
    if prim.kind != "hull":
        return f'<geom name="{name}" type="{prim.kind}" {place} size="{_v(prim.size)}"/>'
    assert prim.vertices is not None
    mesh = "mesh:" + name
    assets.append(f'<mesh name="{mesh}" vertex="{_v(prim.vertices)}"/>')
    return f'<geom name="{name}" type="mesh" mesh="{mesh}" {place}/>'


def _link_geoms(finger: str, k: int, lk: _LinkSpec, eps: float, assets: list[str]) -> list[tuple[str, str, float]]:
    """The geoms of one link: ``(MJCF, geom name, pair margin)``: its capsule grown by ``eps``
    (margin 0), or its URDF collision shapes at their own size (margin ``eps``)."""
    if lk.shapes is None:
        name = link_geom_name(finger, k)
        return [(_segment_geom(name, lk.seg_a, lk.seg_b, lk.radius + eps), name, 0.0)]
    out = []
    for i, (g, R, t) in enumerate(lk.shapes):
        name = link_geom_name(finger, k, i)
        out.append((_shape_geom(_xml_escape(name), g, R, t, assets), name, eps))
    return out


#: the largest sine of the angle between a cylinder object's axis and a capsule link's axis for their
#: line contact to be simulated at its ends (:func:`_line_contact_feet`)
LINE_PARALLEL_TOL = 1e-6


def _line_contact_feet(scene: Scene, hand: HandKinematics, lk: _LinkSpec, eps: float) -> list[Array] | None:
    """A capsule link lying along a cylinder object (axes parallel, :data:`LINE_PARALLEL_TOL`) with
    two or more scene contacts at distinct points (its line contact's ends, the cylinder rolling on
    it, :mod:`planner.link_roll`): the feet ``(3,)`` of those contacts on the link's axis (this
    body's frame). MuJoCo collides a capsule with a cylinder at one point (an end of the line, not
    along it), so such a link touches the object through spheres of its capsule's radius at the
    feet, each moved inwards along the line by that radius (off the rim's edge): the capsule's own
    surface in those cross-sections, which stay on the line contact while it rolls about the
    common axis. None for any other link."""
    if not isinstance(scene.object.shape, Cylinder) or lk.shapes is not None or not lk.radius > 0.0:
        return None
    ref = hand.resolve_body(lk.name)
    if ref is None:
        return None
    a, b = hand.body_segment(ref, hand.q0)
    axis = object_rotation(scene)[:, 2]
    if float(np.linalg.norm(np.cross(axis, b - a))) > LINE_PARALLEL_TOL * float(np.linalg.norm(b - a)):
        return None
    e = lk.seg_b - lk.seg_a
    feet: list[Array] = []
    for c in scene.contacts:
        if c.body != lk.name:
            continue
        x = hand.to_local(ref, np.asarray(c.point, dtype=float), hand.q0)  # (3,) this body's frame
        t = float(np.clip((x - lk.seg_a) @ e / float(e @ e), 0.0, 1.0))
        foot = lk.seg_a + t * e
        if all(np.linalg.norm(foot - f) > 1e-9 for f in feet):
            feet.append(foot)
    if len(feet) < 2:
        return None
    # the line's ends are the cylinder's rims: a sphere there would touch the rim's edge, whose normal
    # MuJoCo takes as it may; moved inwards along the line by the sphere's radius it touches the side
    mid = np.mean(feet, axis=0)
    inward = [mid - f for f in feet]
    shift = lk.radius + eps
    return [f + min(shift, 0.45 * float(np.linalg.norm(v))) * v / float(np.linalg.norm(v))
            for f, v in zip(feet, inward, strict=True)]


def _object_geom(scene: Scene, eps: float, s: float, assets: list[str]) -> str:
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


def geom_of_contact(hand: HandKinematics, body: str) -> str:
    """MuJoCo geom name of the body a scene contact names (``"<finger>/<k>"`` for links, also
    when the scene names a URDF link by its own name)."""
    ref = hand.resolve_body(body)
    if ref is None:  # validated by Scene
        raise SceneError(("contacts",), f"unknown body '{body}'")
    if ref.finger is None:
        return fixed_geom_name(ref.name)
    return link_body_name(hand.fingers[ref.finger].name, ref.link)


def _geom_mu(scene: Scene, hand: HandKinematics, body: str, default: float) -> float:
    """Friction of the pairs of a MuJoCo body (a link ``"<finger>/<k>"`` or a fixed body's geom
    name): the mean ``mu`` of the scene contacts on it, else ``default``."""
    mus = [c.mu for c in scene.contacts if geom_of_contact(hand, c.body) == body]
    return float(np.mean(mus)) if mus else float(default)


def build_mjcf(scene: Scene, params: SimulationParams = DEFAULT_PARAMS, tau: Array | None = None,
               phi: float | None = None) -> str:
    """MJCF (XML text) of the scene at its configuration; see the module docstring.

    ``tau`` ``(M,)``: the joint torques the model is for (they set the force scale, hence
    damping and masses; :func:`damping`); ``phi``: the joint speed per unit object speed of its
    fastest object motion (the fingers' damping, :func:`damping`). The keyframe ``"scene"`` holds the scene's
    configuration (object pose, finger ``q``); the model's reference configuration ``qpos0`` has
    the object at its scene pose and ``q = 0``.
    """
    hand = HandKinematics.from_scene(scene)
    s = object_size(scene)
    der = damping(scene, tau, params, phi)
    eps = params.eps_rel * s
    dim = scene.dim
    assets: list[str] = []
    body_geoms: list[tuple[str, str, float]] = []  # (MuJoCo body or fixed geom, geom name, pair margin)

    world: list[str] = []
    for i, fb in enumerate(scene.fixed_bodies):
        world.append(_fixed_geom(scene, i, eps, s, assets))
        body_geoms.append((fixed_geom_name(fb.name), fixed_geom_name(fb.name), 0.0))

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
            geoms = _link_geoms(fm.name, k, lk, eps, assets)
            feet = _line_contact_feet(scene, hand, lk, eps)
            unpaired: set[str] = set()
            if feet is not None:  # the capsule (no pair) and a sphere at each end of the line contact
                unpaired.add(geoms[0][1])
                size = _f(lk.radius + eps)
                for i, f in enumerate(feet):
                    n = f"{geoms[0][1]}:line{i}"
                    geoms.append((f'<geom name="{_xml_escape(n)}" type="sphere" pos="{_v(f)}" size="{size}"/>', n, 0.0))
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
                + "".join(g for g, _, _ in geoms)
                + f'<site name="{a_name}" pos="{_v(lk.seg_a)}"/><site name="{b_name}" pos="{_v(lk.seg_b)}"/>'
                + xml
                + "</body>"
            )
            body_geoms += [(lk.name, name, margin) for _, name, margin in geoms if name not in unpaired]
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
    for body, geom, margin in body_geoms:
        mu = max(_geom_mu(scene, hand, body, params.default_mu), 0.0)
        condim = 3 if mu > 0 else 1
        pairs.append(
            f'<pair geom1="{_xml_escape(geom)}" geom2="{OBJECT_GEOM}" condim="{condim}" '
            f'friction="{_f(max(mu, 1e-5))} {_f(max(mu, 1e-5))} 0 0 0" '
            f'solref="{_f(tc)} {_f(dr)}" solimp="{_v(solimp)}" margin="{_f(margin)}" gap="{_f(detect)}"/>'
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


def build_model(scene: Scene, params: SimulationParams = DEFAULT_PARAMS, tau: Array | None = None,
                phi: float | None = None) -> mujoco.MjModel:
    """Compile :func:`build_mjcf`."""
    return mujoco.MjModel.from_xml_string(build_mjcf(scene, params, tau, phi))


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


def object_qpos_address(model: mujoco.MjModel, dim: int) -> int:
    """First ``qpos`` index of the object's joints: 2-D the slides ``x``, ``y`` and the hinge
    ``theta`` (3 values), 3-D the free joint (position and quaternion, 7 values)."""
    return int(model.jnt_qposadr[model.joint("object:x" if dim == 2 else "object:free").id])


def object_pose(model: mujoco.MjModel, data: mujoco.MjData, dim: int) -> Pose:
    """The object's pose now, read from ``qpos`` (``xpos`` and ``xmat`` lag one step behind after
    ``mj_step``): 2-D the slides' offsets from the body origin ``p_o`` and the hinge angle, 3-D the
    free joint's position and (normalised) quaternion."""
    adr = object_qpos_address(model, dim)
    q = data.qpos
    if dim == 2:
        x, y, th = q[adr : adr + 3]
        p_o = model.body_pos[model.body(OBJECT_BODY).id]  # (3,) the slides' origin
        return Pose(np.array([p_o[0] + x, p_o[1] + y]), rotz(float(th)), 2)
    quat = np.array(q[adr + 3 : adr + 7])
    R = np.zeros(9)
    mujoco.mju_quat2Mat(R, quat / np.linalg.norm(quat))
    return Pose(np.array(q[adr : adr + 3]), R.reshape(3, 3), 3)


def external_xfrc(scene: Scene) -> Array:
    """The scene's external wrench ``w_ex`` as the object body's ``xfrc_applied`` ``(6,)`` (force,
    torque at its centre of mass ``p_o``, world frame): 2-D ``(fx, fy, m)`` -> ``(fx, fy, 0, 0, 0, m)``."""
    w = np.asarray(scene.external_wrench, dtype=float)  # (D,)
    xfrc = np.zeros(6)
    if scene.dim == 2:
        xfrc[:2], xfrc[5] = w[:2], w[2]
    else:
        xfrc[:] = w
    return xfrc


__all__ = [
    "DEFAULT_PARAMS",
    "OBJECT_BODY",
    "OBJECT_GEOM",
    "Damping",
    "SimulationParams",
    "build_mjcf",
    "build_model",
    "damping",
    "external_xfrc",
    "finger_dof_addresses",
    "finger_qpos_addresses",
    "fixed_geom_name",
    "force_scale",
    "geom_of_contact",
    "joint_name",
    "joint_speed_factor",
    "link_body_name",
    "link_geom_name",
    "link_site_names",
    "object_pose",
    "object_qpos_address",
    "reset_to_scene",
]
