"""The planner's collision checks on the real geometry (issue 10): a finger with
``"link_geometry": "urdf"`` (the Franka Panda's collision meshes, the Allegro hand's boxes and
fingertip spheres) and a mesh object are checked with the detector's geometry
(:class:`analysis.detect.SceneGeometry`). Checked against the detector's own distances
(:func:`analysis.detect.link_distances`), pinocchio's ``computeDistances`` on the URDF's full
model, and exact box distances; capsule scenes keep their model term for term."""

from __future__ import annotations

import functools
import json
from pathlib import Path
from typing import Any

import coal
import numpy as np
import pinocchio as pin
import pytest
from mesh_files import write_box_stl

from analysis.detect import UnplacedScene, link_distances
from analysis.geometry import object_pose
from analysis.kinematics import BodyRef, HandKinematics
from analysis.loader import load_scene, scene_from_dict, with_detected_contacts
from analysis.placement import placed_scene_data
from analysis.scene import Scene
from analysis.urdf import UrdfFinger, example_robot_data_dir, load_collision_model
from planner import Goal, plan
from planner.collision import CollisionModel, _box_segments_distance, path_clearance_certified
from planner.plan import PlanStep
from planner.state import all_f, state_from_scene
from planner.transition import ContactFigures, Transition
from planner.verify import verify_plan, verify_step

ROOT = Path(__file__).resolve().parents[2]
UNPLACED = ROOT / "examples" / "unplaced"

pytestmark = pytest.mark.skipif(example_robot_data_dir() is None, reason="example-robot-data is not installed")


@functools.lru_cache(maxsize=4)
def _urdf_scene_data(name: str) -> str:
    """The unplaced example ``name`` with URDF link geometry, placed on the touching links given
    in its description and its contacts detected (a valid scene, as JSON text)."""
    touch = {"panda_forearm_box": ["panda_link5"],  # link5's mesh is the forearm
             "allegro_cylinder": ["index/link_3.0_tip", "middle/link_7.0_tip", "ring/link_11.0_tip",
                                  "thumb/link_15.0_tip"]}[name]
    data = json.loads((UNPLACED / f"{name}.json").read_text())
    data.pop("contacts", None)
    for f in data["fingers"]:
        f["link_geometry"] = "urdf"
    placed, _ = placed_scene_data(data, touch)
    full, _ = with_detected_contacts(placed)
    return json.dumps(full)


def _urdf_scene(name: str) -> Scene:
    return scene_from_dict(json.loads(_urdf_scene_data(name)))


def _as_capsules(scene: Scene) -> Scene:
    """The same scene and configuration with the links as capsules (contacts dropped: the
    capsules need not touch where the meshes do)."""
    data = scene.model_dump(mode="json", exclude_none=True)
    data["contacts"] = []
    for f in data["fingers"]:
        f["link_geometry"] = "capsule"
    return UnplacedScene.model_validate(data)


def _random_q(hand: HandKinematics, rng: np.random.Generator, scale: float) -> np.ndarray:
    q = hand.q0 + rng.normal(scale=scale, size=hand.q0.shape)  # (M,)
    for f, chain in enumerate(hand.fingers):  # within the URDF's joint limits
        if isinstance(chain, UrdfFinger):
            sl = hand.finger_slice(f)
            q[sl] = np.clip(q[sl], chain.lower, chain.upper)
    return q


def _pose(scene: Scene) -> tuple[np.ndarray, np.ndarray]:
    """The object's pose in the scene: position ``(3,)``, rotation ``(3, 3)``."""
    p = object_pose(scene)
    return np.asarray(p.position, dtype=float), np.asarray(p.rotation, dtype=float)


def _detector_object_distance(scene: Scene, hand: HandKinematics, q: np.ndarray) -> dict[tuple[int, int], float]:
    """The detector's distance of each planner link (finger, k) to the object: per URDF link, the
    last chain link with the links fixed beyond it (a fingertip)."""
    out: dict[tuple[int, int], float] = {}
    for p in link_distances(scene, hand, q):
        if p.target != "object":
            continue
        assert p.link.finger is not None and p.link.link is not None
        k = min(int(p.link.link), hand.fingers[p.link.finger].n_joints - 1)
        key = (p.link.finger, k)
        out[key] = min(out.get(key, np.inf), p.distance)
    return out


# --------------------------------------------------------------------------------------------
# pinocchio, independently: the URDF's full model and its collision model


def _pin_world(finger: UrdfFinger, hand: HandKinematics, f: int, q: np.ndarray) -> tuple[Any, Any, pin.SE3]:
    """pinocchio's full model and data at the finger's ``q`` and the transform from the URDF's
    world to the scene's (from the first chain link's pose in both)."""
    model = pin.buildModelFromUrdf(str(finger.path))
    data = model.createData()
    qp = pin.neutral(model)
    sl = hand.finger_slice(f)
    for name, v in zip(finger.joint_names, q[sl], strict=True):
        qp[model.joints[model.getJointId(name)].idx_q] = v
    pin.framesForwardKinematics(model, data, qp)
    R, p = hand.body_pose(BodyRef(f"{finger.name}/{finger.links[0]}", f, 0), q)
    urdf = data.oMf[model.getFrameId(finger.links[0], pin.FrameType.BODY)]
    return model, qp, pin.SE3(np.asarray(R), np.asarray(p)) * urdf.inverse()


def _pinocchio_object_distances(scene: Scene, hand: HandKinematics, f: int, q: np.ndarray,
                                obj: Any, obj_pose: pin.SE3, collisions: bool = False) -> dict[str, float]:
    """pinocchio's ``computeDistances`` between each chain link of finger ``f`` and the object
    (``obj``, a coal shape at the world pose ``obj_pose``), on the URDF's own collision model;
    ``collisions``: ``computeCollisions`` instead (1.0: in collision, 0.0: not)."""
    finger = hand.fingers[f]
    assert isinstance(finger, UrdfFinger)
    model, qp, world = _pin_world(finger, hand, f, q)
    geom = load_collision_model(finger.path, []).copy()
    oid = geom.addGeometryObject(pin.GeometryObject("object", 0, world.inverse() * obj_pose, obj))
    names: dict[int, str] = {}
    for i, o in enumerate(geom.geometryObjects):
        if i == oid:
            continue
        link = str(model.frames[o.parentFrame].name)
        if link in finger.links:
            geom.addCollisionPair(pin.CollisionPair(i, oid))
            names[len(geom.collisionPairs) - 1] = link
    data, gdata = model.createData(), pin.GeometryData(geom)
    out: dict[str, float] = {}
    if collisions:
        pin.computeCollisions(model, data, geom, gdata, qp, False)
        for k, link in names.items():
            out[link] = max(out.get(link, 0.0), float(gdata.collisionResults[k].isCollision()))
        return out
    pin.computeDistances(model, data, geom, gdata, qp)
    for k, link in names.items():
        out[link] = min(out.get(link, np.inf), float(gdata.distanceResults[k].min_distance))
    return out


# --------------------------------------------------------------------------------------------
# The Allegro hand: boxes and fingertip spheres (exact shapes, no hulls)


def test_allegro_urdf_object_clearance_equals_the_detector_and_pinocchio() -> None:
    scene = _urdf_scene("allegro_cylinder")
    hand = HandKinematics.from_scene(scene)
    model = CollisionModel.of(scene, hand)
    pos, R = _pose(scene)
    shape = scene.object.shape
    cyl = coal.Cylinder(shape.radius, shape.height)  # type: ignore[union-attr]
    rng = np.random.default_rng(7)
    compared = 0
    for _ in range(6):
        q = _random_q(hand, rng, 0.15)
        ours = _detector_object_distance(scene, hand, q)
        for f in range(len(hand.fingers)):
            n = hand.fingers[f].n_joints
            terms = model.clearance_terms(f, q, pos, R)  # [object (n), fixed (n), pairs]
            # EPA (penetrating pairs) reached from another placement of the same shapes: 1e-8
            np.testing.assert_allclose(terms[:n], [ours[(f, k)] for k in range(n)], rtol=0, atol=1e-6)
            theirs = _pinocchio_object_distances(scene, hand, f, q, cyl, pin.SE3(R, pos))
            finger = hand.fingers[f]
            assert isinstance(finger, UrdfFinger)
            for k in range(n):
                links = finger.links[k:] if k == n - 1 else [finger.links[k]]
                d = min(theirs.get(lk, np.inf) for lk in links)
                if d > 1e-6:  # apart: both exact (pinocchio reports penetration as 0 here)
                    assert terms[k] == pytest.approx(d, abs=1e-6), (f, k)
                    compared += 1
    assert compared >= 60


def test_allegro_urdf_link_pairs_equal_pinocchio() -> None:
    # all four fingers are one URDF (one base): pinocchio's distances between links on the full
    # model are the planner's pair terms (non-adjacent links of a finger, links of two fingers)
    scene = _urdf_scene("allegro_cylinder")
    hand = HandKinematics.from_scene(scene)
    model = CollisionModel.of(scene, hand)
    pos, R = _pose(scene)
    base = {json.dumps(f.base.model_dump(mode="json")) for f in scene.fingers}
    assert len(base) == 1
    finger0 = hand.fingers[0]
    assert isinstance(finger0, UrdfFinger)
    rng = np.random.default_rng(11)
    checked = 0
    for _ in range(4):
        q = _random_q(hand, rng, 0.2)
        full = pin.buildModelFromUrdf(str(finger0.path))
        qp = pin.neutral(full)
        for f, chain in enumerate(hand.fingers):
            assert isinstance(chain, UrdfFinger)
            for name, v in zip(chain.joint_names, q[hand.finger_slice(f)], strict=True):
                qp[full.joints[full.getJointId(name)].idx_q] = v
        geom = load_collision_model(finger0.path, []).copy()
        owner = {}  # geometry index -> (finger, planner link)
        for i, o in enumerate(geom.geometryObjects):
            link = str(full.frames[o.parentFrame].name)
            for f, chain in enumerate(hand.fingers):
                assert isinstance(chain, UrdfFinger)
                if link in chain.links:
                    owner[i] = (f, min(chain.links.index(link), chain.n_joints - 1))
        idx = sorted(owner)
        for a in idx:
            for b in idx:
                (fa, ka), (fb, kb) = owner[a], owner[b]
                if a < b and (fa != fb or abs(ka - kb) >= 2):  # the planner's pairs: non-adjacent links
                    geom.addCollisionPair(pin.CollisionPair(a, b))
        data, gdata = full.createData(), pin.GeometryData(geom)
        pin.computeDistances(full, data, geom, gdata, qp)
        theirs: dict[tuple[tuple[int, int], tuple[int, int]], float] = {}
        for k, cp in enumerate(geom.collisionPairs):
            key = (owner[cp.first], owner[cp.second])
            key = (min(key), max(key))
            theirs[key] = min(theirs.get(key, np.inf), float(gdata.distanceResults[k].min_distance))
        for f in range(len(hand.fingers)):
            fd = model._finger_data(f)
            n = hand.fingers[f].n_joints
            terms = model.clearance_terms(f, q, pos, R)[2 * n:]
            for (i, j), t in zip(fd.pairs, terms, strict=True):
                a, b = fd.stacked[i], fd.stacked[j]
                key = ((int(a.finger or 0), int(a.link or 0)), (int(b.finger or 0), int(b.link or 0)))
                key = (min(key), max(key))
                if theirs[key] > 1e-6:
                    assert t == pytest.approx(theirs[key], abs=1e-6), key
                    checked += 1
    assert checked >= 50


# --------------------------------------------------------------------------------------------
# The Panda: collision meshes (their convex hulls)


def test_panda_urdf_clearance_equals_the_detector_and_pinocchio() -> None:
    scene = _urdf_scene("panda_forearm_box")
    hand = HandKinematics.from_scene(scene)
    model = CollisionModel.of(scene, hand)
    pos, R = _pose(scene)
    box = coal.Box(*scene.object.shape.size)  # type: ignore[union-attr]
    finger = hand.fingers[0]
    assert isinstance(finger, UrdfFinger)
    n = finger.n_joints
    rng = np.random.default_rng(5)
    compared = 0
    for _ in range(8):
        q = _random_q(hand, rng, 0.1)
        terms = model.clearance_terms(0, q, pos, R)
        ours = _detector_object_distance(scene, hand, q)
        np.testing.assert_allclose(terms[:n], [ours[(0, k)] for k in range(n)], rtol=0, atol=1e-9)
        table = {(int(p.link.link) if p.link.link is not None else -1): p.distance
                 for p in link_distances(scene, hand, q) if p.target == "table"}
        for k in range(n):  # the fixed term: every link not mounted on the table at the start
            expect = min(v for m, v in table.items() if min(m, n - 1) == k)
            assert (0, k) in model.mounted or terms[n + k] == pytest.approx(expect, abs=1e-9), k
        theirs = _pinocchio_object_distances(scene, hand, 0, q, box, pin.SE3(R, pos))
        for k in range(n):
            links = finger.links[k:] if k == n - 1 else [finger.links[k]]
            d = min(theirs.get(lk, np.inf) for lk in links)
            if d > 1e-6:  # pinocchio on the raw (convex) meshes: exact where apart
                assert terms[k] == pytest.approx(d, abs=1e-6), k
                compared += 1
    assert compared >= 30


def test_panda_configuration_is_judged_by_the_mesh_not_the_capsule() -> None:
    # the box moved about the arm at random: wherever the capsules (radius 0.05) and the meshes
    # disagree, the planner follows the meshes, and pinocchio's computeCollisions on the URDF's
    # own meshes (convex: their hulls) agrees with it
    scene = _urdf_scene("panda_forearm_box")
    hand = HandKinematics.from_scene(scene)
    model = CollisionModel.of(scene, hand)
    capsules = _as_capsules(scene)
    cap_model = CollisionModel.of(capsules, HandKinematics.from_scene(capsules))
    finger = hand.fingers[0]
    assert isinstance(finger, UrdfFinger)
    n = finger.n_joints
    box = coal.Box(*scene.object.shape.size)  # type: ignore[union-attr]
    rng = np.random.default_rng(2)
    mesh_only = capsule_only = 0
    for _ in range(80):
        q = _random_q(hand, rng, 0.15)
        k = int(rng.integers(3, n))  # near the forearm, the wrist or the hand
        a, b = hand.body_segment(BodyRef("", 0, k), q)
        R = pin.exp3(rng.normal(size=3))
        pos = a + rng.uniform() * (b - a) + R @ (np.array([0.08, 0.0, 0.0]) + rng.normal(scale=0.04, size=3))
        urdf = model.clearance_terms(0, q, pos, R)[:n]
        cap = cap_model.clearance_terms(0, q, pos, R)[:n]
        hit = _pinocchio_object_distances(scene, hand, 0, q, box, pin.SE3(R, pos), collisions=True)
        for m in range(n):
            links = finger.links[m:] if m == n - 1 else [finger.links[m]]
            if abs(urdf[m]) > 1e-6:
                assert (urdf[m] < 0) == any(hit.get(lk, 0.0) > 0 for lk in links), m
        if urdf.min() < -1e-6 and cap.min() > 0:
            mesh_only += 1  # penetrates with the mesh only: invalid for the planner
            assert model.finger_clearance(0, q, pos, R) < 0
        if urdf.min() > 1e-6 and cap.min() < 0:
            capsule_only += 1  # the capsule penetrates, the mesh does not
            assert cap_model.finger_clearance(0, q, pos, R) < 0
    assert mesh_only >= 1 and capsule_only >= 1


def test_lipschitz_bound_of_urdf_links_holds_for_their_shapes() -> None:
    # every vertex of the Panda's hulls moves at most K |dq| (finite differences)
    scene = _urdf_scene("panda_forearm_box")
    hand = HandKinematics.from_scene(scene)
    model = CollisionModel.of(scene, hand)
    K = model.lipschitz(0)
    geo = model.geometry
    finger = hand.fingers[0]
    assert isinstance(finger, UrdfFinger)

    def points(q: np.ndarray) -> np.ndarray:
        out = []
        for m, name in enumerate(finger.body_names()):
            Rm, pm = hand.body_pose(BodyRef(name, 0, m), q)
            for g, Rl, tl in geo.local_shapes(0, m) or []:
                V = np.asarray(g.points(), dtype=float) if hasattr(g, "points") else np.zeros((1, 3))
                out.append(pm + (tl + V @ Rl.T) @ np.asarray(Rm).T)
        return np.vstack(out)

    rng = np.random.default_rng(4)
    P0 = points(hand.q0)
    for _ in range(20):
        dq = rng.normal(size=hand.q0.shape) * 1e-4
        speed = float(np.linalg.norm(points(hand.q0 + dq) - P0, axis=1).max()) / float(np.linalg.norm(dq))
        assert speed <= K
    assert K > 0


# --------------------------------------------------------------------------------------------
# A mesh object (before: not seen by the planner at all)


def _mesh_scene(stl: Path) -> dict[str, Any]:
    """Two capsule rods over a mesh box (turned 45 degrees about z) standing on a table."""
    def rod(name: str, a: list[float], tip: list[float]) -> dict[str, Any]:
        return {"name": name, "base": {"position": a},
                "joints": [{"axis": [0.0, 1.0, 0.0], "origin": [0.0, 0.0, 0.0], "radius": 0.02},
                           {"axis": [0.0, 1.0, 0.0], "origin": [0.1, 0.0, 0.0], "radius": 0.02}],
                "tip": tip, "q": [0.0, 0.0]}

    return {"dim": 3, "object": {"pose": {"position": [0.0, 0.0, 0.05],
                                          "quat_wxyz": [0.9238795325112867, 0.0, 0.0, 0.3826834323650898]},
                                 "shape": {"type": "mesh", "file": str(stl)}},
            "external_wrench": [0.0, 0.0, -1.0, 0.0, 0.0, 0.0],
            "fixed_bodies": [{"name": "table", "shape": {"type": "box", "size": [1.0, 1.0, 0.1],
                                                          "position": [0.0, 0.0, -0.05]}}],
            "fingers": [rod("f", [-0.12, 0.0, 0.12], [0.1, 0.0, 0.0]), rod("g", [0.02, 0.05, 0.2], [0.1, 0.0, 0.0])],
            "contacts": []}


def test_mesh_object_clearance_is_the_exact_box_distance(tmp_path: Path) -> None:
    half = np.array([0.1, 0.15, 0.05])
    stl = tmp_path / "box.stl"
    write_box_stl(stl, half)
    scene = UnplacedScene.model_validate(_mesh_scene(stl))
    hand = HandKinematics.from_scene(scene)
    model = CollisionModel.of(scene, hand)
    rng = np.random.default_rng(9)
    hits = 0
    for _ in range(20):
        q = rng.uniform(-1.2, 1.2, size=hand.q0.shape)
        pos = np.array([0.0, 0.0, 0.05]) + rng.normal(scale=0.03, size=3)
        axis = rng.normal(size=3)
        Rm = pin.exp3(axis / np.linalg.norm(axis) * rng.uniform(0, np.pi))
        for f in range(2):
            n = hand.fingers[f].n_joints
            terms = model.clearance_terms(f, q, pos, Rm)[:n]
            A, B = model.segment_arrays(f, q)  # (n, 3) link axes
            exact = _box_segments_distance(np.zeros(3), half, (A - pos) @ Rm, (B - pos) @ Rm, 4e-7)  # within 2e-7
            radius = np.array([model.radius(r) for r in model.links(f)])
            apart = exact > 1e-9
            # apart: the distance, exactly; penetrating: coal's depth is the translation that
            # separates the two (EPA), the sampled one the deepest point's: the same sign only
            np.testing.assert_allclose(terms[apart], (exact - radius)[apart], rtol=0, atol=1e-6)
            assert np.all(terms[~apart] < 0)
            hits += int((~apart).any())
        # the object against the table: the lowest corner (exact where apart; a depth where not)
        corners = np.array(np.meshgrid(*[[-h, h] for h in half], indexing="ij")).reshape(3, -1).T @ Rm.T + pos
        lowest = float(corners[:, 2].min())
        oc = model.object_clearance(pos, Rm)
        if lowest > 0:
            assert oc == pytest.approx(lowest, abs=1e-6)
        else:
            assert oc < 0
    assert hits >= 3  # some configurations penetrate the mesh, and are found


def test_mesh_object_scene_at_the_detectors_pose_equals_link_distances(tmp_path: Path) -> None:
    stl = tmp_path / "box.stl"
    write_box_stl(stl, np.array([0.1, 0.15, 0.05]))
    scene = UnplacedScene.model_validate(_mesh_scene(stl))
    hand = HandKinematics.from_scene(scene)
    model = CollisionModel.of(scene, hand)
    pos, R = _pose(scene)
    rng = np.random.default_rng(1)
    for _ in range(5):
        q = rng.uniform(-1.0, 1.0, size=hand.q0.shape)
        # the detector's capsule of the link radius is the planner's bare axis minus the radius
        ours = _detector_object_distance(scene, hand, q)
        for f in range(2):
            n = hand.fingers[f].n_joints
            terms = model.clearance_terms(f, q, pos, R)[:n]
            for k, ref in enumerate(model.links(f)):
                inflate = model.radius(ref) - hand.body_radius(ref)
                assert terms[k] == pytest.approx(ours[(f, k)] - inflate, abs=1e-6)


# --------------------------------------------------------------------------------------------
# Capsule scenes keep their model, and the certificate sees the real geometry


@pytest.mark.parametrize("name", ["planar_disk_envelope", "sphere_four_finger_palm", "panda_forearm_box"])
def test_capsule_scenes_do_not_use_coal(name: str) -> None:
    scene = load_scene(ROOT / "examples" / f"{name}.json")
    hand = HandKinematics.from_scene(scene)
    model = CollisionModel.of(scene, hand)
    st = state_from_scene(scene, hand)
    for f in range(len(hand.fingers)):
        assert not model.is_urdf(f)
        model.clearance_terms(f, st.q, st.position, st.rotation)
        fd = model._finger_data(f)
        assert not fd.urdf and not fd.coal_object and len(fd.coal_pairs) == 0
    assert "geometry" not in model._cache  # the capsule formulas only


def test_certified_path_through_the_mesh_fails_and_around_it_passes() -> None:
    # the Panda's forearm swept down through the box: the certificate stops inside the mesh; the
    # capsule model of the same scene is no judge of it (the same check, another geometry)
    scene = _urdf_scene("panda_forearm_box")
    hand = HandKinematics.from_scene(scene)
    model = CollisionModel.of(scene, hand)
    pos, R = _pose(scene)
    q0 = hand.q0.copy()
    down = q0.copy()
    down[1] += 0.25  # shoulder forward: the forearm into the box
    path = np.linspace(q0, down, 6)
    ok, clear, checks = path_clearance_certified(model, 0, q0, path, pos, R)
    assert not ok and clear < 0 and checks > 1
    truth = min(_detector_object_distance(scene, hand, down).values())
    assert truth < 0
    up = q0.copy()
    up[1] -= 0.2  # shoulder back: away from the box and the table
    ok, clear, _ = path_clearance_certified(model, 0, q0, np.linspace(q0, up, 4), pos, R)
    assert ok and clear >= 0


def test_verify_checks_a_finger_path_with_the_urdf_shapes() -> None:
    # a real plan on the Allegro hand with URDF geometry (boxes, fingertip spheres): the index
    # finger released (its retreat certified on the URDF shapes); then the release reversed as a
    # contact step, which verify re-checks on the same shapes: the path passes, and a detour
    # through a configuration where only the URDF shapes collide (the capsules of the same
    # scene are clear all along it) is refused
    scene = _urdf_scene("allegro_cylinder")
    hand = HandKinematics.from_scene(scene)
    found = plan(scene, Goal(type="combination", combination="DFFFF"), time_limit=60)
    assert found.found and [s.transition.kind for s in found.steps] == ["release"]
    assert verify_plan(scene, found) == []
    rel = found.steps[0]
    sl = hand.finger_slice(0)

    def contact_step(path: np.ndarray) -> PlanStep:
        tau = rel.transition.tau_stationary
        figures = ContactFigures("index", tuple(rel.before.world_point(0)), 0.0, 0.0, len(path), 0.0)
        t = Transition("contact", all_f(rel.after) + "D", rel.after.bodies(), rel.before.bodies(), path,
                       np.tile(rel.after.pose_vector(), (len(path), 1)), tau, tau, None, figures, 0.0)
        return PlanStep(1, t, rel.after, rel.before)

    back = rel.transition.q_path[::-1].copy()  # (n, M)
    assert verify_step(scene, hand, contact_step(back)) == []
    model = CollisionModel.of(scene, hand)
    capsules = _as_capsules(scene)
    cap_model = CollisionModel.of(capsules, HandKinematics.from_scene(capsules))
    pos, R = rel.after.position, rel.after.rotation
    n = hand.fingers[0].n_joints
    tip = BodyRef(f"index/{n - 1}", 0, n - 1)
    rng = np.random.default_rng(3)
    for _ in range(400):
        bad = back[0].copy()
        bad[sl] += rng.normal(scale=0.3, size=bad[sl].shape)
        detour = np.vstack([back[:1], bad[None, :], back[-1:]])
        # as verify checks it: the fingertip may touch the object on the last segment
        urdf_ok, _, _ = path_clearance_certified(model, 0, back[0], detour[:, sl], pos, R, [tip], 1)
        cap_ok, _, _ = path_clearance_certified(cap_model, 0, back[0], detour[:, sl], pos, R, [tip], 1)
        if cap_ok and not urdf_ok and model.finger_clearance(0, bad, pos, R,
                                                             allowance=model.start_allowance(0, back[0], pos, R)) < 0:
            break
    else:
        pytest.fail("no configuration where only the URDF shapes collide")
    problems = verify_step(scene, hand, contact_step(np.vstack([back[:1], bad[None, :], back[-1:]])))
    assert any("finger path collides" in p for p in problems), problems
