"""Footsteps planned for the robot along the reference's path, instead of the human's own steps.

A human walk retargeted to a 0.5 m robot keeps the human's stride: on op3_like a Bandai walk
steps 15-18 cm per step, 1.4 foot lengths, with support passing between the feet within one
20 fps frame.  The robot cannot execute that stride: played as retargeted it falls in half the
clips, played slower it falls more often, and a gait on the human's footholds with a planned
CoM falls as often (docs/experiments/2026-12-02-own-steps.md).  A synthetic walk of half
a foot length per step stays up at the same cadence.  So the robot walks the reference's path
with steps of its own:

* **Timing.**  The robot steps every ``step_period_s`` with ``double_support`` of each period on
  both feet, advancing at most ``advance_per_leg`` x its leg length per step and turning at most
  ``turn_per_step_rad``.  Where the reference moves faster than that, the whole motion is played
  slower (the time warp, at most ``max_time_warp``, recorded in the report).
* **Where each foot lands.**  Where the (smoothed) reference base will be half a step after the
  landing, offset sideways by that foot's stance offset, turned with the base's heading; clamped
  to the step limits relative to the stance foot.  Stepping continues after the reference stops
  until both feet stand at their final place.
* **Swing.**  Up by ``clearance_per_leg`` x the leg length (a half sine), across (min-jerk)
  only between the first and last 15 % of the swing, so the foot leaves and meets the floor
  vertically.
* **Which foot carries the robot.**  Support passes to a swing foot when it lands: in physics
  the trailing foot's load falls from 0.95 to 0.13 of the robot's weight within 16 ms of the
  touchdown.  So the trailing foot is planned unloaded from the other foot's landing until it
  lifts (``StepSchedule.loaded``), and the inverse dynamics behind the feedforward goals gives
  it no share of the weight there (docs/experiments/2026-12-02-load-at-touchdown.md).

:func:`plan_steps` returns the schedule (foot poses and contacts per frame, the footholds);
:mod:`.gait` turns it into a whole-body trajectory.
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np

from motok_robot.feasibility.geometry import heading


@dataclass
class Foothold:
    foot: int         # 0 left, 1 right
    start: int        # first frame down
    end: int          # last frame down
    pos: np.ndarray   # [3] sole body position
    quat: np.ndarray  # [4] sole body orientation
    centre: np.ndarray  # [2] the ZMP target while this foot carries the robot (its sole centre, moved outward)


@dataclass
class StepSchedule:
    contacts: np.ndarray   # [T, 2] bool
    foot_pos: np.ndarray   # [T, 2, 3] sole body positions
    foot_quat: np.ndarray  # [T, 2, 4]
    footholds: list        # [Foothold], in time order
    steps: int             # number of swings
    heading: np.ndarray    # [T] the smoothed reference heading the footholds turn with (rad)
    loaded: np.ndarray     # [T, 2] bool: the feet planned to carry weight (down, and not a
    #                        trailing foot between the other's landing and its own lift-off)

    def record(self) -> dict:
        return {"steps": self.steps, "double_support_fraction": float(np.mean(self.contacts.all(axis=1))),
                "footholds": [{"foot": "left" if f.foot == 0 else "right", "start_frame": f.start, "end_frame": f.end,
                               "x": round(float(f.pos[0]), 4), "y": round(float(f.pos[1]), 4)} for f in self.footholds]}


class RobotFeet:
    """The robot's feet at its nominal pose: leg length, stance offsets, flat sole orientation."""

    def __init__(self, index):
        model = index.kin_model
        data = mujoco.MjData(model)
        data.qpos[:] = index.nominal_qpos
        mujoco.mj_kinematics(model, data)
        base = index.nominal_qpos[:3]
        self.yaw0 = float(heading(index.nominal_qpos[None])[0])
        c, s = np.cos(self.yaw0), np.sin(self.yaw0)
        rel = data.xpos[index.sole_body][:, :2] - base[:2]
        self.offset = np.stack([c * rel[:, 0] + s * rel[:, 1], -s * rel[:, 0] + c * rel[:, 1]], axis=1)  # [2, 2]
        lowest = data.site_xpos[index.corner_sites][:, :, 2].min(axis=1)
        self.height = data.xpos[index.sole_body][:, 2] - lowest  # sole body above the floor when flat
        self.quat0 = data.xquat[index.sole_body].copy()
        # sole centre in the sole body's frame
        self.centre_local = np.stack([data.xmat[b].reshape(3, 3).T @ (data.site_xpos[s_] - data.xpos[b])
                                      for b, s_ in zip(index.sole_body, index.sole_site)])
        self.leg_length = float(base[2] - data.xpos[index.sole_body][:, 2].mean())
        self.foot_length = float(np.ptp(data.site_xpos[index.corner_sites[0]][:, 0]))

    def flat_quat(self, foot: int, yaw: float) -> np.ndarray:
        out = np.zeros(4)
        mujoco.mju_mulQuat(out, np.array([np.cos((yaw - self.yaw0) / 2), 0, 0, np.sin((yaw - self.yaw0) / 2)]),
                           self.quat0[foot])
        return out

    def hold(self, foot: int, xy: np.ndarray, yaw: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(position [3], orientation [4], sole centre [2]) of foot ``foot`` flat at ``xy``, ``yaw``."""
        quat = self.flat_quat(foot, yaw)
        pos = np.r_[xy, self.height[foot]]
        rot = np.zeros(9)
        mujoco.mju_quat2Mat(rot, quat)
        centre = pos + rot.reshape(3, 3) @ self.centre_local[foot]
        return pos, quat, centre[:2]


#: feet closer than the nominal stance plus this many leg lengths collide when they pass
MIN_GAP_PER_LEG = 0.12


def stance_offsets(feet: RobotFeet, qpos: np.ndarray, foot_xy: np.ndarray, contacts: np.ndarray,
                   min_gap_per_leg: float = MIN_GAP_PER_LEG) -> np.ndarray:
    """[2, 2] each foot's place relative to the base (in its heading frame) while standing: the
    reference's median sideways offset of the sole body over the frames that foot is down (the
    robot's nominal one where it never is), never closer to the other foot than the nominal
    stance plus ``min_gap_per_leg`` x the leg length (feet that pass each other closer collide),
    fore-aft centred under the base."""
    yaw = heading(qpos)
    c, s = np.cos(yaw), np.sin(yaw)
    out = feet.offset.copy()
    out[:, 0] = 0.0
    for k in range(2):
        down = np.asarray(contacts[:, k], dtype=bool)
        if down.any():
            rel = foot_xy[down, k] - qpos[down, :2]
            out[k, 1] = float(np.median(-s[down] * rel[:, 0] + c[down] * rel[:, 1]))
    half_gap = 0.5 * min_gap_per_leg * feet.leg_length
    for k, sign in ((0, 1.0), (1, -1.0)):
        out[k, 1] = sign * max(sign * out[k, 1], sign * feet.offset[k, 1] + half_gap)
    return out


def base_path(qpos: np.ndarray, fps: float, window_s: float) -> tuple[np.ndarray, np.ndarray]:
    """The reference base's horizontal path [T, 2] and heading [T] (unwrapped), smoothed over
    ``window_s`` (the sway of each step averaged out)."""
    half = max(0, int(round(window_s * fps / 2)))
    xy = np.asarray(qpos[:, :2], dtype=np.float64)
    yaw = np.unwrap(heading(qpos))
    if half:
        kernel = np.ones(2 * half + 1) / (2 * half + 1)
        xy = np.stack([np.convolve(np.pad(xy[:, a], half, mode="edge"), kernel, mode="valid") for a in range(2)], axis=1)
        yaw = np.convolve(np.pad(yaw, half, mode="edge"), kernel, mode="valid")
    return xy, yaw


#: how far a swing foot may land to the side of where it would stand beside the stance foot,
#: per step length (``plan_steps``), and how far towards the stance foot at least (a quarter step)
SIDE_STEP_SHARE = 0.5
INWARD_STEP_SHARE = 0.25


@dataclass(frozen=True)
class WalkTiming:
    """How the robot walks a reference's path (:func:`walk_timing`)."""

    advance_per_leg: float  # the longest step, per leg length
    step_period_s: float    # one step every this many seconds (of the played motion)
    time_warp: float        # how many times slower than the reference the motion is played


def _path_rates(qpos: np.ndarray, fps: float, window_s: float) -> np.ndarray:
    """[W, 3]: the reference's forward speed, sideways speed (m/s, in the frame of its smoothed
    heading) and turn rate (rad/s) over each one-second window of its path smoothed over
    ``window_s`` (no rows for a clip shorter than a window)."""
    xy, yaw = base_path(qpos, fps, window_s)
    window = max(1, int(round(fps)))
    if qpos.shape[0] <= window:
        return np.zeros((0, 3))
    move = (xy[window:] - xy[:-window]) * fps / window
    mid = 0.5 * (yaw[window:] + yaw[:-window])
    c, s = np.cos(mid), np.sin(mid)
    forward, side = c * move[:, 0] + s * move[:, 1], -s * move[:, 0] + c * move[:, 1]
    return np.abs(np.stack([forward, side, (yaw[window:] - yaw[:-window]) * fps / window], axis=1))


def walk_timing(qpos: np.ndarray, fps: float, feet: RobotFeet, gait) -> WalkTiming:
    """How the robot follows ``qpos``'s path with its own steps, for ``gait`` (a
    :class:`~motok_robot.feasibility.config.GaitConfig`).

    The robot steps every ``gait.step_period_s`` with steps of at most ``gait.advance_per_leg``
    leg lengths forward or back, ``SIDE_STEP_SHARE`` of that outward and ``INWARD_STEP_SHARE``
    inward (so sideways it covers ``(SIDE + INWARD) / 2`` of a step length per step: the
    trailing foot cannot cross the leading one) and ``gait.turn_per_step_rad`` of turn.  The
    time warp is the largest ratio, over one-second windows, of what the reference asks (its
    speed, or with ``gait.sideways_timing`` its forward and sideways speed in its own heading
    frame, and its turn rate) to what those steps give, at most ``gait.max_time_warp``.  Where
    even that slow the robot would fall behind its path, it takes longer steps, up to
    ``gait.max_advance_per_leg``, and then quicker ones, down to ``gait.min_step_period_s``."""
    rates = _path_rates(qpos, fps, gait.step_period_s)
    if not gait.sideways_timing and rates.size:  # the path's speed against forward steps
        rates = np.c_[np.hypot(rates[:, 0], rates[:, 1]), np.zeros(len(rates)), rates[:, 2]]
    cap = float(gait.max_time_warp)
    side_share = 0.5 * (SIDE_STEP_SHARE + INWARD_STEP_SHARE)

    def needs(advance: float, period: float) -> tuple[float, float]:
        """(how many times slower the path's travel, its turning, must be played for these steps)"""
        if not rates.size:
            return 1.0, 1.0
        step = advance * feet.leg_length
        move = max((rates[:, 0] * period / step).max(), (rates[:, 1] * period / (side_share * step)).max())
        turn = (rates[:, 2] * period / max(gait.turn_per_step_rad, 1e-12)).max()
        return max(1.0, float(move)), max(1.0, float(turn))

    advance, period = float(gait.advance_per_leg), float(gait.step_period_s)
    longest = max(float(gait.max_advance_per_leg), advance)
    move = needs(advance, period)[0]
    if move > cap and longest > advance:  # longer steps travel faster; they do not turn faster
        advance = min(longest, advance * move / cap)
    quickest = min(float(gait.min_step_period_s), period)
    need = max(needs(advance, period))
    if need > cap and quickest < period:
        period = max(quickest, period * cap / need)
        need = max(needs(advance, period))
    return WalkTiming(advance_per_leg=advance, step_period_s=period, time_warp=min(need, cap))


def swing_progress(n: int, lift_share: float) -> np.ndarray:
    """[n] horizontal progress (0 -> 1) of a swing foot over the ``n`` frames of its swing: it
    moves across only once up, after the first and before the last ``lift_share`` of the swing,
    along a minimum-jerk profile."""
    u = (np.arange(n) + 1) / (n + 1)
    v = np.clip((u - lift_share) / max(1e-9, 1 - 2 * lift_share), 0.0, 1.0)
    return 10 * v ** 3 - 15 * v ** 4 + 6 * v ** 5


def plan_steps(index, qpos: np.ndarray, fps: float, *, first_step_frame: int, step_period_s: float = 0.5,
               double_support: float = 0.2, advance_per_leg: float = 0.27, turn_per_step_rad: float = 0.3,
               clearance_per_leg: float = 0.15, first_foot: int = 1, feet: RobotFeet | None = None,
               offsets: np.ndarray | None = None, lift_share: float = 0.15,
               zmp_outward_per_leg: float = 0.04, reference_lift: np.ndarray | None = None,
               max_clearance_per_leg: float | None = None) -> StepSchedule:
    """The robot's footsteps and foot trajectories for reference ``qpos`` [T, nq] at ``fps``:
    both feet stand until ``first_step_frame``, then ``first_foot`` (0 left, 1 right) steps
    first and the feet alternate (see the module docstring).  ``offsets`` [2, 2]: each foot's
    place relative to the base while standing (default: the nominal stance).  The swing foot
    rises and lands vertically over the first and last ``lift_share`` of the swing.  The ZMP
    target of a foothold is its sole centre moved ``zmp_outward_per_leg`` leg lengths away from
    the other foot: the CoM then sways far enough to stand over the stance foot where it slows
    down at the end of its sway.  With ``reference_lift`` [T, 2] (how high each of the
    reference's soles is above the floor, m) a swing rises as high as the same reference foot
    rose within a step period of it, at least ``clearance_per_leg`` and at most
    ``max_clearance_per_leg`` leg lengths (a run or a kick lifts its feet higher than a walk)."""
    feet = feet or RobotFeet(index)
    offsets = feet.offset if offsets is None else np.asarray(offsets, dtype=np.float64)
    T = qpos.shape[0]
    xy, yaw = base_path(qpos, fps, step_period_s)
    period = max(2, int(round(step_period_s * fps)))
    ds = max(1, int(round(double_support * period)))
    advance = advance_per_leg * feet.leg_length
    # how far a swing foot may land towards the stance foot from where it would stand beside it:
    # a quarter step, or as far as a stance wider than the closest the feet may pass allows (a
    # diagonal walk needs its inner foot to step in: on a Bandai walk-right clip at a quarter step
    # every foothold landed 4 cm off the path)
    closest = feet.offset[0, 1] - feet.offset[1, 1] + MIN_GAP_PER_LEG * feet.leg_length
    inward = max(INWARD_STEP_SHARE * advance, float(offsets[0, 1] - offsets[1, 1]) - closest)
    lift = clearance_per_leg * feet.leg_length
    highest = max(lift, (max_clearance_per_leg if max_clearance_per_leg is not None else clearance_per_leg)
                  * feet.leg_length)

    def swing_height(foot: int, first: int, last: int) -> float:
        if reference_lift is None:
            return lift
        near = reference_lift[max(0, first - period):min(T, last + period + 1), foot]
        return float(np.clip(near.max(), lift, highest)) if near.size else lift
    outward = zmp_outward_per_leg * feet.leg_length

    def hold(foot: int, xy: np.ndarray, yaw: float):
        pos, quat, centre = feet.hold(foot, xy, yaw)
        side = 1.0 if foot == 0 else -1.0  # the left foot is on the +y side of the heading frame
        return pos, quat, centre + side * outward * np.array([-np.sin(yaw), np.cos(yaw)])

    def target(foot: int, frame: int) -> tuple[np.ndarray, float]:
        f = int(np.clip(frame, 0, T - 1))
        c, s = np.cos(yaw[f]), np.sin(yaw[f])
        o = offsets[foot]
        return xy[f] + np.array([c * o[0] - s * o[1], s * o[0] + c * o[1]]), float(yaw[f])

    contacts = np.ones((T, 2), dtype=bool)
    foot_pos = np.zeros((T, 2, 3))
    foot_quat = np.zeros((T, 2, 4))
    current = []
    for k in range(2):
        place, heading_k = target(k, 0)
        pos, quat, centre = hold(k, place, heading_k)
        current.append([pos, quat, centre, heading_k, 0])  # pose, centre, yaw, start frame of the hold
    footholds = []
    loaded = np.ones((T, 2), dtype=bool)
    swing = first_foot
    t0 = int(first_step_frame)
    steps = 0
    landed = False  # whether the stance foot landed at t0 (else both feet stood before it)
    while t0 + period <= T - 1:
        land = t0 + period  # first frame of the next hold
        stance = 1 - swing
        goal, goal_yaw = target(swing, land + period // 2)
        # the step limits, relative to where this foot would stand beside the stance foot
        s_pos, _, _, s_yaw, _ = current[stance]
        beside = _beside(offsets, stance, swing, s_pos[:2], s_yaw)
        c, s = np.cos(s_yaw), np.sin(s_yaw)
        d = goal - beside
        local = np.array([c * d[0] + s * d[1], -s * d[0] + c * d[1]])
        local = np.clip(local, [-advance, -SIDE_STEP_SHARE * advance], [advance, SIDE_STEP_SHARE * advance])
        if swing == 0:  # never step across the stance foot, nor closer to it than the feet may pass
            local[1] = max(local[1], -inward)
        else:
            local[1] = min(local[1], inward)
        goal = beside + np.array([c * local[0] - s * local[1], s * local[0] + c * local[1]])
        goal_yaw = s_yaw + float(np.clip(goal_yaw - s_yaw, -turn_per_step_rad, turn_per_step_rad))
        p0, q0, _, yaw0, start0 = current[swing]
        moved = np.linalg.norm(goal - p0[:2]) > 0.005 or abs(goal_yaw - yaw0) > 0.02
        if not moved and land > T - 1 - period and np.linalg.norm(target(stance, T - 1)[0] - s_pos[:2]) < 0.005:
            break  # the path has ended and both feet stand where it ends
        if moved:
            footholds.append(Foothold(swing, start0, t0 + ds - 1, p0, q0, current[swing][2]))
            p1, q1, c1 = hold(swing, goal, goal_yaw)
            if landed:  # the lifting foot carries nothing once the other has landed
                loaded[t0:t0 + ds, swing] = False
            lift_frames = range(t0 + ds, land)
            n = len(lift_frames)
            across = swing_progress(n, lift_share)
            apex = swing_height(swing, t0 + ds, land - 1)
            for i, t in enumerate(lift_frames):
                u = (i + 1) / (n + 1)
                ease = across[i]
                foot_pos[t, swing] = p0 + ease * (p1 - p0)
                foot_pos[t, swing, 2] = p0[2] + ease * (p1[2] - p0[2]) + apex * np.sin(np.pi * u)
                foot_quat[t, swing] = feet.flat_quat(swing, yaw0 + ease * (goal_yaw - yaw0))
                contacts[t, swing] = False
            current[swing] = [p1, q1, c1, goal_yaw, land]
            steps += 1
        landed = moved
        swing = stance
        t0 = land
    for k in range(2):
        footholds.append(Foothold(k, current[k][4], T - 1, current[k][0], current[k][1], current[k][2]))
    footholds.sort(key=lambda f: (f.start, f.foot))
    for f in footholds:
        foot_pos[f.start:f.end + 1, f.foot] = f.pos
        foot_quat[f.start:f.end + 1, f.foot] = f.quat
    return StepSchedule(contacts=contacts, foot_pos=foot_pos, foot_quat=foot_quat, footholds=footholds, steps=steps,
                        heading=yaw, loaded=loaded & contacts)


def _beside(offsets: np.ndarray, stance: int, swing: int, stance_xy: np.ndarray, yaw: float) -> np.ndarray:
    """Where foot ``swing`` stands beside foot ``stance`` (at ``stance_xy``, heading ``yaw``)."""
    o = offsets[swing] - offsets[stance]
    c, s = np.cos(yaw), np.sin(yaw)
    return stance_xy + np.array([c * o[0] - s * o[1], s * o[0] + c * o[1]])
