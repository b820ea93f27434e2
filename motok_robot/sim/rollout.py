"""Physics rollout: the robot tracks the trajectory with its own actuators.

The robot starts at frame 0 (``qpos[0]``, base velocity and joint velocities from the
reference's finite differences, or the file's ``initial_qvel``), with its free base, gravity
and contacts.  Closed loop (validation's default), the balance controller of
:mod:`motok_robot.feasibility.balance` corrects the servo goals every 8 ms tick from the
simulated IMU and the goals are held over the tick, as playback sends them
(:mod:`motok_robot.feasibility.physics`).  Open loop, the actuators receive the servo goals
linearly interpolated from the clip's frame rate to the physics timestep (each step gets the
target of the step's end time) and the rollout runs in C with ``mujoco.rollout``.

Servo goals: the reference joint angles, or the feedforward goals of
:mod:`motok_robot.feasibility.feedforward` (validation's default, which playback then streams).

Servo model: the robot's own actuators.  Position actuators (affine bias with a negative
position gain: MuJoCo ``<position>``) get the target angle as control (times the
transmission gear).  Plain motors are given a PD servo law on a copy of the model:
``kp = motor_kp_per_nm x force limit`` (N m/rad), ``kd = motor_kd_ratio x kp``, their force
limits kept.

Fall detection (per physics step, relative to the reference so a deliberate squat or bow is
no fall): the root body is lower than ``fall_height_ratio`` x the reference root height at
that time, or its up axis is tilted more than ``fall_tilt_rad`` from the reference's up axis.

Centre of pressure: sampled at ``cop_rate_hz``; the state is restored (``mj_setState``),
``mj_forward`` recomputes the contacts, and the CoP is the normal-force weighted mean of the
floor contact points.  It is compared with the support polygon of the simulated soles in
contact (convex hull of their corner sites): a CoP outside means something other than the
soles carries load; a CoP on the edge means the robot is tipping.

Tracking RMSE and base drift are measured at the reference frame times before the fall
(the whole clip when it does not fall).

Robustness tests change the physics only: ``model`` (a changed copy of :func:`servo_model`, e.g.
stiffer servos or heavier links) and ``pushes`` (:class:`Push`, external forces on a body during
the rollout); the reference, the servo goals and the balance plan stay as given.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import mujoco
import numpy as np
from mujoco import rollout as mj_rollout

from motok_robot.feasibility.balance import BalanceController, BalancePlan
from motok_robot.feasibility.dynamics import finite_difference_qvel
from motok_robot.feasibility.physics import ServoPhysics
from motok_robot.feasibility.physics import servo_model as physics_servo_model
from motok_robot.robots.index import RobotIndex
from motok_robot.sim.config import ValidationConfig
from motok_robot.feasibility.geometry import convex_hull, signed_distance


@dataclass
class RolloutResult:
    """What happened in physics.  Frame arrays are sampled at the reference frame times
    (T frames at ``fps``); CoP arrays at ``cop_rate_hz`` (S samples)."""

    fps: float
    timestep: float                  # physics timestep (s)
    qpos: np.ndarray                 # [T, nq] simulated qpos at the reference frame times
    fell: bool
    fall_time_s: float | None        # first time the fall criteria hold
    fall_reason: str | None          # "height" or "tilt"
    root_height: np.ndarray          # [T] m, simulated root body height
    root_tilt: np.ndarray            # [T] rad, angle between simulated and reference up axes
    tracking_error: np.ndarray       # [T, nj] rad, simulated - reference joint angle
    tracking_rmse_per_joint: np.ndarray  # [nj] rad (frames before the fall)
    tracking_rmse: float             # rad, RMS over joints and frames before the fall
    base_drift: np.ndarray           # [T] m, horizontal root distance sim vs reference
    cop_time: np.ndarray             # [S] s
    cop: np.ndarray                  # [S, 2] m (NaN without floor contact)
    cop_margin: np.ndarray           # [S] m, signed distance to the simulated sole polygon
    cop_support: list                # S hulls [H, 2]
    valid_frames: np.ndarray         # bool [T] frames before the fall
    step_qpos: np.ndarray            # [nstep + 1, nq] qpos at every physics step (row 0: start)
    wall_s: float = 0.0


@dataclass(frozen=True)
class Push:
    """An external force on one body during a rollout: ``force`` (N, world frame, at the body's
    centre of mass) from ``start_s`` for ``duration_s`` (a step gets it when it starts inside)."""

    body: int
    force: tuple[float, float, float]
    start_s: float
    duration_s: float = 0.1


def push_wrench(pushes: Sequence[Push], nbody: int, time_s: float) -> np.ndarray:
    """``xfrc_applied`` [nbody, 6] of a physics step starting at ``time_s``."""
    out = np.zeros((nbody, 6))
    for push in pushes:
        if push.start_s <= time_s + 1e-9 and time_s + 1e-9 < push.start_s + push.duration_s:
            out[push.body, :3] += push.force
    return out


def servo_model(index: RobotIndex, config: ValidationConfig) -> tuple[mujoco.MjModel, np.ndarray]:
    """Copy of the robot model ready for tracking, and each actuator's gear [nu]
    (:func:`motok_robot.feasibility.physics.servo_model` with the validation settings)."""
    return physics_servo_model(index, config.physics_timestep_s, config.motor_kp_per_nm, config.motor_kd_ratio)


def _up_axis(quat: np.ndarray) -> np.ndarray:
    """World up axis [N, 3] of bodies with orientations ``quat`` [N, 4] (wxyz)."""
    w, x, y, z = quat.T
    return np.stack([2 * (x * z + w * y), 2 * (y * z - w * x), 1 - 2 * (x * x + y * y)], axis=1)


def simulate(index: RobotIndex, qpos: np.ndarray, fps: float, config: ValidationConfig,
             goals: np.ndarray | None = None, plan: BalancePlan | None = None,
             initial_qvel: np.ndarray | None = None, judge_qpos: np.ndarray | None = None,
             model: mujoco.MjModel | None = None, pushes: Sequence[Push] = (),
             track_qpos: np.ndarray | None = None) -> RolloutResult:
    """Roll the robot out in physics tracking ``qpos`` [T, nq] (frames at ``fps``).

    ``goals`` [T, nj] (rad, robot joint order) are the servo goals when they differ from the
    reference joint angles (feedforward, :mod:`motok_robot.feasibility.feedforward`); tracking error,
    drift and falls are always measured against ``qpos``.  With a balance ``plan`` the robot runs
    closed loop: the balance controller corrects the goals at its rate from the simulated IMU
    (:mod:`motok_robot.feasibility.physics`), goals held over each controller tick.

    The robot starts at ``qpos[0]`` with ``initial_qvel`` (default: the finite-difference velocity
    of ``qpos``).  Falls, tracking and drift are judged against ``judge_qpos`` when given (the
    kinematic reference of an executed trajectory), else against ``qpos``; tracking is judged
    against ``track_qpos`` when given (what the servos were commanded to follow).  ``model`` replaces
    the servo model (default ``servo_model(index, config)``; a changed copy of it tests
    robustness) and ``pushes`` are applied during the rollout."""
    import time as _time

    start = _time.perf_counter()
    if model is None:
        model, gear = servo_model(index, config)
    else:
        gear = np.where(model.actuator_gear[:, 0] == 0, 1.0, model.actuator_gear[:, 0])
    dt = float(model.opt.timestep)
    T = qpos.shape[0]
    duration = (T - 1) / fps
    nstep = max(1, int(round(duration / dt)))
    ref_time = np.arange(T) / fps
    step_end = (np.arange(nstep) + 1) * dt

    goal_frames = qpos[:, index.qpos_adr] if goals is None else np.asarray(goals, dtype=np.float64)
    qvel_ref = finite_difference_qvel(model, qpos[: min(T, 3)], fps)
    if initial_qvel is not None:
        qvel_ref[0] = initial_qvel
    judge = qpos if judge_qpos is None else np.asarray(judge_qpos, dtype=np.float64)
    spec = mujoco.mjtState.mjSTATE_FULLPHYSICS
    data = mujoco.MjData(model)
    if plan is None:
        # open loop: controls [nstep, nu], the target angle at each step's end time times the gear
        control = np.zeros((nstep, model.nu))
        for a in range(model.nu):
            j = index.actuator_joint[a]
            if j >= 0:
                control[:, a] = gear[a] * np.interp(step_end, ref_time, goal_frames[:, j])
        data.qpos[:] = qpos[0]
        data.qvel[:] = qvel_ref[0]
        data.ctrl[:] = control[0]
        mujoco.mj_forward(model, data)
        initial = np.zeros(mujoco.mj_stateSize(model, spec))
        mujoco.mj_getState(model, data, initial, spec)
        if pushes:  # each step's control is then its ctrl followed by its xfrc_applied
            wrench = np.stack([push_wrench(pushes, model.nbody, i * dt).ravel() for i in range(nstep)])
            states, _ = mj_rollout.rollout(model, data, initial[None], np.hstack([control, wrench])[None],
                                           control_spec=mujoco.mjtState.mjSTATE_CTRL | mujoco.mjtState.mjSTATE_XFRC_APPLIED)
        else:
            states, _ = mj_rollout.rollout(model, data, initial[None], control[None])
        states = states[0]  # [nstep, nstate] state after each step
    else:
        physics = ServoPhysics(index, rate_hz=plan.config.rate_hz, model=model)
        initial = physics.initial_state(qpos[0], qvel_ref[0], goal_frames[0])
        controller = BalanceController(plan, index.joint_range)

        def push(step, b, data):
            data.xfrc_applied[:] = push_wrench(pushes, model.nbody, step * dt)

        out = physics.run(initial[None], goal_frames, fps, duration, controller, perturb=push if pushes else None)
        states = out["states"][0]
        nstep = states.shape[0]
        step_end = out["step_time"]
        tick_of_step = np.arange(nstep) // physics.steps_per_tick
        control = np.zeros((nstep, model.nu))
        for j, a in enumerate(physics.actuator_of_joint):
            if a >= 0:
                control[:, a] = gear[a] * out["commands"][0, tick_of_step, j]
    all_qpos = states[:, 1:1 + model.nq]

    # per-step fall detection against the reference interpolated at each step's end
    ref_z = np.interp(step_end, ref_time, judge[:, 2])
    ref_quat = np.stack([np.interp(step_end, ref_time, judge[:, 3 + i]) for i in range(4)], axis=1)
    ref_quat /= np.linalg.norm(ref_quat, axis=1, keepdims=True)
    up_sim = _up_axis(all_qpos[:, 3:7] / np.linalg.norm(all_qpos[:, 3:7], axis=1, keepdims=True))
    up_ref = _up_axis(ref_quat)
    tilt = np.arccos(np.clip((up_sim * up_ref).sum(1), -1.0, 1.0))
    low = all_qpos[:, 2] < config.fall_height_ratio * ref_z
    tilted = tilt > config.fall_tilt_rad
    fallen = low | tilted
    fell = bool(fallen.any())
    fall_time = fall_reason = None
    if fell:
        first = int(np.argmax(fallen))
        fall_time = float(step_end[first])
        fall_reason = "height" if low[first] else "tilt"

    # sample at the reference frame times (frame 0 = the initial state)
    frame_step = np.clip(np.round(ref_time / dt).astype(int) - 1, -1, nstep - 1)
    sim_qpos = np.where(frame_step[:, None] < 0, qpos[0][None], all_qpos[np.maximum(frame_step, 0)])
    valid = np.ones(T, dtype=bool) if not fell else ref_time < fall_time
    valid[0] = True
    track = judge if track_qpos is None else np.asarray(track_qpos, dtype=np.float64)
    err = sim_qpos[:, index.qpos_adr] - track[:, index.qpos_adr]
    rmse_joint = np.sqrt((err[valid] ** 2).mean(axis=0))
    rmse = float(np.sqrt((err[valid] ** 2).mean()))
    drift = np.linalg.norm(sim_qpos[:, :2] - judge[:, :2], axis=1)
    frame_tilt = np.interp(ref_time, step_end, tilt, left=0.0)

    # centre of pressure
    n_cop = max(2, int(round(duration * config.cop_rate_hz)) + 1)
    cop_time = np.linspace(0.0, duration, n_cop)
    cop_step = np.clip(np.round(cop_time / dt).astype(int) - 1, 0, nstep - 1)
    cop = np.full((n_cop, 2), np.nan)
    cop_margin = np.full(n_cop, np.nan)
    hulls = []
    is_floor = model.geom_bodyid == 0
    pyramid = model.opt.cone == mujoco.mjtCone.mjCONE_PYRAMIDAL
    for s, step in enumerate(cop_step):
        mujoco.mj_setState(model, data, states[step], spec)
        data.ctrl[:] = control[step]
        if pushes:
            data.xfrc_applied[:] = push_wrench(pushes, model.nbody, step_end[step])
        mujoco.mj_forward(model, data)
        total, weighted = 0.0, np.zeros(2)
        if data.ncon:
            contacts = data.contact
            robot_floor = is_floor[contacts.geom1] != is_floor[contacts.geom2]
            adr, dim = contacts.efc_address, contacts.dim
            if pyramid:  # the normal force is the sum of the pyramid facet forces
                normal = np.array([data.efc_force[a:a + max(1, 2 * (k - 1))].sum() if a >= 0 else 0.0
                                   for a, k in zip(adr, dim)])
            else:
                normal = np.where(adr >= 0, data.efc_force[np.maximum(adr, 0)], 0.0)
            normal = np.abs(normal * contacts.frame[:, 2]) * robot_floor  # world-vertical part
            total = float(normal.sum())
            weighted = normal @ contacts.pos[:, :2]
        corners = data.site_xpos[index.corner_sites]  # [2, 4, 3]
        in_contact = corners[:, :, 2].min(axis=1) < config.contact_height_m
        hull = convex_hull(corners[in_contact].reshape(-1, 3)[:, :2]) if in_contact.any() else np.zeros((0, 2))
        hulls.append(hull)
        if total > 1e-6:
            cop[s] = weighted / total
            if len(hull):
                cop_margin[s] = signed_distance(cop[s], hull)
    return RolloutResult(
        fps=fps, timestep=dt, qpos=sim_qpos, fell=fell, fall_time_s=fall_time, fall_reason=fall_reason,
        root_height=sim_qpos[:, 2], root_tilt=frame_tilt, tracking_error=err, tracking_rmse_per_joint=rmse_joint,
        tracking_rmse=rmse, base_drift=drift, cop_time=cop_time, cop=cop, cop_margin=cop_margin,
        cop_support=hulls, valid_frames=valid, step_qpos=np.vstack([qpos[:1], all_qpos]), wall_s=_time.perf_counter() - start)
