"""The MuJoCo model of a scene (sim/mjcf.py).

Known answers: the MJCF reproduces the scene's kinematics (link end points for random ``q``, also
for URDF fingers) and contact geometry (every scene contact just touching at the scene
configuration, MuJoCo's contact at ``p + eps n``); it has one contact pair per hand body and one
motor per joint, and no gravity.
"""

from __future__ import annotations

from pathlib import Path

import mujoco
import numpy as np
import pytest

from analysis.geometry import object_size
from analysis.kinematics import HandKinematics
from analysis.loader import load_scene
from sim.mjcf import (
    DEFAULT_PARAMS,
    build_mjcf,
    build_model,
    finger_qpos_addresses,
    fixed_geom_name,
    link_body_name,
    link_site_names,
    reset_to_scene,
)

EXAMPLES = Path(__file__).parents[2] / "examples"
PLANAR = EXAMPLES / "planar_disk_envelope.json"
SPHERE = EXAMPLES / "sphere_four_finger_palm.json"
ALLEGRO = EXAMPLES / "allegro_right_box.json"
ALLEGRO_URDF = EXAMPLES / "allegro_cylinder_urdf.json"  # link_geometry urdf: the links' own shapes


def _geom_of(hand: HandKinematics, body: str) -> str:
    ref = hand.resolve_body(body)
    assert ref is not None
    if ref.finger is None:
        return fixed_geom_name(ref.name)
    return link_body_name(hand.fingers[ref.finger].name, ref.link)


# --------------------------------------------------------------------------------------------
# The MJCF is the scene


@pytest.mark.parametrize("path", [PLANAR, SPHERE, ALLEGRO, ALLEGRO_URDF],
                         ids=["planar", "sphere", "allegro-urdf", "allegro-urdf-shapes"])
def test_link_end_points_match_kinematics(path: Path) -> None:
    """MuJoCo's sites at the link ends equal ``HandKinematics.body_segment`` for random ``q``:
    same chain, same joint axes, same ``q`` convention (also for URDF fingers, whose tip links
    hang on fixed joints)."""
    scene = load_scene(path)
    hand = HandKinematics.from_scene(scene)
    model = build_model(scene)
    data = mujoco.MjData(model)
    qadr = finger_qpos_addresses(model, scene)  # (M,)
    rng = np.random.default_rng(7)
    for _ in range(5):
        q = hand.q0 + rng.uniform(-1.5, 1.5, size=hand.M)  # (M,)
        data.qpos[qadr] = q
        mujoco.mj_kinematics(model, data)
        for f in hand.fingers:
            for k, label in enumerate(f.body_names()):
                ref = hand.resolve_body(label)
                assert ref is not None
                a, b = hand.body_segment(ref, q)  # (d,), (d,)
                site_a, site_b = link_site_names(f.name, k)
                np.testing.assert_allclose(data.site(site_a).xpos[: scene.dim], a, atol=1e-12)
                np.testing.assert_allclose(data.site(site_b).xpos[: scene.dim], b, atol=1e-12)
                if scene.dim == 2:  # planar chains stay in the plane
                    assert abs(data.site(site_b).xpos[2]) < 1e-12


@pytest.mark.parametrize("path", [PLANAR, SPHERE], ids=["planar", "sphere"])
def test_scene_configuration_and_contacts_touch(path: Path) -> None:
    """At the keyframe the finger qpos is the scene's q, the object is at its pose, and every
    scene contact is exactly touching: geom distance 0, MuJoCo's contact at ``p + eps n`` with
    normal ``n`` (hand -> object)."""
    scene = load_scene(path)
    hand = HandKinematics.from_scene(scene)
    model = build_model(scene)
    data = mujoco.MjData(model)
    reset_to_scene(model, data)
    np.testing.assert_array_equal(data.qpos[finger_qpos_addresses(model, scene)], hand.q0)
    np.testing.assert_allclose(data.body("object").xpos[: scene.dim], scene.object.pose.position, atol=1e-15)
    eps = DEFAULT_PARAMS.eps_rel * object_size(scene)
    obj = model.geom("object").id
    fromto = np.zeros(6)
    for c in scene.contacts:
        g = model.geom(_geom_of(hand, c.body)).id
        assert abs(mujoco.mj_geomDistance(model, data, g, obj, 1.0, fromto)) < 1e-9
        p, n = np.zeros(3), np.zeros(3)
        p[: scene.dim], n[: scene.dim] = c.point, c.normal
        found = []
        for i in range(data.ncon):
            con = data.contact[i]
            if {int(con.geom1), int(con.geom2)} == {g, obj}:
                sign = 1.0 if int(con.geom2) == obj else -1.0
                found.append((np.array(con.pos), sign * con.frame[:3]))
        assert len(found) == 1, c.body
        pos, normal = found[0]
        np.testing.assert_allclose(pos, p + eps * n, atol=1e-9)
        np.testing.assert_allclose(normal, n, atol=1e-9)


def test_mjcf_is_text_with_pairs_and_motors() -> None:
    scene = load_scene(PLANAR)
    xml = build_mjcf(scene)
    assert xml.count("<pair ") == 1 + 4  # palm + every link
    assert xml.count("<motor ") == 4
    assert 'gravity="0 0 0"' in xml
