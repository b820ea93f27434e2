"""Swing feet that lift off and touch down vertically, with clearance over the floor.

A retargeted human walk moves the swing foot forward while it is still a few millimetres above
the floor: a human foot rolls off the toes and lands on the heel.  A servo robot with flat
feet tracks that path a few millimetres low (its legs give under load), so in physics the
foot scuffs the floor as it leaves and lands while still moving forward: on op3_like the
planted feet of a Bandai walk executed closed loop slide 7 cm per foot over 6.5 s, most of it
in the ticks around touchdown (slip measured at the contact points, up to 0.9 m/s).

For every swing phase of the planned contacts (frames a .. b-1 in the air between the
lift-off frame a-1 and the touchdown frame b), each foot's path is reshaped in phase
``s = (t - (a-1)) / (b - (a-1))``:

* horizontally (position and heading), the foot follows the reference path re-timed by
  ``(s - d) / (1 - 2 d)`` clipped to [0, 1]: it stays over its lift-off spot for the first
  ``d`` of the swing and is over its landing spot for the last ``d``;
* vertically, ``clearance x sin(pi s)`` is added to the reference height, so it leaves and
  lands along the vertical, higher than the reference in between.

Planted frames are not changed.  The legs are re-solved to the new foot poses (the damped
least squares of :mod:`.zmp_shift`); the base and upper body keep the reference.
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np

from motok_robot.feasibility.zmp_shift import _kinematics, _leg_dofs, _solve_legs


@dataclass
class SwingResult:
    qpos: np.ndarray         # [T, nq] the trajectory with reshaped swing feet
    phases: int              # swing phases reshaped (both feet)
    foot_change_m: float     # largest change of a foot position (m)
    foot_error_m: float      # largest foot position error of the leg re-solve (m)

    def record(self) -> dict:
        return {"method": "vertical lift-off and touchdown", "phases": self.phases,
                "foot_change_m_max": self.foot_change_m, "foot_error_m": self.foot_error_m}


def swing_phases(contact: np.ndarray) -> list[tuple[int, int]]:
    """``(a, b)`` of every swing phase of one foot's contacts [T] (bool): frames a .. b-1 in
    the air, a-1 and b on the floor (a phase at either end of the clip has no landing or no
    lift-off in the clip and is left alone)."""
    contact = np.asarray(contact, dtype=bool)
    phases, t, T = [], 1, contact.size
    while t < T:
        if contact[t - 1] and not contact[t]:
            b = t
            while b < T and not contact[b]:
                b += 1
            if b < T:
                phases.append((t, b))
            t = b
        t += 1
    return phases


def _yaw_quat(yaw: float) -> np.ndarray:
    return np.array([np.cos(yaw / 2), 0.0, 0.0, np.sin(yaw / 2)])


def _yaw(quat: np.ndarray) -> float:
    w, x, y, z = quat
    return float(np.arctan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z)))


def shape_swing(index, qpos: np.ndarray, contacts: np.ndarray, clearance_m: float, dwell: float = 0.2,
                min_frames: int = 3) -> SwingResult:
    """``qpos`` [T, nq] with every swing phase of ``contacts`` [T, 2] (bool) of at least
    ``min_frames`` frames reshaped as the module docstring says (``dwell`` is ``d``)."""
    qpos = np.asarray(qpos, dtype=np.float64).copy()
    contacts = np.asarray(contacts, dtype=bool)
    _, _, foot_pos, foot_quat = _kinematics(index, qpos)
    target_pos, target_quat = foot_pos.copy(), foot_quat.copy()
    changed = np.zeros(qpos.shape[0], dtype=bool)
    count = 0
    for side in range(2):
        for a, b in swing_phases(contacts[:, side]):
            if b - a < min_frames:
                continue
            count += 1
            frames = np.arange(a - 1, b + 1)
            s_ref = (frames - (a - 1)) / (b - (a - 1))
            yaw_ref = np.unwrap([_yaw(q) for q in foot_quat[frames, side]])
            for t in range(a, b):
                s = (t - (a - 1)) / (b - (a - 1))
                u = float(np.clip((s - dwell) / (1 - 2 * dwell), 0.0, 1.0))
                for axis in range(2):
                    target_pos[t, side, axis] = np.interp(u, s_ref, foot_pos[frames, side, axis])
                target_pos[t, side, 2] = foot_pos[t, side, 2] + clearance_m * np.sin(np.pi * s)
                # the reference tilt of the foot, turned to the re-timed heading
                turn = np.interp(u, s_ref, yaw_ref) - yaw_ref[t - (a - 1)]
                q = np.zeros(4)
                mujoco.mju_mulQuat(q, _yaw_quat(turn), foot_quat[t, side])
                target_quat[t, side] = q
                changed[t] = True
    legs = _leg_dofs(index)
    data = mujoco.MjData(index.kin_model)
    worst = 0.0
    for t in np.nonzero(changed)[0]:
        worst = max(worst, _solve_legs(index, qpos[t], target_pos[t], target_quat[t], legs, data))
    change = float(np.linalg.norm(target_pos - foot_pos, axis=2).max()) if count else 0.0
    return SwingResult(qpos=qpos, phases=count, foot_change_m=change, foot_error_m=worst)
