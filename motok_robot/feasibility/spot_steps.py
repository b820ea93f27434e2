"""Steps of a motion on the spot: the reference's own lift-offs, the weight on the stance foot first.

A kick, a stamp or a shuffle does not travel, so it is not walked (:func:`.stage.walks`), yet
it stands on one foot.  Retargeted kinematically, the robot's centre of mass stays where the
human's put it, which is not over the robot's stance foot when the other one lifts: the real
Bandai kick fell at its first lift-off on both OP3 models, its CoM 9 cm behind the stance sole
centre, with the lateral ZMP shift (:mod:`.zmp_shift`) on.  A human also shuffles a foot along
the floor between kicks (8 mm up, 4 cm across), which a robot's loaded foot cannot do.

This module plans for the reference's own support phases what a walking pattern generator
plans for its steps, and hands them to :func:`.gait.generate_gait` for the CoM path and the
whole body:

1. **support phases**: a foot is down where its lowest sole corner is below the contact height
   and it does not slide (horizontal speed below ``slide_speed_per_leg`` leg lengths a second);
   a swing lasts at least ``min_swing_s`` (a shuffle becomes a step), starts at least
   ``min_double_support_s`` after the other foot's touchdown, and a swing closer than
   ``min_stance_s`` to the same foot's next one joins it (:func:`support_phases`).  A motion
   with both feet higher than ``hop_height_per_leg`` leg lengths in some frame (a hop), or that
   starts or ends on one foot, has no spot steps;
2. **footholds**: a foot that is down stays flat where the reference has it at the middle of
   that stance, but, in the other foot's frame, no more than ``max_stagger_per_leg`` leg
   lengths ahead of or behind it (a human kicks from a staggered stance, 0.7 leg lengths on the
   Bandai kick, over which the robot's CoM cannot move onto one foot with its legs in reach)
   and on its own side of it, at least the nominal stance width away;
3. **swings**: the reference's own foot path (the kick itself), moved at its ends onto the
   footholds, at least ``clearance_per_leg`` leg lengths above the floor at mid-swing;
4. **pauses**: where a double support is too short for the ZMP to move onto the next stance
   foot at ``zmp_speed_per_leg`` leg lengths a second, the reference holds its middle frame
   (:func:`weight_shift_frames`; the motion waits, its speed is not changed);
5. **a ZMP reference** on the sole centres' midpoint while both feet stand, on the stance foot's
   sole centre while one does, moving across over ``transfer_s`` before each lift-off and after
   each touchdown (:func:`spot_zmp_reference`).
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np

from motok_robot.feasibility.config import SpotStepConfig
from motok_robot.feasibility.footsteps import Foothold, RobotFeet, StepSchedule
from motok_robot.feasibility.geometry import heading
from motok_robot.feasibility.zmp_shift import _kinematics
from motok_robot.motion.rotations import quat_conjugate, quat_mul, quat_slerp
from retarget.contacts import contact_phases


@dataclass
class SpotSteps:
    schedule: StepSchedule | None  # None: the motion has no spot steps (see ``reason``); else on
    #                                the reference played through ``frames``
    zmp: np.ndarray | None         # [T', 2] the ZMP reference for the schedule
    frames: np.ndarray | None      # [T'] the reference's frame shown at each planned frame (a
    #                                repeated one: a pause to shift the weight)
    reason: str                    # why there is no schedule ("" when there is one)

    def record(self, fps: float) -> dict:
        if self.schedule is None:
            return {"steps": 0, "reason": self.reason}
        swings = []
        for k, name in ((0, "left"), (1, "right")):
            for start, stop in runs(~self.schedule.contacts[:, k]):
                swings.append({"foot": name, "start_s": round(start / fps, 3), "end_s": round(stop / fps, 3)})
        held = np.r_[False, np.diff(self.frames) == 0]
        pauses = [{"at_s": round(int(self.frames[a]) / fps, 3), "s": round((b - a + 1) / fps, 3)} for a, b in runs(held)]
        return {"steps": self.schedule.steps, "swings": sorted(swings, key=lambda s: s["start_s"]),
                "pauses": pauses, "pause_s": round(float(held.sum()) / fps, 3)}


def runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """``[(first, last), ...]`` frames of each run of True in ``mask`` [T] (the last one
    included: :func:`retarget.contacts.contact_phases` gives them half-open)."""
    return [(start, stop - 1) for start, stop in contact_phases(mask)]


def support_phases(low: np.ndarray, xy: np.ndarray, fps: float, leg_length: float, *, contact_height_m: float,
                   slide_speed_per_leg: float, min_swing_s: float, min_stance_s: float,
                   min_double_support_s: float) -> np.ndarray:
    """bool [T, 2]: each foot down (step 1 of the module docstring), from the lowest sole
    corner heights ``low`` [T, 2] and the horizontal sole positions ``xy`` [T, 2, 2].

    Swings are taken in the order they start: a short one is lengthened on both sides, one
    that starts fewer than ``min_double_support_s`` after the other foot's touchdown starts
    that much after it instead (a human lands a kick while its stance foot already slides on;
    the robot's ZMP needs that time to move across), and a swing that then comes within
    ``min_stance_s`` of the same foot's next one joins it.  One foot is always down."""
    T = low.shape[0]
    step = np.zeros((T, 2))
    if T > 1:
        moved = np.linalg.norm(np.diff(xy, axis=0), axis=2) * fps  # [T-1, 2]
        step[1:] = moved
        step[:-1] = np.maximum(step[:-1], moved)
    raw = (low < contact_height_m) & (step < slide_speed_per_leg * leg_length)
    shortest_swing = max(1, int(round(min_swing_s * fps)))
    shortest_stance = max(1, int(round(min_stance_s * fps)))
    settle = max(1, int(round(min_double_support_s * fps)))
    swings = sorted(((first, last, k) for k in range(2) for first, last in runs(~raw[:, k])), key=lambda s: s[0])
    planned: list[list[int]] = []  # [first, last, foot]
    landed = [-1, -1]  # the frame each foot last touched down
    for first, last, k in swings:
        if planned and planned[-1][2] == k and first <= planned[-1][1] + shortest_stance:
            planned[-1][1] = max(planned[-1][1], last)  # joins this foot's previous swing
            landed[k] = planned[-1][1] + 1
            continue
        grow = shortest_swing - (last - first + 1)
        if grow > 0:
            first, last = first - grow // 2, last + grow - grow // 2
        first = max(first, landed[1 - k] + settle, 1)
        last = min(max(last, first + shortest_swing - 1), T - 2)
        if last < first:
            continue
        same = [p for p in planned if p[2] == k]
        if same and first <= same[-1][1] + shortest_stance:
            same[-1][1] = max(same[-1][1], last)
            landed[k] = same[-1][1] + 1
            continue
        planned.append([first, last, k])
        landed[k] = last + 1
    down = np.ones((T, 2), dtype=bool)
    for first, last, k in planned:
        down[first:last + 1, k] = False
    return down


def weight_shift_frames(contacts: np.ndarray, centre: np.ndarray, fps: float, *, zmp_speed_m_s: float,
                        min_double_support_s: float) -> np.ndarray:
    """[T'] frame indices of the reference with pauses: each double support lasts at least
    ``min_double_support_s`` and long enough for the ZMP to move at ``zmp_speed_m_s`` from
    where it was (the foot that stood alone before, or between the feet at the start) onto the
    foot that stands alone next (or between the feet at the end); a pause holds its middle
    frame.  ``contacts`` [T, 2]: planned support phases; ``centre`` [T, 2, 2]: sole centres."""
    T = contacts.shape[0]
    repeat = np.ones(T, dtype=int)
    for first, last in runs(contacts.all(axis=1)):
        mid = centre[first:last + 1].mean(axis=1)
        start = mid[0] if first == 0 else centre[first, 0 if contacts[first - 1, 0] else 1]
        end = mid[-1] if last == T - 1 else centre[last, 0 if contacts[last + 1, 0] else 1]
        if first == 0 and last == T - 1:
            continue
        need = max(min_double_support_s, float(np.linalg.norm(end - start)) / max(zmp_speed_m_s, 1e-9))
        extra = int(np.ceil(need * fps - 1e-9)) - (last - first + 1)
        if extra > 0:
            repeat[(first + last) // 2] += extra
    return np.repeat(np.arange(T), repeat)


def _beside(offset: np.ndarray, yaw: float, foot: int, stagger: float, width: float) -> np.ndarray:
    """``offset`` [2] (world frame) of foot ``foot`` (0 left, 1 right) from the other foot, in
    that foot's frame (heading ``yaw``) at most ``stagger`` ahead or behind and at least
    ``width`` to its own side (the left foot on +y)."""
    c, s = np.cos(yaw), np.sin(yaw)
    along, across = c * offset[0] + s * offset[1], -s * offset[0] + c * offset[1]
    along = float(np.clip(along, -stagger, stagger))
    across = max(across, width) if foot == 0 else min(across, -width)
    return np.array([c * along - s * across, s * along + c * across])


def _ease(u: float) -> float:
    return 10 * u ** 3 - 15 * u ** 4 + 6 * u ** 5


def plan_spot_steps(index, qpos: np.ndarray, fps: float, config: SpotStepConfig, *, contact_height_m: float,
                    feet: RobotFeet | None = None) -> SpotSteps:
    """The spot steps of reference ``qpos`` [T, nq] at ``fps`` with the settings ``config``
    (see the module docstring), planned on the reference with the pauses of
    :func:`weight_shift_frames`."""
    feet = feet or RobotFeet(index)
    qpos = np.asarray(qpos, dtype=np.float64)
    T = qpos.shape[0]
    _, corners, ref_pos, ref_quat = _kinematics(index, qpos)
    low = corners[:, :, :, 2].min(axis=2)
    airborne = (low > config.hop_height_per_leg * feet.leg_length).all(axis=1)
    if airborne.any():
        first = int(np.nonzero(airborne)[0][0])
        return SpotSteps(None, None, None, f"both feet are off the floor at {first / fps:.2f} s (a hop)")
    contacts = support_phases(low, ref_pos[:, :, :2], fps, feet.leg_length, contact_height_m=contact_height_m,
                              slide_speed_per_leg=config.slide_speed_per_leg, min_swing_s=config.min_swing_s,
                              min_stance_s=config.min_stance_s, min_double_support_s=config.min_double_support_s)
    if contacts.all():
        return SpotSteps(None, None, None, "both feet stay down")
    if not (low[0] < contact_height_m).all() or not (low[-1] < contact_height_m).all():
        return SpotSteps(None, None, None, "it starts or ends on one foot")
    centre_now = np.zeros((T, 2, 2))
    rot = np.zeros(9)
    for t in range(T):
        for k in range(2):
            mujoco.mju_quat2Mat(rot, ref_quat[t, k])
            centre_now[t, k] = (ref_pos[t, k] + rot.reshape(3, 3) @ feet.centre_local[k])[:2]
    frames = weight_shift_frames(contacts, centre_now, fps, zmp_speed_m_s=config.zmp_speed_per_leg * feet.leg_length,
                                 min_double_support_s=config.min_double_support_s)
    qpos, ref_pos, ref_quat, contacts = qpos[frames], ref_pos[frames], ref_quat[frames], contacts[frames]
    T = len(frames)
    # footholds: flat where the reference has the foot at the middle of each stance, but in the
    # frame of the other foot's sole no farther ahead or behind than ``max_stagger_per_leg`` and
    # on its own side of it, at least the nominal stance width apart
    nominal_yaw = heading(np.c_[np.zeros((2, 3)), feet.quat0])  # each sole's own yaw at the nominal pose
    foot_yaw = feet.yaw0 + heading(np.c_[np.zeros((T * 2, 3)), ref_quat.reshape(-1, 4)]).reshape(T, 2) - nominal_yaw
    limits = (config.max_stagger_per_leg * feet.leg_length, float(feet.offset[0, 1] - feet.offset[1, 1]))
    foot_pos, foot_quat = np.zeros((T, 2, 3)), np.zeros((T, 2, 4))
    centre = np.zeros((T, 2, 2))
    footholds = []
    stances = sorted(((first, last, k) for k in range(2) for first, last in runs(contacts[:, k])))
    place, yaw = [None, None], [float(foot_yaw[0, 0]), float(foot_yaw[0, 1])]
    right = _beside(ref_pos[0, 1, :2] - ref_pos[0, 0, :2], yaw[0], 1, *limits)
    middle = 0.5 * (ref_pos[0, 0, :2] + ref_pos[0, 1, :2])
    place = [middle - 0.5 * right, middle + 0.5 * right]  # the first stance: both feet towards their middle
    for first, last, k in stances:
        mid = (first + last) // 2
        if first > 0:
            yaw[k] = float(foot_yaw[mid, k])
            place[k] = place[1 - k] + _beside(ref_pos[mid, k, :2] - place[1 - k], yaw[1 - k], k, *limits)
        pos, quat, c = feet.hold(k, place[k], yaw[k])
        foot_pos[first:last + 1, k], foot_quat[first:last + 1, k], centre[first:last + 1, k] = pos, quat, c
        footholds.append(Foothold(k, first, last, pos, quat, c))
    # swings: the reference's path, moved at its ends onto the footholds, lifted to the clearance
    lift = config.clearance_per_leg * feet.leg_length
    steps = 0
    for k in range(2):
        for first, last in runs(~contacts[:, k]):
            before, after = first - 1, last + 1
            shift0 = foot_pos[before, k] - ref_pos[before, k]
            shift1 = foot_pos[after, k] - ref_pos[after, k]
            turn0 = quat_mul(foot_quat[before, k], quat_conjugate(ref_quat[before, k]))
            turn1 = quat_mul(foot_quat[after, k], quat_conjugate(ref_quat[after, k]))
            n = last - first + 1
            for i, t in enumerate(range(first, last + 1)):
                u = (i + 1) / (n + 1)
                w = _ease(u)
                pos = ref_pos[t, k] + (1 - w) * shift0 + w * shift1
                floor = (1 - w) * foot_pos[before, k, 2] + w * foot_pos[after, k, 2]
                pos[2] = max(pos[2], floor + lift * np.sin(np.pi * u))
                foot_pos[t, k] = pos
                foot_quat[t, k] = quat_mul(quat_slerp(turn0, turn1, w), ref_quat[t, k])
            steps += 1
    footholds.sort(key=lambda f: (f.start, f.foot))
    schedule = StepSchedule(contacts=contacts, foot_pos=foot_pos, foot_quat=foot_quat, footholds=footholds,
                            steps=steps, heading=heading(qpos), loaded=contacts.copy())
    zmp = spot_zmp_reference(contacts, centre, max(1, int(round(config.transfer_s * fps))))
    return SpotSteps(schedule, zmp, frames, "")


def spot_zmp_reference(contacts: np.ndarray, centre: np.ndarray, transfer: int) -> np.ndarray:
    """[T, 2] ZMP reference (step 4 of the module docstring) for support phases ``contacts``
    [T, 2] with each foot's sole centre ``centre`` [T, 2, 2] where it is down; ``transfer``
    frames to move across (a double support shorter than two of them moves straight from the
    foot that stood before it to the one that stands after it)."""
    T = contacts.shape[0]
    zmp = np.zeros((T, 2))
    single = contacts.sum(axis=1) == 1
    zmp[single] = np.where(contacts[single, :1], centre[single, 0], centre[single, 1])
    for first, last in runs(contacts.all(axis=1)):
        n = last - first + 1
        mid = centre[first:last + 1].mean(axis=1)
        start = mid.copy() if first == 0 else centre[first:last + 1, 0 if contacts[first - 1, 0] else 1]
        end = mid.copy() if last == T - 1 else centre[first:last + 1, 0 if contacts[last + 1, 0] else 1]
        i = np.arange(n)[:, None]
        if n >= 2 * transfer:
            into = np.minimum(1.0, (i + 1) / transfer)         # from the foot that stood onto the middle
            out = np.clip((i + 1 - (n - transfer)) / transfer, 0.0, 1.0)  # from the middle onto the next
            zmp[first:last + 1] = start + into * (mid - start) + out * (end - mid)
        else:
            w = (i + 1) / (n + 1)
            zmp[first:last + 1] = (1 - w) * start + w * end
    return zmp
