"""The drafted nominal standing pose: knees bent, hip and ankle pitch solved for flat soles with the
ankles under the hips, arms lowered when the zero pose holds them out."""

from __future__ import annotations

import math

import numpy as np

#: knee bend of the drafted nominal pose, rad
KNEE_BEND = 0.4
#: angle between a lowered upper arm and the vertical, rad (outwards)
ARM_HANG = 0.15


class NominalPose:
    """:meth:`nominal_pose` of a :class:`~motok_robot.robots.draft.drafter.Drafter` (a mixin: it
    reads the sites, soles, joint roles and ranges and sets ``nominal_notes``)."""

    def nominal_pose(self) -> dict[str, float]:
        M, m = self.M, self.M.m
        from scipy.optimize import least_squares

        pose: dict[int, float] = {}
        q0 = M.q0.copy()

        def qp(j):
            return m.jnt_qposadr[j]

        def set_q(assign):
            q = q0.copy()
            for j, v in assign.items():
                q[qp(j)] = v
            M.set_pose(q)

        notes = []
        bent = {}
        if self.knee_bend > 0:
            for side, roles in self.roles.items():
                hip_j, knee_j, ankle_j = roles["hip"], roles["knee"], roles["ankle"]
                foot = self.feet[side]
                hip_b = m.jnt_bodyid[hip_j]
                set_q({})
                R0 = M.d.xmat[foot].reshape(3, 3).copy()
                p_hip0 = M.d.xpos[hip_b].copy()
                ank0 = M.d.xpos[foot].copy() - p_hip0
                best = None
                for sign in (1.0, -1.0):
                    k = sign * self.knee_bend
                    lo, hi = self.joint_range(knee_j)
                    if not lo <= k <= hi:
                        continue

                    def resid(x):
                        set_q({hip_j: x[0], knee_j: k, ankle_j: x[1]})
                        R = M.d.xmat[foot].reshape(3, 3)
                        rel = R0.T @ R
                        ank = M.d.xpos[foot] - M.d.xpos[hip_b]
                        return [rel[0, 2] - rel[2, 0], (ank[0] - ank0[0])]

                    bounds = list(zip(self.joint_range(hip_j), self.joint_range(ankle_j)))
                    try:
                        sol = least_squares(resid, [0.0, 0.0], bounds=bounds)
                    except ValueError:
                        continue
                    set_q({hip_j: sol.x[0], knee_j: k, ankle_j: sol.x[1]})
                    knee_x = M.d.xpos[m.jnt_bodyid[knee_j], 0] - M.d.xpos[hip_b, 0]
                    ok = np.max(np.abs(sol.fun)) < 1e-4
                    if ok and knee_x > 0 and (best is None or knee_x > best[0]):
                        best = (knee_x, {hip_j: float(sol.x[0]), knee_j: k, ankle_j: float(sol.x[1])})
                if best is None:
                    notes.append(f"{side} leg: no flat-sole knee bend of {self.knee_bend} rad found")
                else:
                    bent.update(best[1])
            if len(bent) == 6:
                pose.update(bent)
            else:
                notes.append("the nominal pose keeps the legs straight")
        # arms: lower them to hang ARM_HANG from the body when the zero pose holds them out
        for side, (chain, groups) in self.arms.items():
            sign = 1.0 if side == "left" else -1.0
            sh, el = self.points[f"{side}_shoulder"], self.points[f"{side}_elbow"]
            v = (el - sh) / np.linalg.norm(el - sh)
            target = np.array([0.0, sign * math.sin(ARM_HANG), -math.cos(ARM_HANG)])
            if np.dot(v, target) > math.cos(0.3):
                continue
            best = (math.acos(np.clip(np.dot(v, target), -1, 1)), None, 0.0)
            elbow_body = m.jnt_bodyid[groups[1].joints[0]]
            for j in groups[0].joints:
                lo, hi = self.joint_range(j)
                for a in np.linspace(lo, hi, int((hi - lo) / 0.01) + 2):
                    set_q({j: a})
                    # the elbow point moves with the elbow body
                    p = M.d.xmat[elbow_body].reshape(3, 3) @ self._local(elbow_body, el) + M.d.xpos[elbow_body]
                    u = p - self._world_of("shoulder", side)
                    u = u / max(np.linalg.norm(u), 1e-9)
                    err = math.acos(np.clip(np.dot(u, target), -1, 1))
                    if err < best[0] - 1e-6:
                        best = (err, j, float(a))
            if best[1] is not None:
                pose[best[1]] = round(best[2], 3)
            else:
                notes.append(f"{side} arm: no single shoulder joint lowers it")
        set_q(pose)
        # soles flat?
        for side, (foot, half, z) in self.soles.items():
            zs = [self._world(f"{side[0]}_sole_{k}")[2] for k in ("fl", "fr", "rr", "rl")]
            if max(zs) - min(zs) > 1e-3:
                notes.append(f"{side} sole not flat at the nominal pose ({(max(zs) - min(zs)) * 1000:.1f} mm)")
        M.set_pose(q0)
        self.nominal_notes = notes
        return {M.joint_name(j): round(v, 4) for j, v in sorted(pose.items(), key=lambda kv: m.jnt_qposadr[kv[0]])}
