"""The feasibility stage: a kinematic robot trajectory in, the trajectory the robot executes out.

Steps (each recorded in the output's ``feasibility`` field and ``feasibility.json``):

1. optional uniform slow-down (``retime``; the time warp the fidelity checks see);
2. the task: with ``gait.enabled`` a motion that travels is walked with the robot's own steps
   along its path (:func:`walk_task`: :mod:`.footsteps`, :mod:`.gait`; slower where the robot
   cannot step as fast, with standing added before and after); otherwise a CoM path whose
   cart-table ZMP stays on the planned feet (:mod:`.zmp_shift`), a motion on the spot played
   slower where it needs more than ``max_torque_share`` of the servos' torque
   (:func:`torque_feasible_task`);
3. servo goals with inverse-dynamics feedforward (:mod:`.feedforward`) of that task;
4. the balance controller's plan (:mod:`.balance`), which validation and playback run; on a
   walk with the robot's own steps it tracks the planned footholds (:mod:`.stepping`);
5. optional predictive-sampling refinement of the goals over physics rollouts (:mod:`.refine`);
6. the rollout of the goals from rest with the controller in the loop: ``qpos`` of the output.

Output ``robot.npz`` keeps retargeting's fields, with ``qpos`` = the executed trajectory,
``reference_qpos`` = the kinematic trajectory it was asked to do (after the slow-down), which
validation judges it against (falls, drift, fidelity), ``task_qpos`` = what the servos were
commanded to follow (validation's ``tracking``), and ``initial_qvel`` = zeros (playback starts
the robot at rest).  ``servo_goals.npz`` beside it (mode ``feasibility``)
holds the goals and the plan; validation of that ``robot.npz`` replays exactly them.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import time
from dataclasses import dataclass
from pathlib import Path

import mujoco
import numpy as np

from motok_robot.feasibility.balance import BalancePlan, build_plan
from motok_robot.feasibility.clearance import keep_arms_clear
from motok_robot.feasibility.config import FeasibilityConfig, robot_config
from motok_robot.feasibility.dynamics import required_torque
from motok_robot.feasibility.footsteps import RobotFeet, plan_steps, stance_offsets, walk_timing
from motok_robot.feasibility.gait import generate_gait
from motok_robot.feasibility.feedforward import GOALS_FILE, feedforward_goals, save_servo_goals, servo_gains
from motok_robot.feasibility.physics import execute, servo_model
from motok_robot.feasibility.refine import refine_goals
from motok_robot.feasibility.stepping import build_stepping
from motok_robot.feasibility.spot_steps import plan_spot_steps
from motok_robot.feasibility.zmp_shift import shift_com

RECORD_FILE = "feasibility.json"


@dataclass
class FeasibleResult:
    trajectory: object          # retarget.io.RobotTrajectory: qpos executed, reference_qpos, initial_qvel
    goals: np.ndarray           # [T, nj] servo goals (rad)
    plan: BalancePlan | None
    record: dict                # what the stage changed and measured

    @property
    def fell(self) -> bool:
        return bool(self.record["executed"]["fell"])


def sole_contacts(index, qpos: np.ndarray, contact_height_m: float) -> np.ndarray:
    """bool [T, 2]: a foot is down where its lowest sole corner is below ``contact_height_m``."""
    return _soles(index, qpos)[1] < contact_height_m


def _soles(index, qpos: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Horizontal sole body positions [T, 2, 2] and lowest sole corner heights [T, 2] of ``qpos``."""
    data = mujoco.MjData(index.kin_model)
    xy, low = np.zeros((qpos.shape[0], 2, 2)), np.zeros((qpos.shape[0], 2))
    for t in range(qpos.shape[0]):
        data.qpos[:] = qpos[t]
        mujoco.mj_kinematics(index.kin_model, data)
        xy[t] = data.xpos[index.sole_body][:, :2]
        low[t] = data.site_xpos[index.corner_sites][:, :, 2].min(axis=1)
    return xy, low


def walks(index, qpos: np.ndarray, feet, config, soles: tuple | None = None) -> bool:
    """Whether ``qpos`` [T, nq] is a walk to re-plan: both soles travel farther than
    ``config.min_travel_per_leg`` leg lengths over the clip, and no sole corner rises above
    ``config.max_lift_per_leg`` leg lengths (a kick that high keeps its retargeted legs) unless
    the base ends more than ``config.min_run_travel_per_leg`` leg lengths from where it started
    (a run lifts its feet as high, but does not stay on the spot).
    ``soles``: :func:`_soles` of ``qpos`` when the caller has it."""
    xy, low = soles if soles is not None else _soles(index, qpos)
    travel = np.linalg.norm(np.diff(xy, axis=0), axis=2).sum(axis=0)
    moved = float(np.linalg.norm(qpos[-1, :2] - qpos[0, :2])) if len(qpos) else 0.0
    return bool(travel.min() > config.min_travel_per_leg * feet.leg_length
                and (low.max() < config.max_lift_per_leg * feet.leg_length
                     or moved > config.min_run_travel_per_leg * feet.leg_length))


def first_lifted_foot(contacts: np.ndarray) -> int:
    """The foot (0 left, 1 right) that leaves the floor first in ``contacts`` [T, 2] (right if neither)."""
    contacts = np.asarray(contacts, dtype=bool)
    for t in range(1, contacts.shape[0]):
        lifted = contacts[t - 1] & ~contacts[t]
        if lifted.any():
            return int(np.nonzero(lifted)[0][0])
    return 1


@dataclass
class SpotTask:
    """What the stage asks of a motion that is not walked (:func:`_spot_task`)."""

    trajectory: object               # the reference, played slower where the task needed it (and
    #                                  with the spot steps' pauses)
    task: np.ndarray                 # [T, nq]
    record: dict
    contacts: np.ndarray | None      # [T, 2] planned support phases (None: the task's own)
    loaded: np.ndarray | None        # [T, 2] feet planned to carry weight (None: every foot down)


def _spot_task(trajectory, index, config) -> SpotTask:
    """The task of a motion that is not walked: where it lifts a foot, its own steps with the
    weight moved onto the stance foot first (:mod:`.spot_steps`, when
    ``config.spot_steps.enabled``; the trajectory then pauses where the weight needs the time);
    else its CoM moved so the cart-table ZMP stays on its feet (:mod:`.zmp_shift`) when
    ``config.zmp_shift``; else the motion itself (contacts None: the task's own)."""
    from retarget.retime import hold_frames

    reference = np.asarray(trajectory.qpos, dtype=np.float64)
    fps = float(trajectory.fps)
    record: dict = {}
    if config.spot_steps.enabled:
        spot = plan_spot_steps(index, reference, fps, config.spot_steps, contact_height_m=config.contact_height_m)
        record["spot_steps"] = spot.record(fps)
        if spot.schedule is not None:
            held = hold_frames(trajectory, spot.frames)
            gait = config.gait
            walk = generate_gait(index, np.asarray(held.qpos, dtype=np.float64), fps, spot.schedule, zmp=spot.zmp,
                                 speed_limit=damping_speed_limit(index, gait.damping_speed_share)
                                 if gait.damping_speed_share > 0 else None)
            record["spot_steps"].update(walk.record())
            return SpotTask(held, walk.qpos, record, spot.schedule.contacts, spot.schedule.loaded)
    if not config.zmp_shift:
        return SpotTask(trajectory, reference, record, None, None)
    contacts = sole_contacts(index, reference, config.contact_height_m)
    shifted = shift_com(index, reference, fps, contacts, margin_m=config.zmp_margin_m, axes=config.zmp_axes)
    return SpotTask(trajectory, shifted.qpos, {**record, "zmp_shift": shifted.record()}, None, None)


def torque_share(index, task: np.ndarray, fps: float, config, loaded: np.ndarray | None = None) -> float:
    """The largest required torque of ``task`` [T, nq] over any joint, as a share of its limit
    (``loaded``: the feet planned to carry weight, :func:`~.dynamics.required_torque`)."""
    torque = required_torque(index, task, fps, config.contact_height_m, config.friction, loaded=loaded)[2]
    return float((np.abs(torque) / np.maximum(index.torque_limit, 1e-9)).max()) if torque.size else 0.0


def torque_feasible_task(trajectory, index, config, tries: int = 4) -> SpotTask:
    """The task of a motion that is not walked (:func:`_spot_task`), played slower where it
    needs more than ``config.max_torque_share`` of a servo's torque and it does not travel
    (:func:`walks`; a walk tracked on its retargeted legs keeps its timing): each try slows it by the
    share it needs over that (joint damping, a servo's back-EMF, is the part that falls with
    speed), the whole time warp at most ``config.gait.max_time_warp``.  The record's
    ``torque_retime`` says by how much, from which share to which."""
    from retarget.retime import retime

    fps = float(trajectory.fps)
    spot = _spot_task(trajectory, index, config)
    share = first = torque_share(index, spot.task, fps, config, spot.loaded)
    slowed = 1.0
    # a motion that travels keeps its timing: slowed, a walk on its retargeted legs falls more
    # often (29 of 31 real walks fell at 1.5x, 16 at human timing)
    travels = walks(index, np.asarray(trajectory.qpos, dtype=np.float64), RobotFeet(index), config.gait)
    for _ in range(tries if config.max_torque_share < 1.0 and not travels else 0):
        room = config.gait.max_time_warp / float(trajectory.retime_factor)
        if share <= config.max_torque_share or room <= 1.0 + 1e-6:
            break
        factor = min(room, max(1.05, share / config.max_torque_share))
        trajectory = retime(trajectory, factor)
        if factor == room:  # the bound itself, not the bound times the rounding of each factor
            # (3.0000000000000004 failed validation's time_warp check at its 3.0)
            trajectory = dataclasses.replace(trajectory, retime_factor=float(config.gait.max_time_warp))
        slowed *= factor
        spot = _spot_task(trajectory, index, config)
        share = torque_share(index, spot.task, float(trajectory.fps), config, spot.loaded)
    spot.record["torque_retime"] = {"factor": slowed, "torque_share_before": first, "torque_share_after": share,
                                    "travels": travels}
    return spot


def damping_speed_limit(index, share: float) -> np.ndarray:
    """[nj] rad/s: the speed at which each joint's damping (a servo's back-EMF in an identified
    model) takes ``share`` of its torque limit; inf for a joint without damping."""
    damping = np.asarray(index.kin_model.dof_damping, dtype=np.float64)[np.asarray(index.dof_adr, dtype=int)]
    limit = np.asarray(index.torque_limit, dtype=np.float64)
    return np.where(damping > 0, share * limit / np.maximum(damping, 1e-12), np.inf)


def walk_task(trajectory, index, config, record: dict):
    """(trajectory, task qpos, planned contacts, feet planned to carry weight) of the robot's own
    walk along ``trajectory``'s path (:mod:`.footsteps`, :mod:`.gait`), or None when the motion
    does not travel."""
    from retarget.retime import hold_ends, retime

    gait = config.gait
    fps = float(trajectory.fps)
    feet = RobotFeet(index)
    qpos = np.asarray(trajectory.qpos, dtype=np.float64)
    soles = _soles(index, qpos)
    if not walks(index, qpos, feet, gait, soles):
        return None
    timing = walk_timing(qpos, fps, feet, gait)
    warp = timing.time_warp
    contacts = soles[1] < config.contact_height_m  # as sole_contacts
    if warp > 1.0:
        trajectory = retime(trajectory, warp)
    before = int(round(gait.lead_in_s * fps))
    trajectory = hold_ends(trajectory, before, int(round(gait.lead_out_s * fps)))
    reference = np.asarray(trajectory.qpos, dtype=np.float64)
    offsets = stance_offsets(feet, qpos, soles[0], contacts)
    schedule = plan_steps(index, reference, fps, first_step_frame=before, step_period_s=timing.step_period_s,
                          double_support=gait.double_support, advance_per_leg=timing.advance_per_leg,
                          turn_per_step_rad=gait.turn_per_step_rad, clearance_per_leg=gait.clearance_per_leg,
                          first_foot=first_lifted_foot(contacts), feet=feet, offsets=offsets,
                          lift_share=gait.vertical_share, zmp_outward_per_leg=gait.zmp_outward_per_leg,
                          reference_lift=_soles(index, reference)[1] if gait.max_clearance_per_leg > gait.clearance_per_leg
                          else None, max_clearance_per_leg=gait.max_clearance_per_leg)
    walk = generate_gait(index, reference, fps, schedule, base_yaw=schedule.heading,
                         zmp_transfer_share=gait.zmp_transfer_share, height_window_s=gait.height_smoothing_s * warp,
                         speed_limit=damping_speed_limit(index, gait.damping_speed_share)
                         if gait.damping_speed_share > 0 else None)
    record["gait"] = {"time_warp": warp, "advance_per_leg": timing.advance_per_leg,
                      "step_period_s": timing.step_period_s, "lead_in_s": before / fps,
                      "lead_out_s": round(gait.lead_out_s * fps) / fps, **schedule.record(), **walk.record()}
    task = walk.qpos
    if gait.arm_clearance_per_height > 0:  # the reference's arms swing with the human's legs, not these
        task, record["gait"]["arm_clearance"] = keep_arms_clear(index, task, fps,
                                                                gait.arm_clearance_per_height * index.height_m)
    return trajectory, task, walk.contacts, schedule.loaded


def make_feasible(trajectory, index, config: FeasibilityConfig | None = None, progress=None) -> FeasibleResult:
    """Run the stage on ``trajectory`` (a :class:`retarget.io.RobotTrajectory`) for robot ``index``
    (a :class:`~motok_robot.robots.index.RobotIndex`), with ``config`` (default: the robot's
    settings, :func:`~motok_robot.feasibility.config.robot_config`)."""
    from retarget.retime import retime

    config = config if config is not None else robot_config(index)
    started = time.perf_counter()
    timing = {}
    record: dict = {"config": config.to_dict(), "robot_settings": dict(getattr(index, "feasibility_settings", {}))}
    if config.retime > 1.0:
        trajectory = retime(trajectory, config.retime)
    record["time_warp"] = float(trajectory.retime_factor)
    fps = float(trajectory.fps)
    reference = np.asarray(trajectory.qpos, dtype=np.float64)
    t0 = time.perf_counter()
    walk = walk_task(trajectory, index, config, record) if config.gait.enabled else None
    task, plan_contacts, loaded = reference, None, None
    if walk is not None:  # the robot's own walk along the path (it may be slower and longer)
        trajectory, task, plan_contacts, loaded = walk
        reference = np.asarray(trajectory.qpos, dtype=np.float64)
        record["time_warp"] = float(trajectory.retime_factor)
    else:
        spot = torque_feasible_task(trajectory, index, config)
        trajectory, task, plan_contacts, loaded = spot.trajectory, spot.task, spot.contacts, spot.loaded
        reference = np.asarray(trajectory.qpos, dtype=np.float64)
        record["time_warp"] = float(trajectory.retime_factor)
        record.update(spot.record)
    timing["task"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    joint_pos, joint_vel, torque = required_torque(index, task, fps, config.contact_height_m, config.friction,
                                                   loaded=loaded)
    stiffness, damping = servo_gains(servo_model(index, config.timestep_s)[0], index)
    goals = feedforward_goals(index, joint_pos, joint_vel, torque, fps, stiffness, damping, config.goal_velocity_fraction)
    if plan_contacts is None:
        plan_contacts = sole_contacts(index, task, config.contact_height_m)
    stepping = None
    if walk is not None and config.balance.enabled and config.balance.foothold_gain > 0:
        stepping = build_stepping(index, task, fps, plan_contacts, lift_share=config.gait.vertical_share,
                                  gain=config.balance.foothold_gain,
                                  max_offset_m=config.balance.max_foothold_offset_per_leg * RobotFeet(index).leg_length)
    plan = build_plan(index, task, fps, plan_contacts, config.balance, stepping) \
        if config.balance.enabled else None
    timing["goals"] = time.perf_counter() - t0
    if config.refine:
        t0 = time.perf_counter()
        refined = refine_goals(index, task, fps, goals, plan, config.refine_config, config.timestep_s,
                               initial_qvel=np.zeros(index.model.nv), progress=progress)
        goals = refined.goals
        record["refine"] = refined.record()
        timing["refine"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    executed, fall_frame = execute(index, task[0], goals, fps, plan, config.timestep_s)
    timing["execute"] = time.perf_counter() - t0
    upright = slice(0, fall_frame if fall_frame is not None else len(executed))
    drift = np.linalg.norm(executed[upright, :2] - reference[upright, :2], axis=1)
    record["executed"] = {"fell": fall_frame is not None,
                          "fall_time_s": None if fall_frame is None else fall_frame / fps,
                          "base_drift_max_m": float(drift.max()) if drift.size else 0.0}
    record["balance"] = config.balance.to_dict() if plan is not None else None
    record["timing_s"] = {**timing, "total": time.perf_counter() - started}
    out = dataclasses.replace(trajectory, qpos=executed, reference_qpos=reference, task_qpos=task,
                              initial_qvel=np.zeros(index.model.nv), feasibility=record)
    return FeasibleResult(trajectory=out, goals=goals, plan=plan, record=record)


def write_feasible(result: FeasibleResult, out_dir: str | Path, robot_name: str) -> Path:
    """Write ``robot.npz`` (executed), ``servo_goals.npz`` (goals + plan, bound to that file) and
    ``feasibility.json`` into ``out_dir``; returns the robot.npz path."""
    from retarget.io import write_robot_npz

    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    path = write_robot_npz(out_dir / "robot.npz", result.trajectory)
    digest = hashlib.sha256(path.read_bytes()).hexdigest()
    save_servo_goals(out_dir / GOALS_FILE, result.goals, result.trajectory.joint_names, result.trajectory.fps,
                     robot_name, "feasibility", digest, plan=result.plan)
    (out_dir / RECORD_FILE).write_text(json.dumps(result.record, indent=2, default=float) + "\n")
    return path
