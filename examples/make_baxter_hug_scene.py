"""Generate ``examples/baxter_hug_box.json`` and ``examples/baxter_hug_box_chains.json``: Baxter
(example-robot-data) hugging a box that stands on a table.

Run from the repository root: ``.venv/bin/python examples/make_baxter_hug_scene.py``
(``--check`` compares with the committed files instead of writing them).

Each arm is a URDF chain from ``torso`` to ``<side>_wrist`` (7 revolute joints s0 s1 e0 e1 w0 w1
w2), every link a capsule of radius ``LINK_RADIUS`` about the segment from its frame origin to
the next link's origin (see :mod:`analysis.urdf`). The torso stands at ``TORSO`` (world, no
rotation). The box (``BOX_SIZE`` = 0.30 x 0.40 x 0.40 m, x = depth away from the robot, y =
width, z = height; ``MASS`` kg) stands on a table in front of the robot, centred on the robot's
sagittal plane ``y = 0``; its side faces are the planes ``y = +-0.20``.

Each arm lies with its elbow link (``<side>_lower_elbow``, joint e1 to w0) and its forearm link
(``<side>_upper_forearm``, w0 to w1) flat on one side face: both link axes in the plane
``|y| = 0.20 + LINK_RADIUS`` (three conditions: e1, w0 and w1 in that plane). The contact point
of a link is the foot on the face of its axis' midpoint, the normal the face's inward normal,
mu 0.5. The upper arm (``<side>_upper_elbow``) comes down from the shoulder behind the box's back
face and the wrist bends away from the box, so no other link touches it (at least ``CLEARANCE``
between every other capsule and the box or the table). Two table contacts on the box's bottom
face, ``(x_c, +-TABLE_Y, z_bottom)`` with normal ``+z``, mu 0.4: six contacts, 3^6 = 729
combinations, in the order left elbow, left forearm, right elbow, right forearm, table (+y),
table (-y).

How the configuration is found: a bounded least-squares solve (scipy) over the right arm's seven
angles and the box's position (its back face x and its top z): the three plane conditions, hinge
penalties for the contact points to stay ``FACE_MARGIN`` inside their faces, for every other link
to keep ``CLEARANCE`` from the box and the table and to stay ``|y| >= 0.07`` (away from the other
arm), and weak pulls toward a nominal hug posture; then Gauss-Newton with minimum-norm steps on
the three conditions alone (to 1e-14), and the inequalities are checked again. The left arm is
the right arm's mirror image through the sagittal plane: Baxter's URDF is mirror-symmetric with
``q_left = MIRROR_SIGNS * q_right`` (checked here to 1e-9 on the link segments). Angles are
rounded to 12 digits before the contact points are computed from them, so the points lie on the
capsules of the written configuration.

``baxter_hug_box_chains.json`` is the same scene with each arm written as a plain spatial chain
(``joints`` of ``axis`` and ``origin``): at ``q = 0`` every joint frame of the chain is aligned
with the torso, so a joint's axis is its URDF axis in the torso frame at the neutral
configuration and its origin is the offset from the previous joint (product-of-exponentials
form); the tip is the end of the wrist link's segment. The contact points and normals are the
same numbers; link ``<side>_lower_elbow`` is chain body ``<side>/3`` and ``<side>_upper_forearm``
is ``<side>/4``.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pinocchio as pin
from numpy.typing import NDArray
from scipy.optimize import least_squares

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from analysis.loader import load_scene, scene_from_dict  # noqa: E402
from analysis.torque_limits import hand_torque_limits  # noqa: E402
from analysis.urdf import UrdfFinger, load_urdf_model, resolve_urdf_path  # noqa: E402

Array = NDArray[np.float64]

URDF = "example-robot-data:baxter_description/urdf/baxter.urdf"
OUT = ROOT / "examples" / "baxter_hug_box.json"
OUT_CHAINS = ROOT / "examples" / "baxter_hug_box_chains.json"

LINK_RADIUS = 0.06
BOX_SIZE = np.array([0.30, 0.40, 0.40])
MASS = 2.0  # kg
G = 9.81
MU_ARM, MU_TABLE = 0.5, 0.4
TORSO = np.array([0.0, 0.0, 0.93])  # world position of the torso frame (no rotation)
TABLE_Y = 0.12  # the table contacts at y = +-TABLE_Y under the box's centre
TABLE_SIZE = np.array([0.9, 1.6, 0.04])
FACE_MARGIN = 0.02  # contact points at least this far inside their faces
CLEARANCE = 0.002  # every other capsule at least this far from the box and the table
#: q_left = MIRROR_SIGNS * q_right: Baxter's arms are mirror images through the plane y = 0
MIRROR_SIGNS = np.array([-1.0, 1.0, -1.0, 1.0, -1.0, 1.0, -1.0])
#: Nominal right-arm posture (initial guess and weak regulariser): the arm in the vertical plane
#: through the shoulder (s0 = pi/4 undoes the mount's yaw, e0 = w0 = 0), the upper arm down
#: forward, the elbow bent down; and the box's nominal back-face x and top z (torso frame).
Q_NOMINAL = np.array([0.8, 0.3, 0.0, 0.6, 0.0, 0.0, 0.0])
BOX_NOMINAL = np.array([0.40, 0.20])
#: Contact links of one arm and their chain body indices (joint that moves them last).
#: The contact point of a link is the foot on the face of the point at this fraction of its axis
#: (the elbow link's contact is near its w0 end, so that e1 and the upper arm stay off the face).
CONTACT_LINKS = (("lower_elbow", 3, 0.8), ("upper_forearm", 4, 0.5))


def arm(side: str, q: Array | None = None) -> UrdfFinger:
    """One arm (torso -> wrist) in the TORSO frame: the scene's base is applied at write time."""
    q = np.zeros(7) if q is None else q
    return UrdfFinger(side, resolve_urdf_path(URDF), "torso", f"{side}_wrist", q, link_radius=LINK_RADIUS)


def link_index(f: UrdfFinger, side: str, name: str) -> int:
    k = f.body_index(f"{side}_{name}")
    assert k is not None, name
    return k


def box_bounds(x: Array) -> tuple[Array, Array]:
    """Box corners ``lo, hi`` (torso frame) from the solver's back-face x and top z."""
    x_back, z_top = float(x[7]), float(x[8])
    lo = np.array([x_back, -BOX_SIZE[1] / 2, z_top - BOX_SIZE[2]])
    return lo, lo + BOX_SIZE


def box_sdf(P: Array, lo: Array, hi: Array) -> Array:
    """Signed distances ``(m,)`` of points ``(m, 3)`` to the box ``[lo, hi]`` (negative inside)."""
    c, h = (lo + hi) / 2, (hi - lo) / 2
    d = np.abs(P - c) - h
    return np.asarray(np.linalg.norm(np.maximum(d, 0.0), axis=1) + np.minimum(d.max(axis=1), 0.0))


def table_bounds(lo: Array, hi: Array) -> tuple[Array, Array]:
    """The table (a box whose top face is the box's bottom plane), torso frame."""
    c = np.array([(lo[0] + hi[0]) / 2 + 0.1, 0.0, lo[2] - TABLE_SIZE[2] / 2])
    return c - TABLE_SIZE / 2, c + TABLE_SIZE / 2


_T = np.linspace(0.0, 1.0, 401)[:, None]


def gaps(f: UrdfFinger, q: Array, lo: Array, hi: Array) -> dict[str, tuple[float, float]]:
    """Per link: (capsule-box gap, capsule-table gap), sampled along the link's axis."""
    tlo, thi = table_bounds(lo, hi)
    out = {}
    for k, link in enumerate(f.links):
        a, b = f.body_segment(k, q)
        P = a + _T * (b - a)
        out[link] = (float(box_sdf(P, lo, hi).min()) - LINK_RADIUS, float(box_sdf(P, tlo, thi).min()) - LINK_RADIUS)
    return out


def plane_conditions(f: UrdfFinger, q: Array) -> Array:
    """e1, w0 and w1 (the ends of the two contact links) in the plane y = -(0.20 + r)."""
    y = -(BOX_SIZE[1] / 2 + LINK_RADIUS)
    k_elbow = link_index(f, "right", "lower_elbow")
    a, b = f.body_segment(k_elbow, q)
    _, c = f.body_segment(k_elbow + 1, q)
    return np.array([a[1] - y, b[1] - y, c[1] - y])


def contact_feet(f: UrdfFinger, side: str, q: Array) -> list[Array]:
    """Feet on the side face of the contact points of the two contact links (torso frame)."""
    sign = -1.0 if side == "right" else 1.0
    out = []
    for name, _, t in CONTACT_LINKS:
        a, b = f.body_segment(link_index(f, side, name), q)
        m = a + t * (b - a)
        out.append(np.array([m[0], sign * BOX_SIZE[1] / 2, m[2]]))
    return out


def residuals(x: Array, f: UrdfFinger, regularise: bool) -> Array:
    q = x[:7]
    lo, hi = box_bounds(x)
    res = list(10.0 * plane_conditions(f, q))
    if not regularise:
        return np.asarray(res)
    hinge = lambda v: max(0.0, v)  # noqa: E731
    for p in contact_feet(f, "right", q):
        for ax in (0, 2):
            res += [5.0 * hinge(lo[ax] + 2 * FACE_MARGIN - p[ax]), 5.0 * hinge(p[ax] - hi[ax] + 2 * FACE_MARGIN)]
    contact = {f"right_{n}" for n, _, _ in CONTACT_LINKS}
    for k, (link, (g_box, g_table)) in enumerate(gaps(f, q, lo, hi).items()):
        if link not in contact:
            res.append(5.0 * hinge(3 * CLEARANCE - g_box))
        res.append(5.0 * hinge(3 * CLEARANCE - g_table))
        a, b = f.body_segment(k, q)
        res += [5.0 * hinge(a[1] + 0.075), 5.0 * hinge(b[1] + 0.075)]  # away from the other arm
    res += list(0.02 * (q - Q_NOMINAL))
    res += list(0.02 * (x[7:] - BOX_NOMINAL))
    return np.asarray(res)


def solve(f: UrdfFinger) -> Array:
    margin = 0.05
    lo = np.concatenate([f.lower + margin, [0.3, -0.4]])
    hi = np.concatenate([f.upper - margin, [0.8, 0.5]])
    x0 = np.clip(np.concatenate([Q_NOMINAL, BOX_NOMINAL]), lo, hi)
    sol = least_squares(residuals, x0, bounds=(lo, hi), args=(f, True), xtol=1e-14, ftol=1e-14, gtol=1e-14,
                        max_nfev=4000)
    x = np.asarray(sol.x)
    # Gauss-Newton with minimum-norm steps on the three plane conditions alone
    for _ in range(30):
        r = residuals(x, f, False)
        if np.max(np.abs(r)) < 1e-14:
            break
        h = 1e-7
        J = np.array([(residuals(x + h * e, f, False) - r) / h for e in np.eye(len(x))]).T
        x = x - np.linalg.lstsq(J, r, rcond=None)[0]
    x[:7] = np.round(x[:7], 12)
    x[7:] = np.round(x[7:], 12)
    if np.any(x < lo - 1e-9) or np.any(x > hi + 1e-9):
        raise RuntimeError("the solution left the joint limits")
    return x


def check_configuration(f: UrdfFinger, x: Array) -> dict[str, tuple[float, float]]:
    """Raise unless the solution meets every condition; return the gaps of the right arm."""
    q = x[:7]
    lo, hi = box_bounds(x)
    r = plane_conditions(f, q)
    if np.max(np.abs(r)) > 1e-11:
        raise RuntimeError(f"plane conditions not met: {r}")
    for p in contact_feet(f, "right", q):
        inside = min(p[0] - lo[0], hi[0] - p[0], p[2] - lo[2], hi[2] - p[2])
        if inside < FACE_MARGIN:
            raise RuntimeError(f"a contact point is only {inside:.4f} inside its face")
    contact = {f"right_{n}" for n, _, _ in CONTACT_LINKS}
    g = gaps(f, q, lo, hi)
    for link, (g_box, g_table) in g.items():
        if g_table < CLEARANCE or (link not in contact and g_box < CLEARANCE):
            raise RuntimeError(f"{link} is too close to the box or the table: {g_box:.4g}, {g_table:.4g}")
        if link in contact and g_box < -1e-12:
            raise RuntimeError(f"{link} penetrates the box by {-g_box:.3g}")
    # the left arm with the mirrored angles is the right arm reflected through y = 0
    left, M = arm("left"), np.diag([1.0, -1.0, 1.0])
    for k in range(len(f.links)):
        a, b = f.body_segment(k, q)
        a2, b2 = left.body_segment(k, MIRROR_SIGNS * q)
        if max(np.abs(M @ a - a2).max(), np.abs(M @ b - b2).max()) > 1e-9:
            raise RuntimeError("the left arm is not the mirror image of the right arm")
    return g


def _r(v: Any) -> list[float]:
    """Full double precision (json writes the shortest exact representation)."""
    return [float(c) for c in np.asarray(v, dtype=float).reshape(-1)]


def build_scenes(verbose: bool = False) -> tuple[dict[str, Any], dict[str, Any]]:
    right = arm("right")
    x = solve(right)
    g = check_configuration(right, x)
    q = {"right": x[:7] + 0.0, "left": MIRROR_SIGNS * x[:7] + 0.0}  # + 0.0: no -0.0 in the file
    lo, hi = box_bounds(x)
    centre = (lo + hi) / 2
    tlo, thi = table_bounds(lo, hi)
    if verbose:
        print("q_right:", np.round(q["right"], 6).tolist())
        print("box (torso frame):", np.round(lo, 4).tolist(), np.round(hi, 4).tolist())
        print("right-arm gaps (box, table):", {k: (round(a, 4), round(b, 4)) for k, (a, b) in g.items()})
    contacts: list[dict[str, Any]] = []
    for side in ("left", "right"):
        f = arm(side, q[side])
        sign = 1.0 if side == "left" else -1.0
        feet = contact_feet(f, side, q[side])
        for (name, _, _), p in zip(CONTACT_LINKS, feet, strict=True):
            contacts.append({"body": f"{side}/{side}_{name}", "point": _r(p + TORSO),
                             "normal": [0.0, -sign, 0.0], "mu": MU_ARM})
    for y in (TABLE_Y, -TABLE_Y):
        contacts.append({"body": "table", "point": _r(np.array([centre[0], y, lo[2]]) + TORSO),
                         "normal": [0.0, 0.0, 1.0], "mu": MU_TABLE})
    weight = MASS * G
    scene: dict[str, Any] = {
        "name": "baxter-hug-box",
        "description": (
            f"Baxter (example-robot-data URDF, each arm torso -> wrist, link capsules of radius {LINK_RADIUS}) "
            f"hugs a {BOX_SIZE[0]:.2f} x {BOX_SIZE[1]:.2f} x {BOX_SIZE[2]:.2f} m, {MASS:g} kg box standing on a "
            "table: elbow (lower_elbow) and forearm (upper_forearm) links flat on the box's side faces "
            f"(mu {MU_ARM}), two table contacts (mu {MU_TABLE}). Generated by examples/make_baxter_hug_scene.py."
        ),
        "dim": 3,
        "object": {"pose": {"position": _r(centre + TORSO), "quat_wxyz": [1.0, 0.0, 0.0, 0.0]},
                   "shape": {"type": "box", "size": _r(BOX_SIZE)}},
        "external_wrench": [0.0, 0.0, -weight, 0.0, 0.0, 0.0],
        "fixed_bodies": [{"name": "table", "shape": {"type": "box", "size": _r(TABLE_SIZE),
                                                     "position": _r((tlo + thi) / 2 + TORSO)}}],
        "fingers": [
            {"name": side, "base": {"position": _r(TORSO), "quat_wxyz": [1.0, 0.0, 0.0, 0.0]},
             "urdf": {"file": URDF, "root_link": "torso", "tip_link": f"{side}_wrist"},
             "q": _r(q[side]), "link_radius": LINK_RADIUS}
            for side in ("left", "right")
        ],
        "contacts": contacts,
    }
    return scene, chains_scene(scene)


def _joint_axis(joint: Any) -> Array:
    """The axis ``(3,)`` of a revolute pinocchio joint in its own frame."""
    kind = joint.shortname()
    if "Unaligned" in kind:
        return np.asarray(joint.extract().axis, dtype=float)
    return np.eye(3)["XYZ".index(kind[-1])]


def urdf_finger_as_chain(fd: dict[str, Any]) -> tuple[dict[str, Any], dict[str, str]]:
    """A URDF finger of a scene (a dict) as an axis/origin chain with the same base and ``q``, and
    the map from its URDF body names (``"<finger>/<link>"``) to chain body names
    (``"<finger>/<k>"``, ``k`` = the last chain joint that moves the link).

    At ``q = 0`` every frame of the chain is aligned with the root link: a joint's ``axis`` is its
    URDF axis in the root frame at the neutral configuration, its ``origin`` the offset from the
    previous joint (the first: from the root link's origin), and the ``tip`` is the end of the
    last link's segment. A link that no chain joint moves has no chain body (not in the map).
    """
    path = resolve_urdf_path(fd["urdf"]["file"])
    root, tip_link = fd["urdf"]["root_link"], fd["urdf"]["tip_link"]
    radius = float(fd.get("link_radius", 0.0))
    f = UrdfFinger(fd["name"], path, root, tip_link, np.asarray(fd["q"], dtype=float), link_radius=radius)
    model = load_urdf_model(path)
    data = model.createData()
    pin.forwardKinematics(model, data, pin.neutral(model))
    pin.updateFramePlacements(model, data)
    T_root = data.oMf[model.getFrameId(root, pin.FrameType.BODY)]
    joints, prev = [], np.zeros(3)
    for name in f.joint_names:
        jid = model.getJointId(name)
        rel = T_root.actInv(data.oMi[jid])  # the joint frame in the root frame
        axis = rel.rotation @ _joint_axis(model.joints[jid])
        pos = np.asarray(rel.translation, dtype=float)
        joints.append({"axis": _r(axis), "origin": _r(pos - prev), "radius": radius})
        prev = pos
    f0 = UrdfFinger(fd["name"], path, root, tip_link, np.zeros(f.n_joints), link_radius=radius)
    _, tip_end = f0.body_segment(len(f0.links) - 1, np.zeros(f.n_joints))  # root frame (identity base)
    chain = {"name": fd["name"], "base": fd["base"], "joints": joints, "tip": _r(tip_end - prev), "q": fd["q"]}
    bodies = {f"{fd['name']}/{link}": f"{fd['name']}/{f.joints_moving(k)[-1]}"
              for k, link in enumerate(f.links) if f.joints_moving(k)}
    return chain, bodies


def chains_scene(scene: dict[str, Any]) -> dict[str, Any]:
    """The same scene with every URDF finger written as an axis/origin chain."""
    out = json.loads(json.dumps(scene))
    out["name"] = f"{scene['name']}-chains"
    out["description"] = scene["description"].replace(
        "Generated by", "Each arm written as axis/origin joints computed from the URDF at q = 0. Generated by")
    bodies: dict[str, str] = {}
    for i, fd in enumerate(scene["fingers"]):
        if "urdf" in fd:
            out["fingers"][i], names = urdf_finger_as_chain(fd)
            bodies.update(names)
    for c in out["contacts"]:
        c["body"] = bodies.get(c["body"], c["body"])
    if "joint_torque_limits" not in scene:  # the URDF's effort limits, which a chain does not carry
        limits = hand_torque_limits(scene_from_dict(scene))
        if limits is not None and np.all(np.isfinite(limits)):
            out["joint_torque_limits"] = [float(x) for x in limits]
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    parser.add_argument("--check", action="store_true", help="compare with the committed scenes")
    parser.add_argument("--verbose", action="store_true", help="print the posture and the gaps")
    args = parser.parse_args()
    scenes = build_scenes(args.verbose)
    texts = [json.dumps(s, indent=2) + "\n" for s in scenes]
    if args.check:
        same = all(p.read_text() == t for p, t in zip((OUT, OUT_CHAINS), texts, strict=True))
        print(f"{OUT.relative_to(ROOT)} and {OUT_CHAINS.name} are {'up to date' if same else 'OUT OF DATE'}")
        sys.exit(0 if same else 1)
    for p, t in zip((OUT, OUT_CHAINS), texts, strict=True):
        p.write_text(t)
        load_scene(p)  # validates: contact points on the link capsules and the box, normals inward
    print(f"wrote {OUT.relative_to(ROOT)} and {OUT_CHAINS.relative_to(ROOT)}")


if __name__ == "__main__":
    main()
