"""Physics cross-check in MuJoCo (sim/torque_replay.py).

Known answers (the MJCF itself: ``test_mjcf.py``; the report: ``test_report.py``): a disk left
alone on the palm stays put with the palm carrying its weight; a stationary grasp (eq. 18) from
:mod:`analysis.stationary` holds the object still with every loaded contact sticking, and the
contact forces MuJoCo reports balance both the external wrench and the joint torques; pushes
whose quasi-static answer is known in closed form (pure translation; sliding on the palm with
kinetic friction ``mu N``) move the object in that direction, in 2-D and 3-D.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from analysis._types import Array
from analysis.contacts import build_system, selection
from analysis.exceptions import CombinationError, SceneError
from analysis.friction import friction_set
from analysis.geometry import object_size
from analysis.loader import load_scene, scene_from_dict
from analysis.scene import Scene
from analysis.statics import statics
from analysis.stationary import stationary_grasp
from sim.mjcf import damping
from sim.report import format_report
from sim.torque_replay import simulate_torques

EXAMPLES = Path(__file__).parents[2] / "examples"
PLANAR = EXAMPLES / "planar_disk_envelope.json"
SPHERE = EXAMPLES / "sphere_four_finger_palm.json"


# --------------------------------------------------------------------------------------------
# Statics


def test_torque_free_fingers_disk_rests_on_palm() -> None:
    """Zero joint torques, gravity -y: the palm carries the weight, the fingers carry nothing
    (they are free to yield), the disk does not sink (only the contact's elastic penetration)."""
    scene = load_scene(PLANAR)
    r = simulate_torques(scene, np.zeros(4), duration=0.2, combination="DDDDF")
    assert not r.dropped
    assert abs(r.dr[1]) < 1e-4 * object_size(scene)
    assert np.linalg.norm(r.dr) < 1e-4 * object_size(scene)
    palm = r.contacts[4]
    assert palm.observed == "stick"
    np.testing.assert_allclose(palm.mean_force, [0.0, 1.0], atol=1e-3)
    assert all(c.observed == "separate" and c.mean_normal_force < 1e-3 for c in r.contacts[:4])
    assert r.agrees


def _stationary_tau(scene: Scene, combination: str) -> Array:
    system = build_system(scene)
    sel = selection(system, combination)
    st = statics(system, sel)
    return stationary_grasp(system, sel, st, friction_set(system, sel)).tau  # (M,)


@pytest.mark.parametrize("path", [PLANAR, SPHERE], ids=["planar", "sphere"])
def test_stationary_grasp_holds_still(path: Path) -> None:
    """tau_st from eq. (18) (all contacts F): the object stays put, every contact sticks, and
    the forces MuJoCo applies balance the external wrench (G f = -w_ex) and the joint torques
    (J^T f = tau)."""
    scene = load_scene(path)
    system = build_system(scene)
    comb = "F" * system.L
    tau = _stationary_tau(scene, comb)
    duration = 0.3
    r = simulate_torques(scene, tau, duration=duration, combination=comb)
    s = object_size(scene)
    assert not r.dropped
    assert np.linalg.norm(r.dr) < 1e-4 * s  # contact deformation only
    drift = np.linalg.norm(r.displacement_between(duration / 2)) / (duration / 2)
    assert drift < 1e-4 * s  # per second, once loaded
    assert r.agrees, format_report(r)
    f = np.concatenate([c.mean_force for c in r.contacts])  # (L d,)
    scale = max(1.0, float(np.abs(tau).max()))
    np.testing.assert_allclose(system.G @ f, -system.w_ex, atol=1e-3 * scale)
    np.testing.assert_allclose(system.J.T @ f, tau, atol=2e-3 * scale)
    assert not r.extra_contacts


# --------------------------------------------------------------------------------------------
# Pushing: closed-form quasi-static answers

MU = 0.5
PUSH = 2.0  # pusher force at the start (|tau| / lever)
LEVER = 0.4  # base -> contact along the pusher link
PUSH_TIME = 0.02  # s: the ramp (0.01 s), then about 0.01 of motion (2 % of the object size)


def _push_scene(dim: int, mu_pusher: float, mu_palm: float, retractor: bool = False) -> tuple[Scene, Array]:
    """A disk/sphere of radius 0.5 on a palm (gravity 1) and a one-link pusher whose link is
    tangent to the object at its equator on the -x side (contact normal +x through the centre);
    optionally a retractor on the +x side. Returns the scene and the torques: the pusher presses
    with ``PUSH``, the retractor pulls away."""
    if dim == 2:
        fingers = [
            {
                "name": "pusher",
                "base": {"position": [-0.5, 0.1], "angle": np.pi / 2},
                "links": [{"length": 0.8}],
                "q": [0.0],
            }
        ]
        contacts = [{"body": "pusher/0", "point": [-0.5, 0.5], "normal": [1, 0], "mu": mu_pusher}]
        if retractor:
            fingers.append(
                {
                    "name": "retractor",
                    "base": {"position": [0.5, 0.1], "angle": np.pi / 2},
                    "links": [{"length": 0.8}],
                    "q": [0.0],
                }
            )
            contacts.append({"body": "retractor/0", "point": [0.5, 0.5], "normal": [-1, 0], "mu": MU})
        contacts.append({"body": "palm", "point": [0, 0], "normal": [0, 1], "mu": mu_palm})
        data = {
            "dim": 2,
            "object": {"pose": {"position": [0, 0.5], "angle": 0.0}, "shape": {"type": "disk", "radius": 0.5}},
            "external_wrench": [0, -1, 0],
            "fixed_bodies": [{"name": "palm", "shape": {"type": "segment", "points": [[-1, 0], [1, 0]]}}],
            "fingers": fingers,
            "contacts": contacts,
        }
        tau = [-PUSH * LEVER] + ([-0.2] if retractor else [])  # negative: clockwise
    else:
        assert not retractor
        data = {
            "dim": 3,
            "object": {
                "pose": {"position": [0, 0, 0.5], "quat_wxyz": [1, 0, 0, 0]},
                "shape": {"type": "sphere", "radius": 0.5},
            },
            "external_wrench": [0, 0, -1, 0, 0, 0],
            "fixed_bodies": [
                {"name": "palm", "shape": {"type": "box", "size": [2, 2, 0.02], "position": [0, 0, -0.01]}}
            ],
            "fingers": [
                {
                    "name": "pusher",
                    "base": {"position": [-0.5, 0, 0.1]},
                    "joints": [{"axis": [0, 1, 0], "origin": [0, 0, 0]}],
                    "tip": [0, 0, 0.8],
                    "q": [0.0],
                }
            ],
            "contacts": [
                {"body": "pusher/0", "point": [-0.5, 0, 0.5], "normal": [1, 0, 0], "mu": mu_pusher},
                {"body": "palm", "point": [0, 0, 0], "normal": [0, 0, 1], "mu": mu_palm},
            ],
        }
        tau = [PUSH * LEVER]  # rotation about +y moves the link's upper part to +x
    scene = scene_from_dict(data)
    # the torques are J^T f of the intended push
    system = build_system(scene)
    f = np.zeros(system.L * system.d)
    f[0] = PUSH
    np.testing.assert_allclose((system.J.T @ f)[0], tau[0], atol=1e-12)
    return scene, np.array(tau)


@pytest.mark.parametrize("dim", [2, 3])
def test_push_on_frictionless_palm_translates(dim: int) -> None:
    """Sticking pusher, frictionless palm: every force passes through the centre and the pushed
    point moves along +x, so the object translates along +x (first order); the pusher sticks
    (F) and the palm slides (N)."""
    scene, tau = _push_scene(dim, mu_pusher=MU, mu_palm=0.0)
    r = simulate_torques(scene, tau, duration=PUSH_TIME, combination="FN")
    ex = np.zeros(scene.D)
    ex[0] = 1.0
    assert r.cosine(ex) > 0.99, r.dr
    assert 0.005 < r.dr[0] < 0.05  # it moved, a little
    assert r.agrees, format_report(r)
    assert [c.observed for c in r.contacts] == ["stick", "slide"]
    assert not r.dropped


@pytest.mark.parametrize("dim", [2, 3])
def test_push_sliding_on_palm_matches_kinetic_friction(dim: int) -> None:
    """Frictionless pusher, palm with mu = 0.5: the push (2) exceeds what rolling could take
    (rolling needs palm friction 0.8 * push > mu N), so the object slides on the palm against
    kinetic friction mu N = 0.5 at the palm point, which also turns it:
    ``b_r v = push - mu N`` and ``b_r omega = -(r x mu N e_x) = -r mu N`` about the rolling axis.
    The pusher's torque is also spent on its joint damping, ``b_q v / lever^2``."""
    scene, tau = _push_scene(dim, mu_pusher=0.0, mu_palm=MU)
    r = simulate_torques(scene, tau, duration=PUSH_TIME, combination="NS")
    b = r.damping
    assert b is not None and b == damping(scene, tau)
    v = (PUSH - MU * 1.0) / (b.object_damping + b.finger_damping / LEVER**2)
    omega = 0.5 * MU * 1.0 / b.object_damping  # magnitude, rolling sense
    expected = np.zeros(scene.D)
    expected[0] = v
    if dim == 2:
        expected[2] = -omega  # clockwise about z
    else:
        expected[4] = omega  # about +y
    assert r.cosine(expected) > 0.999, (r.dr, expected)
    assert r.agrees, format_report(r)
    assert r.contacts[1].observed == "slide"
    assert r.contacts[1].slip > 0.5 * r.contacts[1].travel
    # kinetic friction at the palm: tangential force mu n against the motion
    f_palm = r.contacts[1].mean_force
    assert f_palm[0] == pytest.approx(-MU * f_palm[-1], rel=0.02)


def test_retracting_finger_separates() -> None:
    """A second finger pulled away from the object separates (D) while the pusher pushes."""
    scene, tau = _push_scene(2, mu_pusher=MU, mu_palm=0.0, retractor=True)
    r = simulate_torques(scene, tau, duration=PUSH_TIME, combination="FDN")
    assert [c.observed for c in r.contacts] == ["stick", "separate", "slide"], format_report(r)
    assert r.contacts[1].final_gap > 1e-3
    assert r.agrees
    assert r.cosine([1.0, 0.0, 0.0]) > 0.99


def test_disagreement_is_reported() -> None:
    """The sliding push declared as if the palm stuck: the palm contact disagrees."""
    scene, tau = _push_scene(2, mu_pusher=0.0, mu_palm=MU)
    r = simulate_torques(scene, tau, duration=PUSH_TIME, combination="NF")
    assert r.contacts[1].observed == "slide"
    assert r.contacts[1].agrees is False
    assert r.agrees is False
    assert "DISAGREE" in format_report(r)


# --------------------------------------------------------------------------------------------
# Dropping, inputs


def test_object_pulled_away_is_dropped() -> None:
    scene_data = load_scene(PLANAR).model_dump()
    scene_data["external_wrench"] = [0.0, 1.0, 0.0]  # pulls the disk off the palm
    scene_data["fingers"] = []
    scene_data["contacts"] = [scene_data["contacts"][4]]
    scene = scene_from_dict(scene_data)
    r = simulate_torques(scene, np.zeros(0), duration=0.05, combination="D")
    assert r.dropped and "contacts" in r.drop_reason
    assert r.dr[1] > 0.01
    assert r.contacts[0].observed == "separate"


def test_early_stop_at_distance() -> None:
    scene, tau = _push_scene(2, mu_pusher=MU, mu_palm=0.0)
    r = simulate_torques(scene, tau, duration=1.0, stop_distance=0.01)
    assert r.stopped_early and r.duration < 1.0
    assert 0.01 < np.linalg.norm(r.dr) < 0.012


def test_bad_inputs() -> None:
    scene = load_scene(PLANAR)
    with pytest.raises(SceneError, match="tau"):
        simulate_torques(scene, np.zeros(3), duration=0.01)
    with pytest.raises(SceneError, match="duration"):
        simulate_torques(scene, np.zeros(4), duration=0.0)
    with pytest.raises(CombinationError):
        simulate_torques(scene, np.zeros(4), duration=0.01, combination="FFF")
