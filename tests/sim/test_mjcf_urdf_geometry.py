"""MuJoCo with a URDF finger's own collision shapes (``"link_geometry": "urdf"``, sim/mjcf.py).

The Allegro hand holding a cylinder (examples/allegro_cylinder_urdf.json) touches it with the tip
spheres and, on the thumb, also with the pad box of link_15.0. Known answers:

* the MuJoCo model carries the shapes the detector uses: at random hand configurations the
  distance MuJoCo computes between every link geom and the object (its own collision code) equals
  coal's distance between the URDF shapes and the object shrunk by ``eps`` (analysis.detect, an
  independent engine), to 1e-6 m; a capsule model (the earlier one) misses by millimetres;
* at the scene configuration the object's contacts in MuJoCo are the scene's: one per scene
  contact, on the same link, at ``p + eps n / 2`` (halfway between the shape and the shrunk
  object) with normal ``n``, at ``dist - margin = 0``; no other link within the detection
  tolerance;
* the contact statistics read the pair margin off: a contact pressed by its holding torque sticks
  with gap 0, not "separated by eps";
* the plan to active closure (release the thumb pad) replays with the pad touching in MuJoCo at
  the start and off the cylinder at the end, the object never dropped.

The replay meets the issue's 5 %: the plan does not move the object, so its replay is judged
against 1 % of the object's size (0.7 mm). A stationary grasp's torque does no first-order work
along any motion its sticking contacts allow (``G f = -w_ex`` and ``tau = J^T f`` give
``tau . dq + w_ex . dr = 0``), so under torque control alone a hold is neutral to first order and
decided at second order; MuJoCo's tip spheres roll on the cylinder (the analysis glues the two
material points, which agrees to first order), and the four-fingertip grasp drifts at a growing
rate. The replay holds as a real hand does (sim/plan_replay.py, ``hold_rate``): the plan's
holding torque as feed-forward and a joint servo (3.1 N m/rad here, about the Allegro's) on the
joint motions that move the contacts, never during object motions. The link release turns the
thumb's kept tip link 0.05 rad, so the torque that holds the grasp changes along the release path
(the thumb's second joint by 0.0087 N m, 17 %: the plan's final holding torque against the
release's ``tau_st``); the replay goes from one to the other with the path's progress. Kept at
``tau_st`` (the replay before) the unbalanced difference drifted the grasp 44.5 um (6.4 %); now
15.5 um (2.2 %), rotation 0.02 %. Without the servo 40 um (5.8 %); holding on for 0.3 s more
59 um with the servo and 0.42 mm without. The planned path of the thumb keeps its tip's material
point glued while the tip link turns, which presses the tip sphere 8.9 um into the cylinder at the
path's end (coal's distance, :func:`test_the_release_path_presses_the_tip_into_the_cylinder`).
"""

from __future__ import annotations

from pathlib import Path

import mujoco
import numpy as np
import pytest

from analysis.detect import link_distances, link_refs
from analysis.geometry import object_size
from analysis.kinematics import HandKinematics
from analysis.loader import load_scene
from analysis.pose import Pose
from analysis.rotations import matrix_to_quat_wxyz
from analysis.scene import Scene
from planner import Goal, plan
from planner.verify import verify_plan
from sim.mjcf import (
    DEFAULT_PARAMS,
    build_model,
    finger_qpos_addresses,
    link_body_name,
    object_qpos_address,
    reset_to_scene,
)
from sim.plan_replay import PlanSimulationOptions, simulate_plan
from sim.torque_replay import simulate_torques

EXAMPLES = Path(__file__).parents[2] / "examples"
SCENE = EXAMPLES / "allegro_cylinder_urdf.json"


@pytest.fixture(scope="module")
def scene() -> Scene:
    return load_scene(SCENE)


def _shrunk(scene: Scene, eps: float) -> Scene:
    """The scene with its cylinder eroded by ``eps`` (radius and half height), as MuJoCo's object."""
    data = scene.model_dump(mode="json")
    data["object"]["shape"]["radius"] -= eps
    data["object"]["shape"]["height"] -= 2 * eps
    data["contacts"] = []
    from analysis.detect import UnplacedScene

    return UnplacedScene.model_validate(data)


def _link_geoms(model: mujoco.MjModel, finger: str, k: int) -> list[int]:
    body = model.body(link_body_name(finger, k)).id
    return [int(g) for g in np.flatnonzero(model.geom_bodyid == body)]


def test_link_geoms_are_the_detectors_shapes(scene: Scene) -> None:
    """MuJoCo's link-object distances equal coal's on the URDF shapes (object shrunk by eps)."""
    hand = HandKinematics.from_scene(scene)
    eps = DEFAULT_PARAMS.eps_rel * object_size(scene)
    shrunk = _shrunk(scene, eps)
    model = build_model(scene)
    data = mujoco.MjData(model)
    reset_to_scene(model, data)
    obj = model.geom("object").id
    qadr = finger_qpos_addresses(model, scene)
    refs = link_refs(scene, hand)
    rng = np.random.default_rng(11)
    fromto = np.zeros(6)
    compared = 0
    for _ in range(6):
        q = hand.q0 + rng.uniform(-0.25, 0.25, size=hand.M)  # (M,)
        data.qpos[qadr] = q
        mujoco.mj_kinematics(model, data)
        expected = {(d.link.finger, d.link.link): d.distance
                    for d in link_distances(shrunk, hand, q, refs) if d.target == "object"}
        for ref in refs:
            assert ref.finger is not None and ref.link is not None
            geoms = _link_geoms(model, hand.fingers[ref.finger].name, int(ref.link))
            assert geoms, ref.name  # every Allegro link has a collision shape
            d_mj = min(mujoco.mj_geomDistance(model, data, g, obj, 1.0, fromto) for g in geoms)
            d_coal = expected[(ref.finger, ref.link)]
            if d_coal < 0.2:  # mj_geomDistance caps at distmax
                assert abs(d_mj - d_coal) <= 1e-6, (ref.name, d_mj, d_coal)
                compared += 1
    assert compared > 60


def test_capsules_would_miss_the_urdf_shapes(scene: Scene) -> None:
    """The earlier model (the link capsules) is not the detector's geometry: at the scene
    configuration the thumb pad's capsule is millimetres off the cylinder the pad box touches."""
    hand = HandKinematics.from_scene(scene)
    data = scene.model_dump(mode="json")
    for f in data["fingers"]:
        f["link_geometry"] = "capsule"
    data["contacts"] = []
    from analysis.detect import UnplacedScene

    capsules = UnplacedScene.model_validate(data)
    pad = hand.resolve_body("thumb/link_15.0")
    assert pad is not None
    d_caps = next(d.distance for d in link_distances(capsules, HandKinematics.from_scene(capsules), hand.q0, [pad])
                  if d.target == "object")
    d_urdf = next(d.distance for d in link_distances(scene, hand, hand.q0, [pad]) if d.target == "object")
    assert abs(d_urdf) < 1e-6
    assert abs(d_caps) > 1e-3, d_caps


def test_mujoco_contacts_at_the_start_are_the_scenes(scene: Scene) -> None:
    hand = HandKinematics.from_scene(scene)
    eps = DEFAULT_PARAMS.eps_rel * object_size(scene)
    model = build_model(scene)
    data = mujoco.MjData(model)
    reset_to_scene(model, data)
    obj = model.geom("object").id
    found: list[tuple[str, np.ndarray, np.ndarray, float]] = []  # (link body, pos, normal hand -> object, gap)
    for i in range(data.ncon):
        con = data.contact[i]
        g1, g2 = int(con.geom1), int(con.geom2)
        if obj not in (g1, g2):
            continue
        other = g2 if g1 == obj else g1
        sign = 1.0 if g2 == obj else -1.0
        gap = float(con.dist - con.includemargin)
        if gap <= 1e-3:  # the detector's tolerance
            found.append((model.body(int(model.geom_bodyid[other])).name, np.array(con.pos),
                          sign * np.array(con.frame[:3]), gap))
    assert len(found) == len(scene.contacts)
    for c in scene.contacts:
        ref = hand.resolve_body(c.body)
        assert ref is not None and ref.finger is not None
        body = link_body_name(hand.fingers[ref.finger].name, int(ref.link))
        p, n = np.asarray(c.point), np.asarray(c.normal)
        mine = [f for f in found if f[0] == body and np.linalg.norm(f[1] - (p + 0.5 * eps * n)) < 1e-3]
        assert len(mine) == 1, (c.body, found)
        _, pos, normal, gap = mine[0]
        np.testing.assert_allclose(pos, p + 0.5 * eps * n, atol=1e-7)
        np.testing.assert_allclose(normal, n, atol=1e-4)  # the box-cylinder pair: MuJoCo's convex collider
        assert abs(gap) < 1e-6  # (5.5e-8 on the box-cylinder pair)


def test_contacts_pressed_by_their_holding_torque_stick_with_no_gap(scene: Scene) -> None:
    """The statistics take the pair margin off MuJoCo's distance: the five contacts, pressed by
    the grasp's stationary torque (18) for 20 ms, each carry force and end at gap ~0 (below the
    1e-3 s of 'separated'), and none is read as separated."""
    from planner.state import StateAnalysis, all_f, state_from_scene

    hand = HandKinematics.from_scene(scene)
    state = state_from_scene(scene, hand)
    grasp = StateAnalysis.of(scene, state, hand).stationary(all_f(state))
    assert grasp is not None
    r = simulate_torques(scene, np.asarray(grasp.tau), duration=0.02)
    s = object_size(scene)
    for c in r.contacts:
        assert c.observed != "separate", c
        assert c.mean_normal_force > 0.0, c
        assert abs(c.final_gap) < 0.05 * DEFAULT_PARAMS.eps_rel * s, c  # not the margin eps (penetration ~9 um)


def test_active_closure_plan_replays_with_the_object_still(scene: Scene) -> None:
    """The plan releases the thumb's pad (a link release: the thumb keeps its tip on the cylinder,
    so it stays torque-controlled and the posture torque takes it along its planned path, which
    moves no kept contact point). In MuJoCo the pad touches at the start and is off the cylinder
    at the end, at the simulated final pose; the object is never dropped, and its position and
    rotation each stay within the issue's 5 % of the floor (1 % of the object's size: the plan does
    not move it): 15.5 um, 2.2 % (module docstring). Held at the release's tau_st instead of moving
    to the final grasp's holding torque along the path, the same replay drifts 44.5 um, 6.4 %."""
    p = plan(scene, Goal(type="active"))
    assert p.found and len(p.steps) == 1 and p.steps[0].transition.kind == "release", p.reason
    assert verify_plan(scene, p) == []
    sim = simulate_plan(scene, p)
    assert not sim.dropped, sim.drop_reason
    err = sim.error
    assert err.planned_translation == 0.0 and err.planned_rotation == 0.0
    assert err.relative_rotation <= 0.05, err
    assert err.relative_position <= 0.05, err  # 2.2 % (6.4 % with the torque kept at tau_st)
    assert sim.tolerance == 0.05 and sim.ok
    assert "link release" in sim.steps[0].note
    assert "joint servo" in sim.control and sim.hold_servo_share <= 0.01, (sim.control, sim.hold_servo_share)
    assert "a release's torque goes along its path to the holding torque of the grasp after it" in sim.control
    # the pad box (thumb link 3) touches in MuJoCo at the start and is off the cylinder at the end
    assert sim.start_contacts is not None and "thumb/3" in sim.start_contacts and "thumb/4" in sim.start_contacts
    model = build_model(scene)
    data = mujoco.MjData(model)
    reset_to_scene(model, data)
    final = Pose.from_vector(sim.simulated_final_pose, 3)
    adr = object_qpos_address(model, 3)
    data.qpos[adr: adr + 3] = final.position
    data.qpos[adr + 3: adr + 7] = matrix_to_quat_wxyz(final.rotation)
    assert sim.final_q is not None
    data.qpos[finger_qpos_addresses(model, scene)] = sim.final_q
    mujoco.mj_kinematics(model, data)
    eps = DEFAULT_PARAMS.eps_rel * object_size(scene)
    obj = model.geom("object").id

    def gap(k: int) -> float:
        geoms = _link_geoms(model, "thumb", k)
        return min(mujoco.mj_geomDistance(model, data, g, obj, 1.0, np.zeros(6)) for g in geoms)

    pad, tip = gap(3) - eps, gap(4) - eps
    assert pad > 2e-4, pad  # the plan lifts it 0.37 mm
    assert abs(tip) < 5e-5, tip  # the tip stays on


def test_the_four_tip_grasp_drifts_on_under_torque_control_and_stays_with_a_servo(scene: Scene) -> None:
    """``final_hold`` runs the final grasp on (its holding torque and the posture torque) after the
    last step: the run is that much longer and the final pose is taken after it. Under torque
    control alone (``hold_rate = 0``, the analysis' model) the drift of the module docstring grows
    from 40 um to 0.42 mm within 0.3 s; with the replay's hold servo it is 59 um then, the servo
    carrying about 1 % of the holding torque, the grasp never dropped."""
    p = plan(scene, Goal(type="active"))
    free = PlanSimulationOptions(hold_rate=0.0)
    short = simulate_plan(scene, p, options=free)
    drifting = simulate_plan(scene, p, options=PlanSimulationOptions(hold_rate=0.0, final_hold=0.3))
    held = simulate_plan(scene, p, options=PlanSimulationOptions(final_hold=0.3))
    assert drifting.duration == pytest.approx(short.duration + 0.3, abs=2 * DEFAULT_PARAMS.timestep)
    assert held.object_path.times[-1] == pytest.approx(held.duration)
    assert not drifting.dropped and not held.dropped, (drifting.drop_reason, held.drop_reason)
    assert drifting.error.position > 5 * short.error.position > 0
    assert drifting.error.position > 3e-4
    assert held.error.position < 1e-4 and held.error.position < 0.2 * drifting.error.position
    assert 0.0 < held.hold_servo_share <= 0.02
    with pytest.raises(ValueError, match="final_hold"):
        PlanSimulationOptions(final_hold=-1.0)


def test_the_release_path_presses_the_tip_into_the_cylinder(scene: Scene) -> None:
    """The planned link release keeps the thumb tip's material point where it is (eq. 33 glues it)
    while the tip link turns; the tip is a sphere, so at the end of the path it lies 8.9 um inside
    the cylinder (coal's distance between the URDF shape and the object; the pad box comes 0.37 mm
    off): the second-order push behind the replay's remaining drift."""
    hand = HandKinematics.from_scene(scene)
    p = plan(scene, Goal(type="active"))
    q_end = p.steps[0].transition.q_path[-1]
    refs = [r for r in link_refs(scene, hand) if r.finger == hand.finger_of("thumb/link_15.0_tip")]
    gaps = {d.link.name: d.distance for d in link_distances(scene, hand, q_end, refs)}
    assert -1.2e-5 < gaps["thumb/link_15.0_tip"] < -5e-6
    assert gaps["thumb/link_15.0"] > 3e-4


def test_the_link_release_changes_the_thumbs_holding_torque(scene: Scene) -> None:
    """The torque the replay goes to along the link release: the plan's final holding torque (18,
    at the end of the thumb's path) differs from the release's tau_st (at its start) on the thumb's
    joints only (the other fingers do not move), by 17 % of the thumb's second joint's torque."""
    hand = HandKinematics.from_scene(scene)
    p = plan(scene, Goal(type="active"))
    st = p.steps[0].transition
    assert st.tau_stationary is not None and p.final_tau is not None
    diff = np.asarray(p.final_tau) - np.asarray(st.tau_stationary)  # (M,)
    thumb = hand.finger_slice(hand.finger_of("thumb/link_15.0_tip"))
    others = np.ones(hand.M, dtype=bool)
    others[thumb] = False
    assert np.max(np.abs(diff[others])) < 1e-9
    k = int(np.argmax(np.abs(diff)))
    assert thumb.start <= k < thumb.stop
    assert abs(diff[k]) > 0.1 * abs(float(p.final_tau[k])), (diff, p.final_tau)
