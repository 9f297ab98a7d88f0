"""The contact manifold: its Jacobian against finite differences, its tangent space against the
motion space of the analysis (eq. 7), planar and spatial."""

from __future__ import annotations

import numpy as np
from closure_helpers import EXAMPLES
from scipy.linalg import null_space

from analysis.kinematics import HandKinematics
from analysis.loader import load_scene
from analysis.scene import Scene
from planner.manifold import ContactManifold
from planner.state import StateAnalysis, state_from_scene


def test_contact_manifold_jacobian_and_tangent_space(planar_scene: Scene, motion_step) -> None:  # type: ignore[no-untyped-def]
    """F'(x) equals central finite differences away from the start, F(x0) = 0, and at the start
    the tangent space null(F'(x0)) is the paper's motion space null(A_c) = span(Lambda) (eq. 7)."""
    hand = HandKinematics.from_scene(planar_scene)
    step, sticking, _ = motion_step
    before = step.before
    man = ContactManifold(hand, before, sticking)
    x0 = np.concatenate([before.q, np.zeros(man.D)])
    assert float(np.linalg.norm(man.function(x0))) < 1e-12
    rng = np.random.default_rng(3)
    for _ in range(3):
        x = x0 + 0.05 * rng.standard_normal(len(x0))
        J = man.jacobian(x)  # (d n, M + D)
        Jn = np.column_stack([(man.function(x + e) - man.function(x - e)) / 2e-6
                              for e in 1e-6 * np.eye(len(x))])
        np.testing.assert_allclose(J, Jn, atol=1e-7)
    N = null_space(man.jacobian(x0))
    Lam = StateAnalysis.of(planar_scene, before, hand).parts(step.transition.combination).ms.Lambda
    assert N.shape[1] == Lam.shape[1]
    np.testing.assert_allclose(N @ N.T, Lam @ Lam.T, atol=1e-9)


def test_spatial_manifold_jacobian_matches_finite_differences() -> None:
    """The 3-D rotation part: d(exp(w) y)/dw = -[exp(w) y]x J_l(w), at random w."""
    scene = load_scene(EXAMPLES / "sphere_four_finger_palm.json")
    hand = HandKinematics.from_scene(scene)
    st = state_from_scene(scene, hand)
    man = ContactManifold(hand, st, list(range(st.L)))
    rng = np.random.default_rng(4)
    x0 = np.concatenate([st.q, np.zeros(man.D)])
    assert float(np.linalg.norm(man.function(x0))) < 1e-9
    for scale in (1e-3, 0.3, 1.5):
        x = x0 + scale * rng.standard_normal(len(x0))
        Jn = np.column_stack([(man.function(x + e) - man.function(x - e)) / 2e-7
                              for e in 1e-7 * np.eye(len(x))])
        np.testing.assert_allclose(man.jacobian(x), Jn, atol=1e-6)



def test_planar_function_and_jacobian_equal_the_generic_ones() -> None:
    """For planar serial chains F' is assembled in float arithmetic from the joints' positions
    (``_jacobian_planar``) and, without sliding contacts, F too (``_function_planar``, its own
    forward kinematics); they equal the generic evaluation (``HandKinematics``' forward kinematics
    and point Jacobians) to round-off, with glued and rolling contacts, a disk sliding on the
    palm, with and without the direction rows, at random points; a spatial hand has no planar path."""
    scene = load_scene(EXAMPLES / "planar_disk_envelope.json")
    hand = HandKinematics.from_scene(scene)
    st = state_from_scene(scene, hand)
    palm = [i for i, c in enumerate(st.contacts) if c.body == "palm"]
    fingers = [i for i in range(st.L) if i not in palm]
    rng = np.random.default_rng(8)
    cases = [dict(sticking=list(range(st.L))), dict(sticking=fingers, rolling=True),
             dict(sticking=fingers, sliding=palm, rolling=True, direction=np.array([0.0, 1.0, 0.0])),
             dict(sticking=fingers[:2], sliding=palm, direction=np.array([0.3, 1.0, -0.2]))]
    for case in cases:
        man = ContactManifold(hand, st, scene=scene, **case)  # type: ignore[arg-type]
        assert man._z_axes is not None
        x0 = np.concatenate([st.q, np.zeros(man.D)])
        for _ in range(5):
            x = x0 + 0.05 * rng.standard_normal(len(x0))
            J, F = man.jacobian(x), man.function(x)
            z, man._z_axes = man._z_axes, None
            J_generic, F_generic = man.jacobian(x), man.function(x)
            man._z_axes = z
            np.testing.assert_allclose(J, J_generic, rtol=0, atol=1e-14)
            np.testing.assert_allclose(F, F_generic, rtol=0, atol=1e-15)
    spatial = load_scene(EXAMPLES / "sphere_four_finger_palm.json")
    sh = HandKinematics.from_scene(spatial)
    assert ContactManifold(sh, state_from_scene(spatial, sh), [0])._z_axes is None
