"""The contact tracker: what each scene contact did in a MuJoCo run (stick, slide or separate).

:class:`ContactTracker` reads MuJoCo's contacts with the object after every sampled step and
records, per scene contact, normal force, force, slip and travel; :meth:`ContactTracker.statistics`
averages them over the evaluated samples and :func:`observed_states` classifies each contact.
The expected states of a combination's letters (the paper's F, S, D, N, eq. 4-7) are
:data:`sim.torque_replay.EXPECTED_STATE`.

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

"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np
from numpy.typing import NDArray

from analysis._types import Array
from analysis.geometry import object_origin, object_rotation, object_size
from analysis.kinematics import HandKinematics
from analysis.scene import Scene
from sim.mjcf import OBJECT_BODY, OBJECT_GEOM, SimulationParams, fixed_geom_name, geom_of_contact, link_body_name


@dataclass(frozen=True)
class ContactStatistics:
    """Per scene contact, over the evaluated samples (:meth:`ContactTracker.window`)."""

    mean_normal: Array  # (L,) time average of n . f (0 while not touching)
    mean_force: Array  # (L, d) time average of the force the hand applies on the object, world
    max_normal: Array  # (L,)
    loaded_fraction: Array  # (L,) fraction of samples with a positive normal force
    slip: Array  # (L,) path length of the tangential relative motion of the material points
    travel: Array  # (L,) path length of the faster of the two material points
    typical_penetration: float  # median of the deepest penetration of a loaded contact per sample
    extra: dict[str, float]  # mean normal force of bodies without a scene contact, by body name


def _cross(a: Array, b: Array) -> Array:
    """Row-wise ``a x b`` of ``(3,)`` or ``(k, 3)`` arrays (``np.cross`` is slow on small arrays)."""
    a1, a2, a3 = a[..., 0], a[..., 1], a[..., 2]
    b1, b2, b3 = b[..., 0], b[..., 1], b[..., 2]
    return np.stack([a2 * b3 - a3 * b2, a3 * b1 - a1 * b3, a1 * b2 - a2 * b1], axis=-1)



class ContactTracker:
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
                body = model.body(link_body_name(fm.name, k)).id
                for g in np.flatnonzero(model.geom_bodyid == body):  # the capsule, or every URDF shape
                    self.name_of_geom[int(g)] = label
        # rigid piece of every geom: -1 - geom for static geoms, the weld id for the others
        weld = model.body_weldid[model.geom_bodyid]  # (ngeom,)
        self.piece = np.where(weld == 0, -1 - np.arange(model.ngeom), weld)  # (ngeom,)
        fixed = {fixed_geom_name(fb.name) for fb in scene.fixed_bodies}

        def piece_of(name: str) -> int:  # a fixed body's geom, or a link's body (any of its geoms)
            if name in fixed:
                return int(self.piece[model.geom(name).id])
            return int(model.body_weldid[model.body(name).id])

        self.contact_piece = np.array([piece_of(geom_of_contact(hand, c.body)) for c in scene.contacts],
                                      dtype=int)  # (L,)
        self.n_on_piece = {int(p): int(np.sum(self.contact_piece == p)) for p in self.contact_piece}
        # each hand geom's pair margin with the object (a URDF collision shape's: eps, sim.mjcf):
        # its own surface is that far inside the distance MuJoCo reports
        self.margin = np.zeros(model.ngeom)  # (ngeom,)
        for p in range(model.npair):
            g1, g2 = int(model.pair_geom1[p]), int(model.pair_geom2[p])
            self.margin[g1 if g2 == self.obj_geom else g2] = float(model.pair_margin[p])
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
        # penetration of the contact's own surfaces: MuJoCo's distance less the pair's margin
        # (a URDF collision shape's pair has margin eps, sim.mjcf)
        self.penetration.append(float(-np.min(con.dist[idx] - con.includemargin[idx], initial=0.0)))
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
        (negative: penetration; a geom's pair margin taken off MuJoCo's distance). For a piece with
        one scene contact, the smallest geom distance; with several, the distance of the MuJoCo
        contacts assigned to each (at least the detection distance when none is assigned)."""
        model, L = self.model, self.L
        fromto = np.zeros(6)
        dist_geom = {
            g: float(mujoco.mj_geomDistance(model, data, g, self.obj_geom, self.s, fromto)) - self.margin[g]
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
                con = data.contact
                local[i] = min(local[i], float(con.dist[idx[r]] - con.includemargin[idx[r]]))
        detect = self.params.detect_rel * self.s
        for i in range(L):
            if self.n_on_piece[int(self.contact_piece[i])] >= 2:
                gaps[i] = local[i] if np.isfinite(local[i]) else max(gaps[i], detect)
        return gaps

    def statistics(self, t_from: float) -> ContactStatistics:
        """Means, maxima and path lengths of the samples of :meth:`window` ``(t_from)``."""
        L, dim = self.L, self.dim
        win = self.window(t_from)  # (n,)
        nf = max(int(win.sum()), 1)
        normal = np.array(self.normal).reshape(-1, L)[win]  # (nf, L)
        extra: dict[str, float] = {}
        for k in np.flatnonzero(win):
            for name, fn in self.extra[k].items():
                extra[name] = extra.get(name, 0.0) + fn / nf
        pens = np.asarray(self.penetration)[win]
        return ContactStatistics(
            mean_normal=normal.sum(axis=0) / nf,
            mean_force=np.array(self.force).reshape(-1, L, 3)[win].sum(axis=0)[:, :dim] / nf,
            max_normal=normal.max(axis=0, initial=0.0),
            loaded_fraction=(normal > 0).sum(axis=0) / nf,
            slip=np.array(self.slip).reshape(-1, L)[win].sum(axis=0),
            travel=np.array(self.travel).reshape(-1, L)[win].sum(axis=0),
            typical_penetration=float(np.median(pens)) if len(pens) else 0.0,
            extra=extra,
        )


def observed_states(stats: ContactStatistics, final_gap: Array, external_force: float, s: float,
                    params: SimulationParams) -> tuple[str, ...]:
    """``'separate'``, ``'slide'`` or ``'stick'`` per scene contact (the rules of the module
    docstring); ``final_gap`` ``(L,)`` from :meth:`ContactTracker.final_gaps`, ``external_force``
    the norm of the external wrench's force part, ``s`` the object size."""
    mean_normal, slip, travel = stats.mean_normal, stats.slip, stats.travel
    L = len(mean_normal)
    f_ref = max(float(np.max(mean_normal)) if L else 0.0, external_force)
    out = []
    for i in range(L):
        if final_gap[i] > params.gap_tol_rel * s or mean_normal[i] <= params.force_tol_rel * f_ref:
            observed = "separate"
        elif slip[i] > max(
            params.slip_tol_rel * travel[i],
            params.slip_abs_rel * s,
            params.slip_pen_factor * stats.typical_penetration,
        ):
            observed = "slide"
        else:
            observed = "stick"
        out.append(observed)
    return tuple(out)


__all__ = ["ContactStatistics", "ContactTracker", "observed_states"]
