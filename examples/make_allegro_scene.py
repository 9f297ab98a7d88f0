"""Generate ``examples/allegro_right_box.json``: the Allegro right hand holding a bar (a box).

Run from the repository root: ``.venv/bin/python examples/make_allegro_scene.py``
(``--check`` compares with the committed file instead of writing it).

The grasp is built in the palm frame, the frame of the URDF's ``palm_link``: the fingers point
along +z and flex toward +x, the palm's inner face is the plane ``x = 0.0111`` (its collision
box has centre x = -0.0093 and width 0.0408), the thumb is on the +y side. A bar (a box whose
faces are parallel to the palm frame's planes) lies against the palm, below the finger roots,
and the hand wraps it in a power grasp:

* back face (-x) on the palm, a fixed body (contact ``palm``),
* top face (+z): the proximal links of index and ring (``link_1.0``, ``link_9.0``) lie flat
  on it, pressing toward -z,
* front face (+x): the middle links of index and middle (``link_2.0``, ``link_6.0``) lie flat
  on it, pressing the bar into the palm,
* bottom face (-z): the thumb's fingertip sphere (``link_15.0_tip``) pushes toward +z, opposing
  the fingers on the top face.

The hand is then placed palm up (its base turns palm +x to world +z), so gravity (world -z)
presses the bar into the palm; the external wrench is the bar's weight at its centre.

Every link is a capsule of radius ``LINK_RADIUS`` about its axis segment (see
:mod:`analysis.urdf`). "Flat on a face" means the segment is parallel to the face at the
distance ``LINK_RADIUS``; the contact point is the foot of the segment's midpoint on the face
and the normal is the face's inward normal. The joint angles and the bar's top, front and
bottom planes come from a least-squares solve of those conditions (scipy, with weak pulls
toward a nominal posture, then Gauss-Newton on the conditions alone), within the URDF's joint
limits. The script then checks that no link capsule penetrates the bar, that links without a
declared contact keep clear of it, that every contact lies inside its face, that contact forces
in the friction cones can balance the weight, and that the scene validates.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import least_squares, linprog

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from analysis.contacts import build_system, tangent_basis  # noqa: E402
from analysis.loader import load_scene, scene_from_dict  # noqa: E402
from analysis.rotations import matrix_to_quat_wxyz, quat_wxyz_to_matrix  # noqa: E402
from analysis.urdf import UrdfFinger, resolve_urdf_path  # noqa: E402

Array = NDArray[np.float64]

URDF = "example-robot-data:allegro_hand_description/urdf/allegro_right_hand.urdf"
OUT = ROOT / "examples" / "allegro_right_box.json"

#: Capsule radius of the links: half the 0.0196 thickness of the phalanges' collision boxes in
#: the flexion direction (their pads), rounded up. (The URDF's fingertip spheres have radius
#: 0.012; a larger capsule would make the finger roots overlap the palm's inner face.)
LINK_RADIUS = 0.01
MU = 0.5
MASS = 0.05  # kg (a 50 g bar); its weight MASS * 9.81 N acts along world -z
PALM_CENTER = np.array([-0.0093, 0.0, -0.0475])  # palm_link collision box, palm frame
PALM_SIZE = np.array([0.0408, 0.1130, 0.095])
PALM_FACE_X = PALM_CENTER[0] + PALM_SIZE[0] / 2  # 0.0111, the palm's inner face
BAR_Y = (-0.065, 0.065)  # the bar's extent across the hand (palm frame y)

# The hand's base (the world pose of palm_link): palm up, i.e. palm +x -> world +z, fingers
# (palm +z) -> world -x, thumb side (palm +y) -> world +y; the palm 10 cm above the origin.
BASE_R = np.array([[0.0, 0.0, -1.0], [0.0, 1.0, 0.0], [1.0, 0.0, 0.0]])
BASE_P = np.array([0.0, 0.0, 0.1])

#: finger name -> (tip link, nominal q: initial guess and weak regulariser)
FINGERS: dict[str, tuple[str, Array]] = {
    "index": ("link_3.0_tip", np.array([0.0, 1.55, 1.55, 0.3])),
    "middle": ("link_7.0_tip", np.array([0.0, 1.55, 1.55, 0.3])),
    "ring": ("link_11.0_tip", np.array([0.0, 1.55, 1.2, 0.6])),
    "thumb": ("link_15.0_tip", np.array([0.6, 0.9, 1.4, 1.3])),
}
#: Weak target of the bar's bottom plane; target (x, y) of the thumb tip (palm frame).
Z_BOTTOM = -0.015
THUMB_XY = np.array([0.03, 0.01])

#: Contacts in scene order: (finger or "palm", link, face). Faces: "top" (+z), "front" (+x),
#: "bottom" (-z), "back" (-x).
CONTACTS = [
    ("index", "link_1.0", "top"),
    ("index", "link_2.0", "front"),
    ("middle", "link_6.0", "front"),
    ("ring", "link_9.0", "top"),
    ("thumb", "link_15.0_tip", "bottom"),
    ("palm", "", "back"),
]
OUTWARD = {"top": np.array([0.0, 0.0, 1.0]), "front": np.array([1.0, 0.0, 0.0]),
           "bottom": np.array([0.0, 0.0, -1.0]), "back": np.array([-1.0, 0.0, 0.0])}


def build_fingers() -> dict[str, UrdfFinger]:
    """The four fingers with an identity base, so that their poses are in the palm frame."""
    path = resolve_urdf_path(URDF)
    return {name: UrdfFinger(name, path, "palm_link", tip, q, link_radius=LINK_RADIUS)
            for name, (tip, q) in FINGERS.items()}


def segment(f: UrdfFinger, link: str, q: Array) -> tuple[Array, Array]:
    """Axis segment ``(3,)``, ``(3,)`` of a link, palm frame."""
    k = f.body_index(link)
    assert k is not None, link
    return f.body_segment(k, q)


def unpack(x: Array) -> tuple[dict[str, Array], dict[str, float]]:
    """Solver vector -> joint angles per finger and the bar's planes (palm frame)."""
    qs = {name: x[4 * i : 4 * i + 4] for i, name in enumerate(FINGERS)}
    planes = {"back": PALM_FACE_X, "top": float(x[16]), "front": float(x[17]), "bottom": float(x[18])}
    return qs, planes


def residuals(x: Array, fingers: dict[str, UrdfFinger], regularise: bool) -> Array:
    """Contact conditions (zero when met), then optionally the weak pulls."""
    qs, planes = unpack(x)
    r = LINK_RADIUS
    res: list[float] = []
    for name, link, face in CONTACTS:
        if name == "palm":
            continue
        a, b = segment(fingers[name], link, qs[name])
        m = OUTWARD[face]
        axis = int(np.argmax(np.abs(m)))
        level = planes[face] + r * float(m[axis])  # the plane the segment must lie in
        if np.allclose(a, b):  # a fingertip sphere: only its centre's level
            res.append(a[axis] - level)
        else:  # a link lying flat: parallel to the face, at the distance r
            res += [(b - a)[axis], a[axis] - level]
    tip, _ = segment(fingers["thumb"], "link_15.0_tip", qs["thumb"])
    res += list(tip[:2] - THUMB_XY)
    if regularise:
        res.append(0.2 * (planes["bottom"] - Z_BOTTOM))
        for name, (_, q_nom) in FINGERS.items():
            res += list(0.002 * (qs[name] - q_nom))
    return np.asarray(res)


def solve(fingers: dict[str, UrdfFinger]) -> Array:
    margin = 0.02  # stay this far inside the joint limits
    lo = np.concatenate([f.lower + margin for f in fingers.values()] + [np.array([-0.1, 0.0, -0.02])])
    hi = np.concatenate([f.upper - margin for f in fingers.values()] + [np.array([0.1, 0.1, -0.01])])
    x0 = np.concatenate([q for _, q in FINGERS.values()] + [np.array([0.0, 0.05, Z_BOTTOM])])
    x0 = np.clip(x0, lo, hi)
    # 1) the conditions plus weak pulls toward the nominal posture and bar
    sol = least_squares(residuals, x0, bounds=(lo, hi), args=(fingers, True),
                        xtol=1e-14, ftol=1e-14, gtol=1e-14, max_nfev=5000)
    x = np.asarray(sol.x)
    # 2) Gauss-Newton with minimum-norm steps on the conditions alone: the nearest exact solution
    for _ in range(30):
        r = residuals(x, fingers, False)
        if np.max(np.abs(r)) < 1e-13:
            break
        h = 1e-7
        J = np.array([(residuals(x + h * e, fingers, False) - r) / h for e in np.eye(len(x))]).T
        x = x - np.linalg.lstsq(J, r, rcond=None)[0]
    r = residuals(x, fingers, False)
    if np.max(np.abs(r)) > 1e-12:
        raise RuntimeError(f"contact conditions not met: {r}")
    if np.any(x < lo - 1e-9) or np.any(x > hi + 1e-9):
        raise RuntimeError("the solution left the joint limits")
    return x


def box_sdf(p: Array, lo: Array, hi: Array) -> Array:
    """Signed distance (negative inside) of points ``(m, 3)`` to the box ``[lo, hi]``."""
    c, h = (lo + hi) / 2, (hi - lo) / 2
    d = np.abs(p - c) - h  # (m, 3)
    return np.asarray(np.linalg.norm(np.maximum(d, 0.0), axis=1) + np.minimum(d.max(axis=1), 0.0))


def clearances(fingers: dict[str, UrdfFinger], qs: dict[str, Array], lo: Array,
               hi: Array) -> dict[str, tuple[float, Array]]:
    """Per link: the distance from its capsule to the bar (0 = touching, < 0 = penetrating) and
    the point ``(3,)`` of its axis nearest to the bar (sampled finely along the axis)."""
    t = np.linspace(0.0, 1.0, 4001)[:, None]  # (m, 1)
    out = {}
    for name, f in fingers.items():
        for k, link in enumerate(f.links):
            a, b = f.body_segment(k, qs[name])
            pts = a + t * (b - a)  # (m, 3)
            d = box_sdf(pts, lo, hi)  # (m,)
            i = int(np.argmin(d))
            out[f"{name}/{link}"] = (float(d[i]) - LINK_RADIUS, pts[i])
    return out


def contact_points(fingers: dict[str, UrdfFinger], qs: dict[str, Array], planes: dict[str, float],
                   lo: Array, hi: Array) -> list[tuple[str, Array, Array]]:
    """``(body, point, inward normal)`` of every contact, palm frame."""
    out = []
    for name, link, face in CONTACTS:
        m = OUTWARD[face]
        if name == "palm":
            # the middle of the face region the palm and the bar share
            z_hi = min(planes["top"], 0.0)
            p = np.array([PALM_FACE_X, 0.0, 0.5 * (planes["bottom"] + z_hi)])
            out.append(("palm", p, -m))
            continue
        a, b = segment(fingers[name], link, qs[name])
        p = 0.5 * (a + b) - LINK_RADIUS * m  # the foot of the midpoint on the face
        out.append((f"{name}/{link}", p, -m))
    for body, p, _ in out:  # inside its face, at least 2 mm from the face's edges
        inner = np.all(p >= lo - 1e-12) and np.all(p <= hi + 1e-12)
        face_margin = np.sort(np.minimum(p - lo, hi - p))[1]  # the smallest in-face distance
        if not inner or face_margin < 0.002:
            raise RuntimeError(f"contact on {body} is not inside its face: {p}")
    return out


def weight_balance_margin(scene_dict: dict[str, Any]) -> float:
    """Largest ``s <= 1`` (newtons) such that contact forces with normal components ``>= s``
    inside the 16-sided friction pyramids balance the weight: ``G f = -w_ex`` (an LP; internal
    forces make it scale-free, hence the cap). ``> 0`` means every contact can press and the
    grasp can hold the bar."""
    scene = scene_from_dict(scene_dict)
    system = build_system(scene)
    L, k = system.L, scene.friction_cone_sides
    # f_i = sum_j lambda_ij (n_i + mu cos(th_j) t1_i + mu sin(th_j) t2_i), lambda >= 0, s <= n.f_i
    th = 2 * np.pi * np.arange(k) / k
    cols = []
    for i in range(L):
        t1, t2 = tangent_basis(system.normals[i])
        gens = system.normals[i] + system.mu[i] * (np.outer(np.cos(th), t1) + np.outer(np.sin(th), t2))
        cols.append(system.G_blocks[i] @ gens.T)  # (6, k)
    W = np.hstack(cols)  # (6, L k)
    n_var = L * k + 1  # lambdas, s
    A_eq = np.hstack([W, np.zeros((6, 1))])
    b_eq = -system.w_ex
    # s - sum_j lambda_ij <= 0  (the normal force of each generator is lambda, n . g = 1)
    A_ub = np.zeros((L, n_var))
    for i in range(L):
        A_ub[i, i * k : (i + 1) * k] = -1.0
        A_ub[i, -1] = 1.0
    c = np.zeros(n_var)
    c[-1] = -1.0
    bounds = [(0, None)] * (L * k) + [(None, 1.0)]  # cap s: the LP is scale-free otherwise
    res = linprog(c, A_ub=A_ub, b_ub=np.zeros(L), A_eq=A_eq, b_eq=b_eq, bounds=bounds, method="highs")
    return float(res.x[-1]) if res.status == 0 else -np.inf


def world(p: Array) -> list[float]:
    return [round(float(v), 10) for v in BASE_R @ p + BASE_P]


def world_dir(v: Array) -> list[float]:
    return [round(float(c), 10) for c in BASE_R @ v]


def build_scene(verbose: bool = False) -> dict[str, Any]:
    fingers = build_fingers()
    x = solve(fingers)
    qs, planes = unpack(x)
    lo = np.array([planes["back"], BAR_Y[0], planes["bottom"]])  # (3,) bar corners, palm frame
    hi = np.array([planes["front"], BAR_Y[1], planes["top"]])  # (3,)
    contacts = contact_points(fingers, qs, planes, lo, hi)
    touching = {body for body, _, _ in contacts}
    gaps = clearances(fingers, qs, lo, hi)
    if verbose:
        print("q:", {k: np.round(v, 4).tolist() for k, v in qs.items()})
        print("bar (palm frame):", np.round(lo, 4), np.round(hi, 4))
        print("capsule-bar gaps:", {k: round(v[0], 4) for k, v in gaps.items()})
    for body, (gap, s) in gaps.items():
        if gap < -1e-9:
            raise RuntimeError(f"{body} penetrates the bar by {-gap:.3g}")
        # a link may touch only at a declared contact (e.g. a fingertip's parent link touches
        # where the tip sphere, the end cap of its capsule, does)
        at_contact = any(abs(np.linalg.norm(s - p) - LINK_RADIUS) < 1e-7 for _, p, _ in contacts)
        if body not in touching and gap < 0.001 and not at_contact:
            raise RuntimeError(f"{body} touches the bar (gap {gap:.3g}) without a declared contact")
    quat = [round(float(v), 10) for v in matrix_to_quat_wxyz(BASE_R)]
    assert np.allclose(quat_wxyz_to_matrix(quat), BASE_R)
    palm_size = np.abs(BASE_R) @ PALM_SIZE  # BASE_R permutes axes: the palm stays axis-aligned
    weight = MASS * 9.81
    return {
        "name": "allegro-right-bar",
        "description": (
            "Allegro right hand (example-robot-data URDF), palm up, holding a "
            f"{hi[0] - lo[0]:.3f} x {hi[1] - lo[1]:.3f} x {hi[2] - lo[2]:.3f} m bar "
            f"({MASS * 1000:.0f} g) in a power grasp: the bar lies on the palm, the proximal links of "
            "index and ring and the middle links of index and middle wrap it, the thumb tip "
            "pushes from the other side. Generated by examples/make_allegro_scene.py."
        ),
        "dim": 3,
        "object": {
            "pose": {"position": world((lo + hi) / 2), "quat_wxyz": quat},
            "shape": {"type": "box", "size": [round(float(v), 10) for v in hi - lo]},
        },
        "external_wrench": [0.0, 0.0, round(-weight, 10), 0.0, 0.0, 0.0],
        "fixed_bodies": [
            {"name": "palm", "shape": {"type": "box", "size": [round(float(v), 10) for v in palm_size],
                                        "position": world(PALM_CENTER)}}
        ],
        "fingers": [
            {
                "name": name,
                "base": {"position": [round(float(v), 10) for v in BASE_P], "quat_wxyz": quat},
                "urdf": {"file": URDF, "root_link": "palm_link", "tip_link": tip},
                "q": [round(float(v), 10) for v in qs[name]],
                "link_radius": LINK_RADIUS,
            }
            for name, (tip, _) in FINGERS.items()
        ],
        "contacts": [
            {"body": body, "point": world(p), "normal": world_dir(n), "mu": MU}
            for body, p, n in contacts
        ],
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--check", action="store_true", help="compare with the committed scene")
    parser.add_argument("--verbose", action="store_true", help="print the posture and the gaps")
    args = parser.parse_args()
    scene = build_scene(args.verbose)
    margin = weight_balance_margin(scene)
    if margin <= 0:
        raise RuntimeError("the contacts cannot balance the weight")
    text = json.dumps(scene, indent=2) + "\n"
    if args.check:
        same = OUT.read_text() == text
        print(f"{OUT.relative_to(ROOT)} is {'up to date' if same else 'OUT OF DATE'}")
        sys.exit(0 if same else 1)
    OUT.write_text(text)
    load_scene(OUT)  # validates: contact points on the link capsules and the bar, normals inward
    print(f"wrote {OUT.relative_to(ROOT)}; forces in the friction cones with every normal force "
          f">= {margin:.3g} N balance the weight")


if __name__ == "__main__":
    main()
