"""Joint limits from the MJCF: ranges and torque limits per hinge, ranges for hinges that have
none, and a draft servo map when the actuators look like Dynamixel position servos."""

from __future__ import annotations

import math

import numpy as np


class JointLimits:
    """Joint limits of a :class:`~motok_robot.robots.draft.drafter.Drafter` (a mixin: it reads
    ``self.M`` and sets ``added_ranges``)."""

    def joint_limits(self):
        """[(joint id, name, lo, hi, torque or None, how)] for the hinges in qpos order."""
        M, m = self.M, self.M.m
        act = {}
        for a in range(m.nu):
            if m.actuator_trntype[a] == M.mj.mjtTrn.mjTRN_JOINT:
                act.setdefault(int(m.actuator_trnid[a, 0]), []).append(a)
        rows = []
        for j in M.hinges:
            lims = []
            for a in act.get(j, []):
                if m.actuator_forcelimited[a]:
                    lims.append(float(np.max(np.abs(m.actuator_forcerange[a]))))
                if m.actuator_biastype[a] == 0 and m.actuator_ctrllimited[a]:
                    lims.append(float(np.max(np.abs(m.actuator_ctrlrange[a])) * m.actuator_gainprm[a, 0]
                                      * abs(m.actuator_gear[a, 0])))
            if m.jnt_actfrclimited[j]:
                lims.append(float(np.max(np.abs(m.jnt_actfrcrange[j]))))
            lo, hi = (float(v) for v in m.jnt_range[j]) if m.jnt_limited[j] else (None, None)
            rows.append((j, M.joint_name(j), lo, hi, min(lims) if lims else None, act.get(j, [])))
        return rows

    def fill_missing_ranges(self, rows) -> None:
        """Hinges without a range get the range of their position actuator's ctrlrange (else +-pi)."""
        m = self.M.m
        for j, name, lo, hi, _, acts in rows:
            if lo is not None:
                continue
            rng = None
            for a in acts:
                if m.actuator_ctrllimited[a] and m.actuator_biastype[a] != 0:
                    rng = tuple(float(v) for v in m.actuator_ctrlrange[a])
            how = "its position actuator's ctrlrange" if rng else "+-pi"
            rng = rng or (-math.pi, math.pi)
            # inside one turn of a 4096-tick servo, so a draft servo map can cover it
            rng = (max(rng[0], -math.pi), min(rng[1], math.pi - 2 * math.pi / 4096))
            self.added_ranges[j] = rng
            self.unsure_xml.append((f"joint {name!r} has no range in {self.src.name}: the copy uses {how} "
                                    f"[{rng[0]:.4f}, {rng[1]:.4f}] rad; put the real mechanical range here",
                                    f'<joint name="{name}"'))

    def joint_range(self, j: int) -> tuple[float, float]:
        if j in self.added_ranges:
            return self.added_ranges[j]
        return tuple(float(v) for v in self.M.m.jnt_range[j])

    def servo_guess(self, rows):
        """A draft servo map when the actuators look like Dynamixel position servos, else None."""
        from motok_robot.robots import servo_models

        m = self.M.m
        if m.nu == 0 or self.M.m.body_subtreemass[0] > 15.0:
            return None
        torques = []
        for j, name, lo, hi, tq, acts in rows:
            if len(acts) != 1 or tq is None:
                return None
            a = acts[0]
            kp = m.actuator_gainprm[a, 0]
            position = (m.actuator_biastype[a] == 1 and kp > 0 and abs(m.actuator_biasprm[a, 1] + kp) < 1e-6 * kp)
            if not position:
                return None
            torques.append(tq)
        for j, *_ in rows:
            lo, hi = self.joint_range(j)
            if lo < -math.pi - 1e-9 or hi > math.pi - 2 * math.pi / 4096 + 1e-9:
                self.summary.append(f"no servo map: joint {self.M.joint_name(j)!r} turns beyond one servo turn")
                return None
        sheets = sorted(servo_models.DATASHEETS.values(), key=lambda s: s.stall_torque)
        top = max(torques)
        fits = [s for s in sheets if s.stall_torque >= top * 0.9999]
        if not fits:
            return None
        sheet = fits[0]
        return sheet, top
