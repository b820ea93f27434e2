"""Arms kept clear of the legs on a walk with the robot's own steps.

The robot's own walk (:mod:`.gait`) replaces the legs of a retargeted motion and keeps its upper
body. The human's arms swing in time with the human's legs; the robot's legs step at their own
cadence, crouched, with thicker thighs. On the identified OP3, 4 of 6 real walks measured drove a
forearm 16-32 mm into its own thigh or knee in the plan; in physics the servos then pushed the
forearm against the leg at their torque limit (the shoulder pitch saturated for 0.9 s of a
CMU walk) and the clip failed ``torque``.

:func:`keep_arms_clear` moves each arm, by its own joints only, until every collision geom of
it stays ``clearance_m`` away from every collision geom of the legs:

* per frame, a few Gauss-Newton steps on the signed distances that are too small
  (``mujoco.mj_geomDistance``, finite-difference derivatives over the arm's joints, the smallest
  joint change that restores them), inside the joint ranges;
* over time, each joint's correction is held for ``window_s`` either side of where it is
  needed and eased in and out over another ``window_s`` (a raised-cosine smoothing), so the arm
  moves away and back gradually; frames that still come closer than the clearance after
  smoothing get another pass.

"Arm": a body outside the legs (the chains from the soles up to the base) whose chain up to the
base has hinge joints, with collision geoms, that can reach a leg body. The legs are not moved:
they carry the walk.
"""

from __future__ import annotations

import mujoco
import numpy as np

from motok_robot.robots.collision import collision_capable_geoms


def _leg_bodies(index) -> set[int]:
    model = index.kin_model
    bodies = set()
    for body in index.sole_body:
        b = int(body)
        while b > 0 and b != index.root_body:
            bodies.add(b)
            b = int(model.body_parentid[b])
    return bodies


def _chain_qpos(model, body: int, root: int, legs: set[int]) -> list[int]:
    """qpos addresses of the hinges from ``body`` up to (not including) ``root``."""
    qadr = []
    b = body
    while b > 0 and b != root and b not in legs:
        for jid in range(model.body_jntadr[b], model.body_jntadr[b] + model.body_jntnum[b]):
            if model.jnt_type[jid] == mujoco.mjtJoint.mjJNT_HINGE:
                qadr.append(int(model.jnt_qposadr[jid]))
        b = int(model.body_parentid[b])
    return qadr


class ArmLegPairs:
    """The collision geom pairs (arm geom, leg geom) of a robot, grouped by arm chain."""

    def __init__(self, index):
        model = index.kin_model
        legs = _leg_bodies(index)
        capable = collision_capable_geoms(model)
        leg_geoms = [g for g in range(model.ngeom) if capable[g] and int(model.geom_bodyid[g]) in legs]
        ignored = getattr(index, "ignored_body_pairs", set()) or set()
        arm, leg, group = [], [], []
        chains: dict[tuple, int] = {}
        for g in range(model.ngeom):
            b = int(model.geom_bodyid[g])
            if not capable[g] or b == 0 or b in legs or b == index.root_body:
                continue
            joints = tuple(_chain_qpos(model, b, index.root_body, legs))
            if not joints:
                continue
            for h in leg_geoms:
                if (min(b, int(model.geom_bodyid[h])), max(b, int(model.geom_bodyid[h]))) in ignored:
                    continue
                arm.append(g)
                leg.append(h)
                group.append(chains.setdefault(joints, len(chains)))
        self.model = model
        self.arm, self.leg, self.group = np.array(arm, dtype=int), np.array(leg, dtype=int), np.array(group, dtype=int)
        #: per group: the qpos addresses of its arm chain's joints
        self.joints = [np.array(j, dtype=int) for j, _ in sorted(chains.items(), key=lambda kv: kv[1])]
        self._rbound = model.geom_rbound[self.arm] + model.geom_rbound[self.leg]

    def distances(self, data, reach: float, which: np.ndarray | None = None) -> np.ndarray:
        """Signed distance (m) of each pair (or of the pairs ``which``) at the pose in ``data``,
        capped at ``reach``."""
        which = np.arange(self.arm.size) if which is None else which
        out = np.full(which.size, reach)
        # broad phase: bounding spheres farther apart than reach cannot come closer
        gap = np.linalg.norm(data.geom_xpos[self.arm[which]] - data.geom_xpos[self.leg[which]], axis=1) - self._rbound[which]
        for i in np.nonzero(gap < reach)[0]:
            out[i] = mujoco.mj_geomDistance(self.model, data, int(self.arm[which[i]]), int(self.leg[which[i]]), reach, None)
        return out


def _spread(values: np.ndarray, window: int) -> np.ndarray:
    """[T] non-negative needs -> a smooth envelope at least as large: the largest need within
    ``window`` frames, smoothed with a raised-cosine kernel of the same half-width."""
    T = values.shape[0]
    if window < 1 or not values.any():
        return values
    spread = np.array([values[max(0, t - window):t + window + 1].max() for t in range(T)])
    kernel = 0.5 * (1 + np.cos(np.pi * np.arange(-window, window + 1) / (window + 1)))
    kernel /= kernel.sum()
    smooth = np.convolve(np.pad(spread, window, mode="edge"), kernel, mode="valid")
    return np.maximum(smooth, values)


def keep_arms_clear(index, qpos: np.ndarray, fps: float, clearance_m: float, *, window_s: float = 0.25,
                    iterations: int = 8, passes: int = 10) -> tuple[np.ndarray, dict]:
    """``qpos`` [T, nq] with the arms moved where they come closer than ``clearance_m`` to the
    legs, and a record: frames that needed it before and after, the largest joint correction
    (rad), the closest approach before and after (m)."""
    qpos = np.asarray(qpos, dtype=np.float64).copy()
    T = qpos.shape[0]
    pairs = ArmLegPairs(index)
    model = pairs.model
    data = mujoco.MjData(model)
    reach = 2.0 * clearance_m
    low = np.full(model.nq, -np.inf)
    high = np.full(model.nq, np.inf)
    for j in range(model.njnt):
        if model.jnt_type[j] == mujoco.mjtJoint.mjJNT_HINGE and model.jnt_limited[j]:
            low[model.jnt_qposadr[j]], high[model.jnt_qposadr[j]] = model.jnt_range[j]
    window = max(1, int(round(window_s * fps)))

    def closest(q_all) -> tuple[np.ndarray, float]:
        """Frames closer than the clearance, and the closest approach."""
        close = np.zeros(T, dtype=bool)
        nearest = reach
        for t in range(T):
            data.qpos[:] = q_all[t]
            mujoco.mj_kinematics(model, data)
            d = pairs.distances(data, reach)
            nearest = min(nearest, float(d.min(initial=reach)))
            close[t] = bool((d < clearance_m - 1e-4).any())
        return close, nearest

    close_before, nearest_before = closest(qpos)
    correction = np.zeros_like(qpos)
    close = close_before
    for done in range(passes):
        if done:
            close, _ = closest(qpos + correction)
        if not close.any():
            break
        need = np.zeros_like(qpos)
        for t in np.nonzero(close)[0]:
            q = qpos[t] + correction[t]
            for group, adr in enumerate(pairs.joints):
                mine = np.nonzero(pairs.group == group)[0]
                start = q[adr].copy()
                for _ in range(iterations):
                    data.qpos[:] = q
                    mujoco.mj_kinematics(model, data)
                    d = pairs.distances(data, reach, mine)
                    short = clearance_m - d
                    active = short > 1e-4
                    if not active.any():
                        break
                    jac = np.zeros((int(active.sum()), adr.size))
                    for k, a in enumerate(adr):  # finite differences over the arm's joints
                        saved = q[a]
                        q[a] = saved + 1e-4
                        data.qpos[:] = q
                        mujoco.mj_kinematics(model, data)
                        jac[:, k] = (pairs.distances(data, reach, mine[active]) - d[active]) / 1e-4
                        q[a] = saved
                    step = jac.T @ np.linalg.solve(jac @ jac.T + 1e-6 * np.eye(jac.shape[0]), short[active])
                    q[adr] = np.clip(q[adr] + np.clip(step, -0.1, 0.1), low[adr], high[adr])
                need[t, adr] = q[adr] - start
        for a in np.nonzero(np.abs(need).max(axis=0) > 0)[0]:
            correction[:, a] += _spread(np.maximum(need[:, a], 0), window) - _spread(np.maximum(-need[:, a], 0), window)
        correction = np.clip(qpos + correction, low, high) - qpos
    close_after, nearest_after = closest(qpos + correction)
    record = {"clearance_m": clearance_m, "frames_before": int(close_before.sum()),
              "frames_after": int(close_after.sum()), "closest_before_m": nearest_before,
              "closest_after_m": nearest_after, "max_correction_rad": float(np.abs(correction).max())}
    return qpos + correction, record


def clearance_note(record: dict | None) -> str:
    """``", arms moved off the legs on N frames ..."`` for a run's notes (empty when they were not)."""
    if not record or not record.get("frames_before"):
        return ""
    return (f", arms moved off the legs on {record['frames_before']} frames (up to "
            f"{record['max_correction_rad']:.2f} rad, kept {record['clearance_m'] * 100:.1f} cm away)")
