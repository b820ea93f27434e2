"""The feasibility stage: a kinematic robot trajectory in, the trajectory the robot executes out.

Steps (each recorded in the output's ``feasibility`` field and ``feasibility.json``):

1. optional uniform slow-down (``retime``; the time warp the fidelity checks see);
2. a CoM path whose cart-table ZMP stays on the planned feet (:mod:`.zmp_shift`);
3. servo goals with inverse-dynamics feedforward (:mod:`.feedforward`) of that task;
4. the balance controller's plan (:mod:`.balance`), which validation and playback run;
5. optional predictive-sampling refinement of the goals over physics rollouts (:mod:`.refine`);
6. the rollout of the goals from rest with the controller in the loop: ``qpos`` of the output.

Output ``robot.npz`` keeps retargeting's fields, with ``qpos`` = the executed trajectory,
``reference_qpos`` = the kinematic trajectory it was asked to do (after the slow-down), which
validation judges it against (falls, tracking, drift, fidelity), and ``initial_qvel`` = zeros
(playback starts the robot at rest).  ``servo_goals.npz`` beside it (mode ``feasibility``)
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
from motok_robot.feasibility.config import FeasibilityConfig
from motok_robot.feasibility.dynamics import required_torque
from motok_robot.feasibility.gait import generate_gait
from motok_robot.feasibility.feedforward import GOALS_FILE, feedforward_goals, save_servo_goals, servo_gains
from motok_robot.feasibility.physics import execute, servo_model
from motok_robot.feasibility.refine import refine_goals
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
    data = mujoco.MjData(index.kin_model)
    out = np.zeros((qpos.shape[0], 2), dtype=bool)
    for t in range(qpos.shape[0]):
        data.qpos[:] = qpos[t]
        mujoco.mj_kinematics(index.kin_model, data)
        out[t] = data.site_xpos[index.corner_sites][:, :, 2].min(axis=1) < contact_height_m
    return out


def lead_in_frames(contacts: np.ndarray, fps: float, lead_in_s: float) -> tuple[int, int]:
    """(frames to skip, frames to hold) so that a stepping motion starts from rest on both feet
    and stands ``lead_in_s`` before its first step: a start with a foot in the air is skipped up
    to the first frame with both feet down."""
    contacts = np.asarray(contacts, dtype=bool)
    # the first frame with both feet down, or the first landing (where support passes between
    # the feet within a frame)
    starts = np.r_[np.nonzero(contacts.all(axis=1))[0][:1], np.nonzero((contacts[1:] & ~contacts[:-1]).any(axis=1))[0][:1] + 1]
    skip = int(starts.min()) if starts.size else 0
    lifted = np.nonzero(~contacts[skip + 1:].all(axis=1))[0]
    first = int(lifted[0]) + 1 if lifted.size else contacts.shape[0] - skip
    return skip, max(0, int(round(lead_in_s * fps)) - first)


def make_feasible(trajectory, index, config: FeasibilityConfig | None = None, progress=None) -> FeasibleResult:
    """Run the stage on ``trajectory`` (a :class:`retarget.io.RobotTrajectory`) for robot ``index``
    (a :class:`~motok_robot.robots.index.RobotIndex`)."""
    from retarget.retime import lead_in, retime

    config = config or FeasibilityConfig()
    started = time.perf_counter()
    timing = {}
    record: dict = {"config": config.to_dict()}
    if config.retime > 1.0:
        trajectory = retime(trajectory, config.retime)
    record["time_warp"] = float(trajectory.retime_factor)
    fps = float(trajectory.fps)
    reference = np.asarray(trajectory.qpos, dtype=np.float64)
    t0 = time.perf_counter()
    contacts = sole_contacts(index, reference, config.contact_height_m)
    gait = None
    if config.gait:
        skip, hold = lead_in_frames(contacts, fps, config.gait_lead_in_s)
        started_at = lead_in(trajectory, skip, hold)
        held_reference = np.asarray(started_at.qpos, dtype=np.float64)
        gait = generate_gait(index, held_reference, fps, sole_contacts(index, held_reference, config.contact_height_m),
                             lead_in_frames=hold, min_double_support_s=config.gait_double_support_s)
        if gait is not None:  # a walk: it starts from rest on both feet
            trajectory, reference, contacts = started_at, held_reference, gait.contacts
            record["start"] = {"skipped_s": skip / fps, "lead_in_s": hold / fps}
    task = reference
    if gait is not None:
        task = gait.qpos
        record["gait"] = gait.record()
    elif config.zmp_shift:
        shifted = shift_com(index, reference, fps, contacts, margin_m=config.zmp_margin_m, axes=config.zmp_axes)
        task = shifted.qpos
        record["zmp_shift"] = shifted.record()
    timing["zmp_shift"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    joint_pos, joint_vel, torque = required_torque(index, task, fps, config.contact_height_m, config.friction)
    stiffness, damping = servo_gains(servo_model(index, config.timestep_s)[0], index)
    goals = feedforward_goals(index, joint_pos, joint_vel, torque, fps, stiffness, damping, config.goal_velocity_fraction)
    plan_contacts = gait.contacts if gait is not None else sole_contacts(index, task, config.contact_height_m)
    plan = build_plan(index, task, fps, plan_contacts, config.balance) \
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
    out = dataclasses.replace(trajectory, qpos=executed, reference_qpos=reference,
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
